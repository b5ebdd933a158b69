#include "models/template_generator.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <functional>
#include <limits>
#include <map>
#include <numeric>
#include <queue>
#include <sstream>
#include <unordered_map>
#include <utility>
#include <vector>

#include <Eigen/Geometry>
#include <OpenMesh/Core/Mesh/TriMesh_ArrayKernelT.hh>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "models/error.h"
#include "models/numeric.h"

namespace artex {
namespace {

using Vec3 = Eigen::Vector3d;
// Lengths of SkinningBands are given for this stature and scaled with the height.
constexpr double kReferenceStature = 1.75;
// Lower bound of the loft field's ratio to the true distance (its cross-section distance is an
// approximation and its sections change with height); used to cull it safely.
constexpr double kLoftLipschitz = 0.5;
// Primitives are culled beyond blend + this many grid cells (see Body::Field).
constexpr double kCullMarginCells = 3.0;
// Iso-surface vertices stay this far (fraction of the edge) from grid points, so that marching
// tetrahedra produce no zero-length edges.
constexpr double kEdgeClamp = 0.02;
// Isotropic remeshing (Botsch & Kobbelt 2004): split above 4/3, collapse below 4/5 of the target.
constexpr double kSplitFactor = 4.0 / 3.0;
constexpr double kCollapseFactor = 4.0 / 5.0;
// A collapse may turn no incident face normal by more than acos(0.2) ~ 78 degrees; no edge is
// flipped across a dihedral angle above 60 degrees (cos 0.5).
constexpr double kCollapseNormalCosine = 0.2;
constexpr double kFlipCreaseCosine = 0.5;
// Newton projection onto f = 0: step cap (fraction of the target edge length) and the forward
// difference step (fraction of the stature).
constexpr double kMaxProjectionStep = 0.5;
constexpr double kGradientStep = 1e-5;

constexpr const char* kJointNames[kDefaultNumJoints] = {
    "pelvis",     "spine",   "chest",   "neck",  "head",   "l_shoulder",
    "l_elbow",    "l_wrist", "r_shoulder", "r_elbow", "r_wrist", "l_hip",
    "l_knee",     "l_ankle", "r_hip",   "r_knee", "r_ankle"};
constexpr int kParents[kDefaultNumJoints] = {-1, 0, 1, 2, 3, 2, 5, 6, 2, 8, 9, 0, 11, 12, 0, 14, 15};

enum JointId : int {
  kPelvis = 0, kSpine, kChest, kNeck, kHead,
  kLShoulder, kLElbow, kLWrist, kRShoulder, kRElbow, kRWrist,
  kLHip, kLKnee, kLAnkle, kRHip, kRKnee, kRAnkle
};

// Kinematic groups that the implicit primitives belong to; body parts (joints) are found by
// the dominant group at each vertex, then by planes along the group's bones.
enum class Group { kTrunk, kNeckHead, kLeftArm, kRightArm, kLeftLeg, kRightLeg };

enum class Chart : int {
  kHeadFront = 0, kHeadBack, kTorsoFront, kTorsoBack,
  kLUpperArm, kLForearm, kLPalm, kLHandBack,
  kRUpperArm, kRForearm, kRPalm, kRHandBack,
  kLThigh, kLShank, kLFootMedial, kLFootLateral,
  kRThigh, kRShank, kRFootMedial, kRFootLateral
};

// ----------------------------------------------------------------------------------------------
// Option validation.

bool Check(bool ok, const std::string& field, const std::string& expected, double found,
           std::string* error) {
  if (ok) return true;
  if (error) {
    std::ostringstream msg;
    msg << field << ": expected " << expected << ", found " << found;
    *error = msg.str();
  }
  return false;
}

bool InRange(double v, double lo, double hi) { return std::isfinite(v) && v >= lo && v <= hi; }

// ----------------------------------------------------------------------------------------------
// Implicit body: smooth union of primitives (signed-distance-like fields, negative inside).

double SmoothMin(double a, double b, double k) {
  if (k <= 0.0) return std::min(a, b);
  const double h = std::max(k - std::abs(a - b), 0.0) / k;
  return std::min(a, b) - h * h * k * 0.25;
}

// Exact signed distance of a round cone (sphere-swept cone) from the origin along +X of length
// l, radii r1 at 0 and r2 at l (after I. Quilez).
double RoundConeX(const Vec3& p, double l, double r1, double r2) {
  const double l2 = l * l;
  const double rr = r1 - r2;
  const double a2 = l2 - rr * rr;
  const double il2 = 1.0 / l2;
  const double y = p.x() * l;
  const double z = y - l2;
  const double x2 = (p.y() * p.y() + p.z() * p.z()) * l2 * l2;
  const double y2 = y * y * l2;
  const double z2 = z * z * l2;
  const double k = (rr > 0 ? 1.0 : (rr < 0 ? -1.0 : 0.0)) * rr * rr * x2;
  if ((z > 0 ? 1.0 : (z < 0 ? -1.0 : 0.0)) * a2 * z2 > k) return std::sqrt(x2 + z2) * il2 - r2;
  if ((y > 0 ? 1.0 : (y < 0 ? -1.0 : 0.0)) * a2 * y2 < k) return std::sqrt(x2 + y2) * il2 - r1;
  return (std::sqrt(x2 * a2 * il2) + y * rr) * il2 - r1;
}

struct Primitive {
  enum class Kind { kRoundCone, kEllipsoid, kRoundBox, kLoft };
  Kind kind = Kind::kEllipsoid;
  Group group = Group::kTrunk;
  double blend = 0.0;                               // smooth-union radius (m)
  Vec3 origin = Vec3::Zero();                       // cone start / ellipsoid or box centre
  Eigen::Matrix3d frame = Eigen::Matrix3d::Identity();  // rows: local axes
  Vec3 scale = Vec3::Ones();    // local coordinates are divided by this (cone flattening)
  double length = 0.0, r1 = 0.0, r2 = 0.0;          // round cone
  Vec3 semi_axes = Vec3::Ones();                    // ellipsoid / box half extents
  double rounding = 0.0, rounding_top = 0.0;  // box edge radius; loft bottom / top caps
  // Loft: sections (y, half width, half depth, centre z) and their y-derivatives.
  std::vector<std::array<double, 4>> sections, slopes;
  double lipschitz = 1.0;  // lower bound of (field value / true distance) outside
  Vec3 bound_centre = Vec3::Zero();
  double bound_radius = 0.0;

  double Eval(const Vec3& p) const {
    const Vec3 q = frame * (p - origin);
    switch (kind) {
      case Kind::kRoundCone: {
        const Vec3 s = q.cwiseQuotient(scale);
        return RoundConeX(s, length, r1, r2) * scale.minCoeff();
      }
      case Kind::kEllipsoid: {
        const double k0 = q.cwiseQuotient(semi_axes).norm();
        const double k1 = q.cwiseQuotient(semi_axes.cwiseProduct(semi_axes)).norm();
        if (k1 < 1e-12) return -semi_axes.minCoeff();
        return k0 * (k0 - 1.0) / k1;
      }
      case Kind::kRoundBox: {
        const Vec3 d = q.cwiseAbs() - (semi_axes - Vec3::Constant(rounding));
        return d.cwiseMax(0.0).norm() + std::min(d.maxCoeff(), 0.0) - rounding;
      }
      case Kind::kLoft:
        return LoftEval(p);
    }
    return kInf;
  }

  // Cubic Hermite interpolation of the sections at height y (clamped to the loft's range).
  std::array<double, 4> Section(double y) const {
    const size_t n = sections.size();
    y = std::clamp(y, sections.front()[0], sections.back()[0]);
    size_t i = 0;
    while (i + 2 < n && y > sections[i + 1][0]) ++i;
    const double h = sections[i + 1][0] - sections[i][0];
    const double t = (y - sections[i][0]) / h;
    const double h00 = 2 * t * t * t - 3 * t * t + 1, h10 = t * t * t - 2 * t * t + t;
    const double h01 = -2 * t * t * t + 3 * t * t, h11 = t * t * t - t * t;
    std::array<double, 4> out;
    out[0] = y;
    for (int c = 1; c < 4; ++c) {
      out[c] = h00 * sections[i][c] + h10 * h * slopes[i][c] + h01 * sections[i + 1][c] +
               h11 * h * slopes[i + 1][c];
    }
    return out;
  }

