#pragma once

// A visual memory kept in an SQLite file (io/sqlite.hpp), written key image by key image.
//
//   auto store = vmap::MemoryStore::create("run.vmdb");
//   vmap::OrbVisualMemory memory;
//   for (...) { memory.push(frame); store.sync(memory); }   // one transaction per call
//   ...
//   auto again = vmap::MemoryStore::open("run.vmdb").load<vmap::OrbVisualMemory>();
//
// sync() writes what the memory made since the last sync, in one transaction: each new
// key image (its features, pixels, pose and detections), the link to it, the bag of
// words of each key image newly checked for loops, each new loop edge, and the few small
// rows of state (the selector's I_{j-1}, the loop engine's counters, the options); the
// vocabulary and the GCS only when they change. Rows once written are never rewritten,
// so a sync costs the same at key image 10 as at key image 10,000, and a key image's
// JPEG or PNG is encoded once. A crash or power cut loses at most the sync in flight
// (SQLite's write-ahead log with synchronous=FULL); the file stays a valid memory.
// load() joins the rows back into the memory file's sections (memory/visual_memory.hpp)
// and parses them with the same checks as a .vmem file: a memory loaded from a store is
// the memory that was synced, and pushing on continues exactly as the uninterrupted run.
//
// A working memory bounds the RAM of a long run: bound(memory, N) keeps the features of
// the memory's N most recent key images in RAM, sync() releases the older ones once
// stored, and the memory reads them back from the store when a candidate needs them
// (VisualMemory::bound_features); load_bounded<Memory>(N) loads a memory so, reading the
// older key images' records without their features.
//
// One writer at a time (open(..., write) of a memory another program writes is refused
// with a message naming the file); any number of readers (open(..., read)) load the
// last synced state while the writer goes on.
//
// Schema (version 2; PRAGMA application_id 0x564D4150 "VMAP", PRAGMA user_version 2),
// documented for readers without vmap in examples/memory.md:
//   meta(name TEXT PRIMARY KEY, value BLOB): "options", "policies", "labels",
//        "previous_detections", "selector", "vocabulary", "database", "gcs", "decision"
//        (each the bytes of the memory file's section of that content), "frames" (frames
//        pushed, an integer)
//   key_images(id INTEGER PRIMARY KEY: the key image's index, from 0; frame_index,
//        timestamp (s), name, keypoints; record BLOB: the key image and its pose as the
//        file's "keys" holds one; detections BLOB; bow BLOB: its bag of words as the place
//        database file holds one, NULL until it is checked for loops)
//   links(key INTEGER PRIMARY KEY: the link from key image key - 1 to key; matches,
//        inliers, similarity; record BLOB as the file's "link" holds one)
//   loops(id INTEGER PRIMARY KEY: the edge's index; from_key (newer), to_key (older),
//        inliers, confidence; record BLOB as the file's "loop" holds one)
//   notes(name TEXT PRIMARY KEY, value TEXT): what the program that writes the memory
//        records about it (vmap's command line: the input each session was built from)
//   sessions(id INTEGER PRIMARY KEY: the session's index, from 0; first_key, first_frame:
//        its first key image and the frames pushed before it)
// Version 1 had no sessions table (one session): a reader reads such a store as it is, a
// writer adds the table when it opens one.

#include <vmap/core/error.hpp>
#include <vmap/io/binary.hpp>
#include <vmap/io/sqlite.hpp>
#include <vmap/memory/visual_memory.hpp>
#include <vmap/place/database.hpp>

#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace vmap {

/// The store's schema version (PRAGMA user_version).
inline constexpr std::int64_t memory_store_version = 2;
/// PRAGMA application_id of a memory store: "VMAP".
inline constexpr std::int64_t memory_store_application_id = 0x564D4150;

class MemoryStore {
 public:
  /// A new, empty store at `path`; refused when the file exists.
  [[nodiscard]] static MemoryStore create(const std::filesystem::path& path) {
    MemoryStore s(path, sqlite::Access::create);
    try {
      sqlite::Transaction t(s.db_, "create the tables");
      s.db_.exec(schema_sql(), "create the tables");
      t.commit();
    } catch (...) {
      s.db_ = {};
      std::error_code ec;
      for (const char* suffix : {"", "-wal", "-shm"}) std::filesystem::remove(path.string() + suffix, ec);
      throw;
    }
    s.prepare();
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
    if (access == sqlite::Access::write) s.prepare();
    s.count_rows();
    return s;
  }

