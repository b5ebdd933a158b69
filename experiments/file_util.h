// Whole-file reads shared by the experiment runner, the Slurm backend and the commands.
#pragma once

#include <string>

namespace artex {

// The bytes of the file at `path`; "" when it cannot be opened (an absent record, marker or
// log reads as empty). Never throws for a missing file.
std::string ReadText(const std::string& path);

// The bytes of the file at `path`; throws artex::Error "<path>: cannot open" when it cannot be
// opened.
std::string ReadTextOrThrow(const std::string& path);

}  // namespace artex
