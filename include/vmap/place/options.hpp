#pragma once

// The vocabulary tree's learning options and the bag-of-words scores, alone (see
// place/vocabulary_tree.hpp and place/bow.hpp for what they mean in use).

#include <vmap/core/name_table.hpp>

#include <cstddef>
#include <cstdint>
#include <string_view>

namespace vmap {

/// How two bag-of-words vectors are compared; every score is in [0, 1], 1 for equal
/// directions, 0 for vectors that share no word.
enum class BowScoring {
  l1,     ///< DBoW2's L1 score: 1 - 0.5 * | v/|v|_1 - w/|w|_1 |_1 (T-RO 2012, eq. 2)
  l2,     ///< DBoW2's L2 score: 1 - sqrt(1 - <v, w>) on L2-normalised vectors
  cosine  ///< <v, w> / (|v|_2 |w|_2)
};

/// l1, l2, cosine (core/names.hpp).
[[nodiscard]] constexpr auto names_of(BowScoring) noexcept {
  return detail::NameTable<BowScoring, 3>{
      {{{BowScoring::l1, "l1"}, {BowScoring::l2, "l2"}, {BowScoring::cosine, "cosine"}}}};
}
/// A C string (every name is a literal), for messages built with std::string's +.
[[nodiscard]] inline const char* to_string(BowScoring s) noexcept { return names_of(s).name(s).data(); }

struct VocabularyTreeOptions {
  int branching = 10;                   ///< children per node k, 2..4096
  int depth = 3;                        ///< levels L, 1..64 (at most k^L words)
  int iterations = 10;                  ///< k-means / k-majority rounds per node, >= 1
  std::size_t max_descriptors = 200000; ///< random sample learned from (bounds the time), >= branching
  std::uint64_t seed = 1;               ///< the sample and the k-means++ seeding
};

}  // namespace vmap
