// Subject shape model on top of a rigged template (docs/shape.md): per-bone
// lengths and per-segment girth change the rest pose (joint centres and rest vertices), the
// posed vertex stays the template's LBS + SLERP skinning (models/skinning.h) of that modified
// rest geometry, so the template's rig, skinning constants, triangles and UVs are kept.
//
// Full shape (2 J factors, all 1 for the unchanged template), J = joints:
//   bone_length[j] (j > 0): multiplies the rest offset t_j - t_parent(j) of joint j's centre
//     (the root's entry is unused and stays 1). Joint centres follow down the chain:
//     t_j = t_parent(j) + bone_length[j] (t0_j - t0_parent(j)).
//   girth[j]: radial scale about joint j's twist axis of the vertices of segment j.
// A vertex v of joint k (vertex_joint), rest offset v0 - t0_k = alpha a_k + rho (alpha axial
// along the unit twist axis a_k, rho perpendicular), is moved to
//   v = t_k + L_k alpha a_k + g_v rho,   g_v = w_l girth[k] + (1 - w_l) girth[parent(k)]
// (w_l the vertex's LBS weight: the girth blends across joints like the skinning; the root
// blends with itself). L_k, the segment's axial stretch, is the bone_length of k's child whose
// bone points along a_k (cosine >= 0.9; e.g. the upper arm stretches with the elbow's bone),
// for a leaf joint its own bone_length (the hand with the forearm), else 1. With `leaf_lengths`
// a leaf segment (head, hands, feet) has its own axial stretch leaf_length[k] instead: a foot's
// length is no shank's (a subject with long legs has no long feet). With `fork_widths` a bone
// mostly across its parent's twist axis (shoulders, hips: broad shoulders are wider, not
// higher) is t_j = t_parent + bone_length[j] o_axial + fork_width[j] o_lateral, o_axial and
// o_lateral the rest offset's components along and across the parent's twist axis. With
// `girth_depth` (bones_girth) each girth segment also has a depth factor: the component rho_d of
// rho along the segment's depth axis d_k (the template's forward axis +Z made perpendicular to
// a_k; +Y for a segment along Z, the feet) is scaled by a further D_v - 1, D_v blended across
// the joint like g_v: v = t_k + L_k alpha a_k + g_v rho + (D_v - 1) rho_d. A trunk or limb's
// cross-section then changes its proportions (width against depth), not only its size.
//
// Reduced parameters q (what the estimator optimises), full = 1 + E q, by mode:
//   kFixed: none (Q = 0); kScale: one factor for every bone length and girth (Q = 1);
//   kBones: one per bone (J - 1, or fewer with symmetry); kBonesGirth: bones then girths;
//   with leaf_lengths (kBones, kBonesGirth) then one per leaf segment ("length:<joint>"), with
//   fork_widths one per fork bone ("width:<joint>"), with girth_depth (kBonesGirth) one per
//   girth segment ("depth:<joint>").
// With `symmetric`, joints named l_X and r_X share their parameters (the l_ one is kept).
#pragma once

#include <Eigen/Core>
#include <map>
#include <string>
#include <vector>

#include "models/pose.h"
#include "models/template.h"

namespace artex {

enum class ShapeMode { kFixed, kScale, kBones, kBonesGirth };
const std::map<std::string, ShapeMode>& ShapeModeNames();  // fixed, scale, bones, bones_girth
const char* ShapeModeName(ShapeMode mode);

struct BodyShape {
  Eigen::VectorXd bone_length;  // J (entry 0, the root, unused)
  Eigen::VectorXd girth;        // J
  Eigen::VectorXd leaf_length;  // J: a leaf segment's own axial stretch (1 where unused)
  Eigen::VectorXd fork_width;   // J: a fork bone's lateral factor (1 where unused)
  Eigen::VectorXd depth;        // J: a segment's depth factor D (1 where unused)
  static BodyShape Identity(int num_joints);
};

class ShapeModel {
 public:
  // Throws artex::Error on an invalid template (Template::IsValid).
  ShapeModel(const Template& base, ShapeMode mode, bool symmetric, bool leaf_lengths = false,
             bool fork_widths = false, bool girth_depth = false);

  const Template& base() const { return base_; }
  ShapeMode mode() const { return mode_; }
  int num_parameters() const { return static_cast<int>(names_.size()); }  // Q
  // Q names: "bone:<joint>" (the bone ending at the joint), "girth:<joint>", "length:<leaf>",
  // "width:<joint>", "depth:<joint>", "scale".
  const std::vector<std::string>& parameter_names() const { return names_; }
  // 4 J (5 J with girth_depth) x Q 0/1 matrix E: rows 0..J-1 bone lengths, J..2J-1 girths,
  // 2J..3J-1 leaf lengths, 3J..4J-1 fork widths, 4J..5J-1 depth factors.
  const Eigen::MatrixXd& expansion() const { return expansion_; }
  // Parameter p moves cross-sections only (girth or depth rows), no length.
  bool IsGirthParameter(int p) const;
  // Parameter p is a depth factor ("depth:<joint>", girth_depth only).
  bool IsDepthParameter(int p) const;

  // full = 1 + E q. Throws artex::Error when q has not Q entries.
  BodyShape Expand(const Eigen::VectorXd& q) const;
  // Rest joint centres (J x 3) and vertices (V x 3) of shape q.
  void RestGeometry(const Eigen::VectorXd& q, Eigen::MatrixX3d* centers,
                    Eigen::MatrixX3d* vertices) const;
  // The base template with the rest geometry of shape q (same rig, skinning constants, UVs).
  Template Apply(const Eigen::VectorXd& q) const;

  // Jacobian of the posed vertices S(v; pose) of the template Apply(q) w.r.t. q, for the
  // template vertex indices `vertices` (all when empty): 3 n x Q, rows 3 i .. 3 i + 2 for
  // vertices[i]. Exact and independent of q: for a fixed pose the posed vertex is affine in
  // the rest geometry, which is affine in q. Throws artex::Error on a wrong joint count.
  void PosedJacobian(const Pose& pose, const std::vector<int>& vertices,
                     Eigen::MatrixXd* jacobian) const;

 private:
  int full_rows() const { return (girth_depth_ ? 5 : 4) * base_.num_joints(); }

  Template base_;
  ShapeMode mode_;
  std::vector<std::string> names_;
  Eigen::MatrixXd expansion_;                 // 4J (5J) x Q
  std::vector<Eigen::Vector3d> bone_offset_;  // J: t0_j - t0_parent(j) (root: 0)
  std::vector<int> segment_bone_;  // J: joint whose bone_length stretches segment j (-1: none)
  std::vector<int> stretch_row_;   // J: full row stretching segment j (-1: none; >= 2J: leaf)
  std::vector<bool> fork_;         // J: the bone has a width factor (fork_widths)
  std::vector<Eigen::Vector3d> bone_axial_, bone_lateral_;  // J: bone_offset_ along / across
                                                            // the parent's twist axis
  Eigen::VectorXd alpha_;          // V: axial rest coordinate
  Eigen::MatrixX3d rho_;           // V x 3: radial rest offset
  bool girth_depth_ = false;
  Eigen::MatrixX3d rho_depth_;     // V x 3: rho's component along its segment's depth axis
};

}  // namespace artex
