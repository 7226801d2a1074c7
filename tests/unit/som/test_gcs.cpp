#include <vmap/som/gcs.hpp>

#include "support/shared_data.hpp"

#include <doctest/doctest.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <vector>

// Every member of each shipped instantiation compiles (STYLE.md, Sophus pattern).
template class vmap::GrowingCellStructures<float>;
template class vmap::GrowingCellStructures<double, 2>;
template class vmap::GrowingCellStructures<double, 2, 1>;
template class vmap::GrowingCellStructures<double, 3, 3, vmap::ManhattanDistance>;

namespace {

using Gcs2 = vmap::GrowingCellStructures<double, 2>;
using P = Gcs2::Vector;

// Uniform samples on two unit squares with an empty gap: [0,1]x[0,1] and [2,3]x[0,1].
std::vector<P> two_squares(std::size_t n, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<P> out;
  for (std::size_t i = 0; i < n; ++i) {
    const double x = u(rng) + (i % 2 ? 2.0 : 0.0);
    out.emplace_back(x, u(rng));
  }
  return out;
}

template <class G>
void check_by_observer(G& g, const std::vector<typename G::Vector>& data, std::size_t& inserted, std::size_t& removed) {
  g.train(data, [&](vmap::GcsEvent e, std::size_t) {
    (e == vmap::GcsEvent::inserted ? inserted : removed) += 1;
    REQUIRE_NOTHROW(g.check_topology());
  });
}

}  // namespace

TEST_CASE("GCS options are validated") {
  auto bad = [](vmap::GcsOptions o) { CHECK_THROWS_AS(Gcs2{o}, vmap::Error); };
  bad({.lambda = 0});
  bad({.eps_b = 0.0});
  bad({.eps_b = 1.5});
  bad({.eps_n = 0.0});
  bad({.eps_n = -0.1});
  bad({.alpha = 1.0});
  bad({.alpha = 0.0});
  bad({.eta = -1.0});
  bad({.max_cells = 2});  // fewer than one 2-simplex
  bad({.max_epochs = 0});
  CHECK_NOTHROW(Gcs2{vmap::GcsOptions{.eps_b = 1.0, .eps_n = 1.0}});
}

TEST_CASE("GCS rejects bad training input") {
  Gcs2 g;
  CHECK_THROWS_AS(g.train({}), vmap::Error);
  CHECK_THROWS_AS(g.train({P(0, 0), P(1, 1)}), vmap::Error);  // fewer than K + 1
  CHECK_THROWS_AS((void)g.bmu(P(0, 0)), vmap::Error);               // not trained
  vmap::GcsXf f;
  std::vector<Eigen::VectorXf> mixed{Eigen::VectorXf::Zero(3), Eigen::VectorXf::Ones(3), Eigen::VectorXf::Ones(4)};
  CHECK_THROWS_WITH_AS(f.train(mixed), doctest::Contains("dimension 4"), vmap::Error);
  std::vector<Eigen::VectorXf> ok{Eigen::VectorXf::Zero(3), Eigen::VectorXf::Ones(3), Eigen::VectorXf::Constant(3, 2.f)};
  f.train(ok);
  CHECK_THROWS_AS((void)f.bmu(Eigen::VectorXf::Zero(5)), vmap::Error);  // Dim mismatch at query time
  CHECK_THROWS_AS(f.train(mixed), vmap::Error);
  CHECK(f.dimension() == 3);  // a rejected training set leaves the network as it was
  CHECK_NOTHROW(f.check_topology());
  Eigen::VectorXf nan = Eigen::VectorXf::Zero(3);
  nan[1] = std::nanf("");
  CHECK_THROWS_AS((void)f.bmu(nan), vmap::Error);
}

