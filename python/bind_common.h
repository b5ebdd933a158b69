// Shared helpers of the Python module (python/module.cc): conversions between OpenCV images and
// numpy arrays, options from Python configuration values, and the per-area binding functions.
#pragma once

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <opencv2/core.hpp>
#include <string>

#include "experiments/config.h"
#include "experiments/pipeline.h"

namespace artex::python {

namespace py = pybind11;

// Colour images cross the boundary as H x W x 3 uint8 RGB (numpy users' order); OpenCV's BGR
// stays inside artex. Depth images are H x W uint16, masks H x W uint8.
py::array ImageToNumpy(const cv::Mat& image);  // CV_8UC3 (BGR -> RGB), CV_8UC1, CV_16UC1
cv::Mat RgbFromNumpy(const py::array& rgb, const std::string& what);      // -> CV_8UC3 BGR
cv::Mat DepthFromNumpy(const py::array& depth, const std::string& what);  // -> CV_16UC1

// A configuration given from Python: None (built-in defaults), a dict (nested like
// configs/default.yaml) or a YAML text. Dicts are converted through JSON, which is YAML.
Config ConfigFromPython(const py::object& config, const std::string& source_name);
// LoadPipelineOptions(ConfigFromPython(config)): every key checked, unknown keys are errors.
PipelineOptions PipelineOptionsFromPython(const py::object& config);

void BindModels(py::module_& m);
void BindSensors(py::module_& m);
void BindSolvers(py::module_& m);
void BindExperiments(py::module_& m);

}  // namespace artex::python
