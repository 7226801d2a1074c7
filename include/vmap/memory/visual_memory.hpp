#pragma once

// One visual memory a robot keeps (DESIGN.md sec. 1.4): frames are pushed one by one;
// the key-image selector (Algorithm 1 / eq. 6 of García-Pintos et al. 2023, unchanged:
// keyframe/selector.hpp) keeps key images; each new key image is described by its bag of
// words (TF-IDF over a vocabulary tree, place/) from the features the selector already
// extracted, ranked against the earlier key images in an inverted-file database and the
// best few are verified by the selector's own matcher and F-matrix estimator: a verified
// one is a loop edge. The key images, the chain of F-matrix links and the loop edges form
// a graph (neighbours()). localize(image) answers the visual-map paper's localization
// stage (sec. 1): the key image(s) a query image matches, verified by an F-matrix.
//
// The whole state saves to one file and loads back; push() after load() continues
// exactly as the uninterrupted run would (same key images, same loops).
//
// Memory file format, version 1 (io/binary.hpp's encoding: little-endian fixed width,
// f32/f64 as IEEE-754 bit patterns, str = u32 length + bytes):
//   header: u8[8] magic "VMAPMEMO", u32 version (1), u32 section count
//   sections, in this order, each { u8[4] tag, u64 length, u32 CRC-32 of the bytes, bytes }:
//     "opts" options: f64 tau, u8 rule, u8 skip_by_upper_bound, u8 images, i32 jpeg quality,
//            u64 vocabulary_after, i32 branching, i32 depth, i32 iterations,
//            u64 max_descriptors, u64 seed, u8 scoring, u64 exclude_recent,
//            u64 loop_candidates, i32 min_loop_inliers, u64 localize_candidates,
//            i32 min_localize_inliers
//     "keys" u64 frames pushed, u32 key images m, m x { u64 frame index (increasing),
//            f64 timestamp, str name, features (keyframe/map_io.hpp's layout), image, pose }
//            image = u8 0 (none) | 1 (PNG) | 2 (JPEG), then i32 rows, i32 cols, i32 type,
//            u32 length, the encoded bytes; pose = u8 0 (none) | 1 (SE(2): f64 x, y, theta)
//            | 2 (SE(3): f64[12], the rows of [R | t])
//     "link" u32 pairs (m - 1), each { u8 status, f64[9] F, i32 matches, i32 inliers, f64 S }
//     "loop" u32 edges, each { u32 from, u32 to (< from), f64 BoW score, u8 status,
//            f64[9] F (x_from^T F x_to = 0), i32 matches, i32 inliers, f64 S }
//     "selc" the selector's I_{j-1}: u8 has; if 1: u64 index, f64 timestamp, str name,
//            features, image, pose; then u8 has score; if 1: i32 raw matches, f64 bound,
//            u8 verified run, u8 status, f64[9] F, i32 inliers, i32 matches, u8 degeneracy,
//            i32 homography inliers, f64 S. Then u8 has last; if 1: u64 the index of the
//            last pushed frame (where a resumed stream goes on).
//     "voca" u8 has vocabulary; if 1: u64 length + the vocabulary file (place/vocabulary.hpp)
//     "plcd" u64 length + the place database file (place/database.hpp), ids = key indices
// Each section is parsed by its own reader, so every error names its section; counts
// are checked against the bytes that remain before anything is allocated.
//
// Bytes per key image (ORB 1000, 32-byte descriptors): 28 per keypoint + 32 per
// descriptor, about 60 KB of features in the file and in memory (measured by
// bench_memory: 61.4 KB per key image of the whole file on tum_fr1_rpy, 31.8 KB on
// rtabmap_loop's 512x384 frames), about 8 B per distinct word in the place database,
// 97 B per link and per loop edge, and the image when kept (640x480 grey: about +143 KB
// as PNG, +50 KB as JPEG quality 90). Nothing is kept for frames that are not key images
// except the one I_{j-1} of eq. 6.
//
// Threading: push() and localize() modify scratch state of the descriptor and must not
// run concurrently on one object; const members only read. The memory is move-only (a
// copy would share the descriptor's detector); separate objects (e.g. each thread
// loading the same file) share nothing.

#include <vmap/core/concepts.hpp>
#include <vmap/core/error.hpp>
#include <vmap/core/features.hpp>
#include <vmap/geometry/pose2.hpp>
#include <vmap/io/atomic_file.hpp>
#include <vmap/io/binary.hpp>
#include <vmap/io/files.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/io/image.hpp>
#include <vmap/keyframe/map_io.hpp>
#include <vmap/keyframe/selector.hpp>
#include <vmap/place/bow.hpp>
#include <vmap/place/database.hpp>
#include <vmap/place/vocabulary.hpp>

#include <opencv2/core.hpp>
#include <opencv2/core/affine.hpp>
#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <type_traits>
#include <utility>
#include <variant>
#include <vector>

