// Regressions of the memory's options, merge, push and answers: options a memory saves
// are the options it loads (one check for both), merge compares every option, a push
// that throws leaves the memory as it was, loop edges and answers name their model and
// carry every verified candidate's figures.
#include "support/errors.hpp"
#include "support/sample_memory.hpp"
#include "support/shared_data.hpp"

#include <vmap/geometry/calibrated.hpp>
#include <vmap/geometry/essential.hpp>
#include <vmap/memory/store.hpp>
#include <vmap/memory/visual_memory.hpp>

#include <doctest/doctest.h>

#include <stdexcept>
#include <string>

namespace {

using vmap::test::error_of;
using vmap::test::make_small_memory;
using vmap::test::memory_estimator;
using vmap::test::sample_frames;
using vmap::test::small_memory_options;

}  // namespace

TEST_CASE("memory options: what a memory accepts it can load, and what it cannot load it refuses when made") {
  // Temporal consistency above 1000 was accepted, saved, and refused by every later load.
  auto o = small_memory_options();
  o.loops.temporal_consistency = 2000;
  CHECK(error_of([&] { (void)make_small_memory(o); }) ==
        "MemoryOptions.loops.temporal_consistency must be <= 1000, got 2000");
  o.loops.temporal_consistency = 1000;
  auto ok = make_small_memory(o);
  for (std::size_t i = 0; i < 12; ++i) ok.push(sample_frames()[i]);
  const auto back = vmap::OrbVisualMemory::deserialize(ok.serialize(), "m.vmem", vmap::OrbDescriptor{},
                                                       vmap::BruteForceMatcher{}, memory_estimator());
  CHECK(back.options().loops.temporal_consistency == 1000);

  // A vocabulary the memory would learn with options it cannot learn with is refused
  // when the memory is made, not at the key image that learns it.
  auto v = small_memory_options();
  v.vocabulary.branching = 1;
  CHECK(error_of([&] { (void)make_small_memory(v); }) ==
        "MemoryOptions.vocabulary: VocabularyTreeOptions.branching must be in 2..4096, got 1");
  v = small_memory_options();
  v.vocabulary.max_descriptors = 3;
  CHECK(error_of([&] { (void)make_small_memory(v); }).find("max_descriptors must be >= branching") != std::string::npos);
}

TEST_CASE("memory merge: every option is compared, the label and candidate options too") {
  const auto o = small_memory_options();
  auto a = make_small_memory(o);
  for (std::size_t i = 0; i < 20; ++i) a.push(sample_frames()[i]);
  for (const auto& change : {+[](vmap::MemoryOptions& x) { x.loops.min_candidates = 50; },
                             +[](vmap::MemoryOptions& x) { x.loops.labels.min_score = 0.9f; },
                             +[](vmap::MemoryOptions& x) { x.labels.sample = 7; },
                             +[](vmap::MemoryOptions& x) { x.loops.left_ratio = 0.3; }}) {
    auto other = o;
    change(other);
    auto b = make_small_memory(other);
    for (std::size_t i = 20; i < 40; ++i) b.push(sample_frames()[i]);
    const std::size_t keys = a.key_images();
    CHECK(error_of([&] { a.merge(std::move(b), "memory 'a'", "memory 'b'"); })
              .find("cannot merge memory 'b' into memory 'a': they were made with other options") == 0);
    CHECK(a.key_images() == keys);
  }
}

