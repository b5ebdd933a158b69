#include "sensors/sequence.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <opencv2/imgcodecs.hpp>
#include <tbb/parallel_invoke.h>
#include <sstream>

#include "models/error.h"
#include "sensors/image_io.h"
#include "sensors/yaml_checks.h"

namespace artex {
namespace fs = std::filesystem;

namespace {

constexpr char kFramesHeader[] = "index,depth_timestamp,color_timestamp,depth_file,color_file";
constexpr char kBackgroundHeader[] = "index,depth_file";
constexpr char kPosesHeaderStart[] = "frame,s,tx,ty,tz";
// groundtruth/vertices/NNNNNN.bin: 4-byte magic, uint32 LE vertex count, count x 3 float32 LE.
constexpr char kVertexMagic[4] = {'A', 'X', 'V', '1'};
constexpr size_t kVertexHeaderBytes = 8;
constexpr int kFileNameDigits = 6;

std::string Trim(const std::string& s) {
  const size_t b = s.find_first_not_of(" \t\r\n");
  if (b == std::string::npos) return "";
  const size_t e = s.find_last_not_of(" \t\r\n");
  return s.substr(b, e - b + 1);
}

std::vector<std::string> SplitCsv(const std::string& line) {
  std::vector<std::string> fields;
  std::stringstream ss(line);
  std::string field;
  while (std::getline(ss, field, ',')) fields.push_back(Trim(field));
  if (!line.empty() && line.back() == ',') fields.push_back("");
  return fields;
}

std::string Numbered(int n, const std::string& ext) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%0*d", kFileNameDigits, n);
  return std::string(buf) + ext;
}

std::string FormatDouble(double v) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), "%.17g", v);
  return buf;
}

// A data line of a CSV file: its 1-based line number and fields.
struct CsvLine {
  int line = 0;
  std::vector<std::string> fields;
};

// Reads a CSV file whose first non-comment line must equal (or start with) `header`.
// Lines starting with '#' and blank lines are skipped.
std::vector<CsvLine> ReadCsv(const std::string& path, const std::string& header,
                             bool header_prefix_only, std::string* header_line) {
  CheckNotAFolder(path, "a CSV file");
  std::ifstream in(path);
  if (!in) throw Error(path + ": cannot open the file");
  std::vector<CsvLine> rows;
  std::string line;
  int number = 0;
  bool have_header = false;
  while (std::getline(in, line)) {
    ++number;
    const std::string t = Trim(line);
    if (t.empty() || t[0] == '#') continue;
    if (!have_header) {
      std::string compact;
      for (char c : t) {
        if (c != ' ' && c != '\t') compact += c;
      }
      const bool ok = header_prefix_only ? compact.rfind(header, 0) == 0 : compact == header;
      if (!ok) {
        throw Error(path + ": line " + std::to_string(number) + ": expected the header '" + header +
                    (header_prefix_only ? ",..." : "") + "', found '" + t + "'");
      }
      if (header_line) *header_line = compact;
      have_header = true;
      continue;
    }
    rows.push_back({number, SplitCsv(t)});
  }
  if (!have_header)
    throw Error(path + ": expected the header '" + header + "', found an empty file");
  return rows;
}

[[noreturn]] void RowError(const std::string& path, int line, const std::string& field,
                           const std::string& expected, const std::string& found) {
  throw Error(path + ": line " + std::to_string(line) + ": column '" + field + "': expected " +
              expected + ", found '" + found + "'");
}

double ParseDouble(const std::string& path, int line, const std::string& field,
                   const std::string& s) {
  char* end = nullptr;
  const double v = std::strtod(s.c_str(), &end);
  if (s.empty() || end != s.c_str() + s.size() || !std::isfinite(v)) {
    RowError(path, line, field, "a finite number", s);
  }
  return v;
}

int ParseInt(const std::string& path, int line, const std::string& field, const std::string& s) {
  char* end = nullptr;
  const long v = std::strtol(s.c_str(), &end, 10);
  if (s.empty() || end != s.c_str() + s.size() || v < 0 || v > 1000000000L) {
    RowError(path, line, field, "a non-negative integer", s);
  }
  return static_cast<int>(v);
}

