// Replacing a memory (memory/replace.hpp, MemoryCreateOptions::replace): the new store is
// built beside the old one under the old one's writer lock and renamed over it by
// close(); a writer or a second replacement is refused meanwhile, a run that fails or is
// destroyed unclosed leaves the old memory as it was, a file that is no memory is never
// replaced, and a FIFO is refused as an output or an input without being opened.
#include "support/errors.hpp"
#include "support/raw_sql.hpp"
#include "support/sample_memory.hpp"
#include "support/shared_data.hpp"

#include <vmap/io/database_files.hpp>
#include <vmap/io/sqlite.hpp>
#include <vmap/memory/replace.hpp>
#include <vmap/memory/store.hpp>
#include <vmap/runtime/memory.hpp>

#include <doctest/doctest.h>

#include <fcntl.h>
#include <sqlite3.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <functional>
#include <future>
#include <iterator>
#include <set>
#include <string>

namespace {

namespace fs = std::filesystem;
using vmap::test::error_of;
using vmap::test::sample_frames;

/// A folder of its own per test (its files are what the checks list).
fs::path folder(const std::string& name) { return vmap::test::scratch_dir("replace_" + name); }

/// The names of the files in `dir`, but for the -wal and -shm files SQLite's readers of
/// a memory there make and remove as they come and go.
std::set<std::string> files_in(const fs::path& dir) {
  std::set<std::string> out;
  for (const auto& e : fs::directory_iterator(dir)) {
    const std::string name = e.path().filename().string();
    const bool log = name.ends_with("-wal") || name.ends_with("-shm");
    if (!log || name.find("vmap-new") != std::string::npos) out.insert(name);
  }
  return out;
}

/// The bytes of `path`'s write-ahead log (0 when there is none).
std::uintmax_t wal_bytes(const fs::path& path) {
  std::error_code ec;
  const auto n = fs::file_size(path.string() + "-wal", ec);
  return ec ? 0 : n;
}

std::string bytes_of(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>()};
}

/// Frames [first, first + n) of the sample pushed.
void push(vmap::AnyMemory& mem, std::size_t first, std::size_t n) {
  for (std::size_t i = first; i < first + n; ++i) (void)mem.push(sample_frames()[i]);
}

vmap::MemoryOptions options() { return vmap::test::small_memory_options(); }

/// A memory store at `path` of `frames` frames, closed.
void make_memory(const fs::path& path, std::size_t frames) {
  auto mem = vmap::AnyMemory::create(path, vmap::PolicyStack{}, options());
  push(mem, 0, frames);
  mem.close();
}

/// A memory replacing the one at `path` (not yet closed), of `frames` frames.
vmap::AnyMemory replacing(const fs::path& path, std::size_t frames) {
  auto mem = vmap::AnyMemory::create(path, vmap::PolicyStack{}, options(), {}, {.replace = true});
  push(mem, 10, frames);
  return mem;
}

std::size_t frames_of(const fs::path& path) { return vmap::AnyMemory::open(path).frames(); }

/// `action` run in another thread; a FAIL when it has not returned after 20 s (then a
/// writer opening the FIFO `fifo` releases a reader stuck in open()).
std::string within_seconds(const fs::path& fifo, const std::function<std::string()>& action) {
  auto result = std::async(std::launch::async, action);
  if (result.wait_for(std::chrono::seconds(20)) != std::future_status::ready) {
    const int fd = ::open(fifo.c_str(), O_WRONLY | O_NONBLOCK);
    if (fd >= 0) ::close(fd);
    FAIL("blocked on the FIFO '" << fifo.string() << "'");
  }
  return result.get();
}

}  // namespace

