// Vocabulary file formats: files of the first vmap layout (tests/unit/place/data) still
// load to the same bags of words; the dispatched Hamming kernel equals the portable
// one; vocabularies written by ORB-SLAM2, DBoW2 and FBoW (../shared/data/vocabularies)
// give the bags of words those libraries computed, word for word; hostile files of
// each format are a vmap::Error naming the file.

#include <vmap/place/detail/hamming_rows.hpp>
#include <vmap/place/vocabulary.hpp>

#include "place_support.hpp"

#include <doctest/doctest.h>

#include <cstdio>
#include <fstream>
#include <map>
#include <random>
#include <sstream>
#include <string>
#include <vector>

namespace {

using Bows = std::map<std::string, vmap::BowVector>;

/// "KIND IMAGE WORD WEIGHT" or "IMAGE WORD WEIGHT" lines (kind filtered when given).
Bows read_bows(const std::filesystem::path& p, const std::string& kind = "") {
  std::ifstream in(p);
  REQUIRE(in);
  Bows out;
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream s(line);
    std::string k;
    if (!kind.empty()) {
      s >> k;
      if (k != kind) continue;
    }
    std::string image;
    std::uint32_t word = 0;
    double weight = 0.0;
    REQUIRE(static_cast<bool>(s >> image >> word >> weight));
    out[image].entries.push_back({word, static_cast<float>(weight)});
  }
  return out;
}

/// Binary descriptors "[KIND] IMAGE [ROW] HEX" by image.
std::map<std::string, cv::Mat> read_binary(const std::filesystem::path& p, bool with_kind) {
  std::ifstream in(p);
  REQUIRE(in);
  std::map<std::string, cv::Mat> out;
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream s(line);
    std::string kind, hex, image;
    int row = 0;
    if (with_kind) {
      s >> kind;
      if (kind != "binary") continue;
      s >> image >> hex;
    } else {
      s >> image >> row >> hex;
    }
    REQUIRE(hex.size() == 64);
    cv::Mat d(1, 32, CV_8UC1);
    for (int b = 0; b < 32; ++b) d.at<uchar>(0, b) = static_cast<uchar>(std::stoi(hex.substr(static_cast<std::size_t>(2 * b), 2), nullptr, 16));
    out[image].push_back(d);
  }
  return out;
}

std::map<std::string, cv::Mat> read_float(const std::filesystem::path& p) {
  std::ifstream in(p);
  std::map<std::string, cv::Mat> out;
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream s(line);
    std::string kind, image;
    s >> kind;
    if (kind != "float") continue;
    s >> image;
    cv::Mat d(1, 16, CV_32FC1);
    for (int c = 0; c < 16; ++c) s >> d.at<float>(0, c);
    out[image].push_back(d);
  }
  return out;
}

std::string file_bytes(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

/// Word ids exact, weights within `tolerance` (absolute).
void check_equal(const vmap::BowVector& got, const vmap::BowVector& want, double tolerance, const std::string& image) {
  INFO("image " << image);
  REQUIRE(got.size() == want.size());
  double worst = 0.0;
  for (std::size_t i = 0; i < got.size(); ++i) {
    CHECK(got.entries[i].word == want.entries[i].word);
    worst = std::max(worst, std::fabs(static_cast<double>(got.entries[i].weight) - static_cast<double>(want.entries[i].weight)));
  }
  CHECK(worst <= tolerance);
}

}  // namespace

TEST_CASE_TEMPLATE("files of the first layout load to the same bags of words, and again after saving", Tree,
                   vmap::BinaryVocabularyTree, vmap::FloatVocabularyTree) {
  constexpr bool binary = std::is_same_v<Tree, vmap::BinaryVocabularyTree>;
  const auto dir = vmap::test::source_dir() / "tests/unit/place/data";
  const auto file = dir / (binary ? "binary_k6L3.v1.vmapvoc" : "float_k4L2.v1.vmapvoc");
  const auto want = read_bows(dir / "v1_transforms.txt", binary ? "binary" : "float");
  const auto images = binary ? read_binary(dir / "v1_descriptors.txt", true) : read_float(dir / "v1_descriptors.txt");
  REQUIRE(images.size() == 3);
  const Tree v1 = Tree::load(file);
  CHECK(v1.weighting() == vmap::BowWeighting::tf_idf_l1);
  CHECK(vmap::AnyVocabulary::load(file).size() == v1.size());
  const auto again_dir = vmap::test::scratch_dir(binary ? "voc_v1_b" : "voc_v1_f");
  v1.save(again_dir / "v2.vmapvoc");
  const std::string v2_bytes = file_bytes(again_dir / "v2.vmapvoc");
  CHECK(static_cast<int>(v2_bytes[8]) == 2);
  const Tree v2 = Tree::load(again_dir / "v2.vmapvoc");
  CHECK(v2_bytes.size() < std::filesystem::file_size(file));  // one-byte child counts
  for (const auto& [image, d] : images) {
    CHECK(v1.transform(d) == want.at(image));  // float-exact: the weights were printed with %.9g
    CHECK(v2.transform(d) == want.at(image));
  }
  // a v1 file damaged anywhere behind its header is caught by its CRC-32
  std::string damaged = file_bytes(file);
  damaged[damaged.size() / 2] = static_cast<char>(damaged[damaged.size() / 2] ^ 1);
  CHECK_THROWS_WITH_AS((void)Tree::deserialize(damaged, "old.voc"), doctest::Contains("checksum"), vmap::Error);
}

