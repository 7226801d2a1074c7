#pragma once

// The GCS localizer's options (its histogram and its network), alone (see
// som/histogram.hpp and som/gcs.hpp).

#include <vmap/place/options.hpp>

#include <cstddef>
#include <cstdint>

namespace vmap {

enum class HistogramNorm { l1, l2 };

struct BowHistogramOptions {
  /// How the words are learned in fit(): a flat vocabulary, i.e. a BinaryVocabularyTree
  /// of depth 1 (any other depth is an Error) whose `branching` k-majority clusters of the
  /// training descriptors are the words (2..4096; empty clusters are dropped). Fewer words
  /// and descriptors than a place-recognition tree's defaults: a GCS map is learned from
  /// a few hundred images. A designated initializer starts from VocabularyTreeOptions'
  /// own defaults (depth 3), so it names all five: `{.branching = 128, .depth = 1, ...}`.
  VocabularyTreeOptions vocabulary{.branching = 64, .depth = 1, .iterations = 8, .max_descriptors = 20000, .seed = 1};
  HistogramNorm norm = HistogramNorm::l2;  ///< normalisation of the word counts
};

/// Options with the paper's names (Trujillo-Romero 2024, Algorithm 1; Fritzke 1994).
struct GcsOptions {
  double eps_b = 0.06;   ///< winner learning rate, in (0, 1]
  double eps_n = 0.002;  ///< learning rate of the winner's direct neighbours, in (0, 1]
  double alpha = 0.005;  ///< every counter is multiplied by (1 - alpha) each step, in (0, 1)
  std::size_t lambda = 100;  ///< a cell is inserted every lambda adaptation steps, >= 1
  /// Removal threshold on a cell's estimated probability density relative to the mean
  /// density (1 = average; see GrowingCellStructures::relative_density). Cells below it
  /// are removed every lambda steps. 0 disables removal: the paper's maps hold more
  /// neurons than training images, so most cells rarely win and must be kept.
  double eta = 0.0;
  std::size_t max_cells = 100;    ///< training stops after the epoch in which this many cells exist
  std::size_t max_epochs = 1000;  ///< ... or after this many passes over the data, >= 1
  std::uint64_t seed = 1;         ///< initial cells and the order of inputs
};

}  // namespace vmap
