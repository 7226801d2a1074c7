// VisualMemory: the selector's key images unchanged, loops and localization with the key
// images' own features, the graph, save/load/resume equal to an uninterrupted run, and
// hostile memory files (truncated at every section, flipped bytes, wrong version).
#include "support/errors.hpp"
#include "support/memory_file.hpp"
#include "support/sample_memory.hpp"
#include "support/shared_data.hpp"

#include <vmap/keyframe/map_io.hpp>
#include <vmap/keyframe/pipeline.hpp>
#include <vmap/keyframe/stacks.hpp>
#include <vmap/memory/stacks.hpp>
#include <vmap/memory/visual_memory.hpp>

#include <doctest/doctest.h>

#include <opencv2/core.hpp>

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <thread>
#include <type_traits>
#include <vector>

// Every member of the shipped stacks compiles (binary ORB and float SIFT descriptors).
template class vmap::VisualMemory<vmap::OrbDescriptor, vmap::BruteForceMatcher, vmap::FundamentalEstimator, vmap::InlierRatio>;
template class vmap::VisualMemory<vmap::SiftDescriptor, vmap::BruteForceMatcher, vmap::FundamentalEstimator, vmap::InlierRatio>;

static_assert(!std::is_copy_constructible_v<vmap::OrbVisualMemory>, "a copy would share the ORB detector");
static_assert(std::is_move_constructible_v<vmap::OrbVisualMemory> && std::is_move_assignable_v<vmap::OrbVisualMemory>);

namespace {

using vmap::test::check_same_memory;

using vmap::test::section_starts;

using vmap::test::sample_list;

using vmap::test::sample_frames;
using vmap::test::memory_estimator;
using vmap::test::small_memory_options;
using vmap::test::make_small_memory;

using vmap::test::read_grey_frames;

vmap::OrbVisualMemory load_memory(const std::filesystem::path& p) {
  return vmap::OrbVisualMemory::load(p, vmap::OrbDescriptor{}, vmap::BruteForceMatcher{}, memory_estimator(), vmap::InlierRatio{});
}

vmap::OrbVisualMemory deserialize_memory(const std::string& bytes, const std::string& name = "<memory>") {
  return vmap::OrbVisualMemory::deserialize(bytes, name, vmap::OrbDescriptor{}, vmap::BruteForceMatcher{}, memory_estimator(),
                                            vmap::InlierRatio{});
}

/// Pushes `frames` (every `hold_out`-th left out when > 0); every `every` frames (> 0)
/// the memory is saved, dropped and loaded into a new object before going on.
vmap::OrbVisualMemory run(const std::vector<vmap::Frame>& frames, const vmap::MemoryOptions& o, std::size_t every,
                          const std::filesystem::path& file) {
  std::optional<vmap::OrbVisualMemory> mem;
  mem.emplace(make_small_memory(o));
  for (std::size_t i = 0; i < frames.size(); ++i) {
    if (every > 0 && i > 0 && i % every == 0) {
      mem->save(file);
      mem.reset();
      mem.emplace(load_memory(file));
    }
    mem->push(frames[i]);
  }
  return std::move(*mem);
}

bool names_a_part(const std::string& message) {
  return message.find("section '") != std::string::npos || message.find("header") != std::string::npos;
}

}  // namespace

