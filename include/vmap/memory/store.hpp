#pragma once

// A visual memory kept in an SQLite file (io/sqlite.hpp), written key image by key image.
//
//   auto store = vmap::MemoryStore::create("run.vmdb");
//   vmap::OrbVisualMemory memory;
//   for (...) { memory.push(frame); store.sync(memory); }   // one transaction per call
//   store.flush();                                          // the last one committed
//   ...
//   auto again = vmap::MemoryStore::open("run.vmdb").load<vmap::OrbVisualMemory>();
//
// sync() writes what the memory made since the last sync, in one transaction: each new
// key image (its features, pixels, pose and detections), the link to it, the bag of
// words of each key image newly checked for loops, each new loop edge, and the few small
// rows of state (the selector's I_{j-1}, the loop engine's counters, the options); the
// vocabulary and the GCS only when they change. Rows once written are never rewritten,
// so a sync costs the same at key image 10 as at key image 10,000, and a key image's
// JPEG or PNG is encoded once.
//
// sync() collects and serialises the rows in the caller's thread (copies: the memory
// changes once sync() returns) and hands them to the store's writer thread, which runs
// the transaction (inserts, COMMIT and its fsync) while the caller pushes the next frame.
// One sync is in flight at a time: sync() first waits for the previous one's commit.
// A crash or power cut thus loses at most the sync in flight (SQLite's write-ahead log
// with synchronous=FULL makes each committed one durable); the file stays a valid memory.
// A transaction that fails in the writer thread is thrown as a vmap::Error by the next
// sync(), flush() or reader of the store (below); it stored nothing, and the sync after
// the error writes its rows again. flush() waits until every sync handed over is
// committed (and throws its error). The destructor waits too but cannot throw, so a
// failure of the last sync is seen only by a flush() (or checkpoint()) before the store
// goes out of scope, as the command line does at the end of a run; a store destroyed
// without one (e.g. while another exception unwinds) drops it.
//
// load() joins the rows back into the memory file's sections (memory/visual_memory.hpp)
// and parses them with the same checks as a .vmem file: a memory loaded from a store is
// the memory that was synced, and pushing on continues exactly as the uninterrupted run.
//
// A working memory bounds the RAM of a long run: bound(memory, N) keeps the features of
// the memory's N most recent key images in RAM, sync() releases the older ones once
// committed, and the memory reads them back from the store when a candidate needs them
// (VisualMemory::bound_features); load_bounded<Memory>(N) loads a memory so, reading the
// older key images' records without their features.
//
// One writer at a time (open(..., write) of a memory another program writes is refused
// with a message naming the file); any number of readers (open(..., read)) load the
// last committed sync while the writer goes on.
//
// Threading: a MemoryStore object is used by one thread at a time (the one that pushes
// into the memory). Its writer thread uses the SQLite connection only while a sync is
// in flight; everything else that reads or writes the file through the object
// (key_images(), loops(), synced(), note(), set_note(), load(), load_bounded(),
// checkpoint(), key_image_bytes(), features(), bound()) waits for that sync first
// (flush()), so the connection is used by one thread at a time.
//
// Schema version 3 (PRAGMA application_id 0x564D4150 "VMAP", PRAGMA user_version 3):
// the tables meta, key_images, links, loops, notes and sessions, whose columns and blobs
// (each the bytes of the .vmem section of that content) are documented for readers
// without vmap in examples/memory.md, "The memory store". A reader reads a store of
// version 1 (no sessions table: one session) or 2 (no deferred degeneracy in the
// selector's blob) as it is; a writer brings it to version 3 when it opens it.

#include <vmap/core/error.hpp>
#include <vmap/io/binary.hpp>
#include <vmap/io/sqlite.hpp>
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
#include <utility>
#include <vector>

