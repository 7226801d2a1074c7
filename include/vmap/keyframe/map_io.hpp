#pragma once

// Visual map files: one binary file, written atomically (io/atomic_file.hpp).
//
// Format version 1, in io/binary.hpp's encoding: all integers little-endian and fixed
// width; f32/f64 are IEEE-754 bit patterns stored as little-endian u32/u64; str = u32
// length (<= 4096) + bytes.
//
//   header (24 bytes)
//     u8[8]  magic "VMAPKEYS"
//     u32    version (1)
//     u64    payload size in bytes (must equal the rest of the file)
//     u32    CRC-32 (IEEE 802.3, as zlib) of the payload
//   payload
//     u64    frames n (frames pushed to the selector: eq. 7's n)
//     u32    key images m
//     m x key image
//       u64  frame index (strictly increasing). It is the frame's index in its sequence
//            (Frame::index), not its position among the pushed frames: a map built with
//            a start or a stride has indices >= n, so they are not compared with n.
//       f64  timestamp
//       str  name
//       i32  norm (cv::NORM_HAMMING, NORM_HAMMING2, NORM_L1 or NORM_L2)
//       i32  image width, i32 image height (of the features; >= 0)
//       u32  keypoints k
//       k x  { f32 x, y, size, angle, response; i32 octave, class_id }
//       i32  descriptor type (CV_8UC1 or CV_32FC1), i32 rows (0 or k), i32 cols (0..4096)
//       rows * cols descriptor values, row-major: u8 (CV_8UC1) or f32 (CV_32FC1)
//       u8   has image (0 or 1); if 1: i32 rows, i32 cols, i32 type (CV_8UC1/3/4 or
//            CV_16UC1), u32 length, then a PNG of exactly that size and shape
//     u32    pairs (m - 1, or 0 when m == 0)
//     pairs x { u8 status (VerificationStatus); f64[9] F row-major; i32 matches;
//               i32 inliers (0 <= inliers <= matches); f64 similarity in [0, 1] }
//
// Loading checks every count against the bytes that remain before allocating, so a
// truncated, corrupt or hostile file is a vmap::Error, never a crash or a huge
// allocation; the CRC rejects accidental corruption before anything is parsed. Key
// images are compressed, so their size is bounded separately (MapLoadOptions): the
// PNG header's width x height is checked against the limits before it is decoded.

#include <vmap/core/error.hpp>
#include <vmap/io/atomic_file.hpp>
#include <vmap/io/binary.hpp>
#include <vmap/io/files.hpp>
#include <vmap/io/image.hpp>
#include <vmap/io/timestamps.hpp>
#include <vmap/keyframe/front_end.hpp>
#include <vmap/keyframe/selector.hpp>
#include <vmap/keyframe/visual_map.hpp>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace vmap {

inline constexpr std::uint32_t map_format_version = 1;

/// Limits of `load_map` / `deserialize_map` (a map file is untrusted input), and of a
/// visual memory's key images (`VisualMemory::deserialize` / `load`, `MemoryStore::load`).
struct MapLoadOptions {
  /// Pixels of one key image (default 64 Mi pixels), checked before decoding it.
  std::uint64_t max_image_pixels = default_max_image_pixels;
  /// Pixels of all key images together (default 512 Mi pixels, e.g. 1700 VGA images).
  std::uint64_t max_total_image_pixels = std::uint64_t{1} << 29;
  /// Size of the file (load_map only).
  std::uintmax_t max_file_bytes = default_max_file_bytes;
  /// Visual memories: false leaves the key images' pixels undecoded (their recorded
  /// sizes and encoded headers still checked), for a reader that never shows them; such
  /// a memory refuses to be written with pixels, which it no longer has.
  bool decode_images = true;
};

