#pragma once

// Reading input files and preparing output folders so that every failure is a
// vmap::Error naming the path and the reason (the operating system's words), never a
// std::filesystem_error, an iostream failure or a bad_alloc escaping from a loader.
//
// Policy for inputs that must be files (maps, GCS and tree files, ground truth, poses,
// detections, class names, list files, images, vocabularies, calibration files, bag
// files) and for those that may be folders too (frame sources, rosbag2 bags):
//   - a folder is refused ("is a folder, expected a file") where a file is expected;
//   - anything else that is not a regular file after following symbolic links (a device
//     such as /dev/zero, a FIFO, a socket) is refused before it is opened, so reading never
//     blocks on a FIFO and never runs until memory is exhausted (require_regular_file,
//     require_file_or_folder: every reader of an input calls one of them first);
//   - the size is checked against a limit before anything is allocated (each loader
//     documents its limit; `default_max_file_bytes` otherwise).
// Videos go through require_file_or_folder too (FrameSource::open); only camera indices,
// V4L devices, URLs and GStreamer pipelines, which the frame sources tell from their
// text, do not.

#include <vmap/core/error.hpp>
#include <vmap/io/database_files.hpp>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdint>
#include <filesystem>
#include <new>
#include <string>
#include <system_error>

namespace vmap {

/// Largest file `read_file` reads unless told otherwise (binary maps with key images
/// stay far below it; a larger file is almost certainly the wrong input).
inline constexpr std::uintmax_t default_max_file_bytes = std::uintmax_t{2} << 30;  // 2 GiB

/// Largest text input (ground truth, poses, detections, lists) read by default.
inline constexpr std::uintmax_t default_max_text_bytes = std::uintmax_t{256} << 20;  // 256 MiB

namespace detail {

/// The operating system's description of errno `e` ("Permission denied"), thread-safe.
inline std::string os_reason(int e) { return std::generic_category().message(e); }

/// stat() of an input `path` (symbolic links followed); a missing or unreachable path
/// is an Error naming `what` ("map file", "bag") and the path.
inline struct stat stat_input(const std::filesystem::path& path, const std::string& what) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) {
    const int e = errno;
    fail(e == ENOENT || e == ENOTDIR ? ErrorKind::not_found : ErrorKind::io,
         what + " '" + path.string() + "': " + (e == ENOENT ? std::string("does not exist") : os_reason(e)));
  }
  return st;
}

/// Fails unless `path` names a regular file (symbolic links followed); `what` names
/// the role of the input ("map file", "class names file").
inline struct stat require_regular_file(const std::filesystem::path& path, const std::string& what) {
  const struct stat st = stat_input(path, what);
  if (S_ISDIR(st.st_mode)) fail(what + " '" + path.string() + "' is a folder, expected a file");
  if (!S_ISREG(st.st_mode))
    fail(what + " '" + path.string() + "' is not a regular file (a device, FIFO or socket cannot be read as one)");
  return st;
}

/// Fails unless `path` names a regular file or a folder (symbolic links followed): the
/// check of an input that may be either (a frame source, a bag, a rosbag2 folder), made
/// before anything opens it, since opening a FIFO for reading waits for a writer and a
/// device never ends. `what` names the role of the input.
inline struct stat require_file_or_folder(const std::filesystem::path& path, const std::string& what) {
  const struct stat st = stat_input(path, what);
  if (!S_ISREG(st.st_mode) && !S_ISDIR(st.st_mode))
    fail(what + " '" + path.string() +
         "' is not a regular file or a folder (a device, FIFO or socket cannot be read as one)");
  return st;
}

/// Closes a file descriptor on scope exit, through io/database_files.hpp: the file read
/// may be a memory store this process has open, whose SQLite locks a plain close() would
/// drop.
struct FdGuard {
  int fd = -1;
  FdGuard() = default;
  explicit FdGuard(int f) : fd(f) {}
  FdGuard(const FdGuard&) = delete;
  FdGuard& operator=(const FdGuard&) = delete;
  ~FdGuard() { close_descriptor(fd); }
};

}  // namespace detail

