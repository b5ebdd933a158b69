// `artex experiment FILE -o OUT`: runs every (sequence, configuration) of an experiment file in
// child processes with a progress display, then writes results.csv, summary.md and the plots
// (scripts/plot_results.py). Hidden subcommands `experiment-run` and `experiment-synth` are
// the children's entry points (`artex overlay` is in overlay_command.cc).
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "experiments/commands.h"
#include "experiments/config.h"
#include "experiments/heap_retention.h"
#include "experiments/pipeline.h"
#include "experiments/progress_display.h"
#include "experiments/runner.h"
#include "experiments/slurm_backend.h"
#include "models/error.h"

namespace artex {
namespace {
namespace fs = std::filesystem;

struct ExperimentCliOptions {
  std::string file;
  std::string output;
  int jobs = 0;
  int threads = 0;
  bool dry_run = false;
  bool no_plots = false;
  bool replace_changed = false;
  std::string backend = "local";  // local | slurm
  bool no_wait = false;           // slurm: submit and return
  SlurmOptions slurm;
};

// A python3 that can import matplotlib ("" when none).
std::string FindPlottingPython() {
  for (const char* candidate : {"python3", "/usr/bin/python3"}) {
    const std::string cmd = std::string(candidate) + " -c 'import matplotlib' >/dev/null 2>&1";
    if (std::system(cmd.c_str()) == 0) return candidate;
  }
  return "";
}

std::string Quote(const std::string& s) {
  std::string out = "'";
  for (char c : s) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return out + "'";
}

}  // namespace

void MakeExperimentPlots(const std::string& out) {
  const std::string script = (fs::path(SourceDirectory()) / "scripts" / "plot_results.py").string();
  const std::string python = FindPlottingPython();
  if (python.empty() || !fs::exists(script)) {
    std::fprintf(stderr,
                 "experiment: plots not made (needs python3 with matplotlib); run:\n"
                 "  python3 %s %s\n",
                 script.c_str(), out.c_str());
    return;
  }
  const std::string cmd = python + " " + Quote(script) + " " + Quote(out);
  if (std::system(cmd.c_str()) != 0) {
    std::fprintf(stderr, "experiment: plotting failed; rerun: %s\n", cmd.c_str());
  }
}

namespace {

void RunExperimentCli(const ExperimentCliOptions& cli) {
  if (cli.file.empty()) throw Error("experiment: an experiment file is required (or collect|status OUT)");
  if (cli.output.empty()) throw Error("-o/--output: an output folder is required");
  if (cli.backend != "local" && cli.backend != "slurm") {
    throw Error("--backend: expected local or slurm, found '" + cli.backend + "'");
  }
  const Experiment experiment = LoadExperiment(cli.file);
  std::fprintf(stderr, "experiment %s: %zu sequences x %zu configurations (validated)\n",
               experiment.name.c_str(), experiment.sequences.size(),
               experiment.combinations.size());
  if (cli.dry_run) {
    for (const auto& s : experiment.sequences) {
      for (const auto& c : experiment.combinations) {
        std::printf("%s\n", RunFolder(cli.output, s.name, c.id).c_str());
      }
    }
  }
  RunnerOptions options;
  options.jobs = cli.jobs;
  options.threads_per_run = cli.threads;
  options.dry_run = cli.dry_run;
  options.replace_changed = cli.replace_changed;
  if (cli.backend == "slurm") {
    SlurmOptions slurm = cli.slurm;
    slurm.wait = !cli.no_wait;
    options.threads_per_run = slurm.cpus_per_task;
    options.backend = MakeSlurmBackend(experiment, cli.output, slurm);
  }
  ExperimentProgressDisplay display(stderr, isatty(STDERR_FILENO));
  const ExperimentSummary summary =
      RunExperiment(experiment, cli.output, options, [&](const RunnerEvent& e) { display.Handle(e); });
  if (cli.dry_run) return;
  std::fprintf(stderr,
               "experiment: %d runs: %d completed now, %d skipped (complete before), %d failed; "
               "%.1f s\n",
               summary.runs_total, summary.runs_completed, summary.runs_skipped, summary.runs_failed,
               summary.seconds);
  if (summary.runs_unfinished > 0) {
    std::fprintf(stderr,
                 "experiment: %d run(s) queued or running; follow with `artex experiment status %s`, "
                 "gather with `artex experiment collect %s`\n",
                 summary.runs_unfinished, cli.output.c_str(), cli.output.c_str());
  }
  std::fprintf(stderr, "experiment: wrote %s/results.csv and %s/summary.md\n", cli.output.c_str(),
               cli.output.c_str());
  if (!cli.no_plots && summary.runs_completed + summary.runs_skipped > 0) MakeExperimentPlots(cli.output);
  if (summary.runs_failed > 0) {
    std::string msg = std::to_string(summary.runs_failed) + " run(s) failed (rerun to retry):";
    for (const auto& f : summary.failures) msg += "\n  " + f;
    throw Error(msg);
  }
}

void PrintProgress(int done, int total) {
  std::printf("progress %d %d\n", done, total);
  std::fflush(stdout);
}

}  // namespace

void RegisterExperimentCommand(CLI::App* app) {
  auto cli = std::make_shared<ExperimentCliOptions>();
  CLI::App* sub = app->add_subcommand(
      "experiment",
      "Run every sequence x configuration of an experiment file (resumable), then write "
      "results.csv, summary.md and plots");
  sub->add_option("file", cli->file, "Experiment file (YAML; docs/experiments.md)")
      ->check(CLI::ExistingFile);
  sub->add_option("-o,--output", cli->output, "Output folder (runs, sequences, results)");
  sub->add_option("-j,--jobs", cli->jobs, "Runs at a time (0: number of cores)")
      ->capture_default_str()
      ->check(CLI::Range(0, 256));
  sub->add_option("--threads-per-run", cli->threads,
                  "Worker threads per run (0: cores / jobs, at least 1)")
      ->capture_default_str()
      ->check(CLI::Range(0, 256));
  sub->add_flag("--dry-run", cli->dry_run, "Validate and list the run folders; run nothing");
  sub->add_flag("--no-plots", cli->no_plots, "Do not call scripts/plot_results.py");
  sub->add_flag("--replace-changed", cli->replace_changed,
                "Recompute complete runs (and regenerate sequences) whose inputs changed instead of "
                "stopping with an error");
  sub->add_option("--backend", cli->backend,
                  "Where runs execute: local (child processes here) or slurm (one job array)")
      ->capture_default_str();
  sub->add_flag("--no-wait", cli->no_wait, "slurm: submit and return (follow with status/collect)");
  SlurmOptions& so = cli->slurm;
  sub->add_option("--partition", so.partition, "slurm: partition (default: the cluster's)");
  sub->add_option("--time", so.time, "slurm: time limit per run, e.g. 00:30:00");
  sub->add_option("--mem", so.mem, "slurm: memory per run, e.g. 4G");
  sub->add_option("--cpus-per-task", so.cpus_per_task, "slurm: CPUs (and worker threads) per run")
      ->capture_default_str()
      ->check(CLI::Range(1, 1024));
  sub->add_option("--max-parallel", so.max_parallel, "slurm: array throttle %K (0: none)")
      ->capture_default_str()
      ->check(CLI::Range(0, 100000));
  sub->add_option("--max-array-size", so.max_array_size,
                  "slurm: runs per job array; more are split into several arrays (<= MaxArraySize - 1)")
      ->capture_default_str()
      ->check(CLI::Range(1, 4000000));
  sub->add_option("--sbatch-arg", so.sbatch_args, "slurm: further sbatch argument (repeatable)")
      ->allow_extra_args(false);
  sub->add_option("--poll-seconds", so.poll_seconds, "slurm: seconds between squeue/sacct polls")
      ->capture_default_str();
  sub->add_flag("!--no-probe", so.probe,
                "slurm: skip the probe job that checks OUT is writable from a task");
  RegisterSlurmSubcommands(app, sub);
  sub->callback([cli, sub]() {
    if (sub->got_subcommand("collect") || sub->got_subcommand("status")) return;
    RunExperimentCli(*cli);
  });

  // Child entry points (not listed in the help).
  struct RunArgs {
    std::string config, sequence, template_path, out;
    int threads = 0;
  };
  auto run = std::make_shared<RunArgs>();
  CLI::App* run_sub = app->add_subcommand("experiment-run", "One run of an experiment (internal)");
  run_sub->group("");
  run_sub->add_option("--config", run->config)->required();
  run_sub->add_option("--sequence", run->sequence)->required();
  run_sub->add_option("--template", run->template_path);
  run_sub->add_option("--out", run->out)->required();
  run_sub->add_option("--threads", run->threads);
  run_sub->callback([run]() {
    // pipeline.huge_pages, as `artex track` (experiments/heap_retention.h): the run's process
    // restarts itself once, before it writes anything.
    if (LoadPipelineOptions(Config::Load(run->config)).realtime.huge_pages) {
      ReexecWithHugePageHeap(ProgramArguments());
    }
    RunSingle(run->config, run->sequence, run->template_path, run->out, run->threads, PrintProgress);
  });

  struct SynthArgs {
    std::string spec, name, out;
  };
  auto synth = std::make_shared<SynthArgs>();
  CLI::App* synth_sub =
      app->add_subcommand("experiment-synth", "Generate an experiment's synthetic sequence (internal)");
  synth_sub->group("");
  synth_sub->add_option("--spec", synth->spec)->required();
  synth_sub->add_option("--name", synth->name);
  synth_sub->add_option("--out", synth->out)->required();
  synth_sub->callback([synth]() {
    std::string text;
    {
      FILE* f = std::fopen(synth->spec.c_str(), "rb");
      if (!f) throw Error(synth->spec + ": cannot open the synthesis spec");
      char buf[4096];
      std::size_t n;
      while ((n = std::fread(buf, 1, sizeof(buf), f)) > 0) text.append(buf, n);
      std::fclose(f);
    }
    while (!text.empty() && text.back() == '\n') text.pop_back();
    GenerateSyntheticSequence(text, synth->name.empty() ? synth->spec : synth->name, synth->out,
                              PrintProgress);
  });
}

}  // namespace artex