void PutU32(uint32_t v, char* out) {
  for (int i = 0; i < 4; ++i) out[i] = static_cast<char>((v >> (8 * i)) & 0xff);
}
uint32_t GetU32(const char* in) {
  uint32_t v = 0;
  for (int i = 0; i < 4; ++i)
    v |= static_cast<uint32_t>(static_cast<unsigned char>(in[i])) << (8 * i);
  return v;
}
void PutF32(float f, char* out) {
  uint32_t v;
  std::memcpy(&v, &f, 4);
  PutU32(v, out);
}
float GetF32(const char* in) {
  const uint32_t v = GetU32(in);
  float f;
  std::memcpy(&f, &v, 4);
  return f;
}

std::string EncodeVertices(const Eigen::MatrixX3d& vertices) {
  const size_t n = static_cast<size_t>(vertices.rows());
  std::string data(kVertexHeaderBytes + 12 * n, '\0');
  std::memcpy(&data[0], kVertexMagic, 4);
  PutU32(static_cast<uint32_t>(n), &data[4]);
  char* p = &data[kVertexHeaderBytes];
  for (size_t i = 0; i < n; ++i) {
    for (int k = 0; k < 3; ++k, p += 4) PutF32(static_cast<float>(vertices(i, k)), p);
  }
  return data;
}

