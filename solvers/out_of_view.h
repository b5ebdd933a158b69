// Joints the depth camera cannot see (docs/fitting.md "Joints out of view"): a joint whose
// vertices, posed at a frame's initial guess, mostly project outside the depth image (or behind
// the camera) has no scan points that could observe it. Fitting its rotation anyway lets the
// E-step's wide first-frame radii pull it into the image to explain points of other parts (on a
// person framed from the waist up, the legs below the image border are lifted beside the body to
// cover a hand). The fitter holds such a joint's rotation at the frame's initial guess; the
// global similarity and every joint in view stay free.
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

#include "render/camera.h"

namespace artex {

struct OutOfViewOptions {
  // A joint is held in a frame when fewer than this fraction of its vertices (the template
  // vertices whose dominant skinning joint it is) project inside the depth image, in front of
  // the camera, at the frame's initial guess. 0: off (every joint is fitted: the paper).
  double min_in_view_fraction = 0.25;
  // Also held: a joint whose bone is cut by the image border, i.e. whose child joints' centres
  // all project outside the image (a thigh whose knee is below the image): the part in view is
  // a stub at the border that does not tell the bone's direction, and the wide first-frame
  // radii fold it up into the body (on the virtual Kinect's upper-body view, 150 degrees at
  // both hips). Joints without children are judged by their vertices only.
  bool hold_cut_bones = true;
  // Pixels inside the image border that still count as out of view: the depth image's outermost
  // columns and rows are often invalid (the sensor's border), so a limb that only touches the
  // border is not seen.
  double border_px = 4.0;
  // Joints with fewer vertices than this are never held by their vertices (too few to tell).
  int min_vertices = 10;

  bool enabled() const { return min_in_view_fraction > 0.0 || hold_cut_bones; }
  bool IsValid(std::string* error) const;
};

// Template joint indices to hold: posed_vertices (V x 3, world) are the template posed at the
// frame's initial guess, vertex_joint (V) each vertex's dominant joint, joint_centers (J x 3) the
// posed joint centres and parents (J) each joint's parent (-1 for the root); camera is the depth
// camera (intrinsics and world_to_camera). Sorted ascending; empty when the options are off.
std::vector<int> OutOfViewJoints(const Eigen::MatrixX3d& posed_vertices,
                                 const Eigen::VectorXi& vertex_joint,
                                 const Eigen::MatrixX3d& joint_centers,
                                 const std::vector<int>& parents, const PinholeCamera& camera,
                                 const OutOfViewOptions& options);

}  // namespace artex
