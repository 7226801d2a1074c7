// Live input: camera indices, devices, URLs and GStreamer pipelines go to
// cv::VideoCapture without a file-existence check, and a source that does not open is
// a clear error naming it. No camera is needed: every source here fails to open.
#include <vmap/io/frame_source.hpp>

#include "support/errors.hpp"
#include "support/images.hpp"
#include "support/shared_data.hpp"

#include <doctest/doctest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>

#include <filesystem>
#include <string>

namespace fs = std::filesystem;
using vmap::test::error_of;

TEST_CASE("live sources are recognised from the string alone") {
  for (const char* s : {"0", "3", "63", "/dev/video0", "/dev/video12", "rtsp://10.0.0.2:554/stream", "http://cam/mjpg",
                        "udpsrc port=5000 ! decodebin ! videoconvert ! appsink"})
    CHECK_MESSAGE(vmap::detail::is_live_source(s), s);
  for (const char* s : {"", "video.mp4", "rgb.txt", "frames/", "./0", "0.png", "/data/video0.avi", "123456"})
    CHECK_MESSAGE(!vmap::detail::is_live_source(s), s);
}

TEST_CASE("a camera index is opened as a camera even where a folder of that name exists") {
  // A folder "63" full of images in the working directory: FrameSource::open("63") must
  // still ask for camera 63 (which no test machine has) and not read the folder.
  const fs::path dir = vmap::test::scratch_dir("live_index");
  fs::create_directories(dir / "63");
  cv::imwrite((dir / "63" / "a.png").string(), vmap::test::textured_image(1, {32, 24}));
  const fs::path cwd = fs::current_path();
  fs::current_path(dir);
  const std::string e = error_of([] { (void)vmap::FrameSource::open("63"); });
  const std::string e_folder = error_of([] { (void)vmap::FrameSource::open("./63"); });
  fs::current_path(cwd);
  CHECK(e == "frame source: cannot open live input '63' (no camera with this index; file paths that look like this "
             "need a ./ prefix)");
  CHECK(e_folder == "no error");  // the folder is still reachable as a path
}

TEST_CASE("devices, URLs and pipelines that do not open name the source") {
  CHECK(error_of([] { (void)vmap::FrameSource::open("/dev/video63"); }) ==
        "frame source: cannot open live input '/dev/video63' (device or stream not available; file paths that look "
        "like this need a ./ prefix)");
  // Port 9 on the loopback: nothing listens, the connection is refused at once.
  CHECK(error_of([] { (void)vmap::FrameSource::open("rtsp://127.0.0.1:9/none"); })
            .find("frame source: cannot open live input 'rtsp://127.0.0.1:9/none'") == 0);
  CHECK(error_of([] { (void)vmap::FrameSource::open("vmapnosuchelement ! appsink"); })
            .find("cannot open live input 'vmapnosuchelement ! appsink' (GStreamer pipeline did not start") !=
        std::string::npos);
  // Options are still checked first.
  CHECK(error_of([] { (void)vmap::FrameSource::open("0", {.stride = 0}); }) == "frame source: stride must be >= 1");
}
