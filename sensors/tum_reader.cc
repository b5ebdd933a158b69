#include "sensors/tum_reader.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <sstream>
#include <tuple>

#include "models/error.h"
#include "sensors/image_io.h"
#include "sensors/yaml_checks.h"

namespace artex {
namespace fs = std::filesystem;

namespace {

struct Entry {
  double timestamp = 0;
  std::string file;
  int line = 0;  // 1-based line of the list file
};

constexpr char kIntrinsicsKeys[] =
    "width, height, fx, fy, cx, cy (pixels), optional k1, k2, p1, p2, k3 and depth_scale "
    "(units per metre, default 5000)";

std::string FormatNumber(double v) {
  std::ostringstream s;
  s.precision(17);
  s << v;
  return s.str();
}

std::vector<Entry> ReadList(const std::string& path) {
  CheckNotAFolder(path, "a TUM list file");
  std::ifstream in(path);
  if (!in) throw Error(path + ": missing or unreadable TUM list file");
  std::vector<Entry> entries;
  std::string line;
  int number = 0;
  while (std::getline(in, line)) {
    ++number;
    const size_t first = line.find_first_not_of(" \t\r");
    if (first == std::string::npos || line[first] == '#') continue;
    std::istringstream ss(line);
    std::string ts, file, extra;
    ss >> ts >> file;
    const std::string where = path + ": line " + std::to_string(number);
    char* end = nullptr;
    const double t = std::strtod(ts.c_str(), &end);
    if (ts.empty() || end != ts.c_str() + ts.size() || !std::isfinite(t)) {
      throw Error(where + ": expected 'timestamp filename', found '" + line + "'");
    }
    if (file.empty()) throw Error(where + ": expected 'timestamp filename', found no file name");
    if (!entries.empty() && !(t > entries.back().timestamp)) {
      std::ostringstream msg;
      msg.precision(17);
      msg << where << ": expected increasing timestamps (> " << entries.back().timestamp
          << "), found " << ts;
      throw Error(msg.str());
    }
    entries.push_back({t, file, number});
  }
  return entries;
}

double ReadNumber(const std::string& path, const YAML::Node& root, const std::string& key,
                  bool required, double fallback, bool positive) {
  const YAML::Node n = root[key];
  const std::string where = path +
                            (n.IsDefined() ? ": line " + std::to_string(n.Mark().line + 1) : "") +
                            ": field '" + key + "'";
  if (!n.IsDefined() || n.IsNull()) {
    if (required) throw Error(path + ": field '" + key + "': expected a number, found nothing");
    return fallback;
  }
  double v = 0;
  try {
    v = n.as<double>();
  } catch (const YAML::Exception&) {
    throw Error(where + ": expected a number, found " +
                (n.IsScalar() ? "'" + n.Scalar() + "'" : "a non-scalar"));
  }
  if (!std::isfinite(v) || (positive && v <= 0)) {
    throw Error(where + ": expected a " + std::string(positive ? "positive" : "finite") +
                " number, found '" + n.Scalar() + "'");
  }
  return v;
}

void ReadIntrinsics(const std::string& path, Calibration* c) {
  CheckNotAFolder(path, "an intrinsics file");
  YAML::Node root;
  try {
    root = YAML::LoadFile(path);
  } catch (const YAML::BadFile&) {
    throw Error(path + ": cannot open the intrinsics file");
  } catch (const YAML::Exception& e) {
    throw Error(path + ": not valid YAML: " + e.what());
  }
  if (!root.IsMap()) throw Error(path + ": expected a mapping of intrinsics (fx, fy, cx, cy ...)");
  CheckYamlKeys(root, path);
  const char* valid[] = {"width", "height", "fx", "fy", "cx", "cy",
                         "k1",    "k2",     "p1", "p2", "k3", "depth_scale"};
  for (const auto& kv : root) {
    const std::string key = kv.first.Scalar();
    if (std::find(std::begin(valid), std::end(valid), key) == std::end(valid)) {
      throw Error(path + ": line " + std::to_string(kv.first.Mark().line + 1) + ": unknown key '" +
                  key +
                  "', expected one of width, height, fx, fy, cx, cy, k1, k2, p1, p2, k3, "
                  "depth_scale");
    }
  }
  PinholeCamera cam;
  const double w = ReadNumber(path, root, "width", true, 0, true);
  const double h = ReadNumber(path, root, "height", true, 0, true);
  if (w != std::floor(w) || h != std::floor(h)) {
    throw Error(path + ": fields 'width', 'height': expected integers");
  }
  // Checked before the conversion to int (found by the TUM fuzzer: 4.8e31 was undefined).
  const double max_side = CalibrationLimits::kMaxImageSide;
  if (w > max_side || h > max_side) {
    std::ostringstream msg;
    msg << path << ": fields 'width', 'height': expected at most " << max_side
        << " pixels, found " << w << " x " << h;
    throw Error(msg.str());
  }
  cam.width = static_cast<int>(w);
  cam.height = static_cast<int>(h);
  cam.fx = ReadNumber(path, root, "fx", true, 0, true);
  cam.fy = ReadNumber(path, root, "fy", true, 0, true);
  cam.cx = ReadNumber(path, root, "cx", true, 0, false);
  cam.cy = ReadNumber(path, root, "cy", true, 0, false);
  Distortion d;
  d.k1 = ReadNumber(path, root, "k1", false, 0, false);
  d.k2 = ReadNumber(path, root, "k2", false, 0, false);
  d.p1 = ReadNumber(path, root, "p1", false, 0, false);
  d.p2 = ReadNumber(path, root, "p2", false, 0, false);
  d.k3 = ReadNumber(path, root, "k3", false, 0, false);
  c->depth_scale = ReadNumber(path, root, "depth_scale", false, c->depth_scale, true);
  c->depth = cam;
  c->color = cam;
  c->depth_distortion = d;
  c->color_distortion = d;
  std::string why;
  if (!CalibrationIsPlausible(*c, &why)) throw Error(path + ": " + why);
}

// Mean specific force of an accelerometer.txt ("timestamp ax ay az", '#' comments).
Eigen::Vector3d ReadAccelerometer(const std::string& path, int* samples) {
  std::ifstream in(path);
  if (!in) throw Error(path + ": cannot open the accelerometer file");
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  int count = 0;
  std::string line;
  int number = 0;
  while (std::getline(in, line)) {
    ++number;
    const size_t first = line.find_first_not_of(" \t\r");
    if (first == std::string::npos || line[first] == '#') continue;
    std::istringstream ss(line);
    std::string field;
    double v[4];
    int n = 0;
    bool ok = true;
    while (ss >> field) {
      char* end = nullptr;
      const double x = std::strtod(field.c_str(), &end);
      if (end != field.c_str() + field.size() || !std::isfinite(x) || n == 4) {
        ok = false;
        break;
      }
      v[n++] = x;
    }
    if (!ok || n != 4) {
      std::string found = line;
      while (!found.empty() && (found.back() == '\r' || found.back() == ' ')) found.pop_back();
      throw Error(path + ": line " + std::to_string(number) +
                  ": expected 'timestamp ax ay az' (4 numbers, m/s^2), found '" + found + "'");
    }
    sum += Eigen::Vector3d(v[1], v[2], v[3]);
    ++count;
  }
  *samples = count;
  return count > 0 ? Eigen::Vector3d(sum / count) : Eigen::Vector3d::Zero();
}

}  // namespace

const std::map<std::string, TumIntrinsicsPreset>& TumIntrinsicsPresetNames() {
  static const std::map<std::string, TumIntrinsicsPreset> names = {
      {"none", TumIntrinsicsPreset::kNone},
      {"fr1", TumIntrinsicsPreset::kFreiburg1},
      {"fr2", TumIntrinsicsPreset::kFreiburg2},
      {"fr3", TumIntrinsicsPreset::kFreiburg3},
      {"kinect", TumIntrinsicsPreset::kKinect}};
  return names;
}

std::string TumIntrinsicsPresetName(TumIntrinsicsPreset preset) {
  for (const auto& [name, p] : TumIntrinsicsPresetNames()) {
    if (p == preset) return name;
  }
  return "?";
}

Calibration TumPresetCalibration(TumIntrinsicsPreset preset) {
  struct Values {
    double fx, fy, cx, cy, k1, k2, p1, p2, k3;
  };
  Values v{};
  switch (preset) {
    case TumIntrinsicsPreset::kFreiburg1:
      v = {517.3, 516.5, 318.6, 255.3, 0.2624, -0.9531, -0.0054, 0.0026, 1.1633};
      break;
    case TumIntrinsicsPreset::kFreiburg2:
      v = {520.9, 521.0, 325.1, 249.7, 0.2312, -0.7849, -0.0033, -0.0001, 0.9172};
      break;
    case TumIntrinsicsPreset::kFreiburg3:
      v = {535.4, 539.2, 320.1, 247.6, 0, 0, 0, 0, 0};
      break;
    case TumIntrinsicsPreset::kKinect:
      v = {525.0, 525.0, 319.5, 239.5, 0, 0, 0, 0, 0};
      break;
    case TumIntrinsicsPreset::kNone:
      throw Error("TUM intrinsics preset: expected one of fr1, fr2, fr3, kinect, found none");
  }
  Calibration c;
  c.depth_scale = 5000.0;
  c.frame_rate = 30.0;
  PinholeCamera cam;
  cam.width = 640;
  cam.height = 480;
  cam.fx = v.fx;
  cam.fy = v.fy;
  cam.cx = v.cx;
  cam.cy = v.cy;
  Distortion d;
  d.k1 = v.k1;
  d.k2 = v.k2;
  d.p1 = v.p1;
  d.p2 = v.p2;
  d.k3 = v.k3;
  c.depth = c.color = cam;
  c.depth_distortion = c.color_distortion = d;
  return c;
}

void TumReaderOptions::SetIntrinsics(const std::string& name_or_file) {
  const auto& names = TumIntrinsicsPresetNames();
  auto it = names.find(name_or_file);
  if (it != names.end()) {
    intrinsics_preset = it->second;
    intrinsics_path.clear();
  } else {
    intrinsics_preset = TumIntrinsicsPreset::kNone;
    intrinsics_path = name_or_file;
  }
}

bool TumReaderOptions::IsValid(std::string* error) const {
  std::string msg;
  if (!(max_time_difference >= 0) || !std::isfinite(max_time_difference)) {
    msg = "input.max_time_difference: expected a finite number >= 0, found " +
          FormatNumber(max_time_difference);
  } else if (!std::isfinite(time_offset)) {
    msg = "input.time_offset: expected a finite number, found " + FormatNumber(time_offset);
  } else if (!intrinsics_path.empty() && intrinsics_preset != TumIntrinsicsPreset::kNone) {
    msg = "input.intrinsics: expected a file or a preset, found both (" + intrinsics_path + ", " +
          TumIntrinsicsPresetName(intrinsics_preset) + ")";
  } else if (!(min_gravity_norm >= 0) || !std::isfinite(min_gravity_norm)) {
    msg = "input.min_gravity_norm: expected a finite number >= 0 (m/s^2), found " +
          FormatNumber(min_gravity_norm);
  }
  if (msg.empty()) return true;
  if (error) *error = msg;
  return false;
}

struct TumReader::Impl {
  std::string folder;
  TumReaderOptions options;
  Calibration calibration;
  std::vector<std::pair<Entry, Entry>> pairs;  // (depth, colour)
  int num_depth_entries = 0;
  int num_color_entries = 0;
  int unmatched_depth = 0;
  int unmatched_color = 0;
  int missing_files = 0;
  std::string intrinsics_source;
  int accelerometer_samples = 0;
  Eigen::Vector3d mean_specific_force = Eigen::Vector3d::Zero();
  std::optional<Eigen::Vector3d> up;