TEST_CASE("memory: key images are the selector's, with links, poses and the graph") {
  const auto& frames = sample_frames();
  REQUIRE(frames.size() == 60);
  auto mem = make_small_memory(small_memory_options());
  vmap::OrbMagsacSelector plain(vmap::OrbDescriptor{}, vmap::BruteForceMatcher{}, memory_estimator(), vmap::InlierRatio{},
                                {.tau = 0.3});
  std::size_t new_keys = 0;
  for (std::size_t i = 0; i < frames.size(); ++i) {
    const auto step = mem.push(frames[i], vmap::Pose2(static_cast<double>(i), 0.0, 0.0));
    const auto expected = plain.push(frames[i]);
    CHECK(step.frame.key_taken == expected.key_taken);
    CHECK(step.new_key.has_value() == expected.key_taken);
    if (step.new_key) ++new_keys;
  }
  CHECK(mem.map().key_indices() == plain.map().key_indices());
  CHECK(mem.key_images() == new_keys);
  REQUIRE(mem.key_images() >= 3);
  // Each key image carries the pose pushed with its own frame (eq. 6 takes I_{j-1}).
  REQUIRE(mem.poses().size() == mem.key_images());
  for (std::size_t k = 0; k < mem.key_images(); ++k) {
    const auto* p = std::get_if<vmap::Pose2>(&mem.poses()[k]);
    REQUIRE(p != nullptr);
    CHECK(p->x() == static_cast<double>(mem.map().keys[k].frame_index));
  }
  // Every key image is in the place database once the vocabulary was learned (after 3).
  CHECK(!mem.vocabulary().empty());
  CHECK(mem.database().size() == mem.key_images());
  // The graph: the chain, plus the loop edges both ways.
  const auto n1 = mem.neighbours(1);
  REQUIRE(n1.size() >= 2);
  CHECK(n1[0].key == 0);
  CHECK(n1[1].key == 2);
  for (const auto& e : mem.loops()) {
    CHECK(e.link.key + 2 < e.from);  // window = 2
    CHECK(e.link.inliers >= 30);
    CHECK(e.link.confidence >= 0.5);
    CHECK(e.link.status == vmap::VerificationStatus::verified);
    bool found = false;
    for (const auto& n : mem.neighbours(e.link.key))
      found = found || (n.key == e.from && n.kind == vmap::GraphNeighbour::Kind::loop);
    CHECK(found);
  }
  CHECK_THROWS_WITH_AS((void)mem.neighbours(static_cast<std::uint32_t>(mem.key_images())), doctest::Contains("neighbours"),
                       vmap::Error);
}

TEST_CASE("memory: localize answers the key image a held-out frame shows, with the place decision") {
  const auto& all = sample_frames();
  std::vector<vmap::Frame> kept, held;
  for (std::size_t i = 0; i < all.size(); ++i) (i % 10 == 5 ? held : kept).push_back(all[i]);
  auto mem = make_small_memory(small_memory_options());
  for (const auto& f : kept) mem.push(f);
  std::size_t near = 0;
  for (const auto& f : held) {
    const auto loc = mem.localize(f.image);
    if (!loc.ok()) continue;
    const auto& best = *loc.best();
    CHECK(best.status == vmap::VerificationStatus::verified);
    CHECK(best.inliers >= 12);
    CHECK(best.inliers <= best.matches);
    CHECK(loc.confidence >= 0.5);
    CHECK(best.confidence == loc.confidence);
    CHECK(loc.evidence.inliers == best.inliers);
    CHECK(loc.reason.rfind("confidence", 0) == 0);
    CHECK(loc.verified_candidates <= 5);
    const auto key_frame = mem.map().keys[best.key].frame_index;
    if ((key_frame > f.index ? key_frame - f.index : f.index - key_frame) <= 15) ++near;
  }
  CHECK(near >= held.size() - 1);
  // A key image's own frame finds itself with (nearly) all its features.
  const auto self = mem.localize(all[mem.map().keys[1].frame_index].image);
  REQUIRE(self.ok());
  CHECK(self.best()->key == 1);
  CHECK(self.best()->inliers > 500);
  CHECK(self.confidence > 0.99);
  // A stricter threshold for one query: the same evidence, now short of it.
  vmap::PlaceDecisionOptions strict;
  strict.half_significance = 1e6;  // the same evidence weighs almost nothing
  const auto refused = mem.localize(all[mem.map().keys[1].frame_index].image, &strict);
  CHECK(refused.status == vmap::PlaceStatus::unknown_place);
  CHECK(refused.best() == nullptr);
  CHECK(refused.confidence < 0.5);
  CHECK(refused.evidence.inliers == self.evidence.inliers);
  CHECK(refused.reason_code == vmap::DecisionReason::low_confidence);
  CHECK(refused.reason.find("< 0.50") != std::string::npos);
  // A blank image has no features: a value, not an error; an empty one is an error.
  const auto blank = mem.localize(cv::Mat(480, 640, CV_8UC1, cv::Scalar(128)));
  CHECK(blank.status == vmap::PlaceStatus::too_little_evidence);
  CHECK(blank.reason_code == vmap::DecisionReason::no_query_features);
  CHECK(blank.reason == "the query image has no features");
  CHECK_THROWS_AS((void)mem.localize(cv::Mat()), vmap::Error);
  // An empty memory answers so.
  auto empty = make_small_memory(small_memory_options());
  const auto none = empty.localize(all[0].image);
  CHECK(none.status == vmap::PlaceStatus::too_little_evidence);
  CHECK(none.reason_code == vmap::DecisionReason::empty_memory);
  CHECK(none.reason == "the memory has no key image");
}

