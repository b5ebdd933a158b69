#include "sensors/motion.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <sstream>

#include "models/error.h"
#include "models/numeric.h"
#include "models/so3.h"

namespace artex {
namespace {

// The default joint names in index order (models/template_generator.h).
constexpr int kNumMotionJoints = 17;
constexpr std::array<const char*, kNumMotionJoints> kJointNames = {
    "pelvis",  "spine",   "chest",      "neck",    "head",    "l_shoulder",
    "l_elbow", "l_wrist", "r_shoulder", "r_elbow", "r_wrist", "l_hip",
    "l_knee",  "l_ankle", "r_hip",      "r_knee",  "r_ankle"};

struct MotionName {
  MotionType type;
  const char* name;
};
constexpr std::array<MotionName, 6> kMotionNames = {{{MotionType::kWalk, "walk"},
                                                     {MotionType::kArmRaise, "arm_raise"},
                                                     {MotionType::kTurn, "turn"},
                                                     {MotionType::kBend, "bend"},
                                                     {MotionType::kStill, "still"},
                                                     {MotionType::kPunchKick, "punch_kick"}}};

// Indices of the default joints in a template, looked up by name.
struct Skeleton {
  int pelvis, spine, chest, neck, head;
  int l_shoulder, l_elbow, l_wrist, r_shoulder, r_elbow, r_wrist;
  int l_hip, l_knee, l_ankle, r_hip, r_knee, r_ankle;
};

Skeleton FindSkeleton(const Template& tmpl) {
  std::array<int, kNumMotionJoints> idx;
  std::string missing;
  for (int i = 0; i < kNumMotionJoints; ++i) {
    idx[i] = tmpl.FindJoint(kJointNames[i]);
    if (idx[i] < 0) missing += std::string(missing.empty() ? "" : ", ") + kJointNames[i];
  }
  if (!missing.empty()) {
    throw Error("GenerateMotion: template joints: expected the default joint names, missing " +
                missing);
  }
  return Skeleton{idx[0], idx[1],  idx[2],  idx[3],  idx[4],  idx[5],  idx[6],  idx[7], idx[8],
                  idx[9], idx[10], idx[11], idx[12], idx[13], idx[14], idx[15], idx[16]};
}

// Minimum-jerk ramp 0 -> 1 on [0, 1] (zero velocity and acceleration at both ends).
double MinimumJerk(double x) {
  x = std::clamp(x, 0.0, 1.0);
  return x * x * x * (10.0 + x * (-15.0 + 6.0 * x));
}

Eigen::Matrix3d Rot(const Eigen::Vector3d& axis, double angle_rad) {
  return ExpSO3(axis.normalized() * angle_rad);
}

Eigen::Vector3d BoneDirection(const Template& tmpl, int from, int to) {
  const Eigen::Vector3d d = tmpl.joints[to].center - tmpl.joints[from].center;
  if (d.norm() <= 0.0)
    throw Error("GenerateMotion: template joints '" + tmpl.joints[from].name + "' and '" +
                tmpl.joints[to].name + "' coincide");
  return d.normalized();
}

// Axis about which a positive rotation moves bone direction d towards +Z (anterior).
Eigen::Vector3d AnteriorAxis(const Eigen::Vector3d& d) {
  const Eigen::Vector3d a = d.cross(Eigen::Vector3d::UnitZ());
  return a.norm() > 1e-9 ? a.normalized() : Eigen::Vector3d::UnitX();
}

// Axis about which a positive rotation moves bone direction d upwards (abduction for arms).
Eigen::Vector3d RaisingAxis(const Eigen::Vector3d& d) {
  const Eigen::Vector3d a = d.cross(Eigen::Vector3d::UnitY());
  return a.norm() > 1e-9 ? a.normalized() : Eigen::Vector3d::UnitZ();
}

// Anatomical axes of one arm, from the template's rest joints.
struct ArmAxes {
  Eigen::Vector3d shoulder_flexion, shoulder_abduction, elbow_flexion, forearm_twist;
};

ArmAxes ComputeArmAxes(const Template& tmpl, int shoulder, int elbow, int wrist) {
  const Eigen::Vector3d upper = BoneDirection(tmpl, shoulder, elbow);
  const Eigen::Vector3d fore = BoneDirection(tmpl, elbow, wrist);
  return ArmAxes{AnteriorAxis(upper), RaisingAxis(upper), AnteriorAxis(fore),
                 tmpl.joints[elbow].twist_axis.normalized()};
}

class MotionBuilder {
 public:
  MotionBuilder(const Template& tmpl, const MotionOptions& options)
      : tmpl_(tmpl), options_(options), sk_(FindSkeleton(tmpl)) {
    left_arm_ = ComputeArmAxes(tmpl, sk_.l_shoulder, sk_.l_elbow, sk_.l_wrist);
    right_arm_ = ComputeArmAxes(tmpl, sk_.r_shoulder, sk_.r_elbow, sk_.r_wrist);
  }

