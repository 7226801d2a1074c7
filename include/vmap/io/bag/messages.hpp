#pragma once

// The ROS messages a bag frame source reads, decoded from ROS 1 or CDR bytes by one
// decoder per type (io/bag/cdr.hpp): sensor_msgs/Image, sensor_msgs/CompressedImage and
// sensor_msgs/CameraInfo (the same fields in ROS 1 and ROS 2; ROS 1 headers have a seq
// number first and an unsigned seconds field), and their conversion to a cv::Mat or a
// vmap::Camera.
//
// Images: mono8, 8UC1, mono16, 16UC1 (is_bigendian honoured), rgb8, bgr8, 8UC3, rgba8,
// bgra8; colour comes out in OpenCV's BGR(A) order, and straight to 8-bit grey when asked
// (16-bit grey keeps its high byte, as OpenCV's grey decoding of a 16-bit PNG does).
// CompressedImage: JPEG or PNG bytes, decoded by OpenCV after their header's size is
// checked (io/image.hpp). Anything else is refused with a reason naming the encoding.

#include <vmap/core/error.hpp>
#include <vmap/geometry/camera.hpp>
#include <vmap/io/bag/cdr.hpp>
#include <vmap/io/image.hpp>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace vmap::detail {

/// The image-related message types, by name in either ROS generation.
enum class RosMessageKind : std::uint8_t { other, image, compressed_image, camera_info };

/// "sensor_msgs/Image" and "sensor_msgs/msg/Image" alike.
inline RosMessageKind ros_message_kind(std::string_view type) noexcept {
  if (type == "sensor_msgs/Image" || type == "sensor_msgs/msg/Image") return RosMessageKind::image;
  if (type == "sensor_msgs/CompressedImage" || type == "sensor_msgs/msg/CompressedImage")
    return RosMessageKind::compressed_image;
  if (type == "sensor_msgs/CameraInfo" || type == "sensor_msgs/msg/CameraInfo") return RosMessageKind::camera_info;
  return RosMessageKind::other;
}

struct RosHeader {
  std::int64_t stamp_ns = 0;
  std::string_view frame_id;
};

struct ImageMessage {
  RosHeader header;
  std::uint32_t height = 0, width = 0;
  std::string_view encoding;
  bool big_endian = false;
  std::uint32_t step = 0;
  std::string_view data;
};

struct CompressedImageMessage {
  RosHeader header;
  std::string_view format;
  std::string_view data;
};

struct CameraInfoMessage {
  RosHeader header;
  std::uint32_t height = 0, width = 0;
  std::string_view distortion_model;
  std::vector<double> d;
  std::array<double, 9> k{};
};

/// std_msgs/Header: ROS 1 `uint32 seq, time stamp (uint32 sec, uint32 nsec), string
/// frame_id`; ROS 2 `builtin_interfaces/Time stamp (int32 sec, uint32 nanosec), string
/// frame_id`.
template <class Reader>
RosHeader read_ros_header(Reader& r, bool ros1) {
  RosHeader h;
  if (ros1) (void)r.u32();
  const std::int64_t sec = ros1 ? static_cast<std::int64_t>(r.u32()) : static_cast<std::int64_t>(r.i32());
  const std::uint32_t nsec = r.u32();
  h.stamp_ns = sec * 1000000000 + static_cast<std::int64_t>(nsec);
  h.frame_id = r.string();
  return h;
}

template <class Reader>
ImageMessage read_image_message(Reader& r, bool ros1) {
  ImageMessage m;
  m.header = read_ros_header(r, ros1);
  m.height = r.u32();
  m.width = r.u32();
  m.encoding = r.string();
  m.big_endian = r.u8() != 0;
  m.step = r.u32();
  m.data = r.byte_sequence();
  return m;
}

template <class Reader>
CompressedImageMessage read_compressed_image_message(Reader& r, bool ros1) {
  CompressedImageMessage m;
  m.header = read_ros_header(r, ros1);
  m.format = r.string();
  m.data = r.byte_sequence();
  return m;
}

template <class Reader>
CameraInfoMessage read_camera_info_message(Reader& r, bool ros1) {
  CameraInfoMessage m;
  m.header = read_ros_header(r, ros1);
  m.height = r.u32();
  m.width = r.u32();
  m.distortion_model = r.string();
  m.d = r.f64_sequence(64);
  r.f64_array(m.k.data(), 9);
  return m;
}

/// Calls f(reader) with the reader for `encoding` ("ros1" or "cdr") over `bytes`.
template <class F>
decltype(auto) with_message_reader(std::string_view encoding, std::string_view bytes, std::string what, F&& f) {
  if (encoding == "ros1") {
    Ros1Reader r(bytes, std::move(what));
    return f(r, true);
  }
  if (encoding != "cdr") fail(what + ": message encoding '" + std::string(encoding) + "' is not ros1 or cdr");
  CdrReader r(bytes, std::move(what));
  return f(r, false);
}

