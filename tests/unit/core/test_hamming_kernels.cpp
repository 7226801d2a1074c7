// The Hamming matcher kernels: every dispatch level against the portable one on random
// descriptors of many widths and counts, the level selection and its fall-back, and the
// matches on real frames against OpenCV's cross-check and batchDistance(K = 2), the
// code paths the matcher used before the kernels.
#include <vmap/features/akaze.hpp>
#include <vmap/features/orb.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/matching/brute_force.hpp>
#include <vmap/matching/hamming.hpp>

#include "support/shared_data.hpp"

#include <doctest/doctest.h>
#include <opencv2/features2d.hpp>

#include <climits>
#include <cstdlib>
#include <vector>

namespace {

constexpr vmap::HammingLevel kLevels[] = {vmap::HammingLevel::portable, vmap::HammingLevel::popcnt,
                                          vmap::HammingLevel::avx2, vmap::HammingLevel::avx512};

/// Random rows; with `ties`, bytes from {0, 1, 3} so that many distances repeat.
cv::Mat random_descriptors(int rows, int cols, bool ties, std::uint64_t seed) {
  cv::RNG rng(seed);
  cv::Mat m(rows, cols, CV_8U);
  for (int i = 0; i < rows; ++i)
    for (int k = 0; k < cols; ++k) {
      const int v = ties ? (rng.uniform(0, 3) == 2 ? 3 : rng.uniform(0, 2)) : rng.uniform(0, 256);
      m.at<std::uint8_t>(i, k) = static_cast<std::uint8_t>(v);
    }
  return m;
}

/// Distances by definition, for the expected values below.
int hamming(const cv::Mat& a, int i, const cv::Mat& b, int j) {
  return static_cast<int>(cv::norm(a.row(i), b.row(j), cv::NORM_HAMMING));
}

vmap::Features features_of(const cv::Mat& d) {
  vmap::Features f;
  f.norm = cv::NORM_HAMMING;
  f.descriptors = d;
  f.keypoints.resize(static_cast<std::size_t>(d.rows));
  return f;
}

/// Sets an environment variable for one scope.
struct ScopedEnv {
  ScopedEnv(const char* name, const char* value) : name_(name) { ::setenv(name, value, 1); }
  ~ScopedEnv() { ::unsetenv(name_); }
  ScopedEnv(const ScopedEnv&) = delete;
  ScopedEnv& operator=(const ScopedEnv&) = delete;
  const char* name_;
};

}  // namespace

