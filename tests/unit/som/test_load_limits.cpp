// The SOM loaders as untrusted input: a GCS file claiming more cells than
// its own max_cells, or a folder / device given as a GCS or pose file, is an Error
// naming the input.
#include <vmap/features/akaze.hpp>
#include <vmap/som/gcs.hpp>
#include <vmap/som/pose_io.hpp>
#include <vmap/som/virtual_room.hpp>

#include "support/errors.hpp"
#include "support/shared_data.hpp"

#include <doctest/doctest.h>

#include <cmath>
#include <random>
#include <string>
#include <vector>

using vmap::test::error_of;

namespace {
bool contains(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }
}  // namespace

TEST_CASE("GCS file: more cells than max_cells, folders and devices are errors") {
  std::vector<Eigen::VectorXf> data;
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(0, 1);
  for (int i = 0; i < 200; ++i) data.push_back(Eigen::VectorXf::NullaryExpr(4, [&] { return u(rng); }));
  vmap::GcsXf g({.lambda = 20, .max_cells = 12, .seed = 4});
  g.train(data);
  REQUIRE(g.size() > 3);
  std::string bytes = g.serialize();
  // max_cells is the u64 at byte 72 (magic 8, version, byte order, scalar size, K: 4
  // each, dimension 8, eps_b, eps_n, alpha, lambda, eta: 8 each). 3 = K + 1 is valid
  // on its own but less than the cells the file holds.
  const std::size_t at = 72;
  REQUIRE(vmap::detail::BinaryReader(std::string_view(bytes).substr(at, 8), "x").u64("max_cells") == 12);
  bytes[at] = 3;
  const auto e = error_of([&] { (void)vmap::GcsXf::deserialize(bytes, "GCS file 'x.gcs'"); });
  CHECK(contains(e, "x.gcs"));
  CHECK(contains(e, "more than its max_cells 3"));

  const auto dir = vmap::test::scratch_dir("som_load_limits");
  CHECK(contains(error_of([&] { (void)vmap::GcsXf::load(dir); }), "GCS file '" + dir.string() + "' is a folder"));
  CHECK(contains(error_of([] { (void)vmap::GcsXf::load("/dev/zero"); }), "not a regular file"));
  CHECK(contains(error_of([&] { (void)vmap::read_xytheta_poses(dir); }), "pose file '" + dir.string() + "' is a folder"));
  CHECK(contains(error_of([&] { (void)vmap::guess_pose_format("/dev/zero"); }), "pose file '/dev/zero' is not a regular file"));
}

TEST_CASE("circuit and capture options: non-finite values are named by their meaning") {
  const vmap::VirtualRoomOptions room;
  CHECK(contains(error_of([&] { (void)vmap::square_circuit(room, {.margin_m = std::nan("")}); }),
                 "the path's distance from the walls (CircuitOptions.margin_m) must be more than 0"));
  CHECK(contains(error_of([&] { (void)vmap::square_circuit(room, {.margin_m = room.size_m}); }), "less than half"));
  CHECK(contains(error_of([&] { (void)vmap::square_circuit(room, {.path_noise_m = -1.0}); }), "CircuitOptions.path_noise_m"));

  vmap::VirtualRoomOptions small;
  small.image_size = {64, 48};
  const vmap::VirtualRoom r(vmap::load_posters(vmap::test::source_dir() / "examples/data/tum_fr1_rpy_60/rgb",
                                               static_cast<std::size_t>(4 * small.posters_per_wall)),
                            small);
  vmap::AkazeDescriptor akaze;
  const auto e = error_of([&] {
    (void)vmap::capture_view(r, akaze, vmap::Pose2(small.size_m / 2, small.size_m / 2, 0.0), std::nan(""));
  });
  CHECK(contains(e, "the camera's pan angle (pan_rad) is not a finite number"));
  CHECK_FALSE(contains(e, "wrap_angle"));
}
