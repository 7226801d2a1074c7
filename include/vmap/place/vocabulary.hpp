#pragma once

// Vocabulary trees (Nistér and Stewénius, "Scalable Recognition with a Vocabulary
// Tree", CVPR 2006; in the form of DBoW2, Gálvez-López and Tardós, T-RO 2012, sec. III):
// descriptors are clustered into `branching` groups, each group again, down to `depth`
// levels; the leaves are the words. Assigning a descriptor walks from the root to a leaf
// comparing it with the children of one node per level: O(branching * depth) distances,
// not O(words).
//
// One template over a distance traits type:
//  - HammingTraits: binary descriptors (CV_8UC1: ORB, BRIEF, A-KAZE M-LDB), Hamming
//    distance, k-majority centres (each bit the majority vote of the members; Grana et
//    al., "A Fast Approach for Integrating ORB Descriptors in the Bag of Words Model",
//    SPIE 2013);
//  - L2Traits: float descriptors (CV_32FC1: SIFT, XFeat), Euclidean distance, k-means
//    centres (the members' mean).
// Both seed each k-means with k-means++ (Arthur and Vassilvitskii 2007), as DBoW2 does.
//
// A flat vocabulary of k words (som/histogram.hpp) is the tree of depth 1.
//
// File format (version 1), io/binary.hpp's encoding:
//   header (24 bytes): u8[8] magic "VMAPVOCB", u32 version, u64 payload size, u32 CRC-32
//   payload:
//     u8   kind (0 = binary / Hamming, 1 = float / L2)
//     i32  descriptor columns (bytes for binary, floats for float; 1..4096)
//     u32  branching (2..4096), u32 depth (1..64)
//     u64  nodes n (>= 1; node 0 is the root)
//     n x  u32 child count (<= branching); nodes are in breadth-first order, so the
//          children of node i are the next unclaimed nodes after those of nodes < i
//     n x  centre (cols u8 or cols f32; the root's is zeros)
//     u64  words w (= the nodes without children, numbered in node order)
//     w x  f32 idf (finite, >= 0)
// Loading checks every count against the bytes that remain before allocating, checks
// that the counts form a tree of at most `depth` levels, and copies the centres in one
// block, so a 1M-word vocabulary loads in a fraction of a second (bench_place).

#include <vmap/core/error.hpp>
#include <vmap/io/atomic_file.hpp>
#include <vmap/io/binary.hpp>
#include <vmap/place/bow.hpp>
#include <vmap/place/detail/format.hpp>

#include <opencv2/core.hpp>
#include <opencv2/core/hal/hal.hpp>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <deque>
#include <filesystem>
#include <limits>
#include <random>
#include <string>
#include <string_view>
#include <type_traits>
#include <utility>
#include <variant>
#include <vector>

namespace vmap {

/// Binary descriptors: Hamming distance, k-majority centres.
struct HammingTraits {
  using value_type = std::uint8_t;
  using distance_type = std::uint32_t;
  static constexpr int descriptor_type = CV_8UC1;
  static constexpr std::uint8_t file_kind = 0;
  static constexpr const char* name = "binary (CV_8UC1, Hamming)";

  static distance_type distance(const value_type* a, const value_type* b, int cols) noexcept {
    distance_type d = 0;
    int i = 0;
    for (; i + 8 <= cols; i += 8) {
      std::uint64_t x = 0, y = 0;
      std::memcpy(&x, a + i, 8);
      std::memcpy(&y, b + i, 8);
      d += static_cast<distance_type>(std::popcount(x ^ y));
    }
    for (; i < cols; ++i) d += static_cast<distance_type>(std::popcount(static_cast<unsigned>(a[i] ^ b[i])));
    return d;
  }

