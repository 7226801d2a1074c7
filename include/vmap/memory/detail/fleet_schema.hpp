#pragma once

// A fleet's memory on a PostgreSQL server: where each robot's memory lives in the
// database, and the checks that the database is one vmap made (memory/store.hpp opens
// a robot's memory through these; examples/memory.md, "A fleet's memory", shows the
// layout to readers without vmap).
//
//   schema vmap          info(name, value)       application id "VMAP" and the schema version
//                        robots(id, name, created, linked)
//                        postings(word, robot, key, weight, vocabulary): the fleet's inverted file
//                        of heavy words (place/heavy_words.hpp)
//                        fleet_loops(a_robot, a_key, b_robot, b_key, from_robot, ...): loops
//                        between robots (memory/fleet.hpp)
//   schema vmap_robot_N  meta, key_images, links, loops, notes, sessions: robot N's
//                        memory, the tables and columns of an SQLite memory store
//
// A robot's memory is a memory store of its own (its sessions, key images, loops), so a
// robot's writer and every reader use the store's own statements, unchanged, with the
// robot's schema as the search path. The schema's name holds only the robot's number,
// which the database gave; the robot's name is a parameter of every statement.
//
// One writer per robot: the writer holds a session-level advisory lock on (the
// application id, the robot's number) for as long as its connection lives, so a second
// writer of the same robot is refused (busy), and a writer killed at any moment frees
// it as the server closes its connection.

#include <vmap/core/error.hpp>
#include <vmap/memory/detail/store_db.hpp>
#include <vmap/place/bow.hpp>
#include <vmap/place/heavy_words.hpp>

#include <cstdint>
#include <cstdio>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace vmap::detail {

/// The advisory lock's first key, and vmap.info's application id: "VMAP".
inline constexpr std::int64_t fleet_application_id = 0x564D4150;
/// The fleet's schema version (vmap.info 'version'); each robot's tables are a memory
/// store's of version memory_store_version. Version 1 (a build of 2026-11-28) held every
/// word of a key image as a floating-point weight; version 2 holds its heavy words, in
/// fixed point.
inline constexpr std::int64_t fleet_version = 2;
/// Longest robot name (bytes).
inline constexpr std::size_t fleet_max_robot_name = 128;

/// An integer array parameter as PostgreSQL's text form ("{1,2,3}"), cast by the statement.
[[nodiscard]] inline std::string pg_array(const std::vector<std::int64_t>& values) {
  std::string out = "{";
  char buf[32];
  for (std::size_t i = 0; i < values.size(); ++i) {
    std::snprintf(buf, sizeof buf, "%lld", static_cast<long long>(values[i]));
    if (i > 0) out += ',';
    out += buf;
  }
  return out + "}";
}

/// A key image index read from the server: refused (corrupt) unless it is one.
[[nodiscard]] inline std::uint32_t checked_key(std::int64_t v, const StoreDb& db) {
  if (v < 0 || v > std::numeric_limits<std::uint32_t>::max())
    db.fail("is corrupt: key image index " + std::to_string(v) + " in the fleet's tables", ErrorKind::corrupt);
  return static_cast<std::uint32_t>(v);
}

/// `bow`'s heavy words and their weights (place/heavy_words.hpp): a key image's postings.
inline std::pair<std::vector<std::int64_t>, std::vector<std::int64_t>> heavy_postings(const BowVector& bow) {
  std::pair<std::vector<std::int64_t>, std::vector<std::int64_t>> out;
  for (const HeavyWord& w : heavy_words(bow)) {
    out.first.push_back(w.word);
    out.second.push_back(static_cast<std::int64_t>(w.weight));
  }
  return out;
}

/// `name` checked as a robot's name: 1 to 128 bytes of printable text. A new robot's
/// name (`new_robot`) neither begins nor ends with a space, so that no two robots' names
/// look alike in a listing ("r1" and "r1 "); robots named so before stay reachable.
inline void check_robot_name(std::string_view name, const std::string& who, bool new_robot = false) {
  if (name.empty())
    fail(who + ": a fleet's memory holds one memory per robot: name the robot (--robot NAME, or the robot option)");
  if (name.size() > fleet_max_robot_name)
    fail(who + ": a robot's name is at most " + std::to_string(fleet_max_robot_name) + " bytes (got " +
         std::to_string(name.size()) + ")");
  for (const unsigned char c : name)
    if (c < 0x20 || c == 0x7f) fail(who + ": a robot's name holds a control character");
  if (new_robot && (name.front() == ' ' || name.back() == ' '))
    fail(who + ": a robot's name begins or ends with a space ('" + std::string(name) +
         "'); names that differ in spaces alone look alike in listings: give it without them");
}

