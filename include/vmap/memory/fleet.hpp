#pragma once

// Loops between robots of a fleet's memory (a PostgreSQL server; memory/store.hpp given a
// postgresql:// URI): each robot's new key image is looked for among the key images every
// other robot of the fleet has written, as it maps.
//
//   vmap::FleetIndex fleet("postgresql://vmap@db/fleet", "robot-b");
//   ... memory.push(frame); store.sync(memory); store.flush(); ...
//   for (auto& loop : vmap::link_across_fleet(memory, key, fleet)) ...   // after its commit
//
// The place database of the whole fleet is one inverted file in the database
// (vmap.postings: word, robot, key image, weight), written by each robot's store in the
// same transaction as the key image's bag of words; a robot never loads the fleet's
// postings. It holds each key image's heavy words (place/heavy_words.hpp), and a query
// asks the server for the other robots' key images whose heavy score against it reaches
// run_link_min_score (the server sums integers over the query's 64 heavy words), among
// robots whose vocabulary is the query's (by the CRC-32 of its record: bags of words of
// two vocabularies do not compare). The features of those candidates, and only those,
// cross the network; each pair is verified and decided by the place rule between runs
// (VisualMemory::link_pair), the rule that joins the sessions of one memory. An accepted
// pair is an inter-robot loop edge (vmap.fleet_loops), recorded once whichever robot
// found it.
//
// Every pair of key images of two robots is considered at least once: a robot queries
// after its own postings are committed, so of two key images written at the same time
// the later query sees the other. Since the candidates are a pair's own (its heavy
// score) and so is the decision, the loops between robots are those between the same
// runs added to one memory as sessions, whatever the order the robots mapped in, as long
// as no query has more than run_link_candidates candidates (bench_fleet counts them).

#include <vmap/core/error.hpp>
#include <vmap/core/features.hpp>
#include <vmap/io/binary.hpp>
#include <vmap/io/postgres.hpp>
#include <vmap/keyframe/map_io.hpp>
#include <vmap/memory/detail/fleet_schema.hpp>
#include <vmap/memory/detail/record_codecs.hpp>
#include <vmap/memory/detail/store_db.hpp>
#include <vmap/memory/options.hpp>
#include <vmap/memory/store.hpp>
#include <vmap/memory/types.hpp>
#include <vmap/place/bow.hpp>
#include <vmap/place/heavy_words.hpp>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <type_traits>
#include <algorithm>
#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace vmap {

/// A key image of another robot that the fleet's inverted file ranked for a query.
struct FleetCandidate {
  std::string robot;
  std::uint32_t key = 0;
  double score = 0.0;  ///< the heavy score against the query (place/heavy_words.hpp), in [0, 1]
};

/// A robot's connection to the fleet's shared tables: the inverted file, the other robots'
/// key images and the inter-robot loop edges (see the top of this file). Its own
/// connection, apart from the robot's store: it reads what the store committed.
class FleetIndex {
 public:
  /// Robot `robot` of the fleet's memory at `uri` (the robot must exist: its store made it).
  FleetIndex(const std::string& uri, const std::string& robot)
      : robot_(robot), db_(pg::Connection(uri, "robot '" + robot + "' of memory '" + pg::redacted(uri) + "'")) {
    if (!detail::fleet_present(db_, detail::fleet_version))
      db_.fail("does not exist: the database holds no vmap memory", ErrorKind::not_found);
    const auto id = detail::fleet_robot(db_, robot);
    if (!id) db_.fail("does not exist: the fleet has no such robot", ErrorKind::not_found);
    id_ = *id;
  }

  [[nodiscard]] const std::string& robot() const noexcept { return robot_; }

