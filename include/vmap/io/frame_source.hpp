#pragma once

// Frame sources: a video file, a folder of images, a text list of image paths, a TUM
// RGB-D `rgb.txt`, or an ASL / EuRoC camera folder (`mav0/cam0`: `data.csv` beside
// `data/`, or the `data.csv` itself), read one frame at a time with optional
// start/end/stride/resize.
//
// Frame times (Frame::timestamp, FrameSource::timestamps()), in seconds, plus
// FrameSourceOptions::time_offset:
//   - EuRoC: the nanosecond timestamps of `data.csv`;
//   - TUM rgb.txt: its times;
//   - an image folder whose file names (without extension) are all numbers: the
//     numbers, as timestamps in a unit told by the magnitude of the largest one:
//     >= 1e17 nanoseconds (EuRoC's 19-digit names), >= 1e14 microseconds, >= 1e11
//     milliseconds, else seconds (Unix times in seconds have 10 digits; a name with a
//     decimal point, such as TUM's 1305031229.528748.png, is seconds). Names numbered
//     0, 1, 2, ... thus time their frames in seconds by their number;
//   - any other folder or list: the frame's index;
//   - a video: its position in seconds (0 for the first frame);
//   - a robot bag (io/bag/bag.hpp: ROS 1 `.bag`, rosbag2 `.db3` or its folder, `.mcap`):
//     the header stamps of the image topic's messages (Frame::time_ns exact), or their
//     record times with FrameSourceOptions::record_time. Frames are named
//     `topic@stamp` (the stamp in nanoseconds) and indexed by their position among the
//     topic's messages; FrameSourceOptions::topic picks the topic when the bag has
//     several image topics, and camera() gives the calibration of a CameraInfo topic
//     beside it.
// A time beyond +-9.2e9 s (io/timestamps.hpp, max_time_seconds: what whole nanoseconds
// in an int64 hold) is never clamped: a list line, a file name or a time offset beyond it
// is an Error naming it; a bag message, a warning and a skipped message.
//
// An input that is neither a regular file nor a folder (a FIFO, a device, a socket) is
// refused by name before anything opens it (io/files.hpp, require_file_or_folder): a
// video backend would wait on a FIFO's writer. Cameras and streams are told from their
// text first (is_live_source below).
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
//     of the stream, not frames);
//   - bags: a message whose image cannot be decoded (a corrupt or stub image, an
//     encoding vmap does not read, a size outside the bounds). Damage to the bag itself
//     (a truncated file, a corrupt chunk) is reported through
//     FrameSourceOptions::on_warning and warnings(), naming the byte where it is; the
//     frames before it are delivered.
//
// This header declares; the readers themselves (videos through OpenCV's videoio, bags,
// lists) are in io/detail/frame_source_impl.hpp, included here unless the program links
// vmap::stacks, which compiles them once (core/compiled.hpp).

#include <vmap/core/compiled.hpp>
#include <vmap/core/error.hpp>
#include <vmap/io/bag/types.hpp>
#include <vmap/io/frame.hpp>
#include <vmap/io/image.hpp>

#include <opencv2/core.hpp>

#include <algorithm>
#include <cctype>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <iterator>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <variant>
#include <vector>

