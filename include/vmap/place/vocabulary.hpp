#pragma once

// Vocabularies: the vocabulary tree (vocabulary_tree.hpp), the readers of other
// libraries' vocabulary files (vocabulary_import.hpp), and AnyVocabulary, a binary or
// float vocabulary chosen at run time from whatever file it is given.

#include <vmap/core/error.hpp>
#include <vmap/place/bow.hpp>
#include <vmap/place/detail/format.hpp>
#include <vmap/place/vocabulary_import.hpp>
#include <vmap/place/vocabulary_tree.hpp>

#include <opencv2/core.hpp>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string_view>
#include <string>
#include <utility>
#include <variant>
#include <vector>

namespace vmap {

namespace detail {
/// Whether the bytes of one of vmap's own vocabulary files (from its start, at least
/// through the kind) hold a float tree: the kind is the first payload byte; the typed
/// reader checks the rest.
[[nodiscard]] inline bool holds_float_tree(std::string_view head) noexcept {
  return head.size() > place_header_size && static_cast<std::uint8_t>(head[place_header_size]) == L2Traits::file_kind;
}
}  // namespace detail

/// A binary or a float vocabulary chosen at run time (a file given on a command line,
/// descriptors of whatever kind a descriptor produces).
class AnyVocabulary {
 public:
  AnyVocabulary() = default;
  AnyVocabulary(BinaryVocabularyTree v) : v_(std::move(v)) {}  // NOLINT: implicit on purpose
  AnyVocabulary(FloatVocabularyTree v) : v_(std::move(v)) {}   // NOLINT: implicit on purpose

  /// Learns a binary tree from CV_8UC1 descriptors, a float tree from CV_32FC1 ones (the
  /// type of the first non-empty matrix).
  static AnyVocabulary learn(const std::vector<cv::Mat>& descriptor_sets, const VocabularyTreeOptions& o = {}) {
    for (const auto& d : descriptor_sets) {
      if (d.empty()) continue;
      if (d.type() == CV_8UC1) return BinaryVocabularyTree::learn(descriptor_sets, o);
      if (d.type() == CV_32FC1) return FloatVocabularyTree::learn(descriptor_sets, o);
      detail::fail("AnyVocabulary::learn: descriptors of type " + cv::typeToString(d.type()) +
                   " (a vocabulary needs CV_8UC1 or CV_32FC1)");
    }
    detail::fail("AnyVocabulary::learn: no image has descriptors");
  }

  /// Reads a vocabulary file of any format vmap knows, told apart by its content
  /// (vocabulary_import.hpp): vmap's own (binary or float, VocabularyTree::save),
  /// ORB-SLAM2/3's ORBvoc.txt, DBoW2's YAML (.yml, .yml.gz) or FBoW's binary.
  static AnyVocabulary load(const std::filesystem::path& path) {
    {
      std::ifstream in = detail::open_regular_file(path, "vocabulary file");
      char head[detail::place_header_size + 1] = {};
      in.read(head, sizeof head);
      if (in.gcount() == static_cast<std::streamsize>(sizeof head) &&
          std::string_view(head, 8) == BinaryVocabularyTree::file_magic() &&
          detail::holds_float_tree(std::string_view(head, sizeof head)))
        return FloatVocabularyTree::load(path);
    }
    return import_binary_vocabulary(path);
  }

  /// The typed tree's bytes (VocabularyTree::serialize), as its file holds them.
  [[nodiscard]] std::string serialize() const {
    return std::visit([](const auto& v) { return v.serialize(); }, v_);
  }

  /// Reads serialize()'s bytes, a binary or a float tree by its kind; `what` names the
  /// bytes in an error (e.g. a memory file's section).
  [[nodiscard]] static AnyVocabulary deserialize(std::string_view bytes, const std::string& what) {
    if (detail::holds_float_tree(bytes)) return FloatVocabularyTree::deserialize(bytes, what);
    return BinaryVocabularyTree::deserialize(bytes, what);
  }

  [[nodiscard]] BowWeighting weighting() const noexcept {
    return std::visit([](const auto& v) { return v.weighting(); }, v_);
  }
  [[nodiscard]] BowScoring scoring() const noexcept {
    return std::visit([](const auto& v) { return v.scoring(); }, v_);
  }

  void save(const std::filesystem::path& path) const {
    std::visit([&](const auto& v) { v.save(path); }, v_);
  }

  [[nodiscard]] BowVector transform(const cv::Mat& descriptors) const {
    return std::visit([&](const auto& v) { return v.transform(descriptors); }, v_);
  }
  [[nodiscard]] std::vector<std::uint32_t> assign(const cv::Mat& descriptors) const {
    return std::visit([&](const auto& v) { return v.assign(descriptors); }, v_);
  }
  [[nodiscard]] std::size_t size() const noexcept {
    return std::visit([](const auto& v) { return v.size(); }, v_);
  }
  [[nodiscard]] bool empty() const noexcept { return size() == 0; }
  [[nodiscard]] int branching() const noexcept {
    return std::visit([](const auto& v) { return v.branching(); }, v_);
  }
  [[nodiscard]] int depth() const noexcept {
    return std::visit([](const auto& v) { return v.depth(); }, v_);
  }
  [[nodiscard]] int descriptor_type() const noexcept {
    return std::visit([](const auto& v) { return v.descriptor_type(); }, v_);
  }
  [[nodiscard]] int descriptor_cols() const noexcept {
    return std::visit([](const auto& v) { return v.descriptor_cols(); }, v_);
  }
  [[nodiscard]] std::size_t memory_bytes() const noexcept {
    return std::visit([](const auto& v) { return v.memory_bytes(); }, v_);
  }
  void learn_idf(const std::vector<cv::Mat>& descriptor_sets) {
    std::visit([&](auto& v) { v.learn_idf(descriptor_sets); }, v_);
  }

  /// The typed vocabulary, or nullptr when it is of the other kind.
  [[nodiscard]] const BinaryVocabularyTree* binary() const noexcept { return std::get_if<BinaryVocabularyTree>(&v_); }
  [[nodiscard]] const FloatVocabularyTree* floating() const noexcept { return std::get_if<FloatVocabularyTree>(&v_); }

 private:
  std::variant<BinaryVocabularyTree, FloatVocabularyTree> v_;
};

}  // namespace vmap
