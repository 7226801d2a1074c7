// Map files: round trip, and a fuzz-style test that feeds thousands of mutated files.
#include "support/map_file.hpp"
#include "support/shared_data.hpp"

#include <vmap/keyframe/map_io.hpp>

#include <doctest/doctest.h>

#include <opencv2/core.hpp>

#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>

namespace {

/// A small map with every field set: ORB-like binary features, float features, an
/// 8-bit grey image, a colour image, a key without image, pairs with F.
vmap::VisualMap sample_map() {
  cv::RNG rng(7);
  vmap::VisualMap m;
  m.frames = 50;
  for (int k = 0; k < 3; ++k) {
    vmap::KeyImage key;
    key.frame_index = static_cast<std::size_t>(10 * k + 3);
    key.name = "frame_" + std::to_string(k) + ".png";
    key.timestamp = 1305031229.5 + k;
    const int n = 6 + k;
    for (int i = 0; i < n; ++i)
      key.features.keypoints.emplace_back(cv::Point2f(rng.uniform(0.f, 32.f), rng.uniform(0.f, 24.f)),
                                          rng.uniform(1.f, 9.f), rng.uniform(0.f, 360.f), rng.uniform(0.f, 1.f),
                                          i % 4, -1);
    if (k == 1) {
      key.features.descriptors.create(n, 4, CV_32FC1);
      rng.fill(key.features.descriptors, cv::RNG::UNIFORM, -1.0, 1.0);
      key.features.norm = cv::NORM_L2;
    } else {
      key.features.descriptors.create(n, 32, CV_8UC1);
      rng.fill(key.features.descriptors, cv::RNG::UNIFORM, 0, 256);
    }
    key.features.image_size = {32, 24};
    if (k == 0) {
      key.image.create(24, 32, CV_8UC1);
      rng.fill(key.image, cv::RNG::UNIFORM, 0, 256);
    } else if (k == 1) {
      key.image.create(12, 16, CV_8UC3);
      rng.fill(key.image, cv::RNG::UNIFORM, 0, 256);
    }
    m.keys.push_back(key);
  }
  for (int p = 0; p < 2; ++p) {
    vmap::KeyPair pair;
    pair.status = p == 0 ? vmap::VerificationStatus::verified : vmap::VerificationStatus::too_few_matches;
    pair.fundamental = p == 0 ? cv::Matx33d(0, -1e-4, 0.02, 1e-4, 0, -0.03, -0.02, 0.03, 1) : cv::Matx33d::zeros();
    pair.matches = 40 + p;
    pair.inliers = p == 0 ? 33 : 0;
    pair.similarity = p == 0 ? 0.33 : 0.0;
    m.pairs.push_back(pair);
  }
  return m;
}

bool same_mat(const cv::Mat& a, const cv::Mat& b) {
  if (a.empty() || b.empty()) return a.empty() && b.empty();
  return a.size() == b.size() && a.type() == b.type() && cv::norm(a, b, cv::NORM_INF) == 0;
}

void check_equal(const vmap::VisualMap& a, const vmap::VisualMap& b) {
  CHECK(a.frames == b.frames);
  REQUIRE(a.keys.size() == b.keys.size());
  for (std::size_t k = 0; k < a.keys.size(); ++k) {
    const auto& x = a.keys[k];
    const auto& y = b.keys[k];
    CHECK(x.frame_index == y.frame_index);
    CHECK(x.name == y.name);
    CHECK(x.timestamp == y.timestamp);
    CHECK(x.features.norm == y.features.norm);
    CHECK(x.features.image_size == y.features.image_size);
    REQUIRE(x.features.keypoints.size() == y.features.keypoints.size());
    for (std::size_t i = 0; i < x.features.keypoints.size(); ++i) {
      const auto &p = x.features.keypoints[i], &q = y.features.keypoints[i];
      CHECK(p.pt == q.pt);
      CHECK(p.size == q.size);
      CHECK(p.angle == q.angle);
      CHECK(p.response == q.response);
      CHECK(p.octave == q.octave);
      CHECK(p.class_id == q.class_id);
    }
    CHECK(same_mat(x.features.descriptors, y.features.descriptors));
    CHECK(same_mat(x.image, y.image));
  }
  REQUIRE(a.pairs.size() == b.pairs.size());
  for (std::size_t p = 0; p < a.pairs.size(); ++p) {
    CHECK(a.pairs[p].status == b.pairs[p].status);
    CHECK(a.pairs[p].fundamental == b.pairs[p].fundamental);
    CHECK(a.pairs[p].matches == b.pairs[p].matches);
    CHECK(a.pairs[p].inliers == b.pairs[p].inliers);
    CHECK(a.pairs[p].similarity == b.pairs[p].similarity);
  }
}

using vmap::test::with_valid_checksum;

std::string mutate(const std::string& in, cv::RNG& rng) {
  std::string s = in;
  const int kind = rng.uniform(0, 5);
  const auto pos = [&] { return static_cast<std::size_t>(rng.uniform(0, static_cast<int>(s.size()))); };
  switch (kind) {
    case 0:  // flip a few bits
      for (int k = rng.uniform(1, 4); k > 0; --k) s[pos()] ^= static_cast<char>(1 << rng.uniform(0, 8));
      break;
    case 1:  // truncate
      s.resize(pos());
      break;
    case 2:  // insert random bytes
      s.insert(pos(), std::string(static_cast<std::size_t>(rng.uniform(1, 9)), static_cast<char>(rng.uniform(0, 256))));
      break;
    case 3: {  // a 32-bit field set to a large or negative value
      const std::size_t p = pos();
      const std::uint32_t v = rng.uniform(0, 2) ? 0xFFFFFFFFU : 0x7FFFFFF0U;
      for (int i = 0; i < 4 && p + static_cast<std::size_t>(i) < s.size(); ++i)
        s[p + static_cast<std::size_t>(i)] = static_cast<char>((v >> (8 * i)) & 0xFF);
      break;
    }
    default:  // erase a span
      s.erase(pos(), static_cast<std::size_t>(rng.uniform(1, 16)));
      break;
  }
  return s;
}

}  // namespace