TEST_CASE("replace: the new memory appears at close, with no file left beside it; readers see the old one until then") {
  const fs::path dir = folder("close");
  const fs::path path = dir / "m.vmdb";
  make_memory(path, 8);
  const std::string old_bytes = bytes_of(path);
  {
    auto mem = replacing(path, 20);
    // Until close() the path holds the old memory, bytes and all; the new one is built
    // under a name of its own beside it.
    CHECK(mem.replaces());
    CHECK(frames_of(path) == 8);
    CHECK(bytes_of(path) == old_bytes);
    CHECK(files_in(dir).size() >= 2);
    mem.close();
    CHECK(!mem.replaces());
    CHECK(mem.frames() == 20);
    CHECK(mem.path() == path);
  }
  CHECK(frames_of(path) == 20);
  CHECK(files_in(dir) == std::set<std::string>{"m.vmdb"});

  // A .vmem memory is replaced by a store too, and a link to a memory keeps naming it.
  const fs::path file = dir / "m.vmem";
  vmap::AnyMemory::open(path).save(file);
  replacing(file, 12).close();
  CHECK(vmap::memory_kind(file) == vmap::MemoryKind::store);
  CHECK(frames_of(file) == 12);
  fs::create_symlink("m.vmem", dir / "link.vmdb");
  replacing(dir / "link.vmdb", 5).close();
  CHECK(fs::is_symlink(dir / "link.vmdb"));
  CHECK(frames_of(file) == 5);
  CHECK(files_in(dir) == std::set<std::string>{"m.vmdb", "m.vmem", "link.vmdb"});
}

TEST_CASE("replace: a replacement that fails or is not closed leaves the old memory as it was") {
  const fs::path dir = folder("fail");
  const fs::path path = dir / "m.vmdb";
  make_memory(path, 8);
  const std::string old_bytes = bytes_of(path);

  SUBCASE("destroyed without close") { (void)replacing(path, 20); }
  SUBCASE("an exception in the middle of the run") {
    CHECK(error_of([&] {
            auto mem = replacing(path, 10);
            vmap::detail::fail("the run stopped");
            mem.close();
          }) == "the run stopped");
  }
  SUBCASE("abandoned") {
    auto mem = replacing(path, 10);
    mem.abandon();
    CHECK(!mem.writes());
    mem.close();
  }
  SUBCASE("a copy into a store, destroyed without close") {
    (void)vmap::AnyMemory::copy_into_store(vmap::AnyMemory::open(path), path, {.replace = true});
  }
  CHECK(bytes_of(path) == old_bytes);
  CHECK(frames_of(path) == 8);
  CHECK(files_in(dir) == std::set<std::string>{"m.vmdb"});
}

TEST_CASE("replace: refused while another writer holds the memory, and a writer refused while it is replaced") {
  const fs::path dir = folder("locked");
  const fs::path path = dir / "m.vmdb";
  make_memory(path, 8);
  const std::string busy = "memory '" + path.string() + "' is being written by another program";
  {
    // flock locks belong to the open file description: a writer in this process is a
    // writer like another program's.
    auto writer = vmap::MemoryStore::open(path, vmap::sqlite::Access::write);
    CHECK(error_of([&] { (void)replacing(path, 20); }).find(busy) == 0);
  }
  {
    auto writer = vmap::AnyMemory::open(path, {.write = true, .new_session = true});
    CHECK(error_of([&] { (void)replacing(path, 20); }).find(busy) == 0);
    CHECK(error_of([&] {
            (void)vmap::AnyMemory::copy_into_store(vmap::AnyMemory::open(path), path, {.replace = true});
          }).find(busy) == 0);
  }
  CHECK(files_in(dir) == std::set<std::string>{"m.vmdb"});
  CHECK(frames_of(path) == 8);

  // Two replacements of one memory at once: the second is refused, the first completes;
  // a writer is refused while it runs.
  auto first = replacing(path, 20);
  CHECK(error_of([&] { (void)replacing(path, 12); }).find(busy) == 0);
  CHECK(error_of([&] { (void)vmap::AnyMemory::open(path, {.write = true}); }).find(busy) == 0);
  first.close();
  CHECK(frames_of(path) == 20);
  CHECK(files_in(dir) == std::set<std::string>{"m.vmdb"});
}

