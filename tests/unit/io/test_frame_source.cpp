// Frame sources on files made by the test: folders, lists, TUM lists, videos, and the
// errors a user meets (missing paths, empty folders, corrupt frames).
#include <vmap/io/atomic_file.hpp>
#include <vmap/io/detail/natural_order.hpp>
#include <vmap/io/frame_source.hpp>

#include "support/images.hpp"
#include "support/shared_data.hpp"

#include <doctest/doctest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>

#include <fstream>
#include <string>
#include <vector>

namespace fs = std::filesystem;

namespace {

using vmap::test::numbered_image;
using vmap::test::write_bytes;

std::vector<std::size_t> indices(vmap::FrameSource& s) {
  std::vector<std::size_t> out;
  while (auto f = s.next()) out.push_back(f->index);
  return out;
}

}  // namespace

TEST_CASE("natural sort orders digit runs by value") {
  std::vector<std::string> names = {"img10.png", "img2.png", "img1.png", "img02.png", "a.png", "img1b.png", "img100.png"};
  std::sort(names.begin(), names.end(), vmap::detail::natural_less);
  const std::vector<std::string> expected = {"a.png", "img1.png", "img1b.png", "img2.png", "img02.png", "img10.png",
                                             "img100.png"};
  CHECK(names == expected);
  CHECK_FALSE(vmap::detail::natural_less("x5", "x5"));
}

TEST_CASE("image folder: natural order, start/end/stride, resize, grey") {
  const auto dir = vmap::test::scratch_dir("folder");
  for (int k = 0; k < 12; ++k) cv::imwrite((dir / ("f" + std::to_string(k) + ".png")).string(), numbered_image(k, 11));
  write_bytes(dir / "notes.txt", "not an image");

  auto all = vmap::FrameSource::open(dir);
  CHECK(all.kind() == vmap::SourceKind::image_folder);
  CHECK(all.total() == std::optional<std::size_t>(12));
  std::vector<int> pixel;
  while (auto f = all.next()) pixel.push_back(f->image.at<std::uint8_t>(0, 0));
  CHECK(pixel == std::vector<int>{0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11});  // f10 after f9

  auto some = vmap::FrameSource::open(dir, {.start = 2, .end = 11, .stride = 3});
  CHECK(indices(some) == std::vector<std::size_t>{2, 5, 8});

  auto small = vmap::FrameSource::open(dir, {.end = 1, .resize = {32, 24}});
  auto f = small.next();
  REQUIRE(f);
  CHECK(f->image.size() == cv::Size(32, 24));
  CHECK(f->name == "f0.png");
}

TEST_CASE("list files: plain paths relative to the list, and TUM rgb.txt") {
  const auto dir = vmap::test::scratch_dir("lists");
  fs::create_directories(dir / "rgb");
  for (int k = 0; k < 4; ++k) cv::imwrite((dir / "rgb" / (std::to_string(k) + ".png")).string(), numbered_image(k, 11));

  write_bytes(dir / "plain.txt", "# my frames\nrgb/3.png\n\nrgb/1.png\n" + (dir / "rgb" / "2.png").string() + "\n");
  auto plain = vmap::FrameSource::open(dir / "plain.txt");
  CHECK(plain.kind() == vmap::SourceKind::image_list);
  std::vector<int> pixel;
  while (auto f = plain.next()) pixel.push_back(f->image.at<std::uint8_t>(0, 0));
  CHECK(pixel == std::vector<int>{3, 1, 2});

  write_bytes(dir / "rgb.txt", "# color images\n# timestamp filename\n100.5 rgb/0.png\n100.25 rgb/1.png\n101 rgb/2.png\n");
  auto tum = vmap::FrameSource::open(dir / "rgb.txt", {.grey = true});
  CHECK(tum.kind() == vmap::SourceKind::tum_rgb);
  auto f = tum.next();
  REQUIRE(f);
  CHECK(f->timestamp == 100.5);
  CHECK(f->image.type() == CV_8UC1);
  f = tum.next();
  REQUIRE(f);
  CHECK(f->timestamp == 100.25);  // file order, not timestamp order
  CHECK(f->time_ns == 100250000000LL);
  CHECK(f->image.at<std::uint8_t>(0, 0) == 1);
  CHECK(tum.times_ns() == std::vector<std::int64_t>{100500000000LL, 100250000000LL, 101000000000LL});
}

TEST_CASE("a corrupt or missing frame inside a sequence is reported and skipped") {
  const auto dir = vmap::test::scratch_dir("corrupt");
  for (int k = 0; k < 5; ++k) cv::imwrite((dir / (std::to_string(k) + ".png")).string(), numbered_image(k, 11));
  write_bytes(dir / "2.png", "this is not a PNG");
  std::vector<std::string> reported;
  auto s = vmap::FrameSource::open(dir, {.on_skip = [&](const vmap::SkippedFrame& sk) { reported.push_back(sk.name); }});
  CHECK(indices(s) == std::vector<std::size_t>{0, 1, 3, 4});
  REQUIRE(s.skipped().size() == 1);
  CHECK(s.skipped()[0].index == 2);
  CHECK(s.skipped()[0].reason == "cannot be decoded as an image");
  REQUIRE(reported.size() == 1);
  CHECK(reported[0].find("2.png") != std::string::npos);

  write_bytes(dir / "list.txt", "0.png\nmissing.png\n1.png\n");
  auto l = vmap::FrameSource::open(dir / "list.txt");
  CHECK(indices(l) == std::vector<std::size_t>{0, 2});
  REQUIRE(l.skipped().size() == 1);
  CHECK(l.skipped()[0].reason == "file does not exist");
}

