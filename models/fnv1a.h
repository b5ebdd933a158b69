// FNV-1a, 64 bits: a fast non-cryptographic hash of bytes (short names for experiment runs and
// templates, the template cache file's checksum).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

namespace artex {

inline std::uint64_t Fnv1a(const char* data, std::size_t size) {
  std::uint64_t h = 1469598103934665603ull;
  for (std::size_t i = 0; i < size; ++i) {
    h ^= static_cast<unsigned char>(data[i]);
    h *= 1099511628211ull;
  }
  return h;
}

inline std::uint64_t Fnv1a(const std::string& s) { return Fnv1a(s.data(), s.size()); }

}  // namespace artex
