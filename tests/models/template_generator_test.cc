#include "models/template_generator.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <map>
#include <set>
#include <string>
#include <vector>

#include "models/error.h"
#include "models/pose.h"
#include "models/skinning.h"
#include "models/so3.h"
#include "models/uv_atlas.h"

namespace artex {
namespace {

constexpr double kPi = 3.14159265358979323846;

BodyShapeOptions Coarse() {
  BodyShapeOptions o;
  o.resolution = 0;
  return o;
}

TemplateGeneratorOptions NoAtlas() {
  TemplateGeneratorOptions g;
  g.build_atlas = false;
  return g;
}

double Volume(const Template& t) {
  double volume = 0.0;
  for (int f = 0; f < t.num_triangles(); ++f) {
    const Eigen::Vector3d a = t.vertices.row(t.triangles(f, 0));
    const Eigen::Vector3d b = t.vertices.row(t.triangles(f, 1));
    const Eigen::Vector3d c = t.vertices.row(t.triangles(f, 2));
    volume += a.dot(b.cross(c)) / 6.0;
  }
  return volume;
}

std::vector<std::pair<int, int>> Edges(const Template& t) {
  std::set<std::pair<int, int>> edges;
  for (int f = 0; f < t.num_triangles(); ++f) {
    for (int q = 0; q < 3; ++q) {
      const int a = t.triangles(f, q), b = t.triangles(f, (q + 1) % 3);
      edges.emplace(std::min(a, b), std::max(a, b));
    }
  }
  return {edges.begin(), edges.end()};
}

bool InSubtree(const Template& t, int joint, int root) {
  for (int j = joint; j >= 0; j = t.joints[j].parent) {
    if (j == root) return true;
  }
  return false;
}

// Largest ratio posed / rest length over the given edges.
double MaxEdgeStretch(const Template& t, const std::vector<std::pair<int, int>>& edges,
                      const Eigen::MatrixX3d& posed) {
  double worst = 0.0;
  for (const auto& [a, b] : edges) {
    const double rest = (t.vertices.row(a) - t.vertices.row(b)).norm();
    const double now = (posed.row(a) - posed.row(b)).norm();
    worst = std::max(worst, now / rest);
  }
  return worst;
}

// Generated once at the default resolution (the expensive case) and shared by the tests.
class DefaultTemplateTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    summary_ = new TemplateGeneratorSummary;
    template_ = new Template(GenerateTemplate(BodyShapeOptions(), TemplateGeneratorOptions(),
                                              summary_));
  }
  static void TearDownTestSuite() {
    delete template_;
    delete summary_;
  }
  static Template* template_;
  static TemplateGeneratorSummary* summary_;
};
Template* DefaultTemplateTest::template_ = nullptr;
TemplateGeneratorSummary* DefaultTemplateTest::summary_ = nullptr;

TEST_F(DefaultTemplateTest, SizeJointsAndValidity) {
  const Template& t = *template_;
  EXPECT_GE(t.num_vertices(), 10000);
  EXPECT_LE(t.num_vertices(), 15000);
  EXPECT_EQ(t.num_triangles(), 2 * t.num_vertices() - 4);  // closed genus-0 triangle mesh
  ASSERT_EQ(t.num_joints(), kDefaultNumJoints);
  EXPECT_EQ(t.num_pose_parameters(), 58);
  for (int j = 0; j < kDefaultNumJoints; ++j) {
    EXPECT_EQ(t.joints[j].name, DefaultJointNames()[j]);
  }
  std::string error;
  EXPECT_TRUE(t.IsValid(&error)) << error;
  EXPECT_TRUE(t.has_uvs());
  EXPECT_EQ(summary_->removed_components, 0);
}

