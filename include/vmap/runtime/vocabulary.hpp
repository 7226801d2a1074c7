#pragma once

// Vocabularies as a program gets them: learned on a set of frames' features with a
// number of words and a depth (`vmap vocabulary`, the offline loop run without a
// vocabulary file), and written in the formats vmap writes.
//
//   vmap::VocabularyLearning learning{.words = 1000, .depth = 3};
//   learning.validate();                       // before any frame is read
//   vmap::AnyVocabulary v = vmap::learn_vocabulary(features, learning);
//   vmap::save_vocabulary(v, "voc.txt");      // ORB-SLAM2 text, by the file's name
//
// The words and the depth give the tree's branching k: the smallest with k^depth >= words
// (a tree leaves small nodes unsplit, so it ends with fewer than k^depth words). Formats:
// vmap's own, ORB-SLAM2's text (ORBvoc.txt) and FBoW's binary, the last two for binary
// vocabularies only; picked from a file's name (.txt ORB-SLAM2 text, .fbow FBoW, anything
// else vmap's) unless named.

#include <vmap/core/error.hpp>
#include <vmap/core/features.hpp>
#include <vmap/core/names.hpp>
#include <vmap/io/atomic_file.hpp>
#include <vmap/place/vocabulary.hpp>
#include <vmap/place/vocabulary_import.hpp>
#include <vmap/place/vocabulary_tree.hpp>
#include <vmap/runtime/option_names.hpp>

#include <opencv2/core.hpp>

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <system_error>
#include <vector>

namespace vmap {

/// A vocabulary to learn (see the top of this file). Options of `vmap vocabulary` and of
/// the loop run (--words, --depth, --seed; Python's words, depth, seed).
struct VocabularyLearning {
  /// At most this many words, in [2, max_words]. 1000 (k = 10, L = 3): the ORB vocabulary
  /// of the loop-closure benchmarks (examples/loops.md).
  std::size_t words = 1000;
  int depth = 3;           ///< L of the tree, in [1, max_depth]
  std::uint64_t seed = 1;  ///< of the sample and the clustering

  static constexpr std::size_t max_words = 100000000;
  /// Deeper trees than this have words of a handful of descriptors at any size we learn.
  static constexpr int max_depth = 16;

  /// k: the smallest branching with k^depth >= words, but at most one above the tree's
  /// largest (validate() refuses that).
  [[nodiscard]] int branching() const noexcept {
    int k = 2;
    while (k <= BinaryVocabularyTree::max_branching &&
           std::pow(static_cast<double>(k), depth) < static_cast<double>(words))
      ++k;
    return k;
  }

