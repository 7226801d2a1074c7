#pragma once

// The binary classified tree of LFM-LCD (Zhu et al., Sensors 2021, sec. 3.3): a binary
// trie of depth N, one level per kept label (large objects first). Each key frame is
// stored at the leaf its label vector leads to; a query returns the frames of its leaf
// and, when they are fewer than m, backtracks to the parent and takes its whole subtree,
// and so on up to the root.

#include <vmap/core/error.hpp>
#include <vmap/io/atomic_file.hpp>
#include <vmap/lcd/label_vector.hpp>

#include <algorithm>
#include <charconv>
#include <concepts>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <map>
#include <string>
#include <string_view>
#include <system_error>
#include <utility>
#include <vector>

namespace vmap {

/// A binary trie over label vectors of a fixed length N (the depth).
///
/// Costs: `insert` O(N + log size); `candidates` O(N + visited), where visited counts
/// the returned ids and the nodes of the subtrees they come from (at most N per returned
/// id, since empty branches are skipped); `erase` O(N + leaf size + log size).
///
/// Order of `candidates`: the query's leaf first (insertion order), then, per backtrack
/// step, the sibling subtree that step adds, each subtree walked with the 0-branch before
/// the 1-branch. So earlier ids share a longer label prefix with the query.
///
/// Thread safety: const members (`candidates`, `contains`, `size`, `to_text`, `save`)
/// only read, so any number of threads may call them concurrently on one tree.
/// `insert`, `erase` and `clear` modify it and need exclusive access: no other call may
/// run at the same time (guard with a std::shared_mutex, shared for queries and unique
/// for updates, when frames are inserted while other threads query).
template <std::totally_ordered Id>
  requires std::copyable<Id>
class BinaryClassifiedTree {
 public:
  /// Deepest tree `load` accepts; far more labels than any detector has classes.
  static constexpr std::size_t max_depth = 4096;
  /// Most nodes `from_text` / `load` build (4 Mi nodes, ~250 MB): 100 000 key frames
  /// with 40 labels need at most 4 M, and real label vectors share most prefixes.
  static constexpr std::uint64_t max_load_nodes = std::uint64_t{1} << 22;

  explicit BinaryClassifiedTree(std::size_t depth = 0) : depth_(depth) {
    detail::check(depth <= max_depth, [&] {
      return "BinaryClassifiedTree: depth " + std::to_string(depth) + " exceeds " + std::to_string(max_depth);
    });
    nodes_.emplace_back();
  }

  [[nodiscard]] std::size_t depth() const noexcept { return depth_; }
  [[nodiscard]] std::size_t size() const noexcept { return where_.size(); }
  [[nodiscard]] bool empty() const noexcept { return where_.empty(); }
  [[nodiscard]] bool contains(const Id& id) const { return where_.find(id) != where_.end(); }

  /// Stores `id` at the leaf of `vector`. A vector of the wrong length or with values
  /// other than 0/1, or an id already in the tree, is an Error.
  void insert(const LabelVector& vector, const Id& id) {
    check_vector(vector, "insert");
    detail::check(!contains(id), "BinaryClassifiedTree::insert: the id is already in the tree");
    std::int32_t node = 0;
    ++nodes_[0].count;
    for (std::size_t level = 0; level < depth_; ++level) {
      const auto bit = vector[level];
      std::int32_t next = nodes_[static_cast<std::size_t>(node)].child[bit];
      if (next < 0) {
        next = static_cast<std::int32_t>(nodes_.size());
        Node n;
        n.parent = node;
        nodes_.push_back(std::move(n));
        nodes_[static_cast<std::size_t>(node)].child[bit] = next;
      }
      node = next;
      ++nodes_[static_cast<std::size_t>(node)].count;
    }
    nodes_[static_cast<std::size_t>(node)].ids.push_back(id);
    where_.emplace(id, node);
  }

  /// Removes `id`; returns false when it was not in the tree. Emptied nodes stay (they
  /// are skipped by queries and reused by later inserts).
  bool erase(const Id& id) {
    const auto it = where_.find(id);
    if (it == where_.end()) return false;
    std::int32_t node = it->second;
    auto& ids = nodes_[static_cast<std::size_t>(node)].ids;
    ids.erase(std::find(ids.begin(), ids.end(), id));
    for (; node >= 0; node = nodes_[static_cast<std::size_t>(node)].parent) --nodes_[static_cast<std::size_t>(node)].count;
    where_.erase(it);
    return true;
  }

