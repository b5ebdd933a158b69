#include "experiments/ground_truth_evaluation.h"

#include <pthread.h>
#include <sched.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <tbb/task_arena.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <limits>

#include "experiments/cpu_clock.h"
#include "experiments/surface_error.h"
#include "models/normals.h"

namespace artex {
namespace {

// Rows of `points` mapped by `t`.
Eigen::MatrixX3d TransformRows(const Eigen::Isometry3d& t, const Eigen::MatrixX3d& points) {
  Eigen::MatrixX3d out = (points * t.linear().transpose()).rowwise() + t.translation().transpose();
  return out;
}

// This thread at the lowest priority: SCHED_IDLE (runs when nothing else wants the core), else
// nice 19. Lowering a thread's priority needs no privilege; a failure leaves it as it was.
void LowestPriorityForThisThread() {
  sched_param param{};
  param.sched_priority = 0;
  if (pthread_setschedparam(pthread_self(), SCHED_IDLE, &param) == 0) return;
  setpriority(PRIO_PROCESS, static_cast<id_t>(syscall(SYS_gettid)), 19);
}

}  // namespace

FrameErrors GroundTruthEvaluator::Evaluate(const FrameEvaluation& frame) const {
  FrameErrors e;
  const GroundTruthFrame truth = truth_.sequence->ReadGroundTruth(frame.frame);
  Eigen::MatrixX3d truth_normals;
  ComputeVertexNormals(truth.vertices, truth_.subject->triangles, &truth_normals);
  double mean = 0.0, max = 0.0;
  const Eigen::MatrixX3d tracked_in_truth = TransformRows(truth_.to_truth_world, frame.posed);
  std::vector<int> nearest;
  {
    const std::lock_guard<std::mutex> lock(nearest_mutex_);
    nearest.swap(nearest_);
  }
  SurfaceErrors(tracked_in_truth, truth.vertices, truth_normals, &mean, &max, &nearest);
  {
    const std::lock_guard<std::mutex> lock(nearest_mutex_);
    if (nearest_.empty()) nearest_.swap(nearest);
  }
  e.mean_vertex_error_mm = 1000.0 * mean;
  e.max_vertex_error_mm = 1000.0 * max;
  const Eigen::MatrixX3d ours = TransformRows(truth_.to_truth_world, frame.joints);
  Eigen::MatrixX3d theirs;
  truth_.subject_skinning->PosedJointCenters(truth.pose, &theirs);
  double joint = 0.0;
  e.joint_errors_mm.assign(ours.rows(), std::numeric_limits<double>::quiet_NaN());
  for (const auto& [a, b] : truth_.joint_pairs) {
    const double d = (ours.row(a) - theirs.row(b)).norm();
    joint += d;
    e.joint_errors_mm[a] = 1000.0 * d;
  }
  e.mean_joint_error_mm =
      truth_.joint_pairs.empty() ? 0.0 : 1000.0 * joint / truth_.joint_pairs.size();
  if (truth_.truth_scene && frame.evaluate_texture) {
    // The truth scene posed for this frame; its texture a view (no reference count shared
    // between threads), read only.
    const TruthScene& shared = *truth_.truth_scene;
    TruthScene scene;
    scene.subject = shared.subject;
    scene.texture = cv::Mat(shared.texture.rows, shared.texture.cols, shared.texture.type(),
                            shared.texture.data, shared.texture.step);
    scene.camera = shared.camera;
    scene.vertices = truth.vertices;
    e.texture_quality = EvaluateNovelViews(model_, tracked_in_truth, frame.atlas,
                                           frame.triangle_frames, scene, held_out_);
    e.has_texture_quality = true;
  }
  return e;
}

BackgroundEvaluation::BackgroundEvaluation(const GroundTruthEvaluator* evaluator,
                                           std::size_t queue_depth)
    : evaluator_(evaluator),
      queue_(queue_depth),
      latest_error_mm_(std::numeric_limits<double>::quiet_NaN()),
      thread_([this] { Run(); }) {}

BackgroundEvaluation::~BackgroundEvaluation() {
  queue_.Close();
  if (thread_.joinable()) thread_.join();
}

void BackgroundEvaluation::Store(int order, FrameErrors&& errors) {
  std::lock_guard<std::mutex> lock(results_mutex_);
  results_.emplace(order, std::move(errors));
}

void BackgroundEvaluation::Run() {
  pthread_setname_np(pthread_self(), "artex-evaluate");
  LowestPriorityForThisThread();
  // Its parallel loops on this thread alone: oneTBB's workers run at the stages' priority.
  tbb::task_arena arena(1, 1);
  const double cpu_start = ThreadCpuSeconds();
  FrameEvaluation frame;
  while (queue_.Pop(&frame)) {
    if (failed_) continue;  // drain what is queued; the error is reported
    try {
      const auto start = std::chrono::steady_clock::now();
      FrameErrors errors;
      arena.execute([&] { errors = evaluator_->Evaluate(frame); });
      busy_seconds_ = busy_seconds_ +
                      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      latest_error_mm_ = errors.mean_vertex_error_mm;
      Store(frame.order, std::move(errors));
      ++done_;
    } catch (...) {
      error_ = std::current_exception();
      failed_ = true;
    }
    frame = FrameEvaluation();  // its memory back before waiting
    cpu_seconds_ = ThreadCpuSeconds() - cpu_start;
  }
  cpu_seconds_ = ThreadCpuSeconds() - cpu_start;
}

bool BackgroundEvaluation::TryPush(FrameEvaluation&& frame) {
  if (failed_) Finish();  // rethrows
  frame.order = pushed_;
  if (!queue_.TryPush(std::move(frame))) return false;
  ++pushed_;
  return true;
}

std::vector<FrameErrors> BackgroundEvaluation::Finish() {
  std::exception_ptr caller_error;
  if (!finished_) {
    finished_ = true;
    queue_.Close();
    // What is still queued, on this thread at its priority (the background thread takes
    // frames too; Pop hands each frame to one of them).
    FrameEvaluation frame;
    while (queue_.Pop(&frame)) {
      if (caller_error || failed_) continue;
      try {
        Store(frame.order, evaluator_->Evaluate(frame));
        ++done_by_finish_;
      } catch (...) {
        caller_error = std::current_exception();
      }
    }
    thread_.join();
  }
  if (error_) std::rethrow_exception(error_);
  if (caller_error) std::rethrow_exception(caller_error);
  std::vector<FrameErrors> ordered;
  ordered.reserve(results_.size());
  for (auto& [order, errors] : results_) ordered.push_back(std::move(errors));
  results_.clear();
  return ordered;
}

}  // namespace artex
