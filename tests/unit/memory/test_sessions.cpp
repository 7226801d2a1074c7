// Sessions: several runs in one memory, each its own chain of key images, loops searched
// across them; a memory with sessions saves, loads, syncs into a store and resumes
// exactly; merging two memories equals building both runs into one.
#include "support/errors.hpp"
#include "support/memory_file.hpp"
#include "support/raw_sql.hpp"
#include "support/sample_memory.hpp"
#include "support/shared_data.hpp"

#include <vmap/memory/stacks.hpp>
#include <vmap/memory/store.hpp>
#include <vmap/memory/visual_memory.hpp>

#include <doctest/doctest.h>

#include <algorithm>
#include <cstdint>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <tuple>
#include <vector>

namespace {

using vmap::test::load_small_memory;

using vmap::test::sample_frames;

namespace fs = std::filesystem;
using vmap::test::error_of;
using vmap::test::raw_sql;
using vmap::test::sql_integer;
using vmap::test::make_small_memory;
using vmap::test::memory_estimator;
using vmap::test::small_memory_options;

/// `name` in this file's scratch folder, with nothing there (vmap::test::fresh_path).
std::filesystem::path sessions_path(const std::string& name) { return vmap::test::fresh_path("sessions", name); }

/// The sample frames first .. last - 1 (their own indices, as a run of that part reads them).
std::vector<vmap::Frame> part(std::size_t first, std::size_t last) {
  return {sample_frames().begin() + static_cast<std::ptrdiff_t>(first), sample_frames().begin() + static_cast<std::ptrdiff_t>(last)};
}

/// Two runs over the sample frames: 0-39, then 20-59 (revisiting half of the first).
const std::vector<vmap::Frame>& run1() {
  static const auto f = part(0, 40);
  return f;
}
const std::vector<vmap::Frame>& run2() {
  static const auto f = part(20, 60);
  return f;
}

vmap::OrbVisualMemory two_sessions(const vmap::MemoryOptions& o) {
  auto mem = make_small_memory(o);
  for (const auto& f : run1()) mem.push(f);
  mem.start_session();
  for (const auto& f : run2()) mem.push(f);
  return mem;
}

vmap::OrbVisualMemory reload(const vmap::OrbVisualMemory& m) {
  return vmap::OrbVisualMemory::deserialize(m.serialize(), "<memory>", vmap::OrbDescriptor{}, vmap::BruteForceMatcher{},
                                            memory_estimator(), vmap::InlierRatio{});
}

}  // namespace

