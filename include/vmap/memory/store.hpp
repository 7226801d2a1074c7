#pragma once

// A visual memory kept in an SQLite file (io/sqlite.hpp), or as one robot's memory in a
// fleet's memory on a PostgreSQL server (io/postgres.hpp, memory/detail/fleet_schema.hpp:
// give a postgresql:// URI and the robot's name instead of a path), written key image by
// key image: the back-ends of the memory's records that grow (memory/records.hpp; the
// other is the single file of memory/vmem.hpp). Both hold the same tables, rows and
// bytes, read and written by the code below through one interface
// (memory/detail/store_db.hpp); what differs on a server is said where it differs.
//
//   auto store = vmap::MemoryStore::create("run.vmdb");
//   vmap::OrbVisualMemory memory;
//   for (...) { memory.push(frame); store.sync(memory); }   // one transaction per call
//   store.flush();                                          // the last one committed
//   ...
//   auto again = vmap::MemoryStore::open("run.vmdb").load<vmap::OrbVisualMemory>();
//
// sync() writes the records the memory made since the last sync (VisualMemory::records),
// in one transaction: each new key image (its features, pixels, pose and detections),
// the link to it, the bag of words of each key image newly checked for loops, each new
// loop edge, and the few small rows of state (the selector's I_{j-1}, the loop engine's
// counts, the options); the vocabulary and the GCS only when they change. Rows once
// written are never rewritten, so a sync costs the same at key image 10 as at key image
// 10,000, and a key image's JPEG or PNG is encoded once.
//
// sync() encodes the rows in the caller's thread (the memory changes once sync()
// returns) and hands them to the store's writer thread, which runs the transaction
// (inserts, COMMIT and its fsync) while the caller pushes the next frame. One sync is in
// flight at a time: sync() first waits for the previous one's commit. A crash or power
// cut thus loses at most the sync in flight (SQLite's write-ahead log with
// synchronous=FULL makes each committed one durable); the file stays a valid memory. A
// transaction that fails in the writer thread is thrown as a vmap::Error by the next
// sync(), flush() or reader of the store; it stored nothing, and the sync after the
// error writes its rows again. The destructor waits too but cannot throw: flush() (or
// checkpoint()) before the store goes out of scope to learn a failure of the last sync.
//
// load() reads the rows back into records and rebuilds the memory from them
// (VisualMemory::from_records), with the same checks as a .vmem file: a memory loaded
// from a store is the memory that was synced, and pushing on continues exactly as the
// uninterrupted run. Every row is checked: its CRC-32 (each blob's), its plain columns
// against the record they repeat, and the row counts against the counts the state
// records, so a damaged, deleted or duplicated row is an Error naming it.
//
// A working memory bounds the RAM of a long run: bound(memory, N) keeps the features of
// the memory's N most recent key images in RAM, sync() releases the older ones once
// committed, and the memory reads them back from the store when a candidate needs them
// (VisualMemory::bound_features); load_bounded<Memory>(N) loads a memory so, reading the
// older key images' records without their features.
//
// One writer at a time (open(..., write) of a memory another program writes is refused
// with a message naming the file; on a server, the robot's advisory lock); any number of
// readers (open(..., read)) load the last committed sync while the writer goes on. On a
// server, a sync whose connection broke (the server restarted) fails as `unavailable`;
// the next sync connects again and writes the rows again, those a lost COMMIT answer
// may have stored kept as they are; each sync also writes the bags of words into the
// fleet's inverted file (memory/fleet.hpp). An existing memory is replaced by a new
// store through MemoryReplacement (memory/replace.hpp): the new store is built beside it
// under another name and renamed over it when closed, so readers see the old memory
// until then, and a failed or killed run leaves the old memory as it was.
//
// Threading: a MemoryStore object is used by one thread at a time (the one that pushes
// into the memory). Its writer thread uses the SQLite connection only while a sync is
// in flight; everything else that reads or writes the file through the object waits for
// that sync first (flush()), so the connection is used by one thread at a time.
//
// Schema version 4 (PRAGMA application_id 0x564D4150 "VMAP", PRAGMA user_version 4): the
// tables meta, key_images, links, loops, notes and sessions, whose columns and blobs
// (each the bytes of one record, memory/detail/record_codecs.hpp) are documented for
// readers without vmap in examples/memory.md, "The memory store". A reader reads a store
// of version 1 (no sessions table: one session), 2 or 3 (records as the single-file
// format's version 4, no checksums) as it is; a writer brings it to version 4 when it
// opens it, in one transaction.

#include <vmap/core/error.hpp>
#include <vmap/io/binary.hpp>
#include <vmap/io/sqlite.hpp>
#include <vmap/memory/detail/fleet_schema.hpp>
#include <vmap/memory/detail/format.hpp>
#include <vmap/memory/detail/store_db.hpp>
#include <vmap/memory/detail/record_codecs.hpp>
#include <vmap/memory/records.hpp>
#include <vmap/memory/replace.hpp>
#include <vmap/memory/visual_memory.hpp>
#include <vmap/place/database.hpp>

#include <array>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <exception>
#include <filesystem>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <system_error>
#include <thread>
#include <tuple>
#include <type_traits>
#include <utility>
#include <vector>

