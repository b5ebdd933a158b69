// Importers from linear-blend-skinned (LBS) characters to the paper's per-vertex skinning
// model (eq. 2: one joint k, an LBS weight w_l between k and its parent, a SLERP parameter tau)
// and the MakeHuman base mesh + mpfb2 "cmu_mb" rig importer. The conversion rules are
// documented in docs/formats-template.md ("Converting linear-blend weights").
#pragma once

#include <map>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "models/pose.h"
#include "models/template.h"
#include "models/template_io.h"

namespace artex {

struct LbsConversionOptions {
  // Weights below this are ignored when choosing the joint pair (they still count in the
  // pair's normalisation only if kept); in [0, 1).
  double min_weight = 1e-4;
};

// Converts per-vertex LBS weights over `joints` (parents precede children) into the paper's
// constants. For each vertex the bone (child c, parent p) -- the root joint paired with the
// global similarity -- carrying the largest weight w_c + w_p is chosen (ties: larger w_c);
// then k = c, w_l = w_c / (w_c + w_p), tau = w_l. Weight on other joints is dropped.
// Exact when each vertex is weighted on one joint and its parent and no joint twists.
// Outputs have weights.size() entries. Throws artex::Error on a joint index out of range or a
// vertex without positive weight (naming the vertex).
void ConvertLbsWeights(const std::vector<Joint>& joints, const VertexJointWeights& weights,
                       const LbsConversionOptions& options, Eigen::VectorXi* vertex_joint,
                       Eigen::VectorXd* lbs_weight, Eigen::VectorXd* slerp_tau);

// Twist axes from the joint tree and centres: towards the only child; with several children,
// towards the child best aligned with the parent-to-joint direction (for the root: the child
// with the largest subtree, ties to the first); leaves continue the parent-to-joint direction.
// Degenerate (zero-length) directions fall back to +Y.
void AssignDefaultTwistAxes(std::vector<Joint>* joints);

// Linear-blend skinning of the template's rest vertices with per-joint transforms equal to the
// paper's chain transforms: A_j(x) = s0 R0 T_root o ... o T_j (x) + t0. This is how a glTF
// viewer poses the original LBS character when the pose drives the joint nodes; used to
// measure the conversion error. Returns V x 3.
Eigen::MatrixX3d PoseLinearBlend(const Template& tmpl, const VertexJointWeights& weights,
                                 const Pose& pose);

// Triangle charts = connected components of the UV layout (triangles sharing an edge with the
// same UV indices on both corners). F entries, numbered from 0 in triangle order.
Eigen::VectorXi UvIslands(const Eigen::MatrixX3i& triangles, const Eigen::MatrixX3i& uv_triangles);

// ---------------------------------------------------------------------------------------------
// MakeHuman base mesh (hm08 base.obj, decimetres, Y up, facing +Z) + mpfb2 rig/weights JSON.

enum class RigPositionSource {
  kJointCubes,        // centres of the rig's joint-* helper cubes (or listed vertices) in base.obj
  kDefaultPositions,  // the rig's "default_position" (Blender frame, metres)
};

struct MakeHumanImportOptions {
  std::string obj_file = "base.obj";
  std::string rig_file = "mpfb_rig.cmu_mb.json";
  std::string weights_file = "mpfb_weights.cmu_mb.json";
  std::string group = "body";           // OBJ group kept (others are helper geometry)
  double unit_to_metres = 0.1;          // base.obj is in decimetres
  bool feet_on_floor = true;            // translate so the lowest vertex has y = 0
  RigPositionSource joint_positions = RigPositionSource::kJointCubes;
  bool split_quads_shorter_diagonal = true;  // else (0,1,2),(0,2,3)
  // artex joint name -> rig bone whose head is the joint centre. Bones not listed merge their
  // weights into the nearest listed ancestor. The artex joint tree follows the rig's.
  std::map<std::string, std::string> bone_of_joint = {
      {"pelvis", "Hips"},          {"spine", "LowerBack"},     {"chest", "Spine1"},
      {"neck", "Neck"},            {"head", "Head"},           {"l_shoulder", "LeftArm"},
      {"l_elbow", "LeftForeArm"},  {"l_wrist", "LeftHand"},    {"r_shoulder", "RightArm"},
      {"r_elbow", "RightForeArm"}, {"r_wrist", "RightHand"},   {"l_hip", "LeftUpLeg"},
      {"l_knee", "LeftLeg"},       {"l_ankle", "LeftFoot"},    {"r_hip", "RightUpLeg"},
      {"r_knee", "RightLeg"},      {"r_ankle", "RightFoot"}};
  // Joint order of the result; empty: the 17 names of DefaultJointNames()
  // (models/template_generator.h), in that order.
  std::vector<std::string> joint_order;
  LbsConversionOptions conversion;
};

// Facts about the imported mesh for reports.
struct MakeHumanImportReport {
  int obj_vertices = 0;           // all vertices in the OBJ
  int group_quads = 0;            // polygons of the kept group with 4 corners
  int group_triangles = 0;        // ... with 3 corners
  int boundary_edges = 0;         // edges with one incident triangle (0: closed)
  int non_manifold_edges = 0;     // edges with more than two incident triangles
  double height_m = 0.0;          // vertical extent of the kept group
  double max_joint_weight_loss = 0.0;  // largest per-vertex weight dropped by the conversion
};

// Reads `folder`/{obj,rig,weights} and builds a 17-joint template (metres, Y up, facing +Z,
// feet at y = 0; UVs flipped to the glTF convention; UV islands as charts). If `lbs_weights`
// is non-null it receives the rig's weights merged onto the kept joints, per template vertex.
// Throws artex::Error naming the file (and OBJ line) on any problem.
Template ImportMakeHuman(const std::string& folder,
                         const MakeHumanImportOptions& options = MakeHumanImportOptions(),
                         VertexJointWeights* lbs_weights = nullptr,
                         MakeHumanImportReport* report = nullptr);

// A minimal Wavefront OBJ reader (v, vt, f with v, v/vt, v/vt/vn, v//vn and negative indices;
// g/o group names). Faces keep their polygon size; indices are 0-based. Throws artex::Error
// naming the file and line for malformed numbers, indices out of range or missing vertices.
struct ObjMesh {
  std::vector<Eigen::Vector3d> positions;
  std::vector<Eigen::Vector2d> texcoords;
  struct Face {
    std::vector<int> position;   // corners
    std::vector<int> texcoord;   // same size, or empty when the face has no UVs
    std::string group;
    int line = 0;                // 1-based line of the face in the file
  };
  std::vector<Face> faces;
};
ObjMesh ReadObj(const std::string& path);

}  // namespace artex