  Pose At(double t) const {
    Pose pose = Pose::Identity(tmpl_.num_joints());
    const double phase = 2.0 * M_PI * t / options_.period_s;
    const double ramp = options_.ramp_s > 0.0 ? MinimumJerk(t / options_.ramp_s) : 1.0;
    // Raise-and-lower profile (starts at rest with zero velocity).
    const double bump = 0.5 * (1.0 - std::cos(phase)) * options_.amplitude;
    switch (options_.type) {
      case MotionType::kWalk:
        Walk(phase, ramp * options_.amplitude, &pose);
        break;
      case MotionType::kArmRaise:
        ArmRaise(bump, &pose);
        break;
      case MotionType::kTurn:
        Turn(phase, ramp * options_.amplitude, &pose);
        break;
      case MotionType::kBend:
        Bend(bump, &pose);
        break;
      case MotionType::kPunchKick:
        PunchKick(t, &pose);
        break;
      case MotionType::kStill:
        break;
    }
    return pose;
  }

  // Lift of the whole body above the floor placement (m): the flight of the punch_kick jump.
  double Lift(double t) const {
    if (options_.type != MotionType::kPunchKick) return 0.0;
    const PunchKickShape& s = options_.punch_kick;
    const double cycle = t / s.move_s;
    const int move = static_cast<int>(std::floor(cycle)) % 4;
    const double u = cycle - std::floor(cycle);
    if (move != 3 || u < 0.35 || u > 0.65) return 0.0;
    return options_.amplitude * s.jump_height_m * std::sin(M_PI * (u - 0.35) / 0.3);
  }

 private:
  void Walk(double phase, double a, Pose* pose) const {
    const WalkShape& w = options_.walk;
    const Eigen::Vector3d x = Eigen::Vector3d::UnitX(), y = Eigen::Vector3d::UnitY();
    auto& r = pose->joint_rotations;
    auto leg = [&](double p, int hip, int knee, int ankle) {
      const double flexion = a * w.hip_flexion_deg * kDegToRad * std::sin(p);
      const double swing = 0.5 * (1.0 + std::cos(p));  // 1 in mid swing, 0 in mid stance
      const double knee_flexion = a * w.knee_flexion_deg * kDegToRad * swing * swing;
      const double shank_pitch = -flexion + knee_flexion;  // about +x (positive: backwards)
      r[hip] = Rot(x, -flexion);
      r[knee] = Rot(x, knee_flexion);
      r[ankle] = Rot(x, -w.ankle_compensation * shank_pitch);
    };
    leg(phase, sk_.l_hip, sk_.l_knee, sk_.l_ankle);
    leg(phase + M_PI, sk_.r_hip, sk_.r_knee, sk_.r_ankle);
    auto arm = [&](double p, const ArmAxes& axes, int shoulder, int elbow) {
      // Opposite to the same side's hip: p is the other leg's phase.
      r[shoulder] = Rot(axes.shoulder_flexion, a * w.arm_swing_deg * kDegToRad * std::sin(p));
      r[elbow] = Rot(axes.elbow_flexion,
                     a * (w.elbow_flexion_deg + w.elbow_swing_deg * std::sin(p)) * kDegToRad);
    };
    arm(phase + M_PI, left_arm_, sk_.l_shoulder, sk_.l_elbow);
    arm(phase, right_arm_, sk_.r_shoulder, sk_.r_elbow);
    // Left leg forward (sin > 0) turns the pelvis' left side forward: negative yaw.
    const double yaw = -a * w.pelvis_yaw_deg * kDegToRad * std::sin(phase);
    r[sk_.pelvis] = Rot(y, yaw);
    r[sk_.spine] = Rot(y, -0.5 * w.thorax_counter_yaw * yaw);
    r[sk_.chest] = Rot(y, -0.5 * w.thorax_counter_yaw * yaw);
    // The head keeps facing forward: undo the thorax' net yaw.
    r[sk_.neck] = Rot(y, (w.thorax_counter_yaw - 1.0) * yaw);
  }

