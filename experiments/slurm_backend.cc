#include "experiments/slurm_backend.h"

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <thread>

#include "experiments/slurm_queue.h"
#include "models/error.h"
#include "sensors/sequence.h"

namespace artex {
namespace fs = std::filesystem;
using namespace slurm;  // NOLINT(build/namespaces): the backend's own plumbing

namespace {

constexpr const char* kExperimentRecord = "experiment.txt";
constexpr const char* kProbeRecord = "probe.ok";
constexpr int kFailureLines = 3;     // log lines quoted for a failed task
constexpr double kProbePollMax = 2;  // seconds between polls of the probe job

std::string Quote(const std::string& s) {
  std::string out = "'";
  for (char c : s) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return out + "'";
}

std::string SelfExecutable() {
  std::error_code ec;
  const fs::path p = fs::read_symlink("/proc/self/exe", ec);
  return ec ? std::string("/proc/self/exe") : p.string();
}

std::string JobName(const std::string& experiment_name, const SlurmOptions& options) {
  std::string name = options.job_name.empty() ? "artex-" + experiment_name : options.job_name;
  for (char& c : name) {
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '_' || c == '.')) c = '_';
  }
  return name;
}

// sbatch options every job of a submission shares (partition, limits, the user's extras).
std::vector<std::string> ResourceArgs(const SlurmOptions& o, bool with_cpus) {
  std::vector<std::string> args;
  if (!o.partition.empty()) args.push_back("--partition=" + o.partition);
  if (!o.time.empty()) args.push_back("--time=" + o.time);
  if (!o.mem.empty()) args.push_back("--mem=" + o.mem);
  if (with_cpus) args.push_back("--cpus-per-task=" + std::to_string(o.cpus_per_task));
  return args;
}

// Runs sbatch; returns the job id or throws quoting Slurm's answer.
std::string Submit(const std::vector<std::string>& args, const std::string& what,
                   const SlurmOptions& options) {
  const CommandResult r = RunCommand(args, options.bin_dir);
  if (r.status == 127) {
    throw Error("--backend slurm: cannot run " + Program("sbatch", options.bin_dir) + " (" +
                r.Quoted() +
                "); run on a machine with Slurm's client commands (a login node; `module load "
                "slurm` on some clusters) or use the local backend");
  }
  if (!r.Ok()) {
    throw Error("sbatch refused " + what + " (" + r.Quoted() + ")");
  }
  std::string id = Trim(r.out);
  id = id.substr(0, id.find(';'));  // "<id>;<cluster>" on federated clusters
  if (id.empty() || id.find_first_not_of("0123456789") != std::string::npos) {
    throw Error("sbatch accepted " + what + " but printed no job id (output: '" + Trim(r.out) +
                "')");
  }
  return id;
}

// Checks once per output folder that a task can run this artex and write to OUT.
void Probe(const fs::path& out, const std::vector<std::string>& paths, const SlurmOptions& options,
           const std::string& exe) {
  const fs::path record = fs::path(SlurmDir(out.string())) / kProbeRecord;
  if (!options.probe || fs::exists(record)) return;
  const std::string token = std::to_string(getpid()) + "-" + std::to_string(std::time(nullptr));
  const fs::path log = fs::path(SlurmDir(out.string())) / ("probe-" + token + ".log");
  const fs::path ok = fs::path(SlurmDir(out.string())) / ("probe-" + token + ".ok");
  std::string wrap =
      "exec " + Quote(exe) + " experiment-probe --out " + Quote(out.string()) + " --token " + token;
  for (const auto& p : paths) wrap += " --check " + Quote(p);
  std::vector<std::string> args = {"sbatch", "--parsable", "--job-name=artex-probe",
                                   "--output=" + log.string(), "--ntasks=1"};
  for (const auto& a : ResourceArgs(options, false)) args.push_back(a);
  for (const auto& a : options.sbatch_args) args.push_back(a);
  args.push_back("--wrap=" + wrap);
  const std::string id = Submit(args, "the probe job", options);
  Submission probe;
  probe.job_id = id;
  const auto t0 = std::chrono::steady_clock::now();
  std::string state;
  while (true) {
    const CommandResult q =
        RunCommand({"squeue", "-h", "-t", "all", "-j", id, "-o", "%T"}, options.bin_dir);
    state = q.Ok() ? Trim(q.out) : "";
    if (fs::exists(ok) || (!state.empty() && !IsActiveState(state)) ||
        (state.empty() && !q.Ok() && fs::exists(log))) {
      break;
    }
    const double waited =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (waited > options.probe_timeout_seconds) {
      RunCommand({"scancel", id}, options.bin_dir);
      throw Error("the probe job " + id + " (checks that tasks can write to " + out.string() +
                  ") did not end within " + std::to_string(static_cast<int>(waited)) +
                  " s (state " + (state.empty() ? "unknown" : state) +
                  "); pass --no-probe to submit without the check");
    }
    std::this_thread::sleep_for(
        std::chrono::duration<double>(std::min(options.poll_seconds, kProbePollMax)));
  }
  if (!fs::exists(ok)) {
    throw Error("the probe job " + id + " could not run artex or write to " + out.string() +
                " (state " + (state.empty() ? "unknown" : state) + "; log " + log.string() + ": " +
                LastLines(log.string(), kFailureLines) +
                "); the output folder and the artex binary must be on a filesystem the nodes "
                "share");
  }
  fs::rename(ok, record);
  std::error_code ec;
  fs::remove(log, ec);
}