TEST_CASE("memory: save, load and push continue exactly where an uninterrupted run would") {
  const auto dir = vmap::test::scratch_dir("memory_resume");
  const auto& frames = sample_frames();
  for (auto images : {vmap::ImageStorage::none, vmap::ImageStorage::png, vmap::ImageStorage::jpeg}) {
    CAPTURE(static_cast<int>(images));
    const auto o = small_memory_options(images);
    const auto whole = run(frames, o, 0, dir / "m.vmem");
    for (std::size_t every : {7U, 13U, 30U}) {
      CAPTURE(every);
      check_same_memory(run(frames, o, every, dir / "m.vmem"), whole);
    }
    // A loaded memory keeps the images in the chosen storage.
    whole.save(dir / "w.vmem");
    const auto back = load_memory(dir / "w.vmem");
    check_same_memory(back, whole);
    CHECK(back.options().images == images);
    for (std::size_t k = 0; k < back.key_images(); ++k) {
      CHECK(back.map().keys[k].image.empty() == (images == vmap::ImageStorage::none));
      CHECK(back.map().keys[k].features.descriptors.rows == whole.map().keys[k].features.descriptors.rows);
    }
    if (images == vmap::ImageStorage::png)
      CHECK(cv::norm(back.map().keys[0].image, whole.map().keys[0].image, cv::NORM_INF) == 0.0);
    // Saving the loaded memory gives the same bytes (JPEG is re-encoded, so not there).
    if (images != vmap::ImageStorage::jpeg) CHECK(back.serialize() == whole.serialize());
  }
}

TEST_CASE("memory: a vocabulary given by the user is used from the first key image") {
  const auto& frames = sample_frames();
  std::vector<cv::Mat> sets;
  vmap::OrbDescriptor orb;
  for (std::size_t i = 0; i < frames.size(); i += 10) sets.push_back(orb.extract(frames[i].image).descriptors);
  auto voc = vmap::BinaryVocabularyTree::learn(sets, {.branching = 8, .depth = 2, .seed = 3});
  const std::size_t words = voc.size();
  auto o = small_memory_options();
  vmap::OrbVisualMemory mem(vmap::OrbDescriptor{}, vmap::BruteForceMatcher{}, memory_estimator(), vmap::InlierRatio{}, o,
                            std::move(voc));
  mem.push(frames[0]);
  CHECK(mem.database().size() == 1);
  CHECK(mem.vocabulary().size() == words);
  // A float vocabulary does not fit ORB's binary descriptors: an Error naming both.
  cv::Mat fwords(4, 8, CV_32FC1);
  cv::randu(fwords, 0.0f, 1.0f);
  vmap::OrbVisualMemory wrong(vmap::OrbDescriptor{}, vmap::BruteForceMatcher{}, memory_estimator(), vmap::InlierRatio{}, o,
                              vmap::FloatVocabularyTree::from_words(fwords));
  CHECK(vmap::test::error_of([&] { wrong.push(frames[0]); }).find("do not fit the vocabulary") != std::string::npos);
}

