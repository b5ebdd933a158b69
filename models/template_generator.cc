// GenerateTemplate (models/template_generator.h): option checks, the manifold check, the steps.
#include "models/template_generator.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <numeric>
#include <sstream>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "models/error.h"
#include "models/template_generator_internal.h"

namespace artex {
namespace {

using generator_internal::AssignCharts;
using generator_internal::Body;
using generator_internal::BuildBody;
using generator_internal::ComputeSkinningConstants;
using generator_internal::ExtractIsoSurface;
using generator_internal::FaceNormal;
using generator_internal::FixSegmentAdjacency;
using generator_internal::KeepLargestComponent;
using generator_internal::kJointNames;
using generator_internal::kParents;
using generator_internal::MergeIslands;
using generator_internal::Remesh;
using generator_internal::SeamCost;
using generator_internal::SegmentBody;
using generator_internal::TriangleMesh;
using generator_internal::VertexNeighbours;

// ----------------------------------------------------------------------------------------------
// Option validation.

bool Check(bool ok, const std::string& field, const std::string& expected, double found,
           std::string* error) {
  if (ok) return true;
  if (error) {
    std::ostringstream msg;
    msg << field << ": expected " << expected << ", found " << found;
    *error = msg.str();
  }
  return false;
}

bool InRange(double v, double lo, double hi) { return std::isfinite(v) && v >= lo && v <= hi; }

}  // namespace

bool BodyShapeOptions::IsValid(std::string* error) const {
  return Check(InRange(height, 1.0, 2.3), "height", "a stature in [1.0, 2.3] m", height, error) &&
         Check(InRange(girth, 0.6, 1.6), "girth", "a value in [0.6, 1.6]", girth, error) &&
         Check(InRange(shoulder_width, 0.7, 1.3), "shoulder_width", "a value in [0.7, 1.3]",
               shoulder_width, error) &&
         Check(InRange(hip_width, 0.7, 1.3), "hip_width", "a value in [0.7, 1.3]", hip_width,
               error) &&
         Check(InRange(arm_length, 0.8, 1.2), "arm_length", "a value in [0.8, 1.2]", arm_length,
               error) &&
         Check(InRange(leg_length, 0.8, 1.2), "leg_length", "a value in [0.8, 1.2]", leg_length,
               error) &&
         Check(InRange(arm_angle_deg, 0.0, 80.0), "arm_angle_deg", "an angle in [0, 80] degrees",
               arm_angle_deg, error) &&
         Check(resolution == 0 || resolution == 1, "resolution", "0 (coarse) or 1 (default)",
               resolution, error) &&
         Check(atlas_size >= 256, "atlas_size", "at least 256 texels", atlas_size, error) &&
         Check(InRange(atlas_padding_texels, 0.0, atlas_size / 8.0), "atlas_padding_texels",
               "a value in [0, atlas_size / 8]", atlas_padding_texels, error);
}

namespace {
bool CheckSections(const BodyProportions& bp, std::string* error) {
  const auto& sec = bp.torso_sections;
  if (!Check(sec.size() >= 2, "torso_sections", "at least 2 sections",
             static_cast<double>(sec.size()), error))
    return false;
  for (size_t i = 0; i < sec.size(); ++i) {
    const std::string name = "torso_sections[" + std::to_string(i) + "]";
    if (!Check(InRange(sec[i].y, 0.0, 1.0) && (i == 0 || sec[i].y > sec[i - 1].y), name + ".y",
               "heights in (0, 1) increasing with the index", sec[i].y, error) ||
        !Check(InRange(sec[i].half_width, 1e-3, 0.5), name + ".half_width",
               "a ratio in [0.001, 0.5]", sec[i].half_width, error) ||
        !Check(InRange(sec[i].half_depth, 1e-3, 0.5), name + ".half_depth",
               "a ratio in [0.001, 0.5]", sec[i].half_depth, error) ||
        !Check(InRange(sec[i].centre_z, -0.5, 0.5), name + ".centre_z", "a ratio in [-0.5, 0.5]",
               sec[i].centre_z, error))
      return false;
  }
  return Check(bp.hip_section_top < bp.shoulder_section_bottom, "hip_section_top",
               "below shoulder_section_bottom", bp.hip_section_top, error);
}
}  // namespace

bool BodyProportions::IsValid(std::string* error) const {
  const double values[] = {ankle_height,
                           hip_height,
                           hip_half_spacing,
                           thigh_length,
                           shank_length,
                           pelvis_height,
                           spine_height,
                           chest_height,
                           neck_height,
                           head_joint_height,
                           shoulder_height,
                           shoulder_half_breadth,
                           upper_arm_length,
                           forearm_length,
                           hand_length,
                           palm_fraction,
                           neck_base_radius,
                           neck_top_radius,
                           deltoid_radius,
                           upper_arm_radius_top,
                           upper_arm_radius_bottom,
                           forearm_radius_top,
                           forearm_radius_bulge,
                           forearm_bulge_fraction,
                           forearm_radius_wrist,
                           palm_half_width,
                           trapezius_radius,
                           thigh_muscle_radius,
                           thigh_muscle_fraction,
                           finger_half_width,
                           fingertip_half_width,
                           hand_flattening,
                           thumb_length,
                           thumb_radius,
                           thigh_radius_top,
                           thigh_radius_bottom,
                           shank_radius_top,
                           calf_radius,
                           calf_fraction,
                           shank_radius_ankle,
                           foot_length,
                           foot_half_width,
                           foot_half_height,
                           foot_rounding,
                           blend_trunk,
                           blend_limb_root,
                           blend_limb,
                           blend_hand,
                           neck_extension_bottom,
                           neck_extension_top,
                           torso_cap_rounding,
                           trapezius_neck_x,
                           trapezius_taper,
                           acromion_rise,
                           acromion_inset,
                           deltoid_offset,
                           forearm_bulge_length,
                           palm_start_offset,
                           thumb_base_fraction,
                           thumb_base_offset,
                           thumb_taper,
                           thigh_muscle_length,
                           calf_length,
                           calf_back_offset,
                           foot_ball_fraction,
                           heel_width};
  for (double v : values) {
    if (!(std::isfinite(v) && v > 0.0 && v < 1.0)) {
      return Check(false, "body proportions", "every ratio in (0, 1) of the stature", v, error);
    }
  }
  return Check(InRange(leg_spread_deg, 0.0, 30.0), "leg_spread_deg", "an angle in [0, 30]",
               leg_spread_deg, error) &&
         Check(InRange(thumb_angle_deg, 0.0, 90.0), "thumb_angle_deg", "an angle in [0, 90]",
               thumb_angle_deg, error) &&
         Check(InRange(instep_height, 0.1, 4.0), "instep_height", "a value in [0.1, 4]",
               instep_height, error) &&
         Check(InRange(heel_radius, 0.1, 4.0), "heel_radius", "a value in [0.1, 4]", heel_radius,
               error) &&
         Check(InRange(neck_base_z, -0.1, 0.1), "neck_base_z", "a ratio in [-0.1, 0.1]",
               neck_base_z, error) &&
         Check(InRange(trapezius_neck_z, -0.1, 0.1), "trapezius_neck_z", "a ratio in [-0.1, 0.1]",
               trapezius_neck_z, error) &&
         Check(ankle_height < hip_height && hip_height < pelvis_height &&
                   pelvis_height < spine_height && spine_height < chest_height &&
                   chest_height < neck_height && neck_height < head_joint_height &&
                   head_joint_height < 1.0,
               "body proportions", "joint heights increasing from ankle to head", head_joint_height,
               error) &&
         Check(foot_rounding < std::min(foot_half_width, foot_half_height), "foot_rounding",
               "less than the foot half width and half height", foot_rounding, error) &&
         CheckSections(*this, error) &&
         Check(buttock_semi_axes.minCoeff() > 0 && head_semi_axes.minCoeff() > 0 &&
                   jaw_semi_axes.minCoeff() > 0 && nose_semi_axes.minCoeff() > 0,
               "body proportions", "positive ellipsoid semi-axes", 0.0, error);
}

bool SkinningBands::IsValid(std::string* error) const {
  const double values[] = {spine, chest, neck, head,  shoulder,   elbow,
                           wrist, hip,   knee, ankle, neck_radius};
  for (double v : values) {
    if (!InRange(v, 1e-3, 0.2)) {
      return Check(false, "skinning bands", "half widths in [0.001, 0.2] m", v, error);
    }
  }
  return true;
}

bool MeshingOptions::IsValid(std::string* error) const {
  return Check(InRange(grid_cell, 1e-3, 0.02), "meshing.grid_cell",
               "a fraction of the stature in [0.001, 0.02]", grid_cell, error) &&
         Check(InRange(grid_cell_coarse, 1e-3, 0.02), "meshing.grid_cell_coarse",
               "a fraction of the stature in [0.001, 0.02]", grid_cell_coarse, error) &&
         Check(target_vertices_coarse >= 500 && target_vertices_coarse <= 200000,
               "meshing.target_vertices_coarse", "a count in [500, 200000]", target_vertices_coarse,
               error) &&
         Check(target_vertices_default >= 500 && target_vertices_default <= 200000,
               "meshing.target_vertices_default", "a count in [500, 200000]",
               target_vertices_default, error) &&
         Check(InRange(edge_length_factor, 0.25, 4.0), "meshing.edge_length_factor",
               "a value in [0.25, 4]", edge_length_factor, error) &&
         Check(remesh_iterations >= 1 && remesh_iterations <= 50, "meshing.remesh_iterations",
               "a count in [1, 50]", remesh_iterations, error) &&
         Check(projection_iterations >= 1 && projection_iterations <= 20,
               "meshing.projection_iterations", "a count in [1, 20]", projection_iterations,
               error) &&
         Check(InRange(min_part_component, 0.0, 1.0), "meshing.min_part_component",
               "a fraction in [0, 1]", min_part_component, error);
}

const char* const* DefaultJointNames() { return kJointNames; }

bool IsClosedManifoldSphere(int num_vertices, const Eigen::MatrixX3i& triangles,
                            std::string* error) {
  std::ostringstream msg;
  auto fail = [&]() {
    if (error) *error = msg.str();
    return false;
  };
  const int nf = static_cast<int>(triangles.rows());
  if (nf == 0 || num_vertices == 0) {
    msg << "mesh: expected a non-empty mesh";
    return fail();
  }
  if (triangles.minCoeff() < 0 || triangles.maxCoeff() >= num_vertices) {
    msg << "triangles: vertex index out of range";
    return fail();
  }
  // Directed edges must be unique and each must have its reverse.
  std::unordered_map<int64_t, int> directed;
  directed.reserve(3 * nf);
  const int64_t n = num_vertices;
  for (int f = 0; f < nf; ++f) {
    for (int q = 0; q < 3; ++q) {
      const int64_t a = triangles(f, q), b = triangles(f, (q + 1) % 3);
      if (a == b) {
        msg << "triangle " << f << ": repeated vertex " << a;
        return fail();
      }
      if (!directed.emplace(a * n + b, f).second) {
        msg << "edge (" << a << ", " << b << "): used twice in the same direction "
            << "(non-manifold or inconsistently oriented), triangle " << f;
        return fail();
      }
    }
  }
  for (const auto& [key, f] : directed) {
    const int64_t a = key / n, b = key % n;
    if (!directed.count(b * n + a)) {
      msg << "edge (" << a << ", " << b << "): expected two triangles, found one (triangle " << f
          << ")";
      return fail();
    }
  }
  // Vertex links: for each vertex, the map next[b] = c over its triangles (v, b, c) must be a
  // single cycle.
  std::vector<std::vector<std::pair<int, int>>> link(num_vertices);
  for (int f = 0; f < nf; ++f) {
    for (int q = 0; q < 3; ++q) {
      link[triangles(f, q)].emplace_back(triangles(f, (q + 1) % 3), triangles(f, (q + 2) % 3));
    }
  }
  for (int v = 0; v < num_vertices; ++v) {
    if (link[v].empty()) {
      msg << "vertex " << v << ": not used by any triangle";
      return fail();
    }
    std::unordered_map<int, int> next(link[v].begin(), link[v].end());
    int steps = 0;
    int x = link[v][0].first;
    do {
      x = next[x];
      ++steps;
    } while (x != link[v][0].first && steps <= static_cast<int>(link[v].size()));
    if (steps != static_cast<int>(link[v].size())) {
      msg << "vertex " << v << ": its triangles do not form a single fan (non-manifold vertex)";
      return fail();
    }
  }
  // One component, Euler characteristic 2.
  std::vector<int> parent(num_vertices);
  std::iota(parent.begin(), parent.end(), 0);
  auto find = [&](int x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  };
  for (int f = 0; f < nf; ++f) {
    parent[find(triangles(f, 0))] = find(triangles(f, 1));
    parent[find(triangles(f, 1))] = find(triangles(f, 2));
  }
  int components = 0;
  for (int v = 0; v < num_vertices; ++v) components += find(v) == v;
  if (components != 1) {
    msg << "mesh: expected one connected component, found " << components;
    return fail();
  }
  const int64_t edges = static_cast<int64_t>(directed.size()) / 2;
  const int64_t euler = num_vertices - edges + nf;
  if (euler != 2) {
    msg << "mesh: expected Euler characteristic 2 (a sphere), found " << euler;
    return fail();
  }
  return true;
}

Template GenerateTemplate(const BodyShapeOptions& options) {
  return GenerateTemplate(options, TemplateGeneratorOptions(), nullptr);
}

Template GenerateTemplate(const BodyShapeOptions& options,
                          const TemplateGeneratorOptions& generator,
                          TemplateGeneratorSummary* summary) {
  std::string error;
  if (!options.IsValid(&error)) throw Error("body shape options: " + error);
  if (!generator.proportions.IsValid(&error)) throw Error("body proportions: " + error);
  if (!generator.bands.IsValid(&error)) throw Error("skinning bands: " + error);
  if (!generator.meshing.IsValid(&error)) throw Error("meshing options: " + error);
  UvAtlasOptions atlas_options = generator.atlas;
  atlas_options.atlas_size = options.atlas_size;
  atlas_options.padding_texels = options.atlas_padding_texels;
  if (!atlas_options.IsValid(&error)) throw Error("uv atlas options: " + error);

  TemplateGeneratorSummary local_summary;
  TemplateGeneratorSummary& sum = summary ? *summary : local_summary;
  sum = TemplateGeneratorSummary();
  using Clock = std::chrono::steady_clock;
  auto seconds_since = [](Clock::time_point t0) {
    return std::chrono::duration<double>(Clock::now() - t0).count();
  };

  const MeshingOptions& meshing = generator.meshing;
  const double cell =
      (options.resolution == 0 ? meshing.grid_cell_coarse : meshing.grid_cell) * options.height;
  auto t0 = Clock::now();
  const Body body = BuildBody(options, generator.proportions, cell);
  TriangleMesh iso = ExtractIsoSurface(body, cell);
  sum.removed_components = KeepLargestComponent(&iso);
  sum.grid_vertices = static_cast<int>(iso.vertices.size());
  sum.seconds_field = seconds_since(t0);

  // Target edge length from the surface area: an ideal mesh of equilateral triangles with
  // F = 2V has area 2V * sqrt(3)/4 * L^2.
  t0 = Clock::now();
  double area = 0.0;
  for (const auto& t : iso.triangles) {
    area += 0.5 * FaceNormal(iso.vertices[t[0]], iso.vertices[t[1]], iso.vertices[t[2]]).norm();
  }
  const int target_vertices =
      options.resolution == 0 ? meshing.target_vertices_coarse : meshing.target_vertices_default;
  const double edge_length =
      meshing.edge_length_factor * std::sqrt(2.0 * area / (std::sqrt(3.0) * target_vertices));
  sum.target_edge_length = edge_length;
  const TriangleMesh mesh = Remesh(body, iso, edge_length, meshing);
  sum.seconds_remesh = seconds_since(t0);

  Template tmpl;
  const int nv = static_cast<int>(mesh.vertices.size());
  const int nf = static_cast<int>(mesh.triangles.size());
  tmpl.vertices.resize(nv, 3);
  for (int v = 0; v < nv; ++v) tmpl.vertices.row(v) = mesh.vertices[v].transpose();
  tmpl.triangles.resize(nf, 3);
  for (int f = 0; f < nf; ++f) {
    tmpl.triangles.row(f) =
        Eigen::RowVector3i(mesh.triangles[f][0], mesh.triangles[f][1], mesh.triangles[f][2]);
  }
  if (!IsClosedManifoldSphere(nv, tmpl.triangles, &error)) {
    throw Error("template generator: the generated surface is not a closed 2-manifold sphere: " +
                error);
  }
  double volume = 0.0;
  area = 0.0;
  for (int f = 0; f < nf; ++f) {
    const Eigen::Vector3d a = tmpl.vertices.row(tmpl.triangles(f, 0)).transpose();
    const Eigen::Vector3d b = tmpl.vertices.row(tmpl.triangles(f, 1)).transpose();
    const Eigen::Vector3d c = tmpl.vertices.row(tmpl.triangles(f, 2)).transpose();
    volume += a.dot(b.cross(c)) / 6.0;
    area += 0.5 * (b - a).cross(c - a).norm();
  }
  sum.surface_area = area;
  sum.volume = volume;
  if (!(volume > 0.0)) {
    throw Error("template generator: the generated surface is not oriented outwards (volume " +
                std::to_string(volume) + ")");
  }

  // Joints.
  tmpl.joints.resize(kDefaultNumJoints);
  for (int j = 0; j < kDefaultNumJoints; ++j) {
    tmpl.joints[j].name = kJointNames[j];
    tmpl.joints[j].parent = kParents[j];
    tmpl.joints[j].center = body.centre[j];
    tmpl.joints[j].twist_axis = body.axis[j].normalized();
  }

  // Segmentation and skinning constants.
  t0 = Clock::now();
  const auto adj = VertexNeighbours(nv, tmpl.triangles);
  std::vector<int> joint = SegmentBody(body, generator.bands, tmpl.vertices);
  for (int round = 0; round < 16; ++round) {
    const int a = MergeIslands(adj, &joint);
    const int b = FixSegmentAdjacency(adj, &joint);
    sum.relabelled_vertices += a + b;
    if (a == 0 && b == 0) break;
  }
  Eigen::VectorXd w_l, tau;
  ComputeSkinningConstants(body, generator.bands, tmpl.vertices, adj, joint, &w_l, &tau);
  tmpl.vertex_joint = Eigen::Map<Eigen::VectorXi>(joint.data(), nv);
  tmpl.lbs_weight = w_l;
  tmpl.slerp_tau = tau;
  sum.seconds_skinning = seconds_since(t0);

  // UV atlas.
  t0 = Clock::now();
  if (!generator.build_atlas) {
    if (!tmpl.IsValid(&error)) throw Error("template generator: invalid result: " + error);
    return tmpl;
  }
  tmpl.triangle_chart = AssignCharts(body, tmpl.vertices, tmpl.triangles, joint);
  UvAtlas atlas;
  BuildUvAtlas(tmpl.vertices, tmpl.triangles, tmpl.triangle_chart,
               SeamCost(body, tmpl.vertices, joint), atlas_options, &atlas, &sum.atlas);
  tmpl.uvs = atlas.uvs;
  tmpl.uv_triangles = atlas.uv_triangles;
  sum.seconds_atlas = seconds_since(t0);

  if (!tmpl.IsValid(&error)) throw Error("template generator: invalid result: " + error);
  return tmpl;
}

}  // namespace artex
