// Reading what users record through the `artex` binary (ARTEX_BINARY): `artex import` of an
// artex sequence and of a TUM RGB-D folder (read back with SequenceReader, same depth pixels),
// `artex track` on a TUM folder, clear errors, and the real skeltrack TUM recording read in
// place (skipped when absent).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <opencv2/imgcodecs.hpp>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "experiments/heap_retention.h"
#include "sensors/frame_source.h"
#include "sensors/sequence.h"
#include "sensors/virtual_kinect.h"
#include "tests/solvers/virtual_kinect_scans.h"
#include "tests/testing_util.h"

namespace artex {
namespace {

namespace fs = std::filesystem;
using testing_util::ReadFileBytes;

constexpr int kFrames = 5;

using Result = testing_util::CommandResult;

int CountLines(const std::string& text) {
  int n = 0;
  std::istringstream s(text);
  std::string line;
  while (std::getline(s, line)) n += !line.empty() && line[0] != '#';
  return n;
}

class InputCliTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new fs::path(testing_util::FreshTempDir("input_cli_test"));
  }
  static void TearDownTestSuite() {
    fs::remove_all(*dir_);
    delete dir_;
    dir_ = nullptr;
  }
  void SetUp() override {
    ASSERT_TRUE(fs::exists(ARTEX_BINARY)) << "build the artex target first: " << ARTEX_BINARY;
  }

  static std::string Path(const std::string& name) { return (*dir_ / name).string(); }

  static Result Run(const std::string& args) { return testing_util::RunArtex(args, *dir_); }

  // A 5-frame synthetic walk (no noise, 320 x 240 depth, the colour camera equal to the depth
  // camera so that it can pose as a registered TUM recording), made once.
  static const std::string& Synthetic() {
    static const std::string folder = [] {
      SynthOptions options = testing_util::SmallSequenceOptions(kFrames);
      options.kinect.SetNoiseLevel(NoiseLevel::kOff);
      options.kinect.color_width = 320;
      options.kinect.color_height = 240;
      options.kinect.color_vertical_fov_deg = 2 * std::atan(120.0 / 262.5) * 180.0 / M_PI;
      options.kinect.color_offset_m = Eigen::Vector3d::Zero();
      options.kinect.color_yaw_deg = 0;
      options.kinect.color_pitch_deg = 0;
      options.background_frames = 3;
      const std::string out = Path("synthetic");
      SynthesizeSequence(options, out);
      return out;
    }();
    return folder;
  }

  // The synthetic sequence in TUM layout: rgb.txt, depth.txt, camera.yaml, depth in 5000
  // units per metre, colour 8 ms after depth; `extra` lines are appended to rgb.txt.
  static std::string WriteTum(const std::string& name, const std::string& extra = "") {
    const std::string folder = Path(name);
    fs::create_directories(folder + "/rgb");
    fs::create_directories(folder + "/depth");
    SequenceReader reader(Synthetic());
    const Calibration& c = reader.calibration();
    std::ofstream rgb(folder + "/rgb.txt"), depth(folder + "/depth.txt");
    rgb << "# color images\n# timestamp filename\n";
    depth << "# depth maps\n# timestamp filename\n";
    rgb << std::fixed << std::setprecision(6);
    depth << std::fixed << std::setprecision(6);
    for (int i = 0; i < reader.num_frames(); ++i) {
      Frame f;
      std::string warning;
      EXPECT_TRUE(reader.ReadFrame(i, &f, &warning)) << warning;
      cv::Mat tum_depth;
      f.depth.convertTo(tum_depth, CV_16UC1, 5000.0 / c.depth_scale);
      const double t = 1000.0 + i / 30.0;
      char name_buf[64];
      std::snprintf(name_buf, sizeof(name_buf), "%.6f.png", t);
      cv::imwrite(folder + "/depth/" + name_buf, tum_depth);
      std::snprintf(name_buf, sizeof(name_buf), "%.6f.png", t + 0.008);
      cv::imwrite(folder + "/rgb/" + name_buf, f.color);
      depth << t << " depth/" << std::fixed << std::setprecision(6) << t << ".png\n";
      rgb << t + 0.008 << " rgb/" << t + 0.008 << ".png\n";
    }
    rgb << extra;
    std::ofstream(folder + "/camera.yaml")
        << "width: " << c.depth.width << "\nheight: " << c.depth.height << "\nfx: " << c.depth.fx
        << "\nfy: " << c.depth.fy << "\ncx: " << c.depth.cx << "\ncy: " << c.depth.cy << "\n";
    return folder;
  }

