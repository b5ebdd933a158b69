// Python bindings of sensors/ and render/camera.h: cameras and calibration, frames, recording
// readers (artex sequence with ground truth, TUM RGB-D, Matroska), scans, the preprocessor and
// synthetic sequence generation.
#include <pybind11/eigen.h>
#include <pybind11/stl.h>

#include "experiments/runner.h"
#include "models/error.h"
#include "python/bind_common.h"
#include "render/camera.h"
#include "sensors/bvh.h"
#include "sensors/bvh_export.h"
#include "sensors/calibration.h"
#include "sensors/frame_source.h"
#include "sensors/preprocess.h"
#include "sensors/scan.h"
#include "sensors/sequence.h"

namespace artex::python {
namespace {

Eigen::Matrix4d IsometryToMatrix(const Eigen::Isometry3d& t) { return t.matrix(); }

Eigen::Isometry3d MatrixToIsometry(const Eigen::Matrix4d& m) {
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.linear() = m.topLeftCorner<3, 3>();
  t.translation() = m.topRightCorner<3, 1>();
  return t;
}

py::dict StatsToDict(const PreprocessStats& s) {
  py::dict d;
  d["valid_depth_pixels"] = s.valid_depth_pixels;
  d["foreground_pixels"] = s.foreground_pixels;
  d["mesh_vertices"] = s.mesh.vertices;
  d["mesh_triangles"] = s.mesh.triangles;
  d["color_invalid"] = s.color_invalid;
  d["total_seconds"] = s.total_seconds;
  return d;
}

}  // namespace

void BindSensors(py::module_& m) {
  py::class_<PinholeCamera>(m, "PinholeCamera", "Pinhole intrinsics and the world -> camera pose.")
      .def(py::init<>())
      .def_readwrite("width", &PinholeCamera::width)
      .def_readwrite("height", &PinholeCamera::height)
      .def_readwrite("fx", &PinholeCamera::fx)
      .def_readwrite("fy", &PinholeCamera::fy)
      .def_readwrite("cx", &PinholeCamera::cx)
      .def_readwrite("cy", &PinholeCamera::cy)
      .def_property(
          "world_to_camera",
          [](const PinholeCamera& c) { return IsometryToMatrix(c.world_to_camera); },
          [](PinholeCamera& c, const Eigen::Matrix4d& m) {
            c.world_to_camera = MatrixToIsometry(m);
          },
          "4 x 4 rigid transform, x_camera = T x_world")
      .def(
          "project",
          [](const PinholeCamera& c, const Eigen::Vector3d& world) {
            double z = 0;
            Eigen::Vector2d uv = c.Project(world, &z);
            return py::make_tuple(uv, z);
          },
          py::arg("world"), "((u, v) pixel, camera depth z in m)")
      .def("unproject", &PinholeCamera::Unproject, py::arg("u"), py::arg("v"), py::arg("depth"))
      .def("center", &PinholeCamera::Center, "camera centre (world)");

  py::class_<Calibration>(m, "Calibration", "Depth and colour cameras of an RGB-D rig.")
      .def(py::init<>())
      .def_readwrite("depth", &Calibration::depth)
      .def_readwrite("color", &Calibration::color)
      .def_readwrite("depth_scale", &Calibration::depth_scale, "16-bit depth units per metre")
      .def_readwrite("frame_rate", &Calibration::frame_rate, "Hz")
      .def_property_readonly("depth_to_color", [](const Calibration& c) {
        return IsometryToMatrix(c.DepthToColor());
      });
  m.def("read_calibration", &ReadCalibration, py::arg("path"), "reads calibration.yaml");

  py::class_<Frame>(m, "Frame", "One RGB-D frame: depth H x W uint16 (0 = missing), colour RGB.")
      .def(py::init<>())
      .def_readwrite("index", &Frame::index)
      .def_readwrite("depth_timestamp", &Frame::depth_timestamp)
      .def_readwrite("color_timestamp", &Frame::color_timestamp)
      .def_property(
          "depth", [](const Frame& f) { return ImageToNumpy(f.depth); },
          [](Frame& f, const py::array& a) { f.depth = DepthFromNumpy(a, "Frame.depth"); })
      .def_property(
          "color", [](const Frame& f) { return ImageToNumpy(f.color); },
          [](Frame& f, const py::array& a) { f.color = RgbFromNumpy(a, "Frame.color"); });

  py::class_<FrameSource>(m, "FrameSource",
                          "A recording: artex sequence, TUM RGB-D folder or Matroska file.")
      .def_property_readonly("calibration", &FrameSource::calibration)
      .def_property_readonly("num_frames", &FrameSource::num_frames)
      .def("__len__", &FrameSource::num_frames)
      .def(
          "read_frame",
          [](FrameSource& s, int i) {
            if (i < 0 || i >= s.num_frames()) {
              throw py::index_error("frame " + std::to_string(i) + " out of range [0, " +
                                    std::to_string(s.num_frames()) + ")");
            }
            Frame f;
            std::string warning;
            if (!s.ReadFrame(i, &f, &warning))
              throw Error("frame " + std::to_string(i) + ": " + warning);
            return f;
          },
          py::arg("index"), "Frame i (raises artex.Error when unusable)")
      .def(
          "background_frames",
          [](FrameSource& s) {
            std::vector<py::array> out;
            for (const cv::Mat& d : s.ReadBackgroundFrames()) out.push_back(ImageToNumpy(d));
            return out;
          },
          "empty-scene depth frames (list of H x W uint16)")
      .def_property_readonly("gravity", &FrameSource::gravity, "up direction (camera) or None")
      .def("description", &FrameSource::Description);

  py::class_<SequenceReader, FrameSource>(
      m, "SequenceReader", "An artex sequence folder (docs/formats.md), with ground truth.")
      .def(py::init<const std::string&>(), py::arg("folder"))
      .def_property_readonly("has_ground_truth", &SequenceReader::has_ground_truth)
      .def_property_readonly("folder", &SequenceReader::folder)
      .def(
          "read_ground_truth",
          [](const SequenceReader& s, int i) {
            GroundTruthFrame g = s.ReadGroundTruth(i);
            return py::make_tuple(g.pose, g.vertices);
          },
          py::arg("index"), "(Pose, V x 3 posed subject vertices in m) of frame i")
      .def_property_readonly("ground_truth_texture_path", &SequenceReader::GroundTruthTexturePath)
      .def_property_readonly("ground_truth_subject_path", &SequenceReader::GroundTruthSubjectPath);

  m.def(
      "open_recording",
      [](const std::string& path, const py::object& config) {
        return OpenFrameSource(path, PipelineOptionsFromPython(config).input);
      },
      py::arg("path"), py::arg("config") = py::none(),
      "Opens any recording by its layout (config: the `input` section applies).");

  py::class_<Scan>(m, "Scan",
                   "A preprocessed frame: foreground depth mesh in world coordinates (points,\n"
                   "normals towards the camera, RGB colours in [0, 1], triangles).")
      .def(py::init<>())
      .def(py::init([](const Eigen::MatrixX3d& points, const Eigen::MatrixX3d& normals,
                       const py::object& colors) {
             Scan s;
             s.points = points;
             s.normals = normals;
             if (normals.rows() != points.rows()) throw Error("Scan: normals must match points");
             if (colors.is_none()) {
               s.colors = Eigen::MatrixX3d::Constant(points.rows(), 3, 0.5);
               s.color_valid.assign(points.rows(), 0);
             } else {
               s.colors = colors.cast<Eigen::MatrixX3d>();
               if (s.colors.rows() != points.rows()) throw Error("Scan: colors must match points");
               s.color_valid.assign(points.rows(), 1);
             }
             return s;
           }),
           py::arg("points"), py::arg("normals"), py::arg("colors") = py::none())
      .def_readwrite("points", &Scan::points)
      .def_readwrite("normals", &Scan::normals)
      .def_readwrite("colors", &Scan::colors)
      .def_readwrite("color_valid", &Scan::color_valid)
      .def_readwrite("triangles", &Scan::triangles)
      .def("__len__", &Scan::size);

  py::class_<Preprocessor>(m, "Preprocessor",
                           "Background subtraction or subject segmentation, depth mesh, colours.")
      .def(py::init([](const Calibration& c, const py::object& config) {
             return std::make_unique<Preprocessor>(c, PipelineOptionsFromPython(config).preprocess);
           }),
           py::arg("calibration"), py::arg("config") = py::none(),
           "config: None or a dict/YAML with a `preprocess` section (configs/default.yaml)")
      .def(
          "train",
          [](Preprocessor& p, const std::vector<py::array>& depth) {
            std::vector<cv::Mat> mats;
            for (const auto& d : depth) mats.push_back(DepthFromNumpy(d, "background depth"));
            p.Train(mats);
          },
          py::arg("background_depth"), "trains the background model on empty-scene depth frames")
      .def("train_without_background", &Preprocessor::TrainWithoutBackground)
      .def_property_readonly("trained", &Preprocessor::trained)
      .def(
          "process",
          [](Preprocessor& p, const Frame& f) {
            Scan scan;
            PreprocessStats stats;
            {
              py::gil_scoped_release release;
              p.Process(f, &scan, &stats);
            }
            return py::make_tuple(scan, StatsToDict(stats));
          },
          py::arg("frame"), "(Scan, stats dict) of one frame")
      .def_property_readonly("foreground_mask", [](const Preprocessor& p) {
        return ImageToNumpy(p.foreground_mask());
      });

  m.def(
      "write_bvh",
      [](const std::string& path, const Template& t, const std::vector<Pose>& poses,
         double frame_rate, double units_per_metre) {
        BvhExportOptions o;
        o.units_per_metre = units_per_metre;
        WriteBvh(path, t, poses, frame_rate, o);
      },
      py::arg("path"), py::arg("template"), py::arg("poses"), py::arg("frame_rate"),
      py::arg("units_per_metre") = BvhExportOptions().units_per_metre,
      "Writes the poses as a BVH motion over the template's joint tree (centimetres).");
  m.def(
      "read_bvh_joint_positions",
      [](const std::string& path) {
        const BvhClip clip = ReadBvh(path);
        py::dict out;
        std::vector<std::string> names;
        for (const auto& j : clip.joints) names.push_back(j.name);
        std::vector<Eigen::MatrixX3d> frames;
        for (int f = 0; f < clip.num_frames(); ++f) {
          std::vector<Eigen::Matrix3d> rotations;
          Eigen::MatrixX3d positions;
          BvhForwardKinematics(clip, BvhFrameAt(clip, f), &rotations, &positions);
          frames.push_back(positions);
        }
        out["names"] = names;
        out["frame_time"] = clip.frame_time;
        out["positions"] = frames;
        return out;
      },
      py::arg("path"),
      "A BVH file's joints (names incl. End Sites) and their world positions per frame (BVH "
      "units).");

  m.def(
      "synthesize_sequence",
      [](const std::string& out_dir, const py::object& spec) {
        const std::string yaml = ConfigFromPython(spec, "<python synth spec>").ToYaml();
        py::gil_scoped_release release;
        GenerateSyntheticSequence(yaml, "<python synth spec>", out_dir);
      },
      py::arg("out_dir"), py::arg("spec") = py::none(),
      "Renders a synthetic sequence with ground truth into out_dir (must not exist) from a\n"
      "`synth:` spec (dict, keys as in experiment files: motion, frames, seed, noise, ...).");
}

}  // namespace artex::python
