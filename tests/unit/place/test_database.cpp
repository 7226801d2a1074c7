// The inverted-file database against a brute-force scoring of the same vectors; filters,
// erase, concurrent queries, temporal consistency.

#include <vmap/place/consistency.hpp>
#include <vmap/place/database.hpp>

#include "place_support.hpp"

#include <doctest/doctest.h>

#include <random>
#include <thread>
#include <vector>

template class vmap::PlaceDatabase<std::uint32_t>;
template class vmap::PlaceDatabase<int>;
template class vmap::TemporalConsistency<std::uint32_t>;

namespace {

struct RandomDb {
  std::vector<vmap::BowVector> bows;
  std::vector<bool> present;
  vmap::PlaceDatabase<std::uint32_t> db;
};

RandomDb random_db(std::size_t n, std::size_t words, vmap::BowScoring s, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<std::size_t> len(1, 60);
  RandomDb r{{}, std::vector<bool>(n, true), vmap::PlaceDatabase<std::uint32_t>(words, s)};
  for (std::size_t i = 0; i < n; ++i) {
    r.bows.push_back(vmap::test::random_bow(words, len(rng), rng));
    r.db.add(static_cast<std::uint32_t>(i), r.bows.back());
  }
  return r;
}

}  // namespace

TEST_CASE("the inverted file returns exactly the brute-force top k") {
  for (auto scoring : {vmap::BowScoring::l1, vmap::BowScoring::l2, vmap::BowScoring::cosine})
    for (std::size_t n : {1U, 10U, 100U, 1000U}) {
      CAPTURE(vmap::to_string(scoring));
      CAPTURE(n);
      // few words: many images share words with a query, ranks are dense
      const std::size_t words = n < 100 ? 50 : 400;
      auto r = random_db(n, words, scoring, static_cast<unsigned>(n));
      CHECK(r.db.size() == n);
      std::mt19937 rng(99);
      for (int qi = 0; qi < 20; ++qi) {
        const vmap::BowVector q = qi % 4 == 0 ? r.bows[rng() % n] : vmap::test::random_bow(words, 1 + rng() % 50, rng);
        for (std::size_t top : {1U, 5U, 50U, 5000U}) {
          const auto got = r.db.query(q, top);
          vmap::test::check_same_ranking(got, vmap::test::brute_force_top(r.bows, r.present, q, top, scoring));
        }
        if (qi % 4 == 0) {  // a stored vector finds itself first, score 1
          const auto got = r.db.query(q, 1);
          REQUIRE(got.size() == 1);
          CHECK(got[0].score == doctest::Approx(1.0));
        }
      }
      CHECK(r.db.query(vmap::BowVector{}, 5).empty());
      CHECK(r.db.query(r.bows[0], 0).empty());
    }
}

TEST_CASE("filters: only a candidate set, and a range of ids") {
  auto r = random_db(300, 60, vmap::BowScoring::l1, 3);
  std::mt19937 rng(5);
  for (int qi = 0; qi < 10; ++qi) {
    const vmap::BowVector q = vmap::test::random_bow(60, 20, rng);
    // before: only ids < 150 are candidates
    std::vector<bool> early(300, false);
    for (std::size_t i = 0; i < 150; ++i) early[i] = true;
    vmap::test::check_same_ranking(r.db.query(q, 10, {.before = 150U}),
                                   vmap::test::brute_force_top(r.bows, r.present, q, 10, vmap::BowScoring::l1, &early));
    // from and before: only ids 100 <= id < 150 (the frames of a session older than its window)
    std::vector<bool> session(300, false);
    for (std::size_t i = 100; i < 150; ++i) session[i] = true;
    const auto in_session = r.db.query(q, 10, {.before = 150U, .from = 100U});
    vmap::test::check_same_ranking(in_session,
                                   vmap::test::brute_force_top(r.bows, r.present, q, 10, vmap::BowScoring::l1, &session));
    for (const auto& m : in_session) CHECK((m.id >= 100 && m.id < 150));
    // only: a small set (scored directly) and a large one (through the inverted file),
    // with an unknown id and a repeated one that must not matter
    for (std::size_t k : {3U, 250U}) {
      std::vector<std::uint32_t> only;
      std::vector<bool> allowed(300, false);
      for (std::size_t i = 0; i < k; ++i) {
        const auto id = static_cast<std::uint32_t>(rng() % 300);
        only.push_back(id);
        allowed[id] = true;
      }
      only.push_back(only.front());
      only.push_back(12345);
      vmap::test::check_same_ranking(r.db.query(q, 10, {.only = only}),
                                     vmap::test::brute_force_top(r.bows, r.present, q, 10, vmap::BowScoring::l1, &allowed));
      // both filters at once
      std::vector<bool> both(300, false);
      for (std::size_t i = 0; i < 300; ++i) both[i] = allowed[i] && i < 100;
      vmap::test::check_same_ranking(r.db.query(q, 10, {.only = only, .before = 100U}),
                                     vmap::test::brute_force_top(r.bows, r.present, q, 10, vmap::BowScoring::l1, &both));
    }
    CHECK(r.db.query(q, 10, {.only = std::vector<std::uint32_t>{}}).empty());
  }
}