  /// k-majority: bit b of the centre is 1 when more than half of the members have it.
  static void centre(const cv::Mat& sample, const std::uint32_t* members, std::size_t n, int cols, value_type* out) {
    std::vector<std::uint32_t> ones(static_cast<std::size_t>(cols) * 8, 0);
    for (std::size_t m = 0; m < n; ++m) {
      const value_type* p = sample.ptr<value_type>(static_cast<int>(members[m]));
      for (int b = 0; b < cols; ++b)
        for (int bit = 0; bit < 8; ++bit) ones[static_cast<std::size_t>(b * 8 + bit)] += (p[b] >> bit) & 1U;
    }
    for (int b = 0; b < cols; ++b) {
      unsigned byte = 0;
      for (int bit = 0; bit < 8; ++bit)
        if (2 * static_cast<std::size_t>(ones[static_cast<std::size_t>(b * 8 + bit)]) > n) byte |= 1U << bit;
      out[b] = static_cast<value_type>(byte);
    }
  }
};

/// Float descriptors: squared Euclidean distance (same order as L2), mean centres.
struct L2Traits {
  using value_type = float;
  using distance_type = float;
  static constexpr int descriptor_type = CV_32FC1;
  static constexpr std::uint8_t file_kind = 1;
  static constexpr const char* name = "float (CV_32FC1, L2)";

  static distance_type distance(const value_type* a, const value_type* b, int cols) noexcept {
    return cv::hal::normL2Sqr_(a, b, cols);
  }

  static void centre(const cv::Mat& sample, const std::uint32_t* members, std::size_t n, int cols, value_type* out) {
    std::vector<double> sum(static_cast<std::size_t>(cols), 0.0);
    for (std::size_t m = 0; m < n; ++m) {
      const value_type* p = sample.ptr<value_type>(static_cast<int>(members[m]));
      for (int c = 0; c < cols; ++c) sum[static_cast<std::size_t>(c)] += p[c];
    }
    for (int c = 0; c < cols; ++c)
      out[c] = n == 0 ? 0.0f : static_cast<float>(sum[static_cast<std::size_t>(c)] / static_cast<double>(n));
  }
};

struct VocabularyTreeOptions {
  int branching = 10;                   ///< children per node k, 2..4096
  int depth = 3;                        ///< levels L, 1..64 (at most k^L words)
  int iterations = 10;                  ///< k-means / k-majority rounds per node, >= 1
  std::size_t max_descriptors = 200000; ///< random sample learned from (bounds the time), >= branching
  std::uint64_t seed = 1;               ///< the sample and the k-means++ seeding
};

/// A vocabulary tree over descriptors of `Traits` (HammingTraits or L2Traits).
///
/// Words are the leaves. A node whose share of the training sample is smaller than
/// `branching` (or whose members are all equal) is not split and becomes a leaf (as in
/// DBoW2), so a tree may hold fewer than branching^depth words; clusters left empty by
/// k-means are dropped.
///
/// Thread safety: const members (`assign`, `transform`, `save`, ...) only read, so any
/// number of threads may use one tree at once; `set_idf` / `learn_idf` need exclusive
/// access.
template <class Traits>
class VocabularyTree {
 public:
  using traits_type = Traits;
  using value_type = typename Traits::value_type;
  using distance_type = typename Traits::distance_type;

  static constexpr int max_branching = 4096;
  static constexpr int max_depth = 64;
  static constexpr int max_cols = 4096;

  /// An empty vocabulary (size() == 0): learn or load one before use.
  VocabularyTree() = default;

  /// Learns the tree from the descriptor matrices of a set of images (all of Traits'
  /// type and one width), then the idf of every word from the same images (learn_idf).
  /// Deterministic for a seed.
  static VocabularyTree learn(const std::vector<cv::Mat>& descriptor_sets, const VocabularyTreeOptions& o = {}) {
    check_options(o);
    int cols = -1;
    std::vector<const value_type*> rows;
    for (std::size_t i = 0; i < descriptor_sets.size(); ++i) {
      const cv::Mat& d = descriptor_sets[i];
      if (d.empty()) continue;
      detail::check(d.type() == Traits::descriptor_type, [&] {
        return "VocabularyTree::learn: descriptors of image " + std::to_string(i) + " are " +
               cv::typeToString(d.type()) + ", this vocabulary is " + Traits::name;
      });
      if (cols < 0) cols = d.cols;
      detail::check(d.cols == cols, [&] {
        return "VocabularyTree::learn: descriptors of image " + std::to_string(i) + " have " + std::to_string(d.cols) +
               " columns, earlier ones " + std::to_string(cols);
      });
      for (int r = 0; r < d.rows; ++r) rows.push_back(d.ptr<value_type>(r));
    }
    detail::check(rows.size() >= static_cast<std::size_t>(o.branching), [&] {
      return "VocabularyTree::learn: " + std::to_string(rows.size()) + " descriptors cannot make " +
             std::to_string(o.branching) + " clusters (VocabularyTreeOptions.branching)";
    });
    detail::check(cols <= max_cols, [&] {
      return "VocabularyTree::learn: descriptors of " + std::to_string(cols) + " columns (at most " +
             std::to_string(max_cols) + ")";
    });
    std::mt19937_64 rng(o.seed);
    std::shuffle(rows.begin(), rows.end(), rng);
    // The sample is one cv::Mat: at most INT_MAX rows whatever max_descriptors says.
    rows.resize(std::min({rows.size(), o.max_descriptors, static_cast<std::size_t>(std::numeric_limits<int>::max())}));
    cv::Mat sample(static_cast<int>(rows.size()), cols, Traits::descriptor_type);
    for (std::size_t r = 0; r < rows.size(); ++r)
      std::copy(rows[r], rows[r] + cols, sample.ptr<value_type>(static_cast<int>(r)));

    VocabularyTree v;
    v.branching_ = o.branching;
    v.depth_ = o.depth;
    v.cols_ = cols;
    v.build(sample, o, rng);
    v.learn_idf(descriptor_sets);
    return v;
  }

