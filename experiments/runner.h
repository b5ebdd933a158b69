// The experiment runner behind `artex experiment` (docs/experiments.md): an experiment file
// (YAML) names sequences (recorded folders or synthetic specs generated once into
// OUT/sequences/), a base configuration and a grid and/or list of overrides; every
// (sequence, combination) is one run of the pipeline (experiments/pipeline.h) in its own child
// process, into OUT/runs/<sequence>/<combination>/. A run folder is complete iff it holds a
// DONE marker: runs are executed in a temporary folder and renamed into place when complete,
// so reruns skip finished runs, redo interrupted ones from scratch and never mix partial
// results in. Results: OUT/results.csv (tidy: one row per run x metric) and OUT/summary.md.
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "experiments/config.h"

namespace artex {

// One sequence of an experiment.
struct ExperimentSequence {
  std::string name;         // unique within the experiment; [A-Za-z0-9._-]
  std::string folder;       // recorded: the folder (relative paths resolved against the
                            // experiment file); synthetic: "" until placed (OUT/sequences/name)
  bool synthetic = false;
  std::string synth_yaml;   // synthetic: the `synth:` mapping as canonical YAML text
};

// One override: a dotted key of the configuration ("texture.lambda") and a YAML value text.
struct Override {
  std::string key;
  std::string value;
};

// One configuration of the experiment: the base plus these overrides (in key order).
struct ExperimentCombination {
  std::string id;                   // folder name, derived from the overrides ("base" if none)
  std::vector<Override> overrides;
};

struct Experiment {
  std::string name;                 // `name:` (default: the file's stem)
  std::string file;                 // the experiment file
  Config base;                      // base configuration (file or inline mapping)
  std::string base_yaml;            // its text and source name: CombinationConfig parses a
  std::string base_source;          // fresh copy (Config copies share their YAML nodes)
  std::string template_path;        // tracking template (.glb); "" = generated (below)
  std::string template_yaml;        // BodyShapeOptions mapping of the generated template
  std::vector<ExperimentSequence> sequences;
  std::vector<std::string> keys;    // every overridden key, in first-appearance order
  std::vector<ExperimentCombination> combinations;  // list entries x grid (grid varies fastest)
};

// Most combinations (list entries x grid) one experiment file may declare; more is an error
// before anything is expanded (docs/reliability.md).
constexpr std::size_t kMaxExperimentCombinations = 10000;

// Parses and validates an experiment file: every combination's configuration (base + Config::Set
// overrides) goes through LoadPipelineOptions and IsValid before anything runs, and every
// synthetic spec through SynthOptionsFromSpec. Throws artex::Error naming the file, the
// combination and the problem (unknown keys and values list the valid choices).
Experiment LoadExperiment(const std::string& path);
// Same, from text (source_name is used in messages; relative paths resolve against base_dir).
Experiment ParseExperiment(const std::string& yaml, const std::string& source_name,
                           const std::string& base_dir);

// The resolved configuration of one combination (base with the overrides applied).
Config CombinationConfig(const Experiment& experiment, const ExperimentCombination& combination);

// Keys accepted in a `synth:` mapping (documented in docs/experiments.md).
std::vector<std::string> SynthSpecKeys();

// Metrics written per run (results.json, results.csv) and how to rank them.
struct MetricInfo {
  const char* name;
  bool lower_is_better;
  bool timing;  // wall-clock dependent (excluded from determinism checks)
  const char* description;
};
const std::vector<MetricInfo>& Metrics();
const MetricInfo* FindMetric(const std::string& name);

struct ExperimentSummary;
struct RunnerEvent;

// One run that RunExperiment found pending (not complete), handed to a RunnerOptions::backend
// (e.g. the Slurm backend, experiments/slurm_backend.h) instead of a local child process.
struct PendingRun {
  std::string label;            // "sequence/combination"
  std::string sequence;         // sequence name
  std::string combination;      // combination id
  std::string sequence_folder;  // the (generated) sequence
  std::string template_path;    // tracking template (.glb)
  std::string run_folder;       // OUT/runs/<sequence>/<combination> (absolute)
  std::string config_text;      // resolved configuration (run_config.yaml)
  std::string key;              // stored inputs (run_key.txt)
  std::string info_json;        // run.json without wall_seconds/command (JSON object text)
};

// Runs the pending runs elsewhere; fills summary's counts and failures and reports progress
// through `emit` like the local scheduler (kPlan is already sent).
using RunBackend = std::function<void(const std::vector<PendingRun>& pending,
                                      ExperimentSummary* summary,
                                      const std::function<void(const RunnerEvent&)>& emit)>;

struct RunnerOptions {
  std::string executable;   // the artex binary for child processes; "" = /proc/self/exe
  int jobs = 0;             // runs at a time; 0 = hardware concurrency
  int threads_per_run = 0;  // worker threads of each child; 0 = max(1, cores / jobs)
  bool dry_run = false;     // validate, place sequences' paths, report the plan, run nothing
  // A complete run or generated sequence whose stored inputs differ from the experiment's is
  // an error (false) or deleted and recomputed (true).
  bool replace_changed = false;
  // Set: the pending runs go to this backend instead of local child processes (sequences and
  // the template are still generated here first). Empty: the local backend.
  RunBackend backend;
};

// Progress of an experiment (for the CLI's display; the runner never prints).
struct RunnerEvent {
  enum class Kind {
    kPlan,             // total runs / skipped known
    kSequenceStarted,  // synthetic sequence generation started
    kSequenceReady,    // generated (or reused)
    kSequenceProgress, // frames done / total of a sequence being generated
    kRunStarted,
    kRunProgress,      // frames done / total of a running run
    kRunFinished,
    kRunSkipped,       // already complete
    kRunFailed,
    kNote,             // a backend's message (message): the job ids it submitted
  } kind = Kind::kPlan;
  std::string label;   // "sequence/combination" or the sequence name
  int done = 0;        // frames (kRunProgress)
  int total = 0;
  int runs_total = 0, runs_done = 0, runs_skipped = 0, runs_failed = 0, runs_running = 0;
  int runs_pending = -1;  // queued, not started (-1: not tracked, the local backend)
  double seconds = 0;  // run wall time (finished / failed)
  std::string message; // failure reason (last lines of the run's log)
};

struct ExperimentSummary {
  int runs_total = 0;
  int runs_completed = 0;  // completed now
  int runs_skipped = 0;    // complete before
  int runs_failed = 0;
  std::vector<std::string> failures;  // "label: reason (log: path)"
  double seconds = 0;
  // Remote backends (Slurm): tasks submitted now, of which runs whose earlier task had been
  // killed or had failed, and runs still queued or running when the call returned (--no-wait).
  int runs_submitted = 0;
  int runs_resubmitted = 0;
  int runs_unfinished = 0;
  std::string note;  // what the backend wants the user to know (job ids, how to follow)
};

// Generates missing synthetic sequences and the tracking template, then runs every pending
// (sequence, combination) in child processes, `jobs` at a time. Writes results.csv and
// summary.md at the end (also when some runs failed; failed runs are absent and retried on
// the next call). Throws artex::Error for an unusable output folder, a sequence or a run whose
// stored configuration conflicts with the experiment, or a failing sequence generation.
ExperimentSummary RunExperiment(const Experiment& experiment, const std::string& out_dir,
                                const RunnerOptions& options,
                                const std::function<void(const RunnerEvent&)>& on_event = {});

// Writes OUT/results.csv and OUT/summary.md from the completed runs (atomically). Returns the
// number of complete runs found.
int WriteExperimentResults(const Experiment& experiment, const std::string& out_dir);

// Completes a run executed in tmp_dir: writes run.json (run_json) and the DONE marker, then
// renames tmp_dir to run_folder. When run_folder is already complete (another task finished
// the same run first) tmp_dir is deleted and the complete one kept. Returns "" or an error.
std::string CompleteRun(const std::string& tmp_dir, const std::string& run_folder,
                        const std::string& run_json);

// Folder of a run and its completion test.
std::string RunFolder(const std::string& out_dir, const std::string& sequence,
                      const std::string& combination_id);
bool RunIsComplete(const std::string& run_folder);

// ---- Child-process entry points (hidden subcommands of the artex binary) -------------------

// Runs the pipeline for one run: config_path (resolved configuration), sequence folder,
// template (.glb, "" = default), into out_dir (which must not exist yet; created). Besides the
// pipeline's own files it writes results.json (the metrics of Metrics()), trace.csv (per frame:
// errors, EM iterations, stage timings, seam metrics) and em_trace.csv (per EM iteration).
// `progress(done, total)` is called after every frame. threads > 0 limits worker threads.
void RunSingle(const std::string& config_path, const std::string& sequence_dir,
               const std::string& template_path, const std::string& out_dir, int threads,
               const std::function<void(int, int)>& progress = {});

// Generates a synthetic sequence from a `synth:` spec (YAML text) into out_dir (must not
// exist; created), including the outlier corruption of the spec, and writes synth.yaml.
void GenerateSyntheticSequence(const std::string& synth_yaml, const std::string& source_name,
                               const std::string& out_dir,
                               const std::function<void(int, int)>& progress = {});

// Git revision of the source tree this binary was built from ("<sha>[-dirty]" or "unknown").
std::string SourceRevision();
// The source tree this binary was built from (for scripts/plot_results.py).
std::string SourceDirectory();

}  // namespace artex
