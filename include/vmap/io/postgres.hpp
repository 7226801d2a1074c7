#pragma once

// A thin RAII layer over libpq (Debian's libpq-dev, linked by vmap::vmap) for the memory
// store's PostgreSQL back-end (memory/store.hpp, a fleet's shared memory): a connection,
// prepared statements and transactions, with the same calls as the SQLite layer
// (io/sqlite.hpp), so that the store reads and writes its rows through either. Every
// failure is a vmap::Error naming the database (its address without a password), what
// was being done and the server's own message.
//
// The connection string is libpq's: a URI (postgresql://user@host:port/db?sslmode=...)
// with libpq's conventions for what it leaves out (PGPASSWORD, ~/.pgpass, PGHOST, ...).
// A password written in the URI reaches the server only: every message and the name a
// store keeps show the URI with it removed (redacted()).
//
// Statements are written with SQLite's '?' parameters and numbered for the server ($1,
// $2, ...); each is prepared on the server at its first run, with the types of the
// values bound then (bigint, double precision, text, bytea), and every value and row
// crosses in binary, so blobs are not escaped. Nothing but a parameter carries a value:
// names (robots, notes) never become SQL text.
//
// Kinds of failure (the SQLSTATE's class): a server that cannot be reached, went away
// or shuts down is ErrorKind::unavailable; a lock another session holds, a serialization
// failure or a deadlock is busy; a table or column that is not the one vmap made
// (undefined, wrong type) is corrupt; a disk full on the server is io. A connection that
// broke is made again by reconnect() (the caller then sets its session up again: its
// prepared statements are prepared again by themselves).
//
// Threads: as io/sqlite.hpp, one thread at a time per connection.

#include <vmap/core/error.hpp>

#include <libpq-fe.h>

#include <bit>
#include <cstdint>
#include <cstring>
#include <memory>
#include <string>
#include <string_view>
#include <type_traits>
#include <utility>
#include <vector>

