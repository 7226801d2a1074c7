#pragma once

// Atomic saves.
//
// One file (`write_file_atomically`, `AtomicFile`): the bytes go to a temporary file
// with a unique name in the target's folder (mkstemp: `.<name>.vmap-XXXXXX`), which is
// flushed to disk (fsync), renamed over the target (rename() within one folder is
// atomic on POSIX), and the folder is fsynced so the rename itself survives a crash.
// A reader sees the old file or the new one, never a mix; two processes saving to the
// same path at once each write their own temporary file, and the last rename wins with
// a complete file. A writer that fails or throws before `commit()` leaves the previous
// file untouched and removes its temporary file. A process killed mid-save (kill -9,
// power loss) leaves the target intact and may leave its hidden temporary file
// (`.<name>.vmap-XXXXXX`) beside it; such files are never read and can be deleted.
//
// Several files as one set (`AtomicDirectory`): the files are written into a
// temporary folder beside the target folder (`.<name>.vmap-XXXXXX`), which is then
// renamed into place. When the target folder exists it is swapped with the new one in
// one step (Linux renameat2 RENAME_EXCHANGE) and the old set is deleted, so a reader
// sees either the whole old set or the whole new set. Because the old folder is
// deleted, an existing target folder is replaced only when it is empty or was itself
// written by AtomicDirectory (it holds the marker file `.vmap-output`); any other
// existing folder is refused, so `--out $HOME` can never delete a user's files. The
// marker lists the names the set was published with; a marked folder that has since
// gained anything else (a memory file saved into it, a user's notes) is refused too, so
// replacing an output never deletes what another command or a person put there. A
// marker without a list (older vmap) still refuses a folder holding a memory (`*.vmem`,
// `*.vmdb`).
//
// Symbolic links: a target file that is a symbolic link is followed on purpose: the
// file the link points to is replaced (the temporary file is made in that file's
// folder) and the link stays a link. A target (or link destination) that exists but is
// not a regular file (a folder, a device such as /dev/full, a FIFO) is refused, so a
// save never renames over /dev/null. A target folder of AtomicDirectory that is a
// symbolic link is refused (swapping it would replace the link, not the folder).

#include <vmap/core/error.hpp>
#include <vmap/io/files.hpp>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include <fcntl.h>
#include <stdio.h>  // renameat2 (glibc >= 2.28)
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <string_view>
#include <system_error>
#include <utility>
#include <vector>

namespace vmap {

namespace detail {

/// The file a save to `target` really replaces: `target`, or where its symbolic link
/// chain leads (relative links resolved against the link's folder).
inline std::filesystem::path resolve_save_target(const std::filesystem::path& target) {
  std::filesystem::path p = target;
  std::error_code ec;
  for (int hops = 0; std::filesystem::is_symlink(std::filesystem::symlink_status(p, ec)); ++hops) {
    if (hops >= 40) fail("cannot save '" + target.string() + "': too many levels of symbolic links");
    const auto to = std::filesystem::read_symlink(p, ec);
    if (ec) fail(ErrorKind::io, "cannot save '" + target.string() + "': " + ec.message());
    p = to.is_absolute() ? to : p.parent_path() / to;
  }
  const auto st = std::filesystem::status(p, ec);
  if (std::filesystem::exists(st) && !std::filesystem::is_regular_file(st))
    fail("cannot save '" + target.string() + "': " +
         (std::filesystem::is_directory(st) ? std::string("it is a folder")
                                            : std::string("it is not a regular file (device, FIFO or socket)")));
  return p;
}

inline std::filesystem::path folder_of(const std::filesystem::path& p) {
  return p.has_parent_path() ? p.parent_path() : std::filesystem::path(".");
}

/// fsync of a folder, so that a rename in it is on disk. Failures are ignored: some
/// file systems refuse fsync on folders and the rename is done either way.
inline void sync_folder(const std::filesystem::path& dir) noexcept {
  const int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) return;
  (void)::fsync(fd);
  ::close(fd);
}

inline constexpr const char* output_marker = ".vmap-output";

}  // namespace detail

