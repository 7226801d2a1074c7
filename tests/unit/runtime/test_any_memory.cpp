// AnyMemory (runtime/memory.hpp) and record() (runtime/recorder.hpp): a memory of any
// shipped stack opened from whatever keeps it, with the stack read back from its own
// records; the answers of the typed memory it holds.
#include "support/errors.hpp"
#include "support/sample_memory.hpp"
#include "support/shared_data.hpp"

#include <vmap/memory/store.hpp>
#include <vmap/runtime/exports.hpp>
#include <vmap/runtime/memory.hpp>
#include <vmap/runtime/recorder.hpp>

#include <doctest/doctest.h>

#include <filesystem>
#include <fstream>
#include <string>

namespace {

namespace fs = std::filesystem;
using vmap::test::error_of;
using vmap::test::sample_frames;

/// `name` in this file's scratch folder, with nothing there (vmap::test::fresh_path).
std::filesystem::path any_memory_path(const std::string& name) { return vmap::test::fresh_path("any_memory", name); }

vmap::MemoryOptions small() {
  vmap::MemoryOptions o;
  o.vocabulary_after = 3;
  o.vocabulary = {.branching = 8, .depth = 2, .seed = 5};
  o.loops.window = 2;
  o.loops.decision.min_inliers = 30;
  return o;
}

}  // namespace

TEST_CASE("AnyMemory: a memory in RAM answers as the typed memory of its stack") {
  const vmap::PolicyStack stack = vmap::PolicyStack::from_string("orb features=800 method=magsac");
  auto any = vmap::AnyMemory::in_ram(stack, small());
  using Typed = vmap::VisualMemory<vmap::OrbDescriptor, vmap::BruteForceMatcher, vmap::Calibrated<vmap::FundamentalEstimator>,
                                   vmap::InlierRatio>;
  Typed typed(vmap::OrbDescriptor({.features = 800}), vmap::BruteForceMatcher{},
              vmap::Calibrated<vmap::FundamentalEstimator>(std::nullopt, vmap::FundamentalEstimator{}), vmap::InlierRatio{},
              small());
  for (std::size_t i = 0; i < 60; i += 2) {
    const auto a = any.push(sample_frames()[i]);
    const auto b = typed.push(sample_frames()[i]);
    CHECK(a.new_key == b.new_key);
    CHECK(a.loops.size() == b.loops.size());
  }
  CHECK(any.records().policies == typed.policy_records());
  CHECK(vmap::policy_records(stack) == typed.policy_records());
  CHECK(any.key_images() == typed.key_images());
  CHECK(any.loops().size() == typed.loops().size());
  const auto q = any.localize(sample_frames()[13].image);
  const auto t = typed.localize(sample_frames()[13].image);
  CHECK(q.status == t.status);
  CHECK(q.confidence == t.confidence);
  REQUIRE(q.matches.size() == t.matches.size());
  for (std::size_t k = 0; k < q.matches.size(); ++k) CHECK(q.matches[k].key == t.matches[k].key);
}

TEST_CASE("AnyMemory: created, recorded, reopened to read and to continue, its stack read back from its records") {
  const fs::path path = any_memory_path("run.vmdb");
  const vmap::PolicyStack stack = vmap::PolicyStack::from_string("sift features=600 method=ransac");
  auto src = vmap::FrameSource::open(vmap::test::source_dir() / "examples/data/tum_fr1_rpy_60/rgb.txt",
                                     {.end = 30, .grey = true});
  {
    auto mem = vmap::AnyMemory::create(path, stack, small());
    vmap::set_session_input(mem, vmap::recorded_input("rgb.txt", src, 1));
    std::size_t seen = 0;
    const auto r = vmap::record(mem, src, {.on_frame = [&](const vmap::AnyMemory& m) { seen = m.frames(); }});
    CHECK(r.pushed == 30);
    CHECK(seen == 30);
    CHECK(r.syncs >= mem.key_images());
    mem.close();
    CHECK(!mem.writes());
    CHECK(error_of([&] { (void)mem.push(sample_frames()[0]); }).find("the memory was closed") != std::string::npos);
  }
  auto reader = vmap::AnyMemory::open(path);
  CHECK(reader.stack() == stack);
  CHECK(reader.kind() == vmap::MemoryKind::store);
  CHECK(reader.frames() == 30);
  CHECK(!reader.writes());
  CHECK(error_of([&] { (void)reader.push(sample_frames()[0]); }).find("opened read-only") != std::string::npos);
  const auto input = vmap::session_input(reader, 0);
  REQUIRE(input.has_value());
  CHECK(input->stride == 1);
  CHECK(input->first_frame == "1305031229.528748.jpg");

  // Continued with a second session, bounded to 2 key images in RAM.
  {
    auto mem = vmap::AnyMemory::open(path, {.write = true, .new_session = true, .working_memory = 2});
    CHECK(mem.sessions().size() == 2);
    auto rest = vmap::FrameSource::open(vmap::test::source_dir() / "examples/data/tum_fr1_rpy_60/rgb.txt",
                                        {.start = 20, .grey = true});
    (void)vmap::record(mem, rest);
    CHECK(!mem.holds_features(0));
    mem.close();
  }
  auto again = vmap::AnyMemory::open(path, {.pixels = true});
  CHECK(again.sessions().size() == 2);
  CHECK(again.frames() == 70);
  // A .vmem file of it reads back as the same memory, and a store made of that file too.
  const fs::path file = any_memory_path("run.vmem");
  again.save(file);
  auto from_file = vmap::AnyMemory::open(file);
  CHECK(from_file.kind() == vmap::MemoryKind::file);
  CHECK(from_file.stack() == stack);
  CHECK(from_file.records().policies == again.records().policies);
  const fs::path copy = any_memory_path("copy.vmdb");
  auto copied = vmap::AnyMemory::copy_into_store(vmap::AnyMemory::open(file, {.pixels = true}), copy);
  copied.close();
  CHECK(vmap::AnyMemory::open(copy).map().key_indices() == again.map().key_indices());
}