namespace vmap::pg {

/// Whether `location` is a PostgreSQL connection URI (postgresql:// or postgres://)
/// rather than a file.
[[nodiscard]] inline bool is_uri(std::string_view location) noexcept {
  return location.starts_with("postgresql://") || location.starts_with("postgres://");
}

/// `uri` without its password: "user:secret@" becomes "user@", and a "password=" query
/// parameter is dropped. What messages and stores show of a connection string.
[[nodiscard]] inline std::string redacted(std::string_view uri) {
  std::string out(uri);
  const std::size_t scheme = out.find("://");
  if (scheme != std::string::npos) {
    const std::size_t start = scheme + 3;
    const std::size_t end = out.find_first_of("/?", start);
    const std::size_t at = out.rfind('@', end == std::string::npos ? out.size() : end);
    if (at != std::string::npos && at >= start) {
      const std::size_t colon = out.find(':', start);
      if (colon != std::string::npos && colon < at) out.erase(colon, at - colon);
    }
  }
  const std::size_t query = out.find('?');
  if (query != std::string::npos) {
    std::string kept = out.substr(0, query);
    std::string_view rest = std::string_view(out).substr(query + 1);
    char sep = '?';
    while (!rest.empty()) {
      const std::size_t amp = rest.find('&');
      const std::string_view param = rest.substr(0, amp);
      if (!param.starts_with("password=")) {
        kept += sep;
        kept += param;
        sep = '&';
      }
      if (amp == std::string_view::npos) break;
      rest.remove_prefix(amp + 1);
    }
    out = std::move(kept);
  }
  return out;
}

namespace detail {

// Type OIDs of the server's built-in types (catalog/pg_type_d.h; stable across versions).
inline constexpr Oid bool_oid = 16, bytea_oid = 17, name_oid = 19, int8_oid = 20, int2_oid = 21, int4_oid = 23,
                     text_oid = 25, float4_oid = 700, float8_oid = 701, varchar_oid = 1043;

/// The kind of Error a server error is, by its SQLSTATE (see the top of this file).
[[nodiscard]] inline ErrorKind kind_of_state(const char* state, bool connection_bad) {
  if (connection_bad) return ErrorKind::unavailable;
  const std::string_view s = state ? state : "";
  if (s.size() != 5) return ErrorKind::unavailable;  // no SQLSTATE: the connection broke
  const std::string_view cls = s.substr(0, 2);
  if (cls == "08" || cls == "57" || (cls == "53" && s != "53100")) return ErrorKind::unavailable;
  if (s == "53100") return ErrorKind::io;  // disk full
  if (cls == "40" || s == "55P03") return ErrorKind::busy;
  if (cls == "42" || cls == "22" || cls == "23") return ErrorKind::corrupt;
  return ErrorKind::io;
}

/// `v` with its bytes reversed on a little-endian machine: the server's byte order.
template <class T>
[[nodiscard]] T network_order(T v) noexcept {
  if constexpr (std::endian::native == std::endian::little) {
    auto u = std::bit_cast<std::make_unsigned_t<T>>(v);
    if constexpr (sizeof(T) == 8) u = __builtin_bswap64(u);
    if constexpr (sizeof(T) == 4) u = __builtin_bswap32(u);
    if constexpr (sizeof(T) == 2) u = __builtin_bswap16(u);
    v = std::bit_cast<T>(u);
  }
  return v;
}

template <class T>
[[nodiscard]] T big_endian(const char* p) noexcept {
  T v;
  std::memcpy(&v, p, sizeof v);
  return network_order(v);
}

template <class T>
void put_big_endian(std::string& out, T v) {
  v = network_order(v);
  char b[sizeof v];
  std::memcpy(b, &v, sizeof v);
  out.append(b, sizeof v);
}

/// A PGresult, cleared when it goes.
struct ResultDeleter {
  void operator()(PGresult* r) const noexcept { PQclear(r); }
};
using Result = std::unique_ptr<PGresult, ResultDeleter>;

/// The connection's state, shared by the Connection and its Statements (so that they
/// stay valid when the Connection object moves).
struct Session {
  PGconn* conn = nullptr;
  std::string what;
  std::uint64_t generation = 0;  ///< bumped by each reconnect: statements prepared before are gone
  std::uint64_t statements = 0;  ///< names of prepared statements
  ~Session() {
    if (conn) PQfinish(conn);
  }
  [[nodiscard]] bool broken() const noexcept { return !conn || PQstatus(conn) != CONNECTION_OK; }
  /// The server's message, one line.
  [[nodiscard]] std::string message() const {
    std::string m = conn ? PQerrorMessage(conn) : "not connected";
    while (!m.empty() && (m.back() == '\n' || m.back() == ' ')) m.pop_back();
    for (char& c : m)
      if (c == '\n') c = ' ';
    return m.empty() ? std::string("the connection failed") : m;
  }
  [[noreturn]] void fail(std::string_view doing, const std::string& message, ErrorKind kind) const {
    vmap::detail::fail(kind, what + " " + std::string(doing) + ": " + message);
  }
  /// Throws the failure of `r` (or of the connection when `r` is null).
  [[noreturn]] void fail_result(std::string_view doing, const PGresult* r) const {
    std::string m = r ? PQresultErrorMessage(r) : "";
    while (!m.empty() && (m.back() == '\n' || m.back() == ' ')) m.pop_back();
    for (char& c : m)
      if (c == '\n') c = ' ';
    if (m.empty()) m = message();
    const char* state = r ? PQresultErrorField(r, PG_DIAG_SQLSTATE) : nullptr;
    const ErrorKind kind = kind_of_state(state, broken());
    fail(doing, kind == ErrorKind::unavailable ? m + " (the database server is unavailable; try again when it is back)" : m,
         kind);
  }
};

/// `sql` with its '?' parameters numbered $1, $2, ... (none inside quotes); `count` gets
/// how many there are.
[[nodiscard]] inline std::string numbered(std::string_view sql, int& count) {
  std::string out;
  out.reserve(sql.size() + 16);
  count = 0;
  bool quoted = false;
  for (const char c : sql) {
    if (c == '\'') quoted = !quoted;
    if (c == '?' && !quoted) {
      out += '$';
      out += std::to_string(++count);
    } else {
      out += c;
    }
  }
  return out;
}

}  // namespace detail

class Statement;

/// One connection to a PostgreSQL database.
class Connection {
 public:
  Connection() = default;

