#pragma once

// What a file given as a memory is (memory_kind), and the replacement of an existing
// memory by a new store without a moment where neither is there (MemoryReplacement):
//
//   vmap::MemoryReplacement r("run.vmdb");       // locked, checked, its log emptied
//   auto store = vmap::MemoryStore::create(r.path());   // built beside it
//   ... sync, checkpoint, close the store ...
//   r.commit();                                   // renamed over run.vmdb
//
// The replacement takes the file's writer lock (io/sqlite.hpp's WriterLock, the flock a
// writer holds) for as long as it runs, so a memory being written is never replaced and
// a writer or a second replacement is refused while it runs. Readers keep reading the
// old memory until commit() renames the new one over it. A replacement destroyed before
// commit() (a failed run, an exception) removes what it built; the old memory is never
// touched before the rename, so a program killed at any point leaves either the old
// memory or the new one (and possibly a file ".NAME.vmap-new-PID-N" beside it, which
// nothing reads, and which the next replacement or new store there removes once the
// process PID has ended: remove_dead_leftovers).
//
// A memory is recognised by its own records, never by being an SQLite file: a store by
// the application id its creation writes ("VMAP", memory/store.hpp), a .vmem file by its
// magic bytes. Any other file (a user's SQLite database, a rosbag2 .db3, a note, an empty
// file) is never replaced.
//
// A memory made where no file is can be built so too (MemoryReplacement(path, true)):
// it appears whole at commit(), which refuses a file made there meanwhile.
//
// The old store's write-ahead log is emptied into it first (while the lock keeps writers
// out, it stays empty): its -wal and -shm files are removed just before the rename, so
// the new store is never opened with the old store's log, and a crash between the two
// steps loses nothing of the old memory.

#include <vmap/core/error.hpp>
#include <vmap/io/atomic_file.hpp>
#include <vmap/io/database_files.hpp>
#include <vmap/io/postgres.hpp>
#include <vmap/io/sqlite.hpp>
#include <vmap/memory/detail/format.hpp>
#include <vmap/memory/types.hpp>

#include <fcntl.h>
#include <signal.h>
#include <stdio.h>
#include <sys/file.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <limits>
#include <map>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