TEST_F(DefaultTemplateTest, ClosedOutwardManifoldOfPlausibleVolume) {
  const Template& t = *template_;
  std::string error;
  EXPECT_TRUE(IsClosedManifoldSphere(t.num_vertices(), t.triangles, &error)) << error;
  const double volume = Volume(t);
  EXPECT_GT(volume, 0.06);  // outward orientation and a human volume (m^3)
  EXPECT_LT(volume, 0.10);
  EXPECT_NEAR(volume, summary_->volume, 1e-9);
  // Every triangle's normal points away from the body's interior along the local field: checked
  // indirectly by the positive volume; here also per vertex-normal vs. joint-axis sanity on the
  // head top: the highest vertex's incident normals point up.
  int top = 0;
  for (int v = 0; v < t.num_vertices(); ++v) {
    if (t.vertices(v, 1) > t.vertices(top, 1)) top = v;
  }
  for (int f = 0; f < t.num_triangles(); ++f) {
    for (int q = 0; q < 3; ++q) {
      if (t.triangles(f, q) != top) continue;
      const Eigen::Vector3d a = t.vertices.row(t.triangles(f, 0));
      const Eigen::Vector3d b = t.vertices.row(t.triangles(f, 1));
      const Eigen::Vector3d c = t.vertices.row(t.triangles(f, 2));
      EXPECT_GT((b - a).cross(c - a).y(), 0.0);
    }
  }
}

TEST_F(DefaultTemplateTest, RestPoseFrame) {
  const Template& t = *template_;
  const Eigen::Vector3d lo = t.vertices.colwise().minCoeff();
  const Eigen::Vector3d hi = t.vertices.colwise().maxCoeff();
  EXPECT_NEAR(lo.y(), 0.0, 1e-6);                  // feet on the floor
  EXPECT_NEAR(hi.y() - lo.y(), 1.75, 0.02 * 1.75);  // stature
  EXPECT_NEAR(lo.x() + hi.x(), 0.0, 0.02);          // centred, symmetric arms
  EXPECT_GT(hi.x() - lo.x(), 1.3);                  // A-pose arm span
  // Faces +Z: the feet and the nose stick out forwards.
  EXPECT_GT(hi.z(), -lo.z());
  const Eigen::Vector3d centroid = t.vertices.colwise().mean();
  EXPECT_NEAR(centroid.x(), 0.0, 0.01);
  EXPECT_NEAR(centroid.z(), 0.0, 0.05);
}

TEST_F(DefaultTemplateTest, JointLayout) {
  const Template& t = *template_;
  auto c = [&](const char* name) { return t.joints[t.FindJoint(name)].center; };
  auto axis = [&](const char* name) { return t.joints[t.FindJoint(name)].twist_axis; };
  for (const char* name : {"pelvis", "spine", "chest", "neck", "head"}) {
    EXPECT_GT(axis(name).y(), 0.9) << name;
    EXPECT_NEAR(c(name).x(), 0.0, 1e-9) << name;
  }
  EXPECT_LT(c("pelvis").y(), c("spine").y());
  EXPECT_LT(c("spine").y(), c("chest").y());
  EXPECT_LT(c("chest").y(), c("neck").y());
  EXPECT_LT(c("neck").y(), c("head").y());
  for (const std::string side : {"l_", "r_"}) {
    const double sx = side == "l_" ? 1.0 : -1.0;  // the body's left is +X
    const std::string sh = side + "shoulder", el = side + "elbow", wr = side + "wrist";
    const std::string hip = side + "hip", kn = side + "knee", an = side + "ankle";
    EXPECT_GT(sx * c(sh.c_str()).x(), 0.1);
    EXPECT_GT(sx * c(hip.c_str()).x(), 0.03);
    // Twist axes point outwards along the bones.
    EXPECT_GT(axis(sh.c_str()).dot((c(el.c_str()) - c(sh.c_str())).normalized()), 0.999);
    EXPECT_GT(axis(el.c_str()).dot((c(wr.c_str()) - c(el.c_str())).normalized()), 0.999);
    EXPECT_GT(axis(hip.c_str()).dot((c(kn.c_str()) - c(hip.c_str())).normalized()), 0.999);
    EXPECT_GT(axis(kn.c_str()).dot((c(an.c_str()) - c(kn.c_str())).normalized()), 0.999);
    EXPECT_LT(axis(hip.c_str()).y(), -0.9);
    EXPECT_LT(axis(kn.c_str()).y(), -0.9);
    EXPECT_GT(axis(an.c_str()).z(), 0.5);  // along the foot
    // A-pose: the upper arm about 40 degrees below horizontal.
    const Eigen::Vector3d arm = c(el.c_str()) - c(sh.c_str());
    EXPECT_NEAR(std::atan2(-arm.y(), std::abs(arm.x())) * 180.0 / kPi, 40.0, 1e-6);
  }
}

