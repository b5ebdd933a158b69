// Synthetic ground truth for the kinematic fitting: a template posed with a known random pose,
// a depth-camera-like scan sampled from its front-facing surface with noise, a perturbed
// start; the EM fitter must recover the pose (Gauss-Newton and Ceres LM), both M-step backends
// must reach the same cost, the ICP baseline and the dense E-step are reported, and the
// literal energy with a free scale must show the scale collapse of docs/design.md.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <limits>
#include <memory>
#include <random>
#include <set>

#include "energies/one_to_many_correspondence.h"
#include "energies/tikhonov_term.h"
#include "models/error.h"
#include "models/normals.h"
#include "models/so3.h"
#include "solvers/em_fitter.h"
#include "solvers/estep.h"
#include "solvers/fit_solver.h"
#include "solvers/fit_vertex_subset.h"
#include "solvers/icp_init.h"
#include "tests/solvers/fitting_test_util.h"

namespace artex {
namespace {

using testing_util::MeanVertexError;

class FittingTest : public ::testing::Test {
 protected:
  FittingTest() : model_(testing_util::MakeStickTemplate()), skinning_(model_), rng_(42) {
    truth_ = testing_util::RandomPose(model_.num_joints(), 0.3, 0.25, 0.1, &rng_);
    Eigen::MatrixX3d posed;
    skinning_.Apply(truth_, &posed);
    scan_ = testing_util::SampleScan(posed, model_.triangles, camera_, 6000.0, 0.003, &rng_);
    // Start: 2 cm / ~3 degrees off globally, ~0.07 rad per joint.
    Eigen::VectorXd d = Eigen::VectorXd::Zero(truth_.num_parameters());
    std::normal_distribution<double> g(0.0, 1.0);
    for (int i = 0; i < 3; ++i) d[kTranslationIndex + i] = 0.02 / std::sqrt(3.0) * g(rng_);
    for (int i = 0; i < 3; ++i) d[kGlobalRotationIndex + i] = 0.03 * g(rng_);
    for (int i = kNumGlobalParameters; i < d.size(); ++i) d[i] = 0.04 * g(rng_);
    start_ = truth_.Retracted(d);
  }

  EMFitterOptions DefaultOptions() const {
    EMFitterOptions options;
    options.icp_first_frame = false;
    options.scale_mode = ScaleMode::kFixed;
    return options;
  }

  // Fits a's and b's first frames from start_ (the same, bit for bit, expected), then starts b
  // again and c from a's pose as accepted tracking poses and fits a tracking frame with each.
  struct TrackingFits {
    FitSummary a, b, c;
  };
  TrackingFits FitFirstThenTrack(EMFitter* a, EMFitter* b, EMFitter* c) {
    a->SetInitialPose(start_);
    b->SetInitialPose(start_);
    const FitSummary first_a = a->FitFrame(scan_), first_b = b->FitFrame(scan_);
    EXPECT_EQ(first_a.iterations, first_b.iterations);
    EXPECT_TRUE(a->pose().ToVector() == b->pose().ToVector());
    b->Reset();
    b->AcceptPose(scan_, a->pose());
    c->AcceptPose(scan_, a->pose());
    EXPECT_TRUE(a->tracking() && b->tracking() && c->tracking());
    return {a->FitFrame(scan_), b->FitFrame(scan_), c->FitFrame(scan_)};
  }

  FitSummary Fit(const EMFitterOptions& options, const Pose& start, Pose* result,
                 const Scan* scan = nullptr) {
    EMFitter fitter(model_, options);
    fitter.SetInitialPose(start);
    const FitSummary summary = fitter.FitFrame(scan ? *scan : scan_);
    *result = fitter.pose();
    return summary;
  }

