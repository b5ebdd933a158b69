#include "texture/texturer.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <opencv2/imgproc.hpp>
#include <sstream>

#include "models/error.h"
#include "models/numeric.h"
#include "render/rasterizer.h"
#include "sensors/subject_texture.h"

namespace artex {

bool TexturingOptions::IsValid(std::string* error) const {
  if (!selection.IsValid(error) || !mrf.IsValid(error) || !pool.IsValid(error) ||
      !visibility.IsValid(error) || !levelling.IsValid(error))
    return false;
  std::ostringstream msg;
  if (atlas_size < 16)
    msg << "texture.atlas_size: expected >= 16, found " << atlas_size;
  else if (padding_texels < 0)
    msg << "texture.padding_texels: expected >= 0, found " << padding_texels;
  else if (add_every < 1)
    msg << "texture.add_every: expected >= 1, found " << add_every;
  if (msg.str().empty()) return true;
  if (error) *error = msg.str();
  return false;
}

Texturer::Texturer(const Template& tmpl, const TexturingOptions& options)
    : template_(tmpl), options_(options) {
  std::string why;
  if (!options_.IsValid(&why)) throw Error(why);
  mesh_ = TextureMesh::Build(template_.triangles);
  map_ = std::make_unique<AtlasMap>(template_, options_.atlas_size);
  pool_ = std::make_unique<ImagePool>(&mesh_, options_.pool, options_.visibility);
  solver_ = MrfSolver::Create(options_.mrf);
  geodesics_ = std::make_unique<MeshGeodesics>(template_.vertices, template_.triangles);
  if (options_.seam_levelling) {
    leveller_ = std::make_unique<SeamLeveller>(template_.num_vertices(), template_.triangles,
                                               options_.levelling);
  }
  base_ = TexelBuffer(*map_);
  frames_.assign(template_.num_triangles(), -1);
  seam_distance_.assign(template_.num_vertices(), std::numeric_limits<double>::infinity());
  const int e_count = static_cast<int>(mesh_.edges.rows());
  edge_weight_.resize(e_count);
  double mean = 0.0;
  for (int e = 0; e < e_count; ++e) {
    edge_weight_[e] =
        (template_.vertices.row(mesh_.edges(e, 0)) - template_.vertices.row(mesh_.edges(e, 1)))
            .norm();
    mean += edge_weight_[e];
  }
  mean = e_count > 0 ? mean / e_count : 1.0;
  for (double& w : edge_weight_) w /= mean;
  corrections_.setZero(3 * template_.num_triangles(), 3);
}

Texturer::~Texturer() = default;

TextureFrameSummary Texturer::AddFrame(int frame, const cv::Mat& color_bgr,
                                       const PinholeCamera& camera,
                                       const Eigen::MatrixX3d& posed_vertices) {
  return AddPrepared(PrepareFrame(frame, color_bgr, camera, posed_vertices));
}

PreparedFrame Texturer::PrepareFrame(int frame, const cv::Mat& color_bgr,
                                     const PinholeCamera& camera,
                                     const Eigen::MatrixX3d& posed_vertices) {
  const auto start = std::chrono::steady_clock::now();
  if (posed_vertices.rows() != template_.num_vertices() || !posed_vertices.allFinite()) {
    std::ostringstream msg;
    msg << "texturing frame " << frame << ": expected " << template_.num_vertices()
        << " finite posed vertices, found " << posed_vertices.rows();
    throw Error(msg.str());
  }
  PreparedFrame prepared;
  prepared.frame = frame;
  if (frames_seen_++ % options_.add_every == 0)
    prepared.entry = pool_->MakeEntry(frame, color_bgr, camera, posed_vertices);
  prepared.seconds = SecondsSince(start);
  return prepared;
}

TextureFrameSummary Texturer::AddPrepared(PreparedFrame prepared) {
  const auto start = std::chrono::steady_clock::now();
  TextureFrameSummary s;
  const int frame = prepared.frame;
  s.frame = frame;
  if (prepared.entry) {
    pool_->Insert(std::move(prepared.entry));
    pool_->Prune();
    s.image_added = true;
  }
  s.seconds_pool = prepared.seconds + SecondsSince(start);
  s.pool_size = pool_->size();
  s.pool_bytes = pool_->MemoryBytes();

  const auto t_mrf = std::chrono::steady_clock::now();
  ViewSelectionInput input;
  input.mesh = &mesh_;
  input.pool = pool_.get();
  input.current_frame = frame;
  input.previous_frames = frames_;
  input.seam_distance = seam_distance_;
  input.edge_weight = edge_weight_;
  ViewSelectionResult result = SelectViews(input, options_.selection, solver_.get());
  s.seconds_mrf = SecondsSince(t_mrf);
  s.energy = result.mrf.energy;
  s.lower_bound = result.mrf.lower_bound;
  s.mrf_iterations = result.mrf.iterations;

  const int f_count = template_.num_triangles();
  changed_.clear();
  for (int f = 0; f < f_count; ++f) {
    if (result.frames[f] != frames_[f]) changed_.push_back(f);
  }
  s.changed_triangles = static_cast<int>(changed_.size());
  frames_ = std::move(result.frames);
  for (int f = 0; f < f_count; ++f) s.textured_triangles += frames_[f] >= 0;

  // Three independent tasks on the new labelling: resampling of the changed triangles, Psi's
  // distance field for the next frame, and seam levelling.
  const auto resample = [&] {
    const auto t_sample = std::chrono::steady_clock::now();
    // Resample only where the source image changed (labels always name pooled images). Every
    // texel belongs to one triangle, so triangles are written in parallel.
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, changed_.size(), 16),
                      [&](const tbb::blocked_range<std::size_t>& range) {
                        for (std::size_t k = range.begin(); k < range.end(); ++k) {
                          const int f = changed_[k];
                          if (frames_[f] < 0) {
                            ClearTriangle(*map_, f, &base_);
                          } else {
                            SampleTriangle(*map_, f, template_.triangles,
                                           pool_->entry(pool_->SlotOfFrame(frames_[f])), &base_);
                          }
                        }
                      });
    s.seconds_sampling = SecondsSince(t_sample);
  };
  const auto seams = [&] {
    std::vector<int> seam_vertices;
    for (int e = 0; e < mesh_.edges.rows(); ++e) {
      if (frames_[mesh_.edge_faces(e, 0)] != frames_[mesh_.edge_faces(e, 1)]) {
        ++s.seam_edges;
        seam_vertices.push_back(mesh_.edges(e, 0));
        seam_vertices.push_back(mesh_.edges(e, 1));
      }
    }
    // Psi = min(1, d / seam_distance_scale) of an edge's mean vertex distance d: an edge with
    // d < seam_distance_scale has both ends within seam_distance_scale plus half its length,
    // so distances beyond seam_distance_scale plus the longest edge are not needed (Psi = 1).
    seam_distance_ =
        geodesics_->DistanceField(seam_vertices, options_.selection.terms.seam_distance_scale +
                                                     geodesics_->max_edge_length());
  };
  const bool level_now = options_.seam_levelling && options_.levelling_every_frame;
  levelled_ = !options_.seam_levelling;
  levelling_seconds_ = 0.0;
  if (!options_.seam_levelling) {
    corrections_.setZero(3 * f_count, 3);
    seam_rms_before_ = seam_rms_after_ = 0.0;
  }
  const auto level = [&] {
    if (!level_now) return;
    s.seconds_levelling = LevelSeams();
    s.seam_rms_before = seam_rms_before_;
    s.seam_rms_after = seam_rms_after_;
  };
  if (options_.seam_levelling && !level_now) {
    s.seam_rms_before = s.seam_rms_after = std::numeric_limits<double>::quiet_NaN();
  }
  tbb::parallel_invoke(resample, seams, level);
  s.seconds_total = prepared.seconds + SecondsSince(start);
  return s;
}

