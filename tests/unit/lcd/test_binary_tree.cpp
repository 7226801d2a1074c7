#include <vmap/lcd/binary_tree.hpp>

#include "support/shared_data.hpp"

#include <doctest/doctest.h>

#include <opencv2/core.hpp>

#include <cstddef>
#include <string>
#include <thread>
#include <vector>

using vmap::BinaryClassifiedTree;
using vmap::LabelVector;

// Sophus-style explicit instantiation: every member compiles for the shipped id types.
template class vmap::BinaryClassifiedTree<std::size_t>;
template class vmap::BinaryClassifiedTree<int>;

namespace {

// Leaves of a depth-2 tree: 00 -> {1}, 01 -> {2}, 10 -> {3}, 11 -> {4, 5}.
BinaryClassifiedTree<int> small_tree() {
  BinaryClassifiedTree<int> t(2);
  t.insert({0, 0}, 1);
  t.insert({0, 1}, 2);
  t.insert({1, 0}, 3);
  t.insert({1, 1}, 4);
  t.insert({1, 1}, 5);
  return t;
}

using Ids = std::vector<int>;

}  // namespace

TEST_CASE("tree: the query's leaf, then backtracking one level at a time") {
  const auto t = small_tree();
  CHECK(t.size() == 5);
  CHECK(t.depth() == 2);
  CHECK(t.candidates({1, 1}, 0) == Ids{4, 5});
  CHECK(t.candidates({1, 1}, 2) == Ids{4, 5});
  CHECK(t.candidates({1, 1}, 3) == Ids{4, 5, 3});        // parent "1": sibling leaf 10 added
  CHECK(t.candidates({1, 1}, 4) == Ids{4, 5, 3, 1, 2});  // root: the 0-subtree, 0-branch first
  CHECK(t.candidates({0, 0}, 1) == Ids{1});
  CHECK(t.candidates({0, 0}, 2) == Ids{1, 2});
  CHECK(t.candidates({0, 0}, 3) == Ids{1, 2, 3, 4, 5});
  CHECK(t.candidates({0, 1}, 100) == Ids{2, 1, 3, 4, 5});  // m larger than the tree: everything
}

TEST_CASE("tree: a query whose leaf is empty backtracks from it") {
  BinaryClassifiedTree<int> t(3);
  t.insert({1, 1, 1}, 7);
  t.insert({0, 0, 0}, 8);
  CHECK(t.candidates({1, 1, 0}, 0).empty());    // own leaf is empty
  CHECK(t.candidates({1, 1, 0}, 1) == Ids{7});  // parent 11 holds 7
  CHECK(t.candidates({1, 0, 0}, 1) == Ids{7});  // grandparent 1 holds 7
  CHECK(t.candidates({1, 0, 0}, 2) == Ids{7, 8});
}

TEST_CASE("tree: empty tree, depth 0 and erase") {
  BinaryClassifiedTree<int> empty(4);
  CHECK(empty.empty());
  CHECK(empty.candidates({0, 1, 0, 1}, 0).empty());
  CHECK(empty.candidates({0, 1, 0, 1}, 10).empty());

  BinaryClassifiedTree<int> flat(0);  // no label kept: one leaf, brute force
  flat.insert({}, 3);
  flat.insert({}, 1);
  CHECK(flat.candidates({}, 0) == Ids{3, 1});

  auto t = small_tree();
  CHECK(t.erase(5));
  CHECK_FALSE(t.erase(5));
  CHECK_FALSE(t.contains(5));
  CHECK(t.size() == 4);
  CHECK(t.candidates({1, 1}, 0) == Ids{4});
  CHECK(t.erase(4));
  CHECK(t.candidates({1, 1}, 0).empty());       // emptied leaf
  CHECK(t.candidates({1, 1}, 1) == Ids{3});     // skipped on the way up
  t.insert({1, 1}, 4);                          // the emptied node is reused
  CHECK(t.candidates({1, 1}, 0) == Ids{4});
  t.clear();
  CHECK(t.empty());
  CHECK(t.candidates({1, 1}, 5).empty());
}

TEST_CASE("tree: bad input is an Error") {
  auto t = small_tree();
  CHECK_THROWS_AS(t.insert({1, 0, 1}, 9), vmap::Error);  // wrong length
  CHECK_THROWS_AS(t.insert({1}, 9), vmap::Error);
  CHECK_THROWS_AS(t.insert({1, 2}, 9), vmap::Error);  // not 0/1
  CHECK_THROWS_AS(t.insert({1, 0}, 3), vmap::Error);  // id already present
  CHECK_THROWS_AS((void)t.candidates({1}, 1), vmap::Error);
  CHECK_THROWS_WITH_AS((void)t.candidates({0, 0, 0}, 1), doctest::Contains("length 3"), vmap::Error);
  CHECK_THROWS_AS(BinaryClassifiedTree<int>(BinaryClassifiedTree<int>::max_depth + 1), vmap::Error);
  CHECK(t.size() == 5);  // failed inserts left it unchanged
}

