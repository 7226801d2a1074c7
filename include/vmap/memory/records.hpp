#pragma once

// The visual memory's state as records (examples/methods.md, sec. 6): what a memory is made of,
// apart from where it is kept. VisualMemory assembles them (records()) and is rebuilt
// from them (from_records()); the back-ends keep them: the single-file format
// (memory/vmem.hpp, whole) and the memory store (memory/store.hpp: SQLite, key image by
// key image). Each record is encoded by the codec beside its part (memory/detail/
// record_codecs.hpp), so every back-end stores the same bytes.
//
// A MemoryRecords is either a whole memory or what a memory made since a back-end last
// took its records (VisualMemory::records(since)): the lists then start at `first_*`,
// and the vocabulary and the GCS are present only when they changed.

#include <vmap/geometry/pose2.hpp>
#include <vmap/hooks/detection.hpp>
#include <vmap/keyframe/selector.hpp>
#include <vmap/keyframe/visual_map.hpp>
#include <vmap/lcd/loop_engine.hpp>
#include <vmap/memory/gcs.hpp>
#include <vmap/memory/types.hpp>
#include <vmap/place/bow.hpp>
#include <vmap/place/vocabulary.hpp>

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace vmap {

/// Written by this build: the single-file format's version (memory/vmem.hpp). Records
/// read from a file or store of an older format carry theirs (MemoryRecords::version).
inline constexpr std::uint32_t memory_format_version = 5;

/// A key image as the memory keeps it: the key image (frame, times, name, features and
/// pixels), the odometry pose pushed with its frame, and that frame's detections.
struct KeyImageRecord {
  KeyImage key;
  OdometryPose pose;
  std::vector<Detection> detections;
};

/// The key-image selector's state besides its key images and links (Algorithm 1 / eq. 6):
/// I_{j-1} while it is not the last key image (its features, pose and detections: a
/// later key image may be that frame), its score against the key image, and the index
/// of the last frame pushed.
struct SelectorRecord {
  std::optional<KeyImageRecord> previous;
  std::optional<PairScore> previous_score;
  /// previous_score's homography degeneracy test was deferred (SelectorState): its inlier
  /// mask is kept so the restored selector completes it.
  bool degeneracy_deferred = false;
  std::optional<std::size_t> last_frame_index;
};

/// What a back-end holds of a memory: where the next records() starts.
struct RecordsHeld {
  std::size_t keys = 0, loops = 0, bows = 0, sessions = 0;
  /// Whether it holds a vocabulary record, and whether that one is a learned (or given)
  /// vocabulary rather than the empty one of a memory that has none yet.
  std::optional<bool> vocabulary_written;
  std::optional<std::uint64_t> gcs;  ///< the GCS generation it holds (VisualMemory::gcs_generation)
};

/// A memory's records (see the top of this file).
struct MemoryRecords {
  std::uint32_t version = memory_format_version;  ///< the format they were read from
  MemoryOptions options;
  std::array<std::string, 4> policies;  ///< descriptor, matcher, estimator, similarity (VisualMemory::policy_records)
  std::size_t frames = 0;               ///< frames pushed

  std::size_t first_key = 0;            ///< keys[i] is key image first_key + i
  std::vector<KeyImageRecord> keys;
  /// The link into each key image of `keys` but key image 0: links[i] joins key image
  /// first_link() + i to the one after it.
  std::vector<KeyPair> links;
  std::size_t first_loop = 0;
  std::vector<LoopEdge> loops;          ///< with their confidences
  std::size_t first_bow = 0;            ///< bows[i] is key image first_bow + i's bag of words
  std::vector<BowVector> bows;          ///< of the key images checked for loops (the place database)
  std::size_t words = 0;                ///< the place database's vocabulary size

  SelectorRecord selector;
  /// The place vocabulary (empty before one is learned); null in a delta that does not
  /// change it.
  std::shared_ptr<const AnyVocabulary> vocabulary;
  bool labelled = false;                ///< frames come with detections
  std::optional<LabelSchema> schema;    ///< the label schema once fixed
  bool gcs_written = true;              ///< false in a delta whose GCS did not change
  std::optional<MemoryGcs> gcs;
  LoopEngineState engine;               ///< the loop engine's counts (zero before it runs)
  std::size_t first_session = 0;
  std::vector<MemorySession> sessions;  ///< the first starts at key image 0 and frame 0

  /// The first link in `links`: the link into key image max(first_key, 1), which is
  /// pairs[max(first_key, 1) - 1] of the map.
  [[nodiscard]] std::size_t first_link() const noexcept { return first_key > 0 ? first_key - 1 : 0; }
  /// Key images of the memory (those before `first_key` and those in `keys`).
  [[nodiscard]] std::size_t key_count() const noexcept { return first_key + keys.size(); }
};

}  // namespace vmap
