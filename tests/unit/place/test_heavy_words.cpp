// Heavy words and the heavy score (the place rule between runs): the n heaviest words,
// ties, a score that is the pair's (symmetric, exact in integers), its index against a
// brute-force scoring, and the order that makes a pair's verification the pair's.

#include <vmap/core/features.hpp>
#include <vmap/place/heavy_words.hpp>

#include "place_support.hpp"

#include <doctest/doctest.h>

#include <algorithm>
#include <cstdint>
#include <random>
#include <vector>

TEST_CASE("heavy words: the n heaviest of the L1-normalised vector, by word id; ties go to the lower word") {
  std::mt19937 rng(7);
  for (int t = 0; t < 20; ++t) {
    const vmap::BowVector bow = vmap::test::random_bow(1000, 200, rng);
    const auto heavy = vmap::heavy_words(bow);
    REQUIRE(heavy.size() == vmap::heavy_word_count);
    CHECK(std::is_sorted(heavy.begin(), heavy.end(), [](const auto& a, const auto& b) { return a.word < b.word; }));
    // Every word left out weighs no more than the lightest kept.
    std::uint64_t lightest = UINT64_MAX;
    for (const auto& h : heavy) lightest = std::min(lightest, h.weight);
    const double norm = bow.l1_norm();
    for (const auto& e : bow) {
      const bool kept = std::any_of(heavy.begin(), heavy.end(), [&](const auto& h) { return h.word == e.word; });
      const auto units = static_cast<std::uint64_t>(std::llround(e.weight / norm * vmap::heavy_weight_unit));
      if (kept)
        CHECK(std::find(heavy.begin(), heavy.end(), vmap::HeavyWord{e.word, units}) != heavy.end());
      else
        CHECK(units <= lightest);
    }
  }
  // A short vector keeps every word, and its weights sum to 1 (2^32 units, up to rounding).
  const vmap::BowVector few{{{3, 1.0f}, {9, 3.0f}, {40, 4.0f}}};
  const auto all = vmap::heavy_words(few);
  REQUIRE(all.size() == 3);
  CHECK(all[0] == vmap::HeavyWord{3, 536870912});   // 1/8
  CHECK(all[1] == vmap::HeavyWord{9, 1610612736});  // 3/8
  CHECK(all[2] == vmap::HeavyWord{40, 2147483648});  // 1/2
  // Equal weights: the lower words are the heavy ones.
  vmap::BowVector flat;
  for (std::uint32_t w = 0; w < 100; ++w) flat.entries.push_back({w * 2, 1.0f});
  const auto first = vmap::heavy_words(flat, 10);
  REQUIRE(first.size() == 10);
  for (std::uint32_t i = 0; i < 10; ++i) CHECK(first[i].word == i * 2);
  CHECK(vmap::heavy_words(vmap::BowVector{}).empty());
}

TEST_CASE("heavy score: the pair's own (symmetric, exact), DBoW2's L1 score when every word is heavy") {
  std::mt19937 rng(11);
  std::vector<std::vector<vmap::HeavyWord>> heavy;
  std::vector<vmap::BowVector> bows;
  for (int i = 0; i < 30; ++i) {
    bows.push_back(vmap::test::random_bow(300, 20 + static_cast<std::size_t>(rng() % 150), rng));
    heavy.push_back(vmap::heavy_words(bows.back()));
  }
  for (std::size_t a = 0; a < bows.size(); ++a)
    for (std::size_t b = 0; b < bows.size(); ++b) {
      const std::uint64_t s = vmap::heavy_score_units(heavy[a], heavy[b]);
      CHECK(s == vmap::heavy_score_units(heavy[b], heavy[a]));
      std::uint64_t want = 0;
      for (const auto& x : heavy[a])
        for (const auto& y : heavy[b])
          if (x.word == y.word) want += std::min(x.weight, y.weight);
      CHECK(s == want);
      // No more than the L1 score over all words; equal to it when no word was dropped.
      const double l1 = vmap::bow_score(bows[a], bows[b], vmap::BowScoring::l1);
      CHECK(vmap::heavy_score(s) <= l1 + 1e-6);
      if (bows[a].size() <= vmap::heavy_word_count && bows[b].size() <= vmap::heavy_word_count)
        CHECK(vmap::heavy_score(s) == doctest::Approx(l1).epsilon(1e-6));
    }
  // A vector against itself: the share of its heavy words, 1 when every word is heavy.
  for (std::size_t a = 0; a < bows.size(); ++a) {
    std::uint64_t mass = 0;
    for (const auto& h : heavy[a]) mass += h.weight;
    CHECK(vmap::heavy_score_units(heavy[a], heavy[a]) == mass);
    if (bows[a].size() <= vmap::heavy_word_count)
      CHECK(vmap::heavy_score(mass) == doctest::Approx(1.0).epsilon(1e-8));
  }
  CHECK(vmap::heavy_units(0.02) == 85899346);
  CHECK(vmap::heavy_units(-1.0) == 0);
  CHECK(vmap::heavy_units(2.0) == 4294967296ULL);
}

