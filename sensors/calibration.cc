#include "sensors/calibration.h"

#include <yaml-cpp/yaml.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <set>
#include <sstream>

#include "models/error.h"
#include "sensors/sequence.h"
#include "sensors/yaml_checks.h"

namespace artex {
namespace {

constexpr int kCalibrationVersion = 1;
// A stored rotation must satisfy |R R^T - I| and |det R - 1| below this (rounding slack).
constexpr double kRotationTolerance = 1e-6;
// Fixed-point undistortion: stop when the normalised coordinate moves less than this.
constexpr double kUndistortTolerance = 1e-14;
constexpr int kUndistortMaxIterations = 100;

std::string Where(const std::string& file, const YAML::Node& node) {
  std::string s = file;
  if (node.Mark().line >= 0) s += ": line " + std::to_string(node.Mark().line + 1);
  return s;
}

std::string Found(const YAML::Node& node) {
  if (!node.IsDefined() || node.IsNull()) return "nothing";
  if (node.IsScalar()) return "'" + node.Scalar() + "'";
  if (node.IsSequence()) return "a list of " + std::to_string(node.size()) + " entries";
  return "a mapping";
}

[[noreturn]] void Fail(const std::string& file, const YAML::Node& where, const std::string& field,
                       const std::string& expected, const std::string& found) {
  throw Error(Where(file, where) + ": field '" + field + "': expected " + expected + ", found " +
              found);
}

YAML::Node Require(const std::string& file, const YAML::Node& parent, const std::string& prefix,
                   const std::string& key) {
  const YAML::Node node = parent[key];
  if (!node.IsDefined() || node.IsNull()) {
    Fail(file, parent, prefix + key, "a value (key is missing)", "nothing");
  }
  return node;
}

void CheckKeys(const std::string& file, const YAML::Node& map, const std::string& prefix,
               const std::set<std::string>& valid) {
  for (const auto& kv : map) {
    const std::string key = kv.first.Scalar();
    if (valid.count(key)) continue;
    std::string list;
    for (const auto& v : valid) list += (list.empty() ? "" : ", ") + v;
    Fail(file, kv.first, prefix + key, "one of the keys {" + list + "}",
         "the unknown key '" + key + "'");
  }
}

double AsDouble(const std::string& file, const YAML::Node& node, const std::string& field) {
  if (!node.IsScalar()) Fail(file, node, field, "a number", Found(node));
  double v = 0;
  try {
    v = node.as<double>();
  } catch (const YAML::Exception&) {
    Fail(file, node, field, "a number", Found(node));
  }
  if (!std::isfinite(v)) Fail(file, node, field, "a finite number", Found(node));
  return v;
}

double ReadPositive(const std::string& file, const YAML::Node& parent, const std::string& prefix,
                    const std::string& key) {
  const YAML::Node node = Require(file, parent, prefix, key);
  const double v = AsDouble(file, node, prefix + key);
  if (v <= 0) Fail(file, node, prefix + key, "a positive number", Found(node));
  return v;
}

int ReadPositiveInt(const std::string& file, const YAML::Node& parent, const std::string& prefix,
                    const std::string& key) {
  const YAML::Node node = Require(file, parent, prefix, key);
  int v = 0;
  try {
    v = node.as<int>();
  } catch (const YAML::Exception&) {
    Fail(file, node, prefix + key, "a positive integer", Found(node));
  }
  if (v <= 0) Fail(file, node, prefix + key, "a positive integer", Found(node));
  return v;
}

Eigen::VectorXd ReadList(const std::string& file, const YAML::Node& parent,
                         const std::string& prefix, const std::string& key, int size) {
  const YAML::Node node = Require(file, parent, prefix, key);
  const std::string expected = "a list of " + std::to_string(size) + " numbers";
  if (!node.IsSequence() || static_cast<int>(node.size()) != size) {
    Fail(file, node, prefix + key, expected, Found(node));
  }
  Eigen::VectorXd v(size);
  for (int i = 0; i < size; ++i) {
    v[i] = AsDouble(file, node[i], prefix + key + "[" + std::to_string(i) + "]");
  }
  return v;
}

void ReadCamera(const std::string& file, const YAML::Node& root, const std::string& name,
                PinholeCamera* camera, Distortion* distortion) {
  const YAML::Node node = Require(file, root, "", name);
  const std::string prefix = name + ".";
  if (!node.IsMap()) Fail(file, node, name, "a mapping", Found(node));
  CheckKeys(file, node, prefix,
            {"width", "height", "fx", "fy", "cx", "cy", "distortion", "world_to_camera"});
  camera->width = ReadPositiveInt(file, node, prefix, "width");
  camera->height = ReadPositiveInt(file, node, prefix, "height");
  camera->fx = ReadPositive(file, node, prefix, "fx");
  camera->fy = ReadPositive(file, node, prefix, "fy");
  camera->cx = AsDouble(file, Require(file, node, prefix, "cx"), prefix + "cx");
  camera->cy = AsDouble(file, Require(file, node, prefix, "cy"), prefix + "cy");

  *distortion = Distortion();
  const YAML::Node d = node["distortion"];
  if (d.IsDefined() && !d.IsNull()) {
    const std::string dp = prefix + "distortion.";
    if (!d.IsMap())
      Fail(file, d, prefix + "distortion", "a mapping {k1, k2, p1, p2, k3}", Found(d));
    CheckKeys(file, d, dp, {"k1", "k2", "p1", "p2", "k3"});
    auto opt = [&](const char* key, double* out) {
      if (d[key].IsDefined() && !d[key].IsNull()) *out = AsDouble(file, d[key], dp + key);
    };
    opt("k1", &distortion->k1);
    opt("k2", &distortion->k2);
    opt("p1", &distortion->p1);
    opt("p2", &distortion->p2);
    opt("k3", &distortion->k3);
  }

  const YAML::Node pose = Require(file, node, prefix, "world_to_camera");
  const std::string pp = prefix + "world_to_camera.";
  if (!pose.IsMap()) Fail(file, pose, prefix + "world_to_camera", "a mapping", Found(pose));
  CheckKeys(file, pose, pp, {"rotation", "translation"});
  const Eigen::VectorXd r = ReadList(file, pose, pp, "rotation", 9);
  const Eigen::VectorXd t = ReadList(file, pose, pp, "translation", 3);
  Eigen::Matrix3d rot;
  rot << r[0], r[1], r[2], r[3], r[4], r[5], r[6], r[7], r[8];
  const double orth = (rot * rot.transpose() - Eigen::Matrix3d::Identity()).norm();
  const double det = rot.determinant();
  if (orth > kRotationTolerance || std::abs(det - 1.0) > kRotationTolerance) {
    std::ostringstream found;
    found << "|R R^T - I| = " << orth << ", det R = " << det;
    Fail(file, pose["rotation"], pp + "rotation", "a proper rotation matrix (9 numbers, row-major)",
         found.str());
  }
  camera->world_to_camera = Eigen::Isometry3d::Identity();
  camera->world_to_camera.linear() = rot;
  camera->world_to_camera.translation() = t;
}

// Shortest decimal text that reads back as exactly `v`.
std::string Num(double v) {
  char buf[40];
  std::snprintf(buf, sizeof(buf), "%.17g", v);
  const bool exponent_ok = std::string(buf).find('e') != std::string::npos;
  for (int precision = 1; precision <= 17; ++precision) {
    std::snprintf(buf, sizeof(buf), "%.*g", precision, v);
    if (std::strtod(buf, nullptr) != v) continue;
    if (exponent_ok || std::string(buf).find('e') == std::string::npos) break;
  }
  return buf;
}

void EmitCamera(YAML::Emitter& out, const char* name, const PinholeCamera& c, const Distortion& d) {
  out << YAML::Key << name << YAML::Value << YAML::BeginMap;
  out << YAML::Key << "width" << YAML::Value << c.width << YAML::Comment("pixels");
  out << YAML::Key << "height" << YAML::Value << c.height << YAML::Comment("pixels");
  out << YAML::Key << "fx" << YAML::Value << Num(c.fx) << YAML::Comment("pixels");
  out << YAML::Key << "fy" << YAML::Value << Num(c.fy) << YAML::Comment("pixels");
  out << YAML::Key << "cx" << YAML::Value << Num(c.cx) << YAML::Comment("pixels, column");
  out << YAML::Key << "cy" << YAML::Value << Num(c.cy) << YAML::Comment("pixels, row");
  out << YAML::Key << "distortion" << YAML::Value << YAML::Flow << YAML::BeginMap;
  out << YAML::Key << "k1" << YAML::Value << Num(d.k1) << YAML::Key << "k2" << YAML::Value
      << Num(d.k2);
  out << YAML::Key << "p1" << YAML::Value << Num(d.p1) << YAML::Key << "p2" << YAML::Value
      << Num(d.p2);
  out << YAML::Key << "k3" << YAML::Value << Num(d.k3) << YAML::EndMap;
  out << YAML::Key << "world_to_camera" << YAML::Value << YAML::BeginMap;
  out << YAML::Key << "rotation" << YAML::Value << YAML::Flow << YAML::BeginSeq;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) out << Num(c.world_to_camera.linear()(i, j));
  }
  out << YAML::EndSeq << YAML::Comment("row-major");
  out << YAML::Key << "translation" << YAML::Value << YAML::Flow << YAML::BeginSeq;
  for (int i = 0; i < 3; ++i) out << Num(c.world_to_camera.translation()[i]);
  out << YAML::EndSeq << YAML::Comment("metres");
  out << YAML::EndMap;
  out << YAML::EndMap;
}

