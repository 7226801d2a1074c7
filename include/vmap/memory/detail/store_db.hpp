#pragma once

// The memory store's connection to either of its databases, an SQLite file
// (io/sqlite.hpp) or a PostgreSQL server (io/postgres.hpp), behind one set of calls, so
// that MemoryStore (memory/store.hpp) reads and writes its rows with one piece of code.
// Both layers take the same SQL ('?' parameters; the statements the store runs are
// written in the subset both dialects share) and throw vmap::Errors naming the memory.

#include <vmap/core/error.hpp>
#include <vmap/io/postgres.hpp>
#include <vmap/io/sqlite.hpp>

#include <cstdint>
#include <cstdlib>
#include <functional>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <variant>

namespace vmap::detail {

/// A prepared statement of either database.
class StoreQuery {
 public:
  explicit StoreQuery(sqlite::Statement s) : s_(std::move(s)) {}
  explicit StoreQuery(pg::Statement s) : s_(std::move(s)) {}

  StoreQuery& bind(int i, std::int64_t v) {
    std::visit([&](auto& s) { s.bind(i, v); }, s_);
    return *this;
  }
  StoreQuery& bind(int i, double v) {
    std::visit([&](auto& s) { s.bind(i, v); }, s_);
    return *this;
  }
  StoreQuery& bind_text(int i, std::string_view v) {
    std::visit([&](auto& s) { s.bind_text(i, v); }, s_);
    return *this;
  }
  StoreQuery& bind_blob(int i, std::string_view v) {
    std::visit([&](auto& s) { s.bind_blob(i, v); }, s_);
    return *this;
  }
  bool step() {
    return std::visit([](auto& s) { return s.step(); }, s_);
  }
  void run() {
    std::visit([](auto& s) { s.run(); }, s_);
  }
  void reset() {
    std::visit([](auto& s) { s.reset(); }, s_);
  }
  [[nodiscard]] bool is_null(int c) const {
    return std::visit([&](const auto& s) { return s.is_null(c); }, s_);
  }
  [[nodiscard]] std::int64_t integer(int c) const {
    return std::visit([&](const auto& s) { return s.integer(c); }, s_);
  }
  [[nodiscard]] double real(int c) const {
    return std::visit([&](const auto& s) { return s.real(c); }, s_);
  }
  [[nodiscard]] std::string text(int c) const {
    return std::visit([&](const auto& s) { return s.text(c); }, s_);
  }
  [[nodiscard]] std::string_view blob(int c) const {
    return std::visit([&](const auto& s) { return s.blob(c); }, s_);
  }

 private:
  std::variant<sqlite::Statement, pg::Statement> s_;
};

/// A connection to either database.
class StoreDb {
 public:
  explicit StoreDb(sqlite::Database db) : db_(std::move(db)) {}
  explicit StoreDb(pg::Connection c) : db_(std::move(c)) {}

  /// Whether it is a PostgreSQL server (a fleet's memory) rather than an SQLite file.
  [[nodiscard]] bool postgres() const noexcept { return std::holds_alternative<pg::Connection>(db_); }
  [[nodiscard]] sqlite::Database& sqlite() { return std::get<sqlite::Database>(db_); }
  [[nodiscard]] pg::Connection& server() { return std::get<pg::Connection>(db_); }

  [[nodiscard]] const std::string& what() const noexcept {
    return std::visit([](const auto& d) -> const std::string& { return d.what(); }, db_);
  }
  [[nodiscard]] StoreQuery prepare(std::string_view sql, std::string_view doing) {
    return std::visit([&](auto& d) { return StoreQuery(d.prepare(sql, doing)); }, db_);
  }
  void exec(const std::string& sql, std::string_view doing) {
    std::visit([&](auto& d) { d.exec(sql, doing); }, db_);
  }
  [[noreturn]] void fail(const std::string& message, ErrorKind kind = ErrorKind::invalid_argument) const {
    std::visit([&](const auto& d) { d.fail(message, kind); }, db_);
    std::abort();  // unreachable: both fail() throw
  }

 private:
  std::variant<sqlite::Database, pg::Connection> db_;
};

/// A transaction of either database: a writer's, or a reader's (one snapshot for every
/// read in it); rolled back when destroyed uncommitted.
class StoreTransaction {
 public:
  enum class Kind : std::uint8_t { write, read };

  StoreTransaction(StoreDb& db, std::string doing, Kind kind = Kind::write) {
    if (db.postgres())
      pg_.emplace(db.server(), std::move(doing), kind == Kind::write ? pg::Transaction::Kind::write : pg::Transaction::Kind::read);
    else
      sqlite_.emplace(db.sqlite(), std::move(doing),
                      kind == Kind::write ? sqlite::Transaction::Kind::write : sqlite::Transaction::Kind::read);
  }
  void commit() {
    if (pg_) pg_->commit();
    if (sqlite_) sqlite_->commit();
  }

 private:
  std::optional<sqlite::Transaction> sqlite_;
  std::optional<pg::Transaction> pg_;
};

}  // namespace vmap::detail
