// Test helper: the message of the artex::Error that `f` throws, or "" when it throws none.
#pragma once

#include <functional>
#include <string>

#include "models/error.h"

namespace artex {

inline std::string ErrorOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

}  // namespace artex
