// The POSIX locks SQLite holds on a memory store are never dropped by a descriptor vmap
// closes (io/database_files.hpp): closing any descriptor of a file drops every POSIX lock
// the process holds on it, SQLite's included. A connection in WAL mode holds a shared
// lock on the database file for as long as it is open (the lock by which the last
// connection to close knows it may delete the write-ahead log); these tests ask another
// process (a child, fcntl F_GETLK) whether this one still holds it after each code path
// that opens and closes a descriptor of the file: a writer's flock released while a
// reader stays open, a writer refused, a look at the file's kind, a replacement's flush.
#include "support/errors.hpp"
#include "support/sample_memory.hpp"
#include "support/shared_data.hpp"

#include <vmap/io/database_files.hpp>
#include <vmap/io/sqlite.hpp>
#include <vmap/memory/replace.hpp>
#include <vmap/memory/store.hpp>
#include <vmap/runtime/memory.hpp>

#include <doctest/doctest.h>

#include <fcntl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>
#include <string>

namespace {

namespace fs = std::filesystem;
using vmap::test::error_seen;
using vmap::test::sample_frames;

/// Whether this process holds SQLite's shared lock on `db` (a read lock on the bytes
/// SQLite's unix VFS locks for SHARED), as another process sees it.
bool shared_lock_held(const fs::path& db) {
  const pid_t parent = ::getpid();
  const pid_t child = ::fork();
  REQUIRE(child >= 0);
  if (child == 0) {
    // Only async-signal-safe calls here.
    const int fd = ::open(db.c_str(), O_RDWR);
    struct flock probe {};
    probe.l_type = F_WRLCK;
    probe.l_whence = SEEK_SET;
    probe.l_start = 0x40000000 + 2;  // SQLite's SHARED_FIRST (PENDING_BYTE + 2)
    probe.l_len = 510;               // SHARED_SIZE
    if (fd < 0 || ::fcntl(fd, F_GETLK, &probe) != 0) ::_exit(2);
    ::_exit(probe.l_type == F_RDLCK && probe.l_pid == parent ? 1 : 0);
  }
  int status = 0;
  REQUIRE(::waitpid(child, &status, 0) == child);
  REQUIRE(WIFEXITED(status));
  REQUIRE(WEXITSTATUS(status) != 2);
  return WEXITSTATUS(status) == 1;
}

/// A store at `path` of the first `frames` sample frames, closed.
void make_store(const fs::path& path, std::size_t frames) {
  auto mem = vmap::AnyMemory::create(path, vmap::PolicyStack{}, vmap::test::small_memory_options());
  for (std::size_t i = 0; i < frames; ++i) (void)mem.push(sample_frames()[i]);
  mem.close();
}

/// A reader connection that has read the file (so it holds its shared lock).
vmap::sqlite::Database reader_of(const fs::path& path) {
  vmap::sqlite::Database reader(path, vmap::sqlite::Access::read, "reader");
  auto q = reader.prepare("SELECT count(*) FROM key_images", "count");
  REQUIRE(q.step());
  return reader;
}

}  // namespace

TEST_CASE("locks: a writer refused, a look at the file and a writer closed keep a reader's lock") {
  const fs::path path = vmap::test::scratch_dir("locks_refused") / "m.vmdb";
  make_store(path, 12);
  auto reader = reader_of(path);
  REQUIRE(shared_lock_held(path));

  // A process that holds a reader tries to write while another writer has the file.
  {
    auto writer = vmap::MemoryStore::open(path, vmap::sqlite::Access::write);
    CHECK(error_seen([&] { (void)vmap::MemoryStore::open(path, vmap::sqlite::Access::write); }).kind ==
          vmap::ErrorKind::busy);
    CHECK(shared_lock_held(path));
  }
  // The writer closed (its flock released): the reader still holds its lock.
  CHECK(shared_lock_held(path));
  // What kind of file it is, asked while the reader is open.
  CHECK(vmap::memory_kind(path) == vmap::MemoryKind::store);
  CHECK(shared_lock_held(path));
  CHECK(vmap::detail::fsync_file(path) == 0);
  CHECK(shared_lock_held(path));

  // The descriptors kept for the reader are closed with it; the file is lockable again.
  const auto id = vmap::detail::file_id(path);
  REQUIRE(id);
  CHECK(vmap::detail::OpenDatabases::instance().kept(*id) > 0);
  reader = vmap::sqlite::Database();
  CHECK(vmap::detail::OpenDatabases::instance().kept(*id) == 0);
  CHECK(!shared_lock_held(path));
  auto writer = vmap::MemoryStore::open(path, vmap::sqlite::Access::write);
  CHECK(error_seen([&] { (void)vmap::MemoryStore::open(path, vmap::sqlite::Access::write); }).kind ==
        vmap::ErrorKind::busy);
}

TEST_CASE("locks: closing a bounded memory keeps the lock of its reader of released features") {
  const fs::path path = vmap::test::scratch_dir("locks_bounded") / "m.vmdb";
  auto mem = vmap::AnyMemory::create(path, vmap::PolicyStack{}, vmap::test::small_memory_options(), {},
                                     {.working_memory = 2});
  for (std::size_t i = 0; i < 40; ++i) (void)mem.push(sample_frames()[i]);
  REQUIRE(mem.key_images() > 4);
  REQUIRE(!mem.holds_features(0));
  // The memory reads released key images through a connection of its own, which stays
  // open after close(): closing the writer (its flock's descriptor) must not drop it.
  mem.close();
  CHECK(mem.key_features(0).keypoints.size() > 0);
  CHECK(shared_lock_held(path));
  // Another writer may open the file now, and the reader still reads.
  {
    auto writer = vmap::AnyMemory::open(path, {.write = true, .new_session = true});
    CHECK(shared_lock_held(path));
  }
  CHECK(mem.key_features(1).keypoints.size() > 0);
}

TEST_CASE("locks: a replacement of a memory that this process reads keeps the reader's lock") {
  const fs::path dir = vmap::test::scratch_dir("locks_replace");
  const fs::path path = dir / "m.vmdb";
  make_store(path, 12);
  auto reader = reader_of(path);
  // The old file stays reachable by this name after the new one is renamed over it.
  fs::create_hard_link(path, dir / "old.vmdb");
  // The replacement locks the old file, looks at what it is and empties its log...
  auto mem = vmap::AnyMemory::create(path, vmap::PolicyStack{}, vmap::test::small_memory_options(), {}, {.replace = true});
  CHECK(shared_lock_held(path));
  for (std::size_t i = 0; i < 20; ++i) (void)mem.push(sample_frames()[i]);
  // ...and releases that lock once the new store is renamed over it.
  mem.close();
  CHECK(shared_lock_held(dir / "old.vmdb"));
  CHECK(vmap::AnyMemory::open(path).frames() == 20);
}
