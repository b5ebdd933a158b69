// PointCloudIndex (solvers/estep.h): a nanoflann kd-tree over a copied point set.
#include <limits>
#include <memory>
#include <nanoflann.hpp>
#include <string>
#include <utility>
#include <vector>

#include "models/error.h"
#include "solvers/estep.h"

namespace artex {

namespace {
struct RowMajorCloud {
  std::vector<double> xyz;  // 3 N
  size_t kdtree_get_point_count() const { return xyz.size() / 3; }
  double kdtree_get_pt(size_t i, size_t d) const { return xyz[3 * i + d]; }
  template <class Box>
  bool kdtree_get_bbox(Box&) const {
    return false;
  }
};
// nanoflann result set of the one nearest point below a squared-distance bound. It keeps the
// first of equal distances and prunes with its current best, as KNNResultSet(1) does, so
// whatever it finds is what KNNResultSet(1) finds.
class BoundedNearest {
 public:
  explicit BoundedNearest(double bound2) : worst_(bound2) {}
  bool addPoint(double distance2, int index) {
    if (distance2 < worst_) {
      worst_ = distance2;
      index_ = index;
    }
    return true;
  }
  double worstDist() const { return worst_; }
  bool full() const { return index_ >= 0; }
  int index() const { return index_; }

 private:
  double worst_;
  int index_ = -1;
};

using KdTree =
    nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<double, RowMajorCloud>,
                                        RowMajorCloud, 3, int>;
}  // namespace

struct PointCloudIndex::Impl {
  RowMajorCloud cloud;
  std::unique_ptr<KdTree> tree;
};

PointCloudIndex::PointCloudIndex(const Eigen::MatrixX3d& points, int leaf_size) : impl_(new Impl) {
  if (leaf_size < 1) {
    throw Error("point cloud index: leaf_size: expected >= 1, found " + std::to_string(leaf_size));
  }
  impl_->cloud.xyz.resize(3 * points.rows());
  for (Eigen::Index i = 0; i < points.rows(); ++i) {
    for (int d = 0; d < 3; ++d) impl_->cloud.xyz[3 * i + d] = points(i, d);
  }
  impl_->tree = std::make_unique<KdTree>(3, impl_->cloud,
                                         nanoflann::KDTreeSingleIndexAdaptorParams(leaf_size));
  if (points.rows() > 0) impl_->tree->buildIndex();
}

PointCloudIndex::~PointCloudIndex() = default;

int PointCloudIndex::size() const {
  return static_cast<int>(impl_->cloud.kdtree_get_point_count());
}

int PointCloudIndex::Nearest(const Eigen::Vector3d& query, double* distance2) const {
  return NearestWithin(query, std::numeric_limits<double>::infinity(), distance2);
}

int PointCloudIndex::NearestWithin(const Eigen::Vector3d& query, double bound2,
                                   double* distance2) const {
  BoundedNearest result(bound2);
  if (size() > 0 && bound2 > 0.0) {
    impl_->tree->findNeighbors(result, query.data(), nanoflann::SearchParams());
  }
  const int index = result.index();
  if (distance2) {
    *distance2 = index >= 0 ? result.worstDist() : std::numeric_limits<double>::infinity();
  }
  return index;
}

int PointCloudIndex::KNearest(const Eigen::Vector3d& query, int k, int* indices,
                              double* distances2) const {
  if (size() == 0 || k <= 0) return 0;
  nanoflann::KNNResultSet<double, int, int> result(k);
  result.init(indices, distances2);
  impl_->tree->findNeighbors(result, query.data(), nanoflann::SearchParams());
  return static_cast<int>(result.size());
}

void PointCloudIndex::Radius(const Eigen::Vector3d& query, double radius,
                             std::vector<std::pair<int, double>>* out) const {
  out->clear();
  if (size() == 0) return;
  nanoflann::RadiusResultSet<double, int> result(radius * radius, *out);
  impl_->tree->findNeighbors(result, query.data(), nanoflann::SearchParams(32, 0.0f, false));
}

}  // namespace artex
