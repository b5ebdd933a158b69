// Numeric constants and the elapsed-time helper shared by artex's sources: one definition each
// (the sanitizer tiers compile several sources of a library as one, where copies would clash).
#pragma once

#include <chrono>
#include <cmath>
#include <cstdint>
#include <limits>

namespace artex {

inline constexpr double kPi = 3.14159265358979323846;
inline constexpr double kDegToRad = kPi / 180.0;
inline constexpr double kInf = std::numeric_limits<double>::infinity();

// The fractional part of x, in [0, 1) (x - floor(x)).
inline double Frac(double x) { return x - std::floor(x); }

// floor(x) as an integer without the library call (no SSE4.1 rounding in the baseline ISA):
// truncate, then step down for negative non-integers. For |x| well inside the int64 range
// (callers clamp first).
inline int64_t FloorToInt64(double x) {
  int64_t i = static_cast<int64_t>(x);
  i -= static_cast<double>(i) > x;
  return i;
}

// Seconds of steady-clock time since `start`.
inline double SecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace artex