TEST_CASE("AnyMemory: memories written by the format-4 code open with the stack their store noted") {
  const fs::path copy = any_memory_path("old.vmdb");
  fs::copy_file(vmap::test::source_dir() / "tests/unit/memory/data/tum_two_sessions_v3.vmdb", copy);
  auto mem = vmap::AnyMemory::open(copy);
  CHECK(vmap::to_string(mem.stack()) ==
        "orb features=80 method=magsac camera=(pinhole fx=517.3 fy=516.5 cx=318.6 cy=255.3 distortion=[0.2624 -0.9531 "
        "-0.0054 0.0026 1.1633] size=640x480) camera_source=\"examples/data/tum_fr1_camera.yaml\"");
  CHECK(mem.key_images() == 13);
  const auto file = vmap::AnyMemory::open(vmap::test::source_dir() / "tests/unit/memory/data/tum_two_sessions_v4.vmem");
  CHECK(file.stack() == mem.stack());
  CHECK(file.map().key_indices() == mem.map().key_indices());
}

TEST_CASE("AnyMemory: errors name the memory and what is wrong") {
  const fs::path missing = any_memory_path("missing.vmdb");
  CHECK(error_of([&] { (void)vmap::AnyMemory::open(missing); }) == "memory '" + missing.string() + "' does not exist");
  const fs::path text = any_memory_path("notes.txt");
  std::ofstream(text) << "not a memory";
  CHECK(error_of([&] { (void)vmap::AnyMemory::open(text); }) ==
        "'" + text.string() + "' is not a vmap memory (neither a memory store nor a .vmem memory file)");
  const fs::path empty = any_memory_path("empty.vmdb");
  (void)vmap::MemoryStore::create(empty);
  CHECK(error_of([&] { (void)vmap::AnyMemory::open(empty); }).find("holds nothing yet") != std::string::npos);
  // A memory of policies that are not a shipped stack (the tests' estimator skips the
  // degeneracy test) is refused by name; the library loads it with its own policies.
  auto typed = vmap::test::make_small_memory(vmap::test::small_memory_options());
  for (std::size_t i = 0; i < 10; ++i) typed.push(sample_frames()[i]);
  const fs::path custom = any_memory_path("custom.vmem");
  typed.save(custom);
  CHECK(error_of([&] { (void)vmap::AnyMemory::open(custom); }).find("its policies are not one of vmap's stacks") !=
        std::string::npos);
  const fs::path exists = any_memory_path("exists.vmdb");
  vmap::AnyMemory::create(exists, vmap::PolicyStack{}).close();
  CHECK(error_of([&] { (void)vmap::AnyMemory::create(exists, vmap::PolicyStack{}); }).find("exists already") !=
        std::string::npos);
}

TEST_CASE("AnyMemory exports: key images and loop edges with their times to the nanosecond") {
  auto mem = vmap::AnyMemory::in_ram(vmap::PolicyStack{}, small());
  for (std::size_t i = 0; i < 60; i += 2) {
    vmap::Frame f = sample_frames()[i];
    f.time_ns = 1403636579763555584LL + static_cast<std::int64_t>(i) * 50000000LL;  // EuRoC-like stamps
    f.timestamp = vmap::seconds_from_nanoseconds(static_cast<std::uint64_t>(f.time_ns));
    (void)mem.push(f);
  }
  const fs::path dir = vmap::test::scratch_dir("any_memory_export");
  const auto written = vmap::export_memory(mem, dir);
  CHECK(written == std::vector<std::string>{"key_images.txt", "loops.txt"});
  std::ifstream keys(dir / "key_images.txt");
  std::string header, first;
  std::getline(keys, header);
  std::getline(keys, first);
  CHECK(first == "0 1305031229.528748.jpg 1403636579.763555584");
}

TEST_CASE("AnyMemory: a query before any vocabulary is learned, with candidates far apart that compete, is answered") {
  // Every key image is verified by an engine that holds no frame (no vocabulary yet):
  // telling whether two verified candidates are one place must not read the views of
  // frames that engine never added (it read past an empty list and crashed).
  auto memory = vmap::AnyMemory::in_ram(vmap::PolicyStack{});
  for (std::size_t i = 0; i < 40; ++i) (void)memory.push(sample_frames()[i]);
  REQUIRE(memory.checked_key_images() == 0);
  REQUIRE(memory.key_images() > 10);
  const vmap::MemoryLocalization a = memory.localize(sample_frames()[37].image);
  CHECK(a.ok());
  REQUIRE(a.best());
  CHECK(memory.map().keys[a.best()->key].frame_index <= 37);
  CHECK(a.verified_candidates >= 2);
}