  static fs::path* dir_;
};

fs::path* InputCliTest::dir_ = nullptr;

// Every depth pixel of `a` equals `b`'s, frame by frame, after scaling to metres.
void ExpectSameDepth(FrameSource* a, FrameSource* b) {
  ASSERT_EQ(a->num_frames(), b->num_frames());
  for (int i = 0; i < a->num_frames(); ++i) {
    Frame fa, fb;
    std::string warning;
    ASSERT_TRUE(a->ReadFrame(i, &fa, &warning)) << warning;
    ASSERT_TRUE(b->ReadFrame(i, &fb, &warning)) << warning;
    EXPECT_EQ(fa.index, fb.index);
    EXPECT_DOUBLE_EQ(fa.depth_timestamp, fb.depth_timestamp);
    cv::Mat da, db;
    fa.depth.convertTo(da, CV_64F, 1.0 / a->calibration().depth_scale);
    fb.depth.convertTo(db, CV_64F, 1.0 / b->calibration().depth_scale);
    EXPECT_EQ(cv::norm(da, db, cv::NORM_INF), 0.0) << "frame " << i;
    EXPECT_EQ(cv::norm(fa.color, fb.color, cv::NORM_INF), 0.0) << "frame " << i;
  }
}

TEST_F(InputCliTest, ImportsAnArtexSequenceWithItsGroundTruth) {
  const std::string out = Path("imported_artex");
  const Result r = Run("import -q '" + Synthetic() + "' -o '" + out + "'");
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.out.find(std::to_string(kFrames) + " frames written"), std::string::npos) << r.out;
  SequenceReader source(Synthetic()), copy(out);
  ExpectSameDepth(&source, &copy);
  EXPECT_TRUE(copy.has_ground_truth());
  EXPECT_FALSE(copy.GroundTruthSubjectPath().empty());
  EXPECT_EQ(copy.ReadBackgroundFrames().size(), source.ReadBackgroundFrames().size());
  EXPECT_TRUE(copy.calibration().depth.world_to_camera.isApprox(
      source.calibration().depth.world_to_camera));
  // --max-frames, and an existing output is refused.
  const Result partial =
      Run("import -q '" + Synthetic() + "' -o '" + Path("two") + "' --max-frames 2");
  ASSERT_EQ(partial.status, 0) << partial.err;
  EXPECT_EQ(SequenceReader(Path("two")).num_frames(), 2);
  const Result again = Run("import -q '" + Synthetic() + "' -o '" + out + "'");
  EXPECT_NE(again.status, 0);
  EXPECT_NE(again.err.find(out), std::string::npos) << again.err;
}

TEST_F(InputCliTest, ImportsATumFolderWithTheSameDepthPixels) {
  // One listed colour file is missing: its frame is skipped with a warning and counted.
  const std::string tum = WriteTum("tum_import", "2000.000000 rgb/late.png\n");
  fs::remove(tum + "/rgb/1000.041333.png");  // frame 1's colour
  const std::string out = Path("imported_tum");
  const Result r = Run("import '" + tum + "' -o '" + out + "' --world-frame calibration");
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.err.find("TUM RGB-D folder"), std::string::npos) << r.err;  // what was inferred
  EXPECT_NE(r.err.find("1 colour unpaired"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("1000.041333.png: missing frame file"), std::string::npos) << r.err;
  EXPECT_NE(r.out.find(std::to_string(kFrames - 1) + " frames written"), std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("1 skipped"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("world frame: camera frame"), std::string::npos) << r.out;
  SequenceReader copy(out);
  ASSERT_EQ(copy.num_frames(), kFrames - 1);
  EXPECT_EQ(copy.calibration().depth_scale, 5000.0);
  EXPECT_TRUE(copy.calibration().depth.world_to_camera.matrix().isIdentity(0));
  TumReader source(tum);
  int row = 0;
  for (int i = 0; i < source.num_frames(); ++i) {
    Frame a, b;
    std::string warning;
    if (!source.ReadFrame(i, &a, &warning)) continue;
    ASSERT_TRUE(copy.ReadFrame(row++, &b, &warning)) << warning;
    EXPECT_EQ(b.index, i);
    EXPECT_EQ(cv::norm(a.depth, b.depth, cv::NORM_INF), 0.0) << "frame " << i;
  }
  EXPECT_EQ(row, kFrames - 1);
  // The synthetic depth survives the trip in metres (1000 -> 5000 units: exact).
  SequenceReader synthetic(Synthetic());
  Frame s, c;
  std::string warning;
  ASSERT_TRUE(synthetic.ReadFrame(0, &s, &warning));
  ASSERT_TRUE(copy.ReadFrame(0, &c, &warning));
  ASSERT_EQ(synthetic.calibration().depth_scale, 1000.0);
  cv::Mat scaled;
  s.depth.convertTo(scaled, CV_32S, 5.0);
  cv::Mat copied;
  c.depth.convertTo(copied, CV_32S);
  EXPECT_EQ(cv::norm(scaled, copied, cv::NORM_INF), 0.0);
}

TEST_F(InputCliTest, ImportEstimatesAWorldFrameWithYUp) {
  // A TUM folder is in the camera frame; import estimates a world frame from the floor of the
  // first frame whose up direction is the synthetic world's +Y.
  const std::string tum = WriteTum("tum_world");
  const std::string out = Path("imported_world");
  const Result r = Run("import -q '" + tum + "' -o '" + out + "'");
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.out.find("world frame: estimated from frame 0"), std::string::npos) << r.out;
  const Calibration estimated = SequenceReader(out).calibration();
  const Calibration truth = SequenceReader(Synthetic()).calibration();
  const Eigen::Vector3d up_estimated =
      estimated.depth.world_to_camera.linear() * Eigen::Vector3d::UnitY();
  const Eigen::Vector3d up_true = truth.depth.world_to_camera.linear() * Eigen::Vector3d::UnitY();
  const double angle_deg = std::acos(std::min(1.0, up_estimated.dot(up_true))) * 180.0 / M_PI;
  EXPECT_LT(angle_deg, 2.0);
  std::printf("import: estimated up %.2f deg from the true one\n", angle_deg);
  EXPECT_TRUE(estimated.color.world_to_camera.isApprox(estimated.depth.world_to_camera, 1e-9));
}