struct Watch {
  const TaskEntry* task = nullptr;
  std::size_t submission = 0;
  int index = 0;
  bool started = false, finished = false;
  std::string progress;
};

double WallSeconds(const std::string& run_folder) {
  try {
    const auto j = nlohmann::json::parse(ReadText((fs::path(run_folder) / "run.json").string()));
    return j.value("wall_seconds", 0.0);
  } catch (const std::exception&) {
    return 0;
  }
}

std::string FailureText(const Submission& s, int index, const TaskEntry& t, const TaskState& st) {
  const std::string log = TaskLogPath(t, s.job_id, index);
  std::string text = st.state + " (task " + s.job_id + "_" + std::to_string(index) + ", log " + log;
  std::string tail = LastLines(log, kFailureLines);
  const std::string slurm_log =
      (fs::path(s.dir) / ("slurm-" + s.job_id + "_" + std::to_string(index) + ".log")).string();
  const std::string slurm_tail = LastLines(slurm_log, 1);  // e.g. slurmstepd's CANCELLED line
  if (!slurm_tail.empty()) tail += (tail.empty() ? "" : " | ") + slurm_tail;
  return text + ")" + (tail.empty() ? "" : ": " + tail);
}

// Polls until every watched task ended; reports like the local scheduler.
void Wait(std::vector<Watch>& watch, const std::vector<Submission>& subs,
          const SlurmOptions& options, ExperimentSummary* summary,
          const std::function<void(const RunnerEvent&)>& emit) {
  std::vector<Submission> involved;
  std::map<std::size_t, bool> seen;
  for (const auto& w : watch) {
    if (!seen[w.submission]) involved.push_back(subs[w.submission]);
    seen[w.submission] = true;
  }
  auto event = [&](RunnerEvent::Kind kind, const Watch& w) {
    RunnerEvent e;
    e.kind = kind;
    e.label = w.task->label;
    e.runs_total = summary->runs_total;
    e.runs_skipped = summary->runs_skipped;
    e.runs_done = summary->runs_skipped + summary->runs_completed;
    e.runs_failed = summary->runs_failed;
    int running = 0, pending = 0;
    for (const auto& o : watch) {
      if (o.finished) continue;
      (o.started ? running : pending) += 1;
    }
    e.runs_running = running;
    e.runs_pending = pending;
    return e;
  };
  while (true) {
    const TaskStates states(involved, options.bin_dir);
    bool all_finished = true;
    for (auto& w : watch) {
      if (w.finished) continue;
      const Submission& s = subs[w.submission];
      const TaskState st = states.Of(s, w.index);
      const bool complete = RunIsComplete(w.task->run_folder);
      if (!w.started &&
          (st.state == "RUNNING" || st.state == "COMPLETING" || complete || !st.active)) {
        w.started = true;
        emit(event(RunnerEvent::Kind::kRunStarted, w));
      }
      if (complete || !st.active) {
        w.finished = true;
        if (complete) {
          ++summary->runs_completed;
          RunnerEvent e = event(RunnerEvent::Kind::kRunFinished, w);
          e.seconds = WallSeconds(w.task->run_folder);
          emit(e);
        } else {
          ++summary->runs_failed;
          const std::string why = FailureText(s, w.index, *w.task, st);
          summary->failures.push_back(w.task->label + ": " + why);
          RunnerEvent e = event(RunnerEvent::Kind::kRunFailed, w);
          e.message = why;
          emit(e);
        }
        continue;
      }
      all_finished = false;
      const std::string progress = Trim(ReadText(MarkerPath(s, w.index, "progress")));
      int done = 0, total = 0;
      if (progress != w.progress && std::sscanf(progress.c_str(), "%d %d", &done, &total) == 2) {
        w.progress = progress;
        RunnerEvent e = event(RunnerEvent::Kind::kRunProgress, w);
        e.done = done;
        e.total = total;
        emit(e);
      }
    }
    if (all_finished) return;
    std::this_thread::sleep_for(std::chrono::duration<double>(options.poll_seconds));
  }
}

}  // namespace