Eigen::MatrixX3d DecodeVertices(const std::string& path) {
  CheckNotAFolder(path, "a ground-truth vertex file");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(path + ": missing ground-truth vertex file");
  const std::string data((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (data.size() < kVertexHeaderBytes || std::memcmp(data.data(), kVertexMagic, 4) != 0) {
    throw Error(path + ": expected a vertex file starting with the magic 'AXV1', found " +
                (data.size() < 4
                     ? std::string("a file of ") + std::to_string(data.size()) + " bytes"
                     : "'" + data.substr(0, 4) + "'"));
  }
  const size_t n = GetU32(&data[4]);
  if (data.size() != kVertexHeaderBytes + 12 * n) {
    throw Error(path + ": expected " + std::to_string(kVertexHeaderBytes + 12 * n) + " bytes for " +
                std::to_string(n) + " vertices, found " + std::to_string(data.size()));
  }
  Eigen::MatrixX3d v(n, 3);
  const char* p = &data[kVertexHeaderBytes];
  for (size_t i = 0; i < n; ++i) {
    for (int k = 0; k < 3; ++k, p += 4) {
      v(i, k) = GetF32(p);
      if (!std::isfinite(v(i, k))) {
        throw Error(path + ": vertex " + std::to_string(i) + " coordinate " + std::to_string(k) +
                    ": expected a finite number, found " + std::to_string(v(i, k)));
      }
    }
  }
  return v;
}

struct FrameRow {
  int index = 0;
  double depth_timestamp = 0;
  double color_timestamp = 0;
  std::string depth_file;
  std::string color_file;
};

}  // namespace

// ---------------------------------------------------------------------------------------------
// SequenceReader

struct SequenceReader::Impl {
  std::string folder;
  Calibration calibration;
  std::vector<FrameRow> rows;
  std::vector<std::string> background_files;  // relative to folder
  bool has_ground_truth = false;
  int num_joints = 0;
  std::map<int, Eigen::VectorXd> poses;  // frame index -> pose vector

  std::string Path(const std::string& relative) const {
    return (fs::path(folder) / relative).string();
  }
};

SequenceReader::SequenceReader(const std::string& folder) : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.folder = folder;
  std::error_code ec;
  if (!fs::is_directory(folder, ec))
    throw Error(folder + ": expected a sequence folder, found none");
  if (fs::is_empty(folder, ec)) {
    throw Error(folder +
                ": expected a sequence folder (calibration.yaml, frames.csv, depth/, "
                "color/), found an empty folder");
  }
  const std::string calib = m.Path("calibration.yaml");
  if (!fs::exists(calib, ec)) throw Error(calib + ": missing calibration file");
  m.calibration = ReadCalibration(calib);

  const std::string frames = m.Path("frames.csv");
  if (!fs::exists(frames, ec)) {
    throw Error(frames + ": missing frame list (an unfinished recording has no frames.csv)");
  }
  for (const CsvLine& r : ReadCsv(frames, kFramesHeader, false, nullptr)) {
    if (r.fields.size() != 5) {
      throw Error(frames + ": line " + std::to_string(r.line) + ": expected 5 columns (" +
                  kFramesHeader + "), found " + std::to_string(r.fields.size()));
    }
    FrameRow row;
    row.index = ParseInt(frames, r.line, "index", r.fields[0]);
    row.depth_timestamp = ParseDouble(frames, r.line, "depth_timestamp", r.fields[1]);
    row.color_timestamp = ParseDouble(frames, r.line, "color_timestamp", r.fields[2]);
    row.depth_file = r.fields[3];
    row.color_file = r.fields[4];
    if (row.depth_file.empty()) RowError(frames, r.line, "depth_file", "a file name", "");
    if (row.color_file.empty()) RowError(frames, r.line, "color_file", "a file name", "");
    if (!m.rows.empty()) {
      const FrameRow& prev = m.rows.back();
      if (row.index <= prev.index) {
        RowError(frames, r.line, "index", "an index greater than " + std::to_string(prev.index),
                 r.fields[0]);
      }
      if (!(row.depth_timestamp > prev.depth_timestamp)) {
        RowError(frames, r.line, "depth_timestamp",
                 "increasing timestamps (> " + FormatDouble(prev.depth_timestamp) + ")",
                 r.fields[1]);
      }
      if (!(row.color_timestamp > prev.color_timestamp)) {
        RowError(frames, r.line, "color_timestamp",
                 "increasing timestamps (> " + FormatDouble(prev.color_timestamp) + ")",
                 r.fields[2]);
      }
    }
    m.rows.push_back(row);
  }
  if (m.rows.empty()) throw Error(frames + ": expected at least one frame, found none");

  const std::string background = m.Path("background.csv");
  if (fs::exists(background, ec)) {
    for (const CsvLine& r : ReadCsv(background, kBackgroundHeader, false, nullptr)) {
      if (r.fields.size() != 2 || r.fields[1].empty()) {
        throw Error(background + ": line " + std::to_string(r.line) + ": expected 2 columns (" +
                    kBackgroundHeader + ")");
      }
      ParseInt(background, r.line, "index", r.fields[0]);
      m.background_files.push_back(r.fields[1]);
    }
  } else if (fs::is_directory(m.Path("background"), ec)) {
    for (const auto& entry : fs::directory_iterator(m.Path("background"))) {
      if (entry.path().extension() == ".png") {
        m.background_files.push_back((fs::path("background") / entry.path().filename()).string());
      }
    }
    std::sort(m.background_files.begin(), m.background_files.end());
  }

  const std::string poses = m.Path("groundtruth/poses.csv");
  if (fs::exists(poses, ec)) {
    m.has_ground_truth = true;
    std::string header;
    const std::vector<CsvLine> lines = ReadCsv(poses, kPosesHeaderStart, true, &header);
    const int columns = static_cast<int>(SplitCsv(header).size());
    const int parameters = columns - 1;
    if (parameters < kNumGlobalParameters || (parameters - kNumGlobalParameters) % 3 != 0) {
      throw Error(poses +
                  ": expected a header with 'frame' and 7 + 3 x joints pose columns, "
                  "found " +
                  std::to_string(columns) + " columns");
    }
    m.num_joints = (parameters - kNumGlobalParameters) / 3;
    for (const CsvLine& r : lines) {
      if (static_cast<int>(r.fields.size()) != columns) {
        throw Error(poses + ": line " + std::to_string(r.line) + ": expected " +
                    std::to_string(columns) + " columns (as the header), found " +
                    std::to_string(r.fields.size()));
      }
      const int frame = ParseInt(poses, r.line, "frame", r.fields[0]);
      Eigen::VectorXd v(parameters);
      for (int k = 0; k < parameters; ++k) {
        v[k] = ParseDouble(poses, r.line, "pose[" + std::to_string(k) + "]", r.fields[k + 1]);
      }
      if (m.poses.count(frame)) {
        RowError(poses, r.line, "frame", "each frame once", r.fields[0]);
      }
      // Validates length, finiteness and scale now, so that a malformed file fails early.
      Pose::FromVector(v, m.num_joints, poses + ": line " + std::to_string(r.line));
      m.poses[frame] = v;
    }
  }
}

SequenceReader::~SequenceReader() = default;