  // Elliptical cross-section distance (approximation after I. Quilez), extruded along y with
  // rounded caps of radius `rounding` (bottom) / `rounding_top`.
  double LoftEval(const Vec3& p) const {
    const std::array<double, 4> s = Section(p.y());
    const double a = s[1], b = s[2];
    const double x = p.x(), z = p.z() - s[3];
    const double k0 = std::hypot(x / a, z / b);
    const double k1 = std::hypot(x / (a * a), z / (b * b));
    const double d_xz = k1 < 1e-12 ? -std::min(a, b) : k0 * (k0 - 1.0) / k1;
    const double y0 = sections.front()[0], y1 = sections.back()[0];
    const double r = p.y() < 0.5 * (y0 + y1) ? rounding : rounding_top;
    const double dy = std::max(y0 - p.y(), p.y() - y1);
    const double wx = d_xz + r, wy = dy + r;
    return std::min(std::max(wx, wy), 0.0) + std::hypot(std::max(wx, 0.0), std::max(wy, 0.0)) - r;
  }
};

Eigen::Matrix3d FrameFromAxis(const Vec3& axis, const Vec3& thickness_hint) {
  const Vec3 u = axis.normalized();
  Vec3 t = thickness_hint - thickness_hint.dot(u) * u;
  if (t.norm() < 1e-9) t = u.unitOrthogonal();
  t.normalize();
  const Vec3 w = u.cross(t);
  Eigen::Matrix3d frame;
  frame.row(0) = u;
  frame.row(1) = t;
  frame.row(2) = w;
  return frame;
}

Primitive MakeCone(Group group, double blend, const Vec3& a, const Vec3& b, double ra, double rb,
                   double flattening = 1.0, const Vec3& thickness_axis = Vec3::UnitZ()) {
  Primitive p;
  p.kind = Primitive::Kind::kRoundCone;
  p.group = group;
  p.blend = blend;
  p.origin = a;
  p.frame = FrameFromAxis(b - a, thickness_axis);
  p.scale = Vec3(1.0, flattening, 1.0);
  p.length = (b - a).norm();
  p.r1 = ra;
  p.r2 = rb;
  p.lipschitz = flattening;
  p.bound_centre = 0.5 * (a + b);
  p.bound_radius = 0.5 * p.length + std::max(ra, rb);
  return p;
}

// Ellipsoid with semi-axes along the rows of `frame` (world axes by default).
Primitive MakeEllipsoid(Group group, double blend, const Vec3& centre, const Vec3& semi_axes,
                        const Eigen::Matrix3d& frame = Eigen::Matrix3d::Identity()) {
  Primitive p;
  p.frame = frame;
  p.kind = Primitive::Kind::kEllipsoid;
  p.group = group;
  p.blend = blend;
  p.origin = centre;
  p.semi_axes = semi_axes;
  p.lipschitz = semi_axes.minCoeff() / semi_axes.maxCoeff();
  p.bound_centre = centre;
  p.bound_radius = semi_axes.maxCoeff();
  return p;
}

// sections: (y, half width, half depth, centre z) in metres, increasing y.
Primitive MakeLoft(Group group, double blend, const std::vector<std::array<double, 4>>& sections,
                   double cap_rounding) {
  Primitive p;
  p.kind = Primitive::Kind::kLoft;
  p.group = group;
  p.blend = blend;
  p.sections = sections;
  const size_t n = sections.size();
  p.slopes.assign(n, {0.0, 0.0, 0.0, 0.0});
  for (size_t i = 0; i < n; ++i) {
    const size_t lo = i == 0 ? 0 : i - 1, hi = i + 1 == n ? n - 1 : i + 1;
    for (int c = 1; c < 4; ++c) {
      p.slopes[i][c] = (sections[hi][c] - sections[lo][c]) / (sections[hi][0] - sections[lo][0]);
    }
  }
  // Rounded caps: a fraction of the end sections' smaller half axis.
  p.rounding = cap_rounding * std::min(sections.front()[1], sections.front()[2]);
  p.rounding_top = cap_rounding * std::min(sections.back()[1], sections.back()[2]);
  double max_extent = 0.0, z_mid = 0.0;
  for (const auto& s : sections) z_mid += s[3] / n;
  for (const auto& s : sections) {
    max_extent = std::max(max_extent, std::hypot(s[1], s[2] + std::abs(s[3] - z_mid)));
  }
  const double half_height = 0.5 * (sections.back()[0] - sections.front()[0]);
  p.bound_centre = Vec3(0.0, sections.front()[0] + half_height, z_mid);
  p.bound_radius = std::hypot(max_extent, half_height);
  p.lipschitz = kLoftLipschitz;
  return p;
}

Primitive MakeBox(Group group, double blend, const Vec3& centre, const Vec3& half, double r) {
  Primitive p;
  p.kind = Primitive::Kind::kRoundBox;
  p.group = group;
  p.blend = blend;
  p.origin = centre;
  p.semi_axes = half;
  p.rounding = r;
  p.bound_centre = centre;
  p.bound_radius = half.norm();
  return p;
}

// Skeleton and implicit primitives of one body.
struct Body {
  double height = 0.0;
  std::array<Vec3, kDefaultNumJoints> centre;
  std::array<Vec3, kDefaultNumJoints> axis;
  std::array<Vec3, kDefaultNumJoints> incoming;  // parent-to-joint bone direction (planes)
  std::vector<Primitive> primitives;
  double cull_margin = 0.0;
  Vec3 box_min, box_max;
  // Chart splitting planes.
  double torso_mid_z = 0.0, head_mid_z = 0.0;
  std::array<Vec3, 2> palm_normal;  // per side (0 left, 1 right): points to the palm side
  std::array<Vec3, 2> arm_seam, leg_seam;  // preferred seam side of the limb cylinders

