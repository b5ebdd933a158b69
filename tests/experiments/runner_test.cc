#include "experiments/runner.h"

#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "experiments/runner_internal.h"
#include "models/error.h"
#include "models/template_cache.h"
#include "models/template_generator.h"
#include "tests/error_of.h"
#include "tests/testing_util.h"

namespace artex {
namespace {
namespace fs = std::filesystem;
using testing_util::ReadFileBytes;

fs::path FreshDir(const std::string& name) {
  return testing_util::FreshTempDir("runner_test_" + name);
}

void WriteText(const fs::path& path, const std::string& text) {
  std::ofstream out(path);
  out << text;
}

const char* kSynthSequences =
    "sequences:\n"
    "  - {name: a, synth: {motion: walk, frames: 2}}\n"
    "  - {name: b, synth: {motion: arm_raise, frames: 2, seed: 3, noise: high}}\n";

Experiment Parse(const std::string& body) {
  return ParseExperiment(std::string(kSynthSequences) + body, "exp.yaml", "");
}

TEST(ExperimentParseTest, GridExpandsEveryCombinationLastKeyFastest) {
  const Experiment ex = Parse(
      "base: {texture: {alpha: 0.25}}\n"
      "grid:\n  texture.lambda: [0, 0.5]\n  fitting.solver: [gauss_newton, ceres_lm]\n");
  ASSERT_EQ(ex.sequences.size(), 2u);
  EXPECT_TRUE(ex.sequences[1].synthetic);
  EXPECT_EQ(ex.sequences[1].name, "b");
  ASSERT_EQ(ex.keys, (std::vector<std::string>{"texture.lambda", "fitting.solver"}));
  ASSERT_EQ(ex.combinations.size(), 4u);
  EXPECT_EQ(ex.combinations[0].id, "texture.lambda=0,fitting.solver=gauss_newton");
  EXPECT_EQ(ex.combinations[1].id, "texture.lambda=0,fitting.solver=ceres_lm");
  EXPECT_EQ(ex.combinations[3].id, "texture.lambda=0.5,fitting.solver=ceres_lm");
  const Config c = CombinationConfig(ex, ex.combinations[3]);
  double lambda = -1, alpha = -1;
  std::string solver;
  c.Section("texture").Get("lambda", &lambda);
  c.Section("texture").Get("alpha", &alpha);
  c.Section("fitting").Get("solver", &solver);
  EXPECT_DOUBLE_EQ(lambda, 0.5);
  EXPECT_DOUBLE_EQ(alpha, 0.25);  // base kept
  EXPECT_EQ(solver, "ceres_lm");
}

TEST(ExperimentParseTest, ListEntriesTimesGrid) {
  const Experiment ex = Parse(
      "list:\n  - {fitting.correspondence: one_to_many}\n"
      "  - {fitting.correspondence: one_to_one, fitting.solver: ceres_lm}\n"
      "grid: {texture.beta: [0.2, 0.8]}\n");
  ASSERT_EQ(ex.combinations.size(), 4u);
  EXPECT_EQ(ex.keys, (std::vector<std::string>{"fitting.correspondence", "fitting.solver", "texture.beta"}));
  EXPECT_EQ(ex.combinations[2].overrides.size(), 3u);
  EXPECT_EQ(ex.combinations[2].overrides[1].value, "ceres_lm");
}

// Issue 20: a million combinations hung --dry-run (each was expanded and validated).
TEST(ExperimentParseTest, GridSizeIsCappedBeforeExpansion) {
  std::string values = "[";
  for (int v = 0; v < 1000; ++v) values += (v ? ", " : "") + std::to_string(v);
  values += "]";
  const std::string msg = ErrorOf(
      [&] { Parse("grid:\n  texture.lambda: " + values + "\n  texture.alpha: " + values + "\n"); });
  EXPECT_NE(msg.find("exp.yaml"), std::string::npos) << msg;
  EXPECT_NE(msg.find("at most " + std::to_string(kMaxExperimentCombinations)), std::string::npos)
      << msg;
  EXPECT_NE(msg.find("1000 texture.alpha"), std::string::npos) << msg;
}

// Found by the experiment fuzzer: a mapping where a name is expected escaped as yaml-cpp's
// unnamed "bad conversion" (and aborted `artex experiment`).
TEST(ExperimentParseTest, ValuesOfTheWrongShapeNameTheFileAndLine) {
  const std::string msg = ErrorOf([] { Parse("name: {a: 1}\n"); });
  EXPECT_NE(msg.find("exp.yaml"), std::string::npos) << msg;
  EXPECT_NE(msg.find("line 4"), std::string::npos) << msg;  // after 3 lines of sequences
}

TEST(ExperimentParseTest, NoOverridesGivesTheBaseConfiguration) {
  const Experiment ex = Parse("");
  ASSERT_EQ(ex.combinations.size(), 1u);
  EXPECT_EQ(ex.combinations[0].id, "base");
}

TEST(ExperimentParseTest, UnknownOverrideKeyListsValidKeys) {
  const std::string msg = ErrorOf([] { Parse("grid: {texture.lamda: [0, 1]}\n"); });
  EXPECT_NE(msg.find("exp.yaml"), std::string::npos) << msg;
  EXPECT_NE(msg.find("texture.lamda"), std::string::npos) << msg;
  EXPECT_NE(msg.find("lambda"), std::string::npos) << msg;
  EXPECT_NE(msg.find("t_max"), std::string::npos) << msg;
}

TEST(ExperimentParseTest, WrongTypeNamesKeyAndValue) {
  const std::string msg = ErrorOf([] { Parse("grid: {texture.lambda: [0, abc]}\n"); });
  EXPECT_NE(msg.find("texture.lambda"), std::string::npos) << msg;
  EXPECT_NE(msg.find("abc"), std::string::npos) << msg;
}

TEST(ExperimentParseTest, UnknownChoiceListsValidChoices) {
  const std::string msg = ErrorOf([] { Parse("grid: {fitting.solver: [gauss_newton, newton]}\n"); });
  EXPECT_NE(msg.find("newton"), std::string::npos) << msg;
  EXPECT_NE(msg.find("ceres_lm"), std::string::npos) << msg;
}

TEST(ExperimentParseTest, InvalidValueIsRejectedBeforeRunning) {
  const std::string msg = ErrorOf([] { Parse("grid: {pipeline.max_frames: [-1]}\n"); });
  EXPECT_NE(msg.find("max_frames"), std::string::npos) << msg;
}

// The depth sensor's effects one by one (docs/synthesis.md), over the noise preset.
TEST(ExperimentParseTest, SynthSpecSetsTheDepthEffects) {
  const runner_internal::SynthSpec spec = runner_internal::SynthSpecFromConfig(Config::FromString(
      "noise: off\nedge_drop_probability: 0.6\ngrazing_angle_deg: 78\n"
      "projector_shadow: true\ndisparity_step_px: 0.25\n",
      "synth.yaml"));
  const DepthNoiseOptions& d = spec.options.kinect.depth_noise;
  EXPECT_EQ(d.edge_drop_probability, 0.6);
  EXPECT_EQ(d.grazing_angle_deg, 78.0);
  EXPECT_TRUE(d.projector_shadow);
  EXPECT_EQ(d.disparity_step_px, 0.25);
  EXPECT_EQ(d.disparity_noise_px, 0.0) << "the off preset's";
}

TEST(ExperimentParseTest, BadSynthSpecListsValidKeys) {
  std::string msg = ErrorOf([] {
    ParseExperiment("sequences:\n  - {synth: {motion: walk, frame: 3}}\n", "exp.yaml", "");
  });
  EXPECT_NE(msg.find("frame"), std::string::npos) << msg;
  EXPECT_NE(msg.find("frames"), std::string::npos) << msg;
  EXPECT_NE(msg.find("outlier_fraction"), std::string::npos) << msg;
  msg = ErrorOf([] { ParseExperiment("sequences:\n  - {synth: {motion: dance}}\n", "exp.yaml", ""); });
  EXPECT_NE(msg.find("dance"), std::string::npos) << msg;
  EXPECT_NE(msg.find("arm_raise"), std::string::npos) << msg;
}

TEST(ExperimentParseTest, SynthConditionKeys) {
  const Experiment e = ParseExperiment(
      "sequences:\n  - {synth: {motion: walk, frames: 2, condition: 'room, facing_away',"
      " camera_roll_deg: 10, world_frame: camera, boxes: 2, second_person: true}}\n",
      "exp.yaml", "");
  ASSERT_EQ(e.sequences.size(), 1u);
  EXPECT_NE(e.sequences[0].name.find("room"), std::string::npos) << e.sequences[0].name;
  std::string msg = ErrorOf([] {
    ParseExperiment("sequences:\n  - {synth: {motion: walk, condition: kitchen}}\n", "exp.yaml", "");
  });
  EXPECT_NE(msg.find("condition"), std::string::npos) << msg;
  EXPECT_NE(msg.find("kitchen"), std::string::npos) << msg;
  EXPECT_NE(msg.find("upper_body"), std::string::npos) << msg;
  msg = ErrorOf([] {
    ParseExperiment("sequences:\n  - {synth: {motion: walk, world_frame: world}}\n", "exp.yaml", "");
  });
  EXPECT_NE(msg.find("world_frame"), std::string::npos) << msg;
  msg = ErrorOf([] {
    ParseExperiment("sequences:\n  - {synth: {motion: walk, camera_roll_deg: 400}}\n", "exp.yaml", "");
  });
  EXPECT_NE(msg.find("depth_roll_deg"), std::string::npos) << msg;
}

TEST(ExperimentParseTest, SynthSubjectTemplateIsResolvedAgainstTheExperimentFile) {
  const Experiment e = ParseExperiment(
      "sequences:\n  - {synth: {motion: walk, frames: 2, subject_template: bodies/mh.glb}}\n",
      "exp.yaml", "/data/exp");
  ASSERT_EQ(e.sequences.size(), 1u);
  EXPECT_NE(e.sequences[0].synth_yaml.find("/data/exp/bodies/mh.glb"), std::string::npos)
      << e.sequences[0].synth_yaml;
  EXPECT_EQ(e.sequences[0].name, "walk_mh_f2") << e.sequences[0].name;
}

TEST(ExperimentParseTest, StructuralErrors) {
  EXPECT_NE(ErrorOf([] { Parse("grids: {texture.lambda: [0]}\n"); }).find("valid keys"), std::string::npos);
  EXPECT_NE(ErrorOf([] {
              ParseExperiment("sequences:\n  - {name: x, synth: {frames: 2}}\n  - {name: x, synth: {frames: 3}}\n",
                              "exp.yaml", "");
            }).find("duplicate sequence"),
            std::string::npos);
  EXPECT_NE(ErrorOf([] { ParseExperiment("sequences: []\n", "exp.yaml", ""); }).find("sequences"),
            std::string::npos);
  EXPECT_NE(ErrorOf([] { ParseExperiment("sequences: [/no/such/folder]\n", "exp.yaml", ""); })
                .find("/no/such/folder"),
            std::string::npos);
  EXPECT_NE(ErrorOf([] {
              Parse("list: [{texture.lambda: 1}]\ngrid: {texture.lambda: [0, 1]}\n");
            }).find("texture.lambda"),
            std::string::npos);
}

TEST(ExperimentParseTest, RecordedSequencesAreArtexOrTumFolders) {
  const fs::path dir = FreshDir("recorded");
  fs::create_directories(dir / "tum");
  WriteText(dir / "tum" / "rgb.txt", "1.0 rgb/a.png\n");
  WriteText(dir / "tum" / "depth.txt", "1.0 depth/a.png\n");
  fs::create_directories(dir / "other");
  WriteText(dir / "other" / "notes.txt", "x\n");
  const Experiment ex = ParseExperiment(
      "base: {input: {intrinsics: kinect}}\nsequences:\n  - {name: lab, path: tum}\n", "exp.yaml",
      dir.string());
  ASSERT_EQ(ex.sequences.size(), 1u);
  EXPECT_EQ(ex.sequences[0].folder, (dir / "tum").string());
  const std::string msg = ErrorOf(
      [&] { ParseExperiment("sequences: [other]\n", "exp.yaml", dir.string()); });
  EXPECT_NE(msg.find("other"), std::string::npos) << msg;
  EXPECT_NE(msg.find("rgb.txt"), std::string::npos) << msg;
  EXPECT_NE(msg.find("calibration.yaml"), std::string::npos) << msg;
}

TEST(ExperimentParseTest, BaseFileIsResolvedAgainstTheExperimentFile) {
  const fs::path dir = FreshDir("base");
  WriteText(dir / "base.yaml", "texture:\n  lambda: 2.5\n");
  WriteText(dir / "exp.yaml", std::string("base: base.yaml\n") + kSynthSequences);
  const Experiment ex = LoadExperiment((dir / "exp.yaml").string());
  double lambda = 0;
  CombinationConfig(ex, ex.combinations[0]).Section("texture").Get("lambda", &lambda);
  EXPECT_DOUBLE_EQ(lambda, 2.5);
  WriteText(dir / "bad.yaml", "texture:\n  lambda: [1]\n");
  WriteText(dir / "exp2.yaml", std::string("base: bad.yaml\n") + kSynthSequences);
  const std::string msg = ErrorOf([&] { LoadExperiment((dir / "exp2.yaml").string()); });
  EXPECT_NE(msg.find("bad.yaml"), std::string::npos) << msg;
  fs::remove_all(dir);
}

TEST(ExperimentParseTest, MetricsHaveUniqueNamesAndDirections) {
  std::map<std::string, int> seen;
  for (const auto& m : Metrics()) EXPECT_EQ(seen[m.name]++, 0) << m.name;
  ASSERT_NE(FindMetric("mean_vertex_error_mm"), nullptr);
  EXPECT_TRUE(FindMetric("mean_vertex_error_mm")->lower_is_better);
  EXPECT_FALSE(FindMetric("converged_fraction")->lower_is_better);
  EXPECT_TRUE(FindMetric("fit_ms")->timing);
  EXPECT_EQ(FindMetric("no_such_metric"), nullptr);
}

// ---- end to end through the artex binary -------------------------------------------------------

// The smallest useful experiment: 2 synthetic sequences of 3 frames (320 x 240 depth, small
// colour images, coarse subject and template, 128^2 atlas) x 2 smoothness weights.
const char* kTinyExperiment =
    "name: tiny\n"
    "base:\n"
    "  texture: {atlas_size: 128}\n"
    "  fitting: {max_fit_vertices: 800}\n"
    "template: {resolution: 0, atlas_size: 256}\n"
    "sequences:\n"
    "  - {name: walk, synth: {motion: walk, frames: 3, seed: 1, subject_resolution: 0,"
    " texture_size: 256, color_width: 200, color_height: 254, depth_width: 320,"
    " depth_height: 240, background_frames: 5}}\n"
    "  - {name: arms, synth: {motion: arm_raise, frames: 3, seed: 2, subject_resolution: 0,"
    " texture_size: 256, color_width: 200, color_height: 254, depth_width: 320,"
    " depth_height: 240, background_frames: 5, outlier_fraction: 0.01}}\n"
    "grid:\n"
    "  texture.lambda: [0, 1]\n";

std::string ArtexCommand(const fs::path& file, const fs::path& out, int jobs) {
  return std::string(ARTEX_BINARY) + " experiment " + file.string() + " -o " + out.string() +
         " --jobs " + std::to_string(jobs) + " --threads-per-run 1 --no-plots";
}

// (sequence, lambda, metric) -> value of the non-timing metrics; fails on duplicate rows.
std::map<std::string, std::string> ReadResults(const fs::path& csv) {
  std::map<std::string, std::string> rows;
  std::ifstream in(csv);
  std::string line;
  std::getline(in, line);
  EXPECT_EQ(line, "experiment,sequence,texture.lambda,metric,value");
  while (std::getline(in, line)) {
    std::vector<std::string> f;
    std::stringstream ss(line);
    std::string cell;
    while (std::getline(ss, cell, ',')) f.push_back(cell);
    if (f.size() != 5) {
      ADD_FAILURE() << "malformed row: " << line;
      continue;
    }
    const MetricInfo* info = FindMetric(f[3]);
    EXPECT_NE(info, nullptr) << f[3];
    if (info == nullptr || info->timing) continue;
    const std::string key = f[1] + "|" + f[2] + "|" + f[3];
    EXPECT_EQ(rows.count(key), 0u) << "duplicate row " << key;
    rows[key] = f[4];
  }
  return rows;
}

int CountDone(const fs::path& out) {
  int n = 0;
  std::error_code ec;
  if (!fs::is_directory(out / "runs", ec)) return 0;
  for (const auto& e : fs::recursive_directory_iterator(out / "runs", ec)) {
    if (e.path().filename() == "DONE" &&
        e.path().parent_path().filename().string().rfind(".", 0) != 0) {
      ++n;
    }
  }
  return n;
}

TEST(ExperimentRunTest, KilledRunResumesWithIdenticalResultsAndRerunSkips) {
  const fs::path dir = FreshDir("run");
  const fs::path file = dir / "tiny.yaml";
  WriteText(file, kTinyExperiment);

  // Reference: uninterrupted, two runs at a time.
  ASSERT_EQ(std::system(
                (ArtexCommand(file, dir / "ref", 2) + " 2>" + (dir / "ref.log").string()).c_str()),
            0)
      << ReadFileBytes(dir / "ref.log");
  const auto reference = ReadResults(dir / "ref" / "results.csv");
  ASSERT_FALSE(reference.empty());
  EXPECT_EQ(CountDone(dir / "ref"), 4);
  EXPECT_TRUE(reference.count("walk|0|mean_vertex_error_mm"));
  EXPECT_TRUE(reference.count("arms|1|seam_rms_after"));
  EXPECT_TRUE(fs::exists(dir / "ref" / "summary.md"));
  EXPECT_NE(ReadFileBytes(dir / "ref" / "summary.md").find("mean_vertex_error_mm"),
            std::string::npos);
  const std::string run_json =
      ReadFileBytes(dir / "ref" / "runs" / "walk" / "texture.lambda=1" / "run.json");
  EXPECT_NE(run_json.find("git_revision"), std::string::npos);
  EXPECT_TRUE(fs::exists(dir / "ref" / "runs" / "walk" / "texture.lambda=1" / "trace.csv"));
  EXPECT_TRUE(fs::exists(dir / "ref" / "runs" / "walk" / "texture.lambda=1" / "config.yaml"));
  // The runs track with the generated template bit for bit (as `artex track` does): its .bin
  // beside the .glb to look at, named in run.json.
  int bins = 0;
  for (const auto& e : fs::directory_iterator(dir / "ref" / "templates")) {
    if (e.path().extension() != ".bin") continue;
    ++bins;
    BodyShapeOptions shape;
    shape.resolution = 0;
    shape.atlas_size = 256;
    const Template generated = GenerateTemplate(shape);
    const Template used = ReadTemplateFile(e.path().string());
    EXPECT_TRUE(used.vertices == generated.vertices);
    EXPECT_TRUE(used.lbs_weight == generated.lbs_weight);
    EXPECT_TRUE(used.uvs == generated.uvs);
    EXPECT_TRUE(fs::exists(fs::path(e.path()).replace_extension(".glb")));
    EXPECT_NE(run_json.find(e.path().filename().string()), std::string::npos) << run_json;
  }
  EXPECT_EQ(bins, 1);

  // Interrupted: one run at a time, SIGKILL of the whole process group once a run is done.
  const fs::path out = dir / "killed";
  const std::string cmd = ArtexCommand(file, out, 1) + " 2>" + (dir / "killed.log").string();
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    setpgid(0, 0);
    execl("/bin/sh", "sh", "-c", cmd.c_str(), static_cast<char*>(nullptr));
    _exit(127);
  }
  setpgid(pid, pid);
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(120);
  bool exited = false;
  while (CountDone(out) < 1 && std::chrono::steady_clock::now() < deadline) {
    int status = 0;
    if (waitpid(pid, &status, WNOHANG) == pid) {
      exited = true;
      break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ASSERT_FALSE(exited) << "the runner ended before it could be interrupted: "
                       << ReadFileBytes(dir / "killed.log");
  kill(-pid, SIGKILL);
  int status = 0;
  waitpid(pid, &status, 0);
  const int done_at_kill = CountDone(out);
  EXPECT_GE(done_at_kill, 1);
  EXPECT_LT(done_at_kill, 4) << "nothing was interrupted";

  // Resume: completes the rest; identical (non-timing) results, no duplicates.
  ASSERT_EQ(
      std::system((ArtexCommand(file, out, 1) + " 2>" + (dir / "resume.log").string()).c_str()), 0)
      << ReadFileBytes(dir / "resume.log");
  const std::string resume_log = ReadFileBytes(dir / "resume.log");
  EXPECT_NE(resume_log.find(std::to_string(done_at_kill) + " already complete"), std::string::npos) << resume_log;
  EXPECT_EQ(CountDone(out), 4);
  EXPECT_EQ(ReadResults(out / "results.csv"), reference);
  // No temporary folders left behind.
  for (const auto& e : fs::directory_iterator(out / "runs" / "walk")) {
    EXPECT_NE(e.path().filename().string().rfind(".tmp-", 0), 0u) << e.path();
  }

  // Rerun: everything skipped, nothing recomputed.
  const auto done_time = fs::last_write_time(out / "runs" / "walk" / "texture.lambda=0" / "DONE");
  ASSERT_EQ(std::system((ArtexCommand(file, out, 2) + " 2>" + (dir / "rerun.log").string()).c_str()), 0);
  EXPECT_NE(ReadFileBytes(dir / "rerun.log").find("4 already complete"), std::string::npos)
      << ReadFileBytes(dir / "rerun.log");
  EXPECT_EQ(fs::last_write_time(out / "runs" / "walk" / "texture.lambda=0" / "DONE"), done_time);
  EXPECT_EQ(ReadResults(out / "results.csv"), reference);

  // A changed configuration under the same run name is refused rather than silently mixed.
  std::string changed = kTinyExperiment;
  changed.replace(changed.find("atlas_size: 128"), 15, "atlas_size: 64");
  WriteText(file, changed);
  const int rc = std::system((ArtexCommand(file, out, 1) + " 2>" + (dir / "changed.log").string()).c_str());
  EXPECT_NE(rc, 0);
  EXPECT_NE(ReadFileBytes(dir / "changed.log").find("different inputs"), std::string::npos)
      << ReadFileBytes(dir / "changed.log");
  // ... unless asked to recompute changed runs (the sequences are unchanged and reused).
  ASSERT_EQ(std::system((ArtexCommand(file, out, 2) + " --replace-changed 2>" +
                         (dir / "replaced.log").string())
                            .c_str()),
            0)
      << ReadFileBytes(dir / "replaced.log");
  EXPECT_EQ(CountDone(out), 4);
  EXPECT_NE(ReadFileBytes(dir / "replaced.log").find("0 already complete"), std::string::npos)
      << ReadFileBytes(dir / "replaced.log");
  EXPECT_NE(ReadFileBytes(out / "runs" / "arms" / "texture.lambda=1" / "run_config.yaml")
                .find("atlas_size: 64"),
            std::string::npos);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace artex