TEST_CASE("every Hamming kernel level equals the portable one, every width and count") {
  const int widths[] = {1, 8, 13, 32, 33, 61, 64, 250};  // 250: more than 31 words (AVX2 byte counters)
  const int counts[] = {0, 1, 2, 7, 8, 9, 16, 17, 31, 300, 530};  // 530: past a 16 KB column block
  std::uint64_t seed = 1;
  for (const int width : widths)
    for (const bool ties : {false, true})
      for (const int na : counts)
        for (const int nb : counts) {
          if (width > 64 && (na > 31 || nb > 31)) continue;  // the wide rows need not be many
          if (na * nb > 40000 && ties) continue;
          const cv::Mat a = random_descriptors(na, width, ties, ++seed);
          const cv::Mat b = random_descriptors(nb, width, ties, ++seed);
          CAPTURE(width);
          CAPTURE(ties);
          CAPTURE(na);
          CAPTURE(nb);
          vmap::detail::HammingScratch s;
          vmap::detail::MutualResult ref_m, m;
          vmap::detail::TwoNearestResult ref_t, t;
          vmap::detail::mutual_hamming(a, b, vmap::HammingLevel::portable, s, ref_m);
          vmap::detail::two_nearest_hamming(a, b, vmap::HammingLevel::portable, s, ref_t);
          REQUIRE(ref_m.best_b.size() == static_cast<std::size_t>(na));
          REQUIRE(ref_m.best_a.size() == static_cast<std::size_t>(nb));
          // The portable kernel itself, by definition, on the first and last rows.
          for (const int i : {0, na - 1}) {
            if (na == 0 || nb == 0) break;
            int best = 0, d1 = INT_MAX, d2 = INT_MAX;
            for (int j = 0; j < nb; ++j) {
              const int d = hamming(a, i, b, j);
              if (d < d1) {
                d2 = d1;
                d1 = d;
                best = j;
              } else if (d < d2) {
                d2 = d;
              }
            }
            CHECK(ref_m.best_b[static_cast<std::size_t>(i)] == best);
            CHECK(ref_m.best_b_dist[static_cast<std::size_t>(i)] == d1);
            CHECK(ref_t.best[static_cast<std::size_t>(i)] == best);
            CHECK(ref_t.second_dist[static_cast<std::size_t>(i)] == d2);
          }
          if (na > 0 && nb > 0) {
            int best = 0, d1 = INT_MAX;
            for (int i = 0; i < na; ++i)
              if (const int d = hamming(a, i, b, nb - 1); d < d1) {
                d1 = d;
                best = i;
              }
            CHECK(ref_m.best_a[static_cast<std::size_t>(nb - 1)] == best);
            CHECK(ref_m.best_a_dist[static_cast<std::size_t>(nb - 1)] == d1);
          }
          for (const auto level : kLevels) {
            const auto run = vmap::resolve_hamming_level(level);
            CAPTURE(vmap::to_string(run));
            vmap::detail::mutual_hamming(a, b, run, s, m);
            vmap::detail::two_nearest_hamming(a, b, run, s, t);
            CHECK(m.best_b == ref_m.best_b);
            CHECK(m.best_b_dist == ref_m.best_b_dist);
            CHECK(m.best_a == ref_m.best_a);
            CHECK(m.best_a_dist == ref_m.best_a_dist);
            CHECK(t.best == ref_t.best);
            CHECK(t.best_dist == ref_t.best_dist);
            CHECK(t.second_dist == ref_t.second_dist);
          }
        }
}

TEST_CASE("forced Hamming levels fall back to what the CPU has") {
  const auto cpu = vmap::cpu_hamming_level();
  MESSAGE("this CPU's Hamming kernel level: " << vmap::to_string(cpu));
  for (const auto level : kLevels) {
    CAPTURE(vmap::to_string(level));
    const auto expected = level < cpu ? level : cpu;
    CHECK(vmap::resolve_hamming_level(level) == expected);
    CHECK(vmap::BruteForceMatcher({.hamming_level = level}).hamming_level() == expected);
    const ScopedEnv env("VMAP_HAMMING_LEVEL", std::string(vmap::to_string(level)).c_str());
    CHECK(vmap::BruteForceMatcher{}.hamming_level() == expected);
    // The option wins over the environment.
    CHECK(vmap::BruteForceMatcher({.hamming_level = vmap::HammingLevel::portable}).hamming_level() ==
          vmap::HammingLevel::portable);
  }
  CHECK(vmap::BruteForceMatcher{}.hamming_level() == cpu);
  CHECK(vmap::parse_hamming_level("avx2", "test") == vmap::HammingLevel::avx2);
  {
    const ScopedEnv env("VMAP_HAMMING_LEVEL", "sse9");
    CHECK_THROWS_WITH_AS(vmap::BruteForceMatcher{}, doctest::Contains("VMAP_HAMMING_LEVEL"), vmap::Error);
    CHECK_THROWS_WITH_AS(vmap::BruteForceMatcher{}, doctest::Contains("'sse9'"), vmap::Error);
  }
  const ScopedEnv empty("VMAP_HAMMING_LEVEL", "");
  CHECK(vmap::BruteForceMatcher{}.hamming_level() == cpu);
}

