// The artex Python extension module `artex._artex` (imported by python/artex/__init__.py):
// the template, poses, skinning, sequence readers, preprocessing, the EM fitter, the texturer,
// the pipeline and the experiment runner. Usage and array conventions: docs/python.md.
#include <pybind11/stl.h>

#include <cstring>
#include <opencv2/imgproc.hpp>

#include "models/error.h"
#include "python/bind_common.h"

namespace artex::python {

py::array ImageToNumpy(const cv::Mat& image) {
  if (image.empty()) return py::array_t<uint8_t>(std::vector<py::ssize_t>{0, 0});
  cv::Mat src = image.isContinuous() ? image : image.clone();
  if (src.type() == CV_8UC3) {
    cv::Mat rgb;
    cv::cvtColor(src, rgb, cv::COLOR_BGR2RGB);
    py::array_t<uint8_t> out({rgb.rows, rgb.cols, 3});
    std::memcpy(out.mutable_data(), rgb.data, rgb.total() * 3);
    return out;
  }
  if (src.type() == CV_8UC1) {
    py::array_t<uint8_t> out({src.rows, src.cols});
    std::memcpy(out.mutable_data(), src.data, src.total());
    return out;
  }
  if (src.type() == CV_16UC1) {
    py::array_t<uint16_t> out({src.rows, src.cols});
    std::memcpy(out.mutable_data(), src.data, src.total() * 2);
    return out;
  }
  if (src.type() == CV_32FC1) {
    py::array_t<float> out({src.rows, src.cols});
    std::memcpy(out.mutable_data(), src.data, src.total() * 4);
    return out;
  }
  throw Error("image conversion: unsupported OpenCV type " + std::to_string(src.type()));
}

cv::Mat RgbFromNumpy(const py::array& rgb, const std::string& what) {
  auto a = py::array_t<uint8_t, py::array::c_style | py::array::forcecast>::ensure(rgb);
  if (!a || a.ndim() != 3 || a.shape(2) != 3) {
    throw Error(what + ": expected an H x W x 3 uint8 RGB array");
  }
  cv::Mat wrapped(static_cast<int>(a.shape(0)), static_cast<int>(a.shape(1)), CV_8UC3,
                  const_cast<uint8_t*>(a.data()));
  cv::Mat bgr;
  cv::cvtColor(wrapped, bgr, cv::COLOR_RGB2BGR);
  return bgr;
}

cv::Mat DepthFromNumpy(const py::array& depth, const std::string& what) {
  auto a = py::array_t<uint16_t, py::array::c_style>::ensure(depth);
  if (!a || a.ndim() != 2) throw Error(what + ": expected an H x W uint16 array");
  cv::Mat wrapped(static_cast<int>(a.shape(0)), static_cast<int>(a.shape(1)), CV_16UC1,
                  const_cast<uint16_t*>(a.data()));
  return wrapped.clone();
}

Config ConfigFromPython(const py::object& config, const std::string& source_name) {
  if (config.is_none()) return Config();
  if (py::isinstance<py::str>(config)) {
    return Config::FromString(config.cast<std::string>(), source_name);
  }
  if (py::isinstance<py::dict>(config)) {
    std::string text = py::module_::import("json").attr("dumps")(config).cast<std::string>();
    return Config::FromString(text, source_name);
  }
  throw Error(source_name + ": expected None, a dict or a YAML string");
}

PipelineOptions PipelineOptionsFromPython(const py::object& config) {
  return LoadPipelineOptions(ConfigFromPython(config, "<python config>"));
}

}  // namespace artex::python

PYBIND11_MODULE(_artex, m) {
  namespace py = pybind11;
  m.doc() =
      "artex: articulated 3D human tracking with on-the-fly texturing from RGB-D (C++ core).\n"
      "Arrays are numpy: positions N x 3 float64 (m), triangles F x 3 int32, colour images\n"
      "H x W x 3 uint8 RGB, depth images H x W uint16. Errors raise artex.Error.";
  py::register_exception<artex::Error>(m, "Error", PyExc_RuntimeError);
  artex::python::BindModels(m);
  artex::python::BindSensors(m);
  artex::python::BindSolvers(m);
  artex::python::BindExperiments(m);
}
