#include "experiments/config.h"

#include <cstdio>
#include <fstream>
#include <map>
#include <string>

#include <gtest/gtest.h>

#include "models/error.h"
#include "tests/error_of.h"

namespace artex {
namespace {

enum class Color { kRed, kGreen };
const std::map<std::string, Color> kColors = {{"red", Color::kRed}, {"green", Color::kGreen}};

TEST(ConfigTest, ReadsTypedValuesAndLeavesAbsentKeysUntouched) {
  Config c = Config::FromString("fitting:\n  eps: 0.5\n  iterations: 12\n  dense: true\n"
                                "  name: gn\n  radii: [0.15, 0.1]\n", "test.yaml");
  Config f = c.Section("fitting");
  double eps = 0;
  int it = 0;
  bool dense = false;
  std::string name;
  std::vector<double> radii;
  double untouched = 7.0;
  f.Get("eps", &eps);
  f.Get("iterations", &it);
  f.Get("dense", &dense);
  f.Get("name", &name);
  f.Get("radii", &radii);
  f.Get("missing", &untouched);
  EXPECT_DOUBLE_EQ(eps, 0.5);
  EXPECT_EQ(it, 12);
  EXPECT_TRUE(dense);
  EXPECT_EQ(name, "gn");
  ASSERT_EQ(radii.size(), 2u);
  EXPECT_DOUBLE_EQ(radii[1], 0.1);
  EXPECT_DOUBLE_EQ(untouched, 7.0);
}

TEST(ConfigTest, WrongTypeNamesFileKeyAndValue) {
  Config c = Config::FromString("fitting:\n  eps: abc\n", "run.yaml");
  double eps = 0;
  const std::string msg = ErrorOf([&] { c.Section("fitting").Get("eps", &eps); });
  EXPECT_NE(msg.find("run.yaml"), std::string::npos) << msg;
  EXPECT_NE(msg.find("fitting.eps"), std::string::npos) << msg;
  EXPECT_NE(msg.find("abc"), std::string::npos) << msg;
}

TEST(ConfigTest, UnknownKeyListsValidKeys) {
  Config c = Config::FromString("fitting:\n  epz: 1\n", "run.yaml");
  const std::string msg = ErrorOf([&] { c.Section("fitting").CheckKeys({"eps", "iterations"}); });
  EXPECT_NE(msg.find("fitting.epz"), std::string::npos) << msg;
  EXPECT_NE(msg.find("eps"), std::string::npos) << msg;
  EXPECT_NE(msg.find("iterations"), std::string::npos) << msg;
}

TEST(ConfigTest, EnumChoicesAreValidated) {
  Config c = Config::FromString("color: blue\nother: green\n", "e.yaml");
  Color color = Color::kRed;
  c.GetEnum("other", kColors, &color);
  EXPECT_EQ(color, Color::kGreen);
  const std::string msg = ErrorOf([&] { c.GetEnum("color", kColors, &color); });
  EXPECT_NE(msg.find("blue"), std::string::npos) << msg;
  EXPECT_NE(msg.find("green"), std::string::npos) << msg;
  EXPECT_NE(msg.find("red"), std::string::npos) << msg;
}

TEST(ConfigTest, OverridesCreateNestedKeys) {
  Config c = Config::FromString("texture:\n  lambda: 1\n", "o.yaml");
  c.Set("texture.lambda", "0.25");
  c.Set("fitting.solver", "ceres_lm");
  double lambda = 0;
  std::string solver;
  c.Section("texture").Get("lambda", &lambda);
  c.Section("fitting").Get("solver", &solver);
  EXPECT_DOUBLE_EQ(lambda, 0.25);
  EXPECT_EQ(solver, "ceres_lm");
  // The resolved YAML reads back to the same values.
  Config again = Config::FromString(c.ToYaml(), "resolved.yaml");
  again.Section("texture").Get("lambda", &lambda);
  EXPECT_DOUBLE_EQ(lambda, 0.25);
}

TEST(ConfigTest, MissingAndMalformedFilesAreErrors) {
  EXPECT_NE(ErrorOf([] { Config::Load("/nonexistent/artex.yaml"); }).find("/nonexistent/artex.yaml"),
            std::string::npos);
  const std::string path = testing::TempDir() + "/bad_config.yaml";
  {
    std::ofstream out(path);
    out << "a: [1, 2\n";
  }
  EXPECT_NE(ErrorOf([&] { Config::Load(path); }).find("bad_config.yaml"), std::string::npos);
  std::remove(path.c_str());
  EXPECT_NE(ErrorOf([] { Config::FromString("- 1\n- 2\n", "list.yaml"); }).find("mapping"),
            std::string::npos);
}

// Issue 20: duplicate keys were dropped silently, `--set key=` was ignored, a folder given
// as the file failed with "basic_filebuf::underflow" and no path, non-scalar keys with
// yaml-cpp's unnamed "bad conversion".
TEST(ConfigTest, DuplicateKeysEmptyOverridesFoldersAndOddKeysAreErrors) {
  std::string what = ErrorOf(
      [] { Config::FromString("texture:\n  lambda: 1\n  alpha: 2\n  lambda: 3\n", "dup.yaml"); });
  EXPECT_NE(what.find("dup.yaml: line 4"), std::string::npos) << what;
  EXPECT_NE(what.find("texture.lambda"), std::string::npos) << what;
  EXPECT_NE(what.find("defined twice (first at line 2)"), std::string::npos) << what;
  what = ErrorOf([] { Config::FromString("[a, b]: 1\n", "key.yaml"); });
  EXPECT_NE(what.find("key.yaml"), std::string::npos) << what;
  EXPECT_NE(what.find("plain key"), std::string::npos) << what;
  Config c;
  what = ErrorOf([&] { c.Set("texture.lambda", ""); });
  EXPECT_NE(what.find("texture.lambda"), std::string::npos) << what;
  EXPECT_NE(what.find("expected a value"), std::string::npos) << what;
  EXPECT_NE(ErrorOf([&] { c.Set("texture.lambda", "  "); }), "");
  EXPECT_EQ(ErrorOf([&] { c.Set("texture.lambda", "0"); }), "");
  const std::string folder = testing::TempDir();
  what = ErrorOf([&] { Config::Load(folder); });
  EXPECT_NE(what.find(folder), std::string::npos) << what;
  EXPECT_NE(what.find("found a folder"), std::string::npos) << what;
}

TEST(ConfigTest, NonFiniteNumberIsRejected) {
  Config c = Config::FromString("x: .nan\n", "n.yaml");
  double x = 0;
  EXPECT_THROW(c.Get("x", &x), Error);
}

// Issue 17: a bad override on the built-in defaults (no file) named an empty file name
// (": unknown key ..."); messages now name the override, or "built-in defaults".
TEST(ConfigTest, OverrideErrorsNameTheOverrideNotAnEmptyFileName) {
  Config c;
  c.Set("fitting.no_such_option", "1");
  std::string msg = ErrorOf([&] { c.Section("fitting").CheckKeys({"solver", "max_iterations"}); });
  EXPECT_EQ(msg.rfind("override fitting.no_such_option: unknown key 'fitting.no_such_option'", 0),
            0u)
      << msg;
  EXPECT_NE(msg.find("max_iterations"), std::string::npos) << msg;

  Config typed;
  typed.Set("fitting.max_iterations", "many");
  int it = 0;
  msg = ErrorOf([&] { typed.Section("fitting").Get("max_iterations", &it); });
  EXPECT_EQ(msg.rfind("override fitting.max_iterations: expected an integer", 0), 0u) << msg;

  // Keys from a file keep naming the file, also next to overrides.
  Config file = Config::FromString("fitting: {bad_key: 1}\n", "run.yaml");
  file.Set("fitting.solver", "gauss_newton");
  msg = ErrorOf([&] { file.Section("fitting").CheckKeys({"solver"}); });
  EXPECT_EQ(msg.rfind("run.yaml: unknown key 'fitting.bad_key'", 0), 0u) << msg;
  // A configuration without a file or overrides is called "built-in defaults".
  EXPECT_EQ(Config().Path("texture"), "built-in defaults: texture");
}

}  // namespace
}  // namespace artex

namespace artex {
namespace {

// Reading absent keys must not modify the document (yaml-cpp's non-const operator[] would
// insert pending nodes that later break emitting the resolved configuration).
TEST(ConfigTest, ReadingAbsentKeysLeavesTheDocumentIntact) {
  Config c = Config::FromString("pipeline:\n  max_frames: 0\nfitting:\n  k: 3\n", "r.yaml");
  const std::string before = c.ToYaml();
  double x = 1.0;
  int k = 0;
  for (int i = 0; i < 50; ++i) {
    c.Section("fitting").Get("absent", &x);
    c.Section("missing_section").Get("absent", &x);
    c.Section("fitting").Get("k", &k);
    EXPECT_FALSE(c.Has("nothing"));
  }
  EXPECT_EQ(c.ToYaml(), before);
  c.Set("pipeline.max_frames", "2");
  Config again = Config::FromString(c.ToYaml(), "again.yaml");
  int frames = 0;
  again.Section("pipeline").Get("max_frames", &frames);
  EXPECT_EQ(frames, 2);
  EXPECT_EQ(k, 3);
}

}  // namespace
}  // namespace artex
