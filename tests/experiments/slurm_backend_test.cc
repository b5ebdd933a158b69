// The Slurm backend against fake sbatch/squeue/sacct commands (a folder of shell scripts given
// as SlurmOptions::bin_dir): the array script, submission records, errors quoting Slurm's
// answer, and which runs a rerun submits again. The real-Slurm run is tests/slurm/.
#include "experiments/slurm_backend.h"

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "experiments/slurm_queue.h"
#include "models/error.h"
#include "tests/error_of.h"
#include "tests/testing_util.h"

namespace artex {
namespace {
namespace fs = std::filesystem;
using testing_util::ReadFileBytes;

fs::path FreshDir(const std::string& name) {
  return testing_util::FreshTempDir("slurm_test_" + name);
}

void WriteText(const fs::path& path, const std::string& text) {
  std::ofstream out(path);
  out << text;
}

// A fake Slurm command: a shell script in bin/ (its arguments are appended to bin/<name>.args).
void FakeCommand(const fs::path& bin, const std::string& name, const std::string& body) {
  const fs::path path = bin / name;
  WriteText(path, "#!/bin/sh\necho \"$@\" >> '" + (bin / (name + ".args")).string() + "'\n" + body +
                      "\n");
  chmod(path.c_str(), 0755);
}

std::vector<PendingRun> Pending(const fs::path& out, int n) {
  std::vector<PendingRun> runs;
  for (int i = 0; i < n; ++i) {
    PendingRun p;
    p.sequence = "seq";
    p.combination = "texture.lambda=" + std::to_string(i);
    p.label = p.sequence + "/" + p.combination;
    p.sequence_folder = (out / "sequences" / "seq").string();
    p.template_path = (out / "templates" / "t.glb").string();
    p.run_folder = (out / "runs" / p.sequence / p.combination).string();
    p.config_text = "texture: {lambda: " + std::to_string(i) + "}\n";
    p.key = "key " + std::to_string(i);
    p.info_json = "{\"combination\": \"" + p.combination + "\"}";
    runs.push_back(p);
  }
  return runs;
}

Experiment NamedExperiment(const fs::path& dir) {
  Experiment ex;
  ex.name = "fake";
  ex.file = (dir / "fake.yaml").string();
  return ex;
}

SlurmOptions FakeOptions(const fs::path& bin) {
  SlurmOptions o;
  o.bin_dir = bin.string();
  o.probe = false;
  o.wait = false;
  o.executable = "/opt/artex/bin/artex";
  return o;
}

TEST(SlurmBackendTest, ArrayScriptHasOneTaskPerRunThrottleAndResources) {
  SlurmOptions o;
  o.partition = "short";
  o.time = "00:20:00";
  o.mem = "4G";
  o.cpus_per_task = 3;
  o.max_parallel = 5;
  const std::string script =
      SlurmArrayScript("abl", "/shared/out", "submit-002", 8, o, "/sw/artex");
  EXPECT_NE(script.find("#SBATCH --array=0-7%5\n"), std::string::npos) << script;
  EXPECT_NE(script.find("#SBATCH --partition=short\n"), std::string::npos);
  EXPECT_NE(script.find("#SBATCH --time=00:20:00\n"), std::string::npos);
  EXPECT_NE(script.find("#SBATCH --mem=4G\n"), std::string::npos);
  EXPECT_NE(script.find("#SBATCH --cpus-per-task=3\n"), std::string::npos);
  EXPECT_NE(script.find("#SBATCH --job-name=artex-abl\n"), std::string::npos);
  EXPECT_NE(script.find("#SBATCH --output=/shared/out/slurm/submit-002/slurm-%A_%a.log\n"),
            std::string::npos);
  EXPECT_NE(
      script.find("exec '/sw/artex' experiment-task --out '/shared/out' --submission submit-002 "
                  "--index \"$SLURM_ARRAY_TASK_ID\" --threads 3\n"),
      std::string::npos)
      << script;
  o.max_parallel = 0;
  EXPECT_NE(SlurmArrayScript("abl", "/o", "s", 1, o, "a").find("#SBATCH --array=0-0\n"),
            std::string::npos);
}

TEST(SlurmBackendTest, OptionsRejectArraySetByHandAndBadCounts) {
  SlurmOptions o;
  std::string why;
  EXPECT_TRUE(o.IsValid(&why));
  o.sbatch_args = {"--array=0-3"};
  EXPECT_FALSE(o.IsValid(&why));
  EXPECT_NE(why.find("--array"), std::string::npos);
  o.sbatch_args = {"--qos=high"};
  o.cpus_per_task = 0;
  EXPECT_FALSE(o.IsValid(&why));
  EXPECT_NE(why.find("cpus_per_task"), std::string::npos);
}

TEST(SlurmBackendTest, MissingSbatchIsAClearError) {
  const fs::path dir = FreshDir("missing");
  fs::create_directories(dir / "bin");  // empty: no sbatch
  const RunBackend backend =
      MakeSlurmBackend(NamedExperiment(dir), (dir / "out").string(), FakeOptions(dir / "bin"));
  ExperimentSummary summary;
  const std::string msg = ErrorOf([&] { backend(Pending(dir / "out", 2), &summary, {}); });
  EXPECT_NE(msg.find("cannot run " + (dir / "bin" / "sbatch").string()), std::string::npos) << msg;
  EXPECT_NE(msg.find("exit 127"), std::string::npos) << msg;
  fs::remove_all(dir);
}

TEST(SlurmBackendTest, RefusedSubmissionQuotesSlurm) {
  const fs::path dir = FreshDir("refused");
  fs::create_directories(dir / "bin");
  FakeCommand(
      dir / "bin", "sbatch",
      "echo 'sbatch: error: invalid partition specified: nope' >&2\n"
      "echo 'sbatch: error: Batch job submission failed: Invalid partition name specified' >&2\n"
      "exit 1");
  SlurmOptions o = FakeOptions(dir / "bin");
  o.partition = "nope";
  const RunBackend backend = MakeSlurmBackend(NamedExperiment(dir), (dir / "out").string(), o);
  ExperimentSummary summary;
  const std::string msg = ErrorOf([&] { backend(Pending(dir / "out", 3), &summary, {}); });
  EXPECT_NE(msg.find("sbatch refused the job array"), std::string::npos) << msg;
  EXPECT_NE(msg.find("exit 1: sbatch: error: invalid partition specified: nope"), std::string::npos)
      << msg;
  EXPECT_NE(ReadFileBytes(dir / "bin" / "sbatch.args").find("--parsable"), std::string::npos);
  fs::remove_all(dir);
}

TEST(SlurmBackendTest, ProbeFailureSaysTheFolderMustBeShared) {
  const fs::path dir = FreshDir("probe");
  fs::create_directories(dir / "bin");
  // The probe job "runs" and ends without writing its file (as on a node without OUT).
  FakeCommand(dir / "bin", "sbatch",
              "echo 'probe ran on node7: No such file or directory' > \"$(echo \"$@\" | sed -n "
              "'s/.*--output=\\([^ ]*\\).*/\\1/p')\"\necho 77");
  FakeCommand(dir / "bin", "squeue", "echo FAILED");
  SlurmOptions o = FakeOptions(dir / "bin");
  o.probe = true;
  o.poll_seconds = 0.05;
  const RunBackend backend = MakeSlurmBackend(NamedExperiment(dir), (dir / "out").string(), o);
  ExperimentSummary summary;
  const std::string msg = ErrorOf([&] { backend(Pending(dir / "out", 1), &summary, {}); });
  EXPECT_NE(msg.find("the probe job 77 could not run artex or write to"), std::string::npos) << msg;
  EXPECT_NE(msg.find("state FAILED"), std::string::npos) << msg;
  EXPECT_NE(msg.find("probe ran on node7"), std::string::npos) << msg;
  EXPECT_NE(msg.find("filesystem the nodes share"), std::string::npos) << msg;
  fs::remove_all(dir);
}

TEST(SlurmBackendTest, RerunSubmitsOnlyRunsWhoseTaskEndedWithoutCompleting) {
  const fs::path dir = FreshDir("rerun");
  const fs::path out = dir / "out";
  fs::create_directories(dir / "bin");
  FakeCommand(dir / "bin", "sbatch", "echo '42;cluster'");
  FakeCommand(dir / "bin", "squeue", "exit 0");
  FakeCommand(dir / "bin", "sacct",
              "echo 'sacct: error: Slurm accounting storage is disabled' >&2; exit 1");
  const SlurmOptions o = FakeOptions(dir / "bin");
  ExperimentSummary first;
  MakeSlurmBackend(NamedExperiment(dir), out.string(), o)(Pending(out, 4), &first, {});
  EXPECT_EQ(first.runs_submitted, 4);
  EXPECT_EQ(first.runs_unfinished, 4);
  EXPECT_EQ(first.runs_resubmitted, 0);
  const fs::path sub = out / "slurm" / "submit-001";
  EXPECT_EQ(ReadFileBytes(sub / "job_id"), "42\n");
  EXPECT_NE(ReadFileBytes(sub / "job.sh").find("--array=0-3\n"), std::string::npos);
  EXPECT_EQ(slurm::LoadSubmission(sub.string()).tasks.size(), 4u);
  EXPECT_NE(ReadFileBytes(out / "slurm" / "experiment.txt").find("fake.yaml"), std::string::npos);

  // Task 0 still running, task 1 cancelled (squeue), task 2 started and vanished (killed),
  // task 3 complete. Runs 1 and 2 are pending again; run 3 is no longer pending.
  FakeCommand(dir / "bin", "squeue", "echo '42_0|RUNNING'; echo '42_1|CANCELLED'");
  FakeCommand(dir / "bin", "sbatch", "echo 43");
  WriteText(sub / "state" / "2.started", "node 2026\n");
  const std::vector<PendingRun> all = Pending(out, 4);
  const std::vector<PendingRun> pending(all.begin(), all.begin() + 3);
  ExperimentSummary second;
  MakeSlurmBackend(NamedExperiment(dir), out.string(), o)(pending, &second, {});
  EXPECT_EQ(second.runs_submitted, 2);
  EXPECT_EQ(second.runs_resubmitted, 2);
  EXPECT_EQ(second.runs_unfinished, 3);  // 2 new + the running one
  EXPECT_NE(second.note.find("seq/texture.lambda=1 (CANCELLED)"), std::string::npos) << second.note;
  EXPECT_NE(second.note.find("seq/texture.lambda=2 (KILLED)"), std::string::npos) << second.note;
  EXPECT_NE(second.note.find("1 run(s) still queued or running"), std::string::npos) << second.note;
  const slurm::Submission next = slurm::LoadSubmission((out / "slurm" / "submit-002").string());
  ASSERT_EQ(next.tasks.size(), 2u);
  EXPECT_EQ(next.tasks[0].label, "seq/texture.lambda=1");
  EXPECT_EQ(next.tasks[1].label, "seq/texture.lambda=2");
  EXPECT_EQ(next.job_id, "43");
  fs::remove_all(dir);
}

TEST(SlurmBackendTest, RunsBeyondMaxArraySizeAreSplitIntoSeveralArrays) {
  const fs::path dir = FreshDir("split");
  const fs::path out = dir / "out";
  fs::create_directories(dir / "bin");
  // Job ids 100, 101, ... from a counter file.
  FakeCommand(dir / "bin", "sbatch",
              "n=$(cat '" + (dir / "n").string() +
                  "' 2>/dev/null || echo 100); echo $((n + 1)) > '" + (dir / "n").string() +
                  "'; echo $n");
  SlurmOptions o = FakeOptions(dir / "bin");
  o.max_array_size = 2;
  ExperimentSummary summary;
  MakeSlurmBackend(NamedExperiment(dir), out.string(), o)(Pending(out, 5), &summary, {});
  EXPECT_EQ(summary.runs_submitted, 5);
  const auto subs = slurm::LoadSubmissions(out.string());
  ASSERT_EQ(subs.size(), 3u);
  EXPECT_EQ(subs[0].job_id, "100");
  EXPECT_EQ(subs[2].job_id, "102");
  EXPECT_EQ(subs[0].tasks.size(), 2u);
  EXPECT_EQ(subs[2].tasks.size(), 1u);
  EXPECT_EQ(subs[2].tasks[0].label, "seq/texture.lambda=4");
  EXPECT_NE(ReadFileBytes(fs::path(subs[1].dir) / "job.sh").find("--array=0-1\n"),
            std::string::npos);
  EXPECT_NE(summary.note.find("as job arrays 100 ("), std::string::npos) << summary.note;
  fs::remove_all(dir);
}

// The task entry point as a Slurm node runs it, on a run whose sequence does not exist: it fails
// with exit status 1, logs why in its log, writes its exit marker and leaves no run folder.
TEST(SlurmBackendTest, FailingTaskLogsAndMarksItsExit) {
  const fs::path dir = FreshDir("task");
  const fs::path out = dir / "out";
  fs::create_directories(dir / "bin");
  FakeCommand(dir / "bin", "sbatch", "echo 5");
  ExperimentSummary summary;
  MakeSlurmBackend(NamedExperiment(dir), out.string(), FakeOptions(dir / "bin"))(Pending(out, 1),
                                                                                 &summary, {});
  const std::string cmd = "SLURM_ARRAY_JOB_ID=5 '" + std::string(ARTEX_BINARY) +
                          "' experiment-task --out '" + out.string() +
                          "' --submission submit-001 --index 0 --threads 1";
  const int status = std::system(cmd.c_str());
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 1);
  const fs::path sub = out / "slurm" / "submit-001";
  EXPECT_EQ(ReadFileBytes(sub / "state" / "0.exit").rfind("1 ", 0), 0u)
      << ReadFileBytes(sub / "state" / "0.exit");
  EXPECT_TRUE(fs::exists(sub / "state" / "0.started"));
  const std::string log =
      ReadFileBytes(out / "runs" / "seq" / "slurm-logs" / "texture.lambda=0" / "slurm-5_0.log");
  EXPECT_NE(log.find("artex experiment-task 5_0: seq/texture.lambda=0 on "), std::string::npos)
      << log;
  EXPECT_NE(log.find("FAILED"), std::string::npos) << log;
  EXPECT_FALSE(RunIsComplete((out / "runs" / "seq" / "texture.lambda=0").string()));
  EXPECT_TRUE(fs::exists(out / "runs" / "seq" / ".failed-texture.lambda=0"));
  const slurm::TaskStates states(slurm::LoadSubmissions(out.string()), (dir / "bin").string());
  EXPECT_EQ(states.Of(slurm::LoadSubmission(sub.string()), 0).state, "FAILED");  // from markers
  fs::remove_all(dir);
}

TEST(SlurmBackendTest, TaskStateFallsBackToMarkersWithoutAccounting) {
  const fs::path dir = FreshDir("states");
  fs::create_directories(dir / "bin");
  FakeCommand(dir / "bin", "squeue", "echo '9_0|PENDING'");
  FakeCommand(dir / "bin", "sacct", "echo 'Slurm accounting storage is disabled' >&2; exit 1");
  slurm::Submission s;
  s.dir = (dir / "submit-001").string();
  s.job_id = "9";
  fs::create_directories(fs::path(s.dir) / "state");
  WriteText(slurm::MarkerPath(s, 1, "started"), "x\n");
  WriteText(slurm::MarkerPath(s, 1, "exit"), "1 boom\n");
  WriteText(slurm::MarkerPath(s, 2, "started"), "x\n");
  WriteText(slurm::MarkerPath(s, 3, "started"), "x\n");
  WriteText(slurm::MarkerPath(s, 3, "exit"), "0\n");
  const slurm::TaskStates states({s}, (dir / "bin").string());
  EXPECT_FALSE(states.sacct_available());
  EXPECT_NE(states.sacct_error().find("accounting storage is disabled"), std::string::npos);
  EXPECT_EQ(states.Of(s, 0).state, "PENDING");
  EXPECT_TRUE(states.Of(s, 0).active);
  EXPECT_EQ(states.Of(s, 1).state, "FAILED");
  EXPECT_EQ(states.Of(s, 2).state, "KILLED");
  EXPECT_FALSE(states.Of(s, 2).active);
  EXPECT_EQ(states.Of(s, 3).state, "COMPLETED");
  EXPECT_EQ(states.Of(s, 4).state, "LOST");
  fs::remove_all(dir);
}

}  // namespace
}  // namespace artex