TEST_CASE("replace: the old store's write-ahead log is emptied into it before anything else") {
  const fs::path dir = folder("wal");
  const fs::path path = dir / "m.vmdb";
  make_memory(path, 8);
  // A reader connection keeps the writer's log from being removed when it closes: the
  // second session stays in m.vmdb-wal.
  vmap::sqlite::Database reader(path, vmap::sqlite::Access::read, "reader");
  auto count = reader.prepare("SELECT count(*) FROM key_images", "count");
  REQUIRE(count.step());
  count.reset();
  {
    auto mem = vmap::AnyMemory::open(path, {.write = true, .new_session = true});
    push(mem, 20, 10);
    mem.sync();
    mem.flush();
  }
  REQUIRE(wal_bytes(path) > 0);
  {
    auto mem = replacing(path, 20);
    CHECK(wal_bytes(path) == 0);
  }
  // The old memory, both sessions of it, in its file.
  CHECK(frames_of(path) == 18);
  CHECK(files_in(dir) == std::set<std::string>{"m.vmdb"});
}

TEST_CASE("replace: a file that is no memory is never replaced") {
  const fs::path dir = folder("other");
  const fs::path text = dir / "notes.txt";
  {
    std::ofstream(text) << "not a memory";
  }
  const std::string refused = "'" + text.string() + "' is not a vmap memory";
  CHECK(error_of([&] { (void)replacing(text, 5); }).find(refused) == 0);
  make_memory(dir / "m.vmdb", 5);
  CHECK(error_of([&] {
          (void)vmap::AnyMemory::copy_into_store(vmap::AnyMemory::open(dir / "m.vmdb"), text, {.replace = true});
        }).find(refused) == 0);
  CHECK(bytes_of(text) == "not a memory");
  // Without replace, any existing file is refused.
  CHECK(error_of([&] { (void)vmap::AnyMemory::create(dir / "m.vmdb", vmap::PolicyStack{}); }).find("exists already") !=
        std::string::npos);
  fs::create_directory(dir / "folder.vmdb");
  CHECK(error_of([&] { (void)replacing(dir / "folder.vmdb", 5); }) ==
        "memory '" + (dir / "folder.vmdb").string() + "' is not a regular file");
  CHECK(files_in(dir) == std::set<std::string>{"notes.txt", "m.vmdb", "folder.vmdb"});
}

TEST_CASE("replace: a FIFO is refused as an output and as an input without being opened") {
  const fs::path dir = folder("fifo");
  const fs::path fifo = dir / "f.vmdb";
  REQUIRE(::mkfifo(fifo.c_str(), 0644) == 0);
  make_memory(dir / "m.vmdb", 5);
  const std::string not_regular = "memory '" + fifo.string() + "' is not a regular file";
  CHECK(within_seconds(fifo, [&] { return error_of([&] { (void)replacing(fifo, 5); }); }) == not_regular);
  CHECK(within_seconds(fifo, [&] {
          return error_of([&] {
            (void)vmap::AnyMemory::copy_into_store(vmap::AnyMemory::open(dir / "m.vmdb"), fifo, {.replace = true});
          });
        }) == not_regular);
  CHECK(within_seconds(fifo, [&] {
          return error_of([&] { (void)vmap::AnyMemory::create(fifo, vmap::PolicyStack{}); });
        }) == "'" + fifo.string() + "' exists and is not a vmap memory; refusing to replace it");
  CHECK(within_seconds(fifo, [&] { return error_of([&] { (void)vmap::AnyMemory::open(fifo); }); })
            .find("is not a regular file") != std::string::npos);
  CHECK(within_seconds(fifo, [&] {
          return error_of([&] { (void)vmap::MemoryStore::open(fifo, vmap::sqlite::Access::write); });
        }).find("is not a regular file") != std::string::npos);
  CHECK(within_seconds(fifo, [&] {
          return std::string(vmap::memory_kind(fifo) == vmap::MemoryKind::other ? "other" : "a memory");
        }) == "other");
  CHECK(fs::is_fifo(fifo));
  CHECK(files_in(dir) == std::set<std::string>{"f.vmdb", "m.vmdb"});
}

