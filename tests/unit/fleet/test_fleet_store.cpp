// A fleet's memory on PostgreSQL (memory/store.hpp given a postgresql:// URI): a robot's
// memory synced frame by frame into the server loads back as the same memory, row for
// row as an SQLite store holds it; robots write at the same time, one writer per robot;
// names reach the server as parameters only; a database another program wrote is
// refused; a server that goes away makes syncs fail as `unavailable`, and the rows are
// written again once it is back. Each test case uses a database of its own on the test's
// own server (tests/support/pg_server.hpp).
#include "support/errors.hpp"
#include "support/pg_server.hpp"
#include "support/sample_memory.hpp"
#include "support/shared_data.hpp"

#include <vmap/io/postgres.hpp>
#include <vmap/memory/detail/fleet_schema.hpp>
#include <vmap/memory/fleet.hpp>
#include <vmap/memory/stacks.hpp>
#include <vmap/memory/store.hpp>

#include <doctest/doctest.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <thread>
#include <vector>

namespace {

using vmap::test::error_seen;
using vmap::test::load_small_memory;
using vmap::test::sample_frames;
namespace fs = std::filesystem;

vmap::OrbVisualMemory fleet_memory() {
  return vmap::test::make_small_memory(vmap::test::small_memory_options(vmap::ImageStorage::png));
}

/// Runs `sql` on the server (a test's own statements: a table another program made).
void server_sql(const std::string& uri, const std::string& sql) {
  vmap::pg::Connection c(uri, "test server");
  c.exec(sql, "run the test's SQL");
}

}  // namespace

TEST_CASE("fleet store: a robot's memory on the server loads back as the same memory, row for row as an SQLite store") {
  auto* server = vmap::test::test_server();
  if (!server) return;
  const std::string uri = server->uri("same_rows");
  const fs::path file = vmap::test::fresh_path("fleet", "same_rows.vmdb");
  auto on_server = vmap::MemoryStore::create(uri, {}, "robot a");
  auto in_file = vmap::MemoryStore::create(file);
  CHECK(on_server.on_server());
  CHECK(!in_file.on_server());
  CHECK(on_server.robot() == "robot a");
  CHECK(on_server.path() == uri);
  auto memory = fleet_memory();
  for (const auto& f : sample_frames()) {
    memory.push(f);
    on_server.sync(memory);
    in_file.sync(memory);
  }
  REQUIRE(memory.loops().size() > 0);
  CHECK(on_server.key_images() == memory.key_images());
  CHECK(on_server.loops() == memory.loops().size());
  // The same rows: each key image's record, detections and bag of words, byte for byte.
  CHECK(on_server.key_image_bytes() == in_file.key_image_bytes());
  const auto back = load_small_memory(on_server);
  CHECK(back.serialize() == memory.serialize());
  vmap::test::check_same_memory(back, memory);
  on_server.set_note("camera source", "calibration 'x.yaml'");
  CHECK(on_server.note("camera source") == "calibration 'x.yaml'");
  CHECK(on_server.policy_records() == in_file.policy_records());

  // A reader opens the robot while it is written; a resumed writer goes on exactly.
  auto reader = vmap::MemoryStore::open(uri, vmap::sqlite::Access::read, "robot a");
  CHECK(load_small_memory(reader).serialize() == memory.serialize());
  CHECK(error_seen([&] { (void)vmap::MemoryStore::open(uri, vmap::sqlite::Access::write, "robot a"); }).kind ==
        vmap::ErrorKind::busy);
  on_server.flush();
  {
    auto moved = std::move(on_server);
  }
  auto again = vmap::MemoryStore::open(uri, vmap::sqlite::Access::write, "robot a");
  auto resumed = load_small_memory(again);
  resumed.start_session();
  auto uninterrupted = load_small_memory(in_file);
  uninterrupted.start_session();
  for (std::size_t i = 0; i < 20; ++i) {
    resumed.push(sample_frames()[i]);
    uninterrupted.push(sample_frames()[i]);
    again.sync(resumed);
  }
  again.flush();
  CHECK(load_small_memory(again).serialize() == uninterrupted.serialize());
  CHECK(reader.key_images() < resumed.key_images());  // a reader's snapshot is of when it loaded
  CHECK(load_small_memory(reader).key_images() == resumed.key_images());
}