/// The header stamp of an Image or CompressedImage message (both start with it).
inline std::int64_t message_stamp(std::string_view encoding, std::string_view bytes, const std::string& what) {
  return with_message_reader(encoding, bytes, what, [](auto& r, bool ros1) { return read_ros_header(r, ros1).stamp_ns; });
}

/// The layout of a raw image encoding.
struct RawEncoding {
  int depth = CV_8U;  ///< CV_8U or CV_16U
  int channels = 1;
  int to_bgr = -1;    ///< cvtColor code to OpenCV's order, -1: already
  int to_grey = -1;   ///< cvtColor code to grey, -1: already grey
};

inline std::optional<RawEncoding> raw_encoding(std::string_view e) {
  if (e == "mono8" || e == "8UC1") return RawEncoding{CV_8U, 1, -1, -1};
  if (e == "mono16" || e == "16UC1") return RawEncoding{CV_16U, 1, -1, -1};
  if (e == "bgr8" || e == "8UC3") return RawEncoding{CV_8U, 3, -1, cv::COLOR_BGR2GRAY};
  if (e == "rgb8") return RawEncoding{CV_8U, 3, cv::COLOR_RGB2BGR, cv::COLOR_RGB2GRAY};
  if (e == "bgra8") return RawEncoding{CV_8U, 4, -1, cv::COLOR_BGRA2GRAY};
  if (e == "rgba8") return RawEncoding{CV_8U, 4, cv::COLOR_RGBA2BGRA, cv::COLOR_RGBA2GRAY};
  return std::nullopt;
}

inline constexpr const char* raw_encodings_read = "mono8, mono16, rgb8, bgr8, rgba8, bgra8, 8UC1, 8UC3, 16UC1";

/// Image bounds a frame source applies (FrameSourceOptions max_pixels, min_side).
struct ImageBounds {
  std::uint64_t max_pixels = default_max_image_pixels;
  int min_side = 1;
};

inline std::string size_text(std::uint64_t w, std::uint64_t h) { return std::to_string(w) + "x" + std::to_string(h); }

/// The image of a sensor_msgs/Image, or empty and the reason it is refused. Every size
/// is checked against the message's bytes before a pixel is read.
inline cv::Mat image_from_raw(const ImageMessage& m, bool grey, const ImageBounds& bounds, std::string& reason) {
  const auto enc = raw_encoding(m.encoding);
  if (!enc) {
    reason = "encoding '" + std::string(m.encoding) + "' is not read (vmap reads " + raw_encodings_read + ")";
    return {};
  }
  const std::uint64_t w = m.width, h = m.height;
  if (w * h > bounds.max_pixels || w > static_cast<std::uint64_t>(std::numeric_limits<int>::max()) ||
      h > static_cast<std::uint64_t>(std::numeric_limits<int>::max())) {
    reason = "the image is " + size_text(w, h) + " pixels, more than the limit of " + std::to_string(bounds.max_pixels) +
             " (FrameSourceOptions::max_pixels)";
    return {};
  }
  const std::uint64_t row = w * static_cast<std::uint64_t>(enc->channels) * (enc->depth == CV_16U ? 2u : 1u);
  if (m.step < row) {
    reason = std::string(m.encoding) + " " + size_text(w, h) + " needs a step of at least " + std::to_string(row) +
             " bytes, the message says " + std::to_string(m.step);
    return {};
  }
  const std::uint64_t need = static_cast<std::uint64_t>(m.step) * h;
  if (m.data.size() < need) {
    reason = "the message carries " + std::to_string(m.data.size()) + " bytes of pixels, " + std::string(m.encoding) +
             " " + size_text(w, h) + " with step " + std::to_string(m.step) + " needs " + std::to_string(need);
    return {};
  }
  if (w < static_cast<std::uint64_t>(bounds.min_side) || h < static_cast<std::uint64_t>(bounds.min_side)) {
    reason = "the image is " + size_text(w, h) + " pixels, smaller than " + std::to_string(bounds.min_side) + "x" +
             std::to_string(bounds.min_side) + " (FrameSourceOptions::min_side)";
    return {};
  }
  const int type = CV_MAKETYPE(enc->depth, enc->channels);
  // A view of the message's pixels (no copy yet); every path below writes a new image.
  const cv::Mat view(static_cast<int>(h), static_cast<int>(w), type, const_cast<char*>(m.data.data()),
                     static_cast<std::size_t>(m.step));
  cv::Mat out;
  if (enc->depth == CV_16U) {
    out = view.clone();
    // The message's bytes are big-endian when is_bigendian says so: swap them into this
    // machine's order where it differs.
    if (m.big_endian != (std::endian::native == std::endian::big))
      for (int y = 0; y < out.rows; ++y) {
        auto* p = out.ptr<std::uint16_t>(y);
        for (int x = 0; x < out.cols; ++x) p[x] = static_cast<std::uint16_t>((p[x] >> 8) | (p[x] << 8));
      }
    if (grey) {
      cv::Mat g(out.rows, out.cols, CV_8UC1);
      for (int y = 0; y < out.rows; ++y) {
        const auto* s = out.ptr<std::uint16_t>(y);
        auto* d = g.ptr<std::uint8_t>(y);
        for (int x = 0; x < out.cols; ++x) d[x] = static_cast<std::uint8_t>(s[x] >> 8);
      }
      out = g;
    }
    return out;
  }
  if (grey && enc->to_grey >= 0)
    cv::cvtColor(view, out, enc->to_grey);
  else if (!grey && enc->to_bgr >= 0)
    cv::cvtColor(view, out, enc->to_bgr);
  else
    out = view.clone();
  return out;
}

