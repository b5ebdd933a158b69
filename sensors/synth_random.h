// Counter-based random numbers of the virtual Kinect (sensors/virtual_kinect.h): every
// number comes from (seed, stream, frame, row) through SplitMix64, so results do not depend
// on threads or on the order in which frames are rendered. Internal to sensors/.
#pragma once

#include <cstdint>

namespace artex {
namespace synth_random {

// Independent streams (mixed into the generator seeds).
constexpr uint64_t kStreamFrameDepth = 1;
constexpr uint64_t kStreamBackgroundDepth = 2;
constexpr uint64_t kStreamColor = 3;
constexpr uint64_t kStreamColorWalk = 4;
constexpr uint64_t kStreamScene = 5;
constexpr uint64_t kStreamBoxes = 6;

inline uint64_t SplitMix(uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}
inline uint64_t MixSeed(uint64_t seed, uint64_t stream, uint64_t frame, uint64_t row) {
  return SplitMix(SplitMix(SplitMix(SplitMix(seed) ^ stream) ^ frame) ^ row);
}
// Uniform in [0, 1) from (seed, stream, a, b).
inline double Hash01(uint64_t seed, uint64_t stream, uint64_t a, uint64_t b) {
  return (MixSeed(seed, stream, a, b) >> 11) * (1.0 / 9007199254740992.0);
}

}  // namespace synth_random
}  // namespace artex
