#include "stream/bit_io.h"

namespace artex {

void BitWriter::Put(uint32_t bits, int count) {
  if (count <= 0) return;
  const uint64_t mask = count >= 32 ? 0xffffffffull : ((1ull << count) - 1);
  acc_ = (acc_ << count) | (bits & mask);
  bits_ += count;
  while (bits_ >= 8) {
    bits_ -= 8;
    bytes_.push_back(static_cast<uint8_t>(acc_ >> bits_));
  }
  acc_ &= (1ull << bits_) - 1;
}

void BitWriter::PutUnary(int ones) {
  while (ones >= 16) {
    Put(0xffff, 16);
    ones -= 16;
  }
  Put((1u << (ones + 1)) - 2, ones + 1);
}

void BitWriter::PutExpGolomb(uint32_t value, int k) {
  // Order-k Exp-Golomb: (value >> k) + 1 in Elias-gamma, then the k low bits.
  const uint64_t high = (static_cast<uint64_t>(value) >> k) + 1;
  int length = 0;
  while ((high >> (length + 1)) != 0) ++length;
  Put(0, length);
  Put(static_cast<uint32_t>(high), length + 1);
  Put(value, k);
}

std::vector<uint8_t> BitWriter::Finish() {
  if (bits_ > 0) Put(0, 8 - bits_);
  std::vector<uint8_t> out;
  out.swap(bytes_);
  acc_ = 0;
  bits_ = 0;
  return out;
}

bool BitReader::Get(int count, uint32_t* bits) {
  if (count == 0) {
    *bits = 0;
    return true;
  }
  if (position_ + count > 8 * size_) {
    position_ = 8 * size_;
    return false;
  }
  uint32_t v = 0;
  for (int i = 0; i < count; ++i, ++position_)
    v = (v << 1) | ((data_[position_ >> 3] >> (7 - (position_ & 7))) & 1u);
  *bits = v;
  return true;
}

bool BitReader::GetUnary(int max_ones, int* ones) {
  *ones = 0;
  uint32_t bit = 0;
  while (true) {
    if (!Get(1, &bit)) return false;
    if (!bit) return true;
    if (++*ones > max_ones) return false;
  }
}

bool BitReader::GetExpGolomb(int k, uint32_t* value) {
  int zeros = 0;
  uint32_t bit = 0;
  while (true) {
    if (!Get(1, &bit)) return false;
    if (bit) break;
    if (++zeros > 32) return false;
  }
  uint32_t rest = 0;
  if (!Get(zeros, &rest)) return false;
  const uint64_t high = ((1ull << zeros) | rest) - 1;
  uint32_t low = 0;
  if (!Get(k, &low)) return false;
  const uint64_t v = (high << k) | low;
  if (v > 0xffffffffull) return false;
  *value = static_cast<uint32_t>(v);
  return true;
}

int AdaptiveRice::Parameter() const {
  int k = 0;
  while (k < 24 && (static_cast<uint64_t>(count_) << k) < sum_) ++k;
  return k;
}

void AdaptiveRice::Update(uint32_t magnitude) {
  sum_ += magnitude;
  if (++count_ >= kRiceReset) {
    sum_ = (sum_ + 1) / 2;
    count_ /= 2;
  }
}

void AdaptiveRice::Encode(int32_t value, BitWriter* out) {
  const uint32_t u = ZigZag(value);
  const int k = Parameter();
  const uint32_t q = u >> k;
  if (q >= static_cast<uint32_t>(kRiceEscape)) {
    out->PutUnary(kRiceEscape);
    out->Put(u, 32);
  } else {
    out->PutUnary(static_cast<int>(q));
    out->Put(u, k);
  }
  Update(u >> 1);
}

bool AdaptiveRice::Decode(BitReader* in, int32_t* value) {
  const int k = Parameter();
  int q = 0;
  if (!in->GetUnary(kRiceEscape, &q)) return false;
  uint32_t u = 0;
  if (q == kRiceEscape) {
    if (!in->Get(32, &u)) return false;
  } else {
    uint32_t low = 0;
    if (!in->Get(k, &low)) return false;
    u = (static_cast<uint32_t>(q) << k) | low;
  }
  *value = UnZigZag(u);
  Update(u >> 1);
  return true;
}

}  // namespace artex
