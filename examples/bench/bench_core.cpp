// Benchmark of the core per-pair steps (ORB extract, match, MAGSAC verification) on
// 640x480 TUM fr1_rpy frames, against the same steps written as in
// ../shared/baselines/keyframes_opencv.cpp, interleaved pair by pair in one run so the
// shared machine's noise hits both alike. Prints mean milliseconds and ratios.
//
// usage: bench_core [RGB_TXT] [PAIRS]
#include <vmap/features/orb.hpp>
#include <vmap/geometry/fundamental.hpp>
#include <vmap/geometry/similarity.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/matching/brute_force.hpp>

#include <opencv2/calib3d.hpp>
#include <opencv2/features2d.hpp>

#include <chrono>
#include <cstdio>
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
  return 0;
}
