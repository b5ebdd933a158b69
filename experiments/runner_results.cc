// Results of an experiment (experiments/runner.h): the metrics table, and OUT/results.csv
// (tidy: one row per run x metric) and OUT/summary.md (best configuration per metric, all
// configurations) from the completed runs.
#include <cmath>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "experiments/file_util.h"
#include "experiments/runner.h"
#include "experiments/runner_internal.h"
#include "models/error.h"
#include "sensors/sequence.h"

namespace artex {
namespace fs = std::filesystem;

namespace {

using runner_internal::CombinationLabel;
using runner_internal::FormatNumber;
using runner_internal::Mean;

std::string CsvField(const std::string& s) {
  if (s.find_first_of(",\"\n") == std::string::npos) return s;
  std::string out = "\"";
  for (char c : s) {
    if (c == '"') out += '"';
    out += c;
  }
  return out + "\"";
}

struct RunResult {
  const ExperimentSequence* sequence = nullptr;
  const ExperimentCombination* combination = nullptr;
  std::map<std::string, double> metrics;
};

}  // namespace

const std::vector<MetricInfo>& Metrics() {
  static const std::vector<MetricInfo> kMetrics = {
      {"mean_vertex_error_mm", true, false, "mean over evaluated frames (fitted, not failed) of the mean per-vertex distance to ground truth"},
      {"max_vertex_error_mm", true, false, "largest per-vertex distance to ground truth over all frames"},
      {"mean_joint_error_mm", true, false, "mean over evaluated frames of the mean joint-centre distance to ground truth"},
      {"final_vertex_error_mm", true, false, "mean per-vertex error of the last evaluated frame (drift)"},
      {"lost_frames", true, false, "failed fits and frames whose mean vertex error exceeds pipeline.lost_threshold_mm"},
      {"lost_fraction", true, false, "lost_frames / fitted frames (failed fits included)"},
      {"evaluated_frames", false, false, "frames the ground-truth errors average over (fitted, not failed)"},
      {"failed_frames", true, false, "frames flagged too few points, non-finite or diverged"},
      {"skipped_frames", true, false, "unreadable input frames"},
      {"mean_em_iterations", true, false, "EM iterations per frame (mean)"},
      {"converged_fraction", false, false, "fraction of frames whose EM converged before its iteration cap"},
      {"seam_rms_before", true, false, "RMS colour jump at texture seams before levelling (mean over the levelled frames; colours in [0, 1])"},
      {"seam_rms_after", true, false, "RMS colour jump at texture seams after levelling (mean over the levelled frames)"},
      {"seam_edges", true, false, "interior edges whose triangles use different source images (last frame)"},
      {"changed_triangles", true, false, "triangles whose source image changed, per frame (mean; temporal stability)"},
      {"textured_triangles", false, false, "triangles with a source image (last frame)"},
      {"mrf_energy", true, false, "view-selection energy E(L) of the last frame (comparable only at equal lambda/alpha/beta)"},
      {"mrf_iterations", true, false, "view-selection (MRF) solver iterations per frame (mean; warm-started)"},
      {"pool_size", true, false, "images in the pool (mean over frames)"},
      {"stream_kbit_per_s", true, false, "compressed pose + texture update stream at the frame rate"},
      {"novel_view_psnr_db", false, false, "ground truth: PSNR (dB) of the textured model against the true render from held-out views (last evaluated frame)"},
      {"novel_view_ssim", false, false, "ground truth: SSIM of the same renders (last evaluated frame)"},
      {"texture_coverage", false, false, "ground truth: fraction of the true visible surface the model textures (held-out views)"},
      {"mean_novel_view_psnr_db", false, false, "novel-view PSNR averaged over the evaluated frames"},
      {"preprocess_ms", true, true, "preprocessing per frame (ms)"},
      {"estep_ms", true, true, "E-step per frame (ms)"},
      {"mstep_ms", true, true, "M-step per frame (ms)"},
      {"fit_ms", true, true, "whole fit per frame incl. ICP (ms)"},
      {"texture_ms", true, true, "texturing per frame (ms)"},
      {"texture_mrf_ms", true, true, "view selection (MRF) per frame (ms)"},
      {"texture_levelling_ms", true, true, "seam levelling per frame (ms)"},
      {"frame_ms", true, true, "preprocess + fit + texture per frame (ms)"},
  };
  return kMetrics;
}

const MetricInfo* FindMetric(const std::string& name) {
  for (const auto& m : Metrics()) {
    if (name == m.name) return &m;
  }
  return nullptr;
}

int WriteExperimentResults(const Experiment& experiment, const std::string& out_dir) {
  std::vector<RunResult> runs;
  for (const auto& s : experiment.sequences) {
    for (const auto& c : experiment.combinations) {
      const std::string folder = RunFolder(out_dir, s.name, c.id);
      if (!RunIsComplete(folder)) continue;
      RunResult r;
      r.sequence = &s;
      r.combination = &c;
      const std::string path = (fs::path(folder) / "results.json").string();
      try {
        const auto doc = nlohmann::json::parse(ReadText(path));
        for (const auto& kv : doc.at("metrics").items()) r.metrics[kv.key()] = kv.value().get<double>();
      } catch (const std::exception& e) {
        throw Error(path + ": malformed results: " + e.what());
      }
      runs.push_back(r);
    }
  }

  // results.csv (tidy).
  std::ostringstream csv;
  csv << "experiment,sequence";
  for (const auto& k : experiment.keys) csv << "," << CsvField(k);
  csv << ",metric,value\n";
  for (const auto& r : runs) {
    for (const auto& info : Metrics()) {
      auto it = r.metrics.find(info.name);
      if (it == r.metrics.end()) continue;
      csv << CsvField(experiment.name) << "," << CsvField(r.sequence->name);
      for (const auto& k : experiment.keys) {
        std::string v;
        for (const auto& o : r.combination->overrides) {
          if (o.key == k) v = o.value;
        }
        csv << "," << CsvField(v);
      }
      csv << "," << info.name << "," << FormatNumber(it->second) << "\n";
    }
  }
  WriteFileAtomic((fs::path(out_dir) / "results.csv").string(), csv.str());

  // summary.md: per configuration, the mean of each metric over the sequences it completed.
  const std::size_t num_sequences = experiment.sequences.size();
  struct Row {
    const ExperimentCombination* combination;
    std::map<std::string, std::vector<double>> values;
    std::size_t runs = 0;
  };
  std::vector<Row> rows;
  for (const auto& c : experiment.combinations) {
    Row row{&c, {}, 0};
    for (const auto& r : runs) {
      if (r.combination != &c) continue;
      ++row.runs;
      for (const auto& kv : r.metrics) row.values[kv.first].push_back(kv.second);
    }
    rows.push_back(row);
  }
  std::ostringstream md;
  md << "# Experiment `" << experiment.name << "`\n\n";
  md << "Experiment file: `" << experiment.file << "`. " << runs.size() << " of "
     << num_sequences * experiment.combinations.size() << " runs complete ("
     << num_sequences << " sequences x " << experiment.combinations.size()
     << " configurations). Values are means over the sequences of a configuration; a "
        "configuration missing runs is marked *partial* and not ranked.\n\n";
  md << "Sequences:";
  for (const auto& s : experiment.sequences) md << " `" << s.name << "`";
  md << "\n\n## Best configuration per metric\n\n";
  md << "| metric | better | best configuration | value | worst | spread |\n|---|---|---|---|---|---|\n";
  for (const auto& info : Metrics()) {
    const Row* best = nullptr;
    double best_v = 0, worst_v = 0;
    int ranked = 0;
    for (const auto& row : rows) {
      if (row.runs != num_sequences) continue;
      auto it = row.values.find(info.name);
      if (it == row.values.end() || it->second.size() != num_sequences) continue;
      const double v = Mean(it->second);
      if (!std::isfinite(v)) continue;
      const bool better = info.lower_is_better ? v < best_v : v > best_v;
      const bool worse = info.lower_is_better ? v > worst_v : v < worst_v;
      if (!best || better) {
        best = &row;
        best_v = v;
      }
      if (ranked == 0 || worse) worst_v = v;
      ++ranked;
    }
    if (!best) continue;
    md << "| " << info.name << (info.timing ? " (timing)" : "") << " | "
       << (info.lower_is_better ? "lower" : "higher") << " | "
       << CombinationLabel(*best->combination)
       << (ranked == 1 ? " (only one)" : best_v == worst_v ? " (all equal)" : "")
       << " | " << FormatNumber(best_v) << " | " << FormatNumber(worst_v) << " | "
       << FormatNumber(std::fabs(worst_v - best_v)) << " |\n";
  }
  static const std::vector<std::string> kHeadline = {
      "mean_vertex_error_mm", "mean_joint_error_mm", "lost_fraction", "mean_em_iterations",
      "seam_rms_after", "changed_triangles", "fit_ms", "texture_ms"};
  md << "\n## All configurations\n\n| configuration | runs |";
  for (const auto& h : kHeadline) md << " " << h << " |";
  md << "\n|---|---|";
  for (std::size_t i = 0; i < kHeadline.size(); ++i) md << "---|";
  md << "\n";
  for (const auto& row : rows) {
    md << "| " << CombinationLabel(*row.combination) << " | " << row.runs << "/" << num_sequences
       << (row.runs != num_sequences ? " *partial*" : "") << " |";
    for (const auto& h : kHeadline) {
      auto it = row.values.find(h);
      md << " " << (it == row.values.end() ? std::string("") : FormatNumber(Mean(it->second))) << " |";
    }
    md << "\n";
  }
  md << "\nMetric definitions and directions: docs/experiments.md. The tidy table of every run and "
        "metric is results.csv; per-frame data are in runs/<sequence>/<configuration>/trace.csv.\n";
  WriteFileAtomic((fs::path(out_dir) / "summary.md").string(), md.str());
  return static_cast<int>(runs.size());
}

}  // namespace artex
