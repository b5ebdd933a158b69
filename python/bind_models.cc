// Python bindings of models/: Template, Joint, Pose, Skinning (with its Jacobian), the template
// generator and the .glb reader/writers.
#include <pybind11/eigen.h>
#include <pybind11/stl.h>

#include <cstring>

#include "models/error.h"
#include "models/normals.h"
#include "models/pose.h"
#include "models/skinning.h"
#include "models/template.h"
#include "models/template_cache.h"
#include "models/template_generator.h"
#include "models/template_io.h"
#include "models/textured_mesh_export.h"
#include "python/bind_common.h"
#include "sensors/image_codec.h"

namespace artex::python {
namespace {

// RGB array -> GlbTexture (row 0 at v = 0, as glTF and the atlas images).
GlbTexture TextureFromNumpy(const py::array& rgb) {
  auto a = py::array_t<uint8_t, py::array::c_style | py::array::forcecast>::ensure(rgb);
  if (!a || a.ndim() != 3 || a.shape(2) != 3) {
    throw Error("texture: expected an H x W x 3 uint8 RGB array");
  }
  GlbTexture t;
  t.height = static_cast<int>(a.shape(0));
  t.width = static_cast<int>(a.shape(1));
  t.rgb.assign(a.data(), a.data() + a.size());
  return t;
}

py::object TextureToNumpy(const GlbTexture& texture) {
  if (texture.png.empty()) return py::none();
  cv::Mat bgr;
  std::string error;
  if (!DecodeImage(texture.png.data(), texture.png.size(), ImageRead::kColor, &bgr, &error)) {
    throw Error("glb texture: the embedded PNG does not decode (" + error + ")");
  }
  return ImageToNumpy(bgr);
}

}  // namespace

void BindModels(py::module_& m) {
  py::class_<Joint>(m, "Joint", "One joint of the template's tree (rest frame, metres).")
      .def(py::init<>())
      .def_readwrite("name", &Joint::name)
      .def_readwrite("parent", &Joint::parent, "parent joint index, -1 for the root")
      .def_readwrite("center", &Joint::center, "joint centre t_i (3,)")
      .def_readwrite("twist_axis", &Joint::twist_axis, "unit twist axis a_i (3,)")
      .def("__repr__", [](const Joint& j) {
        return "<artex.Joint " + j.name + " parent=" + std::to_string(j.parent) + ">";
      });

  py::class_<Template>(m, "Template",
                       "The rigged template: mesh, per-corner UVs, joint tree and per-vertex\n"
                       "skinning constants (joint k, LBS weight w_l, SLERP parameter tau).\n"
                       "Y up, facing +Z, metres. Array attributes are copies: assign a whole\n"
                       "array to change one (t.vertices = v), not an element in place.")
      .def(py::init<>())
      .def_readwrite("vertices", &Template::vertices, "V x 3 rest positions (m)")
      .def_readwrite("triangles", &Template::triangles, "F x 3 vertex indices, CCW outwards")
      .def_readwrite("uvs", &Template::uvs, "U x 2 atlas coordinates (v downwards)")
      .def_readwrite("uv_triangles", &Template::uv_triangles, "F x 3 indices into uvs")
      .def_readwrite("triangle_chart", &Template::triangle_chart, "F: UV chart of each triangle")
      .def_readwrite("joints", &Template::joints, "list of Joint, parents first")
      .def_readwrite("vertex_joint", &Template::vertex_joint, "V: joint k of each vertex")
      .def_readwrite("lbs_weight", &Template::lbs_weight, "V: LBS weight w_l in [0, 1]")
      .def_readwrite("slerp_tau", &Template::slerp_tau, "V: twist SLERP parameter tau in [0, 1]")
      .def_property_readonly("num_vertices", &Template::num_vertices)
      .def_property_readonly("num_triangles", &Template::num_triangles)
      .def_property_readonly("num_joints", &Template::num_joints)
      .def_property_readonly("num_pose_parameters", &Template::num_pose_parameters)
      .def_property_readonly("has_uvs", &Template::has_uvs)
      .def_property_readonly(
          "joint_names",
          [](const Template& t) {
            std::vector<std::string> names;
            for (const auto& j : t.joints) names.push_back(j.name);
            return names;
          },
          "joint names in index order")
      .def_property_readonly(
          "joint_centers",
          [](const Template& t) {
            Eigen::MatrixX3d c(t.num_joints(), 3);
            for (int j = 0; j < t.num_joints(); ++j) c.row(j) = t.joints[j].center.transpose();
            return c;
          },
          "J x 3 rest joint centres (m)")
      .def("find_joint", &Template::FindJoint, py::arg("name"), "joint index, -1 when absent")
      .def("chain", &Template::Chain, py::arg("joint"), "joint indices from the root to joint")
      .def(
          "validate",
          [](const Template& t) {
            std::string why;
            if (!t.IsValid(&why)) throw Error("template: " + why);
          },
          "raises artex.Error describing the first problem (shapes, ranges, joint order)")
      .def("__repr__", [](const Template& t) {
        return "<artex.Template " + std::to_string(t.num_vertices()) + " vertices, " +
               std::to_string(t.num_triangles()) + " triangles, " + std::to_string(t.num_joints()) +
               " joints>";
      });

  m.def(
      "generate_template",
      [](double height, double girth, double shoulder_width, double hip_width, double arm_length,
         double leg_length, double arm_angle_deg, int resolution, int atlas_size) {
        BodyShapeOptions o;
        o.height = height;
        o.girth = girth;
        o.shoulder_width = shoulder_width;
        o.hip_width = hip_width;
        o.arm_length = arm_length;
        o.leg_length = leg_length;
        o.arm_angle_deg = arm_angle_deg;
        o.resolution = resolution;
        o.atlas_size = atlas_size;
        return GenerateTemplate(o);
      },
      py::arg("height") = BodyShapeOptions().height, py::arg("girth") = BodyShapeOptions().girth,
      py::arg("shoulder_width") = BodyShapeOptions().shoulder_width,
      py::arg("hip_width") = BodyShapeOptions().hip_width,
      py::arg("arm_length") = BodyShapeOptions().arm_length,
      py::arg("leg_length") = BodyShapeOptions().leg_length,
      py::arg("arm_angle_deg") = BodyShapeOptions().arm_angle_deg,
      py::arg("resolution") = BodyShapeOptions().resolution,
      py::arg("atlas_size") = BodyShapeOptions().atlas_size,
      py::call_guard<py::gil_scoped_release>(),
      "The generated human template (A-pose, 17 joints). resolution 0: ~3k vertices (fast),\n"
      "1: ~12.5k (the tracking default). Parameters as `artex template generate`.");

  m.def(
      "default_template",
      [](bool cache, const std::string& cache_dir) {
        TemplateCacheOptions o;
        o.enabled = cache;
        o.directory = cache_dir;
        std::string note;
        Template t = DefaultTemplate(o, &note);
        if (!note.empty()) {
          py::gil_scoped_acquire gil;
          PyErr_WarnEx(PyExc_RuntimeWarning, note.c_str(), 1);
        }
        return t;
      },
      py::arg("cache") = true, py::arg("cache_dir") = "",
      py::call_guard<py::gil_scoped_release>(),
      "generate_template() with its defaults (the tracker's default template), bit for bit, read\n"
      "from this build's cache when it wrote it there (docs/template.md, \"The default template's\n"
      "cache\"); cache_dir \"\": $ARTEX_CACHE_DIR, $XDG_CACHE_HOME/artex or ~/.cache/artex.");

  m.def(
      "read_glb",
      [](const std::string& path) {
        GlbTexture texture;
        Template t = ReadTemplateGlb(path, &texture);
        return py::make_tuple(t, TextureToNumpy(texture));
      },
      py::arg("path"),
      "Reads an artex .glb (template, subject.glb, tracked.glb): (Template, texture) with the\n"
      "texture an H x W x 3 RGB array or None.");
  m.def(
      "write_glb",
      [](const std::string& path, const Template& t, const py::object& texture) {
        if (texture.is_none()) return WriteTemplateGlb(path, t);
        GlbTexture g = TextureFromNumpy(texture.cast<py::array>());
        WriteTemplateGlb(path, t, &g);
      },
      py::arg("path"), py::arg("template"), py::arg("texture") = py::none(),
      "Writes a skinned glTF binary (exact artex attributes; optional RGB texture).");
  m.def(
      "write_animated_glb",
      [](const std::string& path, const Template& t, const std::vector<Pose>& poses,
         double frame_rate, const py::object& texture, bool exact) {
        AnimatedGlbOptions options;
        options.exact = exact;
        AnimatedGlbSummary s;
        GlbTexture g;
        if (!texture.is_none()) g = TextureFromNumpy(texture.cast<py::array>());
        WriteAnimatedGlb(path, t, poses, frame_rate, texture.is_none() ? nullptr : &g, options, &s);
        py::dict d;
        d["frames"] = s.frames;
        d["morph_targets"] = s.morph_targets;
        d["lbs_max_residual_mm"] = s.lbs_max_residual_mm;
        d["lbs_mean_residual_mm"] = s.lbs_mean_residual_mm;
        d["max_residual_mm"] = s.exact_max_residual_mm;
        d["mean_residual_mm"] = s.exact_mean_residual_mm;
        d["bytes"] = s.bytes;
        return d;
      },
      py::arg("path"), py::arg("template"), py::arg("poses"), py::arg("frame_rate"),
      py::arg("texture") = py::none(), py::arg("exact") = true,
      "Writes a .glb with one keyframe per pose; exact: per-frame corrective morph targets so\n"
      "that glTF viewers reproduce artex's LBS+SLERP skinning. Returns the residuals (mm).");
  m.def(
      "write_textured_mesh",
      [](const std::string& path, const Template& t, const Eigen::MatrixX3d& posed,
         const std::string& texture_file, const std::string& up) {
        TexturedMeshOptions o;
        o.texture_file = texture_file;
        auto it = UpAxisNames().find(up);
        if (it == UpAxisNames().end()) throw Error("up: expected 'y' or 'z', found '" + up + "'");
        o.up = it->second;
        WriteTexturedMesh(path, t, posed, o);
      },
      py::arg("path"), py::arg("template"), py::arg("posed_vertices"), py::arg("texture_file") = "",
      py::arg("up") = "y",
      "Writes posed vertices with the template's UVs as .obj (+ .mtl) or .ply; up: 'y' or 'z'.");

  py::class_<Pose>(m, "Pose",
                   "Pose parameters: global scale, translation (m), rotation (3 x 3) and one\n"
                   "rotation per joint. Tangent layout of every Jacobian (P = 7 + 3 J):\n"
                   "[ds, dt(3), w0(3), w_1(3) ... w_J(3)], rotations updated R <- Exp(w) R.")
      .def(py::init([](int num_joints) { return Pose::Identity(num_joints); }),
           py::arg("num_joints") = 17, "the identity (rest) pose")
      .def_readwrite("scale", &Pose::scale)
      .def_readwrite("translation", &Pose::translation, "(3,) metres")
      .def_readwrite("rotation", &Pose::rotation, "3 x 3 global rotation R0")
      .def_readwrite("joint_rotations", &Pose::joint_rotations, "list of 3 x 3 rotations R_j")
      .def_property_readonly("num_joints", &Pose::num_joints)
      .def_property_readonly("num_parameters", &Pose::num_parameters)
      .def("retracted", &Pose::Retracted, py::arg("delta"), "pose (+) delta (a new Pose)")
      .def("retract", &Pose::Retract, py::arg("delta"), "in place: pose <- pose (+) delta")
      .def("local_coordinates", &Pose::LocalCoordinates, py::arg("other"),
           "tangent d with self.retracted(d) == other")
      .def("to_vector", &Pose::ToVector,
           "flat [s, t(3), r0(3), r_1(3) ...] with rotation vectors (poses.csv layout)")
      .def_static(
          "from_vector",
          [](const Eigen::VectorXd& v, int num_joints) {
            return Pose::FromVector(v, num_joints, "pose vector");
          },
          py::arg("vector"), py::arg("num_joints") = 17)
      .def("__repr__", [](const Pose& p) {
        return "<artex.Pose scale=" + std::to_string(p.scale) + ", " +
               std::to_string(p.num_joints()) + " joints>";
      });

  py::class_<Skinning>(m, "Skinning",
                       "S(v; theta): LBS of the swing and SLERP of the twist per joint, the\n"
                       "global similarity on top; analytic Jacobian w.r.t. the pose tangent.")
      .def(py::init([](const Template& t, bool parallel) {
             SkinningOptions o;
             o.parallel = parallel;
             return std::make_unique<Skinning>(t, o);
           }),
           py::arg("template"), py::arg("parallel") = true)
      .def_property_readonly("template", &Skinning::model)
      .def(
          "apply",
          [](const Skinning& s, const Pose& pose) {
            Eigen::MatrixX3d posed;
            s.Apply(pose, &posed);
            return posed;
          },
          py::arg("pose"), py::call_guard<py::gil_scoped_release>(), "V x 3 posed vertices")
      .def(
          "apply_with_jacobian",
          [](const Skinning& s, const Pose& pose) {
            Eigen::MatrixX3d posed;
            SkinningJacobian jac;
            Eigen::MatrixXd dense;
            {
              py::gil_scoped_release release;
              s.ApplyWithJacobian(pose, &posed, &jac);
              dense = jac.ToDense();
            }
            return py::make_tuple(posed, dense);
          },
          py::arg("pose"),
          "(V x 3 posed vertices, 3V x P dense Jacobian; rows 3v..3v+2 belong to vertex v)")
      .def(
          "posed_joint_centers",
          [](const Skinning& s, const Pose& pose) {
            Eigen::MatrixX3d c;
            s.PosedJointCenters(pose, &c);
            return c;
          },
          py::arg("pose"), "J x 3 posed joint centres");

  m.def(
      "vertex_normals",
      [](const Eigen::MatrixX3d& vertices, const Eigen::MatrixX3i& triangles) {
        Eigen::MatrixX3d n;
        ComputeVertexNormals(vertices, triangles, &n);
        return n;
      },
      py::arg("vertices"), py::arg("triangles"), "V x 3 unit vertex normals of a mesh");
}

}  // namespace artex::python