TEST_CASE("fleet store: robots write at the same time, each into its own memory; robots are found by name") {
  auto* server = vmap::test::test_server();
  if (!server) return;
  const std::string uri = server->uri("robots");
  // Names with quotes, semicolons and SQL reach the server as parameters only.
  const std::vector<std::string> names = {"alpha", "b'; DROP TABLE vmap.robots; --", "gamma \"3\""};
  std::vector<std::string> failures(names.size());
  std::vector<std::thread> robots;
  for (std::size_t r = 0; r < names.size(); ++r)
    robots.emplace_back([&, r] {
      try {
        auto store = vmap::MemoryStore::create(uri, {}, names[r]);
        auto memory = fleet_memory();
        for (std::size_t i = r * 5; i < sample_frames().size(); ++i) {
          memory.push(sample_frames()[i]);
          store.sync(memory);
        }
        store.flush();
        if (load_small_memory(store).serialize() != memory.serialize()) failures[r] = "differs";
      } catch (const std::exception& e) {
        failures[r] = e.what();
      }
    });
  for (auto& t : robots) t.join();
  for (const auto& f : failures) CHECK(f == "");
  for (const auto& name : names) {
    auto store = vmap::MemoryStore::open(uri, vmap::sqlite::Access::read, name);
    CHECK(store.key_images() > 5);
  }
  const auto missing = error_seen([&] { (void)vmap::MemoryStore::open(uri, vmap::sqlite::Access::read, "delta"); });
  CHECK(missing.kind == vmap::ErrorKind::not_found);
  CHECK(missing.message.find("robot 'delta'") != std::string::npos);
  for (const auto& name : names) CHECK(missing.message.find(name) != std::string::npos);
  const auto twice = error_seen([&] { (void)vmap::MemoryStore::create(uri, {}, "alpha"); });
  CHECK(twice.kind == vmap::ErrorKind::invalid_argument);
  CHECK(twice.message.find("exists already") != std::string::npos);
  CHECK(error_seen([&] { (void)vmap::MemoryStore::create(uri, {}, ""); }).message.find("name the robot") != std::string::npos);
  CHECK(error_seen([&] { (void)vmap::MemoryStore::create(uri, {}, std::string(129, 'x')); }).message.find("at most 128") !=
        std::string::npos);
  CHECK(error_seen([&] { (void)vmap::MemoryStore::create(uri, {}, "a\nb"); }).message.find("control character") !=
        std::string::npos);
  const auto none = error_seen([&] { (void)vmap::MemoryStore::open(server->uri("empty_db"), vmap::sqlite::Access::read, "a"); });
  CHECK(none.kind == vmap::ErrorKind::not_found);
  CHECK(none.message.find("holds no vmap memory") != std::string::npos);
}

TEST_CASE("fleet store: no password in messages; a server that cannot be reached is `unavailable`") {
  CHECK(vmap::pg::redacted("postgresql://fleet:s3cret@db.local:5433/vmap?sslmode=require") ==
        "postgresql://fleet@db.local:5433/vmap?sslmode=require");
  CHECK(vmap::pg::redacted("postgresql://db/vmap?password=s3cret&sslmode=disable") == "postgresql://db/vmap?sslmode=disable");
  CHECK(vmap::pg::redacted("postgresql://db/vmap?sslmode=disable&password=s3cret") == "postgresql://db/vmap?sslmode=disable");
  CHECK(vmap::pg::redacted("postgres://u@h/d") == "postgres://u@h/d");
  CHECK(vmap::pg::is_uri("postgresql://h/d"));
  CHECK(vmap::pg::is_uri("postgres://h/d"));
  CHECK(!vmap::pg::is_uri("run.vmdb"));
  // A port nothing listens on (the test server's port once stopped is not reused here).
  const auto e = error_seen([] {
    (void)vmap::MemoryStore::open("postgresql://fleet:s3cret@127.0.0.1:1/vmap?connect_timeout=2", vmap::sqlite::Access::read,
                                  "a");
  });
  CHECK(e.kind == vmap::ErrorKind::unavailable);
  CHECK(e.message.find("s3cret") == std::string::npos);
  CHECK(e.message.find("robot 'a' of memory 'postgresql://fleet@127.0.0.1:1/vmap?connect_timeout=2'") != std::string::npos);
  // A connection string libpq cannot parse is the caller's mistake.
  const auto bad = error_seen([] { (void)vmap::MemoryStore::open("postgresql://h:notaport/db", vmap::sqlite::Access::read, "a"); });
  CHECK(bad.kind == vmap::ErrorKind::invalid_argument);
  CHECK(bad.message.find("notaport") != std::string::npos);
}