  void ArmRaise(double u, Pose* pose) const {
    const ArmRaiseShape& s = options_.arm_raise;
    auto& r = pose->joint_rotations;
    auto arm = [&](const ArmAxes& axes, double side, int shoulder, int elbow) {
      r[shoulder] = Rot(axes.shoulder_abduction, u * s.abduction_deg * kDegToRad);
      r[elbow] = Rot(axes.elbow_flexion, u * s.elbow_flexion_deg * kDegToRad) *
                 Rot(axes.forearm_twist, side * u * s.forearm_twist_deg * kDegToRad);
    };
    arm(left_arm_, 1.0, sk_.l_shoulder, sk_.l_elbow);
    arm(right_arm_, -1.0, sk_.r_shoulder, sk_.r_elbow);
  }

  void Turn(double phase, double a, Pose* pose) const {
    const TurnShape& s = options_.turn;
    const Eigen::Vector3d y = Eigen::Vector3d::UnitY();
    const double yaw = a * s.yaw_deg * kDegToRad * std::sin(phase);
    pose->rotation = Rot(y, yaw);
    // Rotate about the vertical line through the rest pelvis centre.
    const Eigen::Vector3d c = tmpl_.joints[sk_.pelvis].center;
    pose->translation = c - pose->rotation * c;
    pose->translation.y() = 0.0;
    pose->joint_rotations[sk_.neck] = Rot(y, 0.5 * s.head_follow * yaw);
    pose->joint_rotations[sk_.head] = Rot(y, 0.5 * s.head_follow * yaw);
  }

  void Bend(double u, Pose* pose) const {
    const BendShape& s = options_.bend;
    const Eigen::Vector3d x = Eigen::Vector3d::UnitX();
    auto& r = pose->joint_rotations;
    const double tilt = u * s.pelvis_tilt_deg * kDegToRad;
    r[sk_.pelvis] = Rot(x, tilt);
    r[sk_.l_hip] = Rot(x, -tilt);  // thighs stay vertical: the hips flex
    r[sk_.r_hip] = Rot(x, -tilt);
    r[sk_.spine] = Rot(x, u * s.spine_flexion_deg * kDegToRad);
    r[sk_.chest] = Rot(x, u * s.chest_flexion_deg * kDegToRad);
    const double trunk =
        u * (s.pelvis_tilt_deg + s.spine_flexion_deg + s.chest_flexion_deg) * kDegToRad;
    const double adduction = -u * s.arm_adduction_deg * kDegToRad;
    r[sk_.l_shoulder] = Rot(x, -s.arm_hang * trunk) * Rot(left_arm_.shoulder_abduction, adduction);
    r[sk_.r_shoulder] = Rot(x, -s.arm_hang * trunk) * Rot(right_arm_.shoulder_abduction, adduction);
    r[sk_.neck] = Rot(x, -u * s.neck_extension_deg * kDegToRad);
  }