  /// The flat vocabulary (depth 1) whose words are the rows of `words` (at least 2;
  /// idf 1 for every word).
  static VocabularyTree from_words(const cv::Mat& words) {
    if (words.type() != Traits::descriptor_type || words.rows < 2 || words.cols < 1 || words.cols > max_cols ||
        words.rows > max_branching) {
      std::string m = "VocabularyTree::from_words: words must be a ";
      m += Traits::name;
      m += " matrix of 2..4096 rows and 1..4096 columns, got ";
      m += cv::typeToString(words.type());
      m += " " + std::to_string(words.rows) + "x" + std::to_string(words.cols);
      detail::fail(m);
    }
    VocabularyTree v;
    v.branching_ = words.rows;
    v.depth_ = 1;
    v.cols_ = words.cols;
    v.centres_ = cv::Mat::zeros(words.rows + 1, words.cols, Traits::descriptor_type);
    words.copyTo(v.centres_.rowRange(1, words.rows + 1));
    v.child_count_.assign(static_cast<std::size_t>(words.rows) + 1, 0);
    v.child_count_[0] = static_cast<std::uint32_t>(words.rows);
    v.idf_.assign(static_cast<std::size_t>(words.rows), 1.0f);
    v.index();
    return v;
  }

  /// A tree given node by node (e.g. converted from another library's vocabulary, or
  /// generated): `child_count[i]` children for node i, nodes in breadth-first order (the
  /// children of node i are the next unclaimed nodes after those of nodes < i; node 0 is
  /// the root), `centres` one row per node (the root's is ignored), `idf` one weight per
  /// leaf, leaves numbered in node order. Checked as a loaded file is.
  static VocabularyTree from_tree(int branching, int depth, std::vector<std::uint32_t> child_count, const cv::Mat& centres,
                                  std::vector<float> idf) {
    check_options({.branching = branching, .depth = depth});
    VocabularyTree v;
    v.branching_ = branching;
    v.depth_ = depth;
    v.child_count_ = std::move(child_count);
    if (const std::string problem = v.tree_problem(); !problem.empty()) detail::fail("VocabularyTree::from_tree: " + problem);
    detail::check(centres.type() == Traits::descriptor_type &&
                      static_cast<std::size_t>(centres.rows) == v.child_count_.size() && centres.cols >= 1 &&
                      centres.cols <= max_cols,
                  [&] {
                    return "VocabularyTree::from_tree: centres must be " + cv::typeToString(Traits::descriptor_type) +
                           " with one row per node (" + std::to_string(v.child_count_.size()) + ") and 1..4096 columns";
                  });
    if constexpr (std::is_same_v<value_type, float>)
      detail::check(cv::checkRange(centres), "VocabularyTree::from_tree: a centre value is not finite");
    v.cols_ = centres.cols;
    v.centres_ = centres.clone();
    v.index();
    v.set_idf(std::move(idf));
    return v;
  }

  /// The word (leaf id) of each descriptor row. O(branching * depth) per row.
  [[nodiscard]] std::vector<std::uint32_t> assign(const cv::Mat& descriptors) const {
    check_descriptors(descriptors, "assign");
    std::vector<std::uint32_t> out(static_cast<std::size_t>(descriptors.rows));
    for (int r = 0; r < descriptors.rows; ++r) out[static_cast<std::size_t>(r)] = word_of(descriptors.ptr<value_type>(r));
    return out;
  }