namespace vmap {

inline constexpr std::uint32_t memory_format_version = 1;

/// How key images' pixels are kept and saved.
enum class ImageStorage : std::uint8_t {
  none,  ///< features only (the smallest memory; localize and loops need no pixels)
  png,   ///< lossless
  jpeg,  ///< lossy, MemoryOptions::jpeg_quality (about 8x smaller than PNG)
};

/// An odometry pose given with a frame: none, SE(2) (a ground robot) or SE(3).
using OdometryPose = std::variant<std::monostate, Pose2, cv::Affine3d>;

struct MemoryOptions {
  /// The key-image selector's options (tau, eq. 6 / Algorithm 1 rule, fast path).
  /// `keep_images` is set from `images`.
  SelectorOptions selector{};
  ImageStorage images = ImageStorage::none;
  int jpeg_quality = 90;  ///< 1..100, for ImageStorage::jpeg
  /// Without a vocabulary given to the constructor, one is learned from the descriptors
  /// of the first `vocabulary_after` key images (>= 1); loop detection then runs for
  /// those in order, as if the vocabulary had been there from the start.
  std::size_t vocabulary_after = 20;
  /// The learned vocabulary's shape (DBoW2-like tree; default 10^3 words, seeded).
  VocabularyTreeOptions vocabulary{};
  BowScoring scoring = BowScoring::l1;
  /// The key images just before a new one (trivially similar) are not loop candidates.
  std::size_t exclude_recent = 10;
  /// Loop detection verifies the best `loop_candidates` key images by BoW score (>= 1).
  std::size_t loop_candidates = 5;
  /// A loop edge needs a verified F-matrix with at least this many inliers (>= 8).
  int min_loop_inliers = 40;
  /// localize() verifies the best `localize_candidates` key images by BoW score (>= 1).
  std::size_t localize_candidates = 5;
  /// A localization answer needs a verified F-matrix with at least this many inliers.
  int min_localize_inliers = 20;
};

/// A verified match between two key images (a loop edge) or a query and a key image.
struct PlaceLink {
  std::uint32_t key = 0;        ///< the matched key image (the older one for a loop)
  double bow_score = 0.0;       ///< its rank score (place/bow.hpp), in [0, 1]
  VerificationStatus status = VerificationStatus::too_few_matches;
  cv::Matx33d fundamental = cv::Matx33d::zeros();  ///< x_query^T F x_key = 0 (when verified)
  int matches = 0;                                 ///< raw correspondences
  int inliers = 0;                                 ///< F-matrix inliers
  double similarity = 0.0;                         ///< eq. 5
};

/// A loop closure: key image `from` (the newer) revisits key image `link.key`.
struct LoopEdge {
  std::uint32_t from = 0;
  PlaceLink link;
};

/// What push() did: the selector's answer, the key image it added, the loops found.
struct MemoryStep {
  FrameResult frame;
  std::optional<std::uint32_t> new_key;  ///< index of the key image added, if any
  std::vector<LoopEdge> loops;           ///< loop edges found in this step
};

enum class LocalizeStatus : std::uint8_t {
  localized,     ///< at least one key image verified
  empty_memory,  ///< no key image yet
  no_features,   ///< the query has no features
  not_verified,  ///< candidates were ranked, none passed the F-matrix check
};

[[nodiscard]] constexpr std::string_view to_string(LocalizeStatus s) noexcept {
  switch (s) {
    case LocalizeStatus::localized: return "localized";
    case LocalizeStatus::empty_memory: return "the memory has no key image";
    case LocalizeStatus::no_features: return "the query image has no features";
    case LocalizeStatus::not_verified: return "no candidate passed the F-matrix check";
  }
  return "unknown";
}

/// localize()'s answer: verified key images, most inliers first.
struct MemoryLocalization {
  LocalizeStatus status = LocalizeStatus::empty_memory;
  std::vector<PlaceLink> matches;
  std::size_t verified_candidates = 0;  ///< key images the estimator ran on
  [[nodiscard]] bool ok() const noexcept { return status == LocalizeStatus::localized; }
  [[nodiscard]] const PlaceLink* best() const noexcept { return matches.empty() ? nullptr : &matches.front(); }
};

/// A neighbour of a key image in the memory's graph.
struct GraphNeighbour {
  enum class Kind : std::uint8_t { link, loop };
  std::uint32_t key = 0;
  Kind kind = Kind::link;
};

namespace detail {

inline constexpr char memory_magic[8] = {'V', 'M', 'A', 'P', 'M', 'E', 'M', 'O'};
inline constexpr std::uint32_t memory_sections = 7;

inline void memory_write_matx(BinaryWriter& w, const cv::Matx33d& m) {
  for (double e : m.val) w.f64(e);
}

inline cv::Matx33d memory_read_matx(BinaryReader& r, std::string_view what) {
  cv::Matx33d m;
  for (double& e : m.val) {
    e = r.f64(what);
    if (!std::isfinite(e)) r.corrupt(std::string(what) + " is not finite");
  }
  return m;
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

inline cv::Mat read_memory_image(BinaryReader& r) {
  const std::uint8_t kind = r.u8("image kind");
  if (kind == 0) return {};
  if (kind > 2) r.corrupt("image kind " + std::to_string(kind) + " is not 0, 1 or 2");
  const int rows = r.i32("image rows");
  const int cols = r.i32("image cols");
  const int type = r.i32("image type");
  if (rows <= 0 || cols <= 0 || rows > map_max_image_side || cols > map_max_image_side)
    r.corrupt("invalid key image size " + std::to_string(cols) + "x" + std::to_string(rows));
  if (!valid_image_type(type) || (kind == 2 && CV_MAT_DEPTH(type) != CV_8U))
    r.corrupt("invalid key image type " + std::to_string(type));
  const std::uint32_t len = r.u32("image length");
  const std::string_view bytes = r.bytes(len, "image");
  // The encoded header's size is checked before decoding, so a hostile file cannot make
  // the decoder allocate more than the recorded (bounded) size.
  const auto header = image_header_size(bytes);
  if (!header || header->width != cols || header->height != rows)
    r.corrupt("key image is not a " + std::string(kind == 1 ? "PNG" : "JPEG") + " of the recorded size");
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
  memory_write_matx(w, l.fundamental);
  w.i32(l.matches);
  w.i32(l.inliers);
  w.f64(l.similarity);
}

inline VerificationStatus memory_read_status(BinaryReader& r) {
  const std::uint8_t s = r.u8("verification status");
  if (s > static_cast<std::uint8_t>(VerificationStatus::too_few_inliers)) r.corrupt("unknown verification status");
  return static_cast<VerificationStatus>(s);
}

inline PlaceLink memory_read_link(BinaryReader& r) {
  PlaceLink l;
  l.bow_score = r.f64("BoW score");
  if (!(l.bow_score >= 0.0 && l.bow_score <= 1.0 + 1e-9)) r.corrupt("BoW score outside [0, 1]");
  l.status = memory_read_status(r);
  l.fundamental = memory_read_matx(r, "fundamental matrix");
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
    fail(name + ": truncated (the file ends at byte " + std::to_string(at + file.remaining()) + " inside its header)");
  if (file.bytes(4, "section tag") != std::string_view(tag, 4))
    fail(name + ": missing (another tag at byte " + std::to_string(at) + ")");
  const std::uint64_t len = file.u64("section length");
  const std::uint32_t crc = file.u32("section checksum");
  if (len > file.remaining())
    fail(name + ": truncated (" + std::to_string(len) + " bytes announced, " + std::to_string(file.remaining()) +
         " left)");
  const std::size_t base = file.offset();
  const std::string_view bytes = file.bytes(len, "section");
  if (crc32(bytes) != crc) fail(name + ": checksum mismatch (the file is corrupt)");
  return BinaryReader(bytes, name, base);
}

}  // namespace detail

/// The memory over the paper's feature stack (Descriptor, Matcher, Estimator,
/// Similarity; keyframe/selector.hpp).
template <Descriptor D, Matcher M, Estimator E, Similarity S>
class VisualMemory {
 public:
  using Selector = KeyframeSelector<D, M, E, S>;

