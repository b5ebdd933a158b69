// Bit-level writer and reader and the adaptive Golomb-Rice code of the pose stream
// (docs/streaming.md): signed values are zigzag-mapped, the Rice parameter of every
// coded quantity follows the running mean of its magnitudes (as in LOCO-I / JPEG-LS), and
// values whose unary part would exceed kRiceEscape are sent raw after an escape.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace artex {

class BitWriter {
 public:
  void Put(uint32_t bits, int count);  // count in [0, 32], most significant first
  void PutUnary(int ones);             // `ones` 1-bits then a 0
  // Exp-Golomb of order k for an unsigned value.
  void PutExpGolomb(uint32_t value, int k);
  std::vector<uint8_t> Finish();  // pads the last byte with zeros

 private:
  std::vector<uint8_t> bytes_;
  uint64_t acc_ = 0;
  int bits_ = 0;
};

class BitReader {
 public:
  BitReader(const uint8_t* data, std::size_t size) : data_(data), size_(size) {}
  // False when the input ends (the reader then stays exhausted).
  bool Get(int count, uint32_t* bits);
  bool GetUnary(int max_ones, int* ones);
  bool GetExpGolomb(int k, uint32_t* value);
  std::size_t bits_read() const { return position_; }

 private:
  const uint8_t* data_;
  std::size_t size_;
  std::size_t position_ = 0;  // bits
};

inline uint32_t ZigZag(int32_t v) {
  return (static_cast<uint32_t>(v) << 1) ^ static_cast<uint32_t>(v >> 31);
}
inline int32_t UnZigZag(uint32_t u) {
  return static_cast<int32_t>(u >> 1) ^ -static_cast<int32_t>(u & 1);
}

// Adaptive Rice coding of one signed quantity: k = the smallest k with count << k >= sum of
// magnitudes; the statistics halve when count reaches kRiceReset (adapts to changes).
class AdaptiveRice {
 public:
  static constexpr int kRiceEscape = 20;  // unary length that announces a raw 32-bit value
  static constexpr int kRiceReset = 32;
  void Reset() { sum_ = 2, count_ = 1; }
  void Encode(int32_t value, BitWriter* out);
  bool Decode(BitReader* in, int32_t* value);

 private:
  int Parameter() const;
  void Update(uint32_t magnitude);
  uint32_t sum_ = 2, count_ = 1;
};

}  // namespace artex
