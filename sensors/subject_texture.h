// The synthetic subject's true texture (albedo) for the virtual Kinect: a procedural,
// clothing-like atlas over the template's UV charts (shirt with stripes and a printed
// text-like panel, plaid trousers, shoes, skin for head and hands with hair and facial
// marks). Patterns are defined in the rest-pose 3D frame, so they continue across UV seams;
// each chart gets its own garment colourway. Deterministic given the seed.
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <opencv2/core.hpp>
#include <string>

#include "models/template.h"

namespace artex {

struct SubjectTextureOptions {
  int size = 2048;                // atlas side (texels); [64, 8192]
  uint64_t seed = 1;              // colour choices, glyphs and fabric noise
  double stripe_period_m = 0.05;  // shirt stripes (rest-pose height period, m)
  double plaid_period_m = 0.08;   // trouser plaid (m)
  double glyph_size_m = 0.012;    // height of one text glyph on the chest panel (m)
  double sleeve_length_m = 0.10;  // how far the shirt sleeve reaches below the elbow (m)
  double fabric_noise = 0.04;     // per-texel multiplicative albedo noise (relative)
  int padding_texels = 4;         // chart colours dilated this far into the empty gutter
  Eigen::Vector3d gutter_rgb = Eigen::Vector3d(0.5, 0.5, 0.5);  // texels outside all charts

  // Returns false and describes the first invalid field in `error` (name, valid range, value).
  bool IsValid(std::string* error) const;
};

// Returns a size x size CV_8UC3 image in BGR order (OpenCV), row 0 at v = 0 (glTF UVs:
// texel (x, y) covers u in [x, x+1) / size, v in [y, y+1) / size). The template must have
// UVs and joints named as in models/template_generator.h (other names fall back to the
// shirt pattern). Throws artex::Error for invalid options or a template without UVs.
cv::Mat GenerateSubjectTexture(const Template& subject, const SubjectTextureOptions& options);

// Bilinear lookup (texel centres at ((x + 0.5) / W, (y + 0.5) / H), clamped at the border)
// of a W x H BGR image (8 bits a channel, rows `step` bytes apart) at glTF uv; returns linear RGB
// in [0, 1]. Inline: renders call it per pixel.
inline Eigen::Vector3d SampleTextureBilinear(const uint8_t* bgr, std::size_t step, int w, int h,
                                             const Eigen::Vector2d& uv) {
  const double fx = std::clamp(uv.x() * w - 0.5, 0.0, w - 1.0);
  const double fy = std::clamp(uv.y() * h - 0.5, 0.0, h - 1.0);
  const int x0 = std::min(static_cast<int>(fx), w - 1), y0 = std::min(static_cast<int>(fy), h - 1);
  const int x1 = std::min(x0 + 1, w - 1), y1 = std::min(y0 + 1, h - 1);
  const double ax = fx - x0, ay = fy - y0;
  const uint8_t* c00 = bgr + y0 * step + 3 * x0;
  const uint8_t* c01 = bgr + y0 * step + 3 * x1;
  const uint8_t* c10 = bgr + y1 * step + 3 * x0;
  const uint8_t* c11 = bgr + y1 * step + 3 * x1;
  Eigen::Vector3d rgb;
  for (int ch = 0; ch < 3; ++ch) {
    const int k = 2 - ch;
    rgb[ch] =
        ((1 - ay) * ((1 - ax) * c00[k] + ax * c01[k]) + ay * ((1 - ax) * c10[k] + ax * c11[k])) /
        255.0;
  }
  return rgb;
}
// The same of a CV_8UC3 image.
inline Eigen::Vector3d SampleTextureBilinear(const cv::Mat& texture_bgr,
                                             const Eigen::Vector2d& uv) {
  return SampleTextureBilinear(texture_bgr.data, texture_bgr.step[0], texture_bgr.cols,
                               texture_bgr.rows, uv);
}

// V x 3 RGB in [0, 1]: the texture at each vertex (mean over its UV corners, which differ
// only at chart seams). Vertices without a corner get the mean texture colour.
// Throws artex::Error when the template has no UVs or the image is not CV_8UC3.
Eigen::MatrixX3d VertexColorsFromTexture(const Template& tmpl, const cv::Mat& texture_bgr);

}  // namespace artex
