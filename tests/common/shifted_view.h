#pragma once
// A pinhole camera of the propagation tests' rigs: looking down +z with the
// world's axes, principal point at the frame's centre, its centre at
// (centre_x, 0, 0): neighbours differ only by a baseline along x, so a point at
// depth z shifts by fx · baseline / z pixels along the rows.
#include "geometry/pinhole_view.h"

namespace lfrecon::testing {

inline PinholeView ShiftedView(int width, int height, double fx, double centre_x) {
  PinholeView v;
  v.width = width;
  v.height = height;
  v.K << fx, 0, width / 2.0, 0, fx, height / 2.0, 0, 0, 1;
  v.K_inv = v.K.inverse();
  v.t = Eigen::Vector3d(-centre_x, 0, 0);  // cam_from_world
  return v;
}

}  // namespace lfrecon::testing
