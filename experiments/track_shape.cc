// TrackStage's part of the subject shape estimation (section shape, docs/shape.md): feeding
// accepted frames to the estimator and swapping the subject's template into the fitter.
#include "experiments/pipeline_stages.h"
#include "sensors/silhouette.h"

namespace artex {

void TrackStage::FeedShape(const Frame& input, const Pose& pose, int frame) {
  if (shape_ == nullptr || tmpl_ == nullptr || !shape_->enabled()) return;
  const bool scale_settled = !fitter_->ScaleIsFree() ||
                             fitter_->scale_samples() >= options_.fitting.scale_estimation_frames;
  if (shape_->NeedsFreeSpace() && !scan_.silhouette && shape_->KeepsNextFrame(scale_settled)) {
    // The scan mask's free space, built for the frames the estimator keeps only (the
    // preprocessing builds it for every frame when the silhouette term needs it).
    scan_.silhouette =
        BuildSilhouetteMap(input.depth, calibration_.depth_scale,
                           preprocessor_->foreground_mask(), calibration_.depth,
                           options_.preprocess.silhouette);
  }
  Pose refined;
  if (!shape_->AddFrame(scan_, pose, scale_settled, &refined)) return;
  *tmpl_ = shape_->SubjectTemplate();
  fitter_->SetRestShape(*tmpl_);
  rest_shape_ = std::make_shared<const Template>(*tmpl_);
  if (options_.shape.seed_pose && refined.AllFinite() &&
      refined.num_joints() == tmpl_->num_joints()) {
    // The tracked pose was fitted with the previous shape (e.g. the template's feet on the
    // subject's shins); the solve refined this frame's pose with the new one: continue
    // from it, as after a re-initialisation (the motion history restarts).
    fitter_->Reset(/*keep_scale=*/true);
    fitter_->AcceptPose(scan_, refined);
  }
  if (shape_calibrated_frame < 0) shape_calibrated_frame = frame;
  // The last calibration round's swap (the shape is final, or refined from here on).
  if (shape_final_frame < 0 && shape_->calibrated()) shape_final_frame = frame;
  if (shape_detail_frame < 0 && shape_->detail().size() > 0) shape_detail_frame = frame;
}

}  // namespace artex