  double Field(const Vec3& p) const {
    double f = kInf;
    for (const Primitive& prim : primitives) {
      const double bound = (p - prim.bound_centre).norm() - prim.bound_radius;
      // A primitive at least (blend + margin) away cannot change the union where |f| < margin,
      // i.e. near the surface; far from the surface only the sign matters.
      if (prim.lipschitz * bound >= prim.blend + cull_margin) continue;
      f = SmoothMin(f, prim.Eval(p), prim.blend);
    }
    // Nothing below the floor: the smooth union would bulge the soles below y = 0.
    return std::max(f, -p.y());
  }
  // Forward differences from the known value f = Field(p).
  Vec3 Gradient(const Vec3& p, double f, double eps) const {
    Vec3 g;
    for (int i = 0; i < 3; ++i) {
      Vec3 a = p;
      a[i] += eps;
      g[i] = (Field(a) - f) / eps;
    }
    return g;
  }
  Group DominantGroup(const Vec3& p) const {
    double best = kInf;
    Group group = Group::kTrunk;
    for (const Primitive& prim : primitives) {
      const double d = prim.Eval(p);
      if (d < best) {
        best = d;
        group = prim.group;
      }
    }
    return group;
  }
};

Body BuildBody(const BodyShapeOptions& shape, const BodyProportions& bp, double grid_cell) {
  Body body;
  const double h = shape.height;
  body.height = h;
  const double g = shape.girth;
  const double arm_angle = shape.arm_angle_deg * kPi / 180.0;
  const double spread = bp.leg_spread_deg * kPi / 180.0;

  // Legs decide the hip height; the upper body is mapped so the head top stays at h.
  const double thigh = bp.thigh_length * shape.leg_length * h;
  const double shank = bp.shank_length * shape.leg_length * h;
  const double hip_y = bp.ankle_height * h + (thigh + shank) * std::cos(spread);
  const double sigma = (h - hip_y) / ((1.0 - bp.hip_height) * h);
  auto y_of = [&](double nominal) { return hip_y + (nominal - bp.hip_height) * h * sigma; };
  auto trunk_semi = [&](const Vec3& s, double x_extra) {
    return Vec3(s.x() * h * g * x_extra, s.y() * h * sigma, s.z() * h * g);
  };

  auto& c = body.centre;
  c[kPelvis] = Vec3(0, y_of(bp.pelvis_height), 0);
  c[kSpine] = Vec3(0, y_of(bp.spine_height), 0);
  c[kChest] = Vec3(0, y_of(bp.chest_height), 0);
  c[kNeck] = Vec3(0, y_of(bp.neck_height), bp.neck_base_z * h);
  c[kHead] = Vec3(0, y_of(bp.head_joint_height), 0.0);
  const double shoulder_x =
      h * (bp.shoulder_half_breadth * shape.shoulder_width + (g - 1.0) * bp.girth_shoulder_shift);
  const double hip_x = bp.hip_half_spacing * h * shape.hip_width;
  const double upper_arm = bp.upper_arm_length * shape.arm_length * h;
  const double forearm = bp.forearm_length * shape.arm_length * h;
  const double hand = bp.hand_length * shape.arm_length * h;

  const Vec3 up = Vec3::UnitY();
  body.axis[kPelvis] = up;
  body.axis[kSpine] = up;
  body.axis[kChest] = up;
  body.axis[kNeck] = (c[kHead] - c[kNeck]).normalized();
  body.axis[kHead] = up;
  body.incoming[kPelvis] = up;
  body.incoming[kSpine] = up;
  body.incoming[kChest] = up;
  body.incoming[kNeck] = up;
  body.incoming[kHead] = body.axis[kNeck];

  const double blend_trunk = bp.blend_trunk * h;
  const double blend_root = bp.blend_limb_root * h;
  const double blend_limb = bp.blend_limb * h;
  const double blend_hand = bp.blend_hand * h;
  auto& prims = body.primitives;

  // Trunk: loft of cross-sections plus buttocks.
  {
    std::vector<std::array<double, 4>> sections;
    for (const auto& sec : bp.torso_sections) {
      const double t = std::clamp((sec.y - bp.hip_section_top) /
                                      (bp.shoulder_section_bottom - bp.hip_section_top),
                                  0.0, 1.0);
      const double width = (1.0 - t) * shape.hip_width + t * shape.shoulder_width;
      sections.push_back({y_of(sec.y), sec.half_width * h * g * width, sec.half_depth * h * g,
                          sec.centre_z * h});
    }
    prims.push_back(MakeLoft(Group::kTrunk, blend_trunk, sections, bp.torso_cap_rounding));
  }
  for (int side = 0; side < 2; ++side) {
    const double sx = side == 0 ? 1.0 : -1.0;
    prims.push_back(MakeEllipsoid(
        Group::kTrunk, blend_trunk,
        Vec3(sx * bp.buttock_centre.x() * h * shape.hip_width * g, y_of(bp.buttock_centre.y()),
             bp.buttock_centre.z() * h * g),
        trunk_semi(bp.buttock_semi_axes, 1.0)));
  }
  // Neck and head.
  const Vec3 head_semi(bp.head_semi_axes.x() * h, bp.head_semi_axes.y() * h * sigma,
                       bp.head_semi_axes.z() * h);
  const Vec3 head_centre(0, y_of(1.0 - bp.head_semi_axes.y()), bp.head_centre_z * h);
  const Vec3 neck_bottom = c[kNeck] - bp.neck_extension_bottom * h * body.axis[kNeck];
  const Vec3 neck_top = c[kHead] + bp.neck_extension_top * h * body.axis[kNeck];
  prims.push_back(MakeCone(Group::kNeckHead, blend_trunk, neck_bottom, neck_top,
                           bp.neck_base_radius * h * g, bp.neck_top_radius * h * g));
  prims.push_back(MakeEllipsoid(Group::kNeckHead, blend_root, head_centre, head_semi));
  prims.push_back(MakeEllipsoid(
      Group::kNeckHead, blend_root, Vec3(0, y_of(bp.jaw_centre.y()), bp.jaw_centre.z() * h),
      Vec3(bp.jaw_semi_axes.x() * h, bp.jaw_semi_axes.y() * h * sigma, bp.jaw_semi_axes.z() * h)));
  prims.push_back(MakeEllipsoid(
      Group::kNeckHead, blend_limb, Vec3(0, y_of(bp.nose_centre.y()), bp.nose_centre.z() * h),
      bp.nose_semi_axes * h));
  body.head_mid_z = head_centre.z();
  body.torso_mid_z = 0.0;
  for (const auto& sec : bp.torso_sections) body.torso_mid_z += sec.centre_z * h / bp.torso_sections.size();

  // Arms.
  for (int side = 0; side < 2; ++side) {
    const double sx = side == 0 ? 1.0 : -1.0;
    const Group group = side == 0 ? Group::kLeftArm : Group::kRightArm;
    const int js = side == 0 ? kLShoulder : kRShoulder;
    const Vec3 dir(sx * std::cos(arm_angle), -std::sin(arm_angle), 0.0);
    // Perpendicular to the arm in the frontal plane, pointing down and towards the body: the
    // palm side (palms face the thighs) and the underside of the arm.
    const Vec3 inner(-sx * std::sin(arm_angle), -std::cos(arm_angle), 0.0);
    c[js] = Vec3(sx * shoulder_x, y_of(bp.shoulder_height), 0.0);
    c[js + 1] = c[js] + upper_arm * dir;
    c[js + 2] = c[js + 1] + forearm * dir;
    for (int j = js; j < js + 3; ++j) body.axis[j] = dir;
    body.incoming[js] = dir;
    body.incoming[js + 1] = dir;
    body.incoming[js + 2] = dir;
    body.palm_normal[side] = inner;
    body.arm_seam[side] = inner;

    // Trapezius slope from the neck base to the top of the shoulder (trunk), deltoid (arm).
    const Vec3 acromion =
        c[js] + bp.acromion_rise * h * up - bp.acromion_inset * h * Vec3(sx, 0.0, 0.0);
    prims.push_back(MakeCone(
        Group::kTrunk, blend_trunk,
        Vec3(sx * bp.trapezius_neck_x * shoulder_x, y_of(bp.neck_height), bp.trapezius_neck_z * h),
        acromion, bp.trapezius_radius * h * g, bp.trapezius_taper * bp.trapezius_radius * h * g));
    prims.push_back(MakeEllipsoid(group, blend_trunk, c[js] + bp.deltoid_offset * h * (dir + up),
                                  Vec3::Constant(bp.deltoid_radius * h * g)));
    prims.push_back(MakeCone(group, blend_root, c[js], c[js + 1], bp.upper_arm_radius_top * h * g,
                             bp.upper_arm_radius_bottom * h * g));
    prims.push_back(MakeCone(group, blend_limb, c[js + 1], c[js + 2], bp.forearm_radius_top * h * g,
                             bp.forearm_radius_wrist * h * g));
    prims.push_back(MakeEllipsoid(
        group, blend_limb, c[js + 1] + bp.forearm_bulge_fraction * forearm * dir,
        Vec3(bp.forearm_bulge_length * forearm, bp.forearm_radius_bulge * h * g,
             bp.forearm_radius_bulge * h * g),
        FrameFromAxis(dir, inner)));
    // Hand: flattened palm and finger cones (width along Z), thumb to the front.
    const Vec3 knuckles = c[js + 2] + bp.palm_fraction * hand * dir;
    const double tip_r = bp.fingertip_half_width * h;
    prims.push_back(MakeCone(group, blend_limb, c[js + 2] - bp.palm_start_offset * h * dir, knuckles,
                             bp.palm_half_width * h, bp.palm_half_width * h, bp.hand_flattening,
                             inner));
    prims.push_back(MakeCone(group, blend_hand, knuckles, c[js + 2] + (hand - tip_r * bp.hand_flattening) * dir,
                             bp.finger_half_width * h, tip_r, bp.hand_flattening, inner));
    const Vec3 thumb_base = c[js + 2] + bp.thumb_base_fraction * hand * dir +
                            bp.thumb_base_offset * bp.palm_half_width * h * Vec3::UnitZ();
    const double thumb_angle = bp.thumb_angle_deg * kPi / 180.0;
    const Vec3 thumb_dir = (std::cos(thumb_angle) * dir + std::sin(thumb_angle) * Vec3::UnitZ()).normalized();
    prims.push_back(MakeCone(group, blend_hand, thumb_base,
                             thumb_base + bp.thumb_length * h * thumb_dir, bp.thumb_radius * h,
                             bp.thumb_taper * bp.thumb_radius * h));
  }

  // Legs.
  for (int side = 0; side < 2; ++side) {
    const double sx = side == 0 ? 1.0 : -1.0;
    const Group group = side == 0 ? Group::kLeftLeg : Group::kRightLeg;
    const int jh = side == 0 ? kLHip : kRHip;
    const Vec3 dir(sx * std::sin(spread), -std::cos(spread), 0.0);
    c[jh] = Vec3(sx * hip_x, hip_y, 0.0);
    c[jh + 1] = c[jh] + thigh * dir;
    c[jh + 2] = c[jh + 1] + shank * dir;
    body.axis[jh] = dir;
    body.axis[jh + 1] = dir;
    body.incoming[jh] = dir;
    body.incoming[jh + 1] = dir;
    body.incoming[jh + 2] = dir;
    body.leg_seam[side] = Vec3(-sx, 0.0, 0.0);  // inseam

    prims.push_back(MakeCone(group, blend_root, c[jh], c[jh + 1], bp.thigh_radius_top * h * g,
                             bp.thigh_radius_bottom * h * g));
    prims.push_back(MakeEllipsoid(
        group, blend_limb, c[jh] + bp.thigh_muscle_fraction * thigh * dir,
        Vec3(bp.thigh_muscle_length * thigh, bp.thigh_muscle_radius * h * g,
             bp.thigh_muscle_radius * h * g),
        FrameFromAxis(dir, Vec3::UnitZ())));
    prims.push_back(MakeCone(group, blend_limb, c[jh + 1], c[jh + 2], bp.shank_radius_top * h * g,
                             bp.shank_radius_ankle * h * g));
    // The calf bulges backwards.
    prims.push_back(MakeEllipsoid(
        group, blend_limb,
        c[jh + 1] + bp.calf_fraction * shank * dir - bp.calf_back_offset * h * Vec3::UnitZ(),
        Vec3(bp.calf_length * shank, bp.calf_radius * h * g, bp.calf_radius * h * g),
        FrameFromAxis(dir, Vec3::UnitZ())));
    // Foot: rounded box with the sole on y = 0, plus an instep cone from the ankle.
    const double foot_len = bp.foot_length * h;
    const double heel_z = c[jh + 2].z() - bp.heel_offset * h;
    const Vec3 half(bp.foot_half_width * h, bp.foot_half_height * h, 0.5 * foot_len);
    const Vec3 foot_centre(c[jh + 2].x(), half.y(), heel_z + half.z());
    prims.push_back(MakeBox(group, blend_limb, foot_centre, half, bp.foot_rounding * h));
    const Vec3 ball(c[jh + 2].x(), bp.instep_height * half.y(),
                    heel_z + bp.foot_ball_fraction * foot_len);
    prims.push_back(MakeCone(group, blend_limb, c[jh + 2], ball, bp.shank_radius_ankle * h,
                             half.y()));
    prims.push_back(MakeEllipsoid(group, blend_limb,
                                  Vec3(c[jh + 2].x(), bp.heel_radius * half.y(),
                                       heel_z + bp.heel_radius * half.y()),
                                  Vec3(bp.heel_width * half.x(), bp.heel_radius * half.y(),
                                       bp.heel_radius * half.y())));
    body.axis[jh + 2] = (ball - c[jh + 2]).normalized();
  }

  body.cull_margin = kCullMarginCells * grid_cell;
  body.box_min = Vec3::Constant(kInf);
  body.box_max = Vec3::Constant(-kInf);
  for (const Primitive& p : prims) {
    body.box_min = body.box_min.cwiseMin(p.bound_centre - Vec3::Constant(p.bound_radius));
    body.box_max = body.box_max.cwiseMax(p.bound_centre + Vec3::Constant(p.bound_radius));
  }
  return body;
}

// ----------------------------------------------------------------------------------------------
// Iso-surface extraction: marching tetrahedra on the Kuhn subdivision of a regular grid
// (consistent across cells, so the result is a closed 2-manifold for a field without zeros at
// grid points).

struct TriangleMesh {
  std::vector<Vec3> vertices;
  std::vector<std::array<int, 3>> triangles;
};

TriangleMesh ExtractIsoSurface(const Body& body, double cell) {
  const Vec3 lo = body.box_min - Vec3::Constant(2.0 * cell);
  const Vec3 hi = body.box_max + Vec3::Constant(2.0 * cell);
  const int nx = static_cast<int>(std::ceil((hi.x() - lo.x()) / cell)) + 1;
  const int ny = static_cast<int>(std::ceil((hi.y() - lo.y()) / cell)) + 1;
  const int nz = static_cast<int>(std::ceil((hi.z() - lo.z()) / cell)) + 1;
  auto index = [&](int i, int j, int k) {
    return (static_cast<int64_t>(k) * ny + j) * nx + i;
  };
  auto point = [&](int i, int j, int k) -> Vec3 { return lo + cell * Vec3(i, j, k); };
  // Coarse-to-fine sampling: blocks of kBlock^3 cells whose corners are all farther from the
  // surface than (safety * block diagonal) cannot contain it; their points only need the sign.
  constexpr int kBlock = 4;
  constexpr double kSafety = 1.5;
  const int bx = (nx - 1 + kBlock - 1) / kBlock, by = (ny - 1 + kBlock - 1) / kBlock,
            bz = (nz - 1 + kBlock - 1) / kBlock;
  auto coarse_index = [&](int i, int j, int k) {
    return (static_cast<int64_t>(k) * (by + 1) + j) * (bx + 1) + i;
  };
  std::vector<float> coarse(static_cast<size_t>(bx + 1) * (by + 1) * (bz + 1));
  auto sample = [&](int i, int j, int k) {
    double f = body.Field(point(i, j, k));
    if (f == 0.0) f = 1e-12;  // no grid value exactly on the iso-level
    return static_cast<float>(f);
  };
  tbb::parallel_for(tbb::blocked_range<int>(0, bz + 1), [&](const tbb::blocked_range<int>& r) {
    for (int k = r.begin(); k < r.end(); ++k) {
      for (int j = 0; j <= by; ++j) {
        for (int i = 0; i <= bx; ++i) coarse[coarse_index(i, j, k)] = sample(i * kBlock, j * kBlock, k * kBlock);
      }
    }
  });
  const double threshold = kSafety * kBlock * cell * std::sqrt(3.0);
  auto block_index = [&](int ib, int jb, int kb) {
    return (static_cast<int64_t>(kb) * by + jb) * bx + ib;
  };
  std::vector<char> near(static_cast<size_t>(bx) * by * bz);
  std::vector<float> block_sign(near.size());
  for (int kb = 0; kb < bz; ++kb) {
    for (int jb = 0; jb < by; ++jb) {
      for (int ib = 0; ib < bx; ++ib) {
        float min_abs = std::numeric_limits<float>::infinity();
        float corner = 0.0f;
        for (int c = 0; c < 8; ++c) {
          corner = coarse[coarse_index(ib + (c & 1), jb + ((c >> 1) & 1), kb + ((c >> 2) & 1))];
          min_abs = std::min(min_abs, std::abs(corner));
        }
        near[block_index(ib, jb, kb)] = min_abs < threshold;
        block_sign[block_index(ib, jb, kb)] = corner;
      }
    }
  }
  // A grid point is sampled exactly when one of the blocks containing it is near the surface;
  // far blocks cannot contain the surface, so elsewhere only the sign matters.
  std::vector<float> values(static_cast<size_t>(nx) * ny * nz);
  auto block_range = [](int i, int nb) {
    const int hi = std::min(i / kBlock, nb - 1);
    const int lo = (i % kBlock == 0 && i > 0) ? i / kBlock - 1 : hi;
    return std::make_pair(std::min(lo, hi), hi);
  };
  tbb::parallel_for(tbb::blocked_range<int>(0, nz), [&](const tbb::blocked_range<int>& r) {
    for (int k = r.begin(); k < r.end(); ++k) {
      const auto [k0, k1] = block_range(k, bz);
      for (int j = 0; j < ny; ++j) {
        const auto [j0, j1] = block_range(j, by);
        for (int i = 0; i < nx; ++i) {
          const auto [i0, i1] = block_range(i, bx);
          bool exact = false;
          for (int kb = k0; kb <= k1 && !exact; ++kb) {
            for (int jb = j0; jb <= j1 && !exact; ++jb) {
              for (int ib = i0; ib <= i1 && !exact; ++ib) exact = near[block_index(ib, jb, kb)];
            }
          }
          values[index(i, j, k)] = exact ? sample(i, j, k) : block_sign[block_index(i1, j1, k1)];
        }
      }
    }
  });

  TriangleMesh mesh;
  std::unordered_map<int64_t, int> edge_vertex;
  auto corner_offset = [](int c) { return Eigen::Vector3i(c & 1, (c >> 1) & 1, (c >> 2) & 1); };
  static constexpr int kTets[6][4] = {{0, 1, 3, 7}, {0, 1, 5, 7}, {0, 2, 3, 7},
                                      {0, 2, 6, 7}, {0, 4, 5, 7}, {0, 4, 6, 7}};
  auto vertex_on_edge = [&](const Eigen::Vector3i& base, int ca, int cb) {
    // Corners of a Kuhn edge: one corner's bits are a subset of the other's.
    if ((ca & cb) != ca) std::swap(ca, cb);
    const Eigen::Vector3i pa = base + corner_offset(ca);
    const Eigen::Vector3i pb = base + corner_offset(cb);
    const int64_t key = index(pa.x(), pa.y(), pa.z()) * 8 + (cb ^ ca);
    auto it = edge_vertex.find(key);
    if (it != edge_vertex.end()) return it->second;
    const double fa = values[index(pa.x(), pa.y(), pa.z())];
    const double fb = values[index(pb.x(), pb.y(), pb.z())];
    const double t = std::clamp(fa / (fa - fb), kEdgeClamp, 1.0 - kEdgeClamp);
    const Vec3 p = (1.0 - t) * point(pa.x(), pa.y(), pa.z()) + t * point(pb.x(), pb.y(), pb.z());
    const int id = static_cast<int>(mesh.vertices.size());
    mesh.vertices.push_back(p);
    edge_vertex.emplace(key, id);
    return id;
  };
  auto emit = [&](int a, int b, int c, const Vec3& outward) {
    const Vec3 n =
        (mesh.vertices[b] - mesh.vertices[a]).cross(mesh.vertices[c] - mesh.vertices[a]);
    if (n.dot(outward) < 0.0) std::swap(b, c);
    mesh.triangles.push_back({a, b, c});
  };
  for (int k = 0; k + 1 < nz; ++k) {
    for (int j = 0; j + 1 < ny; ++j) {
      for (int i = 0; i + 1 < nx; ++i) {
        float f[8];
        int inside = 0;
        for (int cidx = 0; cidx < 8; ++cidx) {
          const Eigen::Vector3i o = corner_offset(cidx);
          f[cidx] = values[index(i + o.x(), j + o.y(), k + o.z())];
          inside += f[cidx] < 0.0f;
        }
        if (inside == 0 || inside == 8) continue;
        const Eigen::Vector3i base(i, j, k);
        for (const auto& tet : kTets) {
          int in[4], out[4], n_in = 0, n_out = 0;
          for (int v : tet) {
            if (f[v] < 0.0f) in[n_in++] = v; else out[n_out++] = v;
          }
          if (n_in == 0 || n_out == 0) continue;
          Vec3 in_centre = Vec3::Zero(), out_centre = Vec3::Zero();
          for (int q = 0; q < n_in; ++q) in_centre += corner_offset(in[q]).cast<double>() / n_in;
          for (int q = 0; q < n_out; ++q)
            out_centre += corner_offset(out[q]).cast<double>() / n_out;
          const Vec3 outward = out_centre - in_centre;
          if (n_in == 1 || n_out == 1) {
            const int lone = n_in == 1 ? in[0] : out[0];
            const int* others = n_in == 1 ? out : in;
            emit(vertex_on_edge(base, lone, others[0]), vertex_on_edge(base, lone, others[1]),
                 vertex_on_edge(base, lone, others[2]), outward);
          } else {
            const int a = vertex_on_edge(base, in[0], out[0]);
            const int b = vertex_on_edge(base, in[0], out[1]);
            const int c2 = vertex_on_edge(base, in[1], out[1]);
            const int d = vertex_on_edge(base, in[1], out[0]);
            emit(a, b, c2, outward);
            emit(a, c2, d, outward);
          }
        }
      }
    }
  }
  return mesh;
}

// Keeps the connected component with the most triangles; returns the number dropped.
int KeepLargestComponent(TriangleMesh* mesh) {
  const int nv = static_cast<int>(mesh->vertices.size());
  std::vector<int> parent(nv);
  std::iota(parent.begin(), parent.end(), 0);
  std::function<int(int)> find = [&](int x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  };
  for (const auto& t : mesh->triangles) {
    parent[find(t[0])] = find(t[1]);
    parent[find(t[1])] = find(t[2]);
  }
  std::map<int, int> count;
  for (const auto& t : mesh->triangles) ++count[find(t[0])];
  int best = -1, best_count = -1;
  for (const auto& [root, n] : count) {
    if (n > best_count) {
      best = root;
      best_count = n;
    }
  }
  std::vector<int> remap(nv, -1);
  TriangleMesh kept;
  for (const auto& t : mesh->triangles) {
    if (find(t[0]) != best) continue;
    std::array<int, 3> nt;
    for (int q = 0; q < 3; ++q) {
      if (remap[t[q]] < 0) {
        remap[t[q]] = static_cast<int>(kept.vertices.size());
        kept.vertices.push_back(mesh->vertices[t[q]]);
      }
      nt[q] = remap[t[q]];
    }
    kept.triangles.push_back(nt);
  }
  *mesh = std::move(kept);
  return static_cast<int>(count.size()) - 1;
}

// ----------------------------------------------------------------------------------------------
// Isotropic remeshing (Botsch & Kobbelt 2004) with projection onto the implicit surface.

struct OmTraits : public OpenMesh::DefaultTraits {
  using Point = OpenMesh::Vec3d;
  using Normal = OpenMesh::Vec3d;
  VertexAttributes(OpenMesh::Attributes::Status | OpenMesh::Attributes::Normal);
  EdgeAttributes(OpenMesh::Attributes::Status);
  FaceAttributes(OpenMesh::Attributes::Status | OpenMesh::Attributes::Normal);
  HalfedgeAttributes(OpenMesh::Attributes::PrevHalfedge);
};
using OmMesh = OpenMesh::TriMesh_ArrayKernelT<OmTraits>;

Vec3 ToEigen(const OpenMesh::Vec3d& p) { return Vec3(p[0], p[1], p[2]); }
OpenMesh::Vec3d ToOm(const Vec3& p) { return OpenMesh::Vec3d(p.x(), p.y(), p.z()); }

Vec3 ProjectToSurface(const Body& body, Vec3 p, int iterations, double eps, double max_step) {
  for (int it = 0; it < iterations; ++it) {
    const double f = body.Field(p);
    if (std::abs(f) < 1e-9) break;
    const Vec3 g = body.Gradient(p, f, eps);
    const double g2 = g.squaredNorm();
    if (g2 < 1e-12) break;
    Vec3 step = -f * g / g2;
    if (step.norm() > max_step) step *= max_step / step.norm();
    p += step;
  }
  return p;
}

Vec3 FaceNormal(const Vec3& a, const Vec3& b, const Vec3& c) { return (b - a).cross(c - a); }

class Remesher {
 public:
  Remesher(const Body& body, const TriangleMesh& input, double edge_length,
           const MeshingOptions& options)
      : body_(body), target_(edge_length), options_(options) {
    std::vector<OmMesh::VertexHandle> handles;
    handles.reserve(input.vertices.size());
    for (const Vec3& p : input.vertices) handles.push_back(mesh_.add_vertex(ToOm(p)));
    for (const auto& t : input.triangles) {
      const auto fh = mesh_.add_face(handles[t[0]], handles[t[1]], handles[t[2]]);
      if (!fh.is_valid()) throw Error("template generator: iso-surface is not a manifold");
    }
  }

