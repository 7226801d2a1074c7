#pragma once

// Front ends of the key-image selector: what turns a frame into something comparable and
// scores a pair (eq. 5 of García-Pintos et al. 2023). The selection logic (Algorithm 1,
// keyframe/selector.hpp) is written once over the KeyframeFrontEnd concept; two front ends
// model it:
//   - FeatureFrontEnd<Descriptor, Matcher, Estimator, Similarity>: per-frame features,
//     matched and verified by a fundamental matrix (the paper's method);
//   - PairFrontEnd<PairMatcher, Estimator>: a detector-free matcher that takes the image
//     pair and returns correspondences plus its eq. 5 denominator (examples/methods.md, sec. 5).

#include <vmap/core/concepts.hpp>
#include <vmap/core/error.hpp>
#include <vmap/core/features.hpp>
#include <vmap/core/verification.hpp>
#include <vmap/hooks/pair_matcher.hpp>
#include <vmap/keyframe/result.hpp>

#include <opencv2/core.hpp>

#include <algorithm>
#include <concepts>
#include <cstddef>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace vmap {

/// The score of one (key image, frame) pair.
struct PairScore {
  int raw_matches = 0;       ///< correspondences before verification
  double upper_bound = 0.0;  ///< raw_matches / eq. 5 denominator: S can only be lower
  /// False when the estimator was skipped because upper_bound was already below the
  /// threshold (the fast path); `verification` and `similarity` are then not computed.
  bool verified_run = false;
  Verification verification;  ///< the estimator's result (when verified_run)
  double similarity = 0.0;    ///< eq. 5 (when verified_run; else 0)
};

/// A pair's score from its tentative matches before verification: their count and the
/// bound they put on eq. 5.
template <Similarity S>
[[nodiscard]] PairScore bound_pair(const S& similarity, const Features& key, const Features& frame,
                                   const Matches& matches) {
  PairScore s;
  s.raw_matches = static_cast<int>(matches.size());
  s.upper_bound = similarity.upper_bound(key, frame, s.raw_matches);
  return s;
}

/// Verifies the pair's matches and completes its score with eq. 5 (0 when no model).
template <Estimator E, Similarity S>
void verify_pair(const E& estimator, const S& similarity, const Features& key, const Features& frame,
                 const Matches& matches, PairScore& s) {
  s.verification = estimator.verify(key, frame, matches);
  s.verified_run = true;
  s.similarity = s.verification.ok() ? static_cast<double>(similarity(key, frame, s.verification)) : 0.0;
}

/// Eq. 5 for a pair of feature sets: matched, bounded, and verified unless the bound is
/// already below `skip_below` (the selector's fast path).
template <Matcher M, Estimator E, Similarity S>
[[nodiscard]] PairScore score_pair(const M& matcher, const E& estimator, const S& similarity, const Features& key,
                                   const Features& frame, double skip_below) {
  const Matches matches = matcher.match(key, frame);
  PairScore s = bound_pair(similarity, key, frame, matches);
  if (s.upper_bound >= skip_below) verify_pair(estimator, similarity, key, frame, matches, s);
  return s;
}

/// Why a frame scored so no longer resembles the key image at threshold `tau`, the test
/// of Algorithm 1 (KeyReason::none: it still does).
[[nodiscard]] constexpr KeyReason key_reason(const PairScore& s, double tau) noexcept {
  if (!s.verified_run) return KeyReason::bound_below_threshold;
  if (!s.verification.ok()) return KeyReason::verification_failed;  // the paper: no F-matrix also ends the key image
  if (s.similarity < tau) return KeyReason::below_threshold;
  return KeyReason::none;
}

// ---- the front-end concept --------------------------------------------------------

/// Turns a frame into the representation the selector caches (`Item`). Called once per
/// frame; may run on another thread than `score` (the two touch disjoint state).
template <class F>
concept PreparesFrames = requires(F& f, const cv::Mat& image) {
  { f.prepare(image) } -> std::same_as<typename F::Item>;
};

/// Scores a pair. Fast path: the estimator is skipped when the upper bound is already
/// below `skip_below`; 0 (no bound is below 0) forces the full verification.
template <class F>
concept ScoresItems = requires { typename F::Item; } &&
    requires(F& f, const typename F::Item& a, const typename F::Item& b, double skip_below) {
      { f.score(a, b, skip_below) } -> std::same_as<PairScore>;
    };

/// The features a key image keeps in the VisualMap (empty for pair matchers).
template <class F>
concept ExposesFeatures = requires(const F& f, const typename F::Item& a) {
  { f.features_of(a) } -> std::convertible_to<Features>;
};

/// What the selection logic needs: score a pair of prepared items, and expose the
/// features a key image keeps. Items may come from anywhere (the sweep's come from a
/// feature cache), so preparing frames is a separate concept.
template <class F>
concept KeyframeFrontEnd = std::move_constructible<F>  // held by value
                           && ScoresItems<F>           // PairScore score(key, frame, skip_below)
                           && ExposesFeatures<F>;      // Features features_of(item) const