  /// The other robots' key images whose heavy score against `bow` (of the vocabulary
  /// whose record has CRC-32 `vocabulary`) is at least run_link_min_score, the best
  /// run_link_candidates of them, best first (ties by robot and key image, so the order
  /// is the same at every run).
  [[nodiscard]] std::vector<FleetCandidate> candidates(const BowVector& bow, std::int64_t vocabulary) {
    revive();
    const auto [words, weights] = detail::heavy_postings(bow);
    if (!rank_)
      rank_.emplace(db_.prepare(
          "SELECT r.name, p.key, CAST(sum(least(q.x, p.weight)) AS bigint) AS s "
          "FROM unnest(CAST(? AS integer[]), CAST(? AS bigint[])) AS q(w, x) "
          "JOIN vmap.postings p ON p.word = q.w AND p.vocabulary = ? "
          "JOIN vmap.robots r ON r.id = p.robot "
          "WHERE p.robot <> ? GROUP BY r.name, p.robot, p.key HAVING sum(least(q.x, p.weight)) >= ? "
          "ORDER BY s DESC, p.robot, p.key LIMIT ?",
          "rank the fleet's key images"));
    detail::StoreQuery& q = *rank_;
    q.reset();
    q.bind_text(1, detail::pg_array(words)).bind_text(2, detail::pg_array(weights)).bind(3, vocabulary).bind(4, id_);
    q.bind(5, static_cast<std::int64_t>(heavy_units(run_link_min_score)));
    q.bind(6, static_cast<std::int64_t>(run_link_candidates));
    std::vector<FleetCandidate> out;
    while (q.step()) {
      const std::int64_t units = q.integer(2);
      out.push_back({q.text(0), detail::checked_key(q.integer(1), db_), heavy_score(static_cast<std::uint64_t>(std::max<std::int64_t>(units, 0)))});
    }
    q.reset();
    return out;
  }

  /// The features of another robot's key image, read from its memory (its checksum checked).
  [[nodiscard]] Features features(const FleetCandidate& c) {
    revive();
    const std::int64_t id = robot_id(c.robot);
    auto it = read_key_.find(id);
    if (it == read_key_.end())
      it = read_key_
               .emplace(id, db_.prepare("SELECT CASE WHEN length(record) <= ? THEN record END, CASE WHEN "
                                            "length(detections) <= ? THEN detections END, crc, length(record), "
                                            "length(detections) FROM " + detail::robot_schema(id) +
                                            ".key_images WHERE id = ?",
                                        "read another robot's key image"))
               .first;
    StoreQuery& q = it->second;
    q.reset();
    // Each blob read only within its limit, as MemoryStore reads its own rows.
    MapLoadOptions limits;
    q.bind(1, static_cast<std::int64_t>(limits.max_file_bytes))
        .bind(2, static_cast<std::int64_t>(detail::detections_limit))
        .bind(3, static_cast<std::int64_t>(c.key));
    const std::string who = db_.what() + ": robot '" + c.robot + "' key image " + std::to_string(c.key);
    if (!q.step()) detail::fail(ErrorKind::corrupt, who + " is missing");
    if (q.is_null(0) || q.is_null(1))
      detail::fail(ErrorKind::corrupt, who + ": its record (" + std::to_string(q.integer(3)) + " bytes) or detections (" +
                                           std::to_string(q.integer(4)) + " bytes) are longer than they can be");
    if (detail::row_crc(q.blob(0), q.blob(1)) != q.integer(2))
      detail::fail(ErrorKind::corrupt, who + ": checksum mismatch (the store is corrupt)");
    detail::BinaryReader r(q.blob(0), who);
    limits.decode_images = false;
    std::uint64_t pixels = 0;
    Features f = detail::read_key_record(r, 5, {limits, pixels, nullptr, true}).key.features;
    r.expect_end("the key image");
    q.reset();
    return f;
  }

  /// Records an inter-robot loop edge (once per pair of key images: a pair another robot
  /// recorded already is kept as it is).
  void record(const FleetLoop& e) {
    revive();
    const std::int64_t other = robot_id(e.to_robot);
    // The record is a loop edge's without its two key images, which the columns hold
    // (with their robots): the link (format.hpp) and the confidence.
    detail::BinaryWriter w;
    detail::memory_write_link(w, e.link);
    w.f64(e.link.confidence);
    const std::string record = std::move(w).take();
    const bool first = id_ < other || (id_ == other && e.from_key < e.to_key);
    StoreQuery& q = statement(record_,
                              "INSERT INTO vmap.fleet_loops(a_robot, a_key, b_robot, b_key, from_robot, inliers, "
                              "confidence, record, crc) VALUES(?,?,?,?,?,?,?,?,?) ON CONFLICT DO NOTHING",
                              "record a loop between robots");
    q.bind(1, first ? id_ : other).bind(2, static_cast<std::int64_t>(first ? e.from_key : e.to_key));
    q.bind(3, first ? other : id_).bind(4, static_cast<std::int64_t>(first ? e.to_key : e.from_key));
    q.bind(5, id_).bind(6, static_cast<std::int64_t>(e.link.inliers)).bind(7, e.link.confidence);
    q.bind_blob(8, record).bind(9, detail::row_crc(record));
    q.run();
  }

