// Pose stream (docs/streaming.md): every parameter of Pose::ToVector (scale, translation in m,
// rotation vectors in rad) is quantised with a uniform step, predicted from the previous
// decoded frames (constant velocity, or the previous value), and the integer residual is coded
// with an adaptive Rice code per parameter. A keyframe codes the quantised values themselves
// and resets the prediction and the code statistics, so decoding can start at any keyframe.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "models/pose.h"
#include "stream/bit_io.h"

namespace artex {

enum class PosePrediction { kPrevious, kVelocity };

struct PoseCodecOptions {
  double scale_step = 1e-4;        // quantisation step of the global scale (unitless); > 0
  double translation_step = 1e-4;  // m; > 0
  double rotation_step = 2e-4;     // rad, per rotation-vector component; > 0
  PosePrediction prediction = PosePrediction::kVelocity;

  bool IsValid(std::string* error) const;
};

const char* PosePredictionName(PosePrediction p);
PosePrediction ParsePosePrediction(const std::string& name);  // throws artex::Error

class PoseEncoder {
 public:
  PoseEncoder(int num_joints, const PoseCodecOptions& options);
  // Codes `pose` (num_joints joints, finite; throws artex::Error otherwise); `decoded` (may be
  // null) receives what a decoder reconstructs.
  std::vector<uint8_t> Encode(const Pose& pose, bool keyframe, Pose* decoded = nullptr);

 private:
  friend class PoseDecoder;
  // Rotation vectors (global and per joint) whose quantised angle exceeds pi get their largest
  // component rounded towards zero until it does not (the sender's twist branch).
  void KeepRotationsWithinPi(std::vector<int32_t>* q) const;

  int num_joints_;
  PoseCodecOptions options_;
  std::vector<int32_t> previous_, before_;  // quantised values of the last two frames
  int history_ = 0;                         // decoded frames since the keyframe (capped at 2)
  std::vector<AdaptiveRice> codes_;
};

class PoseDecoder {
 public:
  PoseDecoder(int num_joints, const PoseCodecOptions& options);
  // False (with a reason) for a malformed payload or a delta frame without a preceding
  // keyframe; the decoder then needs a keyframe again.
  bool Decode(const uint8_t* data, std::size_t size, bool keyframe, Pose* pose, std::string* error);
  void Reset() { history_ = 0; }

 private:
  PoseEncoder state_;  // the same quantiser, predictor and statistics
  int history_ = 0;
};

// The quantisation step of parameter i of Pose::ToVector.
double PoseParameterStep(int i, const PoseCodecOptions& options);

}  // namespace artex
