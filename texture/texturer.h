// On-the-fly texturing (paper sec. 4), one call per frame: the frame's colour image joins the
// pool (visibility, colours), the pool is pruned, views are selected per triangle by an MRF
// warm-started from the previous frame, texels of triangles whose source changed are resampled,
// and seams are levelled. The atlas and per-vertex colours (the fitting's rgb(v'_t)) are read
// from the current state at any time.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <memory>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "models/template.h"
#include "solvers/mrf.h"
#include "solvers/seam_levelling.h"
#include "texture/image_pool.h"
#include "texture/texel_sampling.h"
#include "texture/view_selection.h"

namespace artex {

struct TexturingOptions {
  ViewSelectionOptions selection;
  // View-selection solver: alpha-expansion, warm-started from the previous frame's labelling,
  // one sweep (one expansion per label) per frame by default, so the minimisation goes on over
  // the frames instead of converging within each; docs/texturing.md measures the energy this
  // leaves per frame (4e-5 relative on the walk benchmark). max_iterations = 50 converges.
  MrfSolverOptions mrf = [] {
    MrfSolverOptions o;
    o.max_iterations = 1;
    return o;
  }();
  ImagePoolOptions pool;
  VisibilityOptions visibility;
  int atlas_size = 1024;       // atlas side (texels); >= 16
  int padding_texels = 4;      // dilation passes at chart borders when composing the atlas
  bool seam_levelling = true;  // Lempitsky-Ivanov levelling on/off
  SeamLevellingOptions levelling;
  // texture.levelling_every_frame. false: the seams are levelled when the texture is read
  // (Atlas, VertexColors, LevelSeams) and the labelling changed since the last levelling, not
  // in every AddFrame: the same atlas and colours bit for bit, but a frame's summary has no
  // seam_rms_before/after (NaN; LevelSeams reports them). true: every AddFrame levels.
  bool levelling_every_frame = false;
  int add_every = 1;  // add every n-th frame's image to the pool; >= 1

  bool IsValid(std::string* error) const;
};

struct TextureFrameSummary {
  int frame = 0;
  bool image_added = false;
  double energy = 0.0;
  double lower_bound = 0.0;  // -inf when the MRF solver gives none
  int mrf_iterations = 0;
  int pool_size = 0;
  std::size_t pool_bytes = 0;
  int seam_edges = 0;         // interior edges whose triangles use different images
  int changed_triangles = 0;  // triangles whose source image changed
  int textured_triangles = 0;
  double seam_rms_before = 0.0;  // RMS colour jump at seam vertices before levelling
  double seam_rms_after = 0.0;
  double seconds_pool = 0.0, seconds_mrf = 0.0, seconds_sampling = 0.0, seconds_levelling = 0.0,
         seconds_total = 0.0;
};

// A frame's image made ready to join the pool (Texturer::PrepareFrame).
struct PreparedFrame {
  int frame = -1;
  std::unique_ptr<PoolEntry> entry;  // null: the image does not join the pool (add_every)
  double seconds = 0.0;              // wall time of the preparation
};

class Texturer {
 public:
  // Throws artex::Error for invalid options or a template without UVs.
  Texturer(const Template& tmpl, const TexturingOptions& options);
  ~Texturer();

  // color_bgr: the full colour image (CV_8UC3) of `frame`; camera: the colour camera;
  // posed_vertices: V x 3 fitted template of that frame (world, m).
  // AddPrepared(PrepareFrame(...)).
  TextureFrameSummary AddFrame(int frame, const cv::Mat& color_bgr, const PinholeCamera& camera,
                               const Eigen::MatrixX3d& posed_vertices);
  // AddFrame in two halves, for two threads: the image of frame t+1 is prepared while frame t
  // is textured. PrepareFrame decides whether the image joins the pool (every add_every-th
  // call) and builds its entry (visibility, colours; ImagePool::MakeEntry); it reads only the
  // template's mesh and the options, so one thread may call it while another calls
  // AddPrepared. AddPrepared does the rest of AddFrame (pooling, pruning, view selection,
  // resampling, levelling). Every PrepareFrame's result goes to AddPrepared once, in the
  // order of the PrepareFrame calls; the results are those of AddFrame bit for bit.
  // PrepareFrame throws artex::Error for posed vertices of the wrong count or not finite.
  PreparedFrame PrepareFrame(int frame, const cv::Mat& color_bgr, const PinholeCamera& camera,
                             const Eigen::MatrixX3d& posed_vertices);
  TextureFrameSummary AddPrepared(PreparedFrame prepared);