namespace detail {

inline constexpr char map_magic[8] = {'V', 'M', 'A', 'P', 'K', 'E', 'Y', 'S'};
inline constexpr std::size_t map_header_size = 24;
inline constexpr std::uint32_t map_max_string = 4096;
inline constexpr int map_max_descriptor_cols = 4096;
inline constexpr int map_max_image_side = 16384;

/// A 3x3 model (F, E or H) row-major, as the map file's pairs and the memory's records
/// hold it.
inline void write_matx33(BinaryWriter& w, const cv::Matx33d& m) {
  for (double e : m.val) w.f64(e);
}

inline cv::Matx33d read_matx33(BinaryReader& r, std::string_view what) {
  cv::Matx33d m;
  for (double& e : m.val) {
    e = r.f64(what);
    if (!std::isfinite(e)) r.corrupt(std::string(what) + " is not finite");
  }
  return m;
}

inline VerificationStatus read_verification_status(BinaryReader& r, std::string_view what) {
  const std::uint8_t s = r.u8(what);
  if (s > static_cast<std::uint8_t>(VerificationStatus::too_few_inliers)) r.corrupt("unknown verification status");
  return static_cast<VerificationStatus>(s);
}

/// The selector's link between consecutive key images (KeyPair): the map file's pair
/// record, which the memory's section "link" and its store's links hold too.
inline void write_key_pair(BinaryWriter& w, const KeyPair& p) {
  w.u8(static_cast<std::uint8_t>(p.status));
  write_matx33(w, p.fundamental);
  w.i32(p.matches);
  w.i32(p.inliers);
  w.f64(p.similarity);
}

/// Reads write_key_pair()'s bytes; `status_what` names the status byte in an error.
inline KeyPair read_key_pair(BinaryReader& r, std::string_view status_what) {
  KeyPair pair;
  pair.status = read_verification_status(r, status_what);
  pair.fundamental = read_matx33(r, "fundamental matrix");
  pair.matches = r.i32("matches");
  pair.inliers = r.i32("inliers");
  if (pair.matches < 0 || pair.inliers < 0 || pair.inliers > pair.matches) r.corrupt("invalid match/inlier counts");
  pair.similarity = r.f64("similarity");
  if (!(pair.similarity >= 0.0 && pair.similarity <= 1.0)) r.corrupt("similarity outside [0, 1]");
  return pair;
}

/// The selector's score of its frame I_{j-1} against the key image (SelectorState::
/// previous_score): what the link to the next key image is made of (selector.hpp's
/// add_key). The inlier mask is not written (write_previous_score adds it where a
/// deferred degeneracy test needs it).
inline void write_pair_score(BinaryWriter& w, const PairScore& p) {
  w.i32(p.raw_matches);
  w.f64(p.upper_bound);
  w.u8(p.verified_run ? 1 : 0);
  w.u8(static_cast<std::uint8_t>(p.verification.status));
  write_matx33(w, p.verification.model);
  w.i32(p.verification.inliers);
  w.i32(p.verification.matches);
  w.u8(static_cast<std::uint8_t>(p.verification.degeneracy));
  w.i32(p.verification.homography_inliers);
  w.f64(p.similarity);
}

inline PairScore read_pair_score(BinaryReader& r) {
  PairScore p;
  p.raw_matches = r.i32("raw matches");
  p.upper_bound = r.f64("upper bound");
  const std::uint8_t run = r.u8("verified flag");
  if (run > 1) r.corrupt("verified flag is not 0 or 1");
  p.verified_run = run == 1;
  p.verification.status = read_verification_status(r, "verification status");
  p.verification.model = read_matx33(r, "fundamental matrix");
  p.verification.inliers = r.i32("inliers");
  p.verification.matches = r.i32("matches");
  const std::uint8_t deg = r.u8("degeneracy");
  if (deg > 1) r.corrupt("unknown degeneracy");
  p.verification.degeneracy = static_cast<Degeneracy>(deg);
  p.verification.homography_inliers = r.i32("homography inliers");
  p.similarity = r.f64("similarity");
  if (p.raw_matches < 0 || p.verification.inliers < 0 || p.verification.inliers > p.verification.matches ||
      !std::isfinite(p.upper_bound) || !(p.similarity >= 0.0 && p.similarity <= 1.0))
    r.corrupt("invalid score");
  return p;
}

/// The selector's score of I_{j-1} (SelectorState::previous_score): u8 0 (none) | 1 (a
/// complete score) | 2 (a verified score whose homography degeneracy test is deferred,
/// SelectorState::degeneracy_deferred), then the score, then for 2 the F-matrix's inlier
/// mask that completes it (u32 n = matches, n x u8).
template <class Item>
void write_previous_score(BinaryWriter& w, const SelectorState<Item>& s) {
  w.u8(!s.previous_score ? 0 : s.degeneracy_deferred ? 2 : 1);
  if (!s.previous_score) return;
  write_pair_score(w, *s.previous_score);
  if (!s.degeneracy_deferred) return;
  const Verification& v = s.previous_score->verification;
  w.u32(static_cast<std::uint32_t>(v.inlier_mask.size()));
  for (const std::uint8_t b : v.inlier_mask) w.u8(b);
}

/// Reads write_previous_score()'s bytes into `s`, whose I_{j-1} (`s.previous`) is read.
template <class Item>
void read_previous_score(BinaryReader& r, SelectorState<Item>& s) {
  const std::uint8_t flag = r.u8("previous score flag");
  if (flag > 2 || (flag != 0 && !s.previous)) r.corrupt("invalid previous score flag");
  if (flag == 0) return;
  s.previous_score = read_pair_score(r);
  if (flag == 1) return;
  Verification& v = s.previous_score->verification;
  if (!v.ok() || v.degeneracy != Degeneracy::none || v.homography_inliers != 0)
    r.corrupt("a deferred degeneracy on a score that is not verified or already has one");
  const std::uint32_t n = r.u32("inlier mask length");
  if (n != static_cast<std::uint32_t>(v.matches)) r.corrupt("the inlier mask's length is not the score's matches");
  r.require_items(n, 1, "inlier mask length");  // the matches come from the same bytes: bound before allocating
  v.inlier_mask.resize(n);
  int inliers = 0;
  for (std::uint8_t& b : v.inlier_mask) {
    b = r.u8("inlier mask");
    if (b > 1) r.corrupt("an inlier mask byte is not 0 or 1");
    inliers += b;
  }
  if (inliers != v.inliers) r.corrupt("the inlier mask does not hold the score's inliers");
  s.degeneracy_deferred = true;
}

inline bool valid_image_type(int type) {
  return type == CV_8UC1 || type == CV_8UC3 || type == CV_8UC4 || type == CV_16UC1;
}

inline void write_features(BinaryWriter& w, const Features& f) {
  w.i32(f.norm);
  w.i32(f.image_size.width);
  w.i32(f.image_size.height);
  w.u32(static_cast<std::uint32_t>(f.keypoints.size()));
  for (const auto& k : f.keypoints) {
    w.f32(k.pt.x);
    w.f32(k.pt.y);
    w.f32(k.size);
    w.f32(k.angle);
    w.f32(k.response);
    w.i32(k.octave);
    w.i32(k.class_id);
  }
  const cv::Mat& d = f.descriptors;
  check(d.empty() || d.type() == CV_8UC1 || d.type() == CV_32FC1, [&] {
    return "save_map: descriptors of type " + cv::typeToString(d.type()) + " cannot be stored (CV_8UC1 or CV_32FC1)";
  });
  check(d.empty() || d.rows == static_cast<int>(f.keypoints.size()),
        "save_map: descriptor rows and keypoint count differ");
  w.i32(d.empty() ? CV_8UC1 : d.type());
  w.i32(d.empty() ? 0 : d.rows);
  w.i32(d.empty() ? 0 : d.cols);
  for (int r = 0; r < (d.empty() ? 0 : d.rows); ++r) {
    if (d.type() == CV_8UC1)
      w.bytes(d.ptr(r), static_cast<std::size_t>(d.cols));
    else
      w.f32s(d.ptr<float>(r), static_cast<std::size_t>(d.cols));
  }
}

/// Reads write_features()'s bytes. With `keep` false the keypoints and descriptors are
/// checked for size and skipped, not allocated: Features with only the norm and image
/// size (what a memory keeps in RAM of a key image outside its working memory).
inline Features read_features(BinaryReader& r, bool keep = true) {
  Features f;
  f.norm = r.i32("norm");
  if (f.norm != cv::NORM_HAMMING && f.norm != cv::NORM_HAMMING2 && f.norm != cv::NORM_L1 && f.norm != cv::NORM_L2)
    r.corrupt("unknown descriptor norm " + std::to_string(f.norm));
  f.image_size.width = r.i32("image width");
  f.image_size.height = r.i32("image height");
  if (f.image_size.width < 0 || f.image_size.height < 0 || f.image_size.width > map_max_image_side ||
      f.image_size.height > map_max_image_side)
    r.corrupt("invalid feature image size");
  const std::uint32_t k = r.u32("keypoint count");
  constexpr std::uint64_t keypoint_bytes = 28;
  r.require_items(k, keypoint_bytes, "keypoint count");
  if (!keep) {
    (void)r.bytes(std::uint64_t{k} * keypoint_bytes, "keypoints");
    const int type = r.i32("descriptor type");
    const int rows = r.i32("descriptor rows");
    const int cols = r.i32("descriptor cols");
    if (type != CV_8UC1 && type != CV_32FC1) r.corrupt("descriptor type " + std::to_string(type) + " is not supported");
    if ((rows != 0 && rows != static_cast<int>(k)) || cols < 0 || cols > map_max_descriptor_cols || (rows == 0) != (cols == 0))
      r.corrupt("invalid descriptor size");
    const auto values = static_cast<std::uint64_t>(rows) * static_cast<std::uint64_t>(cols);
    (void)r.bytes(type == CV_8UC1 ? values : values * sizeof(float), "descriptors");
    return f;
  }
  f.keypoints.resize(k);
  for (auto& kp : f.keypoints) {
    kp.pt.x = r.f32("keypoint");
    kp.pt.y = r.f32("keypoint");
    kp.size = r.f32("keypoint");
    kp.angle = r.f32("keypoint");
    kp.response = r.f32("keypoint");
    kp.octave = r.i32("keypoint");
    kp.class_id = r.i32("keypoint");
    if (!std::isfinite(kp.pt.x) || !std::isfinite(kp.pt.y)) r.corrupt("keypoint position is not finite");
  }
  const int type = r.i32("descriptor type");
  const int rows = r.i32("descriptor rows");
  const int cols = r.i32("descriptor cols");
  if (type != CV_8UC1 && type != CV_32FC1) r.corrupt("descriptor type " + std::to_string(type) + " is not supported");
  if (rows != 0 && rows != static_cast<int>(k)) r.corrupt("descriptor rows differ from the keypoint count");
  if (cols < 0 || cols > map_max_descriptor_cols || (rows == 0) != (cols == 0))
    r.corrupt("invalid descriptor width " + std::to_string(cols));
  if (rows > 0) {
    const auto values = static_cast<std::uint64_t>(rows) * static_cast<std::uint64_t>(cols);
    if (type == CV_8UC1) {
      const auto raw = r.bytes(values, "descriptors");
      f.descriptors.create(rows, cols, type);
      std::memcpy(f.descriptors.data, raw.data(), raw.size());
    } else {
      r.require_items(values, sizeof(float), "descriptors");  // before allocating
      f.descriptors.create(rows, cols, type);
      r.f32s(f.descriptors.ptr<float>(), values, "descriptors");
      if (!cv::checkRange(f.descriptors)) r.corrupt("descriptors hold a non-finite value");
    }
  }
  return f;
}

inline void write_image(BinaryWriter& w, const cv::Mat& image) {
  if (image.empty()) {
    w.u8(0);
    return;
  }
  check(valid_image_type(image.type()), [&] {
    return "save_map: key image of type " + cv::typeToString(image.type()) +
           " cannot be stored (8-bit grey/BGR/BGRA or 16-bit grey)";
  });
  std::vector<unsigned char> png;
  if (!cv::imencode(".png", image, png)) fail("save_map: PNG encoding of a key image failed");
  w.u8(1);
  w.i32(image.rows);
  w.i32(image.cols);
  w.i32(image.type());
  w.u32(static_cast<std::uint32_t>(png.size()));
  w.bytes(png.data(), png.size());
}

inline std::uint32_t big_endian32(std::string_view b, std::size_t at) {
  std::uint32_t v = 0;
  for (std::size_t i = 0; i < 4; ++i) v = (v << 8) | static_cast<unsigned char>(b[at + i]);
  return v;
}

/// Reads a stored key image's recorded rows, cols and type and checks them against the
/// load limits, counting its pixels into `total_pixels`: all before anything is decoded,
/// so a file can make the reader allocate no more than the limits state (maps and
/// memories both store key images this way).
inline cv::Size read_key_image_size(BinaryReader& r, const MapLoadOptions& limits, std::uint64_t& total_pixels, int& type) {
  const int rows = r.i32("image rows");
  const int cols = r.i32("image cols");
  type = r.i32("image type");
  if (rows <= 0 || cols <= 0 || rows > map_max_image_side || cols > map_max_image_side)
    r.corrupt("invalid key image size " + std::to_string(cols) + "x" + std::to_string(rows));
  if (!valid_image_type(type)) r.corrupt("invalid key image type " + std::to_string(type));
  const auto pixels = static_cast<std::uint64_t>(rows) * static_cast<std::uint64_t>(cols);
  if (pixels > limits.max_image_pixels)
    r.corrupt("key image of " + std::to_string(cols) + "x" + std::to_string(rows) + " pixels is above the limit of " +
              std::to_string(limits.max_image_pixels) + " pixels (MapLoadOptions::max_image_pixels)");
  total_pixels += pixels;
  if (total_pixels > limits.max_total_image_pixels)
    r.corrupt("the key images hold more than " + std::to_string(limits.max_total_image_pixels) +
              " pixels together (MapLoadOptions::max_total_image_pixels)");
  return {cols, rows};
}

inline cv::Mat read_image(BinaryReader& r, const MapLoadOptions& limits, std::uint64_t& total_pixels) {
  const std::uint8_t has = r.u8("image flag");
  if (has == 0) return {};
  if (has != 1) r.corrupt("image flag is " + std::to_string(has) + ", not 0 or 1");
  int type = 0;
  const cv::Size size = read_key_image_size(r, limits, total_pixels, type);
  const int rows = size.height;
  const int cols = size.width;
  const std::uint32_t len = r.u32("image length");
  const std::string_view png = r.bytes(len, "image");
  // Check the PNG's own header before the decoder sees it, so a hostile size field
  // cannot make it allocate: signature, then IHDR width and height (big-endian).
  static constexpr unsigned char signature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1A, '\n'};
  if (png.size() < 33 || std::memcmp(png.data(), signature, 8) != 0 || png.substr(12, 4) != "IHDR")
    r.corrupt("key image is not a PNG");
  if (big_endian32(png, 16) != static_cast<std::uint32_t>(cols) || big_endian32(png, 20) != static_cast<std::uint32_t>(rows))
    r.corrupt("key image PNG size differs from the recorded size");
  const cv::Mat buf(1, static_cast<int>(png.size()), CV_8UC1, const_cast<char*>(png.data()));
  cv::Mat img;
  try {
    img = cv::imdecode(buf, cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception&) {
    r.corrupt("key image PNG cannot be decoded");
  }
  if (img.empty() || img.rows != rows || img.cols != cols || img.type() != type)
    r.corrupt("key image PNG cannot be decoded to the recorded size and type");
  return img;
}

inline VisualMap parse_map(std::string_view file, const std::string& name, const MapLoadOptions& limits) {
  BinaryReader r(file, "map file '" + name + "'");
  if (file.size() < map_header_size)
    r.corrupt("too short (" + std::to_string(file.size()) + " bytes) to be a vmap map");
  if (r.bytes(8, "magic") != std::string_view(map_magic, 8)) r.corrupt("not a vmap map (wrong magic bytes)");
  const std::uint32_t version = r.u32("version");
  if (version != map_format_version)
    r.fail_here(version > map_format_version ? ErrorKind::unsupported_version : ErrorKind::corrupt,
                "format version " + std::to_string(version) + " is not supported (this build reads " +
                    std::to_string(map_format_version) + ")");
  const std::uint64_t size = r.u64("payload size");
  const std::uint32_t crc = r.u32("checksum");
  if (size != r.remaining())
    r.corrupt("truncated or padded (header says " + std::to_string(size) + " payload bytes, file has " +
              std::to_string(r.remaining()) + ")");
  if (crc32(r.rest()) != crc) r.corrupt("checksum mismatch (the file is corrupt)");

  VisualMap map;
  std::uint64_t total_pixels = 0;
  map.frames = static_cast<std::size_t>(r.u64("frame count"));
  const std::uint32_t m = r.u32("key image count");
  // Each key image takes at least 49 bytes, so m is bounded by the file before any
  // allocation happens (keys are appended one by one).
  r.require_items(m, 49, "key image count");
  if (m > map.frames) r.corrupt(std::to_string(m) + " key images for " + std::to_string(map.frames) + " frames");
  for (std::uint32_t i = 0; i < m; ++i) {
    KeyImage k;
    const std::uint64_t idx = r.u64("frame index");
    if (!map.keys.empty() && idx <= map.keys.back().frame_index) r.corrupt("key image frame indices are not increasing");
    k.frame_index = static_cast<std::size_t>(idx);
    k.timestamp = r.f64("timestamp");
    const auto time_ns = nanoseconds_in_range(k.timestamp);  // a map file keeps seconds only
    if (!time_ns) r.corrupt("key image " + std::to_string(i) + ": " + time_out_of_range(k.timestamp));
    k.time_ns = *time_ns;
    k.name = r.str("name", map_max_string);
    k.features = read_features(r);
    k.image = read_image(r, limits, total_pixels);
    map.keys.push_back(std::move(k));
  }
  const std::uint32_t p = r.u32("pair count");
  if (p != (m == 0 ? 0U : m - 1U)) r.corrupt("pair count " + std::to_string(p) + " does not match " + std::to_string(m) + " key images");
  for (std::uint32_t i = 0; i < p; ++i) map.pairs.push_back(read_key_pair(r, "pair status"));
  r.expect_end("the last pair");
  return map;
}

}  // namespace detail

