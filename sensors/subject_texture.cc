#include "sensors/subject_texture.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <limits>
#include <random>
#include <sstream>
#include <vector>

#include "models/error.h"
#include "models/numeric.h"
#include "models/uv_raster.h"

namespace artex {
namespace {

// Pattern geometry relative to body landmarks (fractions of the measured extents); these
// define the look of the garments, not tunable physics.
constexpr double kPanelBottom = 0.50, kPanelTop = 0.85;  // chest panel: waist -> shoulder
constexpr double kPanelHalfWidth = 0.40;                 // of the shoulder half-breadth
constexpr double kFrontNormal = 0.45;                    // normal z above which is "front"
constexpr double kEyeHeight = 0.58, kMouthHeight = 0.30, kHairLine = 0.78;  // of head height
constexpr double kShoeTop = 0.03;    // m above the ankle centre
constexpr double kSoleTop = 0.015;   // m above the floor
constexpr double kChartTint = 0.10;  // relative colour change per chart

uint64_t SplitMix(uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}
double Hash01(uint64_t a, uint64_t b, uint64_t c) {
  return (SplitMix(SplitMix(SplitMix(a) ^ b) ^ c) >> 11) * (1.0 / 9007199254740992.0);
}

enum class Part { kShirt, kSleeve, kForearm, kHand, kHead, kNeck, kTrousers, kFoot };

Part PartOfJoint(const std::string& name) {
  if (name == "head") return Part::kHead;
  if (name == "neck") return Part::kNeck;
  if (name == "l_wrist" || name == "r_wrist") return Part::kHand;
  if (name == "l_elbow" || name == "r_elbow") return Part::kForearm;
  if (name == "l_shoulder" || name == "r_shoulder") return Part::kSleeve;
  if (name == "pelvis" || name == "l_hip" || name == "r_hip" || name == "l_knee" ||
      name == "r_knee") {
    return Part::kTrousers;
  }
  if (name == "l_ankle" || name == "r_ankle") return Part::kFoot;
  return Part::kShirt;  // spine, chest and unknown names
}

struct Palette {
  Eigen::Vector3d shirt_a, shirt_b, sleeve, pinstripe, trousers, plaid_line, skin, hair, shoe, sole,
      panel, ink, lips, eye_white, iris;
};

Palette MakePalette(std::mt19937_64* rng) {
  const std::array<Eigen::Vector3d, 5> shirts = {
      Eigen::Vector3d(0.80, 0.15, 0.12), Eigen::Vector3d(0.12, 0.35, 0.75),
      Eigen::Vector3d(0.15, 0.55, 0.25), Eigen::Vector3d(0.85, 0.60, 0.10),
      Eigen::Vector3d(0.45, 0.20, 0.60)};
  const std::array<Eigen::Vector3d, 4> trousers = {
      Eigen::Vector3d(0.12, 0.18, 0.38), Eigen::Vector3d(0.30, 0.25, 0.18),
      Eigen::Vector3d(0.20, 0.20, 0.22), Eigen::Vector3d(0.35, 0.38, 0.20)};
  const std::array<Eigen::Vector3d, 4> skins = {
      Eigen::Vector3d(0.93, 0.76, 0.65), Eigen::Vector3d(0.80, 0.60, 0.45),
      Eigen::Vector3d(0.60, 0.42, 0.30), Eigen::Vector3d(0.40, 0.27, 0.19)};
  std::uniform_int_distribution<int> pick_shirt(0, 4), pick_trousers(0, 3), pick_skin(0, 3);
  Palette p;
  const int s = pick_shirt(*rng);
  p.shirt_a = shirts[s];
  p.shirt_b = shirts[(s + 2) % 5] * 0.5 + Eigen::Vector3d(0.45, 0.45, 0.45);
  p.sleeve = shirts[(s + 1) % 5];
  p.pinstripe = Eigen::Vector3d(0.05, 0.05, 0.07);
  p.trousers = trousers[pick_trousers(*rng)];
  p.plaid_line = Eigen::Vector3d(0.85, 0.80, 0.55);
  p.skin = skins[pick_skin(*rng)];
  p.hair = Eigen::Vector3d(0.10, 0.07, 0.05);
  p.shoe = Eigen::Vector3d(0.08, 0.06, 0.05);
  p.sole = Eigen::Vector3d(0.92, 0.92, 0.90);
  p.panel = Eigen::Vector3d(0.95, 0.94, 0.88);
  p.ink = Eigen::Vector3d(0.03, 0.03, 0.03);
  p.lips = Eigen::Vector3d(0.70, 0.25, 0.25);
  p.eye_white = Eigen::Vector3d(0.95, 0.95, 0.95);
  p.iris = Eigen::Vector3d(0.15, 0.25, 0.35);
  return p;
}

// Body landmarks measured on the rest pose.
struct Landmarks {
  double waist_y = 1.0;  // between pelvis and spine joint centres
  double shoulder_y = 1.4;
  double shoulder_half_width = 0.2;
  double head_bottom = 1.5, head_top = 1.75;
  double head_center_x = 0.0;
  Eigen::Vector3d center = Eigen::Vector3d::Zero();  // torso centre (x, z used)
};

struct LimbFrame {
  Eigen::Vector3d center, axis, p, q;
  int around = 6;  // plaid repeats around the limb (integer: seamless at the wrap)
};

constexpr int kGlyphCols = 5, kGlyphRows = 7, kNumGlyphs = 32;

struct Context {
  const Template* tmpl;
  const SubjectTextureOptions* options;
  Palette palette;
  Landmarks marks;
  std::vector<Part> joint_part;
  std::vector<LimbFrame> limb;              // per joint
  std::vector<Eigen::Vector3d> chart_tint;  // per chart
  std::vector<std::array<uint8_t, kGlyphCols * kGlyphRows>> glyphs;
};

void BuildContext(const Template& t, const SubjectTextureOptions& o, Context* c) {
  c->tmpl = &t;
  c->options = &o;
  std::mt19937_64 rng(o.seed);
  c->palette = MakePalette(&rng);
  const int nj = t.num_joints();
  c->joint_part.resize(nj);
  for (int j = 0; j < nj; ++j) c->joint_part[j] = PartOfJoint(t.joints[j].name);

  // Limb frames: joint centre, twist axis, and the mean radius of its vertices.
  c->limb.resize(nj);
  std::vector<double> radius_sum(nj, 0.0);
  std::vector<int> count(nj, 0);
  for (int j = 0; j < nj; ++j) {
    LimbFrame& f = c->limb[j];
    f.center = t.joints[j].center;
    f.axis = t.joints[j].twist_axis.normalized();
    const Eigen::Vector3d helper =
        std::abs(f.axis.z()) < 0.9 ? Eigen::Vector3d::UnitZ() : Eigen::Vector3d::UnitX();
    f.p = f.axis.cross(helper).normalized();
    f.q = f.axis.cross(f.p);
  }
  for (int v = 0; v < t.num_vertices(); ++v) {
    const int j = t.vertex_joint(v);
    const Eigen::Vector3d d = t.vertices.row(v).transpose() - c->limb[j].center;
    radius_sum[j] += (d - d.dot(c->limb[j].axis) * c->limb[j].axis).norm();
    ++count[j];
  }
  for (int j = 0; j < nj; ++j) {
    const double r = count[j] ? radius_sum[j] / count[j] : 0.05;
    c->limb[j].around = std::max(2, static_cast<int>(std::lround(2 * kPi * r / o.plaid_period_m)));
  }

  // Landmarks.
  Landmarks& m = c->marks;
  const int pelvis = t.FindJoint("pelvis"), spine = t.FindJoint("spine");
  const int ls = t.FindJoint("l_shoulder"), rs = t.FindJoint("r_shoulder");
  const int head = t.FindJoint("head");
  const Eigen::Vector3d lo = t.vertices.colwise().minCoeff(), hi = t.vertices.colwise().maxCoeff();
  m.center = 0.5 * (lo + hi);
  if (pelvis >= 0 && spine >= 0) {
    m.waist_y = 0.5 * (t.joints[pelvis].center.y() + t.joints[spine].center.y());
  } else {
    m.waist_y = lo.y() + 0.55 * (hi.y() - lo.y());
  }
  if (ls >= 0 && rs >= 0) {
    m.shoulder_y = 0.5 * (t.joints[ls].center.y() + t.joints[rs].center.y());
    m.shoulder_half_width = 0.5 * std::abs(t.joints[ls].center.x() - t.joints[rs].center.x());
  } else {
    m.shoulder_y = lo.y() + 0.8 * (hi.y() - lo.y());
    m.shoulder_half_width = 0.25 * (hi.x() - lo.x());
  }
  m.head_bottom = hi.y(), m.head_top = lo.y();
  double head_x = 0;
  int head_count = 0;
  for (int v = 0; v < t.num_vertices(); ++v) {
    if (head < 0 || t.vertex_joint(v) != head) continue;
    m.head_bottom = std::min(m.head_bottom, t.vertices(v, 1));
    m.head_top = std::max(m.head_top, t.vertices(v, 1));
    head_x += t.vertices(v, 0);
    ++head_count;
  }
  if (head_count == 0) m.head_bottom = hi.y() - 0.2, m.head_top = hi.y();
  m.head_center_x = head_count ? head_x / head_count : m.center.x();

  // Per-chart colourway tints.
  const int num_charts = t.triangle_chart.size() ? std::max(1, t.triangle_chart.maxCoeff() + 1) : 1;
  c->chart_tint.resize(num_charts);
  for (int k = 0; k < num_charts; ++k) {
    for (int ch = 0; ch < 3; ++ch) {
      c->chart_tint[k][ch] = 1.0 + kChartTint * (2.0 * Hash01(o.seed, 1000 + k, ch) - 1.0);
    }
  }
  // Random 5 x 7 glyphs (about half the dots set, never an empty glyph).
  c->glyphs.resize(kNumGlyphs);
  std::bernoulli_distribution dot(0.45);
  for (auto& g : c->glyphs) {
    int set = 0;
    do {
      set = 0;
      for (auto& d : g) set += (d = dot(rng));
    } while (set < 6);
  }
}

Eigen::Vector3d ShirtColor(const Context& c, const Eigen::Vector3d& x, const Eigen::Vector3d& n) {
  const Palette& p = c.palette;
  const Landmarks& m = c.marks;
  const SubjectTextureOptions& o = *c.options;
  // Printed chest panel with lines of text-like glyphs.
  const double panel_y0 = m.waist_y + kPanelBottom * (m.shoulder_y - m.waist_y);
  const double panel_y1 = m.waist_y + kPanelTop * (m.shoulder_y - m.waist_y);
  const double panel_half = kPanelHalfWidth * m.shoulder_half_width;
  if (n.z() > kFrontNormal && x.y() > panel_y0 && x.y() < panel_y1 &&
      std::abs(x.x() - m.center.x()) < panel_half) {
    const double dot_size = o.glyph_size_m / (kGlyphRows + 1);
    const double col = (x.x() - (m.center.x() - panel_half)) / dot_size;
    const double row = (panel_y1 - x.y()) / dot_size;
    const int cell_x = static_cast<int>(col / (kGlyphCols + 1));
    const int cell_y = static_cast<int>(row / (kGlyphRows + 1));
    const int dx = static_cast<int>(col) - cell_x * (kGlyphCols + 1) - 1;  // 1-dot margin
    const int dy = static_cast<int>(row) - cell_y * (kGlyphRows + 1) - 1;
    const double h = Hash01(o.seed, 17 + cell_y, cell_x);
    const bool space = h < 0.15;
    if (!space && dx >= 0 && dx < kGlyphCols && dy >= 0 && dy < kGlyphRows) {
      const auto& g = c.glyphs[static_cast<int>(h * kNumGlyphs) % kNumGlyphs];
      if (g[dy * kGlyphCols + dx]) return p.ink;
    }
    return p.panel;
  }
  const double t = Frac(x.y() / o.stripe_period_m);
  if (std::abs(t - 0.75) < 0.04) return p.pinstripe;
  return t < 0.5 ? p.shirt_a : p.shirt_b;
}

Eigen::Vector3d TrousersColor(const Context& c, const Eigen::Vector3d& x, int joint) {
  const Palette& p = c.palette;
  const LimbFrame& f = c.limb[joint];
  const Eigen::Vector3d d = x - f.center;
  const double angle = std::atan2(d.dot(f.q), d.dot(f.p));
  const double ty = Frac(x.y() / c.options->plaid_period_m);
  const double ta = Frac(angle / (2 * kPi) * f.around);
  Eigen::Vector3d color = p.trousers;
  if (ty < 0.25) color *= 0.7;
  if (ta < 0.25) color *= 0.7;
  if (std::abs(ty - 0.6) < 0.03 || std::abs(ta - 0.6) < 0.03) color = p.plaid_line;
  return color;
}

Eigen::Vector3d HeadColor(const Context& c, const Eigen::Vector3d& x, const Eigen::Vector3d& n) {
  const Palette& p = c.palette;
  const Landmarks& m = c.marks;
  const double h = m.head_top - m.head_bottom;
  const double rel = (x.y() - m.head_bottom) / h;
  const bool front = n.z() > kFrontNormal;
  if (rel > kHairLine || (!front && n.z() < -0.2 && rel > 0.35)) return p.hair;
  if (!front) return p.skin;
  const double dx = x.x() - m.head_center_x;
  // Eyes: white ellipses with a dark iris; eyebrows above; mouth below.
  const double eye_y = m.head_bottom + kEyeHeight * h;
  const double eye_dx = 0.15 * h;
  for (int side = -1; side <= 1; side += 2) {
    const double ex = (dx - side * eye_dx) / (0.055 * h), ey = (x.y() - eye_y) / (0.025 * h);
    const double r2 = ex * ex + ey * ey;
    if (r2 < 0.25) return p.iris * 0.5;
    if (r2 < 1.0) return std::abs(ex) < 0.45 ? p.iris : p.eye_white;
    if (std::abs(dx - side * eye_dx) < 0.07 * h && std::abs(x.y() - eye_y - 0.07 * h) < 0.012 * h)
      return p.hair;
  }
  const double mouth_y = m.head_bottom + kMouthHeight * h;
  if (std::abs(dx) < 0.10 * h && std::abs(x.y() - mouth_y) < 0.018 * h) return p.lips;
  return p.skin;
}

Eigen::Vector3d TexelColor(const Context& c, int triangle, const Eigen::Vector3d& x,
                           const Eigen::Vector3d& n, int joint) {
  const Palette& p = c.palette;
  Part part = c.joint_part[joint];
  if (part == Part::kTrousers && x.y() > c.marks.waist_y) part = Part::kShirt;
  Eigen::Vector3d color;
  bool garment = true;
  switch (part) {
    case Part::kShirt:
      color = ShirtColor(c, x, n);
      break;
    case Part::kSleeve:
      color = p.sleeve;
      break;
    case Part::kForearm: {
      const LimbFrame& f = c.limb[joint];
      const double along = (x - f.center).dot(f.axis);
      garment = along < c.options->sleeve_length_m;
      color = garment ? p.sleeve : p.skin;
      break;
    }
    case Part::kHand:
    case Part::kNeck:
      color = p.skin;
      garment = false;
      break;
    case Part::kHead:
      color = HeadColor(c, x, n);
      garment = false;
      break;
    case Part::kTrousers:
      color = TrousersColor(c, x, joint);
      break;
    case Part::kFoot:
      if (x.y() < kSoleTop) {
        color = p.sole;
      } else if (x.y() < c.limb[joint].center.y() + kShoeTop) {
        color = p.shoe;
      } else {
        color = TrousersColor(c, x, joint);
      }
      break;
  }
  if (garment && c.tmpl->triangle_chart.size()) {
    color = color.cwiseProduct(c.chart_tint[c.tmpl->triangle_chart(triangle)]);
  }
  return color;
}

}  // namespace

bool SubjectTextureOptions::IsValid(std::string* error) const {
  std::ostringstream msg;
  if (size < 64 || size > 8192) {
    msg << "texture size must be in [64, 8192], found " << size;
  } else if (!(stripe_period_m > 0) || !(plaid_period_m > 0) || !(glyph_size_m > 0)) {
    msg << "stripe_period_m, plaid_period_m and glyph_size_m must be > 0, found " << stripe_period_m
        << ", " << plaid_period_m << ", " << glyph_size_m;
  } else if (!(sleeve_length_m >= 0)) {
    msg << "sleeve_length_m must be >= 0, found " << sleeve_length_m;
  } else if (!(fabric_noise >= 0 && fabric_noise <= 0.5)) {
    msg << "fabric_noise must be in [0, 0.5], found " << fabric_noise;
  } else if (padding_texels < 0 || padding_texels > 64) {
    msg << "padding_texels must be in [0, 64], found " << padding_texels;
  } else {
    return true;
  }
  if (error) *error = msg.str();
  return false;
}

cv::Mat GenerateSubjectTexture(const Template& subject, const SubjectTextureOptions& options) {
  std::string why;
  if (!options.IsValid(&why)) throw Error("subject texture options: " + why);
  if (!subject.has_uvs()) {
    throw Error("GenerateSubjectTexture: the subject template has no UV atlas (uv_triangles " +
                std::to_string(subject.uv_triangles.rows()) + " rows, expected " +
                std::to_string(subject.num_triangles()) + ")");
  }
  Context c;
  BuildContext(subject, options, &c);
  const int n = options.size;
  const int num_triangles = subject.num_triangles();

  // Texel -> triangle map: the lowest-index triangle covering the texel centre (an atomic
  // minimum, so the parallel result is deterministic), then dilation into the gutter.
  constexpr int32_t kNone = std::numeric_limits<int32_t>::max();
  std::vector<std::atomic<int32_t>> cover(static_cast<size_t>(n) * n);
  tbb::parallel_for(size_t{0}, cover.size(),
                    [&](size_t i) { cover[i].store(kNone, std::memory_order_relaxed); });
  tbb::parallel_for(0, num_triangles, [&](int f) {
    const UvTriangleCells t = UvTriangleOnGrid(subject, f, n);
    if (t.area2 == 0) return;
    ForEachCellInside(t, [&](int x, int y) {
      std::atomic<int32_t>& c = cover[static_cast<size_t>(y) * n + x];
      int32_t current = c.load(std::memory_order_relaxed);
      while (f < current && !c.compare_exchange_weak(current, f, std::memory_order_relaxed)) {
      }
    });
  });
  std::vector<int32_t> owner(cover.size());
  tbb::parallel_for(size_t{0}, cover.size(), [&](size_t i) {
    const int32_t c = cover[i].load(std::memory_order_relaxed);
    owner[i] = c == kNone ? -1 : c;
  });
  std::vector<int32_t> next = owner;
  for (int pass = 0; pass < options.padding_texels; ++pass) {
    tbb::parallel_for(0, n, [&](int y) {
      for (int x = 0; x < n; ++x) {
        const size_t i = static_cast<size_t>(y) * n + x;
        if (owner[i] >= 0) continue;
        if (x > 0 && owner[i - 1] >= 0) {
          next[i] = owner[i - 1];
        } else if (x + 1 < n && owner[i + 1] >= 0) {
          next[i] = owner[i + 1];
        } else if (y > 0 && owner[i - n] >= 0) {
          next[i] = owner[i - n];
        } else if (y + 1 < n && owner[i + n] >= 0) {
          next[i] = owner[i + n];
        }
      }
    });
    owner = next;
  }

  // Rest-pose triangle normals and majority joints.
  std::vector<Eigen::Vector3d> normal(num_triangles);
  std::vector<int> joint(num_triangles);
  for (int f = 0; f < num_triangles; ++f) {
    const Eigen::Vector3d a = subject.vertices.row(subject.triangles(f, 0));
    const Eigen::Vector3d b = subject.vertices.row(subject.triangles(f, 1));
    const Eigen::Vector3d d = subject.vertices.row(subject.triangles(f, 2));
    const Eigen::Vector3d nn = (b - a).cross(d - a);
    normal[f] = nn.norm() > 0 ? Eigen::Vector3d(nn.normalized()) : Eigen::Vector3d::Zero();
    const int j0 = subject.vertex_joint(subject.triangles(f, 0));
    const int j1 = subject.vertex_joint(subject.triangles(f, 1));
    const int j2 = subject.vertex_joint(subject.triangles(f, 2));
    joint[f] = (j1 == j2) ? j1 : j0;
  }

  cv::Mat image(n, n, CV_8UC3);
  tbb::parallel_for(0, n, [&](int y) {
    auto* row = image.ptr<cv::Vec3b>(y);
    for (int x = 0; x < n; ++x) {
      const int f = owner[static_cast<size_t>(y) * n + x];
      Eigen::Vector3d rgb = options.gutter_rgb;
      if (f >= 0) {
        // Barycentrics of the texel centre (extrapolated for padding texels).
        Eigen::Vector2d uv[3];
        for (int k = 0; k < 3; ++k)
          uv[k] = subject.uvs.row(subject.uv_triangles(f, k)).transpose() * n;
        Eigen::Matrix2d m;
        m.col(0) = uv[1] - uv[0];
        m.col(1) = uv[2] - uv[0];
        const Eigen::Vector2d b = m.inverse() * (Eigen::Vector2d(x + 0.5, y + 0.5) - uv[0]);
        const Eigen::Vector3d p =
            (1 - b.x() - b.y()) * subject.vertices.row(subject.triangles(f, 0)).transpose() +
            b.x() * subject.vertices.row(subject.triangles(f, 1)).transpose() +
            b.y() * subject.vertices.row(subject.triangles(f, 2)).transpose();
        rgb = TexelColor(c, f, p, normal[f], joint[f]);
        rgb *= 1.0 + options.fabric_noise * (2.0 * Hash01(options.seed, y, x) - 1.0);
      }
      for (int ch = 0; ch < 3; ++ch) {
        row[x][2 - ch] = static_cast<uint8_t>(std::lround(255.0 * std::clamp(rgb[ch], 0.0, 1.0)));
      }
    }
  });
  return image;
}

Eigen::MatrixX3d VertexColorsFromTexture(const Template& tmpl, const cv::Mat& texture_bgr) {
  if (!tmpl.has_uvs()) throw Error("VertexColorsFromTexture: the template has no UV atlas");
  if (texture_bgr.type() != CV_8UC3 || texture_bgr.empty()) {
    throw Error("VertexColorsFromTexture: expected a non-empty CV_8UC3 texture, found type " +
                std::to_string(texture_bgr.type()));
  }
  Eigen::MatrixX3d sum = Eigen::MatrixX3d::Zero(tmpl.num_vertices(), 3);
  Eigen::VectorXi count = Eigen::VectorXi::Zero(tmpl.num_vertices());
  for (int f = 0; f < tmpl.num_triangles(); ++f) {
    for (int k = 0; k < 3; ++k) {
      const int v = tmpl.triangles(f, k);
      sum.row(v) +=
          SampleTextureBilinear(texture_bgr, tmpl.uvs.row(tmpl.uv_triangles(f, k))).transpose();
      ++count(v);
    }
  }
  const cv::Scalar mean = cv::mean(texture_bgr);
  const Eigen::RowVector3d fallback(mean[2] / 255.0, mean[1] / 255.0, mean[0] / 255.0);
  for (int v = 0; v < tmpl.num_vertices(); ++v) {
    if (count(v)) {
      sum.row(v) /= count(v);
    } else {
      sum.row(v) = fallback;
    }
  }
  return sum;
}

}  // namespace artex