  /// The word of one descriptor (`cols` values).
  [[nodiscard]] std::uint32_t word_of(const value_type* descriptor) const noexcept {
    std::uint32_t node = 0;
    while (child_count_[node] > 0) {
      const std::uint32_t first = first_child_[node];
      const std::uint32_t end = first + child_count_[node];
      std::uint32_t best = first;
      distance_type best_d = Traits::distance(descriptor, centres_.ptr<value_type>(static_cast<int>(first)), cols_);
      for (std::uint32_t c = first + 1; c < end; ++c) {
        const distance_type d = Traits::distance(descriptor, centres_.ptr<value_type>(static_cast<int>(c)), cols_);
        if (d < best_d) {  // ties: the first child, so assignment is deterministic
          best_d = d;
          best = c;
        }
      }
      node = best;
    }
    return word_of_node_[node];
  }

  /// The image's bag of words: each descriptor adds its word's idf (TF-IDF: the term
  /// frequency times idf, T-RO 2012 eq. 3, the count being the sum), words of idf 0 are
  /// left out, and the vector is L1-normalised. No descriptors: an empty vector.
  [[nodiscard]] BowVector transform(const cv::Mat& descriptors) const {
    std::vector<std::uint32_t> words = assign(descriptors);
    std::sort(words.begin(), words.end());
    BowVector v;
    double total = 0.0;
    for (std::size_t i = 0; i < words.size();) {
      std::size_t j = i;
      while (j < words.size() && words[j] == words[i]) ++j;
      const double w = static_cast<double>(j - i) * idf_[words[i]];
      if (w > 0.0) {
        v.entries.push_back({words[i], static_cast<float>(w)});
        total += w;
      }
      i = j;
    }
    for (auto& e : v.entries) e.weight = static_cast<float>(e.weight / total);
    return v;
  }

  /// Sets idf_i = log(N / n_i) (T-RO 2012 eq. 3) from a set of images: N the images with
  /// descriptors, n_i those in which word i occurs. A word that occurs in none gets
  /// log(N), as if it occurred once (it is as distinctive as a word can be).
  void learn_idf(const std::vector<cv::Mat>& descriptor_sets) {
    detail::check(size() > 0, "VocabularyTree::learn_idf: the vocabulary is empty");
    std::vector<std::uint32_t> images_with(size(), 0);
    std::vector<std::uint32_t> last_seen(size(), 0);
    std::uint32_t n = 0;
    for (const auto& d : descriptor_sets) {
      if (d.empty()) continue;
      ++n;
      for (std::uint32_t w : assign(d))
        if (last_seen[w] != n) {
          last_seen[w] = n;
          ++images_with[w];
        }
    }
    detail::check(n > 0, "VocabularyTree::learn_idf: no image has descriptors");
    idf_.resize(size());
    for (std::size_t w = 0; w < size(); ++w)
      idf_[w] = static_cast<float>(std::log(static_cast<double>(n) / static_cast<double>(std::max<std::uint32_t>(1, images_with[w]))));
  }

  /// Sets the idf weights (one per word, finite and >= 0).
  void set_idf(std::vector<float> idf) {
    detail::check(idf.size() == size(), [&] {
      return "VocabularyTree::set_idf: " + std::to_string(idf.size()) + " weights for " + std::to_string(size()) +
             " words";
    });
    for (std::size_t w = 0; w < idf.size(); ++w)
      detail::check(std::isfinite(idf[w]) && idf[w] >= 0.0f, [&] {
        return "VocabularyTree::set_idf: weight of word " + std::to_string(w) + " is negative or not finite";
      });
    idf_ = std::move(idf);
  }

  [[nodiscard]] const std::vector<float>& idf() const noexcept { return idf_; }
  /// Number of words (leaves); 0 for an empty vocabulary.
  [[nodiscard]] std::size_t size() const noexcept { return leaves_; }
  [[nodiscard]] bool empty() const noexcept { return leaves_ == 0; }
  [[nodiscard]] int branching() const noexcept { return branching_; }
  [[nodiscard]] int depth() const noexcept { return depth_; }
  [[nodiscard]] static constexpr int descriptor_type() noexcept { return Traits::descriptor_type; }
  /// Columns of a descriptor (bytes for binary, floats for float); 0 when empty.
  [[nodiscard]] int descriptor_cols() const noexcept { return cols_; }
  /// Nodes of the tree, the root included.
  [[nodiscard]] std::size_t nodes() const noexcept { return child_count_.size(); }

