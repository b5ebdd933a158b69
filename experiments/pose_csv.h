// Pose tables as CSV (poses.csv of `artex track` runs, groundtruth/poses.csv of sequences, and
// pose files given to the CLI): one pose vector per row (models/pose.h ToVector layout), with
// an optional header whose first column "frame" marks a leading frame-index column.
#pragma once

#include <Eigen/Core>
#include <string>
#include <utility>
#include <vector>

#include "models/pose.h"
#include "models/template.h"

namespace artex {

// Numbers separated by commas and/or whitespace; throws artex::Error naming `what` and the
// field on a non-number.
Eigen::VectorXd ParseNumberList(const std::string& text, const std::string& what);

// (frame, pose) per row, in file order (rows without a frame column are numbered 0, 1, ...).
// Blank lines and lines starting with '#' are skipped. Throws artex::Error naming path:line on
// a malformed row and when the file is missing or has no pose rows.
std::vector<std::pair<int, Pose>> ReadPoseCsv(const std::string& path, int num_joints);

// Writes frame,scale,tx,ty,tz,rx,ry,rz,<joint>_x,... atomically.
void WritePoseCsv(const std::string& path, const Template& tmpl, const std::vector<int>& frames,
                  const std::vector<Pose>& poses);

}  // namespace artex
