// Vocabulary trees: clusters recovered, determinism, TF-IDF and the scores against
// hand-computed values, bad input.

#include <vmap/place/bow.hpp>
#include <vmap/place/vocabulary.hpp>

#include "place_support.hpp"

#include <doctest/doctest.h>

#include <cmath>
#include <set>
#include <vector>

template class vmap::VocabularyTree<vmap::HammingTraits>;
template class vmap::VocabularyTree<vmap::L2Traits>;

using vmap::test::HierarchicalClusters;

TEST_CASE_TEMPLATE("every descriptor of a synthetic cluster lands in its cluster's word", Tree, vmap::BinaryVocabularyTree,
                   vmap::FloatVocabularyTree) {
  constexpr bool binary = std::is_same_v<Tree, vmap::BinaryVocabularyTree>;
  // 4 groups of 4 leaf clusters, 40 descriptors each, spread over 8 "images"
  const HierarchicalClusters data = binary ? vmap::test::binary_clusters(4, 4, 40, 11) : vmap::test::float_clusters(4, 4, 40, 11);
  const vmap::VocabularyTreeOptions o{.branching = 4, .depth = 2, .iterations = 10, .seed = 5};
  const Tree v = Tree::learn(data.images, o);
  REQUIRE(v.size() == 16);
  CHECK(v.branching() == 4);
  CHECK(v.depth() == 2);
  CHECK(v.nodes() == 1 + 4 + 16);
  CHECK(v.descriptor_type() == (binary ? CV_8UC1 : CV_32FC1));
  CHECK(v.descriptor_cols() == data.all.cols);

  const auto words = v.assign(data.all);
  REQUIRE(words.size() == data.cluster.size());
  std::vector<std::set<std::uint32_t>> words_of_cluster(16);
  for (std::size_t i = 0; i < words.size(); ++i) words_of_cluster[static_cast<std::size_t>(data.cluster[i])].insert(words[i]);
  std::set<std::uint32_t> used;
  for (const auto& s : words_of_cluster) {
    CHECK(s.size() == 1);  // one word per cluster
    used.insert(*s.begin());
  }
  CHECK(used.size() == 16);  // and a different word for each

  // The word of a descriptor is its nearest leaf along the tree; for these separated
  // clusters it is also the nearest word of all (brute force over words()).
  const cv::Mat centres = v.words();
  REQUIRE(centres.rows == 16);
  for (int r = 0; r < data.all.rows; r += 37) {
    double best = 1e300;
    int arg = -1;
    for (int w = 0; w < centres.rows; ++w) {
      const double d = cv::norm(data.all.row(r), centres.row(w), binary ? cv::NORM_HAMMING : cv::NORM_L2);
      if (d < best) {
        best = d;
        arg = w;
      }
    }
    CHECK(static_cast<int>(words[static_cast<std::size_t>(r)]) == arg);
  }

  // deterministic for a seed
  const Tree again = Tree::learn(data.images, o);
  CHECK(cv::norm(again.words(), centres, cv::NORM_L1) == 0.0);
  CHECK(again.assign(data.all) == words);
  CHECK(again.idf() == v.idf());
  CHECK(again.serialize() == v.serialize());

  // every cluster occurs in every image (the images are interleaved), so idf = log(8/8) = 0
  // and the bag of words is empty; learn_idf on images holding one group each gives
  // idf = log(4 / 1) for every word.
  for (float f : v.idf()) CHECK(f == doctest::Approx(0.0));
  std::vector<cv::Mat> by_group(4);
  for (int r = 0; r < data.all.rows; ++r) by_group[static_cast<std::size_t>(data.cluster[static_cast<std::size_t>(r)] / 4)].push_back(data.all.row(r));
  Tree g = v;
  g.learn_idf(by_group);
  for (float f : g.idf()) CHECK(f == doctest::Approx(std::log(4.0)));
  const vmap::BowVector b = g.transform(by_group[1]);
  REQUIRE(b.size() == 4);  // the 4 words of group 1, 40 descriptors each: 1/4 each
  for (const auto& e : b) CHECK(e.weight == doctest::Approx(0.25));
  CHECK(g.transform(cv::Mat()).empty());
}

