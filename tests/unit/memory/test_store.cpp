// MemoryStore: a memory synced frame by frame into an SQLite file loads back as the same
// memory (the same file bytes), resumes exactly, refuses a second writer, serves readers
// while it is written, turns bad files into Errors naming the memory, and reports a
// transaction that failed in its writer thread at the next sync or flush.
#include "support/errors.hpp"
#include "support/raw_sql.hpp"
#include "support/sample_memory.hpp"
#include "support/shared_data.hpp"

#include <vmap/io/sqlite.hpp>
#include <vmap/memory/stacks.hpp>
#include <vmap/memory/store.hpp>
#include <vmap/memory/visual_memory.hpp>

#include <doctest/doctest.h>

#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <optional>
#include <string>
#include <vector>

namespace {

using vmap::test::load_small_memory;

using vmap::test::sample_frames;

using vmap::test::error_of;
using vmap::test::raw_sql;
using vmap::test::sql_integer;
namespace fs = std::filesystem;

using vmap::test::memory_estimator;

/// `name` in this file's scratch folder, with nothing there (vmap::test::fresh_path).
std::filesystem::path store_path(const std::string& name) { return vmap::test::fresh_path("store", name); }

vmap::MemoryOptions options(vmap::ImageStorage images) { return vmap::test::small_memory_options(images); }
vmap::OrbVisualMemory make(const vmap::MemoryOptions& o) { return vmap::test::make_small_memory(o); }

}  // namespace

TEST_CASE("store: a memory synced at every frame loads back as the same memory, for each pixel storage") {
  for (auto images : {vmap::ImageStorage::none, vmap::ImageStorage::png, vmap::ImageStorage::jpeg}) {
    CAPTURE(static_cast<int>(images));
    const fs::path file = store_path("every_frame.vmdb");
    auto store = vmap::MemoryStore::create(file);
    auto memory = make(options(images));
    std::size_t synced_keys = 0;
    for (const auto& f : sample_frames()) {
      memory.push(f);
      store.sync(memory);
      // Each sync wrote exactly the key images made since the last one.
      CHECK(store.key_images() == memory.key_images());
      CHECK(store.key_images() >= synced_keys);
      synced_keys = store.key_images();
    }
    REQUIRE(memory.loops().size() > 0);
    REQUIRE(memory.database().size() > 0);
    const auto back = load_small_memory(store);
    CHECK(back.key_images() == memory.key_images());
    CHECK(back.loops().size() == memory.loops().size());
    CHECK(back.database().ids() == memory.database().ids());
    if (images != vmap::ImageStorage::jpeg) {
      CHECK(back.serialize() == memory.serialize());
    } else {
      // Each key image's JPEG was encoded once, when its row was written: the stored
      // pixels are the ones decoded from it, within JPEG's loss of the original.
      for (std::size_t k = 0; k < back.key_images(); ++k)
        CHECK(cv::norm(back.map().keys[k].image, memory.map().keys[k].image, cv::NORM_L1) /
                  static_cast<double>(back.map().keys[k].image.total()) < 3.0);
    }
  }
}

// sync() hands its rows to the store's writer thread and returns before they are
// committed, while the memory goes on at once. Whatever the timing, every sync is stored:
// another connection sees all of them after flush(), and the store loads as the memory,
// also when the store object was moved with a sync in flight.
TEST_CASE("store: syncs committed in the writer thread: after each flush a reader sees every sync") {
  const fs::path file = store_path("async.vmdb");
  std::optional<vmap::MemoryStore> store;
  store.emplace(vmap::MemoryStore::create(file));
  auto reader = vmap::MemoryStore::open(file, vmap::sqlite::Access::read);
  auto memory = make(options(vmap::ImageStorage::png));
  std::size_t flushes = 0;
  for (std::size_t i = 0; i < sample_frames().size(); ++i) {
    memory.push(sample_frames()[i]);
    store->sync(memory);
    if (i == 25) {
      vmap::MemoryStore moved = std::move(*store);
      store.emplace(std::move(moved));
    }
    if (i % 15 == 14) {
      store->flush();
      ++flushes;
      CHECK(sql_integer(file, "SELECT count(*) FROM key_images") == static_cast<std::int64_t>(memory.key_images()));
      CHECK(sql_integer(file, "SELECT count(*) FROM loops") == static_cast<std::int64_t>(memory.loops().size()));
      CHECK(sql_integer(file, "SELECT count(bow) FROM key_images") ==
            static_cast<std::int64_t>(memory.database().size()));
      CHECK(load_small_memory(reader).serialize() == memory.serialize());
    }
  }
  CHECK(flushes == 4);
  REQUIRE(memory.loops().size() > 0);
  store->flush();
  CHECK(load_small_memory(reader).serialize() == memory.serialize());
  CHECK(load_small_memory(*store).serialize() == memory.serialize());
}

