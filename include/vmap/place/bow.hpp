#pragma once

// Bag-of-words vectors and their similarity scores (Gálvez-López and Tardós, "Bags of
// Binary Words for Fast Place Recognition in Image Sequences", IEEE T-RO 2012; the
// scores are those of DBoW2's ScoringObject.cpp).
//
// A BowVector is sparse: (word, weight) entries sorted by word id, each word at most
// once. Vocabulary trees (vocabulary.hpp) produce them TF-IDF weighted and
// L1-normalised; the scores below normalise their inputs themselves, so any vector of
// non-negative weights can be scored.

#include <vmap/core/error.hpp>
#include <vmap/core/name_table.hpp>
#include <vmap/place/options.hpp>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace vmap {

struct BowEntry {
  std::uint32_t word = 0;  ///< word (leaf) id of the vocabulary
  float weight = 0.0f;     ///< its weight in the image (TF-IDF), >= 0

  friend bool operator==(const BowEntry&, const BowEntry&) = default;
};

/// Sparse bag-of-words vector: entries sorted by strictly increasing word id.
struct BowVector {
  std::vector<BowEntry> entries;

  [[nodiscard]] std::size_t size() const noexcept { return entries.size(); }
  [[nodiscard]] bool empty() const noexcept { return entries.empty(); }
  [[nodiscard]] auto begin() const noexcept { return entries.begin(); }
  [[nodiscard]] auto end() const noexcept { return entries.end(); }

  /// Sum of the weights (the L1 norm, weights being >= 0).
  [[nodiscard]] double l1_norm() const noexcept {
    double s = 0.0;
    for (const auto& e : entries) s += std::fabs(static_cast<double>(e.weight));
    return s;
  }
  [[nodiscard]] double l2_norm() const noexcept {
    double s = 0.0;
    for (const auto& e : entries) s += static_cast<double>(e.weight) * static_cast<double>(e.weight);
    return std::sqrt(s);
  }

  friend bool operator==(const BowVector&, const BowVector&) = default;
};

namespace detail {

/// Fails unless `v` is a valid BowVector: words strictly increasing (below `words` when
/// `words` > 0), weights finite and >= 0. `what` names the vector in the message.
inline void check_bow(const BowVector& v, std::size_t words, const std::string& what) {
  for (std::size_t i = 0; i < v.entries.size(); ++i) {
    const auto& e = v.entries[i];
    if (i > 0 && e.word <= v.entries[i - 1].word)
      fail(what + ": words are not strictly increasing at entry " + std::to_string(i));
    if (words > 0 && e.word >= words)
      fail(what + ": word " + std::to_string(e.word) + " is outside the vocabulary of " + std::to_string(words) +
           " words");
    if (!(std::isfinite(e.weight) && e.weight >= 0.0f))
      fail(what + ": weight of word " + std::to_string(e.word) + " is negative or not finite");
  }
}

/// The norm a scoring normalises with: L1 for BowScoring::l1, L2 otherwise.
inline double scoring_norm(const BowVector& v, BowScoring s) noexcept {
  return s == BowScoring::l1 ? v.l1_norm() : v.l2_norm();
}

/// The score from the sum over shared words of min(v_i, w_i) (L1) or v_i w_i (L2,
/// cosine), the vectors being normalised. For L1 with non-negative weights,
/// |v - w|_1 = |v|_1 + |w|_1 - 2 sum min(v_i, w_i) = 2 - 2 sum min, so DBoW2's
/// 1 - 0.5 |v - w|_1 is exactly that sum (DBoW2's L1Scoring computes the same from
/// the shared words: sum |v_i - w_i| - |v_i| - |w_i|, times -1/2).
inline double score_from_shared(double shared, BowScoring s) noexcept {
  switch (s) {
    case BowScoring::l1: return std::min(1.0, shared);
    case BowScoring::l2: return shared >= 1.0 ? 1.0 : 1.0 - std::sqrt(1.0 - shared);  // DBoW2 L2Scoring
    case BowScoring::cosine: return std::min(1.0, shared);
  }
  return 0.0;
}

/// The contribution of one shared word (normalised weights a, b).
inline double shared_term(double a, double b, BowScoring s) noexcept {
  return s == BowScoring::l1 ? std::min(a, b) : a * b;
}

}  // namespace detail

/// Similarity of two bag-of-words vectors (weights >= 0; each is normalised here by the
/// norm of the scoring). An empty or all-zero vector scores 0 against anything. Cost:
/// O(|v| + |w|).
[[nodiscard]] inline double bow_score(const BowVector& v, const BowVector& w, BowScoring scoring = BowScoring::l1) {
  detail::check_bow(v, 0, "bow_score: first vector");
  detail::check_bow(w, 0, "bow_score: second vector");
  const double nv = detail::scoring_norm(v, scoring);
  const double nw = detail::scoring_norm(w, scoring);
  if (nv <= 0.0 || nw <= 0.0) return 0.0;
  double shared = 0.0;
  auto a = v.entries.begin();
  auto b = w.entries.begin();
  while (a != v.entries.end() && b != w.entries.end()) {
    if (a->word < b->word) {
      ++a;
    } else if (b->word < a->word) {
      ++b;
    } else {
      shared += detail::shared_term(a->weight / nv, b->weight / nw, scoring);
      ++a;
      ++b;
    }
  }
  return detail::score_from_shared(shared, scoring);
}

}  // namespace vmap