// Normalised (x, y) -> distorted normalised coordinates (OpenCV radial-tangential model).
Eigen::Vector2d DistortNormalised(const Distortion& d, const Eigen::Vector2d& p) {
  const double x = p.x(), y = p.y();
  const double r2 = x * x + y * y;
  const double radial = 1 + r2 * (d.k1 + r2 * (d.k2 + r2 * d.k3));
  return {x * radial + 2 * d.p1 * x * y + d.p2 * (r2 + 2 * x * x),
          y * radial + d.p1 * (r2 + 2 * y * y) + 2 * d.p2 * x * y};
}

}  // namespace

bool CalibrationIsPlausible(const Calibration& c, std::string* why) {
  using L = CalibrationLimits;
  std::ostringstream msg;
  auto check = [&](const std::string& field, double v, double lo, double hi, const char* unit) {
    if (!msg.str().empty() || (v >= lo && v <= hi)) return;
    msg << "field '" << field << "': expected a value in [" << lo << ", " << hi << "] " << unit
        << ", found " << v;
  };
  check("depth_scale", c.depth_scale, L::kMinDepthScale, L::kMaxDepthScale, "units per metre");
  check("frame_rate", c.frame_rate, L::kMinFrameRate, L::kMaxFrameRate, "Hz");
  const std::pair<const char*, const PinholeCamera*> cameras[] = {{"depth", &c.depth},
                                                                  {"color", &c.color}};
  const Distortion* distortions[] = {&c.depth_distortion, &c.color_distortion};
  for (int k = 0; k < 2; ++k) {
    const std::string p = std::string(cameras[k].first) + ".";
    const PinholeCamera& cam = *cameras[k].second;
    check(p + "width", cam.width, 1, L::kMaxImageSide, "pixels");
    check(p + "height", cam.height, 1, L::kMaxImageSide, "pixels");
    check(p + "fx", cam.fx, L::kMinFocal, L::kMaxFocal, "pixels");
    check(p + "fy", cam.fy, L::kMinFocal, L::kMaxFocal, "pixels");
    check(p + "cx", cam.cx, -cam.width, 2.0 * cam.width, "pixels");
    check(p + "cy", cam.cy, -cam.height, 2.0 * cam.height, "pixels");
    const Distortion& d = *distortions[k];
    const std::pair<const char*, double> coefficients[] = {
        {"k1", d.k1}, {"k2", d.k2}, {"p1", d.p1}, {"p2", d.p2}, {"k3", d.k3}};
    for (const auto& [name, value] : coefficients) {
      check(p + "distortion." + name, value, -L::kMaxDistortion, L::kMaxDistortion, "");
    }
    const Eigen::Vector3d t = cam.world_to_camera.translation();
    for (int a = 0; a < 3; ++a) {
      check(p + "world_to_camera.translation[" + std::to_string(a) + "]", t[a], -L::kMaxTranslation,
            L::kMaxTranslation, "m");
    }
  }
  if (msg.str().empty()) return true;
  if (why) *why = msg.str();
  return false;
}