  /// `vocabulary`: a vocabulary for the descriptors' kind (binary / float), or empty to
  /// learn one from the first MemoryOptions::vocabulary_after key images.
  explicit VisualMemory(D descriptor = D(), M matcher = M(), E estimator = E(), S similarity = S(),
                        const MemoryOptions& options = {}, AnyVocabulary vocabulary = {})
      : options_(checked(options)),
        selector_(std::move(descriptor), std::move(matcher), std::move(estimator), std::move(similarity),
                  selector_options(options_)),
        vocabulary_(std::move(vocabulary)),
        database_(vocabulary_.size(), options_.scoring) {}

  explicit VisualMemory(const MemoryOptions& options, AnyVocabulary vocabulary = {})
      : VisualMemory(D{}, M{}, E{}, S{}, options, std::move(vocabulary)) {}

  // Move-only: a copy would share the descriptor's detector (OrbDescriptor holds a
  // cv::Ptr<cv::ORB> with scratch buffers), so two copies used from two threads would
  // race. Two threads each load their own memory from the file instead.
  VisualMemory(VisualMemory&&) noexcept(std::is_nothrow_move_constructible_v<Selector>) = default;
  VisualMemory& operator=(VisualMemory&&) noexcept(std::is_nothrow_move_assignable_v<Selector>) = default;
  VisualMemory(const VisualMemory&) = delete;
  VisualMemory& operator=(const VisualMemory&) = delete;
  ~VisualMemory() = default;

  /// Pushes a frame of a sequence (its index is its place in the sequence).
  MemoryStep push(const Frame& frame, const OdometryPose& pose = {}) {
    MemoryStep step;
    step.frame = selector_.push(frame);
    after_push(step, frame.index, pose);
    return step;
  }

  /// Pushes a bare image: its index is the number of frames pushed so far; the timestamp
  /// defaults to that index.
  MemoryStep push(const cv::Mat& image, std::optional<double> timestamp = {}, const OdometryPose& pose = {}) {
    Frame f;
    f.image = image;
    f.index = frames();
    f.name = "frame#" + std::to_string(f.index);
    f.timestamp = timestamp.value_or(static_cast<double>(f.index));
    return push(f, pose);
  }

