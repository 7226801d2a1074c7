#pragma once

// A visual memory's options, alone: a program (or a configuration file's reader) that
// builds MemoryOptions includes this, which holds no code of the memory, instead of
// memory/types.hpp or memory/visual_memory.hpp.

#include <vmap/keyframe/options.hpp>
#include <vmap/lcd/options.hpp>
#include <vmap/place/options.hpp>
#include <vmap/som/options.hpp>

#include <cstddef>
#include <cstdint>
#include <vector>

namespace vmap {

/// How key images' pixels are kept and saved.
enum class ImageStorage : std::uint8_t {
  none,  ///< features only (the smallest memory; localize and loops need no pixels)
  png,   ///< lossless
  jpeg,  ///< lossy, MemoryOptions::jpeg_quality (smaller than PNG; sizes per key image: see
         ///< examples/bench/bench_memory.cpp; results in examples/results/memory.md)
};

/// LFM-LCD's label tree inside the memory (Zhu et al., Sensors 2021, sec. 3.2-3.3;
/// examples/methods.md, sec. 2), used when the frames are pushed with object detections.
/// (Eq. 3's score threshold, the candidate source and m of sec. 3.3 are the loop
/// engine's: MemoryOptions::loops.labels, .index, .min_candidates.)
struct MemoryLabelOptions {
  /// The label order, large objects first. Given: it is the schema from the first key
  /// image on, as given (no eq. 5 pruning). Empty: the schema is learned online (below).
  std::vector<int> order{};
  /// Without an order: the detections of the first `sample` key images are the eq. 5
  /// sample M; the schema (labels by mean box area, pruned to the `influence` band) is
  /// then fixed, the tree built and the earlier key images caught up in order (>= 1).
  std::size_t sample = 20;
  InfluenceOptions influence{};
};

/// The GCS localizer trained on the memory's key images (Trujillo-Romero 2024,
/// examples/methods.md, sec. 3): their own features -> BowHistogram -> GCS -> a pose per neuron.
struct MemoryGcsOptions {
  BowHistogramOptions histogram{};  ///< its vocabulary is learned from the key images
  GcsOptions gcs{};                 ///< the network's options (max_cells 100, seed 1)
};

/// The place rule between runs (sessions of one memory, robots of a fleet's:
/// VisualMemory::link_pair): a key image's candidates in the other runs are those whose
/// heavy score against it (place/heavy_words.hpp) is at least this; each is then
/// verified, and the verification decides (examples/results/fleet.md measures the rule).
inline constexpr double run_link_min_score = 0.02;
/// ... and the best this many of them are verified. The rule is the pair's own (the same
/// pairs whatever the order runs are mapped in) while fewer reach the score; the
/// benchmark counts the queries that had more.
inline constexpr std::size_t run_link_candidates = 16;
/// ... and a verified pair is a loop when the place decision accepts it with at least
/// this confidence (or the memory's own min_confidence, if higher). A pair between runs
/// stands alone: no temporal consistency and no revisit rule back it, and every pair is
/// kept, not only a query's best, so it needs more evidence than a loop within a run.
/// On rtabmap_loop as two sessions, 8 of the 151 pairs accepted at 0.5 were no revisit
/// and none of the 84 at 0.9 (examples/results/memory.md, "Sessions across runs").
inline constexpr double run_link_min_confidence = 0.9;

struct MemoryOptions {
  /// The key-image selector's options (tau, eq. 6 / Algorithm 1 rule, fast path).
  /// `keep_images` is set from `images`.
  SelectorOptions selector{};
  ImageStorage images = ImageStorage::none;
  int jpeg_quality = 90;  ///< 1..100, for ImageStorage::jpeg
  /// Without a vocabulary given to the constructor, one is learned from the descriptors
  /// of the first `vocabulary_after` key images (>= 1); loop detection then runs for
  /// those in order, as if the vocabulary had been there from the start.
  std::size_t vocabulary_after = 20;
  /// The learned vocabulary's shape (DBoW2-like tree; default 10^3 words, seeded).
  VocabularyTreeOptions vocabulary{};
  BowScoring scoring = BowScoring::l1;
  /// The loop engine's options (lcd/loop_engine.hpp): the window of recent key images
  /// that are not candidates, the top k verified, the decision (confidence threshold),
  /// the revisit rule. `index` is used with detections (tree or tree_ranked); without,
  /// the memory ranks every key image by bag of words (bow).
  LoopOptions loops{};
  /// localize() verifies the best `localize_top_k` key images by BoW score (>= 1)
  /// and decides with loops.decision.
  std::size_t localize_top_k = 5;
  /// The label-tree loop detection, used when frames are pushed with detections.
  MemoryLabelOptions labels{};
};

}  // namespace vmap