TEST_CASE("GCS on two squares: cells cover the support, none stay in the gap, invariants hold") {
  const auto data = two_squares(1000, 3);
  Gcs2 g({.eps_b = 0.06, .eps_n = 0.006, .alpha = 0.005, .lambda = 100, .eta = 0.02, .max_cells = 40, .seed = 5});
  std::size_t inserted = 0, removed = 0;
  check_by_observer(g, data, inserted, removed);
  CHECK(inserted >= 37);
  CHECK(removed > 0);  // cells that fell into the gap were removed
  CHECK(g.size() == 40);
  REQUIRE_NOTHROW(g.check_topology());
  std::size_t left = 0, right = 0, in_gap = 0;
  for (const auto& w : g.weights()) {
    if (w.x() > 1.15 && w.x() < 1.85) ++in_gap;
    (w.x() < 1.5 ? left : right) += 1;
    CHECK(w.y() > -0.1);
    CHECK(w.y() < 1.1);
  }
  CHECK(in_gap == 0);
  CHECK(left >= 14);  // both squares get a fair share of the 40 cells
  CHECK(right >= 14);
  // every sample has a cell near it: 40 cells on area 2 are ~0.22 apart
  double worst = 0.0;
  for (const auto& x : data) worst = std::max(worst, g.bmu(x).distance);
  CHECK(worst < 0.35);
}

TEST_CASE("GCS without removal grows to max_cells and is deterministic for a seed") {
  std::mt19937 rng(9);
  std::normal_distribution<double> n(0.0, 1.0);
  std::vector<P> data;
  for (int i = 0; i < 500; ++i) data.emplace_back(n(rng), 0.3 * n(rng));
  const vmap::GcsOptions o{.lambda = 50, .max_cells = 30, .seed = 11};
  Gcs2 a(o), b(o), c(vmap::GcsOptions{.lambda = 50, .max_cells = 30, .seed = 12});
  std::size_t ins = 0, rem = 0;
  check_by_observer(a, data, ins, rem);
  b.train(data);
  c.train(data);
  CHECK(ins == 27);
  CHECK(rem == 0);
  REQUIRE(a.size() == 30);
  REQUIRE(b.size() == 30);
  CHECK(a.simplices() == b.simplices());
  bool same_as_other_seed = c.size() == a.size();
  for (std::size_t i = 0; i < a.size(); ++i) {
    CHECK(a.weights()[i] == b.weights()[i]);
    CHECK(a.counters()[i] == b.counters()[i]);
    if (same_as_other_seed && !(a.weights()[i] == c.weights()[i])) same_as_other_seed = false;
  }
  CHECK_FALSE(same_as_other_seed);
  // Euler-type count of a triangulated disc built by edge splits: each insertion
  // splits every triangle on the edge it cuts, so #triangles >= 1 + #insertions.
  CHECK(a.simplices().size() >= 28);
  // every edge lies in a triangle and cells have at least two neighbours
  for (std::size_t c2 = 0; c2 < a.size(); ++c2) CHECK(a.neighbours(c2).size() >= 2);
}

TEST_CASE("GCS k_nearest and bmu agree; other K and metrics keep their invariants") {
  const auto data = two_squares(300, 4);
  Gcs2 g({.lambda = 30, .max_cells = 20, .seed = 2});
  g.train(data);
  const P q(0.5, 0.5);
  const auto k = g.k_nearest(q, 5);
  REQUIRE(k.size() == 5);
  CHECK(k.front().cell == g.bmu(q).cell);
  for (std::size_t i = 1; i < k.size(); ++i) CHECK(k[i - 1].distance <= k[i].distance);
  CHECK(g.k_nearest(q, 1000).size() == g.size());

  vmap::GrowingCellStructures<double, 2, 1> chain({.lambda = 30, .eta = 0.02, .max_cells = 15, .seed = 2});
  std::size_t i1 = 0, r1 = 0;
  check_by_observer(chain, data, i1, r1);
  for (const auto& s : chain.simplices()) CHECK(s.size() == 2);
  for (std::size_t c = 0; c < chain.size(); ++c) CHECK(chain.neighbours(c).size() <= 2 * chain.size());

  std::vector<vmap::GrowingCellStructures<double, 3, 3, vmap::ManhattanDistance>::Vector> d3;
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> u(0, 1);
  for (int i = 0; i < 400; ++i) d3.emplace_back(u(rng), u(rng), u(rng));
  vmap::GrowingCellStructures<double, 3, 3, vmap::ManhattanDistance> tet({.lambda = 40, .eta = 0.01, .max_cells = 25, .seed = 3});
  std::size_t i3 = 0, r3 = 0;
  check_by_observer(tet, d3, i3, r3);
  CHECK(tet.size() == 25);
  CHECK(tet.bmu(d3[0]).distance == doctest::Approx(tet.metric()(d3[0], tet.weights()[tet.bmu(d3[0]).cell])));
}