// A transaction that fails in the writer thread (here: a row another program inserted
// where the next key image goes) is not lost: the next sync() or flush() throws it as a
// vmap::Error naming the store. It stored nothing, the destructor waits for it without
// throwing, and once the cause is gone the next sync writes its rows again.
TEST_CASE("store: a sync that fails in the writer thread is an Error at the next sync or flush, then written again") {
  const auto o = options(vmap::ImageStorage::none);
  auto whole = make(o);
  for (const auto& f : sample_frames()) whole.push(f);

  const fs::path file = store_path("failed.vmdb");
  std::optional<vmap::MemoryStore> store;
  store.emplace(vmap::MemoryStore::create(file));
  auto memory = make(o);
  std::size_t i = 0;
  for (; i < 20; ++i) {
    memory.push(sample_frames()[i]);
    store->sync(memory);
  }
  store->flush();
  const std::size_t m = memory.key_images();
  REQUIRE(m >= 2);
  raw_sql(file, "INSERT INTO key_images(id, frame_index, timestamp, time_ns, name, keypoints, record, detections, crc) "
                "VALUES(" + std::to_string(m) + ", 0, 0, 0, 'intruder', 0, x'', x'', 0)");
  // Pushed and synced up to the frame that makes key image m: the sync that writes it
  // returns, and fails in the writer thread.
  while (memory.key_images() == m) {
    REQUIRE(i < sample_frames().size());
    memory.push(sample_frames()[i++]);
    store->sync(memory);
  }
  const std::string failed = error_of([&] { store->sync(memory); });
  CHECK(failed.find("memory '" + file.string() + "' insert a key image: UNIQUE constraint failed: key_images.id") == 0);
  CHECK(failed.find("the next sync writes its rows again") != std::string::npos);
  // It stored nothing: the key images before it and the intruder, no link to key image m.
  CHECK(store->key_images() == m);
  CHECK(sql_integer(file, "SELECT count(*) FROM key_images") == static_cast<std::int64_t>(m + 1));
  CHECK(sql_integer(file, "SELECT count(*) FROM links") == static_cast<std::int64_t>(m - 1));
  // While the cause remains, each sync fails again; flush() reports it as well.
  store->sync(memory);
  CHECK(error_of([&] { store->flush(); }) == failed);
  CHECK(error_of([&] { store->flush(); }) == "no error");  // reported once
  // The destructor waits for a failing sync and does not throw.
  store->sync(memory);
  store.reset();
  CHECK(sql_integer(file, "SELECT count(*) FROM key_images") == static_cast<std::int64_t>(m + 1));

  raw_sql(file, "DELETE FROM key_images WHERE name = 'intruder'");
  store.emplace(vmap::MemoryStore::open(file));
  for (; i < sample_frames().size(); ++i) {
    memory.push(sample_frames()[i]);
    store->sync(memory);
  }
  store->flush();
  CHECK(memory.serialize() == whole.serialize());
  CHECK(load_small_memory(*store).serialize() == whole.serialize());
}

// The key images' pixels are counted from their recorded sizes before any is decoded:
// a memory (file or store) holding more than the budget is refused, naming the limit.
TEST_CASE("store: a memory's key images are loaded within a pixel budget") {
  const fs::path file = store_path("budget.vmdb");
  auto store = vmap::MemoryStore::create(file);
  auto memory = make(options(vmap::ImageStorage::png));
  for (const auto& f : sample_frames()) memory.push(f);
  store.sync(memory);
  const std::uint64_t keys = memory.key_images();
  REQUIRE(keys >= 3);
  const std::uint64_t pixels = memory.map().keys[0].image.total();  // 640x480 each
  CHECK(pixels == 640 * 480);
  // The selector's pending frame (its last frame, a possible next key image) counts too.
  const std::uint64_t held = (keys + 1) * pixels;
  const auto with = [](vmap::MapLoadOptions limits) {
    return [limits](const std::string& bytes) {
      return vmap::OrbVisualMemory::deserialize(bytes, "m", vmap::OrbDescriptor{}, vmap::BruteForceMatcher{}, memory_estimator(),
                                                vmap::InlierRatio{}, limits);
    };
  };
  const std::string bytes = memory.serialize();
  CHECK(with({.max_total_image_pixels = held})(bytes).serialize() == bytes);
  // The pending frame is the one over the budget: its section names it.
  CHECK(error_of([&] { (void)with({.max_total_image_pixels = held - 1})(bytes); })
            .find("memory file 'm' section 'selc': the key images hold more than " + std::to_string(held - 1) +
                  " pixels together (MapLoadOptions::max_total_image_pixels)") == 0);
  CHECK(error_of([&] { (void)with({.max_image_pixels = pixels - 1})(bytes); })
            .find("key image of 640x480 pixels is above the limit of 307199 pixels (MapLoadOptions::max_image_pixels)") !=
        std::string::npos);
  // The store's load takes the same limits after the policies.
  CHECK(error_of([&] {
          (void)store.load<vmap::OrbVisualMemory>(vmap::OrbDescriptor{}, vmap::BruteForceMatcher{}, memory_estimator(),
                                                  vmap::InlierRatio{}, vmap::MapLoadOptions{.max_total_image_pixels = 2 * pixels});
        }).find("the key images hold more than 614400 pixels together") != std::string::npos);
}

