// Key-image selection throughput: vmap against ../shared/baselines/keyframes_opencv.cpp
// in the same run (ORB 1000 + mutual NN + MAGSAC 1 px 0.99, S = inliers / max, eq. 6,
// tau 0.3), where vmap's time goes, and a 9-threshold sweep against one build. vmap runs
// as run_selector's default (two threads decode + extract, the calling thread scores),
// with one preparing thread, on one thread, and on one thread without the bound skip. Then the
// learned configurations against ORB, time per frame on one core and on two
// (cv::setNumThreads): XFeat native (any-size model at the image's resolution, top-k
// 1000), the detector-free XFeat dense front end and XFeat* (the same with the
// refinement network, both as PairKeyframeSelector). PART refine: the cost of XFeat*'s
// refinement per pair for 1000 and 5000 coarse matches, next to the pair's other stages
// and ORB's per-frame cost in the same run.
//
// usage: bench_keyframes [REPEATS=2] [SHARED_DIR] [PART=all|orb|learned|refine] [FRAMES=60]
// (FRAMES: frames of each sequence in the learned part)
// Each timing is the best of REPEATS runs; vmap and the baseline alternate, so both see
// the same machine load. Ratios are what counts on a shared machine.
#include <vmap/core/concepts.hpp>
#include <vmap/features/orb.hpp>
#include <vmap/geometry/fundamental.hpp>
#include <vmap/geometry/similarity.hpp>
#include <vmap/hooks/xfeat.hpp>
#include <vmap/hooks/xfeat_dense.hpp>
#include <vmap/hooks/xfeat_fine.hpp>
#include <vmap/io/atomic_file.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/keyframe/pipeline.hpp>
#include <vmap/keyframe/selector.hpp>
#include <vmap/keyframe/stacks.hpp>
#include <vmap/keyframe/sweep.hpp>
#include <vmap/matching/brute_force.hpp>

#include <opencv2/core/utility.hpp>

#include <sys/resource.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