namespace vmap {

/// A frame that could not be decoded and was skipped.
struct SkippedFrame {
  std::size_t index = 0;
  std::string name;
  std::string reason;
};

/// A frame taken from its sequence by FrameSource::claim() and not decoded yet: an
/// image file (decoded by FrameSource::decode(), on any thread), or a video or camera
/// frame already read (a video decodes in order).
struct PendingFrame {
  std::size_t index = 0;
  std::string name;
  double timestamp = 0.0;
  std::int64_t time_ns = 0;    ///< Frame::time_ns, before the time offset
  std::filesystem::path path;  ///< the image file; empty for a video or camera frame
  cv::Mat image;               ///< the video or camera frame as read
  /// A bag frame's serialized message, decoded by decode(): its bytes stay valid while
  /// `message_owner` (the chunk or row they lie in) is held.
  std::string_view message;
  std::shared_ptr<const void> message_owner;
  std::uint64_t message_offset = 0;  ///< where the message lies (BagFormat-dependent, for messages)
};

enum class SourceKind { video, image_folder, image_list, tum_rgb, live, euroc, bag };

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
  /// Seconds added to every frame time, to put frames on the clock of a pose file (a
  /// video's times start at 0).
  double time_offset = 0.0;
  /// Called for each unreadable frame inside a sequence before it is skipped;
  /// `FrameSource::skipped()` keeps the same list.
  std::function<void(const SkippedFrame&)> on_skip{};
  /// A bag's image topic (empty: its only one; several are an Error listing them).
  std::string topic{};
  /// A bag's frames are timed by the messages' record times (when the recorder received
  /// them) instead of their header stamps.
  bool record_time = false;
  /// Called with each damage found in a bag (a truncated file, a corrupt chunk: the text
  /// names the byte), on the thread that reads the bag; `FrameSource::warnings()` keeps
  /// the same list.
  std::function<void(const std::string&)> on_warning{};
  /// What a bag's reader may allocate at once.
  BagLimits bag_limits{};
};

namespace detail {

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

/// A live source for cv::VideoCapture rather than a path: a camera index ("0"), a V4L
/// device (/dev/video0), a URL (rtsp://, http://, ...) or a GStreamer pipeline (holds
/// '!'). Decided from the string alone, without touching the file system.
inline bool is_live_source(const std::string& s) {
  if (s.empty()) return false;
  if (std::all_of(s.begin(), s.end(), [](unsigned char c) { return std::isdigit(c) != 0; })) return s.size() <= 4;
  return s.rfind("/dev/video", 0) == 0 || s.find("://") != std::string::npos || s.find('!') != std::string::npos;
}

struct ListEntry {
  std::filesystem::path path;
  double timestamp = 0.0;
  std::int64_t time_ns = 0;
};

/// Largest list file (one path a line) read; a million frames take ~50 MB.
inline constexpr std::uintmax_t max_list_file_bytes = std::uintmax_t{64} << 20;

}  // namespace detail

/// Reads frames one at a time. Not thread-safe (but see claim() / decode() below);
/// move-only.
///
/// Errors (vmap::Error naming the path): a missing input, a folder without images, an
/// empty or unreadable list, a video that cannot be opened or has no frame, invalid
/// options, and a sequence in which no frame at all could be decoded. A single
/// unreadable image inside a sequence is reported (on_skip, skipped()) and skipped.
class FrameSource {
 public:  static FrameSource open(const std::filesystem::path& input, FrameSourceOptions options = {});

  FrameSource(FrameSource&&) noexcept;
  FrameSource& operator=(FrameSource&&) noexcept;
  FrameSource(const FrameSource&) = delete;
  FrameSource& operator=(const FrameSource&) = delete;
  ~FrameSource();

  /// The next frame, or nullopt at the end of the sequence (or at options.end).
  [[nodiscard]] std::optional<Frame> next();

  // next() in three steps, so that several threads can decode the image files of one
  // sequence (run_selector's preparing threads do): claim() and record() are called by
  // one thread at a time, record() in sequence order; decode() is const and may run on
  // any number of threads at once. Everything next() reports (skipped frames, on_skip,
  // delivered(), the error for a sequence without a readable frame) comes from
  // record() and finish(), so both ways report the same. A video is read by claim(),
  // which records its unreadable frames itself, in order.

  /// The next frame of the sequence, in order, without decoding an image file (a video
  /// or camera frame is read here); nullopt at the end (or at options.end).
  [[nodiscard]] std::optional<PendingFrame> claim();
  /// The claimed frame decoded, converted and resized as the options say, or the reason
  /// it is skipped.
  [[nodiscard]] std::variant<Frame, SkippedFrame> decode(PendingFrame p) const;
  /// Counts a decoded frame, or reports (on_skip) and keeps a skipped one; called in
  /// sequence order.
  void record(const std::variant<Frame, SkippedFrame>& decoded);
  /// At the end of the sequence, every claimed frame recorded: an Error when no frame at
  /// all could be read.
  void finish() const;