  std::string Path(const std::string& relative) const {
    return (fs::path(folder) / relative).string();
  }
};

TumReader::TumReader(const std::string& folder, const TumReaderOptions& options)
    : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.folder = folder;
  m.options = options;
  std::string error;
  if (!options.IsValid(&error)) throw Error(error);
  std::error_code ec;
  if (!fs::is_directory(folder, ec))
    throw Error(folder + ": expected a TUM RGB-D folder, found none");

  // TUM defaults: 640x480, 5000 units per metre; intrinsics from a preset or a file.
  if (options.intrinsics_preset != TumIntrinsicsPreset::kNone) {
    m.calibration = TumPresetCalibration(options.intrinsics_preset);
    m.intrinsics_source = "preset " + TumIntrinsicsPresetName(options.intrinsics_preset);
  } else {
    m.calibration.depth_scale = 5000.0;
    m.calibration.frame_rate = 30.0;
    const std::string intrinsics =
        options.intrinsics_path.empty() ? m.Path("camera.yaml") : options.intrinsics_path;
    if (!fs::exists(intrinsics, ec)) {
      std::string presets;
      for (const auto& kv : TumIntrinsicsPresetNames()) {
        if (kv.second != TumIntrinsicsPreset::kNone)
          presets += (presets.empty() ? "" : "|") + kv.first;
      }
      throw Error(intrinsics + ": missing intrinsics file" +
                  (options.intrinsics_path.empty() ? " of the TUM RGB-D folder" : "") +
                  "; expected a YAML file with the keys " + kIntrinsicsKeys +
                  ", or give one with --intrinsics FILE, or use the TUM benchmark's published "
                  "intrinsics with --intrinsics " +
                  presets + " (config key input.intrinsics; docs/formats.md)");
    }
    ReadIntrinsics(intrinsics, &m.calibration);
    m.intrinsics_source = intrinsics;
  }

