// Direction interpolation: Delaunay triangulation in parabolic coordinates (Bowyer-Watson) and
// barycentric point location. See core/interp.h for the contract.
#include "core/interp.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>

namespace btfc {

namespace {

// Relative tie band of the orientation and incircle predicates: a determinant below k_rel_eps
// times the size of its terms counts as zero. The UBO rings make many cocircular quads (only
// nearly so after float rounding); the band gives all of them the same answer.
constexpr double k_rel_eps = 1e-12;
// A set whose points all lie within k_collinear * (its length) of a line is treated as
// collinear: float directions put "collinear" points ~1e-7 off their line, and triangulating
// that noise would give needle triangles.
constexpr double k_collinear = 1e-6;
// Points closer than this in parabolic space are one direction (the first index wins).
constexpr double k_dup_dist = 1e-9;
// A weight this close to 1 snaps to exactly (1, 0, 0): measured directions come back exact.
constexpr double k_snap = 1e-6;
// Absolute slack (parabolic area units, points are O(1)) for "inside a triangle" at query time;
// rounding misses have a fallback, so this can stay tiny.
constexpr double k_inside_tol = 1e-12;
// Fine lookup table cells per side per sqrt(triangle count), i.e. ~1000 cells per triangle:
// bench/interp_bench.cpp on UBO2003 (theta 0..80 deg) ran about 24 / 22 / 21 ns per call at
// 16 / 24 / 32 (the table answers 74 / 81 / 86 %), and the build takes ~13 ms at 32.
constexpr double k_fine_per_tri = 32;

double cross(const Vec2& o, const Vec2& a, const Vec2& b) {
  return (a.x - o.x) * (b.y - o.y) - (a.y - o.y) * (b.x - o.x);
}

// +1 if (a, b, c) turns counter-clockwise, -1 clockwise, 0 if collinear within the tie band
// (the sine of the angle at a below ~k_rel_eps; the tolerance scales with the edge lengths so
// that a point 1e-17 off the x axis, as phi = 180 deg gives, counts as on it).
int orient(const Vec2& a, const Vec2& b, const Vec2& c) {
  double bx = b.x - a.x, by = b.y - a.y, cx = c.x - a.x, cy = c.y - a.y;
  double det = bx * cy - by * cx;
  double tol = k_rel_eps * (std::fabs(bx) + std::fabs(by)) * (std::fabs(cx) + std::fabs(cy));
  return det > tol ? 1 : det < -tol ? -1 : 0;
}

// True when d is clearly inside the circumcircle of the ccw triangle (a, b, c). Cocircular
// points count as outside, so ties never grow a cavity.
bool in_circle(const Vec2& a, const Vec2& b, const Vec2& c, const Vec2& d) {
  double adx = a.x - d.x, ady = a.y - d.y, bdx = b.x - d.x, bdy = b.y - d.y;
  double cdx = c.x - d.x, cdy = c.y - d.y;
  double al = adx * adx + ady * ady, bl = bdx * bdx + bdy * bdy, cl = cdx * cdx + cdy * cdy;
  double det = al * (bdx * cdy - cdx * bdy) + bl * (cdx * ady - adx * cdy) + cl * (adx * bdy - bdx * ady);
  double perm = al * (std::fabs(bdx * cdy) + std::fabs(cdx * bdy)) +
                bl * (std::fabs(cdx * ady) + std::fabs(adx * cdy)) +
                cl * (std::fabs(adx * bdy) + std::fabs(bdx * ady));
  return det > k_rel_eps * perm;
}

bool is_vertex(const Vec2& p) { return !std::isnan(p.x); }

// Bowyer-Watson over the non-NaN entries of `pts` (NaN marks a merged duplicate); returns ccw
// index triples, or nothing when all points are collinear.
//
// Instead of a finite super-triangle the triangulation is closed by one vertex at infinity
// (index n): each hull edge u -> v carries a "ghost" triangle (v, u, ghost). This is the
// limit of an infinitely large super-triangle. A finite one, however huge, fails on nearly
// collinear hull points: a thin hull triangle has a circumcircle far larger than the point
// set, a super vertex falls inside it, and removing the super triangles leaves a notch in
// the hull (seen on a float-rounded square lattice with a 1e5x super-triangle).
std::vector<std::array<int, 3>> bowyer_watson(const std::vector<Vec2>& pts) {
  struct Tri {
    std::array<int, 3> v;   // ccw
    std::array<int, 3> nb;  // nb[i]: triangle across edge (v[i+1], v[i+2])
    bool alive;
  };
  const int n = int(pts.size()), ghost = n;

  // Seed triangle: the first point, the point farthest from it, and the point farthest from
  // the line through those two. If even that one is within k_collinear of the line, the set is
  // collinear up to float noise in the directions and gets no triangles (1D fallback).
  std::vector<int> order;
  for (int i = 0; i < n; ++i)
    if (is_vertex(pts[i])) order.push_back(i);
  if (order.size() < 3) return {};
  auto dist2 = [&](int i, int j) { return std::pow(pts[i].x - pts[j].x, 2) + std::pow(pts[i].y - pts[j].y, 2); };
  auto far = std::max_element(order.begin() + 1, order.end(),
                              [&](int i, int j) { return dist2(order[0], i) < dist2(order[0], j); });
  std::iter_swap(order.begin() + 1, far);
  auto off = [&](int c) { return std::fabs(cross(pts[order[0]], pts[order[1]], pts[c])); };
  auto third = std::max_element(order.begin() + 2, order.end(), [&](int i, int j) { return off(i) < off(j); });
  if (off(*third) <= k_collinear * dist2(order[0], order[1])) return {};
  std::iter_swap(order.begin() + 2, third);
  int a0 = order[0], b0 = order[1], c0 = order[2];
  if (cross(pts[a0], pts[b0], pts[c0]) < 0) std::swap(b0, c0);
  std::vector<Tri> tris = {{{a0, b0, c0}, {1, 2, 3}, true},
                           {{c0, b0, ghost}, {3, 2, 0}, true},
                           {{a0, c0, ghost}, {1, 3, 0}, true},
                           {{b0, a0, ghost}, {2, 1, 0}, true}};

  // Does p conflict with (lie in the circumcircle of) triangle t? For a ghost (u, w, ghost)
  // the "circumcircle" is the open half-plane beyond hull edge w -> u plus the open edge itself.
  auto conflict = [&](const Tri& t, const Vec2& p) {
    int k = t.v[0] == ghost ? 0 : t.v[1] == ghost ? 1 : t.v[2] == ghost ? 2 : -1;
    if (k < 0) return in_circle(pts[t.v[0]], pts[t.v[1]], pts[t.v[2]], p);
    const Vec2 &u = pts[t.v[(k + 1) % 3]], &w = pts[t.v[(k + 2) % 3]];
    int o = orient(u, w, p);
    if (o != 0) return o > 0;
    double d = (p.x - u.x) * (w.x - u.x) + (p.y - u.y) * (w.y - u.y);
    return d > 0 && d < (w.x - u.x) * (w.x - u.x) + (w.y - u.y) * (w.y - u.y);
  };
  // How deeply p lies inside t (real: smallest edge orientation) or beyond it (ghost: the
  // orientation against the hull edge). The largest score is the triangle containing p; unlike
  // a tolerance test this always picks one, even when rounding puts p on an edge. A ghost only
  // qualifies if p conflicts with it: on the line of a hull edge but past its end, p scores 0
  // there, and starting the cavity from that ghost would swallow the edge's end vertex.
  auto score = [&](const Tri& t, const Vec2& p) {
    bool is_ghost = t.v[0] == ghost || t.v[1] == ghost || t.v[2] == ghost;
    if (is_ghost && !conflict(t, p)) return -std::numeric_limits<double>::infinity();
    double m = std::numeric_limits<double>::infinity();
    for (int k = 0; k < 3; ++k) {
      int a = t.v[k], b = t.v[(k + 1) % 3];
      if (a != ghost && b != ghost) m = std::min(m, cross(pts[a], pts[b], p));
    }
    return m;
  };

  std::vector<char> in_cavity;
  std::vector<int> cavity, start_of(n + 1, -1), end_of(n + 1, -1);
  struct Edge {
    int a, b, outer;
  };
  std::vector<Edge> boundary;
  for (size_t oi = 3; oi < order.size(); ++oi) {
    const int pi = order[oi];
    const Vec2& p = pts[pi];
    int start = -1;
    double best = -std::numeric_limits<double>::infinity();
    for (int t = 0; t < int(tris.size()); ++t) {
      if (!tris[t].alive) continue;
      double m = score(tris[t], p);
      if (m > best) best = m, start = t;
    }
    // Cavity: the triangles connected to `start` that conflict with p. Growing by adjacency
    // (not by testing every triangle) keeps it connected whatever rounding does.
    in_cavity.assign(tris.size(), 0);
    cavity.assign(1, start);
    in_cavity[start] = 1;
    for (size_t k = 0; k < cavity.size(); ++k)
      for (int nb : tris[cavity[k]].nb)
        if (!in_cavity[nb] && conflict(tris[nb], p)) in_cavity[nb] = 1, cavity.push_back(nb);
    // The cavity must be star-shaped from p (p strictly left of every real boundary edge), or
    // the fan of new triangles would overlap or be flat. Exact arithmetic guarantees it; near-
    // ties (cocircular rings) do not, so absorb the triangle behind an offending edge, re-check.
    for (bool repaired = true; repaired;) {
      repaired = false;
      boundary.clear();
      for (size_t k = 0; k < cavity.size() && !repaired; ++k) {
        const Tri& t = tris[cavity[k]];
        for (int i = 0; i < 3 && !repaired; ++i) {
          if (in_cavity[t.nb[i]]) continue;
          int a = t.v[(i + 1) % 3], b = t.v[(i + 2) % 3];
          if (a != ghost && b != ghost && orient(pts[a], pts[b], p) <= 0) {
            in_cavity[t.nb[i]] = 1, cavity.push_back(t.nb[i]), repaired = true;
          } else {
            boundary.push_back({a, b, t.nb[i]});
          }
        }
      }
    }
    // Replace the cavity by the fan (a, b, p) over its boundary (edges to the ghost give the new
    // ghost triangles) and stitch the adjacency: the fan triangle across (b, p) is the one
    // starting at b, the one across (p, a) the one ending at a.
    for (int t : cavity) tris[t].alive = false;
    const int first = int(tris.size());
    for (const Edge& e : boundary) {
      int id = int(tris.size());
      tris.push_back({{e.a, e.b, pi}, {-1, -1, e.outer}, true});
      start_of[e.a] = id, end_of[e.b] = id;
      // The outer triangle sees this edge as (b, a); it may touch the cavity on other edges
      // too, so match the edge rather than "a neighbour that died".
      Tri& o = tris[e.outer];
      for (int k = 0; k < 3; ++k)
        if (o.v[(k + 1) % 3] == e.b && o.v[(k + 2) % 3] == e.a) o.nb[k] = id;
    }
    for (int id = first; id < int(tris.size()); ++id) {
      tris[id].nb[0] = start_of[tris[id].v[1]];
      tris[id].nb[1] = end_of[tris[id].v[0]];
    }
  }

  std::vector<std::array<int, 3>> out;
  for (const Tri& t : tris)
    if (t.alive && t.v[0] != ghost && t.v[1] != ghost && t.v[2] != ghost) out.push_back(t.v);
  return out;
}

// Unnormalized barycentric weights of p in triangle t (twice the sub-triangle areas). The one
// definition both the fast path and the reference search use, so they agree bit for bit.
inline std::array<double, 3> bary(const std::vector<Vec2>& pts, const std::array<int, 3>& t, const Vec2& p) {
  const Vec2 &a = pts[size_t(t[0])], &b = pts[size_t(t[1])], &c = pts[size_t(t[2])];
  return {cross(b, c, p), cross(c, a, p), cross(a, b, p)};
}

double min3(const std::array<double, 3>& w) { return std::min({w[0], w[1], w[2]}); }

// Running nearest point on the hull edges fed to add(), in their order (the first of equal
// distances wins). Only edges that p is not strictly inside of can hold it.
struct HullHit {
  double best = std::numeric_limits<double>::infinity(), u = 0;
  int ia = -1, ib = -1;
  void add(const Vec2& a, const Vec2& b, int i, int j, const Vec2& p) {
    if (cross(a, b, p) > 0) return;
    double ex = b.x - a.x, ey = b.y - a.y;
    double t = std::clamp(((p.x - a.x) * ex + (p.y - a.y) * ey) / (ex * ex + ey * ey), 0.0, 1.0);
    double dx = a.x + t * ex - p.x, dy = a.y + t * ey - p.y, d2 = dx * dx + dy * dy;
    if (d2 < best) best = d2, u = t, ia = i, ib = j;
  }
};

// Exact (1, 0, 0) on one direction.
DirWeights single(int i) {
  DirWeights w;
  w.index = {i, i, i};
  w.weight = {1, 0, 0};
  return w;
}

// Clamps tiny negatives, renormalizes, and snaps to a vertex when one weight is ~1.
DirWeights make_weights(std::array<int, 3> idx, std::array<double, 3> w) {
  double sum = 0;
  for (double& x : w) sum += (x = std::max(x, 0.0));
  if (!(sum > 0)) return single(idx[0]);
  for (int k = 0; k < 3; ++k) {
    w[k] /= sum;
    if (w[k] >= 1 - k_snap) return single(idx[k]);
  }
  DirWeights out;
  out.index = idx;
  out.weight = {float(w[0]), float(w[1]), float(w[2])};
  return out;
}

}  // namespace

Vec2 to_parabolic(const Vec3& d) {
  // Near z = -1 (straight down) the map diverges. Clamp 1 + z at k_min_den but keep the point
  // where it belongs, far outside the unit disc: radius sqrt((1 - z) / (1 + z)) at the clamp,
  // azimuth of (x, y) (phi = 0 when there is none). It is projected onto the hull anyway.
  constexpr double k_min_den = 1e-6;
  const double x = d.x, y = d.y, den = 1.0 + double(d.z);
  if (den >= k_min_den) return {x / den, y / den};
  const double r = std::sqrt((2 - k_min_den) / k_min_den), h = std::hypot(x, y);
  return h > 0 ? Vec2{r * x / h, r * y / h} : Vec2{r, 0};
}

DirectionInterpolator::DirectionInterpolator(const DirectionSet& set) {
  const int n = int(set.size());
  m_pts.reserve(n);
  for (int i = 0; i < n; ++i) {
    Vec2 p = to_parabolic(set.dirs[i]);
    // A duplicate is stored as NaN: it never becomes a vertex and is never returned, so the
    // first of equal directions wins everywhere (triangles, edges and the 1D fallback).
    for (int j = 0; j < i && is_vertex(p); ++j)
      if (is_vertex(m_pts[j]) && std::hypot(p.x - m_pts[j].x, p.y - m_pts[j].y) <= k_dup_dist)
        p = {std::nan(""), std::nan("")};
    m_pts.push_back(p);
  }
  m_tris = bowyer_watson(m_pts);
  if (m_tris.empty()) return;

  // Hull edges: directed triangle edges whose reverse is not a triangle edge.
  std::vector<std::array<int, 2>> edges;
  for (const auto& t : m_tris)
    for (int k = 0; k < 3; ++k) edges.push_back({t[k], t[(k + 1) % 3]});
  std::sort(edges.begin(), edges.end());
  for (const auto& e : edges)
    if (!std::binary_search(edges.begin(), edges.end(), std::array<int, 2>{e[1], e[0]})) m_hull.push_back(e);

  // Grid: about one cell per triangle, so a cell lists a handful of candidates. Each triangle
  // is entered in every cell its bounding box overlaps (conservative, and cheap to build).
  double lo_x = 1e300, lo_y = 1e300, hi_x = -1e300, hi_y = -1e300;
  for (const Vec2& p : m_pts)
    if (is_vertex(p)) lo_x = std::min(lo_x, p.x), lo_y = std::min(lo_y, p.y), hi_x = std::max(hi_x, p.x), hi_y = std::max(hi_y, p.y);
  const int g = std::clamp(int(std::ceil(std::sqrt(double(m_tris.size())))), 1, 64);
  m_grid_n = g;
  m_grid_lo = {lo_x, lo_y};
  m_grid_inv = {g / std::max(hi_x - lo_x, 1e-12), g / std::max(hi_y - lo_y, 1e-12)};
  auto cell_range = [&](const std::array<int, 3>& t, int axis, int& c0, int& c1) {
    double lo = 1e300, hi = -1e300;
    for (int v : t) {
      double c = axis == 0 ? (m_pts[v].x - m_grid_lo.x) * m_grid_inv.x : (m_pts[v].y - m_grid_lo.y) * m_grid_inv.y;
      lo = std::min(lo, c), hi = std::max(hi, c);
    }
    // Widen by a hair so a point on a cell border finds triangles on both sides.
    c0 = std::clamp(int(std::floor(lo - 1e-9)), 0, g - 1), c1 = std::clamp(int(std::floor(hi + 1e-9)), 0, g - 1);
  };
  m_cell_start.assign(size_t(g) * g + 1, 0);
  for (int pass = 0; pass < 2; ++pass) {  // pass 0 counts, pass 1 fills (CSR)
    std::vector<int> fill(m_cell_start.begin(), m_cell_start.end() - 1);
    if (pass == 1) m_cell_tris.resize(m_cell_start.back());
    for (int ti = 0; ti < int(m_tris.size()); ++ti) {
      int x0, x1, y0, y1;
      cell_range(m_tris[ti], 0, x0, x1), cell_range(m_tris[ti], 1, y0, y1);
      for (int y = y0; y <= y1; ++y)
        for (int x = x0; x <= x1; ++x) {
          if (pass == 0) ++m_cell_start[y * g + x + 1];
          else m_cell_tris[fill[y * g + x]++] = ti;
        }
    }
    if (pass == 0)
      for (int c = 0; c < g * g; ++c) m_cell_start[c + 1] += m_cell_start[c];
  }
  m_lazy = std::make_shared<LazyTable>();
}

namespace {

// A closed rectangle of parabolic space.
struct Rect {
  double x0, y0, x1, y1;
};

// Bounds on what cross(o, a, q) evaluates to in double, for every q in r. The exact value is
// affine in q, so its extremes are at corners; each corner value is off by at most a few ulps
// of its terms (bounded 45x over by k_ulps), and so is the value at any q (convex in q, so also
// bounded by the corners).
std::array<double, 3> cross_bounds(const Vec2& o, const Vec2& a, const Rect& r) {
  constexpr double k_ulps = 1e-14;
  const double ex = std::fabs(a.x - o.x), ey = std::fabs(a.y - o.y);
  double lo = std::numeric_limits<double>::infinity(), hi = -lo, err = 0;
  for (const Vec2& q : {Vec2{r.x0, r.y0}, Vec2{r.x1, r.y0}, Vec2{r.x0, r.y1}, Vec2{r.x1, r.y1}}) {
    const double v = cross(o, a, q);
    const double e = k_ulps * (ex * (std::fabs(q.y) + std::fabs(o.y)) + ey * (std::fabs(q.x) + std::fabs(o.x)));
    lo = std::min(lo, v - e), hi = std::max(hi, v + e), err = std::max(err, e);
  }
  return {lo - err, hi + err, err};  // the bounds, and the largest rounding error
}

// Does the search's test min3(bary(t, q)) >= -k_inside_tol fail for every q in r? Yes when one
// cross product is below -k_inside_tol all over r; or when r lies beside t's bounding box, by
// gap along x or y: with barycentrics l summing to 1, q.x - max v.x = sum l_k (v_k.x - max v.x)
// <= 2 * (-min l) * width, so min l <= -gap / (2 width) and that cross product is at most
// -area2 * gap / (2 width) exactly, still below -k_inside_tol after rounding (err). The gap test
// runs first with a looser bound on err (no cross_bounds), as it rejects most candidates.
// Accepted for every q in r when all three stay >= -k_inside_tol.
struct TriVerdict {
  bool accept, reject;
};
TriVerdict classify(const std::vector<Vec2>& pts, const std::array<int, 3>& t, const Rect& r) {
  const Vec2 &a = pts[size_t(t[0])], &b = pts[size_t(t[1])], &c = pts[size_t(t[2])];
  const double x0 = std::min({a.x, b.x, c.x}), x1 = std::max({a.x, b.x, c.x});
  const double y0 = std::min({a.y, b.y, c.y}), y1 = std::max({a.y, b.y, c.y});
  const double area2 = 0.5 * std::fabs(cross(a, b, c));  // halved: room for its own rounding
  const double gx = std::max(r.x0 - x1, x0 - r.x1), gy = std::max(r.y0 - y1, y0 - r.y1);
  const double worst = std::max(gx > 0 ? area2 * gx / (2 * (x1 - x0)) : 0.0, gy > 0 ? area2 * gy / (2 * (y1 - y0)) : 0.0);
  if (worst > 0) {
    // Most candidates are rejected here, before cross_bounds, with a looser bound on its err.
    const double ext = std::max(x1 - x0, y1 - y0);
    const double mag = std::max({std::fabs(x0), std::fabs(x1), std::fabs(y0), std::fabs(y1)});
    const double rmag = std::max({std::fabs(r.x0), std::fabs(r.x1), std::fabs(r.y0), std::fabs(r.y1)});
    if (worst > 2 * (k_inside_tol + 2e-14 * ext * (mag + rmag))) return {false, true};
  }
  bool accept = true, reject = false;
  double err = 0;
  for (int e = 0; e < 3; ++e) {
    const auto bd = cross_bounds(pts[size_t(t[(e + 1) % 3])], pts[size_t(t[(e + 2) % 3])], r);
    accept = accept && bd[0] >= -k_inside_tol;
    reject = reject || bd[1] < -k_inside_tol;
    err = std::max(err, bd[2]);
  }
  return {accept, reject || worst > 2 * (k_inside_tol + err)};
}

double dist_to_segment(const Vec2& a, const Vec2& b, const Vec2& p) {
  const double ex = b.x - a.x, ey = b.y - a.y;
  const double t = std::clamp(((p.x - a.x) * ex + (p.y - a.y) * ey) / (ex * ex + ey * ey), 0.0, 1.0);
  const double dx = a.x + t * ex - p.x, dy = a.y + t * ey - p.y;
  return std::sqrt(dx * dx + dy * dy);
}

}  // namespace

// The table holds, per cell, what weights_at() is proven to do for EVERY point that the query
// arithmetic maps into the cell, so that the fast path returns the same bits:
//  - triangle t: for each coarse cell the rectangle can map to, every candidate listed before t
//    rejects all of the rectangle and t accepts all of it (classify). The search then returns
//    make_weights(t, bary(t, p)), computed the same way by the fast path.
//  - hull edge list: every candidate triangle rejects the rectangle (or it lies outside the coarse
//    grid), so the search projects onto the hull. The list keeps, in m_hull order, every edge
//    that can come within a margin of the nearest; the edges left out are farther for every
//    point of the cell, so they can neither win nor tie, and the first-of-equals rule agrees.
//  - candidate list: the candidates that can accept some point of the rectangle, in the order
//    the search tests them (the same for every coarse cell it can map to), up to one that
//    accepts all of it. The others reject every point, so testing only these finds the same
//    first triangle; if none holds the point, the search would go on to the hull, and so does
//    the fast path (weights_at).
// "Every" is made rigorous by bounding rounding (cross_bounds, and a cell rectangle widened far
// past what fx = (p - lo) * inv can round into); any doubt leaves the cell undecided (-1).
void DirectionInterpolator::build_fine_table(FineTable& T) const {
  double lo_x = 1e300, lo_y = 1e300, hi_x = -1e300, hi_y = -1e300;
  for (const Vec2& p : m_pts)
    if (is_vertex(p)) lo_x = std::min(lo_x, p.x), lo_y = std::min(lo_y, p.y), hi_x = std::max(hi_x, p.x), hi_y = std::max(hi_y, p.y);
  // Square, over the bounding box widened by k_widen of its size on each side: for a set up to
  // theta 75 deg (UBO) that reaches theta 85 deg, so grazing queries hit the table too.
  constexpr double k_widen = 0.1;
  const double size = std::max(hi_x - lo_x, hi_y - lo_y), side = size * (1 + 2 * k_widen);
  // Entries and lists hold triangle and hull edge indices as int16_t.
  if (!(size > 0) || !std::isfinite(side) || m_hull.size() > size_t(INT16_MAX) || m_tris.size() > size_t(INT16_MAX)) return;
  const int n = std::clamp(int(std::lround(k_fine_per_tri * std::sqrt(double(m_tris.size())))), 16, k_fine_max);
  const double cw = side / n;
  T.lo = {0.5 * (lo_x + hi_x) - 0.5 * side, 0.5 * (lo_y + hi_y) - 0.5 * side};
  // A point maps into a cell when its rounded fx lies in [i, i + 1): allow far more than that
  // rounding around the exact cell.
  const double margin = 1e-7 * cw + 1e-13 * (std::fabs(T.lo.x) + std::fabs(T.lo.y) + side);
  const double path_margin = 1e-9 * (1 + std::fabs(T.lo.x) + std::fabs(T.lo.y) + side);
  const int g = m_grid_n;
  std::map<std::vector<int16_t>, int> lists, multis;  // distinct hull edge / candidate lists, by id
  std::vector<int16_t> seq, cell_seq;
  std::vector<int16_t> list;
  std::vector<double> lower(m_hull.size());
  std::vector<int> order;

  // The table entry for the points of [x0, x0 + w] x [y0, y0 + w], widened by m.
  auto classify_cell = [&](double x0, double y0, double w, double m) -> int16_t {
    const Rect r{x0 - m, y0 - m, x0 + w + m, y0 + w + m};
    // Coarse cells the query arithmetic can put a point of r in (monotone in p, so the range
    // of the corners); a point outside [0, g) skips the triangle search.
    const double cx0 = (r.x0 - m_grid_lo.x) * m_grid_inv.x, cx1 = (r.x1 - m_grid_lo.x) * m_grid_inv.x;
    const double cy0 = (r.y0 - m_grid_lo.y) * m_grid_inv.y, cy1 = (r.y1 - m_grid_lo.y) * m_grid_inv.y;
    // Per coarse cell: its candidates that can accept some point of r, in list order, up to the
    // first that accepts all of r (the later ones are never reached). The search on a point of r
    // tests exactly these in this order, up to the rejected ones (which fail for it anyway).
    bool first = true, same = true, ends_accepted = false;
    seq.clear();
    if (cx1 >= 0 && cy1 >= 0 && cx0 < g && cy0 < g) {
      const int x_0 = int(std::max(cx0, 0.0)), x_1 = int(std::min(cx1, g - 1.0));
      const int y_0 = int(std::max(cy0, 0.0)), y_1 = int(std::min(cy1, g - 1.0));
      for (int y = y_0; y <= y_1 && same; ++y)
        for (int x = x_0; x <= x_1 && same; ++x) {
          const int c = y * g + x;
          cell_seq.clear();
          bool accepted = false;
          for (int k = m_cell_start[c]; k < m_cell_start[c + 1] && !accepted; ++k) {
            const TriVerdict v = classify(m_pts, m_tris[size_t(m_cell_tris[k])], r);
            if (!v.reject) cell_seq.push_back(int16_t(m_cell_tris[k])), accepted = v.accept;
          }
          if (first) seq = cell_seq, ends_accepted = accepted, first = false;
          else same = seq == cell_seq;  // a mix of answers is undecided
        }
    }
    if (!same) return -1;
    if (!seq.empty()) {
      // Points of r outside the coarse grid skip the search: not allowed here.
      const bool all_in_grid = cx0 >= 0 && cy0 >= 0 && cx1 < g && cy1 < g;
      if (!all_in_grid) return -1;
      if (seq.size() == 1 && ends_accepted) return seq[0];
      if (seq.size() > size_t(k_multi)) return -1;
      seq.resize(k_multi, -1);
      const int id = multis.emplace(seq, int(multis.size())).first->second;
      return id < k_multi_count ? int16_t(k_multi_base - id) : int16_t(-1);
    }
    // Hull projection for every point of r. The nearest distance is at most `best` (from edges
    // that take part everywhere in r); keep the edges that can come near it.
    const Vec2 mid{0.5 * (r.x0 + r.x1), 0.5 * (r.y0 + r.y1)};
    const double half_diag = std::sqrt(0.5) * (r.x1 - r.x0) * (1 + 1e-9);
    for (size_t h = 0; h < m_hull.size(); ++h)
      lower[h] = dist_to_segment(m_pts[size_t(m_hull[h][0])], m_pts[size_t(m_hull[h][1])], mid) - half_diag;
    // The nearest edge (by distance to mid) that takes part everywhere in r; usually the first.
    double best = std::numeric_limits<double>::infinity();
    order.resize(m_hull.size());
    for (size_t h = 0; h < order.size(); ++h) order[h] = int(h);
    std::sort(order.begin(), order.end(), [&](int x, int y) { return lower[size_t(x)] < lower[size_t(y)]; });
    for (int h : order)
      if (cross_bounds(m_pts[size_t(m_hull[size_t(h)][0])], m_pts[size_t(m_hull[size_t(h)][1])], r)[1] <= 0) {
        best = lower[size_t(h)] + 2 * half_diag;
        break;
      }
    if (!(best < std::numeric_limits<double>::infinity())) return -1;
    list.clear();
    for (size_t h = 0; h < m_hull.size(); ++h)
      if (lower[h] <= best + path_margin) list.push_back(int16_t(h));
    const int id = lists.emplace(list, int(lists.size())).first->second;
    return id < k_list_count ? int16_t(-2 - id) : int16_t(-1);
  };

  // Blocks of k_block x k_block cells first: a block of one triangle, or of hull edges, gives
  // that answer to all its cells (a proof for the block, widened past its cells' own margins,
  // holds for each of them), which saves most of the build time.
  std::vector<int16_t> table(size_t(n) * size_t(n));
  for (int bj = 0; bj < n; bj += k_block)
    for (int bi = 0; bi < n; bi += k_block) {
      const int nj = std::min(k_block, n - bj), ni = std::min(k_block, n - bi);
      const int16_t e = ni == nj ? classify_cell(T.lo.x + bi * cw, T.lo.y + bj * cw, ni * cw, 2 * margin) : -1;
      const bool whole = e >= 0 || (e < -1 && e > k_multi_base);
      for (int j = bj; j < bj + nj; ++j)
        for (int i = bi; i < bi + ni; ++i)
          table[size_t(j) * size_t(n) + size_t(i)] = whole ? e : classify_cell(T.lo.x + i * cw, T.lo.y + j * cw, cw, margin);
    }
  std::vector<const std::vector<int16_t>*> by_id(lists.size());
  for (const auto& [l, id] : lists) by_id[size_t(id)] = &l;
  T.out_start.assign(1, 0);
  for (const auto* l : by_id) {
    T.out_edges.insert(T.out_edges.end(), l->begin(), l->end());
    T.out_start.push_back(int(T.out_edges.size()));
  }
  T.multi.assign(multis.size() * k_multi, -1);
  for (const auto& [l, id] : multis) std::copy(l.begin(), l.end(), T.multi.begin() + ptrdiff_t(id) * k_multi);
  for (const auto& t : m_tris) T.corner_tris.push_back({m_pts[size_t(t[0])], m_pts[size_t(t[1])], m_pts[size_t(t[2])], t});
  T.cells = std::move(table);
  T.n = n;
  T.inv = n / side;
}

DirWeights DirectionInterpolator::weights_reference(const Vec3& dir) const {
  if (m_pts.empty()) return {};
  return weights_at(to_parabolic(dir));
}

const DirectionInterpolator::FineTable& DirectionInterpolator::fine() const {
  static const FineTable none;
  if (!m_lazy) return none;
  if (!m_lazy->ready.load(std::memory_order_acquire))
    std::call_once(m_lazy->once, [&] {
      build_fine_table(m_lazy->table);
      m_lazy->ready.store(true, std::memory_order_release);
    });
  return m_lazy->table;
}

DirectionInterpolator::FineGrid DirectionInterpolator::fine_grid() const {
  const FineTable& t = fine();
  return {t.lo, t.n > 0 ? 1 / t.inv : 0, t.n};
}

inline int DirectionInterpolator::table_entry(const FineTable& t, const Vec2& p) {
  // The cell arithmetic build_fine_table allows for; NaN fails the range test.
  const double fx = (p.x - t.lo.x) * t.inv, fy = (p.y - t.lo.y) * t.inv;
  if (!(fx >= 0 && fy >= 0 && fx < t.n && fy < t.n)) return -1;
  return t.cells[size_t(int(fy)) * size_t(t.n) + size_t(int(fx))];
}

DirWeights DirectionInterpolator::weights(const Vec3& dir) const {
  // The common case inline and short (one branch); the rest out of line (table_miss).
  const FineTable& ft = fine();
  const Vec2 p = to_parabolic(dir);
  const int c = table_entry(ft, p);  // -1 for an empty interpolator (no table)
  if (c < 0) return table_miss(ft, p, c);
  // bary() on the triangle's own copy of its points: the same doubles, one dependent load less.
  const CornerTri& t = ft.corner_tris[size_t(c)];
  return make_weights(t.index, {cross(t.b, t.c, p), cross(t.c, t.a, p), cross(t.a, t.b, p)});
}

void DirectionInterpolator::weights_batch(const Vec3* dir, size_t n, DirWeights* out) const {
  const FineTable& ft = fine();
  constexpr size_t G = 32;  // queries in flight: enough misses to overlap, all in L1
  Vec2 p[G];
  int c[G];
  for (size_t i0 = 0; i0 < n; i0 += G) {
    const size_t m = std::min(G, n - i0);
    for (size_t k = 0; k < m; ++k) p[k] = to_parabolic(dir[i0 + k]);
    for (size_t k = 0; k < m; ++k) c[k] = table_entry(ft, p[k]);
    for (size_t k = 0; k < m; ++k) {
      if (c[k] < 0) {
        out[i0 + k] = table_miss(ft, p[k], c[k]);
        continue;
      }
      const CornerTri& t = ft.corner_tris[size_t(c[k])];  // as weights()
      out[i0 + k] = make_weights(t.index, {cross(t.b, t.c, p[k]), cross(t.c, t.a, p[k]), cross(t.a, t.b, p[k])});
    }
  }
}

[[gnu::noinline]] DirWeights DirectionInterpolator::table_miss(const FineTable& ft, const Vec2& p, int c) const {
  if (c <= k_multi_base) {
    // Candidates in the search's order: the first that accepts p is what the search returns; if
    // none does, the search goes on past them (to candidates that reject p) to the hull.
    // On the triangles' own copies of their points (bary()'s doubles, one dependent load less).
    for (int k = 0; k < k_multi; ++k) {
      const int ti = ft.multi[size_t(k_multi_base - c) * k_multi + size_t(k)];
      if (ti < 0) break;
      const CornerTri& t = ft.corner_tris[size_t(ti)];
      const std::array<double, 3> w = {cross(t.b, t.c, p), cross(t.c, t.a, p), cross(t.a, t.b, p)};
      if (min3(w) >= -k_inside_tol) return make_weights(t.index, w);
    }
    return weights_at(p);
  }
  if (c < -1) {
    HullHit h;
    for (int k = ft.out_start[size_t(-2 - c)]; k < ft.out_start[size_t(-1 - c)]; ++k) {
      const auto& e = m_hull[size_t(ft.out_edges[size_t(k)])];
      h.add(m_pts[size_t(e[0])], m_pts[size_t(e[1])], e[0], e[1], p);
    }
    return make_weights({h.ia, h.ib, h.ia}, {1 - h.u, h.u, 0});
  }
  if (m_pts.empty()) return {};
  return weights_at(p);
}

int DirectionInterpolator::fast_path_kind(const Vec3& dir) const {
  if (m_pts.empty()) return 0;
  const int c = table_entry(fine(), to_parabolic(dir));
  return c >= 0 ? 1 : c <= k_multi_base ? 3 : c < -1 ? 2 : 0;
}

[[gnu::noinline]] DirWeights DirectionInterpolator::weights_at(const Vec2& p) const {
  if (!m_tris.empty()) {
    const double cx = (p.x - m_grid_lo.x) * m_grid_inv.x, cy = (p.y - m_grid_lo.y) * m_grid_inv.y;
    if (cx >= 0 && cy >= 0 && cx < m_grid_n && cy < m_grid_n) {
      const int c = int(cy) * m_grid_n + int(cx);
      for (int k = m_cell_start[c]; k < m_cell_start[c + 1]; ++k) {
        const auto& t = m_tris[m_cell_tris[k]];
        std::array<double, 3> w = bary(m_pts, t, p);
        if (min3(w) >= -k_inside_tol) return make_weights(t, w);
      }
    }
    // Outside the hull: project onto the nearest point of the hull boundary.
    HullHit h;
    for (const auto& e : m_hull) h.add(m_pts[e[0]], m_pts[e[1]], e[0], e[1], p);
    if (h.ia >= 0) return make_weights({h.ia, h.ib, h.ia}, {1 - h.u, h.u, 0});
    // Inside every hull edge yet in no candidate triangle: only rounding on an edge can do that.
    // Take the triangle p is least outside of and clamp.
    const std::array<int, 3>* best_t = &m_tris[0];
    for (const auto& t : m_tris)
      if (min3(bary(m_pts, t, p)) > min3(bary(m_pts, *best_t, p))) best_t = &t;
    return make_weights(*best_t, bary(m_pts, *best_t, p));
  }

  // Degenerate sets (one point, two points, or all collinear): interpolate along the line
  // through the points. Parametrise by projection onto the direction from the first vertex to
  // the vertex farthest from it, then blend the nearest neighbours below and above.
  int first = -1, far = -1;
  double far_d = -1;
  for (int i = 0; i < int(m_pts.size()); ++i) {
    if (!is_vertex(m_pts[i])) continue;
    if (first < 0) first = i;
    double d = std::hypot(m_pts[i].x - m_pts[first].x, m_pts[i].y - m_pts[first].y);
    if (d > far_d) far_d = d, far = i;
  }
  if (first < 0) return {};  // every direction was NaN
  if (far_d <= 0) return single(first);
  const Vec2 o = m_pts[first];
  const double ux = (m_pts[far].x - o.x) / far_d, uy = (m_pts[far].y - o.y) / far_d;
  auto param = [&](const Vec2& q) { return (q.x - o.x) * ux + (q.y - o.y) * uy; };
  const double tq = param(p);
  int lo = -1, hi = -1, min_i = first, max_i = first;
  double lo_t = -std::numeric_limits<double>::infinity(), hi_t = std::numeric_limits<double>::infinity();
  for (int i = 0; i < int(m_pts.size()); ++i) {
    if (!is_vertex(m_pts[i])) continue;
    double ti = param(m_pts[i]);
    if (ti <= tq && ti > lo_t) lo_t = ti, lo = i;
    if (ti >= tq && ti < hi_t) hi_t = ti, hi = i;
    if (ti < param(m_pts[min_i])) min_i = i;
    if (ti > param(m_pts[max_i])) max_i = i;
  }
  if (lo < 0) return single(min_i);  // before the first point: clamp
  if (hi < 0) return single(max_i);  // past the last point: clamp
  if (hi_t - lo_t <= 0) return single(lo);
  double u = (tq - lo_t) / (hi_t - lo_t);
  return make_weights({lo, hi, lo}, {1 - u, u, 0});
}

}  // namespace btfc