const Calibration& SequenceReader::calibration() const { return impl_->calibration; }
int SequenceReader::num_frames() const { return static_cast<int>(impl_->rows.size()); }
const std::string& SequenceReader::folder() const { return impl_->folder; }
bool SequenceReader::has_ground_truth() const { return impl_->has_ground_truth; }

bool SequenceReader::ReadFrame(int i, Frame* frame, std::string* warning) {
  const Impl& m = *impl_;
  if (i < 0 || i >= num_frames()) {
    throw Error(m.folder + ": frame " + std::to_string(i) + " requested, expected 0.." +
                std::to_string(num_frames() - 1));
  }
  const FrameRow& row = m.rows[i];
  frame->index = row.index;
  frame->depth_timestamp = row.depth_timestamp;
  frame->color_timestamp = row.color_timestamp;
  const Calibration& c = m.calibration;
  // The two images are decoded concurrently (PNG decoding is most of a frame's reading).
  std::string depth_warning, color_warning;
  bool depth_ok = false, color_ok = false;
  tbb::parallel_invoke(
      [&] {
        depth_ok = ReadDepthImage(m.Path(row.depth_file), c.depth.width, c.depth.height,
                                  &frame->depth, &depth_warning);
      },
      [&] {
        color_ok = ReadColorImage(m.Path(row.color_file), c.color.width, c.color.height,
                                  &frame->color, &color_warning);
      });
  if (warning) *warning = !depth_ok ? depth_warning : color_warning;
  return depth_ok && color_ok;
}

std::vector<cv::Mat> SequenceReader::ReadBackgroundFrames() {
  const Impl& m = *impl_;
  std::vector<cv::Mat> frames;
  for (const std::string& file : m.background_files) {
    cv::Mat depth;
    std::string warning;
    if (!ReadDepthImage(m.Path(file), m.calibration.depth.width, m.calibration.depth.height, &depth,
                        &warning)) {
      throw Error("background frame " + warning);
    }
    frames.push_back(depth);
  }
  return frames;
}

std::string SequenceReader::Description() const {
  const Impl& m = *impl_;
  return "artex sequence " + m.folder + ": " + std::to_string(m.rows.size()) + " frames, " +
         std::to_string(m.background_files.size()) + " background frames, " +
         (m.has_ground_truth ? "ground truth" : "no ground truth") + ", depth " +
         std::to_string(m.calibration.depth.width) + "x" +
         std::to_string(m.calibration.depth.height) + ", world frame from calibration.yaml";
}

GroundTruthFrame SequenceReader::ReadGroundTruth(int i) const {
  const Impl& m = *impl_;
  if (i < 0 || i >= num_frames()) {
    throw Error(m.folder + ": ground truth of frame " + std::to_string(i) +
                " requested, expected 0.." + std::to_string(num_frames() - 1));
  }
  const std::string poses = m.Path("groundtruth/poses.csv");
  if (!m.has_ground_truth) throw Error(poses + ": missing (the sequence has no ground truth)");
  const int index = m.rows[i].index;
  auto it = m.poses.find(index);
  if (it == m.poses.end()) {
    throw Error(poses + ": expected a row for frame " + std::to_string(index) + ", found none");
  }
  GroundTruthFrame truth;
  truth.pose =
      Pose::FromVector(it->second, m.num_joints, poses + ": frame " + std::to_string(index));
  truth.vertices = DecodeVertices(m.Path("groundtruth/vertices/" + Numbered(index, ".bin")));
  return truth;
}

std::string SequenceReader::GroundTruthTexturePath() const {
  std::error_code ec;
  const std::string p = impl_->Path("groundtruth/texture.png");
  return fs::exists(p, ec) ? p : "";
}

std::string SequenceReader::GroundTruthSubjectPath() const {
  std::error_code ec;
  const std::string p = impl_->Path("groundtruth/subject.glb");
  return fs::exists(p, ec) ? p : "";
}

// ---------------------------------------------------------------------------------------------
// SequenceWriter

struct SequenceWriter::Impl {
  std::string folder;
  Calibration calibration;
  std::vector<FrameRow> rows;
  std::vector<std::string> background_files;
  std::map<int, Eigen::VectorXd> poses;
  int num_joints = -1;
  bool finished = false;

