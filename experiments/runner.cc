// The experiment runner (experiments/runner.h): RunExperiment places and generates the
// sequences and the template, decides which runs are pending from the stored run keys and DONE
// markers (reruns skip complete runs and redo interrupted ones), hands them to the scheduler
// (runner_schedule.cc) or a backend, and completes run folders. The other parts: experiment
// files (runner_parse.cc), synthetic specs (runner_synth.cc), one run (runner_single.cc),
// results (runner_results.cc).
#include "experiments/runner.h"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "experiments/file_util.h"
#include "experiments/runner_internal.h"
#include "models/error.h"
#include "models/fnv1a.h"
#include "models/template_cache.h"
#include "models/template_generator.h"
#include "models/template_io.h"
#include "sensors/sequence.h"

namespace artex {
namespace fs = std::filesystem;

namespace {

using runner_internal::Hex;
using runner_internal::Job;
using runner_internal::Schedule;
using runner_internal::SelfExecutable;

constexpr const char* kDoneMarker = "DONE";
constexpr const char* kRunKeyFile = "run_key.txt";
constexpr const char* kTmpPrefix = ".tmp-";
constexpr const char* kFailedPrefix = ".failed-";

// Exclusive lock on OUT/.lock for the runner's lifetime (released by the kernel on exit/kill).
class OutputLock {
 public:
  explicit OutputLock(const std::string& out_dir) {
    const std::string path = (fs::path(out_dir) / ".lock").string();
    fd_ = open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
    if (fd_ < 0) throw Error(path + ": cannot open the lock file: " + std::strerror(errno));
    if (flock(fd_, LOCK_EX | LOCK_NB) != 0) {
      close(fd_);
      throw Error(out_dir + ": another `artex experiment` is running on this output folder");
    }
  }
  ~OutputLock() { close(fd_); }
  OutputLock(const OutputLock&) = delete;
  OutputLock& operator=(const OutputLock&) = delete;

 private:
  int fd_ = -1;
};

void RemoveStale(const fs::path& dir) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) return;
  for (const auto& entry : fs::directory_iterator(dir)) {
    const std::string name = entry.path().filename().string();
    if (name.rfind(kTmpPrefix, 0) == 0) fs::remove_all(entry.path(), ec);
  }
}

}  // namespace

std::string RunFolder(const std::string& out_dir, const std::string& sequence,
                      const std::string& combination_id) {
  return (fs::path(out_dir) / "runs" / sequence / combination_id).string();
}

std::string CompleteRun(const std::string& tmp_dir, const std::string& run_folder,
                        const std::string& run_json) {
  const fs::path tmp(tmp_dir);
  WriteFileAtomic((tmp / "run.json").string(), run_json);
  WriteFileAtomic((tmp / kDoneMarker).string(), "complete\n");
  std::error_code ec;
  fs::rename(tmp, run_folder, ec);
  if (ec) {
    if (RunIsComplete(run_folder)) {
      fs::remove_all(tmp, ec);
      return "";
    }
    return "cannot rename " + tmp_dir + " to " + run_folder + ": " + ec.message();
  }
  return "";
}

bool RunIsComplete(const std::string& run_folder) {
  return fs::is_regular_file(fs::path(run_folder) / kDoneMarker);
}

std::string SourceDirectory() {
#ifdef ARTEX_SOURCE_TREE
  return ARTEX_SOURCE_TREE;  // absolute (experiments/CMakeLists.txt)
#else
  // This file is experiments/runner.cc inside the source tree it was compiled from (__FILE__ is
  // relative to the build folder when compiled through ccache with a base directory).
  return fs::absolute(fs::path(__FILE__)).parent_path().parent_path().string();
#endif
}

