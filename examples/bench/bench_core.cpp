// Benchmark of the core per-pair steps (ORB extract, match, MAGSAC verification) on
// 640x480 TUM fr1_rpy frames, against the same steps written as in
// ../shared/baselines/keyframes_opencv.cpp, interleaved pair by pair in one run so the
// shared machine's noise hits both alike. Prints mean milliseconds and ratios.
//
// Then the match step alone, per Hamming kernel level (each forced through
// BruteForceOptions::hamming_level; a level the CPU lacks is reported with the level it
// falls back to), against the matcher's previous kernel (a copy below: one 64-bit POPCNT
// at a time, one distance at a time) and OpenCV's BFMatcher cross-check, on ORB (32-byte)
// and A-KAZE (61-byte) descriptors of the same frames, interleaved pair by pair.
//
// usage: bench_core [RGB_TXT] [PAIRS]
#include <vmap/features/akaze.hpp>
#include <vmap/features/orb.hpp>
#include <vmap/geometry/fundamental.hpp>
#include <vmap/geometry/similarity.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/matching/brute_force.hpp>
#include <vmap/matching/hamming.hpp>

#include <opencv2/calib3d.hpp>
#include <opencv2/features2d.hpp>

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

namespace {

using clock_type = std::chrono::steady_clock;
double ms_since(clock_type::time_point t) {
  return std::chrono::duration<double, std::milli>(clock_type::now() - t).count();
}

struct Times {
  double extract = 0, match = 0, verify = 0;
  long inliers = 0;
};

// The baseline's steps, verbatim in behaviour (keyframes_opencv.cpp: extract, verified).
struct BaselineFeat {
  std::vector<cv::KeyPoint> kp;
  cv::Mat d;
};

// The matcher's mutual Hamming kernel before the vector levels, unchanged: the baseline
// of the match-step table.
namespace previous {

struct MutualResult {
  std::vector<int> best_b, best_b_dist, best_a, best_a_dist;
};

inline __attribute__((always_inline)) int hamming_bytes(const std::uint8_t* x, const std::uint8_t* y, int bytes) {
  int d = 0;
  int k = 0;
  for (; k + 8 <= bytes; k += 8) {
    std::uint64_t u, v;
    std::memcpy(&u, x + k, 8);
    std::memcpy(&v, y + k, 8);
    d += __builtin_popcountll(u ^ v);
  }
  for (; k < bytes; ++k) d += __builtin_popcount(static_cast<unsigned>(x[k] ^ y[k]));
  return d;
}

__attribute__((target("popcnt"))) void mutual_hamming(const cv::Mat& a, const cv::Mat& b, MutualResult& r) {
  const int na = a.rows, nb = b.rows, bytes = a.cols;
  constexpr int none = std::numeric_limits<int>::max();
  r.best_b.assign(static_cast<std::size_t>(na), -1);
  r.best_b_dist.assign(static_cast<std::size_t>(na), none);
  r.best_a.assign(static_cast<std::size_t>(nb), -1);
  r.best_a_dist.assign(static_cast<std::size_t>(nb), none);
  int* const col_best = r.best_a.data();
  int* const col_dist = r.best_a_dist.data();
  for (int i = 0; i < na; ++i) {
    const std::uint8_t* ai = a.ptr<std::uint8_t>(i);
    int row_best = -1, row_dist = none;
    for (int j = 0; j < nb; ++j) {
      const int d = hamming_bytes(ai, b.ptr<std::uint8_t>(j), bytes);
      if (d < row_dist) {
        row_dist = d;
        row_best = j;
      }
      if (d < col_dist[j]) {
        col_dist[j] = d;
        col_best[j] = i;
      }
    }
    r.best_b[static_cast<std::size_t>(i)] = row_best;
    r.best_b_dist[static_cast<std::size_t>(i)] = row_dist;
  }
}

vmap::Matches match(const vmap::Features& a, const vmap::Features& b, MutualResult& r) {
  vmap::Matches out;
  if (a.descriptors.empty() || b.descriptors.empty()) return out;
  mutual_hamming(a.descriptors, b.descriptors, r);
  for (std::size_t i = 0; i < r.best_b.size(); ++i) {
    const int j = r.best_b[i];
    if (j >= 0 && r.best_a[static_cast<std::size_t>(j)] == static_cast<int>(i))
      out.emplace_back(static_cast<int>(i), j, static_cast<float>(r.best_b_dist[i]));
  }
  return out;
}

}  // namespace previous

bool same_matches(const vmap::Matches& x, const std::vector<cv::DMatch>& y) {
  if (x.size() != y.size()) return false;
  for (std::size_t k = 0; k < x.size(); ++k)
    if (x[k].queryIdx != y[k].queryIdx || x[k].trainIdx != y[k].trainIdx || x[k].distance != y[k].distance)
      return false;
  return true;
}

/// The match step alone on consecutive pairs of `feats`: OpenCV's cross-check, the
/// previous kernel and every Hamming level, interleaved pair by pair; best of two passes.
void match_step(const char* name, const std::vector<vmap::Features>& feats) {
  constexpr vmap::HammingLevel levels[] = {vmap::HammingLevel::portable, vmap::HammingLevel::popcnt,
                                           vmap::HammingLevel::avx2, vmap::HammingLevel::avx512};
  std::vector<vmap::BruteForceMatcher> matchers;
  for (const auto l : levels) matchers.emplace_back(vmap::BruteForceOptions{.hamming_level = l});
  const int n = static_cast<int>(feats.size()) - 1;
  double best_cv = 1e300, best_prev = 1e300;
  std::vector<double> best_lvl(std::size(levels), 1e300);
  bool all_same = true;
  long matches = 0;
  double descriptors = 0;
  for (int pass = 0; pass < 2; ++pass) {
    double t_cv = 0, t_prev = 0;
    std::vector<double> t_lvl(std::size(levels), 0.0);
    previous::MutualResult prev_scratch;
    vmap::BruteForceMatcher::Scratch scratch;
    vmap::Matches out;
    matches = 0;
    descriptors = 0;
    for (int i = 0; i < n; ++i) {
      const auto& a = feats[static_cast<std::size_t>(i)];
      const auto& b = feats[static_cast<std::size_t>(i) + 1];
      descriptors += 0.5 * (a.descriptors.rows + b.descriptors.rows);
      auto t = clock_type::now();
      std::vector<cv::DMatch> ref;
      cv::BFMatcher(cv::NORM_HAMMING, true).match(a.descriptors, b.descriptors, ref);
      t_cv += ms_since(t);
      matches += static_cast<long>(ref.size());
      t = clock_type::now();
      const auto pm = previous::match(a, b, prev_scratch);
      t_prev += ms_since(t);
      all_same = all_same && same_matches(pm, ref);
      for (std::size_t l = 0; l < std::size(levels); ++l) {
        t = clock_type::now();
        matchers[l].match_into(a, b, out, scratch);
        t_lvl[l] += ms_since(t);
        all_same = all_same && same_matches(out, ref);
      }
    }
    best_cv = std::min(best_cv, t_cv / n);
    best_prev = std::min(best_prev, t_prev / n);
    for (std::size_t l = 0; l < std::size(levels); ++l) best_lvl[l] = std::min(best_lvl[l], t_lvl[l] / n);
  }
  std::printf("\nmatch step, %s: %d pairs, %.0f descriptors per image on average, best of 2 passes, ms per pair\n",
              name, n, descriptors / n);
  std::printf("  %-44s %9s %12s %12s\n", "", "ms/pair", "x previous", "x OpenCV");
  std::printf("  %-44s %9.3f %11.2fx %11.2fx\n", "OpenCV BFMatcher(NORM_HAMMING, crossCheck)", best_cv,
              best_prev / best_cv, 1.0);
  std::printf("  %-44s %9.3f %11.2fx %11.2fx\n", "previous kernel (POPCNT, one distance a time)", best_prev, 1.0,
              best_cv / best_prev);
  for (std::size_t l = 0; l < std::size(levels); ++l) {
    const auto ran = matchers[l].hamming_level();
    std::string label = "vmap " + std::string(vmap::to_string(levels[l]));
    if (ran != levels[l]) label += " (CPU lacks it: ran " + std::string(vmap::to_string(ran)) + ")";
    std::printf("  %-44s %9.3f %11.2fx %11.2fx\n", label.c_str(), best_lvl[l], best_prev / best_lvl[l],
                best_cv / best_lvl[l]);
  }
  std::printf("  %ld mutual matches in all; identical to OpenCV's at every level and in the previous kernel: %s\n",
              matches, all_same ? "yes" : "NO");
}

}  // namespace

