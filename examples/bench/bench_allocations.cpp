// Heap allocations and speed of the key-image selector's per-frame path, on
// the first frames of a TUM sequence with the paper's stack
// (OrbMagsacSelector default-constructed: ORB 1000, mutual NN, MAGSAC++ 1 px 0.99 with
// the homography degeneracy check, eq. 5, tau 0.3).
//
//  1. Allocations per warm push(Frame): global operator new/delete are replaced by
//     counting versions, and so is the C heap (malloc, posix_memalign, ...), because
//     OpenCV's cv::Mat buffers come from cv::fastMalloc, not operator new.
//  2. The OpenCV calls of the same frames and pairs alone (ORB detectAndCompute,
//     findFundamentalMat, findHomography): what is theirs; the rest is vmap's.
//  3. Speed: the selector's scoring (push of already prepared frames: match + verify)
//     in verifications/s, and FundamentalEstimator::verify with and without the
//     homography check on the same pairs.
//  4. precision_recall_curve against the per-threshold rescan it replaced (equality and
//     speed ratio) on a large synthetic score list.
//
// The program uses only API that existed before the change, so the same file built at
// the parent commit gives the 'before' figures (see examples/results/keyframes.md).
//
// usage: bench_allocations [RGB_TXT] [FRAMES=60] [WARM=5] [PR_FRAMES=2000]
#include <vmap/io/frame_source.hpp>
#include <vmap/keyframe/selector.hpp>
#include <vmap/keyframe/stacks.hpp>
#include <vmap/lcd/evaluation.hpp>

#include <opencv2/calib3d.hpp>
#include <opencv2/features2d.hpp>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <functional>
#include <new>
#include <random>
#include <string>
#include <vector>

// ---- counting allocators ---------------------------------------------------------------

extern "C" {
void* __libc_malloc(std::size_t);
void* __libc_calloc(std::size_t, std::size_t);
void* __libc_realloc(void*, std::size_t);
void* __libc_memalign(std::size_t, std::size_t);
void __libc_free(void*);
}

namespace {

struct Counter {
  std::atomic<std::uint64_t> calls{0};
  std::atomic<std::uint64_t> bytes{0};
  void add(std::size_t n) {
    calls.fetch_add(1, std::memory_order_relaxed);
    bytes.fetch_add(n, std::memory_order_relaxed);
  }
};

std::atomic<bool> g_counting{false};
Counter g_new;     // operator new / new[] (C++ containers, std::string, cv::Ptr, ...)
Counter g_c_heap;  // malloc, calloc, realloc, posix_memalign, ... (cv::Mat buffers)

struct Count {
  std::uint64_t new_calls = 0, new_bytes = 0, c_calls = 0, c_bytes = 0;
  [[nodiscard]] std::uint64_t calls() const { return new_calls + c_calls; }
  [[nodiscard]] std::uint64_t bytes() const { return new_bytes + c_bytes; }
  Count& operator+=(const Count& o) {
    new_calls += o.new_calls;
    new_bytes += o.new_bytes;
    c_calls += o.c_calls;
    c_bytes += o.c_bytes;
    return *this;
  }
};

Count snapshot() {
  return {g_new.calls.load(), g_new.bytes.load(), g_c_heap.calls.load(), g_c_heap.bytes.load()};
}

/// Allocations made while `f` runs (every thread: OpenCV's parallel loops included).
template <class F>
Count count_allocations(F&& f) {
  const Count before = snapshot();
  g_counting.store(true);
  f();
  g_counting.store(false);
  const Count after = snapshot();
  return {after.new_calls - before.new_calls, after.new_bytes - before.new_bytes, after.c_calls - before.c_calls,
          after.c_bytes - before.c_bytes};
}

void* counted_new(std::size_t n) {
  if (g_counting.load(std::memory_order_relaxed)) g_new.add(n);
  void* p = __libc_malloc(n == 0 ? 1 : n);  // not malloc(): counted once, as new
  if (!p) throw std::bad_alloc();
  return p;
}

void* counted_new_aligned(std::size_t n, std::align_val_t al) {
  if (g_counting.load(std::memory_order_relaxed)) g_new.add(n);
  void* p = __libc_memalign(static_cast<std::size_t>(al), n == 0 ? 1 : n);
  if (!p) throw std::bad_alloc();
  return p;
}

}  // namespace

