// The page of a memory (runtime/view.hpp) without a browser: the up axis chosen from
// poses of known geometry, the view from above right-handed, the data's JSON text, the
// folder written whole with the memory's key images, loops and answers, and refused
// (nothing written) for a folder of other files or answers of another memory. The page
// itself is driven in a browser by tests/view.
#include "support/errors.hpp"
#include "support/sample_memory.hpp"
#include "support/shared_data.hpp"

#include <vmap/runtime/memory.hpp>
#include <vmap/runtime/view.hpp>

#include <doctest/doctest.h>

#include <opencv2/calib3d.hpp>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

namespace {


/// A camera at `position` whose image's up (-y of the camera) is `up` and whose optical
/// axis is `forward` (orthogonal unit vectors), camera to world.
vmap::detail::ViewKey view_posed_key(cv::Vec3d position, cv::Vec3d up, cv::Vec3d forward) {
  vmap::detail::ViewKey k;
  const cv::Vec3d y = -up, z = forward, x = y.cross(z);
  k.position = position;
  k.rotation = cv::Matx33d(x[0], y[0], z[0], x[1], y[1], z[1], x[2], y[2], z[2]);
  return k;
}

}  // namespace

TEST_CASE("view: the up axis is the cameras' up when they agree, else the axis the positions spread least along") {
  const cv::Vec3d axes[3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  for (int a = 0; a < 3; ++a)
    for (const int sign : {1, -1}) {
      const cv::Vec3d up = sign * axes[a];
      const cv::Vec3d f0 = axes[(a + 1) % 3], f1 = axes[(a + 2) % 3];
      std::vector<vmap::detail::ViewKey> keys;
      for (int i = 0; i < 12; ++i) {
        const double t = 2 * CV_PI * i / 12;
        // Walking a circle in the floor, looking along it, with a roll of up to 20 degrees.
        const cv::Vec3d forward = std::cos(t) * f0 + std::sin(t) * f1;
        const double roll = 0.35 * std::sin(3 * t);
        const cv::Vec3d side = forward.cross(up);
        const cv::Vec3d tilted = std::cos(roll) * up + std::sin(roll) * side;
        keys.push_back(view_posed_key(3.0 * (std::cos(t) * f1 - std::sin(t) * f0), tilted, forward));
      }
      const vmap::detail::ViewUp found = vmap::detail::view_up_axis(keys);
      CHECK(found.axis == a);
      CHECK(found.sign == sign);
    }
  // Cameras rolled every way (no agreement): the floor the positions lie in (y constant).
  std::vector<vmap::detail::ViewKey> rolled;
  for (int i = 0; i < 16; ++i) {
    const double t = 2 * CV_PI * i / 16;
    const cv::Vec3d forward(0, 0, 1), up(std::cos(t), std::sin(t), 0);
    rolled.push_back(view_posed_key({std::cos(t) * 5, 0.01 * (i % 2), std::sin(t) * 5}, up, forward));
  }
  CHECK(vmap::detail::view_up_axis(rolled).axis == 1);
  // Floor poses (SE(2): positions without a rotation): z up.
  std::vector<vmap::detail::ViewKey> floor(3);
  for (std::size_t i = 0; i < floor.size(); ++i) floor[i].position = cv::Vec3d(static_cast<double>(i), 0, 0);
  CHECK(vmap::detail::view_up_axis(floor).axis == 2);
  CHECK(vmap::detail::view_up_axis(floor).sign == 1);
}

TEST_CASE("view: seen from above, right x top is the up axis (a right-handed view)") {
  const cv::Vec3d e[3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  for (int a = 0; a < 3; ++a)
    for (const int sign : {1, -1}) {
      const auto [right, top] = vmap::detail::view_plane_axes({a, sign});
      CHECK(right != a);
      CHECK(top != a);
      CHECK(e[right].cross(e[top]) == sign * e[a]);
    }
}

TEST_CASE("view: the data's JSON escapes names and writes numbers that read back") {
  vmap::detail::ViewJson j;
  j.open('{');
  j.key("name").str("a \"b\" \\ c\nd\te\x01 é");
  j.key("list").open('[');
  j.item().num(0.1);
  j.item().num(std::nan(""));
  j.item().num(1305031229.528748, 17);
  j.item().open('[');
  j.item().integer(-3);
  j.close(']');
  j.close(']');
  j.key("none").raw("null");
  j.key("empty").open('{').close('}');
  j.close('}');
  CHECK(j.text() == "{\"name\":\"a \\\"b\\\" \\\\ c\\u000ad\\u0009e\\u0001 é\",\"list\":[0.1,null,1305031229.528748,[-3]],"
                    "\"none\":null,\"empty\":{}}");
}

TEST_CASE("view: a memory's page holds its key images, loops and answers, written whole") {
  auto memory = vmap::AnyMemory::in_ram(vmap::PolicyStack{}, vmap::test::small_memory_options(vmap::ImageStorage::jpeg));
  for (const auto& f : vmap::test::sample_frames()) (void)memory.push(f);
  REQUIRE(memory.key_images() > 5);
  REQUIRE(!memory.loops().empty());
  const std::filesystem::path dir = vmap::test::fresh_path("view", "page");
  vmap::ViewOptions o;
  const auto frame = vmap::test::sample_frames()[10].image;
  o.answers.push_back(vmap::view_answer("frame 10", memory.localize(frame)));
  REQUIRE(o.answers[0].accepted);
  vmap::ViewAnswer pose = o.answers[0];
  pose.image = "with a pose";
  pose.pose = vmap::ViewPose{{1.5, -2.0, 0.25}, {0, 0, 0, 1}, {{"inliers", 40}}};
  o.answers.push_back(pose);
  const vmap::ViewResult r = vmap::write_view(memory, dir, o);
  CHECK(r.key_images == memory.key_images());
  CHECK(r.loops == memory.loops().size());
  CHECK(r.images == memory.key_images());  // the memory's own pixels (kept as JPEG)
  CHECK(r.matched_loops == memory.loops().size());
  CHECK(r.answers == 2);
  CHECK(r.placed == 2);
  CHECK_FALSE(r.posed);
  for (const char* f : {"index.html", "view.js", "view.css", "data.js", "img/0/0.jpg", "matches/0.js", ".vmap-output"})
    CHECK_MESSAGE(std::filesystem::is_regular_file(dir / f), f);
  const std::string data = vmap::test::read_bytes(dir / "data.js");
  CHECK(data.rfind("window.VMAP_VIEW = JSON.parse('{", 0) == 0);
  CHECK(data.find("\"image\":\"frame 10\",\"accepted\":true") != std::string::npos);
  CHECK(data.find("\"position\":[1.5,-2,0.25]") != std::string::npos);
  // The page loads nothing from the network.
  for (const char* f : {"index.html", "view.js", "view.css"}) CHECK(vmap::test::read_bytes(dir / f).find("http") == std::string::npos);
  // Written again: replaced whole (no image now).
  o.image_side = 0;
  CHECK(vmap::write_view(memory, dir, o).images == 0);
  CHECK_FALSE(std::filesystem::exists(dir / "img"));

  // Answers of another memory: an Error naming the query, and no folder.
  const std::filesystem::path other = vmap::test::fresh_path("view", "refused");
  vmap::ViewOptions wrong;
  wrong.answers.push_back(o.answers[0]);
  wrong.answers[0].key = static_cast<std::uint32_t>(memory.key_images());
  const auto seen = vmap::test::error_seen([&] { (void)vmap::write_view(memory, other, wrong); });
  CHECK(seen.kind == vmap::ErrorKind::invalid_argument);
  CHECK(seen.message.find("frame 10") != std::string::npos);
  CHECK_FALSE(std::filesystem::exists(other));
  // A folder of other files is refused and kept as it was.
  std::filesystem::create_directories(other);
  { std::ofstream(other / "mine.txt") << "mine\n"; }
  CHECK(vmap::test::error_of([&] { (void)vmap::write_view(memory, other, {}); }).find("did not write") != std::string::npos);
  CHECK(vmap::test::read_bytes(other / "mine.txt") == "mine\n");
  CHECK(std::distance(std::filesystem::directory_iterator(other), std::filesystem::directory_iterator()) == 1);
}

TEST_CASE("view: the source is told by its bytes, a missing or foreign one is an Error of its kind") {
  const std::filesystem::path dir = vmap::test::fresh_path("view", "sources");
  std::filesystem::create_directories(dir);
  CHECK(vmap::test::error_seen([&] { (void)vmap::view_source_kind((dir / "missing.vmdb").string()); }).kind ==
        vmap::ErrorKind::not_found);
  { std::ofstream(dir / "notes.txt") << "not a memory\n"; }
  CHECK(vmap::test::error_seen([&] { (void)vmap::view_source_kind((dir / "notes.txt").string()); }).kind ==
        vmap::ErrorKind::corrupt);
  CHECK(vmap::test::error_seen([&] { (void)vmap::view_source_kind(dir.string()); }).kind == vmap::ErrorKind::not_found);
  CHECK(vmap::view_source_kind("postgresql://robot@db/fleet").first == vmap::ViewSourceKind::fleet);
}