namespace vmap {

/// The store's schema version (PRAGMA user_version).
inline constexpr std::int64_t memory_store_version = 4;
/// PRAGMA application_id of a memory store: "VMAP" (what memory_kind recognises it by).
inline constexpr std::int64_t memory_store_application_id = detail::memory_application_id;

namespace detail {

/// The CRC-32 of a row's blobs, as the store records it (of their bytes one after the
/// other, computed without joining them).
inline std::int64_t row_crc(std::string_view a, std::string_view b = {}) {
  return static_cast<std::int64_t>(crc32(b, crc32(a)));
}

/// One sync's rows, encoded in the caller's thread for the store's writer thread.
struct MemoryStoreRows {
  struct Key {
    std::int64_t id = 0, frame_index = 0;
    double timestamp = 0.0;
    std::int64_t time_ns = 0;
    std::string name;
    std::int64_t keypoints = 0;
    std::string record, detections;
    std::int64_t crc = 0;
  };
  struct Link {
    std::int64_t key = 0, matches = 0, inliers = 0;
    double similarity = 0.0;
    std::string record;
    std::int64_t crc = 0;
  };
  struct Bow {
    std::int64_t key = 0;
    std::string record;
    std::int64_t crc = 0;
    BowVector bow;  ///< its words and weights: the fleet's postings, on a server
  };
  struct Loop {
    std::int64_t id = 0, from_key = 0, to_key = 0, inliers = 0;
    double confidence = 0.0;
    std::string record;
    std::int64_t crc = 0;
  };
  struct Session {
    std::int64_t id = 0, first_key = 0, first_frame = 0;
  };
  std::vector<Key> keys;
  std::vector<Link> links;
  std::vector<Bow> bows;
  std::vector<Loop> loops;
  std::vector<Session> sessions;
  std::vector<std::pair<const char*, std::string>> meta;  ///< the state rows (name, bytes), rewritten at every sync
};

/// The counts the store records with every sync ("counts"): key images, loop edges, bags
/// of words and sessions, so that a missing or extra row is found.
inline std::string store_counts(std::size_t keys, std::size_t loops, std::size_t bows, std::size_t sessions) {
  BinaryWriter w;
  w.u64(keys);
  w.u64(loops);
  w.u64(bows);
  w.u64(sessions);
  return std::move(w).take();
}

/// The state row "sessions": every session's first key image and first frame, what the
/// sessions table repeats (checked against it when the store is read).
inline std::string store_sessions(const std::vector<MemorySession>& sessions) {
  BinaryWriter w;
  w.u64(sessions.size());
  for (const MemorySession& s : sessions) {
    w.u64(s.first_key);
    w.u64(s.first_frame);
  }
  return std::move(w).take();
}

/// The most bytes a link's or a loop edge's record may hold (a few fixed fields).
inline constexpr std::uint64_t small_record_limit = 4096;
/// The most bytes a key image's detections may hold (memory_max_detections of 24 bytes).
inline constexpr std::uint64_t detections_limit = 4 + std::uint64_t{24} * memory_max_detections;

/// SQL that selects the state row `name = ?` of the meta table without searching its
/// key: the meta table is WITHOUT ROWID, where SQLite's search of a key loads the whole
/// row of every key it compares with that holds more than a page, so a row padded to a
/// GB would be read before its length is checked. A scan of its few rows reads each
/// name only ("name || ''" is an expression SQLite cannot search by; PostgreSQL reads
/// it the same).
inline constexpr const char* meta_row_unsearched = "name || '' = ?";

/// The most bytes a state row may hold, by its name: its size where it has one, the
/// limits of its contents where they bound it, and `large` (MapLoadOptions::
/// max_file_bytes) for the rows of features, pixels or a vocabulary, as a single-file
/// memory is bounded whole. A row is refused by its length before it is read.
inline std::uint64_t state_row_limit(std::string_view name, std::uint64_t large) {
  constexpr std::uint64_t small = std::uint64_t{1} << 20;
  if (name == "counts") return 32;                        // four u64
  if (name == "frames") return 8;                         // one u64
  if (name == "database") return 9;                       // u8 scoring, u64 words
  if (name == "decision") return 4096;                    // LoopEngineState: a few counts
  if (name == "policies") return 4 * (4 + memory_max_policy);
  if (name == "previous_detections") return detections_limit;
  if (name == "options" || name == "labels") return small;  // fixed fields and label lists
  return large;                                             // selector, vocabulary, gcs, sessions
}

/// The rows of the records a memory made since the store's last sync (a delta: the
/// lists start where the store's rows end); `sessions` are all of the memory's sessions.
inline MemoryStoreRows store_rows(const MemoryRecords& r, const std::vector<MemorySession>& sessions) {
  const ImageStorage storage = r.options.images;
  const int quality = r.options.jpeg_quality;
  MemoryStoreRows rows;
  for (std::size_t i = 0; i < r.keys.size(); ++i) {
    const KeyImageRecord& k = r.keys[i];
    BinaryWriter record, detections;
    write_key_record(record, k.key, k.key.features, k.pose, storage, quality);
    memory_write_detections(detections, k.detections);
    MemoryStoreRows::Key row{static_cast<std::int64_t>(r.first_key + i),
                             static_cast<std::int64_t>(k.key.frame_index),
                             k.key.timestamp,
                             k.key.time_ns,
                             k.key.name,
                             static_cast<std::int64_t>(k.key.features.keypoints.size()),
                             std::move(record).take(),
                             std::move(detections).take(),
                             0};
    row.crc = row_crc(row.record, row.detections);
    rows.keys.push_back(std::move(row));
  }
  const std::size_t first_linked = std::max<std::size_t>(r.first_key, 1);
  for (std::size_t i = 0; i < r.links.size(); ++i) {
    const KeyPair& p = r.links[i];
    BinaryWriter record;
    write_key_pair(record, p);
    MemoryStoreRows::Link row{static_cast<std::int64_t>(first_linked + i), p.matches, p.inliers, p.similarity,
                              std::move(record).take(), 0};
    row.crc = row_crc(row.record);
    rows.links.push_back(std::move(row));
  }
  for (std::size_t i = 0; i < r.bows.size(); ++i) {
    const auto id = static_cast<std::uint32_t>(r.first_bow + i);
    MemoryStoreRows::Bow row{id, PlaceDatabase<std::uint32_t>::record_of(id, r.bows[i]), 0, r.bows[i]};
    row.crc = row_crc(row.record);
    rows.bows.push_back(std::move(row));
  }
  for (std::size_t i = 0; i < r.loops.size(); ++i) {
    const LoopEdge& e = r.loops[i];
    BinaryWriter record;
    write_loop_record(record, e);
    MemoryStoreRows::Loop row{static_cast<std::int64_t>(r.first_loop + i), e.from, e.link.key, e.link.inliers,
                              e.link.confidence, std::move(record).take(), 0};
    row.crc = row_crc(row.record);
    rows.loops.push_back(std::move(row));
  }
  for (std::size_t i = 0; i < r.sessions.size(); ++i)
    rows.sessions.push_back({static_cast<std::int64_t>(r.first_session + i),
                             static_cast<std::int64_t>(r.sessions[i].first_key),
                             static_cast<std::int64_t>(r.sessions[i].first_frame)});
  // The small state, rewritten at every sync (a few hundred bytes, and I_{j-1}'s features).
  auto& meta = rows.meta;
  const auto add = [&](const char* name, BinaryWriter&& w) { meta.emplace_back(name, std::move(w).take()); };
  {
    BinaryWriter w;
    write_memory_options(w, r.options, storage);
    add("options", std::move(w));
  }
  {
    BinaryWriter w;
    for (const std::string& p : r.policies) w.str(p, memory_max_policy, "MemoryStore::sync: a policy record");
    add("policies", std::move(w));
  }
  {
    BinaryWriter w;
    write_labels_record(w, r.labelled, r.schema);
    add("labels", std::move(w));
  }
  {
    BinaryWriter w;
    memory_write_detections(w, r.selector.previous ? r.selector.previous->detections : std::vector<Detection>{});
    add("previous_detections", std::move(w));
  }
  {
    BinaryWriter w;
    write_selector_record(w, r.selector, storage, quality);
    add("selector", std::move(w));
  }
  {
    BinaryWriter w;
    r.engine.write(w);
    add("decision", std::move(w));
  }
  {
    BinaryWriter w;
    w.u8(static_cast<std::uint8_t>(r.options.scoring));
    w.u64(r.words);
    add("database", std::move(w));
  }
  {
    BinaryWriter w;
    w.u64(r.frames);
    add("frames", std::move(w));
  }
  meta.emplace_back("counts", store_counts(r.key_count(), r.first_loop + r.loops.size(), r.first_bow + r.bows.size(),
                                           r.first_session + r.sessions.size()));
  meta.emplace_back("sessions", store_sessions(sessions));
  if (r.vocabulary) {
    BinaryWriter w;
    write_vocabulary_record(w, *r.vocabulary);
    add("vocabulary", std::move(w));
  }
  if (r.gcs_written) {
    BinaryWriter w;
    write_gcs_record(w, r.gcs);
    add("gcs", std::move(w));
  }
  return rows;
}

/// A store's connection (an SQLite file or a PostgreSQL server) and, for a writer, the
/// thread that commits its syncs, one at a time. MemoryStore holds it on the heap, so that
/// the thread keeps using it while the MemoryStore object moves.
class MemoryStoreConnection {
 public:
  explicit MemoryStoreConnection(StoreDb connection) : db(std::move(connection)) {}
  MemoryStoreConnection(const MemoryStoreConnection&) = delete;
  MemoryStoreConnection& operator=(const MemoryStoreConnection&) = delete;
  /// Lets the writer thread commit the rows in flight, then joins it. Their error, if
  /// any, is dropped here (a destructor does not throw): MemoryStore::flush() reports it.
  ~MemoryStoreConnection() {
    if (!thread_.joinable()) return;
    {
      std::lock_guard lock(mutex_);
      stop_ = true;
    }
    changed_.notify_all();
    thread_.join();
  }

  StoreDb db;  ///< declared first: closed after the statements and the thread
  /// A server's connection that broke (the server restarted) is made again, and its
  /// session set up again, by this, before the next transaction (MemoryStore sets it).
  std::function<void()> revive;
  /// On a server: the robot's number, whose bags of words each sync also writes into the
  /// fleet's inverted file (memory/fleet.hpp), tagged with the CRC-32 of the vocabulary's
  /// record (set from the store, then by MemoryStore::sync before it hands over rows
  /// that write the vocabulary: the writer thread only reads it).
  std::int64_t fleet_robot = 0;
  std::int64_t vocabulary_crc = 0;

  /// Whether the connection writes (a writer thread runs).
  [[nodiscard]] bool writes() const noexcept { return thread_.joinable(); }

  /// Prepares the writer's statements and starts its thread.
  void start_writer() {
    prepare_statements();
    try {
      thread_ = std::thread([this] { run(); });
    } catch (const std::system_error& e) {
      db.fail(std::string("cannot start its writer thread: ") + e.what());
    }
  }

  /// Prepares the statements that insert rows (once).
  void prepare_statements() {
    if (insert_key_) return;
    // A server's COMMIT whose answer was lost (the server went away) may have committed:
    // the sync is sent again, and the rows it holds already are kept as they are (one
    // writer per memory, so they are the same rows). A file's commit is never in doubt,
    // and a row written twice stays an error there.
    const std::string again = db.postgres() ? " ON CONFLICT DO NOTHING" : "";
    insert_key_.emplace(db.prepare(
        "INSERT INTO key_images(id, frame_index, timestamp, time_ns, name, keypoints, record, detections, crc) "
        "VALUES(?,?,?,?,?,?,?,?,?)" + again,
        "insert a key image"));
    insert_link_.emplace(db.prepare(
        "INSERT INTO links(key, matches, inliers, similarity, record, crc) VALUES(?,?,?,?,?,?)" + again, "insert a link"));
    update_bow_.emplace(db.prepare("UPDATE key_images SET bow = ?, bow_crc = ? WHERE id = ?", "write a bag of words"));
    insert_loop_.emplace(db.prepare(
        "INSERT INTO loops(id, from_key, to_key, inliers, confidence, record, crc) VALUES(?,?,?,?,?,?,?)" + again,
        "insert a loop edge"));
    put_meta_.emplace(db.prepare("INSERT INTO meta(name, value, crc) VALUES(?,?,?) "
                                 "ON CONFLICT(name) DO UPDATE SET value = excluded.value, crc = excluded.crc",
                                 "write the state"));
    insert_session_.emplace(
        db.prepare("INSERT INTO sessions(id, first_key, first_frame) VALUES(?,?,?)" + again, "insert a session"));
    if (fleet_robot > 0)
      insert_postings_.emplace(db.prepare(
          "INSERT INTO vmap.postings(robot, key, word, weight, vocabulary) SELECT ?, ?, w, x, ? "
          "FROM unnest(CAST(? AS integer[]), CAST(? AS bigint[])) AS t(w, x) ON CONFLICT DO NOTHING",
          "write the bag of words into the fleet's inverted file"));
  }