void* operator new(std::size_t n) { return counted_new(n); }
void* operator new[](std::size_t n) { return counted_new(n); }
void* operator new(std::size_t n, const std::nothrow_t&) noexcept {
  try {
    return counted_new(n);
  } catch (...) {
    return nullptr;
  }
}
void* operator new[](std::size_t n, const std::nothrow_t&) noexcept {
  try {
    return counted_new(n);
  } catch (...) {
    return nullptr;
  }
}
void* operator new(std::size_t n, std::align_val_t al) { return counted_new_aligned(n, al); }
void* operator new[](std::size_t n, std::align_val_t al) { return counted_new_aligned(n, al); }
void operator delete(void* p) noexcept { __libc_free(p); }
void operator delete[](void* p) noexcept { __libc_free(p); }
void operator delete(void* p, std::size_t) noexcept { __libc_free(p); }
void operator delete[](void* p, std::size_t) noexcept { __libc_free(p); }
void operator delete(void* p, std::align_val_t) noexcept { __libc_free(p); }
void operator delete[](void* p, std::align_val_t) noexcept { __libc_free(p); }
void operator delete(void* p, std::size_t, std::align_val_t) noexcept { __libc_free(p); }
void operator delete[](void* p, std::size_t, std::align_val_t) noexcept { __libc_free(p); }

// The C heap, interposed for the whole process (OpenCV's shared library included).
extern "C" {
void* malloc(std::size_t n) noexcept {
  if (g_counting.load(std::memory_order_relaxed)) g_c_heap.add(n);
  return __libc_malloc(n);
}
void* calloc(std::size_t k, std::size_t n) noexcept {
  if (g_counting.load(std::memory_order_relaxed)) g_c_heap.add(k * n);
  return __libc_calloc(k, n);
}
void* realloc(void* p, std::size_t n) noexcept {
  if (g_counting.load(std::memory_order_relaxed)) g_c_heap.add(n);
  return __libc_realloc(p, n);
}
int posix_memalign(void** out, std::size_t al, std::size_t n) noexcept {
  if (g_counting.load(std::memory_order_relaxed)) g_c_heap.add(n);
  void* p = __libc_memalign(al, n);
  if (!p) return ENOMEM;
  *out = p;
  return 0;
}
void* aligned_alloc(std::size_t al, std::size_t n) noexcept {
  if (g_counting.load(std::memory_order_relaxed)) g_c_heap.add(n);
  return __libc_memalign(al, n);
}
void* memalign(std::size_t al, std::size_t n) noexcept {
  if (g_counting.load(std::memory_order_relaxed)) g_c_heap.add(n);
  return __libc_memalign(al, n);
}
void free(void* p) noexcept { __libc_free(p); }
}

// ---- the benchmark -----------------------------------------------------------------------