  [[nodiscard]] SourceKind kind() const noexcept { return kind_; }
  [[nodiscard]] const std::filesystem::path& input() const noexcept { return input_; }
  /// Total frames in the underlying sequence if known (lists and folders; videos that
  /// report a frame count), before start/end/stride.
  [[nodiscard]] std::optional<std::size_t> total() const noexcept;
  /// Every frame skipped so far (index, name, reason), in sequence order; its size is
  /// the count a command reports.
  [[nodiscard]] const std::vector<SkippedFrame>& skipped() const noexcept { return skipped_; }
  /// Frames returned by next() so far.
  [[nodiscard]] std::size_t delivered() const noexcept { return delivered_; }
  /// Frame times of a list, folder, TUM or EuRoC source (see the top of this file), with
  /// the time offset, without decoding an image; a video that states its frame count and
  /// rate: frame k at k / fps; empty for a live source or another video.
  [[nodiscard]] std::vector<double> timestamps() const;
  /// timestamps() in whole nanoseconds (Frame::time_ns).
  [[nodiscard]] std::vector<std::int64_t> times_ns() const;
  /// A bag's container (nullopt for other sources).
  [[nodiscard]] std::optional<BagFormat> bag_format() const noexcept;
  /// The bag topic read (its name, type and message count); nullopt for other sources.
  [[nodiscard]] std::optional<BagTopic> bag_topic() const;
  /// The calibration of a bag's CameraInfo topic beside the image topic (io/bag/bag.hpp),
  /// and where it came from; nullopt without one (see camera_note()).
  [[nodiscard]] const std::optional<BagCamera>& camera() const noexcept { return camera_; }
  /// Why a bag's CameraInfo topic gives no calibration; empty when it does or there is none.
  [[nodiscard]] const std::string& camera_note() const noexcept { return camera_note_; }
  /// Damage found in a bag so far (see FrameSourceOptions::on_warning).
  [[nodiscard]] const std::vector<std::string>& warnings() const noexcept { return warnings_; }
  /// Image paths of a list, folder, TUM or EuRoC source (empty for a video).
  [[nodiscard]] std::vector<std::filesystem::path> paths() const;

 private:
  /// What a video or camera source keeps (the capture), and what a bag source keeps;
  /// defined with the readers.
  struct VideoState;
  struct BagState;

  FrameSource();

  [[noreturn]] static void fail_missing(const std::filesystem::path& p);
  [[noreturn]] static void fail_no_image(const std::filesystem::path& folder);
  static FrameSource open_live(const std::string& source, FrameSourceOptions options);
  void open_video();
  bool read_video_frame(cv::Mat& img);
  void skip_video(std::size_t idx);
  std::optional<PendingFrame> claim_video();
  static double seconds_of(std::int64_t ns) noexcept;
  void open_bag();
  void report_bag_warnings();
  [[nodiscard]] std::vector<std::int64_t> bag_times_ns() const;
  std::optional<PendingFrame> claim_bag();
  [[nodiscard]] cv::Mat decode_bag_image(std::string_view bytes, std::string& reason) const;
  std::optional<PendingFrame> claim_image();
  [[nodiscard]] std::string size_reason(cv::Size s) const;

  std::filesystem::path input_;
  FrameSourceOptions options_;
  SourceKind kind_ = SourceKind::image_list;
  std::vector<detail::ListEntry> entries_;
  std::unique_ptr<VideoState> video_;
  cv::Mat pending_;
  std::size_t video_frames_ = 0;
  double video_fps_ = 0.0;
  std::size_t video_pos_ = 0;
  std::size_t next_index_ = 0;
  std::size_t delivered_ = 0;
  std::optional<bool> live_capture_clock_;  ///< live input: time frames by the capture (else wall clock)
  std::vector<SkippedFrame> skipped_;
  std::unique_ptr<BagState> bag_;
  std::optional<BagCamera> camera_;
  std::string camera_note_;
  std::vector<std::string> warnings_;
};

}  // namespace vmap

#ifndef VMAP_COMPILED_STACKS
#include <vmap/io/detail/frame_source_impl.hpp>
#endif