double Texturer::LevelSeams() const {
  if (levelled_) return 0.0;
  const auto start = std::chrono::steady_clock::now();
  SeamLevellingSummary ls;
  leveller_->Level(
      frames_,
      [this](int v, int frame_index, Eigen::Vector3f* c) {
        const int slot = pool_->SlotOfFrame(frame_index);
        if (slot < 0) return false;
        const PoolEntry& entry = pool_->entry(slot);
        if (!entry.vertex_coloured[v]) return false;
        *c = entry.vertex_colors.row(v).transpose();
        return true;
      },
      &corrections_, &ls);
  seam_rms_before_ = ls.seam_residual_before;
  seam_rms_after_ = ls.seam_residual_after;
  levelled_ = true;
  const double seconds = SecondsSince(start);
  levelling_seconds_ += seconds;
  return seconds;
}

double Texturer::seam_rms_before() const {
  LevelSeams();
  return seam_rms_before_;
}

double Texturer::seam_rms_after() const {
  LevelSeams();
  return seam_rms_after_;
}

int Texturer::ColouredVertexCount() const {
  std::vector<uint8_t> seen(template_.num_vertices(), 0);
  ForEachColouredCorner([&](int, int, int v, const Eigen::RowVector3f&) { seen[v] = 1; });
  int count = 0;
  for (uint8_t b : seen) count += b;
  return count;
}

