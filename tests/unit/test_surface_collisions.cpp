// The collision guard's detection (contact/surface_collisions.hpp) against a
// brute force: over a sequence of steps in which a sheet folds onto itself
// (self-contact), a second sheet falls through it (two bodies) and through a
// third one that never moves (static), and the moving ones jitter,
// SurfaceCollisionFinder::Find must report exactly the pairs that CCD reports
// when every vertex-triangle and edge-edge pair is tested, and count the same
// pairs close at the start. The steps alternate between small motions (the
// self-contact and static candidates are reused) and large ones (they are
// rebuilt), and the test checks that both happen. Cached pairs skip CCD when a
// distance bound keeps them apart: a wrong bound misses pairs here.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <set>
#include <vector>

#include "contact/held_surface.hpp"
#include "contact/surface_collisions.hpp"

namespace softbody {
namespace {

constexpr int kSide = 9;          // vertices per side of a sheet
constexpr double kSpacing = 0.1;  // m between neighbouring vertices
constexpr int kSteps = 60;

// A kSide x kSide sheet in the plane z = 0 as body `body`, appended to s.
void AddSheet(ContactSurface *s, int32_t body) {
  const int32_t first = s->num_vertices();
  for (int i = 0; i < kSide * kSide; ++i) {
    s->global.push_back(first + i);
    s->natural.push_back(first + i);
    s->body.push_back(body);
  }
  std::set<std::array<int32_t, 2>> edges;
  for (int j = 0; j + 1 < kSide; ++j)
    for (int i = 0; i + 1 < kSide; ++i) {
      const int32_t a = first + i + kSide * j, b = a + 1, c = a + kSide, d = c + 1;
      for (const auto &t : {std::array<int32_t, 3>{a, b, d}, std::array<int32_t, 3>{a, d, c}}) {
        s->triangle_id.push_back(static_cast<int32_t>(s->triangles.size()));
        s->triangles.push_back(t);
        for (int k = 0; k < 3; ++k)
          edges.insert({std::min(t[k], t[(k + 1) % 3]), std::max(t[k], t[(k + 1) % 3])});
      }
    }
  s->edges.insert(s->edges.end(), edges.begin(), edges.end());
  s->vertex_start.push_back(s->num_vertices());
  s->triangle_start.push_back(static_cast<int32_t>(s->triangles.size()));
  s->edge_start.push_back(static_cast<int32_t>(s->edges.size()));
}

// Step k's positions: sheet 0 folds about the line x = 0.45 (its far half
// turns by up to 190 degrees, through its near half), sheet 1 falls through
// it and through sheet 2, which stays at z = -0.25; every vertex of sheets 0
// and 1 jitters, by 1e-3 m on even steps and 0.03 m on odd ones.
std::vector<Point> Positions(const ContactSurface &s, int k, std::mt19937 &rng) {
  const double amplitude = k % 2 ? 0.03 : 1e-3;
  std::uniform_real_distribution<double> jitter(-amplitude, amplitude);
  const double angle = M_PI * 190.0 / 180.0 * k / kSteps;
  std::vector<Point> x(s.num_vertices());
  for (int32_t v = 0; v < s.num_vertices(); ++v) {
    const int local = v - s.vertex_start[s.body[v]];
    const double u = kSpacing * (local % kSide), w = kSpacing * (local / kSide);
    if (s.body[v] == 0) {
      const double r = u - 0.45;
      x[v] = r <= 0 ? Point(u, w, 0) : Point(0.45 + r * std::cos(angle), w, r * std::sin(angle));
    } else if (s.body[v] == 1) {
      x[v] = Point(0.2 + 0.5 * u, 0.1 + 0.5 * w, 0.5 - 1.0 * k / kSteps);
    } else {
      x[v] = Point(0.1 + 0.7 * u, 0.05 + 0.7 * w, -0.25);
      continue;
    }
    x[v] += Point(jitter(rng), jitter(rng), jitter(rng));
  }
  return x;
}

using PairSet = std::set<std::array<int32_t, 4>>;

// Every vertex-triangle and edge-edge pair (within a body: sharing no vertex)
// through CCD.
PairSet BruteForce(const ContactSurface &s, const std::vector<Point> &start,
                   const std::vector<Point> &end, const CcdTolerance &tolerance, int64_t *close) {
  PairSet found;
  auto test = [&](const std::array<int32_t, 4> &v, bool vertex_triangle) {
    MovingPair pair;
    for (int k = 0; k < 4; ++k) pair.start[k] = start[v[k]], pair.end[k] = end[v[k]];
    const Approach a =
        vertex_triangle ? PointTriangleCcd(pair, tolerance) : EdgeEdgeCcd(pair, tolerance);
    if (a == Approach::kCollides) found.insert(v);
    if (a == Approach::kCloseAtStart) ++*close;
  };
  for (int32_t v = 0; v < s.num_vertices(); ++v)
    for (const auto &t : s.triangles)
      if (v != t[0] && v != t[1] && v != t[2]) test({v, t[0], t[1], t[2]}, true);
  for (size_t e = 0; e < s.edges.size(); ++e)
    for (size_t f = e + 1; f < s.edges.size(); ++f) {
      const auto &a = s.edges[e], &b = s.edges[f];
      if (a[0] != b[0] && a[0] != b[1] && a[1] != b[0] && a[1] != b[1])
        test({a[0], a[1], b[0], b[1]}, false);
    }
  return found;
}

// The query the tests run: separation 1 cm, band 1 mm, self-contact.
CollisionQuery Query(const ContactSurface &s, const std::vector<Point> &start,
                     const std::vector<Point> &end, const std::vector<char> &moving) {
  CollisionQuery q;
  q.surface = &s;
  q.start = &start;
  q.end = &end;
  q.moving = &moving;
  q.tolerance.separation = 0.01;
  q.tolerance.band = 0.001;
  q.self_contact = true;
  return q;
}

// Step k: the finder reports exactly the brute force's pairs and close
// count; returns the brute force's pairs and the finder's count.
PairSet ExpectBruteForce(const SurfaceCollisionFinder &finder, const CollisionQuery &q, int k,
                         CollisionCount *count) {
  PairSet found;
  for (const SurfaceCollision &c : finder.Find(q, count)) found.insert(c.vertices);
  int64_t close = 0;
  const PairSet expected = BruteForce(*q.surface, *q.start, *q.end, q.tolerance, &close);
  EXPECT_EQ(found, expected) << "step " << k;
  EXPECT_EQ(count->close, close) << "step " << k;
  return expected;
}

struct Totals {
  int64_t rebuilds = 0, static_rebuilds = 0, reported = 0, reported_static = 0;
};

// Runs the finder over kSteps steps of positions(k) (sheets 0 and 1 moving,
// sheet 2 static) and checks each step against the brute force.
template <typename Positions>
Totals CheckSteps(Positions positions) {
  ContactSurface s;
  for (int32_t body = 0; body < 3; ++body) AddSheet(&s, body);
  std::vector<Point> start = positions(s, 0), end = start;
  std::vector<char> moving(s.num_vertices(), 1);
  for (int32_t v = s.vertex_start[2]; v < s.num_vertices(); ++v) moving[v] = 0;
  const CollisionQuery q = Query(s, start, end, moving);
  SurfaceCollisionFinder finder;
  finder.Setup(q);
  Totals totals;
  for (int k = 1; k <= kSteps; ++k) {
    end = positions(s, k);
    CollisionCount count;
    const PairSet expected = ExpectBruteForce(finder, q, k, &count);
    totals.rebuilds += count.rebuilds;
    totals.static_rebuilds += count.static_rebuilds;
    totals.reported += static_cast<int64_t>(expected.size());
    for (const auto &pair : expected)
      totals.reported_static +=
          std::any_of(pair.begin(), pair.end(), [&](int32_t v) { return !moving[v]; });
    start = end;
  }
  return totals;
}

TEST(SurfaceCollisionFinder, FindsWhatTestingEveryPairFinds) {
  std::mt19937 rng(11);
  const Totals totals =
      CheckSteps([&](const ContactSurface &s, int k) { return Positions(s, k, rng); });
  // Both bodies fold or fall, so pairs collide, also with the static sheet;
  // candidates are reused after the small motions and rebuilt after the large ones.
  EXPECT_GT(totals.reported, 20);
  EXPECT_GT(totals.reported_static, 5);
  EXPECT_GT(totals.rebuilds, kSteps / 2);
  EXPECT_LT(totals.rebuilds, 2 * kSteps);
  EXPECT_GT(totals.static_rebuilds, kSteps / 4);
}

// Sheet 1 sinks slowly through the static sheet 2 (sheet 0 stays away): the
// static candidates are kept over the small steps and still give every pair.
TEST(SurfaceCollisionFinder, KeepsStaticCandidatesOverSmallSteps) {
  std::mt19937 rng(12);
  const Totals totals = CheckSteps([&](const ContactSurface &s, int k) {
    std::vector<Point> x = Positions(s, 0, rng);
    for (int32_t v = s.vertex_start[1]; v < s.vertex_start[2]; ++v)
      x[v][2] += -0.7 - 0.1 * k / kSteps;  // from z = -0.2 to -0.3, through z = -0.25
    return x;
  });
  EXPECT_GT(totals.reported_static, 5);
  EXPECT_GT(totals.static_rebuilds, 0);
  EXPECT_LT(totals.static_rebuilds, kSteps / 2);
}

// A rank's part of the surfaces, as its halo changes from step to step
// (held_surface.hpp): sheet 0's near columns are its own, sheet 2 is static,
// and the halo brings rows of sheets 0 and 1, a vertex new to it with the
// primitives keyed at it (as the guard's exchange sends them), the rows
// moving by one per step, so that primitives are kept across steps, held or
// pending. The held surface keeps the whole surface's order and exactly the
// static primitives, those at an own vertex and the halo's whose vertices are
// all held; the finder, renumbered on each new part (its static grids kept),
// reports exactly the pairs that CCD reports among the held primitives.
TEST(SurfaceCollisionFinder, FindsEveryPairOnARenumberedHeldPart) {
  ContactSurface whole;
  for (int32_t body = 0; body < 3; ++body) AddSheet(&whole, body);
  const int32_t n = whole.num_vertices();
  std::vector<char> moving(n, 1), own(n, 0);
  for (int32_t v = whole.vertex_start[2]; v < n; ++v) moving[v] = 0;
  for (int32_t v = 0; v < whole.vertex_start[1]; ++v) own[v] = v % kSide < 3;
  std::mt19937 rng(13);
  // Step k's halo: rows of sheets 0 and 1 that move along with k.
  auto halo = [&](int k) {
    std::vector<char> in(n, 0);
    for (int32_t v = 0; v < whole.vertex_start[2]; ++v)
      in[v] = !own[v] && std::abs((v % (kSide * kSide)) / kSide - k % kSide) <= 2;
    return in;
  };
  ContactSurface held;
  std::vector<SurfacePrimitive> pending;
  AssembleHeldSurface(whole, own, moving, {}, {}, &pending, &held);
  std::vector<char> before_in(n, 0);  // the last step's halo
  std::vector<Point> start, end;
  std::vector<char> held_moving;
  auto localise = [&](const std::vector<char> &a) {
    std::vector<char> b(held.num_vertices());
    for (int32_t v = 0; v < held.num_vertices(); ++v) b[v] = a[held.global[v]];
    return b;
  };
  auto positions = [&](const std::vector<Point> &x) {
    std::vector<Point> y(held.num_vertices());
    for (int32_t v = 0; v < held.num_vertices(); ++v) y[v] = x[held.global[v]];
    return y;
  };
  std::vector<Point> x0 = Positions(whole, 0, rng);
  start = end = positions(x0);
  held_moving = localise(moving);
  const CollisionQuery q = Query(held, start, end, held_moving);
  SurfaceCollisionFinder finder;
  finder.Setup(q);
  int64_t reported = 0;
  for (int k = 1; k <= kSteps; ++k) {
    const std::vector<char> in = halo(k);
    std::vector<SurfaceVertex> received;
    for (int32_t v = 0; v < n; ++v)
      if (in[v]) received.push_back({v, whole.natural[v], whole.body[v]});
    std::vector<SurfacePrimitive> primitives;
    for (size_t t = 0; t < whole.triangles.size(); ++t) {
      const auto &w = whole.triangles[t];
      const int32_t key = *std::min_element(w.begin(), w.end());
      if (in[key] && !before_in[key])
        primitives.push_back({static_cast<int32_t>(t), {w[0], w[1], w[2]}});
    }
    for (const auto &e : whole.edges)
      if (in[e[0]] && !before_in[e[0]])
        primitives.push_back({kNoSurfaceVertex, {e[0], e[1], kNoSurfaceVertex}});
    before_in = in;
    const ContactSurface before = held;
    AssembleHeldSurface(before, localise(own), localise(moving), received, primitives, &pending,
                        &held);
    // What must be held: the static and own vertices, the vertices of the
    // primitives at an own vertex, the halo's; the primitives whose vertices
    // are all static or one own, and the halo's whose vertices are all held.
    std::vector<char> kept(n, 0);
    for (int32_t v = 0; v < n; ++v) kept[v] = !moving[v] || own[v] || in[v];
    auto at_own = [&](const auto &w) {
      return std::any_of(w.begin(), w.end(), [&](int32_t v) { return own[v]; });
    };
    for (const auto &w : whole.triangles)
      if (at_own(w))
        for (const int32_t v : w) kept[v] = 1;
    for (const auto &e : whole.edges)
      if (at_own(e)) kept[e[0]] = kept[e[1]] = 1;
    std::vector<int32_t> expected_vertices, expected_triangles;
    for (int32_t v = 0; v < n; ++v)
      if (kept[v]) expected_vertices.push_back(v);
    EXPECT_EQ(held.global, expected_vertices) << "step " << k;
    auto wanted = [&](const auto &w) {
      const bool all_static =
          std::none_of(w.begin(), w.end(), [&](int32_t v) { return moving[v]; });
      const bool all_held = std::all_of(w.begin(), w.end(), [&](int32_t v) { return kept[v]; });
      return all_static || at_own(w) || (in[*std::min_element(w.begin(), w.end())] && all_held);
    };
    for (size_t t = 0; t < whole.triangles.size(); ++t)
      if (wanted(whole.triangles[t])) expected_triangles.push_back(static_cast<int32_t>(t));
    EXPECT_EQ(held.triangle_id, expected_triangles) << "step " << k;
    for (size_t t = 0; t < held.triangles.size(); ++t)
      for (int c = 0; c < 3; ++c)
        EXPECT_EQ(held.global[held.triangles[t][c]], whole.triangles[held.triangle_id[t]][c]);
    size_t expected_edges = 0;
    for (const auto &e : whole.edges) expected_edges += wanted(e);
    EXPECT_EQ(held.edges.size(), expected_edges) << "step " << k;
    // Detection on the held part, renumbered.
    const std::vector<Point> x1 = Positions(whole, k, rng);
    start = positions(x0);
    end = positions(x1);
    held_moving = localise(moving);
    finder.Renumber(q);
    CollisionCount count;
    reported += static_cast<int64_t>(ExpectBruteForce(finder, q, k, &count).size());
    x0 = x1;
  }
  EXPECT_GT(reported, 10);
}

}  // namespace
}  // namespace softbody