TEST_CASE("store: a memory loaded without decoding its pixels answers the same and refuses to write pixels") {
  const fs::path file = store_path("undecoded.vmdb");
  std::optional<vmap::MemoryStore> store;
  store.emplace(vmap::MemoryStore::create(file));
  auto memory = make(options(vmap::ImageStorage::png));
  for (std::size_t i = 0; i < 50; ++i) memory.push(sample_frames()[i]);
  store->sync(memory);
  store.reset();
  store.emplace(vmap::MemoryStore::open(file));
  vmap::MapLoadOptions undecoded;
  undecoded.decode_images = false;
  auto lean = store->load<vmap::OrbVisualMemory>(vmap::OrbDescriptor{}, vmap::BruteForceMatcher{}, memory_estimator(),
                                                 vmap::InlierRatio{}, undecoded);
  REQUIRE(lean.key_images() == memory.key_images());
  for (std::size_t k = 0; k < lean.key_images(); ++k) {
    CHECK(!memory.map().keys[k].image.empty());
    CHECK(lean.map().keys[k].image.empty());
  }
  // Everything but the pixels is there: the same file without pixels, the same answers.
  CHECK(lean.serialize(vmap::ImageStorage::none) == memory.serialize(vmap::ImageStorage::none));
  for (std::size_t i = 50; i < 60; ++i) {
    const auto a = lean.localize(sample_frames()[i].image);
    const auto b = memory.localize(sample_frames()[i].image);
    CHECK(a.status == b.status);
    CHECK(a.confidence == b.confidence);
  }
  // It cannot write the pixels it did not read: refused, the store unchanged.
  const std::string refused = error_of([&] { (void)lean.serialize(); });
  CHECK(refused.find("VisualMemory::serialize: the memory was loaded without its key images' pixels") == 0);
  const auto before = fs::file_size(file);
  CHECK(error_of([&] { store->sync(lean); }).find("MemoryStore::sync: the memory was loaded without") == 0);
  CHECK(fs::file_size(file) == before);
  // Loaded with its pixels (lossless PNG here) it writes them again.
  CHECK(load_small_memory(*store).serialize() == memory.serialize());
}

TEST_CASE("store: stopped and reopened every few frames, the memory goes on exactly as an uninterrupted run") {
  const auto o = options(vmap::ImageStorage::png);
  auto whole = make(o);
  for (const auto& f : sample_frames()) whole.push(f);
  for (std::size_t every : {5U, 17U}) {
    CAPTURE(every);
    const fs::path file = store_path("resumed.vmdb");
    std::optional<vmap::MemoryStore> store;
    std::optional<vmap::OrbVisualMemory> memory;
    store.emplace(vmap::MemoryStore::create(file));
    memory.emplace(make(o));
    for (std::size_t i = 0; i < sample_frames().size(); ++i) {
      if (i > 0 && i % every == 0) {
        memory.reset();
        store.reset();
        store.emplace(vmap::MemoryStore::open(file));
        memory.emplace(load_small_memory(*store));
      }
      memory->push(sample_frames()[i]);
      store->sync(*memory);
    }
    CHECK(memory->serialize() == whole.serialize());
    CHECK(load_small_memory(*store).serialize() == whole.serialize());
  }
}

// The selector defers the homography degeneracy test of I_{j-1}'s score (the estimator
// checks degeneracy by default); the store syncs that score deferred, with its inlier
// mask, and a memory loaded from it completes the test when its state is read: equal to
// the memory that was synced, and going on as it does.
TEST_CASE("store: I_{j-1}'s score synced with its degeneracy test deferred loads complete and goes on exactly") {
  const auto o = options(vmap::ImageStorage::none);
  const vmap::FundamentalEstimator checking;  // check_degeneracy on
  REQUIRE(checking.options().check_degeneracy);
  const auto make_checking = [&] {
    return vmap::OrbVisualMemory(vmap::OrbDescriptor{}, vmap::BruteForceMatcher{}, checking, vmap::InlierRatio{}, o);
  };
  const auto load_checking = [&](vmap::MemoryStore& store) {
    return store.load<vmap::OrbVisualMemory>(vmap::OrbDescriptor{}, vmap::BruteForceMatcher{}, checking,
                                             vmap::InlierRatio{});
  };
  auto whole = make_checking();
  for (const auto& f : sample_frames()) whole.push(f);
  const fs::path file = store_path("deferred.vmdb");
  std::optional<vmap::MemoryStore> store;
  std::optional<vmap::OrbVisualMemory> memory;
  store.emplace(vmap::MemoryStore::create(file));
  memory.emplace(make_checking());
  int deferred = 0, reopened_deferred = 0;
  for (std::size_t i = 0; i < sample_frames().size(); ++i) {
    memory->push(sample_frames()[i]);
    store->sync(*memory);
    const bool is_deferred = memory->selector().deferred_state().degeneracy_deferred;
    deferred += is_deferred ? 1 : 0;
    if (i % 4 == 3) {
      CHECK(load_checking(*store).serialize() == memory->serialize());
      // Stopped here and reopened: the rest of the run from the loaded memory.
      memory.reset();
      store.reset();
      store.emplace(vmap::MemoryStore::open(file));
      memory.emplace(load_checking(*store));
      reopened_deferred += is_deferred ? 1 : 0;
    }
  }
  CHECK(deferred > 10);
  CHECK(reopened_deferred > 3);
  CHECK(memory->serialize() == whole.serialize());
}

