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
// postings. A query ranks the other robots' key images by DBoW2's L1 score (T-RO 2012,
// eq. 2: for L1-normalised weights, sum over the shared words of min(v_i, w_i)), computed
// by the server over the postings of the query's 64 heaviest words (an index that holds
// the postings whole answers it), among robots whose vocabulary is
// the query's (by the CRC-32 of its record: bags of words of two vocabularies do not
// compare). The features of the best `top_k` candidates, and only those, cross the
// network; they are verified with the robot's own matcher and estimator, and the place
// is decided as localization decides it (LoopEngine::decide: evidence, confidence,
// ambiguity; no revisit rule between robots). An accepted place is an inter-robot loop
// edge (vmap.fleet_loops), recorded once per pair of key images whichever robot found it.
//
// Every pair of key images of two robots is considered at least once: a robot queries
// after its own postings are committed, so of two key images written at the same time
// the later query sees the other.

#include <vmap/core/error.hpp>
#include <vmap/core/features.hpp>
#include <vmap/io/binary.hpp>
#include <vmap/io/postgres.hpp>
#include <vmap/keyframe/map_io.hpp>
#include <vmap/memory/detail/fleet_schema.hpp>
#include <vmap/memory/detail/record_codecs.hpp>
#include <vmap/memory/detail/store_db.hpp>
#include <vmap/memory/store.hpp>
#include <vmap/memory/types.hpp>
#include <vmap/place/bow.hpp>

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

/// The words of a query that the fleet's inverted file ranks by (FleetIndex::candidates).
inline constexpr std::size_t fleet_query_words = 64;

/// A key image of another robot that the fleet's inverted file ranked for a query.
struct FleetCandidate {
  std::string robot;
  std::uint32_t key = 0;
  double score = 0.0;  ///< DBoW2's L1 score against the query, in [0, 1]
};