/// The image of a sensor_msgs/CompressedImage (JPEG or PNG), or empty and the reason.
inline cv::Mat image_from_compressed(const CompressedImageMessage& m, bool grey, const ImageBounds& bounds,
                                     std::string& reason) {
  const std::string_view d = m.data;
  const bool jpeg = d.size() >= 3 && static_cast<unsigned char>(d[0]) == 0xFF &&
                    static_cast<unsigned char>(d[1]) == 0xD8 && static_cast<unsigned char>(d[2]) == 0xFF;
  const bool png = d.size() >= 8 && d.substr(0, 8) == std::string_view("\x89PNG\r\n\x1a\n", 8);
  if (!jpeg && !png) {
    reason = "format '" + std::string(m.format) + "': the " + std::to_string(d.size()) +
             " bytes are neither JPEG nor PNG (vmap reads those two)";
    return {};
  }
  if (d.size() > static_cast<std::size_t>(std::numeric_limits<int>::max())) {
    reason = "the compressed image is too large to decode";
    return {};
  }
  cv::Mat out = decode_image_checked(d, grey ? cv::IMREAD_GRAYSCALE : cv::IMREAD_UNCHANGED, bounds.max_pixels, reason);
  if (out.empty()) {
    reason = std::string(jpeg ? "JPEG" : "PNG") + " (format '" + std::string(m.format) + "', " +
             std::to_string(d.size()) + " bytes): " + reason;
    return {};
  }
  if (out.cols < bounds.min_side || out.rows < bounds.min_side) {
    reason = "the image is " + size_text(static_cast<std::uint64_t>(out.cols), static_cast<std::uint64_t>(out.rows)) +
             " pixels, smaller than " + std::to_string(bounds.min_side) + "x" + std::to_string(bounds.min_side) +
             " (FrameSourceOptions::min_side)";
    return {};
  }
  return out;
}

/// A vmap::Camera from a CameraInfo (plumb_bob and rational_polynomial: k1 k2 p1 p2 k3
/// [k4 k5 k6], OpenCV's order; equidistant: k1..k4); nullopt with `reason` when it holds
/// no calibration (K all zero, as an uncalibrated driver publishes) or one vmap cannot use.
inline std::optional<Camera> camera_from_info(const CameraInfoMessage& m, const std::string& what, std::string& reason) {
  if (std::all_of(m.k.begin(), m.k.end(), [](double v) { return v == 0.0; })) {
    reason = "its K matrix is all zero (an uncalibrated camera)";
    return std::nullopt;
  }
  if (m.k[1] != 0.0 || m.k[3] != 0.0 || m.k[6] != 0.0 || m.k[7] != 0.0 || m.k[8] != 1.0) {
    reason = "its K matrix is not [fx 0 cx; 0 fy cy; 0 0 1] (vmap does not model skew)";
    return std::nullopt;
  }
  Camera c;
  c.fx = m.k[0];
  c.fy = m.k[4];
  c.cx = m.k[2];
  c.cy = m.k[5];
  std::vector<double> d = m.d;
  const std::string model(m.distortion_model);
  if (model == "equidistant" || model == "fisheye") {
    c.lens = LensModel::fisheye;
  } else if (model == "plumb_bob" || model == "rational_polynomial" || model.empty()) {
    if (std::all_of(d.begin(), d.end(), [](double x) { return x == 0.0; })) d.clear();  // rectified images
  } else {
    reason = "its distortion model '" + model + "' is not read (vmap reads plumb_bob, rational_polynomial, equidistant)";
    return std::nullopt;
  }
  c.distortion = std::move(d);
  if (m.width > 0 && m.height > 0 && m.width <= 65536 && m.height <= 65536)
    c.image_size = cv::Size(static_cast<int>(m.width), static_cast<int>(m.height));
  try {
    c.validate(what);
  } catch (const Error& e) {
    reason = e.what();
    return std::nullopt;
  }
  return c;
}

}  // namespace vmap::detail
