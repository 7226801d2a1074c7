#pragma once

// Frame sources: a video file, a folder of images, a text list of image paths, or a TUM
// RGB-D `rgb.txt`, read one frame at a time with optional start/end/stride/resize.
//
// Unreadable frames are skipped, counted and reported (FrameSourceOptions::on_skip,
// FrameSource::skipped()), never taken as the end of the sequence:
//   - images (folders, lists): a missing file, a folder, a device or FIFO (never opened,
//     so a FIFO cannot block), an unreadable or undecodable file, an image above
//     `max_pixels` (checked from the file header before decoding, io/image.hpp) or
//     below `min_side`;
//   - videos: a frame the decoder rejects. The end of a video is the frame count the
//     container states; when a read fails before it, the frame is skipped and reading
//     goes on. Without a stated count (or past it), `max_failed_reads` failed reads in a
//     row end the video, and those trailing failures are not reported (they are the end
//     of the stream, not frames).

#include <vmap/core/error.hpp>
#include <vmap/io/detail/lines.hpp>
#include <vmap/io/files.hpp>
#include <vmap/io/image.hpp>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>
#include <opencv2/videoio/registry.hpp>

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstddef>
#include <filesystem>
#include <functional>
#include <system_error>
#include <limits>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace vmap {

/// One frame of a sequence. `index` is the frame's position in the whole sequence
/// (before start/stride are applied), so it lines up with ground-truth files.
struct Frame {
  cv::Mat image;
  std::size_t index = 0;
  std::string name;        ///< file name, or "<video>#<index>"
  double timestamp = 0.0;  ///< TUM timestamp, video position in seconds, else the index
};

/// A frame that could not be decoded and was skipped.
struct SkippedFrame {
  std::size_t index = 0;
  std::string name;
  std::string reason;
};

enum class SourceKind { video, image_folder, image_list, tum_rgb };

struct FrameSourceOptions {
  std::size_t start = 0;                                     ///< first frame index read
  std::size_t end = std::numeric_limits<std::size_t>::max();  ///< one past the last index
  std::size_t stride = 1;                                    ///< read every stride-th frame, >= 1
  cv::Size resize{};        ///< output size; (0, 0) keeps the input size
  bool grey = false;        ///< decode straight to 8-bit grey (faster for ORB/A-KAZE/SIFT)
  /// Frames with more pixels are skipped; for image files the size is read from the
  /// header before decoding, so a hostile file never makes the decoder allocate. A video
  /// whose stated frame size exceeds it is refused when opened.
  std::uint64_t max_pixels = default_max_image_pixels;
  /// Frames narrower or lower than this are skipped ("smaller than ..."): feature
  /// pyramids need some pixels; a 1x1 frame is a broken file, not a picture.
  int min_side = 16;
  /// Failed video reads in a row taken as the end of a video (see the top of the file).
  std::size_t max_failed_reads = 16;
  /// Called for each unreadable frame inside a sequence before it is skipped;
  /// `FrameSource::skipped()` keeps the same list.
  std::function<void(const SkippedFrame&)> on_skip{};
};