  void PunchKick(double t, Pose* pose) const {
    const PunchKickShape& s = options_.punch_kick;
    const Eigen::Vector3d x = Eigen::Vector3d::UnitX();
    auto& r = pose->joint_rotations;
    const double cycle = t / s.move_s;
    const int move = static_cast<int>(std::floor(cycle)) % 4;
    const double u = cycle - std::floor(cycle);
    const double a = options_.amplitude * kDegToRad;
    const double out = std::pow(std::sin(M_PI * u), 2);            // out and back
    const double chamber = std::pow(std::sin(2.0 * M_PI * u), 2);  // twice: out and back
    auto punch = [&](const ArmAxes& axes, int shoulder, int elbow) {
      r[shoulder] = Rot(axes.shoulder_flexion, a * s.punch_shoulder_deg * out);
      r[elbow] = Rot(axes.elbow_flexion, a * s.punch_elbow_deg * chamber);
    };
    switch (move) {
      case 0:
        punch(right_arm_, sk_.r_shoulder, sk_.r_elbow);
        break;
      case 1:
        punch(left_arm_, sk_.l_shoulder, sk_.l_elbow);
        break;
      case 2:
        r[sk_.r_hip] = Rot(x, -a * s.kick_hip_deg * out);
        r[sk_.r_knee] = Rot(x, a * s.kick_knee_deg * chamber);
        break;
      default: {
        // Crouch before take-off (u ~ 0.25) and after landing (u ~ 0.75), straight in flight.
        const double crouch = a * s.jump_crouch_knee_deg * chamber;
        for (auto [hip, knee, ankle] : {std::array<int, 3>{sk_.l_hip, sk_.l_knee, sk_.l_ankle},
                                        std::array<int, 3>{sk_.r_hip, sk_.r_knee, sk_.r_ankle}}) {
          r[hip] = Rot(x, -0.5 * crouch);
          r[knee] = Rot(x, crouch);
          r[ankle] = Rot(x, -0.5 * crouch);
        }
        r[sk_.pelvis] = Rot(x, 0.3 * crouch);  // the trunk leans forward a little
        break;
      }
    }
  }

