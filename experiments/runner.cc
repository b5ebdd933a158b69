#include "experiments/runner.h"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/file.h>
#include <sys/prctl.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <tbb/global_control.h>
#include <unistd.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <limits>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <random>
#include <set>
#include <sstream>
#include <thread>

#include "experiments/file_util.h"
#include "experiments/pipeline.h"
#include "models/error.h"
#include "models/template_generator.h"
#include "models/template_io.h"
#include "sensors/frame_source.h"
#include "sensors/sequence.h"
#include "sensors/synth_conditions.h"
#include "sensors/virtual_kinect.h"
#include "sensors/yaml_checks.h"

namespace artex {
namespace fs = std::filesystem;

namespace {

constexpr const char* kDoneMarker = "DONE";
constexpr const char* kRunKeyFile = "run_key.txt";
constexpr const char* kTmpPrefix = ".tmp-";
constexpr const char* kFailedPrefix = ".failed-";
constexpr int kLogTailLines = 6;        // lines of a failed child's log quoted in the report
constexpr int kPollMilliseconds = 200;  // progress refresh of the parent's event loop
constexpr int kDefaultDepthWidth = 640;
constexpr int kDefaultDepthHeight = 480;

std::string Emit(const YAML::Node& node) {
  YAML::Emitter out;
  out.SetMapFormat(YAML::Flow);
  out.SetSeqFormat(YAML::Flow);
  out << node;
  return out.c_str();
}

std::string EmitBlock(const YAML::Node& node) {
  YAML::Emitter out;
  out << node;
  return out.c_str();
}

// Folder-name-safe text: [A-Za-z0-9._=,+-], everything else '_'.
std::string Sanitize(const std::string& s) {
  std::string out;
  for (char c : s) {
    const bool ok = std::isalnum(static_cast<unsigned char>(c)) || c == '.' || c == '_' ||
                    c == '=' || c == ',' || c == '+' || c == '-';
    out += ok ? c : '_';
  }
  return out;
}

uint64_t Fnv1a(const std::string& s) {
  uint64_t h = 1469598103934665603ull;
  for (unsigned char c : s) {
    h ^= c;
    h *= 1099511628211ull;
  }
  return h;
}

// The last `digits` (<= 16) hexadecimal digits of v.
std::string Hex(uint64_t v, int digits) {
  std::ostringstream s;
  s << std::hex << std::setw(16) << std::setfill('0') << v;
  return s.str().substr(16 - digits);
}

std::string CsvField(const std::string& s) {
  if (s.find_first_of(",\"\n") == std::string::npos) return s;
  std::string out = "\"";
  for (char c : s) {
    if (c == '"') out += '"';
    out += c;
  }
  return out + "\"";
}

std::string FormatNumber(double v) {
  if (std::isnan(v)) return "nan";
  std::ostringstream s;
  s << std::setprecision(10) << v;
  return s.str();
}

// ---- synthetic sequence specs ---------------------------------------------------------------

struct SynthSpec {
  SynthOptions options;
  double outlier_fraction = 0.0;  // per valid depth pixel
  double outlier_range_m = 0.3;   // outliers are displaced uniformly in [-range, range] (m)
};

SynthSpec SynthSpecFromConfig(const Config& c) {
  c.CheckKeys(SynthSpecKeys());
  SynthSpec spec;
  SynthOptions& o = spec.options;
  if (c.Has("motion")) {
    std::string motion;
    c.Get("motion", &motion);
    try {
      o.motion.type = ParseMotionType(motion);
    } catch (const Error& e) {
      throw Error(c.Path("motion") + ": " + e.what());
    }
  }
  c.Get("bvh", &o.bvh_path);
  c.Get("frames", &o.motion.frames);
  int seed = 1;
  c.Get("seed", &seed);
  if (seed < 0) throw Error(c.Path("seed") + ": expected >= 0, found " + std::to_string(seed));
  o.kinect.seed = static_cast<uint64_t>(seed);
  o.texture.seed = static_cast<uint64_t>(seed);
  if (c.Has("noise")) {
    std::string noise;
    c.Get("noise", &noise);
    try {
      o.kinect.SetNoiseLevel(ParseNoiseLevel(noise));
    } catch (const Error& e) {
      throw Error(c.Path("noise") + ": " + e.what());
    }
  }
  c.Get("frame_rate", &o.motion.frame_rate);
  o.kinect.frame_rate = o.motion.frame_rate;
  c.Get("amplitude", &o.motion.amplitude);
  c.Get("period_s", &o.motion.period_s);
  c.Get("ramp_s", &o.motion.ramp_s);
  c.Get("speed", &o.motion.speed);
  c.Get("frame_step", &o.motion.frame_step);
  c.Get("background_frames", &o.background_frames);
  c.Get("color_width", &o.kinect.color_width);
  c.Get("color_height", &o.kinect.color_height);
  c.Get("texture_size", &o.texture.size);
  c.Get("subject_resolution", &o.subject_shape.resolution);
  c.Get("subject_height", &o.subject_shape.height);
  c.Get("subject_girth", &o.subject_shape.girth);
  c.Get("yaw_deg", &o.subject_yaw_deg);
  int depth_width = kDefaultDepthWidth, depth_height = kDefaultDepthHeight;
  c.Get("depth_width", &depth_width);
  c.Get("depth_height", &depth_height);
  if (depth_width < 16 || depth_height < 16) {
    throw Error(c.Path("depth_width") + ": expected a depth image of at least 16 x 16, found " +
                std::to_string(depth_width) + " x " + std::to_string(depth_height));
  }
  PinholeCamera& d = o.kinect.depth_intrinsics;
  const double sx = static_cast<double>(depth_width) / d.width;
  const double sy = static_cast<double>(depth_height) / d.height;
  d.fx *= sx;
  d.fy *= sy;
  d.cx = (d.cx + 0.5) * sx - 0.5;
  d.cy = (d.cy + 0.5) * sy - 0.5;
  d.width = depth_width;
  d.height = depth_height;
  c.Get("disparity_noise_px", &o.kinect.depth_noise.disparity_noise_px);
  c.Get("random_dropout", &o.kinect.depth_noise.random_dropout);
  c.Get("color_noise", &o.kinect.color_model.noise_std);
  c.Get("outlier_fraction", &spec.outlier_fraction);
  c.Get("outlier_range_m", &spec.outlier_range_m);
  // Recording conditions (docs/synthesis.md "Conditions"): presets first, then explicit keys.
  if (c.Has("condition")) {
    std::string list;
    c.Get("condition", &list);
    std::stringstream names(list);
    std::string name;
    while (std::getline(names, name, ',')) {
      name.erase(0, name.find_first_not_of(" \t"));
      name.erase(name.find_last_not_of(" \t") + 1);
      try {
        ApplySynthCondition(ParseSynthCondition(name), &o);
      } catch (const Error& e) {
        throw Error(c.Path("condition") + ": " + e.what());
      }
    }
    c.Get("background_frames", &o.background_frames);
    c.Get("yaw_deg", &o.subject_yaw_deg);
  }
  c.Get("camera_pitch_deg", &o.kinect.depth_pitch_deg);
  c.Get("camera_roll_deg", &o.kinect.depth_roll_deg);
  if (c.Has("world_frame")) {
    std::string frame;
    c.Get("world_frame", &frame);
    try {
      o.world_frame = ParseWorldFrame(frame);
    } catch (const Error& e) {
      throw Error(c.Path("world_frame") + ": " + e.what());
    }
  }
  c.Get("boxes", &o.random_boxes);
  c.Get("second_person", &o.second_person.enabled);
  if (c.Has("second_person")) {
    o.second_person.shape.resolution = o.subject_shape.resolution;
    o.second_person.texture.size = o.texture.size;
    o.second_person.texture.seed = o.texture.seed + 1;
  }
  o.write_subject_glb = true;
  if (!(spec.outlier_fraction >= 0 && spec.outlier_fraction <= 1)) {
    throw Error(c.Path("outlier_fraction") + ": expected a fraction in [0, 1], found " +
                FormatNumber(spec.outlier_fraction));
  }
  if (!(spec.outlier_range_m > 0)) {
    throw Error(c.Path("outlier_range_m") + ": expected > 0, found " +
                FormatNumber(spec.outlier_range_m));
  }
  std::string why;
  if (!o.IsValid(&why)) throw Error(c.Path("") + " invalid synthesis options: " + why);
  return spec;
}

// Replaces a fraction of the valid depth pixels by outliers displaced along the ray
// (deterministic per seed and frame).
void AddDepthOutliers(const SynthSpec& spec, const std::string& folder) {
  if (spec.outlier_fraction <= 0) return;
  std::vector<fs::path> files;
  for (const auto& entry : fs::directory_iterator(fs::path(folder) / "depth")) {
    if (entry.path().extension() == ".png") files.push_back(entry.path());
  }
  std::sort(files.begin(), files.end());
  const double scale = spec.options.kinect.depth_scale;
  for (std::size_t i = 0; i < files.size(); ++i) {
    cv::Mat depth = cv::imread(files[i].string(), cv::IMREAD_UNCHANGED);
    if (depth.empty() || depth.type() != CV_16UC1) {
      throw Error(files[i].string() + ": expected a 16-bit depth PNG");
    }
    std::mt19937_64 rng(spec.options.kinect.seed * 1000003ull + i);
    std::uniform_real_distribution<double> u01(0.0, 1.0);
    std::uniform_real_distribution<double> shift(-spec.outlier_range_m, spec.outlier_range_m);
    for (int y = 0; y < depth.rows; ++y) {
      for (int x = 0; x < depth.cols; ++x) {
        uint16_t& d = depth.at<uint16_t>(y, x);
        if (d == 0 || u01(rng) >= spec.outlier_fraction) continue;
        const double z = d / scale + shift(rng);
        d = static_cast<uint16_t>(std::clamp(std::lround(std::max(z, 0.05) * scale), 1l, 65535l));
      }
    }
    WriteImageAtomic(files[i].string(), depth);
  }
}

std::string DefaultSequenceName(const YAML::Node& synth) {
  std::string name = synth["motion"] ? synth["motion"].as<std::string>() : "walk";
  if (synth["bvh"]) name = fs::path(synth["bvh"].as<std::string>()).stem().string();
  if (synth["frames"]) name += "_f" + synth["frames"].as<std::string>();
  if (synth["seed"]) name += "_s" + synth["seed"].as<std::string>();
  if (synth["noise"]) name += "_" + synth["noise"].as<std::string>();
  if (synth["condition"]) name += "_" + synth["condition"].as<std::string>();
  if (synth["speed"]) name += "_x" + synth["speed"].as<std::string>();
  if (synth["frame_step"]) name += "_step" + synth["frame_step"].as<std::string>();
  return Sanitize(name);
}

// ---- experiment parsing --------------------------------------------------------------------

std::string ScalarText(const YAML::Node& n) { return n.IsScalar() ? n.Scalar() : Emit(n); }

std::string CombinationId(const std::vector<Override>& overrides) {
  if (overrides.empty()) return "base";
  std::string id;
  for (const auto& o : overrides) {
    if (!id.empty()) id += ",";
    id += o.key + "=" + o.value;
  }
  id = Sanitize(id);
  constexpr std::size_t kMaxIdLength = 120;
  if (id.size() > kMaxIdLength) id = id.substr(0, kMaxIdLength - 17) + "-" + Hex(Fnv1a(id), 16);
  return id;
}

void CheckTopKeys(const YAML::Node& root, const std::string& source) {
  static const std::vector<std::string> kValid = {"name", "description", "base", "template",
                                                  "sequences", "grid", "list"};
  for (const auto& kv : root) {
    const std::string key = kv.first.as<std::string>();
    if (std::find(kValid.begin(), kValid.end(), key) == kValid.end()) {
      std::string msg = source + ": unknown key '" + key + "'; valid keys:";
      for (const auto& v : kValid) msg += " " + v;
      throw Error(msg);
    }
  }
}

std::string ResolvePath(const std::string& path, const std::string& base_dir) {
  if (path.empty() || fs::path(path).is_absolute() || base_dir.empty()) return path;
  return (fs::path(base_dir) / path).lexically_normal().string();
}

// ---- process plumbing ------------------------------------------------------------------------

std::string SelfExecutable() {
  std::error_code ec;
  const fs::path p = fs::read_symlink("/proc/self/exe", ec);
  return ec ? std::string("/proc/self/exe") : p.string();
}

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

// ---- results ---------------------------------------------------------------------------------

struct RunResult {
  const ExperimentSequence* sequence = nullptr;
  const ExperimentCombination* combination = nullptr;
  std::map<std::string, double> metrics;
};

double Mean(const std::vector<double>& v) {
  if (v.empty()) return std::numeric_limits<double>::quiet_NaN();
  double s = 0;
  for (double x : v) s += x;
  return s / v.size();
}

std::string CombinationLabel(const ExperimentCombination& c) {
  if (c.overrides.empty()) return "base";
  std::string s;
  for (const auto& o : c.overrides) s += (s.empty() ? "" : ", ") + o.key + "=" + o.value;
  return s;
}

}  // namespace

// ---- public API --------------------------------------------------------------------------------

std::vector<std::string> SynthSpecKeys() {
  return {"motion", "bvh", "frames", "seed", "noise", "frame_rate", "amplitude", "period_s", "ramp_s",
          "speed", "frame_step",
          "background_frames", "color_width", "color_height", "texture_size",
          "subject_resolution", "subject_height", "subject_girth", "yaw_deg", "depth_width",
          "depth_height", "disparity_noise_px", "random_dropout", "color_noise",
          "outlier_fraction", "outlier_range_m", "condition", "camera_pitch_deg",
          "camera_roll_deg", "world_frame", "boxes", "second_person"};
}

const std::vector<MetricInfo>& Metrics() {
  static const std::vector<MetricInfo> kMetrics = {
      {"mean_vertex_error_mm", true, false, "mean over evaluated frames (fitted, not failed) of the mean per-vertex distance to ground truth"},
      {"max_vertex_error_mm", true, false, "largest per-vertex distance to ground truth over all frames"},
      {"mean_joint_error_mm", true, false, "mean over evaluated frames of the mean joint-centre distance to ground truth"},
      {"final_vertex_error_mm", true, false, "mean per-vertex error of the last evaluated frame (drift)"},
      {"lost_frames", true, false, "failed fits and frames whose mean vertex error exceeds pipeline.lost_threshold_mm"},
      {"lost_fraction", true, false, "lost_frames / fitted frames (failed fits included)"},
      {"evaluated_frames", false, false, "frames the ground-truth errors average over (fitted, not failed)"},
      {"failed_frames", true, false, "frames flagged too few points, non-finite or diverged"},
      {"skipped_frames", true, false, "unreadable input frames"},
      {"mean_em_iterations", true, false, "EM iterations per frame (mean)"},
      {"converged_fraction", false, false, "fraction of frames whose EM converged before its iteration cap"},
      {"seam_rms_before", true, false, "RMS colour jump at texture seams before levelling (mean over frames; colours in [0, 1])"},
      {"seam_rms_after", true, false, "RMS colour jump at texture seams after levelling (mean over frames)"},
      {"seam_edges", true, false, "interior edges whose triangles use different source images (last frame)"},
      {"changed_triangles", true, false, "triangles whose source image changed, per frame (mean; temporal stability)"},
      {"textured_triangles", false, false, "triangles with a source image (last frame)"},
      {"mrf_energy", true, false, "view-selection energy E(L) of the last frame (comparable only at equal lambda/alpha/beta)"},
      {"mrf_iterations", true, false, "view-selection (MRF) solver iterations per frame (mean; warm-started)"},
      {"pool_size", true, false, "images in the pool (mean over frames)"},
      {"stream_kbit_per_s", true, false, "compressed pose + texture update stream at the frame rate"},
      {"novel_view_psnr_db", false, false, "ground truth: PSNR (dB) of the textured model against the true render from held-out views (last evaluated frame)"},
      {"novel_view_ssim", false, false, "ground truth: SSIM of the same renders (last evaluated frame)"},
      {"texture_coverage", false, false, "ground truth: fraction of the true visible surface the model textures (held-out views)"},
      {"mean_novel_view_psnr_db", false, false, "novel-view PSNR averaged over the evaluated frames"},
      {"preprocess_ms", true, true, "preprocessing per frame (ms)"},
      {"estep_ms", true, true, "E-step per frame (ms)"},
      {"mstep_ms", true, true, "M-step per frame (ms)"},
      {"fit_ms", true, true, "whole fit per frame incl. ICP (ms)"},
      {"texture_ms", true, true, "texturing per frame (ms)"},
      {"texture_mrf_ms", true, true, "view selection (MRF) per frame (ms)"},
      {"texture_levelling_ms", true, true, "seam levelling per frame (ms)"},
      {"frame_ms", true, true, "preprocess + fit + texture per frame (ms)"},
  };
  return kMetrics;
}

const MetricInfo* FindMetric(const std::string& name) {
  for (const auto& m : Metrics()) {
    if (name == m.name) return &m;
  }
  return nullptr;
}

namespace {
Experiment ParseExperimentYaml(const std::string& yaml, const std::string& source_name,
                               const std::string& base_dir);
}  // namespace

Experiment ParseExperiment(const std::string& yaml, const std::string& source_name,
                           const std::string& base_dir) {
  try {
    return ParseExperimentYaml(yaml, source_name, base_dir);
  } catch (const YAML::Exception& e) {
    // A value of the wrong shape (a list or mapping where text is expected): yaml-cpp's own
    // message carries the line and column (found by the experiment fuzzer, issue 20).
    throw Error(source_name + ": " + e.what() + " (expected a plain value there)");
  }
}

namespace {
Experiment ParseExperimentYaml(const std::string& yaml, const std::string& source_name,
                               const std::string& base_dir) {
  YAML::Node root;
  try {
    root = YAML::Load(yaml);
  } catch (const YAML::Exception& e) {
    throw Error(source_name + ": not valid YAML: " + e.what());
  }
  if (!root.IsMap()) throw Error(source_name + ": expected a mapping at the top level");
  CheckYamlKeys(root, source_name);
  CheckTopKeys(root, source_name);
  Experiment ex;
  ex.file = source_name;
  ex.base_source = source_name + " (base)";
  ex.name = root["name"] ? root["name"].as<std::string>() : fs::path(source_name).stem().string();

  // Base configuration: a path (relative to the experiment file) or an inline mapping.
  if (const YAML::Node base = root["base"]) {
    if (base.IsScalar()) {
      ex.base_source = ResolvePath(base.Scalar(), base_dir);
      ex.base = Config::Load(ex.base_source);  // reports a missing file or bad YAML
      ex.base_yaml = ReadText(ex.base_source);
    } else if (base.IsMap()) {
      ex.base_source = source_name + " (base)";
      ex.base_yaml = EmitBlock(base);
      ex.base = Config::FromString(ex.base_yaml, ex.base_source);
    } else {
      throw Error(source_name + ": base: expected a configuration file path or a mapping");
    }
  }

  // Tracking template: a .glb path, or a mapping of generator options (BodyShapeOptions).
  if (const YAML::Node t = root["template"]) {
    if (t.IsScalar()) {
      ex.template_path = ResolvePath(t.Scalar(), base_dir);
      if (std::error_code ec; !fs::exists(ex.template_path, ec)) {
        throw Error(source_name + ": template: file not found: " + ex.template_path);
      }
    } else if (t.IsMap()) {
      ex.template_yaml = Emit(t);
    } else {
      throw Error(source_name + ": template: expected a .glb path or a mapping of generator options");
    }
  } else {
    ex.template_yaml = "{}";
  }
  if (!ex.template_yaml.empty()) {
    const Config c = Config::FromString(ex.template_yaml, source_name + ": template");
    c.CheckKeys({"resolution", "height", "girth", "shoulder_width", "hip_width", "arm_length",
                 "leg_length", "atlas_size"});
  }

  // Sequences.
  const YAML::Node seqs = root["sequences"];
  if (!seqs || !seqs.IsSequence() || seqs.size() == 0) {
    throw Error(source_name + ": sequences: expected a non-empty list of sequences "
                "(folder paths or {synth: {...}} specs)");
  }
  std::set<std::string> names;
  for (std::size_t i = 0; i < seqs.size(); ++i) {
    const YAML::Node s = seqs[i];
    const std::string where = source_name + ": sequences[" + std::to_string(i) + "]";
    ExperimentSequence seq;
    if (s.IsScalar()) {
      seq.folder = ResolvePath(s.Scalar(), base_dir);
      seq.name = Sanitize(fs::path(seq.folder).filename().string());
    } else if (s.IsMap()) {
      for (const auto& kv : s) {
        const std::string k = kv.first.as<std::string>();
        if (k != "name" && k != "path" && k != "synth") {
          throw Error(where + ": unknown key '" + k + "'; valid keys: name path synth");
        }
      }
      if (s["path"] && s["synth"]) throw Error(where + ": give either path or synth, not both");
      if (s["path"]) {
        seq.folder = ResolvePath(s["path"].as<std::string>(), base_dir);
        seq.name = Sanitize(fs::path(seq.folder).filename().string());
      } else if (s["synth"]) {
        const YAML::Node synth = s["synth"];
        if (!synth.IsMap()) throw Error(where + ".synth: expected a mapping of synthesis options");
        YAML::Node spec = YAML::Clone(synth);
        if (spec["bvh"]) spec["bvh"] = ResolvePath(spec["bvh"].as<std::string>(), base_dir);
        seq.synthetic = true;
        seq.synth_yaml = Emit(spec);
        SynthSpecFromConfig(Config::FromString(seq.synth_yaml, where + ".synth"));
        seq.name = DefaultSequenceName(spec);
      } else {
        throw Error(where + ": expected path or synth");
      }
      if (s["name"]) {
        seq.name = s["name"].as<std::string>();
        if (seq.name.empty() || Sanitize(seq.name) != seq.name || seq.name[0] == '.') {
          throw Error(where + ".name: expected letters, digits, '.', '_', '-', found '" + seq.name + "'");
        }
      }
    } else {
      throw Error(where + ": expected a folder path or a mapping");
    }
    std::error_code exists_ec;  // e.g. a name too long: not found, no filesystem_error
    if (!seq.synthetic && !fs::exists(seq.folder, exists_ec)) {
      throw Error(where + ": sequence folder not found: " + seq.folder);
    }
    if (!seq.synthetic) {
      try {
        DetectFrameSource(seq.folder);  // an artex sequence or a TUM RGB-D folder
      } catch (const Error& e) {
        throw Error(where + ": " + e.what());
      }
    }
    if (!names.insert(seq.name).second) {
      throw Error(where + ": duplicate sequence name '" + seq.name + "' (set name: to distinguish)");
    }
    ex.sequences.push_back(seq);
  }

  // Overrides: list entries x grid product (the last grid key varies fastest).
  std::vector<std::vector<Override>> list_entries;
  if (const YAML::Node list = root["list"]) {
    if (!list.IsSequence()) throw Error(source_name + ": list: expected a list of {key: value} mappings");
    for (std::size_t i = 0; i < list.size(); ++i) {
      if (!list[i].IsMap()) {
        throw Error(source_name + ": list[" + std::to_string(i) + "]: expected a mapping of overrides");
      }
      std::vector<Override> entry;
      for (const auto& kv : list[i]) entry.push_back({kv.first.as<std::string>(), ScalarText(kv.second)});
      list_entries.push_back(entry);
    }
  }
  if (list_entries.empty()) list_entries.push_back({});
  std::vector<std::pair<std::string, std::vector<std::string>>> grid;
  if (const YAML::Node g = root["grid"]) {
    if (!g.IsMap()) throw Error(source_name + ": grid: expected a mapping of key: [values]");
    for (const auto& kv : g) {
      const std::string key = kv.first.as<std::string>();
      std::vector<std::string> values;
      if (kv.second.IsSequence()) {
        for (const auto& v : kv.second) values.push_back(ScalarText(v));
      } else {
        values.push_back(ScalarText(kv.second));
      }
      if (values.empty()) throw Error(source_name + ": grid." + key + ": expected at least one value");
      grid.push_back({key, values});
    }
  }
  for (const auto& entry : list_entries) {
    for (const auto& o : entry) {
      if (std::find(ex.keys.begin(), ex.keys.end(), o.key) == ex.keys.end()) ex.keys.push_back(o.key);
    }
  }
  for (const auto& g : grid) {
    if (std::find(ex.keys.begin(), ex.keys.end(), g.first) != ex.keys.end()) {
      throw Error(source_name + ": grid." + g.first + ": the key is also set by list entries");
    }
    ex.keys.push_back(g.first);
  }
  // Capped before expansion (overflow-safe): a million-combination grid hung --dry-run.
  std::size_t total = list_entries.size();
  for (const auto& g : grid) {
    if (total > kMaxExperimentCombinations / g.second.size()) {
      total = kMaxExperimentCombinations + 1;
      break;
    }
    total *= g.second.size();
  }
  if (total > kMaxExperimentCombinations) {
    std::string sizes = std::to_string(list_entries.size()) + " list entries";
    for (const auto& g : grid) sizes += " x " + std::to_string(g.second.size()) + " " + g.first;
    throw Error(source_name + ": expected at most " + std::to_string(kMaxExperimentCombinations) +
                " combinations, found " + sizes + " (split the experiment)");
  }
  std::set<std::string> ids;
  for (const auto& entry : list_entries) {
    std::vector<std::size_t> index(grid.size(), 0);
    while (true) {
      ExperimentCombination c;
      c.overrides = entry;
      for (std::size_t k = 0; k < grid.size(); ++k) c.overrides.push_back({grid[k].first, grid[k].second[index[k]]});
      c.id = CombinationId(c.overrides);
      if (!ids.insert(c.id).second) {
        throw Error(source_name + ": duplicate configuration " + CombinationLabel(c));
      }
      ex.combinations.push_back(c);
      int k = static_cast<int>(grid.size()) - 1;
      while (k >= 0 && ++index[k] == grid[k].second.size()) index[k--] = 0;
      if (k < 0) break;
    }
  }

  // Validate every combination's configuration up front.
  for (const auto& c : ex.combinations) {
    try {
      const Config config = CombinationConfig(ex, c);
      const PipelineOptions options = LoadPipelineOptions(config);
      std::string why;
      if (!options.IsValid(&why)) throw Error(why);
    } catch (const Error& e) {
      throw Error(source_name + ": configuration {" + CombinationLabel(c) + "}: " + e.what());
    }
  }
  return ex;
}

}  // namespace

Experiment LoadExperiment(const std::string& path) {
  if (std::error_code ec; !fs::is_regular_file(path, ec)) {
    throw Error(path + ": experiment file not found");
  }
  return ParseExperiment(ReadText(path), path, fs::path(path).parent_path().string());
}

Config CombinationConfig(const Experiment& experiment, const ExperimentCombination& combination) {
  Config c = Config::FromString(experiment.base_yaml, experiment.base_source);
  for (const auto& o : combination.overrides) c.Set(o.key, o.value);
  return c;
}

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

void GenerateSyntheticSequence(const std::string& synth_yaml, const std::string& source_name,
                               const std::string& out_dir,
                               const std::function<void(int, int)>& progress) {
  const SynthSpec spec = SynthSpecFromConfig(Config::FromString(synth_yaml, source_name));
  SynthesizeSequence(spec.options, out_dir, [&](const SynthProgress& p) {
    if (p.stage == SynthProgress::Stage::kFrames && progress) progress(p.done, p.total);
  });
  AddDepthOutliers(spec, out_dir);
  WriteFileAtomic((fs::path(out_dir) / "synth.yaml").string(), synth_yaml + "\n");
}

void RunSingle(const std::string& config_path, const std::string& sequence_dir,
               const std::string& template_path, const std::string& out_dir, int threads,
               const std::function<void(int, int)>& progress) {
  std::unique_ptr<tbb::global_control> limit;
  if (threads > 0) {
    limit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                  static_cast<std::size_t>(threads));
    cv::setNumThreads(threads);
  }
  // Two instances: reading options touches the YAML nodes, the pipeline writes the other one.
  const PipelineOptions options = LoadPipelineOptions(Config::Load(config_path));
  const Config config = Config::Load(config_path);
  const PipelineResult result = RunPipeline(sequence_dir, template_path, options, config, out_dir,
                                            [&](const PipelineProgress& p) {
                                              if (progress) progress(p.done, p.total);
                                            });