TEST_CASE("fleet store: a database another program wrote is refused, naming what is wrong") {
  auto* server = vmap::test::test_server();
  if (!server) return;
  {
    const std::string uri = server->uri("foreign_schema");
    server_sql(uri, "CREATE SCHEMA vmap; CREATE TABLE vmap.things(x int);");
    const auto e = error_seen([&] { (void)vmap::MemoryStore::open(uri, vmap::sqlite::Access::read, "a"); });
    CHECK(e.kind == vmap::ErrorKind::corrupt);
    CHECK(e.message.find("made by another program") != std::string::npos);
    CHECK(error_seen([&] { (void)vmap::MemoryStore::create(uri, {}, "a"); }).kind == vmap::ErrorKind::corrupt);
  }
  {
    const std::string uri = server->uri("foreign_id");
    server_sql(uri, "CREATE SCHEMA vmap; CREATE TABLE vmap.info(name text, value bigint);"
                    "CREATE TABLE vmap.robots(id bigint, name text); CREATE TABLE vmap.postings(x int);"
                    "CREATE TABLE vmap.fleet_loops(x int); INSERT INTO vmap.info VALUES('application_id', 7);");
    CHECK(error_seen([&] { (void)vmap::MemoryStore::open(uri, vmap::sqlite::Access::read, "a"); }).message.find(
              "no vmap application id") != std::string::npos);
  }
  {
    const std::string uri = server->uri("newer");
    { auto s = vmap::MemoryStore::create(uri, {}, "a"); }
    server_sql(uri, "UPDATE vmap.info SET value = 99 WHERE name = 'version'");
    CHECK(error_seen([&] { (void)vmap::MemoryStore::open(uri, vmap::sqlite::Access::read, "a"); }).kind ==
          vmap::ErrorKind::unsupported_version);
  }
  {
    // A robot's table of other types: its rows are refused when read, naming the column.
    const std::string uri = server->uri("types");
    {
      auto s = vmap::MemoryStore::create(uri, {}, "a");
      auto memory = fleet_memory();
      for (std::size_t i = 0; i < 12; ++i) {
        memory.push(sample_frames()[i]);
        s.sync(memory);
      }
    }
    server_sql(uri, "ALTER TABLE vmap_robot_1.key_images ALTER COLUMN frame_index TYPE text");
    auto s = vmap::MemoryStore::open(uri, vmap::sqlite::Access::read, "a");
    const auto e = error_seen([&] { (void)load_small_memory(s); });
    CHECK(e.kind == vmap::ErrorKind::corrupt);
    CHECK(e.message.find("column 'frame_index' is not an integer") != std::string::npos);
  }
}