namespace detail {

/// "img2.png" < "img10.png": digit runs compare by value, the rest byte-wise.
inline bool natural_less(const std::string& a, const std::string& b) {
  std::size_t i = 0, j = 0;
  while (i < a.size() && j < b.size()) {
    const auto ca = static_cast<unsigned char>(a[i]);
    const auto cb = static_cast<unsigned char>(b[j]);
    if (std::isdigit(ca) && std::isdigit(cb)) {
      std::size_t ie = i, je = j;
      while (ie < a.size() && std::isdigit(static_cast<unsigned char>(a[ie]))) ++ie;
      while (je < b.size() && std::isdigit(static_cast<unsigned char>(b[je]))) ++je;
      std::size_t iz = i, jz = j;  // skip leading zeros, then compare by length and digits
      while (iz + 1 < ie && a[iz] == '0') ++iz;
      while (jz + 1 < je && b[jz] == '0') ++jz;
      if (ie - iz != je - jz) return ie - iz < je - jz;
      const int c = a.compare(iz, ie - iz, b, jz, je - jz);
      if (c != 0) return c < 0;
      if (ie - i != je - j) return ie - i < je - j;  // "01" after "1": stable, total order
      i = ie;
      j = je;
    } else {
      if (ca != cb) return ca < cb;
      ++i;
      ++j;
    }
  }
  return a.size() - i < b.size() - j;
}

inline bool is_image_file(const std::filesystem::path& p) {
  std::string ext = p.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  static const char* const known[] = {".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm", ".pnm", ".webp"};
  return std::any_of(std::begin(known), std::end(known), [&](const char* k) { return ext == k; });
}

/// a + b, or SIZE_MAX when that overflows (a huge stride must end the sequence, not
/// wrap around to earlier frames).
inline std::size_t saturating_add(std::size_t a, std::size_t b) noexcept {
  return a > std::numeric_limits<std::size_t>::max() - b ? std::numeric_limits<std::size_t>::max() : a + b;
}

inline std::string trim(const std::string& s) {
  const auto b = s.find_first_not_of(" \t\r\n");
  if (b == std::string::npos) return {};
  const auto e = s.find_last_not_of(" \t\r\n");
  return s.substr(b, e - b + 1);
}

struct ListEntry {
  std::filesystem::path path;
  double timestamp = 0.0;
};

/// Largest list file (one path a line) read; a million frames take ~50 MB.
inline constexpr std::uintmax_t max_list_file_bytes = std::uintmax_t{64} << 20;

/// "<timestamp> <path>" with a finite number first and one path token after: a TUM line.
inline bool parse_tum_line(const std::string& line, double& t, std::string& path) {
  const auto sp = line.find_first_of(" \t");
  if (sp == std::string::npos) return false;
  const auto [ptr, ec] = std::from_chars(line.data(), line.data() + sp, t);
  if (ec != std::errc() || ptr != line.data() + sp || !std::isfinite(t)) return false;
  path = trim(line.substr(sp));
  return !path.empty() && path.find_first_of(" \t") == std::string::npos;
}

/// Reads a list file: either one image path a line, or TUM's "timestamp path" lines.
/// Relative paths are relative to the list's folder; '#' starts a comment line. The
/// first entry decides the format: when it is a TUM line every line must be one, and a
/// line that is not is an Error naming "file:line" (as pose files are read).
inline std::vector<ListEntry> read_list(const std::filesystem::path& file, SourceKind& kind) {
  const std::string text = read_text_file(file, "frame source: list file", max_list_file_bytes);
  std::vector<std::pair<std::string, std::size_t>> lines;  // (line, 1-based number)
  for_each_line(text, [&](std::string_view raw, std::size_t no) {
    std::string line = trim(std::string(raw));
    if (line.empty() || line[0] == '#') return;
    lines.emplace_back(std::move(line), no);
  });
  if (lines.empty()) fail("frame source: list file '" + file.string() + "' names no image");
  double t0 = 0;
  std::string p0;
  const bool tum = parse_tum_line(lines.front().first, t0, p0);
  kind = tum ? SourceKind::tum_rgb : SourceKind::image_list;
  const auto base = file.parent_path();
  std::vector<ListEntry> out;
  out.reserve(lines.size());
  for (std::size_t k = 0; k < lines.size(); ++k) {
    ListEntry e;
    std::string p = lines[k].first;
    if (tum) {
      if (!parse_tum_line(lines[k].first, e.timestamp, p))
        fail("frame source: " + file.string() + ":" + std::to_string(lines[k].second) + ": '" + lines[k].first +
             "' is not '<timestamp> <path>' like the lines before it (TUM rgb.txt)");
    } else {
      e.timestamp = static_cast<double>(k);
    }
    std::filesystem::path path(p);
    e.path = path.is_absolute() ? path : base / path;
    out.push_back(std::move(e));
  }
  return out;
}

}  // namespace detail