  void clear() {
    nodes_.assign(1, Node{});
    where_.clear();
  }

  /// The loop candidates for a query vector: the ids of its leaf; while fewer than
  /// `min_candidates`, backtrack one level up and take that node's whole subtree, until
  /// enough or the root (then every id). `min_candidates` 0 returns the leaf alone.
  [[nodiscard]] std::vector<Id> candidates(const LabelVector& vector, std::size_t min_candidates) const {
    check_vector(vector, "candidates");
    std::vector<Id> out;
    // The deepest existing non-empty node on the query's path: if the leaf itself is
    // empty, backtracking from it would reach this node's subtree first anyway.
    std::int32_t node = 0;
    std::size_t level = 0;
    for (; level < depth_; ++level) {
      const std::int32_t next = nodes_[static_cast<std::size_t>(node)].child[vector[level]];
      if (next < 0 || nodes_[static_cast<std::size_t>(next)].count == 0) break;
      node = next;
    }
    if (level < depth_ && min_candidates == 0) return out;  // the query's own leaf is empty
    collect(node, out);
    while (out.size() < min_candidates && node != 0) {
      const std::int32_t parent = nodes_[static_cast<std::size_t>(node)].parent;
      const Node& p = nodes_[static_cast<std::size_t>(parent)];
      const std::int32_t sibling = p.child[0] == node ? p.child[1] : p.child[0];
      if (sibling >= 0) collect(sibling, out);
      node = parent;
    }
    return out;
  }

  /// Text form: a header, then one `<bits> <id>` line per id, leaves in candidate order
  /// (so a loaded tree answers every query with the same ids in the same order).
  [[nodiscard]] std::string to_text() const
    requires std::integral<Id>
  {
    std::string out = "vmap-binary-classified-tree 1\ndepth " + std::to_string(depth_) + "\nids " +
                      std::to_string(size()) + "\n";
    std::string bits;
    write_subtree(0, bits, out);
    return out;
  }

  /// Writes `to_text()` atomically.
  void save(const std::filesystem::path& path) const
    requires std::integral<Id>
  {
    write_file_atomically(path, to_text());
  }

