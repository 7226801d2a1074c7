// LoopDetector weighs the evidence with the geometric model its estimator fits, as the
// loop engine does given the same estimator: an essential matrix's minimal sample is 5,
// a fundamental matrix's 7, and the significance of the inliers counts the inliers
// beyond it (lcd/place_decision.hpp).

#include "support/shared_data.hpp"

#include <vmap/features/orb.hpp>
#include <vmap/geometry/essential.hpp>
#include <vmap/geometry/fundamental.hpp>
#include <vmap/io/calibration.hpp>
#include <vmap/io/files.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/lcd/loop_detector.hpp>
#include <vmap/lcd/loop_engine.hpp>
#include <vmap/lcd/place_decision.hpp>
#include <vmap/matching/brute_force.hpp>

#include <doctest/doctest.h>

#include <cstddef>
#include <vector>

namespace {

vmap::Camera tum_camera() {
  return vmap::parse_camera(
      vmap::read_file(vmap::test::source_dir() / "examples/data/tum_fr1_camera.yaml", 1 << 20, "camera"),
      "tum_fr1_camera.yaml");
}

}  // namespace

static_assert(vmap::place_model_of<vmap::EssentialEstimator>() == vmap::PlaceModel::essential);
static_assert(vmap::place_model_of<vmap::FundamentalEstimator>() == vmap::PlaceModel::fundamental);

TEST_CASE("LoopDetector with an essential-matrix estimator weighs evidence as the loop engine does") {
  const vmap::Camera camera = tum_camera();
  const vmap::LoopOptions o{.window = 1, .index = vmap::CandidateIndex::brute_force};
  vmap::LoopDetector detector(vmap::LabelSchema{}, vmap::OrbDescriptor{}, vmap::BruteForceMatcher{},
                              vmap::EssentialEstimator(camera, {.seed = 3}), o);
  vmap::LoopEngine<vmap::BruteForceMatcher, vmap::EssentialEstimator> engine(
      vmap::BruteForceMatcher{}, vmap::EssentialEstimator(camera, {.seed = 3}), o);
  vmap::OrbDescriptor orb;
  std::vector<vmap::Features> seen;
  const auto lookup = [&](std::size_t j) -> const vmap::Features& { return seen[j]; };
  auto frames = vmap::FrameSource::open(vmap::test::source_dir() / "examples/data/tum_fr1_rpy_60/rgb.txt",
                                        {.end = 16, .grey = true});
  std::size_t weighed = 0;
  while (auto f = frames.next()) {
    vmap::Features features = orb.extract(f->image);
    // Each frame a view of its own for both (the engine's default), so the two weigh the
    // same candidates.
    const vmap::LoopResult d = detector.add(features, {}, vmap::ViewStep::new_view);
    const vmap::PlaceDecision e = engine.add(features, vmap::LabelVector{}, lookup);
    seen.push_back(std::move(features));
    CHECK(d.status == e.status);
    CHECK(d.best == e.best);
    // Every verified candidate weighed alike (the revisit rule may drop the confident
    // ones from the answer: the camera turns on one spot).
    REQUIRE(d.considered.size() == e.considered.size());
    for (std::size_t i = 0; i < e.considered.size(); ++i) {
      CHECK(d.considered[i].frame == e.considered[i].frame);
      CHECK(d.considered[i].inliers == e.considered[i].inliers);
      CHECK(d.considered[i].confidence == e.considered[i].confidence);
      weighed += e.considered[i].inliers > 0 ? 1 : 0;
    }
    if (!e.best) continue;
    CHECK(e.evidence.model == vmap::PlaceModel::essential);
    CHECK(d.evidence.model == vmap::PlaceModel::essential);
    CHECK(d.evidence.significance == e.evidence.significance);
  }
  CHECK(weighed >= 10);

  // The model stays an argument: a caller may still say which one the estimator fits.
  vmap::LoopDetector told(vmap::LabelSchema{}, vmap::OrbDescriptor{}, vmap::BruteForceMatcher{},
                          vmap::EssentialEstimator(camera, {.seed = 3}), o, vmap::PlaceRanker{},
                          vmap::PlaceModel::fundamental);
  std::size_t answered = 0, fundamental = 0;
  for (const vmap::Features& f : seen) {
    const vmap::LoopResult d = told.add(f, {}, vmap::ViewStep::new_view);
    if (!d.best) continue;
    ++answered;
    fundamental += d.evidence.model == vmap::PlaceModel::fundamental ? 1 : 0;
  }
  CHECK(answered >= 1);
  CHECK(fundamental == answered);
}