TEST_CASE("fleet store: a server restart makes a sync fail as unavailable; the rows are written once it is back") {
  auto* server = vmap::test::test_server();
  if (!server) return;
  const std::string uri = server->uri("restart");
  auto store = vmap::MemoryStore::create(uri, {}, "a");
  auto memory = fleet_memory();
  const auto& frames = sample_frames();
  std::size_t i = 0;
  for (; i < 20; ++i) {
    memory.push(frames[i]);
    store.sync(memory);
  }
  store.flush();
  const std::size_t synced = store.key_images();
  server->stop();
  // Pushing goes on while the server is away: each sync (or the flush after it) fails as
  // unavailable, naming the memory, and nothing reported synced is lost.
  std::size_t failures = 0;
  for (; i < 40; ++i) {
    memory.push(frames[i]);
    try {
      store.sync(memory);
      store.flush();
    } catch (const vmap::Error& e) {
      ++failures;
      CHECK(e.kind() == vmap::ErrorKind::unavailable);
      CHECK(std::string(e.what()).find("robot 'a' of memory '" + uri + "'") != std::string::npos);
    }
  }
  CHECK(failures == 20);
  server->start();
  for (; i < frames.size(); ++i) {
    memory.push(frames[i]);
    store.sync(memory);
  }
  store.flush();
  CHECK(store.key_images() == memory.key_images());
  CHECK(store.key_images() > synced);
  CHECK(load_small_memory(store).serialize() == memory.serialize());
  // The writer's lock was taken again with the new connection.
  CHECK(error_seen([&] { (void)vmap::MemoryStore::open(uri, vmap::sqlite::Access::write, "a"); }).kind ==
        vmap::ErrorKind::busy);
}

namespace {

/// A vocabulary every robot of a test fleet is given (bags of words of two vocabularies
/// do not compare): learned from every 4th sample frame.
const vmap::AnyVocabulary& fleet_vocabulary() {
  static const vmap::AnyVocabulary v = [] {
    std::vector<cv::Mat> sets;
    vmap::OrbDescriptor orb;
    for (std::size_t i = 0; i < sample_frames().size(); i += 4) sets.push_back(orb.extract(sample_frames()[i].image).descriptors);
    return vmap::AnyVocabulary::learn(sets, {.branching = 8, .depth = 3, .seed = 3});
  }();
  return v;
}

/// Robot `name` maps frames [first, last) into the fleet, looking for each key image
/// among the other robots' once its sync is committed; the loops it found.
std::vector<vmap::FleetLoop> map_as_robot(const std::string& uri, const std::string& name, std::size_t first,
                                          std::size_t last) {
  auto store = vmap::MemoryStore::create(uri, {}, name);
  vmap::FleetIndex fleet(uri, name);
  vmap::OrbVisualMemory memory(vmap::OrbDescriptor{}, vmap::BruteForceMatcher{}, vmap::test::memory_estimator(),
                               vmap::InlierRatio{}, vmap::test::small_memory_options(), fleet_vocabulary());
  std::vector<vmap::FleetLoop> found;
  std::size_t linked = 0;
  for (std::size_t i = first; i < last; ++i) {
    memory.push(sample_frames()[i]);
    store.sync(memory);
    store.flush();
    for (; linked < memory.database().size(); ++linked)
      for (auto& loop : vmap::link_across_fleet(memory, static_cast<std::uint32_t>(linked), fleet, store.vocabulary_crc()))
        found.push_back(std::move(loop));
  }
  return found;
}

}  // namespace

