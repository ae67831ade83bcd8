#include "fusion/geometric_consistency.h"

#include <algorithm>
#include <cmath>

#include "util/error.h"

namespace lfrecon {

int GeometricConsistencyOptions::Delay() const {
  if (!enabled || offsets.empty()) return 0;
  return *std::max_element(offsets.begin(), offsets.end());
}

std::vector<int> NeighbourPositions(int position, int count, const GeometricConsistencyOptions& options) {
  std::vector<int> out;
  for (int o : options.offsets)
    for (int q : {position - o, position + o})
      if (q >= 0 && q < count) out.push_back(q);
  return out;
}

void GeometricConsistencyOptions::Check() const {
  if (!enabled) return;
  LFRECON_CHECK_OPTION(!offsets.empty());
  for (int o : offsets) LFRECON_CHECK_OPTION(o >= 1 && o <= 64);
  LFRECON_CHECK_OPTION(min_agree >= 1 && min_agree <= 2 * static_cast<int>(offsets.size()));
  LFRECON_CHECK_OPTION(min_agree_fraction >= 0 && min_agree_fraction <= 1);
  LFRECON_CHECK_OPTION(depth_tolerance > 0 && depth_tolerance < 1);
  LFRECON_CHECK_OPTION(own_tolerance >= 0 && own_tolerance < 1);
}

cv::Mat OwnDepthMask(const DepthMap& dense, const DepthMap& filtered, double tolerance) {
  cv::Mat own(dense.depth.size(), CV_8U, cv::Scalar(0));
  if (filtered.depth.size() != dense.depth.size()) return own;
  for (int r = 0; r < own.rows; ++r) {
    const float* d = dense.depth.ptr<float>(r);
    const float* f = filtered.depth.ptr<float>(r);
    std::uint8_t* o = own.ptr<std::uint8_t>(r);
    for (int c = 0; c < own.cols; ++c) o[c] = d[c] > 0 && f[c] > 0 && std::abs(f[c] - d[c]) <= tolerance * d[c];
  }
  return own;
}

GeometricConsistencyStats ApplyGeometricConsistency(const PinholeView& view, const cv::Mat& own,
                                                    const std::vector<NeighbourDepth>& neighbours,
                                                    const BoundingBox& volume,
                                                    const GeometricConsistencyOptions& options, DepthMap* map) {
  GeometricConsistencyStats st;
  if (!map || map->depth.empty()) return st;
  const bool has_own = own.size() == map->depth.size();
  const bool has_conf = map->confidence.size() == map->depth.size();
  const bool has_label = map->label.size() == map->depth.size();
  int present = 0;
  for (const NeighbourDepth& nb : neighbours) present += nb.view && nb.depth && !nb.depth->empty();
  const int needed =
      std::max(options.min_agree, static_cast<int>(std::ceil(options.min_agree_fraction * present - 1e-9)));
  for (int r = 0; r < map->depth.rows; ++r) {
    float* d = map->depth.ptr<float>(r);
    for (int c = 0; c < map->depth.cols; ++c) {
      if (!(d[c] > 0)) continue;
      const Eigen::Vector3d X = view.Unproject(Eigen::Vector2d(c + 0.5, r + 0.5), d[c]);
      if (!volume.Contains(X)) continue;
      ++st.foreground;
      if (has_own && own.at<std::uint8_t>(r, c)) {
        ++st.own;
        continue;
      }
      int agree = 0;
      for (const NeighbourDepth& nb : neighbours) {
        if (!nb.view || !nb.depth || nb.depth->empty()) continue;
        Eigen::Vector2d px;
        const double z = nb.view->Project(X, &px);
        if (!(z > 0) || !nb.view->InImage(px)) continue;
        const int pr = static_cast<int>(px.y()), pc = static_cast<int>(px.x());
        if (pr < 0 || pc < 0 || pr >= nb.depth->rows || pc >= nb.depth->cols) continue;
        const float dd = nb.depth->at<float>(pr, pc);
        if (dd > 0 && std::abs(dd - z) < options.depth_tolerance * z) ++agree;
        if (agree >= needed) break;
      }
      if (agree >= needed) continue;
      ++st.dropped;
      d[c] = 0;
      if (has_conf) map->confidence.at<float>(r, c) = 0;
      if (has_label) map->label.at<std::uint8_t>(r, c) = static_cast<std::uint8_t>(DepthLabel::kNone);
    }
  }
  return st;
}

}  // namespace lfrecon
