// ASL / EuRoC / Kalibr inputs: a EuRoC camera folder made from the sample TUM frames
// (support/euroc_layout.hpp), its sensor.yaml, a Kalibr camchain, EuRoC ground truth,
// and image folders whose names are timestamps.
#include <vmap/io/calibration.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/io/poses.hpp>
#include <vmap/io/timestamps.hpp>

#include "support/euroc_layout.hpp"
#include "support/images.hpp"
#include "support/errors.hpp"
#include "support/shared_data.hpp"

#include <doctest/doctest.h>
#include <opencv2/imgcodecs.hpp>

#include <fstream>
#include <string>
#include <vector>

namespace fs = std::filesystem;

namespace {

const fs::path& sample_layout() {
  static const fs::path mav0 = vmap::test::make_euroc_layout(
      vmap::test::scratch_dir("euroc_sample"), vmap::test::source_dir() / "examples/data/tum_fr1_rpy_60/rgb.txt", 20);
  return mav0;
}

/// The first `n` TUM times of the sample rgb.txt.
std::vector<double> tum_times(std::size_t n) {
  auto src = vmap::FrameSource::open(vmap::test::source_dir() / "examples/data/tum_fr1_rpy_60/rgb.txt");
  auto t = src.timestamps();
  t.resize(n);
  return t;
}

void check_times(const std::vector<double>& got, const std::vector<double>& want) {
  REQUIRE(got.size() == want.size());
  // A double resolves 0.24 us at 1.4e9 s: the times agree to that.
  for (std::size_t k = 0; k < got.size(); ++k) CHECK(std::abs(got[k] - want[k]) < 5e-7);
}

}  // namespace

TEST_CASE("EuRoC camera folder, its data.csv and its data/ folder give the frames with nanosecond times") {
  const fs::path cam0 = sample_layout() / "cam0";
  const auto want = tum_times(20);
  for (const fs::path& input : {cam0, cam0 / "data.csv", cam0 / "data"}) {
    CAPTURE(input);
    auto src = vmap::FrameSource::open(input, {.grey = true});
    CHECK(src.total() == 20);
    check_times(src.timestamps(), want);
    auto first = src.next();
    REQUIRE(first);
    CHECK(first->image.size() == cv::Size(640, 480));
    CHECK(first->name == "1305031229528748000.png");
    CHECK(std::abs(first->timestamp - 1305031229.528748) < 1e-6);
    std::size_t n = 1;
    while (src.next()) ++n;
    CHECK(n == 20);
  }
  CHECK(vmap::FrameSource::open(cam0).kind() == vmap::SourceKind::euroc);
  CHECK(vmap::FrameSource::open(cam0 / "data").kind() == vmap::SourceKind::image_folder);
  // --time-offset: every time shifted, the frames unchanged.
  auto shifted = vmap::FrameSource::open(cam0, {.time_offset = -1305031229.0});
  CHECK(std::abs(shifted.timestamps().front() - 0.528748) < 1e-6);
  CHECK(std::abs(shifted.next()->timestamp - 0.528748) < 1e-6);
}

TEST_CASE("EuRoC data.csv errors name the file and line") {
  const fs::path dir = vmap::test::scratch_dir("euroc_bad_csv");
  fs::create_directories(dir / "data");
  std::ofstream(dir / "data.csv") << "#timestamp [ns],filename\n1403636579763555584,a.png\n12.5,b.png\n";
  CHECK(vmap::test::error_of([&] { (void)vmap::FrameSource::open(dir); }) ==
        "frame source: " + (dir / "data.csv").string() + ":3: '12.5,b.png' is not '<timestamp [ns]>,<file name>' (EuRoC data.csv)");
  std::ofstream(dir / "data.csv") << "#timestamp [ns],filename\n";
  CHECK(vmap::test::error_of([&] { (void)vmap::FrameSource::open(dir); }) ==
        "frame source: EuRoC data.csv '" + (dir / "data.csv").string() + "' names no image");
}

