// Texture quality of a tracked, textured model against a synthetic recording's ground truth
// (texture/texture_quality.h): the model in its tracked pose (mapped into the recording's
// world) and the true subject in its true pose with the true texture, both rendered from the
// held-out cameras around the subject.
#pragma once

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <vector>

#include "models/template.h"
#include "render/camera.h"
#include "texture/texture_quality.h"

namespace artex {

struct TruthScene {
  const Template* subject = nullptr;  // ground-truth subject (UVs into `texture`)
  Eigen::MatrixX3d vertices;          // V_s x 3 true posed subject (recording world, m)
  cv::Mat texture;                    // CV_8UC3 true texture
  PinholeCamera camera;               // the recording's colour camera (recording world)
};

// model_vertices: V x 3 tracked template in the recording world; atlas, triangle_frames: the
// texture (Texturer::Atlas, triangle_frames; untextured triangles are not compared). The held-
// out cameras circle the true subject's centroid about the world +Y axis.
NovelViewQuality EvaluateNovelViews(const Template& model, const Eigen::MatrixX3d& model_vertices,
                                    const cv::Mat& atlas, const std::vector<int>& triangle_frames,
                                    const TruthScene& truth, const HeldOutViewOptions& options);

}  // namespace artex
