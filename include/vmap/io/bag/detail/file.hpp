#pragma once

// Positioned reads of a bag file: the readers ask for byte ranges, each one checked
// against the file's size and a limit before a buffer is allocated for it.

#include <vmap/core/error.hpp>
#include <vmap/io/files.hpp>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <new>
#include <string>
#include <string_view>
#include <utility>

namespace vmap::detail {

/// Little-endian integers at `at` of `b` (the caller checked the bounds).
inline std::uint32_t le_u32(const char* b) noexcept {
  std::uint32_t v = 0;
  for (int i = 3; i >= 0; --i) v = (v << 8) | static_cast<unsigned char>(b[i]);
  return v;
}
inline std::uint64_t le_u64(const char* b) noexcept {
  std::uint64_t v = 0;
  for (int i = 7; i >= 0; --i) v = (v << 8) | static_cast<unsigned char>(b[i]);
  return v;
}

/// A regular file opened for positioned reads (pread: several readers of one file do not
/// share a position). Move-only.
class BagFile {
 public:
  BagFile() = default;
  /// `what` names the file in messages ("bag 'x.bag'").
  BagFile(const std::filesystem::path& path, std::string what) : what_(std::move(what)) {
    require_regular_file(path, "bag");
    fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
    if (fd_ < 0) {
      const int e = errno;
      fail(e == ENOENT ? ErrorKind::not_found : ErrorKind::io, "cannot open " + what_ + ": " + os_reason(e));
    }
    struct stat st {};
    if (::fstat(fd_, &st) != 0 || !S_ISREG(st.st_mode)) {
      ::close(std::exchange(fd_, -1));
      fail(what_ + " is not a regular file");
    }
    size_ = static_cast<std::uint64_t>(st.st_size);
  }
  BagFile(BagFile&& o) noexcept : fd_(std::exchange(o.fd_, -1)), size_(o.size_), what_(std::move(o.what_)) {}
  BagFile& operator=(BagFile&& o) noexcept {
    if (this != &o) {
      if (fd_ >= 0) ::close(fd_);
      fd_ = std::exchange(o.fd_, -1);
      size_ = o.size_;
      what_ = std::move(o.what_);
    }
    return *this;
  }
  BagFile(const BagFile&) = delete;
  BagFile& operator=(const BagFile&) = delete;
  ~BagFile() {
    if (fd_ >= 0) ::close(fd_);
  }

  [[nodiscard]] std::uint64_t size() const noexcept { return size_; }
  [[nodiscard]] const std::string& what() const noexcept { return what_; }

  /// Reads `n` bytes at `offset` into `out`; false when the file ends before (the file
  /// shrank, or the caller asked past the end). Read errors are an Error.
  bool read(std::uint64_t offset, char* out, std::size_t n) const {
    std::size_t got = 0;
    while (got < n) {
      const ssize_t r = ::pread(fd_, out + got, n - got, static_cast<off_t>(offset + got));
      if (r < 0 && errno == EINTR) continue;
      if (r < 0) {
        const int e = errno;
        fail(ErrorKind::io, "reading " + what_ + " at byte " + std::to_string(offset + got) + " failed: " + os_reason(e));
      }
      if (r == 0) return false;
      got += static_cast<std::size_t>(r);
    }
    return true;
  }

  /// `n` bytes at `offset` in a new string, after checking that `n` <= `limit` and that
  /// they lie in the file; otherwise an Error naming the file, the offset and `role`.
  [[nodiscard]] std::string read_string(std::uint64_t offset, std::uint64_t n, std::uint64_t limit,
                                        const char* role) const {
    if (n > limit)
      fail(ErrorKind::corrupt, what_ + ": " + role + " at byte " + std::to_string(offset) + " claims " + std::to_string(n) +
           " bytes, more than the limit of " + std::to_string(limit));
    if (offset > size_ || n > size_ - offset)
      fail(ErrorKind::corrupt, what_ + ": " + role + " at byte " + std::to_string(offset) + " claims " + std::to_string(n) +
           " bytes, past the end of the file (" + std::to_string(size_) + " bytes): the file is truncated");
    std::string s;
    try {
      s.resize(static_cast<std::size_t>(n));
    } catch (const std::bad_alloc&) {
      fail(what_ + ": not enough memory for the " + std::to_string(n) + " bytes of the " + role + " at byte " +
           std::to_string(offset));
    }
    if (!read(offset, s.data(), s.size()))
      fail(ErrorKind::corrupt, what_ + ": the file ended while reading the " + role + " at byte " + std::to_string(offset));
    return s;
  }

 private:
  int fd_ = -1;
  std::uint64_t size_ = 0;
  std::string what_;
};

}  // namespace vmap::detail