  /// Connects to `uri` (libpq's connection string); `what` names it in every message
  /// (e.g. "memory 'postgresql://fleet@db/vmap'": never with a password). A server that
  /// cannot be reached, or refuses the connection, is ErrorKind::unavailable.
  Connection(const std::string& uri, std::string what) : session_(std::make_shared<detail::Session>()) {
    session_->what = std::move(what);
    // A connection string libpq cannot parse (a bad port, an unknown option) is the
    // caller's mistake, not an unreachable server.
    char* parse_error = nullptr;
    PQconninfoOption* options = PQconninfoParse(uri.c_str(), &parse_error);
    if (!options) {
      std::string why = parse_error ? parse_error : "it cannot be parsed";
      PQfreemem(parse_error);
      while (!why.empty() && (why.back() == '\n' || why.back() == ' ')) why.pop_back();
      session_->fail("connect", why, ErrorKind::invalid_argument);
    }
    PQconninfoFree(options);
    session_->conn = PQconnectdb(uri.c_str());
    if (!session_->conn) session_->fail("connect", "out of memory", ErrorKind::io);
    if (PQstatus(session_->conn) != CONNECTION_OK) {
      // libpq checks the options' values (a port that is no number, an unknown sslmode)
      // when it connects; its messages for them begin with "invalid".
      const std::string why = session_->message();
      session_->fail("connect", why, why.starts_with("invalid ") ? ErrorKind::invalid_argument : ErrorKind::unavailable);
    }
    quiet();
  }

  [[nodiscard]] bool is_open() const noexcept { return session_ && session_->conn; }
  [[nodiscard]] const std::string& what() const noexcept { return session_->what; }
  [[nodiscard]] PGconn* handle() const noexcept { return session_->conn; }
  /// Whether the connection broke (the server went away or restarted).
  [[nodiscard]] bool broken() const noexcept { return session_->broken(); }
  /// Connects again with the same parameters (after broken()); an Error of kind
  /// unavailable while the server is still away. The session's settings, locks and
  /// prepared statements are gone: the caller sets them up again.
  void reconnect() {
    PQreset(session_->conn);
    ++session_->generation;
    if (PQstatus(session_->conn) != CONNECTION_OK)
      session_->fail("connect again", session_->message() + " (the database server is unavailable; try again when it is back)",
                     ErrorKind::unavailable);
    quiet();
  }

  /// Runs `sql` (one or more statements without parameters, e.g. DDL or BEGIN).
  void exec(const std::string& sql, std::string_view doing) {
    detail::Result r(PQexec(session_->conn, sql.c_str()));
    const ExecStatusType s = r ? PQresultStatus(r.get()) : PGRES_FATAL_ERROR;
    if (s != PGRES_COMMAND_OK && s != PGRES_TUPLES_OK) session_->fail_result(doing, r.get());
  }

  [[nodiscard]] Statement prepare(std::string_view sql, std::string_view doing);

  [[noreturn]] void fail(const std::string& message, ErrorKind kind = ErrorKind::invalid_argument) const {
    vmap::detail::fail(kind, session_->what + " " + message);
  }

 private:
  friend class Statement;
  /// Notices (e.g. "relation exists, skipping") are not printed on the caller's stderr.
  void quiet() {
    PQsetNoticeProcessor(session_->conn, [](void*, const char*) {}, nullptr);
  }
  std::shared_ptr<detail::Session> session_;
};

/// A statement with '?' parameters: bind (1-based), step through rows, read columns
/// (0-based), as sqlite::Statement. Prepared on the server at its first run.
class Statement {
 public:
  Statement(const Connection& c, std::string_view sql, std::string_view doing)
      : session_(c.session_), sql_(detail::numbered(sql, params_)), doing_(doing) {
    values_.resize(static_cast<std::size_t>(params_));
  }
  Statement(Statement&& o) noexcept
      : session_(std::move(o.session_)),
        params_(o.params_),
        sql_(std::move(o.sql_)),
        doing_(std::move(o.doing_)),
        name_(std::move(o.name_)),
        values_(std::move(o.values_)),
        prepared_types_(std::move(o.prepared_types_)),
        prepared_(std::exchange(o.prepared_, 0)),
        result_(std::move(o.result_)),
        row_(o.row_) {}
  Statement& operator=(Statement&&) = delete;
  Statement(const Statement&) = delete;
  Statement& operator=(const Statement&) = delete;
  /// Frees the statement on the server (a long-lived connection prepares many).
  ~Statement() {
    if (!session_ || prepared_ != session_->generation + 1 || session_->broken()) return;
    const std::string sql = "DEALLOCATE " + name_;
    PQclear(PQexec(session_->conn, sql.c_str()));
  }

