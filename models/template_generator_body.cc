// Template generator's implicit body (template_generator_internal.h): primitives, BuildBody.
#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <vector>

#include "models/numeric.h"
#include "models/template_generator_internal.h"

namespace artex {
namespace generator_internal {
namespace {

// Lower bound of the loft field's ratio to the true distance (its cross-section distance is an
// approximation and its sections change with height); used to cull it safely.
constexpr double kLoftLipschitz = 0.5;
// Primitives are culled beyond blend + this many grid cells (see Body::Field).
constexpr double kCullMarginCells = 3.0;

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

}  // namespace

double Primitive::Eval(const Vec3& p) const {
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

std::array<double, 4> Primitive::Section(double y) const {
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

double Primitive::LoftEval(const Vec3& p) const {
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

double Body::Field(const Vec3& p) const {
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

Vec3 Body::Gradient(const Vec3& p, double f, double eps) const {
  Vec3 g;
  for (int i = 0; i < 3; ++i) {
    Vec3 a = p;
    a[i] += eps;
    g[i] = (Field(a) - f) / eps;
  }
  return g;
}

Group Body::DominantGroup(const Vec3& p) const {
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
      const double t = std::clamp(
          (sec.y - bp.hip_section_top) / (bp.shoulder_section_bottom - bp.hip_section_top), 0.0,
          1.0);
      const double width = (1.0 - t) * shape.hip_width + t * shape.shoulder_width;
      sections.push_back(
          {y_of(sec.y), sec.half_width * h * g * width, sec.half_depth * h * g, sec.centre_z * h});
    }
    prims.push_back(MakeLoft(Group::kTrunk, blend_trunk, sections, bp.torso_cap_rounding));
  }
  for (int side = 0; side < 2; ++side) {
    const double sx = side == 0 ? 1.0 : -1.0;
    prims.push_back(MakeEllipsoid(Group::kTrunk, blend_trunk,
                                  Vec3(sx * bp.buttock_centre.x() * h * shape.hip_width * g,
                                       y_of(bp.buttock_centre.y()), bp.buttock_centre.z() * h * g),
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
  prims.push_back(MakeEllipsoid(Group::kNeckHead, blend_limb,
                                Vec3(0, y_of(bp.nose_centre.y()), bp.nose_centre.z() * h),
                                bp.nose_semi_axes * h));
  body.head_mid_z = head_centre.z();
  body.torso_mid_z = 0.0;
  for (const auto& sec : bp.torso_sections)
    body.torso_mid_z += sec.centre_z * h / bp.torso_sections.size();

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
    prims.push_back(
        MakeEllipsoid(group, blend_limb, c[js + 1] + bp.forearm_bulge_fraction * forearm * dir,
                      Vec3(bp.forearm_bulge_length * forearm, bp.forearm_radius_bulge * h * g,
                           bp.forearm_radius_bulge * h * g),
                      FrameFromAxis(dir, inner)));
    // Hand: flattened palm and finger cones (width along Z), thumb to the front.
    const Vec3 knuckles = c[js + 2] + bp.palm_fraction * hand * dir;
    const double tip_r = bp.fingertip_half_width * h;
    prims.push_back(MakeCone(group, blend_limb, c[js + 2] - bp.palm_start_offset * h * dir,
                             knuckles, bp.palm_half_width * h, bp.palm_half_width * h,
                             bp.hand_flattening, inner));
    prims.push_back(MakeCone(group, blend_hand, knuckles,
                             c[js + 2] + (hand - tip_r * bp.hand_flattening) * dir,
                             bp.finger_half_width * h, tip_r, bp.hand_flattening, inner));
    const Vec3 thumb_base = c[js + 2] + bp.thumb_base_fraction * hand * dir +
                            bp.thumb_base_offset * bp.palm_half_width * h * Vec3::UnitZ();
    const double thumb_angle = bp.thumb_angle_deg * kPi / 180.0;
    const Vec3 thumb_dir =
        (std::cos(thumb_angle) * dir + std::sin(thumb_angle) * Vec3::UnitZ()).normalized();
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
    prims.push_back(
        MakeEllipsoid(group, blend_limb, c[jh] + bp.thigh_muscle_fraction * thigh * dir,
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
    prims.push_back(
        MakeCone(group, blend_limb, c[jh + 2], ball, bp.shank_radius_ankle * h, half.y()));
    prims.push_back(MakeEllipsoid(
        group, blend_limb,
        Vec3(c[jh + 2].x(), bp.heel_radius * half.y(), heel_z + bp.heel_radius * half.y()),
        Vec3(bp.heel_width * half.x(), bp.heel_radius * half.y(), bp.heel_radius * half.y())));
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

}  // namespace generator_internal
}  // namespace artex
