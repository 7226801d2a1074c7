#pragma once

// Streaming key-image selection, Algorithm 1 / eq. 6 of García-Pintos et al. 2023
// (examples/methods.md, sec. 1). The logic lives once, in BasicKeyframeSelector<FrontEnd>; the
// paper's feature stack (KeyframeSelector<D, M, E, S>) and detector-free pair matchers
// (PairKeyframeSelector<P, E>) are front ends of it, and the threshold sweep drives the
// same object.

#include <vmap/core/concepts.hpp>
#include <vmap/core/error.hpp>
#include <vmap/core/names.hpp>
#include <vmap/geometry/fundamental.hpp>
#include <vmap/geometry/similarity.hpp>
#include <vmap/hooks/pair_matcher.hpp>
#include <vmap/io/binary.hpp>
#include <vmap/io/frame.hpp>
#include <vmap/io/timestamps.hpp>
#include <vmap/keyframe/front_end.hpp>
#include <vmap/keyframe/options.hpp>
#include <vmap/keyframe/result.hpp>
#include <vmap/keyframe/visual_map.hpp>
#include <vmap/matching/brute_force.hpp>

#include <opencv2/core.hpp>

#include <cmath>
#include <cstddef>
#include <concepts>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <utility>

namespace vmap {

namespace detail {

/// SelectorOptions as a saved memory keeps them: tau, the rule and the fast path.
/// keep_images is not written: the memory sets it from its image storage.
inline void write_selector_options(BinaryWriter& w, const SelectorOptions& o) {
  static_assert(field_count<SelectorOptions>() == 4, "a new SelectorOptions field must be written and read here");
  w.f64(o.tau);
  w.u8(static_cast<std::uint8_t>(o.rule));
  w.u8(o.skip_by_upper_bound ? 1 : 0);
}

inline SelectorOptions read_selector_options(BinaryReader& r) {
  SelectorOptions o;
  o.tau = r.f64("tau");
  if (!(std::isfinite(o.tau) && o.tau > 0.0 && o.tau <= 1.0)) r.corrupt("tau outside (0, 1]");
  const std::uint8_t rule = r.u8("key rule");
  if (rule > static_cast<std::uint8_t>(KeyRule::current_frame)) r.corrupt("unknown key rule " + std::to_string(rule));
  o.rule = static_cast<KeyRule>(rule);
  const std::uint8_t skip = r.u8("skip flag");
  if (skip > 1) r.corrupt("skip flag is not 0 or 1");
  o.skip_by_upper_bound = skip == 1;
  return o;
}

}  // namespace detail

/// A frame after the front end's `prepare` (features extracted), ready for push().
template <class Item>
struct PreparedFrame {
  Item item;
  std::size_t index = 0;
  std::string name;
  double timestamp = 0.0;
  cv::Mat image;  ///< kept only when SelectorOptions::keep_images
  std::int64_t time_ns = 0;  ///< Frame::time_ns
};

/// What a selector needs besides its options and policies to continue a sequence exactly
/// where it stopped (VisualMemory saves it): the map, whose last key image is the current
/// key, and the frame I_{j-1} of eq. 6 with its score against that key when it has one.
template <class Item>
struct SelectorState {
  VisualMap map;
  std::optional<PreparedFrame<Item>> previous;  ///< I_{j-1} when it is not the key image
  std::optional<PairScore> previous_score;      ///< S(key, previous), when it was scored
  /// previous_score's homography degeneracy test was deferred (deferred_state()): its
  /// degeneracy and homography_inliers are zero and its inlier mask is kept, so that
  /// the selector restored from it computes them when its state() is read.
  bool degeneracy_deferred = false;
};

/// Algorithm 1 over any front end. Streaming: push() one frame at a time; map() can be
/// read at any time. The key image's item (its features) is prepared once and kept.
///
/// Threading: prepare() touches only the front end's preparation state (the Descriptor),
/// push() only the rest, so one thread may prepare frame j+1 while another pushes frame
/// j (run_selector does this). Everything else is single-threaded.
template <KeyframeFrontEnd F>
class BasicKeyframeSelector {
 public:
  using FrontEnd = F;
  using Item = typename F::Item;
  using Prepared = PreparedFrame<Item>;

