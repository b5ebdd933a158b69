// The embedded default human template, generated deterministically from body parameters
// (anthropometric ratios of the stature): a smooth, closed, single-component 2-manifold
// of ~10k-15k vertices, 17 joints, skinning constants and a per-body-part UV atlas.
// Rest pose: A-pose (arms ~40 degrees below horizontal), Y up, facing +Z, feet at y = 0.
// Method, joint layout and constants: docs/template.md.
#pragma once

#include <string>
#include <vector>

#include "models/template.h"
#include "models/uv_atlas.h"

namespace artex {

struct BodyShapeOptions {
  double height = 1.75;        // stature (m), sole to top of head; valid range [1.0, 2.3]
  double girth = 1.0;          // multiplies every body circumference; valid range [0.6, 1.6]
  double shoulder_width = 1.0; // multiplies the biacromial breadth; [0.7, 1.3]
  double hip_width = 1.0;      // multiplies the hip breadth; [0.7, 1.3]
  double arm_length = 1.0;     // multiplies upper arm, forearm and hand lengths; [0.8, 1.2]
  double leg_length = 1.0;     // multiplies thigh and shank lengths; [0.8, 1.2]
  double arm_angle_deg = 40.0; // A-pose: arms below horizontal (degrees); [0, 80]
  int resolution = 1;          // 0: coarse (~3k vertices, tests), 1: default (~12.5k)
  int atlas_size = 2048;       // texture atlas side (texels), used for chart padding; >= 256
  double atlas_padding_texels = 4.0;  // gap kept between charts (texels)