cv::Mat Texturer::Atlas() const {
  LevelSeams();
  return ComposeAtlas(*map_, base_, options_.seam_levelling ? &corrections_ : nullptr,
                      options_.padding_texels, &atlas_scratch_);
}

void Texturer::VertexColors(Eigen::MatrixX3d* rgb, std::vector<uint8_t>* valid) const {
  LevelSeams();
  const int v_count = template_.num_vertices();
  Eigen::MatrixX3d sum = Eigen::MatrixX3d::Zero(v_count, 3);
  std::vector<int> count(v_count, 0);
  ForEachColouredCorner([&](int f, int c, int v, const Eigen::RowVector3f& col) {
    Eigen::Vector3d bgr = (col + corrections_.row(3 * f + c)).cast<double>().transpose();
    sum.row(v) += Eigen::Vector3d(bgr.z(), bgr.y(), bgr.x()).transpose();
    ++count[v];
  });
  rgb->setZero(v_count, 3);
  valid->assign(v_count, 0);
  for (int v = 0; v < v_count; ++v) {
    if (count[v] == 0) continue;
    rgb->row(v) = (sum.row(v) / count[v]).cwiseMax(0.0).cwiseMin(1.0);
    (*valid)[v] = 1;
  }
}

cv::Mat Texturer::ChangedPatch() const {
  const int size = map_->size();
  int x0 = size, y0 = size, x1 = -1, y1 = -1;
  for (int f : changed_) {
    for (const int* t = map_->texels_begin(f); t != map_->texels_end(f); ++t) {
      x0 = std::min(x0, *t % size);
      x1 = std::max(x1, *t % size);
      y0 = std::min(y0, *t / size);
      y1 = std::max(y1, *t / size);
    }
  }
  if (x1 < x0) return cv::Mat();
  return UnlevelledPatch(*map_, base_, cv::Rect(x0, y0, x1 - x0 + 1, y1 - y0 + 1));
}