  /// The key image(s) `image` matches (visual-map paper, sec. 1): key images ranked by
  /// BoW score (every key image while no vocabulary exists yet), the best
  /// `localize_candidates` verified by an F-matrix; those with at least
  /// `min_localize_inliers` inliers, most inliers first.
  [[nodiscard]] MemoryLocalization localize(const cv::Mat& image) {
    detail::check(!image.empty(), "VisualMemory::localize: the query image is empty");
    MemoryLocalization out;
    const VisualMap& map = selector_.map();
    if (map.keys.empty()) return out;
    const Features q = selector_.front_end().descriptor().extract(image);
    if (q.empty()) {
      out.status = LocalizeStatus::no_features;
      return out;
    }
    for (const auto& [key, score] : rank(q.descriptors, options_.localize_candidates, map.keys.size())) {
      PlaceLink l = verify(key, score, q);
      ++out.verified_candidates;
      if (l.status == VerificationStatus::verified && l.inliers >= options_.min_localize_inliers)
        out.matches.push_back(l);
    }
    std::stable_sort(out.matches.begin(), out.matches.end(),
                     [](const PlaceLink& a, const PlaceLink& b) { return a.inliers > b.inliers; });
    out.status = out.matches.empty() ? LocalizeStatus::not_verified : LocalizeStatus::localized;
    return out;
  }

  /// Key images linked to `key`: the chain neighbours (key - 1, key + 1), then loop edges.
  [[nodiscard]] std::vector<GraphNeighbour> neighbours(std::uint32_t key) const {
    const std::size_t m = selector_.map().keys.size();
    detail::check(key < m,
                  [&] { return "VisualMemory::neighbours: key " + std::to_string(key) + " of " + std::to_string(m); });
    std::vector<GraphNeighbour> out;
    if (key > 0) out.push_back({key - 1, GraphNeighbour::Kind::link});
    if (key + 1 < m) out.push_back({key + 1, GraphNeighbour::Kind::link});
    for (const auto& e : loops_) {
      if (e.from == key) out.push_back({e.link.key, GraphNeighbour::Kind::loop});
      if (e.link.key == key) out.push_back({e.from, GraphNeighbour::Kind::loop});
    }
    return out;
  }

  [[nodiscard]] const VisualMap& map() const noexcept { return selector_.map(); }
  [[nodiscard]] std::size_t frames() const noexcept { return selector_.map().frames; }
  [[nodiscard]] std::size_t key_images() const noexcept { return selector_.map().keys.size(); }
  /// The index of the last frame pushed (nullopt before the first): a program that
  /// resumes a stream from a saved memory goes on with the frames after it.
  [[nodiscard]] std::optional<std::size_t> last_frame_index() const noexcept { return last_index_; }
  [[nodiscard]] const std::vector<LoopEdge>& loops() const noexcept { return loops_; }
  /// Odometry poses of the key images (std::monostate where none was given).
  [[nodiscard]] const std::vector<OdometryPose>& poses() const noexcept { return poses_; }
  [[nodiscard]] const AnyVocabulary& vocabulary() const noexcept { return vocabulary_; }
  [[nodiscard]] const PlaceDatabase<std::uint32_t>& database() const noexcept { return database_; }
  [[nodiscard]] const MemoryOptions& options() const noexcept { return options_; }
  [[nodiscard]] Selector& selector() noexcept { return selector_; }

  /// The memory file's bytes (format at the top of this header). `images` overrides
  /// MemoryOptions::images for this file (e.g. none for a small copy; png or jpeg store
  /// only the pixels the memory kept).
  [[nodiscard]] std::string serialize(std::optional<ImageStorage> images = {}) const {
    const ImageStorage storage = images.value_or(options_.images);
    detail::MemorySectionWriter s;
    s.add("opts", options_bytes(storage));
    s.add("keys", keys_bytes(storage));
    s.add("link", links_bytes());
    s.add("loop", loops_bytes());
    s.add("selc", selector_bytes(storage));
    detail::BinaryWriter v;
    v.u8(vocabulary_.empty() ? 0 : 1);
    if (!vocabulary_.empty()) {
      const std::string bytes = vocabulary_.binary() ? vocabulary_.binary()->serialize() : vocabulary_.floating()->serialize();
      v.u64(bytes.size());
      v.bytes(bytes);
    }
    s.add("voca", std::move(v).take());
    detail::BinaryWriter d;
    const std::string db = database_.serialize();
    d.u64(db.size());
    d.bytes(db);
    s.add("plcd", std::move(d).take());
    detail::BinaryWriter h;
    h.bytes(detail::memory_magic, 8);
    h.u32(memory_format_version);
    h.u32(detail::memory_sections);
    h.bytes(s.out_.data());
    return std::move(h).take();
  }

  /// Writes the memory atomically (temporary file, fsync, rename, fsync of the folder):
  /// a crash during save leaves the previous file as it was.
  void save(const std::filesystem::path& path, std::optional<ImageStorage> images = {}) const {
    write_file_atomically(path, serialize(images));
  }