  void Run() {
    const double high = kSplitFactor * target_;
    const double low = kCollapseFactor * target_;
    for (int it = 0; it < options_.remesh_iterations; ++it) {
      SplitLongEdges(high);
      CollapseShortEdges(low, high);
      EqualizeValences();
      TangentialRelaxation();
      Project();
    }
  }

  TriangleMesh Result() {
    mesh_.garbage_collection();
    TriangleMesh out;
    for (auto vh : mesh_.vertices()) out.vertices.push_back(ToEigen(mesh_.point(vh)));
    for (auto fh : mesh_.faces()) {
      std::array<int, 3> t;
      int q = 0;
      for (auto vh : mesh_.fv_range(fh)) t[q++] = vh.idx();
      out.triangles.push_back(t);
    }
    return out;
  }

 private:
  Vec3 P(OmMesh::VertexHandle v) const { return ToEigen(mesh_.point(v)); }

  void SplitLongEdges(double high) {
    for (size_t i = 0; i < mesh_.n_edges(); ++i) {
      const auto eh = mesh_.edge_handle(static_cast<int>(i));
      if (mesh_.status(eh).deleted()) continue;
      const auto hh = mesh_.halfedge_handle(eh, 0);
      const Vec3 a = P(mesh_.from_vertex_handle(hh));
      const Vec3 b = P(mesh_.to_vertex_handle(hh));
      if ((a - b).norm() <= high) continue;
      const auto vh = mesh_.add_vertex(ToOm(0.5 * (a + b)));
      mesh_.split(eh, vh);
    }
  }