  /// The words' centres, row w for word w.
  [[nodiscard]] cv::Mat words() const {
    cv::Mat out(static_cast<int>(size()), cols_, Traits::descriptor_type);
    for (std::size_t n = 0; n < nodes(); ++n)
      if (child_count_[n] == 0) centres_.row(static_cast<int>(n)).copyTo(out.row(static_cast<int>(word_of_node_[n])));
    return out;
  }

  /// Heap bytes held (centres, tree links, idf).
  [[nodiscard]] std::size_t memory_bytes() const noexcept {
    return centres_.total() * centres_.elemSize() +
           (child_count_.capacity() + first_child_.capacity() + word_of_node_.capacity()) * sizeof(std::uint32_t) +
           idf_.capacity() * sizeof(float);
  }

  /// The file's bytes (format at the top of this header).
  [[nodiscard]] std::string serialize() const {
    detail::check(size() > 0, "VocabularyTree::save: the vocabulary is empty");
    detail::BinaryWriter w;
    w.u8(Traits::file_kind);
    w.i32(cols_);
    w.u32(static_cast<std::uint32_t>(branching_));
    w.u32(static_cast<std::uint32_t>(depth_));
    w.u64(nodes());
    if constexpr (std::endian::native == std::endian::little) {
      w.bytes(child_count_.data(), child_count_.size() * sizeof(std::uint32_t));
    } else {
      for (std::uint32_t c : child_count_) w.u32(c);
    }
    for (std::size_t n = 0; n < nodes(); ++n) {
      const value_type* p = centres_.ptr<value_type>(static_cast<int>(n));
      if constexpr (std::is_same_v<value_type, float>) {
        w.f32s(p, static_cast<std::size_t>(cols_));
      } else {
        w.bytes(p, static_cast<std::size_t>(cols_));
      }
    }
    w.u64(size());
    w.f32s(idf_.data(), idf_.size());
    return detail::wrap_payload(file_magic(), file_version, std::move(w).take());
  }

  /// Parses the file's bytes; `name` is used in error messages.
  [[nodiscard]] static VocabularyTree deserialize(std::string_view bytes, const std::string& name = "<memory>") {
    auto r = detail::open_payload(bytes, file_magic(), file_version, "vocabulary", "vocabulary file '" + name + "'");
    const std::uint8_t kind = r.u8("kind");
    if (kind != Traits::file_kind)
      r.corrupt(std::string("holds a") + (kind == 0 ? " binary" : kind == 1 ? " float" : "n unknown") +
                " vocabulary, not a " + Traits::name + " one");
    VocabularyTree v;
    v.cols_ = r.i32("descriptor columns");
    if (v.cols_ < 1 || v.cols_ > max_cols) r.corrupt("descriptor columns " + std::to_string(v.cols_) + " outside 1..4096");
    const std::uint32_t k = r.u32("branching");
    const std::uint32_t depth = r.u32("depth");
    if (k < 2 || k > static_cast<std::uint32_t>(max_branching)) r.corrupt("branching " + std::to_string(k) + " outside 2..4096");
    if (depth < 1 || depth > static_cast<std::uint32_t>(max_depth)) r.corrupt("depth " + std::to_string(depth) + " outside 1..64");
    v.branching_ = static_cast<int>(k);
    v.depth_ = static_cast<int>(depth);
    const std::uint64_t n = r.u64("node count");
    const std::uint64_t row_bytes = static_cast<std::uint64_t>(v.cols_) * sizeof(value_type);
    r.require_items(n, 4 + row_bytes, "node count");
    if (n < 1 || n > std::numeric_limits<std::uint32_t>::max() / 2) r.corrupt("node count " + std::to_string(n) + " is invalid");
    v.child_count_.resize(static_cast<std::size_t>(n));
    if constexpr (std::endian::native == std::endian::little) {
      const auto block = r.bytes(n * 4, "child counts");  // one copy for a million nodes
      std::memcpy(v.child_count_.data(), block.data(), block.size());
    } else {
      for (auto& c : v.child_count_) c = r.u32("child count");
    }
    if (const std::string problem = v.tree_problem(); !problem.empty()) r.corrupt(problem);
    v.index();
    v.centres_.create(static_cast<int>(n), v.cols_, Traits::descriptor_type);
    if constexpr (std::is_same_v<value_type, float>) {
      for (std::size_t i = 0; i < n; ++i) {
        float* p = v.centres_.template ptr<float>(static_cast<int>(i));
        r.f32s(p, static_cast<std::uint64_t>(v.cols_), "centres");
        for (int c = 0; c < v.cols_; ++c)
          if (!std::isfinite(p[c])) r.corrupt("a centre value is not finite");
      }
    } else {
      const auto block = r.bytes(n * row_bytes, "centres");
      std::memcpy(v.centres_.data, block.data(), block.size());  // a new Mat is continuous
    }
    const std::uint64_t words = r.u64("word count");
    if (words != v.leaves_) r.corrupt("word count " + std::to_string(words) + " differs from the tree's " + std::to_string(v.leaves_) + " leaves");
    r.require_items(words, 4, "word count");
    v.idf_.resize(static_cast<std::size_t>(words));
    r.f32s(v.idf_.data(), words, "idf");
    for (float f : v.idf_)
      if (!(std::isfinite(f) && f >= 0.0f)) r.corrupt("an idf weight is negative or not finite");
    r.expect_end("the idf weights");
    return v;
  }