  /// Parses a memory file's bytes; the policies are the caller's (their options are not
  /// in the file), the options are the file's. Anything invalid is a vmap::Error naming
  /// the file and the section.
  [[nodiscard]] static VisualMemory deserialize(std::string_view bytes, const std::string& name = "<memory>",
                                                D descriptor = D(), M matcher = M(), E estimator = E(),
                                                S similarity = S()) {
    detail::BinaryReader file(bytes, "memory file '" + name + "'");
    if (bytes.size() < 16) file.corrupt("header: too short (" + std::to_string(bytes.size()) + " bytes)");
    if (file.bytes(8, "magic") != std::string_view(detail::memory_magic, 8))
      file.corrupt("header: not a vmap memory (wrong magic bytes)");
    const std::uint32_t version = file.u32("version");
    if (version != memory_format_version)
      file.corrupt("header: format version " + std::to_string(version) + " is not supported (this build reads " +
                   std::to_string(memory_format_version) + ")");
    if (const std::uint32_t n = file.u32("section count"); n != detail::memory_sections)
      file.corrupt("header: " + std::to_string(n) + " sections, expected " + std::to_string(detail::memory_sections));

    auto opts = detail::memory_open_section(file, "opts");
    const MemoryOptions options = read_options(opts);
    VisualMemory mem(std::move(descriptor), std::move(matcher), std::move(estimator), std::move(similarity), options);

    SelectorState<Features> state;
    auto keys = detail::memory_open_section(file, "keys");
    state.map.frames = static_cast<std::size_t>(keys.u64("frame count"));
    const std::uint32_t m = keys.u32("key image count");
    keys.require_items(m, 50, "key image count");
    if (m > state.map.frames) keys.corrupt(std::to_string(m) + " key images for " + std::to_string(state.map.frames) + " frames");
    for (std::uint32_t i = 0; i < m; ++i) {
      KeyImage k = read_key(keys);
      if (!state.map.keys.empty() && k.frame_index <= state.map.keys.back().frame_index)
        keys.corrupt("key image frame indices are not increasing");
      state.map.keys.push_back(std::move(k));
      mem.poses_.push_back(detail::memory_read_pose(keys));
    }
    keys.expect_end("the last key image");

    auto links = detail::memory_open_section(file, "link");
    const std::uint32_t p = links.u32("pair count");
    if (p != (m == 0 ? 0U : m - 1U)) links.corrupt("pair count " + std::to_string(p) + " for " + std::to_string(m) + " key images");
    for (std::uint32_t i = 0; i < p; ++i) {
      KeyPair pair;
      pair.status = detail::memory_read_status(links);
      pair.fundamental = detail::memory_read_matx(links, "fundamental matrix");
      pair.matches = links.i32("matches");
      pair.inliers = links.i32("inliers");
      if (pair.matches < 0 || pair.inliers < 0 || pair.inliers > pair.matches) links.corrupt("invalid match/inlier counts");
      pair.similarity = links.f64("similarity");
      if (!(pair.similarity >= 0.0 && pair.similarity <= 1.0)) links.corrupt("similarity outside [0, 1]");
      state.map.pairs.push_back(pair);
    }
    links.expect_end("the last pair");

    auto loops = detail::memory_open_section(file, "loop");
    const std::uint32_t e = loops.u32("loop edge count");
    loops.require_items(e, 8 + 97, "loop edge count");
    for (std::uint32_t i = 0; i < e; ++i) {
      LoopEdge edge;
      edge.from = loops.u32("loop from");
      edge.link.key = loops.u32("loop to");
      if (edge.from >= m || edge.link.key >= edge.from) loops.corrupt("loop edge between invalid key images");
      edge.link = with_key(detail::memory_read_link(loops), edge.link.key);
      mem.loops_.push_back(edge);
    }
    loops.expect_end("the last loop edge");

    auto sel = detail::memory_open_section(file, "selc");
    const std::uint8_t has_prev = sel.u8("previous frame flag");
    if (has_prev > 1) sel.corrupt("previous frame flag is not 0 or 1");
    if (has_prev == 1) {
      if (m == 0) sel.corrupt("a previous frame without a key image");
      PreparedFrame<Features> prev;
      KeyImage k = read_key(sel);
      if (k.frame_index <= state.map.keys.back().frame_index) sel.corrupt("previous frame is not after the key image");
      prev.item = std::move(k.features);
      prev.index = k.frame_index;
      prev.name = std::move(k.name);
      prev.timestamp = k.timestamp;
      prev.image = std::move(k.image);
      state.previous = std::move(prev);
      mem.previous_pose_ = detail::memory_read_pose(sel);
    }
    const std::uint8_t has_score = sel.u8("previous score flag");
    if (has_score > 1 || (has_score == 1 && has_prev == 0)) sel.corrupt("invalid previous score flag");
    if (has_score == 1) state.previous_score = read_score(sel);
    const std::uint8_t has_last = sel.u8("last frame flag");
    if (has_last > 1 || (has_last == 0 && m > 0)) sel.corrupt("invalid last frame flag");
    if (has_last == 1) {
      mem.last_index_ = static_cast<std::size_t>(sel.u64("last frame index"));
      const std::size_t at_least = state.previous ? state.previous->index : (m > 0 ? state.map.keys.back().frame_index : 0);
      if (*mem.last_index_ < at_least) sel.corrupt("the last frame index is before the selector's frames");
    }
    sel.expect_end("the selector state");

    auto voc = detail::memory_open_section(file, "voca");
    const std::uint8_t has_voc = voc.u8("vocabulary flag");
    if (has_voc > 1) voc.corrupt("vocabulary flag is not 0 or 1");
    if (has_voc == 1) {
      const std::uint64_t len = voc.u64("vocabulary length");
      const std::string_view vb = voc.bytes(len, "vocabulary");
      const std::string vname = voc.source() + " vocabulary";
      if (vb.size() > detail::place_header_size && static_cast<std::uint8_t>(vb[detail::place_header_size]) == 1)
        mem.vocabulary_ = FloatVocabularyTree::deserialize(vb, vname);
      else
        mem.vocabulary_ = BinaryVocabularyTree::deserialize(vb, vname);
    }
    voc.expect_end("the vocabulary");

    auto db = detail::memory_open_section(file, "plcd");
    const std::uint64_t dlen = db.u64("database length");
    mem.database_ = PlaceDatabase<std::uint32_t>::deserialize(db.bytes(dlen, "database"), db.source() + " database");
    db.expect_end("the database");
    if (!file.at_end()) file.corrupt(std::to_string(file.remaining()) + " unexpected bytes after the last section");

    if (mem.database_.scoring() != options.scoring || mem.database_.words() != mem.vocabulary_.size())
      detail::fail(db.source() + ": the database does not match the vocabulary or the scoring");
    for (const auto id : mem.database_.ids())
      if (id >= m) detail::fail(db.source() + ": image id " + std::to_string(id) + " is not a key image");
    mem.selector_.restore(std::move(state));
    return mem;
  }