int main(int argc, char** argv) {
  const std::string list = argc > 1 ? argv[1] : std::string(VMAP_SHARED_DIR) + "/data/tum_fr1_rpy/rgb.txt";
  const int pairs = argc > 2 ? std::stoi(argv[2]) : 200;
  std::vector<cv::Mat> frames;
  auto source = vmap::FrameSource::open(list, {.end = static_cast<std::size_t>(pairs) + 1, .grey = true});
  while (auto f = source.next()) frames.push_back(f->image);
  if (frames.size() < 2) {
    std::fprintf(stderr, "bench_core: need at least two frames in %s\n", list.c_str());
    return 1;
  }

  auto orb = cv::ORB::create(1000);
  vmap::OrbDescriptor vorb;
  const vmap::BruteForceMatcher matcher;
  const vmap::FundamentalEstimator with_check;
  const vmap::FundamentalEstimator without_check({.check_degeneracy = false});

  Times base, ours, ours_nocheck;
  const int n = static_cast<int>(frames.size()) - 1;
  for (int rep = 0; rep < 2; ++rep) {  // first pass warms caches and OpenCV's allocators
    base = ours = ours_nocheck = Times{};
    for (int i = 0; i < n; ++i) {
      // Baseline: ORB(1000), BFMatcher Hamming cross-check, findFundamentalMat MAGSAC 1 px 0.99.
      auto t = clock_type::now();
      BaselineFeat a, b;
      orb->detectAndCompute(frames[static_cast<std::size_t>(i)], cv::noArray(), a.kp, a.d);
      orb->detectAndCompute(frames[static_cast<std::size_t>(i) + 1], cv::noArray(), b.kp, b.d);
      base.extract += ms_since(t);
      t = clock_type::now();
      cv::BFMatcher bf(cv::NORM_HAMMING, true);
      std::vector<cv::DMatch> m;
      bf.match(a.d, b.d, m);
      base.match += ms_since(t);
      t = clock_type::now();
      if (m.size() >= 8) {
        std::vector<cv::Point2f> p, q;
        for (auto& x : m) {
          p.push_back(a.kp[static_cast<std::size_t>(x.queryIdx)].pt);
          q.push_back(b.kp[static_cast<std::size_t>(x.trainIdx)].pt);
        }
        cv::Mat mask;
        cv::Mat F = cv::findFundamentalMat(p, q, cv::USAC_MAGSAC, 1.0, 0.99, mask);
        if (!F.empty()) base.inliers += cv::countNonZero(mask);
      }
      base.verify += ms_since(t);

      // vmap: the same steps through the policies.
      t = clock_type::now();
      const vmap::Features fa = vorb.extract(frames[static_cast<std::size_t>(i)]);
      const vmap::Features fb = vorb.extract(frames[static_cast<std::size_t>(i) + 1]);
      const double ext = ms_since(t);
      ours.extract += ext;
      ours_nocheck.extract += ext;
      t = clock_type::now();
      const vmap::Matches vm = matcher.match(fa, fb);
      const double mt = ms_since(t);
      ours.match += mt;
      ours_nocheck.match += mt;
      t = clock_type::now();
      const auto v1 = without_check.verify(fa, fb, vm);
      ours_nocheck.verify += ms_since(t);
      ours_nocheck.inliers += v1.inliers;
      t = clock_type::now();
      const auto v2 = with_check.verify(fa, fb, vm);
      ours.verify += ms_since(t);
      ours.inliers += v2.inliers;
    }
  }
  auto row = [&](const char* name, const Times& x) {
    const double total = x.extract + x.match + x.verify;
    std::printf("%-34s %9.2f %9.2f %9.2f %9.2f %9.3f %12ld\n", name, x.extract / n, x.match / n, x.verify / n,
                total / n, (base.extract + base.match + base.verify) / total, x.inliers);
  };
  std::printf("bench_core: %d consecutive pairs of %s (640x480), ms per pair (two ORB extractions)\n", n,
              list.c_str());
  std::printf("%-34s %9s %9s %9s %9s %9s %12s\n", "", "extract", "match", "verify", "total", "speedup", "sum inliers");
  row("baseline (keyframes_opencv steps)", base);
  row("vmap, degeneracy check off", ours_nocheck);
  row("vmap, default (degeneracy check)", ours);
  std::printf("match step ratio baseline/vmap: %.2f; identical inlier sums (check off): %s\n", base.match / ours.match,
              base.inliers == ours_nocheck.inliers ? "yes" : "no");
  std::printf("CPU's Hamming kernel level: %s (the default matcher's: %s)\n",
              std::string(vmap::to_string(vmap::cpu_hamming_level())).c_str(),
              std::string(vmap::to_string(matcher.hamming_level())).c_str());

  std::vector<vmap::Features> orb_feats, akaze_feats;
  vmap::AkazeDescriptor akaze;
  for (std::size_t i = 0; i < frames.size(); ++i) {
    orb_feats.push_back(vorb.extract(frames[i]));
    if (i <= 50) akaze_feats.push_back(akaze.extract(frames[i]));  // A-KAZE is slow to extract
  }
  match_step("ORB 1000 (32-byte rows)", orb_feats);
  match_step("A-KAZE (61-byte rows)", akaze_feats);
  return 0;
}