TEST_CASE("sessions: each run is its own chain of key images; loops join them") {
  const auto o = small_memory_options();
  auto one = make_small_memory(o);
  for (const auto& f : run1()) one.push(f);
  auto alone = make_small_memory(o);
  for (const auto& f : run2()) alone.push(f);

  const auto mem = two_sessions(o);
  const std::size_t m1 = one.key_images();
  REQUIRE(mem.sessions().size() == 2);
  CHECK(mem.sessions()[0].first_key == 0);
  CHECK(mem.sessions()[0].first_frame == 0);
  CHECK(mem.sessions()[1].first_key == m1);
  CHECK(mem.sessions()[1].first_frame == run1().size());
  CHECK(mem.frames() == run1().size() + run2().size());
  CHECK(mem.key_images() == m1 + alone.key_images());
  CHECK(mem.session_of(m1 - 1) == 0);
  CHECK(mem.session_of(m1) == 1);
  CHECK(mem.session_of(mem.key_images() - 1) == 1);

  // The second session's key images and links are those of its run alone.
  for (std::size_t k = 0; k < alone.key_images(); ++k) {
    CHECK(mem.map().keys[m1 + k].frame_index == alone.map().keys[k].frame_index);
    if (k > 0) {
      CHECK(mem.map().pairs[m1 + k - 1].inliers == alone.map().pairs[k - 1].inliers);
      CHECK(mem.map().pairs[m1 + k - 1].similarity == alone.map().pairs[k - 1].similarity);
    }
  }
  // No link across the sessions: the pair there has no matches, and the graph no edge.
  const vmap::KeyPair& gap = mem.map().pairs[m1 - 1];
  CHECK(gap.matches == 0);
  CHECK(gap.inliers == 0);
  CHECK(gap.similarity == 0.0);
  CHECK(gap.status == vmap::VerificationStatus::too_few_matches);
  for (const auto& n : mem.neighbours(static_cast<std::uint32_t>(m1)))
    CHECK((n.kind != vmap::GraphNeighbour::Kind::link || n.key == m1 + 1));
  for (const auto& n : mem.neighbours(static_cast<std::uint32_t>(m1 - 1)))
    CHECK((n.kind != vmap::GraphNeighbour::Kind::link || n.key == m1 - 2));

  // The second run revisits frames 20-39: loops from the second session into the first.
  std::size_t across = 0;
  for (const auto& e : mem.loops()) {
    CHECK(e.link.key < e.from);
    if (e.from >= m1 && e.link.key < m1) {
      ++across;
      // The place rule between runs: a verified, confident pair.
      CHECK(e.link.inliers >= o.loops.decision.min_inliers);
      CHECK(e.link.confidence >= o.loops.decision.min_confidence);
    }
  }
  CHECK(across >= 3);
  // Within its window of 2 key images the second session's first key images find the
  // first session's last ones: a session start does not hide the run before it.
  const auto first_across = std::find_if(mem.loops().begin(), mem.loops().end(),
                                         [&](const vmap::LoopEdge& e) { return e.from >= m1 && e.link.key < m1; });
  REQUIRE(first_across != mem.loops().end());
  CHECK(first_across->from < m1 + 2 + 3);

  // Localization searches both sessions: a frame of the second run finds a key image.
  auto ask = reload(mem);
  const auto answer = ask.localize(sample_frames()[50].image);
  CHECK(answer.ok());

  // start_session is a no-op before the first frame and twice in a row.
  auto empty = make_small_memory(o);
  empty.start_session();
  CHECK(empty.sessions().size() == 1);
  auto twice = make_small_memory(o);
  twice.push(sample_frames()[0]);
  twice.start_session();
  twice.start_session();
  CHECK(twice.sessions().size() == 2);
  CHECK(vmap::test::error_of([&] { (void)twice.session_of(1); }).find("session_of: key 1 of 1") != std::string::npos);
}

TEST_CASE("sessions: the loops between two runs are the pairs' own, whichever run comes first; a run's own loops are its alone") {
  const auto o = small_memory_options();
  static const vmap::AnyVocabulary vocabulary = [] {
    std::vector<cv::Mat> sets;
    vmap::OrbDescriptor orb;
    for (std::size_t i = 0; i < sample_frames().size(); i += 4) sets.push_back(orb.extract(sample_frames()[i].image).descriptors);
    return vmap::AnyVocabulary::learn(sets, {.branching = 8, .depth = 3, .seed = 3});
  }();
  const auto build = [&](const std::vector<vmap::Frame>& a, const std::vector<vmap::Frame>& b) {
    vmap::OrbVisualMemory m(vmap::OrbDescriptor{}, vmap::BruteForceMatcher{}, memory_estimator(), vmap::InlierRatio{}, o,
                            vocabulary);
    for (const auto& f : a) m.push(f);
    if (!b.empty()) m.start_session();
    for (const auto& f : b) m.push(f);
    return m;
  };
  const auto ab = build(run1(), run2());
  const auto ba = build(run2(), run1());
  // Each pair between the runs by (frame of run 1's key image, frame of run 2's), with
  // its inliers: the verification is the pair's too.
  const auto across = [](const vmap::OrbVisualMemory& m, std::size_t run1_session) {
    std::map<std::pair<std::size_t, std::size_t>, int> out;
    for (const auto& e : m.loops()) {
      const std::size_t sf = m.session_of(e.from), sk = m.session_of(e.link.key);
      if (sf == sk) continue;
      const std::size_t f = m.map().keys[e.from].frame_index, k = m.map().keys[e.link.key].frame_index;
      CHECK(out.emplace(sf == run1_session ? std::pair(f, k) : std::pair(k, f), e.link.inliers).second);
    }
    return out;
  };
  const auto by_ab = across(ab, 0), by_ba = across(ba, 1);
  CHECK(by_ab.size() >= 3);
  CHECK(by_ab == by_ba);
  // The second session's own loops are those of its run in a memory of its own.
  const auto alone = build(run2(), {});
  const std::size_t m1 = ab.sessions()[1].first_key;
  std::vector<std::tuple<std::size_t, std::size_t, int>> own, by_alone;
  for (const auto& e : ab.loops())
    if (e.from >= m1 && e.link.key >= m1) own.emplace_back(e.from - m1, e.link.key - m1, e.link.inliers);
  for (const auto& e : alone.loops()) by_alone.emplace_back(e.from, e.link.key, e.link.inliers);
  CHECK(own == by_alone);
}