TEST_CASE("map file: save -> load round trip") {
  const auto dir = vmap::test::scratch_dir("keyframe_map_io");
  const auto m = sample_map();
  vmap::save_map(m, dir / "map.vmap");
  CHECK_FALSE(std::filesystem::exists(dir / "map.vmap.vmap-tmp"));
  const auto back = vmap::load_map(dir / "map.vmap");
  check_equal(m, back);
  CHECK(back.quality() == doctest::Approx(m.quality()));

  // Overwriting keeps a valid file; an empty map also round-trips.
  vmap::save_map(vmap::VisualMap{}, dir / "map.vmap");
  const auto empty = vmap::load_map(dir / "map.vmap");
  CHECK(empty.keys.empty());
  CHECK(empty.frames == 0);
}

TEST_CASE("map file: wrong magic, version, size and missing files are Errors") {
  const std::string good = vmap::serialize_map(sample_map());
  CHECK_THROWS_WITH_AS(vmap::deserialize_map(""), doctest::Contains("too short"), vmap::Error);
  std::string magic = good;
  magic[0] = 'X';
  CHECK_THROWS_WITH_AS(vmap::deserialize_map(magic), doctest::Contains("magic"), vmap::Error);
  std::string version = good;
  version[8] = 2;
  CHECK_THROWS_WITH_AS(vmap::deserialize_map(version), doctest::Contains("version 2"), vmap::Error);
  CHECK_THROWS_WITH_AS(vmap::deserialize_map(good.substr(0, good.size() - 1)), doctest::Contains("truncated"),
                       vmap::Error);
  std::string flipped = good;
  flipped[good.size() / 2] ^= 1;
  CHECK_THROWS_WITH_AS(vmap::deserialize_map(flipped), doctest::Contains("checksum"), vmap::Error);
  CHECK_THROWS_WITH_AS(vmap::load_map("/nonexistent/vmap/map.vmap"), doctest::Contains("/nonexistent/vmap/map.vmap"),
                       vmap::Error);
  // A hostile count with a valid checksum: two billion key images in a small file.
  std::string hostile = good;
  for (int i = 0; i < 4; ++i) hostile[24 + 8 + static_cast<std::size_t>(i)] = static_cast<char>(0x7F);
  CHECK_THROWS_WITH_AS(vmap::deserialize_map(with_valid_checksum(hostile)), doctest::Contains("key image count"),
                       vmap::Error);
}

TEST_CASE("map file: thousands of mutated files give vmap::Error, never a crash") {
  const std::string good = vmap::serialize_map(sample_map());
  cv::RNG rng(2024);
  int damaged_rejected = 0, hostile_rejected = 0, hostile_parsed = 0;
  constexpr int rounds = 3000;
  for (int i = 0; i < rounds; ++i) {
    const std::string bad = mutate(good, rng);
    if (bad == good) continue;
    // Damaged: the checksum or the size catches every change.
    try {
      (void)vmap::deserialize_map(bad);
    } catch (const vmap::Error&) {
      ++damaged_rejected;
    }
    // Hostile: the header is recomputed so the parser sees the mutated payload. A flip in
    // a descriptor byte still makes a valid map; anything else must be an Error.
    try {
      (void)vmap::deserialize_map(with_valid_checksum(bad));
      ++hostile_parsed;
    } catch (const vmap::Error&) {
      ++hostile_rejected;
    }
  }
  CHECK(damaged_rejected >= rounds - 5);  // all but mutations that changed nothing
  CHECK(hostile_rejected + hostile_parsed >= rounds - 5);
  CHECK(hostile_rejected > rounds / 2);
  MESSAGE("hostile mutations rejected: " << hostile_rejected << ", still valid maps: " << hostile_parsed);
}