  // True when moving vertex `v` to `p` (ignoring faces that contain `skip`) keeps every
  // incident face's orientation.
  bool KeepsOrientation(OmMesh::VertexHandle v, const Vec3& p, OmMesh::VertexHandle skip) const {
    for (auto fh : mesh_.vf_range(v)) {
      std::array<Vec3, 3> old_pts, new_pts;
      bool has_skip = false;
      int q = 0;
      for (auto w : mesh_.fv_range(fh)) {
        if (w == skip) has_skip = true;
        old_pts[q] = P(w);
        new_pts[q] = w == v ? p : P(w);
        ++q;
      }
      if (has_skip) continue;
      const Vec3 n0 = FaceNormal(old_pts[0], old_pts[1], old_pts[2]);
      const Vec3 n1 = FaceNormal(new_pts[0], new_pts[1], new_pts[2]);
      if (n1.norm() < 1e-14 || n0.dot(n1) <= kCollapseNormalCosine * n0.norm() * n1.norm()) {
        return false;
      }
    }
    return true;
  }

  void CollapseShortEdges(double low, double high) {
    const size_t n = mesh_.n_edges();
    for (size_t i = 0; i < n; ++i) {
      const auto eh = mesh_.edge_handle(static_cast<int>(i));
      if (mesh_.status(eh).deleted()) continue;
      auto hh = mesh_.halfedge_handle(eh, 0);
      auto v0 = mesh_.from_vertex_handle(hh);
      auto v1 = mesh_.to_vertex_handle(hh);
      const Vec3 mid = 0.5 * (P(v0) + P(v1));
      if ((P(v0) - P(v1)).norm() >= low) continue;
      if (!mesh_.is_collapse_ok(hh)) {
        hh = mesh_.opposite_halfedge_handle(hh);
        std::swap(v0, v1);
        if (!mesh_.is_collapse_ok(hh)) continue;
      }
      bool ok = true;
      for (auto w : mesh_.vv_range(v0)) {
        if ((P(w) - mid).norm() > high) ok = false;
      }
      for (auto w : mesh_.vv_range(v1)) {
        if ((P(w) - mid).norm() > high) ok = false;
      }
      if (!ok || !KeepsOrientation(v0, mid, v1) || !KeepsOrientation(v1, mid, v0)) continue;
      mesh_.set_point(v1, ToOm(mid));
      mesh_.collapse(hh);
    }
    mesh_.garbage_collection();
  }

  void EqualizeValences() {
    for (auto eh : mesh_.edges()) {
      if (!mesh_.is_flip_ok(eh)) continue;
      const auto h0 = mesh_.halfedge_handle(eh, 0);
      const auto h1 = mesh_.halfedge_handle(eh, 1);
      const auto a = mesh_.to_vertex_handle(h0);
      const auto b = mesh_.to_vertex_handle(h1);
      const auto c = mesh_.to_vertex_handle(mesh_.next_halfedge_handle(h0));
      const auto d = mesh_.to_vertex_handle(mesh_.next_halfedge_handle(h1));
      auto dev = [](int valence) { return (valence - 6) * (valence - 6); };
      const int va = static_cast<int>(mesh_.valence(a)), vb = static_cast<int>(mesh_.valence(b));
      const int vc = static_cast<int>(mesh_.valence(c)), vd = static_cast<int>(mesh_.valence(d));
      if (va <= 3 || vb <= 3) continue;
      const int before = dev(va) + dev(vb) + dev(vc) + dev(vd);
      const int after = dev(va - 1) + dev(vb - 1) + dev(vc + 1) + dev(vd + 1);
      if (after >= before) continue;
      // Faces (a, c, b) and (b, d, a) become (c, d, b)... check both new faces against the
      // old normals so that no fold is introduced.
      const Vec3 n_old = FaceNormal(P(b), P(a), P(c)).normalized() +
                         FaceNormal(P(a), P(b), P(d)).normalized();
      const Vec3 n1 = FaceNormal(P(c), P(d), P(a));
      const Vec3 n2 = FaceNormal(P(d), P(c), P(b));
      if (n1.dot(n_old) <= 0.0 || n2.dot(n_old) <= 0.0) continue;
      const Vec3 f1 = FaceNormal(P(b), P(a), P(c)), f2 = FaceNormal(P(a), P(b), P(d));
      if (f1.normalized().dot(f2.normalized()) < kFlipCreaseCosine) continue;
      mesh_.flip(eh);
    }
  }

  void TangentialRelaxation() {
    mesh_.update_face_normals();
    mesh_.update_vertex_normals();
    std::vector<OpenMesh::Vec3d> updated(mesh_.n_vertices());
    for (auto vh : mesh_.vertices()) {
      Vec3 q = Vec3::Zero();
      int n = 0;
      for (auto w : mesh_.vv_range(vh)) {
        q += P(w);
        ++n;
      }
      const Vec3 p = P(vh);
      if (n == 0) {
        updated[vh.idx()] = ToOm(p);
        continue;
      }
      q /= n;
      const Vec3 normal = ToEigen(mesh_.normal(vh));
      const Vec3 moved = q + normal * normal.dot(p - q);
      updated[vh.idx()] = ToOm(moved);
    }
    for (auto vh : mesh_.vertices()) mesh_.set_point(vh, updated[vh.idx()]);
  }

  void Project() {
    const double eps = kGradientStep * body_.height;
    std::vector<OmMesh::VertexHandle> handles(mesh_.vertices().begin(), mesh_.vertices().end());
    tbb::parallel_for(tbb::blocked_range<size_t>(0, handles.size()),
                      [&](const tbb::blocked_range<size_t>& r) {
                        for (size_t i = r.begin(); i < r.end(); ++i) {
                          const Vec3 p = ProjectToSurface(body_, P(handles[i]),
                                                          options_.projection_iterations, eps,
                                                          kMaxProjectionStep * target_);
                          mesh_.point(handles[i]) = ToOm(p);
                        }
                      });
  }