TEST_CASE("sessions: saved, loaded and resumed at any frame, a memory goes on as the uninterrupted one") {
  for (auto images : {vmap::ImageStorage::none, vmap::ImageStorage::png}) {
    CAPTURE(static_cast<int>(images));
    const auto o = small_memory_options(images);
    const auto whole = two_sessions(o);
    const std::string bytes = whole.serialize();
    CHECK(reload(whole).serialize() == bytes);
    // Stopped after every 9th frame of either run, and right after start_session.
    for (std::size_t stop : {9U, 27U, 40U, 41U, 58U, 70U}) {
      CAPTURE(stop);
      auto mem = make_small_memory(o);
      std::size_t pushed = 0;
      std::optional<vmap::OrbVisualMemory> cur(std::move(mem));
      const auto step = [&](const vmap::Frame& f) {
        if (pushed == stop) cur.emplace(reload(*cur));
        cur->push(f);
        ++pushed;
      };
      for (const auto& f : run1()) step(f);
      cur->start_session();
      if (pushed == stop) {
        cur.emplace(reload(*cur));
        CHECK(cur->sessions().size() == 2);
        CHECK(cur->selector().chain_open());
      }
      for (const auto& f : run2()) step(f);
      CHECK(cur->serialize() == bytes);
    }
  }
}

TEST_CASE("sessions: a store synced at every frame holds the sessions; reopened mid-run it goes on exactly") {
  const auto o = small_memory_options();
  const auto whole = two_sessions(o);
  const fs::path p = sessions_path("two.vmdb");
  {
    auto store = vmap::MemoryStore::create(p);
    auto mem = make_small_memory(o);
    for (const auto& f : run1()) {
      mem.push(f);
      store.sync(mem);
    }
    mem.start_session();
    store.sync(mem);  // a session with no frame yet is stored too
  }
  {
    auto store = vmap::MemoryStore::open(p);
    auto mem = load_small_memory(store);
    REQUIRE(mem.sessions().size() == 2);
    CHECK(mem.selector().chain_open());
    for (std::size_t i = 0; i < 18; ++i) {
      mem.push(run2()[i]);
      store.sync(mem);
    }
  }
  auto store = vmap::MemoryStore::open(p);
  auto mem = load_small_memory(store);
  for (std::size_t i = 18; i < run2().size(); ++i) {
    mem.push(run2()[i]);
    store.sync(mem);
  }
  CHECK(mem.serialize() == whole.serialize());
  CHECK(load_small_memory(store).serialize() == whole.serialize());
}

