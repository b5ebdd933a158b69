// Small helpers of the options' IsValid checks in sensors/ (virtual Kinect, scene, synthesis):
// a failure that fills the optional message, and a value as text for it.
#pragma once

#include <sstream>
#include <string>

namespace artex {
namespace option_text {

// Sets *error (when given) to message and returns false.
inline bool Fail(std::string* error, const std::string& message) {
  if (error) *error = message;
  return false;
}

template <typename T>
std::string Str(const T& value) {
  std::ostringstream s;
  s << value;
  return s.str();
}

}  // namespace option_text
}  // namespace artex