  std::string Path(const std::string& relative) const {
    return (fs::path(folder) / relative).string();
  }
  void MakeDir(const std::string& relative) const {
    std::error_code ec;
    fs::create_directories(Path(relative), ec);
    if (ec) throw Error(Path(relative) + ": cannot create the folder: " + ec.message());
  }
  void CheckOpen(const char* what) const {
    if (finished) throw Error(folder + ": " + what + " called after SequenceWriter::Finish()");
  }
};

SequenceWriter::SequenceWriter(const std::string& folder, const Calibration& calibration)
    : impl_(std::make_unique<Impl>()) {
  impl_->folder = folder;
  impl_->calibration = calibration;
  const PinholeCamera& d = calibration.depth;
  const PinholeCamera& c = calibration.color;
  if (d.width <= 0 || d.height <= 0 || c.width <= 0 || c.height <= 0 || d.fx <= 0 || d.fy <= 0 ||
      c.fx <= 0 || c.fy <= 0 || !(calibration.depth_scale > 0) || !(calibration.frame_rate > 0)) {
    throw Error(folder +
                ": invalid calibration for a new sequence: expected positive image sizes, "
                "focal lengths, depth_scale and frame_rate");
  }
  impl_->MakeDir("");
  impl_->MakeDir("depth");
  impl_->MakeDir("color");
  WriteCalibration(calibration, impl_->Path("calibration.yaml"));
}

SequenceWriter::~SequenceWriter() = default;

void SequenceWriter::AddFrame(const Frame& frame) {
  Impl& m = *impl_;
  m.CheckOpen("AddFrame");
  const std::string what = m.folder + ": frame " + std::to_string(frame.index);
  const PinholeCamera& d = m.calibration.depth;
  const PinholeCamera& c = m.calibration.color;
  if (frame.depth.type() != CV_16UC1 || frame.depth.cols != d.width ||
      frame.depth.rows != d.height) {
    throw Error(what + ": expected a CV_16UC1 " + std::to_string(d.width) + "x" +
                std::to_string(d.height) + " depth image, found " +
                MatTypeName(frame.depth.type()) + " " + std::to_string(frame.depth.cols) + "x" +
                std::to_string(frame.depth.rows));
  }
  if (frame.color.type() != CV_8UC3 || frame.color.cols != c.width ||
      frame.color.rows != c.height) {
    throw Error(what + ": expected a CV_8UC3 " + std::to_string(c.width) + "x" +
                std::to_string(c.height) + " colour image, found " +
                MatTypeName(frame.color.type()) + " " + std::to_string(frame.color.cols) + "x" +
                std::to_string(frame.color.rows));
  }
  if (frame.index < 0) throw Error(what + ": expected a non-negative frame index");
  if (!std::isfinite(frame.depth_timestamp) || !std::isfinite(frame.color_timestamp)) {
    throw Error(what + ": expected finite timestamps");
  }
  if (!m.rows.empty()) {
    const FrameRow& prev = m.rows.back();
    if (frame.index <= prev.index) {
      throw Error(what + ": expected a frame index greater than " + std::to_string(prev.index));
    }
    if (!(frame.depth_timestamp > prev.depth_timestamp) ||
        !(frame.color_timestamp > prev.color_timestamp)) {
      throw Error(what + ": expected timestamps increasing over the previous frame (depth " +
                  FormatDouble(prev.depth_timestamp) + ", colour " +
                  FormatDouble(prev.color_timestamp) + "), found depth " +
                  FormatDouble(frame.depth_timestamp) + ", colour " +
                  FormatDouble(frame.color_timestamp));
    }
  }
  FrameRow row;
  row.index = frame.index;
  row.depth_timestamp = frame.depth_timestamp;
  row.color_timestamp = frame.color_timestamp;
  row.depth_file = "depth/" + Numbered(frame.index, ".png");
  row.color_file = "color/" + Numbered(frame.index, ".png");
  WriteImageAtomic(m.Path(row.depth_file), frame.depth);
  WriteImageAtomic(m.Path(row.color_file), frame.color);
  m.rows.push_back(row);
}

