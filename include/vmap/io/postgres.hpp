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
// Timeouts: a server that stops answering (a stopped or hung server, a network that
// drops packets without a reset) never stalls a caller without bound. Connecting waits at
// most libpq's connect_timeout (a URI parameter, `?connect_timeout=N`, or the environment
// variable PGCONNECT_TIMEOUT; 10 s when neither gives one), and each statement's answer
// (a query, a sync's INSERT, its COMMIT) at most the environment variable
// VMAP_PG_QUERY_TIMEOUT seconds (30 by default). Either ends in ErrorKind::unavailable;
// the connection is then closed (a statement whose answer never came may still run on the
// server), so it counts as broken and reconnect() makes it again.
//
// Threads: as io/sqlite.hpp, one thread at a time per connection.

#include <vmap/core/error.hpp>

#include <libpq-fe.h>

#include <poll.h>

#include <bit>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <string>
#include <string_view>
#include <type_traits>
#include <algorithm>
#include <utility>
#include <vector>

namespace vmap::pg {

/// Whether `location` is a PostgreSQL connection URI (postgresql:// or postgres://)
/// rather than a file.
[[nodiscard]] inline bool is_uri(std::string_view location) noexcept {
  return location.starts_with("postgresql://") || location.starts_with("postgres://");
}

/// `uri` without its password: "user:secret@" becomes "user@", and a "password=" query
/// parameter is dropped. What messages and stores show of a connection string. A password
/// written without percent-escapes may hold '/', '?' or '@', which end the user part of a
/// URI: the user part is taken to end at the last '@' before the first '/' or '?' that
/// follows an '@', so such a password is removed whole too.
[[nodiscard]] inline std::string redacted(std::string_view uri) {
  // What to remove, marked on the URI as given: the user part's password and every
  // password parameter (with a separator), both found on the original, so that neither
  // removal can hide the other's end.
  std::vector<bool> drop(uri.size(), false);
  const auto mark = [&](std::size_t from, std::size_t to) {
    for (std::size_t i = from; i < to && i < drop.size(); ++i) drop[i] = true;
  };
  const std::size_t scheme = uri.find("://");
  if (scheme != std::string_view::npos) {
    const std::size_t start = scheme + 3;
    const std::size_t first_at = uri.find('@', start);
    if (first_at != std::string_view::npos) {
      const std::size_t stop = uri.find_first_of("/?", first_at);
      const std::size_t at = uri.rfind('@', stop);
      const std::size_t colon = uri.find(':', start);
      if (colon < at) mark(colon, at);
    }
  }
  for (std::size_t at = uri.find("password="); at != std::string_view::npos; at = uri.find("password=", at + 1)) {
    if (at == 0 || (uri[at - 1] != '?' && uri[at - 1] != '&')) continue;
    const std::size_t end = std::min(uri.find('&', at), uri.size());
    if (uri[at - 1] == '&')
      mark(at - 1, end);  // "&password=..."
    else
      mark(at, end < uri.size() ? end + 1 : end);  // "?password=...&" keeps the '?'
  }
  std::string out;
  for (std::size_t i = 0; i < uri.size(); ++i)
    if (!drop[i]) out += uri[i];
  if (!out.empty() && (out.back() == '?' || out.back() == '&')) out.pop_back();
  return out;
}

/// The longest wait for one answer of the server (VMAP_PG_QUERY_TIMEOUT, seconds; 30 by
/// default); an Error naming the variable when it holds no number of seconds in
/// (0, 86400].
[[nodiscard]] inline std::chrono::milliseconds query_timeout() {
  const char* given = std::getenv("VMAP_PG_QUERY_TIMEOUT");
  if (!given || !*given) return std::chrono::seconds(30);
  char* end = nullptr;
  const double seconds = std::strtod(given, &end);
  if (end == given || *end != '\0' || !std::isfinite(seconds) || seconds <= 0.0 || seconds > 86400.0)
    vmap::detail::fail("VMAP_PG_QUERY_TIMEOUT: expected a number of seconds in (0, 86400], got '" + std::string(given) + "'");
  return std::chrono::milliseconds(static_cast<std::int64_t>(std::ceil(seconds * 1000.0)));
}

/// connect_timeout's value when neither the URI nor PGCONNECT_TIMEOUT gives one (seconds).
inline constexpr int default_connect_timeout = 10;

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
  std::string conninfo;               ///< as given, with its password if any: never shown
  std::chrono::milliseconds timeout;  ///< the longest wait for one answer (query_timeout)
  std::uint64_t generation = 0;       ///< bumped by each reconnect: statements prepared before are gone
  std::uint64_t statements = 0;       ///< names of prepared statements
  ~Session() { drop(); }
  [[nodiscard]] bool broken() const noexcept { return !conn || PQstatus(conn) != CONNECTION_OK; }
  /// Closes the connection (it is broken() from then on).
  void drop() noexcept {
    if (conn) PQfinish(std::exchange(conn, nullptr));
  }
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