TEST_CASE("memory push: all or nothing; a push that throws leaves the memory exactly as it was") {
  // A working memory of 1 key image whose released features cannot be read: the loop
  // search of a later key image throws in the middle of the push.
  const auto o = small_memory_options();
  auto mem = make_small_memory(o);
  auto whole = make_small_memory(o);
  std::size_t i = 0;
  for (; i < 30; ++i) {
    mem.push(sample_frames()[i]);
    whole.push(sample_frames()[i]);
  }
  REQUIRE(mem.database().size() > 0);
  bool broken = false;
  mem.bound_features(1, [&](std::uint32_t k) -> vmap::Features {
    if (broken) throw vmap::Error("the store is gone");
    return whole.key_features(k);
  });
  mem.release_features(mem.key_images());
  std::size_t failures = 0;
  for (; i < 60; ++i) {
    const std::string before = mem.serialize();
    const auto frames = mem.frames();
    const auto last = mem.last_frame_index();
    broken = true;
    const std::string why = error_of([&] { mem.push(sample_frames()[i]); });
    broken = false;
    if (why != "no error") {
      ++failures;
      CHECK(why == "the store is gone");
      // Nothing changed: the same frames, last frame, and every record.
      CHECK(mem.frames() == frames);
      CHECK(mem.last_frame_index() == last);
      CHECK(mem.serialize() == before);
      mem.push(sample_frames()[i]);  // again, with the source back
    }
    whole.push(sample_frames()[i]);
    CHECK(mem.frames() == whole.frames());
  }
  CHECK(failures > 0);
  // The failed pushes, repeated, give the memory of an uninterrupted run.
  CHECK(mem.serialize() == whole.serialize());
}

TEST_CASE("localization and loop edges: every verified candidate's figures and the model's kind") {
  const auto o = small_memory_options();
  auto mem = make_small_memory(o);
  for (std::size_t i = 0; i < 60; i += 2) mem.push(sample_frames()[i]);
  REQUIRE(!mem.loops().empty());
  for (const auto& e : mem.loops()) {
    CHECK(e.link.model_kind == vmap::PlaceModel::fundamental);
    CHECK(e.link.matches >= e.link.inliers);
    CHECK(e.link.model != cv::Matx33d::zeros());
  }
  std::size_t several = 0;
  for (std::size_t i = 1; i < 60; i += 2) {
    const auto answer = mem.localize(sample_frames()[i].image);
    several += answer.matches.size() > 1 ? 1 : 0;
    for (const auto& l : answer.matches) {
      CAPTURE(i);
      CHECK(l.status == vmap::VerificationStatus::verified);
      CHECK(l.matches >= l.inliers);
      CHECK(l.inliers > 0);
      CHECK(l.similarity > 0.0);
      CHECK(l.model != cv::Matx33d::zeros());
    }
    for (std::size_t k = 1; k < answer.matches.size(); ++k)
      CHECK(answer.matches[k].confidence <= answer.matches[k - 1].confidence + (k == 1 ? 1.0 : 0.0));
  }
  CHECK(several > 0);

  // An essential-matrix memory's edges and answers say so.
  const vmap::Camera tum{.fx = 517.3, .fy = 516.5, .cx = 318.6, .cy = 255.3,
                         .distortion = {0.2624, -0.9531, -0.0054, 0.0026, 1.1633}, .image_size = {640, 480}};
  using Essential = vmap::VisualMemory<vmap::OrbDescriptor, vmap::BruteForceMatcher, vmap::EssentialEstimator, vmap::InlierRatio>;
  Essential e(vmap::OrbDescriptor{}, vmap::BruteForceMatcher{}, vmap::EssentialEstimator(tum), vmap::InlierRatio{}, o);
  for (std::size_t i = 0; i < 60; i += 2) e.push(sample_frames()[i]);
  std::size_t answered = 0;
  // The key images' own frames: each ranks itself first.
  for (std::size_t i = 0; i < 60; i += 6) {
    const auto answer = e.localize(sample_frames()[i].image);
    if (answer.matches.empty()) continue;
    ++answered;
    CHECK(answer.evidence.model == vmap::PlaceModel::essential);
    for (const auto& l : answer.matches) CHECK(l.model_kind == vmap::PlaceModel::essential);
  }
  CHECK(answered > 0);
  CHECK(!e.loops().empty());
  for (const auto& edge : e.loops()) CHECK(edge.link.model_kind == vmap::PlaceModel::essential);
}