  const Body& body_;
  OmMesh mesh_;
  double target_;
  const MeshingOptions& options_;
};

// ----------------------------------------------------------------------------------------------
// Mesh adjacency helpers.

std::vector<std::vector<int>> VertexNeighbours(int nv, const Eigen::MatrixX3i& tris) {
  std::vector<std::vector<int>> adj(nv);
  for (int f = 0; f < tris.rows(); ++f) {
    for (int q = 0; q < 3; ++q) {
      adj[tris(f, q)].push_back(tris(f, (q + 1) % 3));
      adj[tris(f, q)].push_back(tris(f, (q + 2) % 3));
    }
  }
  for (auto& a : adj) {
    std::sort(a.begin(), a.end());
    a.erase(std::unique(a.begin(), a.end()), a.end());
  }
  return adj;
}

// Splits every label into connected components (over `adjacent`) and relabels all but the
// largest component of each label with the most frequent label among their outside
// neighbours. Returns the number of relabelled items.
int MergeIslands(const std::vector<std::vector<int>>& adjacent, std::vector<int>* labels) {
  const int n = static_cast<int>(labels->size());
  std::vector<int> component(n, -1);
  std::vector<int> component_size;
  std::vector<int> component_label;
  for (int s = 0; s < n; ++s) {
    if (component[s] >= 0) continue;
    const int id = static_cast<int>(component_size.size());
    component_size.push_back(0);
    component_label.push_back((*labels)[s]);
    std::vector<int> stack = {s};
    component[s] = id;
    while (!stack.empty()) {
      const int x = stack.back();
      stack.pop_back();
      ++component_size[id];
      for (int y : adjacent[x]) {
        if (component[y] < 0 && (*labels)[y] == (*labels)[x]) {
          component[y] = id;
          stack.push_back(y);
        }
      }
    }
  }
  std::map<int, int> largest;  // label -> component id
  for (int id = 0; id < static_cast<int>(component_size.size()); ++id) {
    auto it = largest.find(component_label[id]);
    if (it == largest.end() || component_size[id] > component_size[it->second])
      largest[component_label[id]] = id;
  }
  int changed = 0;
  // Relabel island by island, smallest first, to the majority outside label.
  std::vector<int> order(component_size.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(),
                   [&](int a, int b) { return component_size[a] < component_size[b]; });
  std::vector<std::vector<int>> members(component_size.size());
  for (int x = 0; x < n; ++x) members[component[x]].push_back(x);
  for (int id : order) {
    if (largest[component_label[id]] == id) continue;
    std::map<int, int> votes;
    for (int x : members[id]) {
      for (int y : adjacent[x]) {
        if (component[y] != id) ++votes[(*labels)[y]];
      }
    }
    if (votes.empty()) continue;
    int best = -1, best_votes = -1;
    for (const auto& [label, v] : votes) {
      if (v > best_votes) {
        best = label;
        best_votes = v;
      }
    }
    for (int x : members[id]) {
      (*labels)[x] = best;
      component[x] = largest.count(best) ? largest[best] : id;
    }
    changed += static_cast<int>(members[id].size());
  }
  return changed;
}

int Depth(int joint) {
  int d = 0;
  for (int j = joint; kParents[j] >= 0; j = kParents[j]) ++d;
  return d;
}

bool InSubtree(int joint, int root) {
  for (int j = joint; j >= 0; j = kParents[j]) {
    if (j == root) return true;
  }
  return false;
}

// Segments may only touch their parent, children and siblings (otherwise the skinned surface
// would tear); offending vertices of the deeper segment move to its parent.
int FixSegmentAdjacency(const std::vector<std::vector<int>>& adj, std::vector<int>* joint) {
  int changed = 0;
  for (int round = 0; round < 64; ++round) {
    std::vector<int> move;
    for (int v = 0; v < static_cast<int>(adj.size()); ++v) {
      const int a = (*joint)[v];
      for (int w : adj[v]) {
        const int b = (*joint)[w];
        if (a == b || kParents[a] == b || kParents[b] == a || kParents[a] == kParents[b]) continue;
        const bool a_deeper = Depth(a) > Depth(b) || (Depth(a) == Depth(b) && a > b);
        if (a_deeper) {
          move.push_back(v);
          break;
        }
      }
    }
    if (move.empty()) return changed;
    for (int v : move) (*joint)[v] = kParents[(*joint)[v]];
    changed += static_cast<int>(move.size());
  }
  throw Error("template generator: body segmentation did not converge");
}

// Multi-source Dijkstra restricted to edges inside one segment (same label).
std::vector<double> SegmentDistance(const Eigen::MatrixX3d& verts,
                                    const std::vector<std::vector<int>>& adj,
                                    const std::vector<int>& label,
                                    const std::vector<char>& is_source) {
  const int n = static_cast<int>(adj.size());
  std::vector<double> dist(n, kInf);
  using Item = std::pair<double, int>;
  std::priority_queue<Item, std::vector<Item>, std::greater<Item>> queue;
  for (int v = 0; v < n; ++v) {
    if (is_source[v]) {
      dist[v] = 0.0;
      queue.emplace(0.0, v);
    }
  }
  while (!queue.empty()) {
    const auto [d, v] = queue.top();
    queue.pop();
    if (d > dist[v]) continue;
    for (int w : adj[v]) {
      if (label[w] != label[v]) continue;
      const double nd = d + (verts.row(v) - verts.row(w)).norm();
      if (nd < dist[w]) {
        dist[w] = nd;
        queue.emplace(nd, w);
      }
    }
  }
  return dist;
}

double SmoothStep(double x) {
  x = std::clamp(x, 0.0, 1.0);
  return x * x * (3.0 - 2.0 * x);
}

double BandHalfWidth(const SkinningBands& b, int joint) {
  switch (joint) {
    case kSpine: return b.spine;
    case kChest: return b.chest;
    case kNeck: return b.neck;
    case kHead: return b.head;
    case kLShoulder: case kRShoulder: return b.shoulder;
    case kLElbow: case kRElbow: return b.elbow;
    case kLWrist: case kRWrist: return b.wrist;
    case kLHip: case kRHip: return b.hip;
    case kLKnee: case kRKnee: return b.knee;
    case kLAnkle: case kRAnkle: return b.ankle;
    default: return 0.0;
  }
}

// Joint k of every vertex: dominant primitive group, then planes along the group's bones.
std::vector<int> SegmentBody(const Body& body, const SkinningBands& bands,
                             const Eigen::MatrixX3d& verts) {
  const double scale = body.height / kReferenceStature;
  const int nv = static_cast<int>(verts.rows());
  std::vector<int> joint(nv, kPelvis);
  auto past = [&](const Vec3& p, int j) {
    return (p - body.centre[j]).dot(body.incoming[j]) >= -BandHalfWidth(bands, j) * scale;
  };
  const double neck_radius = bands.neck_radius * scale;
  // Trunk side: hips below their planes (split at x = 0), the neck within neck_radius of its
  // axis above its plane, then chest / spine / pelvis by horizontal planes.
  auto trunk_joint = [&](const Vec3& p) {
    if (p.x() >= 0.0 && past(p, kLHip)) return static_cast<int>(kLHip);
    if (p.x() < 0.0 && past(p, kRHip)) return static_cast<int>(kRHip);
    const Vec3 r = p - body.centre[kNeck];
    const double radial = (r - r.dot(body.axis[kNeck]) * body.axis[kNeck]).norm();
    if (past(p, kNeck) && radial < neck_radius) {
      return static_cast<int>(past(p, kHead) ? kHead : kNeck);
    }
    return static_cast<int>(past(p, kChest) ? kChest : (past(p, kSpine) ? kSpine : kPelvis));
  };
  tbb::parallel_for(tbb::blocked_range<int>(0, nv), [&](const tbb::blocked_range<int>& r) {
    for (int v = r.begin(); v < r.end(); ++v) {
      const Vec3 p = verts.row(v).transpose();
      int root = -1;
      switch (body.DominantGroup(p)) {
        case Group::kTrunk:
          joint[v] = trunk_joint(p);
          continue;
        case Group::kNeckHead:
          joint[v] = past(p, kHead) ? kHead : (past(p, kNeck) ? kNeck : trunk_joint(p));
          continue;
        case Group::kLeftArm: root = kLShoulder; break;
        case Group::kRightArm: root = kRShoulder; break;
        case Group::kLeftLeg: root = kLHip; break;
        case Group::kRightLeg: root = kRHip; break;
      }
      // Limb vertices on the trunk side of the limb root's plane belong to the trunk.
      joint[v] = past(p, root + 2)   ? root + 2
                 : past(p, root + 1) ? root + 1
                 : past(p, root)     ? root
                                     : trunk_joint(p);
    }
  });
  return joint;
}

void ComputeSkinningConstants(const Body& body, const SkinningBands& bands,
                              const Eigen::MatrixX3d& verts,
                              const std::vector<std::vector<int>>& adj,
                              const std::vector<int>& joint, Eigen::VectorXd* w_l,
                              Eigen::VectorXd* tau) {
  const int nv = static_cast<int>(verts.rows());
  const double scale = body.height / kReferenceStature;
  std::vector<char> proximal(nv, 0), distal(nv, 0);
  for (int v = 0; v < nv; ++v) {
    const int k = joint[v];
    for (int w : adj[v]) {
      const int b = joint[w];
      if (b == k) continue;
      if (InSubtree(b, k)) distal[v] = 1; else proximal[v] = 1;
    }
  }
  const std::vector<double> g_p = SegmentDistance(verts, adj, joint, proximal);
  const std::vector<double> g_d = SegmentDistance(verts, adj, joint, distal);
  int num_children[kDefaultNumJoints] = {};
  for (int j = 1; j < kDefaultNumJoints; ++j) ++num_children[kParents[j]];
  w_l->resize(nv);
  tau->resize(nv);
  for (int v = 0; v < nv; ++v) {
    const int k = joint[v];
    if (k == kPelvis) {
      (*w_l)[v] = 1.0;
      (*tau)[v] = 1.0;
      continue;
    }
    if (!std::isfinite(g_p[v])) {
      std::ostringstream msg;
      msg << "template generator: segment " << kJointNames[k] << " does not touch its parent";
      throw Error(msg.str());
    }
    const double ramp = 2.0 * BandHalfWidth(bands, k) * scale;
    if (proximal[v]) {
      (*w_l)[v] = 0.0;
      (*tau)[v] = 0.0;
      continue;
    }
    if (std::isfinite(g_d[v])) {
      // Must reach w_l = tau = 1 at the children's border.
      const double span = g_p[v] + g_d[v];
      const double w = SmoothStep(g_p[v] / std::min(ramp, span));
      (*w_l)[v] = w;
      (*tau)[v] = num_children[k] == 1 ? std::clamp(g_p[v] / span, 0.0, 1.0) : w;
    } else {
      const double w = SmoothStep(g_p[v] / ramp);
      (*w_l)[v] = w;
      (*tau)[v] = w;
    }
  }
}

// ----------------------------------------------------------------------------------------------
// Charts.

Eigen::VectorXi AssignCharts(const Body& body, const Eigen::MatrixX3d& verts,
                             const Eigen::MatrixX3i& tris, const std::vector<int>& joint) {
  const int nf = static_cast<int>(tris.rows());
  std::vector<int> chart(nf);
  for (int f = 0; f < nf; ++f) {
    const int a = joint[tris(f, 0)], b = joint[tris(f, 1)], c = joint[tris(f, 2)];
    int k = (a == b || a == c) ? a : (b == c ? b : std::max({a, b, c}, [](int x, int y) {
      return Depth(x) < Depth(y) || (Depth(x) == Depth(y) && x < y);
    }));
    const Vec3 centroid = (verts.row(tris(f, 0)) + verts.row(tris(f, 1)) + verts.row(tris(f, 2)))
                              .transpose() / 3.0;
    Chart ch = Chart::kTorsoFront;
    switch (k) {
      case kPelvis: case kSpine: case kChest:
        ch = centroid.z() >= body.torso_mid_z ? Chart::kTorsoFront : Chart::kTorsoBack;
        break;
      case kNeck: case kHead:
        ch = centroid.z() >= body.head_mid_z ? Chart::kHeadFront : Chart::kHeadBack;
        break;
      case kLShoulder: ch = Chart::kLUpperArm; break;
      case kRShoulder: ch = Chart::kRUpperArm; break;
      case kLElbow: ch = Chart::kLForearm; break;
      case kRElbow: ch = Chart::kRForearm; break;
      case kLWrist: case kRWrist: {
        const int side = k == kLWrist ? 0 : 1;
        const bool palm = (centroid - body.centre[k]).dot(body.palm_normal[side]) >= 0.0;
        ch = side == 0 ? (palm ? Chart::kLPalm : Chart::kLHandBack)
                       : (palm ? Chart::kRPalm : Chart::kRHandBack);
        break;
      }
      case kLHip: ch = Chart::kLThigh; break;
      case kRHip: ch = Chart::kRThigh; break;
      case kLKnee: ch = Chart::kLShank; break;
      case kRKnee: ch = Chart::kRShank; break;
      case kLAnkle: case kRAnkle: {
        const double sx = k == kLAnkle ? 1.0 : -1.0;
        const bool lateral = sx * (centroid.x() - body.centre[k].x()) >= 0.0;
        if (k == kLAnkle) ch = lateral ? Chart::kLFootLateral : Chart::kLFootMedial;
        else ch = lateral ? Chart::kRFootLateral : Chart::kRFootMedial;
        break;
      }
      default: break;
    }
    chart[f] = static_cast<int>(ch);
  }
  // Triangle adjacency over shared edges, then island merging so that charts are connected.
  std::unordered_map<int64_t, int> edge_face;
  std::vector<std::vector<int>> adj(nf);
  const int64_t nv = verts.rows();
  for (int f = 0; f < nf; ++f) {
    for (int q = 0; q < 3; ++q) {
      int64_t a = tris(f, q), b = tris(f, (q + 1) % 3);
      if (a > b) std::swap(a, b);
      const int64_t key = a * nv + b;
      auto it = edge_face.find(key);
      if (it == edge_face.end()) {
        edge_face.emplace(key, f);
      } else {
        adj[f].push_back(it->second);
        adj[it->second].push_back(f);
      }
    }
  }
  for (int round = 0; round < 16 && MergeIslands(adj, &chart) > 0; ++round) {
  }
  return Eigen::Map<Eigen::VectorXi>(chart.data(), nf);
}

Eigen::VectorXd SeamCost(const Body& body, const Eigen::MatrixX3d& verts,
                         const std::vector<int>& joint) {
  const int nv = static_cast<int>(verts.rows());
  Eigen::VectorXd cost = Eigen::VectorXd::Zero(nv);
  for (int v = 0; v < nv; ++v) {
    const int k = joint[v];
    Vec3 seam;
    switch (k) {
      case kLShoulder: case kLElbow: seam = body.arm_seam[0]; break;
      case kRShoulder: case kRElbow: seam = body.arm_seam[1]; break;
      case kLHip: case kLKnee: seam = body.leg_seam[0]; break;
      case kRHip: case kRKnee: seam = body.leg_seam[1]; break;
      default: continue;
    }
    const Vec3 a = body.axis[k];
    Vec3 radial = verts.row(v).transpose() - body.centre[k];
    radial -= radial.dot(a) * a;
    if (radial.norm() < 1e-12) continue;
    cost[v] = 0.5 * (1.0 - radial.normalized().dot(seam));
  }
  return cost;
}

}  // namespace

// ------------------------------------------------------------------------------------------------

bool BodyShapeOptions::IsValid(std::string* error) const {
  return Check(InRange(height, 1.0, 2.3), "height", "a stature in [1.0, 2.3] m", height, error) &&
         Check(InRange(girth, 0.6, 1.6), "girth", "a value in [0.6, 1.6]", girth, error) &&
         Check(InRange(shoulder_width, 0.7, 1.3), "shoulder_width", "a value in [0.7, 1.3]",
               shoulder_width, error) &&
         Check(InRange(hip_width, 0.7, 1.3), "hip_width", "a value in [0.7, 1.3]", hip_width,
               error) &&
         Check(InRange(arm_length, 0.8, 1.2), "arm_length", "a value in [0.8, 1.2]", arm_length,
               error) &&
         Check(InRange(leg_length, 0.8, 1.2), "leg_length", "a value in [0.8, 1.2]", leg_length,
               error) &&
         Check(InRange(arm_angle_deg, 0.0, 80.0), "arm_angle_deg", "an angle in [0, 80] degrees",
               arm_angle_deg, error) &&
         Check(resolution == 0 || resolution == 1, "resolution", "0 (coarse) or 1 (default)",
               resolution, error) &&
         Check(atlas_size >= 256, "atlas_size", "at least 256 texels", atlas_size, error) &&
         Check(InRange(atlas_padding_texels, 0.0, atlas_size / 8.0), "atlas_padding_texels",
               "a value in [0, atlas_size / 8]", atlas_padding_texels, error);
}

namespace {
bool CheckSections(const BodyProportions& bp, std::string* error) {
  const auto& sec = bp.torso_sections;
  if (!Check(sec.size() >= 2, "torso_sections", "at least 2 sections",
             static_cast<double>(sec.size()), error))
    return false;
  for (size_t i = 0; i < sec.size(); ++i) {
    const std::string name = "torso_sections[" + std::to_string(i) + "]";
    if (!Check(InRange(sec[i].y, 0.0, 1.0) && (i == 0 || sec[i].y > sec[i - 1].y), name + ".y",
               "heights in (0, 1) increasing with the index", sec[i].y, error) ||
        !Check(InRange(sec[i].half_width, 1e-3, 0.5), name + ".half_width",
               "a ratio in [0.001, 0.5]", sec[i].half_width, error) ||
        !Check(InRange(sec[i].half_depth, 1e-3, 0.5), name + ".half_depth",
               "a ratio in [0.001, 0.5]", sec[i].half_depth, error) ||
        !Check(InRange(sec[i].centre_z, -0.5, 0.5), name + ".centre_z", "a ratio in [-0.5, 0.5]",
               sec[i].centre_z, error))
      return false;
  }
  return Check(bp.hip_section_top < bp.shoulder_section_bottom, "hip_section_top",
               "below shoulder_section_bottom", bp.hip_section_top, error);
}
}  // namespace

bool BodyProportions::IsValid(std::string* error) const {
  const double values[] = {ankle_height, hip_height, hip_half_spacing, thigh_length, shank_length,
                           pelvis_height, spine_height, chest_height, neck_height,
                           head_joint_height, shoulder_height, shoulder_half_breadth,
                           upper_arm_length, forearm_length, hand_length, palm_fraction,
                           neck_base_radius, neck_top_radius,
                           deltoid_radius, upper_arm_radius_top, upper_arm_radius_bottom,
                           forearm_radius_top, forearm_radius_bulge, forearm_bulge_fraction,
                           forearm_radius_wrist, palm_half_width, trapezius_radius,
                           thigh_muscle_radius, thigh_muscle_fraction,
                           finger_half_width, fingertip_half_width, hand_flattening,
                           thumb_length, thumb_radius, thigh_radius_top, thigh_radius_bottom,
                           shank_radius_top, calf_radius, calf_fraction, shank_radius_ankle,
                           foot_length, foot_half_width, foot_half_height, foot_rounding,
                           blend_trunk, blend_limb_root, blend_limb, blend_hand,
                           neck_extension_bottom, neck_extension_top, torso_cap_rounding,
                           trapezius_neck_x, trapezius_taper, acromion_rise, acromion_inset,
                           deltoid_offset, forearm_bulge_length, palm_start_offset,
                           thumb_base_fraction, thumb_base_offset, thumb_taper,
                           thigh_muscle_length, calf_length, calf_back_offset,
                           foot_ball_fraction, heel_width};
  for (double v : values) {
    if (!(std::isfinite(v) && v > 0.0 && v < 1.0)) {
      return Check(false, "body proportions", "every ratio in (0, 1) of the stature", v, error);
    }
  }
  return Check(InRange(leg_spread_deg, 0.0, 30.0), "leg_spread_deg", "an angle in [0, 30]",
               leg_spread_deg, error) &&
         Check(InRange(thumb_angle_deg, 0.0, 90.0), "thumb_angle_deg", "an angle in [0, 90]",
               thumb_angle_deg, error) &&
         Check(InRange(instep_height, 0.1, 4.0), "instep_height", "a value in [0.1, 4]",
               instep_height, error) &&
         Check(InRange(heel_radius, 0.1, 4.0), "heel_radius", "a value in [0.1, 4]", heel_radius,
               error) &&
         Check(InRange(neck_base_z, -0.1, 0.1), "neck_base_z", "a ratio in [-0.1, 0.1]",
               neck_base_z, error) &&
         Check(InRange(trapezius_neck_z, -0.1, 0.1), "trapezius_neck_z",
               "a ratio in [-0.1, 0.1]", trapezius_neck_z, error) &&
         Check(ankle_height < hip_height && hip_height < pelvis_height &&
                   pelvis_height < spine_height && spine_height < chest_height &&
                   chest_height < neck_height && neck_height < head_joint_height &&
                   head_joint_height < 1.0,
               "body proportions", "joint heights increasing from ankle to head",
               head_joint_height, error) &&
         Check(foot_rounding < std::min(foot_half_width, foot_half_height), "foot_rounding",
               "less than the foot half width and half height", foot_rounding, error) &&
         CheckSections(*this, error) &&
         Check(buttock_semi_axes.minCoeff() > 0 &&
                   head_semi_axes.minCoeff() > 0 && jaw_semi_axes.minCoeff() > 0 &&
                   nose_semi_axes.minCoeff() > 0,
               "body proportions", "positive ellipsoid semi-axes", 0.0, error);
}

bool SkinningBands::IsValid(std::string* error) const {
  const double values[] = {spine, chest, neck, head,  shoulder, elbow,
                           wrist, hip,   knee, ankle, neck_radius};
  for (double v : values) {
    if (!InRange(v, 1e-3, 0.2)) {
      return Check(false, "skinning bands", "half widths in [0.001, 0.2] m", v, error);
    }
  }
  return true;
}

bool MeshingOptions::IsValid(std::string* error) const {
  return Check(InRange(grid_cell, 1e-3, 0.02), "meshing.grid_cell",
               "a fraction of the stature in [0.001, 0.02]", grid_cell, error) &&
         Check(InRange(grid_cell_coarse, 1e-3, 0.02), "meshing.grid_cell_coarse",
               "a fraction of the stature in [0.001, 0.02]", grid_cell_coarse, error) &&
         Check(target_vertices_coarse >= 500 && target_vertices_coarse <= 200000,
               "meshing.target_vertices_coarse", "a count in [500, 200000]",
               target_vertices_coarse, error) &&
         Check(target_vertices_default >= 500 && target_vertices_default <= 200000,
               "meshing.target_vertices_default", "a count in [500, 200000]",
               target_vertices_default, error) &&
         Check(InRange(edge_length_factor, 0.25, 4.0), "meshing.edge_length_factor",
               "a value in [0.25, 4]", edge_length_factor, error) &&
         Check(remesh_iterations >= 1 && remesh_iterations <= 50, "meshing.remesh_iterations",
               "a count in [1, 50]", remesh_iterations, error) &&
         Check(projection_iterations >= 1 && projection_iterations <= 20,
               "meshing.projection_iterations", "a count in [1, 20]", projection_iterations,
               error) &&
         Check(InRange(min_part_component, 0.0, 1.0), "meshing.min_part_component",
               "a fraction in [0, 1]", min_part_component, error);
}

const char* const* DefaultJointNames() { return kJointNames; }

bool IsClosedManifoldSphere(int num_vertices, const Eigen::MatrixX3i& triangles,
                            std::string* error) {
  std::ostringstream msg;
  auto fail = [&]() {
    if (error) *error = msg.str();
    return false;
  };
  const int nf = static_cast<int>(triangles.rows());
  if (nf == 0 || num_vertices == 0) {
    msg << "mesh: expected a non-empty mesh";
    return fail();
  }
  if (triangles.minCoeff() < 0 || triangles.maxCoeff() >= num_vertices) {
    msg << "triangles: vertex index out of range";
    return fail();
  }
  // Directed edges must be unique and each must have its reverse.
  std::unordered_map<int64_t, int> directed;
  directed.reserve(3 * nf);
  const int64_t n = num_vertices;
  for (int f = 0; f < nf; ++f) {
    for (int q = 0; q < 3; ++q) {
      const int64_t a = triangles(f, q), b = triangles(f, (q + 1) % 3);
      if (a == b) {
        msg << "triangle " << f << ": repeated vertex " << a;
        return fail();
      }
      if (!directed.emplace(a * n + b, f).second) {
        msg << "edge (" << a << ", " << b << "): used twice in the same direction "
            << "(non-manifold or inconsistently oriented), triangle " << f;
        return fail();
      }
    }
  }
  for (const auto& [key, f] : directed) {
    const int64_t a = key / n, b = key % n;
    if (!directed.count(b * n + a)) {
      msg << "edge (" << a << ", " << b << "): expected two triangles, found one (triangle "
          << f << ")";
      return fail();
    }
  }
  // Vertex links: for each vertex, the map next[b] = c over its triangles (v, b, c) must be a
  // single cycle.
  std::vector<std::vector<std::pair<int, int>>> link(num_vertices);
  for (int f = 0; f < nf; ++f) {
    for (int q = 0; q < 3; ++q) {
      link[triangles(f, q)].emplace_back(triangles(f, (q + 1) % 3), triangles(f, (q + 2) % 3));
    }
  }
  for (int v = 0; v < num_vertices; ++v) {
    if (link[v].empty()) {
      msg << "vertex " << v << ": not used by any triangle";
      return fail();
    }
    std::unordered_map<int, int> next(link[v].begin(), link[v].end());
    int steps = 0;
    int x = link[v][0].first;
    do {
      x = next[x];
      ++steps;
    } while (x != link[v][0].first && steps <= static_cast<int>(link[v].size()));
    if (steps != static_cast<int>(link[v].size())) {
      msg << "vertex " << v << ": its triangles do not form a single fan (non-manifold vertex)";
      return fail();
    }
  }
  // One component, Euler characteristic 2.
  std::vector<int> parent(num_vertices);
  std::iota(parent.begin(), parent.end(), 0);
  auto find = [&](int x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  };
  for (int f = 0; f < nf; ++f) {
    parent[find(triangles(f, 0))] = find(triangles(f, 1));
    parent[find(triangles(f, 1))] = find(triangles(f, 2));
  }
  int components = 0;
  for (int v = 0; v < num_vertices; ++v) components += find(v) == v;
  if (components != 1) {
    msg << "mesh: expected one connected component, found " << components;
    return fail();
  }
  const int64_t edges = static_cast<int64_t>(directed.size()) / 2;
  const int64_t euler = num_vertices - edges + nf;
  if (euler != 2) {
    msg << "mesh: expected Euler characteristic 2 (a sphere), found " << euler;
    return fail();
  }
  return true;
}

Template GenerateTemplate(const BodyShapeOptions& options) {
  return GenerateTemplate(options, TemplateGeneratorOptions(), nullptr);
}

Template GenerateTemplate(const BodyShapeOptions& options,
                          const TemplateGeneratorOptions& generator,
                          TemplateGeneratorSummary* summary) {
  std::string error;
  if (!options.IsValid(&error)) throw Error("body shape options: " + error);
  if (!generator.proportions.IsValid(&error)) throw Error("body proportions: " + error);
  if (!generator.bands.IsValid(&error)) throw Error("skinning bands: " + error);
  if (!generator.meshing.IsValid(&error)) throw Error("meshing options: " + error);
  UvAtlasOptions atlas_options = generator.atlas;
  atlas_options.atlas_size = options.atlas_size;
  atlas_options.padding_texels = options.atlas_padding_texels;
  if (!atlas_options.IsValid(&error)) throw Error("uv atlas options: " + error);

  TemplateGeneratorSummary local_summary;
  TemplateGeneratorSummary& sum = summary ? *summary : local_summary;
  sum = TemplateGeneratorSummary();
  using Clock = std::chrono::steady_clock;
  auto seconds_since = [](Clock::time_point t0) {
    return std::chrono::duration<double>(Clock::now() - t0).count();
  };

  const MeshingOptions& meshing = generator.meshing;
  const double cell =
      (options.resolution == 0 ? meshing.grid_cell_coarse : meshing.grid_cell) * options.height;
  auto t0 = Clock::now();
  const Body body = BuildBody(options, generator.proportions, cell);
  TriangleMesh iso = ExtractIsoSurface(body, cell);
  sum.removed_components = KeepLargestComponent(&iso);
  sum.grid_vertices = static_cast<int>(iso.vertices.size());
  sum.seconds_field = seconds_since(t0);

  // Target edge length from the surface area: an ideal mesh of equilateral triangles with
  // F = 2V has area 2V * sqrt(3)/4 * L^2.
  t0 = Clock::now();
  double area = 0.0;
  for (const auto& t : iso.triangles) {
    area += 0.5 * FaceNormal(iso.vertices[t[0]], iso.vertices[t[1]], iso.vertices[t[2]]).norm();
  }
  const int target_vertices =
      options.resolution == 0 ? meshing.target_vertices_coarse : meshing.target_vertices_default;
  const double edge_length =
      meshing.edge_length_factor * std::sqrt(2.0 * area / (std::sqrt(3.0) * target_vertices));
  sum.target_edge_length = edge_length;
  Remesher remesher(body, iso, edge_length, meshing);
  remesher.Run();
  const TriangleMesh mesh = remesher.Result();
  sum.seconds_remesh = seconds_since(t0);

  Template tmpl;
  const int nv = static_cast<int>(mesh.vertices.size());
  const int nf = static_cast<int>(mesh.triangles.size());
  tmpl.vertices.resize(nv, 3);
  for (int v = 0; v < nv; ++v) tmpl.vertices.row(v) = mesh.vertices[v].transpose();
  tmpl.triangles.resize(nf, 3);
  for (int f = 0; f < nf; ++f) {
    tmpl.triangles.row(f) = Eigen::RowVector3i(mesh.triangles[f][0], mesh.triangles[f][1],
                                               mesh.triangles[f][2]);
  }
  if (!IsClosedManifoldSphere(nv, tmpl.triangles, &error)) {
    throw Error("template generator: the generated surface is not a closed 2-manifold sphere: " +
                error);
  }
  double volume = 0.0;
  area = 0.0;
  for (int f = 0; f < nf; ++f) {
    const Vec3 a = tmpl.vertices.row(tmpl.triangles(f, 0)).transpose();
    const Vec3 b = tmpl.vertices.row(tmpl.triangles(f, 1)).transpose();
    const Vec3 c = tmpl.vertices.row(tmpl.triangles(f, 2)).transpose();
    volume += a.dot(b.cross(c)) / 6.0;
    area += 0.5 * (b - a).cross(c - a).norm();
  }
  sum.surface_area = area;
  sum.volume = volume;
  if (!(volume > 0.0)) {
    throw Error("template generator: the generated surface is not oriented outwards (volume " +
                std::to_string(volume) + ")");
  }

  // Joints.
  tmpl.joints.resize(kDefaultNumJoints);
  for (int j = 0; j < kDefaultNumJoints; ++j) {
    tmpl.joints[j].name = kJointNames[j];
    tmpl.joints[j].parent = kParents[j];
    tmpl.joints[j].center = body.centre[j];
    tmpl.joints[j].twist_axis = body.axis[j].normalized();
  }

  // Segmentation and skinning constants.
  t0 = Clock::now();
  const auto adj = VertexNeighbours(nv, tmpl.triangles);
  std::vector<int> joint = SegmentBody(body, generator.bands, tmpl.vertices);
  for (int round = 0; round < 16; ++round) {
    const int a = MergeIslands(adj, &joint);
    const int b = FixSegmentAdjacency(adj, &joint);
    sum.relabelled_vertices += a + b;
    if (a == 0 && b == 0) break;
  }
  Eigen::VectorXd w_l, tau;
  ComputeSkinningConstants(body, generator.bands, tmpl.vertices, adj, joint, &w_l, &tau);
  tmpl.vertex_joint = Eigen::Map<Eigen::VectorXi>(joint.data(), nv);
  tmpl.lbs_weight = w_l;
  tmpl.slerp_tau = tau;
  sum.seconds_skinning = seconds_since(t0);

  // UV atlas.
  t0 = Clock::now();
  if (!generator.build_atlas) {
    if (!tmpl.IsValid(&error)) throw Error("template generator: invalid result: " + error);
    return tmpl;
  }
  tmpl.triangle_chart = AssignCharts(body, tmpl.vertices, tmpl.triangles, joint);
  UvAtlas atlas;
  BuildUvAtlas(tmpl.vertices, tmpl.triangles, tmpl.triangle_chart,
               SeamCost(body, tmpl.vertices, joint), atlas_options, &atlas, &sum.atlas);
  tmpl.uvs = atlas.uvs;
  tmpl.uv_triangles = atlas.uv_triangles;
  sum.seconds_atlas = seconds_since(t0);

  if (!tmpl.IsValid(&error)) throw Error("template generator: invalid result: " + error);
  return tmpl;
}

}  // namespace artex