/// A file being written atomically: write() appends, commit() publishes it under the
/// target's name. Destroyed without commit() (an exception, an early return) it removes
/// its temporary file and the target keeps its previous content. Move-only; one thread.
class AtomicFile {
 public:
  explicit AtomicFile(const std::filesystem::path& target)
      : target_(target), real_(detail::resolve_save_target(target)) {
    const auto dir = detail::folder_of(real_);
    std::string templ = (dir / ("." + real_.filename().string() + ".vmap-XXXXXX")).string();
    fd_ = ::mkstemp(templ.data());
    if (fd_ < 0) {
      const int e = errno;
      std::error_code ec;
      const bool folder = std::filesystem::is_directory(dir, ec);
      detail::fail(folder ? ErrorKind::io : ErrorKind::not_found,
                   "cannot write '" + target_.string() + "': " +
                       (folder ? detail::os_reason(e) : "the folder '" + dir.string() + "' does not exist"));
    }
    ::fcntl(fd_, F_SETFD, FD_CLOEXEC);
    tmp_ = templ;
    // mkstemp creates mode 0600; a saved file keeps the mode of the file it replaces,
    // or gets 0644 (owner writes, everyone reads) when it is new.
    struct stat st {};
    const mode_t mode = ::stat(real_.c_str(), &st) == 0 ? (st.st_mode & 07777) : 0644;
    (void)::fchmod(fd_, mode);
  }

  AtomicFile(AtomicFile&& o) noexcept
      : target_(std::move(o.target_)), real_(std::move(o.real_)), tmp_(std::move(o.tmp_)), fd_(std::exchange(o.fd_, -1)) {}
  AtomicFile& operator=(AtomicFile&&) = delete;
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;

  ~AtomicFile() { abandon(); }

  /// Appends bytes to the temporary file.
  void write(std::string_view bytes) {
    detail::check(fd_ >= 0, "AtomicFile::write: '" + target_.string() + "' is already committed");
    std::size_t done = 0;
    while (done < bytes.size()) {
      const ssize_t n = ::write(fd_, bytes.data() + done, bytes.size() - done);
      if (n < 0 && errno == EINTR) continue;
      if (n < 0) {
        const int e = errno;
        abandon();
        detail::fail(ErrorKind::io, "writing '" + target_.string() + "' failed: " + detail::os_reason(e));
      }
      done += static_cast<std::size_t>(n);
    }
  }

  /// Flushes the data to disk, renames it over the target and syncs the folder.
  void commit() {
    detail::check(fd_ >= 0, "AtomicFile::commit: '" + target_.string() + "' is already committed");
    if (::fsync(fd_) != 0 && errno != EINVAL) {
      const int e = errno;
      abandon();
      detail::fail(ErrorKind::io, "writing '" + target_.string() + "' failed (fsync): " + detail::os_reason(e));
    }
    const int closed = ::close(std::exchange(fd_, -1));
    if (closed != 0) {
      const int e = errno;
      abandon();
      detail::fail(ErrorKind::io, "writing '" + target_.string() + "' failed (close): " + detail::os_reason(e));
    }
    if (::rename(tmp_.c_str(), real_.c_str()) != 0) {
      const int e = errno;
      abandon();
      detail::fail(ErrorKind::io, "cannot move the new '" + target_.string() + "' into place: " + detail::os_reason(e));
    }
    tmp_.clear();
    detail::sync_folder(detail::folder_of(real_));
  }

  [[nodiscard]] const std::filesystem::path& target() const noexcept { return target_; }
  /// The temporary file (empty after commit).
  [[nodiscard]] const std::filesystem::path& temporary() const noexcept { return tmp_; }

 private:
  void abandon() noexcept {
    if (fd_ >= 0) ::close(std::exchange(fd_, -1));
    if (!tmp_.empty()) {
      ::unlink(tmp_.c_str());
      tmp_.clear();
    }
  }

  std::filesystem::path target_;
  std::filesystem::path real_;  // target_ with symbolic links followed
  std::filesystem::path tmp_;
  int fd_ = -1;
};

/// Writes `bytes` to `target` atomically (see the top of this file).
inline void write_file_atomically(const std::filesystem::path& target, std::string_view bytes) {
  AtomicFile f(target);
  f.write(bytes);
  f.commit();
}

/// Encodes `image` by the extension of `target` (.png, .jpg, ...) and writes it atomically.
inline void write_image_atomically(const std::filesystem::path& target, const cv::Mat& image) {
  std::vector<unsigned char> buf;
  bool encoded = false;
  try {
    encoded = !image.empty() && cv::imencode(target.extension().string(), image, buf);
  } catch (const cv::Exception&) {
    encoded = false;  // OpenCV throws for an extension it has no encoder for
  }
  if (!encoded) detail::fail("cannot encode an image for '" + target.string() + "' (empty image or unknown extension)");
  write_file_atomically(target, std::string_view(reinterpret_cast<const char*>(buf.data()), buf.size()));
}