  explicit BasicKeyframeSelector(F front_end, const SelectorOptions& options = {})
      : front_(std::move(front_end)), options_(options) {
    detail::check(std::isfinite(options_.tau) && options_.tau > 0.0 && options_.tau <= 1.0,
                  [&] { return "SelectorOptions.tau must be in (0, 1], got " + std::to_string(options_.tau); });
  }

  [[nodiscard]] Prepared prepare(const Frame& frame)
    requires PreparesFrames<F>
  {
    return prepare_with(front_, options_.keep_images, frame);
  }

  /// Prepares frames exactly as prepare() does, with its own copy of the front end (its
  /// own Descriptor), so that another thread can prepare frames at the same time
  /// (run_selector's extra preparing threads).
  class Preparer {
   public:
    [[nodiscard]] Prepared prepare(const Frame& frame) { return prepare_with(front_, keep_images_, frame); }

   private:
    friend class BasicKeyframeSelector;
    Preparer(F front, bool keep_images) : front_(std::move(front)), keep_images_(keep_images) {}
    F front_;
    bool keep_images_;
  };

  [[nodiscard]] Preparer preparer() const
    requires PreparesFrames<F> && std::copy_constructible<F>
  {
    return Preparer(front_, options_.keep_images);
  }

  FrameResult push(const Frame& frame)
    requires PreparesFrames<F>
  {
    // prepare(), with the name's buffer taken from the last frame this selector dropped
    // (a frame name is longer than the short-string buffer: one allocation per frame).
    check_frame(frame);
    Prepared p{front_.prepare(frame.image), frame.index, std::move(spare_name_), frame.timestamp, {}, frame.time_ns};
    p.name.assign(frame.name);
    if (options_.keep_images) p.image = frame.image;
    return push(std::move(p));
  }

  /// A bare image: its index is the number of frames pushed so far.
  FrameResult push(const cv::Mat& image)
    requires PreparesFrames<F>
  {
    Frame f;
    f.image = image;
    f.index = map_.frames;
    f.name = "frame#" + std::to_string(f.index);
    f.timestamp = static_cast<double>(f.index);
    f.time_ns = nanoseconds_from_seconds(f.timestamp);
    return push(f);
  }

  FrameResult push(Prepared frame) {
    FrameResult r;
    r.frame_index = frame.index;
    if (!key_) {  // K_1 = I_1, and the first frame of a chain (start_chain)
      ++map_.frames;
      r.similarity = 1.0;
      r.key_taken = true;
      r.key_frame = frame.index;
      r.reason = KeyReason::first_frame;
      add_key(std::move(frame), nullptr);
      return r;
    }
    // Scored into a buffer kept across calls; the homography degeneracy check is
    // deferred because only state() reads it (see complete_previous_score).
    PairScore& s = scratch_score_;
    bool deferred = false;
    const double skip_below = options_.skip_by_upper_bound ? options_.tau : 0.0;
    if constexpr (detail::ScoresIntoBuffers<F>)
      deferred = front_.score_into(key_->item, frame.item, skip_below, s, true);
    else
      s = front_.score(key_->item, frame.item, skip_below);
    ++map_.frames;  // after the score, which may throw: nothing changed before it
    r.raw_matches = s.raw_matches;
    r.exact = s.verified_run;
    r.similarity = s.verified_run ? s.similarity : s.upper_bound;
    if (s.verified_run) {
      r.status = s.verification.status;
      r.verified_matches = s.verification.ok() ? s.verification.inliers : 0;
    }
    r.reason = key_reason(s, options_.tau);
    if (r.reason == KeyReason::none) {
      set_previous(std::move(frame));
      std::swap(prev_score_, scratch_score_);  // the buffers change hands, none is freed
      prev_scored_ = true;
      prev_degeneracy_pending_ = deferred;
      return r;
    }
    r.key_taken = true;
    if (options_.rule == KeyRule::previous_frame && prev_) {
      // Eq. 6: I_{j-1} becomes the key image. Its link to the old key is the score it
      // passed with (cached), unless it arrived right after a key change and was never
      // compared with the current key. Comparison resumes with I_{j+1} against the new
      // key (as in the reference implementation); I_j is scored against it only if it
      // has to become the next key image itself.
      if (!prev_scored_) full_score_into(prev_->item, prev_score_);
      r.key_frame = prev_->index;
      add_key(std::move(*prev_), &prev_score_);  // a link keeps no degeneracy: none is computed
      prev_ = std::move(frame);
      prev_scored_ = false;
      prev_degeneracy_pending_ = false;
    } else {
      // Algorithm 1's rule, or eq. 6 when I_{j-1} already is the key image: take I_j.
      if (!s.verified_run) full_score_into(frame.item, s);
      r.key_frame = frame.index;
      add_key(std::move(frame), &s);
      set_previous(std::nullopt);
      prev_scored_ = false;
      prev_degeneracy_pending_ = false;
    }
    return r;
  }