  // Per-frame trace and metrics.
  std::ostringstream trace, em;
  trace << "frame,skipped,ok,termination,em_iterations,scan_points,vertex_error_mm,"
           "max_vertex_error_mm,joint_error_mm,lost,scale,preprocess_ms,icp_ms,estep_ms,mstep_ms,"
           "fit_ms,texture_pool_ms,texture_mrf_ms,texture_sampling_ms,texture_levelling_ms,"
           "texture_ms,mrf_energy,pool_size,seam_edges,changed_triangles,textured_triangles,"
           "seam_rms_before,seam_rms_after,mrf_iterations\n";
  em << "frame,iteration,stage,radius,cost,max_update,total_weight,num_pairs,scale,converged\n";
  int fitted = 0, lost = 0, failed = 0, converged = 0;
  std::vector<double> iterations, errors, seam_before, seam_after, changed, pool, pre, estep,
      mstep, fit, tex, mrf, lev, mrf_iterations;
  const FrameRecord* last_textured = nullptr;
  const FrameRecord* last_evaluated = nullptr;  // fitted, not failed
  for (const FrameRecord& r : result.frames) {
    // A failed fit is lost whatever its kept pose shows, and no measurement for the errors.
    const bool is_lost = result.has_ground_truth && !r.skipped &&
                         (!r.fit.ok() || !(r.mean_vertex_error_mm <= options.lost_threshold_mm));
    trace << r.frame << "," << (r.skipped ? 1 : 0) << "," << (r.fit.ok() ? 1 : 0) << ","
          << FrameTerminationName(r.fit.termination) << "," << r.fit.iterations << ","
          << r.scan_points << "," << FormatNumber(r.mean_vertex_error_mm) << ","
          << FormatNumber(r.max_vertex_error_mm) << "," << FormatNumber(r.mean_joint_error_mm)
          << "," << (is_lost ? 1 : 0) << "," << FormatNumber(r.fit.scale) << ","
          << FormatNumber(1e3 * r.preprocess_seconds) << "," << FormatNumber(1e3 * r.fit.icp_seconds)
          << "," << FormatNumber(1e3 * r.fit.estep_seconds) << ","
          << FormatNumber(1e3 * r.fit.mstep_seconds) << "," << FormatNumber(1e3 * r.fit.total_seconds)
          << "," << FormatNumber(1e3 * r.texture.seconds_pool) << ","
          << FormatNumber(1e3 * r.texture.seconds_mrf) << ","
          << FormatNumber(1e3 * r.texture.seconds_sampling) << ","
          << FormatNumber(1e3 * r.texture.seconds_levelling) << ","
          << FormatNumber(1e3 * r.texture.seconds_total) << "," << FormatNumber(r.texture.energy)
          << "," << r.texture.pool_size << "," << r.texture.seam_edges << ","
          << r.texture.changed_triangles << "," << r.texture.textured_triangles << ","
          << FormatNumber(r.texture.seam_rms_before) << "," << FormatNumber(r.texture.seam_rms_after)
          << "," << r.texture.mrf_iterations << "\n";
    for (const EMIterationInfo& it : r.fit.trace) {
      em << r.frame << "," << it.iteration << "," << it.stage << "," << FormatNumber(it.radius)
         << "," << FormatNumber(it.cost) << "," << FormatNumber(it.max_update) << ","
         << FormatNumber(it.total_weight) << "," << it.num_pairs << "," << FormatNumber(it.scale)
         << "," << (it.converged ? 1 : 0) << "\n";
    }
    if (r.skipped) continue;
    ++fitted;
    if (is_lost) ++lost;
    if (!r.fit.ok()) ++failed;
    if (r.fit.termination == FrameTermination::kConverged) ++converged;
    iterations.push_back(r.fit.iterations);
    if (result.has_ground_truth && r.fit.ok()) {
      errors.push_back(r.mean_vertex_error_mm);
      last_evaluated = &r;
    }
    pre.push_back(1e3 * r.preprocess_seconds);
    estep.push_back(1e3 * r.fit.estep_seconds);
    mstep.push_back(1e3 * r.fit.mstep_seconds);
    fit.push_back(1e3 * r.fit.total_seconds);
    if (options.texture) {
      tex.push_back(1e3 * r.texture.seconds_total);
      mrf.push_back(1e3 * r.texture.seconds_mrf);
      lev.push_back(1e3 * r.texture.seconds_levelling);
      changed.push_back(r.texture.changed_triangles);
      mrf_iterations.push_back(r.texture.mrf_iterations);
      pool.push_back(r.texture.pool_size);
      if (r.texture.seam_edges > 0) {
        seam_before.push_back(r.texture.seam_rms_before);
        seam_after.push_back(r.texture.seam_rms_after);
      }
      last_textured = &r;
    }
  }
  nlohmann::ordered_json m;
  auto put = [&](const char* name, double value) {
    if (std::isfinite(value)) m[name] = value;
  };
  if (result.has_ground_truth && fitted > 0) {
    put("mean_vertex_error_mm", result.mean_vertex_error_mm);
    put("max_vertex_error_mm", result.max_vertex_error_mm);
    put("mean_joint_error_mm", result.mean_joint_error_mm);
    if (last_evaluated) put("final_vertex_error_mm", last_evaluated->mean_vertex_error_mm);
    put("evaluated_frames", result.evaluated_frames);
    put("lost_frames", lost);
    put("lost_fraction", static_cast<double>(lost) / fitted);
  }
  put("failed_frames", failed);
  put("skipped_frames", result.skipped_frames);
  if (fitted > 0) {
    put("mean_em_iterations", Mean(iterations));
    put("converged_fraction", static_cast<double>(converged) / fitted);
  }
  if (last_textured) {
    put("seam_rms_before", Mean(seam_before));
    put("seam_rms_after", Mean(seam_after));
    put("seam_edges", last_textured->texture.seam_edges);
    put("changed_triangles", Mean(changed));
    put("textured_triangles", last_textured->texture.textured_triangles);
    put("mrf_energy", last_textured->texture.energy);
    put("mrf_iterations", Mean(mrf_iterations));
    put("pool_size", Mean(pool));
    put("stream_kbit_per_s", result.stream_kbit_per_s);
    put("novel_view_psnr_db", result.novel_view_psnr_db);
    put("novel_view_ssim", result.novel_view_ssim);
    put("texture_coverage", result.texture_coverage);
    put("mean_novel_view_psnr_db", result.mean_novel_view_psnr_db);
  }
  if (fitted > 0) {
    put("preprocess_ms", Mean(pre));
    put("estep_ms", Mean(estep));
    put("mstep_ms", Mean(mstep));
    put("fit_ms", Mean(fit));
    if (!tex.empty()) {
      put("texture_ms", Mean(tex));
      put("texture_mrf_ms", Mean(mrf));
      put("texture_levelling_ms", Mean(lev));
    }
    put("frame_ms", Mean(pre) + Mean(fit) + (tex.empty() ? 0.0 : Mean(tex)));
  }
  nlohmann::ordered_json doc;
  doc["metrics"] = m;
  doc["frames"] = static_cast<int>(result.frames.size());
  doc["fitted_frames"] = fitted;
  doc["has_ground_truth"] = result.has_ground_truth;
  doc["warnings"] = result.warnings;
  const fs::path out(out_dir);
  WriteFileAtomic((out / "trace.csv").string(), trace.str());
  WriteFileAtomic((out / "em_trace.csv").string(), em.str());
  WriteFileAtomic((out / "results.json").string(), doc.dump(2) + "\n");
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