  const std::vector<Entry> depth = ReadList(m.Path("depth.txt"));
  const std::vector<Entry> rgb = ReadList(m.Path("rgb.txt"));
  if (depth.empty()) throw Error(m.Path("depth.txt") + ": expected at least one entry, found none");
  if (rgb.empty()) throw Error(m.Path("rgb.txt") + ": expected at least one entry, found none");
  m.num_depth_entries = static_cast<int>(depth.size());
  m.num_color_entries = static_cast<int>(rgb.size());

  // Candidate pairs within the window, then greedy one-to-one by increasing difference.
  std::vector<std::tuple<double, int, int>> candidates;
  for (int di = 0; di < static_cast<int>(depth.size()); ++di) {
    const double t = depth[di].timestamp;
    auto lo = std::lower_bound(rgb.begin(), rgb.end(),
                               t - options.max_time_difference - options.time_offset,
                               [](const Entry& e, double v) { return e.timestamp < v; });
    for (auto it = lo; it != rgb.end(); ++it) {
      const double diff = std::abs(t - (it->timestamp + options.time_offset));
      if (it->timestamp + options.time_offset > t + options.max_time_difference) break;
      if (diff <= options.max_time_difference) {
        candidates.emplace_back(diff, di, static_cast<int>(it - rgb.begin()));
      }
    }
  }
  std::sort(candidates.begin(), candidates.end());
  std::vector<char> depth_used(depth.size(), 0), rgb_used(rgb.size(), 0);
  std::vector<std::pair<int, int>> chosen;
  for (const auto& [diff, di, ri] : candidates) {
    if (depth_used[di] || rgb_used[ri]) continue;
    depth_used[di] = rgb_used[ri] = 1;
    chosen.emplace_back(di, ri);
  }
  std::sort(chosen.begin(), chosen.end());
  for (const auto& [di, ri] : chosen) m.pairs.emplace_back(depth[di], rgb[ri]);
  m.unmatched_depth = static_cast<int>(depth.size() - chosen.size());
  m.unmatched_color = static_cast<int>(rgb.size() - chosen.size());
  if (m.pairs.empty()) {
    std::ostringstream msg;
    msg << folder << ": expected depth/colour pairs within " << options.max_time_difference
        << " s (input.max_time_difference) after shifting colour by " << options.time_offset
        << " s (input.time_offset), found none: all " << depth.size() << " depth and " << rgb.size()
        << " colour entries are unpaired (depth " << std::fixed << std::setprecision(6)
        << depth.front().timestamp << ".." << depth.back().timestamp << " s, colour "
        << rgb.front().timestamp << ".." << rgb.back().timestamp << " s)";
    throw Error(msg.str());
  }
  for (const auto& [d, c] : m.pairs) {
    if (!fs::is_regular_file(m.Path(d.file), ec) || !fs::is_regular_file(m.Path(c.file), ec)) {
      ++m.missing_files;
    }
  }

