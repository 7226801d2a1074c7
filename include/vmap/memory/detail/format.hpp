#pragma once

// What the single-file format (memory/vmem.hpp) and the memory store (memory/store.hpp)
// share of the encoding: the header's constants, the section framing (tag, length, CRC;
// each section read by a reader that names it) and the codecs of the values several
// records hold (detections, poses, images, links; memory/detail/record_codecs.hpp
// composes them). The format itself is described in memory/vmem.hpp.

#include <vmap/core/concepts.hpp>
#include <vmap/core/error.hpp>
#include <vmap/core/verification.hpp>
#include <vmap/geometry/pose2.hpp>
#include <vmap/hooks/detection.hpp>
#include <vmap/io/binary.hpp>
#include <vmap/io/image.hpp>
#include <vmap/keyframe/map_io.hpp>
#include <vmap/memory/types.hpp>

#include <opencv2/core.hpp>
#include <opencv2/core/affine.hpp>
#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <variant>
#include <vector>

namespace vmap {

namespace detail {

inline constexpr char memory_magic[8] = {'V', 'M', 'A', 'P', 'M', 'E', 'M', 'O'};
/// The application id a memory store's creation writes into its SQLite header (PRAGMA
/// application_id, "VMAP"): what memory_kind (memory/replace.hpp) knows a store by.
inline constexpr std::uint32_t memory_application_id = 0x564D4150;
inline constexpr std::uint32_t memory_sections_v1 = 7;
inline constexpr std::uint32_t memory_sections_v2 = 10;
inline constexpr std::uint32_t memory_sections_v3 = 11;
inline constexpr std::uint32_t memory_sections = 12;
/// Longest policy description a file may hold.
inline constexpr std::uint32_t memory_max_policy = 4096;
/// Most detections one key image may have in a file (a detector gives a few hundred).
inline constexpr std::uint32_t memory_max_detections = 1U << 16;
/// The most frames a memory file may say were pushed: 2^40, 348 years at 100 frames a
/// second. A larger count is a damaged or crafted file, not a robot's.
inline constexpr std::uint64_t memory_max_frames = std::uint64_t{1} << 40;

// What the file records of a policy (section "plcy"): its own description
// (core/concepts.hpp, DescribesItself), so that a mismatch on load reads as it is; a
// policy that does not describe itself is recorded as "" (not recorded, not checked).
template <class P>
std::string memory_policy_record(const P& policy) {
  if constexpr (DescribesItself<P>)
    return std::string(policy.describe());
  else
    return {};
}

inline void memory_write_detections(BinaryWriter& w, const std::vector<Detection>& d) {
  if (d.size() > memory_max_detections)
    fail("VisualMemory::save: a key image has " + std::to_string(d.size()) + " detections, more than " +
         std::to_string(memory_max_detections));
  w.u32(static_cast<std::uint32_t>(d.size()));
  for (const Detection& x : d) {
    w.i32(x.label);
    w.f32(x.score);
    w.f32(x.box.x);
    w.f32(x.box.y);
    w.f32(x.box.width);
    w.f32(x.box.height);
  }
}

inline std::vector<Detection> memory_read_detections(BinaryReader& r) {
  const std::uint32_t n = r.u32("detection count");
  if (n > memory_max_detections) r.corrupt(std::to_string(n) + " detections in one key image");
  r.require_items(n, 24, "detection count");
  std::vector<Detection> out(n);
  for (Detection& d : out) {
    d.label = r.i32("detection label");
    d.score = r.f32("detection score");
    d.box.x = r.f32("detection box");
    d.box.y = r.f32("detection box");
    d.box.width = r.f32("detection box");
    d.box.height = r.f32("detection box");
    if (!(d.score >= 0.0f && d.score <= 1.0f)) r.corrupt("a detection score is not in [0, 1]");
    if (!std::isfinite(d.box.x) || !std::isfinite(d.box.y) || !std::isfinite(d.box.width) ||
        !std::isfinite(d.box.height))
      r.corrupt("a detection box is not finite");
  }
  return out;
}

inline void write_memory_image(BinaryWriter& w, const cv::Mat& image, ImageStorage storage, int quality) {
  if (image.empty() || storage == ImageStorage::none) {
    w.u8(0);
    return;
  }
  check(valid_image_type(image.type()) && (storage == ImageStorage::png || image.depth() == CV_8U),
        "VisualMemory::save: a key image of type " + cv::typeToString(image.type()) + " cannot be stored as " +
            (storage == ImageStorage::png ? "PNG" : "JPEG"));
  std::vector<unsigned char> buf;
  const bool png = storage == ImageStorage::png;
  const std::vector<int> params = png ? std::vector<int>{} : std::vector<int>{cv::IMWRITE_JPEG_QUALITY, quality};
  if (!cv::imencode(png ? ".png" : ".jpg", image, buf, params)) fail("VisualMemory::save: encoding a key image failed");
  w.u8(png ? 1 : 2);
  w.i32(image.rows);
  w.i32(image.cols);
  w.i32(image.type());
  w.u32(static_cast<std::uint32_t>(buf.size()));
  w.bytes(buf.data(), buf.size());
}

/// A key image's pixels (none, PNG or JPEG); with MapLoadOptions::decode_images false the
/// encoded image is checked but not decoded, and `skipped` (when given) is set.
inline cv::Mat read_memory_image(BinaryReader& r, const MapLoadOptions& limits, std::uint64_t& total_pixels,
                                 bool* skipped = nullptr) {
  const std::uint8_t kind = r.u8("image kind");
  if (kind == 0) return {};
  if (kind > 2) r.corrupt("image kind " + std::to_string(kind) + " is not 0, 1 or 2");
  int type = 0;
  const cv::Size size = read_key_image_size(r, limits, total_pixels, type);
  const int rows = size.height;
  const int cols = size.width;
  if (kind == 2 && CV_MAT_DEPTH(type) != CV_8U) r.corrupt("invalid key image type " + std::to_string(type));
  const std::uint32_t len = r.u32("image length");
  const std::string_view bytes = r.bytes(len, "image");
  // The encoded header's size is checked before decoding, so a hostile file cannot make
  // the decoder allocate more than the recorded (bounded) size.
  const auto header = image_header_size(bytes);
  if (!header || header->width != cols || header->height != rows)
    r.corrupt("key image is not a " + std::string(kind == 1 ? "PNG" : "JPEG") + " of the recorded size");
  if (!limits.decode_images) {
    if (skipped) *skipped = true;
    return {};
  }
  const cv::Mat buf(1, static_cast<int>(bytes.size()), CV_8UC1, const_cast<char*>(bytes.data()));
  cv::Mat img;
  try {
    img = cv::imdecode(buf, cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception&) {
    r.corrupt("key image cannot be decoded");
  }
  if (img.empty() || img.rows != rows || img.cols != cols || img.type() != type)
    r.corrupt("key image cannot be decoded to the recorded size and type");
  return img;
}

inline void memory_write_pose(BinaryWriter& w, const OdometryPose& p) {
  if (const auto* p2 = std::get_if<Pose2>(&p)) {
    w.u8(1);
    w.f64(p2->x());
    w.f64(p2->y());
    w.f64(p2->theta());
  } else if (const auto* p3 = std::get_if<cv::Affine3d>(&p)) {
    w.u8(2);
    for (int i = 0; i < 12; ++i) w.f64(p3->matrix.val[i]);
  } else {
    w.u8(0);
  }
}

/// Largest deviation of an SE(3) pose's rotation from orthonormal (max |R^T R - I|)
/// that a push accepts: poses read from text files keep 6-7 digits (KITTI's files give
/// deviations near 1e-6), while anything else is not a rotation.
inline constexpr double memory_rotation_tolerance = 1e-4;

/// Checks a frame and its pose as they enter a memory, before anything changes: every
/// value a push accepts is one the memory writes and reads back, so a bad value is an
/// Error naming it here instead of a sync that fails, or a memory that no longer opens,
/// later. `last_in_session` is the last frame index pushed into the current session.
/// (A Frame's fields, io/frame.hpp, given one by one: this header stays light.)
struct PushedFrame {
  const cv::Mat& image;
  std::size_t index;
  const std::string& name;
  double timestamp;
};
inline void check_pushed_frame(const PushedFrame& f, const OdometryPose& pose,
                               std::optional<std::size_t> last_in_session) {
  const auto fail_with = [&](const std::string& what) {
    const bool named = !f.name.empty() && f.name.size() <= 256 && f.name.find('\0') == std::string::npos;
    fail("VisualMemory::push: frame " + std::to_string(f.index) + (named ? " ('" + f.name + "')" : std::string()) +
         ": " + what);
  };
  if (f.image.empty()) fail_with("the image is empty");
  if (static_cast<std::uint64_t>(f.image.total()) > default_max_image_pixels)
    fail_with("the image has " + std::to_string(f.image.cols) + "x" + std::to_string(f.image.rows) +
              " pixels, more than the limit of " + std::to_string(default_max_image_pixels));
  if (f.index > memory_max_frames) fail_with("the frame index is above 2^40");
  if (last_in_session && f.index <= *last_in_session)
    fail_with("frame indices must increase within a session (the last frame pushed is " +
              std::to_string(*last_in_session) + "; start_session() begins a new run)");
  if (!std::isfinite(f.timestamp)) fail_with("the timestamp is not finite");
  if (f.name.size() > map_max_string)
    fail_with("the name is " + std::to_string(f.name.size()) + " bytes long, more than the " +
              std::to_string(map_max_string) + " a memory keeps");
  if (f.name.find('\0') != std::string::npos) fail_with("the name holds a NUL character");
  // (A Pose2 is finite by construction.)
  if (const auto* p3 = std::get_if<cv::Affine3d>(&pose)) {
    for (int i = 0; i < 12; ++i)
      if (!std::isfinite(p3->matrix.val[i])) fail_with("the SE(3) pose is not finite");
    const cv::Matx33d R = p3->rotation();
    const cv::Matx33d e = R.t() * R - cv::Matx33d::eye();
    double worst = 0.0;
    for (int i = 0; i < 9; ++i) worst = std::max(worst, std::abs(e.val[i]));
    if (worst > memory_rotation_tolerance || cv::determinant(R) <= 0.0)
      fail_with("the SE(3) pose's 3x3 part is not a rotation (R^T R differs from I by " + std::to_string(worst) +
                ", det " + std::to_string(cv::determinant(R)) + ")");
  }
}

inline OdometryPose memory_read_pose(BinaryReader& r) {
  const std::uint8_t kind = r.u8("pose kind");
  if (kind == 0) return {};
  if (kind == 1) {
    const double x = r.f64("pose"), y = r.f64("pose"), t = r.f64("pose");
    if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(t)) r.corrupt("SE(2) pose is not finite");
    return Pose2(x, y, t);
  }
  if (kind != 2) r.corrupt("pose kind " + std::to_string(kind) + " is not 0, 1 or 2");
  cv::Matx44d m = cv::Matx44d::eye();
  for (int i = 0; i < 12; ++i) {
    m.val[i] = r.f64("pose");
    if (!std::isfinite(m.val[i])) r.corrupt("SE(3) pose is not finite");
  }
  return cv::Affine3d(m);
}

inline void memory_write_link(BinaryWriter& w, const PlaceLink& l) {
  w.f64(l.bow_score);
  w.u8(static_cast<std::uint8_t>(l.status));
  write_matx33(w, l.model);
  w.i32(l.matches);
  w.i32(l.inliers);
  w.f64(l.similarity);
}

inline PlaceLink memory_read_link(BinaryReader& r) {
  PlaceLink l;
  l.bow_score = r.f64("BoW score");
  if (!(l.bow_score >= 0.0 && l.bow_score <= 1.0 + 1e-9)) r.corrupt("BoW score outside [0, 1]");
  l.status = read_verification_status(r, "verification status");
  l.model = read_matx33(r, "model matrix");
  l.matches = r.i32("matches");
  l.inliers = r.i32("inliers");
  if (l.matches < 0 || l.inliers < 0 || l.inliers > l.matches) r.corrupt("invalid match/inlier counts");
  l.similarity = r.f64("similarity");
  if (!(l.similarity >= 0.0 && l.similarity <= 1.0)) r.corrupt("similarity outside [0, 1]");
  return l;
}

/// Sections: tag + length + CRC, each read by a reader that names it.
class MemorySectionWriter {
 public:
  void add(const char (&tag)[5], const std::string& bytes) {
    out_.bytes(tag, 4);
    out_.u64(bytes.size());
    out_.u32(crc32(bytes));
    out_.bytes(bytes);
  }
  BinaryWriter out_;
};

inline BinaryReader memory_open_section(BinaryReader& file, const char (&tag)[5]) {
  const std::string name = file.source() + " section '" + std::string(tag, 4) + "'";
  const std::size_t at = file.offset();
  if (file.remaining() < 16)
    fail(ErrorKind::corrupt, name + ": truncated (the file ends at byte " + std::to_string(at + file.remaining()) + " inside its header)");
  if (file.bytes(4, "section tag") != std::string_view(tag, 4))
    fail(ErrorKind::corrupt, name + ": missing (another tag at byte " + std::to_string(at) + ")");
  const std::uint64_t len = file.u64("section length");
  const std::uint32_t crc = file.u32("section checksum");
  if (len > file.remaining())
    fail(ErrorKind::corrupt, name + ": truncated (" + std::to_string(len) + " bytes announced, " + std::to_string(file.remaining()) +
         " left)");
  const std::size_t base = file.offset();
  const std::string_view bytes = file.bytes(len, "section");
  if (crc32(bytes) != crc) fail(ErrorKind::corrupt, name + ": checksum mismatch (the file is corrupt)");
  return BinaryReader(bytes, name, base);
}

}  // namespace detail

}  // namespace vmap