std::string SourceRevision() {
  const std::string dir = SourceDirectory();
  if (!fs::exists(fs::path(dir) / ".git")) return "unknown";  // a folder, or a file in a worktree
  auto run = [](const std::string& cmd) {
    std::string out;
    FILE* p = popen(cmd.c_str(), "r");
    if (!p) return out;
    char buf[256];
    while (std::fgets(buf, sizeof(buf), p)) out += buf;
    if (pclose(p) != 0) return std::string();
    return out;
  };
  std::string sha = run("git -C '" + dir + "' rev-parse HEAD 2>/dev/null");
  while (!sha.empty() && std::isspace(static_cast<unsigned char>(sha.back()))) sha.pop_back();
  if (sha.empty()) return "unknown";
  const std::string status = run("git -C '" + dir + "' status --porcelain --untracked-files=no 2>/dev/null");
  return status.empty() ? sha : sha + "-dirty";
}

ExperimentSummary RunExperiment(const Experiment& experiment, const std::string& out_dir,
                                const RunnerOptions& options,
                                const std::function<void(const RunnerEvent&)>& on_event) {
  const auto t0 = std::chrono::steady_clock::now();
  std::error_code ec;
  fs::create_directories(out_dir, ec);
  if (!fs::is_directory(out_dir)) throw Error(out_dir + ": cannot create the output folder");
  const fs::path out = fs::absolute(out_dir);
  OutputLock lock(out.string());
  const std::string exe = options.executable.empty() ? SelfExecutable() : options.executable;
  const int cores = std::max(1u, std::thread::hardware_concurrency());
  const int jobs = options.jobs > 0 ? options.jobs : cores;
  const int threads = options.threads_per_run > 0 ? options.threads_per_run : std::max(1, cores / jobs);
  auto emit = [&](RunnerEvent e) {
    if (on_event) on_event(e);
  };

  // Sequences: reuse OUT/sequences/<name> when generated from the same spec.
  std::vector<ExperimentSequence> sequences = experiment.sequences;
  const fs::path seq_root = out / "sequences";
  fs::create_directories(seq_root);
  if (!options.dry_run) RemoveStale(seq_root);
  std::vector<Job> synth_jobs;
  std::vector<std::string> errors;
  for (auto& s : sequences) {
    if (!s.synthetic) continue;
    const fs::path final_dir = seq_root / s.name;
    s.folder = final_dir.string();
    if (fs::exists(final_dir)) {
      const std::string stored = ReadText((final_dir / "synth.yaml").string());
      if (stored != s.synth_yaml + "\n" && options.replace_changed && !options.dry_run) {
        fs::remove_all(final_dir);
      } else if (stored != s.synth_yaml + "\n") {
        throw Error(final_dir.string() + ": this sequence was generated from a different spec (" +
                    (stored.empty() ? std::string("none") : stored.substr(0, stored.size() - 1)) +
                    "; now " + s.synth_yaml + "); delete the folder, give the sequence another name or pass --replace-changed");
      }
      if (fs::exists(final_dir)) {
        RunnerEvent e;
        e.kind = RunnerEvent::Kind::kSequenceReady;
        e.label = s.name;
        emit(e);
        continue;
      }
    }
    if (options.dry_run) continue;
    const fs::path tmp = seq_root / (kTmpPrefix + s.name + "." + std::to_string(getpid()));
    fs::create_directories(tmp);
    const std::string spec_path = (tmp / "spec.yaml").string();
    WriteFileAtomic(spec_path, s.synth_yaml + "\n");
    Job job;
    job.label = s.name;
    job.tmp_dir = tmp.string();
    job.log_path = (tmp / "log.txt").string();
    job.args = {exe, "experiment-synth", "--spec", spec_path, "--name", experiment.file + ": " + s.name,
                "--out", (tmp / "sequence").string()};
    job.finish = [tmp, final_dir](double) -> std::string {
      fs::rename(tmp / "sequence", final_dir);
      std::error_code e2;
      fs::remove_all(tmp, e2);
      return "";
    };
    job.fail = [&errors, name = s.name](const std::string& message) { errors.push_back(name + ": " + message); };
    synth_jobs.push_back(job);
  }
  auto seq_report = [&](const Job& job, RunnerEvent::Kind kind, int done, int total, double seconds,
                        const std::string& message) {
    RunnerEvent e;
    e.kind = kind == RunnerEvent::Kind::kRunStarted    ? RunnerEvent::Kind::kSequenceStarted
             : kind == RunnerEvent::Kind::kRunFinished ? RunnerEvent::Kind::kSequenceReady
             : kind == RunnerEvent::Kind::kRunProgress ? RunnerEvent::Kind::kSequenceProgress
                                                       : kind;
    e.label = job.label;
    e.done = done;
    e.total = total;
    e.seconds = seconds;
    e.message = message;
    if (kind != RunnerEvent::Kind::kRunFailed) emit(e);
  };
  Schedule(synth_jobs, jobs, seq_report);
  if (!errors.empty()) {
    std::string msg = "sequence generation failed:";
    for (const auto& m : errors) msg += "\n  " + m;
    throw Error(msg);
  }

  // Tracking template: generated once per spec into OUT/templates/: template-<hash>.bin, which
  // the runs read (the generated template bit for bit, as `artex track` tracks with it), and a
  // .glb of it to look at (its positions rounded to float).
  std::string template_path = experiment.template_path;
  std::string template_identity = experiment.template_path;
  if (template_path.empty()) {
    const fs::path dir = out / "templates";
    fs::create_directories(dir);
    template_identity = experiment.template_yaml;
    const std::string stem = "template-" + Hex(Fnv1a(experiment.template_yaml), 12);
    const fs::path bin = dir / (stem + ".bin");
    template_path = bin.string();
    if (!fs::exists(bin) && !options.dry_run) {
      const Config c = Config::FromString(experiment.template_yaml, experiment.file + ": template");
      BodyShapeOptions shape;
      c.Get("resolution", &shape.resolution);
      c.Get("height", &shape.height);
      c.Get("girth", &shape.girth);
      c.Get("shoulder_width", &shape.shoulder_width);
      c.Get("hip_width", &shape.hip_width);
      c.Get("arm_length", &shape.arm_length);
      c.Get("leg_length", &shape.leg_length);
      c.Get("atlas_size", &shape.atlas_size);
      const Template tmpl = GenerateTemplate(shape);
      WriteTemplateGlb((dir / (stem + ".glb")).string(), tmpl);
      WriteFileAtomic((dir / (stem + ".yaml")).string(), experiment.template_yaml + "\n");
      WriteTemplateBinary(tmpl, bin.string());  // last: its presence means the folder is complete
    }
  }

  // Runs.
  const std::string revision = SourceRevision();
  ExperimentSummary summary;
  summary.runs_total = static_cast<int>(sequences.size() * experiment.combinations.size());
  std::vector<Job> run_jobs;
  std::vector<PendingRun> pending;
  int skipped = 0, would_run = 0;
  for (const auto& s : sequences) {
    const fs::path seq_runs = out / "runs" / s.name;
    fs::create_directories(seq_runs);
    if (!options.dry_run) RemoveStale(seq_runs);
    for (const auto& c : experiment.combinations) {
      const std::string config_text = CombinationConfig(experiment, c).ToYaml() + "\n";
      const std::string key = "sequence: " + s.name + "\nsequence_spec: " +
                              (s.synthetic ? s.synth_yaml : s.folder) + "\ntemplate: " +
                              template_identity + "\nconfiguration:\n" + config_text;
      const fs::path final_dir = seq_runs / c.id;
      const std::string label = s.name + "/" + c.id;
      if (RunIsComplete(final_dir.string()) && options.replace_changed && !options.dry_run &&
          ReadText((final_dir / kRunKeyFile).string()) != key) {
        fs::remove_all(final_dir);
      }
      if (RunIsComplete(final_dir.string())) {
        if (ReadText((final_dir / kRunKeyFile).string()) != key) {
          throw Error(final_dir.string() + ": this run was completed with different inputs (see " +
                      (final_dir / kRunKeyFile).string() +
                      "); use another output folder, delete the run folder or pass --replace-changed");
        }
        ++skipped;
        RunnerEvent e;
        e.kind = RunnerEvent::Kind::kRunSkipped;
        e.label = label;
        emit(e);
        continue;
      }
      if (options.dry_run) {
        ++would_run;
        continue;
      }
      nlohmann::ordered_json info;
      info["experiment"] = experiment.name;
      info["experiment_file"] = experiment.file;
      info["sequence"] = s.name;
      info["sequence_folder"] = s.folder;
      info["combination"] = c.id;
      nlohmann::ordered_json ov = nlohmann::ordered_json::object();
      for (const auto& o : c.overrides) ov[o.key] = o.value;
      info["overrides"] = ov;
      info["template"] = template_path;
      info["git_revision"] = revision;
      info["threads"] = threads;
      info["jobs"] = jobs;
      if (options.backend) {  // a remote backend creates the run's folder where it runs
        pending.push_back({label, s.name, c.id, s.folder, template_path, final_dir.string(),
                           config_text, key, info.dump()});
        continue;
      }
      if (fs::exists(final_dir)) fs::remove_all(final_dir);  // incomplete: rerun from scratch
      const fs::path tmp = seq_runs / (kTmpPrefix + c.id + "." + std::to_string(getpid()));
      fs::create_directories(tmp);
      WriteFileAtomic((tmp / "run_config.yaml").string(), config_text);
      WriteFileAtomic((tmp / kRunKeyFile).string(), key);
      Job job;
      job.label = label;
      job.tmp_dir = tmp.string();
      job.log_path = (tmp / "log.txt").string();
      job.args = {exe, "experiment-run", "--config", (tmp / "run_config.yaml").string(),
                  "--sequence", s.folder, "--template", template_path, "--out", tmp.string(),
                  "--threads", std::to_string(threads)};
      std::string command;
      for (const auto& a : job.args) command += (command.empty() ? "" : " ") + a;
      info["command"] = command;
      job.finish = [tmp, final_dir, info](double seconds) mutable -> std::string {
        if (!fs::exists(tmp / "results.json")) return "the run wrote no results.json";
        info["wall_seconds"] = seconds;
        return CompleteRun(tmp.string(), final_dir.string(), info.dump(2) + "\n");
      };
      job.fail = [&summary, tmp, seq_runs, id = c.id, label](const std::string& message) {
        const fs::path failed = seq_runs / (kFailedPrefix + id);
        std::error_code e2;
        fs::remove_all(failed, e2);
        fs::rename(tmp, failed, e2);
        summary.failures.push_back(label + ": " + message + " (log: " + (failed / "log.txt").string() + ")");
      };
      run_jobs.push_back(job);
    }
  }
  summary.runs_skipped = skipped;
  {
    RunnerEvent e;
    e.kind = RunnerEvent::Kind::kPlan;
    e.runs_total = summary.runs_total;
    e.runs_skipped = skipped;
    e.total = static_cast<int>(run_jobs.size() + pending.size()) + would_run;
    emit(e);
  }
  int running = 0;
  auto run_report = [&](const Job& job, RunnerEvent::Kind kind, int done, int total, double seconds,
                        const std::string& message) {
    if (kind == RunnerEvent::Kind::kRunStarted) ++running;
    if (kind == RunnerEvent::Kind::kRunFinished) {
      --running;
      ++summary.runs_completed;
    }
    if (kind == RunnerEvent::Kind::kRunFailed) {
      --running;
      ++summary.runs_failed;
    }
    RunnerEvent e;
    e.kind = kind;
    e.label = job.label;
    e.done = done;
    e.total = total;
    e.seconds = seconds;
    e.message = message;
    e.runs_total = summary.runs_total;
    e.runs_done = summary.runs_completed + skipped;
    e.runs_skipped = skipped;
    e.runs_failed = summary.runs_failed;
    e.runs_running = std::max(0, running);
    emit(e);
  };
  if (!options.dry_run) {
    if (options.backend) {
      options.backend(pending, &summary, [&](const RunnerEvent& e) { emit(e); });
    } else {
      Schedule(run_jobs, jobs, run_report);
    }
    Experiment placed = experiment;
    placed.sequences = sequences;
    WriteExperimentResults(placed, out.string());
  }
  summary.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return summary;
}

}  // namespace artex