  /// An Error naming the inputs (as `names` spells them) when the words and the depth are
  /// out of bounds or ask for a branching above the tree's 4096.
  void validate(const OptionNames& names = OptionNames::keywords()) const {
    detail::check(depth >= 1 && depth <= max_depth, [&] {
      return names("depth") + ": must be in [1, " + std::to_string(max_depth) + "], got " + std::to_string(depth);
    });
    detail::check(words >= 2 && words <= max_words, [&] {
      return names("words") + ": must be in [2, " + std::to_string(max_words) + "], got " + std::to_string(words);
    });
    detail::check(branching() <= BinaryVocabularyTree::max_branching, [&] {
      return names.with_value("words", std::to_string(words)) + " with " +
             names.with_value("depth", std::to_string(depth)) + " needs a branching above " +
             std::to_string(BinaryVocabularyTree::max_branching) + "; raise " + names("depth") + " or lower " +
             names("words");
    });
  }
};

/// A vocabulary learned from the descriptors of a set of frames: binary descriptors by
/// k-majority on Hamming distance, float ones by k-means on L2 (the Features say which).
/// Frames without descriptors are passed over; an Error when none has any.
[[nodiscard]] inline AnyVocabulary learn_vocabulary(const std::vector<Features>& frames, const VocabularyLearning& o) {
  o.validate();
  std::vector<cv::Mat> sets;
  for (const Features& f : frames)
    if (!f.descriptors.empty()) sets.push_back(f.descriptors);
  detail::check(!sets.empty(), "learn_vocabulary: the frames have no descriptors");
  return AnyVocabulary::learn(sets, {.branching = o.branching(), .depth = o.depth, .seed = o.seed});
}

/// The file formats vmap writes a vocabulary in.
enum class VocabularyFileFormat : std::uint8_t {
  vmap,          ///< vmap's own (AnyVocabulary::save), binary or float trees
  orbslam_text,  ///< ORB-SLAM2/3's ORBvoc.txt, binary trees
  fbow,          ///< FBoW's binary, binary trees
};

/// vmap, orbslam_text, fbow (core/names.hpp).
[[nodiscard]] constexpr auto names_of(VocabularyFileFormat) noexcept {
  return detail::NameTable<VocabularyFileFormat, 3>{{{{VocabularyFileFormat::vmap, "vmap"},
                                                      {VocabularyFileFormat::orbslam_text, "orbslam_text"},
                                                      {VocabularyFileFormat::fbow, "fbow"}}}};
}
[[nodiscard]] constexpr std::string_view to_string(VocabularyFileFormat f) noexcept { return names_of(f).name(f); }

/// The format a file's name asks for: .txt ORB-SLAM2 text, .fbow FBoW, anything else vmap's.
[[nodiscard]] inline VocabularyFileFormat vocabulary_format_of(const std::filesystem::path& path) {
  const std::string ext = path.extension().string();
  if (ext == ".txt") return VocabularyFileFormat::orbslam_text;
  if (ext == ".fbow") return VocabularyFileFormat::fbow;
  return VocabularyFileFormat::vmap;
}

/// The bytes of `v` in `format`; an Error naming `who` for a float vocabulary in a format
/// that holds binary ones.
[[nodiscard]] inline std::string vocabulary_file_bytes(const AnyVocabulary& v, VocabularyFileFormat format,
                                                       const std::string& who) {
  if (format == VocabularyFileFormat::vmap) return v.serialize();
  if (v.binary() == nullptr)
    detail::fail(who + " is a float vocabulary; " +
                 (format == VocabularyFileFormat::fbow ? "FBoW" : "ORB-SLAM2 text") + " files hold binary ones");
  return format == VocabularyFileFormat::fbow ? fbow_bytes(*v.binary()) : orbslam_text(*v.binary());
}

/// Fails (an Error naming `out`) unless a vocabulary may be written to `out`, checked
/// before anything is read or written (vmap vocabulary convert and learn, Python's save
/// with overwrite). A save replaces the file whole, so it must never replace what the
/// user did not mean to give up:
///   - `out` that is the same file as `input` (also through links or another name) is
///     refused: the input is what is being converted;
///   - a folder, a FIFO, a device or a socket is refused without being opened;
///   - an existing file is replaced only when `overwrite` is set AND it is itself a
///     vocabulary vmap reads, recognised by its content (AnyVocabulary::load), whatever
///     its name: a memory, an image or any other file is never replaced.
/// `overwrite_option` names how the caller asks to overwrite ("--force") in the message.
inline void check_vocabulary_output(const std::filesystem::path& out, bool overwrite,
                                    const std::optional<std::filesystem::path>& input = std::nullopt,
                                    const std::string& overwrite_option = "overwrite") {
  const std::string name = "vocabulary output '" + out.string() + "'";
  std::error_code ec;
  const auto st = std::filesystem::status(out, ec);
  if (!std::filesystem::exists(st)) return;  // a new file (or a link to one: the save makes it)
  if (input) {
    std::error_code same_ec;
    if (std::filesystem::equivalent(*input, out, same_ec) && !same_ec)
      detail::fail(name + " is the input file '" + input->string() + "'; write the vocabulary to another file");
  }
  if (std::filesystem::is_directory(st)) detail::fail(name + " is a folder, expected a file");
  if (!std::filesystem::is_regular_file(st))
    detail::fail(name + " is not a regular file (a device, FIFO or socket); it is not written to");
  if (!overwrite)
    detail::fail(name + " already exists; it is replaced only when asked to (" + overwrite_option +
                 "), and only when it is a vocabulary");
  try {
    (void)AnyVocabulary::load(out);
  } catch (const Error& e) {
    detail::fail(name + " exists and is not a vocabulary vmap reads, so it is not replaced (" + e.what() + ")");
  }
}

/// Writes `v` to `path` atomically (a temporary file renamed over it) in `format`, or the
/// format the file's name asks for (vocabulary_format_of).
inline void save_vocabulary(const AnyVocabulary& v, const std::filesystem::path& path,
                            std::optional<VocabularyFileFormat> format = std::nullopt,
                            const std::string& who = "the vocabulary") {
  write_file_atomically(path, vocabulary_file_bytes(v, format.value_or(vocabulary_format_of(path)), who));
}

}  // namespace vmap
