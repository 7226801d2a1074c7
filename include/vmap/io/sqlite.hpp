#pragma once

// A thin RAII layer over SQLite's C API (Debian's libsqlite3, linked by vmap::vmap) for
// the memory's store (memory/store.hpp): a connection, prepared statements and
// transactions. Every failure is a vmap::Error naming the database file, what was being
// done and SQLite's own message ("memory 'm.vmdb': insert key image 12: database or disk
// is full"), never an error code to check.
//
// Writers open a database with Access::write: the connection uses a write-ahead log
// (readers keep reading while the writer commits) with synchronous=FULL (a committed
// transaction survives a power cut), and takes an advisory lock (flock) on the file for
// as long as it is open, so a second writer is refused at open with a message naming
// the file, whichever process it is in. flock and SQLite's own POSIX locks do not
// interact on Linux, but closing any descriptor of a file drops every POSIX lock the
// process holds on it: so no descriptor this layer opens on a database file is closed
// while a connection of this process has the file open (io/database_files.hpp: each
// connection registers its file before it opens it; the writer's flock is released
// when the writer closes, and its descriptor closed once the last connection to the file
// is closed). Readers (Access::read) take no lock and see the last committed
// transaction; where they cannot create SQLite's index file beside the database
// (read-only media), they read it as immutable, which nothing can then change either.
// The same lock (WriterLock) is what a replacement of the file takes
// (memory/replace.hpp): a file being written is never replaced, nor written while it is
// replaced.
//
// Threads: a Database and the Statements prepared on it may be used from any thread, by
// one thread at a time. The connection is opened with SQLITE_OPEN_NOMUTEX (SQLite's
// multi-thread mode: it does not lock the connection itself), so a program that hands a
// connection from one thread to another orders the uses itself, e.g. with a mutex as the
// memory store's writer thread does (memory/store.hpp).

#include <vmap/core/error.hpp>
#include <vmap/io/database_files.hpp>

#include <sqlite3.h>

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cctype>
#include <cerrno>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <limits>
#include <optional>
#include <string>
#include <string_view>
#include <utility>

namespace vmap::sqlite {

namespace detail {

/// SQLite's message for the last error on `db`, with what to do where SQLite's own words
/// do not say it.
[[nodiscard]] inline std::string message_of(sqlite3* db) {
  std::string why = db ? sqlite3_errmsg(db) : "not open";
  if (db && sqlite3_extended_errcode(db) == SQLITE_READONLY_ROLLBACK) {
    const char* file = sqlite3_db_filename(db, "main");
    const std::string name = file && *file ? file : "the database";
    why += " (a rollback journal '" + name + "-journal' lies beside it, left by a program that stopped while "
           "writing the file without a write-ahead log, and only a writer may roll it back: open the memory once "
           "to write, e.g. sqlite3 '" + name + "' 'PRAGMA quick_check', or remove the journal if it is not this file's)";
  }
  return why;
}

/// The kind of Error an SQLite result code `rc` is. The library's SQL is fixed, so a
/// statement that fails on a file that opened is the file's fault (a schema that is not
/// a memory's, damaged pages): corrupt, as SQLite's "not a database" is.
[[nodiscard]] inline ErrorKind kind_of(int rc) noexcept {
  switch (rc & 0xff) {
    case SQLITE_BUSY:
    case SQLITE_LOCKED: return ErrorKind::busy;
    case SQLITE_ERROR:
    case SQLITE_CORRUPT:
    case SQLITE_NOTADB:
    case SQLITE_SCHEMA:
    case SQLITE_FORMAT:
    case SQLITE_MISMATCH: return ErrorKind::corrupt;
    case SQLITE_IOERR:
    case SQLITE_FULL:
    case SQLITE_CANTOPEN:
    case SQLITE_READONLY:
    case SQLITE_PERM:
    case SQLITE_NOLFS:
    case SQLITE_NOMEM: return ErrorKind::io;
    default: return ErrorKind::invalid_argument;
  }
}
/// The kind of the last error on `db`.
[[nodiscard]] inline ErrorKind kind_of(sqlite3* db) noexcept {
  return db ? kind_of(sqlite3_extended_errcode(db)) : ErrorKind::invalid_argument;
}

/// `path` as an SQLite URI ("file:" and the path, bytes other than letters, digits and
/// "/._-~" escaped as %HH), for the query parameters a plain file name cannot carry.
[[nodiscard]] inline std::string uri_of(const std::filesystem::path& path, std::string_view query) {
  static constexpr char hex[] = "0123456789ABCDEF";
  std::string out = "file:";
  for (const unsigned char c : path.string()) {
    if (std::isalnum(c) || c == '/' || c == '.' || c == '_' || c == '-' || c == '~') {
      out += static_cast<char>(c);
    } else {
      out += '%';
      out += hex[c >> 4];
      out += hex[c & 15];
    }
  }
  return out + "?" + std::string(query);
}

}  // namespace detail

enum class Access : std::uint8_t {
  read,   ///< an existing database, read-only; any number at once, also while one writes
  write,  ///< an existing database, read and write; one at a time
  create  ///< a new database file (refused when the file exists), then as write
};

class Statement;

/// The writer's lock of a database file: an flock on a descriptor of its own, held until
/// release() or destruction. flock locks belong to the open file description, so a second
/// WriterLock of one file is refused also within one process. `what` names the file in
/// messages (e.g. "memory 'm.vmdb'"). Its descriptor is closed through
/// io/database_files.hpp, never while a connection of this process has the file open.
class WriterLock {
 public:
  WriterLock() = default;