bool SlurmOptions::IsValid(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error) *error = m;
    return false;
  };
  if (cpus_per_task < 1)
    return fail("cpus_per_task: expected >= 1, found " + std::to_string(cpus_per_task));
  if (max_array_size < 1)
    return fail("max_array_size: expected >= 1, found " + std::to_string(max_array_size));
  if (max_parallel < 0)
    return fail("max_parallel: expected >= 0 (0: no throttle), found " +
                std::to_string(max_parallel));
  if (!(poll_seconds > 0))
    return fail("poll_seconds: expected > 0, found " + std::to_string(poll_seconds));
  if (!(probe_timeout_seconds > 0)) {
    return fail("probe_timeout_seconds: expected > 0, found " +
                std::to_string(probe_timeout_seconds));
  }
  for (const auto& a : sbatch_args) {
    if (a.rfind("--array", 0) == 0 || a.rfind("--output", 0) == 0 || a == "-a" || a == "-o") {
      return fail("sbatch argument '" + a + "': artex sets --array and --output itself");
    }
  }
  return true;
}

std::string SlurmArrayScript(const std::string& experiment_name, const std::string& out_dir,
                             const std::string& submission, int tasks, const SlurmOptions& options,
                             const std::string& executable) {
  const fs::path dir = fs::path(SlurmDir(out_dir)) / submission;
  std::ostringstream s;
  s << "#!/bin/bash\n"
    << "# artex experiment '" << experiment_name << "': " << tasks
    << " run(s) as one Slurm job array, written by `artex experiment --backend slurm`.\n"
    << "# Array task i runs entry i of tasks.json beside this script into\n"
    << "# OUT/runs/<sequence>/<configuration>/; its output goes to\n"
    << "# OUT/runs/<sequence>/slurm-logs/<configuration>/slurm-<job>_<i>.log.\n"
    << "#SBATCH --job-name=" << JobName(experiment_name, options) << "\n"
    << "#SBATCH --array=0-" << tasks - 1
    << (options.max_parallel > 0 ? "%" + std::to_string(options.max_parallel) : "") << "\n"
    << "#SBATCH --ntasks=1\n";
  for (const auto& a : ResourceArgs(options, true)) s << "#SBATCH " << a << "\n";
  s << "#SBATCH --output=" << (dir / "slurm-%A_%a.log").string() << "\n";
  if (!options.sbatch_args.empty()) {
    s << "# further sbatch arguments (given on the command line):";
    for (const auto& a : options.sbatch_args) s << " " << a;
    s << "\n";
  }
  s << "exec " << Quote(executable) << " experiment-task --out " << Quote(out_dir)
    << " --submission " << submission << " --index \"$SLURM_ARRAY_TASK_ID\" --threads "
    << options.cpus_per_task << "\n";
  return s.str();
}

