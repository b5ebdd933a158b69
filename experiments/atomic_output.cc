#include "experiments/atomic_output.h"

#include <signal.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <filesystem>
#include <system_error>

#include "models/error.h"
#include "models/mesh_export.h"

namespace artex {
namespace {

namespace fs = std::filesystem;

// True for ".<name>.partial-<pid>" / ".<name>.old-<pid>" of a process that no longer runs.
bool IsStaleSibling(const std::string& entry, const std::string& name) {
  for (const std::string kind : {".partial-", ".old-"}) {
    const std::string prefix = "." + name + kind;
    if (entry.size() <= prefix.size() || entry.compare(0, prefix.size(), prefix) != 0) continue;
    const std::string digits = entry.substr(prefix.size());
    if (digits.find_first_not_of("0123456789") != std::string::npos || digits.size() > 9) {
      return false;
    }
    const pid_t pid = static_cast<pid_t>(std::atol(digits.c_str()));
    if (pid == ::getpid()) return true;
    return ::kill(pid, 0) != 0 && errno == ESRCH;
  }
  return false;
}

}  // namespace

bool IsCompleteOutputFolder(const std::string& path) {
  std::error_code ec;
  return fs::is_regular_file(fs::path(path) / kOutputMarker, ec);
}

AtomicOutputFolder::AtomicOutputFolder(const std::string& path, const std::string& command)
    : command_(command) {
  if (path.empty()) throw Error("output folder: expected a path, found an empty one");
  fs::path target = fs::absolute(fs::path(path)).lexically_normal();
  if (!target.has_filename()) target = target.parent_path();  // "out/" -> "out"
  final_ = target.string();
  const std::string name = target.filename().string();
  if (name.empty() || name == "." || name == "..") {
    throw Error(path + ": expected an output folder name, found '" + name + "'");
  }
  std::error_code ec;
  const fs::file_status status = fs::status(target, ec);
  if (fs::exists(status)) {
    if (!fs::is_directory(status)) {
      throw Error(path + ": expected an output folder, found a file of that name");
    }
    if (!fs::is_empty(target, ec) && !IsCompleteOutputFolder(final_)) {
      throw Error(path + ": exists and is not an artex output folder (no " +
                  std::string(kOutputMarker) +
                  "): not replaced; remove it or choose another output folder");
    }
  }
  const fs::path parent = target.parent_path();
  fs::create_directories(parent, ec);
  if (ec) throw Error(parent.string() + ": cannot create the folder: " + ec.message());
  for (const fs::directory_entry& e : fs::directory_iterator(parent, ec)) {
    if (IsStaleSibling(e.path().filename().string(), name)) {
      std::error_code ignored;
      fs::remove_all(e.path(), ignored);
    }
  }
  const std::string pid = std::to_string(::getpid());
  temp_ = (parent / ("." + name + ".partial-" + pid)).string();
  old_ = (parent / ("." + name + ".old-" + pid)).string();
  fs::remove_all(temp_, ec);
  fs::create_directory(temp_, ec);
  if (ec) throw Error(temp_ + ": cannot create the temporary output folder: " + ec.message());
}

AtomicOutputFolder::~AtomicOutputFolder() {
  if (committed_) return;
  std::error_code ec;
  fs::remove_all(temp_, ec);
}

void AtomicOutputFolder::Commit() {
  if (committed_) throw Error(final_ + ": output folder committed twice");
  WriteFileAtomically((fs::path(temp_) / kOutputMarker).string(), command_ + "\n");
  std::error_code ec;
  const bool had_old = fs::exists(final_, ec);
  if (had_old) {
    fs::rename(final_, old_, ec);
    if (ec) throw Error(final_ + ": cannot move the earlier output aside: " + ec.message());
  }
  fs::rename(temp_, final_, ec);
  if (ec) throw Error(final_ + ": cannot publish the output folder: " + ec.message());
  committed_ = true;
  if (had_old) fs::remove_all(old_, ec);
}

}  // namespace artex
