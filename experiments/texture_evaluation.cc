#include "experiments/texture_evaluation.h"

#include "models/error.h"
#include "texture/texturer.h"

namespace artex {

NovelViewQuality EvaluateNovelViews(const Template& model, const Eigen::MatrixX3d& model_vertices,
                                    const cv::Mat& atlas, const std::vector<int>& triangle_frames,
                                    const TruthScene& truth, const HeldOutViewOptions& options) {
  if (!truth.subject || truth.vertices.rows() != truth.subject->num_vertices() ||
      truth.texture.empty())
    throw Error(
        "EvaluateNovelViews: expected a ground-truth subject, its posed vertices and "
        "its texture");
  const Eigen::Vector3d target = truth.vertices.colwise().mean().transpose();
  NovelViewAccumulator accumulator(options);
  for (const PinholeCamera& camera :
       HeldOutCameras(truth.camera, target, Eigen::Vector3d::UnitY(), options)) {
    cv::Mat truth_image, truth_mask, image, mask;
    RenderTextured(*truth.subject, truth.vertices, truth.texture, camera, &truth_image,
                   &truth_mask);
    RenderTextured(model, model_vertices, atlas, camera, &image, &mask, &triangle_frames);
    accumulator.Add(image, mask, truth_image, truth_mask);
  }
  return accumulator.Result();
}

}  // namespace artex
