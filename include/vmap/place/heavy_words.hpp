#pragma once

// The heavy words of a bag of words, and a score of two images over them that does not
// depend on which of the two asks: the candidates of the place rule between sessions of
// one memory and between robots of a fleet (memory/visual_memory.hpp, memory/fleet.hpp).
//
// An image's heavy words are the `heavy_word_count` words of largest weight in its
// L1-normalised bag of words (T-RO 2012's vectors; ties to the lower word id). The heavy
// score of two images is DBoW2's L1 score (eq. 2: the sum over shared words of
// min(v_i, w_i)) restricted to the words heavy in both. It is symmetric, so a pair of
// images scores the same whichever is the query and whatever else is indexed; a score
// above a threshold is therefore a property of the pair, and the pairs a memory verifies
// are the same whether its sessions come one after the other or its robots map at once.
// Weights are fixed-point integers (units of 2^-32): sums of integers are exact in any
// order, so an index in RAM and a database server's SUM give the same number.
//
// Costs: 64 postings of 16 B per indexed image (HeavyIndex); a query reads the posting
// lists of its 64 heavy words only.

#include <vmap/place/bow.hpp>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <unordered_map>
#include <utility>
#include <vector>

namespace vmap {

/// How many of an image's words are its heavy words.
inline constexpr std::size_t heavy_word_count = 64;

/// One unit of a heavy word's weight: 2^-32 of the bag of words' L1 norm.
inline constexpr double heavy_weight_unit = 4294967296.0;

struct HeavyWord {
  std::uint32_t word = 0;
  std::uint64_t weight = 0;  ///< its share of the L1 norm, in units of 2^-32

  friend bool operator==(const HeavyWord&, const HeavyWord&) = default;
};

/// `bow`'s heavy words, sorted by word id.
[[nodiscard]] inline std::vector<HeavyWord> heavy_words(const BowVector& bow, std::size_t n = heavy_word_count) {
  const double norm = bow.l1_norm();
  std::vector<HeavyWord> all;
  all.reserve(bow.size());
  for (const BowEntry& e : bow) {
    const double w = norm > 0 ? static_cast<double>(e.weight) / norm : 0.0;
    all.push_back({e.word, static_cast<std::uint64_t>(std::llround(std::clamp(w, 0.0, 1.0) * heavy_weight_unit))});
  }
  if (all.size() > n) {
    std::nth_element(all.begin(), all.begin() + static_cast<std::ptrdiff_t>(n), all.end(),
                     [](const HeavyWord& a, const HeavyWord& b) {
                       return a.weight != b.weight ? a.weight > b.weight : a.word < b.word;
                     });
    all.resize(n);
  }
  std::sort(all.begin(), all.end(), [](const HeavyWord& a, const HeavyWord& b) { return a.word < b.word; });
  return all;
}

/// The heavy score of two images in units of 2^-32 (see the top of this file).
[[nodiscard]] inline std::uint64_t heavy_score_units(const std::vector<HeavyWord>& a, const std::vector<HeavyWord>& b) {
  std::uint64_t s = 0;
  for (std::size_t i = 0, j = 0; i < a.size() && j < b.size();) {
    if (a[i].word < b[j].word) {
      ++i;
    } else if (b[j].word < a[i].word) {
      ++j;
    } else {
      s += std::min(a[i++].weight, b[j++].weight);
    }
  }
  return s;
}

/// A score in units of 2^-32 as a number in [0, 1].
[[nodiscard]] inline double heavy_score(std::uint64_t units) noexcept {
  return std::min(1.0, static_cast<double>(units) / heavy_weight_unit);
}
/// A score in [0, 1] in units of 2^-32 (what a threshold compares with).
[[nodiscard]] inline std::uint64_t heavy_units(double score) noexcept {
  return static_cast<std::uint64_t>(std::llround(std::clamp(score, 0.0, 1.0) * heavy_weight_unit));
}

/// An inverted file of heavy words: the images indexed so far, in order of their ids.
class HeavyIndex {
 public:
  struct Hit {
    std::uint32_t id = 0;
    std::uint64_t units = 0;  ///< the heavy score, in units of 2^-32
  };

  /// Indexes image `id` (ids strictly increasing).
  void add(std::uint32_t id, const std::vector<HeavyWord>& words) {
    for (const HeavyWord& w : words) postings_[w.word].push_back({id, w.weight});
    next_ = id + 1;
  }
  /// One past the last id indexed (0 when empty).
  [[nodiscard]] std::uint32_t next() const noexcept { return next_; }
  void clear() {
    postings_.clear();
    next_ = 0;
  }

  /// The indexed images with id < `before` whose heavy score against `query` is at least
  /// `min_units`, best first (ties by id).
  [[nodiscard]] std::vector<Hit> query(const std::vector<HeavyWord>& query, std::uint32_t before,
                                       std::uint64_t min_units) const {
    std::unordered_map<std::uint32_t, std::uint64_t> sums;
    for (const HeavyWord& w : query) {
      const auto it = postings_.find(w.word);
      if (it == postings_.end()) continue;
      for (const Posting& p : it->second) {
        if (p.id >= before) break;  // the list is in id order
        sums[p.id] += std::min(w.weight, p.weight);
      }
    }
    std::vector<Hit> out;
    for (const auto& [id, units] : sums)
      if (units >= min_units) out.push_back({id, units});
    std::sort(out.begin(), out.end(), [](const Hit& a, const Hit& b) { return a.units != b.units ? a.units > b.units : a.id < b.id; });
    return out;
  }

 private:
  struct Posting {
    std::uint32_t id;
    std::uint64_t weight;
  };
  std::unordered_map<std::uint32_t, std::vector<Posting>> postings_;
  std::uint32_t next_ = 0;
};

}  // namespace vmap
