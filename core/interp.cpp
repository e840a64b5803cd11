// Direction interpolation: Delaunay triangulation in parabolic coordinates (Bowyer-Watson) and
// barycentric point location. See core/interp.h for the contract.
#include "core/interp.h"

#include <algorithm>
#include <cmath>
#include <limits>

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
}

DirWeights DirectionInterpolator::weights(const Vec3& dir) const {
  if (m_pts.empty()) return {};
  const Vec2 p = to_parabolic(dir);

  if (!m_tris.empty()) {
    // Unnormalized barycentric weights of p in triangle t (twice the sub-triangle areas).
    auto bary = [&](const std::array<int, 3>& t) {
      const Vec2 &a = m_pts[t[0]], &b = m_pts[t[1]], &c = m_pts[t[2]];
      return std::array<double, 3>{cross(b, c, p), cross(c, a, p), cross(a, b, p)};
    };
    auto min3 = [](const std::array<double, 3>& w) { return std::min({w[0], w[1], w[2]}); };
    const double cx = (p.x - m_grid_lo.x) * m_grid_inv.x, cy = (p.y - m_grid_lo.y) * m_grid_inv.y;
    if (cx >= 0 && cy >= 0 && cx < m_grid_n && cy < m_grid_n) {
      const int c = int(cy) * m_grid_n + int(cx);
      for (int k = m_cell_start[c]; k < m_cell_start[c + 1]; ++k) {
        const auto& t = m_tris[m_cell_tris[k]];
        std::array<double, 3> w = bary(t);
        if (min3(w) >= -k_inside_tol) return make_weights(t, w);
      }
    }
    // Outside the hull: project onto the nearest point of the hull boundary. Only edges that
    // p is not strictly inside of can hold it.
    double best = std::numeric_limits<double>::infinity(), best_u = 0;
    int ia = -1, ib = -1;
    for (const auto& e : m_hull) {
      const Vec2 &a = m_pts[e[0]], &b = m_pts[e[1]];
      if (cross(a, b, p) > 0) continue;
      double ex = b.x - a.x, ey = b.y - a.y;
      double u = std::clamp(((p.x - a.x) * ex + (p.y - a.y) * ey) / (ex * ex + ey * ey), 0.0, 1.0);
      double dx = a.x + u * ex - p.x, dy = a.y + u * ey - p.y, d2 = dx * dx + dy * dy;
      if (d2 < best) best = d2, best_u = u, ia = e[0], ib = e[1];
    }
    if (ia >= 0) return make_weights({ia, ib, ia}, {1 - best_u, best_u, 0});
    // Inside every hull edge yet in no candidate triangle: only rounding on an edge can do that.
    // Take the triangle p is least outside of and clamp.
    const std::array<int, 3>* best_t = &m_tris[0];
    for (const auto& t : m_tris)
      if (min3(bary(t)) > min3(bary(*best_t))) best_t = &t;
    return make_weights(*best_t, bary(*best_t));
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
