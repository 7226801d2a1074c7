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
// nothing reads).
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
#include <vmap/io/postgres.hpp>
#include <vmap/io/sqlite.hpp>
#include <vmap/memory/detail/format.hpp>
#include <vmap/memory/types.hpp>

#include <fcntl.h>
#include <stdio.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>
#include <system_error>

namespace vmap {

/// The kind of memory `file` holds. A path that is not a regular file (a folder, a FIFO,
/// a device or a socket; a symbolic link is followed) is `other` without being opened:
/// opening a FIFO would wait for a writer. A PostgreSQL URI (a fleet's memory) is a
/// store, without connecting.
[[nodiscard]] inline MemoryKind memory_kind(const std::filesystem::path& file) {
  if (pg::is_uri(file.native())) return MemoryKind::store;
  std::error_code ec;
  if (!std::filesystem::is_regular_file(file, ec)) return MemoryKind::other;
  if (std::filesystem::file_size(file, ec) == 0 && !ec) return MemoryKind::store;
  std::ifstream f(file, std::ios::binary);
  char head[16] = {};
  f.read(head, sizeof head);
  const std::string_view h(head, static_cast<std::size_t>(std::max<std::streamsize>(f.gcount(), 0)));
  if (h == std::string_view("SQLite format 3\0", 16)) return MemoryKind::store;
  if (h.size() >= 8 && h.substr(0, 8) == std::string_view(detail::memory_magic, 8)) return MemoryKind::file;
  return MemoryKind::other;
}

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
      path_ = unique_path();
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
    path_ = unique_path();
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
    const int fd = ::open(path_.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0 || ::fsync(fd) != 0) {
      const int err = errno;
      if (fd >= 0) ::close(fd);
      detail::fail(who + ": cannot flush its replacement '" + path_.string() + "': " + std::strerror(err));
    }
    ::close(fd);
    std::error_code ec;
    if (fresh_) {
      // Renamed only where no file is: never over one another program made meanwhile.
      int err = ::renameat2(AT_FDCWD, path_.c_str(), AT_FDCWD, target_.c_str(), RENAME_NOREPLACE) == 0 ? 0 : errno;
      if (err == EINVAL) {
        // A file system without renameat2's flags: a hard link is refused over a file too.
        err = ::link(path_.c_str(), target_.c_str()) == 0 ? 0 : errno;
        if (err == 0) ::unlink(path_.c_str());
      }
      if (err != 0) {
        if (err == EEXIST)
          detail::fail(who + " was created by another program while this one was written; refusing to replace it");
        detail::fail(who + ": cannot rename '" + path_.string() + "' to it: " + std::strerror(err));
      }
    } else {
      for (const char* suffix : {"-wal", "-shm"}) {
        std::filesystem::remove(target_.string() + suffix, ec);
        if (ec) detail::fail(who + ": cannot remove its '" + suffix + "' file: " + ec.message());
      }
      std::filesystem::rename(path_, target_, ec);
      if (ec) detail::fail(who + ": cannot rename its replacement '" + path_.string() + "' over it: " + ec.message());
    }
    // A connection still open on the new store (a reader of released features) may have
    // left its empty log files under the temporary name.
    for (const char* suffix : {"-wal", "-shm"}) std::filesystem::remove(path_.string() + suffix, ec);
    detail::sync_folder(detail::folder_of(target_));
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

  /// A unique name beside the target for the new store (".NAME.vmap-new-PID-N"); the
  /// store's creation (O_EXCL) makes sure it is no other program's file.
  [[nodiscard]] std::filesystem::path unique_path() const {
    static std::atomic<std::uint64_t> counter{0};
    const std::filesystem::path dir = detail::folder_of(target_);
    const std::string prefix = "." + target_.filename().string() + ".vmap-new-" + std::to_string(::getpid()) + "-";
    std::error_code ec;
    for (;;) {
      std::filesystem::path p = dir / (prefix + std::to_string(counter++));
      if (!std::filesystem::exists(std::filesystem::symlink_status(p, ec))) return p;
    }
  }

  std::filesystem::path target_, path_;
  bool fresh_ = false;  ///< no file was at the target
  sqlite::WriterLock lock_;
};

}  // namespace vmap