/// The map file's bytes (format above). Images are stored when the key images carry them.
[[nodiscard]] inline std::string serialize_map(const VisualMap& map) {
  detail::check(map.pairs.size() == (map.keys.empty() ? 0 : map.keys.size() - 1), [&] {
    return "save_map: the map has " + std::to_string(map.pairs.size()) + " pairs for " +
           std::to_string(map.keys.size()) + " key images";
  });
  detail::BinaryWriter w;
  w.u64(map.frames);
  w.u32(static_cast<std::uint32_t>(map.keys.size()));
  for (const auto& k : map.keys) {
    w.u64(k.frame_index);
    w.f64(k.timestamp);
    w.str(k.name, detail::map_max_string, "save_map: a key image name");
    detail::write_features(w, k.features);
    detail::write_image(w, k.image);
  }
  w.u32(static_cast<std::uint32_t>(map.pairs.size()));
  for (const auto& p : map.pairs) detail::write_key_pair(w, p);
  const std::string payload = std::move(w).take();
  detail::BinaryWriter h;
  h.bytes(detail::map_magic, 8);
  h.u32(map_format_version);
  h.u64(payload.size());
  h.u32(detail::crc32(payload));
  h.bytes(payload);
  return std::move(h).take();
}

/// Parses map bytes; `name` is used in error messages. Throws vmap::Error for anything
/// that is not a valid version-1 map.
[[nodiscard]] inline VisualMap deserialize_map(std::string_view bytes, const std::string& name = "<memory>",
                                               const MapLoadOptions& limits = {}) {
  return detail::parse_map(bytes, name, limits);
}

/// Writes the map to `path` atomically (temp file + rename).
inline void save_map(const VisualMap& map, const std::filesystem::path& path) {
  write_file_atomically(path, serialize_map(map));
}

/// Reads a map file. Errors (vmap::Error naming the file): missing, a folder or device,
/// unreadable, corrupt, or above the limits.
[[nodiscard]] inline VisualMap load_map(const std::filesystem::path& path, const MapLoadOptions& limits = {}) {
  return detail::parse_map(read_file(path, limits.max_file_bytes, "map file"), path.string(), limits);
}

}  // namespace vmap
