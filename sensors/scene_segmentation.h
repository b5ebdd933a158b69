// Scene analysis of single-camera recordings without empty-scene frames (docs/real-data.md):
// large planes (floor, walls) found by RANSAC in the depth image, the world frame estimated
// from the floor (or gravity, or the camera convention), and the subject's foreground as one
// tracked 3-D connected component of what the planes and the depth range leave.
// All geometry here is in the depth camera frame (OpenCV: x right, y down, z forward, metres).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <map>
#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <vector>

#include "render/camera.h"
#include "sensors/calibration.h"
#include "sensors/depth_mesh.h"

namespace artex {

struct PlaneDetectionOptions {
  int sample_stride = 4;        // RANSAC on every n-th pixel in both directions
  int ransac_iterations = 300;  // hypotheses per plane
  int score_points = 3000;      // hypotheses are scored on this many random samples
  // |n . x + d| below inlier_distance + inlier_growth * z^2 is on the plane (m; the growth
  // follows the Kinect's depth noise, ~z^2).
  double inlier_distance = 0.03;
  double inlier_growth = 0.003;
  // A plane within merge_angle_deg and merge_distance (m) of an earlier one is the same
  // surface (noise split it): its inliers join the earlier plane.
  double merge_angle_deg = 5.0;
  double merge_distance = 0.15;
  int max_planes = 5;  // planes extracted one after the other
  // A plane needs this fraction of the sampled valid points (in the depth range) ...
  double min_inlier_fraction = 0.05;
  // ... and inliers spanning at least this much (m; 5-95 % quantiles along the principal
  // in-plane axes) in both directions to count as a wall (a person's front is smaller), or
  // floor_min_extent as a floor (a low camera sees the floor foreshortened).
  double min_extent = 1.5;
  double floor_min_extent = 1.0;
  // ... and whose inliers cover at least this fraction of that extent (area of the inlier
  // pixels on the plane / extent[0] * extent[1]): a real floor or wall is dense, a plane
  // through a person and things beside it at the same depth is not.
  double min_coverage = 0.5;
  double floor_max_angle_deg = 40.0;  // floor: normal within this of the up direction
  double wall_max_angle_deg = 25.0;   // wall: normal within this of horizontal
  double min_depth = 0.3;             // m: valid range of the samples
  double max_depth = 6.0;
  uint64_t seed = 1;
  bool IsValid(std::string* error) const;
};

enum class PlaneKind { kFloor, kWall, kOther };
const char* PlaneKindName(PlaneKind kind);

struct ScenePlane {
  Eigen::Vector3d normal = Eigen::Vector3d::UnitY();  // unit, camera frame, towards the camera
  double offset = 0.0;  // n . x + offset = 0 on the plane; offset > 0 (the camera's distance)
  int inliers = 0;      // sampled inliers
  double inlier_fraction = 0.0;   // of the sampled valid points
  double extent[2] = {0.0, 0.0};  // in-plane spread of the inliers (m), larger first
  double coverage = 0.0;          // inlier area / (extent[0] * extent[1])
  PlaneKind kind = PlaneKind::kOther;
  double SignedDistance(const Eigen::Vector3d& x) const { return normal.dot(x) + offset; }
};

// Planes of one depth frame (CV_16UC1, depth_scale units per metre; distortion undone),
// strongest first. up_prior: the up direction in the camera frame used to label floors and
// walls (camera convention: (0, -1, 0)). Deterministic given options.seed. Throws
// artex::Error for invalid options or a depth image of the wrong type or size.
std::vector<ScenePlane> DetectScenePlanes(const cv::Mat& depth, const PinholeCamera& intrinsics,
                                          const Distortion& distortion, double depth_scale,
                                          const Eigen::Vector3d& up_prior,
                                          const PlaneDetectionOptions& options);
// The same with the camera's ray table (distortion undone) already built.
std::vector<ScenePlane> DetectScenePlanes(const cv::Mat& depth, const DepthBackProjector& projector,
                                          double depth_scale, const Eigen::Vector3d& up_prior,
                                          const PlaneDetectionOptions& options);

// Which world frame tracking uses. kAuto: estimated when the calibration's world frame is the
// depth camera's own (identity world_to_camera, as for TUM folders), else the calibration's;
// kEstimate: always estimated; kCalibration: never.
enum class WorldFrameMode { kAuto, kEstimate, kCalibration };
const std::map<std::string, WorldFrameMode>& WorldFrameModeNames();  // auto, estimate, calibration

enum class WorldFrameSource { kCalibration, kFloor, kGravity, kCameraConvention };
const char* WorldFrameSourceName(WorldFrameSource source);

struct WorldFrameOptions {
  PlaneDetectionOptions planes;
  // Without a floor: the world origin lies this far below the camera (m).
  double assumed_camera_height = 1.2;
  bool IsValid(std::string* error) const;
};

// A world frame for the artex conventions (metres, Y up, floor at y = 0 when known) whose
// -Z axis is the camera's viewing direction projected on the floor: a template facing +Z
// faces the camera. world_to_camera maps world points into the depth camera frame.
struct WorldFrameEstimate {
  Eigen::Isometry3d world_to_camera = Eigen::Isometry3d::Identity();
  WorldFrameSource source = WorldFrameSource::kCameraConvention;
  Eigen::Vector3d up_camera = Eigen::Vector3d(0, -1, 0);  // world +Y in the camera frame
  double camera_height = 0.0;     // m above the floor (assumed_camera_height without a floor)
  double camera_pitch_deg = 0.0;  // viewing direction below the horizon (positive: down)
  double camera_roll_deg = 0.0;   // image x axis against the horizon
  std::vector<ScenePlane> planes;
  std::string Describe() const;  // one line for logs and warnings
};

// The world frame with +Y = up (camera frame), origin below the camera at `height`.
Eigen::Isometry3d WorldFrameFromUp(const Eigen::Vector3d& up_camera, double height);

// Up from the floor plane (the largest floor-labelled plane), else from gravity_up (unit, camera
// frame; e.g. a TUM accelerometer), else the camera convention (up = -y of the camera).
// Gravity, when given, is also the prior that labels the floor.
WorldFrameEstimate EstimateWorldFrame(const cv::Mat& depth, const PinholeCamera& intrinsics,
                                      const Distortion& distortion, double depth_scale,
                                      const std::optional<Eigen::Vector3d>& gravity_up,
                                      const WorldFrameOptions& options);

// The floor of a depth frame in the world frame of `camera` (its world_to_camera, world +Y up):
// the floor-labelled plane (up prior: world +Y) with the most inliers, its normal pointing up;
// none when no plane is labelled a floor (a camera framing the upper body sees none).
std::optional<ScenePlane> FindWorldFloor(const cv::Mat& depth, const PinholeCamera& camera,
                                         const Distortion& distortion, double depth_scale,
                                         const PlaneDetectionOptions& options);

// How the subject is chosen among the person-sized components.
enum class SubjectChoice { kCentral, kNearest, kLargest, kPixel };
const std::map<std::string, SubjectChoice>& SubjectChoiceNames();

struct SubjectSegmentationOptions {
  PlaneDetectionOptions planes;
  double min_depth = 0.3;  // m: valid range of the foreground
  double max_depth = 5.0;
  // Points within plane_margin + plane_margin_growth * z^2 of a floor or wall plane, or
  // behind it, are background (m).
  double plane_margin = 0.04;
  double plane_margin_growth = 0.003;
  // Components in two passes. Tight: neighbouring pixels join when their depths differ by
  // less than connect_distance + connect_growth * z^2 (about twice the Kinect's depth step;
  // two people touching in the image stay apart). Loose: a fragment (an arm in front of the
  // body, a limb split off by noise) joins a neighbour across a depth difference below
  // max(connect_distance, merge_relative * z) unless both are at least fragment_height tall
  // (extent along up, m): two people stay apart.
  double connect_distance = 0.01;
  double connect_growth = 0.003;
  double merge_relative = 0.08;
  double fragment_height = 0.9;
  // Stacked parts: two components of at least min_pixels that no pixel chain links join when
  // they share image columns, overlap along up by less than stacked_max_overlap of the shorter
  // one (or leave a gap below stacked_max_gap, m), have depth ranges less than
  // merge_relative * z apart and are at most max_height tall together: one stands on the other (a
  // walking body seen from the side, cut at the waist by a band of dropped pixels along the
  // near arm), not two people (people side by side overlap along up). 0: never.
  double stacked_max_overlap = 0.5;
  double stacked_max_gap = 0.1;
  // People touching in the image at one depth: a component with two or more heads is split
  // between them. A head is a profile peak (the highest point of each lateral bin of
  // head_bin m) within head_top_range of the component's top, narrower than max_head_width
  // head_depth below its top and at least min_shoulder_width wide shoulder_drop below it (a
  // raised hand is narrow there); neighbouring heads must lie min_head_separation apart with
  // a profile valley at least min_valley below the lower one.
  bool split_people = true;
  double head_bin = 0.02;
  double head_top_range = 0.5;
  double head_depth = 0.12;
  double max_head_width = 0.30;
  double shoulder_drop = 0.32;
  double min_shoulder_width = 0.36;
  double min_head_separation = 0.22;
  double min_valley = 0.1;
  // Person-sized: at least min_pixels pixels, an extent along up in [min_height, max_height]
  // and a horizontal extent at most max_width (m; arms spread included).
  int min_pixels = 800;
  double min_height = 0.35;
  double max_height = 2.4;
  double max_width = 2.4;
  SubjectChoice choice = SubjectChoice::kCentral;
  // kPixel: the component containing (or nearest to) this pixel (column, row).
  Eigen::Vector2i pixel = Eigen::Vector2i(-1, -1);
  // Later frames keep the component whose centroid is nearest the previous subject's, within
  // this distance (m); none within it: no subject in the frame (and a new choice next frame).
  double track_max_distance = 0.5;
  bool IsValid(std::string* error) const;
};

struct SegmentationStats {
  int candidate_pixels = 0;  // valid, in range, off the planes
  int components = 0;        // of at least min_pixels
  int person_sized = 0;
  int people_splits = 0;   // components split between several heads
  int subject_pixels = 0;  // 0: nobody found
  bool tracked = false;    // the subject continues the previous frame's
  Eigen::Vector3d subject_centroid = Eigen::Vector3d::Zero();  // camera frame
  double subject_height = 0.0;                                 // m along up
  double subject_width = 0.0;  // m: twice the largest horizontal distance from its centroid
};

// Foreground without background frames: floor and walls (detected on the first frame, or
// given), the depth range, then 3-D connected components on the depth image grid; the subject
// is chosen by options.choice and tracked from frame to frame.
class SubjectSegmenter {
 public:
  // up_camera: world +Y in the depth camera frame. Throws artex::Error for invalid options.
  SubjectSegmenter(const PinholeCamera& intrinsics, const Distortion& distortion,
                   double depth_scale, const Eigen::Vector3d& up_camera,
                   const SubjectSegmentationOptions& options);
  // The same with the camera's ray table already built (e.g. the depth mesher's).
  SubjectSegmenter(const DepthBackProjector& projector, double depth_scale,
                   const Eigen::Vector3d& up_camera, const SubjectSegmentationOptions& options);
  // Uses these planes instead of detecting them on the first frame (only floors and walls
  // are removed).
  void SetPlanes(const std::vector<ScenePlane>& planes);
  // depth: CV_16UC1 of the camera size -> mask CV_8UC1 (255 = subject). Throws artex::Error
  // for a wrong type or size.
  void Segment(const cv::Mat& depth, cv::Mat* mask, SegmentationStats* stats = nullptr);
  // Forgets the tracked subject: the next frame chooses anew.
  void ResetTracking() { has_subject_ = false; }
  const std::vector<ScenePlane>& planes() const { return planes_; }
  bool planes_known() const { return planes_known_; }

 private:
  // Splits the flattened components that hold several people (split_people).
  void SplitPeople(int width, int height, int* splits);

  // Row v of the ray table: 2 floats (x / z, y / z) per pixel.
  const float* RayRow(int v) const {
    return projector_.rays() + 2 * static_cast<size_t>(v) * projector_.camera().width;
  }

  DepthBackProjector projector_;
  double depth_scale_;
  Eigen::Vector3d up_;
  SubjectSegmentationOptions options_;
  std::vector<ScenePlane> planes_;
  bool planes_known_ = false;
  bool has_subject_ = false;
  Eigen::Vector3d subject_centroid_ = Eigen::Vector3d::Zero();
  std::vector<int> parent_;        // union-find over pixels
  std::vector<float> low_, high_;  // extent along up per root (loose merging)
  void JoinStackedParts(int w, int h);
  std::vector<float> z_;
};

}  // namespace artex