TEST_CASE("the dispatched nearest-row Hamming kernel equals the portable one") {
  std::mt19937 rng(3);
  const auto best = vmap::detail::nearest_row_kernel();
  const auto portable = vmap::detail::nearest_row_kernel(true);
  for (std::size_t cols : {std::size_t{1}, std::size_t{7}, std::size_t{8}, std::size_t{31}, std::size_t{32}, std::size_t{61}, std::size_t{64}}) {
    for (std::uint32_t count = 1; count <= 21; ++count) {
      std::vector<std::uint8_t> rows(count * cols), q(cols);
      for (auto& b : rows) b = static_cast<std::uint8_t>(rng());
      for (auto& b : q) b = static_cast<std::uint8_t>(rng());
      if (count > 2) std::copy(rows.begin(), rows.begin() + static_cast<std::ptrdiff_t>(cols), rows.begin() + static_cast<std::ptrdiff_t>(2 * cols));  // a tie
      // the brute-force answer, first on ties
      std::uint32_t want = 0, want_d = ~0U;
      for (std::uint32_t r = 0; r < count; ++r) {
        std::uint32_t d = 0;
        for (std::size_t c = 0; c < cols; ++c) d += static_cast<std::uint32_t>(std::popcount(static_cast<unsigned>(q[c] ^ rows[r * cols + c])));
        if (d < want_d) {
          want_d = d;
          want = r;
        }
      }
      CHECK(best(q.data(), rows.data(), count, cols, cols) == want);
      CHECK(portable(q.data(), rows.data(), count, cols, cols) == want);
    }
  }
}

TEST_CASE("the fuzz seeds of the three foreign formats are valid vocabularies of the same tree") {
  const auto dir = vmap::test::source_dir() / "tests/fuzz/corpus";
  const auto text = vmap::import_orbslam_text(file_bytes(dir / "vocabulary_orbslam_text/k3L2.txt"), "t");
  const auto yml = vmap::import_dbow2_yaml(std::string_view(file_bytes(dir / "vocabulary_dbow2_yaml/k3L2.yml")), "y");
  const auto fbow = vmap::import_fbow(file_bytes(dir / "vocabulary_fbow/k3L2.fbow"), "f");
  CHECK(text.size() == 9);
  CHECK(text.nodes() == 13);
  CHECK(text.depth() == 2);
  CHECK(cv::norm(text.words(), yml.words(), cv::NORM_L1) == 0.0);
  CHECK(cv::norm(text.words(), fbow.words(), cv::NORM_L1) == 0.0);
  CHECK(text.idf() == yml.idf());
  CHECK(fbow.idf() == std::vector<float>(9, 1.0f));
  // the writers give files the readers take back unchanged
  const auto text_again = vmap::import_orbslam_text(vmap::orbslam_text(text), "t2");
  CHECK(cv::norm(text_again.words(), text.words(), cv::NORM_L1) == 0.0);
  CHECK(text_again.idf() == text.idf());
  const auto fbow_again = vmap::import_fbow(vmap::fbow_bytes(fbow), "f2");
  CHECK(fbow_again.serialize() == fbow.serialize());
}