/// A front end that can also prepare frames from images (push(Frame), pipelines).
template <class F>
concept FrameFrontEnd = KeyframeFrontEnd<F>  // scores pairs
                        && PreparesFrames<F>;  // Item prepare(image)

// ---- descriptor + matcher + estimator + similarity ---------------------------------

namespace detail {

/// A matcher that can match into the caller's Matches with reusable buffers
/// (BruteForceMatcher::match_into).
template <class M>
concept MatchesInto = requires(const M& m, const Features& a, const Features& b, Matches& out,
                               typename M::Scratch& scratch) { m.match_into(a, b, out, scratch); };

/// An estimator that can verify into the caller's Verification with reusable buffers and
/// defer its degeneracy check (FundamentalEstimator::verify_into / complete_degeneracy).
template <class E>
concept VerifiesInto = requires(const E& e, const Features& a, const Features& b, const Matches& m,
                                Verification& v, typename E::Scratch& scratch) {
  { e.verify_into(a, b, m, v, scratch, true) } -> std::same_as<bool>;
  e.complete_degeneracy(a, b, m, v);
};

/// The policy's Scratch when it has a buffer-reusing form, else an empty stand-in.
struct NoScratch {};
template <class P, bool has_scratch>
struct ScratchOf {
  using type = NoScratch;
};
template <class P>
struct ScratchOf<P, true> {
  using type = typename P::Scratch;
};
template <class M>
using MatchScratch = typename ScratchOf<M, MatchesInto<M>>::type;
template <class E>
using VerifyScratch = typename ScratchOf<E, VerifiesInto<E>>::type;

}  // namespace detail

/// The paper's front end: features extracted once per frame (the key image's are kept by
/// the selector, never recomputed), matched, and verified by the estimator; S per the
/// Similarity policy. `prepare` uses only the Descriptor and `score` only the other
/// three policies, so a pipeline may extract frame j+1 while frame j is scored.
template <Descriptor D, Matcher M, Estimator E, Similarity S>
class FeatureFrontEnd {
 public:
  using Item = Features;

  FeatureFrontEnd(D descriptor, M matcher, E estimator, S similarity)
      : descriptor_(std::move(descriptor)),
        matcher_(std::move(matcher)),
        estimator_(std::move(estimator)),
        similarity_(std::move(similarity)) {}

  [[nodiscard]] Features prepare(const cv::Mat& image) { return descriptor_.extract(image); }

  [[nodiscard]] PairScore score(const Features& key, const Features& frame, double skip_below) const {
    return score_pair(matcher_, estimator_, similarity_, key, frame, skip_below);
  }

  /// The stages of `score`, public so that the threshold sweep can cache them per pair.
  [[nodiscard]] Matches match(const Features& key, const Features& frame) const { return matcher_.match(key, frame); }
  [[nodiscard]] PairScore bound(const Features& key, const Features& frame, const Matches& matches) const {
    return bound_pair(similarity_, key, frame, matches);
  }
  void verify(const Features& key, const Features& frame, const Matches& matches, PairScore& s) const {
    verify_pair(estimator_, similarity_, key, frame, matches, s);
  }

  /// `score` into `out` with the front end's reusable buffers (no allocation of ours
  /// once warm when the matcher and estimator offer buffer-reusing forms, as
  /// BruteForceMatcher and FundamentalEstimator do). With `defer_degeneracy` an
  /// estimator that supports it leaves the homography degeneracy check out and true is
  /// returned: `complete_degeneracy` on the same pair fills it in when it is read.
  /// Touches the scoring buffers: one thread at a time (like the selector's push).
  bool score_into(const Features& key, const Features& frame, double skip_below, PairScore& out,
                  bool defer_degeneracy) {
    if constexpr (detail::MatchesInto<M>)
      matcher_.match_into(key, frame, matches_, match_scratch_);
    else
      matches_ = matcher_.match(key, frame);
    out.raw_matches = static_cast<int>(matches_.size());
    out.upper_bound = similarity_.upper_bound(key, frame, out.raw_matches);
    out.verified_run = false;
    out.similarity = 0.0;
    if (out.upper_bound < skip_below) {
      // As `score` leaves it (not computed), keeping the inlier mask's capacity.
      std::vector<std::uint8_t> mask = std::move(out.verification.inlier_mask);
      mask.clear();
      out.verification = {};
      out.verification.inlier_mask = std::move(mask);
      return false;
    }
    bool deferred = false;
    if constexpr (detail::VerifiesInto<E>)
      deferred = estimator_.verify_into(key, frame, matches_, out.verification, verify_scratch_, defer_degeneracy);
    else
      out.verification = estimator_.verify(key, frame, matches_);
    out.verified_run = true;
    out.similarity = out.verification.ok() ? static_cast<double>(similarity_(key, frame, out.verification)) : 0.0;
    return deferred;
  }