  /// Locks `path` (with `create`, a new file made with O_EXCL). Refused without waiting
  /// while another holder has it ("is being written by another program"); a path that is
  /// not a regular file is refused without reading it (a FIFO or a device).
  WriterLock(const std::filesystem::path& path, bool create, const std::string& what) {
    // A file renamed over `path` between open() and flock() (a replacement that just
    // finished) is locked again under its new identity, so the lock is always the one
    // of the file the path names.
    for (int attempt = 0; attempt < 8; ++attempt) {
      fd_ = ::open(path.c_str(), O_RDWR | O_CLOEXEC | O_NONBLOCK | (create ? O_CREAT | O_EXCL : 0), 0644);
      if (fd_ < 0) {
        const int err = errno;
        vmap::detail::fail(err == ENOENT ? ErrorKind::not_found : ErrorKind::io,
                           what + " cannot be opened for writing: " + std::strerror(err));
      }
      struct stat st{};
      if (::fstat(fd_, &st) != 0 || !S_ISREG(st.st_mode)) {
        release();
        vmap::detail::fail(what + " is not a regular file");
      }
      if (::flock(fd_, LOCK_EX | LOCK_NB) != 0) {
        const int err = errno;
        release();
        if (err == EWOULDBLOCK)
          vmap::detail::fail(ErrorKind::busy, what + " is being written by another program (one writer at a time; open it read-only to "
                                    "localize while it maps)");
        vmap::detail::fail(ErrorKind::io, what + " cannot be locked: " + std::strerror(err));
      }
      id_ = {st.st_dev, st.st_ino};
      struct stat now{};
      if (create || (::stat(path.c_str(), &now) == 0 && now.st_dev == st.st_dev && now.st_ino == st.st_ino)) return;
      release();
    }
    vmap::detail::fail(ErrorKind::busy, what + " cannot be locked: it was replaced again and again while being opened");
  }
  WriterLock(WriterLock&& o) noexcept : fd_(std::exchange(o.fd_, -1)), id_(o.id_) {}
  WriterLock& operator=(WriterLock&& o) noexcept {
    if (this != &o) {
      release();
      fd_ = std::exchange(o.fd_, -1);
      id_ = o.id_;
    }
    return *this;
  }
  WriterLock(const WriterLock&) = delete;
  WriterLock& operator=(const WriterLock&) = delete;
  ~WriterLock() { release(); }

  [[nodiscard]] bool held() const noexcept { return fd_ >= 0; }
  /// The locked file's identity (while held).
  [[nodiscard]] vmap::detail::FileId file() const noexcept { return id_; }
  /// Unlocks; the descriptor is closed once no connection of this process has the file
  /// open (io/database_files.hpp).
  void release() noexcept {
    if (fd_ < 0) return;
    (void)::flock(fd_, LOCK_UN);
    vmap::detail::close_descriptor(std::exchange(fd_, -1));
  }

