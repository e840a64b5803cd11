// Interpolation between measured directions (seed 000 section 4, after [ND06]).
//
// Each direction set is mapped to parabolic coordinates p = (x, y) / (1 + z) (the upper
// hemisphere becomes the unit disc) and triangulated (Delaunay, Bowyer-Watson). A query
// direction is located in its triangle and gets 3 (index, barycentric weight) pairs; a BTF value
// at (w_l, w_v) is then the 3 x 3 = 9-lookup blend over the light and view triangles.
//
// Contracts:
//  - At a measured direction the weights are exactly (1, 0, 0) on that direction.
//  - Weights are >= 0 and sum to 1.
//  - Queries outside the convex hull (e.g. grazing directions beyond theta = 75 deg, or below the
//    horizon) are projected onto the nearest point of the hull boundary.
//  - Degenerate sets are handled: one direction (weight 1 on it), all directions collinear in
//    parabolic space (interpolation along the nearest segment).
//  - Build is O(n^2) worst case; n is at most a few hundred directions here.
#pragma once
#include <array>
#include <vector>

#include "core/btf.h"

namespace btfc {

struct Vec2 {
  double x = 0, y = 0;
};
Vec2 to_parabolic(const Vec3& d);

struct DirWeights {
  std::array<int, 3> index{0, 0, 0};
  std::array<float, 3> weight{1, 0, 0};
};

class DirectionInterpolator {
 public:
  DirectionInterpolator() = default;
  explicit DirectionInterpolator(const DirectionSet& set);
  DirWeights weights(const Vec3& dir) const;
  // Triangles as index triples into the direction set (empty for degenerate sets).
  const std::vector<std::array<int, 3>>& triangles() const { return m_tris; }

 private:
  std::vector<Vec2> m_pts;  // parabolic points by direction index; NaN = merged duplicate
  std::vector<std::array<int, 3>> m_tris;
  // Point location (built with the triangulation): a uniform grid over the points' bounding box
  // listing, per cell, the triangles whose bounding box overlaps it (CSR), and the hull edges
  // (ccw) for projecting queries that fall outside.
  Vec2 m_grid_lo, m_grid_inv;  // cell coordinate = (p - lo) * inv
  int m_grid_n = 0;
  std::vector<int> m_cell_start, m_cell_tris;
  std::vector<std::array<int, 2>> m_hull;
};

}  // namespace btfc
