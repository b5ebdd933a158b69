// `artex experiment collect OUT` and `artex experiment status OUT` (the Slurm backend's
// companions, docs/experiments.md) and the hidden entry points of its jobs:
// `artex experiment-task` (one array task) and `artex experiment-probe` (the probe job).
#include <CLI/CLI.hpp>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "experiments/commands.h"
#include "experiments/runner.h"
#include "experiments/slurm_backend.h"
#include "models/error.h"

namespace artex {
namespace fs = std::filesystem;

void RegisterSlurmSubcommands(CLI::App* app, CLI::App* experiment) {
  struct OutArgs {
    std::string out, experiment_file;
    bool no_plots = false;
  };
  auto collect = std::make_shared<OutArgs>();
  CLI::App* collect_sub = experiment->add_subcommand(
      "collect", "Write results.csv, summary.md and plots from the runs finished so far");
  collect_sub->add_option("out", collect->out, "Output folder of the experiment")->required();
  collect_sub->add_option("--experiment", collect->experiment_file,
                          "Experiment file (default: the one recorded in OUT/slurm/)");
  collect_sub->add_flag("--no-plots", collect->no_plots, "Do not call scripts/plot_results.py");
  collect_sub->callback([collect]() {
    const std::string file = collect->experiment_file.empty() ? RecordedExperimentFile(collect->out)
                                                              : collect->experiment_file;
    if (file.empty()) {
      throw Error(collect->out + ": no experiment recorded in " + collect->out +
                  "/slurm/experiment.txt; pass --experiment FILE");
    }
    const Experiment experiment = LoadExperiment(file);
    const int complete = WriteExperimentResults(experiment, collect->out);
    std::fprintf(stderr,
                 "experiment: %d of %zu runs complete; wrote %s/results.csv and %s/summary.md\n",
                 complete, experiment.sequences.size() * experiment.combinations.size(),
                 collect->out.c_str(), collect->out.c_str());
    if (!collect->no_plots && complete > 0) MakeExperimentPlots(collect->out);
  });

  auto status = std::make_shared<OutArgs>();
  CLI::App* status_sub = experiment->add_subcommand(
      "status", "State of every run of a Slurm experiment (squeue/sacct), with failed tasks' logs");
  status_sub->add_option("out", status->out, "Output folder of the experiment")->required();
  status_sub->add_option("--experiment", status->experiment_file,
                         "Experiment file (default: the one recorded in OUT/slurm/)");
  status_sub->callback([status]() {
    std::printf("%s",
                FormatSlurmStatus(ReadSlurmStatus(status->out, status->experiment_file)).c_str());
  });

  struct TaskArgs {
    std::string out, submission;
    int index = -1, threads = 1;
  };
  auto task = std::make_shared<TaskArgs>();
  CLI::App* task_sub = app->add_subcommand("experiment-task", "One Slurm array task (internal)");
  task_sub->group("");
  task_sub->add_option("--out", task->out)->required();
  task_sub->add_option("--submission", task->submission)->required();
  task_sub->add_option("--index", task->index)->required();
  task_sub->add_option("--threads", task->threads);
  task_sub->callback([task]() {
    const int rc = RunSlurmTask(task->out, task->submission, task->index, task->threads);
    if (rc != 0) std::exit(rc);
  });

  struct ProbeArgs {
    std::string out, token;
    std::vector<std::string> checks;
  };
  auto probe = std::make_shared<ProbeArgs>();
  CLI::App* probe_sub = app->add_subcommand("experiment-probe", "Slurm probe job (internal)");
  probe_sub->group("");
  probe_sub->add_option("--out", probe->out)->required();
  probe_sub->add_option("--token", probe->token)->required();
  probe_sub->add_option("--check", probe->checks);
  probe_sub->callback([probe]() { RunSlurmProbe(probe->out, probe->token, probe->checks); });
}

}  // namespace artex