TEST_CASE("store: a working memory of 3 key images answers as a memory that holds every key image's features") {
  const auto o = options(vmap::ImageStorage::none);
  // The first 50 frames are mapped; the last 10 are localized, then mapped on.
  const std::vector<vmap::Frame> kept(sample_frames().begin(), sample_frames().begin() + 50);
  const std::vector<vmap::Frame> later(sample_frames().begin() + 50, sample_frames().end());
  auto whole = make(o);
  for (const auto& f : kept) whole.push(f);
  REQUIRE(whole.key_images() >= 10);

  const fs::path file = store_path("working.vmdb");
  std::optional<vmap::MemoryStore> store;
  store.emplace(vmap::MemoryStore::create(file));
  auto bounded = make(o);
  store->bound(bounded, 3);
  CHECK(bounded.working_memory() == 3);
  std::size_t most_held = 0;
  for (const auto& f : kept) {
    bounded.push(f);
    store->sync(bounded);
    std::size_t now = 0;
    for (std::size_t k = 0; k < bounded.key_images(); ++k) now += bounded.holds_features(k) ? 1 : 0;
    most_held = std::max(most_held, now);
  }
  // The bound held after every sync; released key images keep no keypoints in RAM.
  CHECK(most_held == 3);
  const std::size_t m = bounded.key_images();
  REQUIRE(m == whole.key_images());
  for (std::size_t k = 0; k < m; ++k) {
    CAPTURE(k);
    CHECK(bounded.holds_features(k) == (k + 3 >= m));
    CHECK(bounded.map().keys[k].features.keypoints.empty() == (k + 3 < m));
    // Read back from the store, a key image's features are the ones it was made with.
    const vmap::Features back = bounded.key_features(static_cast<std::uint32_t>(k));
    const vmap::Features& original = whole.map().keys[k].features;
    REQUIRE(back.size() == original.size());
    CHECK(back.keypoints.front().pt == original.keypoints.front().pt);
    CHECK(cv::norm(back.descriptors, original.descriptors, cv::NORM_HAMMING) == 0.0);
  }
  // The same loops (features read from the store for the candidates, while the syncs
  // commit in the writer thread), the same file, the same localizations.
  REQUIRE(whole.loops().size() > 0);
  REQUIRE(bounded.loops().size() == whole.loops().size());
  for (std::size_t i = 0; i < whole.loops().size(); ++i) {
    CHECK(bounded.loops()[i].from == whole.loops()[i].from);
    CHECK(bounded.loops()[i].link.key == whole.loops()[i].link.key);
    CHECK(bounded.loops()[i].link.inliers == whole.loops()[i].link.inliers);
  }
  CHECK(bounded.serialize() == whole.serialize());
  std::size_t answered = 0;
  for (const auto& f : later) {
    const auto a = bounded.localize(f.image);
    const auto b = whole.localize(f.image);
    CHECK(a.status == b.status);
    CHECK(a.confidence == b.confidence);
    REQUIRE(a.matches.size() == b.matches.size());
    for (std::size_t i = 0; i < a.matches.size(); ++i) {
      CHECK(a.matches[i].key == b.matches[i].key);
      CHECK(a.matches[i].inliers == b.matches[i].inliers);
      CHECK(a.matches[i].similarity == b.matches[i].similarity);
    }
    answered += a.ok() && !bounded.holds_features(a.best()->key) ? 1 : 0;
  }
  // Some answers are key images whose features were read from the store.
  CHECK(answered > 0);
  // Loaded again holding 2 key images' features (the others read without them), it is
  // the same memory and goes on as the whole run.
  store.reset();  // one writer at a time
  vmap::MemoryStore again = vmap::MemoryStore::open(file);
  auto resumed = again.load_bounded<vmap::OrbVisualMemory>(2, vmap::OrbDescriptor{}, vmap::BruteForceMatcher{},
                                                            memory_estimator(), vmap::InlierRatio{});
  CHECK(resumed.working_memory() == 2);
  CHECK(!resumed.holds_features(m - 3));
  CHECK(resumed.map().keys[m - 3].features.keypoints.empty());
  CHECK(resumed.holds_features(m - 2));
  CHECK(resumed.map().keys[m - 2].features.size() == whole.map().keys[m - 2].features.size());
  CHECK(resumed.serialize() == bounded.serialize());
  CHECK_THROWS_AS((void)again.load_bounded<vmap::OrbVisualMemory>(0), vmap::Error);
  // Bounding a memory this store does not hold is refused, nothing released.
  auto stranger = make(o);
  for (std::size_t i = 0; i < 5; ++i) stranger.push(kept[i]);
  CHECK(error_of([&] { again.bound(stranger, 1); }).find("use the memory loaded from this store") != std::string::npos);
  CHECK(stranger.working_memory() == 0);
  CHECK(stranger.holds_features(0));
  for (const auto& f : later) {
    resumed.push(f);
    again.sync(resumed);
    whole.push(f);
  }
  CHECK(resumed.serialize() == whole.serialize());
  CHECK(load_small_memory(again).serialize() == whole.serialize());

  CHECK_THROWS_AS(bounded.bound_features(0, again.features()), vmap::Error);
  const auto source = again.features();
  CHECK(error_of([&] { (void)source(100000); }).find("holds no key image 100000") != std::string::npos);
}

