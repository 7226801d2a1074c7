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
// Layout in memory: the nodes in breadth-first order, so the children of a node are
// consecutive; their centres are consecutive rows of one matrix (a node block: the k
// distances of one level read one contiguous run) and each node is one 8-byte entry
// (first child and child count, or the word id of a leaf). Assignment interleaves the
// descents of 16 descriptors, prefetching each one's next block, so the cache misses of
// a large tree overlap (bench_place measures it against FBoW).
//
// File format (version 2), io/binary.hpp's encoding:
//   header (24 bytes): u8[8] magic "VMAPVOCB", u32 version, u64 payload size,
//                      u32 CRC-32C of the payload (place/detail/crc32c.hpp)
//   payload:
//     u8   kind (0 = binary / Hamming, 1 = float / L2)
//     i32  descriptor columns (bytes for binary, floats for float; 1..4096)
//     u32  branching (2..4096), u32 depth (1..64)
//     u8   weighting (BowWeighting)
//     u8   child count width c (1 when branching < 256, else 2)
//     u64  nodes n (>= 1; node 0 is the root)
//     n x  child count (c bytes, <= branching); nodes are in breadth-first order, so
//          the children of node i are the next unclaimed nodes after those of nodes < i
//     n x  centre (cols u8 or cols f32; the root's is zeros)
//     u64  words w (= the nodes without children, numbered in node order)
//     w x  f32 idf (finite, >= 0), indexed by word id
//     u8   word numbering: 0 = the leaves in node order are words 0..w-1; 1 = w x u32
//          follow, the word id of each leaf in node order (a permutation; imported
//          vocabularies keep their library's numbering)
// Version 1 (still read): CRC-32 (zlib's) in the header, no weighting byte (tf_idf_l1)
// and no width byte, u32 child counts, no word numbering (node order).
// Loading reads the file once, front to back, straight into the tree's arrays,
// checksumming each piece while it is in cache; every count is checked against the
// bytes that remain before allocating, and the counts must form a tree of at most
// `depth` levels.

#include <vmap/core/error.hpp>
#include <vmap/core/names.hpp>
#include <vmap/io/atomic_file.hpp>
#include <vmap/io/binary.hpp>
#include <vmap/place/bow.hpp>
#include <vmap/place/detail/format.hpp>
#include <vmap/place/detail/hamming_rows.hpp>
#include <vmap/place/detail/large_array.hpp>
#include <vmap/place/options.hpp>

#include <opencv2/core.hpp>
#include <opencv2/core/hal/hal.hpp>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <deque>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <string>
#include <string_view>
#include <type_traits>
#include <utility>
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

/// How a vocabulary turns the words of an image's descriptors into a bag of words; each
/// reproduces the library whose files use it (the weights of an imported vocabulary are
/// those of the file: idf, or 1 for DBoW2's TF / BINARY and for FBoW's trainer).
enum class BowWeighting : std::uint8_t {
  tf_idf_l1 = 0,  ///< sum of the word weights per word, L1-normalised (vmap; DBoW2 TF_IDF / TF with L1_NORM)
  tf_idf_l2 = 1,  ///< the same, L2-normalised (DBoW2 TF_IDF / TF with L2_NORM)
  idf_l1 = 2,     ///< each word's weight once however often it occurs, L1 (DBoW2 IDF / BINARY with L1_NORM)
  idf_l2 = 3,     ///< the same, L2 (DBoW2 IDF / BINARY with L2_NORM)
  fbow = 4,       ///< FBoW: word weights summed in float in descriptor order, L2-normalised as FBoW does
};

/// tf_idf_l1, tf_idf_l2, idf_l1, idf_l2, fbow (core/names.hpp).
[[nodiscard]] constexpr auto names_of(BowWeighting) noexcept {
  return detail::NameTable<BowWeighting, 5>{{{{BowWeighting::tf_idf_l1, "tf_idf_l1"},
                                              {BowWeighting::tf_idf_l2, "tf_idf_l2"},
                                              {BowWeighting::idf_l1, "idf_l1"},
                                              {BowWeighting::idf_l2, "idf_l2"},
                                              {BowWeighting::fbow, "fbow"}}}};
}
[[nodiscard]] constexpr std::string_view to_string(BowWeighting w) noexcept { return names_of(w).name(w); }