  /// The key images of this robot whose bags of words were looked for in the fleet (the
  /// next search starts there; a resumed robot goes on from it).
  [[nodiscard]] std::size_t linked() {
    revive();
    StoreQuery& q = statement(linked_, "SELECT linked FROM vmap.robots WHERE id = ?", "read how far the robot was linked");
    q.bind(1, id_);
    if (!q.step()) db_.fail("does not exist: the fleet has no such robot", ErrorKind::not_found);
    const auto n = static_cast<std::size_t>(std::max<std::int64_t>(q.integer(0), 0));
    q.reset();
    return n;
  }
  void set_linked(std::size_t keys) {
    revive();
    StoreQuery& q =
        statement(set_linked_, "UPDATE vmap.robots SET linked = ? WHERE id = ?", "record how far the robot was linked");
    q.bind(1, static_cast<std::int64_t>(keys)).bind(2, id_);
    q.run();
  }

 private:
  using StoreQuery = detail::StoreQuery;

  void revive() {
    if (db_.server().broken()) db_.server().reconnect();
  }

  /// The statement kept in `slot`, prepared at its first use (the server keeps it for the
  /// connection's life, so a query costs one round trip).
  StoreQuery& statement(std::optional<StoreQuery>& slot, const std::string& sql, const char* what) {
    if (!slot) slot.emplace(db_.prepare(sql, what));
    slot->reset();
    return *slot;
  }

  /// Robot `name`'s number (kept: robots are never renamed, and one that is removed
  /// held nothing another robot could have found).
  std::int64_t robot_id(const std::string& name) {
    if (const auto it = ids_.find(name); it != ids_.end()) return it->second;
    const auto id = detail::fleet_robot(db_, name);
    if (!id) db_.fail("has no robot '" + name + "' any more", ErrorKind::not_found);
    ids_.emplace(name, *id);
    return *id;
  }

  std::string robot_;
  detail::StoreDb db_;
  std::int64_t id_ = 0;
  std::optional<StoreQuery> rank_, record_, linked_, set_linked_;
  std::map<std::int64_t, StoreQuery> read_key_;  ///< by robot
  std::map<std::string, std::int64_t> ids_;
};

/// What a robot of a fleet's memory holds (fleet_summary).
struct FleetRobotSummary {
  std::string robot;
  std::size_t frames = 0, key_images = 0, sessions = 0;
  std::size_t loops = 0;        ///< loop edges within its own memory
  std::size_t fleet_loops = 0;  ///< loop edges between its key images and another robot's
  std::size_t linked = 0;       ///< its key images looked for among the other robots'
};

/// Each robot of the fleet's memory at `uri`, in the order they joined (counted on the
/// server: no memory is loaded). Empty when the database holds no vmap memory.
[[nodiscard]] inline std::vector<FleetRobotSummary> fleet_summary(const std::string& uri) {
  detail::StoreDb db(pg::Connection(uri, "memory '" + pg::redacted(uri) + "'"));
  if (!detail::fleet_present(db, detail::fleet_version)) return {};
  detail::StoreTransaction snapshot(db, "read the fleet", detail::StoreTransaction::Kind::read);
  std::vector<std::pair<std::int64_t, FleetRobotSummary>> robots;
  {
    auto q = db.prepare("SELECT id, name, linked FROM vmap.robots ORDER BY id", "list the robots");
    while (q.step()) {
      FleetRobotSummary r;
      r.robot = q.text(1);
      r.linked = static_cast<std::size_t>(std::max<std::int64_t>(q.integer(2), 0));
      robots.emplace_back(q.integer(0), std::move(r));
    }
  }
  const auto count = [&](const std::string& sql, std::int64_t id) {
    auto q = db.prepare(sql, "count a robot's rows");
    if (sql.find('?') != std::string::npos) q.bind(1, id).bind(2, id);
    if (!q.step()) db.fail("count a robot's rows: no row");
    return static_cast<std::size_t>(std::max<std::int64_t>(q.integer(0), 0));
  };
  std::vector<FleetRobotSummary> out;
  for (auto& [id, r] : robots) {
    const std::string schema = detail::robot_schema(id);
    r.key_images = count("SELECT count(*) FROM " + schema + ".key_images", id);
    r.loops = count("SELECT count(*) FROM " + schema + ".loops", id);
    r.sessions = count("SELECT count(*) FROM " + schema + ".sessions", id);
    r.fleet_loops = count("SELECT count(*) FROM vmap.fleet_loops WHERE a_robot = ? OR b_robot = ?", id);
    auto q = db.prepare("SELECT CASE WHEN length(value) = 8 THEN value END, crc FROM " + schema + ".meta WHERE name = 'frames'",
                        "read a robot's frame count");
    if (q.step()) {
      if (q.is_null(0)) db.fail("is corrupt: robot '" + r.robot + "''s frame count is not 8 bytes long", ErrorKind::corrupt);
      if (detail::row_crc(q.blob(0)) != q.integer(1))
        db.fail("is corrupt: robot '" + r.robot + "''s frame count does not match its checksum", ErrorKind::corrupt);
      detail::BinaryReader f(q.blob(0), db.what() + " robot '" + r.robot + "' state 'frames'");
      r.frames = static_cast<std::size_t>(f.u64("frame count"));
    }
    out.push_back(std::move(r));
  }
  snapshot.commit();
  return out;
}

