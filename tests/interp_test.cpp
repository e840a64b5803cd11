// Tests for core/interp: Delaunay triangulation in parabolic space and direction weights.
#include "core/interp.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <random>
#include <utility>

namespace btfc {
namespace {

constexpr double k_pi = 3.14159265358979323846;
// Random/lattice triangulation trials; build with -DINTERP_STRESS_TRIALS=5000 for a soak run.
#ifndef INTERP_STRESS_TRIALS
#define INTERP_STRESS_TRIALS 60
#endif
constexpr int k_stress_trials = INTERP_STRESS_TRIALS;
double deg(double d) { return d * k_pi / 180.0; }

double cross(const Vec2& o, const Vec2& a, const Vec2& b) {
  return (a.x - o.x) * (b.y - o.y) - (a.y - o.y) * (b.x - o.x);
}

std::vector<Vec2> parabolic(const DirectionSet& s) {
  std::vector<Vec2> p;
  for (const Vec3& d : s.dirs) p.push_back(to_parabolic(d));
  return p;
}

// Convex hull by Andrew's monotone chain (strict: collinear boundary points dropped), ccw.
std::vector<Vec2> convex_hull(std::vector<Vec2> p) {
  std::sort(p.begin(), p.end(), [](const Vec2& a, const Vec2& b) { return a.x < b.x || (a.x == b.x && a.y < b.y); });
  if (p.size() < 3) return p;
  std::vector<Vec2> h(2 * p.size());
  size_t k = 0;
  for (size_t i = 0; i < p.size(); ++i) {
    while (k >= 2 && cross(h[k - 2], h[k - 1], p[i]) <= 0) --k;
    h[k++] = p[i];
  }
  for (size_t i = p.size() - 1, t = k + 1; i-- > 0;) {
    while (k >= t && cross(h[k - 2], h[k - 1], p[i]) <= 0) --k;
    h[k++] = p[i];
  }
  h.resize(k - 1);
  return h;
}

double polygon_area(const std::vector<Vec2>& h) {
  double a = 0;
  for (size_t i = 0; i < h.size(); ++i) a += cross({0, 0}, h[i], h[(i + 1) % h.size()]);
  return 0.5 * a;
}

double dist_to_hull_boundary(const std::vector<Vec2>& hull, const Vec2& q) {
  double best = 1e300;
  for (size_t i = 0; i < hull.size(); ++i) {
    const Vec2 &a = hull[i], &b = hull[(i + 1) % hull.size()];
    double ex = b.x - a.x, ey = b.y - a.y;
    double u = std::clamp(((q.x - a.x) * ex + (q.y - a.y) * ey) / (ex * ex + ey * ey), 0.0, 1.0);
    best = std::min(best, std::hypot(a.x + u * ex - q.x, a.y + u * ey - q.y));
  }
  return best;
}

// Indices of the first occurrence of each distinct point (what the interpolator keeps).
std::vector<int> unique_indices(const std::vector<Vec2>& p) {
  std::vector<int> u;
  for (int i = 0; i < int(p.size()); ++i) {
    bool dup = false;
    for (int j : u) dup = dup || std::hypot(p[i].x - p[j].x, p[i].y - p[j].y) <= 1e-9;
    if (!dup) u.push_back(i);
  }
  return u;
}

// Checks that the triangles form a valid Delaunay triangulation of the distinct points:
// positive area, every distinct point used, duplicates unused, manifold edges, the boundary is
// the convex hull, the areas add up to the hull area, and no point is inside a circumcircle.
void expect_valid_triangulation(const DirectionSet& set, const DirectionInterpolator& in) {
  const std::vector<Vec2> p = parabolic(set);
  const std::vector<int> uniq = unique_indices(p);
  std::vector<Vec2> up;
  for (int i : uniq) up.push_back(p[i]);
  const std::vector<Vec2> hull = convex_hull(up);
  // h counts every point on the hull boundary, including ones in the middle of a hull edge.
  const int n = int(uniq.size());
  int h = 0;
  for (const Vec2& q : up) h += dist_to_hull_boundary(hull, q) <= 1e-14;
  const auto& tris = in.triangles();
  ASSERT_EQ(int(tris.size()), 2 * n - h - 2) << set.name;

  double area = 0, min_area = 1e300;
  std::vector<int> used(p.size(), 0);
  std::map<std::pair<int, int>, int> edges;
  for (const auto& t : tris) {
    for (int k = 0; k < 3; ++k) {
      ASSERT_GE(t[k], 0);
      ASSERT_LT(t[k], int(p.size()));
      used[t[k]] = 1;
      ++edges[{t[k], t[(k + 1) % 3]}];
    }
    double a = 0.5 * cross(p[t[0]], p[t[1]], p[t[2]]);
    area += a;
    min_area = std::min(min_area, a);
  }
  EXPECT_GT(min_area, 1e-12) << set.name << ": zero-area or clockwise triangle";
  for (int i = 0; i < int(p.size()); ++i)
    EXPECT_EQ(used[i], std::find(uniq.begin(), uniq.end(), i) != uniq.end() ? 1 : 0) << set.name << " point " << i;
  int boundary = 0;
  for (const auto& [e, count] : edges) {
    EXPECT_EQ(count, 1) << "directed edge used twice: overlap";
    if (!edges.count({e.second, e.first})) ++boundary;
  }
  EXPECT_EQ(boundary, h) << set.name;
  const double hull_area = polygon_area(hull);
  EXPECT_NEAR(area, hull_area, 1e-9 * hull_area) << set.name;

  for (const auto& t : tris) {
    const Vec2 &a = p[t[0]], &b = p[t[1]], &c = p[t[2]];
    double d = 2 * cross(a, b, c);
    double ux = ((a.x * a.x + a.y * a.y) * (b.y - c.y) + (b.x * b.x + b.y * b.y) * (c.y - a.y) +
                 (c.x * c.x + c.y * c.y) * (a.y - b.y)) / d;
    double uy = ((a.x * a.x + a.y * a.y) * (c.x - b.x) + (b.x * b.x + b.y * b.y) * (a.x - c.x) +
                 (c.x * c.x + c.y * c.y) * (b.x - a.x)) / d;
    double r = std::hypot(a.x - ux, a.y - uy);
    for (int i : uniq) EXPECT_GE(std::hypot(p[i].x - ux, p[i].y - uy), r * (1 - 1e-7)) << set.name << " not Delaunay";
  }
}

void expect_valid_weights(const DirWeights& w, int n) {
  double sum = 0;
  for (int k = 0; k < 3; ++k) {
    EXPECT_GE(w.weight[k], 0.f);
    EXPECT_GE(w.index[k], 0);
    EXPECT_LT(w.index[k], n);
    sum += w.weight[k];
  }
  EXPECT_NEAR(sum, 1.0, 1e-6);
}

// Weighted average of the parabolic points: what interpolating f(p) = p reproduces.
Vec2 blend(const DirWeights& w, const std::vector<Vec2>& p) {
  Vec2 r;
  for (int k = 0; k < 3; ++k) r.x += w.weight[k] * p[w.index[k]].x, r.y += w.weight[k] * p[w.index[k]].y;
  return r;
}

Vec3 random_hemisphere(std::mt19937& rng) {
  std::uniform_real_distribution<double> u(0, 1);
  double z = u(rng), phi = 2 * k_pi * u(rng), s = std::sqrt(1 - z * z);
  return {float(s * std::cos(phi)), float(s * std::sin(phi)), float(z)};
}

bool inside_hull(const std::vector<Vec2>& hull, const Vec2& q, double margin) {
  for (size_t i = 0; i < hull.size(); ++i) {
    const Vec2 &a = hull[i], &b = hull[(i + 1) % hull.size()];
    if (cross(a, b, q) / std::hypot(b.x - a.x, b.y - a.y) < margin) return false;
  }
  return true;
}

TEST(Interp, ParabolicMapping) {
  Vec2 p = to_parabolic({0, 0, 1});
  EXPECT_EQ(p.x, 0);
  EXPECT_EQ(p.y, 0);
  p = to_parabolic({1, 0, 0});  // horizon -> unit circle
  EXPECT_DOUBLE_EQ(p.x, 1);
  p = to_parabolic({0, 0, -1});  // straight down: finite, far outside the disc
  EXPECT_TRUE(std::isfinite(p.x) && std::isfinite(p.y));
}

TEST(Interp, TriangulationUbo2003) {
  DirectionSet s = DirectionSet::ubo2003();
  DirectionInterpolator in(s);
  EXPECT_EQ(in.triangles().size(), size_t(2 * 81 - 24 - 2));  // 136
  expect_valid_triangulation(s, in);
}

TEST(Interp, TriangulationUbo2014) {
  DirectionSet s = DirectionSet::ubo2014();
  DirectionInterpolator in(s);
  EXPECT_EQ(in.triangles().size(), size_t(2 * 151 - 24 - 2));  // 276
  expect_valid_triangulation(s, in);
}

TEST(Interp, TriangulationRandomSets) {
  std::mt19937 rng(1234);
  std::uniform_real_distribution<double> u(0, 1);
  for (int trial = 0; trial < k_stress_trials; ++trial) {
    DirectionSet s;
    s.name = "random" + std::to_string(trial);
    int n = 3 + (trial % 40) * 7;
    for (int i = 0; i < n; ++i) s.dirs.push_back(dir_from_theta_phi(deg(85 * std::sqrt(u(rng))), 2 * k_pi * u(rng)));
    DirectionInterpolator in(s);
    expect_valid_triangulation(s, in);
    // Queries on the same set: valid weights everywhere, linear functions exact inside.
    const std::vector<Vec2> p = parabolic(s);
    const std::vector<Vec2> hull = convex_hull(p);
    for (int q = 0; q < 300; ++q) {
      Vec3 d = random_hemisphere(rng);
      DirWeights w = in.weights(d);
      expect_valid_weights(w, n);
      Vec2 pq = to_parabolic(d), b = blend(w, p);
      if (inside_hull(hull, pq, 1e-9)) {
        EXPECT_NEAR(b.x, pq.x, 1e-5);
        EXPECT_NEAR(b.y, pq.y, 1e-5);
      } else {
        EXPECT_NEAR(std::hypot(b.x - pq.x, b.y - pq.y), dist_to_hull_boundary(hull, pq), 1e-5);
      }
    }
  }
}

TEST(Interp, TriangulationCollinearHullPoints) {
  // Points on the parabolic x axis (phi = 0 / 180 deg leaves ~1e-17 in y) plus one above: every
  // point is on the hull, so n - 2 triangles, and the axis points split the bottom edge.
  DirectionSet s;
  for (int t = -60; t <= 60; t += 15) s.dirs.push_back(dir_from_theta_phi(deg(std::abs(t)), t < 0 ? k_pi : 0));
  s.dirs.push_back(dir_from_theta_phi(deg(40), deg(90)));
  DirectionInterpolator in(s);
  ASSERT_EQ(in.triangles().size(), s.size() - 2);
  const std::vector<Vec2> p = parabolic(s);
  double area = 0;
  for (const auto& t : in.triangles()) {
    double a = 0.5 * cross(p[t[0]], p[t[1]], p[t[2]]);
    EXPECT_GT(a, 1e-6);
    area += a;
  }
  const double base = p[8].x - p[0].x;  // theta 60 at phi 0 minus theta 60 at phi 180
  EXPECT_NEAR(area, 0.5 * base * p.back().y, 1e-7);
  for (int i = 0; i < int(s.size()); ++i) EXPECT_EQ(in.weights(s.dirs[i]).index[0], i);
  // Just below the axis (outside the hull): projected onto it, between two axis points.
  DirWeights w = in.weights(dir_from_theta_phi(deg(20), deg(-5)));
  expect_valid_weights(w, int(s.size()));
  EXPECT_NEAR(blend(w, p).y, 0, 1e-9);
}

TEST(Interp, TriangulationExactLatticeStress) {
  // z = 0 makes to_parabolic the identity on (x, y), so these are exact lattice points: many
  // exactly collinear triples (also along the hull) and exactly cocircular quads, inserted in
  // shuffled orders, as random subsets, and with repeated points.
  std::mt19937 rng(99);
  for (int trial = 0; trial < k_stress_trials; ++trial) {
    DirectionSet s;
    s.name = "lattice" + std::to_string(trial);
    int m = 2 + trial % 7;
    for (int i = 0; i <= m; ++i)
      for (int j = 0; j <= m; ++j)
        if (trial < 20 || rng() % 3 != 0) s.dirs.push_back({float(i) / m, float(j) / m, 0});
    if (trial % 5 == 4) s.dirs.push_back(s.dirs[rng() % s.size()]);
    std::shuffle(s.dirs.begin(), s.dirs.end(), rng);
    DirectionInterpolator in(s);
    if (in.triangles().empty()) continue;  // a subset that came out collinear
    expect_valid_triangulation(s, in);
  }
}

TEST(Interp, TriangulationRandomRingSets) {
  // Dome-like samplings (rings of equally spaced, hence cocircular, directions with random
  // counts and azimuth offsets), the structure of the UBO sets, in many variants.
  std::mt19937 rng(5);
  for (int trial = 0; trial < k_stress_trials; ++trial) {
    DirectionSet s;
    s.name = "rings" + std::to_string(trial);
    if (rng() % 2) s.dirs.push_back({0, 0, 1});
    int rings = 1 + int(rng() % 9);
    for (int r = 1; r <= rings; ++r) {
      int count = 3 + int(rng() % 24);
      double theta = 80.0 * r / rings, offset = (rng() % 4) * 360.0 / count / 4;
      for (int i = 0; i < count; ++i) s.dirs.push_back(dir_from_theta_phi(deg(theta), deg(offset + 360.0 * i / count)));
    }
    DirectionInterpolator in(s);
    expect_valid_triangulation(s, in);
    for (int i = 0; i < int(s.size()); ++i) ASSERT_EQ(in.weights(s.dirs[i]).index[0], i) << s.name;
  }
}

TEST(Interp, TriangulationCocircularAndLattice) {
  // Regular polygons on one circle (all points cocircular) and a square lattice (every cell is
  // a cocircular quad): worst cases for the incircle tie-break.
  for (int m : {4, 8, 24, 60}) {
    DirectionSet s;
    s.name = "ring" + std::to_string(m);
    for (int i = 0; i < m; ++i) s.dirs.push_back(dir_from_theta_phi(deg(60), 2 * k_pi * i / m));
    DirectionInterpolator in(s);
    expect_valid_triangulation(s, in);
  }
  DirectionSet lattice;
  lattice.name = "lattice";
  for (int i = -4; i <= 4; ++i)
    for (int j = -4; j <= 4; ++j) {
      // Invert the parabolic map so the lattice is exact in parabolic space up to float rounding.
      double x = 0.1 * i, y = 0.1 * j, r2 = x * x + y * y;
      lattice.dirs.push_back({float(2 * x / (1 + r2)), float(2 * y / (1 + r2)), float((1 - r2) / (1 + r2))});
    }
  DirectionInterpolator in(lattice);
  expect_valid_triangulation(lattice, in);
}

TEST(Interp, MeasuredDirectionsAreExact) {
  for (const DirectionSet& s : {DirectionSet::ubo2003(), DirectionSet::ubo2014()}) {
    DirectionInterpolator in(s);
    for (int i = 0; i < int(s.size()); ++i) {
      DirWeights w = in.weights(s.dirs[i]);
      EXPECT_EQ(w.index[0], i) << s.name;
      EXPECT_EQ(w.weight[0], 1.f) << s.name;
      EXPECT_EQ(w.weight[1], 0.f) << s.name;
      EXPECT_EQ(w.weight[2], 0.f) << s.name;
    }
  }
}

TEST(Interp, RandomQueriesValidAndLinearExact) {
  std::mt19937 rng(7);
  for (const DirectionSet& s : {DirectionSet::ubo2003(), DirectionSet::ubo2014()}) {
    DirectionInterpolator in(s);
    const std::vector<Vec2> p = parabolic(s);
    const std::vector<Vec2> hull = convex_hull(p);
    int inside = 0;
    for (int q = 0; q < 10000; ++q) {
      Vec3 d = random_hemisphere(rng);
      DirWeights w = in.weights(d);
      expect_valid_weights(w, int(s.size()));
      Vec2 pq = to_parabolic(d);
      if (!inside_hull(hull, pq, 1e-9)) continue;
      ++inside;
      // Barycentric weights reproduce linear functions of the parabolic coordinates.
      double f = 0;
      for (int k = 0; k < 3; ++k) f += w.weight[k] * (3 * p[w.index[k]].x - 2 * p[w.index[k]].y + 1);
      EXPECT_NEAR(f, 3 * pq.x - 2 * pq.y + 1, 1e-5);
    }
    EXPECT_GT(inside, 6000) << s.name;  // ~74% of the hemisphere is within theta 75 deg
  }
}

TEST(Interp, OutsideHullProjectsToBoundary) {
  DirectionSet s = DirectionSet::ubo2003();
  DirectionInterpolator in(s);
  const std::vector<Vec2> p = parabolic(s);
  const std::vector<Vec2> hull = convex_hull(p);
  for (double theta : {76.0, 80.0, 89.9, 90.0, 100.0, 135.0, 179.0, 180.0}) {
    for (int k = 0; k < 37; ++k) {
      Vec3 d = dir_from_theta_phi(deg(theta), deg(10.0 * k + 0.3));
      DirWeights w = in.weights(d);
      expect_valid_weights(w, int(s.size()));
      for (int j = 0; j < 3; ++j)
        if (w.weight[j] > 0) {
          EXPECT_GE(w.index[j], 81 - 24) << "weight on a non-hull (theta < 75) vertex";
        }
      // The blended point is on the hull boundary and is the nearest such point.
      Vec2 b = blend(w, p), q = to_parabolic(d);
      EXPECT_LT(dist_to_hull_boundary(hull, b), 1e-6);
      EXPECT_NEAR(std::hypot(b.x - q.x, b.y - q.y), dist_to_hull_boundary(hull, q), 1e-5);
    }
  }
  // Straight down (z = -1) must not divide by zero.
  expect_valid_weights(in.weights({0, 0, -1}), 81);
  // Just outside the 75 deg ring, exactly at a ring direction: snaps onto that direction.
  DirWeights w = in.weights(dir_from_theta_phi(deg(80), 0));
  EXPECT_EQ(w.index[0], 57);
  EXPECT_EQ(w.weight[0], 1.f);
}

TEST(Interp, SingleDirection) {
  DirectionInterpolator in(DirectionSet::single(dir_from_theta_phi(deg(30), deg(40))));
  EXPECT_TRUE(in.triangles().empty());
  for (Vec3 d : {Vec3{0, 0, 1}, dir_from_theta_phi(deg(80), deg(200)), Vec3{0, 0, -1}}) {
    DirWeights w = in.weights(d);
    EXPECT_EQ(w.index[0], 0);
    EXPECT_EQ(w.weight[0], 1.f);
    expect_valid_weights(w, 1);
  }
}

TEST(Interp, TwoDirections) {
  DirectionSet s;
  s.dirs = {dir_from_theta_phi(0, 0), dir_from_theta_phi(deg(60), 0)};
  DirectionInterpolator in(s);
  EXPECT_TRUE(in.triangles().empty());
  const std::vector<Vec2> p = parabolic(s);
  for (int i = 0; i < 2; ++i) {
    DirWeights w = in.weights(s.dirs[i]);
    EXPECT_EQ(w.index[0], i);
    EXPECT_EQ(w.weight[0], 1.f);
  }
  // Along the segment: linear in parabolic x.
  DirWeights w = in.weights(dir_from_theta_phi(deg(30), 0));
  expect_valid_weights(w, 2);
  EXPECT_NEAR(blend(w, p).x, to_parabolic(dir_from_theta_phi(deg(30), 0)).x, 1e-6);
  // Off the line: projected onto it (phi = 90 deg projects onto the first point).
  w = in.weights(dir_from_theta_phi(deg(30), deg(90)));
  EXPECT_EQ(w.index[0], 0);
  EXPECT_EQ(w.weight[0], 1.f);
  // Beyond the far end: clamped.
  w = in.weights(dir_from_theta_phi(deg(85), 0));
  EXPECT_EQ(w.index[0], 1);
  EXPECT_EQ(w.weight[0], 1.f);
}

TEST(Interp, CollinearSet) {
  // phi = 0 and phi = 180 only: every point on the parabolic x axis, so no triangles.
  DirectionSet s;
  for (int t = 0; t <= 75; t += 15) s.dirs.push_back(dir_from_theta_phi(deg(t), 0));
  for (int t = 15; t <= 75; t += 15) s.dirs.push_back(dir_from_theta_phi(deg(t), k_pi));
  DirectionInterpolator in(s);
  EXPECT_TRUE(in.triangles().empty());
  const std::vector<Vec2> p = parabolic(s);
  for (int i = 0; i < int(s.size()); ++i) {
    DirWeights w = in.weights(s.dirs[i]);
    EXPECT_EQ(w.index[0], i);
    EXPECT_EQ(w.weight[0], 1.f);
  }
  for (double theta = -74; theta <= 74; theta += 3.7) {
    Vec3 d = dir_from_theta_phi(deg(std::fabs(theta)), theta < 0 ? k_pi : 0);
    DirWeights w = in.weights(d);
    expect_valid_weights(w, int(s.size()));
    double f = 0;
    for (int k = 0; k < 3; ++k) f += w.weight[k] * (3 * p[w.index[k]].x + 1);
    EXPECT_NEAR(f, 3 * to_parabolic(d).x + 1, 1e-5);
    // Only the two neighbours along the line carry weight.
    int nonzero = 0;
    for (float x : w.weight) nonzero += x > 0;
    EXPECT_LE(nonzero, 2);
  }
  // Off the line and beyond the ends: still valid.
  expect_valid_weights(in.weights(dir_from_theta_phi(deg(40), deg(90))), int(s.size()));
  DirWeights w = in.weights(dir_from_theta_phi(deg(89), 0));
  EXPECT_EQ(w.index[0], 5);
  EXPECT_EQ(w.weight[0], 1.f);
}

TEST(Interp, NearlyCollinearFloatLine) {
  // phi = 45 deg: float rounding puts the points ~1e-8 off one line. They must be treated as
  // collinear (no needle triangles), and still interpolate along the line.
  DirectionSet s;
  for (int t = 0; t <= 75; t += 5) s.dirs.push_back(dir_from_theta_phi(deg(t), deg(45)));
  DirectionInterpolator in(s);
  EXPECT_TRUE(in.triangles().empty());
  const std::vector<Vec2> p = parabolic(s);
  for (int i = 0; i < int(s.size()); ++i) {
    DirWeights w = in.weights(s.dirs[i]);
    EXPECT_EQ(w.index[0], i);
    EXPECT_EQ(w.weight[0], 1.f);
  }
  Vec3 d = dir_from_theta_phi(deg(32.5), deg(45));
  DirWeights w = in.weights(d);
  expect_valid_weights(w, int(s.size()));
  EXPECT_NEAR(blend(w, p).x, to_parabolic(d).x, 1e-6);
}

TEST(Interp, DuplicateDirection) {
  DirectionSet s = DirectionSet::ubo2003();
  s.dirs.push_back(s.dirs[5]);   // index 81 duplicates 5
  s.dirs.insert(s.dirs.begin(), s.dirs[30]);  // index 0 duplicates (now) 31
  DirectionInterpolator in(s);
  EXPECT_EQ(in.triangles().size(), size_t(136));
  for (const auto& t : in.triangles())
    for (int v : t) EXPECT_TRUE(v != 31 && v != 82) << "duplicate became a vertex";
  expect_valid_triangulation(s, in);
  DirWeights w = in.weights(s.dirs[82]);
  EXPECT_EQ(w.index[0], 6);  // first index wins
  EXPECT_EQ(w.weight[0], 1.f);
  w = in.weights(s.dirs[31]);
  EXPECT_EQ(w.index[0], 0);
  EXPECT_EQ(w.weight[0], 1.f);

  // Collinear fallback with duplicates, and a set of one direction repeated.
  DirectionSet c;
  c.dirs = {dir_from_theta_phi(deg(20), 0), dir_from_theta_phi(deg(20), 0), dir_from_theta_phi(deg(50), 0)};
  DirectionInterpolator ic(c);
  EXPECT_TRUE(ic.triangles().empty());
  w = ic.weights(c.dirs[1]);
  EXPECT_EQ(w.index[0], 0);
  EXPECT_EQ(w.weight[0], 1.f);
  DirectionSet r;
  r.dirs.assign(4, dir_from_theta_phi(deg(10), deg(10)));
  w = DirectionInterpolator(r).weights({0, 0, 1});
  EXPECT_EQ(w.index[0], 0);
  EXPECT_EQ(w.weight[0], 1.f);
}

TEST(Interp, DefaultConstructedIsHarmless) {
  DirectionInterpolator in;
  DirWeights w = in.weights({0, 0, 1});
  EXPECT_EQ(w.index[0], 0);
  EXPECT_EQ(w.weight[0], 1.f);
}

}  // namespace
}  // namespace btfc