TEST_CASE("a node with fewer descriptors than the branching becomes a leaf") {
  const HierarchicalClusters data = vmap::test::binary_clusters(2, 1, 3, 4);  // 2 clusters of 3
  const auto v = vmap::BinaryVocabularyTree::learn(data.images, {.branching = 4, .depth = 3, .seed = 1});
  // root (6 >= 4) splits; each child holds fewer than 4 descriptors: leaves
  CHECK(v.nodes() == 1 + v.size());
  CHECK(v.size() >= 2);
  CHECK(v.size() <= 4);

  // equal descriptors cannot be split: clusters of them stay one word
  cv::Mat same(20, 32, CV_8UC1, cv::Scalar(7));
  cv::Mat other(20, 32, CV_8UC1, cv::Scalar(200));
  const auto two = vmap::BinaryVocabularyTree::learn({same, other}, {.branching = 3, .depth = 4, .seed = 1});
  CHECK(two.size() == 2);
  CHECK(two.nodes() == 3);
  CHECK(two.assign(same) == std::vector<std::uint32_t>(20, two.assign(same)[0]));
  CHECK(two.assign(same)[0] != two.assign(other)[0]);
}

TEST_CASE("a tree given node by node: words are the leaves in node order") {
  // root -> {1, 2}; 1 -> {3, 4}; 2 a leaf. Words: node 2 = 0, node 3 = 1, node 4 = 2.
  cv::Mat c = (cv::Mat_<float>(5, 2) << 0, 0,  //
               0, 0,                            // node 1, left
               10, 0,                           // node 2, right
               -1, 1,                           // node 3
               -1, -1);                         // node 4
  const auto v = vmap::FloatVocabularyTree::from_tree(2, 2, {2, 2, 0, 0, 0}, c, {1.0f, 2.0f, 3.0f});
  CHECK(v.size() == 3);
  CHECK(v.nodes() == 5);
  const cv::Mat d = (cv::Mat_<float>(4, 2) << 9, 0.5f, -0.5f, 3, 0.5f, -3, 12, -1);
  CHECK(v.assign(d) == std::vector<std::uint32_t>{0, 1, 2, 0});
  CHECK(cv::norm(v.words(), c.rowRange(2, 5), cv::NORM_L1) == 0.0);
  const vmap::BowVector b = v.transform(d);  // raw (2 x 1, 1 x 2, 1 x 3) / 7
  REQUIRE(b.size() == 3);
  CHECK(b.entries[0].weight == doctest::Approx(2.0 / 7.0));
  CHECK(b.entries[2].weight == doctest::Approx(3.0 / 7.0));
  using F = vmap::FloatVocabularyTree;
  CHECK_THROWS_AS(F::from_tree(2, 1, {2, 2, 0, 0, 0}, c, {1, 2, 3}), vmap::Error);     // deeper than depth 1
  CHECK_THROWS_AS(F::from_tree(2, 2, {2, 2, 0, 0}, c.rowRange(0, 4), {1, 2, 3}), vmap::Error);  // counts claim 5 nodes
  CHECK_THROWS_AS(F::from_tree(2, 2, {2, 0, 0, 2, 0}, c, {1, 2, 3}), vmap::Error);     // node 3 claims nodes before it
  CHECK_THROWS_AS(F::from_tree(2, 2, {3, 0, 0, 0, 0}, c, {1, 2, 3}), vmap::Error);     // above the branching
  CHECK_THROWS_AS(F::from_tree(2, 2, {2, 2, 0, 0, 0}, c.rowRange(0, 4), {1, 2, 3}), vmap::Error);  // a centre missing
  CHECK_THROWS_AS(F::from_tree(2, 2, {2, 2, 0, 0, 0}, c, {1, 2}), vmap::Error);        // an idf missing
  cv::Mat nan = c.clone();
  nan.at<float>(3, 0) = NAN;
  CHECK_THROWS_AS(F::from_tree(2, 2, {2, 2, 0, 0, 0}, nan, {1, 2, 3}), vmap::Error);
}

