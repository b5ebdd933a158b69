// The one exception type artex throws for bad input (files, fields, options). Its message
// names the file or field, what was expected and what was found; the CLI prints it and
// exits non-zero. Programming errors (broken invariants) are not reported through it.
#pragma once

#include <sstream>
#include <stdexcept>
#include <string>

namespace artex {

class Error : public std::runtime_error {
 public:
  explicit Error(const std::string& message) : std::runtime_error(message) {}
};

// A number as error messages quote it: 9 significant digits.
inline std::string ErrorNumber(double x) {
  std::ostringstream s;
  s.precision(9);
  s << x;
  return s.str();
}

}  // namespace artex
