// The shared robot bags (../shared/data/bags, README there) against the plain files they
// were made from: pixels exact against the same JPEGs decoded by the same OpenCV, JPEG
// bytes identical, stamps exact against contents.txt; key images, map quality, loops
// and a memory from the bags equal those from the JPEG folder and rgb.txt; the
// rosbags-rs conformance bags; the shared bags cut at every record boundary.

#include "support/bags.hpp"
#include "support/errors.hpp"
#include "support/sample_memory.hpp"
#include "support/shared_data.hpp"

#include <vmap/io/bag/bag.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/keyframe/pipeline.hpp>
#include <vmap/keyframe/selector.hpp>
#include <vmap/keyframe/stacks.hpp>
#include <vmap/memory/visual_memory.hpp>

#include <doctest/doctest.h>
#include <opencv2/imgcodecs.hpp>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <vector>

namespace fs = std::filesystem;
using vmap::test::data_path;
using vmap::test::error_of;

namespace {

using vmap::test::same_pixels;

std::vector<vmap::Frame> frames_of(const fs::path& input, vmap::FrameSourceOptions o = {}) {
  auto src = vmap::FrameSource::open(input, o);
  std::vector<vmap::Frame> out;
  while (auto f = src.next()) out.push_back(std::move(*f));
  CHECK(src.skipped().empty());
  CHECK(src.warnings().empty());
  return out;
}

/// TUM rgb.txt of the 60 sample frames: (time ns, JPEG path).
std::vector<std::pair<std::int64_t, fs::path>> tum_sample() {
  const auto list = vmap::test::source_dir() / "examples/data/tum_fr1_rpy_60/rgb.txt";
  std::vector<std::pair<std::int64_t, fs::path>> out;
  std::ifstream in(list);
  for (std::string line; std::getline(in, line);) {
    if (line.empty() || line[0] == '#') continue;
    const auto sp = line.find(' ');
    out.emplace_back(*vmap::nanoseconds_from_decimal(line.substr(0, sp)), list.parent_path() / line.substr(sp + 1));
  }
  return out;
}

fs::path rtabmap_jpeg(std::size_t k) { return data_path("rtabmap_loop/images/" + std::to_string(k + 1) + ".jpg"); }

/// The data of every CompressedImage message of `topic`, in order.
std::vector<std::string> compressed_payloads(const fs::path& bag, const std::string& topic) {
  auto s = vmap::detail::open_message_stream(bag);
  std::vector<std::uint32_t> ids;
  std::string encoding;
  for (const auto& c : s->connections())
    if (c.topic == topic) ids.push_back(c.id), encoding = c.encoding;
  s->select(ids);
  std::vector<std::string> out;
  vmap::detail::StreamMessage m;
  while (s->next(m))
    out.push_back(std::string(vmap::detail::with_message_reader(encoding, m.bytes, "test", [](auto& r, bool ros1) {
      return vmap::detail::read_compressed_image_message(r, ros1).data;
    })));
  return out;
}

const char* const rtabmap_bags[] = {"bags/rtabmap_loop.mcap", "bags/rtabmap_loop_db3", "bags/rtabmap_loop_compressed.bag"};
const char* const tum_bags[] = {"bags/tum_fr1_rpy_60.bag", "bags/tum_fr1_rpy_60_db3", "bags/tum_fr1_rpy_60.mcap"};

}  // namespace