/// The schema of robot number `id`.
[[nodiscard]] inline std::string robot_schema(std::int64_t id) { return "vmap_robot_" + std::to_string(id); }

/// The tables of one robot's memory: those of an SQLite memory store (memory/store.hpp,
/// version 4) in PostgreSQL's types.
[[nodiscard]] inline std::string robot_tables_sql(const std::string& schema) {
  const std::string s = schema + ".";
  return "CREATE TABLE " + s + "meta(name text PRIMARY KEY, value bytea NOT NULL, crc bigint NOT NULL);"
         "CREATE TABLE " + s + "key_images(id bigint PRIMARY KEY, frame_index bigint NOT NULL,"
         " timestamp double precision NOT NULL, time_ns bigint NOT NULL, name text NOT NULL, keypoints bigint NOT NULL,"
         " record bytea NOT NULL, detections bytea NOT NULL, crc bigint NOT NULL, bow bytea, bow_crc bigint);"
         "CREATE TABLE " + s + "links(key bigint PRIMARY KEY, matches bigint NOT NULL, inliers bigint NOT NULL,"
         " similarity double precision NOT NULL, record bytea NOT NULL, crc bigint NOT NULL);"
         "CREATE TABLE " + s + "loops(id bigint PRIMARY KEY, from_key bigint NOT NULL, to_key bigint NOT NULL,"
         " inliers bigint NOT NULL, confidence double precision NOT NULL, record bytea NOT NULL, crc bigint NOT NULL);"
         "CREATE TABLE " + s + "notes(name text PRIMARY KEY, value text NOT NULL);"
         "CREATE TABLE " + s + "sessions(id bigint PRIMARY KEY, first_key bigint NOT NULL, first_frame bigint NOT NULL);";
}

/// Checks that the database holds a fleet's memory of a version this build reads
/// (schema vmap, its application id and version); false when it holds none.
[[nodiscard]] inline bool fleet_present(StoreDb& db, std::int64_t version) {
  {
    auto q = db.prepare("SELECT count(*) FROM pg_catalog.pg_namespace WHERE nspname = 'vmap'", "look for a fleet's memory");
    if (!q.step() || q.integer(0) == 0) return false;
  }
  std::optional<std::int64_t> application, stored;
  {
    auto q = db.prepare("SELECT count(*) FROM information_schema.tables WHERE table_schema = 'vmap' AND "
                        "table_name IN ('info', 'robots', 'postings', 'fleet_loops')",
                        "look for a fleet's memory");
    if (!q.step() || q.integer(0) != 4)
      db.fail("is not a vmap memory: its schema 'vmap' was made by another program (not the tables info, robots, "
              "postings and fleet_loops)",
              ErrorKind::corrupt);
  }
  auto q = db.prepare("SELECT name, value FROM vmap.info", "read the fleet's schema");
  while (q.step()) {
    const std::string name = q.text(0);
    if (name == "application_id") application = q.integer(1);
    if (name == "version") stored = q.integer(1);
  }
  if (application != fleet_application_id)
    db.fail("is not a vmap memory: its schema 'vmap' was made by another program (no vmap application id)",
            ErrorKind::corrupt);
  if (!stored || *stored < 1) db.fail("is corrupt: its fleet schema has no version", ErrorKind::corrupt);
  if (*stored != version)
    db.fail("has fleet schema version " + std::to_string(*stored) + "; this build reads version " + std::to_string(version) +
                " only",
            ErrorKind::unsupported_version);
  return true;
}

