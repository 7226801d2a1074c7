#pragma once

// Readers of the vocabulary files other libraries write, into a BinaryVocabularyTree
// with the same tree, the same word ids, the same weights and the same weighting, so
// that transform() gives the bag of words the writing library gives (word ids exact,
// weights to float precision; tests/unit/place against ../shared/data/vocabularies):
//  - ORB-SLAM2 / ORB-SLAM3 text (ORBvoc.txt; DBoW2's TemplatedVocabulary::
//    saveToTextFile): a line "k L scoring weighting", then one line per node (ids 1..,
//    the root 0 implicit) "parent is_leaf b0 .. b31 weight"; leaves are words in line
//    order. Blank lines are skipped (ORB-SLAM2's own loader turns the empty line after
//    the last newline into a phantom word of weight 0; it has no effect on its vectors).
//  - DBoW2 YAML (.yml, .yml.gz; TemplatedVocabulary::save through cv::FileStorage): map
//    `vocabulary` with k, L, scoringType, weightingType, `nodes` {nodeId, parentId,
//    weight, descriptor} in any order (children keep their order in the file) and
//    `words` {wordId, nodeId}.
//  - FBoW binary (fbow::Vocabulary::saveToFile): u64 signature 55824124, a 120-byte
//    parameter block (its struct as laid out in memory: char[50] name, padding, u32
//    alignment, u32 block count, padding, u64 slot, block, descriptor-offset,
//    child-offset and total sizes, i32 type, i32 size, u32 k, padding), then blocks of the children of one node: u16 N, u16 (unused),
//    u32 parent, k descriptor slots, k {u32 child, f32 weight} where a set top bit marks
//    a leaf (the low bits its word id) and otherwise the child's block.
// DBoW2's weightings TF_IDF / TF / IDF / BINARY with its L1_NORM or L2_NORM scoring map to
// BowWeighting (TF and BINARY files store weight 1); its CHI_SQUARE, KL, BHATTACHARYYA
// and DOT_PRODUCT scorings have no vmap score and are refused. FBoW's transform sums
// the leaf weights in float and L2-normalises (BowWeighting::fbow).
//
// Every reader is bounded and safe on hostile input: sizes are checked against the bytes
// there before anything is allocated, the node links must form one tree (no cycle, no
// node twice, every inner node with children, at most `k` children and 64 levels), and
// anything wrong is a vmap::Error naming the file and what is wrong.

#include <vmap/core/error.hpp>
#include <vmap/io/yaml_limits.hpp>
#include <vmap/place/detail/format.hpp>
#include <vmap/place/vocabulary_tree.hpp>

#include <opencv2/core.hpp>
#include <zlib.h>

#include <algorithm>
#include <array>
#include <bit>
#include <charconv>
#include <cstdio>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <deque>
#include <exception>
#include <filesystem>
#include <limits>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace vmap {

/// The vocabulary file formats vmap reads.
enum class VocabularyFormat { vmap, orbslam_text, dbow2_yaml, fbow };

/// Largest vocabulary file read (the ORB-SLAM2 ORBvoc.txt of 1M words is 145 MB).
inline constexpr std::uint64_t max_vocabulary_file_bytes = std::uint64_t{4} << 30;

/// Largest DBoW2 YAML text a gzipped vocabulary may decompress to. DBoW2's YAML of the
/// 1M-word ORB vocabulary is about 400 MB; the text is held whole while OpenCV parses it.
inline constexpr std::uint64_t max_vocabulary_yaml_bytes = std::uint64_t{1} << 30;  // 1 GiB

/// Most a gzipped DBoW2 vocabulary's text may outgrow its compressed bytes (above
/// `min_vocabulary_yaml_bound`). The text is descriptors learned from images written as
/// decimal bytes, which gzip shrinks about 3.5 times (the k10L3 vocabulary of
/// ../shared/data/vocabularies: 75 kB for 266 kB); gzip shrinks filler up to 1032 times, so
/// without this bound a 1 MB file would be inflated to 1 GB and handed to OpenCV's parser.
inline constexpr std::uint64_t max_vocabulary_gzip_ratio = 32;

/// The text a gzipped vocabulary may decompress to whatever its ratio: small files
/// (crafted or not) are checked as text, as plain YAML is.
inline constexpr std::uint64_t min_vocabulary_yaml_bound = std::uint64_t{16} << 20;  // 16 MiB

