#pragma once

// The place-recognition layer (place/) as the ranking stage of LoopDetector: a
// vocabulary tree turns each key frame's descriptors into a TF-IDF bag of words, and an
// inverted-file PlaceDatabase ranks the indexed frames (all of them, or the tree's leaf)
// by the DBoW2 score.

#include <vmap/core/error.hpp>
#include <vmap/core/features.hpp>
#include <vmap/place/bow.hpp>
#include <vmap/place/database.hpp>
#include <vmap/place/match.hpp>
#include <vmap/place/vocabulary.hpp>

#include <opencv2/core.hpp>

#include <concepts>
#include <cstddef>
#include <cstdint>
#include <string>
#include <memory>
#include <utility>
#include <vector>

namespace vmap {

/// What the ranked candidate sources need from a place-recognition index: a bag of
/// words per frame (computed once, when the frame is pushed), an inverted file the
/// detector adds frames to when they leave the window, and a top-k query that may be
/// restricted to a set of frames (the tree's leaf). PlaceRanker below adapts the place/ layer;
/// a test may script one.
template <class R>
concept PlaceRanking = std::move_constructible<R> &&
    requires(R& r, const R& cr, const Features& f, const typename R::Bow& bow, std::size_t id, std::size_t k,
             const std::vector<std::size_t>* only) {
      typename R::Bow;
      { cr.ready() } -> std::convertible_to<bool>;                      // can describe and rank
      { cr.describe(f) } -> std::same_as<typename R::Bow>;              // the frame's bag of words
      { r.add(id, bow) };                                               // indexes a frame
      // Best first among the indexed frames with from <= id < before (only == nullptr)
      // or among `*only`; the id is the frame's index.
      { cr.rank(bow, k, only, id, id) } -> std::same_as<std::vector<PlaceMatch<std::size_t>>>;
      { cr.similarity(bow, id) } -> std::convertible_to<double>;        // score against an indexed frame
      { cr.similarity(id, id) } -> std::convertible_to<double>;         // score of two indexed frames
      { cr.memory_bytes() } -> std::convertible_to<std::size_t>;        // the index's memory
    };

/// Models PlaceRanking over a shared, read-only vocabulary (one vocabulary may serve
/// several detectors and threads: its const members are thread-safe). Without a
/// vocabulary (default-constructed) it is not `ready()`, which the tree and brute_force
/// sources do not need. `Id` is the database's id type (the visual memory's key images
/// are 32-bit).
template <class Id = std::size_t>
class BasicPlaceRanker {
 public:
  using Bow = BowVector;

  BasicPlaceRanker() = default;
  explicit BasicPlaceRanker(std::shared_ptr<const AnyVocabulary> vocabulary, BowScoring scoring = BowScoring::l1)
      : vocabulary_(std::move(vocabulary)),
        database_(vocabulary_ ? vocabulary_->size() : 0, scoring) {
    detail::check(!vocabulary_ || !vocabulary_->empty(), "PlaceRanker: the vocabulary has no words");
  }
  /// Over a database already filled (a loaded memory): its ids and vectors are the
  /// frames indexed so far.
  BasicPlaceRanker(std::shared_ptr<const AnyVocabulary> vocabulary, PlaceDatabase<Id> database)
      : vocabulary_(std::move(vocabulary)), database_(std::move(database)) {
    detail::check(vocabulary_ && !vocabulary_->empty(), "PlaceRanker: the vocabulary has no words");
    detail::check(database_.words() == vocabulary_->size(), [&] {
      return "PlaceRanker: the database has " + std::to_string(database_.words()) + " words, the vocabulary " +
             std::to_string(vocabulary_->size());
    });
  }

  [[nodiscard]] bool ready() const noexcept { return vocabulary_ != nullptr; }

  /// The frame's TF-IDF bag of words; descriptors of the other kind than the vocabulary
  /// (binary / float) are an Error naming both.
  [[nodiscard]] Bow describe(const Features& f) const {
    detail::check(ready(), "PlaceRanker::describe: no vocabulary");
    if (f.descriptors.empty()) return {};
    detail::check(f.descriptors.type() == vocabulary_->descriptor_type() &&
                      f.descriptors.cols == vocabulary_->descriptor_cols(),
                  ErrorKind::policy_mismatch, [&] {
                    return "PlaceRanker: descriptors of type " + cv::typeToString(f.descriptors.type()) + " x " +
                           std::to_string(f.descriptors.cols) + " do not fit the vocabulary (" +
                           cv::typeToString(vocabulary_->descriptor_type()) + " x " +
                           std::to_string(vocabulary_->descriptor_cols()) + ")";
                  });
    return vocabulary_->transform(f.descriptors);
  }

  void add(std::size_t frame, const Bow& bow) { database_.add(static_cast<Id>(frame), bow); }

  /// The `top_k` best-scoring indexed frames, best first: among `*only` when given, else
  /// among those with `from` <= id < `before`.
  [[nodiscard]] std::vector<PlaceMatch<std::size_t>> rank(const Bow& bow, std::size_t top_k,
                                                          const std::vector<std::size_t>* only,
                                                          std::size_t before = static_cast<std::size_t>(-1),
                                                          std::size_t from = 0) const {
    QueryFilter<Id> filter;
    if (only) {
      filter.only.emplace();
      for (std::size_t id : *only) filter.only->push_back(static_cast<Id>(id));
    } else {
      if (before != static_cast<std::size_t>(-1)) filter.before = static_cast<Id>(before);
      if (from > 0) filter.from = static_cast<Id>(from);
    }
    std::vector<PlaceMatch<std::size_t>> out;
    for (const auto& m : database_.query(bow, top_k, filter)) out.push_back({static_cast<std::size_t>(m.id), m.score});
    return out;
  }

  /// The score of `bow` against indexed frame `id` (0 when it is not indexed).
  [[nodiscard]] double similarity(const Bow& bow, std::size_t id) const {
    const BowVector* v = database_.bow(static_cast<Id>(id));
    return v ? bow_score(bow, *v, database_.scoring()) : 0.0;
  }
  /// The score of two indexed frames (0 when either is not indexed).
  [[nodiscard]] double similarity(std::size_t a, std::size_t b) const {
    const BowVector* v = database_.bow(static_cast<Id>(a));
    return v ? similarity(*v, b) : 0.0;
  }

  /// The inverted file and the stored vectors (the vocabulary is shared, not counted).
  [[nodiscard]] std::size_t memory_bytes() const noexcept { return database_.memory_bytes(); }

  [[nodiscard]] const AnyVocabulary* vocabulary() const noexcept { return vocabulary_.get(); }
  [[nodiscard]] const PlaceDatabase<Id>& database() const noexcept { return database_; }

 private:
  std::shared_ptr<const AnyVocabulary> vocabulary_;
  PlaceDatabase<Id> database_;
};

using PlaceRanker = BasicPlaceRanker<std::size_t>;

static_assert(PlaceRanking<PlaceRanker>);
static_assert(PlaceRanking<BasicPlaceRanker<std::uint32_t>>);

}  // namespace vmap