TEST_CASE("sessions: the store's sessions table, read without vmap; a version-1 store is read as one session") {
  const auto o = small_memory_options();
  const auto whole = two_sessions(o);
  const fs::path p = sessions_path("table.vmdb");
  {
    auto store = vmap::MemoryStore::create(p);
    store.sync(whole);
  }
  CHECK(sql_integer(p, "SELECT count(*) FROM sessions") == 2);
  CHECK(sql_integer(p, "SELECT first_key FROM sessions WHERE id = 1") ==
        static_cast<std::int64_t>(whole.sessions()[1].first_key));
  CHECK(sql_integer(p, "SELECT first_frame FROM sessions WHERE id = 1") == 40);
  CHECK(sql_integer(p, "SELECT count(*) FROM key_images WHERE id >= (SELECT first_key FROM sessions WHERE id = 1)") ==
        static_cast<std::int64_t>(whole.key_images() - whole.sessions()[1].first_key));
  CHECK(sql_integer(p, "PRAGMA user_version") == 4);

  // A store of the version 1 schema (one session, no sessions table, records of the
  // single-file format 3: `vmap memory convert` of the format-3 seed, tests/fuzz/corpus).
  const fs::path corpus = vmap::test::source_dir() / "tests/fuzz/corpus";
  const auto seed = vmap::OrbVisualMemory::deserialize(
      vmap::read_file(corpus / "memory/labels_gcs_v4.vmem", 1 << 20, "seed"), "labels_gcs_v4.vmem");
  const fs::path v1 = sessions_path("v1.vmdb");
  fs::copy_file(corpus / "memory_store/labels_gcs.vmdb", v1);
  CHECK(sql_integer(v1, "PRAGMA user_version") == 1);
  {
    auto reader = vmap::MemoryStore::open(v1, vmap::sqlite::Access::read);
    CHECK(reader.load<vmap::OrbVisualMemory>().serialize() == seed.serialize());
    CHECK(sql_integer(v1, "PRAGMA user_version") == 1);  // a reader changes nothing
  }
  // A writer brings it to version 4 (the same memory) and continues it with a session.
  std::string expected;
  {
    auto store = vmap::MemoryStore::open(v1);
    CHECK(sql_integer(v1, "PRAGMA user_version") == 4);
    auto mem = store.load<vmap::OrbVisualMemory>();
    CHECK(mem.serialize() == seed.serialize());
    mem.start_session();
    for (const auto& f : part(0, 20)) {
      mem.push(f, {}, std::vector<vmap::Detection>{});
      store.sync(mem);
    }
    store.flush();
    expected = mem.serialize();
  }
  auto back = vmap::MemoryStore::open(v1, vmap::sqlite::Access::read);
  CHECK(back.load<vmap::OrbVisualMemory>().serialize() == expected);
  CHECK(sql_integer(v1, "SELECT count(*) FROM sessions") == 2);
}

TEST_CASE("sessions: merging two memories equals building both runs into one; other policies are refused") {
  const auto o = small_memory_options();
  const auto whole = two_sessions(o);

  auto a = make_small_memory(o);
  for (const auto& f : run1()) a.push(f);
  auto b = make_small_memory(o);
  for (const auto& f : run2()) b.push(f);
  a.merge(std::move(b), "A", "B");
  CHECK(a.serialize() == whole.serialize());
  // Pushing on continues the second run as the built memory would (its frames numbered
  // after the run's last: indices increase within a session).
  auto built = reload(whole);
  REQUIRE(a.last_frame_index() == built.last_frame_index());
  for (std::size_t i = 0; i < 6; ++i) {
    vmap::Frame f = sample_frames()[i];
    f.index = *a.last_frame_index() + 1;
    a.push(f);
    built.push(f);
  }
  CHECK(a.serialize() == built.serialize());

  // A memory whose new session holds no frame yet: the other's first session takes its place.
  auto open = make_small_memory(o);
  for (const auto& f : run1()) open.push(f);
  open.start_session();
  auto b2 = make_small_memory(o);
  for (const auto& f : run2()) b2.push(f);
  open.merge(std::move(b2));
  CHECK(open.sessions().size() == 2);
  CHECK(open.serialize() == whole.serialize());

  // Into an empty memory: the other memory itself.
  auto empty = make_small_memory(o);
  auto c = make_small_memory(o);
  for (const auto& f : run1()) c.push(f);
  const std::string c_bytes = c.serialize();
  empty.merge(std::move(c));
  CHECK(empty.serialize() == c_bytes);

  // Another threshold: refused with both names, the memory unchanged.
  auto other_options = o;
  other_options.selector.tau = 0.4;
  auto d = make_small_memory(other_options);
  for (const auto& f : part(0, 10)) d.push(f);
  auto e = make_small_memory(o);
  for (const auto& f : part(0, 10)) e.push(f);
  const std::string e_bytes = e.serialize();
  const std::string msg = error_of([&] { e.merge(std::move(d), "memory 'e'", "memory 'd'"); });
  CHECK(msg.find("cannot merge memory 'd' into memory 'e'") != std::string::npos);
  CHECK(msg.find("options") != std::string::npos);
  CHECK(e.serialize() == e_bytes);
}