  // The current atlas (CV_8UC3, BGR, atlas_size^2): levelled (when on) and padded. Levels the
  // seams first when they are not (LevelSeams). Composed in working images the texturer keeps
  // (13 bytes a texel): not to be called from two threads at once.
  cv::Mat Atlas() const;
  // Levels the seams of the current labelling unless that was done (by AddFrame with
  // levelling_every_frame, or by an earlier read); returns the wall seconds it took now (0:
  // nothing to do). Atlas and VertexColors call it: like them it is not to be called
  // concurrently with other calls on this texturer (PrepareFrame apart).
  double LevelSeams() const;
  // RMS colour jump at the seam vertices of the current labelling before and after levelling
  // (LevelSeams first when they are not levelled; 0 without seams or with levelling off).
  double seam_rms_before() const;
  double seam_rms_after() const;
  // Whether the current labelling's seams are levelled (always with levelling off), and the
  // wall seconds LevelSeams spent since the last AddFrame.
  bool seams_levelled() const { return levelled_; }
  double levelling_seconds_since_add() const { return levelling_seconds_; }
  // F: source frame per triangle, -1 untextured.
  const std::vector<int>& triangle_frames() const { return frames_; }
  // V x 3 RGB in [0, 1] per template vertex from the current texture; valid[v] = 0 where no
  // incident triangle is textured. Levels the seams first when they are not (LevelSeams).
  void VertexColors(Eigen::MatrixX3d* rgb, std::vector<uint8_t>* valid) const;
  // How many vertices VertexColors would mark valid, without levelling.
  int ColouredVertexCount() const;
  // A label map for inspection: every triangle's UV footprint coloured by its source frame.
  cv::Mat LabelMap() const;
  // Triangles whose source image changed in the last AddFrame (their texels were resampled).
  const std::vector<int>& last_changed_triangles() const { return changed_; }
  // The bounding box of the last frame's resampled texels, cut from the unlevelled atlas
  // (CV_8UC3; empty when nothing changed): what a receiver needs to update its texture.
  cv::Mat ChangedPatch() const;
  const ImagePool& pool() const { return *pool_; }
  const TextureMesh& mesh() const { return mesh_; }
  const AtlasMap& atlas_map() const { return *map_; }
  // V: distance (m, along the rest mesh) to the current labelling's seams (Psi of the next
  // frame; +inf without seams, and beyond seam_distance_scale plus the longest rest edge, where
  // Psi = 1). E: rest edge lengths over their mean (the MRF edge weights).
  const std::vector<double>& seam_distance() const { return seam_distance_; }
  const std::vector<double>& edge_weight() const { return edge_weight_; }

 private:
  // visit(f, c, v, colour) for every corner c (vertex v) of a textured triangle f whose source
  // image saw v (finite pooled vertex colour, BGR in [0, 1]), triangles ascending.
  template <class Visit>
  void ForEachColouredCorner(Visit&& visit) const {
    int memo_frame = -1, slot = -1;  // the last frame looked up (neighbours share sources)
    for (int f = 0; f < template_.num_triangles(); ++f) {
      if (frames_[f] < 0) continue;
      if (frames_[f] != memo_frame) {
        memo_frame = frames_[f];
        slot = pool_->SlotOfFrame(memo_frame);
      }
      if (slot < 0) continue;
      const PoolEntry& entry = pool_->entry(slot);
      for (int c = 0; c < 3; ++c) {
        const int v = template_.triangles(f, c);
        if (entry.vertex_coloured[v]) visit(f, c, v, entry.vertex_colors.row(v));
      }
    }
  }

  Template template_;
  TexturingOptions options_;
  TextureMesh mesh_;
  std::unique_ptr<AtlasMap> map_;
  std::unique_ptr<ImagePool> pool_;
  std::unique_ptr<MrfSolver> solver_;
  std::unique_ptr<MeshGeodesics> geodesics_;  // rest mesh, for Psi's distance field
  // Levelling runs on reads too (LevelSeams is const): its state is mutable.
  std::unique_ptr<SeamLeveller> leveller_;
  mutable bool levelled_ = true;  // corrections_ belong to the current labelling
  mutable double seam_rms_before_ = 0.0, seam_rms_after_ = 0.0;
  mutable double levelling_seconds_ = 0.0;  // LevelSeams since the last AddPrepared
  TexelBuffer base_;         // unlevelled texel colours (triangle-major)
  std::vector<int> frames_;  // F
  std::vector<double> seam_distance_;
  std::vector<double> edge_weight_;
  mutable Eigen::MatrixX3f corrections_;  // 3F x 3
  mutable AtlasScratch atlas_scratch_;    // Atlas()'s working images
  std::vector<int> changed_;
  int frames_seen_ = 0;  // PrepareFrame calls (only PrepareFrame reads and writes it)
};

// Renders a textured template (per-corner UVs into `atlas`, bilinear) through a camera: the
// image (CV_8UC3, BGR) and a coverage mask (CV_8UC1). Background pixels are black. With
// `triangle_frames` (F, as Texturer::triangle_frames), triangles with a negative entry are
// left out of the mask (and black): the mask then marks the textured surface.
void RenderTextured(const Template& tmpl, const Eigen::MatrixX3d& posed_vertices,
                    const cv::Mat& atlas, const PinholeCamera& camera, cv::Mat* image,
                    cv::Mat* mask, const std::vector<int>* triangle_frames = nullptr);

}  // namespace artex