 private:
  int fd_ = -1;
  vmap::detail::FileId id_;
};

/// One connection to a database file.
class Database {
 public:
  Database() = default;

  /// Opens `path`; `what` names it in every message (e.g. "memory 'm.vmdb'").
  Database(const std::filesystem::path& path, Access access, std::string what) : what_(std::move(what)) {
    std::error_code ec;
    const bool exists = std::filesystem::exists(path, ec);
    if (access == Access::create && exists) fail("exists already");
    if (access != Access::create && !exists) fail("does not exist", ErrorKind::not_found);
    if (exists && !std::filesystem::is_regular_file(path, ec)) fail("is not a regular file");
    if (access != Access::read) lock_ = WriterLock(path, access == Access::create, what_);
    int flags = access == Access::read ? SQLITE_OPEN_READONLY : SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE;
    std::string name = path.string();
    if (access == Access::read && !folder_writable(path)) {
      // A reader of a write-ahead-log database keeps its index in FILE-shm, which SQLite
      // creates beside the file; where nothing can be created (read-only media, another
      // user's folder) and no writer has left a log to apply, nothing can change the file
      // either, so it is read as immutable. A log left there would be ignored: refused.
      std::error_code e;
      const auto wal = std::filesystem::path(name + "-wal");
      const auto shm = std::filesystem::path(name + "-shm");
      if (std::filesystem::exists(wal, e) && std::filesystem::file_size(wal, e) > 0 && !e)
        fail("has a write-ahead log '" + wal.string() + "' to apply, but its folder cannot be written: copy the " +
                 "file and its -wal file into a folder that can, and read the copy",
             ErrorKind::io);
      if (!std::filesystem::exists(shm, e)) {
        name = detail::uri_of(path, "immutable=1");
        flags |= SQLITE_OPEN_URI;
      }
    }
    connect(path, name, flags, lock_.held() ? std::optional<vmap::detail::FileId>(lock_.file()) : std::nullopt);
    if (access != Access::read) write_ahead();
  }

  /// Opens `path` to write under `lock`, the WriterLock of that file the caller took (a
  /// new file renamed into place while locked, memory/store.hpp). An Error when `path`
  /// does not name the locked file.
  Database(const std::filesystem::path& path, WriterLock lock, std::string what)
      : lock_(std::move(lock)), what_(std::move(what)) {
    if (!lock_.held()) fail("cannot be opened for writing: no writer's lock was given");
    if (vmap::detail::file_id(path) != std::optional<vmap::detail::FileId>(lock_.file()))
      fail("was replaced by another program while it was being made", ErrorKind::busy);
    connect(path, path.string(), SQLITE_OPEN_READWRITE, lock_.file());
    write_ahead();
  }

  /// A connection to write `path` without taking its WriterLock, for a caller that holds
  /// it already (a second flock of the same file from this process would conflict with it).
  [[nodiscard]] static Database under_lock_held(const std::filesystem::path& path, std::string what) {
    Database db;
    db.what_ = std::move(what);
    std::error_code ec;
    if (!std::filesystem::is_regular_file(path, ec)) db.fail("is not a regular file");
    db.connect(path, path.string(), SQLITE_OPEN_READWRITE, std::nullopt);
    return db;
  }

  Database(Database&& o) noexcept
      : db_(std::exchange(o.db_, nullptr)),
        file_(std::exchange(o.file_, std::nullopt)),
        lock_(std::move(o.lock_)),
        what_(std::move(o.what_)) {}
  Database& operator=(Database&& o) noexcept {
    if (this != &o) {
      close();
      db_ = std::exchange(o.db_, nullptr);
      file_ = std::exchange(o.file_, std::nullopt);
      lock_ = std::move(o.lock_);
      what_ = std::move(o.what_);
    }
    return *this;
  }
  Database(const Database&) = delete;
  Database& operator=(const Database&) = delete;
  ~Database() { close(); }

