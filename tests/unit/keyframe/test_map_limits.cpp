// Map files as untrusted input: a key image whose PNG header claims a huge
// size is refused before it is decoded, a folder or device given as the map is named,
// and concurrent saves to one path always leave a loadable map.
#include <vmap/keyframe/map_io.hpp>

#include "support/errors.hpp"
#include "support/map_file.hpp"
#include "support/shared_data.hpp"

#include <doctest/doctest.h>

#include <atomic>
#include <cstring>
#include <string>
#include <thread>
#include <vector>

using vmap::test::error_of;

namespace {

vmap::VisualMap map_with_image(int frames) {
  vmap::VisualMap m;
  m.frames = static_cast<std::size_t>(frames);
  vmap::KeyImage k;
  k.frame_index = 0;
  k.name = "k0.png";
  k.image.create(48, 64, CV_8UC1);
  cv::randu(k.image, 0, 256);
  k.features.image_size = {64, 48};
  m.keys.push_back(k);
  return m;
}

using vmap::test::with_valid_checksum;

void put_le32(std::string& b, std::size_t at, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) b[at + static_cast<std::size_t>(i)] = static_cast<char>((v >> (8 * i)) & 0xFF);
}
void put_be32(std::string& b, std::size_t at, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) b[at + static_cast<std::size_t>(i)] = static_cast<char>((v >> (8 * (3 - i))) & 0xFF);
}

}  // namespace

TEST_CASE("map file: a key image claiming 16384x16384 pixels is refused before decoding") {
  std::string bytes = vmap::serialize_map(map_with_image(3));
  const auto png = bytes.find("\x89PNG");
  REQUIRE(png != std::string::npos);
  // The record before the PNG: i32 rows, i32 cols, i32 type, u32 length.
  put_le32(bytes, png - 16, 16384);
  put_le32(bytes, png - 12, 16384);
  put_be32(bytes, png + 16, 16384);  // IHDR width
  put_be32(bytes, png + 20, 16384);  // IHDR height
  const auto e = error_of([&] { (void)vmap::deserialize_map(with_valid_checksum(bytes), "bomb.vmap"); });
  CHECK(e.find("bomb.vmap") != std::string::npos);
  CHECK(e.find("16384x16384 pixels is above the limit of 67108864") != std::string::npos);

  // The limits are options: a 64x48 key image against a 1000-pixel limit.
  const std::string good = vmap::serialize_map(map_with_image(3));
  CHECK(vmap::deserialize_map(good).keys.at(0).image.size() == cv::Size(64, 48));
  CHECK(error_of([&] { (void)vmap::deserialize_map(good, "m", {.max_image_pixels = 1000}); }).find("MapLoadOptions::max_image_pixels") !=
        std::string::npos);
  CHECK(error_of([&] { (void)vmap::deserialize_map(good, "m", {.max_total_image_pixels = 3000}); })
            .find("max_total_image_pixels") != std::string::npos);
}

TEST_CASE("load_map: a folder, a device or a FIFO is an error naming it") {
  const auto dir = vmap::test::scratch_dir("map_limits_inputs");
  CHECK(error_of([&] { (void)vmap::load_map(dir); }).find("map file '" + dir.string() + "' is a folder") != std::string::npos);
  CHECK(error_of([] { (void)vmap::load_map("/dev/zero"); }).find("'/dev/zero' is not a regular file") != std::string::npos);
}

TEST_CASE("map file: concurrent saves to one path always leave a loadable map") {
  const auto dir = vmap::test::scratch_dir("map_limits_race");
  const auto path = dir / "map.vmap";
  std::vector<vmap::VisualMap> maps;
  for (int w = 0; w < 4; ++w) maps.push_back(map_with_image(10 + w));
  std::atomic<int> failures{0};
  std::atomic<bool> stop{false};
  vmap::save_map(maps[0], path);
  // A reader loads the file while the writers replace it: it must always parse.
  std::thread reader([&] {
    while (!stop)
      try {
        (void)vmap::load_map(path);
      } catch (...) {
        ++failures;
      }
  });
  std::vector<std::thread> writers;
  for (int w = 0; w < 4; ++w)
    writers.emplace_back([&, w] {
      try {
        for (int k = 0; k < 10; ++k) vmap::save_map(maps[static_cast<std::size_t>(w)], path);
      } catch (...) {
        ++failures;
      }
    });
  for (auto& t : writers) t.join();
  stop = true;
  reader.join();
  CHECK(failures == 0);
  const auto back = vmap::load_map(path);
  CHECK(back.frames >= 10);
  CHECK(back.frames <= 13);
}
