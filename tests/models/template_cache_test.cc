#include "models/template_cache.h"

#include <gtest/gtest.h>

#include <chrono>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <utility>
#include <vector>

#include "models/error.h"
#include "models/fnv1a.h"
#include "models/mesh_export.h"
#include "models/template_generator.h"
#include "tests/error_of.h"
#include "tests/testing_util.h"

namespace artex {
namespace {

namespace fs = std::filesystem;
using testing_util::FreshTempDir;
using testing_util::ReadFileBytes;

// Every field of the two templates, exactly (== on doubles: bit for bit but for -0 and NaN,
// which a template does not hold).
void ExpectIdentical(const Template& a, const Template& b) {
  EXPECT_TRUE(a.vertices == b.vertices);
  EXPECT_TRUE(a.triangles == b.triangles);
  EXPECT_TRUE(a.uvs == b.uvs);
  EXPECT_TRUE(a.uv_triangles == b.uv_triangles);
  EXPECT_TRUE(a.triangle_chart == b.triangle_chart);
  ASSERT_EQ(a.joints.size(), b.joints.size());
  for (size_t j = 0; j < a.joints.size(); ++j) {
    EXPECT_EQ(a.joints[j].name, b.joints[j].name);
    EXPECT_EQ(a.joints[j].parent, b.joints[j].parent);
    EXPECT_TRUE(a.joints[j].center == b.joints[j].center);
    EXPECT_TRUE(a.joints[j].twist_axis == b.joints[j].twist_axis);
  }
  EXPECT_TRUE(a.vertex_joint == b.vertex_joint);
  EXPECT_TRUE(a.lbs_weight == b.lbs_weight);
  EXPECT_TRUE(a.slerp_tau == b.slerp_tau);
}

const Template& Coarse() {
  static const Template t = [] {
    BodyShapeOptions o;
    o.resolution = 0;
    return GenerateTemplate(o);
  }();
  return t;
}

void WriteBytes(const fs::path& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

TEST(TemplateCacheTest, TheBinaryFileKeepsEveryField) {
  const fs::path dir = FreshTempDir("template_cache_roundtrip");
  const std::string path = (dir / "t.bin").string();
  WriteTemplateBinary(Coarse(), path);
  ExpectIdentical(ReadTemplateBinary(path), Coarse());
  // No temporary file is left beside it.
  int files = 0;
  for (const auto& entry : fs::directory_iterator(dir)) files += entry.is_regular_file();
  EXPECT_EQ(files, 1);
}

TEST(TemplateCacheTest, ADamagedFileIsRejectedNamingWhatIsWrong) {
  const fs::path dir = FreshTempDir("template_cache_damaged");
  const std::string path = (dir / "t.bin").string();
  WriteTemplateBinary(Coarse(), path);
  const std::string good = ReadFileBytes(path);

  std::string flipped = good;
  flipped[good.size() / 2] ^= 0x10;
  WriteBytes(path, flipped);
  std::string error = ErrorOf([&] { ReadTemplateBinary(path); });
  EXPECT_NE(error.find(path), std::string::npos) << error;
  EXPECT_NE(error.find("checksum"), std::string::npos) << error;

  WriteBytes(path, good.substr(0, good.size() / 3));
  EXPECT_NE(ErrorOf([&] { ReadTemplateBinary(path); }).find("checksum"), std::string::npos);

  WriteBytes(path, "GLTF" + good.substr(4));
  error = ErrorOf([&] { ReadTemplateBinary(path); });
  EXPECT_NE(error.find("header"), std::string::npos) << error;

  WriteBytes(path, "");
  EXPECT_NE(ErrorOf([&] { ReadTemplateBinary(path); }).find("header"), std::string::npos);

  error = ErrorOf([&] { ReadTemplateBinary((dir / "absent.bin").string()); });
  EXPECT_NE(error.find((dir / "absent.bin").string() + ": no such file"), std::string::npos)
      << error;
}

// A header whose counts promise more than the file holds (a consistent checksum: written by
// something else than artex) is reported as truncated, not read past its end.
TEST(TemplateCacheTest, CountsBeyondTheFileAreReportedAsTruncated) {
  const fs::path dir = FreshTempDir("template_cache_counts");
  const std::string path = (dir / "t.bin").string();
  std::string bytes = "ARTEXTPL";
  const auto put = [&](auto value) {
    bytes.append(reinterpret_cast<const char*>(&value), sizeof(value));
  };
  put(std::uint32_t{1});
  put(std::uint64_t{1000});  // vertices: 1000 rows
  put(std::uint64_t{3000});  // 3000 entries, none present
  put(Fnv1a(bytes));
  WriteBytes(path, bytes);
  const std::string error = ErrorOf([&] { ReadTemplateBinary(path); });
  EXPECT_NE(error.find("vertices"), std::string::npos) << error;
  EXPECT_NE(error.find("truncated"), std::string::npos) << error;
}

// The default template: generated and written on the first call, read on the next, the same
// bit for bit; a damaged file is generated again and rewritten with a note; other builds'
// files beyond the limit are removed, the oldest first.
TEST(TemplateCacheTest, TheDefaultTemplateIsWrittenOnceAndReadBack) {
  if (ProgramBuildId().empty()) GTEST_SKIP() << "this build has no GNU build ID: no cache";
  const fs::path dir = FreshTempDir("template_cache_default");
  TemplateCacheOptions options;
  options.directory = (dir / "cache").string();
  options.keep_files = 3;
  // Other builds' files, older than this one's will be, and two temporary files of crashed
  // writers (the older than an hour is removed, the recent one may still be being written).
  for (int k = 0; k < 4; ++k) {
    const fs::path other = dir / "cache" / ("template-old" + std::to_string(k) + ".bin");
    fs::create_directories(other.parent_path());
    WriteBytes(other, "other build");
    fs::last_write_time(other, fs::file_time_type::clock::now() - std::chrono::hours(10 - k));
  }
  const fs::path crashed = dir / "cache" / ".template-old9.bin.tmp-12-0";
  const fs::path writing = dir / "cache" / ".template-old9.bin.tmp-13-0";
  WriteBytes(crashed, "part");
  WriteBytes(writing, "part");
  fs::last_write_time(crashed, fs::file_time_type::clock::now() - std::chrono::hours(2));
  std::string note = "stale";
  const Template generated = DefaultTemplate(options, &note);
  EXPECT_EQ(note, "");
  const fs::path file = dir / "cache" / ("template-" + ProgramBuildId() + ".bin");
  ASSERT_TRUE(fs::exists(file));
  // Three kept: this build's and the two newest others.
  EXPECT_FALSE(fs::exists(dir / "cache" / "template-old0.bin"));
  EXPECT_FALSE(fs::exists(dir / "cache" / "template-old1.bin"));
  EXPECT_TRUE(fs::exists(dir / "cache" / "template-old2.bin"));
  EXPECT_TRUE(fs::exists(dir / "cache" / "template-old3.bin"));
  EXPECT_FALSE(fs::exists(crashed));
  EXPECT_TRUE(fs::exists(writing));

  // Read back: the generated template bit for bit, the file untouched.
  const auto written = fs::last_write_time(file);
  const Template cached = DefaultTemplate(options, &note);
  EXPECT_EQ(note, "");
  ExpectIdentical(cached, generated);
  EXPECT_EQ(fs::last_write_time(file), written);

  // Damaged: generated again, rewritten, and said so.
  std::string bytes = ReadFileBytes(file);
  bytes[100] ^= 1;
  WriteBytes(file, bytes);
  const Template repaired = DefaultTemplate(options, &note);
  ExpectIdentical(repaired, generated);
  EXPECT_NE(note.find(file.string()), std::string::npos) << note;
  EXPECT_NE(note.find("generated again"), std::string::npos) << note;
  ExpectIdentical(ReadTemplateBinary(file.string()), generated);
}

// The cache prunes a crashed writer's temporaries by the name WriteFileAtomically gives them:
// AtomicWriteTarget reads the target back from the temporary that exists while it writes.
TEST(TemplateCacheTest, AtomicWriteTargetNamesTheFileATemporaryIsFor) {
  const fs::path dir = FreshTempDir("template_cache_tmp_name");
  std::vector<std::string> seen;  // the folder while the contents are written
  WriteFileAtomically((dir / "template-abc.bin").string(), [&](std::ostream& out) {
    for (const auto& e : fs::directory_iterator(dir)) seen.push_back(e.path().filename().string());
    out << "x";
  });
  ASSERT_EQ(seen.size(), 1u);
  EXPECT_EQ(AtomicWriteTarget(seen[0]), "template-abc.bin") << seen[0];
  EXPECT_EQ(AtomicWriteTarget(".a.tmp-x.bin.tmp-12-3"), "a.tmp-x.bin");
  for (const std::string name : {"template-abc.bin", ".tmp-1-2", "a.tmp-1-2", "", "."})
    EXPECT_EQ(AtomicWriteTarget(name), "") << name;
}

// No cache: disabled, or a folder that cannot be made (a path through a file; root may write
// anywhere else). The template is generated all the same.
TEST(TemplateCacheTest, WithoutAUsableFolderTheTemplateIsGenerated) {
  const fs::path dir = FreshTempDir("template_cache_none");
  WriteBytes(dir / "file", "a file, not a folder");
  TemplateCacheOptions options;
  options.directory = (dir / "file" / "cache").string();
  std::string note;
  const Template t = DefaultTemplate(options, &note);
  EXPECT_EQ(t.num_vertices(), GenerateTemplate().num_vertices());
  if (!ProgramBuildId().empty()) {
    EXPECT_NE(note.find("cache"), std::string::npos) << note;
    EXPECT_NE(note.find("generated at every run"), std::string::npos) << note;
  }

  options.directory = (dir / "off").string();
  options.enabled = false;
  DefaultTemplate(options, &note);
  EXPECT_EQ(note, "");
  EXPECT_FALSE(fs::exists(dir / "off"));

  options.keep_files = 0;
  EXPECT_NE(ErrorOf([&] { DefaultTemplate(options); }).find("template_cache_keep"),
            std::string::npos);
}

// The environment variables as they were, restored when it ends.
class SavedEnvironment {
 public:
  explicit SavedEnvironment(std::vector<std::string> names) : names_(std::move(names)) {
    for (const std::string& n : names_) {
      const char* v = std::getenv(n.c_str());
      values_.emplace_back(v != nullptr, v != nullptr ? v : "");
    }
  }
  ~SavedEnvironment() {
    for (size_t k = 0; k < names_.size(); ++k) {
      if (values_[k].first) {
        setenv(names_[k].c_str(), values_[k].second.c_str(), 1);
      } else {
        unsetenv(names_[k].c_str());
      }
    }
  }

 private:
  std::vector<std::string> names_;
  std::vector<std::pair<bool, std::string>> values_;
};

TEST(TemplateCacheTest, TheFolderFollowsTheEnvironment) {
  const SavedEnvironment saved({"ARTEX_CACHE_DIR", "XDG_CACHE_HOME", "HOME"});
  unsetenv("ARTEX_CACHE_DIR");
  unsetenv("XDG_CACHE_HOME");
  TemplateCacheOptions options;
  options.directory = "/given";
  EXPECT_EQ(TemplateCacheDirectory(options), "/given");
  options.directory.clear();
  setenv("ARTEX_CACHE_DIR", "/artex-cache", 1);
  EXPECT_EQ(TemplateCacheDirectory(options), "/artex-cache");
  unsetenv("ARTEX_CACHE_DIR");
  setenv("XDG_CACHE_HOME", "/xdg", 1);
  EXPECT_EQ(TemplateCacheDirectory(options), "/xdg/artex");
  unsetenv("XDG_CACHE_HOME");
  setenv("HOME", "/home/someone", 1);
  EXPECT_EQ(TemplateCacheDirectory(options), "/home/someone/.cache/artex");
  unsetenv("HOME");
  EXPECT_EQ(TemplateCacheDirectory(options), "");
}

}  // namespace
}  // namespace artex