  /// Hands one sync's rows to the writer thread. None may be in flight (wait() first):
  /// the caller holds at most one sync's copies besides the one being written.
  void hand_over(MemoryStoreRows rows) {
    {
      std::lock_guard lock(mutex_);
      check(!busy_, "MemoryStoreConnection::hand_over: a sync is in flight (wait for it first)");
      rows_ = std::move(rows);
      busy_ = true;
    }
    changed_.notify_all();
  }

  /// Waits until the rows handed over are committed or have failed: the failure (a
  /// vmap::Error), returned once; null when they were committed (or none was handed).
  [[nodiscard]] std::exception_ptr wait() {
    std::unique_lock lock(mutex_);
    changed_.wait(lock, [&] { return !busy_; });
    return std::exchange(error_, nullptr);
  }

  /// Inserts rows in the caller's thread, in the caller's transaction (a store being
  /// brought to the current version), before the writer thread starts.
  void write_now(const MemoryStoreRows& rows) {
    check(!thread_.joinable(), "MemoryStoreConnection::write_now: the writer thread runs");
    prepare_statements();
    insert(rows);
  }

 private:
  void run() noexcept {
    std::unique_lock lock(mutex_);
    for (;;) {
      changed_.wait(lock, [&] { return busy_ || stop_; });
      if (!busy_) return;  // stopped, nothing in flight
      // The caller does not touch rows_ while busy_: it is this thread's until then.
      lock.unlock();
      std::exception_ptr error;
      try {
        if (revive) revive();
        StoreTransaction t(db, "write the memory");
        insert(*rows_);
        t.commit();
      } catch (const std::exception& e) {
        // The kind of what failed (a full disk is io) reaches the caller with the note.
        const auto* vmap_error = dynamic_cast<const Error*>(&e);
        // On a server whose answer to COMMIT was lost the sync may have been stored: the
        // next sync's rows then keep the ones there (prepare_statements).
        error = std::make_exception_ptr(Error(vmap_error ? vmap_error->kind() : ErrorKind::io,
                                              std::string(e.what()) +
                                                  (db.postgres() ? " (an earlier sync, sent by the store's writer thread: "
                                                                   "the next sync writes its rows again)"
                                                                 : " (an earlier sync, committed in the store's writer "
                                                                   "thread: it stored nothing; the next sync writes its "
                                                                   "rows again)")));
      } catch (...) {
        error = std::make_exception_ptr(Error(ErrorKind::io,
                                              db.what() + " write the memory: an unknown error (an earlier sync, "
                                                          "committed in the store's writer thread: it stored nothing; "
                                                          "the next sync writes its rows again)"));
      }
      lock.lock();
      rows_.reset();
      error_ = error;
      busy_ = false;
      changed_.notify_all();
    }
  }

  void insert(const MemoryStoreRows& rows) {
    for (const auto& k : rows.keys) {
      insert_key_->bind(1, k.id)
          .bind(2, k.frame_index)
          .bind(3, k.timestamp)
          .bind(4, k.time_ns)
          .bind_text(5, k.name)
          .bind(6, k.keypoints)
          .bind_blob(7, k.record)
          .bind_blob(8, k.detections)
          .bind(9, k.crc);
      insert_key_->run();
    }
    for (const auto& l : rows.links) {
      insert_link_->bind(1, l.key).bind(2, l.matches).bind(3, l.inliers).bind(4, l.similarity).bind_blob(5, l.record).bind(6, l.crc);
      insert_link_->run();
    }
    for (const auto& b : rows.bows) {
      update_bow_->bind_blob(1, b.record).bind(2, b.crc).bind(3, b.key);
      update_bow_->run();
      if (insert_postings_) {
        const auto [words, weights] = heavy_postings(b.bow);
        insert_postings_->bind(1, fleet_robot).bind(2, b.key).bind(3, vocabulary_crc);
        insert_postings_->bind_text(4, pg_array(words)).bind_text(5, pg_array(weights));
        insert_postings_->run();
      }
    }
    for (const auto& e : rows.loops) {
      insert_loop_->bind(1, e.id)
          .bind(2, e.from_key)
          .bind(3, e.to_key)
          .bind(4, e.inliers)
          .bind(5, e.confidence)
          .bind_blob(6, e.record)
          .bind(7, e.crc);
      insert_loop_->run();
    }
    for (const auto& x : rows.sessions) {
      insert_session_->bind(1, x.id).bind(2, x.first_key).bind(3, x.first_frame);
      insert_session_->run();
    }
    for (const auto& [name, value] : rows.meta) {
      put_meta_->bind_text(1, name).bind_blob(2, value).bind(3, row_crc(value));
      put_meta_->run();
    }
  }

  // Prepared once for a writer, used by one thread at a time (its thread, or write_now).
  std::optional<StoreQuery> insert_key_, insert_link_, update_bow_, insert_loop_, put_meta_, insert_session_,
      insert_postings_;
  std::mutex mutex_;
  std::condition_variable changed_;      ///< busy_ or stop_ changed
  std::optional<MemoryStoreRows> rows_;  ///< the sync in flight
  bool busy_ = false;                    ///< rows_ handed over, not yet committed or failed
  bool stop_ = false;                    ///< the destructor asks the thread to end
  std::exception_ptr error_;             ///< the last sync's failure, until wait() returns it
  std::thread thread_;                   ///< joined by the destructor, before the members it uses go
};

}  // namespace detail

class MemoryStore {
 public:
  /// A new, empty store at `path`; refused when a file is there. `what` names it in
  /// messages (default "memory '<path>'"). The store is made under a temporary name beside
  /// `path` (".NAME.vmap-new-PID-N": its tables written and flushed to disk) and renamed
  /// there while its writer's lock is held, so `path` never holds a partial store: a run
  /// killed while making it leaves no file at `path` (at most the temporary file, which
  /// the next store made there removes once its process has ended). From then on it is
  /// written in place, sync by sync, and readers can follow it.
  ///
  /// A PostgreSQL connection URI (pg::is_uri) instead of a path is a fleet's memory on
  /// that server: the store is robot `robot`'s memory there, new (refused when the fleet
  /// has the robot), the fleet's schema created on first use.
  [[nodiscard]] static MemoryStore create(const std::filesystem::path& path, std::string what = {},
                                          const std::string& robot = {}) {
    if (pg::is_uri(path.native())) return open_on_server(path.native(), robot, sqlite::Access::create);
    const std::string name = what.empty() ? "memory '" + path.string() + "'" : std::move(what);
    std::error_code ec;
    if (std::filesystem::exists(std::filesystem::symlink_status(path, ec))) detail::fail(name + " exists already");
    const std::filesystem::path temp = detail::new_memory_path(path);
    sqlite::WriterLock lock;
    try {
      detail::StoreDb db(sqlite::Database(temp, sqlite::Access::create, name));
      make_tables(db);
      // The tables (and the application id memory_kind knows a store by) in the file
      // itself: its log stays beside the temporary name.
      db.exec("PRAGMA wal_checkpoint(TRUNCATE)", "move the new tables into the file");
      lock = db.sqlite().close_keeping_lock();
      if (std::filesystem::file_size(temp.string() + "-wal", ec) > 0 && !ec)
        detail::fail(ErrorKind::io, name + ": its new tables stayed in the write-ahead log '" + temp.string() + "-wal'");
      for (const char* suffix : {"-wal", "-shm"}) std::filesystem::remove(temp.string() + suffix, ec);
      detail::publish_new_file(temp, path, name);
    } catch (...) {
      for (const char* suffix : {"", "-wal", "-shm", "-journal"}) std::filesystem::remove(temp.string() + suffix, ec);
      throw;
    }
    MemoryStore s(path, std::move(lock), name);
    s.connection_->start_writer();
    return s;
  }

  /// The new store of `replacement` (memory/replace.hpp), made at its temporary path and
  /// named as the memory it replaces (or `what`); close it before committing the
  /// replacement.
  [[nodiscard]] static MemoryStore create(const MemoryReplacement& replacement, std::string what = {}) {
    const std::filesystem::path& path = replacement.path();
    MemoryStore s(path, sqlite::Access::create,
                  what.empty() ? "memory '" + replacement.target().string() + "'" : std::move(what));
    try {
      make_tables(s.db());
    } catch (...) {
      s.connection_.reset();
      std::error_code ec;
      for (const char* suffix : {"", "-wal", "-shm"}) std::filesystem::remove(path.string() + suffix, ec);
      throw;
    }
    s.connection_->start_writer();
    return s;
  }

  /// An existing store: `write` to sync a memory into it (one writer at a time; a store
  /// of an older schema is brought to the current one first), `read` to load it while
  /// another program may write.
  ///
  /// A PostgreSQL connection URI instead of a path opens robot `robot`'s memory in that
  /// fleet's memory (not_found when the fleet has no such robot, busy when another program
  /// writes it).
  [[nodiscard]] static MemoryStore open(const std::filesystem::path& path, sqlite::Access access = sqlite::Access::write,
                                        const std::string& robot = {}) {
    detail::check(access != sqlite::Access::create, "MemoryStore::open: use MemoryStore::create for a new store");
    if (pg::is_uri(path.native())) return open_on_server(path.native(), robot, access);
    std::error_code ec;
    if (std::filesystem::is_regular_file(path, ec) && std::filesystem::file_size(path, ec) == 0 && !ec)
      detail::fail(ErrorKind::corrupt, "memory '" + path.string() + "' is empty: its creation was interrupted before the tables were "
                   "written (remove it, or create the memory again)");
    MemoryStore s(path, access);
    s.check_schema();
    if (access == sqlite::Access::write && s.version_ < memory_store_version) s.upgrade();
    s.count_rows();
    if (access == sqlite::Access::write) s.connection_->start_writer();
    return s;
  }

