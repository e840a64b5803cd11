// DirectionInterpolator::weights() (lookup table + fallback) against weights_reference() (the
// plain search it must reproduce): the same bits for every query, on sets of every shape and on
// the queries most likely to expose a wrong table cell (vertices, edges, cell borders, and their
// float neighbours).
#include "core/interp.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <vector>

namespace btfc {
namespace {

constexpr double k_pi = 3.14159265358979323846;
double deg(double d) { return d * k_pi / 180.0; }

// Inverse of to_parabolic for the upper hemisphere (and beyond the unit disc, below it).
Vec3 from_parabolic(double x, double y) {
  const double r2 = x * x + y * y;
  return {float(2 * x / (1 + r2)), float(2 * y / (1 + r2)), float((1 - r2) / (1 + r2))};
}

// Compares weights() and weights_reference() on d and on its float neighbours in x and y (a
// few ulps either way step across any border the rounded parabolic point is near).
class Checker {
 public:
  explicit Checker(const DirectionInterpolator& in) : m_in(in) {}
  void check(const Vec3& d) {
    const DirWeights a = m_in.weights(d), b = m_in.weights_reference(d);
    m_dirs.push_back(d), m_fast_out.push_back(a);
    ++m_count;
    m_fast += m_in.fast_path_kind(d) != 0;
    if (std::memcmp(&a, &b, sizeof a) != 0 && m_fail++ < 5)
      ADD_FAILURE() << "dir (" << d.x << ", " << d.y << ", " << d.z << "): fast " << a.index[0] << ' ' << a.index[1]
                    << ' ' << a.index[2] << " / " << a.weight[0] << ' ' << a.weight[1] << ' ' << a.weight[2]
                    << ", reference " << b.index[0] << ' ' << b.index[1] << ' ' << b.index[2] << " / "
                    << b.weight[0] << ' ' << b.weight[1] << ' ' << b.weight[2];
  }
  void check_neighbours(const Vec3& d, int ulps) {
    for (int i = -ulps; i <= ulps; ++i)
      for (int j = -ulps; j <= ulps; ++j) check({step(d.x, i), step(d.y, j), d.z});
  }
  // weights_batch() over every direction checked so far, in one call (groups, a ragged end):
  // the same bits as weights() per direction.
  void check_batch() {
    std::vector<DirWeights> out(m_dirs.size());
    m_in.weights_batch(m_dirs.data(), m_dirs.size(), out.data());
    int fail = 0;
    for (size_t i = 0; i < m_dirs.size(); ++i)
      if (std::memcmp(&out[i], &m_fast_out[i], sizeof(DirWeights)) != 0 && fail++ < 5)
        ADD_FAILURE() << "weights_batch differs from weights() at query " << i;
  }
  size_t count() const { return m_count; }
  double fast_fraction() const { return double(m_fast) / double(m_count); }