TEST_CASE("EuRoC data.csv: names outside data/ and times that do not increase are refused by file and line") {
  const fs::path dir = vmap::test::scratch_dir("euroc_bounds_csv");
  fs::create_directories(dir / "data");
  const std::string csv = (dir / "data.csv").string();
  const auto error = [&](const std::string& lines) {
    std::ofstream(dir / "data.csv") << "#timestamp [ns],filename\n" << lines;
    return vmap::test::error_of([&] { (void)vmap::FrameSource::open(dir); });
  };
  CHECK(error("100,a.png\n200,../../etc/passwd\n") ==
        "frame source: " + csv + ":3: file name '../../etc/passwd' leaves the data/ folder ('..')");
  CHECK(error("100,sub/../../b.png\n") == "frame source: " + csv + ":2: file name 'sub/../../b.png' leaves the data/ folder ('..')");
  CHECK(error("100,/etc/passwd\n") ==
        "frame source: " + csv + ":2: file name '/etc/passwd' is an absolute path; EuRoC names the images of its data/ folder");
  CHECK(error("100,a.png\n100,b.png\n") ==
        "frame source: " + csv + ":3: timestamp 100 ns is the same as line 2's (100 ns); the times must increase");
  CHECK(error("100,a.png\n# a comment\n200,b.png\n150,c.png\n") ==
        "frame source: " + csv + ":5: timestamp 150 ns is before line 4's (200 ns); the times must increase");
  // Increasing times and plain names (a subfolder of data/ too) are read.
  fs::create_directories(dir / "data" / "sub");
  REQUIRE(cv::imwrite((dir / "data" / "a.png").string(), cv::Mat(4, 4, CV_8UC1, cv::Scalar(1))));
  REQUIRE(cv::imwrite((dir / "data" / "sub" / "b.png").string(), cv::Mat(4, 4, CV_8UC1, cv::Scalar(2))));
  std::ofstream(dir / "data.csv") << "#timestamp [ns],filename\n100,a.png\n200,sub/b.png\n";
  const auto names = vmap::FrameSource::open(dir).paths();
  REQUIRE(names.size() == 2);
  CHECK(names[1] == dir / "data" / "sub/b.png");
}

TEST_CASE("TUM rgb.txt: a time that is not finite is refused by file and line, also on the first line") {
  const fs::path dir = vmap::test::scratch_dir("tum_non_finite");
  const std::string list = (dir / "rgb.txt").string();
  for (const std::string& bad : {std::string("inf"), std::string("nan"), std::string("-inf"), std::string("NaN")}) {
    CAPTURE(bad);
    std::ofstream(dir / "rgb.txt") << "# timestamp filename\n" << bad << " rgb/0.png\n";
    CHECK(vmap::test::error_of([&] { (void)vmap::FrameSource::open(dir / "rgb.txt"); }) ==
          "frame source: " + list + ":2: '" + bad + " rgb/0.png' has a time that is not a finite number");
    std::ofstream(dir / "rgb.txt") << "100.5 rgb/0.png\n" << bad << " rgb/1.png\n";
    CHECK(vmap::test::error_of([&] { (void)vmap::FrameSource::open(dir / "rgb.txt"); }) ==
          "frame source: " + list + ":2: '" + bad + " rgb/1.png' has a time that is not a finite number");
  }
}

