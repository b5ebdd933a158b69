#include "sensors/tum_reader.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <tuple>

#include "models/error.h"
#include "sensors/image_io.h"

namespace artex {
namespace fs = std::filesystem;

namespace {

struct Entry {
  double timestamp = 0;
  std::string file;
};

std::vector<Entry> ReadList(const std::string& path) {
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
    entries.push_back({t, file});
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
  YAML::Node root;
  try {
    root = YAML::LoadFile(path);
  } catch (const YAML::BadFile&) {
    throw Error(path + ": cannot open the intrinsics file");
  } catch (const YAML::Exception& e) {
    throw Error(path + ": not valid YAML: " + e.what());
  }
  if (!root.IsMap()) throw Error(path + ": expected a mapping of intrinsics (fx, fy, cx, cy ...)");
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
}

}  // namespace

bool TumReaderOptions::IsValid(std::string* error) const {
  if (!(max_time_difference >= 0) || !std::isfinite(max_time_difference)) {
    if (error) *error = "tum.max_time_difference: expected a finite number >= 0";
    return false;
  }
  if (!std::isfinite(time_offset)) {
    if (error) *error = "tum.time_offset: expected a finite number";
    return false;
  }
  return true;
}

struct TumReader::Impl {
  std::string folder;
  Calibration calibration;
  std::vector<std::pair<Entry, Entry>> pairs;  // (depth, colour)
  int unmatched_depth = 0;
  int unmatched_color = 0;
};

TumReader::TumReader(const std::string& folder, const TumReaderOptions& options)
    : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.folder = folder;
  std::string error;
  if (!options.IsValid(&error)) throw Error(error);
  std::error_code ec;
  if (!fs::is_directory(folder, ec))
    throw Error(folder + ": expected a TUM RGB-D folder, found none");

  // TUM defaults: 640x480, 5000 units per metre; intrinsics from the file.
  m.calibration.depth_scale = 5000.0;
  m.calibration.frame_rate = 30.0;
  const std::string intrinsics = options.intrinsics_path.empty()
                                     ? (fs::path(folder) / "camera.yaml").string()
                                     : options.intrinsics_path;
  if (fs::exists(intrinsics, ec)) {
    ReadIntrinsics(intrinsics, &m.calibration);
  } else if (options.freiburg1_defaults) {
    PinholeCamera cam;
    cam.width = 640;
    cam.height = 480;
    cam.fx = 517.3;
    cam.fy = 516.5;
    cam.cx = 318.6;
    cam.cy = 255.3;
    Distortion d;
    d.k1 = 0.2624;
    d.k2 = -0.9531;
    d.p1 = -0.0054;
    d.p2 = 0.0026;
    d.k3 = 1.1633;
    m.calibration.depth = m.calibration.color = cam;
    m.calibration.depth_distortion = m.calibration.color_distortion = d;
  } else {
    throw Error(intrinsics +
                ": missing intrinsics file (keys width, height, fx, fy, cx, cy; "
                "or enable freiburg1_defaults)");
  }

  const std::vector<Entry> depth = ReadList((fs::path(folder) / "depth.txt").string());
  const std::vector<Entry> rgb = ReadList((fs::path(folder) / "rgb.txt").string());
  if (depth.empty())
    throw Error((fs::path(folder) / "depth.txt").string() +
                ": expected at least one entry, found none");
  if (rgb.empty())
    throw Error((fs::path(folder) / "rgb.txt").string() +
                ": expected at least one entry, found none");

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
        << " s (max_time_difference), found none among " << depth.size() << " depth and "
        << rgb.size() << " colour entries";
    throw Error(msg.str());
  }
}

TumReader::~TumReader() = default;

const Calibration& TumReader::calibration() const { return impl_->calibration; }
int TumReader::num_frames() const { return static_cast<int>(impl_->pairs.size()); }
const std::string& TumReader::depth_file(int i) const { return impl_->pairs.at(i).first.file; }
const std::string& TumReader::color_file(int i) const { return impl_->pairs.at(i).second.file; }
int TumReader::num_unmatched_depth() const { return impl_->unmatched_depth; }
int TumReader::num_unmatched_color() const { return impl_->unmatched_color; }
std::vector<cv::Mat> TumReader::ReadBackgroundFrames() { return {}; }

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
  if (!ReadDepthImage((fs::path(m.folder) / d.file).string(), cal.depth.width, cal.depth.height,
                      &frame->depth, warning)) {
    return false;
  }
  return ReadColorImage((fs::path(m.folder) / c.file).string(), cal.color.width, cal.color.height,
                        &frame->color, warning);
}

}  // namespace artex