TEST_CASE("an untrained GCS saves and loads") {
  const vmap::Gcs2d fixed;
  const auto f = vmap::Gcs2d::deserialize(fixed.serialize());
  CHECK(f.size() == 0);
  const vmap::GcsXf dynamic;
  const auto d = vmap::GcsXf::deserialize(dynamic.serialize());
  CHECK(d.size() == 0);
}

TEST_CASE("GCS save and load round-trip; corrupt files are errors") {
  const auto dir = vmap::test::scratch_dir("som_gcs");
  std::vector<Eigen::VectorXf> data;
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(0, 1);
  for (int i = 0; i < 200; ++i) data.push_back(Eigen::VectorXf::NullaryExpr(6, [&] { return u(rng); }));
  vmap::GcsXf g({.lambda = 20, .max_cells = 25, .seed = 4});
  g.train(data);
  const auto path = dir / "map.gcs";
  g.save(path);
  CHECK_FALSE(std::filesystem::exists(dir / "map.gcs.vmap-tmp"));
  const auto h = vmap::GcsXf::load(path);
  REQUIRE(h.size() == g.size());
  CHECK(h.dimension() == 6);
  CHECK(h.simplices() == g.simplices());
  CHECK(h.counters() == g.counters());
  for (std::size_t i = 0; i < g.size(); ++i) CHECK(h.weights()[i] == g.weights()[i]);
  CHECK(h.options().lambda == 20);
  CHECK(h.bmu(data[7]).cell == g.bmu(data[7]).cell);

  const std::string bytes = g.serialize();
  // every truncation is an error, never a crash
  for (std::size_t cut = 0; cut < bytes.size(); cut += 7)
    CHECK_THROWS_AS(vmap::GcsXf::deserialize(bytes.substr(0, cut)), vmap::Error);
  CHECK_THROWS_AS(vmap::GcsXf::deserialize(bytes + "x"), vmap::Error);
  auto patched = [&](std::size_t at, auto value) {
    std::string b = bytes;
    std::memcpy(b.data() + at, &value, sizeof(value));
    return b;
  };
  CHECK_THROWS_WITH_AS(vmap::GcsXf::deserialize("NOTAGCS!" + bytes.substr(8)), doctest::Contains("magic"), vmap::Error);
  CHECK_THROWS_WITH_AS(vmap::GcsXf::deserialize(patched(8, std::uint32_t{99})), doctest::Contains("version"), vmap::Error);
  // header: magic 8, version 4, endian 4, scalar 4, K 4, dim 8, options 64, cells 8, simplices 8
  const std::size_t cells_at = 8 + 4 + 4 + 4 + 4 + 8 + 64;
  CHECK_THROWS_AS(vmap::GcsXf::deserialize(patched(cells_at, std::uint64_t{1} << 60)), vmap::Error);  // hostile count
  CHECK_THROWS_AS(vmap::GcsXf::deserialize(patched(cells_at + 8, std::uint64_t{1} << 60)), vmap::Error);
  CHECK_THROWS_AS(vmap::GcsXf::deserialize(patched(8 + 4 + 4 + 4 + 4, std::uint64_t{1} << 62)), vmap::Error);  // dim
  CHECK_THROWS_AS(vmap::GcsXf::deserialize(patched(bytes.size() - 8, std::uint64_t{999})), vmap::Error);  // simplex id
  CHECK_THROWS_AS(vmap::GcsXf::deserialize(patched(8 + 4 + 4 + 4 + 4 + 8 + 24, std::uint64_t{0})), vmap::Error);  // lambda 0
  // another K, scalar or fixed dimension
  CHECK_THROWS_WITH_AS((vmap::GrowingCellStructures<float, Eigen::Dynamic, 1>::deserialize(bytes)),
                       doctest::Contains("K = 1"), vmap::Error);
  CHECK_THROWS_AS((vmap::GrowingCellStructures<double>::deserialize(bytes)), vmap::Error);
  CHECK_THROWS_WITH_AS((vmap::GrowingCellStructures<float, 2>::deserialize(bytes)), doctest::Contains("dimension 6"),
                       vmap::Error);
  CHECK_THROWS_AS(vmap::GcsXf::load(dir / "missing.gcs"), vmap::Error);
}
