#pragma once

// Threshold sweep (García-Pintos et al. 2023, the tables of sec. 4): the same video
// selected at several tau, with the paper's columns (threshold, key images, min / max /
// mean verified matches between consecutive key images, quality eq. 7).
//
// Cost: each frame is decoded and its features extracted once (on a second thread,
// overlapped with the selection), and every threshold's BasicKeyframeSelector runs in
// lockstep over the shared features; a (key image, frame) pair that several thresholds
// compare at the same moment is matched and verified once (a per-pair cache). Before
// the selectors see frame j, the distinct pairs (their key images, j) are scored in
// parallel (two threads); each pair's score is a pure function of the pair,
// so the rows do not depend on the number of threads.
//
// Memory: the sweep streams. After frame j has been pushed, a selector can only ever
// read two earlier frames again (Algorithm 1 / eq. 6, keyframe/selector.hpp): its
// current key image K (every later frame is scored against it) and I_j itself (it is
// the I_{j-1} of the next step, which becomes the key image under eq. 6 and may then be
// scored against K). So the cache keeps the features of I_j and of the current key image
// of each threshold and drops every other frame's: while frame j is scored it holds at
// most (thresholds + 2) frames (the key images, I_{j-1} and I_j); the
// pair scores of frames before I_{j-1} are dropped as well. The selectors' own maps keep
// no features (the rows need only the frame indices and the links). Bytes held:
//   - per cached frame: its features, 28 B per keypoint (cv::KeyPoint) + 32 B per ORB
//     descriptor = about 60 KB for ORB 1000 (61 B per keypoint for A-KAZE's 61-byte
//     descriptors, 28 + 512 B for SIFT's 128 floats); at most (thresholds + 2) frames,
//     plus up to 4 prepared frames queued by the decoding thread;
//   - per pair score cached: its raw matches until it is verified (16 B per cv::DMatch)
//     and a PairScore (264 B); only pairs of the last two frames are kept;
//   - per key image, per threshold: a KeyImage without features or pixels (280 B, mostly
//     empty cv::Mat headers, plus its name) and a KeyPair link (96 B; sizes for GCC 12
//     x86-64): the only part that grows with the video, by the number of key images.
// The peak resident memory per frame, streaming against caching every frame's features:
// see examples/bench/bench_rss.cpp; results in examples/results/memory.md.

#include <vmap/core/error.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/keyframe/front_end.hpp>
#include <vmap/keyframe/pipeline.hpp>
#include <vmap/keyframe/selector.hpp>
#include <vmap/keyframe/visual_map.hpp>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstddef>
#include <functional>
#include <cstdint>
#include <exception>
#include <string>
#include <thread>
#include <unordered_map>
#include <utility>
#include <vector>

namespace vmap {

struct SweepOptions {
  /// Thresholds tau, each in (0, 1]; the paper's 0.1..0.9 by default.
  std::vector<double> taus = {0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9};
  KeyRule rule = KeyRule::previous_frame;
  bool skip_by_upper_bound = true;  ///< as SelectorOptions; never changes a row
  bool pipelined = true;            ///< decode + extract on a second thread
  bool parallel_pairs = true;       ///< score a frame's distinct pairs on two threads
  /// Called on the calling thread after each frame with the number of frames done (a
  /// progress line); empty: nothing is called.
  std::function<void(std::size_t)> on_frame = {};
};

struct SweepRow {
  double threshold = 0.0;
  MapStats stats;
  std::vector<std::size_t> key_frames;  ///< frame indices of the key images
};

struct SweepResult {
  std::vector<SweepRow> rows;  ///< in the order of SweepOptions::taus
  std::size_t best = 0;        ///< row with the highest quality (the first of equals)
  std::size_t frames = 0;
  std::size_t pairs_scored = 0;  ///< distinct (key, frame) pairs matched (cache misses)
  std::size_t pair_requests = 0;  ///< pair scores the selectors asked for
  /// The most frames whose features the sweep held at once (at most thresholds + 2; the
  /// decoding thread's queue of up to 4 prepared frames comes on top).
  std::size_t frames_held = 0;

  [[nodiscard]] double best_threshold() const { return rows.empty() ? 0.0 : rows[best].threshold; }
};

namespace detail {

/// Features of the frames the lockstep selectors of a sweep can still read (see the
/// file comment), and the scores of the pairs compared. Single-threaded (the sweep's
/// selection thread).
template <Matcher M, Estimator E, Similarity S>
class SweepCache {
 public:
  struct Entry {
    Matches matches;
    PairScore score;
  };

  const Features& features(std::size_t i) const {
    const auto it = features_.find(i);
    if (it == features_.end()) fail("threshold sweep: the features of frame " + std::to_string(i) + " were dropped");
    return it->second;
  }
  void add(std::size_t i, Features f) { features_.insert_or_assign(i, std::move(f)); }
  /// Drops the features of every frame not in `live` (the frames still referenced).
  void keep_only(const std::vector<std::size_t>& live) {
    std::erase_if(features_, [&](const auto& kv) { return std::find(live.begin(), live.end(), kv.first) == live.end(); });
  }
  [[nodiscard]] std::size_t frames_held() const noexcept { return features_.size(); }