namespace detail {

/// A tree given as parent links (another library's node ids; node 0 the root, children
/// in the order given), converted to vmap's breadth-first layout.
struct ForeignTree {
  int k = 0;
  int levels = 0;  ///< the file's L, or 0: taken from the tree
  int cols = 0;
  std::vector<std::vector<std::uint32_t>> children;  ///< per foreign node id
  std::vector<const std::uint8_t*> descriptor;       ///< per foreign node id (nullptr for the root)
  std::vector<std::int64_t> word;                    ///< per foreign node id: word id of a leaf, else -1
  std::vector<float> weight;                         ///< per word id
  BowWeighting weighting = BowWeighting::tf_idf_l1;
};

[[noreturn]] inline void bad_vocabulary(const std::string& source, const std::string& what) {
  fail(ErrorKind::corrupt, source + ": " + what);
}

/// Breadth-first from the root: each node visited once (a node reached twice or never
/// is an error), inner nodes have children, leaves are words.
inline BinaryVocabularyTree to_vmap_tree(const ForeignTree& t, const std::string& source) {
  const std::size_t n = t.children.size();
  if (n < 2 || t.children[0].empty()) bad_vocabulary(source, "the root has no children");
  if (t.k < 2 || t.k > BinaryVocabularyTree::max_branching)
    bad_vocabulary(source, "branching " + std::to_string(t.k) + " outside 2..4096");
  std::vector<std::uint32_t> order{0};
  std::vector<std::uint8_t> level(n, 0), seen(n, 0);
  seen[0] = 1;
  int depth = 0;
  for (std::size_t i = 0; i < order.size(); ++i) {
    const std::uint32_t id = order[i];
    const auto& ch = t.children[id];
    if (ch.size() > static_cast<std::size_t>(t.k))
      bad_vocabulary(source, "node " + std::to_string(id) + " has " + std::to_string(ch.size()) + " children, more than k = " +
                                 std::to_string(t.k));
    if (ch.empty() && t.word[id] < 0) bad_vocabulary(source, "node " + std::to_string(id) + " is neither a word nor has children");
    if (!ch.empty() && t.word[id] >= 0) bad_vocabulary(source, "word node " + std::to_string(id) + " has children");
    for (std::uint32_t c : ch) {
      if (c >= n || seen[c] != 0) bad_vocabulary(source, "node " + std::to_string(c) + " is reached twice (the links do not form a tree)");
      seen[c] = 1;
      level[c] = static_cast<std::uint8_t>(level[id] + 1);
      if (level[c] > BinaryVocabularyTree::max_depth) bad_vocabulary(source, "the tree is deeper than 64 levels");
      depth = std::max(depth, static_cast<int>(level[c]));
      order.push_back(c);
    }
  }
  if (order.size() != n)
    bad_vocabulary(source, std::to_string(n - order.size()) + " nodes are not reachable from the root");
  if (t.levels > 0 && depth > t.levels)
    bad_vocabulary(source, "the tree has " + std::to_string(depth) + " levels, more than its L = " + std::to_string(t.levels));
  std::vector<std::uint32_t> counts(n);
  cv::Mat centres(static_cast<int>(n), t.cols, CV_8UC1, cv::Scalar(0));
  std::vector<std::uint32_t> ids;
  for (std::size_t i = 0; i < n; ++i) {
    const std::uint32_t id = order[i];
    counts[i] = static_cast<std::uint32_t>(t.children[id].size());
    if (id != 0) std::memcpy(centres.ptr(static_cast<int>(i)), t.descriptor[id], static_cast<std::size_t>(t.cols));
    if (t.word[id] >= 0) ids.push_back(static_cast<std::uint32_t>(t.word[id]));
  }
  if (ids.size() != t.weight.size())
    bad_vocabulary(source, std::to_string(t.weight.size()) + " word weights for " + std::to_string(ids.size()) + " words");
  for (std::size_t w = 0; w < t.weight.size(); ++w)
    if (!(std::isfinite(t.weight[w]) && t.weight[w] >= 0.0f))
      bad_vocabulary(source, "the weight of word " + std::to_string(w) + " is negative or not finite");
  try {
    return BinaryVocabularyTree::from_tree(t.k, std::max(1, t.levels > 0 ? t.levels : depth), counts, centres, t.weight,
                                           t.weighting, ids);
  } catch (const Error& e) {
    bad_vocabulary(source, e.what());
  }
}

/// DBoW2's WeightingType and ScoringType as a BowWeighting.
inline BowWeighting dbow2_weighting(long weighting, long scoring, const std::string& source) {
  static const char* const scorings[] = {"L1_NORM", "L2_NORM", "CHI_SQUARE", "KL", "BHATTACHARYYA", "DOT_PRODUCT"};
  if (weighting < 0 || weighting > 3) bad_vocabulary(source, "unknown DBoW2 weighting type " + std::to_string(weighting));
  if (scoring < 0 || scoring > 5) bad_vocabulary(source, "unknown DBoW2 scoring type " + std::to_string(scoring));
  if (scoring > 1)
    bad_vocabulary(source, std::string("DBoW2 scoring ") + scorings[scoring] +
                               " is not supported (vmap scores L1_NORM and L2_NORM vocabularies)");
  const bool once = weighting >= 2;  // IDF, BINARY: each word once
  if (scoring == 0) return once ? BowWeighting::idf_l1 : BowWeighting::tf_idf_l1;
  return once ? BowWeighting::idf_l2 : BowWeighting::tf_idf_l2;
}

/// Parses one number of type T (after blanks) from s at pos, moving pos past it; false
/// if there is none.
template <class T>
bool next_number(std::string_view s, std::size_t& pos, T& out) {
  while (pos < s.size() && (s[pos] == ' ' || s[pos] == '\t' || s[pos] == '\r')) ++pos;
  const auto r = std::from_chars(s.data() + pos, s.data() + s.size(), out);
  if (r.ec != std::errc{} || r.ptr == s.data() + pos) return false;
  pos = static_cast<std::size_t>(r.ptr - s.data());
  return true;
}
inline bool next_uint(std::string_view s, std::size_t& pos, std::uint64_t& out) { return next_number(s, pos, out); }
inline bool next_int(std::string_view s, std::size_t& pos, long& out) { return next_number(s, pos, out); }
inline bool next_double(std::string_view s, std::size_t& pos, double& out) { return next_number(s, pos, out); }
inline bool only_blanks(std::string_view s, std::size_t pos) {
  for (; pos < s.size(); ++pos)
    if (s[pos] != ' ' && s[pos] != '\t' && s[pos] != '\r') return false;
  return true;
}

}  // namespace detail

