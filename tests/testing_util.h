// Test helpers shared across the test folders (namespace testing_util): fresh temporary
// folders, file bytes, running the artex binary, and the coarse generated template. Topic fixtures build on these:
// tests/solvers/fitting_test_util.h (stick templates, random poses, sampled scans) and
// tests/solvers/virtual_kinect_scans.h (synthesised sequences and scans).
#pragma once

#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <sstream>
#include <string>
#include <system_error>
#include <vector>

#include "models/template.h"
#include "models/template_generator.h"

namespace artex {
namespace testing_util {

// The folders FreshTempDir made, removed when the process (a test suite or a benchmark) ends
// normally. They are kept when it crashed, and when ARTEX_KEEP_TEST_DIRS is set (for a look at
// what a failing test left). Only the process that made them removes them (a forked child
// that exits normally would otherwise remove its parent's folders).
class TempDirCleanup {
 public:
  ~TempDirCleanup() {
    if (::getpid() != owner_ || std::getenv("ARTEX_KEEP_TEST_DIRS") != nullptr) return;
    std::error_code ignored;
    for (const auto& dir : dirs_) std::filesystem::remove_all(dir, ignored);
  }

  void Add(const std::filesystem::path& dir) {
    const std::lock_guard<std::mutex> lock(mutex_);
    dirs_.push_back(dir);
  }

 private:
  pid_t owner_ = ::getpid();
  std::mutex mutex_;
  std::vector<std::filesystem::path> dirs_;
};

inline TempDirCleanup& TempDirs() {
  static TempDirCleanup cleanup;
  return cleanup;
}

// The empty folder artex_<name>_<pid> in the system's temporary directory (removed first when
// a previous run left it; removed again when the test process ends, see TempDirCleanup).
inline std::filesystem::path FreshTempDir(const std::string& name) {
  namespace fs = std::filesystem;
  const fs::path dir =
      fs::temp_directory_path() / ("artex_" + name + "_" + std::to_string(::getpid()));
  TempDirs().Add(dir);
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

// The bytes of a file ("" when it cannot be opened).
inline std::string ReadFileBytes(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

// What a command printed and how it ended.
struct CommandResult {
  int status = -1;  // exit status; -1 when it did not exit normally
  std::string out;  // stdout
  std::string err;  // stderr
};

#ifdef ARTEX_BINARY
// Runs the built artex binary (ARTEX_BINARY, set by tests/CMakeLists.txt) with `args` (shell
// words, quoted by the caller); stdout and stderr pass through numbered files in `dir`.
inline CommandResult RunArtex(const std::string& args, const std::filesystem::path& dir) {
  static int counter = 0;
  const std::string out = (dir / ("stdout" + std::to_string(counter))).string();
  const std::string err = (dir / ("stderr" + std::to_string(counter++))).string();
  const std::string command =
      "'" + std::string(ARTEX_BINARY) + "' " + args + " > '" + out + "' 2> '" + err + "'";
  const int raw = std::system(command.c_str());
  CommandResult r;
  r.status = WIFEXITED(raw) ? WEXITSTATUS(raw) : -1;
  r.out = ReadFileBytes(out);
  r.err = ReadFileBytes(err);
  return r;
}
#endif

// The generated template at its coarsest resolution (BodyShapeOptions::resolution 0), made once
// per process.
inline const Template& CoarseTemplate() {
  static const Template t = [] {
    BodyShapeOptions o;
    o.resolution = 0;
    return GenerateTemplate(o);
  }();
  return t;
}

}  // namespace testing_util
}  // namespace artex
