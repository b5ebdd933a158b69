// An output folder that is complete or absent, never partial (docs/reliability.md): a command
// writes into a temporary sibling ".<name>.partial-<pid>", and Commit() moves an earlier result
// at `path` aside (".<name>.old-<pid>"), renames the temporary to `path`, removes the earlier
// result and marks the folder with kOutputMarker. Killed at any point, `path` holds the earlier
// complete result, the new complete one, or (between the two renames) nothing: never a mix of
// old and new files and never a folder that looks complete when it is not. Leftovers of killed
// runs (siblings of those two patterns whose process is gone) are removed by the next
// AtomicOutputFolder for the same path.
#pragma once

#include <string>

namespace artex {

// Marks a committed artex output folder (its content: the command that wrote it).
constexpr char kOutputMarker[] = ".artex-output";

class AtomicOutputFolder {
 public:
  // Creates the temporary folder. Throws artex::Error when `path` exists and is not a folder,
  // or is a non-empty folder without kOutputMarker (files artex did not write are never
  // replaced), or when the temporary cannot be created. `command` names the writer ("track").
  AtomicOutputFolder(const std::string& path, const std::string& command);
  ~AtomicOutputFolder();  // removes the temporary unless committed
  AtomicOutputFolder(const AtomicOutputFolder&) = delete;
  AtomicOutputFolder& operator=(const AtomicOutputFolder&) = delete;

  const std::string& path() const { return temp_; }  // write the outputs here
  const std::string& final_path() const { return final_; }
  // Publishes the temporary as `final_path()`. Throws artex::Error on a failed rename.
  void Commit();

 private:
  std::string final_, temp_, old_, command_;
  bool committed_ = false;
};

// True when `path` is a folder committed by AtomicOutputFolder.
bool IsCompleteOutputFolder(const std::string& path);

}  // namespace artex
