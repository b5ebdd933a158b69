// Fault tests of the writing commands (docs/reliability.md "Fault tests", issue 20):
// - kill -9 of `artex synth`, `artex track` and `artex experiment` at 20 seeded random instants
//   each: after every kill no folder looks complete unless it is (absent, or identical to the
//   uninterrupted result), and a rerun gives the uninterrupted result;
// - a full disk (a tmpfs smaller than the output; needs root, skipped otherwise) for `synth`,
//   `track`, `render`, `experiment` and `stream encode`: a non-zero exit, an error naming a file
//   on the full disk, and no output that looks complete.
// Small inputs keep the whole file to a few CPU-seconds per command.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/mount.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <random>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "experiments/atomic_output.h"
#include "experiments/pose_csv.h"
#include "experiments/runner.h"
#include "models/error.h"
#include "tests/testing_util.h"

namespace artex {
namespace {

namespace fs = std::filesystem;
using testing_util::ReadFileBytes;
using Files = std::map<std::string, std::string>;  // relative path -> bytes

fs::path FreshDir(const std::string& name) {
  return testing_util::FreshTempDir("fault_test_" + name);
}

std::string Quote(const std::vector<std::string>& argv) {
  std::string command;
  for (const auto& a : argv) command += "'" + a + "' ";
  return command;
}

// Runs `argv` to completion; returns its exit status, stderr into `err` when given.
int RunCommand(const std::vector<std::string>& argv, std::string* err = nullptr) {
  const std::string log = (fs::temp_directory_path() /
                           ("artex_fault_test_" + std::to_string(getpid()) + ".log")).string();
  const int status = std::system((Quote(argv) + " > /dev/null 2>'" + log + "'").c_str());
  if (err) *err = ReadFileBytes(log);
  fs::remove(log);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

// Starts `argv` in its own process group and kills the group with SIGKILL after `delay` (the
// experiment runner's children too); returns false when it ended first.
bool KillAfter(const std::vector<std::string>& argv, std::chrono::microseconds delay) {
  const pid_t pid = fork();
  if (pid == 0) {
    setpgid(0, 0);
    std::vector<char*> args;
    for (const auto& a : argv) args.push_back(const_cast<char*>(a.c_str()));
    args.push_back(nullptr);
    if (!freopen("/dev/null", "w", stdout) || !freopen("/dev/null", "w", stderr)) _exit(126);
    execv(args[0], args.data());
    _exit(127);
  }
  setpgid(pid, pid);
  std::this_thread::sleep_for(delay);
  int status = 0;
  const bool ended = waitpid(pid, &status, WNOHANG) == pid;
  kill(-pid, SIGKILL);  // children of an ended runner are gone already; harmless then
  if (!ended) waitpid(pid, &status, 0);
  return !ended;
}

// Every file below `dir`, timing-dependent ones (by file name) with empty contents.
Files Snapshot(const fs::path& dir, const std::vector<std::string>& volatile_names = {}) {
  Files files;
  for (const auto& e : fs::recursive_directory_iterator(dir)) {
    if (!e.is_regular_file()) continue;
    const std::string name = e.path().filename().string();
    bool is_volatile = false;
    for (const auto& v : volatile_names) is_volatile = is_volatile || name == v;
    files[fs::relative(e.path(), dir).string()] = is_volatile ? "" : ReadFileBytes(e.path());
  }
  return files;
}

// The files that differ between two snapshots ("" when equal): names only, since gtest's diff
// of whole binary files takes memory quadratic in their size.
std::string Differences(const Files& a, const Files& b) {
  std::string out;
  for (const auto& [name, text] : a) {
    auto it = b.find(name);
    if (it == b.end()) out += name + " (only in the first) ";
    else if (it->second != text) out += name + " (differs) ";
  }
  for (const auto& [name, text] : b) {
    if (a.find(name) == a.end()) out += name + " (only in the second) ";
  }
  return out;
}

const std::string kBinary = ARTEX_BINARY;

std::vector<std::string> SynthArgs(const fs::path& out) {
  return {kBinary, "synth", "-o", out.string(), "--frames", "2", "--background-frames", "5",
          "--color-width", "160", "--color-height", "120", "--texture-size", "128",
          "--subject-resolution", "0", "--seed", "5"};
}

// A cheap track: one first-frame hypothesis, a coarse fit subset, a small atlas.
std::vector<std::string> TrackArgs(const fs::path& sequence, const fs::path& out) {
  return {kBinary, "track", sequence.string(), "-o", out.string(), "-q",
          "--set", "texture.atlas_size=128", "--set", "fitting.max_fit_vertices=800",
          "--set", "fitting.init.yaws_deg=[0]", "--set", "fitting.init.arm_angles_deg=[80]",
          "--set", "fitting.init.refine_arms=false", "--set", "fitting.init.em_candidates=1"};
}

const char* kExperiment =
    "name: fault\n"
    "base:\n"
    "  texture: {atlas_size: 128}\n"
    "  fitting: {max_fit_vertices: 800, init: {yaws_deg: [0], arm_angles_deg: [80],"
    " refine_arms: false, em_candidates: 1}}\n"
    "template: {resolution: 0, atlas_size: 256}\n"
    "sequences:\n"
    "  - {name: walk, synth: {motion: walk, frames: 2, seed: 1, subject_resolution: 0,"
    " texture_size: 128, color_width: 160, color_height: 120, depth_width: 160,"
    " depth_height: 120, background_frames: 5}}\n"
    "grid:\n"
    "  texture.lambda: [0, 1]\n";

std::vector<std::string> ExperimentArgs(const fs::path& file, const fs::path& out) {
  return {kBinary, "experiment", file.string(), "-o", out.string(), "--jobs", "1",
          "--threads-per-run", "1", "--no-plots"};
}

// Files of a track run that hold timings (compared by name only).
const std::vector<std::string> kTrackVolatile = {"summary.json", "metrics.json", "frames.csv",
                                                  "realtime.json"};
// ... and of an experiment's run folder.
const std::vector<std::string> kRunVolatile = {"summary.json", "metrics.json", "frames.csv", "realtime.json",
                                               "results.json", "run.json",     "trace.csv",
                                               "log.txt",      "DONE"};

// (sequence, combination, metric) -> value of the non-timing metrics of results.csv.
std::map<std::string, std::string> Results(const fs::path& csv) {
  std::map<std::string, std::string> rows;
  std::ifstream in(csv);
  std::string line;
  std::getline(in, line);
  while (std::getline(in, line)) {
    std::vector<std::string> f;
    std::stringstream ss(line);
    std::string cell;
    while (std::getline(ss, cell, ',')) f.push_back(cell);
    if (f.size() != 5) continue;
    const MetricInfo* info = FindMetric(f[3]);
    if (info == nullptr || info->timing) continue;
    rows[f[1] + "|" + f[2] + "|" + f[3]] = f[4];
  }
  return rows;
}

// ---------------------------------------------------------------------------------------------
// kill -9 at seeded random points.

constexpr int kKillPoints = 20;

// Runs `argv` once to completion, then kills reruns at kKillPoints seeded instants within the
// measured duration (half over an earlier result, half into an absent folder): `out` is absent
// or identical to the complete result after each kill; a final rerun gives that result.
void KillFolderWriter(const std::vector<std::string>& argv, const fs::path& out, uint32_t seed,
                      const std::vector<std::string>& volatile_names) {
  const auto t0 = std::chrono::steady_clock::now();
  ASSERT_EQ(RunCommand(argv), 0) << Quote(argv);
  const auto max_us = std::chrono::duration_cast<std::chrono::microseconds>(
                          std::chrono::steady_clock::now() - t0)
                          .count();
  ASSERT_TRUE(IsCompleteOutputFolder(out.string()));
  const Files complete = Snapshot(out, volatile_names);
  std::mt19937 rng(seed);
  std::uniform_int_distribution<long long> at(0, max_us);
  int killed = 0, absent = 0;
  for (int k = 0; k < kKillPoints; ++k) {
    if (k % 2 == 1) fs::remove_all(out);
    killed += KillAfter(argv, std::chrono::microseconds(at(rng)));
    if (fs::exists(out)) {
      EXPECT_TRUE(IsCompleteOutputFolder(out.string())) << "kill " << k;
      EXPECT_EQ(Differences(Snapshot(out, volatile_names), complete), "")
          << "kill " << k << ": a mixed folder";
    } else {
      ++absent;
    }
  }
  std::cout << argv[1] << ": " << killed << " of " << kKillPoints << " reruns killed, output "
            << "absent after " << absent << "\n";
  EXPECT_GT(killed, 0);
  ASSERT_EQ(RunCommand(argv), 0) << Quote(argv);
  EXPECT_EQ(Differences(Snapshot(out, volatile_names), complete), "");
  for (const auto& e : fs::directory_iterator(out.parent_path())) {
    const std::string name = e.path().filename().string();
    EXPECT_EQ(name.find(".partial-"), std::string::npos) << name;
    EXPECT_EQ(name.find(".old-"), std::string::npos) << name;
  }
}

TEST(FaultKillTest, SynthKilledAtRandomPointsNeverLooksComplete) {
  const fs::path root = FreshDir("kill_synth");
  KillFolderWriter(SynthArgs(root / "sequence"), root / "sequence", 101, {});
  fs::remove_all(root);
}

TEST(FaultKillTest, TrackKilledAtRandomPointsNeverLooksComplete) {
  const fs::path root = FreshDir("kill_track");
  ASSERT_EQ(RunCommand(SynthArgs(root / "sequence")), 0);
  KillFolderWriter(TrackArgs(root / "sequence", root / "run"), root / "run", 102, kTrackVolatile);
  fs::remove_all(root);
}

// What a killed experiment may leave: run folders named like a result (no leading '.') only
// with DONE and identical to the uninterrupted run's; generated sequences and templates only
// complete; results.csv only with the uninterrupted values.
void ExpectNothingLooksComplete(const fs::path& out, const fs::path& reference, int k) {
  if (!fs::exists(out)) return;
  for (const char* sub : {"runs/walk", "sequences", "templates"}) {
    if (!fs::is_directory(out / sub)) continue;
    for (const auto& e : fs::directory_iterator(out / sub)) {
      const std::string name = e.path().filename().string();
      if (!e.is_directory() || name[0] == '.') continue;
      const fs::path rel = fs::path(sub) / name;
      if (std::string(sub) == "runs/walk") {
        EXPECT_TRUE(fs::exists(e.path() / "DONE")) << "kill " << k << ": " << rel;
      }
      EXPECT_EQ(Differences(Snapshot(e.path(), kRunVolatile), Snapshot(reference / rel, kRunVolatile)), "")
          << "kill " << k << ": " << rel << " looks complete but differs";
    }
  }
  if (fs::exists(out / "results.csv")) {
    const auto rows = Results(out / "results.csv");
    const auto ref = Results(reference / "results.csv");
    for (const auto& [key, value] : rows) {
      EXPECT_EQ(ref.count(key) ? ref.at(key) : "(absent)", value) << "kill " << k << ": " << key;
    }
  }
}

TEST(FaultKillTest, ExperimentKilledAtRandomPointsResumesToTheSameResults) {
  const fs::path root = FreshDir("kill_experiment");
  const fs::path file = root / "fault.yaml";
  std::ofstream(file) << kExperiment;
  const fs::path reference = root / "reference";
  const auto t0 = std::chrono::steady_clock::now();
  ASSERT_EQ(RunCommand(ExperimentArgs(file, reference)), 0);
  const auto max_us = std::chrono::duration_cast<std::chrono::microseconds>(
                          std::chrono::steady_clock::now() - t0)
                          .count();
  const auto expected = Results(reference / "results.csv");
  ASSERT_FALSE(expected.empty());

  // Kills accumulate (each rerun resumes the previous one's progress); every 5th starts afresh.
  const fs::path out = root / "killed";
  std::mt19937 rng(103);
  std::uniform_int_distribution<long long> at(0, max_us);
  int killed = 0;
  for (int k = 0; k < kKillPoints; ++k) {
    if (k % 5 == 0) fs::remove_all(out);
    killed += KillAfter(ExperimentArgs(file, out), std::chrono::microseconds(at(rng)));
    ExpectNothingLooksComplete(out, reference, k);
  }
  std::cout << "experiment: " << killed << " of " << kKillPoints << " runs killed\n";
  EXPECT_GT(killed, 0);
  std::string err;
  ASSERT_EQ(RunCommand(ExperimentArgs(file, out), &err), 0) << err;
  EXPECT_EQ(Results(out / "results.csv"), expected);
  ExpectNothingLooksComplete(out, reference, kKillPoints);
  for (const char* combination : {"texture.lambda=0", "texture.lambda=1"}) {
    EXPECT_TRUE(fs::exists(out / "runs" / "walk" / combination / "DONE")) << combination;
  }
  fs::remove_all(root);
}

// ---------------------------------------------------------------------------------------------
// A full disk: each writer's output on a tmpfs half the size of its complete output.

std::uintmax_t TreeBytes(const fs::path& path) {
  if (fs::is_regular_file(path)) return fs::file_size(path);
  std::uintmax_t bytes = 0;
  for (const auto& e : fs::recursive_directory_iterator(path)) {
    if (e.is_regular_file()) bytes += e.file_size();
  }
  return bytes;
}

// A tmpfs of `bytes` (rounded up to pages) at `dir`, unmounted on destruction.
class SmallDisk {
 public:
  SmallDisk(const fs::path& dir, std::uintmax_t bytes) : dir_(dir) {
    fs::create_directories(dir_);
    const std::uintmax_t size = std::max<std::uintmax_t>(4096, (bytes + 4095) / 4096 * 4096);
    const std::string options = "size=" + std::to_string(size);
    mounted_ = mount("tmpfs", dir_.c_str(), "tmpfs", 0, options.c_str()) == 0;
  }
  ~SmallDisk() {
    if (mounted_) umount(dir_.c_str());
  }
  bool mounted() const { return mounted_; }

 private:
  fs::path dir_;
  bool mounted_ = false;
};

// Runs `argv` (whose output is `out`, on a tmpfs of half `complete_bytes`): non-zero exit, the
// error names a file on the small disk, no complete-looking output.
void ExpectFullDiskError(const std::string& what, const std::vector<std::string>& argv,
                         const fs::path& disk, const fs::path& out,
                         std::uintmax_t complete_bytes) {
  SCOPED_TRACE(what);
  SmallDisk small(disk, complete_bytes / 2);
  if (!small.mounted()) GTEST_SKIP() << "cannot mount a tmpfs at " << disk;
  std::string err;
  EXPECT_NE(RunCommand(argv, &err), 0) << err;
  const std::size_t e = err.find("error:");
  const std::string line = err.substr(e == std::string::npos ? 0 : e);
  std::cout << what << " on a full disk: " << line.substr(0, line.find('\n')) << "\n";
  EXPECT_NE(err.find(disk.string() + "/"), std::string::npos)
      << "the error names no file on the full disk: " << err;
  EXPECT_EQ(err.find("basic_"), std::string::npos) << err;  // no unnamed stream error
  if (fs::is_directory(out)) {
    EXPECT_FALSE(IsCompleteOutputFolder(out.string())) << out;
    if (fs::is_directory(out / "runs" / "walk")) {
      for (const auto& e : fs::directory_iterator(out / "runs" / "walk")) {
        EXPECT_FALSE(fs::exists(e.path() / "DONE")) << e.path();
      }
    }
  } else {
    EXPECT_FALSE(fs::exists(out)) << out << " exists after a failed write";
  }
}

TEST(FaultFullDiskTest, EveryWriterFailsNamingTheFileAndLeavesNoCompleteOutput) {
  if (geteuid() != 0) GTEST_SKIP() << "mounting a tmpfs needs root";
  const fs::path root = FreshDir("full_disk");
  const fs::path disk = root / "disk";
  {
    SmallDisk probe(disk, 1 << 20);
    if (!probe.mounted()) GTEST_SKIP() << "cannot mount a tmpfs here (no CAP_SYS_ADMIN?)";
  }
  // Complete outputs on the ordinary disk first: their sizes size the small disk.
  const fs::path sequence = root / "sequence", run = root / "run";
  ASSERT_EQ(RunCommand(SynthArgs(sequence)), 0);
  std::vector<std::string> track = TrackArgs(sequence, run);
  track.insert(track.end(), {"--set", "pipeline.export_atlases=true"});
  ASSERT_EQ(RunCommand(track), 0);
  const std::vector<std::string> render_tail = {"--frames", "2", "--width", "160", "--height",
                                                "120"};
  std::vector<std::string> render = {kBinary, "render", run.string(), "-o",
                                     (root / "render").string()};
  render.insert(render.end(), render_tail.begin(), render_tail.end());
  ASSERT_EQ(RunCommand(render), 0);
  ASSERT_EQ(RunCommand({kBinary, "stream", "encode", run.string(), "-o", (root / "s.artx").string()}),
            0);
  const fs::path file = root / "fault.yaml";
  std::ofstream(file) << kExperiment;
  ASSERT_EQ(RunCommand(ExperimentArgs(file, root / "exp")), 0);

  ExpectFullDiskError("synth", SynthArgs(disk / "sequence"), disk, disk / "sequence",
                      TreeBytes(sequence));
  std::vector<std::string> track_full = TrackArgs(sequence, disk / "run");
  track_full.insert(track_full.end(), {"--set", "pipeline.export_atlases=true"});
  ExpectFullDiskError("track", track_full, disk, disk / "run", TreeBytes(run));
  std::vector<std::string> render_full = {kBinary, "render", run.string(), "-o",
                                          (disk / "render").string()};
  render_full.insert(render_full.end(), render_tail.begin(), render_tail.end());
  ExpectFullDiskError("render", render_full, disk, disk / "render", TreeBytes(root / "render"));
  ExpectFullDiskError("stream encode",
                      {kBinary, "stream", "encode", run.string(), "-o",
                       (disk / "s.artx").string()},
                      disk, disk / "s.artx", TreeBytes(root / "s.artx"));
  ExpectFullDiskError("experiment", ExperimentArgs(file, disk / "exp"), disk, disk / "exp",
                      TreeBytes(root / "exp"));
  fs::remove_all(root);
}


// ---------------------------------------------------------------------------------------------
// Findings of the long fuzz run (docs/reliability.md "Fuzzing"), each as it was found.

TEST(FuzzFindingTest, PosesCsvFrameBeyondIntIsAnError) {
  // poses_csv_fuzzer: a frame column value of 5.6e13 was converted to int (undefined behaviour).
  const fs::path dir = FreshDir("fuzz_poses");
  const fs::path path = dir / "poses.csv";
  std::string row = "55555555555555";
  for (int i = 0; i < 17 * 3 + 3; ++i) row += ",0";
  std::ofstream(path) << "frame,x\n" << row << "\n";
  try {
    ReadPoseCsv(path.string(), 17);
    ADD_FAILURE() << "accepted a frame beyond int";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find(path.string() + ":2: frame: expected an integer"),
              std::string::npos)
        << e.what();
  }
  std::ofstream(path) << "frame,x\n" << "-1" << row.substr(row.find(',')) << "\n";
  EXPECT_THROW(ReadPoseCsv(path.string(), 17), Error);
  fs::remove_all(dir);
}

TEST(FuzzFindingTest, ExperimentSequencePathTooLongIsAnError) {
  // experiment_fuzzer: a sequence path longer than NAME_MAX made std::filesystem::exists throw
  // filesystem_error ("File name too long"), which escaped ParseExperiment.
  const std::string yaml = "name: x\nsequences:\n  - '" + std::string(300, 'a') + "'\n";
  try {
    ParseExperiment(yaml, "long.yaml", fs::temp_directory_path().string());
    ADD_FAILURE() << "accepted a sequence that cannot exist";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("sequence folder not found"), std::string::npos)
        << e.what();
  }
}

}  // namespace
}  // namespace artex
