// Skinning (eq. 1-2) and vertex normals on a body-sized synthetic template: 17 joints in the
// human tree of models/template_generator.h, each bone wrapped by a 16 x 46 cylinder grid
// (12,512 vertices, 24,480 triangles), w_l and tau ramping along each bone.
// Median figures: --benchmark_repetitions=10 --benchmark_report_aggregates_only=true
// Arguments: generated = 0 for that synthetic template, 1 for GenerateTemplate() (~12.5k
// vertices); parallel = SkinningOptions::parallel (0: calling thread only, 1: TBB threads).
#include <benchmark/benchmark.h>

#include <Eigen/Geometry>
#include <cmath>
#include <random>
#include <vector>

#include "models/normals.h"
#include "models/skinning.h"
#include "models/so3.h"
#include "models/template_generator.h"

namespace artex {
namespace {

constexpr int kRingSegments = 16;
constexpr int kRings = 46;
constexpr std::uint64_t kPoseSeed = 7;

Template BodySizedTemplate() {
  struct Spec {
    const char* name;
    int parent;
    Eigen::Vector3d center;
  };
  const std::vector<Spec> specs = {
      {"pelvis", -1, {0.0, 1.00, 0.0}},      {"spine", 0, {0.0, 1.15, 0.0}},
      {"chest", 1, {0.0, 1.35, 0.0}},        {"neck", 2, {0.0, 1.55, 0.0}},
      {"head", 3, {0.0, 1.65, 0.0}},         {"l_shoulder", 2, {0.18, 1.45, 0.0}},
      {"l_elbow", 5, {0.40, 1.25, 0.0}},     {"l_wrist", 6, {0.60, 1.07, 0.0}},
      {"r_shoulder", 2, {-0.18, 1.45, 0.0}}, {"r_elbow", 8, {-0.40, 1.25, 0.0}},
      {"r_wrist", 9, {-0.60, 1.07, 0.0}},    {"l_hip", 0, {0.10, 0.95, 0.0}},
      {"l_knee", 11, {0.11, 0.52, 0.0}},     {"l_ankle", 12, {0.12, 0.09, 0.0}},
      {"r_hip", 0, {-0.10, 0.95, 0.0}},      {"r_knee", 14, {-0.11, 0.52, 0.0}},
      {"r_ankle", 15, {-0.12, 0.09, 0.0}}};
  const int num_joints = static_cast<int>(specs.size());
  Template t;
  std::vector<Eigen::Vector3d> bone_end(num_joints);
  for (int j = 0; j < num_joints; ++j) {
    Joint joint;
    joint.name = specs[j].name;
    joint.parent = specs[j].parent;
    joint.center = specs[j].center;
    t.joints.push_back(joint);
    bone_end[j] = specs[j].center + Eigen::Vector3d(0.0, 0.1, 0.0);  // leaf default
  }
  for (int j = 1; j < num_joints; ++j) bone_end[specs[j].parent] = specs[j].center;
  for (int j = 0; j < num_joints; ++j) {
    const Eigen::Vector3d bone = bone_end[j] - t.joints[j].center;
    t.joints[j].twist_axis = bone.norm() > 1e-9 ? bone.normalized() : Eigen::Vector3d::UnitY();
  }
  const int per_joint = kRingSegments * kRings;
  const int num_vertices = num_joints * per_joint;
  const int num_triangles = num_joints * 2 * kRingSegments * (kRings - 1);
  t.vertices.resize(num_vertices, 3);
  t.vertex_joint.resize(num_vertices);
  t.lbs_weight.resize(num_vertices);
  t.slerp_tau.resize(num_vertices);
  t.triangles.resize(num_triangles, 3);
  int f = 0;
  for (int j = 0; j < num_joints; ++j) {
    const Eigen::Vector3d a = t.joints[j].twist_axis;
    const Eigen::Vector3d u = a.unitOrthogonal();
    const Eigen::Vector3d w = a.cross(u);
    const Eigen::Vector3d start = t.joints[j].center;
    const double length = std::max((bone_end[j] - start).norm(), 0.1);
    const double radius = 0.04 + 0.02 * (j == 0 || j == 1 || j == 2);
    for (int r = 0; r < kRings; ++r) {
      const double s = static_cast<double>(r) / (kRings - 1);
      for (int k = 0; k < kRingSegments; ++k) {
        const double phi = 2.0 * M_PI * k / kRingSegments;
        const int v = j * per_joint + r * kRingSegments + k;
        t.vertices.row(v) =
            (start + s * length * a + radius * (std::cos(phi) * u + std::sin(phi) * w)).transpose();
        t.vertex_joint[v] = j;
        t.lbs_weight[v] = 0.5 + 0.5 * s;
        t.slerp_tau[v] = s;
      }
    }
    for (int r = 0; r + 1 < kRings; ++r) {
      for (int k = 0; k < kRingSegments; ++k) {
        const int k1 = (k + 1) % kRingSegments;
        const int base = j * per_joint;
        const int v00 = base + r * kRingSegments + k, v01 = base + r * kRingSegments + k1;
        const int v10 = base + (r + 1) * kRingSegments + k,
                  v11 = base + (r + 1) * kRingSegments + k1;
        t.triangles.row(f++) << v00, v01, v11;
        t.triangles.row(f++) << v00, v11, v10;
      }
    }
  }
  return t;
}

Pose BenchPose(const Template& t) {
  std::mt19937_64 rng(kPoseSeed);
  std::uniform_real_distribution<double> u(-0.6, 0.6);
  Pose pose = Pose::Identity(t.num_joints());
  pose.scale = 1.05;
  pose.translation = Eigen::Vector3d(0.1, -0.2, 2.5);
  pose.rotation = ExpSO3(Eigen::Vector3d(u(rng), u(rng), u(rng)));
  for (auto& r : pose.joint_rotations) r = ExpSO3(Eigen::Vector3d(u(rng), u(rng), u(rng)));
  return pose;
}

// Built once per process (outside the timed loops).
const Template& SyntheticTemplate() {
  static const Template t = BodySizedTemplate();
  return t;
}
const Template& GeneratedTemplate() {
  static const Template t = GenerateTemplate();
  return t;
}
// Argument "generated": 0 = synthetic body-sized template, 1 = GenerateTemplate().
const Template& SharedTemplate(const benchmark::State& state) {
  return state.range(0) == 0 ? SyntheticTemplate() : GeneratedTemplate();
}

SkinningOptions OptionsFor(const benchmark::State& state) {
  SkinningOptions options;
  options.parallel = state.range(1) != 0;
  return options;
}

void BM_Apply(benchmark::State& state) {
  const Skinning skinning(SharedTemplate(state), OptionsFor(state));
  const Pose pose = BenchPose(SharedTemplate(state));
  Eigen::MatrixX3d posed;
  for (auto _ : state) {
    skinning.Apply(pose, &posed);
    benchmark::DoNotOptimize(posed.data());
  }
  state.counters["vertices"] = SharedTemplate(state).num_vertices();
}
BENCHMARK(BM_Apply)
    ->ArgNames({"generated", "parallel"})
    ->ArgsProduct({{0, 1}, {0, 1}})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

void BM_ApplyWithJacobian(benchmark::State& state) {
  const Skinning skinning(SharedTemplate(state), OptionsFor(state));
  const Pose pose = BenchPose(SharedTemplate(state));
  Eigen::MatrixX3d posed;
  SkinningJacobian jacobian;
  for (auto _ : state) {
    skinning.ApplyWithJacobian(pose, &posed, &jacobian);
    benchmark::DoNotOptimize(posed.data());
    benchmark::DoNotOptimize(jacobian.Block(0).data());
  }
}
BENCHMARK(BM_ApplyWithJacobian)
    ->ArgNames({"generated", "parallel"})
    ->ArgsProduct({{0, 1}, {0, 1}})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

void BM_ComputeVertexNormals(benchmark::State& state) {
  const Skinning skinning(SharedTemplate(state));
  Eigen::MatrixX3d posed, normals;
  skinning.Apply(BenchPose(SharedTemplate(state)), &posed);
  for (auto _ : state) {
    ComputeVertexNormals(posed, SharedTemplate(state).triangles, &normals);
    benchmark::DoNotOptimize(normals.data());
  }
  state.counters["triangles"] = SharedTemplate(state).num_triangles();
}
BENCHMARK(BM_ComputeVertexNormals)
    ->ArgNames({"generated"})
    ->Arg(0)
    ->Arg(1)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

}  // namespace
}  // namespace artex