  const std::string accelerometer = m.Path("accelerometer.txt");
  if (options.read_accelerometer && fs::exists(accelerometer, ec)) {
    m.mean_specific_force = ReadAccelerometer(accelerometer, &m.accelerometer_samples);
    const double norm = m.mean_specific_force.norm();
    if (m.accelerometer_samples > 0 && norm >= options.min_gravity_norm && norm > 0) {
      m.up = m.mean_specific_force / norm;
    }
  }
}

TumReader::~TumReader() = default;

const Calibration& TumReader::calibration() const { return impl_->calibration; }
int TumReader::num_frames() const { return static_cast<int>(impl_->pairs.size()); }
const std::string& TumReader::depth_file(int i) const { return impl_->pairs.at(i).first.file; }
const std::string& TumReader::color_file(int i) const { return impl_->pairs.at(i).second.file; }
int TumReader::num_unmatched_depth() const { return impl_->unmatched_depth; }
int TumReader::num_unmatched_color() const { return impl_->unmatched_color; }
int TumReader::num_missing_files() const { return impl_->missing_files; }
int TumReader::num_accelerometer_samples() const { return impl_->accelerometer_samples; }
const std::string& TumReader::intrinsics_source() const { return impl_->intrinsics_source; }
std::vector<cv::Mat> TumReader::ReadBackgroundFrames() { return {}; }
std::optional<Eigen::Vector3d> TumReader::gravity() const { return impl_->up; }