  const Template& tmpl_;
  const MotionOptions& options_;
  Skeleton sk_;
  ArmAxes left_arm_, right_arm_;
};

}  // namespace

bool MotionOptions::IsValid(std::string* error) const {
  std::ostringstream msg;
  if (frames < 1) {
    msg << "motion.frames: expected >= 1, found " << frames;
  } else if (!(frame_rate > 0.0) || !std::isfinite(frame_rate)) {
    msg << "motion.frame_rate: expected > 0 Hz, found " << frame_rate;
  } else if (!(amplitude >= 0.0 && amplitude <= 1.5)) {
    msg << "motion.amplitude: expected in [0, 1.5], found " << amplitude;
  } else if (!(period_s > 0.0) || !std::isfinite(period_s)) {
    msg << "motion.period_s: expected > 0 s, found " << period_s;
  } else if (!(ramp_s >= 0.0) || !std::isfinite(ramp_s)) {
    msg << "motion.ramp_s: expected >= 0 s, found " << ramp_s;
  } else if (!(walk.ankle_compensation >= 0.0 && walk.ankle_compensation <= 1.0)) {
    msg << "motion.walk.ankle_compensation: expected in [0, 1], found " << walk.ankle_compensation;
  } else if (!(speed > 0.0 && speed <= 8.0)) {
    msg << "motion.speed: expected in (0, 8], found " << speed;
  } else if (frame_step < 1) {
    msg << "motion.frame_step: expected >= 1, found " << frame_step;
  } else if (!(punch_kick.move_s > 0.0) || !std::isfinite(punch_kick.move_s)) {
    msg << "motion.punch_kick.move_s: expected > 0 s, found " << punch_kick.move_s;
  } else if (!(bend.arm_hang >= 0.0 && bend.arm_hang <= 1.0)) {
    msg << "motion.bend.arm_hang: expected in [0, 1], found " << bend.arm_hang;
  } else {
    return true;
  }
  if (error != nullptr) *error = msg.str();
  return false;
}

MotionType ParseMotionType(const std::string& name) {
  std::string valid;
  for (const MotionName& m : kMotionNames) {
    if (name == m.name) return m.type;
    valid += std::string(valid.empty() ? "" : ", ") + m.name;
  }
  throw Error("motion type: expected one of " + valid + ", found '" + name + "'");
}

const char* MotionTypeName(MotionType type) {
  for (const MotionName& m : kMotionNames) {
    if (m.type == type) return m.name;
  }
  return "unknown";
}

std::vector<Pose> GenerateMotion(const Template& tmpl, const MotionOptions& options) {
  std::string error;
  if (!options.IsValid(&error)) throw Error(error);
  const MotionBuilder builder(tmpl, options);
  std::vector<Pose> poses;
  poses.reserve(options.frames);
  const double frame_time = options.frame_step * options.speed / options.frame_rate;
  for (int f = 0; f < options.frames; ++f) poses.push_back(builder.At(f * frame_time));
  PlaceOnFloor(tmpl, options.floor, &poses);
  for (int f = 0; f < options.frames; ++f) poses[f].translation.y() += builder.Lift(f * frame_time);
  return poses;
}

double LowestFootHeight(const Template& tmpl, const Pose& pose) {
  const int num_joints = tmpl.num_joints();
  if (pose.num_joints() != num_joints) {
    throw Error("LowestFootHeight: pose has " + std::to_string(pose.num_joints()) +
                " joint rotations, template has " + std::to_string(num_joints) + " joints");
  }
  // Rigid chain transform x -> rot[j] x + trans[j] of T_root o ... o T_j.
  std::vector<Eigen::Matrix3d> rot(num_joints);
  std::vector<Eigen::Vector3d> trans(num_joints);
  for (int j = 0; j < num_joints; ++j) {
    const Eigen::Matrix3d& r = pose.joint_rotations[j];
    const Eigen::Vector3d& c = tmpl.joints[j].center;
    const int p = tmpl.joints[j].parent;
    const Eigen::Matrix3d parent_rot = p < 0 ? Eigen::Matrix3d::Identity() : rot[p];
    const Eigen::Vector3d parent_trans = p < 0 ? Eigen::Vector3d::Zero() : trans[p];
    rot[j] = parent_rot * r;
    trans[j] = parent_rot * (c - r * c) + parent_trans;
  }
  auto world_y = [&](int j, const Eigen::Vector3d& x) {
    return (pose.scale * (pose.rotation * (rot[j] * x + trans[j])) + pose.translation).y();
  };
  const int feet[2] = {tmpl.FindJoint("l_ankle"), tmpl.FindJoint("r_ankle")};
  const bool has_feet = feet[0] >= 0 || feet[1] >= 0;
  double lowest = std::numeric_limits<double>::infinity();
  if (tmpl.num_vertices() == 0) {
    for (int j : feet) {
      if (j >= 0) lowest = std::min(lowest, world_y(j, tmpl.joints[j].center));
    }
    if (!has_feet) {
      for (int j = 0; j < num_joints; ++j) {
        lowest = std::min(lowest, world_y(j, tmpl.joints[j].center));
      }
    }
    return lowest;
  }
  for (int v = 0; v < tmpl.num_vertices(); ++v) {
    const int j = tmpl.vertex_joint[v];
    if (has_feet && j != feet[0] && j != feet[1]) continue;
    lowest = std::min(lowest, world_y(j, tmpl.vertices.row(v).transpose()));
  }
  return lowest;
}

void PlaceOnFloor(const Template& tmpl, FloorMode mode, std::vector<Pose>* poses) {
  if (mode == FloorMode::kKeep || poses->empty()) return;
  std::vector<double> lowest(poses->size());
  for (size_t f = 0; f < poses->size(); ++f) lowest[f] = LowestFootHeight(tmpl, (*poses)[f]);
  if (mode == FloorMode::kPerFrame) {
    for (size_t f = 0; f < poses->size(); ++f) (*poses)[f].translation.y() -= lowest[f];
  } else {
    const double shift = *std::min_element(lowest.begin(), lowest.end());
    for (Pose& pose : *poses) pose.translation.y() -= shift;
  }
}

}  // namespace artex