RunBackend MakeSlurmBackend(const Experiment& experiment, const std::string& out_dir,
                            const SlurmOptions& options) {
  std::string why;
  if (!options.IsValid(&why)) throw Error("--backend slurm: " + why);
  const std::string experiment_file = fs::absolute(experiment.file).string();
  const std::string name = experiment.name;
  return [=](const std::vector<PendingRun>& pending, ExperimentSummary* summary,
             const std::function<void(const RunnerEvent&)>& on_event) {
    std::function<void(const RunnerEvent&)> emit = on_event;
    if (!emit) emit = [](const RunnerEvent&) {};
    const fs::path out = fs::absolute(out_dir);
    const std::string exe = options.executable.empty() ? SelfExecutable() : options.executable;
    fs::create_directories(SlurmDir(out.string()));
    WriteFileAtomic((fs::path(SlurmDir(out.string())) / kExperimentRecord).string(),
                    experiment_file + "\n");
    std::vector<Submission> subs = LoadSubmissions(out.string());
    const TaskStates states(subs, options.bin_dir);
    std::map<std::string, std::pair<std::size_t, int>> last;  // label -> latest task
    for (std::size_t i = 0; i < subs.size(); ++i) {
      for (std::size_t j = 0; j < subs[i].tasks.size(); ++j)
        last[subs[i].tasks[j].label] = {i, static_cast<int>(j)};
    }
    std::vector<Watch> watch;
    Submission next;
    std::vector<std::string> resubmitted;
    for (const PendingRun& p : pending) {
      auto it = last.find(p.label);
      if (it != last.end()) {
        const TaskState st = states.Of(subs[it->second.first], it->second.second);
        if (RunIsComplete(p.run_folder)) {  // its task finished since RunExperiment looked
          ++summary->runs_completed;
          continue;
        }
        if (st.active) {  // queued or running since an earlier invocation: wait for it
          Watch w;
          w.submission = it->second.first;
          w.index = it->second.second;
          w.task = &subs[w.submission].tasks[w.index];
          w.started = st.state == "RUNNING";
          watch.push_back(w);
          continue;
        }
        ++summary->runs_resubmitted;
        resubmitted.push_back(p.label + " (" + st.state + ")");
      }
      TaskEntry t = p;
      t.sequence_folder = fs::absolute(t.sequence_folder).string();
      t.template_path = fs::absolute(t.template_path).string();
      next.tasks.push_back(t);
      // Folders left by killed tasks of this run (none of its tasks is active).
      const fs::path parent = fs::path(t.run_folder).parent_path();
      std::error_code ec;
      if (fs::is_directory(parent, ec)) {
        for (const auto& e : fs::directory_iterator(parent)) {
          if (e.path().filename().string().rfind(".slurm-" + t.combination + ".", 0) == 0) {
            fs::remove_all(e.path(), ec);
          }
        }
      }
    }
    const std::size_t waiting_before = watch.size();
    std::string job_note;
    if (!next.tasks.empty()) {
      std::vector<std::string> paths = {next.tasks.front().template_path};
      for (const auto& t : next.tasks) {
        if (std::find(paths.begin(), paths.end(), t.sequence_folder) == paths.end())
          paths.push_back(t.sequence_folder);
      }
      Probe(out, paths, options, exe);
      // One job array per at most max_array_size runs (one array when they fit).
      std::string arrays;
      const std::size_t chunk = static_cast<std::size_t>(options.max_array_size);
      for (std::size_t first = 0; first < next.tasks.size(); first += chunk) {
        Submission part;
        part.tasks.assign(next.tasks.begin() + first,
                          next.tasks.begin() + std::min(next.tasks.size(), first + chunk));
        part.name = NextSubmissionName(out.string());
        part.dir = (fs::path(SlurmDir(out.string())) / part.name).string();
        fs::create_directories(fs::path(part.dir) / "state");
        WriteTasks(part);
        const std::string script_path = (fs::path(part.dir) / "job.sh").string();
        WriteFileAtomic(script_path,
                        SlurmArrayScript(name, out.string(), part.name,
                                         static_cast<int>(part.tasks.size()), options, exe));
        std::vector<std::string> args = {"sbatch", "--parsable"};
        for (const auto& a : options.sbatch_args) args.push_back(a);
        args.push_back(script_path);
        const std::string what =
            "the job array " + script_path + " (" + std::to_string(part.tasks.size()) + " tasks" +
            (part.tasks.size() > 1000
                 ? "; more than Slurm's default MaxArraySize allows, see --max-array-size"
                 : "") +
            ")";
        part.job_id = Submit(args, what, options);
        WriteFileAtomic((fs::path(part.dir) / "job_id").string(), part.job_id + "\n");
        subs.push_back(part);
        for (std::size_t j = 0; j < part.tasks.size(); ++j) {
          Watch w;
          w.submission = subs.size() - 1;
          w.index = static_cast<int>(j);
          watch.push_back(w);
        }
        summary->runs_submitted += static_cast<int>(part.tasks.size());
        arrays += std::string(arrays.empty() ? "" : ", ") + part.job_id + " (" + script_path + ")";
      }
      job_note = "submitted " + std::to_string(next.tasks.size()) + " run(s) as job array" +
                 (next.tasks.size() > chunk ? "s " : " ") + arrays;
      if (!resubmitted.empty()) {
        job_note += "; resubmitted " + std::to_string(resubmitted.size()) +
                    " whose task had ended without completing:";
        for (const auto& r : resubmitted) job_note += " " + r;
      }
    }
    if (waiting_before > 0) {
      job_note += std::string(job_note.empty() ? "" : "; ") + std::to_string(waiting_before) +
                  " run(s) still queued or running from an earlier submission (not resubmitted)";
    }
    summary->note = job_note;
    if (!job_note.empty()) {
      RunnerEvent e;
      e.kind = RunnerEvent::Kind::kNote;
      e.message = job_note;
      emit(e);
    }
    // Pointers into subs stay valid from here on (no more push_back).
    for (auto& w : watch) w.task = &subs[w.submission].tasks[w.index];
    if (!options.wait) {
      summary->runs_unfinished = static_cast<int>(watch.size());
      return;
    }
    Wait(watch, subs, options, summary, emit);
  };
}