TEST_CASE("erase, re-add, duplicates and bad vectors") {
  auto r = random_db(200, 80, vmap::BowScoring::l1, 8);
  for (std::uint32_t i = 0; i < 200; i += 2) {
    CHECK(r.db.erase(i));
    r.present[i] = false;
  }
  CHECK_FALSE(r.db.erase(0));
  CHECK_FALSE(r.db.erase(999));
  CHECK(r.db.size() == 100);
  CHECK_FALSE(r.db.contains(0));
  CHECK(r.db.contains(1));
  CHECK(r.db.bow(0) == nullptr);
  REQUIRE(r.db.bow(1) != nullptr);
  CHECK(r.db.bow(1)->size() == r.bows[1].size());
  std::mt19937 rng(1);
  for (int qi = 0; qi < 10; ++qi) {
    const auto q = vmap::test::random_bow(80, 30, rng);
    vmap::test::check_same_ranking(r.db.query(q, 20), vmap::test::brute_force_top(r.bows, r.present, q, 20, vmap::BowScoring::l1));
  }
  // erased slots are reused by new images, which are found
  for (std::uint32_t i = 0; i < 200; i += 4) {
    r.db.add(i, r.bows[i]);
    r.present[i] = true;
  }
  CHECK(r.db.size() == 150);
  for (int qi = 0; qi < 10; ++qi) {
    const auto q = vmap::test::random_bow(80, 30, rng);
    vmap::test::check_same_ranking(r.db.query(q, 20), vmap::test::brute_force_top(r.bows, r.present, q, 20, vmap::BowScoring::l1));
  }
  const auto ids = r.db.ids();
  CHECK(ids.size() == 150);
  CHECK(std::is_sorted(ids.begin(), ids.end()));

  CHECK_THROWS_AS(r.db.add(1, r.bows[1]), vmap::Error);                                    // duplicate id
  CHECK_THROWS_AS(r.db.add(500, vmap::BowVector{{{80, 1.0f}}}), vmap::Error);               // word outside the vocabulary
  CHECK_THROWS_AS(r.db.add(500, vmap::BowVector{{{3, 1.0f}, {2, 1.0f}}}), vmap::Error);     // unsorted
  CHECK_THROWS_AS(r.db.add(500, vmap::BowVector{{{3, -1.0f}}}), vmap::Error);               // negative
  CHECK_THROWS_AS((void)r.db.query(vmap::BowVector{{{90, 1.0f}}}, 3), vmap::Error);
  CHECK_FALSE(r.db.contains(500));
  // an empty vector is stored and never found
  r.db.add(600, vmap::BowVector{});
  CHECK(r.db.contains(600));
  for (const auto& m : r.db.query(r.bows[1], 1000)) CHECK(m.id != 600);

  // memory grows with the content
  const std::size_t before = r.db.memory_bytes();
  r.db.add(700, r.bows[3]);
  CHECK(r.db.memory_bytes() > before);
  std::size_t entries = 0;
  for (auto id : r.db.ids()) entries += r.db.bow(id)->size();
  CHECK(r.db.memory_bytes() >= 16 * entries);  // a stored entry and a posting each
  r.db.clear();
  CHECK(r.db.empty());
  CHECK(r.db.query(r.bows[3], 5).empty());
}