  [[nodiscard]] static VisualMemory load(const std::filesystem::path& path, D descriptor = D(), M matcher = M(),
                                         E estimator = E(), S similarity = S()) {
    return deserialize(read_file(path, default_max_file_bytes, "memory file"), path.string(), std::move(descriptor),
                       std::move(matcher), std::move(estimator), std::move(similarity));
  }

 private:
  static MemoryOptions checked(MemoryOptions o) {
    detail::check(o.vocabulary_after >= 1, "MemoryOptions.vocabulary_after must be >= 1");
    detail::check(o.loop_candidates >= 1, "MemoryOptions.loop_candidates must be >= 1");
    detail::check(o.localize_candidates >= 1, "MemoryOptions.localize_candidates must be >= 1");
    detail::check(o.min_loop_inliers >= 8, "MemoryOptions.min_loop_inliers must be >= 8 (an F-matrix needs 8 points)");
    detail::check(o.min_localize_inliers >= 8, "MemoryOptions.min_localize_inliers must be >= 8");
    detail::check(o.jpeg_quality >= 1 && o.jpeg_quality <= 100, "MemoryOptions.jpeg_quality must be in 1..100, got " +
                                                                    std::to_string(o.jpeg_quality));
    detail::check(o.images <= ImageStorage::jpeg, "MemoryOptions.images is not a known ImageStorage");
    o.selector.keep_images = o.images != ImageStorage::none;
    return o;
  }

  static SelectorOptions selector_options(const MemoryOptions& o) { return o.selector; }

  static PlaceLink with_key(PlaceLink l, std::uint32_t key) {
    l.key = key;
    return l;
  }

  void after_push(MemoryStep& step, std::size_t index, const OdometryPose& pose) {
    const FrameResult& r = step.frame;
    if (r.key_taken) {
      // Eq. 6 takes I_{j-1}: its pose is the one pushed with it.
      poses_.push_back(*r.key_frame == index ? pose : previous_pose_);
      step.new_key = static_cast<std::uint32_t>(key_images() - 1);
      on_new_key(*step.new_key, step.loops);
    }
    previous_pose_ = pose;
    last_index_ = index;
  }

  /// Adds key image `key` to the place database and detects its loops; learns the
  /// vocabulary once enough key images exist, then catches up with the earlier ones in
  /// order.
  void on_new_key(std::uint32_t key, std::vector<LoopEdge>& found) {
    const auto& keys = selector_.map().keys;
    if (vocabulary_.empty()) {
      if (keys.size() < options_.vocabulary_after) return;
      std::vector<cv::Mat> sets;
      for (const auto& k : keys) sets.push_back(k.features.descriptors);
      std::size_t rows = 0;
      for (const auto& d : sets) rows += static_cast<std::size_t>(d.rows);
      // Too few descriptors to split into `branching` words (blank frames): try again
      // at the next key image.
      if (rows < static_cast<std::size_t>(std::max(options_.vocabulary.branching, 1))) return;
      vocabulary_ = AnyVocabulary::learn(sets, options_.vocabulary);
      database_ = PlaceDatabase<std::uint32_t>(vocabulary_.size(), options_.scoring);
      for (std::uint32_t k = 0; k < key; ++k) detect_and_add(k, found);
    }
    detect_and_add(key, found);
  }

  void detect_and_add(std::uint32_t key, std::vector<LoopEdge>& found) {
    const Features& f = selector_.map().keys[key].features;
    const BowVector bow = transform(f.descriptors);
    if (key >= options_.exclude_recent + 1 && !database_.empty()) {
      QueryFilter<std::uint32_t> filter;
      filter.exclude_from = static_cast<std::uint32_t>(key - options_.exclude_recent);
      for (const auto& c : database_.query(bow, options_.loop_candidates, filter)) {
        PlaceLink l = verify(c.id, c.score, f);
        if (l.status == VerificationStatus::verified && l.inliers >= options_.min_loop_inliers) {
          loops_.push_back({key, l});
          found.push_back({key, l});
        }
      }
    }
    database_.add(key, bow);
  }