/// Reads frames one at a time. Not thread-safe; move-only.
///
/// Errors (vmap::Error naming the path): a missing input, a folder without images, an
/// empty or unreadable list, a video that cannot be opened or has no frame, invalid
/// options, and a sequence in which no frame at all could be decoded. A single
/// unreadable image inside a sequence is reported (on_skip, skipped()) and skipped.
class FrameSource {
 public:
  static FrameSource open(const std::filesystem::path& input, FrameSourceOptions options = {}) {
    detail::check(options.stride >= 1, "frame source: stride must be >= 1");
    detail::check(options.max_pixels >= 1, "frame source: max_pixels must be >= 1");
    detail::check(options.min_side >= 1, "frame source: min_side must be >= 1");
    detail::check(options.max_failed_reads >= 1, "frame source: max_failed_reads must be >= 1");
    detail::check(options.start < options.end, "frame source: start (" + std::to_string(options.start) +
                                                   ") must be before end (" + std::to_string(options.end) + ")");
    detail::check(options.resize.width >= 0 && options.resize.height >= 0 &&
                      (options.resize.width > 0) == (options.resize.height > 0),
                  "frame source: resize must be (0, 0) or a positive size");
    std::error_code ec;
    if (!std::filesystem::exists(input, ec)) {
      if (ec && ec != std::errc::no_such_file_or_directory)
        detail::fail("frame source: '" + input.string() + "': " + ec.message());
      fail_missing(input);
    }
    FrameSource s;
    s.input_ = input;
    s.options_ = std::move(options);
    s.next_index_ = s.options_.start;
    if (std::filesystem::is_directory(input, ec)) {
      s.kind_ = SourceKind::image_folder;
      std::vector<std::string> names;
      // Entries are listed by name only; whether each is a readable image is decided
      // when it is read (a symbolic link loop or a FIFO named x.png is then a skipped
      // frame with its reason), so listing never throws a filesystem_error.
      std::filesystem::directory_iterator it(input, ec);
      if (ec) detail::fail("frame source: cannot read folder '" + input.string() + "': " + ec.message());
      for (; it != std::filesystem::directory_iterator(); it.increment(ec)) {
        if (ec) break;
        std::error_code sub;
        if (detail::is_image_file(it->path()) && !it->is_directory(sub)) names.push_back(it->path().filename().string());
      }
      if (ec) detail::fail("frame source: cannot read folder '" + input.string() + "': " + ec.message());
      if (names.empty()) detail::fail("frame source: folder '" + input.string() + "' contains no image file");
      std::sort(names.begin(), names.end(), detail::natural_less);
      for (std::size_t k = 0; k < names.size(); ++k)
        s.entries_.push_back({input / names[k], static_cast<double>(k)});
    } else if (input.extension() == ".txt" || input.extension() == ".lst") {
      s.entries_ = detail::read_list(input, s.kind_);
    } else {
      s.kind_ = SourceKind::video;
      s.open_video();
    }
    return s;
  }

  /// The next frame, or nullopt at the end of the sequence (or at options.end).
  [[nodiscard]] std::optional<Frame> next() {
    std::optional<Frame> f = kind_ == SourceKind::video ? next_video() : next_image();
    if (f) {
      ++delivered_;
      if (options_.resize.width > 0 && f->image.size() != options_.resize)
        cv::resize(f->image, f->image, options_.resize, 0, 0, cv::INTER_AREA);
    } else if (delivered_ == 0 && !skipped_.empty()) {
      detail::fail("frame source: no frame of '" + input_.string() + "' could be read (" +
                   std::to_string(skipped_.size()) + " unreadable, first: " + skipped_.front().name + ")");
    }
    return f;
  }