TEST_CASE("replace: a new memory made whole at close appears only then, and never over a file made meanwhile") {
  const fs::path dir = folder("whole");
  make_memory(dir / "a.vmdb", 8);
  const fs::path out = dir / "c.vmdb";
  {
    auto mem = vmap::AnyMemory::copy_into_store(vmap::AnyMemory::open(dir / "a.vmdb"), out, {.whole_at_close = true});
    CHECK(!fs::exists(out));
    mem.close();
  }
  CHECK(frames_of(out) == 8);
  CHECK(files_in(dir) == std::set<std::string>{"a.vmdb", "c.vmdb"});

  const fs::path late = dir / "d.vmdb";
  auto mem = vmap::AnyMemory::copy_into_store(vmap::AnyMemory::open(dir / "a.vmdb"), late, {.whole_at_close = true});
  {
    std::ofstream(late) << "made meanwhile";
  }
  CHECK(error_of([&] { mem.close(); }) ==
        "memory '" + late.string() + "' was created by another program while this one was written; refusing to "
        "replace it");
  CHECK(bytes_of(late) == "made meanwhile");
  CHECK(files_in(dir) == std::set<std::string>{"a.vmdb", "c.vmdb", "d.vmdb"});
}

TEST_CASE("replace: an SQLite database that is no memory is never replaced, with or without replace") {
  const fs::path dir = folder("sqlite");
  const fs::path user = dir / "p.db";
  vmap::test::raw_sql(user, "CREATE TABLE t(x); INSERT INTO t VALUES('mine')");
  // A rosbag2 file being recorded: SQLite in WAL mode, its recorder's connection open and
  // its log not yet moved into it (read through SQLite to learn what it is).
  const fs::path bag = dir / "bag.db3";
  sqlite3* recorder = nullptr;
  REQUIRE(sqlite3_open(bag.c_str(), &recorder) == SQLITE_OK);
  REQUIRE(sqlite3_exec(recorder, "PRAGMA journal_mode=WAL; PRAGMA wal_autocheckpoint=0; CREATE TABLE messages(data BLOB);"
                                 "INSERT INTO messages VALUES(x'00')",
                       nullptr, nullptr, nullptr) == SQLITE_OK);
  REQUIRE(fs::file_size(bag.string() + "-wal") > 0);
  const fs::path empty = dir / "empty.vmdb";
  { std::ofstream(empty).close(); }
  make_memory(dir / "m.vmdb", 5);
  for (const fs::path& other : {user, bag, empty}) {
    CAPTURE(other);
    const std::string before = bytes_of(other);
    CHECK(vmap::memory_kind(other) == vmap::MemoryKind::other);
    CHECK(error_of([&] { (void)replacing(other, 5); }) ==
          "'" + other.string() + "' is not a vmap memory (neither a memory store nor a .vmem memory file); refusing to "
          "replace it");
    CHECK(error_of([&] {
            (void)vmap::AnyMemory::copy_into_store(vmap::AnyMemory::open(dir / "m.vmdb"), other, {.replace = true});
          }).find("is not a vmap memory") != std::string::npos);
    // Without replace the refusal does not call it a memory.
    const std::string refused = error_of([&] { (void)vmap::AnyMemory::create(other, vmap::PolicyStack{}); });
    CHECK(refused == "'" + other.string() + "' exists and is not a vmap memory; refusing to replace it");
    CHECK(error_of([&] { (void)vmap::AnyMemory::open(other); }).find("is not a vmap memory") != std::string::npos);
    CHECK(bytes_of(other) == before);
  }
  CHECK(vmap::test::sql_integer(user, "SELECT count(*) FROM t WHERE x = 'mine'") == 1);
  sqlite3_close(recorder);
  CHECK(vmap::test::sql_integer(bag, "SELECT count(*) FROM messages") == 1);
  // A memory without replace is refused as one.
  CHECK(error_of([&] { (void)vmap::AnyMemory::create(dir / "m.vmdb", vmap::PolicyStack{}); }) ==
        "memory '" + (dir / "m.vmdb").string() + "' exists already");
}