TEST_CASE("image folder names that are numbers are timestamps: unit by magnitude") {
  const cv::Mat img = vmap::test::textured_image(3, {32, 32});
  const auto folder = [&](const std::string& name, const std::vector<std::string>& files) {
    const fs::path d = vmap::test::scratch_dir(name);
    for (const auto& f : files) cv::imwrite((d / f).string(), img);
    return vmap::FrameSource::open(d).timestamps();
  };
  check_times(folder("names_ns", {"1403636579763555584.png", "1403636579813555456.png"}),
              {1403636579.763555584, 1403636579.813555456});
  check_times(folder("names_us", {"1403636579763555.png", "1403636579813555.png"}), {1403636579.763555, 1403636579.813555});
  check_times(folder("names_ms", {"1403636579763.png", "1403636579813.png"}), {1403636579.763, 1403636579.813});
  check_times(folder("names_s", {"1305031229.528748.png", "1305031229.564425.png"}), {1305031229.528748, 1305031229.564425});
  check_times(folder("names_index", {"000000.png", "000001.png", "000002.png"}), {0, 1, 2});
  check_times(folder("names_words", {"frame7.png", "frame9.png"}), {0, 1});  // not numbers: indices
  check_times(folder("names_mixed", {"12.png", "x.png"}), {0, 1});
}

TEST_CASE("sensor.yaml (EuRoC) and a Kalibr camchain are calibration files") {
  const auto c = vmap::read_camera(sample_layout() / "cam0" / "sensor.yaml");
  CHECK(c.fx == 517.306408);
  CHECK(c.fy == 516.469215);
  CHECK(c.cx == 318.643040);
  CHECK(c.cy == 255.313989);
  CHECK(c.lens == vmap::LensModel::pinhole);
  CHECK(c.distortion == std::vector<double>{0.262383, -0.953104, -0.005358, 0.002628});
  CHECK(c.image_size == cv::Size(640, 480));
  const std::string camchain =
      "cam0:\n  camera_model: pinhole\n  distortion_coeffs: [-0.0034, 0.0007, -0.0020, 0.0002]\n"
      "  distortion_model: equidistant\n  intrinsics: [190.97, 190.96, 254.93, 256.89]\n  resolution: [512, 512]\n"
      "cam1:\n  T_cn_cnm1:\n  - [1.0, 0.0, 0.0, -0.1]\n  - [0.0, 1.0, 0.0, 0.0]\n  - [0.0, 0.0, 1.0, 0.0]\n"
      "  - [0.0, 0.0, 0.0, 1.0]\n  camera_model: pinhole\n  distortion_coeffs: [-0.28, 0.07, 0.0002, 1.7e-05]\n"
      "  distortion_model: radtan\n  intrinsics: [458.654, 457.296, 367.215, 248.375]\n  resolution: [752, 480]\n";
  CHECK(vmap::guess_calibration_format(camchain) == vmap::CalibrationFormat::kalibr);
  const auto k0 = vmap::parse_camera(camchain, "camchain.yaml");
  CHECK(k0.lens == vmap::LensModel::fisheye);
  CHECK(k0.fx == 190.97);
  CHECK(k0.distortion == std::vector<double>{-0.0034, 0.0007, -0.0020, 0.0002});
  CHECK(k0.image_size == cv::Size(512, 512));
  const auto k1 = vmap::parse_kalibr_camera(camchain, "camchain.yaml", "cam1");
  CHECK(k1.lens == vmap::LensModel::pinhole);
  CHECK(k1.cx == 367.215);
  CHECK(k1.image_size == cv::Size(752, 480));
  CHECK(vmap::test::error_of([&] { (void)vmap::parse_kalibr_camera(camchain, "camchain.yaml", "cam2"); }) ==
        "camchain.yaml: no 'intrinsics' and no camera 'cam2' (a Kalibr camchain)");
  CHECK(vmap::test::error_of([&] {
          (void)vmap::parse_camera("intrinsics: [500, 500, 320, 240]\ndistortion_model: omni\n", "s.yaml");
        }) == "s.yaml: key 'distortion_model' is 'omni'; vmap reads radtan (radial-tangential) and equidistant");
  CHECK(vmap::test::error_of([&] { (void)vmap::parse_camera("intrinsics: [500, 500, 320]\n", "s.yaml"); }) ==
        "s.yaml: key 'intrinsics' has 3 numbers, expected 4 (fu fv cu cv)");
}