namespace {

using clock_type = std::chrono::steady_clock;
double seconds_since(clock_type::time_point t) {
  return std::chrono::duration<double>(clock_type::now() - t).count();
}

/// CPU time of the calling thread: what a timed loop cost, whatever else the shared
/// machine runs (the loops below are single-threaded: matching and MAGSAC++).
double thread_cpu_seconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

void print_count(const char* what, const Count& c, double per) {
  std::printf("  %-44s %9.1f allocations %11.0f bytes   (new: %.1f / %.0f B, C heap: %.1f / %.0f B)\n", what,
              static_cast<double>(c.calls()) / per, static_cast<double>(c.bytes()) / per,
              static_cast<double>(c.new_calls) / per, static_cast<double>(c.new_bytes) / per,
              static_cast<double>(c.c_calls) / per, static_cast<double>(c.c_bytes) / per);
}

// The PR curve as it was: evaluate_loops at every distinct proposed score.
std::vector<vmap::PrecisionRecall> rescanning_curve(const std::vector<vmap::LoopScore>& scores,
                                                    const vmap::LoopGroundTruth& gt) {
  std::vector<double> thresholds;
  for (const auto& s : scores)
    if (s.match) thresholds.push_back(s.score);
  std::sort(thresholds.begin(), thresholds.end(), std::greater<>());
  thresholds.erase(std::unique(thresholds.begin(), thresholds.end()), thresholds.end());
  std::vector<vmap::PrecisionRecall> curve;
  for (double t : thresholds) curve.push_back(vmap::evaluate_loops(scores, gt, t));
  return curve;
}

bool same_curve(const std::vector<vmap::PrecisionRecall>& a, const std::vector<vmap::PrecisionRecall>& b) {
  if (a.size() != b.size()) return false;
  for (std::size_t i = 0; i < a.size(); ++i)
    if (a[i].threshold != b[i].threshold || a[i].true_positives != b[i].true_positives ||
        a[i].false_positives != b[i].false_positives || a[i].false_negatives != b[i].false_negatives ||
        a[i].precision != b[i].precision || a[i].recall != b[i].recall)
      return false;
  return true;
}

/// True when this build has the buffer-reusing estimator (the 'after' code).
template <class E>
concept DefersDegeneracy = requires(const E& e, vmap::Verification& v, typename E::Scratch& s) {
  e.verify_into(vmap::Features{}, vmap::Features{}, vmap::Matches{}, v, s, true);
};

struct Pair {
  std::size_t key = 0, frame = 0;  // positions in the loaded frames
  bool verified_run = false;
};

}  // namespace

