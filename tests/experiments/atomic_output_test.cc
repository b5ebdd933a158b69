// AtomicOutputFolder (experiments/atomic_output.h) and the commands that use it: an output
// folder is complete or absent, an overwrite never mixes old and new files (issue 20). kill -9
// of the commands at random points: tests/experiments/fault_test.cc.
#include "experiments/atomic_output.h"

#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "models/error.h"
#include "tests/error_of.h"
#include "tests/testing_util.h"

namespace artex {
namespace {

namespace fs = std::filesystem;
using testing_util::ReadFileBytes;

fs::path FreshDir(const std::string& name) {
  return testing_util::FreshTempDir("atomic_test_" + name);
}

void WriteText(const fs::path& path, const std::string& text) { std::ofstream(path) << text; }

std::vector<std::string> Entries(const fs::path& dir) {
  std::vector<std::string> names;
  for (const auto& e : fs::directory_iterator(dir)) names.push_back(e.path().filename().string());
  std::sort(names.begin(), names.end());
  return names;
}

TEST(AtomicOutputTest, CommitReplacesTheEarlierResultWithoutStaleFiles) {
  const fs::path root = FreshDir("commit");
  const fs::path out = root / "out";
  {
    AtomicOutputFolder folder(out.string(), "test");
    EXPECT_FALSE(fs::exists(out));  // nothing visible before the commit
    WriteText(fs::path(folder.path()) / "stale.txt", "old");
    WriteText(fs::path(folder.path()) / "result.txt", "old");
    folder.Commit();
  }
  EXPECT_TRUE(IsCompleteOutputFolder(out.string()));
  {
    AtomicOutputFolder folder((out.string() + "/"), "test");
    WriteText(fs::path(folder.path()) / "result.txt", "new");
    EXPECT_EQ(ReadFileBytes(out / "result.txt"), "old");  // the earlier result until the commit
    folder.Commit();
  }
  EXPECT_EQ(Entries(out), (std::vector<std::string>{kOutputMarker, "result.txt"}));
  EXPECT_EQ(ReadFileBytes(out / "result.txt"), "new");
  EXPECT_EQ(Entries(root), (std::vector<std::string>{"out"}));  // no temporaries left
}

TEST(AtomicOutputTest, AnAbandonedRunLeavesTheEarlierResult) {
  const fs::path root = FreshDir("abandon");
  const fs::path out = root / "out";
  {
    AtomicOutputFolder folder(out.string(), "test");
    WriteText(fs::path(folder.path()) / "result.txt", "old");
    folder.Commit();
  }
  {
    AtomicOutputFolder folder(out.string(), "test");
    WriteText(fs::path(folder.path()) / "result.txt", "half");
    // An error: no Commit().
  }
  EXPECT_EQ(ReadFileBytes(out / "result.txt"), "old");
  EXPECT_EQ(Entries(root), (std::vector<std::string>{"out"}));
}

TEST(AtomicOutputTest, FoldersArtexDidNotWriteAreNeverReplaced) {
  const fs::path root = FreshDir("foreign");
  WriteText(root / "mine" / "notes.txt", "");
  fs::create_directories(root / "mine");
  WriteText(root / "mine" / "notes.txt", "keep");
  std::string what = ErrorOf([&] { AtomicOutputFolder((root / "mine").string(), "test"); });
  EXPECT_NE(what.find("mine"), std::string::npos) << what;
  EXPECT_NE(what.find("not an artex output folder"), std::string::npos) << what;
  EXPECT_EQ(ReadFileBytes(root / "mine" / "notes.txt"), "keep");
  WriteText(root / "file", "x");
  what = ErrorOf([&] { AtomicOutputFolder((root / "file").string(), "test"); });
  EXPECT_NE(what.find("found a file"), std::string::npos) << what;
  fs::create_directories(root / "empty");  // an empty folder is fine
  AtomicOutputFolder((root / "empty").string(), "test").Commit();
  EXPECT_TRUE(IsCompleteOutputFolder((root / "empty").string()));
}

TEST(AtomicOutputTest, LeftoversOfKilledRunsAreRemoved) {
  const fs::path root = FreshDir("leftovers");
  // pid_max is at most 2^22 on Linux: 999999999 is no process.
  fs::create_directories(root / ".out.partial-999999999");
  fs::create_directories(root / ".out.old-999999999");
  fs::create_directories(root / ".other.partial-999999999");  // another folder's: kept
  AtomicOutputFolder((root / "out").string(), "test").Commit();
  EXPECT_EQ(Entries(root), (std::vector<std::string>{".other.partial-999999999", "out"}));
}

}  // namespace
}  // namespace artex