  [[nodiscard]] bool is_open() const noexcept { return db_ != nullptr; }
  [[nodiscard]] const std::string& what() const noexcept { return what_; }
  [[nodiscard]] sqlite3* handle() const noexcept { return db_; }

  /// Closes the connection and hands over the writer's lock it held (still held), for a
  /// file to be renamed while locked; an empty lock for a reader.
  [[nodiscard]] WriterLock close_keeping_lock() noexcept {
    close_connection();
    return std::move(lock_);
  }

  /// Runs SQL without results (several statements allowed); `doing` names it in errors.
  void exec(const std::string& sql, std::string_view doing) {
    char* message = nullptr;
    const int rc = sqlite3_exec(db_, sql.c_str(), nullptr, nullptr, &message);
    if (rc != SQLITE_OK) {
      const std::string why = sqlite3_extended_errcode(db_) == SQLITE_READONLY_ROLLBACK ? detail::message_of(db_)
                              : message                                               ? message
                                                                                      : sqlite3_errstr(rc);
      sqlite3_free(message);
      fail(std::string(doing) + ": " + why, detail::kind_of(sqlite3_extended_errcode(db_)));
    }
  }

  /// A prepared statement (see Statement).
  [[nodiscard]] Statement prepare(std::string_view sql, std::string_view doing);

  /// An Error "<what> <doing>: <SQLite's message>".
  [[noreturn]] void fail_sqlite(std::string_view doing) const {
    fail(std::string(doing) + ": " + detail::message_of(db_), detail::kind_of(db_));
  }

  /// An Error "<what> <message>".
  [[noreturn]] void fail(const std::string& message, ErrorKind kind = ErrorKind::invalid_argument) const {
    vmap::detail::fail(kind, what_ + " " + message);
  }

 private:
  /// Whether this process may create files in `path`'s folder (a read-only mount, or a
  /// folder of another user, says no).
  static bool folder_writable(const std::filesystem::path& path) {
    const std::filesystem::path folder = path.has_parent_path() ? path.parent_path() : std::filesystem::path(".");
    return ::access(folder.c_str(), W_OK) == 0;
  }

  /// Opens the connection to `path` (as `name`, a path or an SQLite URI, with `flags`),
  /// its file registered first (io/database_files.hpp). `locked`: the identity of the file
  /// a held WriterLock has (nothing can replace it meanwhile); without one, a file renamed
  /// over `path` while it was being opened is opened again.
  void connect(const std::filesystem::path& path, const std::string& name, int flags,
               std::optional<vmap::detail::FileId> locked) {
    auto& files = vmap::detail::OpenDatabases::instance();
    for (int attempt = 0; attempt < 8; ++attempt) {
      const auto id = locked ? locked : vmap::detail::file_id(path);
      if (!id) fail("does not exist", ErrorKind::not_found);
      files.opened_connection(*id);
      file_ = id;
      sqlite3* db = nullptr;
      const int rc = sqlite3_open_v2(name.c_str(), &db, flags | SQLITE_OPEN_NOMUTEX, nullptr);
      db_ = db;
      if (rc != SQLITE_OK) {
        const std::string why = db ? detail::message_of(db) : sqlite3_errstr(rc);
        close();
        fail("cannot be opened: " + why, detail::kind_of(rc));
      }
      if (locked || vmap::detail::file_id(path) == id) {
        sqlite3_extended_result_codes(db_, 1);
        // A reader waits up to 5 s for a writer's checkpoint instead of failing at once.
        sqlite3_busy_timeout(db_, 5000);
        return;
      }
      close_connection();
    }
    fail("cannot be opened: it was replaced again and again while being opened", ErrorKind::busy);
  }

  /// A writer's settings: a write-ahead log, each commit flushed to disk.
  void write_ahead() {
    exec("PRAGMA journal_mode=WAL", "use a write-ahead log");
    exec("PRAGMA synchronous=FULL", "set synchronous=FULL");
  }