/// Reads ORB-SLAM2/3's ORBvoc.txt format (see the top of this header); `name` names the
/// input in messages.
inline BinaryVocabularyTree import_orbslam_text(std::string_view text, const std::string& name = "<memory>") {
  const std::string source = "ORB-SLAM text vocabulary '" + name + "'";
  std::size_t at = 0;
  std::size_t line_no = 0;
  auto next_line = [&](std::string_view& line) {
    while (at < text.size()) {
      const std::size_t end = std::min(text.find('\n', at), text.size());
      line = text.substr(at, end - at);
      at = std::min(end + 1, text.size());
      ++line_no;
      if (!detail::only_blanks(line, 0)) return true;
    }
    return false;
  };
  auto bad = [&](const std::string& what) { detail::bad_vocabulary(source, "line " + std::to_string(line_no) + ": " + what); };
  std::string_view line;
  if (!next_line(line)) detail::bad_vocabulary(source, "empty");
  detail::ForeignTree t;
  {
    std::size_t p = 0;
    long k = 0, levels = 0, scoring = 0, weighting = 0;
    if (!detail::next_int(line, p, k) || !detail::next_int(line, p, levels) || !detail::next_int(line, p, scoring) ||
        !detail::next_int(line, p, weighting) || !detail::only_blanks(line, p))
      bad("the first line is not \"k L scoring weighting\"");
    if (k < 2 || k > BinaryVocabularyTree::max_branching) bad("k = " + std::to_string(k) + " outside 2..4096");
    if (levels < 1 || levels > BinaryVocabularyTree::max_depth) bad("L = " + std::to_string(levels) + " outside 1..64");
    t.k = static_cast<int>(k);
    t.levels = static_cast<int>(levels);
    t.weighting = detail::dbow2_weighting(weighting, scoring, source);
  }
  // A node line is at least "p l " + 1 byte + weight: about 2 bytes a descriptor byte;
  // the nodes are bounded by the lines there are.
  const std::size_t max_nodes = static_cast<std::size_t>(std::count(text.begin() + static_cast<std::ptrdiff_t>(at), text.end(), '\n')) + 2;
  t.children.assign(1, {});
  t.descriptor.assign(1, nullptr);
  t.word.assign(1, -1);
  std::vector<std::uint8_t> bytes;
  std::vector<std::uint8_t> row;
  while (next_line(line)) {
    const auto id = static_cast<std::uint32_t>(t.children.size());
    if (t.children.size() >= max_nodes) bad("more nodes than lines");
    std::size_t p = 0;
    std::uint64_t parent = 0, leaf = 0;
    if (!detail::next_uint(line, p, parent) || !detail::next_uint(line, p, leaf)) bad("a node line starts with \"parent is_leaf\"");
    if (parent >= id) bad("node " + std::to_string(id) + " names parent " + std::to_string(parent) + ", not an earlier node");
    if (leaf > 1) bad("is_leaf is " + std::to_string(leaf) + ", not 0 or 1");
    row.clear();
    double weight = 0.0;
    std::uint64_t v = 0;
    for (;;) {
      const std::size_t before = p;
      if (!detail::next_uint(line, p, v)) bad("a descriptor byte or the weight is missing");
      // the last number is the weight (it may have a point or an exponent)
      std::size_t after = p;
      if (after < line.size() && (line[after] == '.' || line[after] == 'e' || line[after] == 'E' || line[after] == '-')) {
        p = before;
        if (!detail::next_double(line, p, weight)) bad("the weight is not a number");
        break;
      }
      if (detail::only_blanks(line, p)) {
        weight = static_cast<double>(v);
        break;
      }
      if (v > 255) bad("descriptor byte " + std::to_string(v) + " is above 255");
      row.push_back(static_cast<std::uint8_t>(v));
      if (row.size() > static_cast<std::size_t>(BinaryVocabularyTree::max_cols)) bad("more than 4096 descriptor bytes");
    }
    if (!detail::only_blanks(line, p)) bad("unexpected text after the weight");
    if (row.empty()) bad("no descriptor");
    if (t.cols == 0) t.cols = static_cast<int>(row.size());
    if (row.size() != static_cast<std::size_t>(t.cols))
      bad(std::to_string(row.size()) + " descriptor bytes, earlier nodes have " + std::to_string(t.cols));
    if (t.children[parent].size() >= static_cast<std::size_t>(t.k))
      bad("node " + std::to_string(parent) + " gets more than k = " + std::to_string(t.k) + " children");
    t.children[parent].push_back(id);
    t.children.emplace_back();
    bytes.insert(bytes.end(), row.begin(), row.end());
    if (leaf == 1) {
      t.word.push_back(static_cast<std::int64_t>(t.weight.size()));
      t.weight.push_back(static_cast<float>(weight));
    } else {
      t.word.push_back(-1);
    }
  }
  t.descriptor.resize(t.children.size(), nullptr);
  for (std::size_t i = 1; i < t.children.size(); ++i) t.descriptor[i] = bytes.data() + (i - 1) * static_cast<std::size_t>(t.cols);
  return detail::to_vmap_tree(t, source);
}

