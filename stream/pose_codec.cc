#include "stream/pose_codec.h"

#include <cmath>
#include <limits>
#include <sstream>

#include "models/error.h"
#include "models/numeric.h"

namespace artex {
namespace {

constexpr int kKeyframeOrder = 12;  // Exp-Golomb order of keyframe values (|q| ~ 2^12 typical)

int32_t Predict(const std::vector<int32_t>& previous, const std::vector<int32_t>& before,
                int history, int i, PosePrediction prediction) {
  if (history == 0) return 0;
  if (history == 1 || prediction == PosePrediction::kPrevious) return previous[i];
  const int64_t p = 2 * static_cast<int64_t>(previous[i]) - before[i];
  return static_cast<int32_t>(
      std::max<int64_t>(std::numeric_limits<int32_t>::min(),
                        std::min<int64_t>(std::numeric_limits<int32_t>::max(), p)));
}

Pose Dequantise(const std::vector<int32_t>& q, int num_joints, const PoseCodecOptions& o) {
  Eigen::VectorXd v(q.size());
  for (std::size_t i = 0; i < q.size(); ++i)
    v[static_cast<Eigen::Index>(i)] = q[i] * PoseParameterStep(static_cast<int>(i), o);
  return Pose::FromVector(v, num_joints, "decoded pose");
}

}  // namespace

bool PoseCodecOptions::IsValid(std::string* error) const {
  std::ostringstream msg;
  if (!(scale_step > 0.0) || !std::isfinite(scale_step))
    msg << "stream.pose_scale_step: expected a finite value > 0, found " << scale_step;
  else if (!(translation_step > 0.0) || !std::isfinite(translation_step))
    msg << "stream.pose_translation_step: expected a finite value > 0, found " << translation_step;
  else if (!(rotation_step > 0.0) || !std::isfinite(rotation_step))
    msg << "stream.pose_rotation_step: expected a finite value > 0, found " << rotation_step;
  if (msg.str().empty()) return true;
  if (error) *error = msg.str();
  return false;
}

const char* PosePredictionName(PosePrediction p) {
  return p == PosePrediction::kVelocity ? "velocity" : "previous";
}

PosePrediction ParsePosePrediction(const std::string& name) {
  if (name == "velocity") return PosePrediction::kVelocity;
  if (name == "previous") return PosePrediction::kPrevious;
  throw Error("stream.pose_prediction: expected velocity or previous, found " + name);
}

double PoseParameterStep(int i, const PoseCodecOptions& o) {
  if (i == 0) return o.scale_step;
  if (i < 4) return o.translation_step;
  return o.rotation_step;
}

PoseEncoder::PoseEncoder(int num_joints, const PoseCodecOptions& options)
    : num_joints_(num_joints), options_(options) {
  std::string why;
  if (!options_.IsValid(&why)) throw Error(why);
  const int n = kNumGlobalParameters + 3 * num_joints;
  previous_.assign(n, 0);
  before_.assign(n, 0);
  codes_.resize(n);
}

void PoseEncoder::KeepRotationsWithinPi(std::vector<int32_t>* q) const {
  // A rotation vector of angle just below pi (Log's range) can round to one just above it.
  // Exp of that is the same rotation up to a step, but its angle-axis form flips to the
  // opposite axis, and so does the skinning's twist angle about the bone (2 atan2(p, w) jumps
  // from pi to -pi): a joint twisted by ~180 degrees would be skinned the other way round at
  // the receiver (measured: 101 mm on an ankle). Rounding such a vector's largest component
  // towards zero keeps its angle <= pi and the sender's branch.
  const double step = options_.rotation_step;
  for (int i = kGlobalRotationIndex; i + 2 < static_cast<int>(q->size()); i += 3) {
    int32_t* r = q->data() + i;
    for (int guard = 0; guard < 8; ++guard) {
      const double x = step * r[0], y = step * r[1], z = step * r[2];
      if (std::sqrt(x * x + y * y + z * z) <= kPi) break;
      int k = 0;
      for (int d = 1; d < 3; ++d) {
        if (std::abs(r[d]) > std::abs(r[k])) k = d;
      }
      r[k] += r[k] > 0 ? -1 : 1;
    }
  }
}

std::vector<uint8_t> PoseEncoder::Encode(const Pose& pose, bool keyframe, Pose* decoded) {
  if (pose.num_joints() != num_joints_ || !pose.AllFinite()) {
    std::ostringstream msg;
    msg << "pose stream: expected a finite pose with " << num_joints_ << " joints, found "
        << pose.num_joints() << (pose.AllFinite() ? "" : " (non-finite)");
    throw Error(msg.str());
  }
  const Eigen::VectorXd v = pose.ToVector();
  const int n = static_cast<int>(v.size());
  std::vector<int32_t> q(n);
  for (int i = 0; i < n; ++i) {
    const double scaled = std::round(v[i] / PoseParameterStep(i, options_));
    q[i] = static_cast<int32_t>(std::max(-2.0e9, std::min(2.0e9, scaled)));
  }
  KeepRotationsWithinPi(&q);
  BitWriter out;
  if (keyframe) {
    history_ = 0;
    for (AdaptiveRice& c : codes_) c.Reset();
    for (int i = 0; i < n; ++i) out.PutExpGolomb(ZigZag(q[i]), kKeyframeOrder);
  } else {
    if (history_ == 0) throw Error("pose stream: the first frame must be a keyframe");
    for (int i = 0; i < n; ++i)
      codes_[i].Encode(q[i] - Predict(previous_, before_, history_, i, options_.prediction), &out);
  }
  before_ = previous_;
  previous_ = q;
  history_ = std::min(2, history_ + 1);
  if (decoded) *decoded = Dequantise(q, num_joints_, options_);
  return out.Finish();
}

PoseDecoder::PoseDecoder(int num_joints, const PoseCodecOptions& options)
    : state_(num_joints, options) {}

bool PoseDecoder::Decode(const uint8_t* data, std::size_t size, bool keyframe, Pose* pose,
                         std::string* error) {
  PoseEncoder& s = state_;
  const int n = static_cast<int>(s.previous_.size());
  if (!keyframe && history_ == 0) {
    if (error) *error = "pose delta frame without a preceding keyframe";
    return false;
  }
  BitReader in(data, size);
  std::vector<int32_t> q(n);
  if (keyframe) {
    for (AdaptiveRice& c : s.codes_) c.Reset();
    for (int i = 0; i < n; ++i) {
      uint32_t u = 0;
      if (!in.GetExpGolomb(kKeyframeOrder, &u)) {
        if (error)
          *error = "pose keyframe payload ends early (parameter " + std::to_string(i) + ")";
        history_ = 0;
        return false;
      }
      q[i] = UnZigZag(u);
    }
  } else {
    for (int i = 0; i < n; ++i) {
      int32_t r = 0;
      if (!s.codes_[i].Decode(&in, &r)) {
        if (error) *error = "pose payload ends early (parameter " + std::to_string(i) + ")";
        history_ = 0;
        return false;
      }
      q[i] = static_cast<int32_t>(static_cast<int64_t>(Predict(s.previous_, s.before_, history_, i,
                                                               s.options_.prediction)) +
                                  r);
    }
  }
  if (in.bits_read() + 8 <= 8 * size) {
    if (error) *error = "pose payload longer than its parameters";
    history_ = 0;
    return false;
  }
  try {
    *pose = Dequantise(q, s.num_joints_, s.options_);
  } catch (const Error& e) {
    if (error) *error = e.what();
    history_ = 0;
    return false;
  }
  s.before_ = s.previous_;
  s.previous_ = q;
  history_ = keyframe ? 1 : std::min(2, history_ + 1);
  return true;
}

}  // namespace artex