  MemoryStore(MemoryStore&&) noexcept = default;
  MemoryStore& operator=(MemoryStore&&) noexcept = default;
  MemoryStore(const MemoryStore&) = delete;
  MemoryStore& operator=(const MemoryStore&) = delete;
  ~MemoryStore() = default;

  [[nodiscard]] const std::filesystem::path& path() const noexcept { return path_; }
  /// Rows written (as of open or the last sync of this object).
  [[nodiscard]] std::size_t key_images() const noexcept { return keys_; }
  /// Whether a memory was ever synced into the store (load() needs one).
  [[nodiscard]] bool synced() const noexcept { return synced_; }
  [[nodiscard]] std::size_t loops() const noexcept { return loops_; }

  /// Writes what `memory` made since the last sync into the store, in one transaction.
  /// `memory` must be the one the store holds, grown: a memory loaded from this store,
  /// or any memory synced into a new store. Anything else is an Error naming the file.
  template <Descriptor D, Matcher M, Estimator E, Similarity S>
  void sync(const VisualMemory<D, M, E, S>& memory) {
    if (!insert_key_) db_.fail("is open read-only: open it with Access::write to sync a memory into it");
    check_holds(memory);
    const VisualMap& map = memory.selector_.map();
    const std::size_t m = map.keys.size();
    const std::size_t e = memory.loops_.size();
    const auto* database = memory.engine_ ? &memory.engine_->ranker().database() : nullptr;
    const std::size_t checked = database ? database->size() : 0;

    const ImageStorage storage = memory.options_.images;
    memory.check_pixels_read(storage, "MemoryStore::sync");
    sqlite::Transaction t(db_, "write the memory");
    for (std::size_t k = keys_; k < m; ++k) {
      const KeyImage& key = map.keys[k];
      detail::BinaryWriter record, detections;
      memory.write_key_record(record, k, storage);
      detail::memory_write_detections(detections, memory.labels_.key_detections[k]);
      insert_key_->bind(1, static_cast<std::int64_t>(k))
          .bind(2, static_cast<std::int64_t>(key.frame_index))
          .bind(3, key.timestamp)
          .bind_text(4, key.name)
          .bind(5, static_cast<std::int64_t>(key.features.keypoints.size()))
          .bind_blob(6, record.data())
          .bind_blob(7, detections.data());
      insert_key_->run();
    }
    for (std::size_t k = std::max<std::size_t>(keys_, 1); k < m; ++k) {
      const KeyPair& p = map.pairs[k - 1];
      detail::BinaryWriter record;
      memory.write_link_record(record, k - 1);
      insert_link_->bind(1, static_cast<std::int64_t>(k))
          .bind(2, static_cast<std::int64_t>(p.matches))
          .bind(3, static_cast<std::int64_t>(p.inliers))
          .bind(4, p.similarity)
          .bind_blob(5, record.data());
      insert_link_->run();
    }
    for (std::size_t k = bows_; k < checked; ++k) {
      update_bow_->bind_blob(1, database->record(static_cast<std::uint32_t>(k))).bind(2, static_cast<std::int64_t>(k));
      update_bow_->run();
    }
    for (std::size_t i = loops_; i < e; ++i) {
      const LoopEdge& edge = memory.loops_[i];
      detail::BinaryWriter record;
      memory.write_loop_record(record, i);
      insert_loop_->bind(1, static_cast<std::int64_t>(i))
          .bind(2, static_cast<std::int64_t>(edge.from))
          .bind(3, static_cast<std::int64_t>(edge.link.key))
          .bind(4, static_cast<std::int64_t>(edge.link.inliers))
          .bind(5, edge.link.confidence)
          .bind_blob(6, record.data());
      insert_loop_->run();
    }
    const auto& sessions = memory.sessions_;
    for (std::size_t i = sessions_; i < sessions.size(); ++i) {
      insert_session_->bind(1, static_cast<std::int64_t>(i))
          .bind(2, static_cast<std::int64_t>(sessions[i].first_key))
          .bind(3, static_cast<std::int64_t>(sessions[i].first_frame));
      insert_session_->run();
    }
    // The small state, rewritten at every sync (a few hundred bytes, and I_{j-1}'s
    // features).
    put("options", memory.options_bytes(storage));
    put("policies", memory.policies_bytes());
    put("labels", memory.labels_head_bytes());
    put("previous_detections", memory.previous_detections_bytes());
    put("selector", memory.selector_bytes(storage));
    put("decision", memory.decision_head_bytes());
    detail::BinaryWriter head;
    head.u8(static_cast<std::uint8_t>(memory.options_.scoring));
    head.u64(memory.vocabulary_->size());
    put("database", head.data());
    detail::BinaryWriter frames;
    frames.u64(map.frames);
    put("frames", frames.data());
    // The vocabulary once learned, the GCS when trained again: written when they change.
    const bool has_vocabulary = !memory.vocabulary_->empty();
    if (!vocabulary_written_ || (has_vocabulary && !*vocabulary_written_))
      put("vocabulary", memory.vocabulary_bytes());
    if (gcs_written_ != memory.gcs_generation_) put("gcs", memory.gcs_bytes());
    t.commit();
    keys_ = m;
    loops_ = e;
    bows_ = checked;
    sessions_ = sessions.size();
    synced_ = true;
    vocabulary_written_ = has_vocabulary;
    gcs_written_ = memory.gcs_generation_;
  }

