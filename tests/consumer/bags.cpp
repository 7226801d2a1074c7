// A program outside the vmap tree that links the bags component (find_package(vmap
// COMPONENTS bags), vmap::bags): it writes a small MCAP bag with the MCAP library the
// component provides (two PNG frames as ROS 2 CompressedImage messages) and reads it
// back as a frame source. With --expect-no-component it is the same source built
// without vmap::bags, and opening the bag must be the Error that says to link it.
//
// usage: vmap_consumer_bags OUT.mcap | vmap_consumer_no_bags OUT.mcap
#include <vmap/io/frame_source.hpp>

#include <opencv2/imgcodecs.hpp>

#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

#ifdef VMAP_CONSUMER_BAGS
#include <mcap/writer.hpp>

namespace {

/// A ROS 2 sensor_msgs/msg/CompressedImage in little-endian CDR.
std::string compressed_image(std::int32_t sec, const std::vector<uchar>& png) {
  std::string b("\x00\x01\x00\x00", 4);
  const auto u32 = [&](std::uint32_t v) {
    while ((b.size() - 4) % 4 != 0) b += '\0';
    for (int i = 0; i < 4; ++i) b += static_cast<char>((v >> (8 * i)) & 0xff);
  };
  const auto str = [&](const std::string& s) {
    u32(static_cast<std::uint32_t>(s.size() + 1));
    b += s;
    b += '\0';
  };
  u32(static_cast<std::uint32_t>(sec));
  u32(0);
  str("camera");
  str("png");
  u32(static_cast<std::uint32_t>(png.size()));
  b.append(png.begin(), png.end());
  return b;
}

}  // namespace
#endif

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s OUT.mcap\n", argv[0]);
    return 2;
  }
#ifdef VMAP_CONSUMER_BAGS
  mcap::McapWriter writer;
  if (!writer.open(argv[1], mcap::McapWriterOptions("ros2")).ok()) return 1;
  mcap::Schema schema("sensor_msgs/msg/CompressedImage", "ros2msg", std::string());
  writer.addSchema(schema);
  mcap::Channel channel("/cam/image_raw/compressed", "cdr", schema.id);
  writer.addChannel(channel);
  for (std::int32_t k = 0; k < 2; ++k) {
    std::vector<uchar> png;
    cv::imencode(".png", cv::Mat(32, 32, CV_8UC1, cv::Scalar(40 * (k + 1))), png);
    const std::string data = compressed_image(100 + k, png);
    mcap::Message m;
    m.channelId = channel.id;
    m.logTime = m.publishTime = static_cast<mcap::Timestamp>(k + 1);
    m.data = reinterpret_cast<const std::byte*>(data.data());
    m.dataSize = data.size();
    if (!writer.write(m).ok()) return 1;
  }
  writer.close();
  auto frames = vmap::FrameSource::open(argv[1], {.grey = true});
  int n = 0;
  while (auto f = frames.next()) {
    if (f->time_ns != (100 + n) * 1000000000LL || f->image.at<uchar>(0, 0) != 40 * (n + 1)) return 1;
    ++n;
  }
  std::printf("read %d frames of %s through vmap::bags\n", n, argv[1]);
  return n == 2 ? 0 : 1;
#else
  try {
    (void)vmap::FrameSource::open(argv[1]);
  } catch (const vmap::Error& e) {
    const std::string what = e.what();
    std::printf("without vmap::bags: %s\n", what.c_str());
    return what.find("link the CMake target vmap::bags") != std::string::npos ? 0 : 1;
  }
  return 1;
#endif
}