Calibration ReadCalibration(const std::string& path) {
  CheckNotAFolder(path, "a calibration file");
  YAML::Node root;
  try {
    root = YAML::LoadFile(path);
  } catch (const YAML::BadFile&) {
    throw Error(path + ": cannot open the calibration file");
  } catch (const YAML::Exception& e) {
    throw Error(path + ": not valid YAML: " + e.what());
  }
  if (!root.IsMap()) Fail(path, root, "(top level)", "a mapping", Found(root));
  CheckYamlKeys(root, path);
  CheckKeys(path, root, "", {"version", "depth_scale", "frame_rate", "depth", "color"});
  const YAML::Node version = Require(path, root, "", "version");
  int v = 0;
  try {
    v = version.as<int>();
  } catch (const YAML::Exception&) {
    Fail(path, version, "version", std::to_string(kCalibrationVersion), Found(version));
  }
  if (v != kCalibrationVersion) {
    Fail(path, version, "version", std::to_string(kCalibrationVersion), Found(version));
  }
  Calibration c;
  c.depth_scale = ReadPositive(path, root, "", "depth_scale");
  c.frame_rate = ReadPositive(path, root, "", "frame_rate");
  ReadCamera(path, root, "depth", &c.depth, &c.depth_distortion);
  ReadCamera(path, root, "color", &c.color, &c.color_distortion);
  std::string why;
  if (!CalibrationIsPlausible(c, &why)) throw Error(path + ": " + why);
  return c;
}

