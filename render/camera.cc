#include "render/camera.h"

namespace artex {

Eigen::Vector2d PinholeCamera::Project(const Eigen::Vector3d& world, double* depth) const {
  const Eigen::Vector3d c = world_to_camera * world;
  if (depth) *depth = c.z();
  return {fx * c.x() / c.z() + cx, fy * c.y() / c.z() + cy};
}

Eigen::Vector3d PinholeCamera::Unproject(double u, double v, double depth) const {
  const Eigen::Vector3d c((u - cx) / fx * depth, (v - cy) / fy * depth, depth);
  return world_to_camera.inverse() * c;
}

Eigen::Vector3d PinholeCamera::Center() const {
  return world_to_camera.inverse().translation();
}

Eigen::Isometry3d PinholeCamera::LookAt(const Eigen::Vector3d& eye, const Eigen::Vector3d& target,
                                        const Eigen::Vector3d& up) {
  const Eigen::Vector3d z = (target - eye).normalized();
  const Eigen::Vector3d x = z.cross(up).normalized();  // image x to the right (forward x up)
  const Eigen::Vector3d y = z.cross(x);                // image y downwards (-up projected)
  Eigen::Matrix3d r;
  r.row(0) = x.transpose();
  r.row(1) = y.transpose();
  r.row(2) = z.transpose();
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.linear() = r;
  t.translation() = -r * eye;
  return t;
}

}  // namespace artex