  bool IsValid(std::string* error) const;
};

// Throws artex::Error when the options are invalid. The result passes Template::IsValid.
Template GenerateTemplate(const BodyShapeOptions& options = BodyShapeOptions());

// The 17 joint names of generated templates, in index order (root first):
// pelvis, spine, chest, neck, head, l_shoulder, l_elbow, l_wrist, r_shoulder, r_elbow,
// r_wrist, l_hip, l_knee, l_ankle, r_hip, r_knee, r_ankle.
const char* const* DefaultJointNames();
constexpr int kDefaultNumJoints = 17;

// ---------------------------------------------------------------------------------------------
// Finer control. Lengths are fractions of the stature H unless stated; "y" values are nominal
// heights above the floor for a leg_length of 1 (the upper body is shifted/scaled vertically
// so that the head top stays at H whatever the legs). x is the body's left (+X), z the front.
// Defaults: adult segment ratios after Drillis & Contini (1966) / Winter (2009) and adult
// breadths and circumferences (ANSUR-like means) expressed as ratios of a 1.75 m stature.
struct BodyProportions {
  // Skeleton (joint centres).
  double ankle_height = 0.039;       // lateral malleolus
  double hip_height = 0.530;         // hip joint centre (nominal, leg_length = 1)
  double hip_half_spacing = 0.050;   // |x| of each hip joint centre (scaled by hip_width)
  double leg_spread_deg = 7.0;       // each leg's tilt outwards from vertical (degrees)
  double thigh_length = 0.245;       // hip to knee (scaled by leg_length)
  double shank_length = 0.246;       // knee to ankle (scaled by leg_length)
  double pelvis_height = 0.555;      // root joint (lumbosacral)
  double spine_height = 0.620;       // lumbar joint
  double chest_height = 0.715;       // thoracic joint
  double neck_height = 0.822;        // base of the neck (C7)
  double head_joint_height = 0.878;  // atlanto-occipital joint
  double shoulder_height = 0.805;    // glenohumeral joint centre
  double shoulder_half_breadth = 0.117;  // |x| of the shoulder joint (scaled by shoulder_width)
  double girth_shoulder_shift = 0.04;    // shoulder |x| += (girth - 1) * this (wider trunks)
  double upper_arm_length = 0.186;   // shoulder to elbow (scaled by arm_length)
  double forearm_length = 0.146;     // elbow to wrist (scaled by arm_length)
  double hand_length = 0.108;        // wrist to fingertip (scaled by arm_length)
  double palm_fraction = 0.5;        // wrist-to-knuckles share of the hand length
  // Trunk: a loft of elliptical cross-sections (interpolated by C1 cubic Hermite splines in
  // y, rounded caps at both ends). Half widths are scaled by hip_width up to hip_section_top,
  // by shoulder_width from shoulder_section_bottom, blended linearly between; all by girth.
  struct TorsoSection {
    double y;           // nominal height
    double half_width;  // x
    double half_depth;  // z
    double centre_z;
  };
  std::vector<TorsoSection> torso_sections = {
      {0.470, 0.046, 0.050, -0.004},  // crotch
      {0.500, 0.090, 0.066, -0.010},
      {0.530, 0.095, 0.067, -0.011},  // hip joints, greater trochanters
      {0.570, 0.091, 0.062, -0.006},  // iliac crest
      {0.610, 0.082, 0.058, 0.000},   // waist
      {0.660, 0.086, 0.062, 0.002},   // lower ribs
      {0.720, 0.093, 0.068, 0.004},   // chest
      {0.770, 0.097, 0.064, 0.000},   // armpits
      {0.800, 0.098, 0.057, -0.005},
      {0.815, 0.088, 0.051, -0.007},  // trapezius slope
      {0.830, 0.064, 0.044, -0.010},
      {0.845, 0.040, 0.036, -0.012},  // neck base
  };
  double hip_section_top = 0.575;
  double shoulder_section_bottom = 0.770;
  Eigen::Vector3d buttock_centre{0.040, 0.505, -0.034};   // mirrored for the right buttock
  Eigen::Vector3d buttock_semi_axes{0.044, 0.048, 0.040};
  // Neck and head (head semi-axes are not scaled by girth; the head top is at y = 1).
  double neck_base_radius = 0.035;
  double neck_top_radius = 0.031;
  Eigen::Vector3d head_semi_axes{0.045, 0.066, 0.056};
  double head_centre_z = 0.006;
  Eigen::Vector3d jaw_centre{0.0, 0.893, 0.022};  // y measured like the other trunk heights
  Eigen::Vector3d jaw_semi_axes{0.036, 0.030, 0.040};
  Eigen::Vector3d nose_centre{0.0, 0.920, 0.060};
  Eigen::Vector3d nose_semi_axes{0.008, 0.015, 0.013};
  // Limb radii (scaled by girth, except hands and feet).
  double deltoid_radius = 0.029;
  double trapezius_radius = 0.019;       // neck-to-shoulder slope (cone radius)
  double upper_arm_radius_top = 0.029;
  double upper_arm_radius_bottom = 0.0235;
  double forearm_radius_top = 0.0240;
  double forearm_radius_bulge = 0.0250;  // muscle belly at forearm_bulge_fraction
  double forearm_bulge_fraction = 0.30;
  double forearm_radius_wrist = 0.0165;
  double palm_half_width = 0.024;
  double finger_half_width = 0.020;
  double fingertip_half_width = 0.015;
  double hand_flattening = 0.45;         // hand thickness / width
  double thumb_length = 0.032;
  double thumb_radius = 0.0085;
  double thigh_radius_top = 0.050;
  double thigh_radius_bottom = 0.031;
  double thigh_muscle_radius = 0.046;    // muscle belly at thigh_muscle_fraction of the thigh
  double thigh_muscle_fraction = 0.35;
  double shank_radius_top = 0.030;
  double calf_radius = 0.0330;           // muscle belly at calf_fraction of the shank
  double calf_fraction = 0.30;
  double shank_radius_ankle = 0.0185;
  double foot_length = 0.152;
  double foot_half_width = 0.028;
  double foot_half_height = 0.016;       // forefoot box half height (sole at y = 0)
  double heel_offset = 0.030;            // heel end behind the ankle centre
  double foot_rounding = 0.014;          // edge radius of the foot box
  // Placement details (fractions of H unless stated).
  double neck_base_z = -0.012;           // z of the neck joint (the neck leans forwards)
  double neck_extension_bottom = 0.03;   // neck cone starts this far below the neck joint
  double neck_extension_top = 0.015;     // and ends this far above the head joint
  double torso_cap_rounding = 0.8;       // loft end caps: fraction of the end's smaller half axis
  double trapezius_neck_x = 0.3;         // trapezius start |x|, fraction of the shoulder |x|
  double trapezius_neck_z = -0.01;
  double trapezius_taper = 0.8;          // end radius / start radius
  double acromion_rise = 0.012;          // trapezius end above the shoulder joint
  double acromion_inset = 0.02;          // trapezius end medial of the shoulder joint
  double deltoid_offset = 0.005;         // deltoid centre: joint + offset * (arm dir + up)
  double forearm_bulge_length = 0.35;    // forearm muscle semi-axis, fraction of the forearm
  double palm_start_offset = 0.005;      // palm starts this far inside the wrist
  double thumb_angle_deg = 35.0;         // thumb direction between the hand axis and +Z
  double thumb_base_fraction = 0.22;     // of the hand length, from the wrist
  double thumb_base_offset = 0.55;       // towards +Z, fraction of the palm half width
  double thumb_taper = 0.8;              // tip radius / base radius
  double thigh_muscle_length = 0.45;     // thigh muscle semi-axis, fraction of the thigh
  double calf_length = 0.32;             // calf semi-axis, fraction of the shank
  double calf_back_offset = 0.008;       // calf centre behind the shank axis
  double foot_ball_fraction = 0.72;      // ball of the foot, fraction of the foot length
  double instep_height = 1.3;            // instep cone end height, in foot half heights
  double heel_radius = 1.6;              // heel ellipsoid, in foot half heights
  double heel_width = 0.9;               // heel half width, fraction of the foot half width
  // Smooth-union radii (polynomial smooth minimum) with which parts join the body.
  double blend_trunk = 0.030;            // between trunk ellipsoids, neck and head
  double blend_limb_root = 0.018;        // limbs to the trunk
  double blend_limb = 0.014;             // along limbs, feet
  double blend_hand = 0.008;             // palm, fingers, thumb, nose