TEST_CASE("store: one writer at a time; readers load the last sync while the writer goes on") {
  const fs::path file = store_path("shared.vmdb");
  auto writer = vmap::MemoryStore::create(file);
  auto memory = make(options(vmap::ImageStorage::none));
  for (std::size_t i = 0; i < 30; ++i) memory.push(sample_frames()[i]);
  writer.sync(memory);
  writer.flush();  // sync() returns before its commit; a reader sees committed syncs
  const std::size_t first = memory.key_images();

  const std::string second = error_of([&] { (void)vmap::MemoryStore::open(file); });
  CHECK(second.find("memory '" + file.string() + "' is being written by another program") != std::string::npos);

  auto reader = vmap::MemoryStore::open(file, vmap::sqlite::Access::read);
  CHECK(load_small_memory(reader).key_images() == first);
  for (std::size_t i = 30; i < sample_frames().size(); ++i) memory.push(sample_frames()[i]);
  REQUIRE(memory.key_images() > first);
  writer.sync(memory);
  writer.flush();
  // The reader's next load sees the writer's new sync; a reader cannot write.
  CHECK(load_small_memory(reader).serialize() == memory.serialize());
  CHECK(error_of([&] { reader.sync(memory); }).find("is open read-only") != std::string::npos);
}

TEST_CASE("store: a memory is synced only into its own store") {
  const fs::path file = store_path("own.vmdb");
  auto memory = make(options(vmap::ImageStorage::none));
  for (std::size_t i = 0; i < 40; ++i) memory.push(sample_frames()[i]);
  {
    auto store = vmap::MemoryStore::create(file);
    store.sync(memory);
  }
  // A shorter memory: the store holds more than it.
  auto shorter = make(options(vmap::ImageStorage::none));
  for (std::size_t i = 0; i < 10; ++i) shorter.push(sample_frames()[i]);
  {
    auto store = vmap::MemoryStore::open(file);
    CHECK(error_of([&] { store.sync(shorter); }).find("use the memory loaded from this store") != std::string::npos);
  }
  // Another memory (a higher tau: more key images) whose key image of the store's last
  // index is another frame.
  auto o = options(vmap::ImageStorage::none);
  o.selector.tau = 0.6;
  auto other = make(o);
  for (const auto& f : sample_frames()) other.push(f);
  const std::size_t last = memory.key_images() - 1;
  REQUIRE(other.key_images() > last);
  REQUIRE(other.map().keys[last].frame_index != memory.map().keys[last].frame_index);
  {
    auto store = vmap::MemoryStore::open(file);
    CHECK(error_of([&] { store.sync(other); }).find("holds another memory") != std::string::npos);
  }
  CHECK(error_of([&] { (void)vmap::MemoryStore::create(file); }).find("exists already") != std::string::npos);
}

TEST_CASE("store: a .vmem memory file converts to a store that loads as the same memory") {
  auto memory = make(options(vmap::ImageStorage::png));
  for (const auto& f : sample_frames()) memory.push(f);
  const fs::path vmem = store_path("converted.vmem");
  memory.save(vmem);
  const auto loaded = vmap::OrbVisualMemory::load(vmem, vmap::OrbDescriptor{}, vmap::BruteForceMatcher{}, memory_estimator(),
                                                  vmap::InlierRatio{});
  const fs::path file = store_path("converted.vmdb");
  auto store = vmap::MemoryStore::create(file);
  store.sync(loaded);
  CHECK(load_small_memory(store).serialize() == memory.serialize());
}