/// Reads DBoW2's YAML vocabulary (OrbVocabulary::save) from a cv::FileStorage.
inline BinaryVocabularyTree import_dbow2_yaml(const cv::FileStorage& fs, const std::string& name = "<memory>") {
  const std::string source = "DBoW2 YAML vocabulary '" + name + "'";
  const cv::FileNode voc = fs["vocabulary"];
  if (!voc.isMap()) detail::bad_vocabulary(source, "no map 'vocabulary'");
  auto integer = [&](const cv::FileNode& node, const char* key) {
    const cv::FileNode f = node[key];
    if (!f.isInt()) detail::bad_vocabulary(source, std::string("'") + key + "' is missing or not an integer");
    return static_cast<long>(static_cast<int>(f));
  };
  detail::ForeignTree t;
  const long k = integer(voc, "k");
  const long levels = integer(voc, "L");
  if (k < 2 || k > BinaryVocabularyTree::max_branching) detail::bad_vocabulary(source, "k = " + std::to_string(k) + " outside 2..4096");
  if (levels < 1 || levels > BinaryVocabularyTree::max_depth)
    detail::bad_vocabulary(source, "L = " + std::to_string(levels) + " outside 1..64");
  t.k = static_cast<int>(k);
  t.levels = static_cast<int>(levels);
  t.weighting = detail::dbow2_weighting(integer(voc, "weightingType"), integer(voc, "scoringType"), source);
  const cv::FileNode nodes = voc["nodes"];
  const cv::FileNode words = voc["words"];
  if (!nodes.isSeq() || !words.isSeq()) detail::bad_vocabulary(source, "'nodes' or 'words' is missing or not a sequence");
  const std::size_t n = nodes.size() + 1;  // + the root
  t.children.assign(n, {});
  t.descriptor.assign(n, nullptr);
  t.word.assign(n, -1);
  std::vector<std::int64_t> parent(n, -1);
  std::vector<double> node_weight(n, 0.0);
  std::vector<std::uint8_t> bytes;
  std::vector<std::uint32_t> file_order;
  file_order.reserve(n - 1);
  for (std::size_t i = 0; i + 1 < n; ++i) {
    const cv::FileNode f = nodes[static_cast<int>(i)];
    if (!f.isMap()) detail::bad_vocabulary(source, "node entry " + std::to_string(i) + " is not a map");
    const long id = integer(f, "nodeId");
    const long pid = integer(f, "parentId");
    if (id < 1 || static_cast<std::size_t>(id) >= n)
      detail::bad_vocabulary(source, "nodeId " + std::to_string(id) + " outside 1.." + std::to_string(n - 1));
    if (pid < 0 || static_cast<std::size_t>(pid) >= n || pid == id)
      detail::bad_vocabulary(source, "node " + std::to_string(id) + " has parentId " + std::to_string(pid));
    if (parent[static_cast<std::size_t>(id)] >= 0) detail::bad_vocabulary(source, "node " + std::to_string(id) + " appears twice");
    parent[static_cast<std::size_t>(id)] = pid;
    const cv::FileNode w = f["weight"];
    if (!w.isReal() && !w.isInt()) detail::bad_vocabulary(source, "node " + std::to_string(id) + " has no numeric weight");
    node_weight[static_cast<std::size_t>(id)] = static_cast<double>(w);
    const cv::FileNode d = f["descriptor"];
    if (!d.isString()) detail::bad_vocabulary(source, "node " + std::to_string(id) + " has no descriptor string");
    const std::string text = static_cast<std::string>(d);
    std::size_t p = 0;
    std::uint64_t v = 0;
    std::size_t count = 0;
    while (detail::next_uint(text, p, v)) {
      if (v > 255) detail::bad_vocabulary(source, "node " + std::to_string(id) + ": descriptor byte " + std::to_string(v) + " above 255");
      bytes.push_back(static_cast<std::uint8_t>(v));
      ++count;
    }
    if (!detail::only_blanks(text, p)) detail::bad_vocabulary(source, "node " + std::to_string(id) + ": the descriptor is not bytes");
    if (count == 0 || count > static_cast<std::size_t>(BinaryVocabularyTree::max_cols))
      detail::bad_vocabulary(source, "node " + std::to_string(id) + " has " + std::to_string(count) + " descriptor bytes");
    if (t.cols == 0) t.cols = static_cast<int>(count);
    if (count != static_cast<std::size_t>(t.cols))
      detail::bad_vocabulary(source, "node " + std::to_string(id) + " has " + std::to_string(count) + " descriptor bytes, others " +
                                         std::to_string(t.cols));
    file_order.push_back(static_cast<std::uint32_t>(id));
  }
  // children in file order, as DBoW2's load appends them
  for (std::uint32_t id : file_order) {
    auto& ch = t.children[static_cast<std::size_t>(parent[id])];
    if (ch.size() >= static_cast<std::size_t>(t.k))
      detail::bad_vocabulary(source, "node " + std::to_string(parent[id]) + " has more than k = " + std::to_string(t.k) + " children");
    ch.push_back(id);
  }
  for (std::size_t i = 0; i + 1 < n; ++i)
    t.descriptor[file_order[i]] = bytes.data() + i * static_cast<std::size_t>(t.cols);
  t.weight.assign(words.size(), -1.0f);
  for (std::size_t i = 0; i < words.size(); ++i) {
    const cv::FileNode f = words[static_cast<int>(i)];
    if (!f.isMap()) detail::bad_vocabulary(source, "word entry " + std::to_string(i) + " is not a map");
    const long wid = integer(f, "wordId");
    const long nid = integer(f, "nodeId");
    if (wid < 0 || static_cast<std::size_t>(wid) >= words.size())
      detail::bad_vocabulary(source, "wordId " + std::to_string(wid) + " outside 0.." + std::to_string(words.size() - 1));
    if (nid < 1 || static_cast<std::size_t>(nid) >= n) detail::bad_vocabulary(source, "word " + std::to_string(wid) + " names node " + std::to_string(nid));
    if (t.word[static_cast<std::size_t>(nid)] >= 0 || t.weight[static_cast<std::size_t>(wid)] >= 0.0f)
      detail::bad_vocabulary(source, "word " + std::to_string(wid) + " or node " + std::to_string(nid) + " appears twice");
    t.word[static_cast<std::size_t>(nid)] = wid;
    t.weight[static_cast<std::size_t>(wid)] = static_cast<float>(node_weight[static_cast<std::size_t>(nid)]);
  }
  return detail::to_vmap_tree(t, source);
}