TEST_SUITE("data") {
  TEST_CASE("ORB-SLAM2, DBoW2 and FBoW vocabularies give their libraries' bags of words") {
    const auto dir = vmap::test::data_path("vocabularies");
    const auto images = read_binary(dir / "test_orb1000_descriptors.txt", false);
    REQUIRE(images.size() == 5);
    const auto scratch = vmap::test::scratch_dir("voc_import");
    struct Case {
      const char* file;
      const char* reference;
      vmap::BowWeighting weighting;
      double tolerance;
    };
    // ORB-SLAM2's reference used the 6-digit weights of its text file (as vmap reads
    // them); DBoW2's full-precision ones, held by vmap as float.
    for (const Case& c : {Case{"orbslam2_k10L3.txt", "orbslam2_bow_reference.txt", vmap::BowWeighting::tf_idf_l1, 1e-6},
                          Case{"dbow2_k10L3.yml.gz", "dbow2_bow_reference.txt", vmap::BowWeighting::tf_idf_l1, 1e-6},
                          Case{"fbow_k10L3.fbow", "fbow_bow_reference.txt", vmap::BowWeighting::fbow, 0.0}}) {
      INFO(c.file);
      const auto want = read_bows(dir / c.reference);
      const vmap::AnyVocabulary v = vmap::AnyVocabulary::load(dir / c.file);
      REQUIRE(v.binary() != nullptr);
      CHECK(v.size() == 1000);  // no phantom word from the text file's final newline
      CHECK(v.branching() == 10);
      CHECK(v.weighting() == c.weighting);
      CHECK(v.scoring() == (c.weighting == vmap::BowWeighting::fbow ? vmap::BowScoring::l2 : vmap::BowScoring::l1));
      CHECK(v.binary()->nodes() == 1111);
      // converted to vmap's file and read back: the same vectors
      v.save(scratch / "converted.vmapvoc");
      const auto back = vmap::BinaryVocabularyTree::load(scratch / "converted.vmapvoc");
      for (const auto& [image, d] : images) {
        check_equal(v.transform(d), want.at(image), c.tolerance, image);
        CHECK(back.transform(d) == v.transform(d));
      }
    }
    // ORB-SLAM2's text and DBoW2's YAML hold the same tree: the same words
    const auto text = vmap::import_orbslam_text(file_bytes(dir / "orbslam2_k10L3.txt"), "t");
    const auto yml = vmap::AnyVocabulary::load(dir / "dbow2_k10L3.yml.gz");
    CHECK(cv::norm(text.words(), yml.binary()->words(), cv::NORM_L1) == 0.0);
  }

  TEST_CASE("hostile vocabulary files of the other formats are errors naming the file") {
    const auto dir = vmap::test::data_path("vocabularies");
    const std::string text = file_bytes(dir / "orbslam2_k10L3.txt");
    const std::string fbow = file_bytes(dir / "fbow_k10L3.fbow");
    std::mt19937 rng(5);
    int parsed = 0;
    auto attempt = [&](auto parse, const std::string& bytes) {
      try {
        (void)parse(bytes);
        ++parsed;
      } catch (const vmap::Error& e) {
        CHECK(std::string(e.what()).find("'bad'") != std::string::npos);
      }
    };
    auto text_parse = [](const std::string& b) { return vmap::import_orbslam_text(b, "bad"); };
    auto fbow_parse = [](const std::string& b) { return vmap::import_fbow(b, "bad"); };
    for (std::size_t n = 0; n < text.size(); n += 997) attempt(text_parse, text.substr(0, n));
    for (std::size_t n = 0; n < fbow.size(); n += 101) attempt(fbow_parse, fbow.substr(0, n));
    for (int m = 0; m < 300; ++m) {
      std::string t = text, f = fbow;
      t[rng() % t.size()] = "0123456789 .\n-x"[rng() % 16];
      for (int i = 0; i < 4; ++i) f[rng() % f.size()] = static_cast<char>(rng());
      attempt(text_parse, t);
      attempt(fbow_parse, f);
    }
    MESSAGE(parsed << " damaged files still parsed");
    // specific damage: a cycle between FBoW blocks, a parent after its child, k exceeded
    std::string cyc = fbow;
    const std::size_t block1_child0 = 128 + 408 + 328;
    cyc[block1_child0] = 1;  // block 1's first child points at block 1
    cyc[block1_child0 + 1] = cyc[block1_child0 + 2] = cyc[block1_child0 + 3] = 0;
    CHECK_THROWS_WITH_AS((void)vmap::import_fbow(cyc, "cyc"), doctest::Contains("reached twice"), vmap::Error);
    CHECK_THROWS_WITH_AS((void)vmap::import_orbslam_text("10 3  0 0\n5 1 1 2 3  0.5\n", "p"), doctest::Contains("not an earlier node"),
                         vmap::Error);
    CHECK_THROWS_WITH_AS((void)vmap::import_orbslam_text("2 3  0 0\n0 1 1  0.5\n0 1 2  0.5\n0 1 3  0.5\n", "k"),
                         doctest::Contains("more than k"), vmap::Error);
    CHECK_THROWS_WITH_AS((void)vmap::import_orbslam_text("10 3  2 0\n0 1 1  0.5\n", "chi"), doctest::Contains("CHI_SQUARE"), vmap::Error);
    CHECK_THROWS_WITH_AS((void)vmap::import_dbow2_yaml(std::string_view("%YAML:1.0\n" + std::string(100, '[')), "deep"),
                         doctest::Contains("nested"), vmap::Error);
    // OpenCV 4.6's parser never returns on a '-' at the top level after a document.
    CHECK_THROWS_WITH_AS((void)vmap::import_dbow2_yaml("%YAML:1.0\n---\nvocabulary:\n   k: 10\n----e\n", "dash"),
                         "DBoW2 YAML vocabulary 'dash': YAML line 5 starts with '-' at the "
                         "top level, where a key is expected (the file must be a map of keys)",
                         vmap::Error);
    CHECK_THROWS_AS((void)vmap::AnyVocabulary::load(dir), vmap::Error);  // a folder
  }
}
