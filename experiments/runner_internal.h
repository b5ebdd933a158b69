// Private to the experiment runner's files (experiments/runner*.cc): helpers they share, the
// synthetic sequence specs (runner_synth.cc) and the child-process scheduler
// (runner_schedule.cc). Not part of the runner's API (experiments/runner.h).
#pragma once

#include <cmath>
#include <cstdint>
#include <functional>
#include <iomanip>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

#include "experiments/config.h"
#include "experiments/runner.h"
#include "sensors/virtual_kinect.h"

namespace artex {
namespace runner_internal {

// The last `digits` (<= 16) hexadecimal digits of v.
inline std::string Hex(uint64_t v, int digits) {
  std::ostringstream s;
  s << std::hex << std::setw(16) << std::setfill('0') << v;
  return s.str().substr(16 - digits);
}

inline std::string FormatNumber(double v) {
  if (std::isnan(v)) return "nan";
  std::ostringstream s;
  s << std::setprecision(10) << v;
  return s.str();
}

inline double Mean(const std::vector<double>& v) {
  if (v.empty()) return std::numeric_limits<double>::quiet_NaN();
  double s = 0;
  for (double x : v) s += x;
  return s / v.size();
}

inline std::string CombinationLabel(const ExperimentCombination& c) {
  if (c.overrides.empty()) return "base";
  std::string s;
  for (const auto& o : c.overrides) s += (s.empty() ? "" : ", ") + o.key + "=" + o.value;
  return s;
}

// ---- synthetic sequence specs (runner_synth.cc) ----------------------------------------------

struct SynthSpec {
  SynthOptions options;
  double outlier_fraction = 0.0;  // per valid depth pixel
  double outlier_range_m = 0.3;   // outliers are displaced uniformly in [-range, range] (m)
};

// The spec of a `synth:` mapping (keys: SynthSpecKeys()); throws artex::Error naming the key.
SynthSpec SynthSpecFromConfig(const Config& c);

// ---- child processes (runner_schedule.cc) ------------------------------------------------------

// This binary (for the child processes).
std::string SelfExecutable();

// A generic job for the scheduler: a child command, a temporary folder, and what to do on
// success (returns an error message or "").
struct Job {
  std::string label;
  std::vector<std::string> args;
  std::string tmp_dir;
  std::string log_path;
  std::function<std::string(double seconds)> finish;
  std::function<void(const std::string& message)> fail;
};

// Runs jobs `parallel` at a time; reports progress lines "progress D T" from the children.
void Schedule(std::vector<Job>& jobs, int parallel,
              const std::function<void(const Job&, RunnerEvent::Kind, int, int, double,
                                       const std::string&)>& report);

}  // namespace runner_internal
}  // namespace artex
