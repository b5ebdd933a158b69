// The ground-truth metrics of tracked frames (vertex, joint and novel-view texture errors of a
// synthetic recording), computed for the output stage (experiments/pipeline_stages.h) either in
// the stage itself or on a thread of their own off the frame loop (pipeline.evaluate_in_background,
// docs/realtime.md "Ground truth off the frame loop"): a sensor has no ground truth, and with it
// evaluated in the loop a benchmark's frame rate measured the evaluation along with the
// tracking. The numbers are the same either way; only when they are computed differs.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <atomic>
#include <cstddef>
#include <exception>
#include <map>
#include <mutex>
#include <thread>
#include <utility>
#include <vector>

#include <opencv2/core.hpp>

#include "experiments/bounded_queue.h"
#include "experiments/texture_evaluation.h"
#include "models/skinning.h"
#include "models/template.h"
#include "sensors/sequence.h"

namespace artex {

// What the output stage needs of the ground truth (absent: subject == nullptr).
struct GroundTruthContext {
  const SequenceReader* sequence = nullptr;
  const Template* subject = nullptr;
  const Skinning* subject_skinning = nullptr;
  std::vector<std::pair<int, int>> joint_pairs;  // (tracked joint, subject joint)
  const TruthScene* truth_scene = nullptr;       // novel-view quality (may be null)
  Eigen::Isometry3d to_truth_world = Eigen::Isometry3d::Identity();
};

// One tracked frame to evaluate.
struct FrameEvaluation {
  int frame = 0;                // the recording's frame index
  int order = 0;                // BackgroundEvaluation: its place among the frames pushed
  Eigen::MatrixX3d posed;       // V x 3 tracked template (tracking world, m)
  Eigen::MatrixX3d joints;      // J x 3 tracked joint centres (tracking world, m)
  bool evaluate_texture = false;
  cv::Mat atlas;                         // evaluate_texture: Texturer::Atlas of the frame
  std::vector<int> triangle_frames;      // ... and its triangle_frames
};

// Its metrics.
struct FrameErrors {
  double mean_vertex_error_mm = 0.0, max_vertex_error_mm = 0.0, mean_joint_error_mm = 0.0;
  std::vector<double> joint_errors_mm;  // per tracked joint (NaN: no true counterpart)
  bool has_texture_quality = false;
  NovelViewQuality texture_quality;
};

// Computes FrameErrors against the recording's ground truth. `model` gives the triangles and UVs
// of the novel views (its geometry is not read). Evaluate may run on several threads at once.
class GroundTruthEvaluator {
 public:
  GroundTruthEvaluator(const Template& model, const GroundTruthContext& truth,
                       const HeldOutViewOptions& held_out)
      : model_(model), truth_(truth), held_out_(held_out) {}
  FrameErrors Evaluate(const FrameEvaluation& frame) const;

 private:
  const Template& model_;
  GroundTruthContext truth_;
  HeldOutViewOptions held_out_;
  // The last evaluation's nearest truth vertex per tracked vertex: the next one's guess
  // (SurfaceErrors; it spares most of the search, and the errors are the same without it). One
  // evaluation takes it at a time; another running meanwhile searches without a guess.
  mutable std::mutex nearest_mutex_;
  mutable std::vector<int> nearest_;
};

// A GroundTruthEvaluator on its own thread at the lowest CPU priority (SCHED_IDLE, its parallel
// loops on that thread alone): it uses what the frame loop leaves of the cores. At most
// `queue_depth` frames wait for it: TryPush refuses beyond (the caller evaluates that frame
// itself, so memory stays bounded and a machine busy with other work cannot starve the run),
// and Finish evaluates what is left on the calling thread, at its priority, alongside the
// background thread (on a busy machine the idle-priority thread gets almost nothing). The
// results come back in the order the frames were pushed.
class BackgroundEvaluation {
 public:
  BackgroundEvaluation(const GroundTruthEvaluator* evaluator, std::size_t queue_depth);
  ~BackgroundEvaluation();
  BackgroundEvaluation(const BackgroundEvaluation&) = delete;
  BackgroundEvaluation& operator=(const BackgroundEvaluation&) = delete;

  // Queues a frame; false (frame untouched) while queue_depth frames wait. Rethrows the
  // thread's error.
  bool TryPush(FrameEvaluation&& frame);
  // Evaluates the frames still queued (on this thread and the background one), waits for the
  // background thread and returns every pushed frame's metrics in push order; rethrows the first
  // error. Call once, after the last TryPush.
  std::vector<FrameErrors> Finish();
  // Frames the background thread evaluated so far, and its CPU time (s) and time busy
  // evaluating (s); frames Finish evaluated on the calling thread.
  int frames_done() const { return done_.load(); }
  int frames_done_by_finish() const { return done_by_finish_; }
  double cpu_seconds() const { return cpu_seconds_.load(); }
  double busy_seconds() const { return busy_seconds_.load(); }
  // The mean vertex error of the latest frame evaluated (NaN before the first).
  double latest_mean_vertex_error_mm() const { return latest_error_mm_.load(); }

 private:
  void Run();

  // The metrics of a frame into results_ (either thread).
  void Store(int order, FrameErrors&& errors);

  const GroundTruthEvaluator* evaluator_;
  BoundedQueue<FrameEvaluation> queue_;
  int pushed_ = 0, done_by_finish_ = 0;  // the caller's
  std::mutex results_mutex_;
  std::map<int, FrameErrors> results_;  // by order
  std::exception_ptr error_;            // the thread's until joined
  std::atomic<bool> failed_{false};
  std::atomic<int> done_{0};
  std::atomic<double> cpu_seconds_{0.0}, busy_seconds_{0.0}, latest_error_mm_;
  std::thread thread_;
  bool finished_ = false;
};

}  // namespace artex
