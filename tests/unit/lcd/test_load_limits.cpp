// The LCD loaders as untrusted input: a folder or device where a file is
// expected is an Error naming it; a tree file whose label bits would expand into far
// more memory than the file holds is refused before the tree is built.
#include <vmap/hooks/precomputed_detections.hpp>
#include <vmap/lcd/binary_tree.hpp>
#include <vmap/lcd/evaluation.hpp>

#include "support/errors.hpp"
#include "support/shared_data.hpp"

#include <doctest/doctest.h>

#include <random>
#include <string>

using vmap::test::error_of;

namespace {
bool contains(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }
}  // namespace

TEST_CASE("lcd loaders: folders and devices are errors naming the input") {
  const auto dir = vmap::test::scratch_dir("lcd_load_limits");
  using Tree = vmap::BinaryClassifiedTree<int>;
  CHECK(contains(error_of([&] { (void)Tree::load(dir); }), "tree file '" + dir.string() + "' is a folder"));
  CHECK(contains(error_of([&] { (void)vmap::LoopGroundTruth::load(dir); }),
                 "ground truth file '" + dir.string() + "' is a folder"));
  CHECK(contains(error_of([] { (void)vmap::LoopGroundTruth::load("/dev/zero"); }),
                 "ground truth file '/dev/zero' is not a regular file"));
  CHECK(contains(error_of([&] { (void)vmap::PrecomputedDetections::load(dir); }),
                 "detections file '" + dir.string() + "' is a folder"));
  CHECK(contains(error_of([] { (void)vmap::PrecomputedDetections::load("/dev/zero"); }), "not a regular file"));
}

TEST_CASE("tree file: distinct deep label vectors beyond the node limit are refused before building") {
  // 1100 ids at depth 4096 with random bits: ~4.5 M nodes (~270 MB) from a 4.5 MB file.
  std::mt19937 rng(13);
  const std::size_t depth = 4096, ids = 1100;
  std::string text = "vmap-binary-classified-tree 1\ndepth " + std::to_string(depth) + "\nids " + std::to_string(ids) + "\n";
  for (std::size_t k = 0; k < ids; ++k) {
    for (std::size_t i = 0; i < depth; ++i) text.push_back(static_cast<char>('0' + (rng() & 1U)));
    text += " " + std::to_string(k) + "\n";
  }
  const auto e = error_of([&] { (void)vmap::BinaryClassifiedTree<int>::from_text(text, "deep.tree"); });
  CHECK(contains(e, "deep.tree:2: the tree would need"));
  CHECK(contains(e, "more than the limit of 4194304"));

  // The same ids sharing one label vector need only depth + 1 nodes: accepted.
  std::string shared = "vmap-binary-classified-tree 1\ndepth 4096\nids 1100\n";
  const std::string bits(depth, '1');
  for (std::size_t k = 0; k < ids; ++k) shared += bits + " " + std::to_string(k) + "\n";
  const auto tree = vmap::BinaryClassifiedTree<int>::from_text(shared, "shared.tree");
  CHECK(tree.size() == ids);
  CHECK(tree.candidates(vmap::LabelVector(depth, 1), 1).size() == ids);
}