  bool IsValid(std::string* error) const;
};

// Half widths (m, for a 1.75 m stature; scaled with the height) of the bands over which each
// joint's LBS weight w_l rises from 0 to 1 (smoothstep of the geodesic distance from the
// segment's border, full ramp = 2 * half width). Every segment starts at the plane through
// (joint centre - half width * incoming bone direction), so w_l is about 0.5 at the joint
// centre; arm and neck segments are further limited to where their own primitives dominate
// the implicit body (docs/template.md, "Segmentation").
struct SkinningBands {
  double spine = 0.05;
  double chest = 0.05;
  double neck = 0.04;
  double head = 0.03;
  double shoulder = 0.06;
  double elbow = 0.05;
  double wrist = 0.03;
  double hip = 0.06;
  double knee = 0.05;
  double ankle = 0.04;
  // Trunk vertices above the neck band within this distance of the neck axis belong to the
  // neck (the trapezius slope stays with the chest).
  double neck_radius = 0.10;

  bool IsValid(std::string* error) const;
};

struct MeshingOptions {
  double grid_cell = 0.006;         // sampling grid step of the implicit body (fraction of H)
  double grid_cell_coarse = 0.009;  // the same for resolution 0
  int target_vertices_coarse = 3000;   // resolution 0
  int target_vertices_default = 12500; // resolution 1
  double edge_length_factor = 1.0;     // calibration of the remeshing target edge length
  int remesh_iterations = 6;     // isotropic remeshing passes (split, collapse, flip, relax)
  int projection_iterations = 3; // Newton steps onto the implicit surface per pass
  double min_part_component = 0.2;  // body-part islands below this fraction of the part's
                                    // largest component are merged into their neighbours

  bool IsValid(std::string* error) const;
};

struct TemplateGeneratorOptions {
  BodyProportions proportions;
  SkinningBands bands;
  MeshingOptions meshing;
  UvAtlasOptions atlas;  // atlas_size / padding_texels are taken from BodyShapeOptions
  bool build_atlas = true;  // false: no UVs (uvs, uv_triangles and triangle_chart empty)
};

struct TemplateGeneratorSummary {
  int grid_vertices = 0;        // vertices of the extracted iso-surface before remeshing
  int removed_components = 0;   // spurious iso-surface components dropped (expected 0)
  double target_edge_length = 0.0;  // m
  double surface_area = 0.0;    // m^2
  double volume = 0.0;          // m^3 (signed, > 0 for outward orientation)
  int relabelled_vertices = 0;  // vertices moved to a parent joint to keep segments adjacent
  UvAtlasSummary atlas;
  double seconds_field = 0.0, seconds_remesh = 0.0, seconds_skinning = 0.0,
         seconds_atlas = 0.0;
};

// Same as GenerateTemplate(options); `summary` may be null.
Template GenerateTemplate(const BodyShapeOptions& options,
                          const TemplateGeneratorOptions& generator,
                          TemplateGeneratorSummary* summary);

// Checks that `triangles` form a closed, consistently oriented 2-manifold (every edge in
// exactly two triangles with opposite directions, every vertex link a single cycle) with one
// connected component and Euler characteristic 2. Returns false and describes the first
// problem in `error` otherwise.
bool IsClosedManifoldSphere(int num_vertices, const Eigen::MatrixX3i& triangles,
                            std::string* error);

}  // namespace artex
