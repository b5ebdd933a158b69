// Python bindings of the EM fitter (solvers/em_fitter.h) with its per-frame FitSummary and of
// the on-the-fly texturer (texture/texturer.h).
#include <pybind11/eigen.h>
#include <pybind11/stl.h>

#include "models/error.h"
#include "python/bind_common.h"
#include "solvers/em_fitter.h"
#include "texture/texturer.h"

namespace artex::python {
namespace {

py::dict IterationToDict(const EMIterationInfo& it) {
  py::dict d;
  d["frame"] = it.frame;
  d["iteration"] = it.iteration;
  d["stage"] = it.stage;
  d["radius"] = it.radius;
  d["cost"] = it.cost;
  d["max_update"] = it.max_update;
  d["total_weight"] = it.total_weight;
  d["num_pairs"] = it.num_pairs;
  d["scale"] = it.scale;
  d["stage_converged"] = it.stage_converged;
  d["converged"] = it.converged;
  return d;
}

py::dict TextureSummaryToDict(const TextureFrameSummary& s) {
  py::dict d;
  d["frame"] = s.frame;
  d["image_added"] = s.image_added;
  d["energy"] = s.energy;
  d["lower_bound"] = s.lower_bound;
  d["mrf_iterations"] = s.mrf_iterations;
  d["pool_size"] = s.pool_size;
  d["pool_bytes"] = s.pool_bytes;
  d["seam_edges"] = s.seam_edges;
  d["changed_triangles"] = s.changed_triangles;
  d["textured_triangles"] = s.textured_triangles;
  d["seam_rms_before"] = s.seam_rms_before;
  d["seam_rms_after"] = s.seam_rms_after;
  d["seconds_total"] = s.seconds_total;
  return d;
}

}  // namespace

void BindSolvers(py::module_& m) {
  py::class_<FitSummary>(m, "FitSummary", "What the EM fit of one frame did (str(): one line).")
      .def_readonly("frame", &FitSummary::frame)
      .def_readonly("iterations", &FitSummary::iterations)
      .def_readonly("initial_cost", &FitSummary::initial_cost)
      .def_readonly("final_cost", &FitSummary::final_cost)
      .def_property_readonly(
          "termination", [](const FitSummary& s) { return FrameTerminationName(s.termination); },
          "'converged', 'max_iterations' or 'failed'")
      .def_readonly("too_few_points", &FitSummary::too_few_points)
      .def_readonly("non_finite", &FitSummary::non_finite)
      .def_readonly("diverged", &FitSummary::diverged)
      .def_property_readonly("ok", &FitSummary::ok)
      .def_readonly("num_scan_points", &FitSummary::num_scan_points)
      .def_readonly("scale", &FitSummary::scale)
      .def_readonly("mean_motion", &FitSummary::mean_motion, "m from the initial guess")
      .def_readonly("icp_seconds", &FitSummary::icp_seconds)
      .def_readonly("estep_seconds", &FitSummary::estep_seconds)
      .def_readonly("mstep_seconds", &FitSummary::mstep_seconds)
      .def_readonly("skinning_seconds", &FitSummary::skinning_seconds)
      .def_readonly("total_seconds", &FitSummary::total_seconds)
      .def_property_readonly(
          "trace",
          [](const FitSummary& s) {
            py::list out;
            for (const auto& it : s.trace) out.append(IterationToDict(it));
            return out;
          },
          "one dict per EM iteration (cost, radius, max_update, ...)")
      .def("brief_report", &FitSummary::BriefReport)
      .def("__str__", &FitSummary::BriefReport)
      .def("__repr__",
           [](const FitSummary& s) { return "<artex.FitSummary " + s.BriefReport() + ">"; });

  py::class_<EMFitter>(m, "EMFitter",
                       "EM fitting of the template to one scan per frame (one-to-many\n"
                       "correspondences, Gauss-Newton M-step, priors). Frame by frame:\n"
                       "summary = fitter.fit_frame(scan); fitter.pose is the result.")
      .def(py::init([](const Template& t, const py::object& config) {
             return std::make_unique<EMFitter>(t, PipelineOptionsFromPython(config).fitting);
           }),
           py::arg("template"), py::arg("config") = py::none(),
           "config: None (defaults) or a dict/YAML with a `fitting` section")
      .def("fit_frame", &EMFitter::FitFrame, py::arg("scan"),
           py::call_guard<py::gil_scoped_release>(), "fits the next frame: FitSummary")
      .def_property_readonly(
          "pose", [](const EMFitter& f) { return Pose(f.pose()); },
          "the last accepted pose (a copy: later frames do not change it)")
      .def_property_readonly("frames_fitted", &EMFitter::frames_fitted)
      .def_property_readonly("scale_estimate", &EMFitter::scale_estimate)
      .def_property_readonly("fit_vertices", &EMFitter::fit_vertices,
                             "template vertex indices the fit uses")
      .def("set_initial_pose", &EMFitter::SetInitialPose, py::arg("pose"),
           "pose the first frame starts from (before the ICP pre-alignment)")
      .def_property_readonly("initial_pose",
                             [](const EMFitter& f) { return Pose(f.initial_pose()); })
      .def("predict_next_pose", &EMFitter::PredictNextPose)
      .def("set_template_colors", &EMFitter::SetTemplateColors, py::arg("colors"),
           "V x 3 RGB in [0, 1] for the colour term (empty array: off)")
      .def("reset", &EMFitter::Reset, py::arg("keep_scale") = false)
      .def(
          "posed_vertices",
          [](const EMFitter& f) {
            Eigen::MatrixX3d posed;
            f.skinning().Apply(f.pose(), &posed);
            return posed;
          },
          "V x 3 template posed at the current pose");

  py::class_<Texturer>(m, "Texturer",
                       "On-the-fly texturing: per frame the colour image joins the pool, views\n"
                       "are selected per triangle by an MRF, texels resampled, seams levelled.")
      .def(py::init([](const Template& t, const py::object& config) {
             return std::make_unique<Texturer>(t, PipelineOptionsFromPython(config).texturing);
           }),
           py::arg("template"), py::arg("config") = py::none(),
           "config: None (defaults) or a dict/YAML with a `texture` section")
      .def(
          "add_frame",
          [](Texturer& t, int frame, const py::array& color_rgb, const PinholeCamera& camera,
             const Eigen::MatrixX3d& posed) {
            cv::Mat bgr = RgbFromNumpy(color_rgb, "Texturer.add_frame color");
            TextureFrameSummary s;
            {
              py::gil_scoped_release release;
              s = t.AddFrame(frame, bgr, camera, posed);
            }
            return TextureSummaryToDict(s);
          },
          py::arg("frame"), py::arg("color"), py::arg("camera"), py::arg("posed_vertices"),
          "adds a frame (RGB image, colour camera, fitted V x 3 vertices): summary dict")
      .def(
          "atlas", [](const Texturer& t) { return ImageToNumpy(t.Atlas()); },
          "current texture atlas, H x W x 3 RGB")
      .def("label_map", [](const Texturer& t) { return ImageToNumpy(t.LabelMap()); })
      .def_property_readonly("triangle_frames", &Texturer::triangle_frames,
                             "source frame per triangle (-1 untextured)")
      .def(
          "vertex_colors",
          [](const Texturer& t) {
            Eigen::MatrixX3d rgb;
            std::vector<uint8_t> valid;
            t.VertexColors(&rgb, &valid);
            return py::make_tuple(rgb, valid);
          },
          "(V x 3 RGB in [0, 1], V validity flags)");
}

}  // namespace artex::python