TEST_CASE("store: files that are not stores, other versions and damaged rows are Errors naming the memory") {
  const fs::path missing = store_path("missing.vmdb");
  CHECK(error_of([&] { (void)vmap::MemoryStore::open(missing); }).find("'" + missing.string() + "' does not exist") !=
        std::string::npos);

  const fs::path text = store_path("text.vmdb");
  std::ofstream(text) << "not a database at all, but long enough to be looked at as one\n";
  CHECK(error_of([&] { (void)vmap::MemoryStore::open(text, vmap::sqlite::Access::read); }).find(text.string()) !=
        std::string::npos);

  // A creation killed before its tables were written leaves an empty file.
  const fs::path empty = store_path("empty.vmdb");
  std::ofstream(empty).close();
  CHECK(error_of([&] { (void)vmap::MemoryStore::open(empty); }).find("is empty: its creation was interrupted") !=
        std::string::npos);
  {
    // Created, never synced: open, but nothing to load.
    const fs::path unsynced = store_path("unsynced.vmdb");
    (void)vmap::MemoryStore::create(unsynced);
    auto store = vmap::MemoryStore::open(unsynced, vmap::sqlite::Access::read);
    CHECK(!store.synced());
    CHECK(error_of([&] { (void)load_small_memory(store); }).find("holds no 'options' state") != std::string::npos);
  }

  const fs::path foreign = store_path("foreign.vmdb");
  raw_sql(foreign, "CREATE TABLE t(x)");
  CHECK(error_of([&] { (void)vmap::MemoryStore::open(foreign); }).find("is not a vmap memory store") != std::string::npos);

  auto memory = make(options(vmap::ImageStorage::none));
  for (std::size_t i = 0; i < 30; ++i) memory.push(sample_frames()[i]);
  const fs::path file = store_path("damaged.vmdb");
  {
    auto store = vmap::MemoryStore::create(file);
    store.sync(memory);
  }
  raw_sql(file, "PRAGMA user_version = 5");
  CHECK(error_of([&] { (void)vmap::MemoryStore::open(file); })
            .find("has store version 5; this build reads versions 1 to 4") != std::string::npos);
  raw_sql(file, "PRAGMA user_version = 4");

  // A key image's record cut short, a missing key image, a descriptor blob of another
  // width: each an Error from the memory's own checks, naming the store.
  for (const std::string& damage :
       {std::string("UPDATE key_images SET record = substr(record, 1, 100) WHERE id = 1"),
        std::string("DELETE FROM key_images WHERE id = 1"), std::string("UPDATE links SET record = x'00' WHERE key = 1"),
        std::string("UPDATE meta SET value = x'0102' WHERE name = 'options'"),
        std::string("DELETE FROM meta WHERE name = 'selector'")}) {
    CAPTURE(damage);
    const fs::path copy = store_path("damaged_copy.vmdb");
    fs::copy_file(file, copy);
    raw_sql(copy, damage);
    auto store = vmap::MemoryStore::open(copy, vmap::sqlite::Access::read);
    const std::string e = error_of([&] { (void)load_small_memory(store); });
    CHECK(e.find(copy.string()) != std::string::npos);
    CHECK(e != "no error");
  }
}

TEST_CASE("store: every row is checked: a flipped bit, a column that differs from its record, a loop row gone or twice") {
  auto memory = make(options(vmap::ImageStorage::none));
  for (std::size_t i = 0; i < 20; ++i) memory.push(sample_frames()[i]);
  memory.start_session();
  for (std::size_t i = 0; i < 20; ++i) memory.push(sample_frames()[i]);
  REQUIRE(memory.loops().size() >= 2);
  const fs::path file = store_path("rows.vmdb");
  {
    auto store = vmap::MemoryStore::create(file);
    store.sync(memory);
  }
  const auto error_after = [&](const std::string& damage) {
    const fs::path copy = store_path("rows_copy.vmdb");
    fs::copy_file(file, copy);
    raw_sql(copy, damage);
    const std::string e = error_of([&] {
      auto store = vmap::MemoryStore::open(copy, vmap::sqlite::Access::read);
      (void)load_small_memory(store);
    });
    const std::string who = "memory '" + copy.string() + "' is corrupt: ";
    REQUIRE(e.starts_with(who));
    return e.substr(who.size());
  };
  // One bit of a key image's record (its pose or features): the row's CRC-32.
  CHECK(error_after("UPDATE key_images SET record = CAST(substr(record, 1, 60) || CASE WHEN substr(record, 61, 1) = "
                    "x'00' THEN x'01' ELSE x'00' END || substr(record, 62) AS BLOB) WHERE id = 3") ==
        "the checksum of key image 3 does not match");
  // The plain columns SQL readers see are compared with the record they repeat.
  for (const char* column : {"frame_index = frame_index + 1", "timestamp = timestamp + 1", "time_ns = time_ns + 1",
                             "name = 'other.png'"})
    CHECK(error_after(std::string("UPDATE key_images SET ") + column + " WHERE id = 5") ==
          "the columns of key image 5 do not match its record");
  // A state or note twice (in a table remade without its primary key).
  CHECK(error_after("CREATE TABLE meta2(name TEXT NOT NULL, value BLOB NOT NULL, crc INTEGER NOT NULL); INSERT INTO "
                    "meta2 SELECT * FROM meta; INSERT INTO meta2 SELECT * FROM meta WHERE name = 'options'; DROP TABLE "
                    "meta; ALTER TABLE meta2 RENAME TO meta") == "its meta table holds 'options' more than once");
  // Loop rows against the count the state records.
  const std::string loops = std::to_string(memory.loops().size());
  CHECK(error_after("DELETE FROM loops WHERE id = (SELECT max(id) FROM loops)").find(
            std::to_string(memory.loops().size() - 1) + " loop edges") != std::string::npos);
  CHECK(error_after("INSERT INTO loops SELECT id + 1000, from_key, to_key, inliers, confidence, record, crc FROM loops "
                    "WHERE id = (SELECT max(id) FROM loops)") ==
        "loop edge " + std::to_string(memory.loops().size() - 1 + 1000) + " where " + loops + " was expected");
}