/// Reads a whole regular file of at most `max_bytes` bytes. `what` names the input's
/// role in messages ("map file"). Errors (vmap::Error naming the path): missing,
/// unreadable, a folder, not a regular file, larger than the limit, a read error.
[[nodiscard]] inline std::string read_file(const std::filesystem::path& path,
                                           std::uintmax_t max_bytes = default_max_file_bytes,
                                           const std::string& what = "file") {
  const std::string name = what + " '" + path.string() + "'";
  const struct stat st = detail::require_regular_file(path, what);
  const auto size = static_cast<std::uintmax_t>(st.st_size);
  if (size > max_bytes)
    detail::fail(name + " is " + std::to_string(size) + " bytes, more than the limit of " + std::to_string(max_bytes));
  // O_NONBLOCK: should the path have been replaced by a FIFO since the stat, open()
  // must not wait for a writer; fstat below then refuses it.
  detail::FdGuard fd(::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK));
  if (fd.fd < 0) {
    const int e = errno;
    detail::fail(ErrorKind::io, "cannot open " + name + ": " + detail::os_reason(e));
  }
  struct stat now {};
  if (::fstat(fd.fd, &now) != 0 || !S_ISREG(now.st_mode)) detail::fail(name + " is not a regular file");
  std::string data;
  try {
    data.resize(static_cast<std::size_t>(size));
  } catch (const std::bad_alloc&) {
    detail::fail(name + ": not enough memory to read its " + std::to_string(size) + " bytes");
  }
  std::size_t got = 0;
  while (got < data.size()) {
    const ssize_t n = ::read(fd.fd, data.data() + got, data.size() - got);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) {
      const int e = errno;
      detail::fail(ErrorKind::io, "reading " + name + " failed: " + detail::os_reason(e));
    }
    if (n == 0) break;  // shrank while being read: keep what is there
    got += static_cast<std::size_t>(n);
  }
  data.resize(got);
  // A file that grew since the stat is read up to the limit only.
  char extra = 0;
  ssize_t more = 0;
  do more = ::read(fd.fd, &extra, 1);
  while (more < 0 && errno == EINTR);
  if (more > 0) detail::fail(name + " changed size while being read");
  return data;
}

/// `read_file` for text inputs: the limit is `default_max_text_bytes` unless given.
[[nodiscard]] inline std::string read_text_file(const std::filesystem::path& path, const std::string& what,
                                                std::uintmax_t max_bytes = default_max_text_bytes) {
  return read_file(path, max_bytes, what);
}

/// Creates `dir` and its missing parents. An existing folder is fine; an existing file
/// in the way, a missing permission or a read-only / virtual file system (/proc) is a
/// vmap::Error naming `dir` and the reason. `what` names the role ("output folder").
inline void create_directories(const std::filesystem::path& dir, const std::string& what = "output folder") {
  std::error_code ec;
  const auto st = std::filesystem::status(dir, ec);
  if (std::filesystem::is_directory(st)) {
    if (::access(dir.c_str(), W_OK | X_OK) != 0)
      detail::fail(ErrorKind::io, what + " '" + dir.string() + "' is not writable: " + detail::os_reason(errno));
    return;
  }
  if (std::filesystem::exists(st))
    detail::fail(what + " '" + dir.string() + "' exists and is not a folder");
  // Walk up to the first existing ancestor to report which one is in the way.
  for (auto p = dir.parent_path(); !p.empty() && p != p.root_path(); p = p.parent_path()) {
    const auto ps = std::filesystem::status(p, ec);
    if (!std::filesystem::exists(ps)) continue;
    if (!std::filesystem::is_directory(ps))
      detail::fail("cannot create " + what + " '" + dir.string() + "': '" + p.string() + "' is a file, not a folder");
    break;
  }
  std::filesystem::create_directories(dir, ec);
  if (ec) detail::fail(ErrorKind::io, "cannot create " + what + " '" + dir.string() + "': " + ec.message());
  if (!std::filesystem::is_directory(dir, ec))
    detail::fail(ErrorKind::io, "cannot create " + what + " '" + dir.string() + "'");
}

}  // namespace vmap