  /// The robots of the fleet's memory at `uri` (a postgresql:// URI), in the order they
  /// joined; empty when the database holds no vmap memory yet.
  [[nodiscard]] static std::vector<std::string> robots(const std::string& uri) {
    const std::string shown = "memory '" + pg::redacted(uri) + "'";
    detail::StoreDb db(pg::Connection(uri, shown));
    if (!detail::fleet_present(db, detail::fleet_version)) return {};
    return detail::fleet_robots(db);
  }

  /// Removes robot `robot` from the fleet's memory at `uri` when its memory holds
  /// nothing (no sync was committed: a first run that failed before its first key
  /// image), so that the name can start again; true when it was removed. A robot that
  /// holds a memory, or that another program writes, is kept (false).
  static bool remove_unsynced_robot(const std::string& uri, const std::string& robot) {
    const std::string shown = pg::redacted(uri);
    detail::StoreDb db(pg::Connection(uri, "robot '" + robot + "' of memory '" + shown + "'"));
    if (!detail::fleet_present(db, detail::fleet_version)) return false;
    const auto id = detail::fleet_robot(db, robot);
    if (!id) return false;
    try {
      detail::enter_fleet_robot(db, *id, true);
    } catch (const Error& e) {
      if (e.kind() == ErrorKind::busy) return false;
      throw;
    }
    detail::StoreTransaction t(db, "remove the robot");
    {
      auto q = db.prepare("SELECT count(*) FROM meta", "look for a sync");
      if (!q.step() || q.integer(0) > 0) return false;
    }
    auto q = db.prepare("DELETE FROM vmap.robots WHERE id = ?", "remove the robot");
    q.bind(1, *id);
    q.run();
    db.exec("DROP SCHEMA " + detail::robot_schema(*id) + " CASCADE", "remove the robot's tables");
    t.commit();
    return true;
  }

  /// A move keeps the sync in flight going (the writer thread and the connection stay
  /// where they are); a store assigned over waits for its own, as the destructor does.
  MemoryStore(MemoryStore&&) noexcept = default;
  MemoryStore& operator=(MemoryStore&&) noexcept = default;
  MemoryStore(const MemoryStore&) = delete;
  MemoryStore& operator=(const MemoryStore&) = delete;
  /// Waits until the sync in flight is committed. A failure of that transaction cannot be
  /// thrown from a destructor and is dropped: flush() first to learn it.
  ~MemoryStore() = default;

  /// The file, or a fleet's URI without its password.
  [[nodiscard]] const std::filesystem::path& path() const noexcept { return path_; }
  /// The robot whose memory it is in a fleet's memory; empty for a file.
  [[nodiscard]] const std::string& robot() const noexcept { return robot_; }
  /// Whether it is kept on a PostgreSQL server (a fleet's memory) rather than in a file.
  [[nodiscard]] bool on_server() const noexcept { return db().postgres(); }
  /// On a server: the CRC-32 of the vocabulary record the fleet's inverted file tags this
  /// robot's bags of words with (memory/fleet.hpp), as of the last sync handed over.
  [[nodiscard]] std::int64_t vocabulary_crc() const noexcept { return connection_->vocabulary_crc; }
  /// The schema version of the file (memory_store_version once a writer opened it).
  [[nodiscard]] std::int64_t version() const noexcept { return version_; }
  /// Key images in the store, once every sync handed over is committed (flush() first,
  /// and its error thrown).
  [[nodiscard]] std::size_t key_images() {
    flush();
    return held_.keys;
  }
  /// Whether a memory was ever synced into the store (load() needs one); flushes first.
  [[nodiscard]] bool synced() {
    flush();
    return synced_;
  }
  /// Bags of words committed before the sync in flight (all of them after flush()):
  /// what other programs reading the store can see of this memory's place database.
  [[nodiscard]] std::size_t committed_bags() const noexcept { return committed_.bows; }

  /// Loop edges in the store; flushes first.
  [[nodiscard]] std::size_t loops() {
    flush();
    return held_.loops;
  }

  /// Writes what `memory` made since the last sync into the store, in one transaction.
  /// The rows are encoded here, in the caller's thread; the transaction runs in the
  /// store's writer thread, and sync() returns before it commits: it first waits for the
  /// previous sync's commit (one in flight at a time), and throws that one's error if it
  /// failed (then nothing of it was stored, and the next sync writes its rows again).
  /// flush() waits for the last. `memory` must be the one the store holds, grown: a
  /// memory loaded from this store, or any memory synced into a new store. Anything else
  /// is an Error naming the file (nothing handed over).
  template <Descriptor D, Matcher M, Estimator E, Similarity S>
  void sync(const VisualMemory<D, M, E, S>& memory) {
    (void)hand_over(memory);
  }

  /// sync(), then releases from RAM the features of the key images older than the
  /// memory's working memory (VisualMemory::bound_features; a no-op for a memory without
  /// one) that are committed, so that the memory never reads a key image whose commit is
  /// in flight or failed.
  template <Descriptor D, Matcher M, Estimator E, Similarity S>
  void sync(VisualMemory<D, M, E, S>& memory) {
    memory.release_features(hand_over(std::as_const(memory)));
  }

  /// Waits until every sync handed over is committed; a transaction that failed in the
  /// writer thread is thrown here as its vmap::Error (once; nothing of that sync was
  /// stored, and the next sync writes its rows again). On a server, a connection that
  /// broke is then made again: an Error of kind unavailable while the server is away.
  void flush() {
    if (connection_->writes()) {
      if (std::exception_ptr error = connection_->wait()) {
        held_ = committed_;
        std::rethrow_exception(error);
      }
      committed_ = held_;
    }
    revive();
  }

  /// Bounds `memory`'s RAM to the features of its `working_memory` most recent key
  /// images, reading the others from this store (VisualMemory::bound_features), and
  /// releases those already stored (flushes first). The memory must be the one this
  /// store holds (as for sync).
  template <Descriptor D, Matcher M, Estimator E, Similarity S>
  void bound(VisualMemory<D, M, E, S>& memory, std::size_t working_memory) {
    flush();
    check_holds(memory);
    memory.bound_features(working_memory, features());
    memory.release_features(held_.keys);
  }

  /// Reads a stored key image's features, through a read-only connection of its own (so
  /// it stays valid when this object moves, and reads what was committed): the source of
  /// VisualMemory::bound_features. A key image the store does not hold, or a damaged
  /// record, is an Error naming the store.
  [[nodiscard]] std::function<Features(std::uint32_t)> features() {
    flush();
    struct Reader {
      detail::StoreDb db;
      detail::StoreQuery query;
      std::int64_t version;
      std::function<void()> revive;
    };
    auto connection = reader_connection();
    // The record read only within the limit of a row (read_records).
    auto query = connection.prepare(version_ >= 4 ? "SELECT CASE WHEN length(record) <= ? THEN record END, detections, crc, "
                                                     "length(record) FROM key_images WHERE id = ?"
                                                   : "SELECT CASE WHEN length(record) <= ? THEN record END, x'', 0, "
                                                     "length(record) FROM key_images WHERE id = ?",
                                    "read a key image's features");
    auto reader = std::make_shared<Reader>(Reader{std::move(connection), std::move(query), version_, {}});
    if (reader->db.postgres())
      reader->revive = [r = reader.get(), robot = robot_id_] {
        if (r->db.server().broken()) {
          r->db.server().reconnect();
          detail::enter_fleet_robot(r->db, robot, false);
        }
      };
    return [reader](std::uint32_t key) {
      if (reader->revive) reader->revive();
      detail::StoreQuery& q = reader->query;
      const MapLoadOptions limits;
      q.bind(1, static_cast<std::int64_t>(limits.max_file_bytes)).bind(2, static_cast<std::int64_t>(key));
      struct Reset {
        detail::StoreQuery& q;
        ~Reset() { q.reset(); }
      } reset{q};
      if (!q.step()) reader->db.fail("holds no key image " + std::to_string(key));
      const std::string who = reader->db.what() + " key image " + std::to_string(key);
      if (q.is_null(0))
        detail::fail(ErrorKind::corrupt, who + ": its record is " + std::to_string(q.integer(3)) + " bytes long, more than "
                                           "the " + std::to_string(limits.max_file_bytes) + " it can hold");
      if (reader->version >= 4 && detail::row_crc(q.blob(0), q.blob(1)) != q.integer(2))
        detail::fail(ErrorKind::corrupt, who + ": checksum mismatch (the store is corrupt)");
      detail::BinaryReader r(q.blob(0), who);
      MapLoadOptions unread = limits;
      unread.decode_images = false;
      std::uint64_t pixels = 0;
      Features f = detail::read_key_record(r, reader->version >= 4 ? 5 : 4, {unread, pixels, nullptr, true}).key.features;
      r.expect_end("the key image");  // a record is exactly as long as its contents
      return f;
    };
  }

