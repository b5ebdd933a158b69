// Checks shared by artex's YAML readers (calibration.yaml, camera.yaml, configurations,
// experiment files): yaml-cpp keeps the first of two equal keys and drops the second silently,
// so every mapping is checked for duplicate keys, and non-scalar keys are rejected (their
// conversion to a string is yaml-cpp's unnamed "bad conversion").
#pragma once

#include <yaml-cpp/yaml.h>

#include <filesystem>
#include <map>
#include <set>
#include <string>
#include <vector>

#include "models/error.h"

namespace artex {

// Throws artex::Error "<file>: line L: key 'a.b': defined twice (first at line K)" for the
// first duplicate key of any mapping under `node`, or a non-scalar key. Iterative (no
// recursion on deeply nested documents).
inline void CheckYamlKeys(const YAML::Node& node, const std::string& file) {
  struct Item {
    YAML::Node node;
    std::string prefix;
  };
  std::vector<Item> stack = {{node, ""}};
  while (!stack.empty()) {
    const Item item = stack.back();
    stack.pop_back();
    if (item.node.IsMap()) {
      std::map<std::string, int> lines;
      for (const auto& kv : item.node) {
        const int line = kv.first.Mark().line + 1;
        if (!kv.first.IsScalar()) {
          throw Error(file + ": line " + std::to_string(line) + ": under '" + item.prefix +
                      "': expected a plain key, found a list or mapping as a key");
        }
        const std::string key =
            item.prefix.empty() ? kv.first.Scalar() : item.prefix + "." + kv.first.Scalar();
        const auto [it, fresh] = lines.emplace(kv.first.Scalar(), line);
        if (!fresh) {
          throw Error(file + ": line " + std::to_string(line) + ": key '" + key +
                      "': defined twice (first at line " + std::to_string(it->second) + ")");
        }
        stack.push_back({kv.second, key});
      }
    } else if (item.node.IsSequence()) {
      for (std::size_t i = 0; i < item.node.size(); ++i) {
        stack.push_back({item.node[i], item.prefix + "[" + std::to_string(i) + "]"});
      }
    }
  }
}

// Throws artex::Error naming `path` when it is a folder (a stream over a folder fails with
// "basic_filebuf::underflow" and no path).
inline void CheckNotAFolder(const std::string& path, const std::string& what) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) {
    throw Error(path + ": expected " + what + ", found a folder");
  }
}

}  // namespace artex
