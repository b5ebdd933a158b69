// Plumbing of the Slurm backend (experiments/slurm_backend.h): running Slurm's client commands,
// the submission records kept in OUT/slurm/, and the state of every array task from squeue,
// sacct and the tasks' own markers. Internal to the experiments library.
#pragma once

#include <map>
#include <string>
#include <vector>

#include "experiments/file_util.h"
#include "experiments/runner.h"

namespace artex {
namespace slurm {

// Result of one command: exit status (127: not found / not executable) and its outputs.
struct CommandResult {
  int status = -1;
  std::string out;
  std::string err;
  bool Ok() const { return status == 0; }
  std::string Quoted() const;  // "exit N: <stderr or stdout, trimmed>"
};

// Runs `args` (argv[0] looked up in bin_dir, else on PATH) without a shell.
CommandResult RunCommand(const std::vector<std::string>& args, const std::string& bin_dir);
std::string Program(const std::string& name, const std::string& bin_dir);

// One array task of a submission: the run it executes (PendingRun fields, absolute paths).
using TaskEntry = PendingRun;

// One `sbatch` of a job array: OUT/slurm/<name>/ holds job.sh, tasks.json, job_id, the Slurm
// logs slurm-<job>_<task>.log and state/<task>.{started,exit,progress} written by the tasks.
struct Submission {
  std::string name;    // "submit-001"
  std::string dir;     // OUT/slurm/submit-001
  std::string job_id;  // "" while not submitted (or when sbatch failed)
  std::vector<TaskEntry> tasks;
};

std::string SlurmDir(const std::string& out_dir);  // OUT/slurm
// Every submission of OUT in order (the ones without a job id are skipped).
std::vector<Submission> LoadSubmissions(const std::string& out_dir);
void WriteTasks(const Submission& submission);
Submission LoadSubmission(const std::string& dir);
std::string NextSubmissionName(const std::string& out_dir);

// Where task `index` of a submission with job id `job` writes its stdout/stderr:
// OUT/runs/<sequence>/slurm-logs/<combination>/slurm-<job>_<index>.log.
std::string TaskLogPath(const TaskEntry& task, const std::string& job, int index);
// The temporary folder a task computes its run in (beside the run folder, hidden).
std::string TaskTmpDir(const TaskEntry& task, const std::string& job, int index);
std::string MarkerPath(const Submission& s, int index, const std::string& kind);

// State of one array task ("<job>_<index>").
struct TaskState {
  std::string state;    // Slurm's (PENDING, RUNNING, COMPLETED, CANCELLED, TIMEOUT, ...), or
                        // KILLED (started, no exit marker, unknown to Slurm), LOST (never seen)
  std::string source;   // squeue | sacct | markers
  std::string exit;     // exit marker text ("" = none)
  bool active = false;  // queued or running
};

// Queries squeue (all states, array tasks expanded) and sacct for these job ids; a task
// neither knows is judged from its markers. sacct_available is set false when sacct answers
// with an error (e.g. "Slurm accounting storage is disabled").
class TaskStates {
 public:
  TaskStates(const std::vector<Submission>& submissions, const std::string& bin_dir);
  TaskState Of(const Submission& submission, int index) const;
  bool sacct_available() const { return sacct_available_; }
  const std::string& sacct_error() const { return sacct_error_; }

 private:
  std::map<std::string, std::string> squeue_, sacct_;
  bool sacct_available_ = true;
  std::string sacct_error_;
};

bool IsActiveState(const std::string& state);
std::string LastLines(const std::string& path, int lines);  // " | "-joined, "" if none
std::string Trim(const std::string& s);

}  // namespace slurm
}  // namespace artex