  /// The bytes of each key image's row (its record, detections and bag of words), in
  /// order: what a key image costs on disk, without SQLite's page overhead. Flushes first.
  [[nodiscard]] std::vector<std::uintmax_t> key_image_bytes() {
    flush();
    std::vector<std::uintmax_t> out;
    auto q = db().prepare(
        "SELECT length(record) + length(detections) + coalesce(length(bow), 0) FROM key_images ORDER BY id",
        "measure the key images");
    while (q.step()) out.push_back(static_cast<std::uintmax_t>(q.integer(0)));
    return out;
  }

  /// Records `value` under `name` in the notes table (its own transaction, after the
  /// syncs handed over are committed).
  void set_note(std::string_view name, std::string_view value) {
    if (!connection_->writes()) db().fail("is open read-only: open it with Access::write to write a note");
    flush();
    auto q = db().prepare("INSERT INTO notes(name, value) VALUES(?,?) ON CONFLICT(name) DO UPDATE SET value = excluded.value",
                          "write a note");
    q.bind_text(1, name).bind_text(2, value);
    q.run();
  }

  /// The note recorded under `name`, if any (flushes first).
  [[nodiscard]] std::optional<std::string> note(std::string_view name) {
    flush();
    // Not a search of the key (detail::meta_row_unsearched: notes is WITHOUT ROWID too).
    auto q = db().prepare(std::string("SELECT value FROM notes WHERE ") + detail::meta_row_unsearched, "read a note");
    q.bind_text(1, name);
    if (!q.step()) return std::nullopt;
    return q.text(0);
  }

  /// Flushes, then moves the write-ahead log into the database file (the file then holds
  /// every sync and its size is the memory's); a no-op for a reader and on a server.
  void checkpoint() {
    if (!connection_->writes()) return;
    flush();
    if (on_server()) return;
    db().exec("PRAGMA wal_checkpoint(TRUNCATE)", "checkpoint the write-ahead log");
  }

  /// What each policy of the memory recorded of itself (VisualMemory::policy_records), read
  /// without the rest: what a program reads to know the policies to load it with.
  [[nodiscard]] std::array<std::string, 4> policy_records() {
    flush();
    const std::string bytes = meta("policies");
    detail::BinaryReader r(bytes, db().what() + " state 'policies'");
    std::array<std::string, 4> out;
    for (std::string& p : out) p = r.str("policy record", detail::memory_max_policy);
    r.expect_end("the policies");
    return out;
  }

  /// The memory's records as the store holds them (flushes first; a snapshot, also while
  /// another program writes), every row checked. With a `working_memory` (> 0), the key
  /// images older than the most recent `working_memory` are read without their features.
  /// `limits` bound the key images' pixels; `pixels_skipped` is set when they were checked
  /// but not decoded.
  [[nodiscard]] MemoryRecords records(std::size_t working_memory = 0, const MapLoadOptions& limits = {},
                                      bool* pixels_skipped = nullptr) {
    flush();
    detail::StoreTransaction snapshot(db(), "read the memory", detail::StoreTransaction::Kind::read);
    MemoryRecords r = read_records(working_memory, limits, pixels_skipped);
    snapshot.commit();
    return r;
  }

  /// The memory the store holds, as synced last (flushes first; a snapshot, also while
  /// another program writes). `args` are the memory's descriptor, matcher, estimator and
  /// similarity when they are not default-constructed, and after the four the
  /// MapLoadOptions bounding the key images' pixels, as for VisualMemory::load.
  template <class Memory, class... Args>
  [[nodiscard]] Memory load(Args&&... args) {
    return load_holding<Memory>(0, std::forward<Args>(args)...);
  }

  /// load(), holding in RAM the features of the memory's `working_memory` (>= 1) most
  /// recent key images only, also while it loads: the older key images' records are read
  /// without their features, which the memory reads from this store when it needs them
  /// (bound()). The memory is the one load() gives, bounded.
  template <class Memory, class... Args>
  [[nodiscard]] Memory load_bounded(std::size_t working_memory, Args&&... args) {
    detail::check(working_memory >= 1, "MemoryStore::load_bounded: the working memory must hold at least 1 key image");
    return load_holding<Memory>(working_memory, std::forward<Args>(args)...);
  }

 private:
  template <class Memory, class... Args>
  [[nodiscard]] Memory load_holding(std::size_t working_memory, Args&&... args) {
    bool skipped = false;
    std::optional<Memory> memory;
    if constexpr (sizeof...(Args) == 5) {
      auto all = std::forward_as_tuple(std::forward<Args>(args)...);
      MemoryRecords r = records(working_memory, std::get<4>(all), &skipped);
      memory.emplace(Memory::from_records(std::move(r), db().what(), std::get<0>(std::move(all)), std::get<1>(std::move(all)),
                                          std::get<2>(std::move(all)), std::get<3>(std::move(all)), skipped));
    } else {
      // Pixels are decoded with the default limits: none is skipped.
      MemoryRecords r = records(working_memory, MapLoadOptions{}, &skipped);
      memory.emplace(Memory::from_records(std::move(r), db().what(), std::forward<Args>(args)...));
    }
    if (working_memory > 0) {
      const std::size_t m = memory->key_images();
      memory->bound_features(working_memory, features(), m > working_memory ? m - working_memory : 0);
    }
    return std::move(*memory);
  }

  /// sync(): waits for the sync in flight (throwing its error), encodes the records the
  /// memory made since, and hands them to the writer thread. Returns the key images
  /// committed before them (those a working memory may release).
  template <Descriptor D, Matcher M, Estimator E, Similarity S>
  std::size_t hand_over(const VisualMemory<D, M, E, S>& memory) {
    if (!connection_->writes()) db().fail("is open read-only: open it with Access::write to sync a memory into it");
    flush();
    check_holds(memory);
    memory.check_pixels_read(memory.options().images, "MemoryStore::sync");
    const MemoryRecords r = memory.records(held_, false);
    detail::MemoryStoreRows rows = detail::store_rows(r, memory.sessions());
    // The writer thread is idle (flush() above): it reads the vocabulary's CRC only while
    // it writes the rows handed over next.
    for (const auto& [name, value] : rows.meta)
      if (std::string_view(name) == "vocabulary") connection_->vocabulary_crc = detail::row_crc(value);
    connection_->hand_over(std::move(rows));
    held_ = {r.key_count(), r.first_loop + r.loops.size(), r.first_bow + r.bows.size(),
             r.first_session + r.sessions.size(),
             r.vocabulary ? std::optional<bool>(!r.vocabulary->empty()) : held_.vocabulary_written,
             r.gcs_written ? std::optional<std::uint64_t>(memory.gcs_generation()) : held_.gcs};
    synced_ = true;
    return committed_.keys;
  }

  MemoryStore(const std::filesystem::path& path, sqlite::Access access, std::string what = {})
      : path_(path),
        connection_(std::make_unique<detail::MemoryStoreConnection>(detail::StoreDb(
            sqlite::Database(path, access, what.empty() ? "memory '" + path.string() + "'" : std::move(what))))) {}

  /// A new store renamed to `path` under its writer's `lock` (create), opened to write.
  MemoryStore(const std::filesystem::path& path, sqlite::WriterLock lock, std::string what)
      : path_(path),
        connection_(std::make_unique<detail::MemoryStoreConnection>(
            detail::StoreDb(sqlite::Database(path, std::move(lock), std::move(what))))) {}

  /// The current schema's tables in a new file, in one transaction.
  static void make_tables(detail::StoreDb& db) {
    detail::StoreTransaction t(db, "create the tables");
    db.exec(schema_sql(), "create the tables");
    t.commit();
  }

  /// Robot `robot`'s memory in the fleet's memory at `uri` (see create and open).
  static MemoryStore open_on_server(const std::string& uri, const std::string& robot, sqlite::Access access) {
    const std::string shown = pg::redacted(uri);
    const std::string who = "robot '" + robot + "' of memory '" + shown + "'";
    detail::check_robot_name(robot, "memory '" + shown + "'", access == sqlite::Access::create);
    MemoryStore s(uri, shown, robot, detail::StoreDb(pg::Connection(uri, who)));
    detail::StoreDb& db = s.db();
    if (access == sqlite::Access::create) {
      detail::ensure_fleet(db, detail::fleet_version);
      s.robot_id_ = detail::add_fleet_robot(db, robot);
    } else {
      if (!detail::fleet_present(db, detail::fleet_version))
        db.fail("does not exist: the database holds no vmap memory", ErrorKind::not_found);
      const auto id = detail::fleet_robot(db, robot);
      if (!id) {
        std::string robots;
        for (const std::string& r : detail::fleet_robots(db)) robots += (robots.empty() ? "" : ", ") + r;
        db.fail("does not exist: the fleet has no such robot (its robots: " + (robots.empty() ? "none" : robots) + ")",
                ErrorKind::not_found);
      }
      s.robot_id_ = *id;
    }
    const bool write = access != sqlite::Access::read;
    // A robot just added is locked already (add_fleet_robot).
    detail::enter_fleet_robot(db, s.robot_id_, write && access != sqlite::Access::create);
    s.count_rows();
    s.connection_->fleet_robot = s.robot_id_;
    if (s.synced_) s.connection_->vocabulary_crc = detail::row_crc(s.meta("vocabulary"));
    if (write) {
      s.connection_->revive = [c = s.connection_.get(), id = s.robot_id_] {
        if (!c->db.server().broken()) return;
        c->db.server().reconnect();
        detail::enter_fleet_robot(c->db, id, true);
      };
      s.connection_->start_writer();
    }
    return s;
  }