TEST_F(DefaultTemplateTest, VertexJointAssignmentIsPlausible) {
  const Template& t = *template_;
  std::vector<int> count(t.num_joints(), 0);
  const Eigen::Vector3d head = t.joints[t.FindJoint("head")].center;
  for (int v = 0; v < t.num_vertices(); ++v) {
    const int k = t.vertex_joint[v];
    ++count[k];
    const Eigen::Vector3d p = t.vertices.row(v);
    const std::string& name = t.joints[k].name;
    const double sx = name.rfind("l_", 0) == 0 ? 1.0 : (name.rfind("r_", 0) == 0 ? -1.0 : 0.0);
    if (sx != 0.0) {
      EXPECT_GT(sx * p.x(), 0.0) << name << " vertex " << v;
    }
    if (name == "head") {
      EXPECT_GT(p.y(), t.joints[t.FindJoint("neck")].center.y());
    }
    if (name == "l_ankle" || name == "r_ankle") {
      EXPECT_LT(p.y(), 0.2);
    }
    if (name == "l_wrist" || name == "r_wrist") {
      // Hands: within a hand length of the wrist, far from the head.
      EXPECT_LT((p - t.joints[k].center).norm(), 0.25);
      EXPECT_GT((p - head).norm(), 0.6);
    }
    if (name == "l_knee" || name == "r_knee") {
      EXPECT_LT(p.y(), 0.6);
    }
    if (name == "pelvis") {
      EXPECT_LT(std::abs(p.x()), 0.25);
    }
  }
  for (int j = 0; j < t.num_joints(); ++j) {
    EXPECT_GT(count[j], 30) << t.joints[j].name;
  }
  // Left/right symmetry of the segmentation (within a few percent).
  for (const char* part : {"shoulder", "elbow", "wrist", "hip", "knee", "ankle"}) {
    const int l = count[t.FindJoint(std::string("l_") + part)];
    const int r = count[t.FindJoint(std::string("r_") + part)];
    EXPECT_NEAR(l, r, 0.05 * std::max(l, r)) << part;
  }
}

// Continuity conditions of the skinning constants across segment borders: a segment touches
// only its parent, children and siblings; on its border to non-descendants w_l = tau = 0, next
// to its children w_l = tau = 1; the root is rigid.
TEST_F(DefaultTemplateTest, SkinningConstantsAreContinuousAcrossSegments) {
  const Template& t = *template_;
  for (const auto& [a, b] : Edges(t)) {
    const int ja = t.vertex_joint[a], jb = t.vertex_joint[b];
    if (ja == jb) continue;
    const int pa = t.joints[ja].parent, pb = t.joints[jb].parent;
    EXPECT_TRUE(pa == jb || pb == ja || pa == pb)
        << t.joints[ja].name << " touches " << t.joints[jb].name;
    for (const auto& [v, w] : {std::make_pair(a, b), std::make_pair(b, a)}) {
      const int jv = t.vertex_joint[v], jw = t.vertex_joint[w];
      if (jv == 0) continue;
      if (InSubtree(t, jw, jv)) {
        EXPECT_DOUBLE_EQ(t.lbs_weight[v], 1.0) << t.joints[jv].name;
        EXPECT_DOUBLE_EQ(t.slerp_tau[v], 1.0) << t.joints[jv].name;
      } else {
        EXPECT_DOUBLE_EQ(t.lbs_weight[v], 0.0) << t.joints[jv].name;
        EXPECT_DOUBLE_EQ(t.slerp_tau[v], 0.0) << t.joints[jv].name;
      }
    }
  }
  for (int v = 0; v < t.num_vertices(); ++v) {
    if (t.vertex_joint[v] == 0) {
      EXPECT_EQ(t.lbs_weight[v], 1.0);
      EXPECT_EQ(t.slerp_tau[v], 1.0);
    }
  }
  // The elbow band: w_l is about 0.5 at the joint centre, 1 a band width beyond it.
  const int elbow = t.FindJoint("l_elbow");
  const Joint& j = t.joints[elbow];
  for (int v = 0; v < t.num_vertices(); ++v) {
    if (t.vertex_joint[v] != elbow) continue;
    const double s = (t.vertices.row(v).transpose() - j.center).dot(j.twist_axis);
    if (s > 0.07) {
      EXPECT_EQ(t.lbs_weight[v], 1.0);
    }
    if (std::abs(s) < 0.005) {
      EXPECT_NEAR(t.lbs_weight[v], 0.5, 0.25);
    }
  }
}

