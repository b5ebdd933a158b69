#include "experiments/config.h"

#include <yaml-cpp/yaml.h>

#include <cmath>
#include <sstream>

#include "models/error.h"
#include "sensors/yaml_checks.h"

namespace artex {

struct Config::Impl {
  YAML::Node node;
  std::string source;  // file name
  std::string prefix;  // dotted key path of this node, "" at the root
  std::vector<std::string> overrides;  // dotted keys given to Set (messages name them)

  // The override that set `full_key` (itself or a key below it), "" when none did.
  std::string OverrideOf(const std::string& full_key) const {
    for (const auto& o : overrides) {
      if (o == full_key || o.rfind(full_key + ".", 0) == 0) return o;
    }
    return "";
  }
};

// The name of a configuration built in code (no file): default options plus overrides.
constexpr const char* kDefaultSource = "built-in defaults";

Config::Config() : impl_(std::make_unique<Impl>()) {
  impl_->node = YAML::Node(YAML::NodeType::Map);
  impl_->source = kDefaultSource;
}
Config::~Config() = default;
Config::Config(const Config& other) : impl_(std::make_unique<Impl>(*other.impl_)) {}
Config& Config::operator=(const Config& other) {
  if (this != &other) *impl_ = *other.impl_;
  return *this;
}

Config Config::Load(const std::string& path) {
  CheckNotAFolder(path, "a configuration file");
  Config c;
  c.impl_->source = path;
  try {
    c.impl_->node.reset(YAML::LoadFile(path));
  } catch (const YAML::BadFile&) {
    throw Error(path + ": cannot open the configuration file");
  } catch (const YAML::Exception& e) {
    throw Error(path + ": not valid YAML: " + e.what());
  }
  if (c.impl_->node.IsNull()) c.impl_->node = YAML::Node(YAML::NodeType::Map);
  if (!c.impl_->node.IsMap()) throw Error(path + ": expected a mapping at the top level");
  CheckYamlKeys(c.impl_->node, path);
  return c;
}

Config Config::FromString(const std::string& yaml, const std::string& source_name) {
  Config c;
  c.impl_->source = source_name;
  try {
    c.impl_->node.reset(YAML::Load(yaml));
  } catch (const YAML::Exception& e) {
    throw Error(source_name + ": not valid YAML: " + e.what());
  }
  if (c.impl_->node.IsNull()) c.impl_->node = YAML::Node(YAML::NodeType::Map);
  if (!c.impl_->node.IsMap()) throw Error(source_name + ": expected a mapping at the top level");
  CheckYamlKeys(c.impl_->node, source_name);
  return c;
}

std::string Config::Path(const std::string& key) const {
  const std::string full = impl_->prefix.empty() ? key : impl_->prefix + "." + key;
  const std::string override_key = key.empty() ? "" : impl_->OverrideOf(full);
  if (!override_key.empty()) return "override " + override_key;
  return impl_->source + ": " + full;
}

namespace {
// Read-only lookup: yaml-cpp's non-const operator[] inserts pending nodes for missing keys.
YAML::Node Lookup(const YAML::Node& node, const std::string& key) {
  const YAML::Node& map = node;
  return map[key];
}
}  // namespace

bool Config::Has(const std::string& key) const {
  if (!impl_->node.IsMap()) return false;
  const YAML::Node n = Lookup(impl_->node, key);
  return n.IsDefined() && !n.IsNull();
}

Config Config::Section(const std::string& key) const {
  Config c;
  c.impl_->source = impl_->source;
  c.impl_->overrides = impl_->overrides;
  c.impl_->prefix = impl_->prefix.empty() ? key : impl_->prefix + "." + key;
  if (!Has(key)) return c;
  YAML::Node n = Lookup(impl_->node, key);
  if (!n.IsMap()) throw Error(Path(key) + ": expected a mapping of options");
  c.impl_->node.reset(n);
  return c;
}

std::vector<std::string> Config::Keys() const {
  std::vector<std::string> keys;
  for (const auto& kv : impl_->node) keys.push_back(kv.first.as<std::string>());
  return keys;
}

namespace {
template <typename T>
T Convert(const YAML::Node& n, const std::string& path, const char* expected) {
  if (!n.IsScalar()) throw Error(path + ": expected " + expected + ", found a non-scalar value");
  try {
    return n.as<T>();
  } catch (const YAML::Exception&) {
    throw Error(path + ": expected " + expected + ", found '" + n.Scalar() + "'");
  }
}
}  // namespace

void Config::Get(const std::string& key, double* value) const {
  if (!Has(key)) return;
  const double v = Convert<double>(Lookup(impl_->node, key), Path(key), "a number");
  if (!std::isfinite(v)) throw Error(Path(key) + ": expected a finite number, found " + Lookup(impl_->node, key).Scalar());
  *value = v;
}

void Config::Get(const std::string& key, int* value) const {
  if (!Has(key)) return;
  *value = Convert<int>(Lookup(impl_->node, key), Path(key), "an integer");
}

void Config::Get(const std::string& key, bool* value) const {
  if (!Has(key)) return;
  *value = Convert<bool>(Lookup(impl_->node, key), Path(key), "true or false");
}

void Config::Get(const std::string& key, std::string* value) const {
  if (!Has(key)) return;
  *value = Convert<std::string>(Lookup(impl_->node, key), Path(key), "a string");
}

namespace {
// A YAML sequence at `path` whose items are each Convert<T>-ed ("path[i]: expected ...").
template <typename T>
std::vector<T> ConvertList(const YAML::Node& n, const std::string& path, const char* list,
                           const char* item) {
  if (!n.IsSequence()) throw Error(path + ": expected " + list);
  std::vector<T> out;
  for (std::size_t i = 0; i < n.size(); ++i) {
    std::ostringstream p;
    p << path << "[" << i << "]";
    out.push_back(Convert<T>(n[i], p.str(), item));
  }
  return out;
}
}  // namespace

void Config::Get(const std::string& key, std::vector<double>* value) const {
  if (!Has(key)) return;
  *value = ConvertList<double>(Lookup(impl_->node, key), Path(key), "a list of numbers", "a number");
}

void Config::Get(const std::string& key, std::vector<std::string>* value) const {
  if (!Has(key)) return;
  *value = ConvertList<std::string>(Lookup(impl_->node, key), Path(key), "a list of names",
                                    "a name");
}

void Config::CheckKeys(const std::vector<std::string>& valid) const {
  for (const auto& key : Keys()) {
    bool ok = false;
    for (const auto& v : valid) ok = ok || v == key;
    if (!ok) ThrowInvalidChoice("", key, valid);
  }
}

void Config::ThrowInvalidChoice(const std::string& key, const std::string& found,
                                const std::vector<std::string>& valid) const {
  std::ostringstream msg;
  if (key.empty()) {
    const std::string full = impl_->prefix.empty() ? found : impl_->prefix + "." + found;
    const std::string override_key = impl_->OverrideOf(full);
    msg << (override_key.empty() ? impl_->source : "override " + override_key) << ": unknown key '"
        << full << "'; valid keys:";
  } else {
    msg << Path(key) << ": unknown value '" << found << "'; valid choices:";
  }
  for (const auto& v : valid) msg << " " << v;
  throw Error(msg.str());
}

void Config::Set(const std::string& dotted_key, const std::string& yaml_value) {
  if (yaml_value.find_first_not_of(" \t\r\n") == std::string::npos) {
    // YAML reads "" as null, which every reader skips: the override would be ignored.
    throw Error("override " + dotted_key + "=: expected a value after '=', found none");
  }
  YAML::Node value;
  try {
    value = YAML::Load(yaml_value);
  } catch (const YAML::Exception& e) {
    throw Error("override " + dotted_key + ": not valid YAML: " + e.what());
  }
  std::vector<std::string> parts;
  std::stringstream ss(dotted_key);
  std::string part;
  while (std::getline(ss, part, '.')) parts.push_back(part);
  if (parts.empty()) throw Error("override: empty key");
  YAML::Node node = impl_->node;
  for (std::size_t i = 0; i + 1 < parts.size(); ++i) {
    YAML::Node child = node[parts[i]];
    if (!child.IsDefined() || child.IsNull()) {
      node[parts[i]] = YAML::Node(YAML::NodeType::Map);
    } else if (!child.IsMap()) {
      throw Error("override " + dotted_key + ": '" + parts[i] + "' is not a section");
    }
    node.reset(node[parts[i]]);
  }
  node[parts.back()] = value;
  impl_->overrides.push_back(dotted_key);
}

std::string Config::ToYaml() const {
  YAML::Emitter out;
  out << impl_->node;
  return out.c_str();
}

}  // namespace artex
