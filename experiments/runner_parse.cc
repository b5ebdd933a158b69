// Experiment files (experiments/runner.h): the YAML's keys, the base configuration, the
// template, the sequences, the list x grid expansion of the overrides into combinations, and
// the up-front validation of every combination's configuration.
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <set>
#include <string>
#include <vector>

#include "experiments/file_util.h"
#include "experiments/pipeline.h"
#include "experiments/runner.h"
#include "experiments/runner_internal.h"
#include "models/error.h"
#include "models/fnv1a.h"
#include "sensors/frame_source.h"
#include "sensors/yaml_checks.h"

namespace artex {
namespace fs = std::filesystem;

namespace {

using runner_internal::CombinationLabel;
using runner_internal::Hex;
using runner_internal::SynthSpecFromConfig;

std::string Emit(const YAML::Node& node) {
  YAML::Emitter out;
  out.SetMapFormat(YAML::Flow);
  out.SetSeqFormat(YAML::Flow);
  out << node;
  return out.c_str();
}

std::string EmitBlock(const YAML::Node& node) {
  YAML::Emitter out;
  out << node;
  return out.c_str();
}

// Folder-name-safe text: [A-Za-z0-9._=,+-], everything else '_'.
std::string Sanitize(const std::string& s) {
  std::string out;
  for (char c : s) {
    const bool ok = std::isalnum(static_cast<unsigned char>(c)) || c == '.' || c == '_' ||
                    c == '=' || c == ',' || c == '+' || c == '-';
    out += ok ? c : '_';
  }
  return out;
}

std::string DefaultSequenceName(const YAML::Node& synth) {
  std::string name = synth["motion"] ? synth["motion"].as<std::string>() : "walk";
  if (synth["bvh"]) name = fs::path(synth["bvh"].as<std::string>()).stem().string();
  if (synth["subject_template"]) {
    name += "_" + fs::path(synth["subject_template"].as<std::string>()).stem().string();
  }
  if (synth["frames"]) name += "_f" + synth["frames"].as<std::string>();
  if (synth["seed"]) name += "_s" + synth["seed"].as<std::string>();
  if (synth["noise"]) name += "_" + synth["noise"].as<std::string>();
  if (synth["condition"]) name += "_" + synth["condition"].as<std::string>();
  if (synth["speed"]) name += "_x" + synth["speed"].as<std::string>();
  if (synth["frame_step"]) name += "_step" + synth["frame_step"].as<std::string>();
  return Sanitize(name);
}

std::string ScalarText(const YAML::Node& n) { return n.IsScalar() ? n.Scalar() : Emit(n); }

std::string CombinationId(const std::vector<Override>& overrides) {
  if (overrides.empty()) return "base";
  std::string id;
  for (const auto& o : overrides) {
    if (!id.empty()) id += ",";
    id += o.key + "=" + o.value;
  }
  id = Sanitize(id);
  constexpr std::size_t kMaxIdLength = 120;
  if (id.size() > kMaxIdLength) id = id.substr(0, kMaxIdLength - 17) + "-" + Hex(Fnv1a(id), 16);
  return id;
}

void CheckTopKeys(const YAML::Node& root, const std::string& source) {
  static const std::vector<std::string> kValid = {"name", "description", "base", "template",
                                                  "sequences", "grid", "list"};
  for (const auto& kv : root) {
    const std::string key = kv.first.as<std::string>();
    if (std::find(kValid.begin(), kValid.end(), key) == kValid.end()) {
      std::string msg = source + ": unknown key '" + key + "'; valid keys:";
      for (const auto& v : kValid) msg += " " + v;
      throw Error(msg);
    }
  }
}

std::string ResolvePath(const std::string& path, const std::string& base_dir) {
  if (path.empty() || fs::path(path).is_absolute() || base_dir.empty()) return path;
  return (fs::path(base_dir) / path).lexically_normal().string();
}

Experiment ParseExperimentYaml(const std::string& yaml, const std::string& source_name,
                               const std::string& base_dir) {
  YAML::Node root;
  try {
    root = YAML::Load(yaml);
  } catch (const YAML::Exception& e) {
    throw Error(source_name + ": not valid YAML: " + e.what());
  }
  if (!root.IsMap()) throw Error(source_name + ": expected a mapping at the top level");
  CheckYamlKeys(root, source_name);
  CheckTopKeys(root, source_name);
  Experiment ex;
  ex.file = source_name;
  ex.base_source = source_name + " (base)";
  ex.name = root["name"] ? root["name"].as<std::string>() : fs::path(source_name).stem().string();

  // Base configuration: a path (relative to the experiment file) or an inline mapping.
  if (const YAML::Node base = root["base"]) {
    if (base.IsScalar()) {
      ex.base_source = ResolvePath(base.Scalar(), base_dir);
      ex.base = Config::Load(ex.base_source);  // reports a missing file or bad YAML
      ex.base_yaml = ReadText(ex.base_source);
    } else if (base.IsMap()) {
      ex.base_source = source_name + " (base)";
      ex.base_yaml = EmitBlock(base);
      ex.base = Config::FromString(ex.base_yaml, ex.base_source);
    } else {
      throw Error(source_name + ": base: expected a configuration file path or a mapping");
    }
  }

  // Tracking template: a .glb path, or a mapping of generator options (BodyShapeOptions).
  if (const YAML::Node t = root["template"]) {
    if (t.IsScalar()) {
      ex.template_path = ResolvePath(t.Scalar(), base_dir);
      if (std::error_code ec; !fs::exists(ex.template_path, ec)) {
        throw Error(source_name + ": template: file not found: " + ex.template_path);
      }
    } else if (t.IsMap()) {
      ex.template_yaml = Emit(t);
    } else {
      throw Error(source_name + ": template: expected a .glb path or a mapping of generator options");
    }
  } else {
    ex.template_yaml = "{}";
  }
  if (!ex.template_yaml.empty()) {
    const Config c = Config::FromString(ex.template_yaml, source_name + ": template");
    c.CheckKeys({"resolution", "height", "girth", "shoulder_width", "hip_width", "arm_length",
                 "leg_length", "atlas_size"});
  }

  // Sequences.
  const YAML::Node seqs = root["sequences"];
  if (!seqs || !seqs.IsSequence() || seqs.size() == 0) {
    throw Error(source_name + ": sequences: expected a non-empty list of sequences "
                "(folder paths or {synth: {...}} specs)");
  }
  std::set<std::string> names;
  for (std::size_t i = 0; i < seqs.size(); ++i) {
    const YAML::Node s = seqs[i];
    const std::string where = source_name + ": sequences[" + std::to_string(i) + "]";
    ExperimentSequence seq;
    if (s.IsScalar()) {
      seq.folder = ResolvePath(s.Scalar(), base_dir);
      seq.name = Sanitize(fs::path(seq.folder).filename().string());
    } else if (s.IsMap()) {
      for (const auto& kv : s) {
        const std::string k = kv.first.as<std::string>();
        if (k != "name" && k != "path" && k != "synth") {
          throw Error(where + ": unknown key '" + k + "'; valid keys: name path synth");
        }
      }
      if (s["path"] && s["synth"]) throw Error(where + ": give either path or synth, not both");
      if (s["path"]) {
        seq.folder = ResolvePath(s["path"].as<std::string>(), base_dir);
        seq.name = Sanitize(fs::path(seq.folder).filename().string());
      } else if (s["synth"]) {
        const YAML::Node synth = s["synth"];
        if (!synth.IsMap()) throw Error(where + ".synth: expected a mapping of synthesis options");
        YAML::Node spec = YAML::Clone(synth);
        for (const char* file_key : {"bvh", "subject_template"}) {  // relative to this file
          if (spec[file_key]) {
            spec[file_key] = ResolvePath(spec[file_key].as<std::string>(), base_dir);
          }
        }
        seq.synthetic = true;
        seq.synth_yaml = Emit(spec);
        SynthSpecFromConfig(Config::FromString(seq.synth_yaml, where + ".synth"));
        seq.name = DefaultSequenceName(spec);
      } else {
        throw Error(where + ": expected path or synth");
      }
      if (s["name"]) {
        seq.name = s["name"].as<std::string>();
        if (seq.name.empty() || Sanitize(seq.name) != seq.name || seq.name[0] == '.') {
          throw Error(where + ".name: expected letters, digits, '.', '_', '-', found '" + seq.name + "'");
        }
      }
    } else {
      throw Error(where + ": expected a folder path or a mapping");
    }
    std::error_code exists_ec;  // e.g. a name too long: not found, no filesystem_error
    if (!seq.synthetic && !fs::exists(seq.folder, exists_ec)) {
      throw Error(where + ": sequence folder not found: " + seq.folder);
    }
    if (!seq.synthetic) {
      try {
        DetectFrameSource(seq.folder);  // an artex sequence or a TUM RGB-D folder
      } catch (const Error& e) {
        throw Error(where + ": " + e.what());
      }
    }
    if (!names.insert(seq.name).second) {
      throw Error(where + ": duplicate sequence name '" + seq.name + "' (set name: to distinguish)");
    }
    ex.sequences.push_back(seq);
  }

  // Overrides: list entries x grid product (the last grid key varies fastest).
  std::vector<std::vector<Override>> list_entries;
  if (const YAML::Node list = root["list"]) {
    if (!list.IsSequence()) throw Error(source_name + ": list: expected a list of {key: value} mappings");
    for (std::size_t i = 0; i < list.size(); ++i) {
      if (!list[i].IsMap()) {
        throw Error(source_name + ": list[" + std::to_string(i) + "]: expected a mapping of overrides");
      }
      std::vector<Override> entry;
      for (const auto& kv : list[i]) entry.push_back({kv.first.as<std::string>(), ScalarText(kv.second)});
      list_entries.push_back(entry);
    }
  }
  if (list_entries.empty()) list_entries.push_back({});
  std::vector<std::pair<std::string, std::vector<std::string>>> grid;
  if (const YAML::Node g = root["grid"]) {
    if (!g.IsMap()) throw Error(source_name + ": grid: expected a mapping of key: [values]");
    for (const auto& kv : g) {
      const std::string key = kv.first.as<std::string>();
      std::vector<std::string> values;
      if (kv.second.IsSequence()) {
        for (const auto& v : kv.second) values.push_back(ScalarText(v));
      } else {
        values.push_back(ScalarText(kv.second));
      }
      if (values.empty()) throw Error(source_name + ": grid." + key + ": expected at least one value");
      grid.push_back({key, values});
    }
  }
  for (const auto& entry : list_entries) {
    for (const auto& o : entry) {
      if (std::find(ex.keys.begin(), ex.keys.end(), o.key) == ex.keys.end()) ex.keys.push_back(o.key);
    }
  }
  for (const auto& g : grid) {
    if (std::find(ex.keys.begin(), ex.keys.end(), g.first) != ex.keys.end()) {
      throw Error(source_name + ": grid." + g.first + ": the key is also set by list entries");
    }
    ex.keys.push_back(g.first);
  }
  // Capped before expansion (overflow-safe): a million-combination grid hung --dry-run.
  std::size_t total = list_entries.size();
  for (const auto& g : grid) {
    if (total > kMaxExperimentCombinations / g.second.size()) {
      total = kMaxExperimentCombinations + 1;
      break;
    }
    total *= g.second.size();
  }
  if (total > kMaxExperimentCombinations) {
    std::string sizes = std::to_string(list_entries.size()) + " list entries";
    for (const auto& g : grid) sizes += " x " + std::to_string(g.second.size()) + " " + g.first;
    throw Error(source_name + ": expected at most " + std::to_string(kMaxExperimentCombinations) +
                " combinations, found " + sizes + " (split the experiment)");
  }
  std::set<std::string> ids;
  for (const auto& entry : list_entries) {
    std::vector<std::size_t> index(grid.size(), 0);
    while (true) {
      ExperimentCombination c;
      c.overrides = entry;
      for (std::size_t k = 0; k < grid.size(); ++k) c.overrides.push_back({grid[k].first, grid[k].second[index[k]]});
      c.id = CombinationId(c.overrides);
      if (!ids.insert(c.id).second) {
        throw Error(source_name + ": duplicate configuration " + CombinationLabel(c));
      }
      ex.combinations.push_back(c);
      int k = static_cast<int>(grid.size()) - 1;
      while (k >= 0 && ++index[k] == grid[k].second.size()) index[k--] = 0;
      if (k < 0) break;
    }
  }

  // Validate every combination's configuration up front.
  for (const auto& c : ex.combinations) {
    try {
      const Config config = CombinationConfig(ex, c);
      const PipelineOptions options = LoadPipelineOptions(config);
      std::string why;
      if (!options.IsValid(&why)) throw Error(why);
    } catch (const Error& e) {
      throw Error(source_name + ": configuration {" + CombinationLabel(c) + "}: " + e.what());
    }
  }
  return ex;
}

}  // namespace

Experiment ParseExperiment(const std::string& yaml, const std::string& source_name,
                           const std::string& base_dir) {
  try {
    return ParseExperimentYaml(yaml, source_name, base_dir);
  } catch (const YAML::Exception& e) {
    // A value of the wrong shape (a list or mapping where text is expected): yaml-cpp's own
    // message carries the line and column (found by the experiment fuzzer, issue 20).
    throw Error(source_name + ": " + e.what() + " (expected a plain value there)");
  }
}

Experiment LoadExperiment(const std::string& path) {
  if (std::error_code ec; !fs::is_regular_file(path, ec)) {
    throw Error(path + ": experiment file not found");
  }
  return ParseExperiment(ReadText(path), path, fs::path(path).parent_path().string());
}

Config CombinationConfig(const Experiment& experiment, const ExperimentCombination& combination) {
  Config c = Config::FromString(experiment.base_yaml, experiment.base_source);
  for (const auto& o : combination.overrides) c.Set(o.key, o.value);
  return c;
}

}  // namespace artex
