#include "experiments/slurm_queue.h"

#include <fcntl.h>
#include <poll.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "models/error.h"
#include "sensors/sequence.h"

namespace artex {
namespace slurm {
namespace fs = std::filesystem;

namespace {

constexpr const char* kTasksFile = "tasks.json";
constexpr const char* kJobIdFile = "job_id";

std::string JoinIds(const std::vector<Submission>& submissions) {
  std::string ids;
  for (const auto& s : submissions) {
    if (!s.job_id.empty()) ids += (ids.empty() ? "" : ",") + s.job_id;
  }
  return ids;
}

// "123_4|STATE" lines (squeue -o '%i|%T', sacct -P -o JobID,State) into id -> first word.
void ParseStates(const std::string& text, std::map<std::string, std::string>* states) {
  std::istringstream in(text);
  std::string line;
  while (std::getline(in, line)) {
    const auto bar = line.find('|');
    if (bar == std::string::npos) continue;
    const std::string id = Trim(line.substr(0, bar));
    std::string state = Trim(line.substr(bar + 1));
    state = state.substr(0, state.find(' '));  // "CANCELLED by 0" -> CANCELLED
    if (!id.empty() && !state.empty()) (*states)[id] = state;
  }
}

}  // namespace

std::string Trim(const std::string& s) {
  const auto b = s.find_first_not_of(" \t\r\n");
  if (b == std::string::npos) return "";
  const auto e = s.find_last_not_of(" \t\r\n");
  return s.substr(b, e - b + 1);
}

std::string LastLines(const std::string& path, int count) {
  std::ifstream in(path);
  std::vector<std::string> lines;
  std::string line;
  while (std::getline(in, line)) {
    const auto cr = line.find_last_of('\r');
    if (cr != std::string::npos) line = line.substr(cr + 1);
    if (!Trim(line).empty() && line.rfind("progress ", 0) != 0) lines.push_back(line);
  }
  std::string out;
  const std::size_t first =
      lines.size() > static_cast<std::size_t>(count) ? lines.size() - count : 0;
  for (std::size_t i = first; i < lines.size(); ++i) out += (out.empty() ? "" : " | ") + lines[i];
  return out;
}

std::string CommandResult::Quoted() const {
  std::string text = Trim(err);
  if (text.empty()) text = Trim(out);
  if (text.empty()) text = "(no output)";
  return "exit " + std::to_string(status) + ": " + text;
}

std::string Program(const std::string& name, const std::string& bin_dir) {
  return bin_dir.empty() ? name : (fs::path(bin_dir) / name).string();
}

CommandResult RunCommand(const std::vector<std::string>& args, const std::string& bin_dir) {
  CommandResult result;
  if (args.empty()) return result;
  int out_pipe[2], err_pipe[2];
  if (pipe2(out_pipe, O_CLOEXEC) != 0)
    throw Error("cannot create a pipe: " + std::string(std::strerror(errno)));
  if (pipe2(err_pipe, O_CLOEXEC) != 0) {
    close(out_pipe[0]);
    close(out_pipe[1]);
    throw Error("cannot create a pipe: " + std::string(std::strerror(errno)));
  }
  const std::string program = Program(args[0], bin_dir);
  std::vector<char*> argv;
  argv.push_back(const_cast<char*>(program.c_str()));
  for (std::size_t i = 1; i < args.size(); ++i) argv.push_back(const_cast<char*>(args[i].c_str()));
  argv.push_back(nullptr);
  const pid_t pid = fork();
  if (pid < 0) throw Error("fork failed: " + std::string(std::strerror(errno)));
  if (pid == 0) {
    const int devnull = open("/dev/null", O_RDONLY);
    if (devnull >= 0) dup2(devnull, STDIN_FILENO);
    dup2(out_pipe[1], STDOUT_FILENO);
    dup2(err_pipe[1], STDERR_FILENO);
    execvp(argv[0], argv.data());
    const char* msg = "cannot execute the command: not found or not executable\n";
    [[maybe_unused]] const ssize_t n = write(STDERR_FILENO, msg, std::strlen(msg));
    _exit(127);
  }
  close(out_pipe[1]);
  close(err_pipe[1]);
  pollfd fds[2] = {{out_pipe[0], POLLIN, 0}, {err_pipe[0], POLLIN, 0}};
  std::string* sinks[2] = {&result.out, &result.err};
  int open_fds = 2;
  while (open_fds > 0) {
    if (poll(fds, 2, -1) < 0) {
      if (errno == EINTR) continue;
      break;
    }
    for (int i = 0; i < 2; ++i) {
      if (fds[i].fd < 0 || !(fds[i].revents & (POLLIN | POLLHUP | POLLERR))) continue;
      char buf[4096];
      const ssize_t n = read(fds[i].fd, buf, sizeof(buf));
      if (n > 0) {
        sinks[i]->append(buf, static_cast<std::size_t>(n));
      } else {
        close(fds[i].fd);
        fds[i].fd = -1;
        --open_fds;
      }
    }
  }
  int status = 0;
  while (waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  result.status = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  return result;
}

std::string SlurmDir(const std::string& out_dir) { return (fs::path(out_dir) / "slurm").string(); }

void WriteTasks(const Submission& submission) {
  nlohmann::ordered_json tasks = nlohmann::ordered_json::array();
  for (const auto& t : submission.tasks) {
    nlohmann::ordered_json j;
    j["label"] = t.label;
    j["sequence"] = t.sequence;
    j["combination"] = t.combination;
    j["sequence_folder"] = t.sequence_folder;
    j["template"] = t.template_path;
    j["run_folder"] = t.run_folder;
    j["configuration"] = t.config_text;
    j["key"] = t.key;
    j["info"] = nlohmann::ordered_json::parse(t.info_json);
    tasks.push_back(j);
  }
  WriteFileAtomic((fs::path(submission.dir) / kTasksFile).string(), tasks.dump(1) + "\n");
}

Submission LoadSubmission(const std::string& dir) {
  Submission s;
  s.dir = dir;
  s.name = fs::path(dir).filename().string();
  s.job_id = Trim(ReadText((fs::path(dir) / kJobIdFile).string()));
  const std::string path = (fs::path(dir) / kTasksFile).string();
  try {
    const auto doc = nlohmann::ordered_json::parse(ReadText(path));
    for (const auto& j : doc) {
      TaskEntry t;
      t.label = j.at("label").get<std::string>();
      t.sequence = j.at("sequence").get<std::string>();
      t.combination = j.at("combination").get<std::string>();
      t.sequence_folder = j.at("sequence_folder").get<std::string>();
      t.template_path = j.at("template").get<std::string>();
      t.run_folder = j.at("run_folder").get<std::string>();
      t.config_text = j.at("configuration").get<std::string>();
      t.key = j.at("key").get<std::string>();
      t.info_json = j.at("info").dump();
      s.tasks.push_back(t);
    }
  } catch (const std::exception& e) {
    throw Error(path + ": malformed task list: " + e.what());
  }
  return s;
}

std::vector<Submission> LoadSubmissions(const std::string& out_dir) {
  std::vector<std::string> dirs;
  std::error_code ec;
  if (fs::is_directory(SlurmDir(out_dir), ec)) {
    for (const auto& entry : fs::directory_iterator(SlurmDir(out_dir))) {
      const std::string name = entry.path().filename().string();
      if (entry.is_directory() && name.rfind("submit-", 0) == 0 &&
          fs::exists(entry.path() / kJobIdFile) && fs::exists(entry.path() / kTasksFile)) {
        dirs.push_back(entry.path().string());
      }
    }
  }
  std::sort(dirs.begin(), dirs.end());
  std::vector<Submission> out;
  for (const auto& d : dirs) {
    Submission s = LoadSubmission(d);
    if (!s.job_id.empty()) out.push_back(std::move(s));
  }
  return out;
}

std::string NextSubmissionName(const std::string& out_dir) {
  for (int n = 1;; ++n) {
    char name[32];
    std::snprintf(name, sizeof(name), "submit-%03d", n);
    if (!fs::exists(fs::path(SlurmDir(out_dir)) / name)) return name;
  }
}

std::string TaskLogPath(const TaskEntry& task, const std::string& job, int index) {
  return (fs::path(task.run_folder).parent_path() / "slurm-logs" / task.combination /
          ("slurm-" + job + "_" + std::to_string(index) + ".log"))
      .string();
}

std::string TaskTmpDir(const TaskEntry& task, const std::string& job, int index) {
  return (fs::path(task.run_folder).parent_path() /
          (".slurm-" + task.combination + "." + job + "_" + std::to_string(index)))
      .string();
}

std::string MarkerPath(const Submission& s, int index, const std::string& kind) {
  return (fs::path(s.dir) / "state" / (std::to_string(index) + "." + kind)).string();
}

bool IsActiveState(const std::string& state) {
  static const char* kActive[] = {"PENDING",      "RUNNING",   "CONFIGURING",  "COMPLETING",
                                  "SUSPENDED",    "REQUEUED",  "REQUEUE_HOLD", "REQUEUE_FED",
                                  "RESIZING",     "SIGNALING", "STAGE_OUT",    "STOPPED",
                                  "RESV_DEL_HOLD"};
  for (const char* a : kActive) {
    if (state == a) return true;
  }
  return false;
}

TaskStates::TaskStates(const std::vector<Submission>& submissions, const std::string& bin_dir) {
  if (JoinIds(submissions).empty()) return;
  // squeue knows the queued and running tasks and, for MinJobAge seconds, the finished ones.
  // One call per job id: an id the controller has forgotten makes squeue fail.
  for (const auto& s : submissions) {
    const CommandResult q =
        RunCommand({"squeue", "-h", "-r", "-t", "all", "-j", s.job_id, "-o", "%i|%T"}, bin_dir);
    if (q.Ok()) ParseStates(q.out, &squeue_);
  }
  const CommandResult a = RunCommand({"sacct", "-n", "-P", "-X", "-S", "2000-01-01", "-j",
                                      JoinIds(submissions), "-o", "JobID,State"},
                                     bin_dir);
  if (a.Ok()) {
    ParseStates(a.out, &sacct_);
  } else {
    sacct_available_ = false;
    sacct_error_ = a.Quoted();
  }
}

TaskState TaskStates::Of(const Submission& submission, int index) const {
  TaskState t;
  const std::string id = submission.job_id + "_" + std::to_string(index);
  t.exit = Trim(ReadText(MarkerPath(submission, index, "exit")));
  auto q = squeue_.find(id);
  auto a = sacct_.find(id);
  if (q != squeue_.end()) {
    t.state = q->second;
    t.source = "squeue";
  } else if (a != sacct_.end()) {
    t.state = a->second;
    t.source = "sacct";
  } else if (!t.exit.empty()) {
    t.state = t.exit.rfind("0", 0) == 0 ? "COMPLETED" : "FAILED";
    t.source = "markers";
  } else if (fs::exists(MarkerPath(submission, index, "started"))) {
    t.state = "KILLED";  // started, never wrote its exit marker, unknown to Slurm now
    t.source = "markers";
  } else {
    t.state = "LOST";
    t.source = "markers";
  }
  t.active = IsActiveState(t.state);
  return t;
}

}  // namespace slurm
}  // namespace artex
