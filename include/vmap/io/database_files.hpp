#pragma once

// Descriptors of files that this process's SQLite connections may have open, opened and
// closed without dropping SQLite's locks.
//
// POSIX record locks (fcntl), which SQLite takes on a database file, belong to a process
// and a file: closing *any* descriptor of the file drops every one of them, those SQLite
// holds through its own descriptors included. A writer's flock (io/sqlite.hpp's
// WriterLock), a look at a file's first bytes (memory/replace.hpp's memory_kind) or the
// flush of a finished store would thus, by their close(), silently release the locks of
// a connection this process still has open on the file. In WAL mode every connection
// holds a shared lock on the database file for as long as it is open; without it,
// another program that closes its own connection takes the file for itself, checkpoints
// and deletes the write-ahead log under this process's writer, whose next commits then
// go to a deleted file.
//
// So every connection of vmap's SQLite layer (io/sqlite.hpp) registers the file it opens
// (by device and inode, before opening it: opened_connection()/closed_connection()), and
// every descriptor vmap opens itself on a file that may be a database is closed through
// close_descriptor(): while a registered connection has the file open, the descriptor is
// kept open (a caller releases its flock first) and is closed when the last such
// connection closes. Connections other code of the process opens (another SQLite user)
// are not known here. The registry is shared by the whole process (one per copy of vmap
// linked into it) and is safe to use from any thread.

#include <vmap/core/error.hpp>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstddef>
#include <filesystem>
#include <map>
#include <mutex>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace vmap::detail {

/// A file's identity (its device and inode): what POSIX record locks belong to.
struct FileId {
  dev_t device = 0;
  ino_t inode = 0;
  friend bool operator==(const FileId&, const FileId&) = default;
  friend bool operator<(const FileId& a, const FileId& b) noexcept {
    return a.device != b.device ? a.device < b.device : a.inode < b.inode;
  }
};

/// The identity of the file `path` names (symbolic links followed), if it exists.
[[nodiscard]] inline std::optional<FileId> file_id(const std::filesystem::path& path) noexcept {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return std::nullopt;
  return FileId{st.st_dev, st.st_ino};
}

/// The identity of the file open on descriptor `fd`.
[[nodiscard]] inline std::optional<FileId> file_id(int fd) noexcept {
  struct stat st {};
  if (::fstat(fd, &st) != 0) return std::nullopt;
  return FileId{st.st_dev, st.st_ino};
}

/// The files this process's SQLite connections have open, and the descriptors whose
/// close waits for them (see the top of this file).
class OpenDatabases {
 public:
  /// The process's registry (never destroyed: connections may close during exit).
  static OpenDatabases& instance() {
    static auto* registry = new OpenDatabases;
    return *registry;
  }

  /// A connection to file `id` is about to be opened (call before opening it).
  void opened_connection(FileId id) {
    const std::lock_guard lock(mutex_);
    ++files_[id].connections;
  }

  /// A connection to file `id` closed: when it was the last, the descriptors kept for it
  /// are closed.
  void closed_connection(FileId id) noexcept {
    std::vector<int> kept;
    {
      const std::lock_guard lock(mutex_);
      const auto it = files_.find(id);
      if (it == files_.end()) return;
      if (--it->second.connections > 0) return;
      kept = std::move(it->second.kept);
      files_.erase(it);
    }
    for (const int fd : kept) ::close(fd);
  }

  /// Closes `fd` now, or when the last connection to its file closes.
  void close(int fd) noexcept {
    if (fd < 0) return;
    if (const auto id = file_id(fd)) {
      const std::lock_guard lock(mutex_);
      if (const auto it = files_.find(*id); it != files_.end()) {
        it->second.kept.push_back(fd);
        return;
      }
    }
    ::close(fd);
  }

  /// Descriptors kept open for the connections to file `id` (tests).
  [[nodiscard]] std::size_t kept(FileId id) {
    const std::lock_guard lock(mutex_);
    const auto it = files_.find(id);
    return it == files_.end() ? 0 : it->second.kept.size();
  }

 private:
  OpenDatabases() = default;

  struct Entry {
    std::size_t connections = 0;
    std::vector<int> kept;
  };
  std::mutex mutex_;
  std::map<FileId, Entry> files_;
};

/// Closes a descriptor of a file that may be a database (see the top of this file).
inline void close_descriptor(int fd) noexcept { OpenDatabases::instance().close(fd); }

/// A descriptor closed by close_descriptor() when it goes.
class FileDescriptor {
 public:
  FileDescriptor() = default;
  explicit FileDescriptor(int fd) noexcept : fd_(fd) {}
  FileDescriptor(FileDescriptor&& o) noexcept : fd_(std::exchange(o.fd_, -1)) {}
  FileDescriptor& operator=(FileDescriptor&& o) noexcept {
    if (this != &o) {
      reset();
      fd_ = std::exchange(o.fd_, -1);
    }
    return *this;
  }
  FileDescriptor(const FileDescriptor&) = delete;
  FileDescriptor& operator=(const FileDescriptor&) = delete;
  ~FileDescriptor() { reset(); }

  [[nodiscard]] int get() const noexcept { return fd_; }
  [[nodiscard]] bool valid() const noexcept { return fd_ >= 0; }
  void reset() noexcept { close_descriptor(std::exchange(fd_, -1)); }

 private:
  int fd_ = -1;
};

/// The first `n` bytes of the regular file `path` (fewer when it is shorter); nothing when
/// it is not a regular file (a FIFO or a device is never opened) or cannot be read.
[[nodiscard]] inline std::optional<std::string> read_head(const std::filesystem::path& path, std::size_t n) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0 || !S_ISREG(st.st_mode)) return std::nullopt;
  const FileDescriptor fd(::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC));
  if (!fd.valid() || ::fstat(fd.get(), &st) != 0 || !S_ISREG(st.st_mode)) return std::nullopt;
  std::string out(n, '\0');
  std::size_t done = 0;
  while (done < n) {
    const ssize_t got = ::pread(fd.get(), out.data() + done, n - done, static_cast<off_t>(done));
    if (got < 0 && errno == EINTR) continue;
    if (got < 0) return std::nullopt;
    if (got == 0) break;
    done += static_cast<std::size_t>(got);
  }
  out.resize(done);
  return out;
}

/// Flushes the file `path` to disk; 0, or the errno of what failed.
[[nodiscard]] inline int fsync_file(const std::filesystem::path& path) noexcept {
  const FileDescriptor fd(::open(path.c_str(), O_RDONLY | O_CLOEXEC));
  if (!fd.valid()) return errno;
  return ::fsync(fd.get()) == 0 ? 0 : errno;
}

}  // namespace vmap::detail
