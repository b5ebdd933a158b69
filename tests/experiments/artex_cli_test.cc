// Top-level behaviour of the `artex` tool (ARTEX_BINARY): --version, and the messages of bad
// --set overrides without a configuration file (issue 17).
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <string>

namespace artex {
namespace {

namespace fs = std::filesystem;

struct Result {
  int status = -1;
  std::string output;  // stdout and stderr
};

Result RunArtex(const std::string& args) {
  Result r;
  FILE* pipe = popen(("'" + std::string(ARTEX_BINARY) + "' " + args + " 2>&1").c_str(), "r");
  if (!pipe) return r;
  char buf[4096];
  while (fgets(buf, sizeof(buf), pipe)) r.output += buf;
  const int status = pclose(pipe);
  r.status = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

TEST(ArtexCliTest, VersionPrintsTheProjectVersionAndRevision) {
  const Result r = RunArtex("--version");
  EXPECT_EQ(r.status, 0) << r.output;
  EXPECT_EQ(r.output.rfind("artex 0.", 0), 0u) << r.output;
  EXPECT_NE(r.output.find("("), std::string::npos) << r.output;  // the source revision
}

TEST(ArtexCliTest, BadSetKeyWithoutConfigFileNamesTheOverride) {
  const fs::path out = fs::temp_directory_path() / ("artex_cli_test_" + std::to_string(getpid()));
  const Result r = RunArtex("track /nonexistent-recording -o '" + out.string() +
                            "' --set fitting.no_such_option=1");
  EXPECT_NE(r.status, 0);
  EXPECT_EQ(r.output.find("artex: error: : "), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("artex: error: override fitting.no_such_option: unknown key"),
            std::string::npos)
      << r.output;
  EXPECT_NE(r.output.find("max_iterations"), std::string::npos) << r.output;  // the valid keys
  EXPECT_FALSE(fs::exists(out));
}

}  // namespace
}  // namespace artex