  /// Closes the connection and unregisters its file; the writer's lock stays.
  void close_connection() noexcept {
    if (db_) {
      // With statements still alive SQLite keeps the file open until they are finalized:
      // its file stays registered (the descriptors kept for it stay open).
      if (sqlite3_close(db_) != SQLITE_OK) {
        sqlite3_close_v2(db_);
        file_.reset();
      }
      db_ = nullptr;
    }
    if (file_) vmap::detail::OpenDatabases::instance().closed_connection(*std::exchange(file_, std::nullopt));
  }

  void close() noexcept {
    close_connection();
    lock_.release();
  }

  sqlite3* db_ = nullptr;
  std::optional<vmap::detail::FileId> file_;  ///< the registered file, while the connection has it open
  WriterLock lock_;                           ///< the writer's flock; released after the database closed
  std::string what_;
};

/// Moves the write-ahead log of the database at `path` into the file and truncates the
/// log to nothing (PRAGMA wal_checkpoint(TRUNCATE)), through a connection of its own that
/// takes no WriterLock: for a caller that holds the file's WriterLock already. A reader
/// that holds an older snapshot for longer than SQLite's 5 s wait makes it an Error: the
/// log was not emptied. A database that is not in WAL mode is left as it is.
inline void checkpoint_locked(const std::filesystem::path& path, const std::string& what) {
  Database db = Database::under_lock_held(path, what);
  sqlite3_stmt* s = nullptr;
  if (sqlite3_prepare_v2(db.handle(), "PRAGMA wal_checkpoint(TRUNCATE)", -1, &s, nullptr) != SQLITE_OK)
    db.fail_sqlite("checkpoint its write-ahead log");
  const int step = sqlite3_step(s);
  const bool busy = step == SQLITE_ROW && sqlite3_column_int(s, 0) != 0;
  const std::string why = step == SQLITE_ROW ? std::string() : sqlite3_errmsg(db.handle());
  const ErrorKind kind = detail::kind_of(db.handle());
  sqlite3_finalize(s);
  if (step != SQLITE_ROW) db.fail("checkpoint its write-ahead log: " + why, kind);
  if (busy) db.fail("checkpoint its write-ahead log: a reader held an older snapshot for 5 s; try again", ErrorKind::busy);
}

/// A prepared statement: bind parameters (1-based), step through rows, read columns
/// (0-based). Reset before it runs again. It keeps the connection's handle, not the
/// Database object, so it stays valid when that object is moved.
class Statement {
 public:
  Statement(const Database& db, std::string_view sql, std::string_view doing)
      : db_(db.handle()), what_(db.what()), doing_(doing) {
    sqlite3_stmt* s = nullptr;
    if (sqlite3_prepare_v3(db_, sql.data(), static_cast<int>(sql.size()), SQLITE_PREPARE_PERSISTENT, &s, nullptr) !=
        SQLITE_OK)
      fail_sqlite();
    stmt_ = s;
  }
  Statement(Statement&& o) noexcept
      : db_(o.db_), stmt_(std::exchange(o.stmt_, nullptr)), what_(std::move(o.what_)), doing_(std::move(o.doing_)) {}
  Statement& operator=(Statement&& o) noexcept {
    if (this != &o) {
      sqlite3_finalize(stmt_);
      db_ = o.db_;
      stmt_ = std::exchange(o.stmt_, nullptr);
      what_ = std::move(o.what_);
      doing_ = std::move(o.doing_);
    }
    return *this;
  }
  Statement(const Statement&) = delete;
  Statement& operator=(const Statement&) = delete;
  ~Statement() { sqlite3_finalize(stmt_); }

  Statement& bind(int i, std::int64_t v) { return check(sqlite3_bind_int64(stmt_, i, v)); }
  Statement& bind(int i, double v) { return check(sqlite3_bind_double(stmt_, i, v)); }
  Statement& bind_text(int i, std::string_view v) {
    return check(sqlite3_bind_text64(stmt_, i, v.data(), v.size(), SQLITE_TRANSIENT, SQLITE_UTF8));
  }
  Statement& bind_blob(int i, std::string_view v) {
    // A zero-length blob is bound as one, not as NULL (a null pointer would be NULL).
    static const char empty = 0;
    return check(sqlite3_bind_blob64(stmt_, i, v.empty() ? &empty : v.data(), v.size(), SQLITE_TRANSIENT));
  }
  Statement& bind_null(int i) { return check(sqlite3_bind_null(stmt_, i)); }