namespace vmap {

/// The store's schema version (PRAGMA user_version).
inline constexpr std::int64_t memory_store_version = 3;
/// PRAGMA application_id of a memory store: "VMAP".
inline constexpr std::int64_t memory_store_application_id = 0x564D4150;

namespace detail {

/// One sync's rows, copied out of the memory in the caller's thread (the memory changes
/// once sync() returns) for the store's writer thread to insert.
struct MemoryStoreRows {
  struct Key {
    std::int64_t id = 0, frame_index = 0;
    double timestamp = 0.0;
    std::string name;
    std::int64_t keypoints = 0;
    std::string record, detections;
  };
  struct Link {
    std::int64_t key = 0, matches = 0, inliers = 0;
    double similarity = 0.0;
    std::string record;
  };
  struct Bow {
    std::int64_t key = 0;
    std::string record;
  };
  struct Loop {
    std::int64_t id = 0, from_key = 0, to_key = 0, inliers = 0;
    double confidence = 0.0;
    std::string record;
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

/// A store's SQLite connection and, for a writer, the thread that commits its syncs, one
/// at a time. MemoryStore holds it on the heap, so that the thread keeps using it while
/// the MemoryStore object moves.
class MemoryStoreConnection {
 public:
  MemoryStoreConnection(const std::filesystem::path& path, sqlite::Access access, std::string what)
      : db(path, access, std::move(what)) {}
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

  sqlite::Database db;  ///< declared first: closed after the statements and the thread

  /// Whether the connection writes (a writer thread runs).
  [[nodiscard]] bool writes() const noexcept { return thread_.joinable(); }

  /// Prepares the writer's statements and starts its thread.
  void start_writer() {
    insert_key_.emplace(db.prepare(
        "INSERT INTO key_images(id, frame_index, timestamp, name, keypoints, record, detections) VALUES(?,?,?,?,?,?,?)",
        "insert a key image"));
    insert_link_.emplace(
        db.prepare("INSERT INTO links(key, matches, inliers, similarity, record) VALUES(?,?,?,?,?)", "insert a link"));
    update_bow_.emplace(db.prepare("UPDATE key_images SET bow = ? WHERE id = ?", "write a bag of words"));
    insert_loop_.emplace(db.prepare(
        "INSERT INTO loops(id, from_key, to_key, inliers, confidence, record) VALUES(?,?,?,?,?,?)", "insert a loop edge"));
    put_meta_.emplace(db.prepare("INSERT OR REPLACE INTO meta(name, value) VALUES(?,?)", "write the state"));
    insert_session_.emplace(
        db.prepare("INSERT INTO sessions(id, first_key, first_frame) VALUES(?,?,?)", "insert a session"));
    try {
      thread_ = std::thread([this] { run(); });
    } catch (const std::system_error& e) {
      db.fail(std::string("cannot start its writer thread: ") + e.what());
    }
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
        write(*rows_);
      } catch (const std::exception& e) {
        error = std::make_exception_ptr(Error(std::string(e.what()) +
                                              " (an earlier sync, committed in the store's writer thread: it stored "
                                              "nothing; the next sync writes its rows again)"));
      } catch (...) {
        error = std::make_exception_ptr(Error(db.what() + " write the memory: an unknown error (an earlier sync, "
                                              "committed in the store's writer thread: it stored nothing; the next "
                                              "sync writes its rows again)"));
      }
      lock.lock();
      rows_.reset();
      error_ = error;
      busy_ = false;
      changed_.notify_all();
    }
  }

  void write(const MemoryStoreRows& rows) {
    sqlite::Transaction t(db, "write the memory");
    for (const auto& k : rows.keys) {
      insert_key_->bind(1, k.id)
          .bind(2, k.frame_index)
          .bind(3, k.timestamp)
          .bind_text(4, k.name)
          .bind(5, k.keypoints)
          .bind_blob(6, k.record)
          .bind_blob(7, k.detections);
      insert_key_->run();
    }
    for (const auto& l : rows.links) {
      insert_link_->bind(1, l.key).bind(2, l.matches).bind(3, l.inliers).bind(4, l.similarity).bind_blob(5, l.record);
      insert_link_->run();
    }
    for (const auto& b : rows.bows) {
      update_bow_->bind_blob(1, b.record).bind(2, b.key);
      update_bow_->run();
    }
    for (const auto& e : rows.loops) {
      insert_loop_->bind(1, e.id)
          .bind(2, e.from_key)
          .bind(3, e.to_key)
          .bind(4, e.inliers)
          .bind(5, e.confidence)
          .bind_blob(6, e.record);
      insert_loop_->run();
    }
    for (const auto& x : rows.sessions) {
      insert_session_->bind(1, x.id).bind(2, x.first_key).bind(3, x.first_frame);
      insert_session_->run();
    }
    for (const auto& [name, value] : rows.meta) {
      put_meta_->bind_text(1, name).bind_blob(2, value);
      put_meta_->run();
    }
    t.commit();
  }