std::string RecordedExperimentFile(const std::string& out_dir) {
  return Trim(ReadText((fs::path(SlurmDir(out_dir)) / kExperimentRecord).string()));
}

SlurmStatus ReadSlurmStatus(const std::string& out_dir, const std::string& experiment_file,
                            const std::string& bin_dir) {
  SlurmStatus status;
  status.experiment_file =
      experiment_file.empty() ? RecordedExperimentFile(out_dir) : experiment_file;
  if (status.experiment_file.empty()) {
    throw Error(out_dir + ": no experiment recorded (" + SlurmDir(out_dir) + "/" +
                kExperimentRecord +
                " missing); was it run with --backend slurm? Pass --experiment FILE");
  }
  const Experiment experiment = LoadExperiment(status.experiment_file);
  const std::vector<Submission> subs = LoadSubmissions(out_dir);
  const TaskStates states(subs, bin_dir);
  if (!states.sacct_available()) status.sacct_note = "sacct: " + states.sacct_error();
  std::map<std::string, std::pair<std::size_t, int>> last;
  std::map<std::string, int> attempts;
  for (std::size_t i = 0; i < subs.size(); ++i) {
    for (std::size_t j = 0; j < subs[i].tasks.size(); ++j) {
      last[subs[i].tasks[j].label] = {i, static_cast<int>(j)};
      ++attempts[subs[i].tasks[j].label];
    }
  }
  for (const auto& s : experiment.sequences) {
    for (const auto& c : experiment.combinations) {
      SlurmRunStatus r;
      r.label = s.name + "/" + c.id;
      r.attempts = attempts[r.label];
      const auto it = last.find(r.label);
      TaskState st;
      if (it != last.end()) {
        const Submission& sub = subs[it->second.first];
        const int index = it->second.second;
        st = states.Of(sub, index);
        r.task = sub.job_id + "_" + std::to_string(index);
        r.log = TaskLogPath(sub.tasks[index], sub.job_id, index);
        if (!st.active && !RunIsComplete(RunFolder(out_dir, s.name, c.id))) {
          r.detail = FailureText(sub, index, sub.tasks[index], st);
        }
      }
      if (RunIsComplete(RunFolder(out_dir, s.name, c.id))) {
        r.state = "DONE";
        r.source = "run folder";
        ++status.done;
      } else if (it == last.end()) {
        r.state = "NOT_SUBMITTED";
        ++status.not_submitted;
      } else {
        r.state = st.state;
        r.source = st.source;
        if (!st.active) {
          ++status.failed;
        } else if (st.state == "PENDING") {
          ++status.pending;
        } else {
          ++status.running;
        }
      }
      status.runs.push_back(r);
    }
  }
  return status;
}

std::string FormatSlurmStatus(const SlurmStatus& status) {
  std::ostringstream s;
  s << "experiment " << status.experiment_file << ": " << status.runs.size()
    << " runs: " << status.done << " done, " << status.running << " running, " << status.pending
    << " pending, " << status.failed << " failed, " << status.not_submitted << " not submitted\n";
  std::size_t width = 0;
  for (const auto& r : status.runs) width = std::max(width, r.label.size());
  for (const auto& r : status.runs) {
    s << "  " << r.label << std::string(width - r.label.size(), ' ') << "  " << r.state;
    if (!r.task.empty()) {
      s << "  task " << r.task << " (" << r.source << "; " << r.attempts << " attempt"
        << (r.attempts == 1 ? "" : "s") << ")";
    }
    s << "\n";
    if (!r.detail.empty()) s << "      " << r.detail << "\n";
  }
  if (!status.sacct_note.empty()) {
    s << "(" << status.sacct_note << "; states of tasks Slurm no longer lists come from the tasks' "
      << "own markers)\n";
  }
  return s.str();
}

}  // namespace artex