namespace detail {

/// Refuses YAML OpenCV's parser cannot be trusted with (io/yaml_limits.hpp): nested
/// deeper than `max_depth` (it recurses once per level; the DBoW2 vocabulary needs 4:
/// the vocabulary map, its nodes list, an item and its flow map), or a top level that is
/// not a map of keys (it never returns on some).
inline void check_vocabulary_yaml(std::string_view text, const std::string& source, std::size_t max_depth = 16) {
  const std::size_t depth = yaml_depth(text);
  if (depth > max_depth)
    bad_vocabulary(source, "YAML nested " + std::to_string(depth) + " levels deep, more than the " + std::to_string(max_depth) + " accepted");
  if (const auto why = yaml_top_level_error(text)) bad_vocabulary(source, "YAML " + *why);
}

}  // namespace detail

namespace detail {

/// Opens a FileStorage with `open` and reads the DBoW2 vocabulary in it; whatever OpenCV
/// throws (cv::Exception, or std::length_error and the like from its parser) becomes an
/// Error naming the file.
template <class Open>
BinaryVocabularyTree read_dbow2_storage(Open open, const std::string& name) {
  const std::string source = "DBoW2 YAML vocabulary '" + name + "'";
  cv::FileStorage fs;
  try {
    open(fs);
  } catch (const cv::Exception& e) {
    detail::bad_vocabulary(source, std::string("not YAML OpenCV can read: ") + e.err);
  } catch (const std::exception& e) {  // OpenCV's parser lets std::length_error and the like out
    detail::bad_vocabulary(source, std::string("not YAML OpenCV can read (") + e.what() + ")");
  }
  if (!fs.isOpened()) detail::bad_vocabulary(source, "not YAML OpenCV can read");
  try {
    return import_dbow2_yaml(fs, name);
  } catch (const cv::Exception& e) {
    detail::bad_vocabulary(source, std::string("unexpected YAML content: ") + e.err);
  } catch (const Error&) {
    throw;
  } catch (const std::exception& e) {
    detail::bad_vocabulary(source, std::string("unexpected YAML content (") + e.what() + ")");
  }
}

}  // namespace detail

/// Reads DBoW2's YAML vocabulary from text (not gzipped).
inline BinaryVocabularyTree import_dbow2_yaml(std::string_view text, const std::string& name = "<memory>") {
  const std::string source = "DBoW2 YAML vocabulary '" + name + "'";
  detail::check_vocabulary_yaml(text, source);
  return detail::read_dbow2_storage(
      [&](cv::FileStorage& fs) {
        fs.open(std::string(text), cv::FileStorage::READ | cv::FileStorage::MEMORY | cv::FileStorage::FORMAT_YAML);
      },
      name);
}

namespace detail {

/// The gzip data `compressed` (one or more members, as gzip writes and reads them)
/// decompressed, counting the bytes as they come out: more than `max_bytes` is an Error
/// as soon as it happens (`limit` says what the bound is in it). The trailer's size field
/// (ISIZE) is not trusted, as any writer can put any number there.
inline std::string gunzip_bounded(std::string_view compressed, std::uint64_t max_bytes, const std::string& source,
                                  const std::string& limit = "the limit") {
  z_stream z{};
  if (inflateInit2(&z, 15 + 16) != Z_OK) bad_vocabulary(source, "zlib cannot start decompressing");  // 16: gzip wrapper
  struct End {
    z_stream& z;
    ~End() { inflateEnd(&z); }
  } end{z};
  std::string out;
  std::array<char, 1 << 16> buf{};
  std::size_t fed = 0;  // input handed to zlib so far (in pieces: avail_in is 32-bit)
  for (;;) {
    if (z.avail_in == 0 && fed < compressed.size()) {
      const std::size_t n = std::min<std::size_t>(compressed.size() - fed, std::size_t{1} << 30);
      z.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(compressed.data() + fed));
      z.avail_in = static_cast<uInt>(n);
      fed += n;
    }
    z.next_out = reinterpret_cast<Bytef*>(buf.data());
    z.avail_out = static_cast<uInt>(buf.size());
    const int rc = inflate(&z, Z_NO_FLUSH);
    const std::size_t got = buf.size() - z.avail_out;
    if (out.size() + got > max_bytes)
      bad_vocabulary(source, "decompresses to more than " + std::to_string(max_bytes) + " bytes (" + limit + ")");
    out.append(buf.data(), got);
    if (rc == Z_STREAM_END) {
      if (z.avail_in == 0 && fed == compressed.size()) return out;
      if (inflateReset(&z) != Z_OK) bad_vocabulary(source, "zlib cannot go on to the next gzip member");
      continue;
    }
    if (rc == Z_BUF_ERROR && z.avail_in == 0 && fed == compressed.size())
      bad_vocabulary(source, "the gzip data is truncated");
    if (rc != Z_OK && rc != Z_BUF_ERROR)
      bad_vocabulary(source, std::string("not valid gzip data (") + (z.msg != nullptr ? z.msg : "zlib error") + ")");
  }
}

}  // namespace detail