/// Creates the fleet's schema when the database has none (serialized between robots
/// that start at once by a transaction-level advisory lock), then checks it.
inline void ensure_fleet(StoreDb& db, std::int64_t version) {
  StoreTransaction t(db, "create the fleet's schema");
  auto lock = db.prepare("SELECT pg_advisory_xact_lock(CAST(? AS integer), 0)", "lock the fleet's schema");
  lock.bind(1, fleet_application_id);
  (void)lock.step();
  lock.reset();
  if (!fleet_present(db, version)) {
    db.exec("CREATE SCHEMA vmap;"
            "CREATE TABLE vmap.info(name text PRIMARY KEY, value bigint NOT NULL);"
            "CREATE TABLE vmap.robots(id bigserial PRIMARY KEY, name text UNIQUE NOT NULL,"
            " created timestamptz NOT NULL DEFAULT now(), linked bigint NOT NULL DEFAULT 0);"
            "CREATE TABLE vmap.postings(robot integer NOT NULL, key bigint NOT NULL, word integer NOT NULL,"
            " weight bigint NOT NULL, vocabulary bigint NOT NULL, PRIMARY KEY(robot, key, word));"
            "CREATE INDEX postings_word ON vmap.postings(word, vocabulary) INCLUDE (robot, key, weight);"
            "CREATE TABLE vmap.fleet_loops(a_robot integer NOT NULL, a_key bigint NOT NULL, b_robot integer NOT NULL,"
            " b_key bigint NOT NULL, from_robot integer NOT NULL, inliers bigint NOT NULL,"
            " confidence double precision NOT NULL, record bytea NOT NULL, crc bigint NOT NULL,"
            " found timestamptz NOT NULL DEFAULT now(), PRIMARY KEY(a_robot, a_key, b_robot, b_key));",
            "create the fleet's schema");
    auto info = db.prepare("INSERT INTO vmap.info(name, value) VALUES(?, ?)", "write the fleet's schema");
    info.bind_text(1, "application_id").bind(2, fleet_application_id);
    info.run();
    info.bind_text(1, "version").bind(2, version);
    info.run();
  }
  t.commit();
}

/// Robot `name`'s number, if the fleet has it.
[[nodiscard]] inline std::optional<std::int64_t> fleet_robot(StoreDb& db, std::string_view name) {
  auto q = db.prepare("SELECT id FROM vmap.robots WHERE name = ?", "look for the robot");
  q.bind_text(1, name);
  if (!q.step()) return std::nullopt;
  return q.integer(0);
}

/// The fleet's robots, by number.
[[nodiscard]] inline std::vector<std::string> fleet_robots(StoreDb& db) {
  auto q = db.prepare("SELECT name FROM vmap.robots ORDER BY id", "list the robots");
  std::vector<std::string> out;
  while (q.step()) out.push_back(q.text(0));
  return out;
}

/// Takes robot `id`'s writer lock for the connection's session (released when it ends):
/// busy when another program holds it.
inline void lock_fleet_robot(StoreDb& db, std::int64_t id) {
  auto lock = db.prepare("SELECT pg_try_advisory_lock(CAST(? AS integer), CAST(? AS integer))", "lock the robot");
  lock.bind(1, fleet_application_id).bind(2, id);
  if (!lock.step() || lock.integer(0) == 0)
    db.fail("is being written by another program (one writer per robot; open it read-only to localize while it maps)",
            ErrorKind::busy);
}

/// Adds robot `name` and its empty memory (one transaction); an Error when it exists.
/// The connection's name (StoreDb::what) is the robot's. The connection holds the robot's
/// writer lock (enter_fleet_robot) from inside that transaction on: another program sees
/// the robot only once it is locked, so remove_unsynced_robot (memory/store.hpp) never
/// takes a robot whose writer has not locked it yet.
[[nodiscard]] inline std::int64_t add_fleet_robot(StoreDb& db, std::string_view name) {
  StoreTransaction t(db, "add the robot");
  auto q = db.prepare("INSERT INTO vmap.robots(name) VALUES(?) ON CONFLICT(name) DO NOTHING RETURNING id", "add the robot");
  q.bind_text(1, name);
  if (!q.step())
    db.fail("exists already: open it to add a session to its memory, or name another robot");
  const std::int64_t id = q.integer(0);
  q.reset();
  lock_fleet_robot(db, id);
  db.exec("CREATE SCHEMA " + robot_schema(id) + ";" + robot_tables_sql(robot_schema(id)), "create the robot's tables");
  t.commit();
  return id;
}

/// Makes robot `id`'s memory the connection's tables (its search path), and for a
/// writer that does not hold it yet (`lock`) takes the robot's writer lock: busy when
/// another program holds it.
inline void enter_fleet_robot(StoreDb& db, std::int64_t id, bool lock) {
  auto path = db.prepare("SELECT set_config('search_path', ?, false)", "use the robot's tables");
  path.bind_text(1, robot_schema(id));
  (void)path.step();
  path.reset();
  if (lock) lock_fleet_robot(db, id);
}

}  // namespace vmap::detail