TEST_F(InputCliTest, BadInputGivesClearErrors) {
  // Neither layout.
  fs::create_directories(Path("nothing"));
  Result r = Run("import '" + Path("nothing") + "' -o '" + Path("nothing_out") + "'");
  EXPECT_EQ(r.status, 1);
  EXPECT_NE(r.err.find("rgb.txt"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("calibration.yaml"), std::string::npos) << r.err;
  // TUM without camera.yaml: names the keys and the presets; a preset then works.
  const std::string tum = WriteTum("tum_no_camera");
  fs::remove(tum + "/camera.yaml");
  r = Run("track -q '" + tum + "' -o '" + Path("no_camera_run") + "'");
  EXPECT_EQ(r.status, 1);
  EXPECT_NE(r.err.find("camera.yaml"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("fx"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("--intrinsics"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("kinect"), std::string::npos) << r.err;
  r = Run("import -q '" + tum + "' -o '" + Path("kinect_out") + "' --intrinsics kinect");
  EXPECT_NE(r.status, 0);  // 320 x 240 frames do not fit the 640 x 480 preset: all skipped
  EXPECT_NE(r.err.find("640x480"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("no readable frame"), std::string::npos) << r.err;
  r = Run("track -q '" + tum + "' -o '" + Path("bad_preset") + "' --intrinsics fr9");
  EXPECT_EQ(r.status, 1);
  EXPECT_NE(r.err.find("fr9"), std::string::npos) << r.err;
  // Out-of-order timestamps: file, line, expected, found.
  const std::string order = WriteTum("tum_order", "999.000000 rgb/early.png\n");
  r = Run("import -q '" + order + "' -o '" + Path("order_out") + "'");
  EXPECT_EQ(r.status, 1);
  EXPECT_NE(r.err.find("rgb.txt: line " + std::to_string(3 + kFrames)), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("increasing"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("999.000000"), std::string::npos) << r.err;
  // Nothing pairs: the counts.
  r = Run("import -q '" + WriteTum("tum_offset") + "' -o '" + Path("offset_out") +
          "' -s input.time_offset=1.0");
  EXPECT_EQ(r.status, 1);
  EXPECT_NE(r.err.find("all " + std::to_string(kFrames) + " depth and " + std::to_string(kFrames) +
                       " colour entries are unpaired"),
            std::string::npos)
      << r.err;
}

TEST_F(InputCliTest, TrackRunsOnATumFolder) {
  const std::string tum = WriteTum("tum_track");
  const std::string out = Path("tum_run");
  const Result r = Run("track '" + tum + "' -o '" + out + "' --intrinsics '" + tum +
                       "/camera.yaml' --no-texture -s pipeline.export_glb=false");
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.err.find("track: input: TUM RGB-D folder"), std::string::npos) << r.err;
  EXPECT_NE(r.out.find("frames: " + std::to_string(kFrames)), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("0 skipped"), std::string::npos) << r.out;
  const std::string poses = ReadFileBytes(fs::path(out) / "poses.csv");
  EXPECT_EQ(CountLines(poses), kFrames + 1) << poses;  // header + one row per frame
  // --intrinsics FILE is recorded in the run's configuration (absolute path).
  EXPECT_NE(ReadFileBytes(fs::path(out) / "config.yaml")
                .find(fs::absolute(tum).string() + "/camera.yaml"),
            std::string::npos);
  // The overlay finds the recording through the run (summary.json) and reads it as TUM.
  const Result overlay = Run("overlay -q '" + out + "' -o '" + Path("tum_overlay") + "'");
  ASSERT_EQ(overlay.status, 0) << overlay.err;
  EXPECT_TRUE(fs::exists(Path("tum_overlay") + "/000004.png"));
  EXPECT_EQ(cv::imread(Path("tum_overlay") + "/overview.png").cols, 3 * 320);
  // The TUM options through --set and the config: a window that pairs nothing fails clearly.
  const Result narrow = Run("track -q '" + tum + "' -o '" + Path("narrow") +
                            "' --no-texture -s input.max_time_difference=0.001");
  EXPECT_EQ(narrow.status, 1);
  EXPECT_NE(narrow.err.find("unpaired"), std::string::npos) << narrow.err;
}

// pipeline.huge_pages: `artex track` restarts itself once with glibc's heap on transparent
// huge pages where the C library and the kernel allow it (experiments/heap_retention.h), and
// realtime.json says whether the run had them; off, it runs on the ordinary heap (unless the
// kernel puts every heap on huge pages).
TEST_F(InputCliTest, TrackPutsTheHeapOnHugePagesWhereAvailable) {
  const std::string tum = WriteTum("tum_huge_pages");
  const auto huge_page_heap = [&](const std::string& on, const std::string& name) {
    const std::string out = Path(name);
    const Result r = Run("track -q '" + tum + "' -o '" + out + "' --intrinsics '" + tum +
                         "/camera.yaml' --no-texture -s pipeline.export_glb=false "
                         "-s pipeline.huge_pages=" + on);
    EXPECT_EQ(r.status, 0) << r.err;
    const std::string json = ReadFileBytes(fs::path(out) / "realtime.json");
    EXPECT_NE(json.find("\"huge_page_heap\""), std::string::npos) << json;
    // The run's output appears once: the restart happens before anything is written.
    EXPECT_NE(r.out.find("results in"), std::string::npos) << r.out;
    EXPECT_EQ(r.out.find("results in"), r.out.rfind("results in")) << r.out;
    return json.find("\"huge_page_heap\": true") != std::string::npos;
  };
  const std::string mode = fs::exists("/sys/kernel/mm/transparent_hugepage/enabled")
                               ? ReadFileBytes("/sys/kernel/mm/transparent_hugepage/enabled")
                               : std::string();
  const bool everywhere = mode.find("[always]") != std::string::npos;
  EXPECT_EQ(huge_page_heap("true", "huge_pages_on"), HugePageHeapAvailable());
  EXPECT_EQ(huge_page_heap("false", "huge_pages_off"), everywhere);
}

// Without a template file the default template comes from the cache folder: the first run of
// this build writes it, later runs read it and track the same; off, nothing is written; a damaged
// file is replaced with a warning naming it (models/template_cache.h).
TEST_F(InputCliTest, TrackKeepsTheDefaultTemplateInTheCacheFolder) {
  const std::string tum = WriteTum("tum_template_cache");
  const auto track = [&](const std::string& name, const std::string& sets) {
    const std::string out = Path(name);
    const Result r = Run("track -q '" + tum + "' -o '" + out + "' --intrinsics '" + tum +
                         "/camera.yaml' --no-texture -s pipeline.export_glb=false " + sets);
    EXPECT_EQ(r.status, 0) << r.err;
    return std::make_pair(r, ReadFileBytes(fs::path(out) / "poses.csv"));
  };
  const auto cached_files = [](const fs::path& dir) {
    std::vector<fs::path> files;
    if (!fs::exists(dir)) return files;
    for (const auto& e : fs::directory_iterator(dir)) files.push_back(e.path());
    return files;
  };
  const fs::path cache = Path("template_cache");
  const std::string in_cache = "-s pipeline.template_cache_dir='" + cache.string() + "'";
  const auto [first, poses] = track("template_cache_1", in_cache);
  ASSERT_FALSE(poses.empty());
  const std::vector<fs::path> files = cached_files(cache);
  ASSERT_EQ(files.size(), 1u);
  EXPECT_EQ(files[0].extension(), ".bin");
  const auto written = fs::last_write_time(files[0]);
  // Read back, not written again: the same poses.
  EXPECT_EQ(track("template_cache_2", in_cache).second, poses);
  EXPECT_EQ(fs::last_write_time(files[0]), written);
  // Off: generated, nothing written, the same poses.
  const fs::path unused = Path("template_cache_unused");
  EXPECT_EQ(track("template_cache_off", "-s pipeline.template_cache=false "
                                        "-s pipeline.template_cache_dir='" + unused.string() + "'")
                .second,
            poses);
  EXPECT_TRUE(cached_files(unused).empty());
  // Damaged: the run warns naming the file, tracks the same and repairs it.
  std::ofstream(files[0], std::ios::binary | std::ios::trunc) << "ARTEXTPL damaged";
  const auto [repaired, repaired_poses] = track("template_cache_damaged", in_cache);
  EXPECT_EQ(repaired_poses, poses);
  EXPECT_NE(repaired.err.find(files[0].filename().string()), std::string::npos) << repaired.err;
  EXPECT_GT(fs::file_size(files[0]), 100000u);
  // A bad value is an error naming the key.
  const Result bad = Run("track -q '" + tum + "' -o '" + Path("template_cache_bad") +
                         "' --intrinsics '" + tum + "/camera.yaml' -s pipeline.template_cache_keep=0");
  EXPECT_NE(bad.status, 0);
  EXPECT_NE(bad.err.find("pipeline.template_cache_keep"), std::string::npos) << bad.err;
}

TEST_F(InputCliTest, ExperimentRunsARecordedTumFolder) {
  const std::string tum = WriteTum("tum_experiment");
  const std::string file = Path("tum_experiment.yaml");
  std::ofstream(file) << "base: {pipeline: {texture: false, export_glb: false, huge_pages: true}}\n"
                      << "sequences:\n  - {name: lab, path: '" << tum << "'}\n";
  const std::string out = Path("tum_experiment_out");
  const Result r =
      Run("experiment '" + file + "' -o '" + out + "' --jobs 1 --threads-per-run 1 --no-plots");
  ASSERT_EQ(r.status, 0) << r.err;
  // One run of the recorded sequence, with its poses and a row in results.csv.
  bool found = false;
  for (const auto& e : fs::recursive_directory_iterator(fs::path(out) / "runs" / "lab")) {
    if (e.path().filename() == "poses.csv") {
      EXPECT_EQ(CountLines(ReadFileBytes(e.path())), kFrames + 1);
      found = true;
      // The run's process put its heap on huge pages as `artex track` does with
      // pipeline.huge_pages on.
      const std::string realtime = ReadFileBytes(e.path().parent_path() / "realtime.json");
      EXPECT_EQ(realtime.find("\"huge_page_heap\": true") != std::string::npos,
                HugePageHeapAvailable())
          << realtime;
    }
  }
  EXPECT_TRUE(found);
  EXPECT_NE(ReadFileBytes(fs::path(out) / "results.csv").find(",lab,"), std::string::npos);
}

TEST_F(InputCliTest, ImportsTheRealSkeltrackRecordingInPlace) {
  const std::string real = std::string(ARTEX_SHARED_DATA) + "/real/skeltrack";
  if (!fs::is_directory(real)) GTEST_SKIP() << real << " is absent";
  const std::string out = Path("skeltrack");
  const Result r = Run("import -q '" + real + "' -o '" + out + "' --max-frames 4");
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.err.find("TUM RGB-D folder"), std::string::npos) << r.err;
  TumReader source(real);
  SequenceReader copy(out);
  ASSERT_EQ(copy.num_frames(), std::min(4, source.num_frames()));
  EXPECT_EQ(copy.calibration().depth.width, source.calibration().depth.width);
  EXPECT_EQ(copy.calibration().depth.fx, source.calibration().depth.fx);
  int nonzero = 0;
  for (int i = 0; i < copy.num_frames(); ++i) {
    Frame a, b;
    std::string warning;
    ASSERT_TRUE(source.ReadFrame(i, &a, &warning)) << warning;
    ASSERT_TRUE(copy.ReadFrame(i, &b, &warning)) << warning;
    EXPECT_EQ(cv::norm(a.depth, b.depth, cv::NORM_INF), 0.0) << "frame " << i;
    nonzero += cv::countNonZero(b.depth);
  }
  EXPECT_GT(nonzero, 0);
}

}  // namespace
}  // namespace artex
