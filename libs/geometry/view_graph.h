#pragma once
// For each view, the views whose viewing directions lie within a given angle
// (BRIEF §1: 5° for depth and photoconsistency, 15° for depth filtering).
// Directions are hashed into a grid on the unit sphere's bounding cube with
// a cell as large as the chord of the angle, so a query touches 27 cells:
// O(n · k) for n views with k neighbours each, for any path shape (loops,
// helices, several passes), not only a single ordered loop.
#include <Eigen/Core>
#include <vector>

#include "geometry/pinhole_view.h"

namespace lfrecon {

class ViewGraph {
 public:
  ViewGraph() = default;
  // `directions` are unit viewing directions (world), one per view.
  // `max_index_gap` > 0: only views at most that many places apart in the
  // sequence are neighbours (a stream then never waits for a view that comes
  // much later, e.g. the end of a closed loop for its first views).
  ViewGraph(const std::vector<Eigen::Vector3d>& directions, double max_angle_deg, int max_index_gap = 0);

  int num_views() const { return static_cast<int>(neighbors_.size()); }
  double max_angle_deg() const { return max_angle_deg_; }
  // Neighbours of view i (never i itself), sorted by increasing angle, ties by index.
  const std::vector<int>& Neighbors(int i) const { return neighbors_.at(i); }
  // Angle in degrees between views i and j.
  double AngleDeg(int i, int j) const;

  // The same neighbourhoods by brute force (O(n^2)); for tests and tiny inputs.
  static std::vector<std::vector<int>> BruteForce(const std::vector<Eigen::Vector3d>& directions,
                                                  double max_angle_deg);

 private:
  std::vector<Eigen::Vector3d> directions_;
  std::vector<std::vector<int>> neighbors_;
  double max_angle_deg_ = 0;
};

// Greedy thinning along a sequence of directions: the first one, then each
// one at least min_step_deg from the last one kept, up to 1e-6° of rounding
// (a sequence spaced exactly the step apart keeps every entry). Every entry
// is kept when min_step_deg <= 0. The view selection of the plan and the
// depth hierarchy's grid both space views so, and the filter's voters are
// then exactly the selected views.
std::vector<char> SpacedAtLeast(const std::vector<Eigen::Vector3d>& directions, double min_step_deg);
// SpacedAtLeast's rule for one pair: at least step_deg apart, up to 1e-6°.
bool AtLeastStepDeg(double angle_deg, double step_deg);

// The viewing directions of `views`, in order: what ViewGraph and SpacedAtLeast take.
std::vector<Eigen::Vector3d> ViewingDirections(const std::vector<PinholeView>& views);

}  // namespace lfrecon
