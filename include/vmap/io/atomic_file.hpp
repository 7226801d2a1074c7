#pragma once

// Files are written to a temporary name beside the target, flushed, and renamed into
// place: rename() within one folder is atomic on POSIX, so a crash or a full disk
// never destroys the file that was there before.

#include <vmap/core/error.hpp>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

namespace vmap {

namespace detail {

inline std::filesystem::path temp_name_for(const std::filesystem::path& target) {
  auto tmp = target;
  tmp += ".vmap-tmp";
  return tmp;
}

inline void commit_temp(const std::filesystem::path& tmp, const std::filesystem::path& target) {
  std::error_code ec;
  std::filesystem::rename(tmp, target, ec);
  if (ec) {
    std::filesystem::remove(tmp, ec);
    fail("cannot move the new '" + target.string() + "' into place");
  }
}

}  // namespace detail

/// Writes `bytes` to `target` atomically (temp file + rename).
inline void write_file_atomically(const std::filesystem::path& target, std::string_view bytes) {
  const auto tmp = detail::temp_name_for(target);
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) detail::fail("cannot write '" + tmp.string() + "' (does the folder exist and is it writable?)");
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    out.flush();
    if (!out) {
      out.close();
      std::error_code ec;
      std::filesystem::remove(tmp, ec);
      detail::fail("writing '" + target.string() + "' failed (disk full?)");
    }
  }
  detail::commit_temp(tmp, target);
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

/// Reads a whole file; a missing or unreadable file is an Error naming it.
inline std::string read_file(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) detail::fail("cannot open '" + path.string() + "'");
  std::string data((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (in.bad()) detail::fail("reading '" + path.string() + "' failed");
  return data;
}

}  // namespace vmap
