// A program outside the vmap tree, built against the installed package: it must find
// the headers, OpenCV and Eigen through vmap::vmap alone. Its body is the README's
// usage example, so that example is compiled and run by the tests.
//
// usage: vmap_consumer RGB_TXT OUT_MAP
#include <vmap/vmap.hpp>

#include <cstdio>

int main(int argc, char** argv) {
  if (argc != 3) {
    std::fprintf(stderr, "usage: vmap_consumer RGB_TXT OUT_MAP\n");
    return 2;
  }
  // ---- README "Use it from C++" ----
  vmap::KeyframeSelector selector(vmap::OrbDescriptor({.features = 1000}),
                                  vmap::BruteForceMatcher({.mode = vmap::MatchMode::mutual}),
                                  vmap::FundamentalEstimator({.method = vmap::RobustMethod::magsac,
                                                              .threshold_px = 1.0}),
                                  vmap::InlierRatio{}, {.tau = 0.3});

  auto frames = vmap::FrameSource::open(argv[1], {.grey = true});  // video, folder, list or TUM
  while (auto frame = frames.next()) {
    vmap::FrameResult r = selector.push(*frame);
    if (r.key_taken) std::printf("key image: frame %zu\n", *r.key_frame);
  }
  const vmap::VisualMap& map = selector.map();  // key images, F-matrices, similarities
  std::printf("%zu key images, quality %.3f (eq. 7)\n", map.keys.size(), map.quality());
  vmap::save_map(map, argv[2]);                 // written atomically
  // ---- end of the README example ----

  // The sample's 60 frames of a fast rotation give 24 key images at tau 0.3
  // (examples/keyframes.md); the map must read back the same.
  const vmap::VisualMap back = vmap::load_map(argv[2]);
  const bool ok = map.keys.size() == 24 && back.keys.size() == map.keys.size() && map.quality() > 0.4 &&
                  map.quality() < 0.6;
  std::printf("vmap %d.%d.%d consumer: %s\n", vmap::version_major, vmap::version_minor, vmap::version_patch,
              ok ? "ok" : "unexpected result");
  return ok ? 0 : 1;
}
