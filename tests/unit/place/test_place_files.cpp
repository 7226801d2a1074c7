// Vocabulary and database files: round trips, and fuzzed files (every truncation,
// flipped bytes, wrong magic or version, mutated payloads behind a valid header) that
// must be a vmap::Error, never a crash.

#include <vmap/io/binary.hpp>
#include <vmap/place/database.hpp>
#include <vmap/place/vocabulary.hpp>

#include "place_support.hpp"

#include <doctest/doctest.h>

#include <random>
#include <string>

namespace {

/// The bytes with the header's size and checksum recomputed, so the parser sees the
/// mutated payload (CRC-32C for vocabulary files of version 2, else io/binary.hpp's CRC).
std::string reheader(std::string bytes) {
  if (bytes.size() < 24) return bytes;
  const std::string payload = bytes.substr(24);
  vmap::detail::BinaryWriter h;
  h.bytes(std::string_view(bytes.data(), 12));
  h.u64(payload.size());
  const bool castagnoli = bytes.compare(0, 8, "VMAPVOCB") == 0 && bytes[8] == 2;
  h.u32(castagnoli ? vmap::detail::crc32c(payload) : vmap::detail::crc32(payload));
  return std::move(h).take() + payload;
}

/// Feeds `parse` every truncation (up to `max_len` bytes), every single-byte flip of the
/// first bytes, wrong magic / version, and `mutations` random mutations of the payload
/// behind a recomputed header: each must parse or throw vmap::Error.
template <class Parse>
void fuzz(const std::string& good, Parse parse, int mutations) {
  for (std::size_t n = 0; n < good.size(); ++n) CHECK_THROWS_AS(parse(good.substr(0, n)), vmap::Error);
  for (std::size_t i = 0; i < good.size(); ++i) {
    std::string bad = good;
    bad[i] = static_cast<char>(bad[i] ^ 0x5A);
    CHECK_THROWS_AS(parse(bad), vmap::Error);  // the CRC, the size or the header catches it
  }
  std::string magic = good;
  magic[0] = 'X';
  CHECK_THROWS_WITH_AS(parse(magic), doctest::Contains("magic"), vmap::Error);
  std::string version = good;
  version[8] = 9;
  CHECK_THROWS_WITH_AS(parse(version), doctest::Contains("version"), vmap::Error);
  CHECK_THROWS_WITH_AS(parse(good + "x"), doctest::Contains("padded"), vmap::Error);

  std::mt19937 rng(7);
  int parsed = 0;
  for (int m = 0; m < mutations; ++m) {
    std::string bad = good;
    const int kind = static_cast<int>(rng() % 4);
    const std::size_t at = 24 + rng() % (good.size() - 24);
    if (kind == 0) {
      bad[at] = static_cast<char>(bad[at] ^ (1 << (rng() % 8)));
    } else if (kind == 1) {
      bad.resize(at);
    } else if (kind == 2) {  // a big count
      for (std::size_t i = at; i < std::min(bad.size(), at + 8); ++i) bad[i] = static_cast<char>(0xFF);
    } else {
      bad.insert(at, std::string(1 + rng() % 8, static_cast<char>(rng() & 0xFF)));
    }
    try {
      parse(reheader(bad));
      ++parsed;
    } catch (const vmap::Error&) {
    }
  }
  MESSAGE(parsed << " of " << mutations << " hostile mutations still parsed as valid files");
}

}  // namespace

TEST_CASE("the eight-bytes-a-step CRC-32 equals io/binary.hpp's") {
  std::mt19937 rng(1);
  std::string s;
  for (std::size_t n = 0; n < 300; ++n) {
    CHECK(vmap::detail::crc32_fast(s) == vmap::detail::crc32(s));
    s.push_back(static_cast<char>(rng() & 0xFF));
  }
  s.resize(1 << 20);
  for (auto& c : s) c = static_cast<char>(rng() & 0xFF);
  CHECK(vmap::detail::crc32_fast(s) == vmap::detail::crc32(s));
  CHECK(vmap::detail::crc32_fast("123456789") == 0xCBF43926U);  // the standard check value
}