  [[nodiscard]] const VisualMap& map() const noexcept { return map_; }

  /// Drops key image k's features from the map, keeping its norm and image size and
  /// every other field: a visual memory that reads older key images' features from its
  /// store bounds its RAM so. push() goes on unchanged: it matches new frames with its
  /// own copy of the current key image's features, not the map's.
  void release_key_features(std::size_t k) {
    detail::check(k < map_.keys.size(), [&] {
      return "KeyframeSelector::release_key_features: key image " + std::to_string(k) + " of " +
             std::to_string(map_.keys.size());
    });
    Features& f = map_.keys[k].features;
    f = Features{{}, cv::Mat(), f.norm, f.image_size};
  }

  /// Ends the current chain of key images: the next frame becomes a key image as the
  /// first frame does, not joined to the last key image by a verified link (pairs keeps
  /// one entry per consecutive key images: that one is a link of no matches, status
  /// too_few_matches, similarity 0). A visual memory starts a session, another run of
  /// the robot, so. The map is kept; a no-op before the first frame.
  void start_chain() {
    key_.reset();
    set_previous(std::nullopt);
    prev_scored_ = false;
    prev_degeneracy_pending_ = false;
  }

  /// Whether the next frame starts a chain (before the first frame, or after start_chain).
  [[nodiscard]] bool chain_open() const noexcept { return !key_.has_value(); }

  /// Moves the map out and starts a new sequence (options and policies are kept).
  [[nodiscard]] VisualMap take_map() {
    VisualMap out = std::move(map_);
    reset();
    return out;
  }
  void reset() {
    map_ = {};
    key_.reset();
    prev_.reset();
    prev_scored_ = false;
    prev_degeneracy_pending_ = false;
  }

  /// A copy of everything push() continues from (see SelectorState).
  [[nodiscard]] SelectorState<Item> state() const {
    SelectorState<Item> s = pending_state();
    s.map = map_;
    return s;
  }

  /// state() without the map (left empty): I_{j-1} and its score, the part that changes
  /// at every frame. A store that keeps the map's key images apart rewrites only this,
  /// without copying the map.
  [[nodiscard]] SelectorState<Item> pending_state() const {
    SelectorState<Item> s = deferred_state();
    if (s.degeneracy_deferred) {
      complete_previous_score(*s.previous_score);
      s.degeneracy_deferred = false;
    }
    return s;
  }

  /// pending_state() with the score's degeneracy test left deferred (see
  /// SelectorState::degeneracy_deferred): the homography fit push() saved is not paid
  /// for a state that is written at every frame and read rarely. The deferred fields are
  /// zeroed, so equal runs give equal states.
  [[nodiscard]] SelectorState<Item> deferred_state() const {
    SelectorState<Item> s{{}, prev_, std::nullopt};
    if (prev_scored_) {
      s.previous_score = prev_score_;
      if (prev_degeneracy_pending_) {
        s.previous_score->verification.degeneracy = Degeneracy::none;
        s.previous_score->verification.homography_inliers = 0;
        s.degeneracy_deferred = true;
      }
    }
    return s;
  }

