// Internal to the template generator (models/template_generator*.cc): its body, meshes and steps.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <vector>

#include "models/template_generator.h"

namespace artex {
namespace generator_internal {

using Vec3 = Eigen::Vector3d;

inline constexpr const char* kJointNames[kDefaultNumJoints] = {
    "pelvis",  "spine",   "chest",      "neck",    "head",    "l_shoulder",
    "l_elbow", "l_wrist", "r_shoulder", "r_elbow", "r_wrist", "l_hip",
    "l_knee",  "l_ankle", "r_hip",      "r_knee",  "r_ankle"};
inline constexpr int kParents[kDefaultNumJoints] = {-1, 0, 1, 2,  3,  2, 5,  6, 2,
                                                    8,  9, 0, 11, 12, 0, 14, 15};

enum JointId : int {
  kPelvis = 0,
  kSpine,
  kChest,
  kNeck,
  kHead,
  kLShoulder,
  kLElbow,
  kLWrist,
  kRShoulder,
  kRElbow,
  kRWrist,
  kLHip,
  kLKnee,
  kLAnkle,
  kRHip,
  kRKnee,
  kRAnkle
};

// Kinematic groups that the implicit primitives belong to; body parts (joints) are found by
// the dominant group at each vertex, then by planes along the group's bones.
enum class Group { kTrunk, kNeckHead, kLeftArm, kRightArm, kLeftLeg, kRightLeg };

// ----------------------------------------------------------------------------------------------
// Implicit body (template_generator_body.cc): smooth union of primitives (signed-distance-like
// fields, negative inside).

struct Primitive {
  enum class Kind { kRoundCone, kEllipsoid, kRoundBox, kLoft };
  Kind kind = Kind::kEllipsoid;
  Group group = Group::kTrunk;
  double blend = 0.0;                                   // smooth-union radius (m)
  Vec3 origin = Vec3::Zero();                           // cone start / ellipsoid or box centre
  Eigen::Matrix3d frame = Eigen::Matrix3d::Identity();  // rows: local axes
  Vec3 scale = Vec3::Ones();  // local coordinates are divided by this (cone flattening)
  double length = 0.0, r1 = 0.0, r2 = 0.0;    // round cone
  Vec3 semi_axes = Vec3::Ones();              // ellipsoid / box half extents
  double rounding = 0.0, rounding_top = 0.0;  // box edge radius; loft bottom / top caps
  // Loft: sections (y, half width, half depth, centre z) and their y-derivatives.
  std::vector<std::array<double, 4>> sections, slopes;
  double lipschitz = 1.0;  // lower bound of (field value / true distance) outside
  Vec3 bound_centre = Vec3::Zero();
  double bound_radius = 0.0;

  double Eval(const Vec3& p) const;
  // Cubic Hermite interpolation of the sections at height y (clamped to the loft's range).
  std::array<double, 4> Section(double y) const;
  // Elliptical cross-section distance (approximation after I. Quilez), extruded along y with
  // rounded caps of radius `rounding` (bottom) / `rounding_top`.
  double LoftEval(const Vec3& p) const;
};

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
  std::array<Vec3, 2> palm_normal;         // per side (0 left, 1 right): points to the palm side
  std::array<Vec3, 2> arm_seam, leg_seam;  // preferred seam side of the limb cylinders

  double Field(const Vec3& p) const;
  // Forward differences from the known value f = Field(p).
  Vec3 Gradient(const Vec3& p, double f, double eps) const;
  Group DominantGroup(const Vec3& p) const;
};

Body BuildBody(const BodyShapeOptions& shape, const BodyProportions& bp, double grid_cell);

// ----------------------------------------------------------------------------------------------
// Surface meshes (template_generator_mesh.cc): iso-surface extraction and isotropic remeshing.

struct TriangleMesh {
  std::vector<Vec3> vertices;
  std::vector<std::array<int, 3>> triangles;
};

inline Vec3 FaceNormal(const Vec3& a, const Vec3& b, const Vec3& c) { return (b - a).cross(c - a); }

// Marching tetrahedra on the Kuhn subdivision of a grid of spacing `cell` over the body's box.
TriangleMesh ExtractIsoSurface(const Body& body, double cell);
// Keeps the connected component with the most triangles; returns the number dropped.
int KeepLargestComponent(TriangleMesh* mesh);
// Isotropic remeshing towards `edge_length` with projection onto the body's surface; throws
// artex::Error when `input` is not a manifold.
TriangleMesh Remesh(const Body& body, const TriangleMesh& input, double edge_length,
                    const MeshingOptions& options);

// ----------------------------------------------------------------------------------------------
// Segmentation, skinning constants and UV charts (template_generator_skinning.cc).

std::vector<std::vector<int>> VertexNeighbours(int nv, const Eigen::MatrixX3i& tris);
// Splits every label into connected components (over `adjacent`) and relabels all but the
// largest component of each label with the most frequent label among their outside
// neighbours. Returns the number of relabelled items.
int MergeIslands(const std::vector<std::vector<int>>& adjacent, std::vector<int>* labels);
// Segments may only touch their parent, children and siblings (otherwise the skinned surface
// would tear); offending vertices of the deeper segment move to its parent.
int FixSegmentAdjacency(const std::vector<std::vector<int>>& adj, std::vector<int>* joint);
// Joint k of every vertex: dominant primitive group, then planes along the group's bones.
std::vector<int> SegmentBody(const Body& body, const SkinningBands& bands,
                             const Eigen::MatrixX3d& verts);
void ComputeSkinningConstants(const Body& body, const SkinningBands& bands,
                              const Eigen::MatrixX3d& verts,
                              const std::vector<std::vector<int>>& adj,
                              const std::vector<int>& joint, Eigen::VectorXd* w_l,
                              Eigen::VectorXd* tau);
Eigen::VectorXi AssignCharts(const Body& body, const Eigen::MatrixX3d& verts,
                             const Eigen::MatrixX3i& tris, const std::vector<int>& joint);
Eigen::VectorXd SeamCost(const Body& body, const Eigen::MatrixX3d& verts,
                         const std::vector<int>& joint);

}  // namespace generator_internal
}  // namespace artex