/// CPU seconds (user + system, all threads) of this process or of its finished children:
/// on a machine shared with other jobs, CPU time is steadier than wall time.
double cpu_seconds(int who) {
  rusage u{};
  getrusage(who, &u);
  return static_cast<double>(u.ru_utime.tv_sec + u.ru_stime.tv_sec) +
         1e-6 * static_cast<double>(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

// ---- timing wrappers: policies that time the policy they hold --------------------------

struct Timers {
  double extract = 0, match = 0, verify = 0;
  int verifications = 0, matchings = 0;
};

struct TimedOrb {
  vmap::OrbDescriptor inner;
  Timers* t;
  vmap::Features extract(const cv::Mat& image) {
    const auto t0 = Clock::now();
    auto f = inner.extract(image);
    t->extract += since(t0);
    return f;
  }
};
struct TimedMatcher {
  vmap::BruteForceMatcher inner;
  Timers* t;
  vmap::Matches match(const vmap::Features& a, const vmap::Features& b) const {
    const auto t0 = Clock::now();
    auto m = inner.match(a, b);
    t->match += since(t0);
    ++t->matchings;
    return m;
  }
};
struct TimedEstimator {
  vmap::FundamentalEstimator inner;
  Timers* t;
  vmap::Verification verify(const vmap::Features& a, const vmap::Features& b, const vmap::Matches& m) const {
    const auto t0 = Clock::now();
    auto v = inner.verify(a, b, m);
    t->verify += since(t0);
    ++t->verifications;
    return v;
  }
};
static_assert(vmap::Descriptor<TimedOrb>);
static_assert(vmap::Matcher<TimedMatcher>);
static_assert(vmap::Estimator<TimedEstimator>);

const vmap::FundamentalOptions kMagsac{.method = vmap::RobustMethod::magsac,
                                       .threshold_px = 1.0,
                                       .confidence = 0.99,
                                       .check_degeneracy = false};

struct VmapRun {
  double seconds = 0;
  double cpu = 0;
  vmap::VisualMap map;
};

VmapRun run_vmap(const std::filesystem::path& input, double tau, bool pipelined, bool skip,
                 std::size_t prepare_threads = 2) {
  const auto t0 = Clock::now();
  const double c0 = cpu_seconds(RUSAGE_SELF);
  auto src = vmap::FrameSource::open(input, {.grey = true});
  vmap::OrbMagsacSelector sel(vmap::OrbDescriptor{}, vmap::BruteForceMatcher{}, vmap::FundamentalEstimator(kMagsac),
                              vmap::InlierRatio{}, {.tau = tau, .skip_by_upper_bound = skip});
  vmap::run_selector(src, sel, {.pipelined = pipelined, .prepare_threads = prepare_threads});
  VmapRun r;
  r.seconds = since(t0);
  r.cpu = cpu_seconds(RUSAGE_SELF) - c0;
  r.map = sel.take_map();
  return r;
}

struct BaselineRun {
  bool ok = false;
  int frames = 0, keys = 0, min = 0, max = 0;
  double mean = 0, q = 0, seconds = 0, fps = 0, cpu = 0;
  std::string line;
};

BaselineRun run_baseline(const std::filesystem::path& list, double tau) {
  BaselineRun b;
  const std::string cmd = std::string("'") + VMAP_BASELINE_KEYFRAMES_OPENCV + "' '" + list.string() + "' " +
                          std::to_string(tau) + " 2>/dev/null";
  const double c0 = cpu_seconds(RUSAGE_CHILDREN);
  {
    std::unique_ptr<FILE, int (*)(FILE*)> pipe(popen(cmd.c_str(), "r"), pclose);
    if (!pipe) return b;
    char buf[512];
    while (std::fgets(buf, sizeof buf, pipe.get())) b.line += buf;
  }  // pclose waits for the child, so its CPU time is counted now
  b.cpu = cpu_seconds(RUSAGE_CHILDREN) - c0;
  b.ok = std::sscanf(b.line.c_str(), "frames %d keys %d min %d max %d mean %lf Q %lf time %lfs fps %lf", &b.frames,
                     &b.keys, &b.min, &b.max, &b.mean, &b.q, &b.seconds, &b.fps) == 8;
  if (!b.line.empty() && b.line.back() == '\n') b.line.pop_back();
  return b;
}

/// A single-threaded run with every stage timed (decode = FrameSource::next).
void time_stages(const std::filesystem::path& input, double tau) {
  Timers t;
  auto src = vmap::FrameSource::open(input, {.grey = true});
  vmap::KeyframeSelector sel(TimedOrb{vmap::OrbDescriptor{}, &t}, TimedMatcher{vmap::BruteForceMatcher{}, &t},
                             TimedEstimator{vmap::FundamentalEstimator(kMagsac), &t}, vmap::InlierRatio{},
                             vmap::SelectorOptions{.tau = tau});
  double decode = 0;
  const auto t0 = Clock::now();
  while (true) {
    const auto td = Clock::now();
    auto f = src.next();
    decode += since(td);
    if (!f) break;
    sel.push(*f);
  }
  const double total = since(t0);
  const double n = static_cast<double>(sel.map().frames);
  const double rest = total - decode - t.extract - t.match - t.verify;
  std::printf("  where the time goes (one thread, %.0f frames, %.2f s):\n", n, total);
  std::printf("    decode   %6.2f ms/frame  %5.1f %%\n", 1e3 * decode / n, 100 * decode / total);
  std::printf("    extract  %6.2f ms/frame  %5.1f %%\n", 1e3 * t.extract / n, 100 * t.extract / total);
  std::printf("    match    %6.2f ms/frame  %5.1f %%  (%d matchings)\n", 1e3 * t.match / n, 100 * t.match / total,
              t.matchings);
  std::printf("    verify   %6.2f ms/frame  %5.1f %%  (%d F-matrix estimations, %d skipped by the bound)\n",
              1e3 * t.verify / n, 100 * t.verify / total, t.verifications, t.matchings - t.verifications);
  std::printf("    other    %6.2f ms/frame  %5.1f %%\n", 1e3 * rest / n, 100 * rest / total);
}

void bench_dataset(const std::string& label, const std::filesystem::path& input, int repeats) {
  constexpr double tau = 0.3;
  // The baseline reads one image path a line.
  auto probe = vmap::FrameSource::open(input);
  std::string list_text;
  for (const auto& p : probe.paths()) list_text += std::filesystem::absolute(p).string() + "\n";
  const auto list = std::filesystem::temp_directory_path() / ("vmap_bench_keyframes_" + label + ".txt");
  vmap::write_file_atomically(list, list_text);

  BaselineRun base;
  VmapRun two, two_one, one, noskip;
  base.seconds = two.seconds = two_one.seconds = one.seconds = noskip.seconds = 1e30;
  for (int r = 0; r < repeats; ++r) {
    const auto b = run_baseline(list, tau);
    if (!b.ok) {
      std::printf("  baseline failed: '%s'\n", b.line.c_str());
      return;
    }
    if (b.seconds < base.seconds) base = b;
    auto v2 = run_vmap(input, tau, true, true);
    if (v2.seconds < two.seconds) two = std::move(v2);
    auto v21 = run_vmap(input, tau, true, true, 1);
    if (v21.seconds < two_one.seconds) two_one = std::move(v21);
    auto v1 = run_vmap(input, tau, false, true);
    if (v1.seconds < one.seconds) one = std::move(v1);
    auto v0 = run_vmap(input, tau, false, false);
    if (v0.seconds < noskip.seconds) noskip = std::move(v0);
  }
  const auto st = two.map.stats();
  std::printf("\n== %s: %s, tau %.1f, best of %d ==\n", label.c_str(), input.string().c_str(), tau, repeats);
  std::printf("  baseline says: %s\n", base.line.c_str());
  std::printf("  %-30s %6s %5s %4s %4s %6s %6s %8s %7s %7s %8s\n", "", "frames", "keys", "min", "max", "mean", "Q",
              "wall s", "fps", "cpu s", "fps x");
  std::printf("  %-30s %6d %5d %4d %4d %6.1f %6.3f %8.2f %7.1f %7.2f\n", "baseline keyframes_opencv", base.frames,
              base.keys, base.min, base.max, base.mean, base.q, base.seconds, base.frames / base.seconds, base.cpu);
  auto row = [&](const char* name, const VmapRun& r) {
    const auto s = r.map.stats();
    std::printf("  %-30s %6zu %5zu %4d %4d %6.1f %6.3f %8.2f %7.1f %7.2f %7.2fx\n", name, s.frames, s.key_images,
                s.min_matches, s.max_matches, s.mean_matches, s.quality, r.seconds,
                static_cast<double>(s.frames) / r.seconds, r.cpu, base.seconds / r.seconds);
  };
  row("vmap (2 threads, bound skip)", two);
  row("vmap (2 thr, 1 preparing)", two_one);
  row("vmap (1 thread, bound skip)", one);
  row("vmap (1 thread, no skip)", noskip);
  std::printf("  key images: vmap %zu, baseline %d -> %s\n", st.key_images, base.keys,
              static_cast<int>(st.key_images) == base.keys && st.min_matches == base.min && st.max_matches == base.max
                  ? "same count and same inlier min/max"
                  : "DIFFERENT");
  const bool same_modes = two.map.key_indices() == one.map.key_indices() &&
                          two_one.map.key_indices() == one.map.key_indices() &&
                          one.map.key_indices() == noskip.map.key_indices();
  std::printf("  vmap key images identical across threads/skip modes: %s\n", same_modes ? "yes" : "NO");
  std::printf("  fps ratio vmap/baseline: %.2fx (2 threads), %.2fx (1 thread); CPU-time ratio baseline/vmap: %.2fx "
              "(2 threads), %.2fx (1 thread)\n",
              base.seconds / two.seconds, base.seconds / one.seconds, base.cpu / two.cpu, base.cpu / one.cpu);
  time_stages(input, tau);

  // A 9-threshold sweep against one build (both with the second thread).
  double sweep_s = 1e30, sweep_cpu = 0;
  vmap::SweepResult sweep;
  for (int r = 0; r < repeats; ++r) {
    const auto t0 = Clock::now();
    const double c0 = cpu_seconds(RUSAGE_SELF);
    auto src = vmap::FrameSource::open(input, {.grey = true});
    auto res = vmap::sweep_thresholds(src, vmap::OrbDescriptor{}, vmap::BruteForceMatcher{},
                                      vmap::FundamentalEstimator(kMagsac), vmap::InlierRatio{});
    const double s = since(t0);
    if (s < sweep_s) {
      sweep_s = s;
      sweep_cpu = cpu_seconds(RUSAGE_SELF) - c0;
      sweep = std::move(res);
    }
  }
  const auto row3 = std::find_if(sweep.rows.begin(), sweep.rows.end(), [](const auto& r) { return r.threshold == 0.3; });
  std::printf("  sweep of 9 thresholds: %.2f s = %.2fx one build (%.2f s); CPU %.2f s = %.2fx one build's (%.2f s)\n",
              sweep_s, sweep_s / two.seconds, two.seconds, sweep_cpu, sweep_cpu / two.cpu, two.cpu);
  std::printf("  sweep: tau 0.3 row %s the build; %zu of %zu pair scores from the cache\n",
              row3 != sweep.rows.end() && row3->key_frames == two.map.key_indices() ? "equals" : "DIFFERS FROM",
              sweep.pair_requests - sweep.pairs_scored, sweep.pair_requests);
  std::filesystem::remove(list);
}

// ---- learned configurations against ORB --------------------------------------------

struct ConfigRun {
  double seconds = 1e30;  // best wall time of the repeats
  vmap::VisualMap map;
};

/// One streaming selection (no pipelining: the selector's thread plus OpenCV's own pool
/// of cv::getNumThreads() threads), best of `repeats`.
template <class MakeSelector>
ConfigRun time_config(const std::vector<cv::Mat>& frames, int repeats, MakeSelector make) {
  ConfigRun best;
  for (int r = 0; r < repeats; ++r) {
    auto sel = make();  // model loading is not timed
    const auto t0 = Clock::now();
    for (const cv::Mat& f : frames) sel.push(f);
    const double s = since(t0);
    if (s < best.seconds) {
      best.seconds = s;
      best.map = sel.take_map();
    }
  }
  return best;
}

void bench_learned(const std::string& label, const std::filesystem::path& input, const std::filesystem::path& model,
                   const std::filesystem::path& fine, std::size_t count, int repeats) {
  constexpr double tau = 0.3;
  std::vector<cv::Mat> frames;
  {
    auto src = vmap::FrameSource::open(input, {.end = count, .grey = true});
    while (auto f = src.next()) frames.push_back(f->image);
  }
  const double n = static_cast<double>(frames.size());
  const vmap::SelectorOptions so{.tau = tau};
  std::printf("\n== %s: learned configurations against ORB, first %zu frames, tau %.1f, best of %d ==\n",
              label.c_str(), frames.size(), tau, repeats);
  std::printf("  %-34s %7s %5s %7s %6s %11s %11s %9s\n", "", "threads", "keys", "mean", "Q", "ms/frame", "x ORB",
              "x 1 thr");
  std::vector<double> one_core(4, 0.0);
  for (const int threads : {1, 2}) {
    cv::setNumThreads(threads);
    const ConfigRun orb = time_config(frames, repeats, [&] {
      return vmap::KeyframeSelector(vmap::OrbDescriptor{}, vmap::BruteForceMatcher{},
                                    vmap::FundamentalEstimator(kMagsac), vmap::InlierRatio{}, so);
    });
    const ConfigRun native = time_config(frames, repeats, [&] {
      return vmap::KeyframeSelector(vmap::XFeatDescriptor({.model = model, .top_k = 1000}),
                                    vmap::BruteForceMatcher{}, vmap::FundamentalEstimator(kMagsac),
                                    vmap::InlierRatio{}, so);
    });
    const ConfigRun dense = time_config(frames, repeats, [&] {
      return vmap::PairKeyframeSelector(vmap::XFeatDenseMatcher({.model = model}),
                                        vmap::FundamentalEstimator(kMagsac), so);
    });
    const ConfigRun star = time_config(frames, repeats, [&] {
      return vmap::PairKeyframeSelector(vmap::XFeatDenseMatcher({.model = model}, vmap::XFeatFineOptions{.model = fine}),
                                        vmap::FundamentalEstimator(kMagsac), so);
    });
    const ConfigRun* runs[] = {&orb, &native, &dense, &star};
    const char* names[] = {"ORB 1000 + MAGSAC", "XFeat native top-1000 + MAGSAC", "XFeat dense (PairMatcher) + MAGSAC",
                           "XFeat* (PairMatcher) + MAGSAC"};
    for (std::size_t k = 0; k < 4; ++k) {
      const auto st = runs[k]->map.stats();
      const double ms = 1e3 * runs[k]->seconds / n;
      if (threads == 1) one_core[k] = ms;
      std::printf("  %-34s %7d %5zu %7.1f %6.3f %11.1f %10.1fx %8.2fx\n", names[k], threads, st.key_images,
                  st.mean_matches, st.quality, ms, runs[k]->seconds / orb.seconds, one_core[k] / ms);
    }
  }
  cv::setNumThreads(-1);  // back to OpenCV's default
}

/// Median wall time of `repeats` calls of f, in ms.
template <class F>
double median_ms(int repeats, F&& f) {
  std::vector<double> t;
  for (int r = 0; r < repeats; ++r) {
    const auto t0 = Clock::now();
    f();
    t.push_back(1e3 * since(t0));
  }
  std::sort(t.begin(), t.end());
  return t[t.size() / 2];
}

/// XFeat*'s refinement per pair: one batched network call for N coarse matches (the
/// matches of a TUM pair, repeated to reach N), next to the pair's coarse mutual NN, its
/// MAGSAC++ and XFeat's forward pass, and ORB's whole per-frame cost (extract + match +
/// verify), in the same run and with the same OpenCV thread setting.
void bench_refine(const std::filesystem::path& shared, int repeats) {
  const int reps = std::max(5, 3 * repeats);
  std::vector<cv::Mat> frames;
  {
    auto src = vmap::FrameSource::open(shared / "data/tum_fr1_rpy/rgb.txt", {.end = 6, .grey = true});
    while (auto f = src.next()) frames.push_back(f->image);
  }
  const cv::Mat& a = frames.front();
  const cv::Mat& b = frames.back();
  vmap::XFeatDenseDescriptor grid({.model = shared / "models/xfeat_anysize.onnx", .grid = vmap::XFeatGrid::refinable});
  vmap::XFeatRefiner refiner({.model = shared / "models/xfeat_fine.onnx"});
  const vmap::DenseMutualMatcher coarse({.normalise = true});
  const vmap::FundamentalEstimator magsac(kMagsac);
  vmap::OrbDescriptor orb;
  const vmap::BruteForceMatcher bf;
  for (const int threads : {1, 2}) {
    cv::setNumThreads(threads);
    vmap::Features fa, fb;
    const double forward = median_ms(reps, [&] { fa = grid.extract(a); });
    fb = grid.extract(b);
    vmap::Matches m;
    const double nn = median_ms(reps, [&] { m = coarse.match(fa, fb); });
    vmap::Features pa, pb;
    for (const cv::DMatch& d : m) {
      pa.keypoints.push_back(fa.keypoints[static_cast<std::size_t>(d.queryIdx)]);
      pb.keypoints.push_back(fb.keypoints[static_cast<std::size_t>(d.trainIdx)]);
    }
    vmap::Matches one_to_one;
    for (int i = 0; i < static_cast<int>(m.size()); ++i) one_to_one.emplace_back(i, i, 0.0f);
    const double verify = median_ms(reps, [&] { (void)magsac.verify(pa, pb, one_to_one); });
    vmap::Features oa, ob;
    const double orb_frame = median_ms(reps, [&] {
      oa = orb.extract(a);
      ob = orb.extract(b);
      (void)magsac.verify(oa, ob, bf.match(oa, ob));
    }) / 2.0;  // two extractions per call: one per frame, as a selector does
    std::printf("\n== XFeat* refinement per pair (tum_fr1_rpy frames 0 and 5, %d OpenCV thread%s, median of %d) ==\n",
                threads, threads == 1 ? "" : "s", reps);
    std::printf("  ORB 1000 per frame (extract, match, MAGSAC)   %8.2f ms\n", orb_frame);
    std::printf("  XFeat forward pass (640x480, 4800 cells)      %8.2f ms  %6.2fx ORB frame\n", forward,
                forward / orb_frame);
    std::printf("  coarse mutual NN, 4800 x 4800 cells           %8.2f ms  %6.2fx  (%zu matches)\n", nn,
                nn / orb_frame, m.size());
    std::printf("  MAGSAC++ on the %zu coarse matches           %8.2f ms  %6.2fx\n", m.size(), verify,
                verify / orb_frame);
    for (const std::size_t n : {std::size_t{1000}, std::size_t{5000}}) {
      vmap::Matches batch;
      for (std::size_t i = 0; i < n; ++i) batch.push_back(m[i % m.size()]);
      std::vector<vmap::FineOffset> offsets;
      const double ms = median_ms(reps, [&] { refiner.refine(fa.descriptors, fb.descriptors, batch, offsets); });
      std::printf("  refinement of %4zu coarse matches             %8.2f ms  %6.2fx  (%.1f us a match)\n", n, ms,
                  ms / orb_frame, 1e3 * ms / static_cast<double>(n));
    }
  }
  cv::setNumThreads(-1);
}

}  // namespace

int main(int argc, char** argv) {
  const int repeats = argc > 1 ? std::max(1, std::atoi(argv[1])) : 2;
  const std::filesystem::path shared = argc > 2 ? argv[2] : VMAP_SHARED_DIR;
  const std::string part = argc > 3 ? argv[3] : "all";
  const std::size_t learned_frames = argc > 4 ? static_cast<std::size_t>(std::max(2, std::atoi(argv[4]))) : 60;
  if (part != "all" && part != "orb" && part != "learned" && part != "refine") {
    std::fprintf(stderr, "bench_keyframes: PART must be all, orb, learned or refine, got '%s'\n", part.c_str());
    return 2;
  }
  try {
    if (part == "refine") {
      bench_refine(shared, repeats);
      return 0;
    }
    if (part != "learned") {
      bench_dataset("tum_fr1_rpy", shared / "data/tum_fr1_rpy/rgb.txt", repeats);
      bench_dataset("kitti07_160", shared / "data/kitti07_160/image_0", repeats);
    }
    if (part != "orb") {
      // 60 frames each by default: the dense front end costs ~0.2-0.5 s a frame on this CPU.
      const auto model = shared / "models/xfeat_anysize.onnx", fine = shared / "models/xfeat_fine.onnx";
      bench_learned("tum_fr1_rpy", shared / "data/tum_fr1_rpy/rgb.txt", model, fine, learned_frames, repeats);
      bench_learned("kitti07_160", shared / "data/kitti07_160/image_0", model, fine, learned_frames, repeats);
      bench_refine(shared, repeats);
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_keyframes: %s\n", e.what());
    return 1;
  }
  return 0;
}