namespace detail {

}  // namespace detail

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

  /// The other robots' key images whose bags of words share words with `bow` (of the
  /// vocabulary whose record has CRC-32 `vocabulary`), the `top_k` best by L1 score,
  /// best first (ties by robot and key image, so the order is the same at every run).
  /// The score is summed over the query's `max_words` heaviest words (0: all): the
  /// server's work is the postings of the words asked, so the heaviest, which carry most
  /// of the score, keep a query's cost bounded (results/fleet.md measures it).
  [[nodiscard]] std::vector<FleetCandidate> candidates(const BowVector& bow, std::size_t top_k, std::int64_t vocabulary,
                                                       std::size_t max_words = fleet_query_words) {
    revive();
    auto postings = detail::l1_postings(bow);
    std::vector<std::int64_t>& words = postings.first;
    std::vector<double>& weights = postings.second;
    if (max_words > 0 && words.size() > max_words) {
      std::vector<std::size_t> order(words.size());
      for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
      std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return weights[a] > weights[b]; });
      order.resize(max_words);
      std::sort(order.begin(), order.end());
      std::vector<std::int64_t> w;
      std::vector<double> x;
      for (const std::size_t i : order) {
        w.push_back(words[i]);
        x.push_back(weights[i]);
      }
      words = std::move(w);
      weights = std::move(x);
    }
    auto q = db_.prepare(
        "SELECT r.name, p.key, sum(least(q.x, p.weight)) AS s "
        "FROM unnest(CAST(? AS integer[]), CAST(? AS double precision[])) AS q(w, x) "
        "JOIN vmap.postings p ON p.word = q.w AND p.vocabulary = ? "
        "JOIN vmap.robots r ON r.id = p.robot "
        "WHERE p.robot <> ? GROUP BY r.name, p.robot, p.key ORDER BY s DESC, p.robot, p.key LIMIT ?",
        "rank the fleet's key images");
    q.bind_text(1, detail::pg_array(words)).bind_text(2, detail::pg_array(weights)).bind(3, vocabulary).bind(4, id_);
    q.bind(5, static_cast<std::int64_t>(top_k));
    std::vector<FleetCandidate> out;
    while (q.step())
      out.push_back({q.text(0), detail::checked_key(q.integer(1), db_), std::clamp(q.real(2), 0.0, 1.0)});
    return out;
  }

  /// The features of another robot's key image, read from its memory (its checksum checked).
  [[nodiscard]] Features features(const FleetCandidate& c) {
    revive();
    const auto id = detail::fleet_robot(db_, c.robot);
    if (!id) db_.fail("has no robot '" + c.robot + "' any more", ErrorKind::not_found);
    auto q = db_.prepare("SELECT record, detections, crc FROM " + detail::robot_schema(*id) + ".key_images WHERE id = ?",
                         "read another robot's key image");
    q.bind(1, static_cast<std::int64_t>(c.key));
    const std::string who = db_.what() + ": robot '" + c.robot + "' key image " + std::to_string(c.key);
    if (!q.step()) detail::fail(ErrorKind::corrupt, who + " is missing");
    if (detail::row_crc(q.blob(0), q.blob(1)) != q.integer(2))
      detail::fail(ErrorKind::corrupt, who + ": checksum mismatch (the store is corrupt)");
    detail::BinaryReader r(q.blob(0), who);
    MapLoadOptions limits;
    limits.decode_images = false;
    std::uint64_t pixels = 0;
    Features f = detail::read_key_record(r, 5, {limits, pixels, nullptr, true}).key.features;
    r.expect_end("the key image");
    return f;
  }

  /// Records an inter-robot loop edge (once per pair of key images: a pair another robot
  /// recorded already is kept as it is).
  void record(const FleetLoop& e) {
    revive();
    const auto other = detail::fleet_robot(db_, e.to_robot);
    if (!other) db_.fail("has no robot '" + e.to_robot + "' any more", ErrorKind::not_found);
    // The record is a loop edge's without its two key images, which the columns hold
    // (with their robots): the link (format.hpp) and the confidence.
    detail::BinaryWriter w;
    detail::memory_write_link(w, e.link);
    w.f64(e.link.confidence);
    const std::string record = std::move(w).take();
    const bool first = id_ < *other || (id_ == *other && e.from_key < e.to_key);
    auto q = db_.prepare(
        "INSERT INTO vmap.fleet_loops(a_robot, a_key, b_robot, b_key, from_robot, inliers, confidence, record, crc) "
        "VALUES(?,?,?,?,?,?,?,?,?) ON CONFLICT DO NOTHING",
        "record a loop between robots");
    q.bind(1, first ? id_ : *other).bind(2, static_cast<std::int64_t>(first ? e.from_key : e.to_key));
    q.bind(3, first ? *other : id_).bind(4, static_cast<std::int64_t>(first ? e.to_key : e.from_key));
    q.bind(5, id_).bind(6, static_cast<std::int64_t>(e.link.inliers)).bind(7, e.link.confidence);
    q.bind_blob(8, record).bind(9, detail::row_crc(record));
    q.run();
  }

  /// The key images of this robot whose bags of words were looked for in the fleet (the
  /// next search starts there; a resumed robot goes on from it).
  [[nodiscard]] std::size_t linked() {
    revive();
    auto q = db_.prepare("SELECT linked FROM vmap.robots WHERE id = ?", "read how far the robot was linked");
    q.bind(1, id_);
    if (!q.step()) db_.fail("does not exist: the fleet has no such robot", ErrorKind::not_found);
    return static_cast<std::size_t>(std::max<std::int64_t>(q.integer(0), 0));
  }
  void set_linked(std::size_t keys) {
    revive();
    auto q = db_.prepare("UPDATE vmap.robots SET linked = ? WHERE id = ?", "record how far the robot was linked");
    q.bind(1, static_cast<std::int64_t>(keys)).bind(2, id_);
    q.run();
  }

 private:
  void revive() {
    if (db_.server().broken()) db_.server().reconnect();
  }

  std::string robot_;
  detail::StoreDb db_;
  std::int64_t id_ = 0;
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
    auto q = db.prepare("SELECT value, crc FROM " + schema + ".meta WHERE name = 'frames'", "read a robot's frame count");
    if (q.step()) {
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
      "SELECT f.name, l.from_robot = l.a_robot, a.name, l.a_key, b.name, l.b_key, l.record, l.crc, l.inliers, l.confidence "
      "FROM vmap.fleet_loops l JOIN vmap.robots a ON a.id = l.a_robot JOIN vmap.robots b ON b.id = l.b_robot "
      "JOIN vmap.robots f ON f.id = l.from_robot ORDER BY l.a_robot, l.a_key, l.b_robot, l.b_key",
      "read the loops between robots");
  std::vector<FleetLoop> out;
  while (q.step()) {
    const bool from_a = q.integer(1) != 0;
    const std::string who = db.what() + " loop between robots";
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
/// its place database and committed) among the other robots' key images: ranks them in
/// the fleet's inverted file, verifies the memory's `top_k` best (default: its options'
/// localize_top_k) with its own matcher and estimator, decides with its place decision,
/// and records an accepted place as an inter-robot loop edge. Returns it, or nothing.
template <class Memory>
[[nodiscard]] std::optional<FleetLoop> link_across_fleet(Memory& memory, std::uint32_t key, FleetIndex& fleet,
                                                         std::int64_t vocabulary, std::size_t top_k = 0) {
  const auto* engine = memory.loop_engine();
  const BowVector* bow = memory.database().bow(key);
  if (!engine || !bow) return std::nullopt;
  const std::vector<FleetCandidate> ranked =
      fleet.candidates(*bow, top_k > 0 ? top_k : memory.options().localize_top_k, vocabulary);
  if (ranked.empty()) return std::nullopt;
  std::vector<Features> features;
  std::vector<std::pair<std::size_t, double>> to_verify;
  for (std::size_t i = 0; i < ranked.size(); ++i) {
    features.push_back(fleet.features(ranked[i]));
    to_verify.emplace_back(i, ranked[i].score);
  }
  const Features query = memory.key_features(key);
  const auto lookup = [&](std::size_t i) -> const Features& { return features[i]; };
  const PlaceDecision d = engine->decide(query, to_verify, lookup);
  if (!d.accepted() || !d.best) return std::nullopt;
  const std::size_t best = *d.best;
  FleetLoop loop;
  loop.from_robot = fleet.robot();
  loop.from_key = key;
  loop.to_robot = ranked[best].robot;
  loop.to_key = ranked[best].key;
  for (const PlaceCandidate& c : d.considered)
    if (c.stage == CandidateStage::chosen) {
      loop.link = memory.link_to(c, query, features[best]);
      loop.link.key = ranked[best].key;
    }
  fleet.record(loop);
  return loop;
}

}  // namespace vmap