TEST_CASE("store: a store in a folder the reader cannot write is read (as immutable); a stray journal is explained") {
  auto memory = make(options(vmap::ImageStorage::none));
  for (std::size_t i = 0; i < 12; ++i) memory.push(sample_frames()[i]);
  const fs::path file = store_path("read_only.vmdb");
  {
    auto store = vmap::MemoryStore::create(file);
    store.sync(memory);
  }
  // A folder this process cannot write, as read-only media are: a child process reads
  // the store as user 'nobody' when the tests run as root (root writes anywhere), or
  // with the folder made read-only otherwise.
  char tmpl[] = "/tmp/vmap-read-only-XXXXXX";
  REQUIRE(::mkdtemp(tmpl) != nullptr);
  const fs::path folder = tmpl;
  fs::copy_file(file, folder / "m.vmdb");
  ::chmod((folder / "m.vmdb").c_str(), 0644);
  ::chmod(folder.c_str(), 0555);
  const pid_t child = ::fork();
  REQUIRE(child >= 0);
  if (child == 0) {
    int code = 0;
    try {
      if (::getuid() == 0 && (::setgid(65534) != 0 || ::setuid(65534) != 0)) ::_exit(3);
      if (::access(folder.c_str(), W_OK) == 0) ::_exit(4);  // the folder is writable after all
      auto store = vmap::MemoryStore::open(folder / "m.vmdb", vmap::sqlite::Access::read);
      code = load_small_memory(store).key_images() == memory.key_images() ? 0 : 1;
    } catch (...) {
      code = 2;
    }
    ::_exit(code);
  }
  int status = 0;
  REQUIRE(::waitpid(child, &status, 0) == child);
  CHECK(WIFEXITED(status));
  CHECK(WEXITSTATUS(status) == 0);
  CHECK(!fs::exists(folder / "m.vmdb-shm"));  // nothing was created there
  ::chmod(folder.c_str(), 0755);
  fs::remove_all(folder);

  // A rollback journal beside a store (not vmap's: its stores use a write-ahead log)
  // makes SQLite refuse readers; the message says why and what to do.
  const fs::path journaled = store_path("journaled.vmdb");
  fs::copy_file(file, journaled);
  {
    std::ofstream j(journaled.string() + "-journal", std::ios::binary);
    j << std::string(4096, 'j');
  }
  const std::string e = error_of([&] {
    auto store = vmap::MemoryStore::open(journaled, vmap::sqlite::Access::read);
    (void)load_small_memory(store);
  });
  CHECK(e.find("attempt to write a readonly database (a rollback journal '" + journaled.string() +
               "-journal' lies beside it") != std::string::npos);
  fs::remove(journaled.string() + "-journal");
  auto store = vmap::MemoryStore::open(journaled, vmap::sqlite::Access::read);
  CHECK(load_small_memory(store).key_images() == memory.key_images());
}

namespace {

/// Appends `junk` to key image `id`'s record blob and writes the crc the store would
/// have written for the padded row, as a program editing the file could: the checksum
/// then holds, and only the record's own length can tell.
void pad_key_record(const fs::path& p, std::int64_t id, const std::string& junk) {
  sqlite3* db = nullptr;
  REQUIRE(sqlite3_open(p.c_str(), &db) == SQLITE_OK);
  sqlite3_stmt* q = nullptr;
  REQUIRE(sqlite3_prepare_v2(db, "SELECT record, detections FROM key_images WHERE id = ?", -1, &q, nullptr) == SQLITE_OK);
  sqlite3_bind_int64(q, 1, id);
  REQUIRE(sqlite3_step(q) == SQLITE_ROW);
  const auto blob = [&](int c) {
    const void* b = sqlite3_column_blob(q, c);
    return std::string(static_cast<const char*>(b), static_cast<std::size_t>(sqlite3_column_bytes(q, c)));
  };
  const std::string record = blob(0) + junk;
  const std::string detections = blob(1);
  sqlite3_finalize(q);
  REQUIRE(sqlite3_prepare_v2(db, "UPDATE key_images SET record = ?, crc = ? WHERE id = ?", -1, &q, nullptr) == SQLITE_OK);
  sqlite3_bind_blob(q, 1, record.data(), static_cast<int>(record.size()), SQLITE_TRANSIENT);
  sqlite3_bind_int64(q, 2, vmap::detail::row_crc(record, detections));
  sqlite3_bind_int64(q, 3, id);
  REQUIRE(sqlite3_step(q) == SQLITE_DONE);
  sqlite3_finalize(q);
  sqlite3_close(db);
}

}  // namespace

TEST_CASE("store: a key image record with bytes after its contents is refused naming the row, its checksum right") {
  auto memory = make(options(vmap::ImageStorage::png));
  for (std::size_t i = 0; i < 30; ++i) memory.push(sample_frames()[i]);
  REQUIRE(memory.key_images() >= 2);
  const fs::path file = store_path("padded.vmdb");
  {
    auto store = vmap::MemoryStore::create(file);
    store.sync(memory);
  }
  const std::int64_t length = sql_integer(file, "SELECT length(record) FROM key_images WHERE id = 1");
  pad_key_record(file, 1, std::string(4096, 'J'));
  CHECK(sql_integer(file, "SELECT length(record) FROM key_images WHERE id = 1") == length + 4096);

  auto store = vmap::MemoryStore::open(file, vmap::sqlite::Access::read);
  const std::string e = error_of([&] { (void)load_small_memory(store); });
  CHECK(e.find(file.string()) != std::string::npos);
  CHECK(e.find("key image 1") != std::string::npos);
  CHECK(e.find("4096 unexpected bytes after the key image") != std::string::npos);
  // The reader of one key image's features (a bounded working memory) refuses it too.
  const std::string f = error_of([&] { (void)store.features()(1); });
  CHECK(f.find("key image 1") != std::string::npos);
  CHECK(f.find("4096 unexpected bytes after the key image") != std::string::npos);
  // The other rows read as they were written.
  CHECK(store.features()(0).keypoints.size() == memory.map().keys[0].features.keypoints.size());
}

