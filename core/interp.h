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
//  - weights() returns exactly (bit for bit) what weights_reference() returns, for every input.
#pragma once
#include <array>
#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
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
  // Fast: most queries are answered from a fine lookup table (one load and one barycentric
  // evaluation); the rest take weights_reference(). Thread-safe (const, no caches).
  DirWeights weights(const Vec3& dir) const;
  // weights(dir[i]) for i < n, the same bits; for many queries at once (a renderer's or a
  // benchmark's batch). A group's table cells are all located before any is read, so their
  // cache misses overlap instead of forming one chain of dependent loads per query.
  void weights_batch(const Vec3* dir, size_t n, DirWeights* out) const;
  // The simple search (coarse grid of candidate triangles, then nearest hull edge), kept as the
  // definition of the result and to test the fast path against: same output for every input.
  DirWeights weights_reference(const Vec3& dir) const;
  // For tests and benchmarks: how weights(dir) answers (0: weights_reference; a table cell of
  // 1: one triangle, 2: hull edges, 3: a few candidate triangles, the reference if none holds
  // dir), and the table's cells (cell (i, j) covers [lo.x + i * cell, lo.x + (i + 1) * cell) x
  // the same in y; n = 0: no table).
  int fast_path_kind(const Vec3& dir) const;
  struct FineGrid {
    Vec2 lo;
    double cell = 0;
    int n = 0;
  };
  FineGrid fine_grid() const;
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
  // Fast path (see build_fine_table in interp.cpp): a finer square grid over the points'
  // bounding box widened on every side (grazing queries beyond the hull land in it too). A cell
  // holds t >= 0 when the reference search returns triangle t for every point of the cell;
  // -2 - k when it returns the projection onto one of the hull edges in list k (CSR, m_hull
  // indices); k_multi_base - k when it returns the first of up to k_multi candidates (multi,
  // -1 padded) that holds the point, for a cell across a triangle edge; -1 when undecided.
  static constexpr int k_multi = 4, k_list_count = 16383, k_multi_count = 16383;
  static constexpr int k_multi_base = -2 - k_list_count;
  static constexpr int k_fine_max = 384, k_block = 4;  // table side limit; build block size
  struct CornerTri {
    Vec2 a, b, c;  // m_pts[index[0..2]]
    std::array<int, 3> index;
  };
  struct FineTable {
    Vec2 lo;
    double inv = 0;
    int n = 0;  // 0: no table
    std::vector<int16_t> cells, multi;
    std::vector<CornerTri> corner_tris;  // by triangle
    std::vector<int> out_start;
    std::vector<int16_t> out_edges;
  };
  // The table is built on the first weights() call, not with the interpolator: it takes 10-30 ms,
  // and most interpolators (one per model load, per relight call...) never answer a direction
  // query. Copies share it (same directions, same table).
  struct LazyTable {
    std::once_flag once;
    std::atomic<bool> ready{false};  // the fast path's check: call_once is a libc call each time
    FineTable table;
  };
  std::shared_ptr<LazyTable> m_lazy;  // null: no table (empty or degenerate set)
  const FineTable& fine() const;

  DirWeights weights_at(const Vec2& p) const;  // the reference search for a parabolic point
  static int table_entry(const FineTable& t, const Vec2& p);  // -1 when p is not in the table
  DirWeights table_miss(const FineTable& t, const Vec2& p, int entry) const;  // weights() for an entry < 0
  void build_fine_table(FineTable& t) const;
};

}  // namespace btfc
