#pragma once

// Reading images with a bound on their size that is checked BEFORE decoding: an image
// file states its width and height in its header, and a decoder allocates that much
// before it reads the pixels, so a 1 MB PNG claiming 30000 x 30000 pixels would cost
// gigabytes. `image_header_size` reads the size from the header of PNG, JPEG, BMP,
// PNM (PBM/PGM/PPM), WebP and TIFF files; for other formats the size is checked after
// decoding (OpenCV's own CV_IO_MAX_IMAGE_PIXELS, 2^30 by default, bounds the decoder).

#include <vmap/core/error.hpp>
#include <vmap/io/files.hpp>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <limits>
#include <new>
#include <optional>
#include <string>
#include <string_view>

namespace vmap {

/// Default bound on the pixels of one image (input frames, key images inside map
/// files): 64 Mi pixels, e.g. 8192 x 8192, far above any camera frame vmap is used with.
inline constexpr std::uint64_t default_max_image_pixels = std::uint64_t{1} << 26;

/// Default bound on the bytes of one image file.
inline constexpr std::uintmax_t default_max_image_file_bytes = std::uintmax_t{512} << 20;  // 512 MiB

namespace detail {

inline std::uint32_t be16(std::string_view b, std::size_t at) {
  return (std::uint32_t{static_cast<unsigned char>(b[at])} << 8) | static_cast<unsigned char>(b[at + 1]);
}
inline std::uint32_t be32(std::string_view b, std::size_t at) { return (be16(b, at) << 16) | be16(b, at + 2); }
inline std::uint32_t le16(std::string_view b, std::size_t at) {
  return (std::uint32_t{static_cast<unsigned char>(b[at + 1])} << 8) | static_cast<unsigned char>(b[at]);
}
inline std::uint32_t le32(std::string_view b, std::size_t at) { return (le16(b, at + 2) << 16) | le16(b, at); }

inline std::optional<cv::Size2l> jpeg_size(std::string_view b) {
  std::size_t p = 2;  // after FF D8
  while (p + 4 <= b.size()) {
    if (static_cast<unsigned char>(b[p]) != 0xFF) return std::nullopt;
    const auto marker = static_cast<unsigned char>(b[p + 1]);
    if (marker == 0xFF) {  // fill byte
      ++p;
      continue;
    }
    if (marker == 0x01 || (marker >= 0xD0 && marker <= 0xD7)) {  // markers without a length
      p += 2;
      continue;
    }
    const std::uint32_t len = be16(b, p + 2);
    if (len < 2) return std::nullopt;
    // SOF0..SOF15 carry the frame size; C4 (DHT), C8 (JPG) and CC (DAC) are not SOFs.
    if (marker >= 0xC0 && marker <= 0xCF && marker != 0xC4 && marker != 0xC8 && marker != 0xCC) {
      if (p + 9 > b.size()) return std::nullopt;
      return cv::Size2l(be16(b, p + 7), be16(b, p + 5));
    }
    if (marker == 0xDA || marker == 0xD9) return std::nullopt;  // scan data before any SOF
    p += 2 + len;
  }
  return std::nullopt;
}

inline std::optional<cv::Size2l> pnm_size(std::string_view b) {
  std::size_t p = 2;
  long long v[2] = {0, 0};
  for (auto& x : v) {
    for (;;) {  // whitespace and '#' comments
      while (p < b.size() && std::strchr(" \t\r\n\f\v", b[p]) != nullptr && b[p] != '\0') ++p;
      if (p < b.size() && b[p] == '#') {
        while (p < b.size() && b[p] != '\n') ++p;
        continue;
      }
      break;
    }
    const std::size_t start = p;
    while (p < b.size() && b[p] >= '0' && b[p] <= '9' && p - start < 12) x = x * 10 + (b[p++] - '0');
    if (p == start) return std::nullopt;
  }
  return cv::Size2l(v[0], v[1]);
}

inline std::optional<cv::Size2l> tiff_size(std::string_view b) {
  const bool le = b[0] == 'I';
  const auto u16 = [&](std::size_t at) { return le ? le16(b, at) : be16(b, at); };
  const auto u32 = [&](std::size_t at) { return le ? le32(b, at) : be32(b, at); };
  const std::size_t ifd = u32(4);
  if (ifd + 2 > b.size()) return std::nullopt;
  const std::size_t n = u16(ifd);
  long long w = -1, h = -1;
  for (std::size_t k = 0; k < n; ++k) {
    const std::size_t e = ifd + 2 + 12 * k;
    if (e + 12 > b.size()) return std::nullopt;
    const std::uint32_t tag = u16(e), type = u16(e + 2);
    const long long value = type == 3 ? u16(e + 8) : type == 4 ? u32(e + 8) : -1;
    if (tag == 256) w = value;
    if (tag == 257) h = value;
  }
  if (w < 0 || h < 0) return std::nullopt;
  return cv::Size2l(w, h);
}

}  // namespace detail

/// Width and height stated in the header of an encoded image (PNG, JPEG, BMP, PNM,
/// WebP, TIFF), without decoding it; nullopt for another format or a header too short
/// or malformed to tell.
[[nodiscard]] inline std::optional<cv::Size2l> image_header_size(std::string_view b) {
  using namespace detail;
  if (b.size() >= 24 && std::memcmp(b.data(), "\x89PNG\r\n\x1a\n", 8) == 0 && b.substr(12, 4) == "IHDR")
    return cv::Size2l(be32(b, 16), be32(b, 20));
  if (b.size() >= 4 && static_cast<unsigned char>(b[0]) == 0xFF && static_cast<unsigned char>(b[1]) == 0xD8)
    return jpeg_size(b);
  if (b.size() >= 26 && b[0] == 'B' && b[1] == 'M') {
    if (le32(b, 14) == 12) return cv::Size2l(le16(b, 18), le16(b, 20));  // BITMAPCOREHEADER
    const auto w = static_cast<std::int32_t>(le32(b, 18)), h = static_cast<std::int32_t>(le32(b, 22));
    return cv::Size2l(w < 0 ? -static_cast<long long>(w) : w, h < 0 ? -static_cast<long long>(h) : h);
  }
  if (b.size() >= 3 && b[0] == 'P' && b[1] >= '1' && b[1] <= '6') return pnm_size(b);
  if (b.size() >= 30 && b.substr(0, 4) == "RIFF" && b.substr(8, 4) == "WEBP") {
    const auto chunk = b.substr(12, 4);
    if (chunk == "VP8 ") return cv::Size2l(le16(b, 26) & 0x3FFF, le16(b, 28) & 0x3FFF);
    if (chunk == "VP8L") {
      const std::uint32_t bits = le32(b, 21);
      return cv::Size2l((bits & 0x3FFF) + 1, ((bits >> 14) & 0x3FFF) + 1);
    }
    if (chunk == "VP8X" && b.size() >= 31)
      return cv::Size2l((le32(b, 24) & 0xFFFFFF) + 1, (le32(b, 27) & 0xFFFFFF) + 1);
    return std::nullopt;
  }
  if (b.size() >= 8 && (b.substr(0, 4) == std::string_view("II*\0", 4) || b.substr(0, 4) == std::string_view("MM\0*", 4)))
    return detail::tiff_size(b);
  return std::nullopt;
}

/// Limits and mode of `read_image`.
struct ImageReadOptions {
  int flags = cv::IMREAD_UNCHANGED;                   ///< cv::imread flags
  std::uint64_t max_pixels = default_max_image_pixels;  ///< width x height bound, checked before decoding
  std::uintmax_t max_file_bytes = default_max_image_file_bytes;
};

namespace detail {

/// Decodes encoded image bytes after checking the header's size against `max_pixels`.
/// Returns the image, or an empty Mat and the reason it could not be decoded.
inline cv::Mat decode_image_checked(std::string_view bytes, int flags, std::uint64_t max_pixels, std::string& reason) {
  if (const auto size = image_header_size(bytes)) {
    const auto pixels = static_cast<std::uint64_t>(size->width) * static_cast<std::uint64_t>(size->height);
    if (size->width <= 0 || size->height <= 0) {
      reason = "the image header states a size of " + std::to_string(size->width) + "x" + std::to_string(size->height);
      return {};
    }
    if (pixels > max_pixels) {
      reason = "the image is " + std::to_string(size->width) + "x" + std::to_string(size->height) + " pixels, more than the limit of " +
               std::to_string(max_pixels) + " pixels";
      return {};
    }
  }
  cv::Mat img;
  try {
    const cv::Mat buf(1, static_cast<int>(bytes.size()), CV_8UC1, const_cast<char*>(bytes.data()));
    img = cv::imdecode(buf, flags);
  } catch (const cv::Exception& e) {
    reason = std::string("cannot be decoded as an image (") + e.err + ")";
    return {};
  } catch (const std::bad_alloc&) {
    reason = "not enough memory to decode the image";
    return {};
  }
  if (img.empty()) {
    reason = "cannot be decoded as an image";
    return {};
  }
  if (static_cast<std::uint64_t>(img.rows) * static_cast<std::uint64_t>(img.cols) > max_pixels) {
    reason = "the image is " + std::to_string(img.cols) + "x" + std::to_string(img.rows) +
             " pixels, more than the limit of " + std::to_string(max_pixels) + " pixels";
    return {};
  }
  return img;
}

/// Reads and decodes an image file; on failure an empty Mat and the reason (missing,
/// a folder, not a regular file, unreadable, too large, not decodable).
inline cv::Mat try_read_image(const std::filesystem::path& path, const ImageReadOptions& o, std::string& reason) {
  std::string bytes;
  try {
    bytes = read_file(path, o.max_file_bytes, "image");
  } catch (const Error& e) {
    // The message names the image already; keep only what follows the path.
    const std::string m = e.what();
    const auto q = m.find("' ");
    const auto c = m.find("': ");
    reason = c != std::string::npos ? m.substr(c + 3) : q != std::string::npos ? m.substr(q + 2) : m;
    return {};
  }
  if (bytes.size() > static_cast<std::size_t>(std::numeric_limits<int>::max())) {
    reason = "the file is too large to decode";
    return {};
  }
  return decode_image_checked(bytes, o.flags, o.max_pixels, reason);
}

}  // namespace detail

/// Reads an image file; the pixel limit is checked from the header before decoding.
/// Errors (vmap::Error "image '<path>': <reason>"): missing, a folder or a device,
/// unreadable, larger than the limits, not decodable.
[[nodiscard]] inline cv::Mat read_image(const std::filesystem::path& path, const ImageReadOptions& options = {}) {
  std::string reason;
  cv::Mat img = detail::try_read_image(path, options, reason);
  if (img.empty())
    detail::fail(std::filesystem::exists(path) ? ErrorKind::invalid_argument : ErrorKind::not_found,
                 "image '" + path.string() + "': " + reason);
  return img;
}

}  // namespace vmap