  /// Writes the vocabulary to `path` atomically.
  void save(const std::filesystem::path& path) const { write_file_atomically(path, serialize()); }

  /// Reads a vocabulary written by save(); anything else is a vmap::Error naming the file.
  [[nodiscard]] static VocabularyTree load(const std::filesystem::path& path) {
    return deserialize(detail::read_whole_file(path), path.string());
  }

  static constexpr std::uint32_t file_version = 1;
  static constexpr std::string_view file_magic() noexcept { return {"VMAPVOCB", 8}; }

 private:
  static void check_options(const VocabularyTreeOptions& o) {
    detail::check(o.branching >= 2 && o.branching <= max_branching, [&] {
      return "VocabularyTreeOptions.branching must be in 2..4096, got " + std::to_string(o.branching);
    });
    detail::check(o.depth >= 1 && o.depth <= max_depth,
                  [&] { return "VocabularyTreeOptions.depth must be in 1..64, got " + std::to_string(o.depth); });
    detail::check(o.iterations >= 1,
                  [&] { return "VocabularyTreeOptions.iterations must be >= 1, got " + std::to_string(o.iterations); });
    detail::check(o.max_descriptors >= static_cast<std::size_t>(o.branching), [&] {
      return "VocabularyTreeOptions.max_descriptors must be >= branching, got " + std::to_string(o.max_descriptors);
    });
  }

  void check_descriptors(const cv::Mat& d, const char* what) const {
    detail::check(size() > 0, [&] {
      return std::string("VocabularyTree::") + what + ": the vocabulary is empty (learn or load it first)";
    });
    if (d.empty()) return;
    detail::check(d.type() == Traits::descriptor_type && d.cols == cols_, [&] {
      return std::string("VocabularyTree::") + what + ": descriptors must be " +
             cv::typeToString(Traits::descriptor_type) + " with " + std::to_string(cols_) +
             " columns (the vocabulary's), got " + cv::typeToString(d.type()) + " with " + std::to_string(d.cols);
    });
  }