TEST_CASE("CRC-32C: the hardware path equals the portable one") {
  std::mt19937 rng(2);
  std::string s;
  for (std::size_t n = 0; n < 300; ++n) {
    CHECK(vmap::detail::crc32c(s) == vmap::detail::crc32c(s, true));
    s.push_back(static_cast<char>(rng() & 0xFF));
  }
  // lengths around the three-stream block (3 x 4096 bytes) and its multiples
  s.resize(5 * 3 * 4096 + 77);
  for (auto& c : s) c = static_cast<char>(rng() & 0xFF);
  for (std::size_t n : {std::size_t{12287}, std::size_t{12288}, std::size_t{12289}, std::size_t{24576}, s.size()})
    CHECK(vmap::detail::crc32c(std::string_view(s).substr(0, n)) == vmap::detail::crc32c(std::string_view(s).substr(0, n), true));
  CHECK(vmap::detail::crc32c("123456789") == 0xE3069283U);  // the standard check value
  CHECK(vmap::detail::crc32c("123456789", true) == 0xE3069283U);
  MESSAGE("CRC-32C in hardware: " << (vmap::detail::crc32c_hardware_available() ? "yes" : "no"));
}

TEST_CASE_TEMPLATE("vocabulary files: round trip and fuzzing", Tree, vmap::BinaryVocabularyTree, vmap::FloatVocabularyTree) {
  constexpr bool binary = std::is_same_v<Tree, vmap::BinaryVocabularyTree>;
  const auto data = binary ? vmap::test::binary_clusters(3, 3, 6, 2) : vmap::test::float_clusters(3, 3, 6, 2);
  Tree v = Tree::learn(data.images, {.branching = 3, .depth = 2, .seed = 3});
  std::vector<float> idf(v.size());
  for (std::size_t i = 0; i < idf.size(); ++i) idf[i] = 0.25f * static_cast<float>(i + 1);
  v.set_idf(idf);  // distinct weights, so a round trip that mixed them up would show

  const auto dir = vmap::test::scratch_dir(binary ? "place_voc_b" : "place_voc_f");
  v.save(dir / "v.voc");
  const Tree back = Tree::load(dir / "v.voc");
  CHECK(back.size() == v.size());
  CHECK(back.nodes() == v.nodes());
  CHECK(back.branching() == v.branching());
  CHECK(back.depth() == v.depth());
  CHECK(back.idf() == v.idf());
  CHECK(cv::norm(back.words(), v.words(), cv::NORM_L1) == 0.0);
  CHECK(back.assign(data.all) == v.assign(data.all));
  CHECK(back.transform(data.images[2]) == v.transform(data.images[2]));
  CHECK(back.serialize() == v.serialize());
  CHECK(back.memory_bytes() == v.memory_bytes());
  CHECK_THROWS_AS((void)Tree::load(dir / "none.voc"), vmap::Error);
  CHECK_THROWS_AS(Tree{}.save(dir / "empty.voc"), vmap::Error);

  fuzz(v.serialize(), [](const std::string& b) { return Tree::deserialize(b, "fuzz"); }, 3000);
}