/// A set of files published together (see the top of this file):
///
///     AtomicDirectory out("results");      // checks "results" can be replaced
///     save_map(map, out.path() / "map.vmap");
///     write_image_atomically(out.path() / "sheet.png", sheet);
///     out.commit();                        // "results" now holds exactly these files
///
/// Destroyed without commit() it deletes the temporary folder; the target is untouched.
/// The target's parent folders are created if missing (errors name the folder).
/// Move-only; one thread.
class AtomicDirectory {
  struct ChecksOnly {};

  /// Only the checks of the target (check()); creates nothing.
  AtomicDirectory(const std::filesystem::path& target, ChecksOnly) : target_(target) {
    detail::check(!target.empty(), "AtomicDirectory: the output folder name is empty");
    auto name = target_.filename();
    if (name.empty() || name == "." || name == "..") {  // "out/" or "." : use the real name
      std::error_code ec;
      target_ = std::filesystem::weakly_canonical(std::filesystem::absolute(target, ec), ec);
      name = target_.filename();
      detail::check(!name.empty(), "output folder '" + target.string() + "' cannot be replaced");
    }
    check_replaceable();
  }

 public:
  /// The checks the constructor makes before it creates anything: whether `target` may
  /// be replaced. A front end reports their failures as the user's to fix, apart from the
  /// constructor's own (creating the folder or its first file on a full disk).
  static void check(const std::filesystem::path& target) { (void)AtomicDirectory(target, ChecksOnly{}); }

  // (Delegating: once the checks' constructor returned, a failure below runs the
  // destructor, which removes the temporary folder made so far.)
  explicit AtomicDirectory(const std::filesystem::path& target) : AtomicDirectory(target, ChecksOnly{}) {
    const auto name = target_.filename();
    const auto parent = detail::folder_of(target_);
    create_directories(parent, "output folder's parent");
    std::string templ = (parent / ("." + name.string() + ".vmap-XXXXXX")).string();
    if (::mkdtemp(templ.data()) == nullptr) {
      const int e = errno;
      detail::fail(ErrorKind::io, "cannot create output folder '" + target_.string() + "': " + detail::os_reason(e));
    }
    tmp_ = templ;
    ::chmod(tmp_.c_str(), 0755);  // mkdtemp makes 0700; an output folder is a normal folder
    write_file_atomically(tmp_ / detail::output_marker, std::string(marker_header) + "\n");
  }

  AtomicDirectory(AtomicDirectory&& o) noexcept : target_(std::move(o.target_)), tmp_(std::exchange(o.tmp_, {})) {}
  AtomicDirectory& operator=(AtomicDirectory&&) = delete;
  AtomicDirectory(const AtomicDirectory&) = delete;
  AtomicDirectory& operator=(const AtomicDirectory&) = delete;

  ~AtomicDirectory() { abandon(); }

  /// The folder to write the set's files into (until commit()).
  [[nodiscard]] const std::filesystem::path& path() const noexcept { return tmp_; }
  [[nodiscard]] const std::filesystem::path& target() const noexcept { return target_; }

  /// Publishes the set: the temporary folder becomes the target folder in one rename.
  void commit() {
    detail::check(!tmp_.empty(), "AtomicDirectory::commit: '" + target_.string() + "' is already committed");
    write_marker();
    detail::sync_folder(tmp_);
    // First try: the target does not exist (RENAME_NOREPLACE never clobbers a folder
    // created meanwhile by someone else).
    for (int attempt = 0; attempt < 8; ++attempt) {
      if (::renameat2(AT_FDCWD, tmp_.c_str(), AT_FDCWD, target_.c_str(), RENAME_NOREPLACE) == 0) {
        tmp_.clear();
        detail::sync_folder(detail::folder_of(target_));
        return;
      }
      int e = errno;
      if (e != EEXIST) fail_commit(e);
      check_replaceable();
      if (::renameat2(AT_FDCWD, tmp_.c_str(), AT_FDCWD, target_.c_str(), RENAME_EXCHANGE) == 0) {
        // tmp_ now names the previous set: delete it.
        detail::sync_folder(detail::folder_of(target_));
        abandon();
        return;
      }
      e = errno;
      if (e == ENOENT) continue;  // the target vanished between the two calls: retry
      if (e != EINVAL && e != ENOSYS) fail_commit(e);
      // A file system without RENAME_EXCHANGE: move the old set aside, then rename.
      // (A reader may then briefly see no folder, never a mixed one.)
      const auto old = std::filesystem::path(tmp_.string() + ".old");
      if (::rename(target_.c_str(), old.c_str()) != 0) fail_commit(errno);
      if (::rename(tmp_.c_str(), target_.c_str()) != 0) {
        e = errno;
        (void)::rename(old.c_str(), target_.c_str());
        fail_commit(e);
      }
      tmp_ = old;
      detail::sync_folder(detail::folder_of(target_));
      abandon();
      return;
    }
    fail_commit(EBUSY);
  }