namespace vmap {

/// The kind of memory `file` holds, by its own records: a store by the application id
/// in its header ("VMAP"), a .vmem file by its magic bytes; anything else (another SQLite
/// database, an empty file) is `other`. A path that is not a regular file (a folder, a
/// FIFO, a device or a socket; a symbolic link is followed) is `other` without being
/// opened: opening a FIFO would wait for a writer. A PostgreSQL URI (a fleet's memory) is
/// a store, without connecting. The file is read through io/database_files.hpp, so a
/// look at a store this process has open drops none of its connections' locks.
[[nodiscard]] inline MemoryKind memory_kind(const std::filesystem::path& file) {
  if (pg::is_uri(file.native())) return MemoryKind::store;
  const auto head = detail::read_head(file, 100);
  if (!head) return MemoryKind::other;
  const std::string_view h = *head;
  if (h.starts_with(std::string_view(detail::memory_magic, 8))) return MemoryKind::file;
  if (h.size() < 100 || !h.starts_with(std::string_view("SQLite format 3\0", 16))) return MemoryKind::other;
  // The header's application id (bytes 68..71, big-endian).
  std::uint32_t id = 0;
  for (std::size_t i = 68; i < 72; ++i) id = (id << 8) | static_cast<unsigned char>(h[i]);
  if (id == detail::memory_application_id) return MemoryKind::store;
  if (id != 0) return MemoryKind::other;
  // A store made by an older vmap in place holds its id in its first transaction, which
  // stays in the write-ahead log until a checkpoint (while its writer runs, or after that
  // writer was killed): read it through SQLite there. A file that SQLite cannot read so
  // is not known to be a memory.
  std::error_code ec;
  const auto log = std::filesystem::file_size(file.string() + "-wal", ec);
  if (ec || log == 0) return MemoryKind::other;
  try {
    sqlite::Database db(file, sqlite::Access::read, "file '" + file.string() + "'");
    auto q = db.prepare("PRAGMA application_id", "read its application id");
    if (q.step() && q.integer(0) == detail::memory_application_id) return MemoryKind::store;
  } catch (const Error&) {
  }
  return MemoryKind::other;
}

namespace detail {

/// The pattern of the names new stores are built under beside `target`
/// (".NAME.vmap-new-"), before the process id and a counter.
[[nodiscard]] inline std::string new_memory_prefix(const std::filesystem::path& target) {
  return "." + target.filename().string() + ".vmap-new-";
}

/// A unique name beside `target` for a new store (".NAME.vmap-new-PID-N"); the store's
/// creation (O_EXCL) makes sure it is no other program's file.
[[nodiscard]] inline std::filesystem::path new_memory_path(const std::filesystem::path& target) {
  static std::atomic<std::uint64_t> counter{0};
  const std::filesystem::path dir = folder_of(target);
  const std::string prefix = new_memory_prefix(target) + std::to_string(::getpid()) + "-";
  std::error_code ec;
  for (;;) {
    std::filesystem::path p = dir / (prefix + std::to_string(counter++));
    if (!std::filesystem::exists(std::filesystem::symlink_status(p, ec))) return p;
  }
}

/// Removes the files new stores of `target` left beside it (".NAME.vmap-new-PID-N" and
/// their -wal, -shm and -journal files) when process PID has ended: a run killed before
/// it renamed its new store into place. Only such names are touched; a file of this
/// process, of a process still running (or of another user's, which kill(PID, 0) cannot
/// tell apart), or one whose store another program has open to write (its flock; a
/// process of another PID namespace) is kept. Returns the names removed.
inline std::vector<std::string> remove_dead_leftovers(const std::filesystem::path& target) noexcept {
  std::vector<std::string> removed;
  try {
    const std::filesystem::path dir = folder_of(target);
    const std::string prefix = new_memory_prefix(target);
    // Each new store's files ("PID-N" and its suffixes), by store.
    std::map<std::string, std::vector<std::string>> stores;
    std::error_code ec;
    for (const auto& e : std::filesystem::directory_iterator(dir, ec)) {
      const std::string name = e.path().filename().string();
      if (!name.starts_with(prefix)) continue;
      std::string_view rest = std::string_view(name).substr(prefix.size());
      for (const std::string_view suffix : {"-wal", "-shm", "-journal"})
        if (rest.ends_with(suffix)) {
          rest.remove_suffix(suffix.size());
          break;
        }
      const std::size_t dash = rest.find('-');
      const auto digits = [](std::string_view d) {
        return !d.empty() && d.size() <= 18 && d.find_first_not_of("0123456789") == std::string_view::npos;
      };
      if (dash == std::string_view::npos || !digits(rest.substr(0, dash)) || !digits(rest.substr(dash + 1))) continue;
      stores[std::string(rest)].push_back(name);
    }
    for (auto& [key, names] : stores) {
      const long long pid = std::stoll(key.substr(0, key.find('-')));
      if (pid <= 0 || pid == ::getpid() || pid > std::numeric_limits<pid_t>::max()) continue;
      if (::kill(static_cast<pid_t>(pid), 0) == 0 || errno != ESRCH) continue;  // running, or not ours to ask
      // A store being made is flocked by its maker (also one of another PID namespace):
      // kept whole. Its log files go with it; those whose store is gone, alone.
      const std::filesystem::path store = dir / (prefix + key);
      FileDescriptor fd;
      if (std::filesystem::exists(std::filesystem::symlink_status(store, ec))) {
        fd = FileDescriptor(::open(store.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC | O_NOFOLLOW));
        struct stat st {};
        if (!fd.valid() || ::fstat(fd.get(), &st) != 0 || !S_ISREG(st.st_mode) || ::flock(fd.get(), LOCK_EX | LOCK_NB) != 0)
          continue;
      }
      std::sort(names.begin(), names.end(), [](const std::string& a, const std::string& b) { return a.size() > b.size(); });
      for (const std::string& name : names)  // the log files before the store
        if (::unlink((dir / name).c_str()) == 0) removed.push_back(name);
      if (fd.valid()) (void)::flock(fd.get(), LOCK_UN);
    }
  } catch (...) {
    // A folder that cannot be listed: nothing removed.
  }
  return removed;
}

/// Renames the finished file `from` to `to` only where no file is (never over one another
/// program made meanwhile), flushed to disk first, the folder after; removes the leftovers
/// of dead runs beside `to` (remove_dead_leftovers). `who` names `to` in errors.
inline void publish_new_file(const std::filesystem::path& from, const std::filesystem::path& to, const std::string& who) {
  if (const int err = fsync_file(from); err != 0)
    fail(ErrorKind::io, who + ": cannot flush '" + from.string() + "': " + std::strerror(err));
  int err = ::renameat2(AT_FDCWD, from.c_str(), AT_FDCWD, to.c_str(), RENAME_NOREPLACE) == 0 ? 0 : errno;
  if (err == EINVAL) {
    // A file system without renameat2's flags: a hard link is refused over a file too.
    err = ::link(from.c_str(), to.c_str()) == 0 ? 0 : errno;
    if (err == 0) ::unlink(from.c_str());
  }
  if (err == EEXIST) fail(who + " was created by another program while this one was written; refusing to replace it");
  if (err != 0) fail(ErrorKind::io, who + ": cannot rename '" + from.string() + "' to it: " + std::strerror(err));
  sync_folder(folder_of(to));
  (void)remove_dead_leftovers(to);
}

}  // namespace detail

/// The replacement of the memory at a path by a new memory store (see the top of this
/// file); commit() publishes the new store, destruction without it discards it. Not
/// movable (hold it in a unique_ptr).
class MemoryReplacement {
 public:
  /// Prepares replacing the memory at `target` (a symbolic link is followed: the file it
  /// names is replaced). An Error names the file when another program writes it or
  /// replaces it, when it is not a regular file, when it is not a memory (a store or a
  /// .vmem file; nothing else is ever replaced), or when its log cannot be emptied.
  ///
  /// With `fresh`, `target` must be a path with no file (an Error otherwise): the new
  /// store appears there at commit() only, complete, and commit() refuses a file another
  /// program made there meanwhile (there is nothing to lock before then).
  explicit MemoryReplacement(const std::filesystem::path& target, bool fresh = false) {
    std::error_code ec;
    const std::string who = "memory '" + target.string() + "'";
    if (fresh) {
      if (std::filesystem::exists(std::filesystem::symlink_status(target, ec))) detail::fail(who + " exists already");
      target_ = target;
      fresh_ = true;
      path_ = detail::new_memory_path(target_);
      return;
    }
    target_ = std::filesystem::is_symlink(std::filesystem::symlink_status(target, ec))
                  ? std::filesystem::canonical(target, ec)
                  : target;
    if (ec || !std::filesystem::exists(target_, ec)) detail::fail(ErrorKind::not_found, who + " does not exist");
    if (!std::filesystem::is_regular_file(target_, ec)) detail::fail(who + " is not a regular file");
    lock_ = sqlite::WriterLock(target_, false, who);
    const MemoryKind kind = memory_kind(target_);
    if (kind == MemoryKind::other)
      detail::fail("'" + target.string() + "' is not a vmap memory (neither a memory store nor a .vmem memory file); "
                   "refusing to replace it");
    if (kind == MemoryKind::store) sqlite::checkpoint_locked(target_, who);
    // The log beside a .vmem file is no log of it, and a store's was emptied just now:
    // one with frames in it would be applied to the new store.
    if (std::filesystem::file_size(target_.string() + "-wal", ec) > 0 && !ec)
      detail::fail(who + ": '" + target_.string() + "-wal' is not empty (a write-ahead log of another program); "
                   "refusing to replace the memory under it");
    path_ = detail::new_memory_path(target_);
  }

