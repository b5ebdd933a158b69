#include "stream/rest_shape.h"

#include <cmath>
#include <cstring>
#include <limits>

#include "models/error.h"

namespace artex {
namespace {

constexpr std::size_t kFixedBytes = 2 + 4 + 8;

template <class T>
void Put(std::vector<uint8_t>* out, T v) {
  uint8_t b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));  // little-endian hosts (x86-64, arm64)
  out->insert(out->end(), b, b + sizeof(T));
}

template <class T>
T Get(const uint8_t* p) {
  T v;
  std::memcpy(&v, p, sizeof(T));
  return v;
}

// The rest vertex as the receiver decodes it from the header's glTF (float32 positions).
double Base(const Template& base, int v, int c) {
  return static_cast<double>(static_cast<float>(base.vertices(v, c)));
}

}  // namespace

std::vector<uint8_t> EncodeRestShape(const Template& base, const Template& shaped, double step) {
  if (base.num_joints() != shaped.num_joints() || base.num_vertices() != shaped.num_vertices() ||
      base.num_triangles() != shaped.num_triangles()) {
    throw Error("stream rest shape: expected the header template's " +
                std::to_string(base.num_joints()) + " joints, " +
                std::to_string(base.num_vertices()) + " vertices and " +
                std::to_string(base.num_triangles()) + " triangles, found " +
                std::to_string(shaped.num_joints()) + ", " + std::to_string(shaped.num_vertices()) +
                " and " + std::to_string(shaped.num_triangles()));
  }
  if (!(step > 0.0) || !std::isfinite(step))
    throw Error("stream rest shape: step must be > 0, found " + std::to_string(step));
  const int nj = shaped.num_joints(), nv = shaped.num_vertices();
  std::vector<uint8_t> out;
  out.reserve(kFixedBytes + 24 * nj + 6 * static_cast<std::size_t>(nv));
  Put<uint16_t>(&out, static_cast<uint16_t>(nj));
  Put<uint32_t>(&out, static_cast<uint32_t>(nv));
  Put<double>(&out, step);
  for (const Joint& j : shaped.joints)
    for (int c = 0; c < 3; ++c) Put<double>(&out, j.center(c));
  for (int v = 0; v < nv; ++v) {
    for (int c = 0; c < 3; ++c) {
      const double q = std::round((shaped.vertices(v, c) - Base(base, v, c)) / step);
      if (!(std::abs(q) <= std::numeric_limits<int16_t>::max())) {
        throw Error("stream rest shape: vertex " + std::to_string(v) + " moved " +
                    std::to_string(q * step) + " m from the header template's, beyond the " +
                    "payload's +-" + std::to_string(32767 * step) + " m");
      }
      Put<int16_t>(&out, static_cast<int16_t>(q));
    }
  }
  return out;
}

bool DecodeRestShape(const std::vector<uint8_t>& payload, const Template& base, Template* out,
                     std::string* why) {
  const int nj = base.num_joints(), nv = base.num_vertices();
  const std::size_t expected =
      kFixedBytes + 24 * static_cast<std::size_t>(nj) + 6 * static_cast<std::size_t>(nv);
  if (payload.size() < kFixedBytes) {
    *why = "rest shape: " + std::to_string(payload.size()) + " bytes, expected " +
           std::to_string(expected);
    return false;
  }
  const uint8_t* p = payload.data();
  const int joints = Get<uint16_t>(p), vertices = static_cast<int>(Get<uint32_t>(p + 2));
  const double step = Get<double>(p + 6);
  if (joints != nj || vertices != nv) {
    *why = "rest shape: " + std::to_string(joints) + " joints and " + std::to_string(vertices) +
           " vertices, expected the header template's " + std::to_string(nj) + " and " +
           std::to_string(nv);
    return false;
  }
  if (payload.size() != expected || !(step > 0.0) || !std::isfinite(step)) {
    *why = "rest shape: " + std::to_string(payload.size()) + " bytes with step " +
           std::to_string(step) + ", expected " + std::to_string(expected) + " bytes, step > 0";
    return false;
  }
  Template shaped = base;
  p += kFixedBytes;
  for (Joint& j : shaped.joints) {
    for (int c = 0; c < 3; ++c, p += 8) j.center(c) = Get<double>(p);
    if (!j.center.allFinite()) {
      *why = "rest shape: joint " + j.name + "'s centre is not finite";
      return false;
    }
  }
  for (int v = 0; v < nv; ++v)
    for (int c = 0; c < 3; ++c, p += 2)
      shaped.vertices(v, c) = Base(base, v, c) + Get<int16_t>(p) * step;
  *out = std::move(shaped);
  return true;
}

}  // namespace artex