/// The score that goes with a weighting: DBoW2's L1 score for L1-normalised vectors,
/// its L2 score (FBoW's fBow::score too) for L2-normalised ones.
inline BowScoring bow_scoring_of(BowWeighting w) noexcept {
  return w == BowWeighting::tf_idf_l1 || w == BowWeighting::idf_l1 ? BowScoring::l1 : BowScoring::l2;
}

namespace detail {

/// Options a tree can be learned with, or an Error naming the option: the one check of
/// the learning and of whoever keeps the options to learn later (a visual memory).
inline void check_vocabulary_tree_options(const VocabularyTreeOptions& o) {
  check(o.branching >= 2 && o.branching <= 4096, [&] {
    return "VocabularyTreeOptions.branching must be in 2..4096, got " + std::to_string(o.branching);
  });
  check(o.depth >= 1 && o.depth <= 64,
        [&] { return "VocabularyTreeOptions.depth must be in 1..64, got " + std::to_string(o.depth); });
  check(o.iterations >= 1, [&] { return "VocabularyTreeOptions.iterations must be >= 1, got " + std::to_string(o.iterations); });
  check(o.max_descriptors >= static_cast<std::size_t>(o.branching), [&] {
    return "VocabularyTreeOptions.max_descriptors must be >= branching, got " + std::to_string(o.max_descriptors);
  });
}

/// VocabularyTreeOptions as a memory that learns its vocabulary keeps them (checked when
/// the vocabulary is learned).
inline void write_vocabulary_tree_options(BinaryWriter& w, const VocabularyTreeOptions& o) {
  static_assert(field_count<VocabularyTreeOptions>() == 5,
                "a new VocabularyTreeOptions field must be written and read here");
  w.i32(o.branching);
  w.i32(o.depth);
  w.i32(o.iterations);
  w.u64(o.max_descriptors);
  w.u64(o.seed);
}

inline VocabularyTreeOptions read_vocabulary_tree_options(BinaryReader& r) {
  VocabularyTreeOptions o;
  o.branching = r.i32("branching");
  o.depth = r.i32("depth");
  o.iterations = r.i32("iterations");
  o.max_descriptors = static_cast<std::size_t>(r.u64("max_descriptors"));
  o.seed = r.u64("seed");
  return o;
}

}  // namespace detail

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
    std::vector<std::uint32_t> counts(static_cast<std::size_t>(words.rows) + 1, 0);
    counts[0] = static_cast<std::uint32_t>(words.rows);
    v.index(counts);
    v.idf_.assign(static_cast<std::size_t>(words.rows), 1.0f);
    return v;
  }

  /// A tree given node by node (e.g. converted from another library's vocabulary, or
  /// generated): `child_count[i]` children for node i, nodes in breadth-first order (the
  /// children of node i are the next unclaimed nodes after those of nodes < i; node 0 is
  /// the root), `centres` one row per node (the root's is ignored), `idf` one weight per
  /// word. Words are the leaves numbered in node order, or `word_ids[j]` for the j-th
  /// leaf in node order when given (a permutation of 0..leaves-1: another library's word
  /// numbering, kept so that its bags of words are reproduced word for word). Checked as
  /// a loaded file is.
  static VocabularyTree from_tree(int branching, int depth, const std::vector<std::uint32_t>& child_count,
                                  const cv::Mat& centres, std::vector<float> idf,
                                  BowWeighting weighting = BowWeighting::tf_idf_l1,
                                  const std::vector<std::uint32_t>& word_ids = {}) {
    check_options({.branching = branching, .depth = depth});
    VocabularyTree v;
    v.branching_ = branching;
    v.depth_ = depth;
    v.weighting_ = weighting;
    v.nodes_.resize_for_overwrite(child_count.size());
    for (std::size_t i = 0; i < child_count.size(); ++i) v.nodes_[i].count = child_count[i];
    if (const std::string problem = v.link(); !problem.empty()) detail::fail("VocabularyTree::from_tree: " + problem);
    detail::check(centres.type() == Traits::descriptor_type &&
                      static_cast<std::size_t>(centres.rows) == child_count.size() && centres.cols >= 1 &&
                      centres.cols <= max_cols,
                  [&] {
                    return "VocabularyTree::from_tree: centres must be " + cv::typeToString(Traits::descriptor_type) +
                           " with one row per node (" + std::to_string(child_count.size()) + ") and 1..4096 columns";
                  });
    if constexpr (std::is_same_v<value_type, float>)
      detail::check(cv::checkRange(centres), "VocabularyTree::from_tree: a centre value is not finite");
    v.cols_ = centres.cols;
    v.adopt_centres(centres);
    if (!word_ids.empty())
      if (const std::string problem = v.renumber(word_ids); !problem.empty()) detail::fail("VocabularyTree::from_tree: " + problem);
    v.set_idf(std::move(idf));
    return v;
  }

  /// The word (leaf id) of each descriptor row. O(branching * depth) per row.
  [[nodiscard]] std::vector<std::uint32_t> assign(const cv::Mat& descriptors) const {
    check_descriptors(descriptors, "assign");
    std::vector<std::uint32_t> out(static_cast<std::size_t>(descriptors.rows));
    assign_rows(descriptors, out.data());
    return out;
  }

  /// The word of one descriptor (`cols` values).
  [[nodiscard]] std::uint32_t word_of(const value_type* descriptor) const noexcept {
    std::uint32_t node = 0;
    while (nodes_[node].count > 0) node = nearest_child(descriptor, nodes_[node]);
    return nodes_[node].first;
  }

  /// The image's bag of words, weighted as weighting() says. For vmap's own
  /// (tf_idf_l1): each descriptor adds its word's idf (TF-IDF: the term frequency times
  /// idf, T-RO 2012 eq. 3, the count being the sum), words of idf 0 are left out, and
  /// the vector is L1-normalised. No descriptors: an empty vector.
  [[nodiscard]] BowVector transform(const cv::Mat& descriptors) const {
    std::vector<std::uint32_t> words = assign(descriptors);
    if (weighting_ == BowWeighting::fbow) return fbow_weights(words);
    std::sort(words.begin(), words.end());
    BowVector v;
    double total = 0.0;
    const bool once = weighting_ == BowWeighting::idf_l1 || weighting_ == BowWeighting::idf_l2;
    for (std::size_t i = 0; i < words.size();) {
      std::size_t j = i;
      while (j < words.size() && words[j] == words[i]) ++j;
      const double w = (once ? 1.0 : static_cast<double>(j - i)) * idf_[words[i]];
      if (w > 0.0) {
        v.entries.push_back({words[i], static_cast<float>(w)});
        total += weighting_ == BowWeighting::tf_idf_l1 || weighting_ == BowWeighting::idf_l1 ? w : w * w;
      }
      i = j;
    }
    if (weighting_ == BowWeighting::tf_idf_l2 || weighting_ == BowWeighting::idf_l2) total = std::sqrt(total);
    for (auto& e : v.entries) e.weight = static_cast<float>(e.weight / total);
    return v;
  }

  /// How transform() weighs and normalises (vmap's own files: tf_idf_l1; imported
  /// vocabularies: their library's), and the score that goes with it.
  [[nodiscard]] BowWeighting weighting() const noexcept { return weighting_; }
  [[nodiscard]] BowScoring scoring() const noexcept { return bow_scoring_of(weighting_); }

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
  [[nodiscard]] std::size_t nodes() const noexcept { return nodes_.size(); }

  /// Node i (breadth-first; 0 the root): its number of children, 0 for a word.
  [[nodiscard]] std::uint32_t child_count(std::size_t i) const noexcept { return nodes_[i].count; }
  /// The first child of inner node i (its children are consecutive), or leaf i's word id.
  [[nodiscard]] std::uint32_t first_child_or_word(std::size_t i) const noexcept { return nodes_[i].first; }
  /// The centre of node i (descriptor_cols() values; the root's is zeros).
  [[nodiscard]] const value_type* centre(std::size_t i) const { return centres_.ptr<value_type>(static_cast<int>(i)); }

  /// The words' centres, row w for word w.
  [[nodiscard]] cv::Mat words() const {
    cv::Mat out(static_cast<int>(size()), cols_, Traits::descriptor_type);
    for (std::size_t n = 0; n < nodes(); ++n)
      if (nodes_[n].count == 0) centres_.row(static_cast<int>(n)).copyTo(out.row(static_cast<int>(nodes_[n].first)));
    return out;
  }

  /// Heap bytes held (centres, tree links, idf).
  [[nodiscard]] std::size_t memory_bytes() const noexcept {
    return centres_.total() * centres_.elemSize() + nodes_.size() * sizeof(Node) + idf_.capacity() * sizeof(float);
  }

  /// The file's bytes (format at the top of this header, version 2).
  [[nodiscard]] std::string serialize() const {
    detail::check(size() > 0, "VocabularyTree::save: the vocabulary is empty");
    detail::BinaryWriter w;
    w.u8(Traits::file_kind);
    w.i32(cols_);
    w.u32(static_cast<std::uint32_t>(branching_));
    w.u32(static_cast<std::uint32_t>(depth_));
    w.u8(static_cast<std::uint8_t>(weighting_));
    const int count_bytes = branching_ < 256 ? 1 : 2;
    w.u8(static_cast<std::uint8_t>(count_bytes));
    w.u64(nodes());
    {
      std::string counts(nodes() * static_cast<std::size_t>(count_bytes), '\0');
      for (std::size_t i = 0; i < nodes(); ++i)
        for (int b = 0; b < count_bytes; ++b)
          counts[i * static_cast<std::size_t>(count_bytes) + static_cast<std::size_t>(b)] =
              static_cast<char>((nodes_[i].count >> (8 * b)) & 0xFFU);
      w.bytes(counts);
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
    // word numbering: 0 = the leaves in node order, 1 = a u32 word id per leaf follows
    std::vector<std::uint32_t> ids;
    std::uint32_t j = 0;
    bool in_order = true;
    for (const Node& node : nodes_)
      if (node.count == 0) {
        ids.push_back(node.first);
        in_order = in_order && node.first == j++;
      }
    w.u8(in_order ? 0 : 1);
    if (!in_order)
      for (std::uint32_t id : ids) w.u32(id);
    const std::string payload = std::move(w).take();
    detail::BinaryWriter h;
    h.bytes(file_magic());
    h.u32(file_version);
    h.u64(payload.size());
    h.u32(detail::crc32c(payload));
    h.bytes(payload);
    return std::move(h).take();
  }

  /// Parses the file's bytes (version 1 or 2); `name` is used in error messages.
  [[nodiscard]] static VocabularyTree deserialize(std::string_view bytes, const std::string& name = "<memory>") {
    const std::string source = "vocabulary file '" + name + "'";
    const auto head = bytes.substr(0, std::min(bytes.size(), detail::place_header_size));
    const auto h = detail::parse_header(head, bytes.size() - head.size(), file_magic(), 1, file_version, "vocabulary", source);
    detail::PayloadStream r(bytes.substr(detail::place_header_size), source, detail::place_header_size, checksum_of(h.version));
    return parse(r, h);
  }

  /// Writes the vocabulary to `path` atomically.
  void save(const std::filesystem::path& path) const { write_file_atomically(path, serialize()); }

  /// Reads a vocabulary written by save() (either file version), in one pass from the
  /// file into the tree's arrays; anything else is a vmap::Error naming the file.
  [[nodiscard]] static VocabularyTree load(const std::filesystem::path& path) {
    std::ifstream in = detail::open_regular_file(path, "vocabulary file");
    const std::string source = "vocabulary file '" + path.string() + "'";
    in.seekg(0, std::ios::end);
    const std::streamoff size = in.tellg();
    if (size < 0) detail::fail("cannot read the size of '" + path.string() + "'");
    in.seekg(0);
    std::string head(std::min<std::size_t>(static_cast<std::size_t>(size), detail::place_header_size), '\0');
    if (!in.read(head.data(), static_cast<std::streamsize>(head.size()))) detail::fail("reading '" + path.string() + "' failed");
    const auto h = detail::parse_header(head, static_cast<std::uint64_t>(size) - head.size(), file_magic(), 1, file_version,
                                        "vocabulary", source);
    detail::PayloadStream r(in, h.size, source, detail::place_header_size, checksum_of(h.version));
    return parse(r, h);
  }

  /// Version 2: CRC-32C, a weighting byte, child counts of 1 or 2 bytes. Version 1 (read
  /// only): CRC-32, u32 child counts, tf_idf_l1.
  static constexpr std::uint32_t file_version = 2;
  static constexpr std::string_view file_magic() noexcept { return {"VMAPVOCB", 8}; }

 private:
  /// One node: an inner node's children are nodes first..first+count-1 (consecutive, so
  /// their centres are consecutive rows, one block read per level); a leaf has count 0
  /// and first = its word id.
  struct Node {
    std::uint32_t first = 0;
    std::uint32_t count = 0;
  };

  static detail::PayloadChecksum checksum_of(std::uint32_t version) noexcept {
    return version == 1 ? detail::PayloadChecksum::crc32 : detail::PayloadChecksum::crc32c;
  }

  /// The payload after the header: sizes are checked against the bytes that remain
  /// before anything is allocated, everything is read (and checksummed) into place, then
  /// the checksum is compared and the contents checked.
  static VocabularyTree parse(detail::PayloadStream& r, const detail::PayloadHeader& h) {
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
    std::uint64_t count_bytes = 4;
    if (h.version >= 2) {
      const std::uint8_t w = r.u8("weighting");
      if (w > static_cast<std::uint8_t>(BowWeighting::fbow)) r.corrupt("unknown weighting " + std::to_string(w));
      v.weighting_ = static_cast<BowWeighting>(w);
      count_bytes = r.u8("child count width");
      if (count_bytes != 1 && count_bytes != 2) r.corrupt("child count width " + std::to_string(count_bytes) + " is not 1 or 2");
    }
    const std::uint64_t n = r.u64("node count");
    const std::uint64_t row_bytes = static_cast<std::uint64_t>(v.cols_) * sizeof(value_type);
    r.require_items(n, count_bytes + row_bytes, "node count");
    if (n < 1 || n > std::numeric_limits<std::uint32_t>::max() / 2) r.corrupt("node count " + std::to_string(n) + " is invalid");
    std::vector<unsigned char> raw(static_cast<std::size_t>(n * count_bytes));
    r.read(raw.data(), raw.size(), "child counts");
    v.nodes_.resize_for_overwrite(static_cast<std::size_t>(n));
    std::uint64_t leaves = 0;
    // One loop per width, so the little-endian counts are widened without a loop per node.
    const auto widen = [&]<std::size_t W>() {
      const unsigned char* p = raw.data();
      for (std::size_t i = 0; i < n; ++i, p += W) {
        std::uint32_t c = p[0];
        if constexpr (W >= 2) c |= static_cast<std::uint32_t>(p[1]) << 8;
        if constexpr (W == 4) c |= static_cast<std::uint32_t>(p[2]) << 16 | static_cast<std::uint32_t>(p[3]) << 24;
        v.nodes_[i].count = c;
        leaves += c == 0;
      }
    };
    if (count_bytes == 1)
      widen.template operator()<1>();
    else if (count_bytes == 2)
      widen.template operator()<2>();
    else
      widen.template operator()<4>();
    raw = {};
    v.centre_storage_.resize_for_overwrite(static_cast<std::size_t>(n * row_bytes));
    v.centres_ = cv::Mat(static_cast<int>(n), v.cols_, Traits::descriptor_type, v.centre_storage_.data());
    r.read(v.centres_.data, n * row_bytes, "centres");  // a new Mat is continuous
    const std::uint64_t words = r.u64("word count");
    r.require_items(words, 4, "word count");
    v.idf_.resize(static_cast<std::size_t>(words));
    r.read(v.idf_.data(), words * 4, "idf");
    std::vector<std::uint32_t> ids;
    if (h.version >= 2) {
      const std::uint8_t numbering = r.u8("word numbering");
      if (numbering > 1) r.corrupt("unknown word numbering " + std::to_string(numbering));
      if (numbering == 1) {
        r.require_items(words, 4, "word ids");
        ids.resize(static_cast<std::size_t>(words));
        r.read(ids.data(), words * 4, "word ids");
        if constexpr (std::endian::native != std::endian::little)
          for (auto& id : ids) id = (id >> 24) | ((id >> 8) & 0xFF00U) | ((id << 8) & 0xFF0000U) | (id << 24);
      }
    }
    r.finish(h.checksum, h.version >= 2 ? "the word numbering" : "the idf weights");
    detail::f32_from_little_endian(v.idf_.data(), v.idf_.size());
    if constexpr (std::is_same_v<value_type, float>)
      detail::f32_from_little_endian(v.centres_.template ptr<float>(0), v.centres_.total());
    if (const std::string problem = v.link(); !problem.empty()) r.corrupt(problem);
    if (words != leaves) r.corrupt("word count " + std::to_string(words) + " differs from the tree's " + std::to_string(leaves) + " leaves");
    if (!ids.empty())
      if (const std::string problem = v.renumber(ids); !problem.empty()) r.corrupt(problem);
    if constexpr (std::is_same_v<value_type, float>)
      if (!cv::checkRange(v.centres_)) r.corrupt("a centre value is not finite");
    bool bad_idf = false;  // no early exit, so the compiler may vectorize the loop
    for (float f : v.idf_) bad_idf |= !(f >= 0.0f && f <= std::numeric_limits<float>::max());
    if (bad_idf) r.corrupt("an idf weight is negative or not finite");
    return v;
  }

  static void check_options(const VocabularyTreeOptions& o) { detail::check_vocabulary_tree_options(o); }

  void check_descriptors(const cv::Mat& d, const char* what) const {
    // Messages appended piece by piece: GCC 12 at -O2 reports a false -Warray-bounds on a
    // chain of + from a temporary std::string here.
    detail::check(size() > 0, [&] {
      std::string m = "VocabularyTree::";
      m += what;
      m += ": the vocabulary is empty (learn or load it first)";
      return m;
    });
    if (d.empty()) return;
    detail::check(d.type() == Traits::descriptor_type && d.cols == cols_, ErrorKind::policy_mismatch, [&] {
      std::string m = "VocabularyTree::";
      m += what;
      m += ": descriptors must be ";
      m += cv::typeToString(Traits::descriptor_type);
      m += " with " + std::to_string(cols_) + " columns (the vocabulary's), got ";
      m += cv::typeToString(d.type());
      m += " with " + std::to_string(d.cols);
      return m;
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
    std::vector<std::uint32_t> counts(1, 0);
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
      counts[p.node] = static_cast<std::uint32_t>(groups.size());
      for (std::size_t g = 0; g < groups.size(); ++g) {
        const auto id = static_cast<std::uint32_t>(counts.size());
        counts.push_back(0);
        const value_type* c = centres.ptr<value_type>(static_cast<int>(g));
        centre_values.insert(centre_values.end(), c, c + cols_);
        queue.push_back({id, p.level + 1, std::move(groups[g])});
      }
    }
    adopt_centres(cv::Mat(static_cast<int>(counts.size()), cols_, Traits::descriptor_type, centre_values.data()));
    index(counts);
  }

  /// centres_ = a copy of `m` (one row per node) in centre_storage_.
  void adopt_centres(const cv::Mat& m) {
    const std::size_t row_bytes = static_cast<std::size_t>(m.cols) * m.elemSize();
    centre_storage_.resize_for_overwrite(static_cast<std::size_t>(m.rows) * row_bytes);
    centres_ = cv::Mat(m.rows, m.cols, m.type(), centre_storage_.data());
    for (int r = 0; r < m.rows; ++r) std::memcpy(centres_.ptr(r), m.ptr(r), row_bytes);
  }

  /// nodes_ from child counts (a valid breadth-first tree).
  void index(const std::vector<std::uint32_t>& counts) {
    nodes_.resize_for_overwrite(counts.size());
    for (std::size_t i = 0; i < counts.size(); ++i) nodes_[i].count = counts[i];
    const std::string problem = link();
    detail::check(problem.empty(), [&] { return "VocabularyTree: built an invalid tree: " + problem; });
  }

  /// Gives the j-th leaf (in node order) word id ids[j]; what is wrong with `ids` (not
  /// one per leaf, not a permutation), or empty.
  [[nodiscard]] std::string renumber(const std::vector<std::uint32_t>& ids) {
    if (ids.size() != leaves_)
      return std::to_string(ids.size()) + " word ids for " + std::to_string(leaves_) + " leaves";
    std::vector<std::uint8_t> seen(ids.size(), 0);
    for (std::uint32_t id : ids) {
      if (id >= ids.size() || seen[id] != 0)
        return "the word ids are not a permutation of 0.." + std::to_string(ids.size() - 1) + " (word " + std::to_string(id) + ")";
      seen[id] = 1;
    }
    std::size_t j = 0;
    for (Node& node : nodes_)
      if (node.count == 0) node.first = ids[j++];
    return {};
  }

  /// Sets each node's `first` from the counts (the first child of an inner node, the
  /// word id of a leaf, leaves numbered in node order), checking in the same pass that
  /// the counts form one breadth-first tree of at most depth_ levels with at most
  /// branching_ children a node (each node's children come after it, every node but the
  /// root has exactly one parent, the root has children). Returns what is wrong, or
  /// empty. Levels need no array: in breadth-first order the nodes of level l + 1 are
  /// exactly those claimed by the nodes of level l, so a level ends where the claims of
  /// the one before it ended.
  [[nodiscard]] std::string link() {
    const std::size_t n = nodes_.size();
    if (n == 0 || nodes_[0].count == 0) return "the root has no children";
    const auto k = static_cast<std::uint32_t>(branching_);
    // Level by level: in breadth-first order the children of the nodes [begin, end) are
    // the nodes [end, next), so a level is linked by a running sum with no check inside
    // the loop (a load links every node of the file); the counts are checked once per
    // level, and only a level that fails is walked again to name its first bad node.
    std::uint64_t next = 1;
    std::size_t begin = 0, end = 1;
    std::uint32_t leaves = 0;
    for (int level = 0;; ++level) {
      std::uint32_t widest = 0;
      for (std::size_t i = begin; i < end; ++i) {
        Node& node = nodes_[i];
        const std::uint32_t c = node.count;
        widest = std::max(widest, c);
        node.first = static_cast<std::uint32_t>(c == 0 ? leaves++ : next);
        next += c;
      }
      if (widest > k || next > n) {
        std::uint64_t claimed = end;
        for (std::size_t i = begin; i < end; ++i) {
          const std::uint32_t c = nodes_[i].count;
          if (c > k)
            return "node " + std::to_string(i) + " has " + std::to_string(c) + " children, more than the branching " +
                   std::to_string(branching_);
          if (claimed + c > n) return "the child counts claim more nodes than the " + std::to_string(n) + " stored";
          claimed += c;
        }
      }
      if (next == end) break;  // a level of leaves: the tree ends here
      if (level + 1 > depth_) return "the tree is deeper than its depth " + std::to_string(depth_);
      begin = end;
      end = static_cast<std::size_t>(next);
    }
    if (end < n) return "node " + std::to_string(end) + " is nobody's child (the counts do not form a tree)";
    leaves_ = leaves;
    return {};
  }

  /// The child of inner node `node` nearest to `d` (ties: the first, so assignment is
  /// deterministic and equals DBoW2's and FBoW's descent).
  [[nodiscard]] std::uint32_t nearest_child(const value_type* d, const Node& node) const noexcept {
    const auto* rows = centres_.ptr<value_type>(static_cast<int>(node.first));
    if constexpr (std::is_same_v<Traits, HammingTraits>) {
      static const detail::NearestRowFn nearest = detail::nearest_row_kernel();
      return node.first + nearest(d, rows, node.count, static_cast<std::size_t>(cols_), static_cast<std::size_t>(cols_));
    } else {
      std::uint32_t best = 0;
      distance_type best_d = Traits::distance(d, rows, cols_);
      for (std::uint32_t c = 1; c < node.count; ++c) {
        const distance_type dc = Traits::distance(d, rows + static_cast<std::size_t>(c) * static_cast<std::size_t>(cols_), cols_);
        if (dc < best_d) {
          best_d = dc;
          best = c;
        }
      }
      return node.first + best;
    }
  }

  /// Starts fetching what the descent needs at inner node `node`: its children's
  /// centres and their node entries.
  void prefetch(const Node& node) const noexcept {
#if defined(__GNUC__) || defined(__clang__)
    const auto* c = reinterpret_cast<const char*>(centres_.ptr<value_type>(static_cast<int>(node.first)));
    const std::size_t bytes = static_cast<std::size_t>(node.count) * static_cast<std::size_t>(cols_) * sizeof(value_type);
    for (std::size_t o = 0; o < bytes; o += 64) __builtin_prefetch(c + o);
    const auto* e = reinterpret_cast<const char*>(nodes_.data() + node.first);
    for (std::size_t o = 0; o < node.count * sizeof(Node); o += 64) __builtin_prefetch(e + o);
#else
    (void)node;
#endif
  }

  /// The words of all rows. For binary descriptors on a CPU with POPCNT the whole
  /// descent is compiled for it (the distance kernel inlined, no call per node).
  void assign_rows(const cv::Mat& d, std::uint32_t* out) const {
#ifdef VMAP_HAMMING_POPCNT
    if constexpr (std::is_same_v<Traits, HammingTraits>)
      if (detail::popcnt_available()) return assign_rows_popcnt(d, out);
#endif
    descend(d, out);
  }

#ifdef VMAP_HAMMING_POPCNT
  __attribute__((target("popcnt"))) void assign_rows_popcnt(const cv::Mat& d, std::uint32_t* out) const { descend(d, out); }
#endif

  /// The descents of a batch of descriptors are interleaved level by level, each
  /// prefetching its next node's children: in a large tree every level is a cache miss,
  /// and the batch overlaps them.
  [[gnu::always_inline]] void descend(const cv::Mat& d, std::uint32_t* out) const {
    constexpr int batch = 16;
    for (int start = 0; start < d.rows; start += batch) {
      const int m = std::min(batch, d.rows - start);
      std::uint32_t at[batch] = {};
      for (bool moving = true; moving;) {
        moving = false;
        for (int i = 0; i < m; ++i) {
          const Node& node = nodes_[at[i]];
          if (node.count == 0) continue;
          const value_type* q = d.ptr<value_type>(start + i);
          if constexpr (std::is_same_v<Traits, HammingTraits>) {
            at[i] = node.first + detail::nearest_row_inline(q, centres_.ptr<value_type>(static_cast<int>(node.first)), node.count,
                                                            static_cast<std::size_t>(cols_), static_cast<std::size_t>(cols_));
          } else {
            at[i] = nearest_child(q, node);
          }
          const Node& next = nodes_[at[i]];
          if (next.count != 0) prefetch(next);
          moving = true;
        }
      }
      for (int i = 0; i < m; ++i) out[start + i] = nodes_[at[i]].first;
    }
  }

  /// FBoW's weighting (fbow.cpp, Vocabulary::transform): each descriptor adds its word's
  /// weight to a float sum, in descriptor order; then every value is multiplied by
  /// 1 / sqrt(sum of the float squares, in double).
  [[nodiscard]] BowVector fbow_weights(const std::vector<std::uint32_t>& words) const {
    std::vector<std::pair<std::uint32_t, std::uint32_t>> order(words.size());
    for (std::size_t i = 0; i < words.size(); ++i) order[i] = {words[i], static_cast<std::uint32_t>(i)};
    std::sort(order.begin(), order.end());
    BowVector v;
    for (std::size_t i = 0; i < order.size();) {
      float sum = 0.0f;
      std::size_t j = i;
      for (; j < order.size() && order[j].first == order[i].first; ++j) sum += idf_[order[i].first];
      v.entries.push_back({order[i].first, sum});
      i = j;
    }
    double norm = 0.0;
    for (const auto& e : v.entries) norm += static_cast<double>(e.weight * e.weight);
    if (norm > 0.0) {
      const double inv = 1.0 / std::sqrt(norm);
      for (auto& e : v.entries) e.weight = static_cast<float>(static_cast<double>(e.weight) * inv);
    }
    return v;
  }

  int branching_ = 0;
  int depth_ = 0;
  int cols_ = 0;
  BowWeighting weighting_ = BowWeighting::tf_idf_l1;
  cv::Mat centres_;          ///< one row per node (row 0: the root, unused); siblings are consecutive rows
  detail::LargeArray<std::uint8_t> centre_storage_;  ///< what centres_ points into (but for from_words)
  detail::LargeArray<Node> nodes_;  ///< breadth-first
  std::uint32_t leaves_ = 0;
  std::vector<float> idf_;   ///< per word
};

using BinaryVocabularyTree = VocabularyTree<HammingTraits>;
using FloatVocabularyTree = VocabularyTree<L2Traits>;

}  // namespace vmap