  BowVector transform(const cv::Mat& descriptors) const {
    if (descriptors.empty()) return {};
    detail::check(
        descriptors.type() == vocabulary_.descriptor_type() && descriptors.cols == vocabulary_.descriptor_cols(), [&] {
          return "VisualMemory: descriptors of type " + cv::typeToString(descriptors.type()) + " x " +
                 std::to_string(descriptors.cols) + " do not fit the vocabulary (" +
                 cv::typeToString(vocabulary_.descriptor_type()) + " x " +
                 std::to_string(vocabulary_.descriptor_cols()) + ")";
        });
    return vocabulary_.transform(descriptors);
  }

  /// Candidate key images for a query: by BoW score, or all (score 0) without a vocabulary.
  std::vector<std::pair<std::uint32_t, double>> rank(const cv::Mat& descriptors, std::size_t top,
                                                     std::size_t keys) const {
    std::vector<std::pair<std::uint32_t, double>> out;
    if (vocabulary_.empty()) {
      for (std::size_t k = 0; k < keys; ++k) out.emplace_back(static_cast<std::uint32_t>(k), 0.0);
      return out;
    }
    for (const auto& c : database_.query(transform(descriptors), top)) out.emplace_back(c.id, c.score);
    return out;
  }

  /// Matches and verifies key image `key` against `query` with the selector's own
  /// matcher, estimator and similarity (no second extraction).
  PlaceLink verify(std::uint32_t key, double bow_score, const Features& query) {
    const PairScore s = selector_.front_end().score(selector_.map().keys[key].features, query, 0.0);
    PlaceLink l;
    l.key = key;
    l.bow_score = std::clamp(bow_score, 0.0, 1.0);
    l.status = s.verification.status;
    l.matches = s.raw_matches;
    if (s.verification.ok()) {
      l.fundamental = s.verification.model;
      l.inliers = s.verification.inliers;
      l.similarity = s.similarity;
    }
    return l;
  }

  // ---- file sections ------------------------------------------------------------

  std::string options_bytes(ImageStorage storage) const {
    const MemoryOptions& o = options_;
    detail::BinaryWriter w;
    w.f64(o.selector.tau);
    w.u8(static_cast<std::uint8_t>(o.selector.rule));
    w.u8(o.selector.skip_by_upper_bound ? 1 : 0);
    w.u8(static_cast<std::uint8_t>(storage));
    w.i32(o.jpeg_quality);
    w.u64(o.vocabulary_after);
    w.i32(o.vocabulary.branching);
    w.i32(o.vocabulary.depth);
    w.i32(o.vocabulary.iterations);
    w.u64(o.vocabulary.max_descriptors);
    w.u64(o.vocabulary.seed);
    w.u8(static_cast<std::uint8_t>(o.scoring));
    w.u64(o.exclude_recent);
    w.u64(o.loop_candidates);
    w.i32(o.min_loop_inliers);
    w.u64(o.localize_candidates);
    w.i32(o.min_localize_inliers);
    return std::move(w).take();
  }

  static MemoryOptions read_options(detail::BinaryReader& r) {
    MemoryOptions o;
    o.selector.tau = r.f64("tau");
    const std::uint8_t rule = r.u8("key rule");
    if (rule > 1) r.corrupt("unknown key rule " + std::to_string(rule));
    o.selector.rule = static_cast<KeyRule>(rule);
    const std::uint8_t skip = r.u8("skip flag");
    if (skip > 1) r.corrupt("skip flag is not 0 or 1");
    o.selector.skip_by_upper_bound = skip == 1;
    const std::uint8_t images = r.u8("image storage");
    if (images > 2) r.corrupt("unknown image storage " + std::to_string(images));
    o.images = static_cast<ImageStorage>(images);
    o.jpeg_quality = r.i32("jpeg quality");
    o.vocabulary_after = static_cast<std::size_t>(r.u64("vocabulary_after"));
    o.vocabulary.branching = r.i32("branching");
    o.vocabulary.depth = r.i32("depth");
    o.vocabulary.iterations = r.i32("iterations");
    o.vocabulary.max_descriptors = static_cast<std::size_t>(r.u64("max_descriptors"));
    o.vocabulary.seed = r.u64("seed");
    const std::uint8_t scoring = r.u8("scoring");
    if (scoring > 2) r.corrupt("unknown scoring " + std::to_string(scoring));
    o.scoring = static_cast<BowScoring>(scoring);
    o.exclude_recent = static_cast<std::size_t>(r.u64("exclude_recent"));
    o.loop_candidates = static_cast<std::size_t>(r.u64("loop_candidates"));
    o.min_loop_inliers = r.i32("min_loop_inliers");
    o.localize_candidates = static_cast<std::size_t>(r.u64("localize_candidates"));
    o.min_localize_inliers = r.i32("min_localize_inliers");
    r.expect_end("the options");
    if (!(std::isfinite(o.selector.tau) && o.selector.tau > 0.0 && o.selector.tau <= 1.0)) r.corrupt("tau outside (0, 1]");
    try {
      return checked(o);
    } catch (const Error& e) {
      r.corrupt(e.what());
    }
  }