  /// Parses `to_text()` output; anything malformed is an Error naming `name` and the line.
  [[nodiscard]] static BinaryClassifiedTree from_text(std::string_view text, const std::string& name = "<tree>")
    requires std::integral<Id>
  {
    std::vector<std::string_view> lines;
    for (std::size_t pos = 0; pos < text.size();) {
      const std::size_t nl = text.find('\n', pos);
      const std::size_t end = nl == std::string_view::npos ? text.size() : nl;
      std::string_view l = text.substr(pos, end - pos);
      if (!l.empty() && l.back() == '\r') l.remove_suffix(1);
      lines.push_back(l);
      pos = end + 1;
    }
    const auto bad = [&](std::size_t line, const std::string& what) {
      detail::fail(name + ":" + std::to_string(line + 1) + ": " + what);
    };
    if (lines.size() < 3 || lines[0] != "vmap-binary-classified-tree 1")
      bad(0, "not a vmap binary classified tree (expected the header 'vmap-binary-classified-tree 1')");
    const auto number = [&](std::size_t line, std::string_view key) {
      std::string_view l = lines[line];
      if (l.substr(0, key.size() + 1) != std::string(key) + " ") bad(line, "expected '" + std::string(key) + " <n>'");
      l.remove_prefix(key.size() + 1);
      std::size_t v = 0;
      const auto [ptr, ec] = std::from_chars(l.data(), l.data() + l.size(), v);
      if (ec != std::errc() || ptr != l.data() + l.size()) bad(line, "'" + std::string(key) + "' is not a count");
      return v;
    };
    const std::size_t depth = number(1, "depth");
    if (depth > max_depth) bad(1, "depth " + std::to_string(depth) + " exceeds " + std::to_string(max_depth));
    const std::size_t count = number(2, "ids");
    // The count is checked against the lines present before anything is sized by it.
    std::size_t body = lines.size() - 3;
    while (body > 0 && lines[3 + body - 1].empty()) --body;
    if (count != body)
      bad(2, "says " + std::to_string(count) + " ids but " + std::to_string(body) + " lines follow (truncated?)");
    // The nodes the tree will need, counted exactly before any is allocated: one per
    // distinct prefix of the label bits (sorted bit strings share their common prefix).
    // A node costs ~60 bytes against one character of the file, so a hostile file of
    // long distinct bit strings is refused here instead of expanding 60-fold.
    std::uint64_t nodes = 1;
    {
      std::vector<std::string_view> bits;
      bits.reserve(count);
      for (std::size_t k = 0; k < count; ++k) bits.push_back(lines[3 + k].substr(0, lines[3 + k].find(' ')));
      std::sort(bits.begin(), bits.end());
      for (std::size_t k = 0; k < bits.size(); ++k) {
        std::size_t common = 0;
        if (k > 0)
          while (common < bits[k].size() && common < bits[k - 1].size() && bits[k][common] == bits[k - 1][common]) ++common;
        nodes += std::min(bits[k].size(), depth) - std::min(common, depth);
      }
      if (nodes > max_load_nodes)
        bad(1, "the tree would need " + std::to_string(nodes) + " nodes, more than the limit of " +
                   std::to_string(max_load_nodes));
    }
    BinaryClassifiedTree tree(depth);
    tree.nodes_.reserve(static_cast<std::size_t>(nodes));
    LabelVector v(depth);
    for (std::size_t k = 0; k < count; ++k) {
      const std::string_view l = lines[3 + k];
      const std::size_t space = l.find(' ');
      if (space == std::string_view::npos) bad(3 + k, "expected '<bits> <id>'");
      const std::string_view bits = l.substr(0, space);
      const std::string_view id_text = l.substr(space + 1);
      const std::string_view expected_bits = depth == 0 ? "-" : bits;
      if (bits.size() != std::max<std::size_t>(depth, 1) || bits != expected_bits)
        bad(3 + k, "the label bits must be " + std::to_string(depth) + " characters 0/1 ('-' for depth 0)");
      for (std::size_t i = 0; i < depth; ++i) {
        if (bits[i] != '0' && bits[i] != '1') bad(3 + k, "label bits must be 0 or 1");
        v[i] = bits[i] == '1' ? 1 : 0;
      }
      Id id{};
      const auto [ptr, ec] = std::from_chars(id_text.data(), id_text.data() + id_text.size(), id);
      if (ec != std::errc() || ptr != id_text.data() + id_text.size()) bad(3 + k, "the id is not an integer");
      if (tree.contains(id)) bad(3 + k, "id " + std::to_string(id) + " appears twice");
      tree.insert(v, id);
    }
    return tree;
  }

  /// Reads a file written by `save`.
  [[nodiscard]] static BinaryClassifiedTree load(const std::filesystem::path& path)
    requires std::integral<Id>
  {
    return from_text(read_text_file(path, "tree file"), path.string());
  }

 private:
  struct Node {
    std::int32_t child[2] = {-1, -1};
    std::int32_t parent = -1;
    std::size_t count = 0;  // ids in this subtree; 0 lets queries skip emptied branches
    std::vector<Id> ids;    // only at depth N
  };

  void check_vector(const LabelVector& vector, const char* where) const {
    if (vector.size() != depth_)
      detail::fail(std::string("BinaryClassifiedTree::") + where + ": label vector of length " +
                   std::to_string(vector.size()) + " given to a tree of depth " + std::to_string(depth_));
    for (auto c : vector)
      if (c > 1)
        detail::fail(std::string("BinaryClassifiedTree::") + where + ": label vector holds " + std::to_string(c) +
                     ", expected 0 or 1");
  }

  void collect(std::int32_t node, std::vector<Id>& out) const {
    const Node& n = nodes_[static_cast<std::size_t>(node)];
    if (n.count == 0) return;
    out.insert(out.end(), n.ids.begin(), n.ids.end());
    for (std::int32_t c : n.child)
      if (c >= 0) collect(c, out);
  }

  void write_subtree(std::int32_t node, std::string& bits, std::string& out) const
    requires std::integral<Id>
  {
    const Node& n = nodes_[static_cast<std::size_t>(node)];
    if (n.count == 0) return;
    for (const Id& id : n.ids) out += (bits.empty() ? std::string("-") : bits) + " " + std::to_string(id) + "\n";
    for (int b = 0; b < 2; ++b)
      if (n.child[b] >= 0) {
        bits.push_back(static_cast<char>('0' + b));
        write_subtree(n.child[b], bits, out);
        bits.pop_back();
      }
  }

  std::size_t depth_ = 0;
  std::vector<Node> nodes_;     // nodes_[0] is the root
  std::map<Id, std::int32_t> where_;  // id -> its leaf
};

}  // namespace vmap