  MemoryStore(std::string location, const std::string& shown, std::string robot, detail::StoreDb db)
      : path_(shown),
        location_(std::move(location)),
        robot_(std::move(robot)),
        connection_(std::make_unique<detail::MemoryStoreConnection>(std::move(db))) {}

  [[nodiscard]] detail::StoreDb& db() const noexcept { return connection_->db; }

  /// A connection of its own to read what was committed (features()).
  [[nodiscard]] detail::StoreDb reader_connection() const {
    if (!db().postgres()) return detail::StoreDb(sqlite::Database(path_, sqlite::Access::read, db().what()));
    detail::StoreDb reader(pg::Connection(location_, db().what()));
    detail::enter_fleet_robot(reader, robot_id_, false);
    return reader;
  }

  /// A server's connection that broke is made again (a reader's, or a writer's with
  /// nothing in flight: called after flush()).
  void revive() {
    if (!db().postgres() || !db().server().broken()) return;
    db().server().reconnect();
    detail::enter_fleet_robot(db(), robot_id_, connection_->writes());
  }

  static const std::string& schema_sql() {
    static const std::string sql =
        "PRAGMA application_id = " + std::to_string(memory_store_application_id) + ";"
        "PRAGMA user_version = " + std::to_string(memory_store_version) + ";" + tables_sql();
    return sql;
  }

  /// The tables of the current schema: every blob with the CRC-32 of its bytes.
  static std::string tables_sql() {
    return "CREATE TABLE meta(name TEXT PRIMARY KEY NOT NULL, value BLOB NOT NULL, crc INTEGER NOT NULL) WITHOUT ROWID;"
           "CREATE TABLE key_images(id INTEGER PRIMARY KEY, frame_index INTEGER NOT NULL, timestamp REAL NOT NULL,"
           " time_ns INTEGER NOT NULL, name TEXT NOT NULL, keypoints INTEGER NOT NULL, record BLOB NOT NULL,"
           " detections BLOB NOT NULL, crc INTEGER NOT NULL, bow BLOB, bow_crc INTEGER);"
           "CREATE TABLE links(key INTEGER PRIMARY KEY, matches INTEGER NOT NULL, inliers INTEGER NOT NULL,"
           " similarity REAL NOT NULL, record BLOB NOT NULL, crc INTEGER NOT NULL);"
           "CREATE TABLE loops(id INTEGER PRIMARY KEY, from_key INTEGER NOT NULL, to_key INTEGER NOT NULL,"
           " inliers INTEGER NOT NULL, confidence REAL NOT NULL, record BLOB NOT NULL, crc INTEGER NOT NULL);"
           "CREATE TABLE IF NOT EXISTS notes(name TEXT PRIMARY KEY NOT NULL, value TEXT NOT NULL) WITHOUT ROWID;"
           "CREATE TABLE sessions(id INTEGER PRIMARY KEY, first_key INTEGER NOT NULL, first_frame INTEGER NOT NULL);";
  }

  [[nodiscard]] std::int64_t pragma(const char* name) {
    auto q = db().prepare(std::string("PRAGMA ") + name, std::string("read ") + name);
    if (!q.step()) db().fail(std::string("has no ") + name);
    return q.integer(0);
  }

  /// Checks the application id and the version.
  void check_schema() {
    if (pragma("application_id") != memory_store_application_id)
      db().fail("is not a vmap memory store (an SQLite file without vmap's application id)", ErrorKind::corrupt);
    const std::int64_t version = pragma("user_version");
    if (version < 1 || version > memory_store_version)
      db().fail("has store version " + std::to_string(version) + "; this build reads versions 1 to " +
                    std::to_string(memory_store_version),
                version < 1 ? ErrorKind::corrupt : ErrorKind::unsupported_version);
    version_ = version;
  }

  /// Brings a store of an older schema to the current one, in one transaction: its
  /// records read as they are and written again as the current version writes them (the
  /// key images' encoded pixels kept byte for byte), its notes kept.
  void upgrade() {
    const std::int64_t from = version_;
    detail::StoreTransaction t(db(), "bring the store from version " + std::to_string(from) + " to version " +
                                    std::to_string(memory_store_version));
    std::optional<detail::MemoryStoreRows> rows;
    {
      count_rows();
      if (synced_) rows = upgraded_rows();
    }
    db().exec("DROP TABLE IF EXISTS meta; DROP TABLE IF EXISTS key_images; DROP TABLE IF EXISTS links;"
              "DROP TABLE IF EXISTS loops; DROP TABLE IF EXISTS sessions;" +
                  tables_sql() + "PRAGMA user_version = " + std::to_string(memory_store_version) + ";",
              "bring the store to version " + std::to_string(memory_store_version));
    version_ = memory_store_version;
    if (rows) connection_->write_now(*rows);
    t.commit();
  }

  void count_rows() {
    const auto count = [&](const char* sql, const char* doing) {
      auto q = db().prepare(sql, doing);
      if (!q.step()) db().fail(std::string(doing) + ": no row");
      return static_cast<std::size_t>(q.integer(0));
    };
    // The tables vmap makes give each state and note one row (PRIMARY KEY name); a table
    // remade without that key by another program could hold two, and which one a read
    // meets would be SQLite's choice.
    for (const char* table : {"meta", "notes"}) {
      auto q = db().prepare(std::string("SELECT name FROM ") + table + " GROUP BY name HAVING count(*) > 1 LIMIT 1",
                            "look for repeated rows");
      if (q.step())
        db().fail("is corrupt: its " + std::string(table) + " table holds '" + q.text(0) + "' more than once",
                  ErrorKind::corrupt);
    }
    held_ = {};
    held_.keys = count("SELECT count(*) FROM key_images", "count the key images");
    held_.loops = count("SELECT count(*) FROM loops", "count the loop edges");
    held_.bows = count("SELECT count(bow) FROM key_images", "count the bags of words");
    synced_ = count("SELECT count(*) FROM meta WHERE name || '' = 'options'", "look for a sync") > 0;
    held_.sessions = version_ >= 2 ? count("SELECT count(*) FROM sessions", "count the sessions") : (synced_ ? 1 : 0);
    // A store written by an older version holds its vocabulary; whether it is a learned
    // one decides whether the next sync writes it again.
    if (synced_) {
      const std::string v = meta("vocabulary");
      held_.vocabulary_written = !v.empty() && v[0] == 1;
    }
    committed_ = held_;
  }

  /// `memory` is the one the store holds, grown (sync, bound): it has at least the stored
  /// key images, loop edges and bags of words, and its last stored key image is the
  /// stored one (checked once per store object, on the connection: nothing in flight).
  template <Descriptor D, Matcher M, Estimator E, Similarity S>
  void check_holds(const VisualMemory<D, M, E, S>& memory) {
    const std::size_t m = memory.key_images();
    const std::size_t e = memory.loops().size();
    const std::size_t checked = memory.database().size();
    if (m < held_.keys || e < held_.loops || checked < held_.bows || memory.sessions().size() < held_.sessions)
      db().fail("holds " + std::to_string(held_.keys) + " key images and " + std::to_string(held_.loops) +
                " loop edges, the memory given " + std::to_string(m) + " and " + std::to_string(e) +
                ": use the memory loaded from this store, or a memory with a new store");
    if (!matched_ && held_.keys > 0) check_same_memory(memory.map());
    matched_ = true;
  }

  /// The first sync into a store that holds key images: the memory must be the one it
  /// holds (its last stored key image is the memory's key image of that index).
  void check_same_memory(const VisualMap& map) {
    auto q = db().prepare("SELECT frame_index FROM key_images WHERE id = ?", "read the last key image");
    q.bind(1, static_cast<std::int64_t>(held_.keys - 1));
    if (!q.step()) db().fail("is corrupt: key image " + std::to_string(held_.keys - 1) + " is missing", ErrorKind::corrupt);
    const auto stored = q.integer(0);
    if (stored != static_cast<std::int64_t>(map.keys[held_.keys - 1].frame_index))
      db().fail("holds another memory: its key image " + std::to_string(held_.keys - 1) + " is frame " +
                std::to_string(stored) + ", the memory's is frame " +
                std::to_string(map.keys[held_.keys - 1].frame_index));
  }

  /// A state row's bytes, its checksum checked (version 4); its length is checked against
  /// its limit (detail::state_row_limit, `large` for the big ones) before it is read.
  [[nodiscard]] std::string meta(const char* name, std::uint64_t large = default_max_file_bytes) {
    auto value = meta_if(name, large);
    if (!value) db().fail(std::string("holds no '") + name + "' state (an empty store, or not synced)");
    return std::move(*value);
  }