  /// sync(), then releases from RAM the features of the key images now stored that are
  /// older than the memory's working memory (VisualMemory::bound_features; a no-op for a
  /// memory without one).
  template <Descriptor D, Matcher M, Estimator E, Similarity S>
  void sync(VisualMemory<D, M, E, S>& memory) {
    sync(std::as_const(memory));
    memory.release_features(keys_);
  }

  /// Bounds `memory`'s RAM to the features of its `working_memory` most recent key
  /// images, reading the others from this store (VisualMemory::bound_features), and
  /// releases those already stored. The memory must be the one this store holds (as for
  /// sync: anything else is an Error naming the file, and nothing is released).
  template <Descriptor D, Matcher M, Estimator E, Similarity S>
  void bound(VisualMemory<D, M, E, S>& memory, std::size_t working_memory) {
    check_holds(memory);
    memory.bound_features(working_memory, features());
    memory.release_features(keys_);
  }

  /// Reads a stored key image's features, through a read-only connection of its own (so
  /// it stays valid when this object moves, and reads what was committed): the source of
  /// VisualMemory::bound_features. A key image the store does not hold, or a damaged
  /// record, is an Error naming the store.
  [[nodiscard]] std::function<Features(std::uint32_t)> features() const {
    struct Reader {
      sqlite::Database db;
      sqlite::Statement query;
    };
    auto db = sqlite::Database(path_, sqlite::Access::read, db_.what());
    auto query = db.prepare("SELECT record FROM key_images WHERE id = ?", "read a key image's features");
    auto reader = std::make_shared<Reader>(Reader{std::move(db), std::move(query)});
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
  /// order: what a key image costs on disk, without SQLite's page overhead.
  [[nodiscard]] std::vector<std::uintmax_t> key_image_bytes() {
    std::vector<std::uintmax_t> out;
    auto q = db_.prepare("SELECT length(record) + length(detections) + ifnull(length(bow), 0) FROM key_images ORDER BY id",
                         "measure the key images");
    while (q.step()) out.push_back(static_cast<std::uintmax_t>(q.integer(0)));
    return out;
  }

  /// Records `value` under `name` in the notes table (its own transaction).
  void set_note(std::string_view name, std::string_view value) {
    if (!insert_key_) db_.fail("is open read-only: open it with Access::write to write a note");
    auto q = db_.prepare("INSERT OR REPLACE INTO notes(name, value) VALUES(?,?)", "write a note");
    q.bind_text(1, name).bind_text(2, value);
    q.run();
  }

  /// The note recorded under `name`, if any.
  [[nodiscard]] std::optional<std::string> note(std::string_view name) {
    auto q = db_.prepare("SELECT value FROM notes WHERE name = ?", "read a note");
    q.bind_text(1, name);
    if (!q.step()) return std::nullopt;
    return q.text(0);
  }

  /// Moves the write-ahead log into the database file (the file then holds every sync
  /// and its size is the memory's); a no-op for a reader.
  void checkpoint() {
    if (insert_key_) db_.exec("PRAGMA wal_checkpoint(TRUNCATE)", "checkpoint the write-ahead log");
  }

  /// The memory the store holds, as synced last (a snapshot, also while a writer goes
  /// on). `policies` are the memory's descriptor, matcher, estimator and similarity when
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
    sqlite::Transaction snapshot(db_, "read the memory", sqlite::Transaction::Kind::read);
    std::array<std::string, detail::memory_sections> sections;
    sections[0] = meta("options");
    const std::string frames = meta("frames");

    std::string keys, detections, bows;
    std::size_t m = 0, checked = 0;
    std::size_t released = 0;  // key images joined without their features
    if (working_memory > 0) {
      auto q = db_.prepare("SELECT count(*) FROM key_images", "count the key images");
      if (!q.step()) db_.fail("count the key images: no row");
      const auto stored = static_cast<std::size_t>(q.integer(0));
      released = stored > working_memory ? stored - working_memory : 0;
    }
    {
      auto q = db_.prepare("SELECT id, record, detections, bow FROM key_images ORDER BY id", "read the key images");
      while (q.step()) {
        expect_index(q.integer(0), m, "key image");
        if (m < released)
          keys += without_features(q.blob(1), m);
        else
          keys += q.blob(1);
        detections += q.blob(2);
        if (!q.is_null(3)) {
          if (checked != m) db_.fail("is corrupt: key image " + std::to_string(m) + " has a bag of words, an earlier one none");
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
      auto q = db_.prepare("SELECT key, record FROM links ORDER BY key", "read the links");
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
      auto q = db_.prepare("SELECT id, record, confidence FROM loops ORDER BY id", "read the loop edges");
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
      detail::BinaryReader head(bytes, db_.what() + " state 'database'");
      const std::uint8_t scoring = head.u8("scoring");
      const std::uint64_t words = head.u64("words");
      head.expect_end("the database head");
      if (scoring > static_cast<std::uint8_t>(BowScoring::cosine)) db_.fail("is corrupt: unknown scoring");
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
        auto q = db_.prepare("SELECT id, first_key, first_frame FROM sessions ORDER BY id", "read the sessions");
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
    Memory memory = Memory::deserialize(Memory::file_bytes(sections), db_.what(), std::forward<Policies>(policies)...);
    if (working_memory > 0) {
      memory.bound_features(working_memory, features());
      memory.released_ = released;
    }
    return memory;
  }

  MemoryStore(const std::filesystem::path& path, sqlite::Access access)
      : path_(path), db_(path, access, "memory '" + path.string() + "'") {}

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
    auto q = db_.prepare(std::string("PRAGMA ") + name, std::string("read ") + name);
    if (!q.step()) db_.fail(std::string("has no ") + name);
    return q.integer(0);
  }

  /// Checks the application id and version; a writer brings a version-1 store (one
  /// session, no sessions table) to version 2 in one transaction, a reader reads it as is.
  void check_schema(sqlite::Access access) {
    if (pragma("application_id") != memory_store_application_id)
      db_.fail("is not a vmap memory store (an SQLite file without vmap's application id)");
    const std::int64_t version = pragma("user_version");
    if (version < 1 || version > memory_store_version)
      db_.fail("has store version " + std::to_string(version) + "; this build reads versions 1 to " +
               std::to_string(memory_store_version));
    version_ = version;
    if (version == 1 && access == sqlite::Access::write) {
      sqlite::Transaction t(db_, "add the sessions table");
      db_.exec(sessions_sql() + "INSERT INTO sessions SELECT 0, 0, 0 WHERE EXISTS(SELECT 1 FROM key_images);" +
                   "PRAGMA user_version = " + std::to_string(memory_store_version) + ";",
               "add the sessions table");
      t.commit();
      version_ = memory_store_version;
    }
  }

  void prepare() {
    insert_key_.emplace(db_.prepare(
        "INSERT INTO key_images(id, frame_index, timestamp, name, keypoints, record, detections) VALUES(?,?,?,?,?,?,?)",
        "insert a key image"));
    insert_link_.emplace(db_.prepare("INSERT INTO links(key, matches, inliers, similarity, record) VALUES(?,?,?,?,?)",
                                     "insert a link"));
    update_bow_.emplace(db_.prepare("UPDATE key_images SET bow = ? WHERE id = ?", "write a bag of words"));
    insert_loop_.emplace(db_.prepare(
        "INSERT INTO loops(id, from_key, to_key, inliers, confidence, record) VALUES(?,?,?,?,?,?)", "insert a loop edge"));
    put_meta_.emplace(db_.prepare("INSERT OR REPLACE INTO meta(name, value) VALUES(?,?)", "write the state"));
    insert_session_.emplace(
        db_.prepare("INSERT INTO sessions(id, first_key, first_frame) VALUES(?,?,?)", "insert a session"));
  }

  void count_rows() {
    const auto count = [&](const char* sql, const char* doing) {
      auto q = db_.prepare(sql, doing);
      if (!q.step()) db_.fail(std::string(doing) + ": no row");
      return static_cast<std::size_t>(q.integer(0));
    };
    keys_ = count("SELECT count(*) FROM key_images", "count the key images");
    loops_ = count("SELECT count(*) FROM loops", "count the loop edges");
    bows_ = count("SELECT count(bow) FROM key_images", "count the bags of words");
    synced_ = count("SELECT count(*) FROM meta WHERE name = 'options'", "look for a sync") > 0;
    sessions_ = version_ >= 2 ? count("SELECT count(*) FROM sessions", "count the sessions") : (synced_ ? 1 : 0);
  }

  /// `memory` is the one the store holds, grown (sync, bound): it has at least the stored
  /// key images, loop edges and bags of words, and its last stored key image is the
  /// stored one (checked once per store object).
  template <Descriptor D, Matcher M, Estimator E, Similarity S>
  void check_holds(const VisualMemory<D, M, E, S>& memory) {
    const VisualMap& map = memory.selector_.map();
    const std::size_t m = map.keys.size();
    const std::size_t e = memory.loops_.size();
    const std::size_t checked = memory.engine_ ? memory.engine_->ranker().database().size() : 0;
    if (m < keys_ || e < loops_ || checked < bows_ || memory.sessions_.size() < sessions_)
      db_.fail("holds " + std::to_string(keys_) + " key images and " + std::to_string(loops_) +
               " loop edges, the memory given " + std::to_string(m) + " and " + std::to_string(e) +
               ": use the memory loaded from this store, or a memory with a new store");
    if (!matched_ && keys_ > 0) check_same_memory(map);
    matched_ = true;
  }

  /// The first sync into a store that holds key images: the memory must be the one it
  /// holds (its last stored key image is the memory's key image of that index).
  void check_same_memory(const VisualMap& map) {
    auto q = db_.prepare("SELECT frame_index FROM key_images WHERE id = ?", "read the last key image");
    q.bind(1, static_cast<std::int64_t>(keys_ - 1));
    if (!q.step()) db_.fail("is corrupt: key image " + std::to_string(keys_ - 1) + " is missing");
    const auto stored = q.integer(0);
    if (stored != static_cast<std::int64_t>(map.keys[keys_ - 1].frame_index))
      db_.fail("holds another memory: its key image " + std::to_string(keys_ - 1) + " is frame " + std::to_string(stored) +
               ", the memory's is frame " + std::to_string(map.keys[keys_ - 1].frame_index));
  }

  void put(const char* name, std::string_view value) {
    put_meta_->bind_text(1, name).bind_blob(2, value);
    put_meta_->run();
  }

  [[nodiscard]] std::string meta(const char* name) {
    auto q = db_.prepare("SELECT value FROM meta WHERE name = ?", "read the state");
    q.bind_text(1, name);
    if (!q.step()) db_.fail(std::string("holds no '") + name + "' state (an empty store, or not synced)");
    return std::string(q.blob(0));
  }

  void expect_index(std::int64_t got, std::size_t want, const char* what) const {
    if (got != static_cast<std::int64_t>(want))
      db_.fail("is corrupt: " + std::string(what) + " " + std::to_string(got) + " where " + std::to_string(want) +
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
    detail::BinaryReader r(record, db_.what() + " key image " + std::to_string(key));
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

  std::filesystem::path path_;
  sqlite::Database db_;
  // Prepared once for a writer (absent for a reader).
  std::optional<sqlite::Statement> insert_key_, insert_link_, update_bow_, insert_loop_, put_meta_, insert_session_;
  std::size_t keys_ = 0, loops_ = 0, bows_ = 0, sessions_ = 0;  ///< rows in the store
  std::int64_t version_ = memory_store_version;                 ///< the file's schema version
  bool matched_ = false;                         ///< the synced memory was checked against the stored one
  bool synced_ = false;                          ///< the store holds a memory (a sync happened)
  std::optional<bool> vocabulary_written_;       ///< whether the stored vocabulary is a learned one
  std::optional<std::uint64_t> gcs_written_;     ///< the memory's GCS generation stored
};

}  // namespace vmap