  [[nodiscard]] SourceKind kind() const noexcept { return kind_; }
  [[nodiscard]] const std::filesystem::path& input() const noexcept { return input_; }
  /// Total frames in the underlying sequence if known (lists and folders; videos that
  /// report a frame count), before start/end/stride.
  [[nodiscard]] std::optional<std::size_t> total() const noexcept {
    if (kind_ != SourceKind::video) return entries_.size();
    return video_frames_ > 0 ? std::optional<std::size_t>(video_frames_) : std::nullopt;
  }
  /// Every frame skipped so far (index, name, reason), in sequence order; its size is
  /// the count a command reports.
  [[nodiscard]] const std::vector<SkippedFrame>& skipped() const noexcept { return skipped_; }
  /// Frames returned by next() so far.
  [[nodiscard]] std::size_t delivered() const noexcept { return delivered_; }
  /// Image paths of a list, folder or TUM source (empty for a video).
  [[nodiscard]] std::vector<std::filesystem::path> paths() const {
    std::vector<std::filesystem::path> out;
    out.reserve(entries_.size());
    for (const auto& e : entries_) out.push_back(e.path);
    return out;
  }

 private:
  FrameSource() = default;

  [[noreturn]] static void fail_missing(const std::filesystem::path& p) {
    detail::fail("frame source: '" + p.string() + "' does not exist");
  }

  void open_video() {
    // Try OpenCV's file backends one by one, skipping CAP_IMAGES (folders and lists are
    // handled above) and CAP_GPHOTO2 (it probes USB cameras for every file name, which
    // is slow and leaks in libgphoto2).
    for (const cv::VideoCaptureAPIs api : cv::videoio_registry::getStreamBackends()) {
      if (api == cv::CAP_IMAGES || api == cv::CAP_GPHOTO2) continue;
      try {
        if (capture_.open(input_.string(), api)) break;
      } catch (const cv::Exception&) {
        capture_.release();  // a backend that throws on this file: try the next one
      }
    }
    if (!capture_.isOpened())
      detail::fail("frame source: cannot open '" + input_.string() +
                   "' as a video (and it is not a folder or a .txt list)");
    const double count = capture_.get(cv::CAP_PROP_FRAME_COUNT);
    video_frames_ = count > 0 && count < 1e12 ? static_cast<std::size_t>(count) : 0;
    const double w = capture_.get(cv::CAP_PROP_FRAME_WIDTH), h = capture_.get(cv::CAP_PROP_FRAME_HEIGHT);
    if (w > 0 && h > 0 && w * h > static_cast<double>(options_.max_pixels))
      detail::fail("frame source: video '" + input_.string() + "' has frames of " + std::to_string(static_cast<long long>(w)) +
                   "x" + std::to_string(static_cast<long long>(h)) + " pixels, more than the limit of " +
                   std::to_string(options_.max_pixels) + " (FrameSourceOptions::max_pixels)");
    video_pos_ = 0;
    // The first decodable frame proves the file is a video; frames before it that fail
    // are skipped like any other.
    if (!read_video_frame(pending_)) detail::fail("frame source: video '" + input_.string() + "' has no frame");
  }

  /// Reads the next decodable frame into `img` (video_pos_ = its index afterwards).
  /// Failed reads before it are recorded as skipped frames when they lie before the
  /// stated frame count or a later frame was read; false at the end of the video.
  bool read_video_frame(cv::Mat& img) {
    std::vector<std::size_t> failed;  // indices of the failed reads in a row
    const auto finish = [&](bool report) {
      for (std::size_t i : failed)
        if (report && i >= next_index_ && i < options_.end && (i - next_index_) % options_.stride == 0) skip_video(i);
      video_pos_ += failed.size();
    };
    for (;;) {
      const std::size_t idx = video_pos_ + failed.size();
      bool ok = false;
      try {
        ok = capture_.read(img) && !img.empty();
      } catch (const cv::Exception&) {
        ok = false;
      }
      if (ok) {
        finish(true);
        return true;
      }
      if (video_frames_ > 0 && idx >= video_frames_) {  // past the stated count: the end
        finish(true);
        return false;
      }
      failed.push_back(idx);
      if (failed.size() >= options_.max_failed_reads) {
        // With a stated count the failures lie before it: frames. Without, the end.
        finish(video_frames_ > 0);
        return false;
      }
    }
  }