TEST_CASE("memory: invalid options are errors naming the option") {
  auto with = [](auto change) {
    auto o = small_memory_options();
    change(o);
    return vmap::test::error_of([&] { (void)make_small_memory(o); });
  };
  CHECK(with([](vmap::MemoryOptions& o) { o.vocabulary_after = 0; }).find("vocabulary_after") != std::string::npos);
  CHECK(with([](vmap::MemoryOptions& o) { o.loops.top_k = 0; }).find("loops.top_k") != std::string::npos);
  CHECK(with([](vmap::MemoryOptions& o) { o.localize_top_k = 0; }).find("localize_top_k") != std::string::npos);
  CHECK(with([](vmap::MemoryOptions& o) { o.loops.decision.min_inliers = -1; }).find("min_inliers") != std::string::npos);
  CHECK(with([](vmap::MemoryOptions& o) { o.loops.decision.min_confidence = 2; }).find("min_confidence") !=
        std::string::npos);
  CHECK(with([](vmap::MemoryOptions& o) { o.loops.left_ratio = -1; }).find("left_ratio") != std::string::npos);
  CHECK(with([](vmap::MemoryOptions& o) { o.jpeg_quality = 0; }).find("jpeg_quality") != std::string::npos);
  CHECK(with([](vmap::MemoryOptions& o) { o.selector.tau = 1.5; }).find("tau") != std::string::npos);
}

TEST_CASE("memory files: truncated at every section, flipped bytes, wrong version: an Error naming the part") {
  const auto& frames = sample_frames();
  auto mem = make_small_memory(small_memory_options(vmap::ImageStorage::jpeg));
  for (std::size_t i = 0; i < 25; ++i) mem.push(frames[i]);
  REQUIRE(mem.key_images() >= 3);
  const std::string file = mem.serialize();
  const auto starts = section_starts(file);
  REQUIRE(starts.size() == 12);
  CHECK(section_starts(file).back() < file.size());

  auto message_of = [](const std::string& bytes) {
    return vmap::test::error_of([&] { (void)deserialize_memory(bytes, "fuzz.vmem"); });
  };
  const char* tags[] = {"opts", "keys", "link", "loop", "selc", "voca", "plcd", "plcy", "labl", "gcsl", "dcsn", "sess"};
  for (std::size_t s = 0; s < starts.size(); ++s) {
    CAPTURE(tags[s]);
    // Cut inside the section's header, right after it, and in the middle of its bytes.
    for (std::size_t cut : {starts[s], starts[s] + 3, starts[s] + 16, starts[s] + 17,
                            (starts[s] + (s + 1 < starts.size() ? starts[s + 1] : file.size())) / 2}) {
      // A section may be shorter than 17 bytes (an empty GCS): a cut past its end is in the next.
      if (cut >= (s + 1 < starts.size() ? starts[s + 1] : file.size())) continue;
      const std::string m = message_of(file.substr(0, cut));
      CAPTURE(m);
      CHECK(m.find("section '" + std::string(tags[s]) + "'") != std::string::npos);
      CHECK(m.find("fuzz.vmem") != std::string::npos);
    }
  }
  for (std::size_t cut = 0; cut < 16; ++cut) CHECK(message_of(file.substr(0, cut)).find("header") != std::string::npos);
  // Every truncation fails: about 500 cuts spread over the file (the JPEG key images make
  // it large; each cut re-parses it, and the fuzz target tries many more in CI).
  const std::size_t step = file.size() / 500 + 1;
  for (std::size_t cut = 0; cut < file.size(); cut += step) CHECK(names_a_part(message_of(file.substr(0, cut))));
  // A flipped byte anywhere fails, naming the section it is in (CRC per section): about
  // 500 places spread over the file, and the middle of every section (small ones too).
  std::vector<std::size_t> flips;
  for (std::size_t at = 0; at < file.size(); at += step) flips.push_back(at);
  for (std::size_t s = 0; s < starts.size(); ++s)
    flips.push_back((starts[s] + 16 + (s + 1 < starts.size() ? starts[s + 1] : file.size())) / 2);
  for (std::size_t at : flips) {
    if (at >= file.size()) continue;  // an empty last section has no middle byte
    std::string bad = file;
    bad[at] = static_cast<char>(bad[at] ^ 0x5A);
    const std::string m = message_of(bad);
    CAPTURE(at);
    CAPTURE(m);
    CHECK(names_a_part(m));
  }
  // Wrong version, wrong magic, padding.
  std::string v6 = file;
  v6[8] = 6;
  CHECK(message_of(v6).find("format version 6 is not supported") != std::string::npos);
  std::string v1 = file;  // a version 1 header over the 12 sections of version 5
  v1[8] = 1;
  CHECK(message_of(v1).find("12 sections, expected 7 in version 1") != std::string::npos);
  std::string magic = file;
  magic[0] = 'X';
  CHECK(message_of(magic).find("not a vmap memory") != std::string::npos);
  CHECK(message_of(file + "x").find("unexpected bytes") != std::string::npos);
  // The intact file still loads.
  check_same_memory(deserialize_memory(file), mem);
}

