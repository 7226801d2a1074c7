#pragma once

// The frame sources' readers (io/frame_source.hpp declares them): image lists, folders,
// EuRoC and TUM files, videos and cameras through OpenCV's videoio, and robot bags. A
// program includes io/frame_source.hpp, never this file: that header includes it unless
// the program links vmap::stacks, whose one translation unit for the readers includes it
// (core/compiled.hpp).

#include <vmap/core/compiled.hpp>
#include <vmap/core/error.hpp>
#include <vmap/io/bag/bag.hpp>
#include <vmap/io/detail/lines.hpp>
#include <vmap/io/detail/natural_order.hpp>
#include <vmap/io/files.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/io/image.hpp>
#include <vmap/io/timestamps.hpp>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>
#include <opencv2/videoio/registry.hpp>

#include <algorithm>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <system_error>
#include <utility>
#include <variant>
#include <vector>

namespace vmap {

namespace detail {

/// Whether a line begins with a number that is not finite ("inf", "nan", "-inf") and a
/// second token: a TUM line with a time no frame can have, refused rather than taken
/// for an image path with a space.
VMAP_INLINE bool starts_with_non_finite_time(const std::string& line) {
  const auto sp = line.find_first_of(" \t");
  if (sp == std::string::npos || trim(line.substr(sp)).empty()) return false;
  double t = 0;
  const auto [ptr, ec] = std::from_chars(line.data(), line.data() + sp, t);
  return ec == std::errc() && ptr == line.data() + sp && !std::isfinite(t);
}

/// "<timestamp> <path>" with a finite number first and one path token after: a TUM line.
/// `ns` is the time in nanoseconds, exact for a plain decimal number.
VMAP_INLINE bool parse_tum_line(const std::string& line, double& t, std::string& path, std::int64_t* ns = nullptr) {
  const auto sp = line.find_first_of(" \t");
  if (sp == std::string::npos) return false;
  const auto [ptr, ec] = std::from_chars(line.data(), line.data() + sp, t);
  if (ec != std::errc() || ptr != line.data() + sp || !std::isfinite(t)) return false;
  path = trim(line.substr(sp));
  if (ns) *ns = nanoseconds_from_decimal(std::string_view(line.data(), sp)).value_or(nanoseconds_from_seconds(t));
  return !path.empty() && path.find_first_of(" \t") == std::string::npos;
}

/// Reads a list file: either one image path a line, or TUM's "timestamp path" lines.
/// Relative paths are relative to the list's folder; '#' starts a comment line. The
/// first entry decides the format: when it is a TUM line every line must be one, and a
/// line that is not is an Error naming "file:line" (as pose files are read).
VMAP_INLINE std::vector<ListEntry> read_list(const std::filesystem::path& file, SourceKind& kind) {
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
  for (const auto& [line, no] : lines)
    if (starts_with_non_finite_time(line))
      fail("frame source: " + file.string() + ":" + std::to_string(no) + ": '" + line +
           "' has a time that is not a finite number");
  const bool tum = parse_tum_line(lines.front().first, t0, p0);
  kind = tum ? SourceKind::tum_rgb : SourceKind::image_list;
  const auto base = file.parent_path();
  std::vector<ListEntry> out;
  out.reserve(lines.size());
  for (std::size_t k = 0; k < lines.size(); ++k) {
    ListEntry e;
    std::string p = lines[k].first;
    if (tum) {
      if (!parse_tum_line(lines[k].first, e.timestamp, p, &e.time_ns))
        fail("frame source: " + file.string() + ":" + std::to_string(lines[k].second) + ": '" + lines[k].first +
             "' is not '<timestamp> <path>' like the lines before it (TUM rgb.txt)");
      if (!nanoseconds_in_range(e.timestamp))
        fail("frame source: " + file.string() + ":" + std::to_string(lines[k].second) + ": " +
             time_out_of_range(e.timestamp));
    } else {
      e.timestamp = static_cast<double>(k);
      e.time_ns = nanoseconds_from_seconds(e.timestamp);
    }
    std::filesystem::path path(p);
    e.path = path.is_absolute() ? path : base / path;
    out.push_back(std::move(e));
  }
  return out;
}

/// An ASL / EuRoC camera `data.csv`: `timestamp [ns],filename` a line (a '#' header
/// line first), the images in the `data/` folder beside it. Errors name "file:line". A
/// file name must stay inside `data/` (no absolute path, no ".." step) and the times must
/// strictly increase, as the recorder writes them: a name elsewhere would read a file the
/// recording does not hold, and a repeated or earlier time is a damaged or edited list
/// whose frames' order is unknown.
VMAP_INLINE std::vector<ListEntry> read_euroc_csv(const std::filesystem::path& file) {
  const std::string text = read_text_file(file, "frame source: EuRoC data.csv", max_list_file_bytes);
  const auto images = file.parent_path() / "data";
  std::vector<ListEntry> out;
  std::size_t previous_line = 0;
  for_each_line(text, [&](std::string_view raw, std::size_t no) {
    const std::string line = trim(std::string(raw));
    if (line.empty() || line[0] == '#') return;
    const auto comma = line.find(',');
    const std::string where = "frame source: " + file.string() + ":" + std::to_string(no) + ": ";
    std::uint64_t ns = 0;
    const auto [ptr, ec] = std::from_chars(line.data(), line.data() + (comma == std::string::npos ? 0 : comma), ns);
    if (comma == std::string::npos || ec != std::errc() || ptr != line.data() + comma)
      fail(where + "'" + line + "' is not '<timestamp [ns]>,<file name>' (EuRoC data.csv)");
    const std::string name = trim(line.substr(comma + 1));
    if (name.empty() || name.find(',') != std::string::npos)
      fail(where + "'" + line + "' is not '<timestamp [ns]>,<file name>' (EuRoC data.csv)");
    if (ns > static_cast<std::uint64_t>(std::numeric_limits<std::int64_t>::max()))
      fail(where + "timestamp " + std::to_string(ns) + " ns is beyond the year 2262");
    const std::filesystem::path relative(name);
    if (relative.is_absolute() || relative.has_root_path())
      fail(where + "file name '" + name + "' is an absolute path; EuRoC names the images of its data/ folder");
    for (const auto& step : relative)
      if (step == "..") fail(where + "file name '" + name + "' leaves the data/ folder ('..')");
    if (!out.empty() && static_cast<std::int64_t>(ns) <= out.back().time_ns)
      fail(where + "timestamp " + std::to_string(ns) + " ns is " +
           (static_cast<std::int64_t>(ns) == out.back().time_ns ? "the same as" : "before") + " line " +
           std::to_string(previous_line) + "'s (" + std::to_string(out.back().time_ns) +
           " ns); the times must increase");
    previous_line = no;
    out.push_back({images / name, seconds_from_nanoseconds(ns), static_cast<std::int64_t>(ns)});
  });
  if (out.empty()) fail("frame source: EuRoC data.csv '" + file.string() + "' names no image");
  return out;
}

/// The times of image files named by numbers (see the top of io/frame_source.hpp), or
/// nothing when one name is not a number: seconds, and the same in nanoseconds (exact
/// from the digits).
struct NameTimes {
  std::vector<double> seconds;
  std::vector<std::int64_t> ns;
};

VMAP_INLINE std::optional<NameTimes> times_from_names(const std::vector<std::string>& names,
                                                      const std::filesystem::path& folder) {
  const auto beyond = [&](const std::string& name, double seconds) {
    fail("frame source: folder '" + folder.string() + "', file '" + name + "' (its name is its time): " +
         time_out_of_range(seconds));
  };
  NameTimes out;
  std::vector<double>& values = out.seconds;
  bool fractional = false;
  for (const auto& n : names) {
    const std::string stem = std::filesystem::path(n).stem().string();
    const auto dot = stem.find('.');
    const auto all_digits = [](const std::string& d) {
      return !d.empty() && d.find_first_not_of("0123456789") == std::string::npos;
    };
    const bool number = all_digits(stem.substr(0, dot)) && (dot == std::string::npos || all_digits(stem.substr(dot + 1)));
    if (!number || stem.size() > 30) return std::nullopt;
    fractional = fractional || dot != std::string::npos;
    if (dot == std::string::npos) {
      std::uint64_t v = 0;
      const auto [ptr, ec] = std::from_chars(stem.data(), stem.data() + stem.size(), v);
      if (ec != std::errc() || ptr != stem.data() + stem.size()) return std::nullopt;
      values.push_back(static_cast<double>(v));
    } else {
      double v = 0;
      const auto [ptr, ec] = std::from_chars(stem.data(), stem.data() + stem.size(), v);
      if (ec != std::errc() || ptr != stem.data() + stem.size()) return std::nullopt;
      values.push_back(v);
    }
  }
  if (values.empty()) return out;
  if (fractional) {
    for (std::size_t k = 0; k < names.size(); ++k) {
      if (!nanoseconds_in_range(values[k])) beyond(names[k], values[k]);
      out.ns.push_back(nanoseconds_from_decimal(std::filesystem::path(names[k]).stem().string())
                           .value_or(nanoseconds_from_seconds(values[k])));
    }
    return out;
  }
  const double largest = *std::max_element(values.begin(), values.end());
  // Whole numbers: the unit by magnitude; nanoseconds converted exactly from the digits.
  const double unit = largest >= 1e17 ? 1e-9 : largest >= 1e14 ? 1e-6 : largest >= 1e11 ? 1e-3 : 1.0;
  const auto per_second = static_cast<std::uint64_t>(std::llround(1.0 / unit));
  for (std::size_t k = 0; k < names.size(); ++k) {
    const std::string stem = std::filesystem::path(names[k]).stem().string();
    std::uint64_t v = 0;
    (void)std::from_chars(stem.data(), stem.data() + stem.size(), v);
    const std::uint64_t ns_per_unit = 1000000000ULL / per_second;
    const double seconds = seconds_from_count(v, per_second);
    if (!nanoseconds_in_range(seconds)) beyond(names[k], seconds);
    out.ns.push_back(static_cast<std::int64_t>(v * ns_per_unit));  // within +-9.2e9 s: it fits
    if (unit == 1.0) continue;
    values[k] = seconds;
  }
  return out;
}

}  // namespace detail

struct FrameSource::VideoState {
  cv::VideoCapture capture;
};

/// What a bag source keeps: the message stream and the topic read. Read-only after
/// open_bag() except `stream` and `position`, which only claim() uses.
struct FrameSource::BagState {
  std::unique_ptr<detail::MessageStream> stream;
  BagFormat format = BagFormat::ros1;
  BagTopic topic;
  detail::RosMessageKind message = detail::RosMessageKind::image;
  std::vector<std::uint32_t> connections;
  std::string what;           ///< "bag 'x.bag'"
  std::size_t position = 0;   ///< messages of the topic read so far
  std::size_t warnings_seen = 0;
};

VMAP_INLINE FrameSource::FrameSource() = default;
VMAP_INLINE FrameSource::FrameSource(FrameSource&&) noexcept = default;
VMAP_INLINE FrameSource& FrameSource::operator=(FrameSource&&) noexcept = default;
VMAP_INLINE FrameSource::~FrameSource() = default;

VMAP_INLINE FrameSource FrameSource::open(const std::filesystem::path& input, FrameSourceOptions options) {
  detail::check(options.stride >= 1, "frame source: stride must be >= 1");
  detail::check(options.max_pixels >= 1, "frame source: max_pixels must be >= 1");
  detail::check(options.min_side >= 1, "frame source: min_side must be >= 1");
  detail::check(options.max_failed_reads >= 1, "frame source: max_failed_reads must be >= 1");
  detail::check(std::isfinite(options.time_offset), "frame source: time_offset must be a finite number of seconds");
  detail::check(nanoseconds_in_range(options.time_offset).has_value(),
                "frame source: time_offset: " + time_out_of_range(options.time_offset));
  detail::check(options.start < options.end, "frame source: start (" + std::to_string(options.start) +
                                                 ") must be before end (" + std::to_string(options.end) + ")");
  detail::check(options.resize.width >= 0 && options.resize.height >= 0 &&
                    (options.resize.width > 0) == (options.resize.height > 0),
                "frame source: resize must be (0, 0) or a positive size");
  if (detail::is_live_source(input.string())) return open_live(input.string(), std::move(options));
  std::error_code ec;
  if (!std::filesystem::exists(input, ec)) {
    if (ec && ec != std::errc::no_such_file_or_directory)
      detail::fail("frame source: '" + input.string() + "': " + ec.message());
    fail_missing(input);
  }
  // A FIFO or a device would be opened below as a video, and a FIFO's open waits for a
  // writer: refused by name first (cameras are given as "0" or /dev/video0, above).
  (void)detail::require_file_or_folder(input, "frame source: input");
  FrameSource s;
  s.input_ = input;
  s.options_ = std::move(options);
  s.next_index_ = s.options_.start;
  if (is_bag(input)) {
    s.kind_ = SourceKind::bag;
    s.open_bag();
  } else if (std::filesystem::is_directory(input, ec) && std::filesystem::is_regular_file(input / "data.csv", ec) &&
      std::filesystem::is_directory(input / "data", ec)) {
    s.kind_ = SourceKind::euroc;
    s.entries_ = detail::read_euroc_csv(input / "data.csv");
  } else if (std::filesystem::is_directory(input, ec)) {
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
    if (names.empty()) fail_no_image(input);
    std::sort(names.begin(), names.end(), detail::natural_less);
    const auto times = detail::times_from_names(names, input);
    for (std::size_t k = 0; k < names.size(); ++k) {
      const double t = times ? times->seconds[k] : static_cast<double>(k);
      s.entries_.push_back({input / names[k], t, times ? times->ns[k] : nanoseconds_from_seconds(t)});
    }
  } else if (input.extension() == ".csv") {
    s.kind_ = SourceKind::euroc;
    s.entries_ = detail::read_euroc_csv(input);
  } else if (input.extension() == ".txt" || input.extension() == ".lst") {
    s.entries_ = detail::read_list(input, s.kind_);
  } else {
    s.kind_ = SourceKind::video;
    s.open_video();
  }
  return s;
}

VMAP_INLINE std::optional<Frame> FrameSource::next() {
  while (auto pending = claim()) {
    auto decoded = decode(std::move(*pending));
    record(decoded);
    if (auto* f = std::get_if<Frame>(&decoded)) return std::move(*f);
  }
  finish();
  return std::nullopt;
}

VMAP_INLINE std::optional<PendingFrame> FrameSource::claim() {
  if (kind_ == SourceKind::bag) return claim_bag();
  return kind_ == SourceKind::video || kind_ == SourceKind::live ? claim_video() : claim_image();
}

VMAP_INLINE std::variant<Frame, SkippedFrame> FrameSource::decode(PendingFrame p) const {
  Frame f;
  f.index = p.index;
  f.name = std::move(p.name);
  f.timestamp = p.timestamp + options_.time_offset;
  const auto time_ns = add_nanoseconds(p.time_ns, nanoseconds_from_seconds(options_.time_offset));
  if (!time_ns)
    return SkippedFrame{p.index, f.name,
                        "with the time offset (FrameSourceOptions::time_offset), its " + time_out_of_range(f.timestamp)};
  f.time_ns = *time_ns;
  if (p.message_owner) {
    std::string reason;
    f.image = decode_bag_image(p.message, reason);
    if (f.image.empty())
      return SkippedFrame{p.index, f.name,
                          detail::message_where(bag_->what, bag_->format, bag_->topic.name, p.message_offset) + " (" +
                              bag_->topic.type + "): " + reason};
  } else if (p.path.empty()) {  // a video or camera frame, checked when read
    if (options_.grey && p.image.channels() != 1)
      cv::cvtColor(p.image, f.image, p.image.channels() == 4 ? cv::COLOR_BGRA2GRAY : cv::COLOR_BGR2GRAY);
    else
      f.image = std::move(p.image);
  } else {
    std::string reason;
    const ImageReadOptions how{.flags = options_.grey ? cv::IMREAD_GRAYSCALE : cv::IMREAD_UNCHANGED,
                               .max_pixels = options_.max_pixels};
    f.image = detail::try_read_image(p.path, how, reason);
    if (!f.image.empty() && (f.image.cols < options_.min_side || f.image.rows < options_.min_side)) {
      reason = size_reason(f.image.size());
      f.image.release();
    }
    if (f.image.empty()) {
      if (reason == "does not exist") reason = "file does not exist";
      return SkippedFrame{p.index, p.path.string(), std::move(reason)};
    }
  }
  if (options_.resize.width > 0 && f.image.size() != options_.resize)
    cv::resize(f.image, f.image, options_.resize, 0, 0, cv::INTER_AREA);
  return f;
}

VMAP_INLINE void FrameSource::record(const std::variant<Frame, SkippedFrame>& decoded) {
  if (const auto* s = std::get_if<SkippedFrame>(&decoded)) {
    if (options_.on_skip) options_.on_skip(*s);
    skipped_.push_back(*s);
  } else {
    ++delivered_;
  }
}

VMAP_INLINE void FrameSource::finish() const {
  if (delivered_ == 0 && !skipped_.empty())
    detail::fail("frame source: no frame of '" + input_.string() + "' could be read (" +
                 std::to_string(skipped_.size()) + " unreadable, first: " + skipped_.front().name + ")");
}

VMAP_INLINE std::optional<std::size_t> FrameSource::total() const noexcept {
  if (kind_ == SourceKind::live) return std::nullopt;
  if (kind_ == SourceKind::bag) return static_cast<std::size_t>(bag_->topic.messages);
  if (kind_ != SourceKind::video) return entries_.size();
  return video_frames_ > 0 ? std::optional<std::size_t>(video_frames_) : std::nullopt;
}

VMAP_INLINE std::vector<double> FrameSource::timestamps() const {
  std::vector<double> out;
  if (kind_ == SourceKind::bag) {
    for (std::int64_t t : bag_times_ns()) out.push_back(seconds_of(t) + options_.time_offset);
    return out;
  }
  if (kind_ == SourceKind::video && video_frames_ > 0 && video_fps_ > 0) {
    // Frame k at k / fps: the times next() reports for a constant-rate video.
    for (std::size_t k = 0; k < video_frames_; ++k) out.push_back(static_cast<double>(k) / video_fps_ + options_.time_offset);
    return out;
  }
  out.reserve(entries_.size());
  for (const auto& e : entries_) out.push_back(e.timestamp + options_.time_offset);
  return out;
}

VMAP_INLINE std::vector<std::int64_t> FrameSource::times_ns() const {
  std::vector<std::int64_t> out;
  const std::int64_t offset = nanoseconds_from_seconds(options_.time_offset);
  const auto shifted = [&](std::int64_t t) {
    const auto sum = add_nanoseconds(t, offset);
    if (!sum)
      detail::fail("frame source: '" + input_.string() + "': with the time offset (FrameSourceOptions::time_offset), " +
                   "a frame's " + time_out_of_range(seconds_of(t) + options_.time_offset));
    return *sum;
  };
  if (kind_ == SourceKind::bag) {
    out = bag_times_ns();
    for (auto& t : out) t = shifted(t);
    return out;
  }
  if (kind_ == SourceKind::video) {
    for (double t : timestamps()) out.push_back(nanoseconds_from_seconds(t));
    return out;
  }
  out.reserve(entries_.size());
  for (const auto& e : entries_) out.push_back(shifted(e.time_ns));
  return out;
}

VMAP_INLINE std::optional<BagFormat> FrameSource::bag_format() const noexcept {
  return bag_ ? std::optional<BagFormat>(bag_->format) : std::nullopt;
}

VMAP_INLINE std::optional<BagTopic> FrameSource::bag_topic() const {
  return bag_ ? std::optional<BagTopic>(bag_->topic) : std::nullopt;
}

VMAP_INLINE std::vector<std::filesystem::path> FrameSource::paths() const {
  std::vector<std::filesystem::path> out;
  out.reserve(entries_.size());
  for (const auto& e : entries_) out.push_back(e.path);
  return out;
}

VMAP_INLINE void FrameSource::fail_missing(const std::filesystem::path& p) {
  detail::fail(ErrorKind::not_found, "frame source: '" + p.string() + "' does not exist");
}

/// A folder without images; a EuRoC recording (`mav0`, whose cameras are `cam0`,
/// `cam1`, ... with `data.csv` and `data/`) gets its camera folders named, as it holds
/// one sequence per camera and which one is meant is the user's choice.
VMAP_INLINE void FrameSource::fail_no_image(const std::filesystem::path& folder) {
  std::vector<std::string> cameras;
  std::error_code ec;
  for (std::filesystem::directory_iterator it(folder, ec), end; !ec && it != end; it.increment(ec))
    if (std::filesystem::is_regular_file(it->path() / "data.csv", ec) && std::filesystem::is_directory(it->path() / "data", ec))
      cameras.push_back((folder / it->path().filename()).string());
  std::sort(cameras.begin(), cameras.end());
  std::string what = "frame source: folder '";
  what += folder.string();
  what += "' contains no image file";
  if (!cameras.empty()) {
    what += "; it is a EuRoC recording: give one of its camera folders (";
    for (std::size_t k = 0; k < cameras.size(); ++k) {
      if (k > 0) what += ", ";
      what += cameras[k];
    }
    what += ')';
  }
  detail::fail(what);
}

/// A camera index, device, URL or pipeline through cv::VideoCapture: no existence
/// check, GStreamer for pipelines, any backend otherwise.
VMAP_INLINE FrameSource FrameSource::open_live(const std::string& source, FrameSourceOptions options) {
  FrameSource s;
  s.input_ = source;
  s.options_ = std::move(options);
  s.kind_ = SourceKind::live;
  s.video_ = std::make_unique<VideoState>();
  const bool index = std::all_of(source.begin(), source.end(), [](unsigned char c) { return std::isdigit(c) != 0; });
  try {
    if (index)
      s.video_->capture.open(std::stoi(source), cv::CAP_ANY);
    else if (source.find('!') != std::string::npos)
      s.video_->capture.open(source, cv::CAP_GSTREAMER);
    else
      s.video_->capture.open(source, cv::CAP_ANY);
  } catch (const std::exception&) {  // cv::Exception, or std::stoi's out_of_range for a huge index
    s.video_->capture.release();
  }
  if (!s.video_->capture.isOpened())
    detail::fail("frame source: cannot open live input '" + source + "' (" +
                 (index ? "no camera with this index"
                  : source.find('!') != std::string::npos ? "GStreamer pipeline did not start"
                                                           : "device or stream not available") +
                 "; file paths that look like this need a ./ prefix)");
  s.next_index_ = s.options_.start;
  return s;
}

VMAP_INLINE void FrameSource::open_video() {
  video_ = std::make_unique<VideoState>();
  // Try OpenCV's file backends one by one, skipping CAP_IMAGES (folders and lists are
  // handled above) and CAP_GPHOTO2 (it probes USB cameras for every file name, which
  // is slow and leaks in libgphoto2).
  for (const cv::VideoCaptureAPIs api : cv::videoio_registry::getStreamBackends()) {
    if (api == cv::CAP_IMAGES || api == cv::CAP_GPHOTO2) continue;
    try {
      if (video_->capture.open(input_.string(), api)) break;
    } catch (const cv::Exception&) {
      video_->capture.release();  // a backend that throws on this file: try the next one
    }
  }
  if (!video_->capture.isOpened())
    detail::fail("frame source: cannot open '" + input_.string() +
                 "' as a video (and it is not a folder or a .txt list)");
  const double count = video_->capture.get(cv::CAP_PROP_FRAME_COUNT);
  video_frames_ = count > 0 && count < 1e12 ? static_cast<std::size_t>(count) : 0;
  const double fps = video_->capture.get(cv::CAP_PROP_FPS);
  video_fps_ = std::isfinite(fps) && fps > 0 && fps < 1e6 ? fps : 0.0;
  const double w = video_->capture.get(cv::CAP_PROP_FRAME_WIDTH), h = video_->capture.get(cv::CAP_PROP_FRAME_HEIGHT);
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
VMAP_INLINE bool FrameSource::read_video_frame(cv::Mat& img) {
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
      ok = video_->capture.read(img) && !img.empty();
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

VMAP_INLINE void FrameSource::skip_video(std::size_t idx) {
  record(SkippedFrame{idx, input_.filename().string() + "#" + std::to_string(idx),
                      "the video decoder could not read this frame"});
}

VMAP_INLINE std::optional<PendingFrame> FrameSource::claim_video() {
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
      record(SkippedFrame{idx, input_.filename().string() + "#" + std::to_string(idx), size_reason(img.size())});
      continue;
    }
    next_index_ = detail::saturating_add(idx, options_.stride);
    PendingFrame f;
    f.index = idx;
    f.name = (kind_ == SourceKind::live ? input_.string() : input_.filename().string()) + "#" + std::to_string(idx);
    const double msec = video_->capture.get(cv::CAP_PROP_POS_MSEC);
    f.timestamp = msec / 1000.0;
    f.time_ns = nanoseconds_from_seconds(msec / 1000.0);
    if (kind_ == SourceKind::live) {
      // The capture's clock when its first frame has one; otherwise (cameras without a
      // stream clock) the Unix time of each read, so that frames line up with ground
      // truth or odometry stamped by the system clock. Decided once: no mixed clocks.
      if (!live_capture_clock_) live_capture_clock_ = f.timestamp > 0.0;
      if (!*live_capture_clock_) {
        const auto now = std::chrono::system_clock::now().time_since_epoch();
        f.timestamp = std::chrono::duration<double>(now).count();
        f.time_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(now).count();
      }
    }
    f.image = std::move(img);
    return f;
  }
  return std::nullopt;
}

VMAP_INLINE double FrameSource::seconds_of(std::int64_t ns) noexcept {
  return ns < 0 ? -seconds_from_nanoseconds(static_cast<std::uint64_t>(-(ns + 1)) + 1) :
                  seconds_from_nanoseconds(static_cast<std::uint64_t>(ns));
}

VMAP_INLINE void FrameSource::open_bag() {
  auto b = std::make_unique<BagState>();
  b->stream = detail::open_message_stream(input_, options_.bag_limits);
  b->format = b->stream->format();
  b->what = "bag '" + input_.string() + "'";
  const auto topics = detail::bag_topics(*b->stream);
  b->topic = detail::choose_image_topic(topics, options_.topic, b->what);
  b->message = detail::ros_message_kind(b->topic.type);
  b->connections = detail::image_connections(*b->stream, b->topic);
  b->stream->select(b->connections);
  bag_ = std::move(b);
  report_bag_warnings();
  camera_ = detail::read_bag_camera(input_, topics, detail::camera_info_topic_for(bag_->topic.name),
                                    options_.bag_limits, camera_note_);
}

VMAP_INLINE void FrameSource::report_bag_warnings() {
  const auto& w = bag_->stream->warnings();
  for (; bag_->warnings_seen < w.size(); ++bag_->warnings_seen) {
    warnings_.push_back(w[bag_->warnings_seen]);
    if (options_.on_warning) options_.on_warning(warnings_.back());
  }
}

/// The topic's frame times (header stamps or record times), by a pass of their own
/// over the bag (a message whose header cannot be read keeps its record time).
VMAP_INLINE std::vector<std::int64_t> FrameSource::bag_times_ns() const {
  std::vector<std::int64_t> out;
  auto stream = detail::open_message_stream(input_, options_.bag_limits);
  stream->select(bag_->connections);
  detail::StreamMessage m;
  while (stream->next(m)) {
    std::int64_t t = m.record_ns;
    if (!options_.record_time) {
      try {
        t = detail::message_stamp(bag_->topic.encoding, m.bytes, bag_->what);
      } catch (const Error&) {
      }
    }
    out.push_back(t);
  }
  return out;
}

VMAP_INLINE std::optional<PendingFrame> FrameSource::claim_bag() {
  BagState& b = *bag_;
  detail::StreamMessage m;
  while (next_index_ < options_.end) {
    const bool more = b.stream->next(m);
    report_bag_warnings();
    if (!more) return std::nullopt;
    const std::size_t idx = b.position++;
    if (idx < next_index_) continue;  // before start or between strides
    next_index_ = detail::saturating_add(idx, options_.stride);
    std::int64_t t = m.record_ns;
    if (!options_.record_time) {
      try {
        t = detail::message_stamp(b.topic.encoding, m.bytes,
                                  detail::message_where(b.what, b.format, b.topic.name, m.offset));
      } catch (const Error& e) {
        record(SkippedFrame{idx, b.topic.name + "@" + std::to_string(m.record_ns), e.what()});
        continue;
      }
    }
    PendingFrame f;
    f.index = idx;
    f.name = b.topic.name + "@" + std::to_string(t);
    f.timestamp = seconds_of(t);
    f.time_ns = t;
    f.message = m.bytes;
    f.message_owner = std::move(m.owner);
    f.message_offset = m.offset;
    return f;
  }
  return std::nullopt;
}

/// The image of a claimed bag message, or empty and the reason.
VMAP_INLINE cv::Mat FrameSource::decode_bag_image(std::string_view bytes, std::string& reason) const {
  const detail::ImageBounds bounds{options_.max_pixels, options_.min_side};
  try {
    return detail::with_message_reader(bag_->topic.encoding, bytes, "the message", [&](auto& r, bool ros1) {
      if (bag_->message == detail::RosMessageKind::image)
        return detail::image_from_raw(detail::read_image_message(r, ros1), options_.grey, bounds, reason);
      return detail::image_from_compressed(detail::read_compressed_image_message(r, ros1), options_.grey, bounds, reason);
    });
  } catch (const Error& e) {
    reason = e.what();
  } catch (const cv::Exception& e) {
    reason = "OpenCV could not convert it: " + e.err;
  }
  return {};
}

VMAP_INLINE std::optional<PendingFrame> FrameSource::claim_image() {
  if (next_index_ >= options_.end || next_index_ >= entries_.size()) return std::nullopt;
  const std::size_t idx = next_index_;
  next_index_ = detail::saturating_add(next_index_, options_.stride);
  const auto& e = entries_[idx];
  return PendingFrame{idx, e.path.filename().string(), e.timestamp, e.time_ns, e.path, {}, {}, {}, 0};
}

VMAP_INLINE std::string FrameSource::size_reason(cv::Size s) const {
  return "the frame is " + std::to_string(s.width) + "x" + std::to_string(s.height) + " pixels, outside " +
         std::to_string(options_.min_side) + "x" + std::to_string(options_.min_side) + " .. " +
         std::to_string(options_.max_pixels) + " pixels (FrameSourceOptions min_side, max_pixels)";
}

}  // namespace vmap