TEST_CASE("tree: save/load round trip answers every query identically") {
  const auto t = small_tree();
  const auto dir = vmap::test::scratch_dir("lcd_tree");
  t.save(dir / "tree.txt");
  const auto u = BinaryClassifiedTree<int>::load(dir / "tree.txt");
  CHECK(u.size() == t.size());
  CHECK(u.depth() == t.depth());
  for (const LabelVector& v : {LabelVector{0, 0}, LabelVector{0, 1}, LabelVector{1, 0}, LabelVector{1, 1}})
    for (std::size_t m = 0; m <= 6; ++m) CHECK(u.candidates(v, m) == t.candidates(v, m));
  CHECK(u.to_text() == t.to_text());

  BinaryClassifiedTree<int> flat(0);
  flat.insert({}, 2);
  CHECK(BinaryClassifiedTree<int>::from_text(flat.to_text()).candidates({}, 0) == Ids{2});
}

TEST_CASE("tree: corrupt or hostile files are an Error") {
  const std::string good = small_tree().to_text();
  using T = BinaryClassifiedTree<int>;
  CHECK_NOTHROW((void)T::from_text(good));
  CHECK_THROWS_AS((void)T::from_text(""), vmap::Error);
  CHECK_THROWS_AS((void)T::from_text("something else\ndepth 2\nids 0\n"), vmap::Error);
  CHECK_THROWS_AS((void)T::from_text(good.substr(0, good.size() - 4)), vmap::Error);  // truncated line
  const std::string head = "vmap-binary-classified-tree 1\ndepth 2\n";
  CHECK_THROWS_WITH_AS((void)T::from_text(head + "ids 999999999999\n00 1\n"), doctest::Contains("truncated"),
                       vmap::Error);
  CHECK_THROWS_AS((void)T::from_text(head + "ids 1\n0 1\n"), vmap::Error);    // short bits
  CHECK_THROWS_AS((void)T::from_text(head + "ids 1\n02 1\n"), vmap::Error);   // not 0/1
  CHECK_THROWS_AS((void)T::from_text(head + "ids 1\n00 x\n"), vmap::Error);   // id not a number
  CHECK_THROWS_AS((void)T::from_text(head + "ids 2\n00 1\n01 1\n"), vmap::Error);  // duplicate id
  CHECK_THROWS_AS((void)T::from_text("vmap-binary-classified-tree 1\ndepth 99999999\nids 0\n"), vmap::Error);
  CHECK_THROWS_AS((void)T::from_text("vmap-binary-classified-tree 1\ndepth -1\nids 0\n"), vmap::Error);
}

TEST_CASE("tree: concurrent const queries give the sequential answers") {
  // The documented guarantee: const members only read, so several threads may query
  // one tree at once.
  constexpr std::size_t depth = 8;
  cv::RNG rng(42);
  BinaryClassifiedTree<std::size_t> t(depth);
  auto random_vector = [&] {
    LabelVector v(depth);
    for (auto& c : v) c = static_cast<std::uint8_t>(rng.uniform(0, 4) == 0 ? 1 : 0);  // sparse, like labels
    return v;
  };
  for (std::size_t id = 0; id < 3000; ++id) t.insert(random_vector(), id);
  std::vector<LabelVector> queries;
  for (int k = 0; k < 300; ++k) queries.push_back(random_vector());
  std::vector<std::vector<std::size_t>> expected;
  for (std::size_t k = 0; k < queries.size(); ++k) expected.push_back(t.candidates(queries[k], k % 40));

  constexpr int threads = 4;
  std::vector<std::vector<std::vector<std::size_t>>> got(threads);
  std::vector<std::thread> pool;
  for (int th = 0; th < threads; ++th)
    pool.emplace_back([&, th] {
      for (int rep = 0; rep < 5; ++rep)
        for (std::size_t k = 0; k < queries.size(); ++k) {
          // Each thread walks the queries in a different order.
          const std::size_t q = (k + static_cast<std::size_t>(th) * 77) % queries.size();
          auto c = t.candidates(queries[q], q % 40);
          if (rep == 0) got[static_cast<std::size_t>(th)].resize(queries.size());
          got[static_cast<std::size_t>(th)][q] = std::move(c);
        }
    });
  for (auto& p : pool) p.join();
  for (int th = 0; th < threads; ++th) CHECK(got[static_cast<std::size_t>(th)] == expected);
  CHECK(expected[1].size() >= 1);
}