TEST_CASE("memory: bare images with timestamps and SE(3) poses; blank frames postpone the vocabulary") {
  const auto& frames = sample_frames();
  auto mem = make_small_memory(small_memory_options());
  // Blank frames: key images without descriptors; no vocabulary can be learned from them.
  const cv::Mat blank(480, 640, CV_8UC1, cv::Scalar(90));
  mem.push(blank, 0.5);
  mem.push(blank, 0.6);
  CHECK(mem.vocabulary().empty());
  for (std::size_t i = 0; i < 20; ++i) {
    cv::Matx44d m = cv::Matx44d::eye();
    m(0, 3) = static_cast<double>(i);
    mem.push(frames[i].image, 100.0 + static_cast<double>(i), cv::Affine3d(m));
  }
  CHECK(mem.frames() == 22);
  CHECK(mem.last_frame_index() == 21);
  CHECK(!mem.vocabulary().empty());
  CHECK(mem.database().size() == mem.key_images());
  REQUIRE(mem.key_images() >= 3);
  CHECK(mem.map().keys[0].timestamp == 0.5);
  const auto back = deserialize_memory(mem.serialize());
  // Keys 0 and 1 are the blank frames (pushed without a pose), then frames[i] is index i + 2.
  CHECK(std::holds_alternative<std::monostate>(back.poses()[1]));
  for (std::size_t k = 2; k < back.key_images(); ++k) {
    const auto* p = std::get_if<cv::Affine3d>(&back.poses()[k]);
    REQUIRE(p != nullptr);
    CHECK(p->translation()[0] == static_cast<double>(back.map().keys[k].frame_index) - 2.0);
    CHECK(back.map().keys[k].timestamp == 98.0 + static_cast<double>(back.map().keys[k].frame_index));
  }
  check_same_memory(back, mem);
}

TEST_CASE("memory: two memories loaded from one file answer the same from two threads as serially") {
  const auto dir = vmap::test::scratch_dir("memory_threads");
  const auto& frames = sample_frames();
  auto mem = make_small_memory(small_memory_options());
  for (std::size_t i = 0; i < 40; i += 2) mem.push(frames[i]);
  mem.save(dir / "m.vmem");
  auto answers = [&](vmap::OrbVisualMemory& m) {
    std::vector<int> out;
    for (std::size_t i = 1; i < 40; i += 4) {
      const auto a = m.localize(frames[i].image);
      out.push_back(a.ok() ? static_cast<int>(a.best()->key) * 10000 + a.best()->inliers : -1);
    }
    return out;
  };
  const auto serial = answers(mem);
  auto a = load_memory(dir / "m.vmem");
  auto b = load_memory(dir / "m.vmem");
  std::vector<int> ra, rb;
  std::thread ta([&] { ra = answers(a); });
  std::thread tb([&] { rb = answers(b); });
  ta.join();
  tb.join();
  CHECK(ra == serial);
  CHECK(rb == serial);
}