  // Prepared once for a writer, used by its thread only.
  std::optional<sqlite::Statement> insert_key_, insert_link_, update_bow_, insert_loop_, put_meta_, insert_session_;
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
  /// A new, empty store at `path`; refused when the file exists.
  [[nodiscard]] static MemoryStore create(const std::filesystem::path& path) {
    MemoryStore s(path, sqlite::Access::create);
    try {
      sqlite::Transaction t(s.db(), "create the tables");
      s.db().exec(schema_sql(), "create the tables");
      t.commit();
    } catch (...) {
      s.connection_.reset();
      std::error_code ec;
      for (const char* suffix : {"", "-wal", "-shm"}) std::filesystem::remove(path.string() + suffix, ec);
      throw;
    }
    s.connection_->start_writer();
    return s;
  }

  /// An existing store: `write` to sync a memory into it (one writer at a time), `read`
  /// to load it while another program may write.
  [[nodiscard]] static MemoryStore open(const std::filesystem::path& path, sqlite::Access access = sqlite::Access::write) {
    detail::check(access != sqlite::Access::create, "MemoryStore::open: use MemoryStore::create for a new store");
    std::error_code ec;
    if (std::filesystem::is_regular_file(path, ec) && std::filesystem::file_size(path, ec) == 0 && !ec)
      detail::fail("memory '" + path.string() + "' is empty: its creation was interrupted before the tables were "
                   "written (remove it, or create the memory again)");
    MemoryStore s(path, access);
    s.check_schema(access);
    s.count_rows();
    if (access == sqlite::Access::write) s.connection_->start_writer();
    return s;
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

  [[nodiscard]] const std::filesystem::path& path() const noexcept { return path_; }
  /// Key images in the store, once every sync handed over is committed (flush() first,
  /// and its error thrown).
  [[nodiscard]] std::size_t key_images() {
    flush();
    return held_.keys;
  }
  /// Whether a memory was ever synced into the store (load() needs one); flushes first.
  [[nodiscard]] bool synced() {
    flush();
    return held_.synced;
  }
  /// Loop edges in the store; flushes first.
  [[nodiscard]] std::size_t loops() {
    flush();
    return held_.loops;
  }

  /// Writes what `memory` made since the last sync into the store, in one transaction.
  /// The rows are collected here, in the caller's thread; the transaction runs in the
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
  /// in flight or failed. The key images of the sync in flight are the newest: inside
  /// the working memory anyway, unless one sync adds more key images than it holds (the
  /// older of those are then released by the next sync).
  template <Descriptor D, Matcher M, Estimator E, Similarity S>
  void sync(VisualMemory<D, M, E, S>& memory) {
    memory.release_features(hand_over(std::as_const(memory)));
  }

  /// Waits until every sync handed over is committed; a transaction that failed in the
  /// writer thread is thrown here as its vmap::Error (once; nothing of that sync was
  /// stored, and the next sync writes its rows again). A no-op for a reader.
  void flush() {
    if (!connection_->writes()) return;
    if (std::exception_ptr error = connection_->wait()) {
      held_ = committed_;
      std::rethrow_exception(error);
    }
    committed_ = held_;
  }

  /// Bounds `memory`'s RAM to the features of its `working_memory` most recent key
  /// images, reading the others from this store (VisualMemory::bound_features), and
  /// releases those already stored (flushes first). The memory must be the one this
  /// store holds (as for sync: anything else is an Error naming the file, and nothing is
  /// released).
  template <Descriptor D, Matcher M, Estimator E, Similarity S>
  void bound(VisualMemory<D, M, E, S>& memory, std::size_t working_memory) {
    flush();
    check_holds(memory);
    memory.bound_features(working_memory, features());
    memory.release_features(held_.keys);
  }

  /// Reads a stored key image's features, through a read-only connection of its own (so
  /// it stays valid when this object moves, and reads what was committed): the source of
  /// VisualMemory::bound_features. It reads what is committed when it runs: every key
  /// image synced before features() was called (it flushes first), later ones once their
  /// sync is committed (a memory released by sync() or bound() reads committed key images
  /// only). A key image the store does not hold, or a damaged record, is an Error naming
  /// the store.
  [[nodiscard]] std::function<Features(std::uint32_t)> features() {
    flush();
    struct Reader {
      sqlite::Database db;
      sqlite::Statement query;
    };
    auto connection = sqlite::Database(path_, sqlite::Access::read, db().what());
    auto query = connection.prepare("SELECT record FROM key_images WHERE id = ?", "read a key image's features");
    auto reader = std::make_shared<Reader>(Reader{std::move(connection), std::move(query)});
    return [reader](std::uint32_t key) {
      sqlite::Statement& q = reader->query;
      q.bind(1, static_cast<std::int64_t>(key));
      struct Reset {
        sqlite::Statement& q;
        ~Reset() { q.reset(); }
      } reset{q};
      if (!q.step()) reader->db.fail("holds no key image " + std::to_string(key));
      detail::BinaryReader r(q.blob(0), reader->db.what() + " key image " + std::to_string(key));
      skip_to_features(r);
      return detail::read_features(r);
    };
  }

  /// The bytes of each key image's row (its record, detections and bag of words), in
  /// order: what a key image costs on disk, without SQLite's page overhead. Flushes first.
  [[nodiscard]] std::vector<std::uintmax_t> key_image_bytes() {
    flush();
    std::vector<std::uintmax_t> out;
    auto q = db().prepare(
        "SELECT length(record) + length(detections) + ifnull(length(bow), 0) FROM key_images ORDER BY id",
        "measure the key images");
    while (q.step()) out.push_back(static_cast<std::uintmax_t>(q.integer(0)));
    return out;
  }

  /// Records `value` under `name` in the notes table (its own transaction, after the
  /// syncs handed over are committed).
  void set_note(std::string_view name, std::string_view value) {
    if (!connection_->writes()) db().fail("is open read-only: open it with Access::write to write a note");
    flush();
    auto q = db().prepare("INSERT OR REPLACE INTO notes(name, value) VALUES(?,?)", "write a note");
    q.bind_text(1, name).bind_text(2, value);
    q.run();
  }

  /// The note recorded under `name`, if any (flushes first).
  [[nodiscard]] std::optional<std::string> note(std::string_view name) {
    flush();
    auto q = db().prepare("SELECT value FROM notes WHERE name = ?", "read a note");
    q.bind_text(1, name);
    if (!q.step()) return std::nullopt;
    return q.text(0);
  }

  /// Flushes, then moves the write-ahead log into the database file (the file then holds
  /// every sync and its size is the memory's); a no-op for a reader.
  void checkpoint() {
    if (!connection_->writes()) return;
    flush();
    db().exec("PRAGMA wal_checkpoint(TRUNCATE)", "checkpoint the write-ahead log");
  }

  /// The memory the store holds, as synced last (flushes first; a snapshot, also while
  /// another program writes). `policies` are the memory's descriptor, matcher, estimator and similarity when
  /// they are not default-constructed, and then the MapLoadOptions bounding the key
  /// images' pixels, as for VisualMemory::load.
  template <class Memory, class... Policies>
  [[nodiscard]] Memory load(Policies&&... policies) {
    return load_holding<Memory>(0, std::forward<Policies>(policies)...);
  }

  /// load(), holding in RAM the features of the memory's `working_memory` (>= 1) most
  /// recent key images only, also while it loads: the older key images' records are read
  /// without their features, which the memory reads from this store when it needs them
  /// (bound()). The memory is the one load() gives, bounded.
  template <class Memory, class... Policies>
  [[nodiscard]] Memory load_bounded(std::size_t working_memory, Policies&&... policies) {
    detail::check(working_memory >= 1, "MemoryStore::load_bounded: the working memory must hold at least 1 key image");
    return load_holding<Memory>(working_memory, std::forward<Policies>(policies)...);
  }

 private:
  /// load() and load_bounded(): the rows joined into the memory file's sections; with a
  /// working memory, the key images older than it are joined without their features.
  template <class Memory, class... Policies>
  [[nodiscard]] Memory load_holding(std::size_t working_memory, Policies&&... policies) {
    flush();
    sqlite::Transaction snapshot(db(), "read the memory", sqlite::Transaction::Kind::read);
    std::array<std::string, detail::memory_sections> sections;
    sections[0] = meta("options");
    const std::string frames = meta("frames");

    std::string keys, detections, bows;
    std::size_t m = 0, checked = 0;
    std::size_t released = 0;  // key images joined without their features
    if (working_memory > 0) {
      auto q = db().prepare("SELECT count(*) FROM key_images", "count the key images");
      if (!q.step()) db().fail("count the key images: no row");
      const auto stored = static_cast<std::size_t>(q.integer(0));
      released = stored > working_memory ? stored - working_memory : 0;
    }
    {
      auto q = db().prepare("SELECT id, record, detections, bow FROM key_images ORDER BY id", "read the key images");
      while (q.step()) {
        expect_index(q.integer(0), m, "key image");
        if (m < released)
          keys += without_features(q.blob(1), m);
        else
          keys += q.blob(1);
        detections += q.blob(2);
        if (!q.is_null(3)) {
          if (checked != m)
            db().fail("is corrupt: key image " + std::to_string(m) + " has a bag of words, an earlier one none");
          bows += q.blob(3);
          ++checked;
        }
        ++m;
      }
    }
    sections[1] = frames + count32(m) + keys;

    std::string links;
    std::size_t p = 0;
    {
      auto q = db().prepare("SELECT key, record FROM links ORDER BY key", "read the links");
      while (q.step()) {
        expect_index(q.integer(0), p + 1, "link");
        links += q.blob(1);
        ++p;
      }
    }
    sections[2] = count32(p) + links;

    std::string loops, confidences;
    std::size_t e = 0;
    {
      auto q = db().prepare("SELECT id, record, confidence FROM loops ORDER BY id", "read the loop edges");
      while (q.step()) {
        expect_index(q.integer(0), e, "loop edge");
        loops += q.blob(1);
        detail::BinaryWriter c;
        c.f64(q.real(2));
        confidences += c.data();
        ++e;
      }
    }
    sections[3] = count32(e) + loops;
    sections[4] = meta("selector");
    sections[5] = meta("vocabulary");
    {
      const std::string bytes = meta("database");
      detail::BinaryReader head(bytes, db().what() + " state 'database'");
      const std::uint8_t scoring = head.u8("scoring");
      const std::uint64_t words = head.u64("words");
      head.expect_end("the database head");
      if (scoring > static_cast<std::uint8_t>(BowScoring::cosine)) db().fail("is corrupt: unknown scoring");
      sections[6] = Memory::database_section(PlaceDatabase<std::uint32_t>::serialize_records(
          static_cast<BowScoring>(scoring), static_cast<std::size_t>(words), checked, bows));
    }
    sections[7] = meta("policies");
    sections[8] = meta("labels") + count32(m) + detections + meta("previous_detections");
    sections[9] = meta("gcs");
    sections[10] = meta("decision") + count32(e) + confidences;
    {
      // "sess": the sessions after the first (a version-1 store holds one).
      std::string rows;
      std::size_t n = 0;
      if (version_ >= 2) {
        auto q = db().prepare("SELECT id, first_key, first_frame FROM sessions ORDER BY id", "read the sessions");
        while (q.step()) {
          expect_index(q.integer(0), n, "session");
          if (n > 0) {
            detail::BinaryWriter w;
            w.u64(static_cast<std::uint64_t>(q.integer(1)));
            w.u64(static_cast<std::uint64_t>(q.integer(2)));
            rows += w.data();
          }
          ++n;
        }
      }
      sections[11] = count32(n > 0 ? n - 1 : 0) + rows;
    }
    snapshot.commit();
    Memory memory = Memory::deserialize(Memory::file_bytes(sections), db().what(), std::forward<Policies>(policies)...);
    if (working_memory > 0) {
      memory.bound_features(working_memory, features());
      memory.released_ = released;
    }
    return memory;
  }

  /// sync(): waits for the sync in flight (throwing its error), collects the rows the
  /// memory made since, and hands them to the writer thread. Returns the key images
  /// committed before them (those a working memory may release).
  template <Descriptor D, Matcher M, Estimator E, Similarity S>
  std::size_t hand_over(const VisualMemory<D, M, E, S>& memory) {
    if (!connection_->writes()) db().fail("is open read-only: open it with Access::write to sync a memory into it");
    flush();
    check_holds(memory);
    const VisualMap& map = memory.selector_.map();
    const std::size_t m = map.keys.size();
    const std::size_t e = memory.loops_.size();
    const auto* database = memory.engine_ ? &memory.engine_->ranker().database() : nullptr;
    const std::size_t checked = database ? database->size() : 0;
    const auto& sessions = memory.sessions_;

    const ImageStorage storage = memory.options_.images;
    memory.check_pixels_read(storage, "MemoryStore::sync");
    detail::MemoryStoreRows rows;
    rows.keys.reserve(m - held_.keys);
    for (std::size_t k = held_.keys; k < m; ++k) {
      const KeyImage& key = map.keys[k];
      detail::BinaryWriter record, detections;
      memory.write_key_record(record, k, storage);
      detail::memory_write_detections(detections, memory.labels_.key_detections[k]);
      rows.keys.push_back({static_cast<std::int64_t>(k), static_cast<std::int64_t>(key.frame_index), key.timestamp,
                           key.name, static_cast<std::int64_t>(key.features.keypoints.size()), std::move(record).take(),
                           std::move(detections).take()});
    }
    for (std::size_t k = std::max<std::size_t>(held_.keys, 1); k < m; ++k) {
      const KeyPair& p = map.pairs[k - 1];
      detail::BinaryWriter record;
      memory.write_link_record(record, k - 1);
      rows.links.push_back({static_cast<std::int64_t>(k), static_cast<std::int64_t>(p.matches),
                            static_cast<std::int64_t>(p.inliers), p.similarity, std::move(record).take()});
    }
    for (std::size_t k = held_.bows; k < checked; ++k)
      rows.bows.push_back({static_cast<std::int64_t>(k), database->record(static_cast<std::uint32_t>(k))});
    for (std::size_t i = held_.loops; i < e; ++i) {
      const LoopEdge& edge = memory.loops_[i];
      detail::BinaryWriter record;
      memory.write_loop_record(record, i);
      rows.loops.push_back({static_cast<std::int64_t>(i), static_cast<std::int64_t>(edge.from),
                            static_cast<std::int64_t>(edge.link.key), static_cast<std::int64_t>(edge.link.inliers),
                            edge.link.confidence, std::move(record).take()});
    }
    for (std::size_t i = held_.sessions; i < sessions.size(); ++i)
      rows.sessions.push_back({static_cast<std::int64_t>(i), static_cast<std::int64_t>(sessions[i].first_key),
                               static_cast<std::int64_t>(sessions[i].first_frame)});
    // The small state, rewritten at every sync (a few hundred bytes, and I_{j-1}'s
    // features).
    auto& meta = rows.meta;
    meta.emplace_back("options", memory.options_bytes(storage));
    meta.emplace_back("policies", memory.policies_bytes());
    meta.emplace_back("labels", memory.labels_head_bytes());
    meta.emplace_back("previous_detections", memory.previous_detections_bytes());
    meta.emplace_back("selector", memory.selector_bytes(storage, detail::ScoreDegeneracy::deferred));
    meta.emplace_back("decision", memory.decision_head_bytes());
    detail::BinaryWriter head;
    head.u8(static_cast<std::uint8_t>(memory.options_.scoring));
    head.u64(memory.vocabulary_->size());
    meta.emplace_back("database", std::move(head).take());
    detail::BinaryWriter frames;
    frames.u64(map.frames);
    meta.emplace_back("frames", std::move(frames).take());
    // The vocabulary once learned, the GCS when trained again: written when they change.
    const bool has_vocabulary = !memory.vocabulary_->empty();
    if (!held_.vocabulary_written || (has_vocabulary && !*held_.vocabulary_written))
      meta.emplace_back("vocabulary", memory.vocabulary_bytes());
    if (held_.gcs_written != memory.gcs_generation_) meta.emplace_back("gcs", memory.gcs_bytes());

    connection_->hand_over(std::move(rows));
    held_ = {m, e, checked, sessions.size(), true, has_vocabulary, memory.gcs_generation_};
    return committed_.keys;
  }

  MemoryStore(const std::filesystem::path& path, sqlite::Access access)
      : path_(path),
        connection_(std::make_unique<detail::MemoryStoreConnection>(path, access, "memory '" + path.string() + "'")) {}

  [[nodiscard]] sqlite::Database& db() const noexcept { return connection_->db; }

  static const std::string& schema_sql() {
    static const std::string sql =
        "PRAGMA application_id = " + std::to_string(memory_store_application_id) + ";"
        "PRAGMA user_version = " + std::to_string(memory_store_version) + ";"
        "CREATE TABLE meta(name TEXT PRIMARY KEY NOT NULL, value BLOB NOT NULL) WITHOUT ROWID;"
        "CREATE TABLE key_images(id INTEGER PRIMARY KEY, frame_index INTEGER NOT NULL, timestamp REAL NOT NULL,"
        " name TEXT NOT NULL, keypoints INTEGER NOT NULL, record BLOB NOT NULL, detections BLOB NOT NULL, bow BLOB);"
        "CREATE TABLE links(key INTEGER PRIMARY KEY, matches INTEGER NOT NULL, inliers INTEGER NOT NULL,"
        " similarity REAL NOT NULL, record BLOB NOT NULL);"
        "CREATE TABLE loops(id INTEGER PRIMARY KEY, from_key INTEGER NOT NULL, to_key INTEGER NOT NULL,"
        " inliers INTEGER NOT NULL, confidence REAL NOT NULL, record BLOB NOT NULL);"
        "CREATE TABLE notes(name TEXT PRIMARY KEY NOT NULL, value TEXT NOT NULL) WITHOUT ROWID;" +
        sessions_sql();
    return sql;
  }

  /// The table version 2 added (a version-1 store holds one session).
  static std::string sessions_sql() {
    return "CREATE TABLE sessions(id INTEGER PRIMARY KEY, first_key INTEGER NOT NULL, first_frame INTEGER NOT NULL);";
  }

  [[nodiscard]] std::int64_t pragma(const char* name) {
    auto q = db().prepare(std::string("PRAGMA ") + name, std::string("read ") + name);
    if (!q.step()) db().fail(std::string("has no ") + name);
    return q.integer(0);
  }

  /// Checks the application id and version; a writer brings an older store to version 3
  /// in one transaction (version 1: one session, no sessions table; version 2: the
  /// selector blob never defers a degeneracy), a reader reads it as is.
  void check_schema(sqlite::Access access) {
    if (pragma("application_id") != memory_store_application_id)
      db().fail("is not a vmap memory store (an SQLite file without vmap's application id)");
    const std::int64_t version = pragma("user_version");
    if (version < 1 || version > memory_store_version)
      db().fail("has store version " + std::to_string(version) + "; this build reads versions 1 to " +
                std::to_string(memory_store_version));
    version_ = version;
    if (version < memory_store_version && access == sqlite::Access::write) {
      sqlite::Transaction t(db(), "bring the store to version " + std::to_string(memory_store_version));
      db().exec((version == 1 ? sessions_sql() +
                                    "INSERT INTO sessions SELECT 0, 0, 0 WHERE EXISTS(SELECT 1 FROM key_images);"
                              : std::string()) +
                    "PRAGMA user_version = " + std::to_string(memory_store_version) + ";",
                "bring the store to version " + std::to_string(memory_store_version));
      t.commit();
      version_ = memory_store_version;
    }
  }

  void count_rows() {
    const auto count = [&](const char* sql, const char* doing) {
      auto q = db().prepare(sql, doing);
      if (!q.step()) db().fail(std::string(doing) + ": no row");
      return static_cast<std::size_t>(q.integer(0));
    };
    held_.keys = count("SELECT count(*) FROM key_images", "count the key images");
    held_.loops = count("SELECT count(*) FROM loops", "count the loop edges");
    held_.bows = count("SELECT count(bow) FROM key_images", "count the bags of words");
    held_.synced = count("SELECT count(*) FROM meta WHERE name = 'options'", "look for a sync") > 0;
    held_.sessions =
        version_ >= 2 ? count("SELECT count(*) FROM sessions", "count the sessions") : (held_.synced ? 1 : 0);
    committed_ = held_;
  }

  /// `memory` is the one the store holds, grown (sync, bound): it has at least the stored
  /// key images, loop edges and bags of words, and its last stored key image is the
  /// stored one (checked once per store object, on the connection: nothing in flight).
  template <Descriptor D, Matcher M, Estimator E, Similarity S>
  void check_holds(const VisualMemory<D, M, E, S>& memory) {
    const VisualMap& map = memory.selector_.map();
    const std::size_t m = map.keys.size();
    const std::size_t e = memory.loops_.size();
    const std::size_t checked = memory.engine_ ? memory.engine_->ranker().database().size() : 0;
    if (m < held_.keys || e < held_.loops || checked < held_.bows || memory.sessions_.size() < held_.sessions)
      db().fail("holds " + std::to_string(held_.keys) + " key images and " + std::to_string(held_.loops) +
                " loop edges, the memory given " + std::to_string(m) + " and " + std::to_string(e) +
                ": use the memory loaded from this store, or a memory with a new store");
    if (!matched_ && held_.keys > 0) check_same_memory(map);
    matched_ = true;
  }

  /// The first sync into a store that holds key images: the memory must be the one it
  /// holds (its last stored key image is the memory's key image of that index).
  void check_same_memory(const VisualMap& map) {
    auto q = db().prepare("SELECT frame_index FROM key_images WHERE id = ?", "read the last key image");
    q.bind(1, static_cast<std::int64_t>(held_.keys - 1));
    if (!q.step()) db().fail("is corrupt: key image " + std::to_string(held_.keys - 1) + " is missing");
    const auto stored = q.integer(0);
    if (stored != static_cast<std::int64_t>(map.keys[held_.keys - 1].frame_index))
      db().fail("holds another memory: its key image " + std::to_string(held_.keys - 1) + " is frame " +
                std::to_string(stored) + ", the memory's is frame " +
                std::to_string(map.keys[held_.keys - 1].frame_index));
  }

  [[nodiscard]] std::string meta(const char* name) {
    auto q = db().prepare("SELECT value FROM meta WHERE name = ?", "read the state");
    q.bind_text(1, name);
    if (!q.step()) db().fail(std::string("holds no '") + name + "' state (an empty store, or not synced)");
    return std::string(q.blob(0));
  }

  void expect_index(std::int64_t got, std::size_t want, const char* what) const {
    if (got != static_cast<std::int64_t>(want))
      db().fail("is corrupt: " + std::string(what) + " " + std::to_string(got) + " where " + std::to_string(want) +
                " was expected");
  }

  /// Reads past what a key image's record holds before its features: frame index, time
  /// and name, as the file's "keys" section holds a key image.
  static void skip_to_features(detail::BinaryReader& r) {
    (void)r.u64("frame index");
    (void)r.f64("timestamp");
    (void)r.str("name", detail::map_max_string);
  }

  /// A key image's record with its features replaced by none of the same norm and image
  /// size (the record's other fields as they are): what a bounded load keeps in RAM.
  std::string without_features(std::string_view record, std::size_t key) const {
    detail::BinaryReader r(record, db().what() + " key image " + std::to_string(key));
    skip_to_features(r);
    const std::size_t head = r.offset();
    const Features f = detail::read_features(r);
    std::string out(record.substr(0, head));
    detail::BinaryWriter w;
    detail::write_features(w, Features{{}, cv::Mat(), f.norm, f.image_size});
    out += w.data();
    out += record.substr(r.offset());
    return out;
  }

  static std::string count32(std::size_t n) {
    detail::BinaryWriter w;
    w.u32(static_cast<std::uint32_t>(n));
    return std::move(w).take();
  }

  /// What the store holds, counted: each table's rows and the state last written.
  struct Held {
    std::size_t keys = 0, loops = 0, bows = 0, sessions = 0;
    bool synced = false;                       ///< the store holds a memory (a sync happened)
    std::optional<bool> vocabulary_written;    ///< whether the stored vocabulary is a learned one
    std::optional<std::uint64_t> gcs_written;  ///< the memory's GCS generation stored
  };

  std::filesystem::path path_;
  std::unique_ptr<detail::MemoryStoreConnection> connection_;
  Held held_;       ///< with the sync in flight committed: where the next sync goes on from
  Held committed_;  ///< without it: what a failure of the sync in flight leaves
  std::int64_t version_ = memory_store_version;  ///< the file's schema version
  bool matched_ = false;                         ///< the synced memory was checked against the stored one
};

}  // namespace vmap