  Statement& bind(int i, std::int64_t v) {
    std::string b;
    detail::put_big_endian(b, static_cast<std::uint64_t>(v));
    return set(i, detail::int8_oid, std::move(b));
  }
  Statement& bind(int i, double v) {
    std::string b;
    detail::put_big_endian(b, std::bit_cast<std::uint64_t>(v));
    return set(i, detail::float8_oid, std::move(b));
  }
  Statement& bind_text(int i, std::string_view v) {
    if (v.find('\0') != std::string_view::npos) fail("a text value holds a NUL byte", ErrorKind::invalid_argument);
    return set(i, detail::text_oid, std::string(v));
  }
  Statement& bind_blob(int i, std::string_view v) { return set(i, detail::bytea_oid, std::string(v)); }
  Statement& bind_null(int i) {
    Value& x = at(i);
    x = Value{x.type, {}, true};
    return *this;
  }

  /// The next row: true while there is one; false when done. The first call runs it.
  bool step() {
    if (!result_) execute();
    if (row_ + 1 >= PQntuples(result_.get())) {
      row_ = PQntuples(result_.get());
      return false;
    }
    ++row_;
    return true;
  }
  /// Runs a statement that returns no row, then resets it.
  void run() {
    struct Reset {
      Statement& s;
      ~Reset() { s.reset(); }
    } reset{*this};
    execute();
    if (PQntuples(result_.get()) > 0) fail("returned a row", ErrorKind::invalid_argument);
  }
  /// Forgets the rows and the bindings.
  void reset() {
    result_.reset();
    row_ = -1;
    for (Value& v : values_) v = Value{v.type, {}, true};
  }

  [[nodiscard]] bool is_null(int c) const { return PQgetisnull(result_.get(), row_, c) != 0; }
  [[nodiscard]] std::int64_t integer(int c) const {
    const char* p = value(c, "an integer");
    switch (PQftype(result_.get(), c)) {
      case detail::int8_oid: return detail::big_endian<std::int64_t>(p);
      case detail::int4_oid: return detail::big_endian<std::int32_t>(p);
      case detail::int2_oid: return detail::big_endian<std::int16_t>(p);
      case detail::bool_oid: return *p != 0;
      default: type_error(c, "an integer");
    }
  }
  [[nodiscard]] double real(int c) const {
    const char* p = value(c, "a number");
    switch (PQftype(result_.get(), c)) {
      case detail::float8_oid: return std::bit_cast<double>(detail::big_endian<std::uint64_t>(p));
      case detail::float4_oid: return std::bit_cast<float>(detail::big_endian<std::uint32_t>(p));
      case detail::int8_oid:
      case detail::int4_oid:
      case detail::int2_oid: return static_cast<double>(integer(c));
      default: type_error(c, "a number");
    }
  }
  [[nodiscard]] std::string text(int c) const {
    const Oid t = PQftype(result_.get(), c);
    if (t != detail::text_oid && t != detail::varchar_oid && t != detail::name_oid) type_error(c, "text");
    const char* p = value(c, "text");
    return std::string(p, static_cast<std::size_t>(PQgetlength(result_.get(), row_, c)));
  }
  /// The column's bytes, valid until the next reset or run.
  [[nodiscard]] std::string_view blob(int c) const {
    if (PQftype(result_.get(), c) != detail::bytea_oid) type_error(c, "a blob (bytea)");
    const char* p = value(c, "a blob (bytea)");
    return {p, static_cast<std::size_t>(PQgetlength(result_.get(), row_, c))};
  }

 private:
  struct Value {
    Oid type = 0;
    std::string bytes;
    bool null = true;
  };

