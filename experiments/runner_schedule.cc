// The experiment runner's child processes (experiments/runner.h): fork + exec with the
// progress pipe and the log file, and the scheduler that runs jobs `jobs` at a time from a
// single-threaded poll loop.
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "experiments/runner_internal.h"
#include "models/error.h"

namespace artex {
namespace runner_internal {
namespace fs = std::filesystem;

namespace {

constexpr int kLogTailLines = 6;        // lines of a failed child's log quoted in the report
constexpr int kPollMilliseconds = 200;  // progress refresh of the parent's event loop

}  // namespace

std::string SelfExecutable() {
  std::error_code ec;
  const fs::path p = fs::read_symlink("/proc/self/exe", ec);
  return ec ? std::string("/proc/self/exe") : p.string();
}

namespace {

std::string LogTail(const std::string& path) {
  std::ifstream in(path);
  std::vector<std::string> lines;
  std::string line;
  while (std::getline(in, line)) {
    // Progress redraws use '\r'; keep the last segment.
    const auto cr = line.find_last_of('\r');
    if (cr != std::string::npos) line = line.substr(cr + 1);
    if (!line.empty()) lines.push_back(line);
  }
  std::string out;
  const std::size_t first = lines.size() > kLogTailLines ? lines.size() - kLogTailLines : 0;
  for (std::size_t i = first; i < lines.size(); ++i) out += (out.empty() ? "" : " | ") + lines[i];
  return out.empty() ? "(empty log)" : out;
}

struct Child {
  pid_t pid = -1;
  int out_fd = -1;
  std::string buffer;
  int task = -1;
  std::chrono::steady_clock::time_point start;
};

// fork + exec `args` with stdout to a pipe (progress lines) and stderr to log_path. The child
// dies with the parent (PR_SET_PDEATHSIG), so killing the runner never leaves orphans writing.
Child Spawn(const std::vector<std::string>& args, const std::string& log_path) {
  int pipe_fds[2];
  if (pipe2(pipe_fds, O_CLOEXEC) != 0) throw Error("cannot create a pipe: " + std::string(std::strerror(errno)));
  const int log_fd = open(log_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (log_fd < 0) {
    close(pipe_fds[0]);
    close(pipe_fds[1]);
    throw Error(log_path + ": cannot create the log file: " + std::strerror(errno));
  }
  std::vector<char*> argv;
  for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  const pid_t parent = getpid();
  const pid_t pid = fork();
  if (pid < 0) {
    close(pipe_fds[0]);
    close(pipe_fds[1]);
    close(log_fd);
    throw Error("fork failed: " + std::string(std::strerror(errno)));
  }
  if (pid == 0) {
    // Only async-signal-safe calls until exec.
    prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (getppid() != parent) _exit(127);
    dup2(pipe_fds[1], STDOUT_FILENO);
    dup2(log_fd, STDERR_FILENO);
    execv(argv[0], argv.data());
    _exit(127);
  }
  close(pipe_fds[1]);
  close(log_fd);
  Child c;
  c.pid = pid;
  c.out_fd = pipe_fds[0];
  c.start = std::chrono::steady_clock::now();
  return c;
}

}  // namespace

void Schedule(std::vector<Job>& jobs, int parallel,
              const std::function<void(const Job&, RunnerEvent::Kind, int, int, double,
                                       const std::string&)>& report) {
  std::size_t next = 0;
  std::vector<Child> running;
  while (next < jobs.size() || !running.empty()) {
    while (next < jobs.size() && static_cast<int>(running.size()) < parallel) {
      Job& job = jobs[next];
      Child c;
      try {
        c = Spawn(job.args, job.log_path);
      } catch (const Error& e) {
        job.fail(e.what());
        report(job, RunnerEvent::Kind::kRunStarted, 0, 0, 0, "");
        report(job, RunnerEvent::Kind::kRunFailed, 0, 0, 0, e.what());
        ++next;
        continue;
      }
      c.task = static_cast<int>(next);
      running.push_back(c);
      report(job, RunnerEvent::Kind::kRunStarted, 0, 0, 0, "");
      ++next;
    }
    std::vector<pollfd> fds;
    for (const auto& c : running) fds.push_back({c.out_fd, POLLIN, 0});
    if (fds.empty()) continue;
    const int ready = poll(fds.data(), fds.size(), kPollMilliseconds);
    if (ready < 0 && errno != EINTR) throw Error("poll failed: " + std::string(std::strerror(errno)));
    for (std::size_t i = 0; i < running.size();) {
      Child& c = running[i];
      bool closed = false;
      if (fds[i].revents & (POLLIN | POLLHUP | POLLERR)) {
        char buf[4096];
        const ssize_t n = read(c.out_fd, buf, sizeof(buf));
        if (n <= 0) {
          closed = true;
        } else {
          c.buffer.append(buf, static_cast<std::size_t>(n));
          std::size_t pos;
          while ((pos = c.buffer.find('\n')) != std::string::npos) {
            const std::string line = c.buffer.substr(0, pos);
            c.buffer.erase(0, pos + 1);
            int done = 0, total = 0;
            if (std::sscanf(line.c_str(), "progress %d %d", &done, &total) == 2) {
              report(jobs[c.task], RunnerEvent::Kind::kRunProgress, done, total, 0, "");
            }
          }
        }
      }
      if (!closed) {
        ++i;
        continue;
      }
      close(c.out_fd);
      int status = 0;
      while (waitpid(c.pid, &status, 0) < 0 && errno == EINTR) {
      }
      const double seconds =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - c.start).count();
      Job& job = jobs[c.task];
      std::string error;
      if (WIFEXITED(status) && WEXITSTATUS(status) == 0) {
        try {
          error = job.finish(seconds);
        } catch (const std::exception& e) {
          error = e.what();
        }
      } else {
        const std::string how = WIFSIGNALED(status)
                                    ? "killed by signal " + std::to_string(WTERMSIG(status))
                                    : "exit status " + std::to_string(WEXITSTATUS(status));
        error = how + ": " + LogTail(job.log_path);
      }
      if (error.empty()) {
        report(job, RunnerEvent::Kind::kRunFinished, 0, 0, seconds, "");
      } else {
        job.fail(error);
        report(job, RunnerEvent::Kind::kRunFailed, 0, 0, seconds, error);
      }
      running.erase(running.begin() + static_cast<std::ptrdiff_t>(i));
      fds.erase(fds.begin() + static_cast<std::ptrdiff_t>(i));
    }
  }
}

}  // namespace runner_internal
}  // namespace artex