std::string TumReader::Description() const {
  const Impl& m = *impl_;
  const PinholeCamera& c = m.calibration.depth;
  std::ostringstream s;
  s << "TUM RGB-D folder " << m.folder << ": " << m.pairs.size() << " depth/colour pairs of "
    << m.num_depth_entries << " depth and " << m.num_color_entries << " colour entries ("
    << m.unmatched_depth << " depth and " << m.unmatched_color << " colour unpaired within "
    << m.options.max_time_difference << " s";
  if (m.options.time_offset != 0) s << ", colour shifted by " << m.options.time_offset << " s";
  s << ")";
  if (m.missing_files > 0) s << ", missing files in " << m.missing_files << " pairs (skipped)";
  s << "; intrinsics from " << m.intrinsics_source << " (" << c.width << "x" << c.height << ", fx "
    << c.fx << ", fy " << c.fy << ", cx " << c.cx << ", cy " << c.cy
    << (m.calibration.depth_distortion.IsZero() ? ", no distortion" : ", distortion") << ", "
    << m.calibration.depth_scale << " units/m)"
    << "; depth registered to colour (one camera); calibration in the camera frame";
  if (m.up) {
    s << "; up from accelerometer.txt (" << m.accelerometer_samples << " samples, mean "
      << std::setprecision(3) << m.mean_specific_force.norm() << " m/s^2) = (" << (*m.up)[0] << ", "
      << (*m.up)[1] << ", " << (*m.up)[2] << ") in the camera frame";
  } else if (m.accelerometer_samples > 0) {
    s << "; accelerometer.txt mean " << std::setprecision(3) << m.mean_specific_force.norm()
      << " m/s^2 below input.min_gravity_norm: no gravity";
  } else {
    s << "; no accelerometer.txt (no gravity)";
  }
  return s.str();
}

bool TumReader::ReadFrame(int i, Frame* frame, std::string* warning) {
  const Impl& m = *impl_;
  if (i < 0 || i >= num_frames()) {
    throw Error(m.folder + ": frame " + std::to_string(i) + " requested, expected 0.." +
                std::to_string(num_frames() - 1));
  }
  const auto& [d, c] = m.pairs[i];
  frame->index = i;
  frame->depth_timestamp = d.timestamp;
  frame->color_timestamp = c.timestamp;
  const Calibration& cal = m.calibration;
  std::error_code ec;
  for (const auto* e : {&d, &c}) {
    if (!fs::is_regular_file(m.Path(e->file), ec)) {
      if (warning) {
        *warning = m.Path(e->file) + ": missing frame file (listed in " +
                   m.Path(e == &d ? "depth.txt" : "rgb.txt") + " line " + std::to_string(e->line) +
                   "); frame " + std::to_string(i) + " skipped";
      }
      return false;
    }
  }
  if (!ReadDepthImage(m.Path(d.file), cal.depth.width, cal.depth.height, &frame->depth, warning)) {
    return false;
  }
  return ReadColorImage(m.Path(c.file), cal.color.width, cal.color.height, &frame->color, warning);
}

}  // namespace artex