  Value& at(int i) {
    if (i < 1 || i > params_) fail("parameter " + std::to_string(i) + " is out of range", ErrorKind::invalid_argument);
    return values_[static_cast<std::size_t>(i - 1)];
  }
  Statement& set(int i, Oid type, std::string bytes) {
    at(i) = Value{type, std::move(bytes), false};
    return *this;
  }

  void execute() {
    detail::Session& s = *session_;
    if (s.broken()) s.fail_result(doing_, nullptr);
    if (prepared_ != s.generation + 1 || types_changed()) {
      name_ = "vmap_s" + std::to_string(++s.statements);
      std::vector<Oid> types;
      for (const Value& v : values_) types.push_back(v.type);
      detail::Result r(PQprepare(s.conn, name_.c_str(), sql_.c_str(), params_, types.data()));
      if (!r || PQresultStatus(r.get()) != PGRES_COMMAND_OK) s.fail_result(doing_, r.get());
      prepared_ = s.generation + 1;
      prepared_types_ = std::move(types);
    }
    std::vector<const char*> data;
    std::vector<int> lengths, formats;
    for (const Value& v : values_) {
      data.push_back(v.null ? nullptr : v.bytes.data());
      lengths.push_back(static_cast<int>(v.bytes.size()));
      formats.push_back(1);
    }
    result_.reset(PQexecPrepared(s.conn, name_.c_str(), params_, data.data(), lengths.data(), formats.data(), 1));
    const ExecStatusType st = result_ ? PQresultStatus(result_.get()) : PGRES_FATAL_ERROR;
    if (st != PGRES_TUPLES_OK && st != PGRES_COMMAND_OK) {
      detail::Result failed = std::move(result_);
      s.fail_result(doing_, failed.get());
    }
    row_ = -1;
  }
  [[nodiscard]] bool types_changed() const {
    for (std::size_t i = 0; i < values_.size(); ++i)
      if (values_[i].type != 0 && values_[i].type != prepared_types_[i]) return true;
    return false;
  }

  [[nodiscard]] const char* value(int c, const char* name) const {
    if (!result_ || row_ < 0 || row_ >= PQntuples(result_.get()) || c < 0 || c >= PQnfields(result_.get()))
      fail("no such row or column", ErrorKind::invalid_argument);
    if (PQgetisnull(result_.get(), row_, c)) type_error(c, name);
    return PQgetvalue(result_.get(), row_, c);
  }
  [[noreturn]] void type_error(int c, const char* name) const {
    const char* column = PQfname(result_.get(), c);
    fail(std::string("column '") + (column ? column : "?") + "' is not " + name, ErrorKind::corrupt);
  }
  [[noreturn]] void fail(const std::string& message, ErrorKind kind) const {
    vmap::detail::fail(kind, session_->what + " " + doing_ + ": " + message);
  }

  std::shared_ptr<detail::Session> session_;
  int params_ = 0;
  std::string sql_, doing_, name_;
  std::vector<Value> values_;
  std::vector<Oid> prepared_types_;
  std::uint64_t prepared_ = 0;  ///< the session generation + 1 it was prepared in (0: not yet)
  detail::Result result_;
  int row_ = -1;
};

inline Statement Connection::prepare(std::string_view sql, std::string_view doing) { return Statement(*this, sql, doing); }

/// BEGIN .. COMMIT (a reader's: one snapshot, REPEATABLE READ, READ ONLY); rolled back
/// when destroyed uncommitted.
class Transaction {
 public:
  enum class Kind : std::uint8_t { write, read };

  Transaction(Connection& c, std::string doing, Kind kind = Kind::write) : c_(&c), doing_(std::move(doing)) {
    c.exec(kind == Kind::write ? "BEGIN" : "BEGIN ISOLATION LEVEL REPEATABLE READ READ ONLY", doing_ + ": begin");
  }
  Transaction(const Transaction&) = delete;
  Transaction& operator=(const Transaction&) = delete;
  ~Transaction() {
    if (c_ && !c_->broken()) PQclear(PQexec(c_->handle(), "ROLLBACK"));
  }
  void commit() {
    c_->exec("COMMIT", doing_ + ": commit");
    c_ = nullptr;
  }

 private:
  Connection* c_;
  std::string doing_;
};

}  // namespace vmap::pg