  /// The next row: true while there is one; false when done.
  bool step() {
    const int rc = sqlite3_step(stmt_);
    if (rc == SQLITE_ROW) return true;
    if (rc == SQLITE_DONE) return false;
    fail_sqlite();
  }
  /// Runs a statement that returns no row, then resets it for the next bindings (also
  /// when it fails, so that the statement can be used again).
  void run() {
    bool row = false;
    try {
      row = step();
    } catch (...) {
      reset();
      throw;
    }
    reset();
    if (row) fail("returned a row");
  }
  void reset() {
    sqlite3_reset(stmt_);
    sqlite3_clear_bindings(stmt_);
  }

  [[nodiscard]] bool is_null(int c) const { return sqlite3_column_type(stmt_, c) == SQLITE_NULL; }
  [[nodiscard]] std::int64_t integer(int c) const {
    expect(c, SQLITE_INTEGER, "an integer");
    return sqlite3_column_int64(stmt_, c);
  }
  [[nodiscard]] double real(int c) const {
    const int t = sqlite3_column_type(stmt_, c);
    if (t != SQLITE_FLOAT && t != SQLITE_INTEGER) type_error(c, "a number");
    return sqlite3_column_double(stmt_, c);
  }
  [[nodiscard]] std::string text(int c) const {
    expect(c, SQLITE_TEXT, "text");
    const auto* p = reinterpret_cast<const char*>(sqlite3_column_text(stmt_, c));
    return p ? std::string(p, static_cast<std::size_t>(sqlite3_column_bytes(stmt_, c))) : std::string();
  }
  /// The column's bytes, valid until the next step or reset.
  [[nodiscard]] std::string_view blob(int c) const {
    expect(c, SQLITE_BLOB, "a blob");
    const void* p = sqlite3_column_blob(stmt_, c);
    const int n = sqlite3_column_bytes(stmt_, c);
    return p ? std::string_view(static_cast<const char*>(p), static_cast<std::size_t>(n)) : std::string_view();
  }

 private:
  Statement& check(int rc) {
    if (rc != SQLITE_OK) fail_sqlite();
    return *this;
  }
  [[noreturn]] void fail_sqlite() const { fail(detail::message_of(db_), detail::kind_of(db_)); }
  [[noreturn]] void fail(const std::string& message, ErrorKind kind = ErrorKind::invalid_argument) const {
    vmap::detail::fail(kind, what_ + " " + doing_ + ": " + message);
  }
  void expect(int c, int type, const char* name) const {
    if (sqlite3_column_type(stmt_, c) != type) type_error(c, name);
  }
  [[noreturn]] void type_error(int c, const char* name) const {
    const char* column = sqlite3_column_name(stmt_, c);
    fail(std::string("column '") + (column ? column : "?") + "' is not " + name, ErrorKind::corrupt);
  }

  sqlite3* db_ = nullptr;
  sqlite3_stmt* stmt_ = nullptr;
  std::string what_, doing_;
};

inline Statement Database::prepare(std::string_view sql, std::string_view doing) { return Statement(*this, sql, doing); }

/// BEGIN IMMEDIATE (a writer's) or BEGIN (a reader's: one snapshot for every read in
/// it) .. COMMIT; rolled back when destroyed uncommitted (an exception).
class Transaction {
 public:
  enum class Kind : std::uint8_t { write, read };

  Transaction(Database& db, std::string doing, Kind kind = Kind::write) : db_(&db), doing_(std::move(doing)) {
    db.exec(kind == Kind::write ? "BEGIN IMMEDIATE" : "BEGIN", doing_ + ": begin");
  }
  Transaction(const Transaction&) = delete;
  Transaction& operator=(const Transaction&) = delete;
  ~Transaction() {
    if (db_) sqlite3_exec(db_->handle(), "ROLLBACK", nullptr, nullptr, nullptr);
  }
  void commit() {
    db_->exec("COMMIT", doing_ + ": commit");
    db_ = nullptr;
  }

 private:
  Database* db_;
  std::string doing_;
};

}  // namespace vmap::sqlite