TEST_CASE("replace: a store is known by its application id, also while its first transaction is in its log") {
  const fs::path dir = folder("kind");
  // A store made now holds its id in the file from the moment it is there.
  auto mem = vmap::AnyMemory::create(dir / "new.vmdb", vmap::PolicyStack{}, options());
  const auto head = vmap::detail::read_head(dir / "new.vmdb", 100);
  REQUIRE(head);
  REQUIRE(head->size() == 100);
  CHECK(head->substr(68, 4) == "VMAP");
  CHECK(vmap::memory_kind(dir / "new.vmdb") == vmap::MemoryKind::store);
  mem.close();
  // A store an older vmap made in place, its writer still running: the id is in its log.
  const fs::path old = dir / "old.vmdb";
  sqlite3* db = nullptr;
  REQUIRE(sqlite3_open(old.c_str(), &db) == SQLITE_OK);
  REQUIRE(sqlite3_exec(db, "PRAGMA journal_mode=WAL; PRAGMA wal_autocheckpoint=0; PRAGMA application_id = 1447903568;"
                           "CREATE TABLE meta(name TEXT PRIMARY KEY, value BLOB, crc INTEGER)",
                       nullptr, nullptr, nullptr) == SQLITE_OK);
  REQUIRE(vmap::detail::read_head(old, 100)->substr(68, 4) == std::string(4, '\0'));
  CHECK(vmap::memory_kind(old) == vmap::MemoryKind::store);
  sqlite3_close(db);
  CHECK(vmap::memory_kind(old) == vmap::MemoryKind::store);
  CHECK(vmap::memory_kind(dir / "none.vmdb") == vmap::MemoryKind::other);
}

TEST_CASE("replace: the files of new stores that dead runs left are removed by the next one; a live run's are kept") {
  const fs::path dir = folder("leftovers");
  const fs::path path = dir / "m.vmdb";
  make_memory(path, 8);
  // A process that has ended (its PID is free until reused), and one that runs (ours' parent).
  const pid_t child = ::fork();
  REQUIRE(child >= 0);
  if (child == 0) ::_exit(0);
  REQUIRE(::waitpid(child, nullptr, 0) == child);
  const std::string dead = std::to_string(child), alive = std::to_string(::getppid());
  const auto touch = [&](const std::string& name) { std::ofstream(dir / name) << "x"; };
  for (const std::string& name :
       {".m.vmdb.vmap-new-" + dead + "-0", ".m.vmdb.vmap-new-" + dead + "-0-wal", ".m.vmdb.vmap-new-" + dead + "-0-shm",
        ".m.vmdb.vmap-new-" + dead + "-7-journal",  // a log whose store is gone
        ".m.vmdb.vmap-new-" + alive + "-0",         // a run still going
        ".m.vmdb.vmap-new-" + dead + "-1",          // one being written (locked) by another namespace's run
        ".m.vmdb.vmap-new-" + dead + "-x",          // not a name vmap makes
        ".m.vmdb.vmap-new-" + dead + "-2.txt",      // nor this
        ".n.vmdb.vmap-new-" + dead + "-0"})         // another memory's
    touch(name);
  vmap::sqlite::WriterLock held(dir / (".m.vmdb.vmap-new-" + dead + "-1"), false, "a new store");
  replacing(path, 12).close();
  CHECK(files_in(dir) == std::set<std::string>{"m.vmdb", ".m.vmdb.vmap-new-" + alive + "-0",
                                               ".m.vmdb.vmap-new-" + dead + "-1", ".m.vmdb.vmap-new-" + dead + "-x",
                                               ".m.vmdb.vmap-new-" + dead + "-2.txt", ".n.vmdb.vmap-new-" + dead + "-0"});
  CHECK(frames_of(path) == 12);
  // A new store made there removes its own name's leftovers too.
  auto n = vmap::AnyMemory::create(dir / "n.vmdb", vmap::PolicyStack{}, options());
  n.close();
  CHECK(!fs::exists(dir / (".n.vmdb.vmap-new-" + dead + "-0")));
}
