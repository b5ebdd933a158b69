// Resource exhaustion while reading a file, named (docs/reliability.md).
#pragma once

#include <new>
#include <stdexcept>
#include <string>

#include "models/error.h"

namespace artex {

// Runs `read()` (a reader of `path`) and turns resource exhaustion into an artex::Error naming
// the file: std::bad_alloc and std::length_error (vector::reserve / resize beyond max_size)
// come from a count in the file that no cap caught.
template <class Read>
auto WithFileContext(const std::string& path, Read&& read) -> decltype(read()) {
  try {
    return read();
  } catch (const std::bad_alloc&) {
    throw Error(path + ": out of memory while reading the file: expected counts that fit in " +
                "memory, found more (a corrupt or hostile file)");
  } catch (const std::length_error& e) {
    throw Error(path + ": a count in the file is too large (" + e.what() + ")");
  }
}

}  // namespace artex