TEST_F(DefaultTemplateTest, UvAtlasIsInjectiveAndInsideTheUnitSquare) {
  const Template& t = *template_;
  ASSERT_TRUE(t.has_uvs());
  ASSERT_EQ(t.triangle_chart.size(), t.num_triangles());
  EXPECT_GE(t.uvs.minCoeff(), 0.0);
  EXPECT_LE(t.uvs.maxCoeff(), 1.0);
  // Each uv belongs to exactly one mesh vertex; seams duplicate vertices, nothing else.
  std::vector<int> uv_vertex(t.uvs.rows(), -1);
  for (int f = 0; f < t.num_triangles(); ++f) {
    for (int q = 0; q < 3; ++q) {
      int& owner = uv_vertex[t.uv_triangles(f, q)];
      if (owner < 0) owner = t.triangles(f, q);
      EXPECT_EQ(owner, t.triangles(f, q));
    }
  }
  EXPECT_LT(t.uvs.rows(), 1.2 * t.num_vertices());
  // Orientation kept (no flips), positive area.
  for (int f = 0; f < t.num_triangles(); ++f) {
    const double area = UvSignedArea(t.uvs.row(t.uv_triangles(f, 0)).transpose(),
                                     t.uvs.row(t.uv_triangles(f, 1)).transpose(),
                                     t.uvs.row(t.uv_triangles(f, 2)).transpose());
    ASSERT_GT(area, 0.0) << "triangle " << f;
  }
  // Rasterise texel centres at 1024^2: no centre strictly inside two triangles.
  const int size = 1024;
  std::vector<unsigned char> hits(size * size, 0);
  int covered = 0, doubly = 0;
  for (int f = 0; f < t.num_triangles(); ++f) {
    Eigen::Vector2d p[3];
    for (int q = 0; q < 3; ++q) p[q] = t.uvs.row(t.uv_triangles(f, q)).transpose() * size;
    const double area = (p[1] - p[0]).x() * (p[2] - p[0]).y() - (p[1] - p[0]).y() * (p[2] - p[0]).x();
    const int x0 = std::max(0, static_cast<int>(std::floor(std::min({p[0].x(), p[1].x(), p[2].x()}))));
    const int x1 = std::min(size - 1, static_cast<int>(std::ceil(std::max({p[0].x(), p[1].x(), p[2].x()}))));
    const int y0 = std::max(0, static_cast<int>(std::floor(std::min({p[0].y(), p[1].y(), p[2].y()}))));
    const int y1 = std::min(size - 1, static_cast<int>(std::ceil(std::max({p[0].y(), p[1].y(), p[2].y()}))));
    for (int y = y0; y <= y1; ++y) {
      for (int x = x0; x <= x1; ++x) {
        const Eigen::Vector2d c(x + 0.5, y + 0.5);
        bool inside = true;
        for (int q = 0; q < 3; ++q) {
          const Eigen::Vector2d a = p[q], b = p[(q + 1) % 3];
          const double e = ((b - a).x() * (c - a).y() - (b - a).y() * (c - a).x()) / area;
          if (e <= 1e-9) inside = false;  // strictly inside (shared edges are not overlaps)
        }
        if (!inside) continue;
        unsigned char& h = hits[y * size + x];
        if (h == 0) ++covered; else ++doubly;
        ++h;
      }
    }
  }
  EXPECT_EQ(doubly, 0);
  EXPECT_NEAR(static_cast<double>(covered) / (size * size), summary_->atlas.coverage, 0.02);
  EXPECT_GT(summary_->atlas.coverage, 0.4);
  // Uniform texel density: the central 90% of the surface within +-35% of the mean.
  EXPECT_GT(summary_->atlas.density_p05, 0.65);
  EXPECT_LT(summary_->atlas.density_p95, 1.35);
  EXPECT_EQ(summary_->atlas.num_charts, 20);
  EXPECT_EQ(summary_->atlas.num_cylinder_cuts, 8);  // upper arms, forearms, thighs, shanks
}