  /// Continues from a saved state: the next push() behaves as it would have in the run
  /// the state was taken from. The current key's item is its features in the map, so
  /// this needs a front end whose Item is Features (the feature stack).
  void restore(SelectorState<Item> s)
    requires std::same_as<Item, Features>
  {
    const VisualMap& m = s.map;
    detail::check(m.pairs.size() == (m.keys.empty() ? 0 : m.keys.size() - 1), [&] {
      return "KeyframeSelector::restore: " + std::to_string(m.pairs.size()) + " pairs for " +
             std::to_string(m.keys.size()) + " key images";
    });
    detail::check(m.keys.empty() || m.frames >= m.keys.size(),
                  "KeyframeSelector::restore: fewer frames than key images");
    detail::check(!s.previous_score || s.previous, "KeyframeSelector::restore: a previous score without a previous frame");
    detail::check(!s.degeneracy_deferred || (s.previous_score && s.previous_score->verification.ok() &&
                                             s.previous_score->verification.inlier_mask.size() ==
                                                 static_cast<std::size_t>(s.previous_score->verification.matches)),
                  "KeyframeSelector::restore: a deferred degeneracy without a verified score and its inlier mask");
    detail::check(!s.previous || !m.keys.empty(), "KeyframeSelector::restore: a previous frame without a key image");
    detail::check(!s.previous || s.previous->index > m.keys.back().frame_index,
                  "KeyframeSelector::restore: the previous frame is not after the current key image");
    reset();
    map_ = std::move(s.map);
    if (!map_.keys.empty()) {
      const KeyImage& k = map_.keys.back();
      key_ = Prepared{k.features, k.frame_index, k.name, k.timestamp, k.image, k.time_ns};
    }
    prev_ = std::move(s.previous);
    prev_scored_ = s.previous_score.has_value();
    prev_degeneracy_pending_ = s.degeneracy_deferred;
    if (prev_scored_) prev_score_ = std::move(*s.previous_score);
  }

  /// What push() changes, taken before it: rollback() undoes that push, so that a caller
  /// whose own work after the push fails (a visual memory) leaves the selector as it was.
  /// Costs a copy of I_{j-1}'s item and score.
  struct Checkpoint {
    std::size_t keys = 0, pairs = 0, frames = 0;
    std::optional<Prepared> previous;
    PairScore previous_score;
    bool previous_scored = false;
    bool degeneracy_pending = false;
    bool chain_open = false;
  };

  [[nodiscard]] Checkpoint checkpoint() const {
    return {map_.keys.size(), map_.pairs.size(), map_.frames, prev_, prev_score_, prev_scored_,
            prev_degeneracy_pending_, !key_.has_value()};
  }

  /// Undoes the pushes since `c` was taken (at most one: a frame adds at most one key
  /// image and one link). As restore(), needs Features as the item.
  void rollback(Checkpoint c)
    requires std::same_as<Item, Features>
  {
    detail::check(c.keys <= map_.keys.size() && c.pairs <= map_.pairs.size() && c.frames <= map_.frames,
                  "KeyframeSelector::rollback: the checkpoint is not of this selector");
    map_.keys.resize(c.keys);
    map_.pairs.resize(c.pairs);
    map_.frames = c.frames;
    key_.reset();
    if (!c.chain_open && !map_.keys.empty()) {
      const KeyImage& k = map_.keys.back();
      key_ = Prepared{k.features, k.frame_index, k.name, k.timestamp, k.image, k.time_ns};
    }
    prev_ = std::move(c.previous);
    prev_score_ = std::move(c.previous_score);
    prev_scored_ = c.previous_scored;
    prev_degeneracy_pending_ = c.degeneracy_pending;
  }

  /// The current key image's item (its features), nullptr before the first frame. The
  /// next push() scores its frame against this item.
  [[nodiscard]] const Item* key_item() const noexcept { return key_ ? &key_->item : nullptr; }

  [[nodiscard]] const SelectorOptions& options() const noexcept { return options_; }
  [[nodiscard]] F& front_end() noexcept { return front_; }
  [[nodiscard]] const F& front_end() const noexcept { return front_; }

 private:
  /// S(key, item) with the estimator run whatever the bound, into `out`'s buffers.
  void full_score_into(const Item& item, PairScore& out) {
    if constexpr (detail::ScoresIntoBuffers<F>)
      (void)front_.score_into(key_->item, item, 0.0, out, true);  // a link keeps no degeneracy
    else
      out = front_.score(key_->item, item, 0.0);
  }

