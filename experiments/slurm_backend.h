// The Slurm backend of `artex experiment --backend slurm` (docs/experiments.md "On a Slurm
// cluster"). RunExperiment generates the sequences and the template on the submitting machine
// (the login node), then hands the pending runs to this backend, which submits them as one job
// array per invocation (one array task per run, `%K` throttle) with `sbatch --parsable` and
// polls squeue/sacct until every task ended (or returns at once). Each task runs
// `artex experiment-task`, which computes its run in a hidden folder beside the run folder and
// renames it into place when complete, exactly like the local backend, so tables are the same.
// Runs already complete are never submitted; runs whose task is still queued or running (an
// earlier --no-wait) are waited on, not submitted again; runs whose task was killed (timeout,
// preemption, node failure, scancel) or failed are submitted again. State lives in OUT/slurm/.
#pragma once

#include <string>
#include <vector>

#include "experiments/runner.h"

namespace artex {

struct SlurmOptions {
  std::string partition;  // --partition ("" = the cluster's default)
  std::string time;       // --time per task ("" = the partition's default)
  std::string mem;        // --mem per task ("" = the partition's default)
  int cpus_per_task = 1;  // --cpus-per-task; also each run's worker threads
  int max_parallel = 0;   // array throttle %K; 0 = no throttle
  // Runs per job array: more pending runs are split into several arrays (submissions). Slurm
  // refuses arrays whose largest index reaches its MaxArraySize (default 1001).
  int max_array_size = 1000;
  std::vector<std::string> sbatch_args;  // further sbatch arguments, passed verbatim
  bool wait = true;                      // poll until every task ended; false: return at once
  double poll_seconds = 10;              // interval of the squeue/sacct polls while waiting
  // Before the first array of an output folder, a one-task probe job checks that the nodes
  // can run this artex and write to OUT (shared filesystem); false skips it.
  bool probe = true;
  double probe_timeout_seconds = 900;  // the probe must have ended within this time
  std::string job_name;                // "" = artex-<experiment name>
  std::string executable;              // artex binary the tasks run; "" = this one
  std::string bin_dir;                 // folder of sbatch/squeue/sacct; "" = PATH
  bool IsValid(std::string* error) const;
};

// The backend for RunnerOptions::backend. Throws artex::Error quoting Slurm's answer when
// sbatch is missing or refuses a job, or when the probe job cannot write to OUT.
RunBackend MakeSlurmBackend(const Experiment& experiment, const std::string& out_dir,
                            const SlurmOptions& options);

// The job-array script of one submission (what `sbatch` gets; shown in docs/experiments.md).
std::string SlurmArrayScript(const std::string& experiment_name, const std::string& out_dir,
                             const std::string& submission, int tasks, const SlurmOptions& options,
                             const std::string& executable);

// State of every run of an output folder written by the Slurm backend.
struct SlurmRunStatus {
  std::string label;   // sequence/combination
  std::string state;   // DONE, NOT_SUBMITTED, or the state of its last task (PENDING,
                       // RUNNING, CANCELLED, TIMEOUT, FAILED, KILLED, ...)
  std::string task;    // "<job>_<index>" of its last task ("" = never submitted)
  std::string source;  // where the state came from: squeue, sacct, markers, run folder
  std::string log;     // the last task's log (OUT/runs/<seq>/slurm-logs/<comb>/slurm-*.log)
  std::string detail;  // failed: the log's last lines (or the task's exit marker)
  int attempts = 0;    // tasks submitted for this run so far
};
struct SlurmStatus {
  std::string experiment_file;
  std::vector<SlurmRunStatus> runs;
  int done = 0, running = 0, pending = 0, failed = 0, not_submitted = 0;
  std::string sacct_note;  // why sacct gave nothing ("" = it answered)
};

// The experiment file recorded in OUT by the Slurm backend ("" when none).
std::string RecordedExperimentFile(const std::string& out_dir);
// Per-run state (experiment_file "" = the recorded one). Throws when there is none.
SlurmStatus ReadSlurmStatus(const std::string& out_dir, const std::string& experiment_file,
                            const std::string& bin_dir = "");
std::string FormatSlurmStatus(const SlurmStatus& status);

// ---- Entry points of the array tasks (hidden subcommands of the artex binary) ----------------

// Runs task `index` of OUT/slurm/<submission>: its stdout/stderr go to the task's log, the run
// is computed in a hidden folder and renamed into place; markers record start and exit.
// Returns the process exit status.
int RunSlurmTask(const std::string& out_dir, const std::string& submission, int index, int threads);
// The probe job: checks that `paths` are readable and writes OUT/slurm/probe-<token>.ok.
void RunSlurmProbe(const std::string& out_dir, const std::string& token,
                   const std::vector<std::string>& paths);

}  // namespace artex
