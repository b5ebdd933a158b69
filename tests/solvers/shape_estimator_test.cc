#include "solvers/shape_estimator.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <random>

#include "models/error.h"
#include "models/normals.h"
#include "models/skinning.h"
#include "models/so3.h"
#include "render/rasterizer.h"
#include "tests/solvers/fitting_test_util.h"
#include "tests/testing_util.h"

namespace artex {
namespace {

using testing_util::CoarseTemplate;

Pose RandomPose(int joints, std::mt19937* rng, double spread) {
  std::normal_distribution<double> n(0.0, spread);
  Pose p = Pose::Identity(joints);
  p.translation = Eigen::Vector3d(0.0, 0.0, 2.5);
  p.rotation = ExpSO3(Eigen::Vector3d(0.0, n(*rng), 0.0));
  for (auto& r : p.joint_rotations) r = ExpSO3(Eigen::Vector3d(n(*rng), n(*rng), n(*rng)));
  return p;
}

// `frames` random poses (seeded) and noise-free scans of the subject in them.
void PosesAndScans(const Template& subject, int frames, double spread, unsigned seed,
                   std::vector<Pose>* poses, std::vector<Scan>* scans) {
  std::mt19937 rng(seed);
  for (int f = 0; f < frames; ++f) {
    poses->push_back(RandomPose(subject.num_joints(), &rng, spread));
    scans->push_back(testing_util::VertexScan(subject, poses->back()));
  }
}

// The scan's points `keep` (colourless).
Scan Subset(const Scan& scan, const std::vector<int>& keep) {
  Scan cut;
  cut.points = scan.points(keep, Eigen::all);
  cut.normals = scan.normals(keep, Eigen::all);
  cut.colors = Eigen::MatrixX3d::Zero(cut.points.rows(), 3);
  cut.color_valid.assign(keep.size(), 0);
  return cut;
}

// Index of the named shape parameter (num_parameters() when absent).
int ParameterIndex(const ShapeModel& model, const std::string& name) {
  const auto& names = model.parameter_names();
  return static_cast<int>(std::find(names.begin(), names.end(), name) - names.begin());
}

ShapeOptions Options(ShapeMode mode) {
  ShapeOptions o;
  o.mode = mode;
  o.prior_weight = 1e-8;
  // Random known shapes have independent factors along a limb: no chain prior (it would pull
  // the thigh and shank together).
  o.chain_prior_weight = 0.0;
  o.max_fit_vertices = 0;
  return o;
}

// Known shape parameters are recovered from noise-free scans of a subject with that shape,
// jointly with (perturbed) poses, starting from the template; with and without the leaf
// lengths and fork widths (5 more parameters, the hands' and feet's lengths seen on few
// vertices of this coarse mesh: the surface fit is looser), and bones_girth with the depth
// factors too (11 more).
TEST(ShapeEstimatorTest, RecoversKnownShapeFromNoiseFreeScans) {
  const Template& t = CoarseTemplate();
  for (int variant = 0; variant < 5; ++variant) {
    const ShapeMode mode = variant % 2 == 0 && variant < 4 ? ShapeMode::kBones
                                                           : ShapeMode::kBonesGirth;
    const bool extended = variant >= 2;
    ShapeOptions options = Options(mode);
    options.leaf_lengths = options.fork_widths = extended;
    options.girth_depth = variant == 4;
    ShapeEstimator estimator(t, options);
    const ShapeModel& model = estimator.model();
    std::mt19937 rng(11);
    std::uniform_real_distribution<double> u(-0.12, 0.12);
    Eigen::VectorXd truth(model.num_parameters());
    for (int i = 0; i < truth.size(); ++i) truth[i] = u(rng);
    const Template subject = model.Apply(truth);
    std::vector<Scan> scans;
    std::vector<Pose> poses;
    std::normal_distribution<double> noise(0.0, 0.03);
    for (int f = 0; f < 4; ++f) {
      const Pose pose = RandomPose(t.num_joints(), &rng, 0.35);
      scans.push_back(testing_util::VertexScan(subject, pose));
      Eigen::VectorXd d = Eigen::VectorXd::Zero(pose.num_parameters());
      for (int i = 1; i < d.size(); ++i) d[i] = noise(rng);
      poses.push_back(pose.Retracted(d));  // the tracker's pose, a little off
    }
    std::vector<const Scan*> pointers;
    for (const Scan& s : scans) pointers.push_back(&s);
    const ShapeSolveSummary summary =
        estimator.Solve(pointers, &poses, Eigen::VectorXd::Zero(truth.size()), 1e-8);
    EXPECT_GT(summary.iterations, 0);
    EXPECT_LT(summary.final_cost, 0.2 * summary.initial_cost);
    // Bone lengths along the body are observed only through the ends and bends of the limbs
    // (the correspondences pull little along a surface): a few per cent remain on the least
    // observable parameters of this coarse mesh.
    const Eigen::VectorXd error = (estimator.parameters() - truth).cwiseAbs();
    EXPECT_LT(error.mean(), 0.01) << ShapeModeName(mode) << " variant " << variant
                                  << ": initial mean error " << truth.cwiseAbs().mean();
    EXPECT_LT(error.maxCoeff(), 0.04) << ShapeModeName(mode) << " variant " << variant;
    // The fitted surface: mean vertex distance to the truth, against the template's.
    Eigen::MatrixX3d ours, before;
    Skinning(estimator.SubjectTemplate()).Apply(poses[0], &ours);
    Skinning(t).Apply(poses[0], &before);
    EXPECT_GT((before - scans[0].points).rowwise().norm().mean(), 5e-3);
    EXPECT_LT((ours - scans[0].points).rowwise().norm().mean(), extended ? 2.5e-3 : 1.5e-3)
        << ShapeModeName(mode) << " extended " << extended;
  }
}

// A subject whose shanks are 35 % longer than the template's (at s0): the template's feet sit
// on the subject's shins and the scan's feet lie beyond every E-step radius, so the
// template-to-scan energy alone leaves the shank short (the far subject B of docs/shape.md).
// The scan-to-model term (every scan point pulls its nearest template vertex) recovers it.
TEST(ShapeEstimatorTest, ScanToModelTermRecoversLongShanks) {
  const Template& t = CoarseTemplate();
  double error[2] = {0.0, 0.0};
  for (int with_term = 0; with_term < 2; ++with_term) {
    ShapeOptions o = Options(ShapeMode::kBones);
    o.scan_to_model_weight = with_term ? 0.3 : 0.0;
    ShapeEstimator estimator(t, o);
    const ShapeModel& model = estimator.model();
    const int shank = ParameterIndex(model, "bone:l_ankle");
    ASSERT_LT(shank, model.num_parameters());
    Eigen::VectorXd truth = Eigen::VectorXd::Zero(model.num_parameters());
    truth[shank] = 0.35;
    const Template subject = model.Apply(truth);
    std::vector<Scan> scans;
    std::vector<Pose> poses;
    PosesAndScans(subject, 3, 0.25, 7, &poses, &scans);
    std::vector<const Scan*> pointers;
    for (const Scan& s : scans) pointers.push_back(&s);
    estimator.Solve(pointers, &poses, Eigen::VectorXd::Zero(truth.size()), 1e-8);
    error[with_term] = std::abs(estimator.parameters()[shank] - truth[shank]);
  }
  EXPECT_GT(error[0], 0.1) << "the template-to-scan energy alone reaches the shank's end";
  EXPECT_LT(error[1], 0.03);
}

TEST(ShapeEstimatorTest, ScanToModelNormalDistancePicksTheVertexFacingAlike) {
  // A hand's scan point (facing the camera, -z) 1 cm from a thigh's side vertex (facing +x)
  // and 2.5 cm from the hand's vertex (facing -z); a second point on the thigh's side.
  Eigen::MatrixX3d vertices(2, 3), vertex_normals(2, 3), samples(2, 3), sample_normals(2, 3);
  vertices << 0.01, 0.0, 0.0,  //
      0.0, 0.0, 0.025;
  vertex_normals << 1.0, 0.0, 0.0,  //
      0.0, 0.0, -1.0;
  samples << 0.0, 0.0, 0.0,  //
      0.02, 0.0, 0.0;
  sample_normals << 0.0, 0.0, -1.0,  //
      1.0, 0.0, 0.0;
  std::vector<double> count;
  Eigen::MatrixX3d sum;
  ScanToModelSums(vertices, vertex_normals, samples, sample_normals, 0.3, 0.0, &count, &sum);
  EXPECT_EQ(count, (std::vector<double>{2.0, 0.0})) << "by distance alone: both on the thigh";
  // |p - x|^2 + d^2 |n_p - n_x|^2 with d = 2 cm: thigh 1 + 4 * 2 = 9 cm^2, hand 6.25 cm^2.
  ScanToModelSums(vertices, vertex_normals, samples, sample_normals, 0.3, 0.02, &count, &sum);
  EXPECT_EQ(count, (std::vector<double>{1.0, 1.0}));
  EXPECT_TRUE(sum.row(1).isZero()) << sum;
  EXPECT_DOUBLE_EQ(sum(0, 0), 0.02);
  // The distance compared with max_distance is the chosen vertex's (2.5 cm).
  ScanToModelSums(vertices, vertex_normals, samples, sample_normals, 0.02, 0.02, &count, &sum);
  EXPECT_EQ(count, (std::vector<double>{1.0, 0.0}));
}

// A depth camera seeing the subject (posed as RandomPose: 2.5 m in front of it along +z) from
// above its knees: the knee joints 30 px outside the image's top row.
PinholeCamera UpperBodyCamera(const Template& subject) {
  PinholeCamera camera;
  camera.fx = camera.fy = 500.0;
  const int knee = subject.FindJoint("l_knee");
  // v = fy y / 2.5 + cy for a point at depth 2.5 m (identity world_to_camera).
  camera.cy = -30.0 - camera.fy * subject.joints[knee].center.y() / 2.5;
  return camera;
}

// Parameters of parts out of view in every frame are held (hold_unseen); those in view are
// estimated: a subject with longer thighs and forearms, seen from above the knees (the scan
// keeps only the points the camera sees), gets its forearms and keeps the template's thighs.
TEST(ShapeEstimatorTest, HoldsTheParametersOfPartsOutOfView) {
  const Template& t = CoarseTemplate();
  ShapeOptions o = Options(ShapeMode::kBonesGirth);
  ShapeEstimator estimator(t, o);
  const ShapeModel& model = estimator.model();
  const int thigh = ParameterIndex(model, "bone:l_knee");
  const int forearm = ParameterIndex(model, "bone:l_wrist");
  ASSERT_LT(thigh, model.num_parameters());
  ASSERT_LT(forearm, model.num_parameters());
  Eigen::VectorXd truth = Eigen::VectorXd::Zero(model.num_parameters());
  truth[thigh] = 0.2;
  truth[forearm] = 0.1;
  const Template subject = model.Apply(truth);
  const PinholeCamera camera = UpperBodyCamera(t);
  std::vector<Scan> scans;
  std::vector<Pose> poses;
  PosesAndScans(subject, 4, 0.35, 5, &poses, &scans);
  for (Scan& scan : scans) {  // keep what the camera sees
    std::vector<int> keep;
    for (int i = 0; i < scan.size(); ++i) {
      const Eigen::Vector2d uv = camera.Project(scan.points.row(i).transpose());
      if (uv.x() >= 0.0 && uv.x() < camera.width && uv.y() >= 0.0 && uv.y() < camera.height) {
        keep.push_back(i);
      }
    }
    ASSERT_GT(keep.size(), 100u);
    ASSERT_LT(keep.size(), static_cast<size_t>(scan.size()));
    scan = Subset(scan, keep);
  }
  estimator.SetDepthCamera(camera, OutOfViewOptions());
  const std::vector<int> unseen = estimator.UnseenParameters(poses);
  const auto held = [&](const std::string& name) {
    return std::find(unseen.begin(), unseen.end(), ParameterIndex(model, name)) != unseen.end();
  };
  for (const char* name : {"bone:l_knee", "bone:l_ankle", "girth:l_knee", "length:l_ankle"}) {
    EXPECT_TRUE(held(name)) << name;
  }
  for (const char* name : {"bone:l_elbow", "bone:l_wrist", "bone:chest", "girth:chest"}) {
    EXPECT_FALSE(held(name)) << name;
  }
  std::vector<const Scan*> pointers;
  for (const Scan& s : scans) pointers.push_back(&s);
  estimator.Solve(pointers, &poses, Eigen::VectorXd::Zero(truth.size()), 1e-8);
  EXPECT_EQ(estimator.parameters()[thigh], 0.0) << "held at the template's";
  EXPECT_NEAR(estimator.parameters()[forearm], truth[forearm], 0.03);
  // Without a depth camera nothing is held.
  ShapeEstimator blind(t, o);
  EXPECT_TRUE(blind.UnseenParameters(poses).empty());
  o.hold_unseen = false;
  ShapeEstimator off(t, o);
  off.SetDepthCamera(camera, OutOfViewOptions());
  EXPECT_TRUE(off.UnseenParameters(poses).empty());
}

// A depth camera's drop-outs (here the shanks, missing from every frame's one-sided scan, as
// depth discontinuities and grazing angles thin a real one) bias the E-step's means next to the
// hole; the bias correction's self E-step, run on every camera-facing template vertex, does not
// have that hole and so does not cancel it. With bias_scan_mask the self E-step keeps only the
// vertices the depth image saw: the legs of the template, which is the subject here, stay
// closer to its own (measured: thigh and shank factors 0.8 and 1.3 % off without, 0.1 % with).
TEST(ShapeEstimatorTest, ScanMaskGivesTheSelfScanTheSensorsHoles) {
  const Template& t = CoarseTemplate();
  PinholeCamera camera;  // identity world_to_camera: the subject at depth 2.5 m, whole in view
  camera.fx = camera.fy = 500.0;
  camera.cy = 240.0 - camera.fy * 0.85 / 2.5;
  const int l_shank = t.FindJoint("l_knee"), r_shank = t.FindJoint("r_knee");
  ASSERT_GE(l_shank, 0);
  ASSERT_GE(r_shank, 0);
  std::vector<Scan> scans;
  std::vector<Pose> poses;
  PosesAndScans(t, 4, 0.2, 3, &poses, &scans);
  const Eigen::Vector3d eye = camera.Center();
  for (Scan& scan : scans) {  // camera-facing points off the shanks
    std::vector<int> keep;
    for (int i = 0; i < scan.size(); ++i) {
      const Eigen::Vector3d x = scan.points.row(i).transpose();
      const int joint = t.vertex_joint[i];
      if (joint == l_shank || joint == r_shank) continue;
      if (scan.normals.row(i).dot((eye - x).normalized()) > 0.3) keep.push_back(i);
    }
    scan = Subset(scan, keep);
  }
  std::vector<const Scan*> pointers;
  for (const Scan& s : scans) pointers.push_back(&s);
  double error[2] = {0.0, 0.0};
  for (int mask = 0; mask < 2; ++mask) {
    ShapeOptions o = Options(ShapeMode::kBones);
    o.bias_scan_mask = mask == 1;
    // The scans are the subject's vertices: the self scans from the vertices sample alike.
    o.bias_rendered_scan_to_model = false;
    o.bias_rendered_estep_max_radius = 0.0;
    ShapeEstimator estimator(t, o);
    estimator.SetDepthCamera(camera, OutOfViewOptions());
    std::vector<Pose> fitted = poses;
    estimator.Solve(pointers, &fitted, Eigen::VectorXd::Zero(estimator.model().num_parameters()),
                    1e-8);
    // The bones at the hole, thigh and shank (the truth is 0). Others drift alike in both runs
    // (a one-sided scan of this coarse mesh: the hip offsets and the spine by 4-9 %).
    for (const char* name : {"bone:l_knee", "bone:l_ankle"}) {
      const int p = ParameterIndex(estimator.model(), name);
      ASSERT_LT(p, estimator.model().num_parameters()) << name;
      error[mask] = std::max(error[mask], std::abs(estimator.parameters()[p]));
    }
  }
  EXPECT_GT(error[0], 0.008) << "the hole biases the legs without the mask";
  EXPECT_LT(error[1], 0.3 * error[0]) << "without the mask " << error[0] << ", with " << error[1];
}

// A depth camera's scan of the posed subject, noise-free: every pixel of its z-buffer
// back-projected, the normal interpolated from the hit triangle's vertex normals, the pixels
// facing the camera by more than 0.3 (a sensor's grazing-angle drop-outs).
Scan DepthCameraScan(const Template& subject, const Pose& pose, const PinholeCamera& camera) {
  Eigen::MatrixX3d posed, normals;
  Skinning(subject).Apply(pose, &posed);
  ComputeVertexNormals(posed, subject.triangles, &normals);
  RasterBuffers raster;
  Rasterize(posed, subject.triangles, camera, RasterOptions(), &raster);
  std::vector<Eigen::Vector3d> points, point_normals;
  for (int v = 0; v < raster.height; ++v) {
    for (int u = 0; u < raster.width; ++u) {
      const int p = raster.index(u, v);
      if (!std::isfinite(raster.depth[p])) continue;
      const Eigen::Vector3i tri = subject.triangles.row(raster.triangle_id[p]).transpose();
      const Eigen::Vector2f b = raster.barycentric[p];
      const Eigen::Vector3d n = ((1.0 - b.x() - b.y()) * normals.row(tri[0]) +
                                 b.x() * normals.row(tri[1]) + b.y() * normals.row(tri[2]))
                                    .normalized()
                                    .transpose();
      const Eigen::Vector3d x = camera.Unproject(u, v, raster.depth[p]);
      if (n.dot((camera.Center() - x).normalized()) <= 0.3) continue;
      points.push_back(x);
      point_normals.push_back(n);
    }
  }
  Scan scan;
  scan.points.resize(points.size(), 3);
  scan.normals.resize(points.size(), 3);
  for (size_t k = 0; k < points.size(); ++k) {
    scan.points.row(k) = points[k].transpose();
    scan.normals.row(k) = point_normals[k].transpose();
  }
  scan.colors = Eigen::MatrixX3d::Zero(scan.size(), 3);
  scan.color_valid.assign(scan.size(), 0);
  return scan;
}

// A depth camera's scan is a pixel grid, several times denser than the template's vertices and
// subsampled by the scan-to-model term on a voxel grid. The biases of the E-step and of that
// term measured on the template's thinned vertices are not the scan's: the template, scanned
// in exact poses by a noise-free camera, drifts from its own shape by 2-3.5 % per factor,
// whichever of the two self scans comes from the vertices. With both rendered as the camera
// samples the template (bias_rendered_scan_to_model, bias_rendered_estep_max_radius) in every
// stage it stays put. (By default only the scan-to-model term's is rendered: on the virtual
// Kinect, with its noise, the E-step's rendered in the wide stages too sends the tall subjects'
// hips 5 cm low; docs/shape-measurements.md, "The self scans on the depth camera's pixel grid".)
TEST(ShapeEstimatorTest, RenderedSelfScansKeepTheTruthAFixedPoint) {
  const Template& t = CoarseTemplate();
  // Identity world_to_camera: the subject at depth 2.5 m, whole in view; 320x240 pixels (1 cm
  // apart there, still denser than this coarse template's vertices) keep the test short under
  // the sanitizers.
  PinholeCamera camera;
  camera.width = 320;
  camera.height = 240;
  camera.fx = camera.fy = 250.0;
  camera.cx = 160.0;
  camera.cy = 120.0 - camera.fy * 0.85 / 2.5;
  std::mt19937 rng(5);
  std::vector<Pose> poses;
  std::vector<Scan> scans;
  for (int f = 0; f < 2; ++f) {
    poses.push_back(RandomPose(t.num_joints(), &rng, 0.2));
    scans.push_back(DepthCameraScan(t, poses.back(), camera));
  }
  std::vector<const Scan*> pointers;
  for (const Scan& s : scans) pointers.push_back(&s);
  double drift[4] = {0.0, 0.0, 0.0, 0.0};  // E-step / scan-to-model: vv, vr, rv, rr
  for (int variant = 0; variant < 4; ++variant) {
    ShapeOptions o = Options(ShapeMode::kBonesGirth);
    o.bias_rendered_estep_max_radius = variant >= 2 ? 1.0 : 0.0;  // every stage or none
    o.bias_rendered_scan_to_model = variant % 2 == 1;
    o.radii = {0.04, 0.03};  // two stages: short under the sanitizers
    ShapeEstimator estimator(t, o);
    estimator.SetDepthCamera(camera, OutOfViewOptions());
    std::vector<Pose> fitted = poses;
    estimator.Solve(pointers, &fitted, Eigen::VectorXd::Zero(estimator.model().num_parameters()),
                    1e-8);
    drift[variant] = estimator.parameters().cwiseAbs().mean();
  }
  // Measured: 0.026, 0.035, 0.018 and below 1e-7.
  EXPECT_GT(drift[0], 0.01) << "both self scans from the vertices";
  EXPECT_GT(drift[1], 0.01) << "the E-step's self scan from the vertices";
  EXPECT_GT(drift[2], 0.01) << "the scan-to-model term's self scan from the vertices";
  EXPECT_LT(drift[3], 1e-4) << "both rendered: the truth is a fixed point";
}

// The preprocessing removes the floor and with it the feet's underside; nothing in the scan
// then keeps the legs from growing into the floor. Here the scan ends 0.3 m above the floor
// (nothing of the shanks' lower half or the feet) and a prior pulls the shanks 30 % long: without
// the floor term they follow it, the feet sinking under the floor; with it the feet stay on the
// floor and the shanks near their length.
TEST(ShapeEstimatorTest, FloorTermKeepsTheFeetOnTheFloor) {
  const Template& t = CoarseTemplate();
  const Skinning skinning(t);
  std::mt19937 rng(5);
  std::vector<Scan> scans;
  std::vector<Pose> poses;
  for (int f = 0; f < 3; ++f) {
    Pose pose = RandomPose(t.num_joints(), &rng, 0.1);
    Eigen::MatrixX3d posed;
    skinning.Apply(pose, &posed);
    pose.translation.y() -= posed.col(1).minCoeff();  // the lowest vertex on the floor y = 0
    const Scan full = testing_util::VertexScan(t, pose);
    std::vector<int> keep;
    for (int i = 0; i < full.size(); ++i) {
      if (full.points(i, 1) > 0.3) keep.push_back(i);
    }
    scans.push_back(Subset(full, keep));
    poses.push_back(pose);
  }
  std::vector<const Scan*> pointers;
  for (const Scan& s : scans) pointers.push_back(&s);
  double shank[2] = {0.0, 0.0}, lowest[2] = {0.0, 0.0};
  for (int with_floor = 0; with_floor < 2; ++with_floor) {
    ShapeOptions o = Options(ShapeMode::kBones);
    o.floor_weight = 1.0;
    ShapeEstimator estimator(t, o);
    if (with_floor) estimator.SetFloor(Eigen::Vector3d(0.0, 2.0, 0.0), 0.0);  // normalised
    const int p = ParameterIndex(estimator.model(), "bone:l_ankle");
    ASSERT_LT(p, estimator.model().num_parameters());
    Eigen::VectorXd q_ref = Eigen::VectorXd::Zero(estimator.model().num_parameters());
    q_ref[p] = 0.3;
    std::vector<Pose> fitted = poses;
    estimator.Solve(pointers, &fitted, q_ref, 3e-4);
    shank[with_floor] = estimator.parameters()[p];
    EXPECT_FALSE(estimator.floor_contradicted());
    Eigen::MatrixX3d posed;
    double low = 0.0;
    for (const Pose& pose : fitted) {
      Skinning(estimator.SubjectTemplate()).Apply(pose, &posed);
      low = std::min(low, posed.col(1).minCoeff());
    }
    lowest[with_floor] = low;
  }
  // Measured: shanks +0.22 and the feet 9 cm under the floor without it; +0.05 and 2 cm with.
  EXPECT_GT(shank[0], 0.15) << "without a floor the prior stretches the shanks";
  EXPECT_LT(lowest[0], -0.06);
  EXPECT_LT(shank[1], 0.1) << "without the floor term " << shank[0];
  EXPECT_GT(lowest[1], -0.03);
  // A "floor" half a metre up, above the scan's lower part (a table top taken for the floor):
  // the solve leaves the term out and says so.
  ShapeOptions o = Options(ShapeMode::kBones);
  ShapeEstimator raised(t, o);
  raised.SetFloor(Eigen::Vector3d::UnitY(), -0.5);
  const int p = ParameterIndex(raised.model(), "bone:l_ankle");
  Eigen::VectorXd q_ref = Eigen::VectorXd::Zero(raised.model().num_parameters());
  q_ref[p] = 0.3;
  std::vector<Pose> fitted = poses;
  raised.Solve(pointers, &fitted, q_ref, 3e-4);
  EXPECT_TRUE(raised.floor_contradicted());
  EXPECT_EQ(raised.parameters()[p], shank[0]);
  ShapeEstimator estimator(t, Options(ShapeMode::kBones));
  EXPECT_THROW(estimator.SetFloor(Eigen::Vector3d::Zero(), 0.0), Error);
  EXPECT_FALSE(estimator.has_floor());
}

TEST(ShapeEstimatorTest, CalibratesAfterTheConfiguredFramesThenFreezes) {
  const Template& t = CoarseTemplate();
  ShapeOptions o = Options(ShapeMode::kScale);
  o.calibration_frames = 3;
  o.calibration_stride = 2;
  o.calibration_rounds = 1;
  o.radii = {0.03};
  o.iterations_per_stage = 12;
  ShapeEstimator estimator(t, o);
  const Template subject = estimator.model().Apply(Eigen::VectorXd::Constant(1, 0.05));
  std::mt19937 rng(5);
  int changed_at = -1;
  std::vector<int> kept;  // the frames KeepsNextFrame announces
  for (int f = 0; f < 9; ++f) {
    const Pose pose = RandomPose(t.num_joints(), &rng, 0.2);
    Pose refined;
    if (estimator.KeepsNextFrame(/*scale_settled=*/f > 0)) kept.push_back(f);
    // The first frame has no settled scale: it is no calibration frame.
    if (estimator.AddFrame(testing_util::VertexScan(subject, pose), pose, /*scale_settled=*/f > 0, &refined)) {
      EXPECT_EQ(changed_at, -1) << "frozen after calibration (refine_every 0)";
      changed_at = f;
      EXPECT_TRUE(refined.AllFinite());
    }
  }
  EXPECT_EQ(changed_at, 5);  // frames 1, 3, 5
  EXPECT_EQ(kept, (std::vector<int>{1, 3, 5}));
  EXPECT_TRUE(estimator.calibrated());
  EXPECT_EQ(estimator.calibration_summary().frames, 3);
  EXPECT_NEAR(estimator.parameters()[0], 0.05, 0.01);
}

TEST(ShapeEstimatorTest, FixedModeNeverChangesTheTemplate) {
  const Template& t = CoarseTemplate();
  ShapeEstimator estimator(t, ShapeOptions());
  EXPECT_FALSE(estimator.enabled());
  EXPECT_EQ(estimator.parameters().size(), 0);
  std::mt19937 rng(2);
  for (int f = 0; f < 12; ++f) {
    const Pose pose = RandomPose(t.num_joints(), &rng, 0.2);
    EXPECT_FALSE(estimator.AddFrame(testing_util::VertexScan(t, pose), pose, true));
  }
  EXPECT_LT((estimator.SubjectTemplate().vertices - t.vertices).cwiseAbs().maxCoeff(), 1e-15);
}

// A deeper chest (depth factor 1.15, every other parameter the template's) is recovered with
// girth_depth; a strong depth prior holds the depth factors at the girths' proportions.
TEST(ShapeEstimatorTest, DepthPriorHoldsTheProportions) {
  const Template& t = CoarseTemplate();
  for (double weight : {0.0, 1.0}) {
    ShapeOptions o = Options(ShapeMode::kBonesGirth);
    o.girth_depth = true;
    o.depth_prior_weight = weight;
    ShapeEstimator estimator(t, o);
    const auto& names = estimator.model().parameter_names();
    const int chest = ParameterIndex(estimator.model(), "depth:chest");
    ASSERT_LT(chest, estimator.model().num_parameters());
    Eigen::VectorXd truth = Eigen::VectorXd::Zero(estimator.model().num_parameters());
    truth[chest] = 0.15;
    const Template subject = estimator.model().Apply(truth);
    std::vector<Scan> scans;
    std::vector<Pose> poses;
    PosesAndScans(subject, 2, 0.2, 13, &poses, &scans);
    estimator.Solve({&scans[0], &scans[1]}, &poses, Eigen::VectorXd::Zero(truth.size()), 1e-8);
    double depth_max = 0.0;
    for (int p = 0; p < truth.size(); ++p) {
      if (names[p].rfind("depth:", 0) == 0) {
        depth_max = std::max(depth_max, std::abs(estimator.parameters()[p]));
      }
    }
    if (weight == 0.0) {
      EXPECT_NEAR(estimator.parameters()[chest], 0.15, 0.02);
    } else {
      EXPECT_LT(depth_max, 0.01);
    }
  }
  ShapeOptions bad;
  bad.depth_prior_weight = -1.0;
  std::string why;
  EXPECT_FALSE(bad.IsValid(&why));
  EXPECT_NE(why.find("depth_prior_weight"), std::string::npos) << why;
}

// The limb girth prior ties the thigh's girth to the shank's (and the upper arm's to the
// forearm's) and no other pair: with it a subject whose thigh is thicker and shank thinner
// than the template's gets one girth for both, between the two, while the feet's and the
// chest's girths are recovered as without it.
TEST(ShapeEstimatorTest, LimbGirthPriorTiesThighAndShankOnly) {
  const Template& t = CoarseTemplate();
  for (double weight : {0.0, 1.0}) {
    ShapeOptions o = Options(ShapeMode::kBonesGirth);
    o.limb_girth_prior_weight = weight;
    ShapeEstimator estimator(t, o);
    const ShapeModel& model = estimator.model();
    const int thigh = ParameterIndex(model, "girth:l_hip");
    const int shank = ParameterIndex(model, "girth:l_knee");
    const int foot = ParameterIndex(model, "girth:l_ankle");
    const int chest = ParameterIndex(model, "girth:chest");
    ASSERT_LT(std::max({thigh, shank, foot, chest}), model.num_parameters());
    Eigen::VectorXd truth = Eigen::VectorXd::Zero(model.num_parameters());
    truth[thigh] = 0.2;
    truth[shank] = -0.1;
    truth[foot] = 0.15;
    truth[chest] = 0.1;
    const Template subject = model.Apply(truth);
    std::vector<Scan> scans;
    std::vector<Pose> poses;
    PosesAndScans(subject, 2, 0.2, 17, &poses, &scans);
    estimator.Solve({&scans[0], &scans[1]}, &poses, Eigen::VectorXd::Zero(truth.size()), 1e-8);
    const Eigen::VectorXd& q = estimator.parameters();
    EXPECT_NEAR(q[foot], 0.15, 0.03) << "weight " << weight;
    EXPECT_NEAR(q[chest], 0.1, 0.03) << "weight " << weight;
    if (weight == 0.0) {
      EXPECT_NEAR(q[thigh], 0.2, 0.03);
      EXPECT_NEAR(q[shank], -0.1, 0.03);
    } else {
      EXPECT_NEAR(q[thigh], q[shank], 0.01);
      EXPECT_GT(q[shank], -0.1 + 0.05);
      EXPECT_LT(q[thigh], 0.2 - 0.05);
    }
  }
  ShapeOptions bad;
  bad.limb_girth_prior_weight = -1.0;
  std::string why;
  EXPECT_FALSE(bad.IsValid(&why));
  EXPECT_NE(why.find("limb_girth_prior_weight"), std::string::npos) << why;
}

TEST(ShapeEstimatorTest, BoundsHoldAndOptionsAreChecked) {
  const Template& t = CoarseTemplate();
  ShapeOptions o = Options(ShapeMode::kScale);
  o.bone_max = 1.02;
  o.girth_max = 1.02;
  o.radii = {0.05, 0.03};
  ShapeEstimator estimator(t, o);
  const Template subject = estimator.model().Apply(Eigen::VectorXd::Constant(1, 0.1));
  std::vector<Scan> scans;
  std::vector<Pose> poses;
  PosesAndScans(subject, 2, 0.2, 9, &poses, &scans);
  estimator.Solve({&scans[0], &scans[1]}, &poses, Eigen::VectorXd::Zero(1), 1e-8);
  EXPECT_NEAR(estimator.parameters()[0], 0.02, 1e-12);  // pushed to the bound
  ShapeOptions bad;
  bad.calibration_frames = 0;
  EXPECT_THROW(ShapeEstimator(t, bad), Error);
  bad = ShapeOptions();
  bad.bone_min = 1.2;
  std::string why;
  EXPECT_FALSE(bad.IsValid(&why));
  EXPECT_NE(why.find("bone_min"), std::string::npos) << why;
  bad = ShapeOptions();
  bad.bias_rendered_estep_max_radius = -0.01;
  EXPECT_FALSE(bad.IsValid(&why));
  EXPECT_NE(why.find("bias_rendered_estep_max_radius"), std::string::npos) << why;
  bad = ShapeOptions();
  bad.scan_to_model_normal_distance = -0.01;
  EXPECT_FALSE(bad.IsValid(&why));
  EXPECT_NE(why.find("scan_to_model_normal_distance"), std::string::npos) << why;
  bad = ShapeOptions();
  bad.bias_mask_tolerance = 0.0;
  EXPECT_FALSE(bad.IsValid(&why));
  EXPECT_NE(why.find("bias_mask_tolerance"), std::string::npos) << why;
  bad = ShapeOptions();
  bad.bias_mask_radius_px = -1;
  EXPECT_FALSE(bad.IsValid(&why));
  EXPECT_NE(why.find("bias_mask_radius_px"), std::string::npos) << why;
  bad = ShapeOptions();
  bad.floor_weight = -1.0;
  EXPECT_FALSE(bad.IsValid(&why));
  EXPECT_NE(why.find("floor_weight"), std::string::npos) << why;
}

}  // namespace
}  // namespace artex