  MemoryReplacement(MemoryReplacement&&) = delete;
  MemoryReplacement& operator=(MemoryReplacement&&) = delete;
  MemoryReplacement(const MemoryReplacement&) = delete;
  MemoryReplacement& operator=(const MemoryReplacement&) = delete;
  /// Without commit(): removes the new store (and its log files), releases the lock.
  ~MemoryReplacement() { discard(); }

  /// The file replaced.
  [[nodiscard]] const std::filesystem::path& target() const noexcept { return target_; }
  /// Where the new store is built (create it there; a unique name in the target's folder).
  [[nodiscard]] const std::filesystem::path& path() const noexcept { return path_; }

  /// Renames the new store over the target: call it once the new store is closed (its
  /// log moved into it). Flushes it to disk, removes the target's log files (empty since
  /// the constructor), renames, flushes the folder and releases the lock. An Error leaves
  /// the target as it was (and the new store is removed by the destructor).
  void commit() {
    const std::string who = "memory '" + target_.string() + "'";
    if (path_.empty()) detail::fail(who + ": the replacement was committed or discarded already");
    std::error_code ec;
    if (fresh_) {
      detail::publish_new_file(path_, target_, who);
    } else {
      if (const int err = detail::fsync_file(path_); err != 0)
        detail::fail(ErrorKind::io, who + ": cannot flush its replacement '" + path_.string() + "': " + std::strerror(err));
      for (const char* suffix : {"-wal", "-shm"}) {
        std::filesystem::remove(target_.string() + suffix, ec);
        if (ec) detail::fail(ErrorKind::io, who + ": cannot remove its '" + suffix + "' file: " + ec.message());
      }
      std::filesystem::rename(path_, target_, ec);
      if (ec) detail::fail(ErrorKind::io, who + ": cannot rename its replacement '" + path_.string() + "' over it: " + ec.message());
      detail::sync_folder(detail::folder_of(target_));
      (void)detail::remove_dead_leftovers(target_);
    }
    // A connection still open on the new store (a reader of released features) may have
    // left its empty log files under the temporary name.
    for (const char* suffix : {"-wal", "-shm"}) std::filesystem::remove(path_.string() + suffix, ec);
    path_.clear();
    lock_.release();
  }

 private:
  void discard() noexcept {
    if (!path_.empty()) {
      std::error_code ec;
      for (const char* suffix : {"", "-wal", "-shm"}) std::filesystem::remove(path_.string() + suffix, ec);
      path_.clear();
    }
    lock_.release();
  }

  std::filesystem::path target_, path_;
  bool fresh_ = false;  ///< no file was at the target
  sqlite::WriterLock lock_;
};

}  // namespace vmap