  Template model_;
  Skinning skinning_;
  std::mt19937_64 rng_;
  Eigen::Vector3d camera_{0.0, 1.2, 3.5};
  Pose truth_, start_;
  Scan scan_;
};

TEST_F(FittingTest, GaussNewtonRecoversGroundTruth) {
  const double start_error = MeanVertexError(skinning_, start_, truth_);
  ASSERT_GT(start_error, 0.015);
  Pose result;
  const FitSummary summary = Fit(DefaultOptions(), start_, &result);
  const double error = MeanVertexError(skinning_, result, truth_);
  std::cout << "GN-EM: start error " << start_error * 1e3 << " mm, final " << error * 1e3 << " mm, "
            << summary.BriefReport() << "\n";
  RecordProperty("gn_mean_vertex_error_mm", std::to_string(error * 1e3));
  EXPECT_TRUE(summary.ok());
  EXPECT_LT(error, 0.003);
  EXPECT_LT(summary.final_cost, summary.initial_cost);
  EXPECT_GT(summary.iterations, 1);
  EXPECT_EQ(static_cast<int>(summary.trace.size()), summary.iterations);
}

TEST_F(FittingTest, TrackingFramesFitTheTrackingSubset) {
  // tracking_max_fit_vertices: first frames fit max_fit_vertices' subset, tracking frames the
  // smaller one. A fitter with both budgets fits its first frame like a fitter with the large
  // budget alone and a tracking frame (from the same accepted pose) like one with the small
  // budget alone, bit for bit; the large budget alone tracks differently.
  EMFitterOptions both = DefaultOptions(), large = DefaultOptions(), small = DefaultOptions();
  both.max_fit_vertices = 250;
  both.tracking_max_fit_vertices = 100;
  large.max_fit_vertices = 250;
  large.tracking_max_fit_vertices = 0;  // max_fit_vertices
  small.max_fit_vertices = 100;
  small.tracking_max_fit_vertices = 400;  // capped by max_fit_vertices
  EMFitter a(model_, both), b(model_, large), c(model_, small);
  EXPECT_EQ(a.fit_vertices(), b.fit_vertices());
  EXPECT_EQ(a.fit_vertices(true), c.fit_vertices());
  EXPECT_EQ(c.fit_vertices(true), c.fit_vertices());
  EXPECT_EQ(b.fit_vertices(true), b.fit_vertices());
  EXPECT_LE(static_cast<int>(a.fit_vertices(true).size()), 100);
  EXPECT_GT(a.fit_vertices().size(), a.fit_vertices(true).size());

  const TrackingFits track = FitFirstThenTrack(&a, &b, &c);
  EXPECT_TRUE(track.a.ok());
  EXPECT_EQ(track.a.iterations, track.c.iterations);
  EXPECT_TRUE(a.pose().ToVector() == c.pose().ToVector());
  EXPECT_FALSE(a.pose().ToVector() == b.pose().ToVector());
  EXPECT_LT(MeanVertexError(skinning_, a.pose(), truth_), 0.01);
}

TEST_F(FittingTest, TrackingFramesShareOneCloudAndGather) {
  // tracking_shared_cloud: first frames are fitted as without it, bit for bit; a tracking
  // frame is fitted exactly as with E-step options that give every radius the widest tracking
  // radius' cloud and lists, gathering once where the per-radius clouds gather per radius.
  EMFitterOptions shared = DefaultOptions(), per_radius = DefaultOptions();
  ASSERT_TRUE(shared.tracking_shared_cloud);
  ASSERT_GT(shared.tracking_radii.size(), 1u);
  per_radius.tracking_shared_cloud = false;
  EMFitterOptions explicit_options = per_radius;
  const double widest = *std::max_element(shared.tracking_radii.begin(),
                                          shared.tracking_radii.end());
  explicit_options.estep.voxel_cell = widest * shared.estep.voxel_fraction;
  explicit_options.estep.list_radius = widest;
  EMFitter a(model_, shared), b(model_, per_radius), c(model_, explicit_options);
  const TrackingFits track = FitFirstThenTrack(&a, &b, &c);
  EXPECT_TRUE(track.a.ok());
  EXPECT_EQ(track.a.iterations, track.c.iterations);
  EXPECT_TRUE(a.pose().ToVector() == c.pose().ToVector());
  EXPECT_FALSE(a.pose().ToVector() == b.pose().ToVector());
  EXPECT_LT(track.a.neighbor_queries, track.b.neighbor_queries);
  EXPECT_LT(MeanVertexError(skinning_, a.pose(), truth_), 0.01);
  EXPECT_LT(MeanVertexError(skinning_, b.pose(), truth_), 0.01);
}

TEST_F(FittingTest, CandidateListsDoNotChangeTheFit) {
  // The E-step's per-frame candidate lists are exact: the same EM trajectory as a kd-tree
  // search per E-step, on a first frame and on a tracking frame.
  EMFitterOptions cached = DefaultOptions(), fresh = DefaultOptions();
  fresh.estep.candidate_margin = 0.0;
  ASSERT_GT(cached.estep.candidate_margin, 0.0);
  EMFitter a(model_, cached), b(model_, fresh);
  a.SetInitialPose(start_);
  b.SetInitialPose(start_);
  for (int frame = 0; frame < 2; ++frame) {
    const FitSummary sa = a.FitFrame(scan_), sb = b.FitFrame(scan_);
    EXPECT_EQ(sa.iterations, sb.iterations);
    EXPECT_LT(MeanVertexError(skinning_, a.pose(), b.pose()), 1e-9);
    EXPECT_LT(sa.neighbor_queries, sb.neighbor_queries);  // gathers once, not per E-step
    EXPECT_GT(sa.candidates_visited, 0);
  }
}

TEST_F(FittingTest, FitVertexSubsets) {
  // Both selections give at most max_fit_vertices distinct template vertices and recover the
  // pose (from 50 mm); the voxel subset covers the surface at least as evenly as the index stride
  // (largest distance from a template vertex to the nearest fitted vertex).
  const int count = 250;
  double coverage[2] = {0.0, 0.0};
  for (FitVertexSelection selection : {FitVertexSelection::kStride, FitVertexSelection::kVoxel}) {
    EMFitterOptions options = DefaultOptions();
    options.max_fit_vertices = count;
    options.fit_vertex_selection = selection;
    EMFitter fitter(model_, options);
    std::vector<int> subset = fitter.fit_vertices();
    EXPECT_LE(static_cast<int>(subset.size()), count);
    EXPECT_GE(static_cast<int>(subset.size()), count * 6 / 10);
    std::sort(subset.begin(), subset.end());
    EXPECT_EQ(std::unique(subset.begin(), subset.end()), subset.end());
    EXPECT_GE(subset.front(), 0);
    EXPECT_LT(subset.back(), model_.num_vertices());
    double worst = 0.0;
    for (int v = 0; v < model_.num_vertices(); ++v) {
      double best = std::numeric_limits<double>::infinity();
      for (int t : subset)
        best = std::min(best, (model_.vertices.row(v) - model_.vertices.row(t)).norm());
      worst = std::max(worst, best);
    }
    coverage[selection == FitVertexSelection::kVoxel] = worst;
    fitter.SetInitialPose(start_);
    const FitSummary summary = fitter.FitFrame(scan_);
    EXPECT_TRUE(summary.ok());
    // 250 of 588 vertices on thin tubes: coarser than the full fit (1.7 mm), still recovered.
    EXPECT_LT(MeanVertexError(skinning_, fitter.pose(), truth_), 0.015);
  }
  EXPECT_LE(coverage[1], coverage[0] + 1e-12);
  EXPECT_EQ(FitVertexSelectionNames().at("voxel"), FitVertexSelection::kVoxel);
}

TEST_F(FittingTest, MeanMotionIsOverTheFittedVertices) {
  // The divergence check's mean motion: the fitted vertices' mean displacement from the
  // frame's initial guess (the subset's when the fit uses one, else every vertex's).
  for (const int count : {250, 0}) {
    EMFitterOptions options = DefaultOptions();
    options.max_fit_vertices = count;
    EMFitter fitter(model_, options);
    fitter.SetInitialPose(start_);
    const FitSummary summary = fitter.FitFrame(scan_);
    ASSERT_TRUE(summary.ok());
    Eigen::MatrixX3d before, after;
    skinning_.Apply(start_, &before);
    skinning_.Apply(fitter.pose(), &after);
    std::vector<int> vertices = fitter.fit_vertices();
    if (vertices.empty()) {
      for (int v = 0; v < model_.num_vertices(); ++v) vertices.push_back(v);
    }
    if (count > 0) {
      EXPECT_LE(static_cast<int>(vertices.size()), count);
    } else {
      EXPECT_EQ(static_cast<int>(vertices.size()), model_.num_vertices());
    }
    double sum = 0.0;
    for (int v : vertices) sum += (after.row(v) - before.row(v)).norm();
    EXPECT_NEAR(summary.mean_motion, sum / vertices.size(), 1e-12) << count;
    EXPECT_GT(summary.mean_motion, 0.01);  // start_ is ~50 mm from the truth
  }
}

TEST(VoxelVertexSubsetTest, OneVertexPerCellOfTheSmallestGridWithinTheCount) {
  // A 10 x 10 x 10 lattice of unit spacing (extent 9): cells up to 1.8 wide hold at most 6
  // lattice planes per axis (216 cells), wider ones up to 2.25 hold 5 (125 cells), so a count
  // of 125..215 gives 125 vertices, one per 2 x 2 x 2 block of the lattice.
  Eigen::MatrixX3d lattice(1000, 3);
  for (int i = 0; i < 1000; ++i) lattice.row(i) << i % 10, i / 10 % 10, i / 100;
  for (int count : {125, 200}) {
    std::vector<int> subset = VoxelVertexSubset(lattice, count);
    ASSERT_EQ(subset.size(), 125u) << count;
    std::set<int> blocks;
    for (int v : subset) {
      const Eigen::RowVector3d p = lattice.row(v);
      blocks.insert(static_cast<int>(p.x()) / 2 + 5 * (static_cast<int>(p.y()) / 2) +
                    25 * (static_cast<int>(p.z()) / 2));
    }
    EXPECT_EQ(blocks.size(), 125u) << count;
  }
  // Fewer cells allowed than 5 per axis: the next coarser grid (4 planes: 64 cells).
  EXPECT_EQ(VoxelVertexSubset(lattice, 124).size(), 64u);
  // Repeated points share a cell: 1000 copies of 3 distinct points give 3 vertices.
  Eigen::MatrixX3d repeated(3000, 3);
  for (int i = 0; i < 3000; ++i) repeated.row(i) << i % 3, 0.0, 0.0;
  EXPECT_EQ(VoxelVertexSubset(repeated, 10).size(), 3u);
  // Degenerate input: every vertex at one point, no vertices, no count.
  EXPECT_EQ(VoxelVertexSubset(Eigen::MatrixX3d::Ones(5, 3), 3), std::vector<int>{0});
  EXPECT_TRUE(VoxelVertexSubset(Eigen::MatrixX3d(0, 3), 3).empty());
  EXPECT_TRUE(VoxelVertexSubset(lattice, 0).empty());
}

TEST_F(FittingTest, NormalsRefreshedEveryIterationOrPerStage) {
  for (int refresh : {1, 0}) {
    EMFitterOptions options = DefaultOptions();
    options.normal_refresh_iterations = refresh;
    Pose result;
    const FitSummary summary = Fit(options, start_, &result);
    EXPECT_TRUE(summary.ok());
    EXPECT_LT(MeanVertexError(skinning_, result, truth_), 0.003) << "refresh " << refresh;
  }
}

TEST_F(FittingTest, CeresLevenbergMarquardtRecoversGroundTruth) {
  EMFitterOptions options = DefaultOptions();
  options.solver.type = FitSolverType::kCeresLevenbergMarquardt;
  options.solver.max_iterations = 5;
  Pose result;
  const FitSummary summary = Fit(options, start_, &result);
  const double error = MeanVertexError(skinning_, result, truth_);
  std::cout << "Ceres-EM: final " << error * 1e3 << " mm, " << summary.BriefReport() << "\n";
  RecordProperty("ceres_mean_vertex_error_mm", std::to_string(error * 1e3));
  EXPECT_TRUE(summary.ok());
  EXPECT_LT(error, 0.003);
}

TEST_F(FittingTest, GaussNewtonAndCeresReachTheSameCost) {
  // One M-step problem with fixed E-step targets, solved to convergence by both backends.
  Eigen::MatrixX3d posed, normals;
  skinning_.Apply(start_, &posed);
  ComputeVertexNormals(posed, model_.triangles, &normals);
  EStepOptions estep_options;
  EStep estep(scan_, estep_options);
  PosedTemplateView view;
  view.vertices = &posed;
  view.normals = &normals;
  CorrespondenceTargets targets;
  estep.Compute(view, 0.1, &targets);
  ASSERT_GT(targets.total_weight(), 0.0);
  OneToManyCorrespondenceTerm data(&targets, 1.0 / targets.total_weight());
  TikhonovOptions tikhonov_options;
  tikhonov_options.update = {1e-3, 1e-4, 1e-4, 1e-4};
  TikhonovTerm tikhonov(tikhonov_options, model_.num_joints(), &truth_);
  FitProblem problem;
  problem.skinning = &skinning_;
  problem.anchor = start_;
  problem.terms = {&data, &tikhonov};
  problem.constant_parameters = {kScaleIndex};

  FitSolverOptions options;
  options.max_iterations = 50;
  options.function_tolerance = 1e-12;
  options.parameter_tolerance = 1e-12;
  Pose gn_pose = start_, ceres_pose = start_;
  const FitSolverSummary gn = FitSolver::Create(options)->Solve(problem, &gn_pose);
  options.type = FitSolverType::kCeresLevenbergMarquardt;
  const FitSolverSummary lm = FitSolver::Create(options)->Solve(problem, &ceres_pose);
  std::cout << "GN: " << gn.BriefReport() << "\nLM: " << lm.BriefReport() << "\n";
  EXPECT_NE(gn.termination, FitTermination::kFailure);
  EXPECT_NE(lm.termination, FitTermination::kFailure);
  EXPECT_NEAR(gn.initial_cost, lm.initial_cost, 1e-9 * gn.initial_cost);
  EXPECT_LT(gn.final_cost, 0.8 * gn.initial_cost);
  EXPECT_NEAR(gn.final_cost, lm.final_cost, 1e-6 * gn.initial_cost);
  EXPECT_LT(MeanVertexError(skinning_, gn_pose, ceres_pose), 1e-4);
  // The scale was held constant by both.
  EXPECT_EQ(gn_pose.scale, start_.scale);
  EXPECT_NEAR(ceres_pose.scale, start_.scale, 1e-15);
  // The reported cost is the problem's cost at the returned pose.
  FitEvaluation scratch;
  EXPECT_NEAR(problem.Cost(gn.delta, &scratch), gn.final_cost, 1e-12 * gn.initial_cost);
}

TEST_F(FittingTest, OneToOneBaselineRunsAndIsReported) {
  for (IcpMetric metric : {IcpMetric::kPointToPoint, IcpMetric::kPointToPlane}) {
    EMFitterOptions options = DefaultOptions();
    options.correspondence = CorrespondenceModel::kOneToOne;
    options.one_to_one.metric = metric;
    Pose result;
    const FitSummary summary = Fit(options, start_, &result);
    const double error = MeanVertexError(skinning_, result, truth_);
    const char* name = metric == IcpMetric::kPointToPoint ? "point_to_point" : "point_to_plane";
    std::cout << "ICP " << name << ": " << error * 1e3 << " mm, " << summary.BriefReport() << "\n";
    RecordProperty(std::string("icp_") + name + "_mean_vertex_error_mm",
                   std::to_string(error * 1e3));
    EXPECT_TRUE(summary.ok());
    EXPECT_LT(error, MeanVertexError(skinning_, start_, truth_));
  }
}

TEST_F(FittingTest, TruncatedVersusDenseEStep) {
  // Per-vertex position difference after fitting, truncated (default) vs the dense exact
  // E-step (same options otherwise, scale fixed). The dense weights' far field pulls every
  // mu_t towards the scan centroid (docs/design.md), so even with a fixed scale the limbs fold in:
  // the truncated fit must be the accurate one.
  EMFitterOptions truncated = DefaultOptions();
  EMFitterOptions dense = truncated;
  dense.estep.mode = EStepMode::kDense;
  dense.max_mean_motion = 1e3;  // report the dense optimum, do not reject it
  Pose a, b;
  Fit(truncated, start_, &a);
  const FitSummary s = Fit(dense, start_, &b);
  const double deviation = MeanVertexError(skinning_, a, b);
  const double truncated_error = MeanVertexError(skinning_, a, truth_);
  const double dense_error = MeanVertexError(skinning_, b, truth_);
  std::cout << "truncated vs dense: mean per-vertex difference " << deviation * 1e3
            << " mm; errors truncated " << truncated_error * 1e3 << " mm, dense "
            << dense_error * 1e3 << " mm (" << s.BriefReport() << ")\n";
  RecordProperty("truncated_vs_dense_mm", std::to_string(deviation * 1e3));
  RecordProperty("dense_error_mm", std::to_string(dense_error * 1e3));
  EXPECT_FALSE(s.non_finite);
  EXPECT_GT(deviation, 0.0);
  EXPECT_LT(truncated_error, 0.003);
  EXPECT_LT(truncated_error, dense_error);
}

TEST_F(FittingTest, LiteralEnergyWithFreeScaleShrinksTheScale) {
  // docs/design.md: the dense, unnormalised eq. 4 with a free global scale is degenerate (the far
  // field pulls every mu_t towards the scan centroid); the robust default is not.
  EMFitterOptions literal = DefaultOptions();
  literal.estep.mode = EStepMode::kDense;
  literal.estep.weights.normalize_per_scan_point = false;
  literal.scale_mode = ScaleMode::kFree;
  literal.normalize_data_term = false;
  literal.tikhonov.update = {0.0, 0.0, 0.0, 0.0};
  literal.max_iterations = 30;
  literal.relative_cost_tolerance = 0.0;
  literal.parameter_tolerance = 0.0;
  literal.max_mean_motion = 1e3;  // keep the degenerate optimum instead of rejecting it
  literal.max_scale_change = 1e3;
  literal.normal_refresh_iterations = 1;  // literal EM: normals of the current pose every time
  Pose shrunk;
  const FitSummary s = Fit(literal, start_, &shrunk);
  std::cout << "literal dense, free scale: scale " << shrunk.scale << " (" << s.BriefReport()
            << ")\n";
  RecordProperty("literal_free_scale", std::to_string(shrunk.scale));
  EXPECT_LT(shrunk.scale, 0.8);

  EMFitterOptions robust = DefaultOptions();
  robust.scale_mode = ScaleMode::kFree;  // even free, the truncated E-step keeps the scale
  Pose kept;
  Fit(robust, start_, &kept);
  std::cout << "robust default, free scale: scale " << kept.scale << "\n";
  RecordProperty("robust_free_scale", std::to_string(kept.scale));
  EXPECT_NEAR(kept.scale, 1.0, 0.03);
}

TEST_F(FittingTest, ScaleEstimatedOnFirstFrameThenFixed) {
  EMFitterOptions options = DefaultOptions();
  options.scale_mode = ScaleMode::kEstimateThenFix;
  options.scale_estimation_frames = 1;
  Pose start = start_;
  start.scale = 1.04;
  EMFitter fitter(model_, options);
  fitter.SetInitialPose(start);
  const FitSummary first = fitter.FitFrame(scan_);
  EXPECT_TRUE(first.ok());
  // Within the curvature bias of the truncated weights (mu_t are chord means), about 1 %.
  EXPECT_NEAR(fitter.pose().scale, 1.0, 0.02);
  const double estimate = fitter.pose().scale;
  // Second frame: the subject moved a little; the scale stays at the estimate.
  Pose moved = truth_;
  moved.translation += Eigen::Vector3d(0.02, 0.0, -0.01);
  Eigen::MatrixX3d posed;
  skinning_.Apply(moved, &posed);
  const Scan scan2 =
      testing_util::SampleScan(posed, model_.triangles, camera_, 6000.0, 0.003, &rng_);
  const FitSummary second = fitter.FitFrame(scan2);
  EXPECT_TRUE(second.ok());
  EXPECT_EQ(fitter.pose().scale, estimate);
  EXPECT_LT(MeanVertexError(skinning_, fitter.pose(), moved), 0.01);
}

TEST_F(FittingTest, DiscardFrameLeavesNoTraceAndAcceptPoseCommits) {
  const EMFitterOptions options = DefaultOptions();
  EMFitter fitter(model_, options);
  fitter.SetInitialPose(start_);
  fitter.BeginFrame(scan_, start_);
  while (!fitter.frame_done()) fitter.Iterate();
  Pose fitted;
  const FitSummary s = fitter.DiscardFrame(&fitted);
  EXPECT_TRUE(s.ok());
  EXPECT_GT(s.iterations, 1);
  EXPECT_EQ(fitter.frames_fitted(), 0);
  EXPECT_LT(MeanVertexError(skinning_, fitted, truth_), 0.003);
  EXPECT_LT(MeanVertexError(skinning_, fitter.pose(), start_), 1e-12);  // back to the start
  EXPECT_LT(MeanVertexError(skinning_, fitter.PredictNextPose(), start_), 1e-12);
  fitter.AcceptPose(scan_, fitted);
  EXPECT_EQ(fitter.frames_fitted(), 1);
  EXPECT_LT(MeanVertexError(skinning_, fitter.pose(), fitted), 1e-12);
  EXPECT_LT(MeanVertexError(skinning_, fitter.PredictNextPose(), fitted), 1e-12);
  // The same as fitting the frame directly.
  EMFitter direct(model_, options);
  direct.SetInitialPose(start_);
  direct.FitFrame(scan_);
  EXPECT_LT(MeanVertexError(skinning_, direct.pose(), fitted), 1e-9);
  EXPECT_THROW(fitter.AcceptPose(scan_, Pose::Identity(2)), Error);
  EXPECT_THROW(fitter.DiscardFrame(), Error);  // no frame begun
}

// A copy between frames fits the next frames exactly as the original: history, scale estimate,
// the Kalman predictor's state, a subject rest shape and the tracking vertex subset carry over.
TEST_F(FittingTest, CloneFitsTheNextFramesLikeTheOriginal) {
  EMFitterOptions options = DefaultOptions();
  options.scale_mode = ScaleMode::kEstimateThenFix;
  options.scale_estimation_frames = 3;
  options.prediction.model = PredictionModel::kKalman;
  options.tracking_max_fit_vertices = model_.num_vertices() / 2;
  Template shaped = model_;  // 1 % taller and wider, the same rig
  shaped.vertices *= 1.01;
  for (Joint& joint : shaped.joints) joint.center *= 1.01;
  EMFitter fitter(model_, options);
  fitter.SetRestShape(shaped);
  fitter.SetInitialPose(start_);
  ASSERT_TRUE(fitter.FitFrame(scan_).ok());
  std::vector<Scan> next;
  for (int k = 1; k <= 2; ++k) {
    Pose moved = truth_;
    moved.translation += Eigen::Vector3d(0.01 * k, 0.0, -0.005 * k);
    Eigen::MatrixX3d posed;
    skinning_.Apply(moved, &posed);
    next.push_back(
        testing_util::SampleScan(posed, model_.triangles, camera_, 6000.0, 0.003, &rng_));
  }
  const std::unique_ptr<EMFitter> copy = fitter.Clone();
  EXPECT_EQ(copy->frames_fitted(), 1);
  EXPECT_EQ(copy->scale_samples(), 1);
  Eigen::MatrixX3d a, b;
  for (const Scan& scan : next) {
    const FitSummary original = fitter.FitFrame(scan);
    const FitSummary copied = copy->FitFrame(scan);
    ASSERT_TRUE(original.ok());
    EXPECT_EQ(copied.iterations, original.iterations);
    fitter.skinning().Apply(fitter.pose(), &a);
    copy->skinning().Apply(copy->pose(), &b);
    EXPECT_TRUE(a == b) << "max difference " << (a - b).cwiseAbs().maxCoeff() << " m";
    EXPECT_EQ(copy->pose().scale, fitter.pose().scale);
  }
  EXPECT_EQ(copy->scale_estimate(), fitter.scale_estimate());
  fitter.skinning().Apply(fitter.PredictNextPose(), &a);
  copy->skinning().Apply(copy->PredictNextPose(), &b);
  EXPECT_TRUE(a == b);
  // Independent: fitting on the original leaves the copy alone; no copy in mid-frame.
  fitter.Reset();
  EXPECT_EQ(copy->frames_fitted(), 3);
  copy->BeginFrame(scan_, copy->PredictNextPose());
  EXPECT_THROW(copy->Clone(), Error);
  copy->DiscardFrame();
  EXPECT_NO_THROW(copy->Clone());
}

TEST_F(FittingTest, ScaleSamplesByIcpMedianAndResetKeepingTheScale) {
  EMFitterOptions options = DefaultOptions();
  options.scale_mode = ScaleMode::kEstimateThenFix;
  options.scale_estimation_frames = 3;
  ASSERT_EQ(options.scale_estimator, ScaleEstimator::kIcp);
  Pose start = start_;
  start.scale = 1.05;
  EMFitter fitter(model_, options);
  fitter.SetInitialPose(start);
  const FitSummary first = fitter.FitFrame(scan_);
  ASSERT_TRUE(first.ok());
  // The EM held the scale; the frame's ICP sample corrected it.
  EXPECT_EQ(first.trace.back().scale, 1.05);
  EXPECT_NEAR(fitter.pose().scale, 1.0, 0.02);
  EXPECT_EQ(fitter.scale_samples(), 1);
  EXPECT_TRUE(fitter.ScaleIsFree());
  for (int f = 0; f < 3; ++f) ASSERT_TRUE(fitter.FitFrame(scan_).ok());
  EXPECT_EQ(fitter.scale_samples(), 3);
  EXPECT_FALSE(fitter.ScaleIsFree());
  const double estimate = fitter.scale_estimate();
  EXPECT_NEAR(estimate, 1.0, 0.02);
  EXPECT_EQ(fitter.pose().scale, estimate);  // the 4th frame is fitted at the estimate
  // A re-initialisation of the same person keeps the estimate; a full reset does not.
  fitter.Reset(true);
  EXPECT_EQ(fitter.frames_fitted(), 0);
  EXPECT_EQ(fitter.scale_samples(), 3);
  EXPECT_EQ(fitter.PredictNextPose().scale, estimate);
  EXPECT_FALSE(fitter.ScaleIsFree());
  fitter.Reset();
  EXPECT_EQ(fitter.scale_samples(), 0);
  EXPECT_TRUE(fitter.ScaleIsFree());
  EXPECT_EQ(fitter.PredictNextPose().scale, 1.05);
}

TEST_F(FittingTest, TracksASequenceWithConstantVelocity) {
  EMFitterOptions options = DefaultOptions();
  options.smoothness = {0.0, 1e-4, 1e-5, 1e-6};
  options.tikhonov.temporal = {0.0, 0.0, 0.0, 1e-7};
  EMFitter fitter(model_, options);
  fitter.SetInitialPose(truth_);
  Pose pose = truth_;
  const Eigen::VectorXd velocity = [&] {
    Eigen::VectorXd v = Eigen::VectorXd::Zero(truth_.num_parameters());
    v[kTranslationIndex] = 0.02;
    v[JointParameterIndex(4)] = 0.04;
    v[JointParameterIndex(2) + 2] = -0.03;
    return v;
  }();
  double worst = 0.0;
  double prediction_error = 0.0, previous_error = 0.0;
  for (int f = 0; f < 5; ++f) {
    if (f > 0) pose = pose.Retracted(velocity);
    if (f >= 2) {
      prediction_error += MeanVertexError(skinning_, fitter.PredictNextPose(), pose);
      previous_error += MeanVertexError(skinning_, fitter.pose(), pose);
    }
    Eigen::MatrixX3d posed;
    skinning_.Apply(pose, &posed);
    const Scan scan =
        testing_util::SampleScan(posed, model_.triangles, camera_, 6000.0, 0.003, &rng_);
    const FitSummary s = fitter.FitFrame(scan);
    EXPECT_TRUE(s.ok()) << s.BriefReport();
    worst = std::max(worst, MeanVertexError(skinning_, fitter.pose(), pose));
  }
  std::cout << "sequence: worst mean vertex error " << worst * 1e3 << " mm; initial guess error "
            << "constant velocity " << prediction_error / 3 * 1e3 << " mm vs previous pose "
            << previous_error / 3 * 1e3 << " mm\n";
  RecordProperty("sequence_worst_error_mm", std::to_string(worst * 1e3));
  EXPECT_LT(worst, 0.008);
  EXPECT_EQ(fitter.frames_fitted(), 5);
  // The constant-velocity prediction is a better initial guess than the previous pose.
  EXPECT_LT(prediction_error, 0.7 * previous_error);
}

TEST_F(FittingTest, BadFramesAreFlaggedAndKeepThePreviousPose) {
  EMFitter fitter(model_, DefaultOptions());
  fitter.SetInitialPose(start_);
  ASSERT_TRUE(fitter.FitFrame(scan_).ok());
  const Pose good = fitter.pose();

  Scan few;
  few.points = scan_.points.topRows(10);
  few.normals = scan_.normals.topRows(10);
  FitSummary s = fitter.FitFrame(few);
  EXPECT_TRUE(s.too_few_points);
  EXPECT_EQ(s.termination, FrameTermination::kFailed);
  EXPECT_LT(MeanVertexError(skinning_, fitter.pose(), good), 1e-12);

  Scan nan = scan_;
  nan.points(5, 1) = std::numeric_limits<double>::quiet_NaN();
  nan.normals(7, 0) = std::numeric_limits<double>::quiet_NaN();
  s = fitter.FitFrame(nan);
  EXPECT_FALSE(s.ok());
  EXPECT_TRUE(s.non_finite);
  EXPECT_LT(MeanVertexError(skinning_, fitter.pose(), good), 1e-12);

  // A scan of something else 2 m away: the fit runs away or finds nothing; either way flagged.
  Scan far = scan_;
  far.points.col(0).array() += 2.0;
  s = fitter.FitFrame(far);
  EXPECT_FALSE(s.ok());
  EXPECT_LT(MeanVertexError(skinning_, fitter.pose(), good), 1e-12);

  // A good frame afterwards is fitted normally.
  EXPECT_TRUE(fitter.FitFrame(scan_).ok());
  EXPECT_LT(MeanVertexError(skinning_, fitter.pose(), truth_), 0.004);
}

TEST_F(FittingTest, IcpInitialisationRecoversTheSimilarity) {
  // Rest-posed template moved by a similarity; ICP from the rest pose must find it.
  Pose target = Pose::Identity(model_.num_joints());
  target.scale = 1.08;
  target.rotation = ExpSO3(Eigen::Vector3d(0.0, 0.2, 0.0)) * ExpSO3(Eigen::Vector3d(0.05, 0, 0));
  target.translation = Eigen::Vector3d(0.3, 0.05, -0.4);
  Eigen::MatrixX3d posed;
  skinning_.Apply(target, &posed);
  const Scan scan =
      testing_util::SampleScan(posed, model_.triangles, camera_, 6000.0, 0.002, &rng_);
  const IcpInitResult r =
      AlignByIcp(skinning_, Pose::Identity(model_.num_joints()), scan, IcpInitOptions());
  const double error = MeanVertexError(skinning_, r.pose, target);
  std::cout << "ICP init: " << error * 1e3 << " mm after " << r.iterations << " iterations, "
            << "scale " << r.pose.scale << "\n";
  // A pre-alignment only (nearest template vertices, partial view): within ~2 cm / 3 %.
  EXPECT_LT(error, 0.02);
  EXPECT_NEAR(r.pose.scale, 1.08, 0.03);
  EXPECT_LT(error, 0.5 * MeanVertexError(skinning_, Pose::Identity(model_.num_joints()), target));
  // Joint rotations untouched.
  for (int j = 0; j < model_.num_joints(); ++j) {
    EXPECT_TRUE(r.pose.joint_rotations[j].isIdentity(0.0));
  }
  EXPECT_THROW(AlignByIcp(skinning_, Pose::Identity(2), scan, IcpInitOptions()), Error);
  // The kd-tree's leaf size changes the speed only: the same pairs, the same alignment.
  for (int leaf : {1, 10, 64}) {
    IcpInitOptions options;
    options.kd_leaf_size = leaf;
    const IcpInitResult other =
        AlignByIcp(skinning_, Pose::Identity(model_.num_joints()), scan, options);
    EXPECT_EQ(other.iterations, r.iterations) << leaf;
    EXPECT_EQ(other.rms, r.rms) << leaf;
    EXPECT_EQ(other.pose.translation, r.pose.translation) << leaf;
    EXPECT_EQ(other.pose.rotation, r.pose.rotation) << leaf;
    EXPECT_EQ(other.pose.scale, r.pose.scale) << leaf;
  }
  IcpInitOptions no_leaf;
  no_leaf.kd_leaf_size = 0;
  EXPECT_THROW(AlignByIcp(skinning_, Pose::Identity(model_.num_joints()), scan, no_leaf), Error);
}

TEST_F(FittingTest, FirstFrameFromRestPoseWithIcp) {
  // Full first-frame path: rest pose, ICP pre-alignment, coarse-to-fine EM.
  Pose target = testing_util::RandomPose(model_.num_joints(), 0.2, 0.0, 0.0, &rng_);
  target.rotation = ExpSO3(Eigen::Vector3d(0.0, 0.15, 0.0));
  target.translation = Eigen::Vector3d(0.2, 0.0, -0.3);
  Eigen::MatrixX3d posed;
  skinning_.Apply(target, &posed);
  const Scan scan =
      testing_util::SampleScan(posed, model_.triangles, camera_, 6000.0, 0.003, &rng_);
  EMFitterOptions options;
  options.scale_mode = ScaleMode::kEstimateThenFix;
  EMFitter fitter(model_, options);
  const FitSummary s = fitter.FitFrame(scan);
  const double error = MeanVertexError(skinning_, fitter.pose(), target);
  std::cout << "first frame from rest pose: " << error * 1e3 << " mm, " << s.BriefReport() << "\n";
  EXPECT_TRUE(s.ok());
  EXPECT_GT(s.icp_seconds, 0.0);
  // Limited by the first-frame scale estimate (ICP, then the curvature-biased fine stages).
  EXPECT_LT(error, 0.015);
}

TEST(FitOptionsTest, InvalidOptionsThrow) {
  const Template model = testing_util::MakeStickTemplate(3, 6);
  EMFitterOptions options;
  options.tracking_radii = {0.05, -1.0};
  EXPECT_THROW(EMFitter(model, options), Error);
  options = EMFitterOptions();
  options.solver.max_iterations = 0;
  EXPECT_THROW(EMFitter(model, options), Error);
  options = EMFitterOptions();
  options.tikhonov.update.joints = -1.0;
  EXPECT_THROW(EMFitter(model, options), Error);
  options = EMFitterOptions();
  options.tracking_update.joints = -1.0;
  EXPECT_THROW(EMFitter(model, options), Error);
  options = EMFitterOptions();
  options.normal_refresh_iterations = -1;
  EXPECT_THROW(EMFitter(model, options), Error);
  options = EMFitterOptions();
  options.estep.candidate_margin = std::nan("");
  EXPECT_THROW(EMFitter(model, options), Error);
  options = EMFitterOptions();
  options.tracking_max_fit_vertices = -1;
  EXPECT_THROW(EMFitter(model, options), Error);
  options = EMFitterOptions();
  options.scale_sample_max_scan_points = 2;  // 0 (icp_init's) or >= 3
  EXPECT_THROW(EMFitter(model, options), Error);
  options.scale_sample_max_scan_points = 0;
  EXPECT_NO_THROW(EMFitter(model, options));
  options.scale_sample_tolerance = -1e-4;  // 0 (icp_init's) or > 0
  EXPECT_THROW(EMFitter(model, options), Error);
  options.scale_sample_tolerance = std::nan("");
  EXPECT_THROW(EMFitter(model, options), Error);
  options.scale_sample_tolerance = 1e-4;
  EXPECT_NO_THROW(EMFitter(model, options));
  options.scale_sample_grid_cell = -0.03;  // 0 (icp_init's) or > 0
  EXPECT_THROW(EMFitter(model, options), Error);
  options.scale_sample_grid_cell = std::numeric_limits<double>::infinity();
  EXPECT_THROW(EMFitter(model, options), Error);
  options.scale_sample_grid_cell = 0.0;
  EXPECT_NO_THROW(EMFitter(model, options));
  FitSolverOptions solver;
  solver.num_threads = 0;
  EXPECT_THROW(FitSolver::Create(solver), Error);
  EXPECT_EQ(FitSolverTypeNames().at("ceres_lm"), FitSolverType::kCeresLevenbergMarquardt);
}

}  // namespace
}  // namespace artex
