#include "experiments/progress_display.h"

namespace artex {
namespace {

std::string Seconds(double s) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.1f s", s);
  return buf;
}

}  // namespace

void ExperimentProgressDisplay::Handle(const RunnerEvent& e) {
  using K = RunnerEvent::Kind;
  switch (e.kind) {
    case K::kPlan:
      runs_total_ = e.runs_total;
      Line("experiment: " + std::to_string(e.runs_total) + " runs, " +
           std::to_string(e.runs_skipped) + " already complete (skipped), " +
           std::to_string(e.total) + " to run");
      break;
    case K::kSequenceStarted:
      generating_[e.label] = "start";
      Line("experiment: generating sequence " + e.label);
      break;
    case K::kSequenceProgress:
      generating_[e.label] = std::to_string(e.done) + "/" + std::to_string(e.total);
      if (tty_) Status();
      break;
    case K::kSequenceReady:
      generating_.erase(e.label);
      Line("experiment: sequence " + e.label + " ready" +
           (e.seconds > 0 ? " (" + Seconds(e.seconds) + ")" : " (reused)"));
      break;
    case K::kRunStarted:
      active_[e.label] = "start";
      runs_done_ = e.runs_done;
      runs_total_ = e.runs_total;
      if (tty_) {
        Status();
      } else {
        std::fprintf(out_, "experiment: start %s\n", e.label.c_str());
      }
      break;
    case K::kRunProgress:
      active_[e.label] = std::to_string(e.done) + "/" + std::to_string(e.total);
      runs_done_ = e.runs_done;
      runs_total_ = e.runs_total;
      if (tty_) Status();
      break;
    case K::kRunSkipped:
      if (!tty_) Line("experiment: skip " + e.label + " (complete)");
      break;
    case K::kRunFinished:
      active_.erase(e.label);
      runs_done_ = e.runs_done;
      runs_total_ = e.runs_total;
      Line("experiment: [" + std::to_string(e.runs_done) + "/" + std::to_string(e.runs_total) +
           "] done " + e.label + " in " + Seconds(e.seconds));
      break;
    case K::kRunFailed:
      active_.erase(e.label);
      Line("experiment: FAILED " + e.label + ": " + e.message);
      break;
    case K::kNote:
      Line("experiment: " + e.message);
      break;
  }
  if (e.runs_pending >= 0) {
    runs_pending_ = e.runs_pending;
    runs_failed_ = e.runs_failed;
  }
}

std::string ExperimentProgressDisplay::StatusLine() const {
  std::string s = "[" + std::to_string(runs_done_) + "/" + std::to_string(runs_total_) + " done, " +
                  std::to_string(active_.size()) + " running";
  if (runs_pending_ >= 0) {
    s += ", " + std::to_string(runs_pending_) + " pending, " + std::to_string(runs_failed_) +
         " failed";
  }
  s += "]";
  for (const auto& kv : active_) s += "  " + kv.first + " " + kv.second;
  for (const auto& kv : generating_) s += "  generating " + kv.first + " " + kv.second;
  if (s.size() > 160) s = s.substr(0, 157) + "...";
  return s;
}

void ExperimentProgressDisplay::Line(const std::string& text) {
  if (tty_ && status_shown_) std::fprintf(out_, "\r\033[K");
  std::fprintf(out_, "%s\n", text.c_str());
  status_shown_ = false;
  std::fflush(out_);
}

void ExperimentProgressDisplay::Status() {
  std::fprintf(out_, "\r\033[K%s", StatusLine().c_str());
  status_shown_ = true;
  std::fflush(out_);
}

}  // namespace artex