  // Tracking template: generated once per spec into OUT/templates/.
  std::string template_path = experiment.template_path;
  std::string template_identity = experiment.template_path;
  if (template_path.empty()) {
    const fs::path dir = out / "templates";
    fs::create_directories(dir);
    template_identity = experiment.template_yaml;
    const fs::path glb = dir / ("template-" + Hex(Fnv1a(experiment.template_yaml), 12) + ".glb");
    template_path = glb.string();
    if (!fs::exists(glb) && !options.dry_run) {
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
      WriteTemplateGlb(glb.string(), GenerateTemplate(shape));
      WriteFileAtomic((dir / ("template-" + Hex(Fnv1a(experiment.template_yaml), 12) + ".yaml")).string(),
                      experiment.template_yaml + "\n");
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

int WriteExperimentResults(const Experiment& experiment, const std::string& out_dir) {
  std::vector<RunResult> runs;
  for (const auto& s : experiment.sequences) {
    for (const auto& c : experiment.combinations) {
      const std::string folder = RunFolder(out_dir, s.name, c.id);
      if (!RunIsComplete(folder)) continue;
      RunResult r;
      r.sequence = &s;
      r.combination = &c;
      const std::string path = (fs::path(folder) / "results.json").string();
      try {
        const auto doc = nlohmann::json::parse(ReadText(path));
        for (const auto& kv : doc.at("metrics").items()) r.metrics[kv.key()] = kv.value().get<double>();
      } catch (const std::exception& e) {
        throw Error(path + ": malformed results: " + e.what());
      }
      runs.push_back(r);
    }
  }

  // results.csv (tidy).
  std::ostringstream csv;
  csv << "experiment,sequence";
  for (const auto& k : experiment.keys) csv << "," << CsvField(k);
  csv << ",metric,value\n";
  for (const auto& r : runs) {
    for (const auto& info : Metrics()) {
      auto it = r.metrics.find(info.name);
      if (it == r.metrics.end()) continue;
      csv << CsvField(experiment.name) << "," << CsvField(r.sequence->name);
      for (const auto& k : experiment.keys) {
        std::string v;
        for (const auto& o : r.combination->overrides) {
          if (o.key == k) v = o.value;
        }
        csv << "," << CsvField(v);
      }
      csv << "," << info.name << "," << FormatNumber(it->second) << "\n";
    }
  }
  WriteFileAtomic((fs::path(out_dir) / "results.csv").string(), csv.str());

  // summary.md: per configuration, the mean of each metric over the sequences it completed.
  const std::size_t num_sequences = experiment.sequences.size();
  struct Row {
    const ExperimentCombination* combination;
    std::map<std::string, std::vector<double>> values;
    std::size_t runs = 0;
  };
  std::vector<Row> rows;
  for (const auto& c : experiment.combinations) {
    Row row{&c, {}, 0};
    for (const auto& r : runs) {
      if (r.combination != &c) continue;
      ++row.runs;
      for (const auto& kv : r.metrics) row.values[kv.first].push_back(kv.second);
    }
    rows.push_back(row);
  }
  std::ostringstream md;
  md << "# Experiment `" << experiment.name << "`\n\n";
  md << "Experiment file: `" << experiment.file << "`. " << runs.size() << " of "
     << num_sequences * experiment.combinations.size() << " runs complete ("
     << num_sequences << " sequences x " << experiment.combinations.size()
     << " configurations). Values are means over the sequences of a configuration; a "
        "configuration missing runs is marked *partial* and not ranked.\n\n";
  md << "Sequences:";
  for (const auto& s : experiment.sequences) md << " `" << s.name << "`";
  md << "\n\n## Best configuration per metric\n\n";
  md << "| metric | better | best configuration | value | worst | spread |\n|---|---|---|---|---|---|\n";
  for (const auto& info : Metrics()) {
    const Row* best = nullptr;
    double best_v = 0, worst_v = 0;
    int ranked = 0;
    for (const auto& row : rows) {
      if (row.runs != num_sequences) continue;
      auto it = row.values.find(info.name);
      if (it == row.values.end() || it->second.size() != num_sequences) continue;
      const double v = Mean(it->second);
      if (!std::isfinite(v)) continue;
      const bool better = info.lower_is_better ? v < best_v : v > best_v;
      const bool worse = info.lower_is_better ? v > worst_v : v < worst_v;
      if (!best || better) {
        best = &row;
        best_v = v;
      }
      if (ranked == 0 || worse) worst_v = v;
      ++ranked;
    }
    if (!best) continue;
    md << "| " << info.name << (info.timing ? " (timing)" : "") << " | "
       << (info.lower_is_better ? "lower" : "higher") << " | "
       << CombinationLabel(*best->combination)
       << (ranked == 1 ? " (only one)" : best_v == worst_v ? " (all equal)" : "")
       << " | " << FormatNumber(best_v) << " | " << FormatNumber(worst_v) << " | "
       << FormatNumber(std::fabs(worst_v - best_v)) << " |\n";
  }
  static const std::vector<std::string> kHeadline = {
      "mean_vertex_error_mm", "mean_joint_error_mm", "lost_fraction", "mean_em_iterations",
      "seam_rms_after", "changed_triangles", "fit_ms", "texture_ms"};
  md << "\n## All configurations\n\n| configuration | runs |";
  for (const auto& h : kHeadline) md << " " << h << " |";
  md << "\n|---|---|";
  for (std::size_t i = 0; i < kHeadline.size(); ++i) md << "---|";
  md << "\n";
  for (const auto& row : rows) {
    md << "| " << CombinationLabel(*row.combination) << " | " << row.runs << "/" << num_sequences
       << (row.runs != num_sequences ? " *partial*" : "") << " |";
    for (const auto& h : kHeadline) {
      auto it = row.values.find(h);
      md << " " << (it == row.values.end() ? std::string("") : FormatNumber(Mean(it->second))) << " |";
    }
    md << "\n";
  }
  md << "\nMetric definitions and directions: docs/experiments.md. The tidy table of every run and "
        "metric is results.csv; per-frame data are in runs/<sequence>/<configuration>/trace.csv.\n";
  WriteFileAtomic((fs::path(out_dir) / "summary.md").string(), md.str());
  return static_cast<int>(runs.size());
}

}  // namespace artex