TEST_CASE("a vocabulary file whose counts do not form a tree is refused") {
  const auto data = vmap::test::binary_clusters(2, 2, 6, 2);
  const auto v = vmap::BinaryVocabularyTree::learn(data.images, {.branching = 2, .depth = 2, .seed = 3});
  REQUIRE(v.nodes() == 7);
  const std::string good = v.serialize();
  // one-byte child counts start after kind (1), cols (4), branching (4), depth (4),
  // weighting (1), count width (1), nodes (8)
  const std::size_t counts = 24 + 1 + 4 + 4 + 4 + 1 + 1 + 8;
  REQUIRE(good[counts - 9] == 1);
  auto with_count = [&](std::size_t node, std::uint32_t c) {
    std::string b = good;
    b[counts + node] = static_cast<char>(c);
    return reheader(b);
  };
  CHECK_THROWS_WITH_AS((void)vmap::BinaryVocabularyTree::deserialize(with_count(0, 0)), doctest::Contains("root"), vmap::Error);
  CHECK_THROWS_WITH_AS((void)vmap::BinaryVocabularyTree::deserialize(with_count(0, 3)), doctest::Contains("branching"), vmap::Error);
  CHECK_THROWS_AS((void)vmap::BinaryVocabularyTree::deserialize(with_count(6, 2)), vmap::Error);  // more nodes than stored
  CHECK_THROWS_AS((void)vmap::BinaryVocabularyTree::deserialize(with_count(1, 0)), vmap::Error);  // nodes nobody claims
  CHECK_THROWS_WITH_AS((void)vmap::BinaryVocabularyTree::deserialize(with_count(0, 0), "x.voc"), doctest::Contains("'x.voc'"),
                       vmap::Error);
  CHECK(vmap::BinaryVocabularyTree::deserialize(reheader(good)).serialize() == good);
}

TEST_CASE("database files: round trip and fuzzing") {
  std::mt19937 rng(3);
  vmap::PlaceDatabase<std::uint32_t> db(100, vmap::BowScoring::l2);
  std::vector<vmap::BowVector> bows;
  for (std::uint32_t i = 0; i < 30; ++i) {
    bows.push_back(vmap::test::random_bow(100, 1 + rng() % 12, rng));
    db.add(i * 3, bows.back());
  }
  db.erase(9);
  db.add(1000, vmap::BowVector{});
  const auto dir = vmap::test::scratch_dir("place_db");
  db.save(dir / "db.bin");
  const auto back = vmap::PlaceDatabase<std::uint32_t>::load(dir / "db.bin");
  CHECK(back.size() == db.size());
  CHECK(back.ids() == db.ids());
  CHECK(back.scoring() == vmap::BowScoring::l2);
  CHECK(back.words() == 100);
  for (auto id : db.ids()) CHECK(*back.bow(id) == *db.bow(id));
  for (const auto& q : bows) CHECK(back.query(q, 7) == db.query(q, 7));
  CHECK(back.serialize() == db.serialize());

  // signed ids keep their sign
  vmap::PlaceDatabase<int> s;
  s.add(-4, bows[0]);
  s.add(2, bows[1]);
  const auto s2 = vmap::PlaceDatabase<int>::deserialize(s.serialize());
  CHECK(s2.ids() == std::vector<int>{-4, 2});
  // a 64-bit id that does not fit 32 bits is refused by a 32-bit database
  vmap::PlaceDatabase<std::uint64_t> big;
  big.add(std::uint64_t{1} << 40, bows[0]);
  CHECK_THROWS_WITH_AS((void)vmap::PlaceDatabase<std::uint32_t>::deserialize(big.serialize()), doctest::Contains("id type"),
                       vmap::Error);

  fuzz(db.serialize(), [](const std::string& b) { return vmap::PlaceDatabase<std::uint32_t>::deserialize(b, "fuzz"); }, 3000);
  CHECK_THROWS_AS((void)vmap::PlaceDatabase<std::uint32_t>::load(dir / "none.bin"), vmap::Error);
  // a vocabulary is not a database
  const auto data = vmap::test::binary_clusters(2, 2, 6, 2);
  const auto v = vmap::BinaryVocabularyTree::learn(data.images, {.branching = 2, .depth = 2});
  CHECK_THROWS_WITH_AS((void)vmap::PlaceDatabase<std::uint32_t>::deserialize(v.serialize()), doctest::Contains("magic"),
                       vmap::Error);
}
