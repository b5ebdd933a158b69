// Configuration files (YAML) mapped onto options structs. A Config is one mapping node with
// the file name and key path it came from, so every error names file, key, expected and found.
// Unknown keys are errors that list the valid ones (see CheckKeys).
#pragma once

#include <map>
#include <memory>
#include <string>
#include <vector>

namespace artex {

class Config {
 public:
  Config();  // empty mapping
  ~Config();
  Config(const Config&);
  Config& operator=(const Config&);

  // Throws artex::Error naming the file when it is missing or not valid YAML.
  static Config Load(const std::string& path);
  static Config FromString(const std::string& yaml, const std::string& source_name);

  bool Has(const std::string& key) const;
  // A nested mapping (empty Config when absent; artex::Error when present but not a mapping).
  Config Section(const std::string& key) const;
  std::vector<std::string> Keys() const;
  std::string Path(const std::string& key) const;  // "file: a.b.key" for messages

  // Each Get leaves *value untouched when the key is absent and throws artex::Error when the
  // value has the wrong type or is not finite.
  void Get(const std::string& key, double* value) const;
  void Get(const std::string& key, int* value) const;
  void Get(const std::string& key, bool* value) const;
  void Get(const std::string& key, std::string* value) const;
  void Get(const std::string& key, std::vector<double>* value) const;
  void Get(const std::string& key, std::vector<std::string>* value) const;
  // Reads a string and maps it through `choices`; an unknown value lists the valid ones.
  template <typename Enum>
  void GetEnum(const std::string& key, const std::map<std::string, Enum>& choices,
               Enum* value) const {
    if (!Has(key)) return;
    std::string s;
    Get(key, &s);
    *value = Choice(key, s, choices);
  }
  // A list of names, each mapped through `choices` (an unknown one lists the valid ones).
  template <typename Enum>
  void GetEnumList(const std::string& key, const std::map<std::string, Enum>& choices,
                   std::vector<Enum>* value) const {
    if (!Has(key)) return;
    std::vector<std::string> names;
    Get(key, &names);
    std::vector<Enum> out;
    for (const std::string& s : names) out.push_back(Choice(key, s, choices));
    *value = out;
  }
  // Throws when the mapping holds a key not in `valid`, listing the valid keys.
  void CheckKeys(const std::vector<std::string>& valid) const;

  // Sets a dotted key ("fitting.solver") to a YAML scalar/sequence given as text (overrides).
  void Set(const std::string& dotted_key, const std::string& yaml_value);
  std::string ToYaml() const;  // for writing the resolved configuration

 private:
  // `name` mapped through `choices`; an unknown name throws, listing the valid ones.
  template <typename Enum>
  Enum Choice(const std::string& key, const std::string& name,
              const std::map<std::string, Enum>& choices) const {
    auto it = choices.find(name);
    if (it == choices.end()) ThrowChoice(key, name, choices);
    return it->second;
  }
  template <typename Enum>
  [[noreturn]] void ThrowChoice(const std::string& key, const std::string& found,
                                const std::map<std::string, Enum>& choices) const {
    std::vector<std::string> names;
    for (const auto& kv : choices) names.push_back(kv.first);
    ThrowInvalidChoice(key, found, names);
  }
  [[noreturn]] void ThrowInvalidChoice(const std::string& key, const std::string& found,
                                       const std::vector<std::string>& valid) const;
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace artex