TEST_CASE("ratio-test Hamming matches equal OpenCV's batchDistance with K = 2 at every level") {
  for (const bool ties : {false, true}) {
    // b: noisy copies of a's first 100 rows (a few bits flipped: distinctive matches),
    // then unrelated rows.
    const cv::Mat a = random_descriptors(157, 32, ties, 71);
    cv::Mat b = random_descriptors(203, 32, ties, 72);
    cv::RNG rng(73);
    for (int i = 0; i < 100; ++i) {
      a.row(i).copyTo(b.row(2 * i));
      for (int f = rng.uniform(0, 12); f > 0; --f)
        b.at<std::uint8_t>(2 * i, rng.uniform(0, 32)) ^= static_cast<std::uint8_t>(1u << rng.uniform(0, 8));
    }
    cv::Mat dist, idx;
    cv::batchDistance(a, b, dist, CV_32S, idx, cv::NORM_HAMMING, 2);
    vmap::Matches expected;
    for (int i = 0; i < a.rows; ++i) {
      const float d1 = static_cast<float>(dist.at<int>(i, 0)), d2 = static_cast<float>(dist.at<int>(i, 1));
      if (d1 < 0.8f * d2) expected.emplace_back(i, idx.at<int>(i, 0), d1);
    }
    REQUIRE(expected.size() > 5);
    for (const auto level : kLevels) {
      CAPTURE(vmap::to_string(level));
      const auto m = vmap::BruteForceMatcher({.mode = vmap::MatchMode::ratio, .hamming_level = level})
                         .match(features_of(a), features_of(b));
      REQUIRE(m.size() == expected.size());
      for (std::size_t k = 0; k < m.size(); ++k) {
        CHECK(m[k].queryIdx == expected[k].queryIdx);
        CHECK(m[k].trainIdx == expected[k].trainIdx);
        CHECK(m[k].distance == expected[k].distance);
      }
    }
  }
}

TEST_SUITE("data") {
  TEST_CASE_TEMPLATE("matches on real frames at every Hamming level equal OpenCV's", D, vmap::OrbDescriptor,
                     vmap::AkazeDescriptor) {
    // Pairs one, ten and thirty frames apart in both sequences.
    std::vector<cv::Mat> frames;
    for (const char* seq : {"tum_fr1_rpy/rgb.txt", "kitti07_160/image_0"}) {
      auto src = vmap::FrameSource::open(vmap::test::data_path(seq), {.end = 41, .grey = true});
      std::vector<cv::Mat> all;
      while (auto f = src.next()) all.push_back(f->image);
      REQUIRE(all.size() == 41);
      for (const std::size_t k : {0, 1, 10, 40}) frames.push_back(all[k]);
    }
    D descriptor;
    for (std::size_t s = 0; s < frames.size(); s += 4) {
      const auto f = descriptor.extract(frames[s]);
      for (std::size_t k = 1; k < 4; ++k) {
        const auto g = descriptor.extract(frames[s + k]);
        REQUIRE(f.size() > 100);
        CAPTURE(s);
        CAPTURE(k);
        std::vector<cv::DMatch> cross;
        cv::BFMatcher(cv::NORM_HAMMING, true).match(f.descriptors, g.descriptors, cross);
        cv::Mat dist, idx;
        cv::batchDistance(f.descriptors, g.descriptors, dist, CV_32S, idx, cv::NORM_HAMMING, 2);
        vmap::Matches ratio;
        for (int i = 0; i < idx.rows; ++i) {
          const float d1 = static_cast<float>(dist.at<int>(i, 0)), d2 = static_cast<float>(dist.at<int>(i, 1));
          if (d1 < 0.8f * d2) ratio.emplace_back(i, idx.at<int>(i, 0), d1);
        }
        for (const auto level : kLevels) {
          CAPTURE(vmap::to_string(level));
          const auto m = vmap::BruteForceMatcher({.hamming_level = level}).match(f, g);
          REQUIRE(m.size() == cross.size());
          bool same = true;
          for (std::size_t q = 0; q < m.size(); ++q)
            same = same && m[q].queryIdx == cross[q].queryIdx && m[q].trainIdx == cross[q].trainIdx &&
                   m[q].distance == cross[q].distance;
          CHECK(same);
          const auto r = vmap::BruteForceMatcher({.mode = vmap::MatchMode::ratio, .hamming_level = level}).match(f, g);
          REQUIRE(r.size() == ratio.size());
          same = true;
          for (std::size_t q = 0; q < r.size(); ++q)
            same = same && r[q].queryIdx == ratio[q].queryIdx && r[q].trainIdx == ratio[q].trainIdx &&
                   r[q].distance == ratio[q].distance;
          CHECK(same);
        }
      }
    }
  }
}