  /// meta(), or nothing when the store has no such row.
  [[nodiscard]] std::optional<std::string> meta_if(const char* name, std::uint64_t large = default_max_file_bytes) {
    const std::uint64_t limit = detail::state_row_limit(name, large);
    auto q = db().prepare(std::string("SELECT CASE WHEN length(value) <= ? THEN value END, length(value), ") +
                              (version_ >= 4 ? "crc" : "0") + " FROM meta WHERE " + detail::meta_row_unsearched,
                          "read the state");
    q.bind(1, static_cast<std::int64_t>(limit)).bind_text(2, name);
    if (!q.step()) return std::nullopt;
    if (q.is_null(0))
      db().fail(std::string("is corrupt: its '") + name + "' state is " + std::to_string(q.integer(1)) +
                    " bytes long, more than the " + std::to_string(limit) + " it can hold",
                ErrorKind::corrupt);
    std::string value(q.blob(0));
    if (version_ >= 4 && detail::row_crc(value) != q.integer(2))
      db().fail(std::string("is corrupt: the checksum of its '") + name + "' state does not match", ErrorKind::corrupt);
    return value;
  }

  /// An Error for a blob of `row` that is longer than it can be (`length` > `limit`).
  [[noreturn]] void too_long(const std::string& row, std::int64_t length, std::uint64_t limit) const {
    db().fail("is corrupt: " + row + " is " + std::to_string(length) + " bytes long, more than the " +
                  std::to_string(limit) + " it can hold",
              ErrorKind::corrupt);
  }

  [[nodiscard]] detail::BinaryReader state_reader(const std::string& bytes, const char* name) const {
    return detail::BinaryReader(bytes, db().what() + " state '" + name + "'");
  }

  void expect_index(std::int64_t got, std::size_t want, const char* what) const {
    if (got != static_cast<std::int64_t>(want))
      db().fail("is corrupt: " + std::string(what) + " " + std::to_string(got) + " where " + std::to_string(want) +
                    " was expected",
                ErrorKind::corrupt);
  }

  /// A row whose blobs do not match its checksum (version 4).
  void check_crc(std::int64_t got, std::int64_t want, const std::string& row) const {
    if (version_ >= 4 && got != want) db().fail("is corrupt: the checksum of " + row + " does not match", ErrorKind::corrupt);
  }

  /// The records of every row (see records()), inside the caller's read transaction.
  MemoryRecords read_records(std::size_t working_memory, const MapLoadOptions& limits, bool* pixels_skipped) {
    const bool v4 = version_ >= 4;
    const std::uint32_t format = v4 ? memory_format_version : 4;
    const std::uint64_t large = limits.max_file_bytes;
    MemoryRecords r;
    r.version = format;
    const std::string options = meta("options", large);
    {
      auto o = state_reader(options, "options");
      r.options = v4 ? detail::read_memory_options(o) : detail::read_options_v4(o, 4);
    }
    {
      const std::string bytes = meta("policies", large);
      auto p = state_reader(bytes, "policies");
      for (std::string& policy : r.policies) policy = p.str("policy record", detail::memory_max_policy);
      p.expect_end("the policies");
    }
    {
      const std::string bytes = meta("frames", large);
      auto f = state_reader(bytes, "frames");
      const std::uint64_t frames = f.u64("frame count");
      if (frames > detail::memory_max_frames) f.corrupt("frame count " + std::to_string(frames) + " is above 2^40");
      f.expect_end("the frame count");
      r.frames = static_cast<std::size_t>(frames);
    }
    {
      const std::string bytes = meta("database", large);
      auto d = state_reader(bytes, "database");
      const std::uint8_t scoring = d.u8("scoring");
      if (scoring != static_cast<std::uint8_t>(r.options.scoring)) d.corrupt("its scoring is not the memory's");
      const std::uint64_t words = d.u64("words");
      if (words > std::numeric_limits<std::uint32_t>::max()) d.corrupt("vocabulary size " + std::to_string(words) + " is too large");
      d.expect_end("the database head");
      r.words = static_cast<std::size_t>(words);
    }
    {
      const std::string bytes = meta("vocabulary", large);
      auto v = state_reader(bytes, "vocabulary");
      r.vocabulary = detail::read_vocabulary_record(v);
    }

    // Key images, their detections and bags of words.
    std::size_t stored = 0;
    {
      auto q = db().prepare("SELECT count(*) FROM key_images", "count the key images");
      if (!q.step()) db().fail("count the key images: no row");
      stored = static_cast<std::size_t>(q.integer(0));
    }
    const std::size_t released = working_memory > 0 && stored > working_memory ? stored - working_memory : 0;
    std::uint64_t total_pixels = 0;
    {
      // Each blob is read only when its length is within its limit (a record as large as
      // a memory file may be; detections and a bag of words as many as they can hold).
      const std::uint64_t detections_limit = detail::detections_limit;
      const std::uint64_t bow_limit = 12 + std::uint64_t{8} * r.words;
      auto q = db().prepare(
          std::string("SELECT id, frame_index, timestamp, ") + (v4 ? "time_ns" : "0") +
              ", name, keypoints, CASE WHEN length(record) <= ? THEN record END, "
              "CASE WHEN length(detections) <= ? THEN detections END, " + (v4 ? "crc" : "0") +
              ", CASE WHEN length(bow) <= ? THEN bow END, " + (v4 ? "bow_crc" : "0") +
              ", length(record), length(detections), length(bow) FROM key_images ORDER BY id",
          "read the key images");
      q.bind(1, static_cast<std::int64_t>(large))
          .bind(2, static_cast<std::int64_t>(detections_limit))
          .bind(3, static_cast<std::int64_t>(bow_limit));
      std::size_t m = 0;
      while (q.step()) {
        expect_index(q.integer(0), m, "key image");
        const std::string row = "key image " + std::to_string(m);
        if (q.is_null(6)) too_long(row + "'s record", q.integer(11), large);
        if (q.is_null(7)) too_long(row + "'s detections", q.integer(12), detections_limit);
        if (!q.is_null(13) && q.is_null(9)) too_long(row + "'s bag of words", q.integer(13), bow_limit);
        check_crc(detail::row_crc(q.blob(6), q.blob(7)), q.integer(8), row);
        detail::BinaryReader rec(q.blob(6), db().what() + " " + row);
        KeyImageRecord k = detail::read_key_record(rec, format, {limits, total_pixels, pixels_skipped, m >= released});
        rec.expect_end("the key image");
        const KeyImage& key = k.key;
        if (q.integer(1) != static_cast<std::int64_t>(key.frame_index) || q.real(2) != key.timestamp ||
            (v4 && q.integer(3) != key.time_ns) || q.text(4) != key.name ||
            (m >= released && q.integer(5) != static_cast<std::int64_t>(key.features.keypoints.size())))
          db().fail("is corrupt: the columns of " + row + " do not match its record", ErrorKind::corrupt);
        detail::BinaryReader det(q.blob(7), db().what() + " " + row + "'s detections");
        k.detections = detail::memory_read_detections(det);
        det.expect_end("the detections");
        if (!q.is_null(9)) {
          if (r.bows.size() != m) db().fail("is corrupt: " + row + " has a bag of words, an earlier one none", ErrorKind::corrupt);
          check_crc(detail::row_crc(q.blob(9)), q.integer(10), row + "'s bag of words");
          detail::BinaryReader b(q.blob(9), db().what() + " " + row + "'s bag of words");
          auto [id, bow] = PlaceDatabase<std::uint32_t>::read_record(b, r.words, r.options.scoring);
          b.expect_end("the bag of words");
          if (id != m) b.corrupt("it is the bag of words of key image " + std::to_string(id));
          r.bows.push_back(std::move(bow));
        }
        r.keys.push_back(std::move(k));
        ++m;
      }
    }
    const std::size_t m = r.keys.size();
    {
      auto q = db().prepare(std::string("SELECT key, matches, inliers, similarity, CASE WHEN length(record) <= ? THEN "
                                        "record END, ") + (v4 ? "crc" : "0") + ", length(record) FROM links ORDER BY key",
                            "read the links");
      q.bind(1, static_cast<std::int64_t>(detail::small_record_limit));
      while (q.step()) {
        expect_index(q.integer(0), r.links.size() + 1, "link");
        const std::string row = "the link into key image " + std::to_string(r.links.size() + 1);
        if (q.is_null(4)) too_long(row, q.integer(6), detail::small_record_limit);
        check_crc(detail::row_crc(q.blob(4)), q.integer(5), row);
        detail::BinaryReader rec(q.blob(4), db().what() + " " + row);
        KeyPair p = detail::read_key_pair(rec, "verification status");
        rec.expect_end("the link");
        if (q.integer(1) != p.matches || q.integer(2) != p.inliers || q.real(3) != p.similarity)
          db().fail("is corrupt: the columns of " + row + " do not match its record", ErrorKind::corrupt);
        r.links.push_back(p);
      }
    }
    {
      auto q = db().prepare(std::string("SELECT id, from_key, to_key, inliers, confidence, CASE WHEN length(record) <= ? "
                                        "THEN record END, ") + (v4 ? "crc" : "0") + ", length(record) FROM loops ORDER BY id",
                            "read the loop edges");
      q.bind(1, static_cast<std::int64_t>(detail::small_record_limit));
      while (q.step()) {
        expect_index(q.integer(0), r.loops.size(), "loop edge");
        const std::string row = "loop edge " + std::to_string(r.loops.size());
        if (q.is_null(5)) too_long(row, q.integer(7), detail::small_record_limit);
        check_crc(detail::row_crc(q.blob(5)), q.integer(6), row);
        detail::BinaryReader rec(q.blob(5), db().what() + " " + row);
        LoopEdge e = detail::read_loop_record(rec, format, m);
        rec.expect_end("the loop edge");
        if (!v4) {
          // Before version 4 the confidence was only a column.
          const double c = q.real(4);
          if (!(c >= 0.0 && c <= 1.0)) rec.corrupt("a loop confidence outside [0, 1]");
          e.link.confidence = c;
        }
        if (q.integer(1) != e.from || q.integer(2) != e.link.key || q.integer(3) != e.link.inliers ||
            q.real(4) != e.link.confidence)
          db().fail("is corrupt: the columns of " + row + " do not match its record", ErrorKind::corrupt);
        r.loops.push_back(std::move(e));
      }
    }
    {
      const std::string bytes = meta("selector", large);
      auto s = state_reader(bytes, "selector");
      r.selector = detail::read_selector_record(
          s, format, {limits, total_pixels, pixels_skipped, true},
          m > 0 ? std::optional<std::size_t>(r.keys.back().key.frame_index) : std::nullopt);
    }
    {
      const std::string bytes = meta("labels", large);
      auto l = state_reader(bytes, "labels");
      if (!v4) detail::read_options_v4_labels(l, r.options);
      detail::read_labels_record(l, r.options, r.labelled, r.schema);
      l.expect_end("the labels");
    }
    {
      const std::string bytes = meta("previous_detections", large);
      auto p = state_reader(bytes, "previous_detections");
      std::vector<Detection> previous = detail::memory_read_detections(p);
      p.expect_end("the detections");
      if (!r.labelled && !previous.empty()) p.corrupt("detections in a memory without labels");
      if (r.selector.previous) r.selector.previous->detections = std::move(previous);
    }
    {
      const std::string bytes = meta("decision", large);
      auto d = state_reader(bytes, "decision");
      if (!v4) detail::read_options_v4_decision(d, r.options);
      r.engine = LoopEngineState::read(d, r.bows.size());
      d.expect_end("the decision");
    }
    if (!v4) {
      auto o = state_reader(options, "options");
      r.options = detail::checked_or_corrupt(o, r.options);
    }
    {
      const std::string bytes = meta("gcs", large);
      auto g = state_reader(bytes, "gcs");
      std::vector<OdometryPose> poses;
      for (const KeyImageRecord& k : r.keys) poses.push_back(k.pose);
      r.gcs = detail::read_gcs_record(g, poses);
    }
    if (version_ >= 2) {
      auto q = db().prepare("SELECT id, first_key, first_frame FROM sessions ORDER BY id", "read the sessions");
      while (q.step()) {
        expect_index(q.integer(0), r.sessions.size(), "session");
        if (q.integer(1) < 0 || q.integer(2) < 0) db().fail("is corrupt: session " + std::to_string(r.sessions.size()) + " starts before 0", ErrorKind::corrupt);
        r.sessions.push_back({static_cast<std::size_t>(q.integer(1)), static_cast<std::size_t>(q.integer(2))});
      }
    }
    if (r.sessions.empty()) r.sessions.push_back({});
    // The sessions table's plain columns against the state that repeats them (a store
    // written before that state was kept has none: its rows are checked by the memory's
    // own rules, VisualMemory::from_records).
    if (const auto bytes = meta_if("sessions", 8 + 16 * static_cast<std::uint64_t>(r.sessions.size()))) {
      auto s = state_reader(*bytes, "sessions");
      const std::uint64_t n = s.u64("session count");
      if (n != r.sessions.size())
        db().fail("is corrupt: its sessions table holds " + std::to_string(r.sessions.size()) + " sessions, its state " +
                      std::to_string(n),
                  ErrorKind::corrupt);
      for (std::size_t i = 0; i < r.sessions.size(); ++i) {
        const std::uint64_t first_key = s.u64("first key image"), first_frame = s.u64("first frame");
        if (first_key != r.sessions[i].first_key || first_frame != r.sessions[i].first_frame)
          db().fail("is corrupt: session " + std::to_string(i) + " starts at key image " +
                        std::to_string(r.sessions[i].first_key) + " and frame " + std::to_string(r.sessions[i].first_frame) +
                        " in its sessions table, at key image " + std::to_string(first_key) + " and frame " +
                        std::to_string(first_frame) + " in its state",
                    ErrorKind::corrupt);
      }
      s.expect_end("the sessions");
    }
    if (v4) {
      const std::string bytes = meta("counts", large);
      auto c = state_reader(bytes, "counts");
      const std::uint64_t keys = c.u64("key images"), loops = c.u64("loop edges"), bows = c.u64("bags of words"),
                          sessions = c.u64("sessions");
      c.expect_end("the counts");
      if (keys != m || loops != r.loops.size() || bows != r.bows.size() || sessions != r.sessions.size())
        db().fail("is corrupt: it holds " + std::to_string(m) + " key images, " + std::to_string(r.loops.size()) +
                  " loop edges, " + std::to_string(r.bows.size()) + " bags of words and " +
                  std::to_string(r.sessions.size()) + " sessions, its state records " + std::to_string(keys) + ", " +
                  std::to_string(loops) + ", " + std::to_string(bows) + " and " + std::to_string(sessions), ErrorKind::corrupt);
    }
    return r;
  }