int main(int argc, char** argv) {
  std::string list = argc > 1 ? argv[1] : std::string(VMAP_SHARED_DIR) + "/data/tum_fr1_rpy/rgb.txt";
  if (argc <= 1 && !std::filesystem::exists(list))
    list = std::string(VMAP_SOURCE_DIR) + "/examples/data/tum_fr1_rpy_60/rgb.txt";
  const std::size_t n_frames = argc > 2 ? std::stoul(argv[2]) : 60;
  const std::size_t warm = argc > 3 ? std::stoul(argv[3]) : 5;
  const std::size_t pr_frames = argc > 4 ? std::stoul(argv[4]) : 2000;

  std::vector<vmap::Frame> frames;
  auto source = vmap::FrameSource::open(list, {.end = n_frames, .grey = true});
  while (auto f = source.next()) frames.push_back(std::move(*f));
  if (frames.size() <= warm + 1) {
    std::fprintf(stderr, "bench_allocations: need more than %zu frames in %s\n", warm + 1, list.c_str());
    return 1;
  }
  const std::size_t n = frames.size();
  constexpr bool deferring = DefersDegeneracy<vmap::FundamentalEstimator>;
  std::printf("bench_allocations: %zu frames of %s, OrbMagsacSelector (default options), %zu warm-up pushes\n", n,
              list.c_str(), warm);
  std::printf("this build: %s\n", deferring ? "buffers reused, degeneracy check deferred (after)"
                                            : "allocating per call, degeneracy check eager (before)");

  // ---- 1. allocations per push, two passes ------------------------------------------
  // Pass 1: a fresh selector; its first `warm` pushes are not counted. Pass 2: the same
  // selector after reset() (map and key gone, buffers kept), every push but the first
  // counted: the steady state of a long run, whose buffers have seen these sizes.
  vmap::OrbMagsacSelector selector;
  struct Pass {
    std::vector<Count> per_push;
    std::vector<vmap::FrameResult> results;
    std::vector<std::size_t> key_of;  // the key image frame i was scored against
  };
  auto run_pass = [&](Pass& pass) {
    pass.per_push.assign(n, Count{});
    pass.results.assign(n, vmap::FrameResult{});
    pass.key_of.assign(n, 0);
    for (std::size_t i = 0; i < n; ++i) {
      pass.key_of[i] = selector.map().keys.empty() ? 0 : selector.map().keys.back().frame_index;
      vmap::FrameResult r;
      pass.per_push[i] = count_allocations([&] { r = selector.push(frames[i]); });
      pass.results[i] = r;
    }
  };
  Pass pass1, pass2;
  run_pass(pass1);
  const auto keys = selector.map().key_indices();
  selector.reset();
  run_pass(pass2);
  if (selector.map().key_indices() != keys) {
    std::fprintf(stderr, "bench_allocations: the second pass gave other key images\n");
    return 1;
  }
  std::printf("\nkey images:");
  for (const auto k : keys) std::printf(" %zu", k);
  std::printf(" (%zu of %zu frames)\n", keys.size(), n);

  // ---- 2. OpenCV's own calls on the same frames and pairs ---------------------------
  std::vector<vmap::Features> features(n);
  {
    vmap::OrbDescriptor orb;
    for (std::size_t i = 0; i < n; ++i) features[i] = orb.extract(frames[i].image);
  }
  // Per push i: what OpenCV's calls allocate on that push's frame and pair.
  std::vector<Count> orb_at(n), f_at(n), h_at(n);
  Count orb_count, f_count, h_count;
  std::size_t f_calls = 0, h_calls = 0;
  {
    const vmap::OrbOptions o;
    auto orb = cv::ORB::create(o.features, o.scale_factor, o.levels, o.edge_threshold, 0, 2, cv::ORB::HARRIS_SCORE,
                               o.edge_threshold, o.fast_threshold);
    for (std::size_t i = 0; i < warm; ++i) {  // the same warm-up as the selector had
      std::vector<cv::KeyPoint> kp;
      cv::Mat d;
      orb->detectAndCompute(frames[i].image, cv::noArray(), kp, d);
    }
    for (std::size_t i = 0; i < n; ++i) {
      std::vector<cv::KeyPoint> kp;
      cv::Mat d;
      orb_at[i] = count_allocations([&] { orb->detectAndCompute(frames[i].image, cv::noArray(), kp, d); });
      orb_count += orb_at[i];
    }
  }
  const vmap::BruteForceMatcher matcher;
  const vmap::FundamentalOptions fo;
  {
    cv::Mat mask, hmask;  // output buffers kept across calls: only OpenCV's internals count
    for (std::size_t i = 1; i < n; ++i) {
      if (!pass1.results[i].exact) continue;  // the bound skipped the estimator
      const vmap::Features& key = features[pass1.key_of[i]];
      const vmap::Matches m = matcher.match(key, features[i]);
      std::vector<cv::Point2f> pa, pb;
      for (const auto& d : m) {
        pa.push_back(key.keypoints[static_cast<std::size_t>(d.queryIdx)].pt);
        pb.push_back(features[i].keypoints[static_cast<std::size_t>(d.trainIdx)].pt);
      }
      if (pa.size() < 8) continue;
      cv::Mat F;
      f_at[i] = count_allocations([&] {
        F = cv::findFundamentalMat(pa, pb, cv::USAC_MAGSAC, fo.threshold_px, fo.confidence, fo.max_iterations, mask);
      });
      f_count += f_at[i];
      ++f_calls;
      if (F.rows != 3 || cv::countNonZero(mask) < fo.min_inliers) continue;
      std::vector<cv::Point2f> ia, ib;
      for (std::size_t k = 0; k < pa.size(); ++k)
        if (mask.ptr<std::uint8_t>()[k] != 0) {
          ia.push_back(pa[k]);
          ib.push_back(pb[k]);
        }
      h_at[i] = count_allocations([&] {
        (void)cv::findHomography(ia, ib, cv::RANSAC, 2.0 * fo.threshold_px, hmask, 2000, fo.confidence);
      });
      h_count += h_at[i];
      ++h_calls;
    }
  }
  std::printf("\nOpenCV's calls alone on the same frames and pairs (per call, output buffers kept):\n");
  print_count("ORB detectAndCompute (with its output)", orb_count, static_cast<double>(n));
  if (f_calls > 0) print_count("findFundamentalMat USAC_MAGSAC", f_count, static_cast<double>(f_calls));
  if (h_calls > 0) print_count("findHomography RANSAC (degeneracy check)", h_count, static_cast<double>(h_calls));

  auto report = [&](const char* title, const Pass& pass, std::size_t first) {
    Count all, kept, key;
    std::size_t n_kept = 0, n_key = 0;
    double ours_calls = 0, ours_bytes = 0, lo = 1e18, hi = -1e18;
    for (std::size_t i = first; i < n; ++i) {
      all += pass.per_push[i];
      if (pass.results[i].key_taken) {
        key += pass.per_push[i];
        ++n_key;
        continue;
      }
      kept += pass.per_push[i];
      ++n_kept;
      // A push without a key change makes exactly these OpenCV calls (a key change also
      // scores an extra pair and copies the key's features into the map).
      Count theirs = orb_at[i];
      theirs += f_at[i];
      if (!deferring) theirs += h_at[i];  // the eager check fits a homography on every verified pair
      const double c = static_cast<double>(pass.per_push[i].calls()) - static_cast<double>(theirs.calls());
      ours_calls += c;
      ours_bytes += static_cast<double>(pass.per_push[i].bytes()) - static_cast<double>(theirs.bytes());
      lo = std::min(lo, c);
      hi = std::max(hi, c);
    }
    std::printf("\n%s\n", title);
    print_count("every counted push", all, static_cast<double>(n - first));
    if (n_key > 0) print_count("pushes that add a key image", key, static_cast<double>(n_key));
    if (n_kept > 0) {
      print_count("pushes without a key change", kept, static_cast<double>(n_kept));
      std::printf("  %-44s %9.2f allocations %11.0f bytes   (min %.0f, max %.0f over %zu pushes)\n",
                  "  of which vmap's own (push - its OpenCV calls)", ours_calls / static_cast<double>(n_kept),
                  ours_bytes / static_cast<double>(n_kept), lo, hi, n_kept);
    }
  };
  report("1a. allocations per push(Frame), first pass, pushes after the warm-up (vmap + OpenCV)", pass1, warm);
  report("1b. allocations per push(Frame), second pass after reset() (steady state)", pass2, 1);

  // Pairs the selector verified, for the speed section.
  std::vector<Pair> pairs;
  for (std::size_t i = 1; i < n; ++i) pairs.push_back({pass1.key_of[i], i, pass1.results[i].exact});

  // ---- 3. speed --------------------------------------------------------------------
  std::printf("\n3. speed (5 repetitions, median)\n");
  {
    std::vector<double> t_push, cpu_push;
    std::size_t verifications = 0;
    for (int rep = 0; rep < 5; ++rep) {
      vmap::OrbMagsacSelector s;
      std::vector<vmap::OrbMagsacSelector::Prepared> prepared;
      prepared.reserve(n);
      for (std::size_t i = 0; i < n; ++i)
        prepared.push_back({features[i], frames[i].index, frames[i].name, frames[i].timestamp, {}});
      verifications = 0;
      const auto t = clock_type::now();
      const double c = thread_cpu_seconds();
      for (auto& p : prepared) verifications += s.push(std::move(p)).exact ? 1 : 0;
      cpu_push.push_back(thread_cpu_seconds() - c);
      t_push.push_back(seconds_since(t));
      if (s.map().key_indices() != keys) {
        std::fprintf(stderr, "bench_allocations: prepared pushes gave other key images\n");
        return 1;
      }
    }
    verifications -= 1;  // the first frame is not scored
    const double t = median(t_push), c = median(cpu_push);
    std::printf("  selector push(prepared): %zu pushes, %zu verified; wall %.2f ms per push, %.1f verifications/s; "
                "thread CPU %.2f ms per push, %.1f verifications per CPU-second\n",
                n, verifications, 1000.0 * t / static_cast<double>(n), static_cast<double>(verifications) / t,
                1000.0 * c / static_cast<double>(n), static_cast<double>(verifications) / c);
  }
  {
    const vmap::FundamentalEstimator with_check;
    const vmap::FundamentalEstimator without_check({.check_degeneracy = false});
    std::vector<vmap::Matches> matches;
    std::vector<const Pair*> verified;
    for (const Pair& p : pairs)
      if (p.verified_run) {
        matches.push_back(matcher.match(features[p.key], features[p.frame]));
        verified.push_back(&p);
      }
    std::vector<double> t_on, t_off, c_on, c_off;
    for (int rep = 0; rep < 5; ++rep) {
      for (int variant = 0; variant < 2; ++variant) {
        const auto& est = variant == 0 ? with_check : without_check;
        const auto t = clock_type::now();
        const double c = thread_cpu_seconds();
        for (std::size_t k = 0; k < verified.size(); ++k)
          (void)est.verify(features[verified[k]->key], features[verified[k]->frame], matches[k]);
        (variant == 0 ? c_on : c_off).push_back(thread_cpu_seconds() - c);
        (variant == 0 ? t_on : t_off).push_back(seconds_since(t));
      }
    }
    const double on = median(t_on), off = median(t_off), con = median(c_on), coff = median(c_off);
    const double count = static_cast<double>(verified.size());
    std::printf("  FundamentalEstimator::verify on the selector's %zu verified pairs: with the homography check "
                "%.1f/s, without %.1f/s (ratio %.2f); per CPU-second %.1f and %.1f (ratio %.2f)\n",
                verified.size(), count / on, count / off, on / off, count / con, count / coff, con / coff);
  }

  // ---- 4. PR curve -------------------------------------------------------------------
  {
    std::mt19937_64 rng(7);
    vmap::LoopGroundTruth gt(pr_frames);
    std::bernoulli_distribution revisit(0.3);
    for (std::size_t q = 100; q < pr_frames; ++q)
      if (revisit(rng)) {
        const std::size_t centre = std::uniform_int_distribution<std::size_t>(0, q - 100)(rng);
        for (std::size_t f = centre; f < std::min(q - 50, centre + 10); ++f) gt.set(q, f, true);
      }
    std::vector<vmap::LoopScore> scores;
    std::uniform_int_distribution<int> grid(0, 5000);  // ties: 5001 levels
    for (std::size_t q = 0; q < pr_frames; ++q) {
      vmap::LoopScore s{q, std::nullopt, grid(rng) * 0.01};
      if (q > 0 && revisit(rng)) s.match = std::uniform_int_distribution<std::size_t>(0, q - 1)(rng);
      if (q >= 100 && gt.has_loop(q) && revisit(rng)) s.match = q - 60;  // some correct, some not
      scores.push_back(s);
    }
    // Thread CPU time (the library's curve takes about a millisecond: wall time would
    // mostly measure the shared machine); median of 21 and of 3 runs.
    std::vector<double> t_new, t_old;
    bool same = true;
    std::vector<vmap::PrecisionRecall> fast;
    for (int rep = 0; rep < 21; ++rep) {
      const double c = thread_cpu_seconds();
      fast = vmap::precision_recall_curve(scores, gt);
      t_new.push_back(thread_cpu_seconds() - c);
    }
    for (int rep = 0; rep < 3; ++rep) {
      const double c = thread_cpu_seconds();
      const auto slow = rescanning_curve(scores, gt);
      t_old.push_back(thread_cpu_seconds() - c);
      same = same && same_curve(fast, slow);
    }
    const double a = median(t_new), b = median(t_old);
    std::printf("\n4. precision_recall_curve on %zu synthetic frames (%zu loop frames, %zu curve points), thread CPU\n",
                pr_frames, gt.loop_frames(), fast.size());
    std::printf("  library %.3f ms, per-threshold rescan %.3f ms, ratio %.1f, identical points: %s\n", 1000 * a,
                1000 * b, b / a, same ? "yes" : "NO");
    if (!same) return 1;
  }
  return 0;
}