TEST_F(DefaultTemplateTest, ChartsKeepThePaddingApart) {
  const Template& t = *template_;
  const BodyShapeOptions options;
  std::map<int, Eigen::AlignedBox2d> boxes;
  for (int f = 0; f < t.num_triangles(); ++f) {
    for (int q = 0; q < 3; ++q) {
      boxes[t.triangle_chart[f]].extend(t.uvs.row(t.uv_triangles(f, q)).transpose() *
                                        options.atlas_size);
    }
  }
  for (auto a = boxes.begin(); a != boxes.end(); ++a) {
    for (auto b = std::next(a); b != boxes.end(); ++b) {
      const Eigen::Vector2d gap = (a->second.min() - b->second.max())
                                      .cwiseMax(b->second.min() - a->second.max());
      EXPECT_GE(gap.maxCoeff(), options.atlas_padding_texels - 1e-6)
          << "charts " << a->first << " and " << b->first;
    }
  }
}

// Bending or twisting a joint keeps the surface continuous: no edge stretches by a large factor.
TEST_F(DefaultTemplateTest, PosedSurfaceStaysContinuous) {
  const Template& t = *template_;
  const Skinning skinning(t);
  const std::vector<std::pair<int, int>> edges = Edges(t);
  struct Motion {
    const char* joint;
    Eigen::Vector3d axis;  // bending axis in the rest frame
    double bend_degrees;
    double twist_degrees;  // about the joint's twist axis
  };
  const std::vector<Motion> motions = {
      {"l_elbow", Eigen::Vector3d::UnitZ(), 90.0, 90.0},
      {"r_elbow", Eigen::Vector3d::UnitZ(), -90.0, -90.0},
      {"l_shoulder", Eigen::Vector3d::UnitZ(), 70.0, 90.0},
      {"r_shoulder", Eigen::Vector3d::UnitY(), 60.0, 60.0},
      {"l_wrist", Eigen::Vector3d::UnitZ(), 60.0, 60.0},
      {"l_knee", Eigen::Vector3d::UnitX(), -90.0, 30.0},
      {"r_knee", Eigen::Vector3d::UnitX(), -90.0, -30.0},
      {"l_hip", Eigen::Vector3d::UnitX(), -60.0, 45.0},  // flexion; 80+ degrees tear the crotch
      {"r_hip", Eigen::Vector3d::UnitZ(), -40.0, -45.0},
      {"l_ankle", Eigen::Vector3d::UnitX(), 40.0, 30.0},
      {"spine", Eigen::Vector3d::UnitX(), 45.0, 30.0},
      {"chest", Eigen::Vector3d::UnitZ(), 30.0, 30.0},
      {"neck", Eigen::Vector3d::UnitX(), 40.0, 45.0},
      {"head", Eigen::Vector3d::UnitX(), -30.0, 45.0},
  };
  Eigen::MatrixX3d posed;
  for (const Motion& m : motions) {
    const int j = t.FindJoint(m.joint);
    ASSERT_GE(j, 0);
    Pose pose = Pose::Identity(t.num_joints());
    pose.joint_rotations[j] = ExpSO3(m.axis.normalized() * m.bend_degrees * kPi / 180.0);
    skinning.Apply(pose, &posed);
    EXPECT_LT(MaxEdgeStretch(t, edges, posed), 3.0) << m.joint;
    pose.joint_rotations[j] = ExpSO3(t.joints[j].twist_axis * m.twist_degrees * kPi / 180.0);
    skinning.Apply(pose, &posed);
    EXPECT_LT(MaxEdgeStretch(t, edges, posed), 3.0) << m.joint << " (twist)";
  }
}

// The same check fails without the blend band (w_l = tau = 1 on the whole forearm): the test
// above can detect a torn surface.
TEST_F(DefaultTemplateTest, PosedSurfaceTearsWithoutBlendBand) {
  Template t = *template_;
  const int elbow = t.FindJoint("l_elbow");
  for (int v = 0; v < t.num_vertices(); ++v) {
    if (t.vertex_joint[v] == elbow) {
      t.lbs_weight[v] = 1.0;
      t.slerp_tau[v] = 1.0;
    }
  }
  const Skinning skinning(t);
  Pose pose = Pose::Identity(t.num_joints());
  pose.joint_rotations[elbow] = ExpSO3(Eigen::Vector3d::UnitZ() * kPi / 2.0);
  Eigen::MatrixX3d posed;
  skinning.Apply(pose, &posed);
  EXPECT_GT(MaxEdgeStretch(t, Edges(t), posed), 3.0);
}