TEST_CASE("frame source errors name the input") {
  const auto dir = vmap::test::scratch_dir("errors");
  CHECK_THROWS_WITH_AS(vmap::FrameSource::open(dir / "nope.mp4"), doctest::Contains("nope.mp4' does not exist"),
                       vmap::Error);
  fs::create_directories(dir / "empty");
  write_bytes(dir / "empty" / "readme.md", "no images here");
  CHECK_THROWS_WITH_AS(vmap::FrameSource::open(dir / "empty"), doctest::Contains("contains no image"), vmap::Error);
  write_bytes(dir / "blank.txt", "# only a comment\n\n");
  CHECK_THROWS_WITH_AS(vmap::FrameSource::open(dir / "blank.txt"), doctest::Contains("names no image"), vmap::Error);
  write_bytes(dir / "bogus.avi", "");
  CHECK_THROWS_WITH_AS(vmap::FrameSource::open(dir / "bogus.avi"), doctest::Contains("bogus.avi"), vmap::Error);
  write_bytes(dir / "all_bad.txt", "x.png\ny.png\n");
  auto bad = vmap::FrameSource::open(dir / "all_bad.txt");
  CHECK_THROWS_WITH_AS((void)bad.next(), doctest::Contains("no frame of"), vmap::Error);
  CHECK_THROWS_WITH_AS(vmap::FrameSource::open(dir / "all_bad.txt", {.stride = 0}), doctest::Contains("stride"),
                       vmap::Error);
  CHECK_THROWS_WITH_AS(vmap::FrameSource::open(dir / "all_bad.txt", {.start = 5, .end = 5}), doctest::Contains("start"),
                       vmap::Error);
  CHECK_THROWS_WITH_AS(vmap::FrameSource::open(dir / "all_bad.txt", {.resize = {10, 0}}), doctest::Contains("resize"),
                       vmap::Error);
}

TEST_CASE("video files: frames, stride and an empty video") {
  const auto dir = vmap::test::scratch_dir("video");
  const auto path = dir / "clip.avi";
  {
    cv::VideoWriter w(path.string(), cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 10.0, cv::Size(64, 48), true);
    REQUIRE_MESSAGE(w.isOpened(), "OpenCV cannot write MJPG video here");
    for (int k = 0; k < 10; ++k) {
      cv::Mat bgr;
      cv::cvtColor(numbered_image(k, 11), bgr, cv::COLOR_GRAY2BGR);
      w.write(bgr);
    }
  }
  auto all = vmap::FrameSource::open(path);
  CHECK(all.kind() == vmap::SourceKind::video);
  CHECK(indices(all) == std::vector<std::size_t>{0, 1, 2, 3, 4, 5, 6, 7, 8, 9});
  auto some = vmap::FrameSource::open(path, {.start = 1, .end = 8, .stride = 3, .grey = true});
  auto f = some.next();
  REQUIRE(f);
  CHECK(f->index == 1);
  CHECK(f->image.type() == CV_8UC1);
  CHECK(f->name == "clip.avi#1");
  CHECK(indices(some) == std::vector<std::size_t>{4, 7});

  {  // a container with no frame in it
    cv::VideoWriter w((dir / "empty.avi").string(), cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 10.0, cv::Size(64, 48),
                      true);
  }
  CHECK_THROWS_AS(vmap::FrameSource::open(dir / "empty.avi"), vmap::Error);
}

TEST_CASE("atomic writes replace a file whole or not at all") {
  const auto dir = vmap::test::scratch_dir("atomic");
  const auto target = dir / "map.txt";
  vmap::write_file_atomically(target, "first");
  CHECK(vmap::read_file(target) == "first");
  vmap::write_file_atomically(target, "second version");
  CHECK(vmap::read_file(target) == "second version");
  CHECK_FALSE(fs::exists(dir / "map.txt.vmap-tmp"));
  // A folder that does not exist: the write fails with an Error and nothing changes.
  CHECK_THROWS_WITH_AS(vmap::write_file_atomically(dir / "no" / "such" / "dir.txt", "x"), doctest::Contains("cannot write"),
                       vmap::Error);
  // An image: encoded by extension, decodable afterwards.
  vmap::write_image_atomically(dir / "img.png", numbered_image(7, 11));
  CHECK(cv::imread((dir / "img.png").string(), cv::IMREAD_GRAYSCALE).at<std::uint8_t>(0, 0) == 7);
  CHECK_THROWS_AS(vmap::write_image_atomically(dir / "img.unknownext", numbered_image(1, 11)), vmap::Error);
  CHECK_THROWS_WITH_AS(vmap::read_file(dir / "absent.bin"), doctest::Contains("absent.bin"), vmap::Error);
}