/// Every inter-robot loop edge of the fleet's memory at `uri`, by robot and key image.
[[nodiscard]] inline std::vector<FleetLoop> fleet_loops(const std::string& uri) {
  detail::StoreDb db(pg::Connection(uri, "memory '" + pg::redacted(uri) + "'"));
  if (!detail::fleet_present(db, detail::fleet_version)) return {};
  auto q = db.prepare(
      "SELECT f.name, l.from_robot = l.a_robot, a.name, l.a_key, b.name, l.b_key, "
      "CASE WHEN length(l.record) <= " + std::to_string(detail::small_record_limit) + " THEN l.record END, l.crc, l.inliers, "
      "l.confidence "
      "FROM vmap.fleet_loops l JOIN vmap.robots a ON a.id = l.a_robot JOIN vmap.robots b ON b.id = l.b_robot "
      "JOIN vmap.robots f ON f.id = l.from_robot ORDER BY l.a_robot, l.a_key, l.b_robot, l.b_key",
      "read the loops between robots");
  std::vector<FleetLoop> out;
  while (q.step()) {
    const bool from_a = q.integer(1) != 0;
    const std::string who = db.what() + " loop between robots";
    if (q.is_null(6)) detail::fail(ErrorKind::corrupt, who + ": its record is longer than a loop edge's can be");
    if (detail::row_crc(q.blob(6)) != q.integer(7)) detail::fail(ErrorKind::corrupt, who + ": checksum mismatch");
    detail::BinaryReader r(q.blob(6), who);
    FleetLoop l;
    l.link = detail::memory_read_link(r);
    l.link.confidence = detail::read_confidence(r);
    r.expect_end("the loop edge");
    l.from_robot = from_a ? q.text(2) : q.text(4);
    l.to_robot = from_a ? q.text(4) : q.text(2);
    l.from_key = detail::checked_key(from_a ? q.integer(3) : q.integer(5), db);
    l.to_key = detail::checked_key(from_a ? q.integer(5) : q.integer(3), db);
    l.link.key = l.to_key;
    if (q.integer(8) != l.link.inliers || q.real(9) != l.link.confidence)
      detail::fail(ErrorKind::corrupt, who + ": its columns do not match its record");
    out.push_back(std::move(l));
  }
  return out;
}

/// Looks for key image `key` of `memory` (a robot of the fleet; its bag of words is in
/// its place database and committed) among the other robots' key images: the candidates
/// of the fleet's inverted file, each verified and decided by the place rule between runs
/// (VisualMemory::link_pair) with the memory's own matcher and estimator; each accepted
/// pair is recorded as an inter-robot loop edge. Returns them, best candidate first.
template <class Memory>
[[nodiscard]] std::vector<FleetLoop> link_across_fleet(Memory& memory, std::uint32_t key, FleetIndex& fleet,
                                                       std::int64_t vocabulary) {
  std::vector<FleetLoop> out;
  const BowVector* bow = memory.database().bow(key);
  if (!memory.loop_engine() || !bow) return out;
  const std::vector<FleetCandidate> ranked = fleet.candidates(*bow, vocabulary);
  if (ranked.empty()) return out;
  const Features query = memory.key_features(key);
  for (const FleetCandidate& c : ranked) {
    std::optional<PlaceLink> link = memory.link_pair(query, fleet.features(c), c.score);
    if (!link) continue;
    FleetLoop loop;
    loop.from_robot = fleet.robot();
    loop.from_key = key;
    loop.to_robot = c.robot;
    loop.to_key = c.key;
    loop.link = *link;
    loop.link.key = c.key;
    fleet.record(loop);
    out.push_back(std::move(loop));
  }
  return out;
}

}  // namespace vmap