TEST_CASE("heavy index: the images before a bound whose score reaches a threshold, best first, as brute force") {
  std::mt19937 rng(13);
  std::vector<std::vector<vmap::HeavyWord>> heavy;
  vmap::HeavyIndex index;
  for (std::uint32_t i = 0; i < 400; ++i) {
    heavy.push_back(vmap::heavy_words(vmap::test::random_bow(200, 30 + rng() % 100, rng)));
    index.add(i, heavy.back());
  }
  CHECK(index.next() == 400);
  for (int qi = 0; qi < 20; ++qi) {
    const auto q = vmap::heavy_words(vmap::test::random_bow(200, 30 + rng() % 100, rng));
    for (const std::uint32_t before : {0U, 1U, 150U, 400U})
      for (const double min : {0.0, 0.05, 0.1, 0.3}) {
        CAPTURE(before);
        CAPTURE(min);
        std::vector<vmap::HeavyIndex::Hit> want;
        for (std::uint32_t i = 0; i < before; ++i) {
          const std::uint64_t s = vmap::heavy_score_units(q, heavy[i]);
          if (s > 0 && s >= vmap::heavy_units(min)) want.push_back({i, s});
        }
        std::sort(want.begin(), want.end(),
                  [](const auto& a, const auto& b) { return a.units != b.units ? a.units > b.units : a.id < b.id; });
        const auto got = index.query(q, before, vmap::heavy_units(min));
        REQUIRE(got.size() == want.size());
        for (std::size_t i = 0; i < got.size(); ++i) {
          CHECK(got[i].id == want[i].id);
          CHECK(got[i].units == want[i].units);
        }
      }
  }
  index.clear();
  CHECK(index.next() == 0);
  CHECK(index.query(heavy[0], 400, 0).empty());
}

TEST_CASE("features order: a strict total order on content, so a pair is verified the same way whichever asks") {
  std::mt19937 rng(17);
  const auto random_features = [&](int n) {
    vmap::Features f;
    f.descriptors = cv::Mat(n, 32, CV_8U);
    for (int r = 0; r < n; ++r) {
      f.keypoints.emplace_back(static_cast<float>(rng() % 640), static_cast<float>(rng() % 480), 7.0f);
      for (int c = 0; c < 32; ++c) f.descriptors.at<std::uint8_t>(r, c) = static_cast<std::uint8_t>(rng() % 4);
    }
    return f;
  };
  std::vector<vmap::Features> all;
  for (int i = 0; i < 12; ++i) all.push_back(random_features(i % 3 == 0 ? 5 : 6));
  // Same descriptors, keypoints elsewhere; and a copy.
  all.push_back(all[1]);
  all.back().keypoints[3].pt.y += 1.0f;
  all.push_back(all[2]);
  for (std::size_t a = 0; a < all.size(); ++a) {
    CHECK_FALSE(vmap::detail::features_before(all[a], all[a]));
    for (std::size_t b = 0; b < all.size(); ++b) {
      const bool ab = vmap::detail::features_before(all[a], all[b]);
      const bool ba = vmap::detail::features_before(all[b], all[a]);
      CHECK_FALSE((ab && ba));
      const bool same = all[a].keypoints.size() == all[b].keypoints.size() &&
                        cv::norm(all[a].descriptors, all[b].descriptors, cv::NORM_L1) == 0 &&
                        std::equal(all[a].keypoints.begin(), all[a].keypoints.end(), all[b].keypoints.begin(),
                                   [](const auto& x, const auto& y) { return x.pt == y.pt; });
      CHECK((ab || ba) == !same);
      for (std::size_t c = 0; c < all.size(); ++c)
        if (ab && vmap::detail::features_before(all[b], all[c])) CHECK(vmap::detail::features_before(all[a], all[c]));
    }
  }
  // Fewer keypoints first.
  CHECK(vmap::detail::features_before(all[0], all[1]));
}