TEST_SUITE("data") {
  TEST_CASE("shared bags: topics, counts and first/last stamps as contents.txt lists them") {
    std::ifstream in(data_path("bags/contents.txt"));
    std::size_t rows = 0;
    for (std::string line; std::getline(in, line);) {
      if (line.empty() || line[0] == '#') continue;
      std::vector<std::string> cols;
      for (std::size_t pos = 0;;) {
        const auto bar = line.find(" | ", pos);
        cols.push_back(line.substr(pos, bar == std::string::npos ? std::string::npos : bar - pos));
        if (bar == std::string::npos) break;
        pos = bar + 3;
      }
      REQUIRE(cols.size() == 7);
      for (std::size_t pos = 0; pos < cols[0].size();) {
        auto comma = cols[0].find(", ", pos);
        if (comma == std::string::npos) comma = cols[0].size();
        std::string bag = cols[0].substr(pos, comma - pos);
        pos = comma + 2;
        if (!bag.empty() && bag.back() == '/') bag.pop_back();
        CAPTURE(bag);
        CAPTURE(cols[1]);
        const auto path = data_path("bags/" + bag);
        const auto info = vmap::bag_info(path);
        CHECK(info.indexed);
        CHECK(info.warnings.empty());
        const auto topic = std::find_if(info.topics.begin(), info.topics.end(), [&](const auto& t) { return t.name == cols[1]; });
        REQUIRE(topic != info.topics.end());
        CHECK(topic->messages == std::stoull(cols[3]));
        CHECK(topic->type.find(cols[2].substr(0, cols[2].find(' '))) != std::string::npos);
        auto src = vmap::FrameSource::open(path, {.topic = cols[1]});
        const auto times = src.times_ns();
        REQUIRE(times.size() == std::stoull(cols[3]));
        CHECK(times.front() == std::stoll(cols[4]));
        CHECK(times.back() == std::stoll(cols[5]));
        ++rows;
      }
    }
    CHECK(rows == 8);
  }

  TEST_CASE("shared bags: TUM frames equal the JPEGs decoded by OpenCV, stamps exact to the nanosecond") {
    const auto sample = tum_sample();
    REQUIRE(sample.size() == 60);
    for (const char* name : tum_bags) {
      CAPTURE(name);
      for (bool grey : {true, false}) {
        const auto frames = frames_of(data_path(name), {.grey = grey, .topic = "/cam0/image_raw"});
        REQUIRE(frames.size() == 60);
        for (std::size_t k = 0; k < 60; ++k) {
          CHECK(frames[k].time_ns == sample[k].first);
          CHECK(frames[k].name == "/cam0/image_raw@" + std::to_string(sample[k].first));
          // mono8 is libjpeg's own grey decoding of the JPEG (the bags' README).
          CHECK(same_pixels(frames[k].image, cv::imread(sample[k].second.string(), cv::IMREAD_GRAYSCALE)));
        }
      }
    }
    // The rgb8 topic: the colour decoding, 1 us after the mono frames.
    const auto colour = frames_of(data_path("bags/tum_fr1_rpy_60.bag"), {.topic = "/camera/rgb/image_color"});
    REQUIRE(colour.size() == 10);
    for (std::size_t k = 0; k < 10; ++k) {
      CHECK(colour[k].time_ns == sample[k].first + 1000);
      CHECK(same_pixels(colour[k].image, cv::imread(sample[k].second.string(), cv::IMREAD_COLOR)));
    }
    // The compressed colour topic of the MCAP bag: the colour decoding encoded again by
    // OpenCV's JPEG writer (tools/make_bags.py), byte for byte what this OpenCV writes.
    const auto jpegs = compressed_payloads(data_path("bags/tum_fr1_rpy_60.mcap"), "/camera/rgb/image_color/compressed");
    REQUIRE(jpegs.size() == 10);
    const auto compressed = frames_of(data_path("bags/tum_fr1_rpy_60.mcap"), {.topic = "/camera/rgb/image_color/compressed"});
    REQUIRE(compressed.size() == 10);
    for (std::size_t k = 0; k < 10; ++k) {
      std::vector<uchar> again;
      cv::imencode(".jpg", cv::imread(sample[k].second.string(), cv::IMREAD_COLOR), again);
      CHECK(jpegs[k] == std::string(again.begin(), again.end()));
      CHECK(same_pixels(compressed[k].image, cv::imdecode(again, cv::IMREAD_UNCHANGED)));
      CHECK(compressed[k].time_ns == sample[k].first + 1000);
    }
  }

  TEST_CASE("shared bags: RTAB-Map loop frames carry the JPEG files' bytes and decode to the same pixels") {
    for (const char* name : rtabmap_bags) {
      CAPTURE(name);
      const auto payloads = compressed_payloads(data_path(name), "/camera/image_raw/compressed");
      REQUIRE(payloads.size() == 84);
      for (std::size_t k = 0; k < 84; ++k) CHECK(payloads[k] == vmap::test::read_bytes(rtabmap_jpeg(k)));
      const auto frames = frames_of(data_path(name));
      REQUIRE(frames.size() == 84);
      for (std::size_t k = 0; k < 84; k += 7) {
        CHECK(frames[k].time_ns == 1700000000000000000LL + static_cast<std::int64_t>(k) * 1000000000LL);
        CHECK(same_pixels(frames[k].image, cv::imread(rtabmap_jpeg(k).string(), cv::IMREAD_UNCHANGED)));
      }
    }
  }

  TEST_CASE("shared bags: key images, map quality and loops from the RTAB-Map bags equal the JPEG folder's") {
    const auto select = [](const fs::path& input) {
      vmap::OrbMagsacSelector sel(vmap::OrbDescriptor{}, vmap::BruteForceMatcher{}, vmap::FundamentalEstimator{},
                                  vmap::InlierRatio{}, {.tau = 0.3});
      auto src = vmap::FrameSource::open(input, {.grey = true});
      vmap::run_selector(src, sel, {.pipelined = true, .prepare_threads = 2});
      return sel.map();
    };
    const auto loops = [](const fs::path& input) {
      auto memory = vmap::test::make_small_memory(vmap::test::small_memory_options());
      for (const auto& f : frames_of(input, {.grey = true})) (void)memory.push(f);
      std::vector<std::tuple<std::uint32_t, std::uint32_t, int>> out;
      for (const auto& e : memory.loops()) out.emplace_back(e.from, e.link.key, e.link.inliers);
      return out;
    };
    const auto folder = data_path("rtabmap_loop/images");
    const vmap::VisualMap expected = select(folder);
    const auto expected_loops = loops(folder);
    REQUIRE(expected.keys.size() > 5);
    REQUIRE_FALSE(expected_loops.empty());
    for (const char* name : rtabmap_bags) {
      CAPTURE(name);
      const vmap::VisualMap got = select(data_path(name));
      REQUIRE(got.keys.size() == expected.keys.size());
      for (std::size_t k = 0; k < got.keys.size(); ++k) CHECK(got.keys[k].frame_index == expected.keys[k].frame_index);
      REQUIRE(got.pairs.size() == expected.pairs.size());
      for (std::size_t k = 0; k < got.pairs.size(); ++k) CHECK(got.pairs[k].similarity == expected.pairs[k].similarity);
      CHECK(got.quality() == expected.quality());
      CHECK(loops(data_path(name)) == expected_loops);
    }
  }

  TEST_CASE("shared bags: a memory from tum_fr1_rpy_60.bag equals one from the sample frames' rgb.txt, times aside") {
    const auto build = [](const fs::path& input, vmap::FrameSourceOptions o) {
      auto memory = vmap::test::make_small_memory(vmap::test::small_memory_options());
      o.grey = true;
      for (const auto& f : frames_of(input, o)) (void)memory.push(f);
      return memory;
    };
    const auto a = build(vmap::test::source_dir() / "examples/data/tum_fr1_rpy_60/rgb.txt", {});
    const auto b = build(data_path("bags/tum_fr1_rpy_60.bag"), {.topic = "/cam0/image_raw"});
    REQUIRE(a.key_images() == b.key_images());
    REQUIRE(a.key_images() > 3);
    for (std::size_t k = 0; k < a.key_images(); ++k) {
      const auto& ka = a.map().keys[k];
      const auto& kb = b.map().keys[k];
      CHECK(ka.frame_index == kb.frame_index);
      CHECK(ka.features.keypoints.size() == kb.features.keypoints.size());
      CHECK(cv::norm(ka.features.descriptors, kb.features.descriptors, cv::NORM_HAMMING) == 0);
      CHECK(ka.timestamp == kb.timestamp);  // the bag's stamps are rgb.txt's times
    }
    vmap::test::check_same_memory(a, b);
    CHECK(a.map().quality() == b.map().quality());
    for (std::size_t k = 0; k < a.loops().size(); ++k) CHECK(a.loops()[k].link.confidence == b.loops()[k].link.confidence);
  }

  TEST_CASE("conformance bags (rosbags-rs): every topic listed; the two stub images refused with their reasons") {
    for (const char* name : {"bags/conformance/test_bag_mcap.mcap", "bags/conformance/test_bag_sqlite3.db3"}) {
      CAPTURE(name);
      const auto path = data_path(name);
      const auto info = vmap::bag_info(path);
      REQUIRE(info.topics.size() == 94);
      CHECK(info.messages == 188);
      for (const auto& t : info.topics) {
        CHECK(t.messages == 2);
        CHECK(t.encoding == "cdr");
        CHECK(t.name.rfind("/test/", 0) == 0);
        CHECK(t.type.find("/msg/") != std::string::npos);
      }
      // Every message read through, each topic's two in record order.
      std::map<std::string, std::vector<std::int64_t>> seen;
      for (const auto& m : vmap::test::all_messages(path)) seen[m.topic].push_back(m.record_ns);
      CHECK(seen.size() == 94);
      for (const auto& [topic, times] : seen) {
        CHECK(times.size() == 2);
        CHECK(times[0] < times[1]);
        CHECK(times[0] >= info.start_ns);
        CHECK(times[1] <= info.end_ns);
      }
      // The stub images: each message skipped with its reason, none decoded.
      const auto reasons = [&](const std::string& topic) {
        auto src = vmap::FrameSource::open(path, {.topic = topic});
        std::vector<std::string> out;
        while (auto p = src.claim()) {
          auto d = src.decode(std::move(*p));
          REQUIRE(std::holds_alternative<vmap::SkippedFrame>(d));
          out.push_back(std::get<vmap::SkippedFrame>(d).reason);
        }
        return out;
      };
      const auto raw = reasons("/test/sensor_msgs/image");
      REQUIRE(raw.size() == 2);
      for (const auto& r : raw) {
        CHECK(r.find("topic '/test/sensor_msgs/image'") != std::string::npos);
        CHECK(r.find("(sensor_msgs/msg/Image): the message carries 30 bytes of pixels, rgb8 640x480 with step 1920 needs "
                     "921600") != std::string::npos);
      }
      const auto jpeg = reasons("/test/sensor_msgs/compressed_image");
      REQUIRE(jpeg.size() == 2);
      for (const auto& r : jpeg)
        CHECK(r.find("(sensor_msgs/msg/CompressedImage): JPEG (format 'jpeg', 10 bytes)") != std::string::npos);
      CHECK(error_of([&] { (void)frames_of(path, {.topic = "/test/sensor_msgs/image"}); }).find("no frame of") !=
            std::string::npos);
      // Both image topics: a choice the error lists.
      CHECK(error_of([&] { (void)vmap::FrameSource::open(path); }).find("has 2 image topics") != std::string::npos);
      // Every other topic is refused as not images, by its type.
      for (const auto& t : info.topics)
        if (!vmap::detail::is_image_type(t.type))
          CHECK(error_of([&] { (void)vmap::FrameSource::open(path, {.topic = t.name}); })
                    .find("topic '" + t.name + "' holds " + t.type + ", not images") != std::string::npos);
      // The CameraInfo beside the image topic.
      auto src = vmap::FrameSource::open(path, {.topic = "/test/sensor_msgs/image"});
      REQUIRE(src.camera());
      CHECK(src.camera()->camera.describe() == "pinhole fx=525 fy=525 cx=320 cy=240 distortion=[0.1 -0.2 0.001 0.002 0] size=640x480");
    }
  }

  TEST_CASE("shared bags cut at every record boundary (ROS 1 lz4, MCAP) and rosbag2 at every page") {
    vmap::test::check_cuts(data_path("bags/rtabmap_loop_compressed.bag"), vmap::BagFormat::ros1, "cut_shared_ros1");
    vmap::test::check_cuts(data_path("bags/rtabmap_loop.mcap"), vmap::BagFormat::mcap, "cut_shared_mcap");
    const auto db3 = data_path("bags/rtabmap_loop_db3/rtabmap_loop_db3_0.db3");
    const auto bytes = vmap::test::read_bytes(db3);
    const auto full = vmap::test::all_messages(db3);
    const auto dir = vmap::test::scratch_dir("cut_shared_db3");
    std::size_t read_some = 0;
    for (std::size_t page = 4096; page < bytes.size(); page += 4096) {
      CAPTURE(page);
      vmap::test::write_bytes(dir / "cut.db3", std::string_view(bytes).substr(0, page));
      std::vector<vmap::test::ReadMessage> got;
      if (error_of([&] { got = vmap::test::all_messages(dir / "cut.db3"); }) != "no error") continue;
      REQUIRE(got.size() <= full.size());
      for (std::size_t k = 0; k < got.size(); ++k) CHECK(got[k] == full[k]);
      read_some += got.empty() ? 0 : 1;
    }
    CHECK(read_some > 0);
  }
}