TEST_CASE("TF-IDF weights and transform against hand-computed values") {
  cv::Mat words(3, 32, CV_8UC1);
  cv::randu(words, 0, 256);
  auto v = vmap::BinaryVocabularyTree::from_words(words);
  REQUIRE(v.size() == 3);
  CHECK(v.depth() == 1);
  CHECK(v.branching() == 3);
  CHECK(cv::norm(v.words(), words, cv::NORM_L1) == 0.0);
  auto rows = [&](std::initializer_list<int> r) {
    cv::Mat m;
    for (int i : r) m.push_back(words.row(i));
    return m;
  };
  // idf 1 (from_words): term frequencies only
  vmap::BowVector b = v.transform(rows({0, 0, 1, 2}));
  REQUIRE(b.size() == 3);
  CHECK(b.entries[0].word == 0);
  CHECK(b.entries[0].weight == doctest::Approx(0.5));
  CHECK(b.entries[1].weight == doctest::Approx(0.25));
  CHECK(b.entries[2].weight == doctest::Approx(0.25));

  v.set_idf({0.5f, 1.0f, 2.0f});
  // raw weights: 2 x 0.5, 1 x 1, 1 x 2 = (1, 1, 2), L1-normalised (0.25, 0.25, 0.5)
  b = v.transform(rows({0, 0, 1, 2}));
  REQUIRE(b.size() == 3);
  CHECK(b.entries[0].weight == doctest::Approx(0.25));
  CHECK(b.entries[1].weight == doctest::Approx(0.25));
  CHECK(b.entries[2].weight == doctest::Approx(0.5));
  CHECK(b.l1_norm() == doctest::Approx(1.0));

  // learn_idf: word 0 in all 3 images (idf 0, left out of vectors), words 1 and 2 in one
  v.learn_idf({rows({0, 1}), rows({0}), rows({0, 2, 2}), cv::Mat()});
  REQUIRE(v.idf().size() == 3);
  CHECK(v.idf()[0] == 0.0f);
  CHECK(v.idf()[1] == doctest::Approx(std::log(3.0)));
  CHECK(v.idf()[2] == doctest::Approx(std::log(3.0)));
  b = v.transform(rows({0, 0, 0, 1, 2, 2, 2}));
  REQUIRE(b.size() == 2);
  CHECK(b.entries[0].word == 1);
  CHECK(b.entries[0].weight == doctest::Approx(0.25));
  CHECK(b.entries[1].word == 2);
  CHECK(b.entries[1].weight == doctest::Approx(0.75));

  CHECK_THROWS_AS(v.set_idf({1.0f, 2.0f}), vmap::Error);
  CHECK_THROWS_AS(v.set_idf({1.0f, -2.0f, 1.0f}), vmap::Error);
  CHECK_THROWS_AS(v.set_idf({1.0f, NAN, 1.0f}), vmap::Error);
}

TEST_CASE("bow_score: L1 (DBoW2), L2 and cosine against hand-computed values") {
  using vmap::BowScoring;
  const vmap::BowVector v{{{1, 0.5f}, {3, 0.5f}}};
  const vmap::BowVector w{{{1, 0.25f}, {2, 0.25f}, {3, 0.5f}}};
  // L1: 1 - 0.5 (|0.5 - 0.25| + |0 - 0.25| + |0.5 - 0.5|) = 0.75
  CHECK(vmap::bow_score(v, w) == doctest::Approx(0.75));
  CHECK(vmap::bow_score(w, v) == doctest::Approx(0.75));
  // scaling does not change a score (each vector is normalised)
  const vmap::BowVector v2{{{1, 3.0f}, {3, 3.0f}}};
  CHECK(vmap::bow_score(v2, w) == doctest::Approx(0.75));
  // cosine: <v, w> / (|v| |w|) = 0.375 / (sqrt(0.5) sqrt(0.375)) = sqrt(0.75)
  CHECK(vmap::bow_score(v, w, BowScoring::cosine) == doctest::Approx(std::sqrt(0.75)));
  // L2 (DBoW2): 1 - sqrt(1 - cosine)
  CHECK(vmap::bow_score(v, w, BowScoring::l2) == doctest::Approx(1.0 - std::sqrt(1.0 - std::sqrt(0.75))));
  for (auto s : {BowScoring::l1, BowScoring::l2, BowScoring::cosine}) {
    CHECK(vmap::bow_score(v, v, s) == doctest::Approx(1.0));
    CHECK(vmap::bow_score(v, vmap::BowVector{{{2, 1.0f}}}, s) == 0.0);  // no shared word
    CHECK(vmap::bow_score(v, vmap::BowVector{}, s) == 0.0);
  }
  // invalid vectors
  CHECK_THROWS_AS((void)vmap::bow_score(vmap::BowVector{{{3, 0.5f}, {1, 0.5f}}}, w), vmap::Error);   // unsorted
  CHECK_THROWS_AS((void)vmap::bow_score(vmap::BowVector{{{1, 0.5f}, {1, 0.5f}}}, w), vmap::Error);   // repeated
  CHECK_THROWS_AS((void)vmap::bow_score(vmap::BowVector{{{1, -0.5f}}}, w), vmap::Error);             // negative
  CHECK(std::string(vmap::to_string(BowScoring::cosine)) == "cosine");
}