TEST_CASE("memory files: a frame count above 2^40 is an Error naming the section, also with a valid CRC") {
  const auto mem = two_sessions(small_memory_options());
  const std::string bytes = mem.serialize();
  const std::size_t keys = vmap::test::section_starts(bytes)[1];
  REQUIRE(bytes.substr(keys, 4) == "keys");
  for (const std::uint64_t count : {std::uint64_t{1} << 41, ~std::uint64_t{0}}) {
    std::string b = bytes;
    for (int i = 0; i < 8; ++i) b[keys + 16 + static_cast<std::size_t>(i)] = static_cast<char>((count >> (8 * i)) & 0xFF);
    const std::size_t length = vmap::test::section_starts(b)[2] - keys - 16;
    vmap::detail::BinaryWriter crc;
    crc.u32(vmap::detail::crc32(std::string_view(b).substr(keys + 16, length)));
    b.replace(keys + 12, 4, crc.data());
    const std::string msg = error_of([&] {
      (void)vmap::OrbVisualMemory::deserialize(b, "m.vmem", vmap::OrbDescriptor{}, vmap::BruteForceMatcher{},
                                               memory_estimator(), vmap::InlierRatio{});
    });
    INFO(msg);
    CHECK(msg.find("m.vmem") != std::string::npos);
    CHECK(msg.find("section 'keys'") != std::string::npos);
    CHECK(msg.find("is more than a memory can hold (2^40)") != std::string::npos);
  }
}

TEST_CASE("sessions: a damaged session table is an Error naming the section") {
  const auto mem = two_sessions(small_memory_options());
  const std::string bytes = mem.serialize();
  // "sess" is the last section (tag, length, CRC, then its count and the second
  // session's first key image and frame): a bad first key image, with a valid CRC.
  const std::size_t start = vmap::test::section_starts(bytes).back();
  REQUIRE(bytes.substr(start, 4) == "sess");
  const std::size_t at = bytes.size() - 16;
  for (const std::uint64_t bad_key : {std::uint64_t{0}, std::uint64_t{1000}}) {
    std::string b = bytes;
    for (int i = 0; i < 8; ++i) b[at + static_cast<std::size_t>(i)] = static_cast<char>((bad_key >> (8 * i)) & 0xFF);
    vmap::detail::BinaryWriter crc;
    crc.u32(vmap::detail::crc32(std::string_view(b).substr(start + 16)));
    b.replace(start + 12, 4, crc.data());
    const std::string msg = error_of([&] {
      (void)vmap::OrbVisualMemory::deserialize(b, "m.vmem", vmap::OrbDescriptor{}, vmap::BruteForceMatcher{},
                                               memory_estimator(), vmap::InlierRatio{});
    });
    INFO(msg);
    CHECK(msg.find("m.vmem") != std::string::npos);
    CHECK(msg.find("section 'sess'") != std::string::npos);
    CHECK(msg.find("does not start after session 0") != std::string::npos);
  }
}
