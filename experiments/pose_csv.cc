#include "experiments/pose_csv.h"

#include <cctype>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <iomanip>
#include <sstream>

#include "models/error.h"
#include "models/mesh_export.h"
#include "sensors/yaml_checks.h"

namespace artex {
namespace {

// Largest frame index in a poses.csv frame column (checked before the int conversion).
constexpr int kMaxPoseCsvFrame = 100000000;

// Splits on commas and whitespace.
std::vector<std::string> SplitFields(const std::string& text) {
  std::vector<std::string> fields;
  std::string current;
  for (char c : text) {
    if (c == ',' || std::isspace(static_cast<unsigned char>(c))) {
      if (!current.empty()) fields.push_back(current);
      current.clear();
    } else {
      current.push_back(c);
    }
  }
  if (!current.empty()) fields.push_back(current);
  return fields;
}

bool ParseNumber(const std::string& text, double* value) {
  char* end = nullptr;
  *value = std::strtod(text.c_str(), &end);
  return end != text.c_str() && *end == '\0';
}

}  // namespace

Eigen::VectorXd ParseNumberList(const std::string& text, const std::string& what) {
  const std::vector<std::string> fields = SplitFields(text);
  Eigen::VectorXd v(static_cast<Eigen::Index>(fields.size()));
  for (size_t i = 0; i < fields.size(); ++i) {
    if (!ParseNumber(fields[i], &v[static_cast<Eigen::Index>(i)])) {
      throw Error(what + ": field " + std::to_string(i + 1) + ": expected a number, found '" +
                  fields[i] + "'");
    }
  }
  return v;
}

std::vector<std::pair<int, Pose>> ReadPoseCsv(const std::string& path, int num_joints) {
  CheckNotAFolder(path, "a poses.csv file");
  std::ifstream in(path);
  if (!in) throw Error(path + ": cannot open (no such file or not readable)");
  std::vector<std::pair<int, Pose>> rows;
  bool frame_column = false, first = true;
  std::string line;
  for (int line_number = 1; std::getline(in, line); ++line_number) {
    if (!line.empty() && line.back() == '\r') line.pop_back();
    const std::vector<std::string> fields = SplitFields(line);
    if (fields.empty() || fields[0][0] == '#') continue;
    double unused;
    if (first && !ParseNumber(fields[0], &unused)) {  // header
      frame_column = fields[0] == "frame";
      first = false;
      continue;
    }
    first = false;
    const std::string where = path + ":" + std::to_string(line_number);
    Eigen::VectorXd v = ParseNumberList(line, where);
    int frame = static_cast<int>(rows.size());
    if (frame_column) {
      // Checked before the conversion: a frame beyond int is undefined behaviour (fuzzer finding).
      if (!(v[0] >= 0 && v[0] <= kMaxPoseCsvFrame) || v[0] != std::floor(v[0])) {
        std::ostringstream found;
        found << v[0];
        throw Error(where + ": frame: expected an integer in [0, " +
                    std::to_string(kMaxPoseCsvFrame) + "], found " + found.str());
      }
      frame = static_cast<int>(v[0]);
      v = v.tail(v.size() - 1).eval();
    }
    rows.emplace_back(frame, Pose::FromVector(v, num_joints, where));
  }
  if (rows.empty()) throw Error(path + ": no pose rows");
  return rows;
}

void WritePoseCsv(const std::string& path, const Template& tmpl, const std::vector<int>& frames,
                  const std::vector<Pose>& poses) {
  std::ostringstream csv;
  csv << "frame,scale,tx,ty,tz,rx,ry,rz";
  for (const auto& joint : tmpl.joints)
    csv << "," << joint.name << "_x," << joint.name << "_y," << joint.name << "_z";
  csv << "\n";
  for (std::size_t k = 0; k < poses.size(); ++k) {
    csv << frames[k];
    const Eigen::VectorXd v = poses[k].ToVector();
    for (int p = 0; p < v.size(); ++p) csv << "," << std::setprecision(9) << v[p];
    csv << "\n";
  }
  WriteFileAtomically(path, csv.str());
}

}  // namespace artex