TEST_CASE("vocabularies refuse bad input with an Error naming it") {
  const HierarchicalClusters data = vmap::test::binary_clusters(2, 2, 10, 3);
  using B = vmap::BinaryVocabularyTree;
  CHECK_THROWS_AS(B::learn(data.images, {.branching = 1}), vmap::Error);
  CHECK_THROWS_AS(B::learn(data.images, {.depth = 0}), vmap::Error);
  CHECK_THROWS_AS(B::learn(data.images, {.depth = 65}), vmap::Error);
  CHECK_THROWS_AS(B::learn(data.images, {.iterations = 0}), vmap::Error);
  CHECK_THROWS_AS(B::learn(data.images, {.branching = 8, .max_descriptors = 4}), vmap::Error);
  CHECK_THROWS_AS(B::learn({}, {}), vmap::Error);
  CHECK_THROWS_AS(B::learn({data.all.rowRange(0, 3)}, {.branching = 4}), vmap::Error);  // too few descriptors
  CHECK_THROWS_AS(B::learn({cv::Mat(10, 8, CV_32FC1, cv::Scalar(1))}, {.branching = 2}), vmap::Error);
  CHECK_THROWS_AS(vmap::FloatVocabularyTree::learn({data.all}, {.branching = 2}), vmap::Error);
  CHECK_THROWS_AS(B::learn({data.all, data.all.colRange(0, 16).clone()}, {.branching = 2}), vmap::Error);

  const B v = B::learn(data.images, {.branching = 2, .depth = 2});
  const std::string msg = vmap::test::error_of([&] { (void)v.assign(cv::Mat(3, 16, CV_8UC1, cv::Scalar(0))); });
  CHECK(msg.find("32 columns") != std::string::npos);
  CHECK_THROWS_AS((void)v.assign(cv::Mat(3, 32, CV_32FC1, cv::Scalar(0))), vmap::Error);
  CHECK(v.assign(cv::Mat()).empty());
  CHECK_THROWS_AS((void)B{}.assign(data.all), vmap::Error);  // empty vocabulary
  CHECK_THROWS_AS((void)B{}.transform(data.all), vmap::Error);
  CHECK_THROWS_AS(B::from_words(cv::Mat(1, 32, CV_8UC1, cv::Scalar(0))), vmap::Error);
  CHECK_THROWS_AS(B::from_words(cv::Mat(3, 32, CV_32FC1, cv::Scalar(0))), vmap::Error);
  CHECK(B{}.size() == 0);
  CHECK(B{}.empty());
  CHECK(v.memory_bytes() >= v.nodes() * 32);
}

TEST_CASE("AnyVocabulary learns, transforms and loads either kind") {
  const auto bin = vmap::test::binary_clusters(2, 2, 10, 3);
  const auto flt = vmap::test::float_clusters(2, 2, 10, 3);
  const vmap::AnyVocabulary a = vmap::AnyVocabulary::learn(bin.images, {.branching = 2, .depth = 2});
  const vmap::AnyVocabulary f = vmap::AnyVocabulary::learn(flt.images, {.branching = 2, .depth = 2});
  REQUIRE(a.binary() != nullptr);
  CHECK(a.floating() == nullptr);
  REQUIRE(f.floating() != nullptr);
  CHECK(a.descriptor_type() == CV_8UC1);
  CHECK(f.descriptor_type() == CV_32FC1);
  CHECK(f.descriptor_cols() == flt.all.cols);
  CHECK(a.size() == 4);
  CHECK(f.size() == 4);
  CHECK(a.transform(bin.images[0]) == a.binary()->transform(bin.images[0]));
  CHECK(f.assign(flt.all) == f.floating()->assign(flt.all));
  CHECK_THROWS_AS((void)a.transform(flt.all), vmap::Error);

  const auto dir = vmap::test::scratch_dir("place_any");
  a.save(dir / "b.voc");
  f.save(dir / "f.voc");
  const auto a2 = vmap::AnyVocabulary::load(dir / "b.voc");
  const auto f2 = vmap::AnyVocabulary::load(dir / "f.voc");
  REQUIRE(a2.binary() != nullptr);
  REQUIRE(f2.floating() != nullptr);
  CHECK(a2.binary()->serialize() == a.binary()->serialize());
  CHECK(f2.floating()->serialize() == f.floating()->serialize());
  CHECK_THROWS_AS((void)vmap::BinaryVocabularyTree::load(dir / "f.voc"), vmap::Error);  // the other kind
  CHECK_THROWS_AS((void)vmap::AnyVocabulary::load(dir / "missing.voc"), vmap::Error);
  CHECK_THROWS_AS(vmap::AnyVocabulary::learn({cv::Mat(3, 3, CV_16UC1)}, {}), vmap::Error);
}