  /// Clusters `members` of the sample into at most k groups: k-means++ seeding, then
  /// `iterations` rounds of assignment and centre update (stopping when nothing moves).
  /// Returns the non-empty groups and their centres (rows of `centres`).
  std::vector<std::vector<std::uint32_t>> cluster(const cv::Mat& sample, const std::vector<std::uint32_t>& members,
                                                  const VocabularyTreeOptions& o, std::mt19937_64& rng,
                                                  cv::Mat& centres) const {
    const std::size_t m = members.size();
    const int k = o.branching;
    auto row = [&](std::uint32_t i) { return sample.ptr<value_type>(static_cast<int>(i)); };
    auto uniform = [&rng] { return static_cast<double>(rng() >> 11) * 0x1.0p-53; };  // [0, 1), portable
    // k-means++ (Arthur and Vassilvitskii 2007): each next seed drawn with probability
    // proportional to its squared distance to the nearest seed so far.
    std::vector<std::uint32_t> seeds{members[rng() % m]};
    std::vector<double> d2(m);
    for (std::size_t i = 0; i < m; ++i) {
      const double d = static_cast<double>(Traits::distance(row(members[i]), row(seeds[0]), cols_));
      d2[i] = d * d;
    }
    while (seeds.size() < static_cast<std::size_t>(k)) {
      double total = 0.0;
      for (double d : d2) total += d;
      if (total <= 0.0) break;  // every member equals a seed: fewer clusters
      double target = uniform() * total;
      std::size_t pick = 0;
      for (; pick + 1 < m; ++pick) {
        target -= d2[pick];
        if (target < 0.0) break;
      }
      while (d2[pick] <= 0.0) pick = pick == 0 ? m - 1 : pick - 1;  // rounding at the end: a member not yet seeded
      seeds.push_back(members[pick]);
      for (std::size_t i = 0; i < m; ++i) {
        const double d = static_cast<double>(Traits::distance(row(members[i]), row(seeds.back()), cols_));
        d2[i] = std::min(d2[i], d * d);
      }
    }
    const int kk = static_cast<int>(seeds.size());
    centres.create(kk, cols_, Traits::descriptor_type);
    for (int c = 0; c < kk; ++c) std::copy(row(seeds[static_cast<std::size_t>(c)]), row(seeds[static_cast<std::size_t>(c)]) + cols_, centres.ptr<value_type>(c));

    std::vector<std::uint32_t> label(m, std::numeric_limits<std::uint32_t>::max());
    // Labels every member with its nearest centre (ties: the lower one); true if one moved.
    auto relabel = [&] {
      bool moved = false;
      for (std::size_t i = 0; i < m; ++i) {
        std::uint32_t best = 0;
        distance_type best_d = Traits::distance(row(members[i]), centres.ptr<value_type>(0), cols_);
        for (int c = 1; c < kk; ++c) {
          const distance_type d = Traits::distance(row(members[i]), centres.ptr<value_type>(c), cols_);
          if (d < best_d) {
            best_d = d;
            best = static_cast<std::uint32_t>(c);
          }
        }
        moved = moved || label[i] != best;
        label[i] = best;
      }
      return moved;
    };
    std::vector<std::vector<std::uint32_t>> groups(static_cast<std::size_t>(kk));
    auto regroup = [&] {
      for (auto& g : groups) g.clear();
      for (std::size_t i = 0; i < m; ++i) groups[label[i]].push_back(members[i]);
    };
    bool converged = false;
    for (int it = 0; it < o.iterations; ++it) {
      if (!relabel()) {
        converged = true;
        break;
      }
      regroup();
      for (int c = 0; c < kk; ++c) {
        const auto& g = groups[static_cast<std::size_t>(c)];
        if (!g.empty()) Traits::centre(sample, g.data(), g.size(), cols_, centres.ptr<value_type>(c));  // an empty one keeps its centre
      }
    }
    // The last update moved the centres: label once more, so that the groups below are
    // the members nearest to each final centre (what assignment will find).
    if (!converged) relabel();
    regroup();
    std::vector<std::vector<std::uint32_t>> out;
    cv::Mat kept(0, cols_, Traits::descriptor_type);
    for (int c = 0; c < kk; ++c)
      if (!groups[static_cast<std::size_t>(c)].empty()) {
        out.push_back(std::move(groups[static_cast<std::size_t>(c)]));
        kept.push_back(centres.row(c));
      }
    centres = kept;
    return out;
  }