  void skip_video(std::size_t idx) {
    SkippedFrame s{idx, input_.filename().string() + "#" + std::to_string(idx), "the video decoder could not read this frame"};
    if (options_.on_skip) options_.on_skip(s);
    skipped_.push_back(std::move(s));
  }

  std::optional<Frame> next_video() {
    while (next_index_ < options_.end) {
      cv::Mat img;
      if (!pending_.empty()) {
        img = pending_;
        pending_.release();
      } else if (!read_video_frame(img)) {
        return std::nullopt;  // end of stream
      }
      const std::size_t idx = video_pos_++;
      if (idx < next_index_) continue;  // before start or between strides
      if (img.cols < options_.min_side || img.rows < options_.min_side ||
          static_cast<std::uint64_t>(img.cols) * static_cast<std::uint64_t>(img.rows) > options_.max_pixels) {
        next_index_ = detail::saturating_add(idx, options_.stride);
        SkippedFrame s{idx, input_.filename().string() + "#" + std::to_string(idx), size_reason(img.size())};
        if (options_.on_skip) options_.on_skip(s);
        skipped_.push_back(std::move(s));
        continue;
      }
      next_index_ = detail::saturating_add(idx, options_.stride);
      Frame f;
      f.index = idx;
      f.name = input_.filename().string() + "#" + std::to_string(idx);
      f.timestamp = capture_.get(cv::CAP_PROP_POS_MSEC) / 1000.0;
      if (options_.grey && img.channels() != 1)
        cv::cvtColor(img, f.image, img.channels() == 4 ? cv::COLOR_BGRA2GRAY : cv::COLOR_BGR2GRAY);
      else
        f.image = img;
      return f;
    }
    return std::nullopt;
  }

  std::optional<Frame> next_image() {
    while (next_index_ < options_.end && next_index_ < entries_.size()) {
      const std::size_t idx = next_index_;
      next_index_ = detail::saturating_add(next_index_, options_.stride);
      const auto& e = entries_[idx];
      Frame f;
      f.index = idx;
      f.name = e.path.filename().string();
      f.timestamp = e.timestamp;
      std::string reason;
      f.image = detail::try_read_image(
          e.path, {.flags = options_.grey ? cv::IMREAD_GRAYSCALE : cv::IMREAD_UNCHANGED, .max_pixels = options_.max_pixels},
          reason);
      if (!f.image.empty() && (f.image.cols < options_.min_side || f.image.rows < options_.min_side)) {
        reason = size_reason(f.image.size());
        f.image.release();
      }
      if (f.image.empty()) {
        if (reason == "does not exist") reason = "file does not exist";
        SkippedFrame s{idx, e.path.string(), reason};
        if (options_.on_skip) options_.on_skip(s);
        skipped_.push_back(std::move(s));
        continue;
      }
      return f;
    }
    return std::nullopt;
  }

  [[nodiscard]] std::string size_reason(cv::Size s) const {
    return "the frame is " + std::to_string(s.width) + "x" + std::to_string(s.height) + " pixels, outside " +
           std::to_string(options_.min_side) + "x" + std::to_string(options_.min_side) + " .. " +
           std::to_string(options_.max_pixels) + " pixels (FrameSourceOptions min_side, max_pixels)";
  }

  std::filesystem::path input_;
  FrameSourceOptions options_;
  SourceKind kind_ = SourceKind::image_list;
  std::vector<detail::ListEntry> entries_;
  cv::VideoCapture capture_;
  cv::Mat pending_;
  std::size_t video_frames_ = 0;
  std::size_t video_pos_ = 0;
  std::size_t next_index_ = 0;
  std::size_t delivered_ = 0;
  std::vector<SkippedFrame> skipped_;
};

}  // namespace vmap