  static Prepared prepare_with(F& front, bool keep_images, const Frame& frame) {
    check_frame(frame);
    Prepared p{front.prepare(frame.image), frame.index, frame.name, frame.timestamp, {}, frame.time_ns};
    if (keep_images) p.image = frame.image;
    return p;
  }

  static void check_frame(const Frame& frame) {
    detail::check(!frame.image.empty(), [&] {
      return "key-image selector: frame " + std::to_string(frame.index) + " ('" + frame.name + "') is an empty image";
    });
  }

  /// I_{j-1} := p; the frame it replaces lends its name's buffer to the next frame.
  void set_previous(std::optional<Prepared> p) {
    if (prev_) spare_name_ = std::move(prev_->name);
    prev_ = std::move(p);
  }

  /// The degeneracy of S(key, I_{j-1}), deferred by push() (only state() reads it): the
  /// same value the estimator's verify() gives, computed on the same pair.
  void complete_previous_score(PairScore& score) const {
    if constexpr (detail::ScoresIntoBuffers<F>) front_.complete_degeneracy(key_->item, prev_->item, score);
  }

  void add_key(Prepared&& p, const PairScore* link) {
    KeyImage k;
    k.frame_index = p.index;
    k.name = p.name;
    k.timestamp = p.timestamp;
    k.time_ns = p.time_ns;
    k.features = front_.features_of(p.item);
    k.image = p.image;
    if (link) {
      KeyPair pair;
      pair.status = link->verification.status;
      pair.matches = link->raw_matches;
      if (link->verification.ok()) {
        pair.fundamental = link->verification.model;
        pair.inliers = link->verification.inliers;
      }
      pair.similarity = link->similarity;
      map_.pairs.push_back(pair);
    } else if (!map_.keys.empty()) {
      map_.pairs.push_back(KeyPair{});  // a new chain (start_chain): no link to the last key image
    }
    map_.keys.push_back(std::move(k));
    if (key_) spare_name_ = std::move(key_->name);
    key_ = std::move(p);
  }

  F front_;
  SelectorOptions options_;
  VisualMap map_;
  std::optional<Prepared> key_;   // the current key image, prepared once
  std::optional<Prepared> prev_;  // I_{j-1} when it is not the key image
  PairScore prev_score_;          // S(key, prev) when prev_scored_
  bool prev_scored_ = false;
  bool prev_degeneracy_pending_ = false;  // prev_score_'s degeneracy check was deferred
  PairScore scratch_score_;               // push()'s score, reused between frames
  std::string spare_name_;                // a dropped frame's name buffer, reused
};

/// The paper's stack: Descriptor + Matcher + Estimator + Similarity.
template <Descriptor D, Matcher M, Estimator E, Similarity S>
class KeyframeSelector : public BasicKeyframeSelector<FeatureFrontEnd<D, M, E, S>> {
  using Base = BasicKeyframeSelector<FeatureFrontEnd<D, M, E, S>>;

 public:
  KeyframeSelector(D descriptor, M matcher, E estimator, S similarity, const SelectorOptions& options = {})
      : Base(FeatureFrontEnd<D, M, E, S>(std::move(descriptor), std::move(matcher), std::move(estimator),
                                         std::move(similarity)),
             options) {}

  /// Every policy default-constructed (e.g. ORB 1000, mutual NN, MAGSAC 1 px, eq. 5).
  explicit KeyframeSelector(const SelectorOptions& options = {})
    requires std::default_initializable<D> && std::default_initializable<M> && std::default_initializable<E> &&
             std::default_initializable<S>
      : KeyframeSelector(D{}, M{}, E{}, S{}, options) {}
};

/// A detector-free PairMatcher front end (hooks/pair_matcher.hpp); S = inliers / cells.
template <PairMatcher P, Estimator E>
class PairKeyframeSelector : public BasicKeyframeSelector<PairFrontEnd<P, E>> {
  using Base = BasicKeyframeSelector<PairFrontEnd<P, E>>;

 public:
  PairKeyframeSelector(P matcher, E estimator, const SelectorOptions& options = {})
      : Base(PairFrontEnd<P, E>(std::move(matcher), std::move(estimator)), options) {}
};

}  // namespace vmap
