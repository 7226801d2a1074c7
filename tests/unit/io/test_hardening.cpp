// Hostile and broken inputs to the io layer: folders, devices and FIFOs where
// a file is expected, symbolic link loops, unreadable folders, images whose header
// claims a huge size, corrupt video frames, bad TUM lines, concurrent and failed saves.
// Every case must end in a vmap::Error naming the input or in a reported skip, never in
// another exception, an abort or a hang.
#include <vmap/io/atomic_file.hpp>
#include <vmap/io/files.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/io/image.hpp>
#include <vmap/io/timestamps.hpp>

#include "support/errors.hpp"
#include "support/fifo.hpp"
#include "support/images.hpp"
#include "support/shared_data.hpp"

#include <doctest/doctest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>

#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <fstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <variant>
#include <vector>

namespace fs = std::filesystem;
using vmap::test::error_of;

namespace {

using vmap::test::numbered_image;
using vmap::test::write_bytes;

bool contains(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

/// A PNG signature and IHDR chunk claiming width x height, followed by garbage: a
/// decoder would allocate width x height before noticing.
std::string png_header_claiming(std::uint32_t width, std::uint32_t height) {
  std::string b("\x89PNG\r\n\x1a\n", 8);
  b += std::string("\0\0\0\x0dIHDR", 8);
  for (std::uint32_t v : {width, height})
    for (int s = 24; s >= 0; s -= 8) b.push_back(static_cast<char>((v >> s) & 0xFF));
  b += std::string("\x08\x00\x00\x00\x00", 5);  // 8-bit grey
  b += std::string(64, '\x11');
  return b;
}

}  // namespace

TEST_CASE("read_file: folders, devices, FIFOs and limits are errors naming the path") {
  const auto dir = vmap::test::scratch_dir("hardening_read");
  const auto folder_error = error_of([&] { (void)vmap::read_file(dir, vmap::default_max_file_bytes, "map file"); });
  CHECK(contains(folder_error, "map file '" + dir.string() + "' is a folder"));

  CHECK(contains(error_of([] { (void)vmap::read_text_file("/dev/zero", "ground truth file"); }),
                 "ground truth file '/dev/zero' is not a regular file"));

  const auto fifo = dir / "pipe.txt";
  fs::remove(fifo);
  REQUIRE(::mkfifo(fifo.c_str(), 0600) == 0);
  CHECK(contains(error_of([&] { (void)vmap::read_file(fifo); }), "is not a regular file"));  // returns, no hang

  write_bytes(dir / "big.txt", std::string(1000, 'x'));
  CHECK(contains(error_of([&] { (void)vmap::read_file(dir / "big.txt", 999); }), "more than the limit of 999"));
  CHECK(vmap::read_file(dir / "big.txt", 1000).size() == 1000);
  CHECK(contains(error_of([&] { (void)vmap::read_file(dir / "absent"); }), "absent': does not exist"));

  if (::geteuid() != 0) {  // root reads anything
    write_bytes(dir / "secret.txt", "x");
    fs::permissions(dir / "secret.txt", fs::perms::none);
    CHECK(contains(error_of([&] { (void)vmap::read_file(dir / "secret.txt"); }), "Permission denied"));
    fs::permissions(dir / "secret.txt", fs::perms::owner_all);
  }
}

TEST_CASE("create_directories: a file in the way, /proc and read-only parents are errors") {
  const auto dir = vmap::test::scratch_dir("hardening_mkdir");
  write_bytes(dir / "file", "x");
  CHECK(contains(error_of([&] { vmap::create_directories(dir / "file"); }), "exists and is not a folder"));
  CHECK(contains(error_of([&] { vmap::create_directories(dir / "file" / "sub"); }), "is a file, not a folder"));
  CHECK(contains(error_of([] { vmap::create_directories("/proc/vmap_test_out"); }), "/proc/vmap_test_out"));
  vmap::create_directories(dir / "a" / "b");
  CHECK(fs::is_directory(dir / "a" / "b"));
  if (::geteuid() != 0) {
    fs::create_directories(dir / "ro");
    fs::permissions(dir / "ro", fs::perms::owner_read | fs::perms::owner_exec);
    CHECK(contains(error_of([&] { vmap::create_directories(dir / "ro" / "out"); }), "Permission denied"));
    fs::permissions(dir / "ro", fs::perms::owner_all);
  }
}

TEST_CASE("image headers give the size without decoding") {
  const cv::Mat img = numbered_image(1, 3);
  for (const char* ext : {".png", ".jpg", ".bmp", ".pgm", ".tiff", ".webp"}) {
    std::vector<unsigned char> buf;
    REQUIRE(cv::imencode(ext, img, buf));
    const auto size = vmap::image_header_size(std::string_view(reinterpret_cast<const char*>(buf.data()), buf.size()));
    INFO(ext);
    REQUIRE(size);
    CHECK(size->width == 64);
    CHECK(size->height == 48);
  }
  CHECK_FALSE(vmap::image_header_size("not an image"));
  const auto huge = vmap::image_header_size(png_header_claiming(30000, 30000));
  REQUIRE(huge);
  CHECK(huge->width == 30000);
}

TEST_CASE("read_image: a huge header is refused before decoding; limits are options") {
  const auto dir = vmap::test::scratch_dir("hardening_image");
  write_bytes(dir / "huge.png", png_header_claiming(30000, 30000));
  const auto e = error_of([&] { (void)vmap::read_image(dir / "huge.png"); });
  CHECK(contains(e, "huge.png"));
  CHECK(contains(e, "30000x30000 pixels, more than the limit of 67108864"));
  cv::imwrite((dir / "small.png").string(), numbered_image(2, 3));
  CHECK(vmap::read_image(dir / "small.png").size() == cv::Size(64, 48));
  CHECK(contains(error_of([&] { (void)vmap::read_image(dir / "small.png", {.max_pixels = 1000}); }),
                 "64x48 pixels, more than the limit of 1000"));
  CHECK(contains(error_of([&] { (void)vmap::read_image(dir); }), "is a folder"));
}

TEST_CASE("frame source: symlink loops, FIFOs, huge headers and 1x1 frames are skipped with reasons") {
  const auto dir = vmap::test::scratch_dir("hardening_folder");
  for (int k = 0; k < 3; ++k) cv::imwrite((dir / ("f" + std::to_string(k) + ".png")).string(), numbered_image(k, 3));
  fs::create_symlink("self.jpg", dir / "self.jpg");  // a loop
  write_bytes(dir / "f1a.png", png_header_claiming(30000, 30000));
  cv::imwrite((dir / "f1b.png").string(), cv::Mat(1, 1, CV_8UC1, cv::Scalar(9)));
  REQUIRE(::mkfifo((dir / "f1c.png").c_str(), 0600) == 0);

  auto s = vmap::FrameSource::open(dir);
  std::vector<std::string> names;
  while (auto f = s.next()) names.push_back(f->name);
  CHECK(names == std::vector<std::string>{"f0.png", "f1.png", "f2.png"});
  REQUIRE(s.skipped().size() == 4);
  std::string all;
  for (const auto& k : s.skipped()) all += k.name + ": " + k.reason + "\n";
  INFO(all);
  CHECK(contains(all, "f1a.png: the image is 30000x30000 pixels, more than the limit"));
  CHECK(contains(all, "f1b.png: the frame is 1x1 pixels, outside 16x16"));
  CHECK(contains(all, "f1c.png: is not a regular file"));
  CHECK(contains(all, "self.jpg: "));
  CHECK(s.delivered() == 3);

  // A list naming the FIFO: skipped, no hang.
  write_bytes(dir / "list.txt", "f0.png\nf1c.png\nf2.png\n");
  auto l = vmap::FrameSource::open(dir / "list.txt");
  std::size_t n = 0;
  while (l.next()) ++n;
  CHECK(n == 2);
  CHECK(l.skipped().size() == 1);

  // A folder given as the sequence whose only entry is a loop: an error naming it.
  const auto loop_dir = vmap::test::scratch_dir("hardening_loop_only");
  fs::create_symlink("a.png", loop_dir / "a.png");
  auto only = vmap::FrameSource::open(loop_dir);
  CHECK(contains(error_of([&] { (void)only.next(); }), "no frame of '" + loop_dir.string() + "' could be read"));

  if (::geteuid() != 0) {
    const auto locked = vmap::test::scratch_dir("hardening_locked");
    fs::permissions(locked, fs::perms::none);
    CHECK(contains(error_of([&] { (void)vmap::FrameSource::open(locked); }), "cannot read folder '" + locked.string()));
    fs::permissions(locked, fs::perms::owner_all);
  }
}

TEST_CASE("frame source: a TUM rgb.txt with a bad line is an error naming the line") {
  const auto dir = vmap::test::scratch_dir("hardening_tum");
  cv::imwrite((dir / "a.png").string(), numbered_image(0, 3));
  write_bytes(dir / "rgb.txt", "# color images\n1.0 a.png\n2.0 a.png\nthree a.png\n4.0 a.png\n");
  CHECK(contains(error_of([&] { (void)vmap::FrameSource::open(dir / "rgb.txt"); }),
                 "rgb.txt:4: 'three a.png' is not '<timestamp> <path>'"));
  write_bytes(dir / "rgb2.txt", "1.0 a.png\n2.0 a.png extra\n");
  CHECK(contains(error_of([&] { (void)vmap::FrameSource::open(dir / "rgb2.txt"); }), "rgb2.txt:2:"));
  // A list file that is a device: refused by name, never read.
  fs::create_symlink("/dev/zero", dir / "zero.txt");
  CHECK(contains(error_of([&] { (void)vmap::FrameSource::open(dir / "zero.txt"); }), "zero.txt' is not a regular file"));
}

TEST_CASE("frame source: times beyond +-9.2e9 s are refused by name, never clamped") {
  const auto dir = vmap::test::scratch_dir("hardening_times");
  cv::imwrite((dir / "a.png").string(), numbered_image(0, 3));
  const std::string beyond = " s is beyond +-9.2e9 s, the range of nanosecond times (the year 2262)";
  write_bytes(dir / "far.txt", "1.0 a.png\n1e10 a.png\n");
  CHECK(error_of([&] { (void)vmap::FrameSource::open(dir / "far.txt"); }) ==
        "frame source: " + (dir / "far.txt").string() + ":2: time 10000000000" + beyond);
  write_bytes(dir / "decimal.txt", "-99999999999.5 a.png\n");
  CHECK(error_of([&] { (void)vmap::FrameSource::open(dir / "decimal.txt"); }) ==
        "frame source: " + (dir / "decimal.txt").string() + ":1: time -99999999999.5" + beyond);
  // A time no range holds is called what it is.
  CHECK(error_of([] { (void)vmap::frame_time_ns(std::nan(""), "push: timestamp"); }) ==
        "push: timestamp: time nan s is not finite");
  CHECK(error_of([] { (void)vmap::frame_time_ns(-HUGE_VAL, "push: timestamp"); }) ==
        "push: timestamp: time -inf s is not finite");
  // Image names that are times: seconds (below 1e11), and nanoseconds past INT64_MAX.
  for (const std::string name : {"10000000000", "10000000000000000000"}) {
    const auto folder = dir / ("names_" + std::to_string(name.size()));
    fs::create_directories(folder);
    cv::imwrite((folder / (name + ".png")).string(), numbered_image(0, 3));
    CHECK(error_of([&] { (void)vmap::FrameSource::open(folder); }) == "frame source: folder '" + folder.string() + "', file '" +
                                                                         name + ".png' (its name is its time): time 10000000000" +
                                                                         beyond);
  }
  // An offset beyond the range, and one that takes a frame's time past it.
  CHECK(error_of([&] { (void)vmap::FrameSource::open(dir / "a.png", {.time_offset = -1e10}); }) ==
        "frame source: time_offset: time -10000000000" + beyond);
  write_bytes(dir / "late.txt", "1e9 a.png\n2e9 a.png\n");
  auto late = vmap::FrameSource::open(dir / "late.txt", {.time_offset = 9e9});
  CHECK(error_of([&] { (void)late.times_ns(); }) ==
        "frame source: '" + (dir / "late.txt").string() +
            "': with the time offset (FrameSourceOptions::time_offset), a frame's time 10000000000" + beyond);
  auto p = late.claim();
  REQUIRE(p);
  const auto d = late.decode(std::move(*p));
  REQUIRE(std::holds_alternative<vmap::SkippedFrame>(d));
  CHECK(std::get<vmap::SkippedFrame>(d).reason ==
        "with the time offset (FrameSourceOptions::time_offset), its time 10000000000" + beyond);
  // Within the range: exact.
  auto near = vmap::FrameSource::open(dir / "late.txt", {.time_offset = 7e9});
  CHECK(near.times_ns() == std::vector<std::int64_t>{8000000000000000000LL, 9000000000000000000LL});
}

TEST_CASE("frame source: an input that is a FIFO or a device is refused before it is opened (no video backend waits)") {
  const auto dir = vmap::test::scratch_dir("hardening_fifo_input");
  const auto fifo = vmap::test::make_fifo(dir / "pipe.mp4");
  std::string e;
  {
    const vmap::test::FifoWatchdog watchdog({fifo}, std::chrono::seconds(20));  // a hang fails the check below
    e = error_of([&] { (void)vmap::FrameSource::open(fifo); });
  }
  CHECK(e == "frame source: input '" + fifo.string() +
                 "' is not a regular file or a folder (a device, FIFO or socket cannot be read as one)");
  fs::create_symlink("/dev/null", dir / "null.avi");
  CHECK(contains(error_of([&] { (void)vmap::FrameSource::open(dir / "null.avi"); }), "null.avi' is not a regular file or a folder"));
}

TEST_CASE("frame source: a huge stride ends the sequence instead of wrapping around") {
  const auto dir = vmap::test::scratch_dir("hardening_stride");
  for (int k = 0; k < 4; ++k) cv::imwrite((dir / ("f" + std::to_string(k) + ".png")).string(), numbered_image(k, 3));
  auto s = vmap::FrameSource::open(dir, {.start = 1, .stride = std::numeric_limits<std::size_t>::max()});
  std::vector<std::size_t> idx;
  while (auto f = s.next()) idx.push_back(f->index);
  CHECK(idx == std::vector<std::size_t>{1});
}

TEST_CASE("frame source: a corrupt frame inside a video is skipped and reported, later frames kept") {
  const auto dir = vmap::test::scratch_dir("hardening_video");
  const auto path = dir / "garbled.avi";
  {
    cv::VideoWriter w(path.string(), cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 10.0, cv::Size(64, 48), false);
    REQUIRE(w.isOpened());
    for (int k = 0; k < 12; ++k) {
      cv::Mat img = vmap::test::textured_image(static_cast<std::uint64_t>(k) + 50, {64, 48});
      w.write(img);
    }
  }
  std::string bytes = vmap::read_file(path);
  // Frame k's JPEG starts at the k-th SOI marker (FF D8 FF); garble frame 3.
  std::vector<std::size_t> soi;
  for (std::size_t p = bytes.find("\xFF\xD8\xFF"); p != std::string::npos; p = bytes.find("\xFF\xD8\xFF", p + 1))
    soi.push_back(p);
  REQUIRE(soi.size() == 12);
  for (std::size_t i = soi[3]; i + 16 < soi[4]; ++i) bytes[i] = 'x';  // keeps the AVI chunk headers
  vmap::write_file_atomically(path, bytes);

  std::vector<vmap::SkippedFrame> reported;
  auto s = vmap::FrameSource::open(path, {.on_skip = [&](const vmap::SkippedFrame& f) { reported.push_back(f); }});
  std::vector<std::size_t> idx;
  while (auto f = s.next()) idx.push_back(f->index);
  CHECK(idx == std::vector<std::size_t>{0, 1, 2, 4, 5, 6, 7, 8, 9, 10, 11});
  REQUIRE(s.skipped().size() == 1);
  CHECK(s.skipped()[0].index == 3);
  CHECK(s.skipped()[0].name == "garbled.avi#3");
  CHECK(reported.size() == 1);
}

TEST_CASE("atomic file: a writer that fails midway leaves the previous file and no temporary") {
  const auto dir = vmap::test::scratch_dir("hardening_atomic_fail");
  const auto target = dir / "map.bin";
  vmap::write_file_atomically(target, "old content");
  try {
    vmap::AtomicFile f(target);
    f.write("new half");
    throw std::runtime_error("simulated failure");
  } catch (const std::runtime_error&) {
  }
  CHECK(vmap::read_file(target) == "old content");
  std::size_t entries = 0;
  for ([[maybe_unused]] const auto& e : fs::directory_iterator(dir)) ++entries;
  CHECK(entries == 1);  // no temporary file left behind
  // Refused targets: a folder, a device.
  CHECK(contains(error_of([&] { vmap::write_file_atomically(dir, "x"); }), "it is a folder"));
  CHECK(contains(error_of([] { vmap::write_file_atomically("/dev/full", "x"); }), "not a regular file"));
  CHECK(contains(error_of([&] { vmap::write_file_atomically(dir / "no" / "x.bin", "x"); }), "does not exist"));
}

TEST_CASE("atomic file: a symbolic link is followed on purpose and stays a link") {
  const auto dir = vmap::test::scratch_dir("hardening_atomic_link");
  fs::create_directories(dir / "real");
  vmap::write_file_atomically(dir / "real" / "a.csv", "one");
  fs::create_symlink("real/a.csv", dir / "link.csv");
  vmap::write_file_atomically(dir / "link.csv", "two");
  CHECK(fs::is_symlink(dir / "link.csv"));
  CHECK(vmap::read_file(dir / "real" / "a.csv") == "two");
  fs::create_symlink("/dev/null", dir / "null.csv");
  CHECK(contains(error_of([&] { vmap::write_file_atomically(dir / "null.csv", "x"); }), "not a regular file"));
}

TEST_CASE("atomic file: concurrent writers (threads and processes) always leave one complete file") {
  const auto dir = vmap::test::scratch_dir("hardening_atomic_race");
  const auto target = dir / "shared.bin";
  // Large payloads, one distinct byte each, so a mix of two writes is detectable.
  const auto payload = [](int w) { return std::string(std::size_t{1} << 20, static_cast<char>('a' + w)); };
  const auto check_whole = [&] {
    const std::string got = vmap::read_file(target);
    REQUIRE(got.size() == payload(0).size());
    CHECK(got.find_first_not_of(got[0]) == std::string::npos);
  };
  for (int round = 0; round < 3; ++round) {
    std::vector<std::thread> threads;
    std::atomic<int> failures{0};
    for (int w = 0; w < 6; ++w)
      threads.emplace_back([&, w] {
        try {
          for (int k = 0; k < 3; ++k) vmap::write_file_atomically(target, payload(w));
        } catch (...) {
          ++failures;
        }
      });
    for (auto& t : threads) t.join();
    CHECK(failures == 0);
    check_whole();
  }
  std::vector<pid_t> children;
  for (int w = 0; w < 4; ++w) {
    const pid_t pid = ::fork();
    REQUIRE(pid >= 0);
    if (pid == 0) {
      int rc = 0;
      try {
        for (int k = 0; k < 3; ++k) vmap::write_file_atomically(target, payload(10 + w));
      } catch (...) {
        rc = 1;
      }
      ::_exit(rc);
    }
    children.push_back(pid);
  }
  for (pid_t pid : children) {
    int status = 0;
    ::waitpid(pid, &status, 0);
    CHECK((WIFEXITED(status) && WEXITSTATUS(status) == 0));
  }
  check_whole();
  std::size_t entries = 0;
  for ([[maybe_unused]] const auto& e : fs::directory_iterator(dir)) ++entries;
  CHECK(entries == 1);
}

TEST_CASE("atomic directory: a set of files appears whole; foreign folders are never replaced") {
  const auto dir = vmap::test::scratch_dir("hardening_atomic_dir");
  const auto out = dir / "out";
  {
    vmap::AtomicDirectory d(out);
    vmap::write_file_atomically(d.path() / "a.txt", "a1");
    vmap::write_file_atomically(d.path() / "b.txt", "b1");
    CHECK_FALSE(fs::exists(out));  // nothing visible before commit
    d.commit();
  }
  CHECK(vmap::read_file(out / "a.txt") == "a1");
  CHECK(vmap::read_file(out / "b.txt") == "b1");
  {  // a second set replaces the first whole: b.txt of the old set is gone
    vmap::AtomicDirectory d(out);
    vmap::write_file_atomically(d.path() / "a.txt", "a2");
    d.commit();
  }
  CHECK(vmap::read_file(out / "a.txt") == "a2");
  CHECK_FALSE(fs::exists(out / "b.txt"));
  {  // abandoned: the published set is untouched, the temporary folder gone
    vmap::AtomicDirectory d(out);
    vmap::write_file_atomically(d.path() / "a.txt", "a3");
  }
  CHECK(vmap::read_file(out / "a.txt") == "a2");
  std::size_t entries = 0;
  for ([[maybe_unused]] const auto& e : fs::directory_iterator(dir)) ++entries;
  CHECK(entries == 1);

  // A folder holding files vmap did not write (e.g. the input frames) is refused.
  fs::create_directories(dir / "frames");
  write_bytes(dir / "frames" / "f0.png", "x");
  CHECK(contains(error_of([&] { vmap::AtomicDirectory d(dir / "frames"); }), "holds files vmap did not write"));
  CHECK(fs::exists(dir / "frames" / "f0.png"));
  write_bytes(dir / "plain", "x");
  CHECK(contains(error_of([&] { vmap::AtomicDirectory d(dir / "plain"); }), "exists and is not a folder"));
  CHECK(contains(error_of([] { vmap::AtomicDirectory d("/proc/vmap_out"); }), "/proc/vmap_out"));

  // Concurrent sets to the same folder: afterwards it holds one complete set.
  std::vector<std::thread> threads;
  std::atomic<int> failures{0};
  for (int w = 0; w < 4; ++w)
    threads.emplace_back([&, w] {
      try {
        for (int k = 0; k < 3; ++k) {
          vmap::AtomicDirectory d(dir / "race");
          vmap::write_file_atomically(d.path() / "x.txt", std::to_string(w));
          vmap::write_file_atomically(d.path() / "y.txt", std::to_string(w));
          d.commit();
        }
      } catch (...) {
        ++failures;
      }
    });
  for (auto& t : threads) t.join();
  CHECK(failures == 0);
  CHECK(vmap::read_file(dir / "race" / "x.txt") == vmap::read_file(dir / "race" / "y.txt"));
}