  template <Descriptor D>
  PairScore score(const FeatureFrontEnd<D, M, E, S>& stages, std::size_t key, std::size_t frame,
                  double skip_below) {
    ++requests_;
    auto it = entries_.find(id(key, frame));
    if (it == entries_.end()) {
      ++misses_;
      Entry e;
      e.matches = stages.match(features(key), features(frame));
      e.score = stages.bound(features(key), features(frame), e.matches);
      it = entries_.emplace(id(key, frame), std::move(e)).first;
    }
    Entry& e = it->second;
    if (!e.score.verified_run && !(e.score.upper_bound < skip_below)) {
      stages.verify(features(key), features(frame), e.matches, e.score);
      e.matches = {};  // verified once; the matches are not needed again
    }
    return e.score;
  }

  /// Scores the pairs (keys[k], frame) that are not cached yet (on two threads when
  /// `parallel`; the matcher, estimator and similarity are const and thread-safe); pair k is
  /// verified unless its bound is below skip_below[k] (the smallest threshold of the
  /// selectors that will ask for it, 0 when one of them does not skip).
  template <Descriptor D>
  void prefetch(const FeatureFrontEnd<D, M, E, S>& stages, const std::vector<std::size_t>& keys, std::size_t frame,
                const std::vector<double>& skip_below, bool parallel) {
    std::vector<std::size_t> todo;
    for (std::size_t k = 0; k < keys.size(); ++k)
      if (!entries_.count(id(keys[k], frame))) todo.push_back(k);
    if (todo.empty()) return;
    // Looked up here, on this thread: the workers only read the features.
    std::vector<const Features*> key_features(todo.size());
    for (std::size_t t = 0; t < todo.size(); ++t) key_features[t] = &features(keys[todo[t]]);
    const Features& b = features(frame);
    std::vector<Entry> computed(todo.size());
    std::atomic<std::size_t> next{0};
    auto work = [&] {
      for (std::size_t t = next++; t < todo.size(); t = next++) {
        const std::size_t k = todo[t];
        Entry& e = computed[t];
        const Features& a = *key_features[t];
        e.matches = stages.match(a, b);
        e.score = stages.bound(a, b, e.matches);
        if (!(e.score.upper_bound < skip_below[k])) {
          stages.verify(a, b, e.matches, e.score);
          e.matches = {};
        }
      }
    };
    // A helper thread shares the pairs with this one (cv::parallel_for_ would not do:
    // OpenCV runs it serially whenever another thread, here the decoder, is inside one).
    if (todo.size() > 1 && parallel) {
      std::exception_ptr helper_error, own_error;
      std::thread helper([&] {
        try {
          work();
        } catch (...) {
          helper_error = std::current_exception();
          next = todo.size();  // stop the other thread early
        }
      });
      try {
        work();
      } catch (...) {
        own_error = std::current_exception();
        next = todo.size();
      }
      helper.join();
      if (own_error) std::rethrow_exception(own_error);
      if (helper_error) std::rethrow_exception(helper_error);
    } else {
      work();
    }
    misses_ += todo.size();
    for (std::size_t t = 0; t < todo.size(); ++t) entries_.emplace(id(keys[todo[t]], frame), std::move(computed[t]));
  }

  /// Pairs whose frame is older than `frame` are never asked for again: a selector only
  /// scores the current frame and (when it becomes a key image) the previous one.
  void forget_before(std::size_t frame) {
    for (auto it = entries_.begin(); it != entries_.end();)
      if ((it->first & 0xffffffffULL) < frame) {
        it = entries_.erase(it);
      } else {
        ++it;
      }
  }

  [[nodiscard]] std::size_t requests() const noexcept { return requests_; }
  [[nodiscard]] std::size_t misses() const noexcept { return misses_; }

 private:
  static std::uint64_t id(std::size_t key, std::size_t frame) noexcept {
    return (static_cast<std::uint64_t>(key) << 32) | static_cast<std::uint64_t>(frame);
  }

  std::unordered_map<std::size_t, Features> features_;  // frame index -> features
  std::unordered_map<std::uint64_t, Entry> entries_;
  std::size_t requests_ = 0;
  std::size_t misses_ = 0;
};

/// Front end of one threshold's selector in a sweep: items are positions in the cache.
template <Descriptor D, Matcher M, Estimator E, Similarity S>
class CachedFrontEnd {
 public:
  using Item = std::size_t;

  CachedFrontEnd(const FeatureFrontEnd<D, M, E, S>& stages, SweepCache<M, E, S>& cache)
      : stages_(&stages), cache_(&cache) {}

