// AtomicOutputFolder (experiments/atomic_output.h) and the commands that use it: an output
// folder is complete or absent, an overwrite never mixes old and new files, and kill -9 at
// seeded random points of `artex synth` and `artex track` never leaves a folder that looks
// complete; the rerun gives the uninterrupted result (issue 20).
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

namespace artex {
namespace {

namespace fs = std::filesystem;

fs::path FreshDir(const std::string& name) {
  const fs::path dir =
      fs::temp_directory_path() / ("artex_atomic_test_" + name + "_" + std::to_string(getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

void WriteText(const fs::path& path, const std::string& text) { std::ofstream(path) << text; }

std::string ReadText(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

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
    EXPECT_EQ(ReadText(out / "result.txt"), "old");  // the earlier result until the commit
    folder.Commit();
  }
  EXPECT_EQ(Entries(out), (std::vector<std::string>{kOutputMarker, "result.txt"}));
  EXPECT_EQ(ReadText(out / "result.txt"), "new");
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
  EXPECT_EQ(ReadText(out / "result.txt"), "old");
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
  EXPECT_EQ(ReadText(root / "mine" / "notes.txt"), "keep");
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

// ---------------------------------------------------------------------------------------------
// kill -9 of the commands at seeded random points.

int Run(const std::string& command) {
  const int status = std::system((command + " > /dev/null 2>&1").c_str());
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

// Starts `argv` and kills it with SIGKILL after `delay`; returns false when it ended first.
bool KillAfter(const std::vector<std::string>& argv, std::chrono::microseconds delay) {
  const pid_t pid = fork();
  if (pid == 0) {
    std::vector<char*> args;
    for (const auto& a : argv) args.push_back(const_cast<char*>(a.c_str()));
    args.push_back(nullptr);
    freopen("/dev/null", "w", stdout);
    freopen("/dev/null", "w", stderr);
    execv(args[0], args.data());
    _exit(127);
  }
  std::this_thread::sleep_for(delay);
  int status = 0;
  const bool ended = waitpid(pid, &status, WNOHANG) == pid;
  if (!ended) {
    kill(pid, SIGKILL);
    waitpid(pid, &status, 0);
  }
  return !ended;
}

// Every file of a folder (relative path -> bytes), the marker included.
std::map<std::string, std::string> Snapshot(const fs::path& dir) {
  std::map<std::string, std::string> files;
  for (const auto& e : fs::recursive_directory_iterator(dir)) {
    if (e.is_regular_file()) files[fs::relative(e.path(), dir).string()] = ReadText(e.path());
  }
  return files;
}

// Runs `argv` (writing `out`) to completion once, then kills reruns at `points` seeded random
// times within the measured duration: after each kill, `out` is either absent or identical to
// the complete result, and a final rerun gives the complete result again. Timing-dependent
// outputs (`volatile_files`) are compared by name only.
void KillAtRandomPoints(const std::vector<std::string>& argv, const fs::path& out, int points,
                        uint32_t seed, const std::vector<std::string>& volatile_files) {
  const auto t0 = std::chrono::steady_clock::now();
  std::string command;
  for (const auto& a : argv) command += "'" + a + "' ";
  ASSERT_EQ(Run(command), 0) << command;
  const auto duration = std::chrono::steady_clock::now() - t0;
  auto comparable = [&](std::map<std::string, std::string> files) {
    for (const auto& name : volatile_files) {
      if (files.count(name)) files[name] = "";
    }
    return files;
  };
  const auto complete = comparable(Snapshot(out));
  ASSERT_TRUE(IsCompleteOutputFolder(out.string()));
  std::mt19937 rng(seed);
  const auto max_us = std::chrono::duration_cast<std::chrono::microseconds>(duration).count();
  std::uniform_int_distribution<long long> at(0, max_us);
  int killed = 0;
  for (int k = 0; k < points; ++k) {
    if (k % 2 == 1) fs::remove_all(out);  // half the kills over an earlier result, half not
    killed += KillAfter(argv, std::chrono::microseconds(at(rng)));
    if (fs::exists(out)) {
      EXPECT_TRUE(IsCompleteOutputFolder(out.string())) << "kill " << k;
      EXPECT_EQ(comparable(Snapshot(out)), complete) << "kill " << k << ": a mixed folder";
    }
  }
  EXPECT_GT(killed, 0);
  ASSERT_EQ(Run(command), 0) << command;
  EXPECT_EQ(comparable(Snapshot(out)), complete);
  for (const auto& e : fs::directory_iterator(out.parent_path())) {
    const std::string name = e.path().filename().string();
    EXPECT_EQ(name.find(".partial-"), std::string::npos) << name;
    EXPECT_EQ(name.find(".old-"), std::string::npos) << name;
  }
}

TEST(AtomicOutputKillTest, SynthAndTrackKilledAtRandomPointsNeverLookComplete) {
  const std::string binary = ARTEX_BINARY;
  ASSERT_TRUE(fs::exists(binary)) << binary;
  const fs::path root = FreshDir("kill");
  const fs::path sequence = root / "sequence";
  const std::vector<std::string> synth = {binary,
                                          "synth",
                                          "-o",
                                          sequence.string(),
                                          "--frames",
                                          "3",
                                          "--background-frames",
                                          "5",
                                          "--color-width",
                                          "160",
                                          "--color-height",
                                          "120",
                                          "--texture-size",
                                          "128",
                                          "--subject-resolution",
                                          "0",
                                          "--seed",
                                          "5"};
  KillAtRandomPoints(synth, sequence, 5, 20, {});
  const fs::path run = root / "run";
  const std::vector<std::string> track = {
      binary,       "track", sequence.string(), "-o",
      run.string(), "-q",    "--set",           "texture.atlas_size=128"};
  // summary.json and metrics.json hold timings.
  KillAtRandomPoints(track, run, 4, 21, {"summary.json", "metrics.json", "frames.csv"});
}

}  // namespace
}  // namespace artex