  /// Completes a score whose degeneracy check `score_into` deferred: the same matches
  /// are found again (matching is deterministic) and the estimator runs the check.
  /// Nothing to do for an estimator that never defers.
  void complete_degeneracy(const Features& key, const Features& frame, PairScore& s) const {
    if constexpr (detail::VerifiesInto<E>)
      estimator_.complete_degeneracy(key, frame, matcher_.match(key, frame), s.verification);
  }

  [[nodiscard]] const Features& features_of(const Features& item) const noexcept { return item; }

  [[nodiscard]] D& descriptor() noexcept { return descriptor_; }
  [[nodiscard]] const D& descriptor() const noexcept { return descriptor_; }
  [[nodiscard]] const M& matcher() const noexcept { return matcher_; }
  [[nodiscard]] const E& estimator() const noexcept { return estimator_; }
  [[nodiscard]] const S& similarity() const noexcept { return similarity_; }

 private:
  D descriptor_;
  M matcher_;
  E estimator_;
  S similarity_;
  // score_into's buffers, reused between pairs.
  Matches matches_;
  [[no_unique_address]] detail::MatchScratch<M> match_scratch_;
  [[no_unique_address]] detail::VerifyScratch<E> verify_scratch_;
};

namespace detail {

/// A front end that scores into the caller's PairScore with reusable buffers and can
/// complete a deferred degeneracy check (FeatureFrontEnd); the selector uses it when
/// present and `score` otherwise.
template <class F>
concept ScoresIntoBuffers = requires(F& f, const F& cf, const typename F::Item& a, const typename F::Item& b,
                                     PairScore& out) {
  { f.score_into(a, b, 0.0, out, true) } -> std::same_as<bool>;
  cf.complete_degeneracy(a, b, out);
};

}  // namespace detail

// ---- detector-free pair matcher -----------------------------------------------------

namespace detail {

/// Correspondences as Features + one-to-one Matches, so any Estimator verifies them.
inline void correspondences_as_features(const Correspondences& c, cv::Size size_a, cv::Size size_b, Features& a,
                                        Features& b, Matches& m) {
  check(c.points_b.size() == c.points_a.size(), [&] {
    return "PairMatcher: points_a and points_b differ in length (" + std::to_string(c.points_a.size()) + " vs " +
           std::to_string(c.points_b.size()) + ")";
  });
  const std::size_t n = c.size();
  a.keypoints.resize(n);
  b.keypoints.resize(n);
  m.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    a.keypoints[i] = cv::KeyPoint(c.points_a[i], 1.0f);
    b.keypoints[i] = cv::KeyPoint(c.points_b[i], 1.0f);
    const float conf = i < c.confidence.size() ? c.confidence[i] : 1.0f;
    m[i] = cv::DMatch(static_cast<int>(i), static_cast<int>(i), 1.0f - conf);
  }
  a.image_size = size_a;
  b.image_size = size_b;
}

}  // namespace detail

/// A PairMatcher (e.g. a LoFTR-style network behind hooks/pair_matcher.hpp) as the front
/// end. The item is the image itself (cloned: the matcher needs the key image's pixels
/// for every later pair). Eq. 5 with the matcher's own denominator:
/// S = verified correspondences / cells, and raw correspondences / cells bounds it.
template <PairMatcher P, Estimator E>
class PairFrontEnd {
 public:
  using Item = cv::Mat;

  PairFrontEnd(P matcher, E estimator) : matcher_(std::move(matcher)), estimator_(std::move(estimator)) {}

  [[nodiscard]] cv::Mat prepare(const cv::Mat& image) const { return image.clone(); }

  [[nodiscard]] PairScore score(const cv::Mat& key, const cv::Mat& frame, double skip_below) {
    const Correspondences c = matcher_.match_pair(key, frame);
    check_cells(c);
    PairScore s;
    s.raw_matches = static_cast<int>(c.size());
    s.upper_bound = std::min(1.0, static_cast<double>(s.raw_matches) / c.cells);
    if (s.upper_bound < skip_below) return s;
    detail::correspondences_as_features(c, key.size(), frame.size(), a_, b_, matches_);
    s.verification = estimator_.verify(a_, b_, matches_);
    s.verified_run = true;
    s.similarity = s.verification.ok() ? std::min(1.0, static_cast<double>(s.verification.inliers) / c.cells) : 0.0;
    return s;
  }

  /// A pair matcher has no per-image features: key images keep none.
  [[nodiscard]] Features features_of(const cv::Mat&) const { return {}; }

  [[nodiscard]] const P& matcher() const noexcept { return matcher_; }
  [[nodiscard]] const E& estimator() const noexcept { return estimator_; }

 private:
  static void check_cells(const Correspondences& c) {
    if (c.cells <= 0)
      detail::fail("PairMatcher: Correspondences.cells (the eq. 5 denominator) must be > 0, got " +
                   std::to_string(c.cells));
  }

  P matcher_;
  E estimator_;
  Features a_, b_;  // scratch reused between pairs
  Matches matches_;
};

}  // namespace vmap
