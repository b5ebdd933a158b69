// The progress display of `artex experiment` (experiments/experiment_command.cc): runner events
// (experiments/runner.h) become one rewritten status line on a terminal, or one line per event
// otherwise. The status line counts only runs that are running; synthetic sequences being
// generated are listed apart and leave the line when they are ready.
#pragma once

#include <cstdio>
#include <map>
#include <string>

#include "experiments/runner.h"

namespace artex {

class ExperimentProgressDisplay {
 public:
  // Writes to `out` (not owned); tty: rewrite one status line in place.
  ExperimentProgressDisplay(FILE* out, bool tty) : out_(out), tty_(tty) {}

  void Handle(const RunnerEvent& e);

  // "[done/total done, N running]  label progress ...  generating seq progress ..." (the line
  // shown on a terminal after the last event).
  std::string StatusLine() const;
  int running() const { return static_cast<int>(active_.size()); }
  int generating() const { return static_cast<int>(generating_.size()); }

 private:
  void Line(const std::string& text);
  void Status();

  FILE* out_;
  bool tty_;
  bool status_shown_ = false;
  int runs_done_ = 0, runs_total_ = 0;
  int runs_pending_ = -1, runs_failed_ = 0;  // batch backends (Slurm); -1: not reported
  std::map<std::string, std::string> active_;      // running runs -> progress
  std::map<std::string, std::string> generating_;  // sequences being generated -> progress
};

}  // namespace artex
