// Python bindings of experiments/: pipeline options, the per-sequence pipeline (results as
// dicts) and the experiment runner.
#include <pybind11/stl.h>

#include <cmath>
#include <cstdlib>

#include "experiments/pipeline.h"
#include "experiments/runner.h"
#include "models/error.h"
#include "python/bind_common.h"
#include "solvers/fit_quality.h"

#ifndef ARTEX_EXECUTABLE
#define ARTEX_EXECUTABLE ""
#endif

namespace artex::python {
namespace {

py::object NumberOrNone(double v) {
  return std::isfinite(v) ? py::object(py::float_(v)) : py::object(py::none());
}

py::dict RecordToDict(const FrameRecord& r) {
  py::dict d;
  d["frame"] = r.frame;
  d["skipped"] = r.skipped;
  d["fit"] = r.fit;  // artex.FitSummary
  d["quality"] = FitQualityLabelName(r.quality.label);
  d["quality_score"] = r.quality.score;
  d["reinitialised"] = r.reinitialised;
  d["scan_points"] = r.scan_points;
  d["preprocess_seconds"] = r.preprocess_seconds;
  d["texture_seam_rms_after"] = r.texture.seam_rms_after;
  d["mean_vertex_error_mm"] = NumberOrNone(r.mean_vertex_error_mm);
  d["max_vertex_error_mm"] = NumberOrNone(r.max_vertex_error_mm);
  d["mean_joint_error_mm"] = NumberOrNone(r.mean_joint_error_mm);
  return d;
}

py::dict ResultToDict(const PipelineResult& r) {
  py::dict d;
  py::list frames;
  for (const auto& f : r.frames) frames.append(RecordToDict(f));
  d["frames"] = frames;
  d["skipped_frames"] = r.skipped_frames;
  d["good_frames"] = r.good_frames;
  d["doubtful_frames"] = r.doubtful_frames;
  d["lost_frames"] = r.lost_frames;
  d["failed_frames"] = r.failed_frames;
  d["initialisations"] = r.initialisations;
  d["has_ground_truth"] = r.has_ground_truth;
  d["mean_vertex_error_mm"] =
      r.has_ground_truth ? NumberOrNone(r.mean_vertex_error_mm) : py::object(py::none());
  d["max_vertex_error_mm"] =
      r.has_ground_truth ? NumberOrNone(r.max_vertex_error_mm) : py::object(py::none());
  d["mean_joint_error_mm"] =
      r.has_ground_truth ? NumberOrNone(r.mean_joint_error_mm) : py::object(py::none());
  d["lost_fraction"] = r.lost_fraction;
  d["mean_em_iterations"] = r.mean_em_iterations;
  d["fit_ms_per_frame"] = r.fit_ms_per_frame;
  d["texture_ms_per_frame"] = r.texture_ms_per_frame;
  d["stream_kbit_per_s"] = r.stream_kbit_per_s;
  d["warnings"] = r.warnings;
  return d;
}

}  // namespace

void BindExperiments(py::module_& m) {
  m.def(
      "check_config",
      [](const py::object& config) {
        const Config c = ConfigFromPython(config, "<python config>");
        LoadPipelineOptions(c);
        return c.ToYaml();
      },
      py::arg("config") = py::none(),
      "Validates a pipeline configuration (dict or YAML; every key checked) and returns it\n"
      "as YAML text. Raises artex.Error naming the bad key and the valid ones.");

  m.def(
      "run_pipeline",
      [](const std::string& sequence, const std::string& out_dir, const py::object& config,
         const std::string& template_path) {
        const Config c = ConfigFromPython(config, "<python config>");
        const PipelineOptions options = LoadPipelineOptions(c);
        PipelineResult result;
        {
          py::gil_scoped_release release;
          result = RunPipeline(sequence, template_path, options, c, out_dir);
        }
        return ResultToDict(result);
      },
      py::arg("sequence"), py::arg("out_dir"), py::arg("config") = py::none(),
      py::arg("template_path") = "",
      "Runs `artex track` on a recording into out_dir (poses.csv, summary.json, texture.png,\n"
      "tracked.glb ...) and returns the result as a dict (per-frame records under 'frames').");

  m.def(
      "run_experiment",
      [](const std::string& experiment_file, const std::string& out_dir, int jobs,
         const std::string& executable) {
        const Experiment e = LoadExperiment(experiment_file);
        RunnerOptions o;
        o.jobs = jobs;
        o.executable = executable;
        if (o.executable.empty()) {
          const char* env = std::getenv("ARTEX_EXECUTABLE");
          o.executable = env && *env ? env : ARTEX_EXECUTABLE;
        }
        if (o.executable.empty())
          throw Error("run_experiment: no artex executable (set ARTEX_EXECUTABLE)");
        ExperimentSummary s;
        {
          py::gil_scoped_release release;
          s = RunExperiment(e, out_dir, o);
        }
        py::dict d;
        d["runs_total"] = s.runs_total;
        d["runs_completed"] = s.runs_completed;
        d["runs_skipped"] = s.runs_skipped;
        d["runs_failed"] = s.runs_failed;
        d["failures"] = s.failures;
        d["seconds"] = s.seconds;
        return d;
      },
      py::arg("experiment_file"), py::arg("out_dir"), py::arg("jobs") = 1,
      py::arg("executable") = "",
      "Runs an experiment file like `artex experiment` (runs are child processes of the artex\n"
      "executable: `executable`, else $ARTEX_EXECUTABLE, else the one built with this module).\n"
      "Read the results with artex.read_experiment(out_dir).");

  m.def(
      "metrics",
      [] {
        py::list out;
        for (const auto& info : Metrics()) {
          py::dict d;
          d["name"] = info.name;
          d["lower_is_better"] = info.lower_is_better;
          d["timing"] = info.timing;
          d["description"] = info.description;
          out.append(d);
        }
        return out;
      },
      "the metrics of an experiment run (results.json / results.csv), with descriptions");
  m.def("source_revision", &SourceRevision, "git revision the module was built from");
}

}  // namespace artex::python
