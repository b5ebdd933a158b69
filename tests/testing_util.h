// Test helpers shared across the test folders (namespace testing_util): fresh temporary
// folders and the coarse generated template. Topic fixtures build on these:
// tests/solvers/fitting_test_util.h (stick templates, random poses, sampled scans) and
// tests/solvers/virtual_kinect_scans.h (synthesised sequences and scans).
#pragma once

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "models/template.h"
#include "models/template_generator.h"

namespace artex {
namespace testing_util {

// The empty folder artex_<name>_<pid> in the system's temporary directory (removed first when
// a previous run left it).
inline std::filesystem::path FreshTempDir(const std::string& name) {
  namespace fs = std::filesystem;
  const fs::path dir =
      fs::temp_directory_path() / ("artex_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

// The bytes of a file ("" when it cannot be opened).
inline std::string ReadFileBytes(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

// The generated template at its coarsest resolution (BodyShapeOptions::resolution 0), made once
// per process.
inline const Template& CoarseTemplate() {
  static const Template t = [] {
    BodyShapeOptions o;
    o.resolution = 0;
    return GenerateTemplate(o);
  }();
  return t;
}

}  // namespace testing_util
}  // namespace artex