TEST_CASE("EuRoC ground truth CSV: nanosecond times, quaternion w first, extra columns ignored") {
  const std::string text =
      "#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z []\n"
      "1403636580838555648,4.688319,-1.786938,0.783338,0.534108,-0.153029,-0.827383,-0.082152,0,0,0\r\n"
      "1403636580843555328,4.688177,-1.786770,0.787350,0.0,0.0,0.0,1.0\n";
  CHECK(vmap::guess_camera_pose_format(text) == vmap::CameraPoseFormat::euroc);
  const auto p = vmap::parse_camera_poses(text, vmap::CameraPoseFormat::euroc, "gt.csv");
  REQUIRE(p.size() == 2);
  CHECK(p[0].timestamp == 1403636580.838555648);
  CHECK(p[0].position == cv::Vec3d(4.688319, -1.786938, 0.783338));
  const cv::Matx33d r = vmap::rotation_from_quaternion(-0.153029, -0.827383, -0.082152, 0.534108);
  for (int k = 0; k < 9; ++k) CHECK(p[0].rotation.val[k] == r.val[k]);
  // w = 0, z = 1: a half turn about z.
  CHECK(p[1].rotation(0, 0) == doctest::Approx(-1.0));
  CHECK(p[1].rotation(2, 2) == doctest::Approx(1.0));
  CHECK(vmap::test::error_of([&] { (void)vmap::parse_euroc_poses("1,2,3\n", "gt.csv"); }) ==
        "gt.csv:1: 3 fields, an ASL / EuRoC pose has at least 8 (timestamp [ns], p_x, p_y, p_z, q_w, q_x, q_y, q_z)");
  CHECK(vmap::test::error_of([&] { (void)vmap::parse_euroc_poses("1,2,3,4,x,0,0,1\n", "gt.csv"); }) ==
        "gt.csv:1: 'x' is not a finite number");
}

TEST_CASE("association errors name both time ranges") {
  const std::vector<vmap::CameraPose> poses = {{100.0, {}, cv::Matx33d::eye()}, {101.0, {}, cv::Matx33d::eye()}};
  CHECK(vmap::test::error_of([&] { (void)vmap::poses_for_frames(poses, {0.0, 1.0, 2.0}, "gt.txt", 0.05); }) ==
        "gt.txt: no pose within 0.050000 s of frame 0 (time 0.000000 s); the 2 poses cover 100.000000 .. 101.000000 s, "
        "the 3 frames 0.000000 .. 2.000000 s (are both on one clock?)");
}

TEST_SUITE("data") {
  TEST_CASE("EuRoC layout of tum_fr1_rpy: every frame has a ground-truth pose, equal to TUM's") {
    const fs::path rgb = vmap::test::data_path("tum_fr1_rpy/rgb.txt");
    const fs::path tum_gt = vmap::test::data_path("tum_fr1_rpy/groundtruth.txt");
    const fs::path mav0 = vmap::test::make_euroc_layout(vmap::test::scratch_dir("euroc_tum"), rgb, 100, tum_gt);
    const auto euroc = vmap::load_camera_poses(mav0 / "state_groundtruth_estimate0" / "data.csv");
    const auto tum = vmap::load_tum_poses(tum_gt);
    REQUIRE(euroc.size() == tum.size());
    for (std::size_t k = 0; k < tum.size(); k += 97) {
      CHECK(std::abs(euroc[k].timestamp - tum[k].timestamp) < 1e-6);
      CHECK(cv::norm(euroc[k].position - tum[k].position) < 1e-12);
      CHECK(cv::norm(euroc[k].rotation - tum[k].rotation) < 1e-12);
    }
    auto src = vmap::FrameSource::open(mav0 / "cam0");
    const auto poses = vmap::poses_for_frames(euroc, src.timestamps(), "gt", 0.02, false);
    CHECK(poses.size() == 100);
    auto from_tum = vmap::FrameSource::open(rgb);
    auto t = from_tum.timestamps();
    t.resize(100);
    const auto same = vmap::poses_for_frames(tum, t, "tum", 0.02, false);
    for (std::size_t k = 0; k < 100; ++k) CHECK(cv::norm(poses[k].position - same[k].position) < 1e-12);
  }
}