void WriteCalibration(const Calibration& calibration, const std::string& path) {
  YAML::Emitter out;
  out.SetDoublePrecision(17);
  out << YAML::Comment("artex RGB-D rig calibration (docs/formats.md)");
  out << YAML::BeginMap;
  out << YAML::Key << "version" << YAML::Value << kCalibrationVersion;
  out << YAML::Key << "depth_scale" << YAML::Value << Num(calibration.depth_scale)
      << YAML::Comment("16-bit depth units per metre");
  out << YAML::Key << "frame_rate" << YAML::Value << Num(calibration.frame_rate)
      << YAML::Comment("Hz");
  EmitCamera(out, "depth", calibration.depth, calibration.depth_distortion);
  EmitCamera(out, "color", calibration.color, calibration.color_distortion);
  out << YAML::EndMap;
  if (!out.good()) throw Error(path + ": cannot encode the calibration: " + out.GetLastError());
  WriteFileAtomic(path, std::string(out.c_str()) + "\n");
}

Eigen::Vector2d DistortPixel(const PinholeCamera& camera, const Distortion& d,
                             const Eigen::Vector2d& pixel) {
  if (d.IsZero()) return pixel;
  const Eigen::Vector2d n((pixel.x() - camera.cx) / camera.fx, (pixel.y() - camera.cy) / camera.fy);
  const Eigen::Vector2d q = DistortNormalised(d, n);
  return {camera.fx * q.x() + camera.cx, camera.fy * q.y() + camera.cy};
}

Eigen::Vector2d UndistortPixel(const PinholeCamera& camera, const Distortion& d,
                               const Eigen::Vector2d& pixel) {
  if (d.IsZero()) return pixel;
  const Eigen::Vector2d target((pixel.x() - camera.cx) / camera.fx,
                               (pixel.y() - camera.cy) / camera.fy);
  // Newton iterations on f(p) = distort(p) - target with the analytic 2x2 Jacobian, started at
  // the target (converges in a few steps for physical lens distortion).
  Eigen::Vector2d p = target;
  for (int it = 0; it < kUndistortMaxIterations; ++it) {
    const Eigen::Vector2d f = DistortNormalised(d, p) - target;
    const double x = p.x(), y = p.y(), r2 = x * x + y * y;
    const double radial = 1 + r2 * (d.k1 + r2 * (d.k2 + r2 * d.k3));
    const double dradial = d.k1 + r2 * (2 * d.k2 + 3 * r2 * d.k3);  // d radial / d r2
    Eigen::Matrix2d j;
    j(0, 0) = radial + x * dradial * 2 * x + 2 * d.p1 * y + d.p2 * 6 * x;
    j(0, 1) = x * dradial * 2 * y + 2 * d.p1 * x + d.p2 * 2 * y;
    j(1, 0) = y * dradial * 2 * x + d.p1 * 2 * x + 2 * d.p2 * y;
    j(1, 1) = radial + y * dradial * 2 * y + d.p1 * 6 * y + 2 * d.p2 * x;
    const Eigen::Vector2d step = j.partialPivLu().solve(f);
    if (!step.allFinite()) break;
    p -= step;
    if (step.squaredNorm() < kUndistortTolerance * kUndistortTolerance) break;
  }
  return {camera.fx * p.x() + camera.cx, camera.fy * p.y() + camera.cy};
}

}  // namespace artex
