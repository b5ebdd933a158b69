// The two entry points that run on Slurm's nodes: one array task (`artex experiment-task`) and
// the probe job (`artex experiment-probe`); see experiments/slurm_backend.h.
#include <fcntl.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "experiments/slurm_backend.h"
#include "experiments/slurm_queue.h"
#include "models/error.h"
#include "sensors/sequence.h"

namespace artex {
namespace fs = std::filesystem;
using namespace slurm;  // NOLINT(build/namespaces)

namespace {

std::string HostName() {
  char host[256] = {0};
  if (gethostname(host, sizeof(host) - 1) != 0) return "unknown";
  return host;
}

std::string Now() {
  const std::time_t t = std::time(nullptr);
  char buf[32];
  std::strftime(buf, sizeof(buf), "%Y-%m-%dT%H:%M:%SZ", std::gmtime(&t));
  return buf;
}

std::string EnvOr(const char* name, const std::string& fallback) {
  const char* v = std::getenv(name);
  return v && *v ? std::string(v) : fallback;
}

}  // namespace

int RunSlurmTask(const std::string& out_dir, const std::string& submission, int index,
                 int threads) {
  const Submission s = LoadSubmission((fs::path(SlurmDir(out_dir)) / submission).string());
  if (index < 0 || index >= static_cast<int>(s.tasks.size())) {
    std::fprintf(stderr, "artex experiment-task: index %d out of range (%s has %zu tasks)\n", index,
                 s.dir.c_str(), s.tasks.size());
    return 2;
  }
  const TaskEntry& t = s.tasks[index];
  // The job id file is written after sbatch returns; a task may start before that.
  const std::string job = EnvOr("SLURM_ARRAY_JOB_ID", s.job_id.empty() ? "nojob" : s.job_id);
  const std::string task_id = job + "_" + std::to_string(index);
  const std::string log = TaskLogPath(t, job, index);
  fs::create_directories(fs::path(log).parent_path());
  const int fd = open(log.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
  if (fd < 0) {
    std::fprintf(stderr, "artex experiment-task: cannot open %s\n", log.c_str());
    return 2;
  }
  std::fflush(stdout);
  std::fflush(stderr);
  dup2(fd, STDOUT_FILENO);
  dup2(fd, STDERR_FILENO);
  close(fd);
  std::fprintf(stderr, "artex experiment-task %s: %s on %s at %s\n", task_id.c_str(),
               t.label.c_str(), HostName().c_str(), Now().c_str());
  WriteFileAtomic(MarkerPath(s, index, "started"), HostName() + " " + Now() + "\n");
  const fs::path tmp = TaskTmpDir(t, job, index);
  try {
    if (RunIsComplete(t.run_folder)) {
      std::fprintf(stderr, "%s: already complete; nothing to do\n", t.run_folder.c_str());
      WriteFileAtomic(MarkerPath(s, index, "exit"), "0 already complete\n");
      return 0;
    }
    std::error_code ec;
    fs::remove_all(tmp, ec);
    fs::create_directories(tmp);
    const std::string config = (tmp / "run_config.yaml").string();
    WriteFileAtomic(config, t.config_text);
    WriteFileAtomic((tmp / "run_key.txt").string(), t.key);
    const auto t0 = std::chrono::steady_clock::now();
    const std::string progress_path = MarkerPath(s, index, "progress");
    RunSingle(config, t.sequence_folder, t.template_path, tmp.string(), threads,
              [&](int done, int total) {
                WriteFileAtomic(progress_path,
                                std::to_string(done) + " " + std::to_string(total) + "\n");
              });
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::fflush(stderr);
    fs::copy_file(log, tmp / "log.txt", fs::copy_options::overwrite_existing, ec);
    nlohmann::ordered_json info = nlohmann::ordered_json::parse(t.info_json);
    info["threads"] = threads;
    info["backend"] = "slurm";
    info["slurm_task"] = task_id;
    info["host"] = HostName();
    info["command"] = "artex experiment-task --out " + out_dir + " --submission " + submission +
                      " --index " + std::to_string(index) + " --threads " + std::to_string(threads);
    info["wall_seconds"] = seconds;
    if (fs::exists(t.run_folder) && !RunIsComplete(t.run_folder)) fs::remove_all(t.run_folder);
    const std::string error = CompleteRun(tmp.string(), t.run_folder, info.dump(2) + "\n");
    if (!error.empty()) throw Error(error);
    std::fprintf(stderr, "artex experiment-task %s: complete in %.1f s\n", task_id.c_str(),
                 seconds);
    WriteFileAtomic(MarkerPath(s, index, "exit"), "0\n");
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "artex experiment-task %s: FAILED: %s\n", task_id.c_str(), e.what());
    WriteFileAtomic(MarkerPath(s, index, "exit"), std::string("1 ") + e.what() + "\n");
    std::error_code ec;
    const fs::path failed = fs::path(t.run_folder).parent_path() / (".failed-" + t.combination);
    fs::remove_all(failed, ec);
    fs::rename(tmp, failed, ec);
    return 1;
  }
}

void RunSlurmProbe(const std::string& out_dir, const std::string& token,
                   const std::vector<std::string>& paths) {
  for (const auto& p : paths) {
    if (!fs::exists(p)) throw Error(p + ": not visible from node " + HostName());
  }
  WriteFileAtomic((fs::path(SlurmDir(out_dir)) / ("probe-" + token + ".ok")).string(),
                  HostName() + " " + Now() + "\n");
}

}  // namespace artex