 private:
  /// Refuses a target that exists and may hold files that are not vmap's.
  void check_replaceable() const {
    std::error_code ec;
    const auto ls = std::filesystem::symlink_status(target_, ec);
    if (!std::filesystem::exists(ls)) return;
    if (std::filesystem::is_symlink(ls))
      detail::fail("output folder '" + target_.string() +
                   "' is a symbolic link; give the folder it points to (vmap replaces output folders as a whole)");
    if (!std::filesystem::is_directory(ls)) detail::fail("output folder '" + target_.string() + "' exists and is not a folder");
    if (std::filesystem::exists(target_ / detail::output_marker, ec)) {
      check_only_own_files();
      return;
    }
    const bool empty = std::filesystem::is_empty(target_, ec);
    if (ec) detail::fail(ErrorKind::io, "cannot read output folder '" + target_.string() + "': " + ec.message());
    if (!empty)
      detail::fail("output folder '" + target_.string() +
                   "' exists and holds files vmap did not write; vmap replaces its output folder as a whole, "
                   "so give a new or empty folder");
  }

  static constexpr const char* marker_header = "written by vmap; the folder is replaced as a whole";

  /// The marker: its header line, then the name of every entry of the set, one a line.
  void write_marker() const {
    std::string text = std::string(marker_header) + "\n";
    std::error_code ec;
    for (const auto& e : std::filesystem::directory_iterator(tmp_, ec)) {
      const std::string name = e.path().filename().string();
      if (name != detail::output_marker && name.find('\n') == std::string::npos) text += name + "\n";
    }
    if (ec) detail::fail(ErrorKind::io, "cannot list the new output folder '" + tmp_.string() + "': " + ec.message());
    write_file_atomically(tmp_ / detail::output_marker, text);
  }

  /// A marked folder is replaced only while it holds nothing but the files its marker
  /// lists (see the top of this file).
  void check_only_own_files() const {
    const std::filesystem::path marker = target_ / detail::output_marker;
    const std::string text = read_file(marker, std::uintmax_t{1} << 20, "output marker");
    std::vector<std::string> listed;
    std::size_t at = text.find('\n');
    const bool has_list = at != std::string::npos && at + 1 < text.size();
    while (at != std::string::npos && at + 1 < text.size()) {
      const std::size_t end = text.find('\n', at + 1);
      listed.push_back(text.substr(at + 1, (end == std::string::npos ? text.size() : end) - at - 1));
      at = end;
    }
    std::error_code ec;
    for (const auto& e : std::filesystem::directory_iterator(target_, ec)) {
      const std::string name = e.path().filename().string();
      if (name == detail::output_marker) continue;
      const bool own = has_list ? std::find(listed.begin(), listed.end(), name) != listed.end()
                                : e.path().extension() != ".vmem" && e.path().extension() != ".vmdb";
      if (!own)
        detail::fail("output folder '" + target_.string() + "' holds '" + name +
                     "', which is not one of the files vmap wrote there; vmap replaces its output folder as a "
                     "whole, so move it away or give another folder");
    }
    if (ec) detail::fail(ErrorKind::io, "cannot read output folder '" + target_.string() + "': " + ec.message());
  }

  [[noreturn]] void fail_commit(int e) {
    abandon();
    detail::fail(ErrorKind::io, "cannot move the new output folder '" + target_.string() + "' into place: " + detail::os_reason(e));
  }

  void abandon() noexcept {
    if (tmp_.empty()) return;
    std::error_code ec;
    std::filesystem::remove_all(tmp_, ec);
    tmp_.clear();
  }

  std::filesystem::path target_;
  std::filesystem::path tmp_;
};

}  // namespace vmap