TEST_CASE("signed ids, any order of insertion, ties by increasing id") {
  vmap::PlaceDatabase<int> db(10);
  const vmap::BowVector a{{{1, 0.5f}, {2, 0.5f}}};
  db.add(7, a);
  db.add(-3, a);
  db.add(2, a);
  db.add(5, vmap::BowVector{{{1, 1.0f}}});
  const auto m = db.query(a, 10);
  REQUIRE(m.size() == 4);
  CHECK(m[0].id == -3);
  CHECK(m[1].id == 2);
  CHECK(m[2].id == 7);
  CHECK(m[0].score == doctest::Approx(1.0));
  CHECK(m[3].id == 5);
  CHECK(m[3].score == doctest::Approx(0.5));
  const auto ex = db.query(a, 10, {.before = 2});
  REQUIRE(ex.size() == 1);
  CHECK(ex[0].id == -3);
}

TEST_CASE("concurrent const queries give the serial results") {
  auto r = random_db(2000, 300, vmap::BowScoring::l1, 21);
  std::mt19937 rng(4);
  std::vector<vmap::BowVector> queries;
  for (int i = 0; i < 64; ++i) queries.push_back(vmap::test::random_bow(300, 40, rng));
  std::vector<std::vector<vmap::PlaceMatch<std::uint32_t>>> serial;
  for (const auto& q : queries) serial.push_back(r.db.query(q, 10));
  constexpr int threads = 4;
  std::vector<int> mismatches(threads, 0);
  {
    std::vector<std::jthread> pool;
    for (int t = 0; t < threads; ++t)
      pool.emplace_back([&, t] {
        for (int round = 0; round < 5; ++round)
          for (std::size_t i = 0; i < queries.size(); ++i) {
            const std::size_t k = (i + static_cast<std::size_t>(t) * 7) % queries.size();
            const auto filter = k % 3 == 0 ? vmap::QueryFilter<std::uint32_t>{.before = 1000U}
                                           : vmap::QueryFilter<std::uint32_t>{};
            const auto got = r.db.query(queries[k], 10, filter);
            const auto want = k % 3 == 0 ? std::vector<vmap::PlaceMatch<std::uint32_t>>{} : serial[k];
            if (k % 3 != 0 && got != want) ++mismatches[static_cast<std::size_t>(t)];
            if (k % 3 == 0)
              for (const auto& m : got)
                if (m.id >= 1000) ++mismatches[static_cast<std::size_t>(t)];
          }
      });
  }
  for (int t = 0; t < threads; ++t) CHECK(mismatches[static_cast<std::size_t>(t)] == 0);
}

TEST_CASE("temporal consistency on a scripted sequence of best matches") {
  vmap::TemporalConsistency<std::uint32_t> tc({.required = 3, .tolerance = 2});
  using S = vmap::ConsistencyState<std::uint32_t>;
  // query:        best match    accepted  consecutive  island
  auto s = tc.update(10U);
  CHECK(s == S{false, 1, 10, 10, 10U});
  s = tc.update(11U);
  CHECK(s == S{false, 2, 10, 11, 11U});
  s = tc.update(13U);  // within 2 of 11
  CHECK(s == S{true, 3, 10, 13, 13U});
  s = tc.update(12U);  // going back a little is still the same place
  CHECK(s == S{true, 4, 10, 13, 12U});
  s = tc.update(40U);  // a jump: a new island
  CHECK(s == S{false, 1, 40, 40, 40U});
  s = tc.update(41U);
  CHECK(s == S{false, 2, 40, 41, 41U});
  s = tc.update(std::nullopt);  // no match: start again
  CHECK(s == S{});
  s = tc.update(41U);
  CHECK(s == S{false, 1, 41, 41, 41U});
  CHECK(tc.state() == s);
  // restored from a saved state, it goes on as the original
  vmap::TemporalConsistency<std::uint32_t> restored(tc.options(), tc.state());
  CHECK(restored.update(42U) == tc.update(42U));
  CHECK(restored.update(43U) == tc.update(43U));
  CHECK(tc.state().accepted);
  // required = 1 accepts every match; distances never overflow for signed ids
  vmap::TemporalConsistency<int> one({.required = 1, .tolerance = 0});
  CHECK(one.update(-5).accepted);
  CHECK(one.update(std::numeric_limits<int>::max()).consecutive == 1);
  CHECK(one.update(std::numeric_limits<int>::min()).consecutive == 1);
  CHECK_THROWS_AS(vmap::TemporalConsistency<int>({.required = 0}), vmap::Error);
}