void SequenceWriter::AddBackgroundFrame(const cv::Mat& depth) {
  Impl& m = *impl_;
  m.CheckOpen("AddBackgroundFrame");
  const PinholeCamera& d = m.calibration.depth;
  if (depth.type() != CV_16UC1 || depth.cols != d.width || depth.rows != d.height) {
    throw Error(m.folder + ": background frame " + std::to_string(m.background_files.size()) +
                ": expected a CV_16UC1 " + std::to_string(d.width) + "x" +
                std::to_string(d.height) + " depth image, found " + MatTypeName(depth.type()) +
                " " + std::to_string(depth.cols) + "x" + std::to_string(depth.rows));
  }
  m.MakeDir("background");
  const std::string file =
      "background/" + Numbered(static_cast<int>(m.background_files.size()), ".png");
  WriteImageAtomic(m.Path(file), depth);
  m.background_files.push_back(file);
}

void SequenceWriter::AddGroundTruth(int frame_index, const GroundTruthFrame& truth) {
  Impl& m = *impl_;
  m.CheckOpen("AddGroundTruth");
  const std::string what = m.folder + ": ground truth of frame " + std::to_string(frame_index);
  if (frame_index < 0) throw Error(what + ": expected a non-negative frame index");
  if (!truth.pose.AllFinite() || !(truth.pose.scale > 0)) {
    throw Error(what + ": expected a finite pose with a positive scale");
  }
  if (!truth.vertices.allFinite()) throw Error(what + ": expected finite vertices");
  if (m.num_joints >= 0 && truth.pose.num_joints() != m.num_joints) {
    throw Error(what + ": expected " + std::to_string(m.num_joints) +
                " joints (as earlier frames), found " + std::to_string(truth.pose.num_joints()));
  }
  if (m.poses.count(frame_index)) throw Error(what + ": added twice");
  m.num_joints = truth.pose.num_joints();
  m.MakeDir("groundtruth/vertices");
  WriteFileAtomic(m.Path("groundtruth/vertices/" + Numbered(frame_index, ".bin")),
                  EncodeVertices(truth.vertices));
  m.poses[frame_index] = truth.pose.ToVector();
}

void SequenceWriter::SetGroundTruthTexture(const cv::Mat& texture_bgr) {
  impl_->CheckOpen("SetGroundTruthTexture");
  impl_->MakeDir("groundtruth");
  WriteImageAtomic(impl_->Path("groundtruth/texture.png"), texture_bgr);
}

std::string SequenceWriter::subject_path() const {
  impl_->MakeDir("groundtruth");
  return impl_->Path("groundtruth/subject.glb");
}

void SequenceWriter::Finish() {
  Impl& m = *impl_;
  m.CheckOpen("Finish");
  if (m.rows.empty())
    throw Error(m.folder + ": expected at least one frame before Finish(), found none");
  if (!m.background_files.empty()) {
    std::string csv = std::string(kBackgroundHeader) + "\n";
    for (size_t i = 0; i < m.background_files.size(); ++i) {
      csv += std::to_string(i) + "," + m.background_files[i] + "\n";
    }
    WriteFileAtomic(m.Path("background.csv"), csv);
  }
  if (!m.poses.empty()) {
    std::map<int, bool> known;
    for (const FrameRow& r : m.rows) known[r.index] = true;
    std::string csv = kPosesHeaderStart;
    csv += ",r0x,r0y,r0z";
    for (int j = 0; j < m.num_joints; ++j) {
      const std::string n = std::to_string(j + 1);
      csv += ",r" + n + "x,r" + n + "y,r" + n + "z";
    }
    csv += "\n";
    for (const auto& kv : m.poses) {
      if (!known.count(kv.first)) {
        throw Error(m.folder + ": ground truth given for frame " + std::to_string(kv.first) +
                    ", expected only frames added with AddFrame");
      }
      csv += std::to_string(kv.first);
      for (int k = 0; k < kv.second.size(); ++k) csv += "," + FormatDouble(kv.second[k]);
      csv += "\n";
    }
    WriteFileAtomic(m.Path("groundtruth/poses.csv"), csv);
  }
  // frames.csv last: its presence marks a complete sequence.
  std::string csv = std::string(kFramesHeader) + "\n";
  for (const FrameRow& r : m.rows) {
    csv += std::to_string(r.index) + "," + FormatDouble(r.depth_timestamp) + "," +
           FormatDouble(r.color_timestamp) + "," + r.depth_file + "," + r.color_file + "\n";
  }
  WriteFileAtomic(m.Path("frames.csv"), csv);
  m.finished = true;
}

}  // namespace artex