  /// The rows of a store of an older schema as the current version writes them (upgrade):
  /// each record read and written again, the key images' encoded pixels copied as they
  /// are (they are never decoded and encoded again).
  detail::MemoryStoreRows upgraded_rows() {
    MapLoadOptions keep;
    keep.decode_images = false;
    MemoryRecords r = read_records(0, keep, nullptr);
    detail::MemoryStoreRows rows = detail::store_rows(r, r.sessions);
    // The pixels: the old key records' image bytes, spliced into the new records.
    auto q = db().prepare("SELECT record FROM key_images ORDER BY id", "read the key images' pixels");
    for (auto& row : rows.keys) {
      if (!q.step()) db().fail("is corrupt: a key image went missing", ErrorKind::corrupt);
      row.record = with_image_of(row.record, q.blob(0), row.id);
      row.crc = detail::row_crc(row.record, row.detections);
    }
    for (auto& [name, value] : rows.meta)
      if (std::string_view(name) == "selector") {
        const std::string old = meta("selector");
        if (!old.empty() && old[0] == 1) value = with_image_of(value, old, -1, 1);
      }
    return rows;
  }

  /// `fresh` (a current key record, written from records read without their pixels) with
  /// the image part of `old` (a version-4 key record of the same key image) instead of its
  /// own: the encoded pixels carried over byte for byte. `at` skips a prefix of both (the
  /// selector record's flag byte); the rest of `fresh` after its record is kept.
  std::string with_image_of(const std::string& fresh, std::string_view old, std::int64_t key, std::size_t at = 0) const {
    const std::string who = db().what() + (key >= 0 ? " key image " + std::to_string(key) : std::string(" state 'selector'"));
    const auto image_span = [&](std::string_view bytes, std::uint32_t version) {
      detail::BinaryReader r(bytes.substr(at), who, at);
      (void)r.u64("frame index");
      (void)r.f64("timestamp");
      if (version >= 5) (void)r.i64("timestamp in nanoseconds");
      (void)r.str("name", detail::map_max_string);
      (void)detail::read_features(r, false);
      const std::size_t begin = at + (r.offset() - at);
      MapLoadOptions skip;
      skip.decode_images = false;
      std::uint64_t pixels = 0;
      (void)detail::read_memory_image(r, skip, pixels);
      return std::pair{begin, r.offset()};
    };
    const auto [nb, ne] = image_span(fresh, memory_format_version);
    const auto [ob, oe] = image_span(old, 4);
    return fresh.substr(0, nb) + std::string(old.substr(ob, oe - ob)) + fresh.substr(ne);
  }

  std::filesystem::path path_;
  std::string location_;       ///< a server's URI as given (with its password, if any): never shown
  std::string robot_;          ///< the robot's name on a server
  std::int64_t robot_id_ = 0;  ///< the robot's number on a server
  std::unique_ptr<detail::MemoryStoreConnection> connection_;
  RecordsHeld held_;       ///< with the sync in flight committed: where the next sync goes on from
  RecordsHeld committed_;  ///< without it: what a failure of the sync in flight leaves
  bool synced_ = false;    ///< the store holds a memory (a sync happened)
  std::int64_t version_ = memory_store_version;  ///< the file's schema version
  bool matched_ = false;                         ///< the synced memory was checked against the stored one
};

}  // namespace vmap