/// Reads DBoW2's YAML vocabulary from the bytes of a gzipped file (.yml.gz). It is
/// decompressed here, bounded before anything is inflated by what its compressed bytes
/// can hold as a vocabulary (`max_vocabulary_gzip_ratio` times them, at least
/// `min_vocabulary_yaml_bound`, at most `max_vocabulary_yaml_bytes`), and the text gets
/// the same checks as plain YAML before OpenCV parses it: OpenCV would decompress it
/// while parsing, past every check of the text.
inline BinaryVocabularyTree import_dbow2_yaml_gz(std::string_view compressed, const std::string& name = "<memory>") {
  const std::string source = "DBoW2 YAML vocabulary '" + name + "'";
  if (compressed.size() < 18) detail::bad_vocabulary(source, "too short to be gzip");
  const std::uint64_t bound = std::clamp(max_vocabulary_gzip_ratio * static_cast<std::uint64_t>(compressed.size()),
                                         min_vocabulary_yaml_bound, max_vocabulary_yaml_bytes);
  const std::string limit = bound == max_vocabulary_yaml_bytes
                                ? std::string("the limit")
                                : "the limit for " + std::to_string(compressed.size()) + " compressed bytes: " +
                                      std::to_string(max_vocabulary_gzip_ratio) +
                                      " times them, at least 16 MiB; gzip shrinks a vocabulary's text far less";
  return import_dbow2_yaml(detail::gunzip_bounded(compressed, bound, source, limit), name);
}

/// Reads FBoW's binary vocabulary (fbow::Vocabulary::saveToFile; binary descriptors).
inline BinaryVocabularyTree import_fbow(std::string_view bytes, const std::string& name = "<memory>") {
  const std::string source = "FBoW vocabulary '" + name + "'";
  detail::BinaryReader r(bytes, source);
  if (bytes.size() < 128) r.corrupt("too short (" + std::to_string(bytes.size()) + " bytes) to be an FBoW vocabulary");
  if (r.u64("signature") != 55824124U) r.corrupt("not an FBoW vocabulary (wrong signature)");
  const std::string_view desc_name = r.bytes(52, "descriptor name");  // char[50] + padding
  (void)desc_name;
  const std::uint32_t alignment = r.u32("alignment");
  const std::uint32_t nblocks = r.u32("block count");
  (void)r.u32("padding");
  const std::uint64_t slot = r.u64("descriptor slot bytes");
  const std::uint64_t block_bytes = r.u64("block bytes");
  const std::uint64_t feature_off = r.u64("descriptor offset");
  const std::uint64_t child_off = r.u64("child offset");
  const std::uint64_t total = r.u64("total size");
  const std::int32_t type = r.i32("descriptor type");
  const std::int32_t desc_size = r.i32("descriptor size");
  const std::uint32_t k = r.u32("k");
  (void)r.u32("padding");
  (void)alignment;
  if (type != CV_8UC1)
    r.corrupt("holds descriptors of type " + std::to_string(type) + "; vmap imports binary (CV_8UC1) FBoW vocabularies");
  if (desc_size < 1 || desc_size > BinaryVocabularyTree::max_cols) r.corrupt("descriptor size " + std::to_string(desc_size) + " outside 1..4096");
  if (k < 2 || k > static_cast<std::uint32_t>(BinaryVocabularyTree::max_branching)) r.corrupt("k = " + std::to_string(k) + " outside 2..4096");
  if (nblocks < 1) r.corrupt("no blocks");
  if (slot < static_cast<std::uint64_t>(desc_size) || slot > 8192) r.corrupt("descriptor slot of " + std::to_string(slot) + " bytes");
  if (feature_off < 8 || feature_off > block_bytes || child_off > block_bytes || k * slot > block_bytes - feature_off ||
      child_off < feature_off + k * slot || k * 8 > block_bytes - child_off)
    r.corrupt("the block layout does not fit its " + std::to_string(block_bytes) + " bytes");
  if (total / block_bytes != nblocks || total % block_bytes != 0 || total != r.remaining())
    r.corrupt("the data size (" + std::to_string(r.remaining()) + " bytes) is not " + std::to_string(nblocks) + " blocks of " +
              std::to_string(block_bytes) + " bytes (header total " + std::to_string(total) + ")");
  const std::string_view data = r.rest();
  auto u32_at = [&](std::uint64_t off) {
    std::uint32_t v = 0;
    for (int i = 0; i < 4; ++i) v |= static_cast<std::uint32_t>(static_cast<unsigned char>(data[off + static_cast<std::uint64_t>(i)])) << (8 * i);
    return v;
  };
  // node 0 the root (block 0's owner); every child entry becomes a node; a non-leaf
  // child owns the block it points to, which is visited once.
  detail::ForeignTree t;
  t.k = static_cast<int>(k);
  t.cols = desc_size;
  t.weighting = BowWeighting::fbow;
  t.children.assign(1, {});
  t.descriptor.assign(1, nullptr);
  t.word.assign(1, -1);
  std::vector<std::uint8_t> block_seen(nblocks, 0);
  std::deque<std::pair<std::uint32_t, std::uint32_t>> queue{{0U, 0U}};  // (block, owner node)
  block_seen[0] = 1;
  std::vector<std::pair<std::uint32_t, float>> word_weights;
  while (!queue.empty()) {
    const auto [b, owner] = queue.front();
    queue.pop_front();
    const std::uint64_t base = static_cast<std::uint64_t>(b) * block_bytes;
    const std::uint32_t count = u32_at(base) & 0xFFFFU;
    if (count < 1 || count > k) r.corrupt("block " + std::to_string(b) + " has " + std::to_string(count) + " children (k = " + std::to_string(k) + ")");
    for (std::uint32_t c = 0; c < count; ++c) {
      const auto node = static_cast<std::uint32_t>(t.children.size());
      t.children[owner].push_back(node);
      t.children.emplace_back();
      t.descriptor.push_back(reinterpret_cast<const std::uint8_t*>(data.data() + base + feature_off + c * slot));
      const std::uint32_t link = u32_at(base + child_off + 8ULL * c);
      if ((link & 0x80000000U) != 0) {
        const std::uint32_t word = link & 0x7FFFFFFFU;
        float w = 0.0f;
        std::memcpy(&w, data.data() + base + child_off + 8ULL * c + 4, 4);
        detail::f32_from_little_endian(&w, 1);
        t.word.push_back(word);
        word_weights.emplace_back(word, w);
      } else {
        if (link >= nblocks || block_seen[link] != 0)
          r.corrupt("block " + std::to_string(b) + " links to block " + std::to_string(link) + ", which is missing or reached twice");
        block_seen[link] = 1;
        t.word.push_back(-1);
        queue.emplace_back(link, node);
      }
    }
  }
  t.weight.assign(word_weights.size(), -1.0f);
  for (const auto& [word, w] : word_weights) {
    if (word >= t.weight.size() || t.weight[word] != -1.0f)
      r.corrupt("word ids are not 0.." + std::to_string(t.weight.size() - 1) + " each once (word " + std::to_string(word) + ")");
    t.weight[word] = w;
  }
  return detail::to_vmap_tree(t, source);
}