TEST(TemplateGeneratorTest, CoarseResolution) {
  const Template t = GenerateTemplate(Coarse());
  EXPECT_GE(t.num_vertices(), 2000);
  EXPECT_LE(t.num_vertices(), 4500);
  std::string error;
  EXPECT_TRUE(t.IsValid(&error)) << error;
  EXPECT_TRUE(IsClosedManifoldSphere(t.num_vertices(), t.triangles, &error)) << error;
  EXPECT_GT(Volume(t), 0.06);
  EXPECT_LT(Volume(t), 0.10);
  EXPECT_TRUE(t.has_uvs());
}

TEST(TemplateGeneratorTest, Deterministic) {
  const Template a = GenerateTemplate(Coarse());
  const Template b = GenerateTemplate(Coarse());
  ASSERT_EQ(a.num_vertices(), b.num_vertices());
  ASSERT_EQ(a.num_triangles(), b.num_triangles());
  EXPECT_EQ(a.vertices, b.vertices);
  EXPECT_EQ(a.triangles, b.triangles);
  EXPECT_EQ(a.uvs, b.uvs);
  EXPECT_EQ(a.uv_triangles, b.uv_triangles);
  EXPECT_EQ(a.triangle_chart, b.triangle_chart);
  EXPECT_EQ(a.vertex_joint, b.vertex_joint);
  EXPECT_EQ(a.lbs_weight, b.lbs_weight);
  EXPECT_EQ(a.slerp_tau, b.slerp_tau);
}

TEST(TemplateGeneratorTest, HeightIsRespected) {
  for (double height : {1.5, 2.0}) {
    BodyShapeOptions o = Coarse();
    o.height = height;
    const Template t = GenerateTemplate(o, NoAtlas(), nullptr);
    const double extent = t.vertices.col(1).maxCoeff() - t.vertices.col(1).minCoeff();
    EXPECT_NEAR(extent, height, 0.02 * height);
    EXPECT_NEAR(t.vertices.col(1).minCoeff(), 0.0, 1e-6);
  }
}

TEST(TemplateGeneratorTest, ShapeParametersChangeTheBodyAsExpected) {
  auto volume = [](double girth) {
    BodyShapeOptions o = Coarse();
    o.girth = girth;
    return Volume(GenerateTemplate(o, NoAtlas(), nullptr));
  };
  const Template base = GenerateTemplate(Coarse(), NoAtlas(), nullptr);
  EXPECT_LT(volume(0.8), Volume(base));
  EXPECT_GT(volume(1.3), Volume(base));
  // Longer legs: the hips move up, the stature stays.
  BodyShapeOptions o = Coarse();
  o.leg_length = 1.15;
  const Template t = GenerateTemplate(o, NoAtlas(), nullptr);
  EXPECT_GT(t.joints[t.FindJoint("l_hip")].center.y(),
            base.joints[base.FindJoint("l_hip")].center.y() + 0.05);
  EXPECT_NEAR(t.vertices.col(1).maxCoeff(), 1.75, 0.02 * 1.75);
  // Arms at 20 degrees below horizontal span wider.
  o = Coarse();
  o.arm_angle_deg = 20.0;
  const Template raised = GenerateTemplate(o, NoAtlas(), nullptr);
  EXPECT_GT(raised.vertices.col(0).maxCoeff(), base.vertices.col(0).maxCoeff() + 0.05);
}

