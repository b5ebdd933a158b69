// Rest-shape payload of a stream record (docs/streaming.md, version 2): when the sender's
// subject shape changes (shape estimation, docs/shape.md), the record of the first frame
// posed with the new shape carries the template's new rest geometry, so the receiver skins the
// poses with the body they were fitted with. Only the rest joint centres and vertex positions
// change with the shape (bone lengths, girths, surface detail); the rig, triangles, UVs and
// skinning weights stay those of the header's template.
//
// Layout (little-endian): J (uint16), V (uint32), the vertex step s (float64, m), J x 3 joint
// centres (float64, m, rest frame), then V x 3 int16 q with vertex = base + q s, base the header
// template's rest vertex (as the receiver decodes it: float32 values), row by row.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "models/template.h"

namespace artex {

constexpr double kRestShapeStep = 1e-4;  // m: the vertex step (0.1 mm; +-3.27 m of offsets)

// The payload of `shaped` relative to `base` (the header's template). Throws artex::Error when
// they differ in joints, vertices or triangles, or when a vertex moved beyond the int16 range.
std::vector<uint8_t> EncodeRestShape(const Template& base, const Template& shaped,
                                     double step = kRestShapeStep);

// The inverse: *out becomes `base` with the payload's joint centres and vertices. False (with
// *why) for a damaged payload or one of another template's size; *out is then unchanged.
bool DecodeRestShape(const std::vector<uint8_t>& payload, const Template& base, Template* out,
                     std::string* why);

}  // namespace artex