TEST_CASE("fleet loops: a robot that maps where another mapped finds its key images, each pair recorded once") {
  auto* server = vmap::test::test_server();
  if (!server) return;
  const std::string uri = server->uri("loops_between");
  const auto by_a = map_as_robot(uri, "a", 0, 60);
  CHECK(by_a.empty());  // alone in the fleet
  const auto by_b = map_as_robot(uri, "b", 0, 60);
  auto a = vmap::MemoryStore::open(uri, vmap::sqlite::Access::read, "a");
  auto b = vmap::MemoryStore::open(uri, vmap::sqlite::Access::read, "b");
  const auto mem_a = load_small_memory(a), mem_b = load_small_memory(b);
  // B saw what A saw, frame for frame: the same key images, and each of B's checked key
  // images is joined to A's of the same frame (their heavy score is 1), besides others
  // of that one place (the camera turns on the spot). Every pair is verified and
  // confident.
  REQUIRE(mem_b.database().size() > 5);
  REQUIRE(mem_a.key_images() == mem_b.key_images());
  std::set<std::pair<std::uint32_t, std::uint32_t>> pairs;
  for (const auto& l : by_b) {
    CAPTURE(l.from_key);
    CAPTURE(l.to_key);
    CHECK(l.from_robot == "b");
    CHECK(l.to_robot == "a");
    CHECK(l.link.key == l.to_key);
    CHECK(l.link.confidence >= mem_b.options().loops.decision.min_confidence);
    CHECK(l.link.inliers >= mem_b.options().loops.decision.min_inliers);
    CHECK(pairs.insert({l.from_key, l.to_key}).second);
  }
  std::size_t same_frame = 0;
  for (std::uint32_t k = 0; k < mem_b.database().size(); ++k) {
    CAPTURE(k);
    CHECK(mem_a.map().keys[k].frame_index == mem_b.map().keys[k].frame_index);
    same_frame += pairs.count({k, k});
  }
  CHECK(same_frame * 2 >= mem_b.database().size());
  // The rule is the pair's: one memory of the same frames as two sessions joins them by
  // the same pairs, with the same verification.
  vmap::OrbVisualMemory two(vmap::OrbDescriptor{}, vmap::BruteForceMatcher{}, vmap::test::memory_estimator(),
                            vmap::InlierRatio{}, vmap::test::small_memory_options(), fleet_vocabulary());
  for (std::size_t i = 0; i < 60; ++i) two.push(sample_frames()[i]);
  two.start_session();
  for (std::size_t i = 0; i < 60; ++i) two.push(sample_frames()[i]);
  const auto m = static_cast<std::uint32_t>(mem_a.key_images());
  std::map<std::pair<std::uint32_t, std::uint32_t>, int> between_sessions, between_robots;
  for (const auto& e : two.loops())
    if (two.session_of(e.from) == 1 && two.session_of(e.link.key) == 0)
      between_sessions[{e.from - m, e.link.key}] = e.link.inliers;
  for (const auto& l : by_b) between_robots[{l.from_key, l.to_key}] = l.link.inliers;
  CHECK(between_sessions.size() == between_robots.size());
  CHECK(between_sessions == between_robots);
  // The fleet's edges are the ones found, read back with their verification (listed by
  // the first robot's key image).
  auto stored = vmap::fleet_loops(uri);
  auto mine = by_b;
  const auto by_keys = [](const auto& x, const auto& y) { return std::pair(x.from_key, x.to_key) < std::pair(y.from_key, y.to_key); };
  std::sort(stored.begin(), stored.end(), by_keys);
  std::sort(mine.begin(), mine.end(), by_keys);
  REQUIRE(stored.size() == mine.size());
  for (std::size_t i = 0; i < stored.size(); ++i) {
    CHECK(stored[i].from_robot == "b");
    CHECK(stored[i].to_robot == "a");
    CHECK(stored[i].from_key == mine[i].from_key);
    CHECK(stored[i].to_key == mine[i].to_key);
    CHECK(stored[i].link.inliers == mine[i].link.inliers);
    CHECK(stored[i].link.confidence == mine[i].link.confidence);
  }
  // A robot with another vocabulary compares with nobody.
  {
    auto store = vmap::MemoryStore::create(uri, {}, "c");
    vmap::FleetIndex fleet(uri, "c");
    auto memory = fleet_memory();  // learns its own vocabulary
    std::size_t found = 0, linked = 0;
    for (const auto& f : sample_frames()) {
      memory.push(f);
      store.sync(memory);
      store.flush();
      for (; linked < memory.database().size(); ++linked)
        found += vmap::link_across_fleet(memory, static_cast<std::uint32_t>(linked), fleet, store.vocabulary_crc()).size();
    }
    CHECK(linked > 5);
    CHECK(found == 0);
  }
}

