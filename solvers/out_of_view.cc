#include "solvers/out_of_view.h"

#include <cmath>
#include <sstream>

namespace artex {

bool OutOfViewOptions::IsValid(std::string* error) const {
  std::ostringstream msg;
  if (!(min_in_view_fraction >= 0.0 && min_in_view_fraction <= 1.0)) {
    msg << "min_in_view_fraction: expected a value in [0, 1] (0: off), found "
        << min_in_view_fraction;
  } else if (!(std::isfinite(border_px) && border_px >= 0.0)) {
    msg << "border_px: expected a finite value >= 0 (pixels), found " << border_px;
  } else if (min_vertices < 1) {
    msg << "min_vertices: expected >= 1, found " << min_vertices;
  } else {
    return true;
  }
  if (error) *error = msg.str();
  return false;
}

namespace {

// Inside the image, `border_px` in from its edge, and in front of the camera.
struct ViewTest {
  const PinholeCamera& camera;
  double lo_u, hi_u, lo_v, hi_v;
  ViewTest(const PinholeCamera& c, double border)
      : camera(c),
        lo_u(border - 0.5),
        hi_u(c.width - 0.5 - border),
        lo_v(border - 0.5),
        hi_v(c.height - 0.5 - border) {}
  bool operator()(const Eigen::Vector3d& world) const {
    double z = 0.0;
    const Eigen::Vector2d uv = camera.Project(world, &z);
    if (!(z > 1e-6)) return false;  // behind the camera (or not finite)
    return uv.x() >= lo_u && uv.x() <= hi_u && uv.y() >= lo_v && uv.y() <= hi_v;
  }
};

}  // namespace

std::vector<int> OutOfViewJoints(const Eigen::MatrixX3d& posed_vertices,
                                 const Eigen::VectorXi& vertex_joint,
                                 const Eigen::MatrixX3d& joint_centers,
                                 const std::vector<int>& parents, const PinholeCamera& camera,
                                 const OutOfViewOptions& options) {
  std::vector<int> held;
  const int num_joints = static_cast<int>(parents.size());
  if (!options.enabled() || num_joints <= 0) return held;
  const ViewTest in_view(camera, options.border_px);
  std::vector<int> total(num_joints, 0), seen(num_joints, 0);
  const Eigen::Index n = std::min<Eigen::Index>(posed_vertices.rows(), vertex_joint.size());
  for (Eigen::Index i = 0; i < n; ++i) {
    const int j = vertex_joint[i];
    if (j < 0 || j >= num_joints) continue;
    ++total[j];
    if (in_view(posed_vertices.row(i).transpose())) ++seen[j];
  }
  // Children in view, per joint (-1: no children).
  std::vector<int> children(num_joints, 0), children_seen(num_joints, 0);
  if (options.hold_cut_bones && joint_centers.rows() == num_joints) {
    for (int c = 0; c < num_joints; ++c) {
      const int p = parents[c];
      if (p < 0 || p >= num_joints) continue;
      ++children[p];
      if (in_view(joint_centers.row(c).transpose())) ++children_seen[p];
    }
  }
  for (int j = 0; j < num_joints; ++j) {
    const bool few_seen = options.min_in_view_fraction > 0.0 && total[j] >= options.min_vertices &&
                          seen[j] < options.min_in_view_fraction * total[j];
    const bool cut = children[j] > 0 && children_seen[j] == 0;
    if (few_seen || cut) held.push_back(j);
  }
  return held;
}

}  // namespace artex
