#include "models/uv_raster.h"

#include <algorithm>
#include <cmath>

namespace artex {

UvTriangleCells UvTriangleOnGrid(const Template& tmpl, int triangle, int n) {
  UvTriangleCells t;
  Eigen::Vector2d* p = t.p;
  for (int c = 0; c < 3; ++c) p[c] = tmpl.uvs.row(tmpl.uv_triangles(triangle, c)).transpose() * n;
  t.area2 = (p[1] - p[0]).x() * (p[2] - p[0]).y() - (p[1] - p[0]).y() * (p[2] - p[0]).x();
  if (t.area2 == 0.0) return t;  // every caller skips these: no box (its corners may be huge)
  t.x0 = std::max(0, static_cast<int>(std::floor(std::min({p[0].x(), p[1].x(), p[2].x()}))));
  t.x1 = std::min(n - 1, static_cast<int>(std::ceil(std::max({p[0].x(), p[1].x(), p[2].x()}))));
  t.y0 = std::max(0, static_cast<int>(std::floor(std::min({p[0].y(), p[1].y(), p[2].y()}))));
  t.y1 = std::min(n - 1, static_cast<int>(std::ceil(std::max({p[0].y(), p[1].y(), p[2].y()}))));
  return t;
}

}  // namespace artex