/// The vocabulary in ORB-SLAM2/3's text format (what ORBvoc.txt holds), readable by
/// ORB-SLAM2's TemplatedVocabulary::loadFromTextFile and by import_orbslam_text. Words
/// are numbered there by line, so the lines follow the tree in the order that keeps the
/// vocabulary's word ids: breadth-first (vmap's numbering) or DBoW2's (a node's children,
/// then each child's subtree in turn; a vocabulary read from DBoW2 or ORB-SLAM). Weights
/// get 6 significant digits, as ORB-SLAM2 writes them.
inline std::string orbslam_text(const BinaryVocabularyTree& v) {
  detail::check(!v.empty(), "orbslam_text: the vocabulary is empty");
  const BowWeighting w = v.weighting();
  detail::check(w != BowWeighting::fbow, "orbslam_text: an FBoW-weighted vocabulary has no DBoW2 scoring to write");
  const int scoring = w == BowWeighting::tf_idf_l1 || w == BowWeighting::idf_l1 ? 0 : 1;
  const int weighting = w == BowWeighting::tf_idf_l1 || w == BowWeighting::tf_idf_l2 ? 0 : 2;
  // node order: DBoW2's if it numbers the words as they are (then a vocabulary read
  // from ORBvoc.txt is written back line for line), else breadth-first
  std::vector<std::uint32_t> order{0};
  order.reserve(v.nodes());
  std::vector<std::uint32_t> stack{0};  // nodes whose children are still to be written
  while (!stack.empty()) {
    const std::uint32_t n = stack.back();
    stack.pop_back();
    const std::uint32_t first = v.first_child_or_word(n);
    for (std::uint32_t c = 0; c < v.child_count(n); ++c) order.push_back(first + c);
    for (std::uint32_t c = v.child_count(n); c-- > 0;)
      if (v.child_count(first + c) > 0) stack.push_back(first + c);
  }
  auto numbers_words = [&] {
    std::uint32_t next = 0;
    for (std::uint32_t n : order)
      if (v.child_count(n) == 0 && v.first_child_or_word(n) != next++) return false;
    return true;
  };
  if (!numbers_words()) {
    for (std::uint32_t i = 0; i < v.nodes(); ++i) order[i] = i;
    if (!numbers_words()) detail::fail("orbslam_text: the vocabulary's word ids follow neither DBoW2's nor breadth-first node order");
  }
  std::vector<std::uint32_t> line_of(v.nodes(), 0), parent(v.nodes(), 0);
  for (std::uint32_t i = 0; i < order.size(); ++i) line_of[order[i]] = i;
  for (std::uint32_t n = 0; n < v.nodes(); ++n)
    for (std::uint32_t c = 0; c < v.child_count(n); ++c) parent[v.first_child_or_word(n) + c] = n;
  std::string out = std::to_string(v.branching()) + " " + std::to_string(v.depth()) + "  " + std::to_string(scoring) + " " +
                    std::to_string(weighting) + "\n";
  out.reserve(out.size() + v.nodes() * static_cast<std::size_t>(4 * v.descriptor_cols() + 16));
  char buf[32];
  for (std::size_t i = 1; i < order.size(); ++i) {
    const std::uint32_t n = order[i];
    const bool leaf = v.child_count(n) == 0;
    out += std::to_string(line_of[parent[n]]);
    out += leaf ? " 1 " : " 0 ";
    const std::uint8_t* d = v.centre(n);
    for (int b = 0; b < v.descriptor_cols(); ++b) {
      out += std::to_string(d[b]);
      out += ' ';
    }
    out += ' ';
    const double weight = leaf ? static_cast<double>(v.idf()[v.first_child_or_word(n)]) : 0.0;
    std::snprintf(buf, sizeof buf, "%g", weight);  // ostream's default: 6 significant digits
    out += buf;
    out += '\n';
  }
  return out;
}