  void write_key(detail::BinaryWriter& w, std::size_t index, double timestamp, const std::string& name,
                 const Features& f, const cv::Mat& image, ImageStorage storage) const {
    w.u64(index);
    w.f64(timestamp);
    w.str(name, detail::map_max_string, "VisualMemory::save: a key image name");
    detail::write_features(w, f);
    detail::write_memory_image(w, image, storage, options_.jpeg_quality);
  }

  static KeyImage read_key(detail::BinaryReader& r) {
    KeyImage k;
    k.frame_index = static_cast<std::size_t>(r.u64("frame index"));
    k.timestamp = r.f64("timestamp");
    k.name = r.str("name", detail::map_max_string);
    k.features = detail::read_features(r);
    k.image = detail::read_memory_image(r);
    return k;
  }

  std::string keys_bytes(ImageStorage storage) const {
    const VisualMap& map = selector_.map();
    detail::BinaryWriter w;
    w.u64(map.frames);
    w.u32(static_cast<std::uint32_t>(map.keys.size()));
    for (std::size_t i = 0; i < map.keys.size(); ++i) {
      const KeyImage& k = map.keys[i];
      write_key(w, k.frame_index, k.timestamp, k.name, k.features, k.image, storage);
      detail::memory_write_pose(w, poses_[i]);
    }
    return std::move(w).take();
  }

  std::string links_bytes() const {
    detail::BinaryWriter w;
    const auto& pairs = selector_.map().pairs;
    w.u32(static_cast<std::uint32_t>(pairs.size()));
    for (const auto& p : pairs) {
      w.u8(static_cast<std::uint8_t>(p.status));
      detail::memory_write_matx(w, p.fundamental);
      w.i32(p.matches);
      w.i32(p.inliers);
      w.f64(p.similarity);
    }
    return std::move(w).take();
  }

  std::string loops_bytes() const {
    detail::BinaryWriter w;
    w.u32(static_cast<std::uint32_t>(loops_.size()));
    for (const auto& e : loops_) {
      w.u32(e.from);
      w.u32(e.link.key);
      detail::memory_write_link(w, e.link);
    }
    return std::move(w).take();
  }

  std::string selector_bytes(ImageStorage storage) const {
    const SelectorState<Features> s = selector_.state();
    detail::BinaryWriter w;
    w.u8(s.previous ? 1 : 0);
    if (s.previous) {
      const auto& p = *s.previous;
      write_key(w, p.index, p.timestamp, p.name, p.item, p.image, storage);
      detail::memory_write_pose(w, previous_pose_);
    }
    w.u8(s.previous_score ? 1 : 0);
    if (s.previous_score) {
      // What the link to the next key image is made of (selector.hpp's add_key); the
      // inlier mask is not needed and not stored.
      const PairScore& p = *s.previous_score;
      w.i32(p.raw_matches);
      w.f64(p.upper_bound);
      w.u8(p.verified_run ? 1 : 0);
      w.u8(static_cast<std::uint8_t>(p.verification.status));
      detail::memory_write_matx(w, p.verification.model);
      w.i32(p.verification.inliers);
      w.i32(p.verification.matches);
      w.u8(static_cast<std::uint8_t>(p.verification.degeneracy));
      w.i32(p.verification.homography_inliers);
      w.f64(p.similarity);
    }
    w.u8(last_index_ ? 1 : 0);
    if (last_index_) w.u64(*last_index_);
    return std::move(w).take();
  }

  static PairScore read_score(detail::BinaryReader& r) {
    PairScore p;
    p.raw_matches = r.i32("raw matches");
    p.upper_bound = r.f64("upper bound");
    const std::uint8_t run = r.u8("verified flag");
    if (run > 1) r.corrupt("verified flag is not 0 or 1");
    p.verified_run = run == 1;
    p.verification.status = detail::memory_read_status(r);
    p.verification.model = detail::memory_read_matx(r, "fundamental matrix");
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

  MemoryOptions options_;
  Selector selector_;
  AnyVocabulary vocabulary_;
  PlaceDatabase<std::uint32_t> database_;
  std::vector<LoopEdge> loops_;
  std::vector<OdometryPose> poses_;  ///< per key image
  OdometryPose previous_pose_;       ///< of the last pushed frame (eq. 6's I_{j-1})
  std::optional<std::size_t> last_index_;
};

// Named stacks: the paper's ORB 1000 + mutual NN + MAGSAC++ + eq. 5, and A-KAZE / SIFT.
using OrbVisualMemory = VisualMemory<OrbDescriptor, BruteForceMatcher, FundamentalEstimator, InlierRatio>;
using AkazeVisualMemory = VisualMemory<AkazeDescriptor, BruteForceMatcher, FundamentalEstimator, InlierRatio>;
using SiftVisualMemory = VisualMemory<SiftDescriptor, BruteForceMatcher, FundamentalEstimator, InlierRatio>;

}  // namespace vmap