TEST_CASE("memory files: a save that dies before commit leaves the previous file loadable") {
  const auto dir = vmap::test::scratch_dir("memory_failed_save");
  const auto& frames = sample_frames();
  auto mem = make_small_memory(small_memory_options());
  for (std::size_t i = 0; i < 20; ++i) mem.push(frames[i]);
  mem.save(dir / "m.vmem");
  for (std::size_t i = 20; i < 40; ++i) mem.push(frames[i]);
  {
    // The save of the bigger memory is cut half way (power loss before the rename).
    const std::string bytes = mem.serialize();
    vmap::AtomicFile f(dir / "m.vmem");
    f.write(std::string_view(bytes).substr(0, bytes.size() / 2));
  }
  const auto back = load_memory(dir / "m.vmem");
  CHECK(back.frames() == 20);
  // No temporary file is left behind.
  std::size_t files = 0;
  for ([[maybe_unused]] const auto& e : std::filesystem::directory_iterator(dir)) ++files;
  CHECK(files == 1);
  CHECK(vmap::test::error_of([&] { (void)load_memory(dir / "missing.vmem"); }).find("missing.vmem") != std::string::npos);
}

TEST_CASE("map files: a map built with a start and a stride round-trips (frame indices in the sequence's space)") {
  const auto dir = vmap::test::scratch_dir("memory_stride");
  const auto frames = read_grey_frames(sample_list(), {.start = 8, .stride = 4});
  REQUIRE(frames.size() == 13);
  CHECK(frames[1].index == 12);
  vmap::OrbMagsacSelector sel(vmap::OrbDescriptor{}, vmap::BruteForceMatcher{}, memory_estimator(), vmap::InlierRatio{},
                              {.tau = 0.5});
  for (const auto& f : frames) sel.push(f);
  const auto& map = sel.map();
  CHECK(map.frames == 13);
  // The memory records where a resumed stream goes on, in the sequence's index space.
  auto mem = make_small_memory(small_memory_options());
  CHECK(!mem.last_frame_index());
  for (const auto& f : frames) mem.push(f);
  CHECK(mem.last_frame_index() == 8 + 4 * 12);
  REQUIRE(map.keys.size() >= 2);
  CHECK(map.keys.back().frame_index >= map.frames);  // the case load_map used to refuse
  vmap::save_map(map, dir / "map.vmap");
  const auto back = vmap::load_map(dir / "map.vmap");
  CHECK(back.frames == map.frames);
  CHECK(back.key_indices() == map.key_indices());
  // More key images than frames is still refused.
  auto bad = map;
  bad.frames = 1;
  CHECK(vmap::test::error_of([&] { (void)vmap::deserialize_map(vmap::serialize_map(bad)); }).find("key images for 1 frames") !=
        std::string::npos);
}

TEST_SUITE("data") {
  TEST_CASE("memory on real sequences: interrupted every 100 (tum_fr1_rpy) / 20 (rtabmap_loop) frames, resumed, "
            "equals one run") {
    const auto dir = vmap::test::scratch_dir("memory_resume_data");
    struct Case {
      std::filesystem::path input;
      std::size_t end, every;
    };
    const Case cases[] = {{vmap::test::data_path("tum_fr1_rpy/rgb.txt"), 300, 100},
                          {vmap::test::data_path("rtabmap_loop/images"), 84, 20}};
    for (const auto& c : cases) {
      CAPTURE(c.input.string());
      const auto frames = read_grey_frames(c.input, {.end = c.end});
      auto o = vmap::MemoryOptions{};
      o.vocabulary_after = 10;
      o.loops.window = 5;
      const auto whole = run(frames, o, 0, dir / "m.vmem");
      const auto resumed = run(frames, o, c.every, dir / "m.vmem");
      check_same_memory(resumed, whole);
      CHECK(whole.key_images() >= 5);
      MESSAGE(c.input.string() << ": " << whole.key_images() << " key images, " << whole.loops().size() << " loops");
    }
  }
}
