// Per-triangle view selection as an MRF (paper eq. 12-14): labels are pool images plus one
// "untextured" label; D from quality and lifetime (plus the optional switch cost,
// TextureTermOptions::switch_cost), V = (1 - alpha) Pi + alpha Psi on every interior edge,
// solved by any MrfSolver (solvers/mrf.h), warm-started from the previous labelling.
#pragma once

#include <string>
#include <vector>

#include "energies/texture_terms.h"
#include "solvers/mrf.h"
#include "texture/image_pool.h"

namespace artex {

struct ViewSelectionOptions {
  TextureTermOptions terms;
  // Unary cost of leaving a triangle untextured (must exceed every finite D, which is <= 1).
  double untextured_cost = 2.0;
  // Keep only the best `max_candidates` images per triangle by D (plus its warm-start label);
  // 0 keeps all. Bounds the MRF size for a large pool. With the lifetime term the best are the
  // newest images; docs/texturing.md measures the energy each limit leaves (BM_CandidateLimit:
  // 3 costs 8e-5 of the energy against 4 and saves ~11 % of a frame).
  int max_candidates = 3;
  // Pi for a label pair where one side has no colour along the edge.
  double unseen_colour_cost = 1.0;

  bool IsValid(std::string* error) const;
};

struct ViewSelectionInput {
  const TextureMesh* mesh = nullptr;
  const ImagePool* pool = nullptr;
  int current_frame = 0;
  // F: previous labels as pool frame indices (-1 untextured or unknown); may be empty.
  std::vector<int> previous_frames;
  // V: distance (m) along the rest mesh to the previous labelling's seams (+inf: none).
  std::vector<double> seam_distance;
  // E: 3D edge lengths (rest mesh) normalised by their mean.
  std::vector<double> edge_weight;
};

struct ViewSelectionResult {
  std::vector<int> frames;  // F: chosen pool frame index per triangle, -1 untextured
  MrfSummary mrf;
  int num_candidates = 0;  // sum over triangles
};

// Triangles seen by no pooled image (only "untextured" is possible) are not MRF nodes: their
// pairwise terms become unaries of their neighbours and their data costs one isolated node with
// a single label; energies and bounds are those of the whole labelling. Throws artex::Error for
// invalid options.
ViewSelectionResult SelectViews(const ViewSelectionInput& input,
                                const ViewSelectionOptions& options, MrfSolver* solver);

}  // namespace artex