cv::Mat Texturer::LabelMap() const {
  const int size = map_->size();
  cv::Mat out(size, size, CV_8UC3, cv::Scalar(0, 0, 0));
  for (int f = 0; f < template_.num_triangles(); ++f) {
    if (frames_[f] < 0) continue;
    // A fixed pseudo-random colour per source frame (golden-ratio hue walk).
    const double hue = std::fmod(frames_[f] * 0.618033988749895, 1.0) * 180.0;
    cv::Mat hsv(1, 1, CV_8UC3, cv::Scalar(hue, 200, 230)), bgr;
    cv::cvtColor(hsv, bgr, cv::COLOR_HSV2BGR);
    const cv::Vec3b color = bgr.at<cv::Vec3b>(0, 0);
    for (const int* t = map_->texels_begin(f); t != map_->texels_end(f); ++t)
      out.at<cv::Vec3b>(*t / size, *t % size) = color;
  }
  return out;
}

namespace {

// RenderTextured's pixels from the raster: the atlas sampled bilinearly at each covered pixel's
// UV (frames: skip triangles with a negative entry; null: none). image and mask are continuous,
// of the raster's size. The pointers are locals (parameters): the byte stores could alias
// anything reached through memory, which would be reloaded at every pixel.
void PaintTextured(const RasterBuffers& buffers, const Template& tmpl, const cv::Mat& atlas,
                   const int* frames, cv::Vec3b* image, uint8_t* mask) {
  const int pixels = buffers.width * buffers.height;
  const int32_t* ids = buffers.triangle_id.data();
  const Eigen::Vector2f* barycentric = buffers.barycentric.data();
  const Eigen::Map<const Eigen::MatrixX2d> uvs(tmpl.uvs.data(), tmpl.uvs.rows(), 2);
  const Eigen::Map<const Eigen::MatrixX3i> uv_triangles(tmpl.uv_triangles.data(),
                                                        tmpl.uv_triangles.rows(), 3);
  const uint8_t* texels = atlas.data;
  const std::size_t step = atlas.step[0];
  const int width = atlas.cols, height = atlas.rows;
  for (int i = 0; i < pixels; ++i) {
    const int f = ids[i];
    if (f < 0 || (frames && frames[f] < 0)) continue;
    const Eigen::Vector2f b = barycentric[i];
    const Eigen::Vector2d uv = (1.0 - b.x() - b.y()) * uvs.row(uv_triangles(f, 0)) +
                               b.x() * uvs.row(uv_triangles(f, 1)) +
                               b.y() * uvs.row(uv_triangles(f, 2));
    const Eigen::Vector3d rgb =
        255.0 * SampleTextureBilinear(texels, step, width, height, uv);
    image[i] = cv::Vec3b(cv::saturate_cast<uchar>(rgb[2]), cv::saturate_cast<uchar>(rgb[1]),
                         cv::saturate_cast<uchar>(rgb[0]));
    mask[i] = 255;
  }
}

}  // namespace

void RenderTextured(const Template& tmpl, const Eigen::MatrixX3d& posed_vertices,
                    const cv::Mat& atlas, const PinholeCamera& camera, cv::Mat* image,
                    cv::Mat* mask, const std::vector<int>* triangle_frames) {
  if (atlas.type() != CV_8UC3 || atlas.empty())
    throw Error("RenderTextured: expected an 8-bit 3-channel atlas image");
  if (!tmpl.has_uvs()) throw Error("RenderTextured: the template has no UV atlas");
  if (triangle_frames && static_cast<int>(triangle_frames->size()) != tmpl.num_triangles())
    throw Error("RenderTextured: expected one source frame per triangle (" +
                std::to_string(tmpl.num_triangles()) + "), found " +
                std::to_string(triangle_frames->size()));
  RasterBuffers buffers;
  Rasterize(posed_vertices, tmpl.triangles, camera, RasterOptions(), &buffers);
  *image = cv::Mat(camera.height, camera.width, CV_8UC3, cv::Scalar(0, 0, 0));
  *mask = cv::Mat(camera.height, camera.width, CV_8UC1, cv::Scalar(0));
  PaintTextured(buffers, tmpl, atlas, triangle_frames ? triangle_frames->data() : nullptr,
                reinterpret_cast<cv::Vec3b*>(image->data), mask->data);
}

}  // namespace artex