/// The vocabulary in FBoW's binary format (fbow::Vocabulary::readFromFile reads it):
/// one block per inner node in breadth-first order, 8-byte alignment as FBoW's own
/// files; leaf entries carry the word id and its weight. FBoW's transform sums the
/// weights and L2-normalises whatever the vocabulary's own weighting.
inline std::string fbow_bytes(const BinaryVocabularyTree& v) {
  detail::check(!v.empty(), "fbow_bytes: the vocabulary is empty");
  const std::uint64_t k = static_cast<std::uint64_t>(v.branching());
  const std::uint64_t slot = (static_cast<std::uint64_t>(v.descriptor_cols()) + 7) / 8 * 8;
  const std::uint64_t feature_off = 8, child_off = feature_off + k * slot;
  const std::uint64_t block = (child_off + 8 * k + 7) / 8 * 8;
  std::vector<std::uint32_t> block_of(v.nodes(), 0);
  std::uint32_t blocks = 0;
  for (std::uint32_t n = 0; n < v.nodes(); ++n)
    if (v.child_count(n) > 0) block_of[n] = blocks++;
  detail::BinaryWriter w;
  w.u64(55824124U);
  std::string name(52, '\0');
  name.replace(0, 3, "orb");
  w.bytes(name);
  w.u32(8);
  w.u32(blocks);
  w.u32(0);
  w.u64(slot);
  w.u64(block);
  w.u64(feature_off);
  w.u64(child_off);
  w.u64(block * blocks);
  w.i32(CV_8UC1);
  w.i32(v.descriptor_cols());
  w.u32(static_cast<std::uint32_t>(k));
  w.u32(0);
  std::string data(static_cast<std::size_t>(block * blocks), '\0');
  auto put32 = [&](std::uint64_t at, std::uint32_t x) {
    for (int i = 0; i < 4; ++i) data[static_cast<std::size_t>(at) + static_cast<std::size_t>(i)] = static_cast<char>((x >> (8 * i)) & 0xFFU);
  };
  std::vector<std::uint32_t> parent(v.nodes(), 0);
  for (std::uint32_t n = 0; n < v.nodes(); ++n) {
    const std::uint32_t count = v.child_count(n);
    if (count == 0) continue;
    const std::uint64_t base = static_cast<std::uint64_t>(block_of[n]) * block;
    put32(base, count | (1U << 16));  // N, and the flag FBoW always writes as 1
    put32(base + 4, parent[n]);
    const std::uint32_t first = v.first_child_or_word(n);
    for (std::uint32_t c = 0; c < count; ++c) {
      const std::uint32_t child = first + c;
      parent[child] = n;
      std::memcpy(data.data() + base + feature_off + c * slot, v.centre(child), static_cast<std::size_t>(v.descriptor_cols()));
      const bool leaf = v.child_count(child) == 0;
      put32(base + child_off + 8ULL * c, leaf ? (v.first_child_or_word(child) | 0x80000000U) : block_of[child]);
      put32(base + child_off + 8ULL * c + 4, leaf ? std::bit_cast<std::uint32_t>(v.idf()[v.first_child_or_word(child)]) : 0U);
    }
  }
  return std::move(w).take() + data;
}

/// The format of a vocabulary file, from its first bytes (`head`, at least the first 128
/// if the file has them) and its name (.gz: gzipped YAML).
inline VocabularyFormat sniff_vocabulary_format(std::string_view head, const std::filesystem::path& path) {
  if (head.substr(0, 8) == BinaryVocabularyTree::file_magic()) return VocabularyFormat::vmap;
  if (head.size() >= 8) {
    std::uint64_t sig = 0;
    for (int i = 0; i < 8; ++i) sig |= static_cast<std::uint64_t>(static_cast<unsigned char>(head[static_cast<std::size_t>(i)])) << (8 * i);
    if (sig == 55824124U) return VocabularyFormat::fbow;
  }
  if (head.size() >= 2 && static_cast<unsigned char>(head[0]) == 0x1F && static_cast<unsigned char>(head[1]) == 0x8B)
    return VocabularyFormat::dbow2_yaml;  // gzip: FileStorage's .yml.gz
  if (head.substr(0, 5) == "%YAML" || head.find("vocabulary:") != std::string_view::npos) return VocabularyFormat::dbow2_yaml;
  std::size_t p = 0;
  long a = 0;
  if (detail::next_int(head, p, a)) return VocabularyFormat::orbslam_text;
  detail::fail(ErrorKind::corrupt, "'" + path.string() + "' is not a vocabulary file vmap knows (vmap, ORB-SLAM2/3 ORBvoc.txt, DBoW2 YAML "
                                     "(.yml, .yml.gz) or FBoW binary)");
}

/// Reads a binary vocabulary of any known format from a file; anything else is a
/// vmap::Error naming the file.
inline BinaryVocabularyTree import_binary_vocabulary(const std::filesystem::path& path) {
  std::ifstream in = detail::open_regular_file(path, "vocabulary file");
  const auto size = std::filesystem::file_size(path);
  if (size > max_vocabulary_file_bytes)
    detail::fail("'" + path.string() + "' is " + std::to_string(size) + " bytes, larger than a vocabulary file can be (" +
                 std::to_string(max_vocabulary_file_bytes) + ")");
  std::string head(static_cast<std::size_t>(std::min<std::uintmax_t>(size, 4096)), '\0');
  if (!in.read(head.data(), static_cast<std::streamsize>(head.size()))) detail::fail(ErrorKind::io, "reading '" + path.string() + "' failed");
  in.close();
  const auto whole = [&] { return detail::read_whole_file(path, "vocabulary file", max_vocabulary_file_bytes); };
  switch (sniff_vocabulary_format(head, path)) {
    case VocabularyFormat::vmap:
      return BinaryVocabularyTree::load(path);
    case VocabularyFormat::fbow:
      return import_fbow(whole(), path.string());
    case VocabularyFormat::orbslam_text:
      return import_orbslam_text(whole(), path.string());
    case VocabularyFormat::dbow2_yaml:
      break;
  }
  if (static_cast<unsigned char>(head[0]) != 0x1F) return import_dbow2_yaml(whole(), path.string());
  return import_dbow2_yaml_gz(whole(), path.string());
}

}  // namespace vmap