TEST_CASE("store: a row longer than it can be is refused by its length, before it is read") {
  const fs::path file = store_path("long_rows.vmdb");
  auto memory = make(options(vmap::ImageStorage::none));
  for (std::size_t i = 0; i < 30; ++i) memory.push(sample_frames()[i]);
  {
    auto store = vmap::MemoryStore::create(file);
    store.sync(memory);
  }
  const auto refused = [&](const std::string& damage, const std::string& said, const vmap::MapLoadOptions& limits = {}) {
    CAPTURE(damage);
    const fs::path copy = store_path("long_rows_copy.vmdb");
    fs::copy_file(file, copy);
    raw_sql(copy, damage);
    auto store = vmap::MemoryStore::open(copy, vmap::sqlite::Access::read);
    const auto e = vmap::test::error_seen([&] { (void)store.records(0, limits); });
    INFO(e.message);
    CHECK(e.kind == vmap::ErrorKind::corrupt);
    CHECK(e.message.find("memory '" + copy.string() + "' is corrupt: ") != std::string::npos);
    CHECK(e.message.find(said) != std::string::npos);
  };
  // The 32 bytes of the counts, padded: refused at 32 (the 950 MB of the issue cost only
  // their length).
  refused("UPDATE meta SET value = zeroblob(100032) WHERE name = 'counts'",
          "its 'counts' state is 100032 bytes long, more than the 32 it can hold");
  refused("UPDATE meta SET value = zeroblob(24) WHERE name = 'frames'",
          "its 'frames' state is 24 bytes long, more than the 8 it can hold");
  refused("UPDATE key_images SET detections = zeroblob(2000000) WHERE id = 2",
          "key image 2's detections is 2000000 bytes long, more than the 1572868 it can hold");
  refused("UPDATE links SET record = zeroblob(5000) WHERE key = 1",
          "the link into key image 1 is 5000 bytes long, more than the 4096 it can hold");
  refused("UPDATE key_images SET bow = zeroblob(1000000) WHERE id = 0",
          "key image 0's bag of words is 1000000 bytes long, more than the ");
  // The rows of features, pixels and the vocabulary are bounded as a memory file is
  // (MapLoadOptions::max_file_bytes).
  vmap::MapLoadOptions small;
  small.max_file_bytes = 1000;
  refused("SELECT 1", "bytes long, more than the 1000 it can hold", small);
}

TEST_CASE("store: the sessions table is checked against the state that repeats it") {
  const fs::path file = store_path("sessions_checked.vmdb");
  auto memory = make(options(vmap::ImageStorage::none));
  {
    auto store = vmap::MemoryStore::create(file);
    for (std::size_t i = 0; i < 30; ++i) {
      memory.push(sample_frames()[i]);
      store.sync(memory);
    }
    memory.start_session();
    for (std::size_t i = 30; i < 60; ++i) {
      memory.push(sample_frames()[i]);
      store.sync(memory);
    }
  }
  REQUIRE(memory.sessions().size() == 2);
  REQUIRE(memory.sessions()[1].first_frame == 30);
  for (const std::string& damage : {std::string("UPDATE sessions SET first_frame = 35 WHERE id = 1"),
                                    std::string("UPDATE sessions SET first_frame = 35"),
                                    std::string("UPDATE sessions SET first_key = first_key - 1 WHERE id = 1")}) {
    CAPTURE(damage);
    const fs::path copy = store_path("sessions_copy.vmdb");
    fs::copy_file(file, copy);
    raw_sql(copy, damage);
    auto store = vmap::MemoryStore::open(copy, vmap::sqlite::Access::read);
    const auto e = vmap::test::error_seen([&] { (void)load_small_memory(store); });
    CHECK(e.kind == vmap::ErrorKind::corrupt);
    CHECK(e.message.find("memory '" + copy.string() + "' is corrupt") != std::string::npos);
    CHECK(e.message.find("in its sessions table") != std::string::npos);
  }
  const fs::path copy = store_path("sessions_copy.vmdb");
  fs::copy_file(file, copy);
  raw_sql(copy, "DELETE FROM sessions WHERE id = 1");
  auto store = vmap::MemoryStore::open(copy, vmap::sqlite::Access::read);
  CHECK(vmap::test::error_seen([&] { (void)load_small_memory(store); }).kind == vmap::ErrorKind::corrupt);
  // Undamaged, it loads as the memory.
  auto whole = vmap::MemoryStore::open(file, vmap::sqlite::Access::read);
  CHECK(load_small_memory(whole).serialize() == memory.serialize());
}