  /// Connects (again): libpq's connect_timeout bounds it (see the top of this file). An
  /// Error of kind unavailable when the server cannot be reached or does not answer in
  /// time; invalid_argument for an option value libpq refuses.
  void connect(std::string_view doing) {
    drop();
    // Before the URI: a connect_timeout of the URI wins, and PGCONNECT_TIMEOUT when set.
    const std::string fallback = std::to_string(default_connect_timeout);
    const char* env = std::getenv("PGCONNECT_TIMEOUT");
    const char* keywords[] = {"connect_timeout", "dbname", nullptr};
    const char* values[] = {env && *env ? nullptr : fallback.c_str(), conninfo.c_str(), nullptr};
    conn = PQconnectdbParams(keywords, values, 1);
    if (!conn) fail(doing, "out of memory", ErrorKind::io);
    if (PQstatus(conn) != CONNECTION_OK) {
      // libpq checks the options' values (a port that is no number, an unknown sslmode)
      // when it connects; its messages for them begin with "invalid".
      const std::string why = message();
      drop();
      if (why.starts_with("invalid ")) fail(doing, why, ErrorKind::invalid_argument);
      fail(doing, why + " (the database server is unavailable; try again when it is back)", ErrorKind::unavailable);
    }
    // Notices (e.g. "relation exists, skipping") are not printed on the caller's stderr.
    PQsetNoticeProcessor(conn, [](void*, const char*) {}, nullptr);
    // Sends and waits are ours (wait()), bounded by the timeout.
    if (PQsetnonblocking(conn, 1) != 0) fail(doing, message(), ErrorKind::unavailable);
  }

  /// Waits until the query sent is flushed and its answer is in, at most `timeout`
  /// (see the top of this file): an Error of kind unavailable when the server does not
  /// answer in time (the connection is then dropped), or when the connection broke.
  void wait(std::string_view doing) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    const auto wait_for = [&](short events) {
      for (;;) {
        const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
        pollfd p{PQsocket(conn), events, 0};
        const int n = left.count() > 0 ? ::poll(&p, 1, static_cast<int>(std::min<std::int64_t>(left.count(), 1 << 30))) : 0;
        if (n > 0) return;
        if (n < 0 && errno == EINTR) continue;
        if (n < 0) fail(doing, std::string("poll: ") + std::strerror(errno), ErrorKind::unavailable);
        const auto ms = timeout.count();
        drop();
        fail(doing,
             "the database server did not answer within " + std::to_string(ms / 1000) + (ms % 1000 ? "." + std::to_string(ms % 1000) : "") +
                 " s (VMAP_PG_QUERY_TIMEOUT); the connection was closed (the database server is unavailable; try "
                 "again when it is back)",
             ErrorKind::unavailable);
      }
    };
    for (;;) {
      const int flushed = PQflush(conn);
      if (flushed < 0) fail_result(doing, nullptr);
      if (flushed == 0) break;
      wait_for(POLLIN | POLLOUT);
      if (PQconsumeInput(conn) == 0) fail_result(doing, nullptr);
    }
    while (PQisBusy(conn)) {
      wait_for(POLLIN);
      if (PQconsumeInput(conn) == 0) fail_result(doing, nullptr);
    }
  }

  /// Sends a query (`send` returns libpq's PQsend* result) and returns its answer: the
  /// first failed result, or the last one. Bounded by the timeout.
  template <class Send>
  [[nodiscard]] Result run(std::string_view doing, Send&& send) {
    if (broken()) fail_result(doing, nullptr);
    if (send() == 0) fail_result(doing, nullptr);
    Result kept;
    bool kept_failed = false;
    for (;;) {
      wait(doing);
      Result r(PQgetResult(conn));
      if (!r) break;
      if (kept_failed) continue;  // the first failure is the answer
      const ExecStatusType st = PQresultStatus(r.get());
      kept_failed = st != PGRES_COMMAND_OK && st != PGRES_TUPLES_OK;
      kept = std::move(r);
    }
    return kept;
  }

  /// run() of `sql` whose failure is not reported (a cleanup: ROLLBACK, DEALLOCATE).
  void run_quietly(const std::string& sql) noexcept {
    try {
      if (!broken()) (void)run("", [&] { return PQsendQuery(conn, sql.c_str()); });
    } catch (...) {
    }
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
    session_->conninfo = uri;
    session_->timeout = query_timeout();
    session_->connect("connect");
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
    ++session_->generation;
    session_->connect("connect again");
  }

  /// Runs `sql` (one or more statements without parameters, e.g. DDL or BEGIN).
  void exec(const std::string& sql, std::string_view doing) {
    detail::Result r = session_->run(doing, [&] { return PQsendQuery(session_->conn, sql.c_str()); });
    const ExecStatusType s = r ? PQresultStatus(r.get()) : PGRES_FATAL_ERROR;
    if (s != PGRES_COMMAND_OK && s != PGRES_TUPLES_OK) session_->fail_result(doing, r.get());
  }

  [[nodiscard]] Statement prepare(std::string_view sql, std::string_view doing);

  [[noreturn]] void fail(const std::string& message, ErrorKind kind = ErrorKind::invalid_argument) const {
    vmap::detail::fail(kind, session_->what + " " + message);
  }

 private:
  friend class Statement;
  friend class Transaction;
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
    session_->run_quietly("DEALLOCATE " + name_);
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
      detail::Result r =
          s.run(doing_, [&] { return PQsendPrepare(s.conn, name_.c_str(), sql_.c_str(), params_, types.data()); });
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
    result_ = s.run(doing_, [&] {
      return PQsendQueryPrepared(s.conn, name_.c_str(), params_, data.data(), lengths.data(), formats.data(), 1);
    });
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
    if (c_) c_->session_->run_quietly("ROLLBACK");
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