 private:
  static float step(float v, int k) {
    for (; k > 0; --k) v = std::nextafter(v, std::numeric_limits<float>::infinity());
    for (; k < 0; ++k) v = std::nextafter(v, -std::numeric_limits<float>::infinity());
    return v;
  }
  const DirectionInterpolator& m_in;
  std::vector<Vec3> m_dirs;
  std::vector<DirWeights> m_fast_out;
  size_t m_count = 0, m_fast = 0;
  int m_fail = 0;
};

// At least 200k queries: random over the hemisphere and below it, the measured directions,
// points on triangle edges and vertices, and on the borders of the fine table's cells.
// Returns the fraction that took the table.
double check_set(const DirectionSet& s, uint32_t seed) {
  SCOPED_TRACE(s.name + " (" + std::to_string(s.size()) + " directions)");
  const DirectionInterpolator in(s);
  Checker c(in);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  for (int q = 0; q < 200000; ++q) c.check(dir_from_theta_phi(deg(90) * u(rng), 2 * k_pi * u(rng)));
  for (int q = 0; q < 20000; ++q) c.check(dir_from_theta_phi(deg(90 + 90 * u(rng)), 2 * k_pi * u(rng)));
  for (const Vec3& d : s.dirs) c.check_neighbours(d, 3);
  std::vector<Vec2> p;
  for (const Vec3& d : s.dirs) p.push_back(to_parabolic(d));
  for (const auto& t : in.triangles())
    for (int k = 0; k < 3; ++k) {
      const Vec2 &a = p[size_t(t[k])], &b = p[size_t(t[(k + 1) % 3])];
      for (double w : {0.5, u(rng), u(rng) * 1e-6, 1 - u(rng) * 1e-6})
        c.check_neighbours(from_parabolic(a.x + w * (b.x - a.x), a.y + w * (b.y - a.y)), 2);
    }
  const DirectionInterpolator::FineGrid g = in.fine_grid();
  for (int q = 0; g.n > 0 && q < 2000; ++q) {
    // A point on a vertical or horizontal cell border, or on a cell corner.
    const double i = double(int(rng() % uint32_t(g.n + 1))), j = double(int(rng() % uint32_t(g.n + 1)));
    const double x = g.lo.x + i * g.cell, y = g.lo.y + j * g.cell;
    const int kind = q % 3;
    c.check_neighbours(from_parabolic(kind == 1 ? g.lo.x + g.n * g.cell * u(rng) : x,
                                      kind == 2 ? g.lo.y + g.n * g.cell * u(rng) : y),
                       2);
  }
  for (const Vec3& d : {Vec3{0, 0, 1}, Vec3{0, 0, -1}, Vec3{0, 0, 0}, Vec3{1, 0, 0}, Vec3{1e30f, 1e30f, 1},
                        Vec3{std::nanf(""), 0, 1}, Vec3{std::numeric_limits<float>::infinity(), 0, 1}})
    c.check(d);
  c.check_batch();
  EXPECT_GE(c.count(), size_t(200000));
  return c.fast_fraction();
}

DirectionSet random_set(int n, uint32_t seed, double max_theta_deg) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  DirectionSet s;
  s.name = "random" + std::to_string(n);
  for (int i = 0; i < n; ++i) s.dirs.push_back(dir_from_theta_phi(deg(max_theta_deg) * u(rng), 2 * k_pi * u(rng)));
  return s;
}

TEST(InterpFast, MatchesReferenceUbo) {
  // UBO2003 is also the UTIA sampling (same 81 directions).
  const double f2003 = check_set(DirectionSet::ubo2003(), 1);
  const double f2014 = check_set(DirectionSet::ubo2014(), 2);
  // The table must actually serve most queries, or the fast path silently does nothing.
  EXPECT_GT(f2003, 0.8);
  EXPECT_GT(f2014, 0.8);
}

TEST(InterpFast, MatchesReferenceRandomSets) {
  check_set(random_set(30, 3, 80), 3);
  check_set(random_set(30, 4, 40), 4);
  check_set(random_set(30, 5, 120), 5);  // some directions below the horizon
  check_set(random_set(200, 6, 89), 6);
}

TEST(InterpFast, MatchesReferenceDegenerateSets) {
  DirectionSet one;
  one.dirs = {dir_from_theta_phi(deg(30), deg(40))};
  check_set(one, 7);
  DirectionSet two;
  two.dirs = {dir_from_theta_phi(deg(30), deg(40)), dir_from_theta_phi(deg(60), deg(200))};
  check_set(two, 8);
  DirectionSet line;  // collinear in parabolic space: no triangles
  for (int t = 0; t <= 75; t += 15) line.dirs.push_back(dir_from_theta_phi(deg(t), deg(30)));
  check_set(line, 9);
}

TEST(InterpFast, MatchesReferenceDuplicates) {
  DirectionSet s = DirectionSet::ubo2003();
  s.dirs.push_back(s.dirs[5]);
  s.dirs.insert(s.dirs.begin(), s.dirs[30]);
  s.dirs.push_back(s.dirs[80]);
  check_set(s, 10);
  DirectionSet r;  // one direction repeated
  r.dirs.assign(4, dir_from_theta_phi(deg(10), deg(10)));
  check_set(r, 11);
}

TEST(InterpFast, MatchesReferenceLattice) {
  // Exactly cocircular points and axis-aligned edges: triangle edges along cell borders.
  DirectionSet s;
  for (int i = -3; i <= 3; ++i)
    for (int j = -3; j <= 3; ++j) s.dirs.push_back(from_parabolic(0.2 * i, 0.2 * j));
  check_set(s, 12);
}

}  // namespace
}  // namespace btfc