TEST_CASE("fleet loops: robots mapping at the same time meet: every pair is considered, none is recorded twice") {
  auto* server = vmap::test::test_server();
  if (!server) return;
  const std::string uri = server->uri("loops_concurrent");
  std::vector<std::vector<vmap::FleetLoop>> found(3);
  std::vector<std::string> errors(3);
  std::vector<std::thread> robots;
  for (std::size_t r = 0; r < 3; ++r)
    robots.emplace_back([&, r] {
      try {
        found[r] = map_as_robot(uri, "r" + std::to_string(r), r * 10, r * 10 + 30);
      } catch (const std::exception& e) {
        errors[r] = e.what();
      }
    });
  for (auto& t : robots) t.join();
  for (const auto& e : errors) CHECK(e == "");
  std::size_t total = 0;
  for (const auto& f : found) total += f.size();
  const auto stored = vmap::fleet_loops(uri);
  CHECK(total > 0);
  // A pair both robots found is recorded once (the first robot's).
  CHECK(stored.size() <= total);
  CHECK(stored.size() > 0);
  for (std::size_t i = 1; i < stored.size(); ++i)
    CHECK(!(stored[i].from_robot == stored[i - 1].from_robot && stored[i].from_key == stored[i - 1].from_key &&
            stored[i].to_robot == stored[i - 1].to_robot && stored[i].to_key == stored[i - 1].to_key));
}

TEST_CASE("fleet store: a password with '/', '?' or '@' unescaped is removed whole from what is shown") {
  for (const char* uri : {"postgresql://fleet:se/cret@db/vmap", "postgresql://fleet:se?cret@db/vmap",
                          "postgresql://fleet:se@cret@db/vmap"}) {
    CAPTURE(uri);
    CHECK(vmap::pg::redacted(uri) == "postgresql://fleet@db/vmap");
  }
  // A password that looks like a query's password: more than the password goes, none of it stays.
  const std::string looks = vmap::pg::redacted("postgresql://fleet:a?password=se@cret@db/vmap");
  CHECK(looks.starts_with("postgresql://fleet"));
  for (const char* part : {":a", "se", "cret"}) CHECK(looks.find(part) == std::string::npos);
  CHECK(vmap::pg::redacted("postgresql://fleet:secretpw@/vmap?host=/tmp/s") == "postgresql://fleet@/vmap?host=/tmp/s");
  CHECK(vmap::pg::redacted("postgresql://db/vmap?password=se/c?ret") == "postgresql://db/vmap");
  CHECK(vmap::pg::redacted("postgresql://db/vmap?password=s&sslmode=disable&password=t") ==
        "postgresql://db/vmap?sslmode=disable");
  // An '@' of the query is no user part: the port and the query stay.
  CHECK(vmap::pg::redacted("postgresql://u@db:5433/vmap?application_name=a@b") ==
        "postgresql://u@db:5433/vmap?application_name=a@b");
  // A password parameter holding an '@' after a port: nothing of it is left.
  const std::string shown = vmap::pg::redacted("postgresql://db:5433/vmap?password=se@cret");
  CHECK(shown.find("se") == std::string::npos);
  CHECK(shown.find("cret") == std::string::npos);
}

TEST_CASE("fleet store: a robot added is locked before another program sees it, so it is never removed as unsynced") {
  auto* server = vmap::test::test_server();
  if (!server) return;
  const std::string uri = server->uri("add_remove");
  std::optional<vmap::detail::StoreDb> adding;
  adding.emplace(vmap::pg::Connection(uri, "robot 'r' of the test"));
  vmap::detail::ensure_fleet(*adding, vmap::detail::fleet_version);
  // Committed, not yet synced: another program's clean-up of robots that hold nothing
  // finds it locked and keeps it.
  const std::int64_t id = vmap::detail::add_fleet_robot(*adding, "r");
  CHECK(!vmap::MemoryStore::remove_unsynced_robot(uri, "r"));
  CHECK(vmap::MemoryStore::robots(uri) == std::vector<std::string>{"r"});
  CHECK(error_seen([&] { (void)vmap::MemoryStore::open(uri, vmap::sqlite::Access::write, "r"); }).kind ==
        vmap::ErrorKind::busy);
  // Its writer goes on into its tables.
  vmap::detail::enter_fleet_robot(*adding, id, false);
  adding->exec("INSERT INTO notes(name, value) VALUES('k', 'v')", "write a note");
  // Once its writer is gone, a robot that holds nothing may be removed.
  adding.reset();
  CHECK(vmap::MemoryStore::remove_unsynced_robot(uri, "r"));
  CHECK(vmap::MemoryStore::robots(uri).empty());
}