// Corners of the valid parameter box still give valid, closed templates with an atlas whose
// segments only touch their parents, children and siblings.
TEST(TemplateGeneratorTest, ExtremeShapesStayValid) {
  BodyShapeOptions wide = Coarse();
  wide.girth = 1.6;
  wide.hip_width = 1.3;
  wide.arm_angle_deg = 60.0;
  BodyShapeOptions small = Coarse();
  small.height = 1.0;
  small.girth = 0.6;
  small.shoulder_width = 0.7;
  small.arm_length = 1.2;
  small.leg_length = 1.2;
  for (const BodyShapeOptions& o : {wide, small}) {
    const Template t = GenerateTemplate(o);
    std::string error;
    EXPECT_TRUE(t.IsValid(&error)) << error;
    EXPECT_TRUE(IsClosedManifoldSphere(t.num_vertices(), t.triangles, &error)) << error;
    EXPECT_TRUE(t.has_uvs());
    EXPECT_NEAR(t.vertices.col(1).maxCoeff(), o.height, 0.02 * o.height);
    for (const auto& [a, b] : Edges(t)) {
      const int ja = t.vertex_joint[a], jb = t.vertex_joint[b];
      const int pa = t.joints[ja].parent, pb = t.joints[jb].parent;
      EXPECT_TRUE(ja == jb || pa == jb || pb == ja || pa == pb);
    }
  }
}

TEST(TemplateGeneratorTest, InvalidOptionsThrow) {
  auto with = [](auto edit) {
    BodyShapeOptions o = Coarse();
    edit(o);
    return o;
  };
  EXPECT_THROW(GenerateTemplate(with([](BodyShapeOptions& o) { o.height = 0.5; })), Error);
  EXPECT_THROW(GenerateTemplate(with([](BodyShapeOptions& o) { o.girth = 2.0; })), Error);
  EXPECT_THROW(GenerateTemplate(with([](BodyShapeOptions& o) { o.resolution = 2; })), Error);
  EXPECT_THROW(GenerateTemplate(with([](BodyShapeOptions& o) { o.atlas_size = 64; })), Error);
  EXPECT_THROW(GenerateTemplate(with([](BodyShapeOptions& o) { o.arm_angle_deg = NAN; })),
               Error);
  TemplateGeneratorOptions g;
  g.bands.elbow = -0.01;
  EXPECT_THROW(GenerateTemplate(Coarse(), g, nullptr), Error);
  g = TemplateGeneratorOptions();
  g.proportions.torso_sections[3].y = 0.2;  // not increasing
  EXPECT_THROW(GenerateTemplate(Coarse(), g, nullptr), Error);
  std::string error;
  BodyShapeOptions o;
  o.height = 3.0;
  EXPECT_FALSE(o.IsValid(&error));
  EXPECT_NE(error.find("height"), std::string::npos);
}

// ---------------------------------------------------------------------------------------------
// Manifold check and atlas on small meshes.

Eigen::MatrixX3i Tetrahedron(int offset = 0) {
  Eigen::MatrixX3i t(4, 3);
  t << 0, 2, 1, 0, 1, 3, 1, 2, 3, 0, 3, 2;
  return t.array() + offset;
}

TEST(IsClosedManifoldSphereTest, DetectsDefects) {
  std::string error;
  EXPECT_TRUE(IsClosedManifoldSphere(4, Tetrahedron(), &error)) << error;
  Eigen::MatrixX3i open = Tetrahedron().topRows(3);
  EXPECT_FALSE(IsClosedManifoldSphere(4, open, &error));
  Eigen::MatrixX3i flipped = Tetrahedron();
  std::swap(flipped(0, 1), flipped(0, 2));
  EXPECT_FALSE(IsClosedManifoldSphere(4, flipped, &error));
  Eigen::MatrixX3i two(8, 3);
  two << Tetrahedron(), Tetrahedron(4);
  EXPECT_FALSE(IsClosedManifoldSphere(8, two, &error));
  EXPECT_NE(error.find("component"), std::string::npos);
  // Two tetrahedra sharing one vertex: edge-manifold but a pinched vertex.
  Eigen::MatrixX3i pinched(8, 3);
  pinched << Tetrahedron(), Tetrahedron(3);
  EXPECT_FALSE(IsClosedManifoldSphere(7, pinched, &error));
  // A torus (4 x 4 grid wrapped both ways): Euler characteristic 0.
  Eigen::MatrixX3i torus(32, 3);
  int f = 0;
  for (int i = 0; i < 4; ++i) {
    for (int j = 0; j < 4; ++j) {
      const int a = 4 * i + j, b = 4 * ((i + 1) % 4) + j, c = 4 * ((i + 1) % 4) + (j + 1) % 4,
                d = 4 * i + (j + 1) % 4;
      torus.row(f++) << a, b, c;
      torus.row(f++) << a, c, d;
    }
  }
  EXPECT_FALSE(IsClosedManifoldSphere(16, torus, &error));
  EXPECT_NE(error.find("Euler"), std::string::npos);
}

