// Joints out of the depth camera's view (solvers/out_of_view.h): which joints are held, and
// that the fitter holds them at the frame's initial guess while the joints in view are fitted.
#include "solvers/out_of_view.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <string>
#include <vector>

#include "models/skinning.h"
#include "models/template_generator.h"
#include "solvers/em_fitter.h"
#include "solvers/initializer.h"
#include "tests/solvers/virtual_kinect_scans.h"

namespace artex {
namespace {

bool Contains(const std::vector<int>& v, int x) { return std::find(v.begin(), v.end(), x) != v.end(); }

// A camera 1 m in front of a standing template at chest height, looking slightly down: the
// image shows the head, the arms and the torso down to about the hips (as the upper-body
// condition of the virtual Kinect).
PinholeCamera UpperBodyCamera() {
  PinholeCamera camera;
  camera.world_to_camera = PinholeCamera::LookAt(Eigen::Vector3d(0.0, 1.3, 1.0),
                                                 Eigen::Vector3d(0.0, 1.2, 0.0),
                                                 Eigen::Vector3d::UnitY());
  return camera;
}

// The rest-posed template's vertices, joint centres and parents, and the joints to hold.
struct Posed {
  Eigen::MatrixX3d vertices, centers;
  std::vector<int> parents;
  explicit Posed(const Template& t) {
    const Skinning skinning(t);
    const Pose rest = Pose::Identity(t.num_joints());
    skinning.Apply(rest, &vertices);
    skinning.PosedJointCenters(rest, &centers);
    for (const Joint& j : t.joints) parents.push_back(j.parent);
  }
  std::vector<int> Held(const Template& t, const PinholeCamera& camera,
                        const OutOfViewOptions& options = OutOfViewOptions()) const {
    return OutOfViewJoints(vertices, t.vertex_joint, centers, parents, camera, options);
  }
};

TEST(OutOfViewTest, TheLegsBelowTheImageAreHeldTheUpperBodyIsNot) {
  const Template tmpl = GenerateTemplate();
  const Posed posed(tmpl);
  const std::vector<int> held = posed.Held(tmpl, UpperBodyCamera());
  // The thighs are half in view, but the knees are not: their bones are cut by the border.
  for (const char* leg : {"l_hip", "r_hip", "l_knee", "l_ankle", "r_knee", "r_ankle"}) {
    EXPECT_TRUE(Contains(held, tmpl.FindJoint(leg))) << leg << " not held";
  }
  // (The forearms of the rest pose leave the image at its sides: the elbows are held too.)
  for (const char* seen : {"head", "neck", "chest", "spine", "l_shoulder", "r_shoulder"}) {
    EXPECT_FALSE(Contains(held, tmpl.FindJoint(seen))) << seen << " held";
  }
  // The whole body in view (camera 3 m away): nothing is held.
  PinholeCamera far;
  far.world_to_camera = PinholeCamera::LookAt(Eigen::Vector3d(0.0, 1.0, 3.5),
                                              Eigen::Vector3d(0.0, 0.9, 0.0),
                                              Eigen::Vector3d::UnitY());
  EXPECT_TRUE(posed.Held(tmpl, far).empty());
  // Looking away from the body: every joint with enough vertices is held.
  PinholeCamera away;
  away.world_to_camera = PinholeCamera::LookAt(Eigen::Vector3d(0.0, 1.0, 3.5),
                                               Eigen::Vector3d(0.0, 1.0, 7.0),
                                               Eigen::Vector3d::UnitY());
  EXPECT_EQ(static_cast<int>(posed.Held(tmpl, away).size()), tmpl.num_joints());
  // By the vertices alone, the thighs half in view are fitted.
  OutOfViewOptions by_vertices;
  by_vertices.hold_cut_bones = false;
  const std::vector<int> vertices_only = posed.Held(tmpl, UpperBodyCamera(), by_vertices);
  EXPECT_TRUE(Contains(vertices_only, tmpl.FindJoint("l_knee")));
  EXPECT_FALSE(Contains(vertices_only, tmpl.FindJoint("l_hip")));
  // Off: nothing is held.
  OutOfViewOptions off;
  off.min_in_view_fraction = 0.0;
  off.hold_cut_bones = false;
  EXPECT_TRUE(posed.Held(tmpl, away, off).empty());
}

TEST(OutOfViewTest, InvalidOptionsAreRejected) {
  std::string error;
  OutOfViewOptions o;
  o.min_in_view_fraction = 1.5;
  EXPECT_FALSE(o.IsValid(&error));
  EXPECT_NE(error.find("min_in_view_fraction"), std::string::npos) << error;
  o = OutOfViewOptions();
  o.border_px = -1.0;
  EXPECT_FALSE(o.IsValid(&error));
  o = OutOfViewOptions();
  o.min_vertices = 0;
  EXPECT_FALSE(o.IsValid(&error));
  EMFitterOptions fitting;
  fitting.out_of_view.min_in_view_fraction = -0.1;
  EXPECT_FALSE(fitting.IsValid(&error));
  EXPECT_NE(error.find("out_of_view.min_in_view_fraction"), std::string::npos) << error;
}

// The virtual Kinect's upper-body view (the legs below the image): the multi-hypothesis
// initialisation keeps the unseen legs at the chosen hypothesis' pose, bit for bit, while it fits
// the arms and the torso; with the option off the first-frame radii fold the thighs, half in
// view, up into the body.
TEST(OutOfViewTest, TheInitialisationHoldsTheUnseenLegs) {
  SynthOptions options = testing_util::TestSynthOptions(1);
  options.kinect.depth_eye = Eigen::Vector3d(0.0, 1.3, 1.0);
  options.kinect.depth_target = Eigen::Vector3d(0.0, 1.2, 0.0);
  const testing_util::KinectScans data = testing_util::SynthesizeScans(options, "out_of_view");
  ASSERT_EQ(data.scans.size(), 1u);
  BodyShapeOptions coarse;
  coarse.resolution = 0;
  const Template tmpl = GenerateTemplate(coarse);
  const std::vector<int> legs = {tmpl.FindJoint("l_hip"), tmpl.FindJoint("r_hip"),
                                 tmpl.FindJoint("l_knee"), tmpl.FindJoint("r_knee"),
                                 tmpl.FindJoint("l_ankle"), tmpl.FindJoint("r_ankle")};
  double moved_off = 0.0;
  for (const bool on : {true, false}) {
    EMFitterOptions fitting;
    if (!on) {
      fitting.out_of_view.min_in_view_fraction = 0.0;
      fitting.out_of_view.hold_cut_bones = false;
    }
    EMFitter fitter(tmpl, fitting);
    const InitResult r =
        InitializeFit(&fitter, data.scans[0], data.depth_camera, InitializerOptions());
    ASSERT_TRUE(r.ok) << r.BriefReport();
    ASSERT_GE(r.chosen, 0);
    const Pose& start = r.hypotheses[r.chosen].icp.pose;  // the chosen hypothesis before EM
    double moved = 0.0;  // largest leg rotation away from the hypothesis (Frobenius norm)
    for (int j : legs) {
      moved = std::max(moved, (r.pose.joint_rotations[j] - start.joint_rotations[j]).norm());
    }
    std::printf("out of view %s: %d joints held in the accepted fit, legs moved %.4f rad; %s\n",
                on ? "on" : "off", r.fit.out_of_view_joints, moved,
                r.quality.BriefReport().c_str());
    if (on) {
      EXPECT_GE(r.fit.out_of_view_joints, 4);
      EXPECT_EQ(moved, 0.0);
      EXPECT_NE(r.quality.label, FitQualityLabel::kLost) << r.quality.BriefReport();
    } else {
      EXPECT_EQ(r.fit.out_of_view_joints, 0);
      moved_off = moved;
    }
  }
  EXPECT_GT(moved_off, 1e-3);  // the property the option exists for
}

}  // namespace
}  // namespace artex