TEST_CASE("whole sub-second counts are seconds exact to the unit at Unix times") {
  // 1305031229528748035 ns divided as one double would be 1305031229.5287480 (rounded to
  // the double nearest the 19-digit count first); the split keeps the last digits.
  CHECK(vmap::seconds_from_nanoseconds(1305031229528748035ULL) == 1305031229.0 + 528748035e-9);
  CHECK(vmap::seconds_from_count(1305031229528748ULL, 1000000ULL) == 1305031229.0 + 528748e-6);
  CHECK(vmap::seconds_from_count(1305031229528ULL, 1000ULL) == 1305031229.0 + 0.528);
  CHECK(vmap::seconds_from_count(42, 1) == 42.0);
  CHECK(vmap::seconds_from_nanoseconds(0) == 0.0);
}

TEST_CASE("frames carry their time in whole nanoseconds, exact where the source states it") {
  // Decimal seconds as text: exact, the tenth decimal rounded half up.
  CHECK(vmap::nanoseconds_from_decimal("1305031229.528748") == 1305031229528748000LL);
  CHECK(vmap::nanoseconds_from_decimal("1403636579.7635555845") == 1403636579763555585LL);
  CHECK(vmap::nanoseconds_from_decimal("-0.5") == -500000000LL);
  CHECK(vmap::nanoseconds_from_decimal("12") == 12000000000LL);
  CHECK(vmap::nanoseconds_from_decimal(".25") == 250000000LL);
  CHECK_FALSE(vmap::nanoseconds_from_decimal("1e9").has_value());
  CHECK_FALSE(vmap::nanoseconds_from_decimal("").has_value());
  CHECK_FALSE(vmap::nanoseconds_from_decimal("9999999999.0").has_value());  // beyond int64 nanoseconds
  CHECK(vmap::nanoseconds_from_seconds(1.5) == 1500000000LL);
  CHECK(vmap::nanoseconds_from_seconds(-2.25) == -2250000000LL);

  // EuRoC's data.csv: the 19 digits as they are, shifted exactly by a time offset.
  const fs::path cam0 = sample_layout() / "cam0";
  auto src = vmap::FrameSource::open(cam0, {.grey = true});
  const auto ns = src.times_ns();
  REQUIRE(ns.size() == 20);
  CHECK(ns.front() == 1305031229528748000LL);
  CHECK(src.next()->time_ns == 1305031229528748000LL);
  auto shifted = vmap::FrameSource::open(cam0, {.time_offset = -1305031229.0});
  CHECK(shifted.times_ns().front() == 528748000LL);
  CHECK(shifted.next()->time_ns == 528748000LL);

  // Folders named by numbers: nanoseconds from the digits, whatever their unit.
  const cv::Mat img = vmap::test::textured_image(3, {32, 32});
  const auto folder = [&](const std::string& name, const std::vector<std::string>& files) {
    const fs::path d = vmap::test::scratch_dir(name);
    for (const auto& f : files) cv::imwrite((d / f).string(), img);
    return vmap::FrameSource::open(d).times_ns();
  };
  CHECK(folder("ns_names_ns", {"1403636579763555584.png", "1403636579813555456.png"}) ==
        std::vector<std::int64_t>{1403636579763555584LL, 1403636579813555456LL});
  CHECK(folder("ns_names_us", {"1403636579763555.png"}) == std::vector<std::int64_t>{1403636579763555000LL});
  CHECK(folder("ns_names_s", {"1305031229.528748.png"}) == std::vector<std::int64_t>{1305031229528748000LL});
  CHECK(folder("ns_names_index", {"000000.png", "000001.png"}) == std::vector<std::int64_t>{0, 1000000000LL});
  CHECK(folder("ns_names_words", {"frame7.png", "frame9.png"}) == std::vector<std::int64_t>{0, 1000000000LL});
}
