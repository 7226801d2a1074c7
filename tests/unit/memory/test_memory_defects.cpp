// Regressions of the memory's options, merge, push and answers: options a memory saves
// are the options it loads (one check for both), merge compares every option, a push
// that throws leaves the memory as it was, loop edges and answers name their model and
// carry every verified candidate's figures, and values a memory could not keep are refused
// where they enter.
#include "support/errors.hpp"
#include "support/sample_memory.hpp"
#include "support/shared_data.hpp"

#include <vmap/geometry/calibrated.hpp>
#include <vmap/geometry/essential.hpp>
#include <vmap/memory/stacks.hpp>
#include <vmap/memory/store.hpp>
#include <vmap/memory/visual_memory.hpp>

#include <doctest/doctest.h>

#include <limits>
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

TEST_CASE("memory push: a value the memory could not keep is refused where it enters, naming it") {
  const auto o = small_memory_options();
  auto mem = make_small_memory(o);
  for (std::size_t i = 0; i < 10; ++i) mem.push(sample_frames()[i]);
  const std::string before = mem.serialize();
  const vmap::Frame& next = sample_frames()[10];
  const auto refused = [&](vmap::Frame f, const vmap::OdometryPose& pose = {}) {
    const std::string why = error_of([&] { mem.push(f, pose); });
    CHECK(mem.serialize() == before);  // nothing changed
    return why;
  };
  const std::string at = "VisualMemory::push: frame 10 ('" + next.name + "'): ";
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();

  cv::Matx44d m = cv::Matx44d::eye();
  m(0, 3) = nan;
  CHECK(refused(next, cv::Affine3d(m)) == at + "the SE(3) pose is not finite");
  m = cv::Matx44d::eye();
  m(0, 0) = 2.0;  // a scaling, not a rotation
  CHECK(refused(next, cv::Affine3d(m)).starts_with(at + "the SE(3) pose's 3x3 part is not a rotation (R^T R differs from I by 3"));
  m = cv::Matx44d::eye();
  m(2, 2) = -1.0;  // a reflection: orthonormal, det -1
  CHECK(refused(next, cv::Affine3d(m)).find("det -1") != std::string::npos);

  vmap::Frame f = next;
  f.timestamp = inf;
  CHECK(refused(f) == at + "the timestamp is not finite");
  f.timestamp = nan;
  CHECK(refused(f) == at + "the timestamp is not finite");
  f = next;
  f.name = std::string(5000, 'x');
  CHECK(refused(f) == "VisualMemory::push: frame 10: the name is 5000 bytes long, more than the 4096 a memory keeps");
  f.name = std::string("a\0b", 3);
  CHECK(refused(f) == "VisualMemory::push: frame 10: the name holds a NUL character");
  f = next;
  f.index = 9;
  CHECK(refused(f) == "VisualMemory::push: frame 9 ('" + next.name +
                          "'): frame indices must increase within a session (the last frame pushed is 9; "
                          "start_session() begins a new run)");
  f.index = 5;
  CHECK(refused(f).find("frame indices must increase") != std::string::npos);
  f = next;
  f.image = cv::Mat(1, (1 << 26) + 1, CV_8UC1, cv::Scalar(0));
  CHECK(refused(f) == at + "the image has 67108865x1 pixels, more than the limit of 67108864");
  f.image = cv::Mat();
  CHECK(refused(f) == at + "the image is empty");

  // A real rotation (30 degrees about z, as a text file's 7 digits give it) is taken.
  const double c = 0.8660254, s = 0.5;
  const cv::Affine3d turned(cv::Matx33d(c, -s, 0, s, c, 0, 0, 0, 1), cv::Vec3d(1, 2, 3));
  mem.push(next, turned);
  CHECK(mem.frames() == 11);
  // A new session numbers its frames from wherever its run starts.
  mem.start_session();
  mem.push(sample_frames()[0]);
  CHECK(mem.last_frame_index() == 0);
  // A bare image follows the last frame pushed.
  mem.push(sample_frames()[1].image);
  CHECK(mem.last_frame_index() == 1);
  // Every refused value left a memory that saves and loads.
  const auto back = vmap::OrbVisualMemory::deserialize(mem.serialize(), "m.vmem", vmap::OrbDescriptor{},
                                                       vmap::BruteForceMatcher{}, memory_estimator());
  CHECK(back.frames() == 13);
  CHECK(back.sessions().size() == 2);
}