  [[nodiscard]] PairScore score(std::size_t key, std::size_t frame, double skip_below) {
    return cache_->score(*stages_, key, frame, skip_below);
  }
  /// What a key image keeps in the selector's map: nothing (the sweep reads only the
  /// maps' frame indices and links, and keeping features would grow with the key images).
  [[nodiscard]] const Features& features_of(std::size_t) const noexcept { return none_; }

 private:
  const FeatureFrontEnd<D, M, E, S>* stages_;
  SweepCache<M, E, S>* cache_;
  Features none_;
};

}  // namespace detail

/// Runs one selector per threshold over `source` (see the file comment for the cost).
/// Rows are identical to separate single-threshold runs of KeyframeSelector with the
/// same policies and rule.
template <Descriptor D, Matcher M, Estimator E, Similarity S>
[[nodiscard]] SweepResult sweep_thresholds(FrameSource& source, FeatureFrontEnd<D, M, E, S> front,
                                           const SweepOptions& options = {}) {
  detail::check(!options.taus.empty(), "SweepOptions.taus is empty: give at least one threshold");
  for (double t : options.taus)
    detail::check(std::isfinite(t) && t > 0.0 && t <= 1.0,
                  "SweepOptions.taus: every threshold must be in (0, 1], got " + std::to_string(t));

  using Cached = detail::CachedFrontEnd<D, M, E, S>;
  detail::SweepCache<M, E, S> cache;
  std::vector<BasicKeyframeSelector<Cached>> selectors;
  selectors.reserve(options.taus.size());
  for (double t : options.taus)
    selectors.emplace_back(Cached(front, cache), SelectorOptions{.tau = t,
                                                                 .rule = options.rule,
                                                                 .skip_by_upper_bound = options.skip_by_upper_bound,
                                                                 .keep_images = false});

  std::size_t n = 0;
  std::vector<std::size_t> keys;
  std::vector<double> skips;
  std::vector<std::size_t> live;
  std::size_t frames_held = 0;
  auto select = [&](PreparedFrame<Features>&& p) {
    cache.add(n, std::move(p.item));
    const std::size_t held_before_drop = cache.frames_held();
    {
      keys.clear();
      skips.clear();
      for (const auto& s : selectors) {
        const std::size_t* key = s.key_item();
        if (!key) continue;
        const double skip = s.options().skip_by_upper_bound ? s.options().tau : 0.0;
        const auto at = std::find(keys.begin(), keys.end(), *key);
        if (at == keys.end()) {
          keys.push_back(*key);
          skips.push_back(skip);
        } else {
          auto& k = skips[static_cast<std::size_t>(at - keys.begin())];
          k = std::min(k, skip);
        }
      }
      cache.prefetch(front, keys, n, skips, options.parallel_pairs);
    }
    for (auto& s : selectors) s.push(PreparedFrame<std::size_t>{n, p.index, p.name, p.timestamp, {}, p.time_ns});
    if (n > 0) cache.forget_before(n - 1);
    // Still readable: frame n (the next step's I_{j-1}) and each selector's key image.
    live.assign(1, n);
    for (const auto& s : selectors)
      if (const std::size_t* key = s.key_item()) live.push_back(*key);
    cache.keep_only(live);
    frames_held = std::max(frames_held, held_before_drop);
    ++n;
    if (options.on_frame) options.on_frame(n);
  };
  auto prepare = [&](const Frame& f) {
    detail::check(!f.image.empty(),
                  [&] { return "threshold sweep: frame " + std::to_string(f.index) + " is an empty image"; });
    return PreparedFrame<Features>{front.prepare(f.image), f.index, f.name, f.timestamp, {}, f.time_ns};
  };
  if (options.pipelined)
    detail::run_pipelined(source, 4, prepare, select);
  else
    while (auto f = source.next()) select(prepare(*f));

  SweepResult out;
  out.frames = n;
  out.pair_requests = cache.requests();
  out.pairs_scored = cache.misses();
  out.frames_held = frames_held;
  for (std::size_t k = 0; k < selectors.size(); ++k) {
    const VisualMap& m = selectors[k].map();
    SweepRow row;
    row.threshold = options.taus[k];
    row.stats = m.stats();
    for (const auto& key : m.keys) row.key_frames.push_back(key.frame_index);
    out.rows.push_back(std::move(row));
    if (out.rows[k].stats.quality > out.rows[out.best].stats.quality) out.best = k;
  }
  return out;
}

/// Convenience: the four policies instead of a front end.
template <Descriptor D, Matcher M, Estimator E, Similarity S>
[[nodiscard]] SweepResult sweep_thresholds(FrameSource& source, D descriptor, M matcher, E estimator, S similarity,
                                           const SweepOptions& options = {}) {
  return sweep_thresholds(source,
                          FeatureFrontEnd<D, M, E, S>(std::move(descriptor), std::move(matcher),
                                                      std::move(estimator), std::move(similarity)),
                          options);
}

}  // namespace vmap
