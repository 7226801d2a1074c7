#pragma once

// The place-recognition layer (place/) as the ranking stage of LoopDetector: a
// vocabulary tree turns each key frame's descriptors into a TF-IDF bag of words, and an
// inverted-file PlaceDatabase ranks the indexed frames (all of them, or the tree's leaf)
// by the DBoW2 score.

#include <vmap/core/error.hpp>
#include <vmap/core/features.hpp>
#include <vmap/place/bow.hpp>
#include <vmap/place/database.hpp>
#include <vmap/place/vocabulary.hpp>

#include <concepts>
#include <cstddef>
#include <memory>
#include <utility>
#include <vector>

namespace vmap {

/// One frame of the ranked list a ranker returns.
struct RankedFrame {
  std::size_t frame = 0;
  double score = 0.0;  ///< bag-of-words score, higher is more similar
};

/// What the ranked candidate sources need from a place-recognition index: a bag of
/// words per frame (computed once, when the frame is pushed), an inverted file the
/// detector adds frames to when they leave the window, and a top-n query that may be
/// restricted to a set of frames (the tree's leaf). PlaceRanker below adapts the place/ layer;
/// a test may script one.
template <class R>
concept PlaceRanking = std::move_constructible<R> &&
    requires(R& r, const R& cr, const Features& f, const typename R::Bow& bow, std::size_t id, std::size_t n,
             const std::vector<std::size_t>* only) {
      typename R::Bow;
      { cr.ready() } -> std::convertible_to<bool>;                      // can describe and rank
      { cr.describe(f) } -> std::same_as<typename R::Bow>;              // the frame's bag of words
      { r.add(id, bow) };                                               // indexes a frame
      { cr.rank(bow, n, only) } -> std::same_as<std::vector<RankedFrame>>;  // best first; only == nullptr: all
      { cr.memory_bytes() } -> std::convertible_to<std::size_t>;        // the index's memory
    };

/// Models PlaceRanking over a shared, read-only vocabulary (one vocabulary may serve
/// several detectors and threads: its const members are thread-safe). Without a
/// vocabulary (default-constructed) it is not `ready()`, which the tree and brute_force
/// sources do not need.
class PlaceRanker {
 public:
  using Bow = BowVector;

  PlaceRanker() = default;
  explicit PlaceRanker(std::shared_ptr<const AnyVocabulary> vocabulary, BowScoring scoring = BowScoring::l1)
      : vocabulary_(std::move(vocabulary)),
        database_(vocabulary_ ? vocabulary_->size() : 0, scoring) {
    detail::check(!vocabulary_ || !vocabulary_->empty(), "PlaceRanker: the vocabulary has no words");
  }

  [[nodiscard]] bool ready() const noexcept { return vocabulary_ != nullptr; }

  /// The frame's TF-IDF bag of words; descriptors of the other kind than the vocabulary
  /// (binary / float) are an Error naming both.
  [[nodiscard]] Bow describe(const Features& f) const {
    detail::check(ready(), "PlaceRanker::describe: no vocabulary");
    if (f.descriptors.empty()) return {};
    return vocabulary_->transform(f.descriptors);
  }

  void add(std::size_t frame, const Bow& bow) { database_.add(frame, bow); }

  /// The `n` best-scoring indexed frames (among `*only` when given), best first.
  [[nodiscard]] std::vector<RankedFrame> rank(const Bow& bow, std::size_t n,
                                              const std::vector<std::size_t>* only) const {
    QueryFilter<std::size_t> filter;
    if (only) filter.only = *only;
    std::vector<RankedFrame> out;
    for (const auto& m : database_.query(bow, n, filter)) out.push_back({m.id, m.score});
    return out;
  }

  /// The inverted file and the stored vectors (the vocabulary is shared, not counted).
  [[nodiscard]] std::size_t memory_bytes() const noexcept { return database_.memory_bytes(); }

  [[nodiscard]] const AnyVocabulary* vocabulary() const noexcept { return vocabulary_.get(); }
  [[nodiscard]] const PlaceDatabase<std::size_t>& database() const noexcept { return database_; }

 private:
  std::shared_ptr<const AnyVocabulary> vocabulary_;
  PlaceDatabase<std::size_t> database_;
};

static_assert(PlaceRanking<PlaceRanker>);

}  // namespace vmap