TEST_CASE("fleet store: a new robot's name neither begins nor ends with a space") {
  auto* server = vmap::test::test_server();
  if (!server) return;
  const std::string uri = server->uri("names");
  for (const char* name : {"r1 ", " r1", " "}) {
    CAPTURE(name);
    const auto e = error_seen([&] { (void)vmap::MemoryStore::create(uri, {}, name); });
    CHECK(e.kind == vmap::ErrorKind::invalid_argument);
    CHECK(e.message.find("a robot's name begins or ends with a space") != std::string::npos);
  }
  { auto s = vmap::MemoryStore::create(uri, {}, "r 1"); }
  CHECK(vmap::MemoryStore::robots(uri) == std::vector<std::string>{"r 1"});
}

TEST_CASE("fleet store: a server that stops answering ends a sync and a connection as `unavailable`, within the timeouts") {
  auto* server = vmap::test::test_server();
  if (!server) return;
  const std::string uri = server->uri("hung");
  // Short timeouts for the test (the defaults: 30 s an answer, 10 s a connection).
  ::setenv("VMAP_PG_QUERY_TIMEOUT", "2", 1);
  ::setenv("PGCONNECT_TIMEOUT", "2", 1);
  struct Restore {
    ~Restore() {
      ::unsetenv("VMAP_PG_QUERY_TIMEOUT");
      ::unsetenv("PGCONNECT_TIMEOUT");
    }
  } restore;
  auto store = vmap::MemoryStore::create(uri, {}, "a");
  auto memory = fleet_memory();
  const auto& frames = sample_frames();
  std::size_t i = 0;
  for (; i < 20; ++i) {
    memory.push(frames[i]);
    store.sync(memory);
  }
  store.flush();
  const std::size_t synced = store.key_images();
  server->pause();
  struct Resume {
    vmap::test::TestPostgres* server;
    bool done = false;
    ~Resume() {
      if (!done) server->resume();
    }
  } resume{server};
  for (; i < 30; ++i) memory.push(frames[i]);
  using clock = std::chrono::steady_clock;
  auto t0 = clock::now();
  const auto sync = error_seen([&] {
    store.sync(memory);
    store.flush();
  });
  const double sync_seconds = std::chrono::duration<double>(clock::now() - t0).count();
  CHECK(sync.kind == vmap::ErrorKind::unavailable);
  CHECK(sync.message.find("robot 'a' of memory '" + uri + "'") != std::string::npos);
  CHECK(sync.message.find("did not answer within 2 s") != std::string::npos);
  CHECK(sync_seconds >= 1.9);
  CHECK(sync_seconds < 10.0);
  t0 = clock::now();
  const auto open = error_seen([&] { (void)vmap::MemoryStore::open(uri, vmap::sqlite::Access::read, "a"); });
  const double open_seconds = std::chrono::duration<double>(clock::now() - t0).count();
  CHECK(open.kind == vmap::ErrorKind::unavailable);
  CHECK(open_seconds >= 1.9);
  CHECK(open_seconds < 10.0);
  server->resume();
  resume.done = true;
  // Back: the next sync connects again and writes the rows (the closed connection's
  // session, and the robot's lock with it, ends once the server runs again).
  for (int attempt = 0;; ++attempt) {
    try {
      store.sync(memory);
      store.flush();
      break;
    } catch (const vmap::Error& e) {
      if (e.kind() != vmap::ErrorKind::busy || attempt >= 50) throw;
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
  }
  CHECK(store.key_images() == memory.key_images());
  CHECK(store.key_images() > synced);
  CHECK(load_small_memory(store).serialize() == memory.serialize());
}