// A closed capped cylinder: the side is an annulus chart that must be cut open.
TEST(UvAtlasTest, CutsAnnulusChartsAndPacksWithoutFlips) {
  const int ring = 16, rows = 6;
  std::vector<Eigen::Vector3d> verts;
  for (int r = 0; r < rows; ++r) {
    for (int k = 0; k < ring; ++k) {
      const double a = 2.0 * kPi * k / ring;
      verts.emplace_back(0.1 * std::cos(a), 0.1 * r, 0.1 * std::sin(a));
    }
  }
  const int bottom = static_cast<int>(verts.size());
  verts.emplace_back(0.0, 0.0, 0.0);
  const int top = static_cast<int>(verts.size());
  verts.emplace_back(0.0, 0.1 * (rows - 1), 0.0);
  std::vector<Eigen::Vector3i> tris;
  std::vector<int> chart;
  for (int r = 0; r + 1 < rows; ++r) {
    for (int k = 0; k < ring; ++k) {
      const int a = r * ring + k, b = r * ring + (k + 1) % ring;
      const int c = (r + 1) * ring + (k + 1) % ring, d = (r + 1) * ring + k;
      tris.emplace_back(a, c, b);
      tris.emplace_back(a, d, c);
      chart.push_back(1);
      chart.push_back(1);
    }
  }
  for (int k = 0; k < ring; ++k) {
    tris.emplace_back(bottom, k, (k + 1) % ring);
    chart.push_back(0);
    tris.emplace_back(top, (rows - 1) * ring + (k + 1) % ring, (rows - 1) * ring + k);
    chart.push_back(2);
  }
  Eigen::MatrixX3d v(verts.size(), 3);
  for (size_t i = 0; i < verts.size(); ++i) v.row(i) = verts[i].transpose();
  Eigen::MatrixX3i f(tris.size(), 3);
  for (size_t i = 0; i < tris.size(); ++i) f.row(i) = tris[i].transpose();
  std::string error;
  ASSERT_TRUE(IsClosedManifoldSphere(static_cast<int>(v.rows()), f, &error)) << error;
  Template closed;
  closed.vertices = v;
  closed.triangles = f;
  ASSERT_GT(Volume(closed), 0.0);
  UvAtlasOptions options;
  options.atlas_size = 512;
  UvAtlas atlas;
  UvAtlasSummary summary;
  BuildUvAtlas(v, f, Eigen::Map<Eigen::VectorXi>(chart.data(), chart.size()), Eigen::VectorXd(),
               options, &atlas, &summary);
  EXPECT_EQ(summary.num_charts, 3);
  EXPECT_EQ(summary.num_cylinder_cuts, 1);
  EXPECT_EQ(summary.num_tutte_fallbacks, 0);
  // The cut adds one column of uv vertices along the side (rows), the caps are separate.
  EXPECT_EQ(atlas.uvs.rows(), rows * (ring + 1) + 2 * ring + 2);
  for (int t = 0; t < f.rows(); ++t) {
    EXPECT_GT(UvSignedArea(atlas.uvs.row(atlas.uv_triangles(t, 0)).transpose(),
                           atlas.uvs.row(atlas.uv_triangles(t, 1)).transpose(),
                           atlas.uvs.row(atlas.uv_triangles(t, 2)).transpose()),
              0.0);
  }
  EXPECT_GE(atlas.uvs.minCoeff(), 0.0);
  EXPECT_LE(atlas.uvs.maxCoeff(), 1.0);
  // A developable side unrolls isometrically: uniform density.
  EXPECT_GT(summary.density_p05, 0.8);
  EXPECT_LT(summary.density_p95, 1.25);
  // The whole closed surface as one chart is neither a disc nor an annulus.
  EXPECT_THROW(BuildUvAtlas(v, f, Eigen::VectorXi::Zero(f.rows()), Eigen::VectorXd(), options,
                            &atlas, &summary),
               Error);
}

}  // namespace
}  // namespace artex
