// A UV triangle on an n x n grid of cells (texels): its corners in cell units, twice its signed
// area and its clamped cell box, with the inclusive cell-centre test. Shared by the UV coverage
// of SummarizeTemplate (models/template_summary.cc), the texel map of GenerateSubjectTexture
// (sensors/subject_texture.cc) and AtlasMap (texture/texel_sampling.cc, which keeps its own
// barycentric test). Cell (x, y) has its centre at (x + 0.5, y + 0.5); y is the image row
// (UV v downwards, models/template.h).
#pragma once

#include <Eigen/Core>

#include "models/template.h"

namespace artex {

struct UvTriangleCells {
  Eigen::Vector2d p[3];  // the corners in cell units: uv * n
  double area2 = 0.0;    // (p1 - p0) x (p2 - p0): twice the signed area (0: degenerate)
  // Cells x0..x1, y0..y1 (inclusive): floor of the corners' minimum, ceil of their maximum,
  // clamped to [0, n - 1]; empty (x1 < x0 or y1 < y0) when the triangle lies off the grid or
  // area2 == 0.
  int x0 = 0, x1 = -1, y0 = 0, y1 = -1;
};

// UV triangle `triangle` of `tmpl` (which has UVs) on the n x n grid. Callers skip degenerate
// triangles by their own threshold on area2.
UvTriangleCells UvTriangleOnGrid(const Template& tmpl, int triangle, int n);

// Whether the centre of cell (x, y) lies inside t or on one of its edges, in either orientation.
// For a non-degenerate t (area2 != 0).
inline bool CellCentreInside(const UvTriangleCells& t, int x, int y) {
  const Eigen::Vector2d q(x + 0.5, y + 0.5);
  bool inside = true;
  for (int c = 0; c < 3 && inside; ++c) {
    const Eigen::Vector2d e = t.p[(c + 1) % 3] - t.p[c], d = q - t.p[c];
    const double cross = e.x() * d.y() - e.y() * d.x();
    inside = t.area2 > 0.0 ? cross >= 0.0 : cross <= 0.0;
  }
  return inside;
}

// Calls f(x, y) for every cell of t's box whose centre CellCentreInside accepts, row by row.
template <typename F>
void ForEachCellInside(const UvTriangleCells& t, F&& f) {
  for (int y = t.y0; y <= t.y1; ++y) {
    for (int x = t.x0; x <= t.x1; ++x) {
      if (CellCentreInside(t, x, y)) f(x, y);
    }
  }
}

}  // namespace artex