  /// Breadth-first construction: nodes are numbered in the order they are created and
  /// split in that order, so each node's children are consecutive.
  void build(const cv::Mat& sample, const VocabularyTreeOptions& o, std::mt19937_64& rng) {
    struct Pending {
      std::uint32_t node;
      int level;
      std::vector<std::uint32_t> members;
    };
    std::vector<value_type> centre_values(static_cast<std::size_t>(cols_), value_type{});  // the root's
    child_count_.assign(1, 0);
    std::deque<Pending> queue;
    {
      std::vector<std::uint32_t> all(static_cast<std::size_t>(sample.rows));
      for (std::size_t i = 0; i < all.size(); ++i) all[i] = static_cast<std::uint32_t>(i);
      queue.push_back({0, 0, std::move(all)});
    }
    while (!queue.empty()) {
      Pending p = std::move(queue.front());
      queue.pop_front();
      if (p.level >= o.depth || p.members.size() < static_cast<std::size_t>(o.branching)) continue;  // a leaf
      cv::Mat centres;
      auto groups = cluster(sample, p.members, o, rng, centres);
      if (groups.size() < 2) continue;  // all members equal: a leaf
      p.members.clear();
      p.members.shrink_to_fit();
      child_count_[p.node] = static_cast<std::uint32_t>(groups.size());
      for (std::size_t g = 0; g < groups.size(); ++g) {
        const auto id = static_cast<std::uint32_t>(child_count_.size());
        child_count_.push_back(0);
        const value_type* c = centres.ptr<value_type>(static_cast<int>(g));
        centre_values.insert(centre_values.end(), c, c + cols_);
        queue.push_back({id, p.level + 1, std::move(groups[g])});
      }
    }
    child_count_.shrink_to_fit();
    centres_.create(static_cast<int>(child_count_.size()), cols_, Traits::descriptor_type);
    std::memcpy(centres_.data, centre_values.data(), centre_values.size() * sizeof(value_type));
    index();
  }

  /// first_child_ and word_of_node_ from child_count_ (a valid breadth-first tree).
  void index() {
    const std::size_t n = child_count_.size();
    first_child_.assign(n, 0);
    word_of_node_.assign(n, std::numeric_limits<std::uint32_t>::max());
    std::uint32_t next = 1;
    leaves_ = 0;
    for (std::size_t i = 0; i < n; ++i) {
      first_child_[i] = next;
      next += child_count_[i];
      if (child_count_[i] == 0) word_of_node_[i] = leaves_++;
    }
  }

  /// What makes child_count_ not one breadth-first tree of at most depth_ levels with
  /// at most branching_ children a node (each node's children come after it, every node
  /// but the root has exactly one parent, the root has children); empty if nothing.
  [[nodiscard]] std::string tree_problem() const {
    const std::size_t n = child_count_.size();
    if (n == 0 || child_count_[0] == 0) return "the root has no children";
    std::uint64_t next = 1;
    std::vector<std::uint8_t> level(n, 0);
    for (std::size_t i = 0; i < n; ++i) {
      const std::uint32_t c = child_count_[i];
      if (c == 0) continue;
      if (c > static_cast<std::uint32_t>(branching_))
        return "node " + std::to_string(i) + " has " + std::to_string(c) + " children, more than the branching " +
               std::to_string(branching_);
      if (next <= i) return "node " + std::to_string(i) + " is nobody's child (the counts do not form a tree)";
      if (next + c > n) return "the child counts claim more nodes than the " + std::to_string(n) + " stored";
      if (level[i] + 1 > depth_) return "the tree is deeper than its depth " + std::to_string(depth_);
      for (std::uint64_t j = next; j < next + c; ++j) level[j] = static_cast<std::uint8_t>(level[i] + 1);
      next += c;
    }
    if (next != n) return "the child counts claim " + std::to_string(next) + " nodes, " + std::to_string(n) + " are stored";
    return {};
  }

  int branching_ = 0;
  int depth_ = 0;
  int cols_ = 0;
  cv::Mat centres_;                         ///< one row per node (row 0: the root, unused)
  std::vector<std::uint32_t> child_count_;  ///< per node; 0 = a leaf (a word)
  std::vector<std::uint32_t> first_child_;  ///< per node; its children are consecutive
  std::vector<std::uint32_t> word_of_node_; ///< per node: the word id of a leaf
  std::uint32_t leaves_ = 0;
  std::vector<float> idf_;                  ///< per word
};

using BinaryVocabularyTree = VocabularyTree<HammingTraits>;
using FloatVocabularyTree = VocabularyTree<L2Traits>;

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

  /// Reads a binary or a float vocabulary file (VocabularyTree::save).
  static AnyVocabulary load(const std::filesystem::path& path) {
    const std::string bytes = detail::read_whole_file(path);
    const std::string name = path.string();
    // The kind is the first payload byte; the typed parser checks everything else.
    if (bytes.size() > detail::place_header_size && static_cast<std::uint8_t>(bytes[detail::place_header_size]) == 1)
      return FloatVocabularyTree::deserialize(bytes, name);
    return BinaryVocabularyTree::deserialize(bytes, name);
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
