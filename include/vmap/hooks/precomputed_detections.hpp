#pragma once

// Detections computed offline (any network, any runtime) and read back from a text file,
// so loop closure can be run and evaluated without a detector at hand.
//
// File format (one detection a line, whitespace-separated; '#' starts a comment line):
//   <frame> <label> <score> <x> <y> <w> <h>
// frame: 0-based index in the sequence; label: integer class id (e.g. COCO-80 order);
// score in [0, 1]; box in input-image pixels (top-left x, y, width, height). Frames
// without detections have no line. The optional comment `# frames N` gives the sequence
// length so that trailing frames without detections are known. Detections are stored
// unfiltered: the consumer applies its own score threshold.

#include <vmap/core/error.hpp>
#include <vmap/hooks/detection.hpp>
#include <vmap/io/atomic_file.hpp>

#include <opencv2/core.hpp>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <optional>
#include <sstream>
#include <string>
#include <string_view>
#include <system_error>
#include <utility>
#include <vector>

namespace vmap {

namespace detail {

inline std::vector<std::string_view> split_detection_fields(std::string_view line) {
  std::vector<std::string_view> out;
  std::size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && (line[i] == ' ' || line[i] == '\t' || line[i] == '\r')) ++i;
    const std::size_t b = i;
    while (i < line.size() && line[i] != ' ' && line[i] != '\t' && line[i] != '\r') ++i;
    if (i > b) out.push_back(line.substr(b, i - b));
  }
  return out;
}

/// Parses a whole token as T (integers or floating point); nullopt on any junk.
template <class T>
std::optional<T> parse_detection_field(std::string_view token) {
  T value{};
  const char* end = token.data() + token.size();
  const auto [ptr, ec] = std::from_chars(token.data(), end, value);
  if (ec != std::errc() || ptr != end) return std::nullopt;
  return value;
}

}  // namespace detail

/// Per-frame detections read from a labels file (format above). Models ObjectDetector:
/// the k-th `detect` call returns the detections of frame k (from the `seek` position),
/// without looking at the image, so a LoopDetector fed the same frames in order sees
/// exactly what the offline network saw. `at(frame)` gives random access by index.
/// Memory is proportional to the number of detections, whatever the frame indices say.
/// Const members are safe to call concurrently; `detect` and `seek` move the cursor.
class PrecomputedDetections {
 public:
  PrecomputedDetections() = default;

  /// From detections held in memory: `per_frame[k]` are frame k's detections, and the
  /// sequence has `per_frame.size()` frames.
  explicit PrecomputedDetections(const std::vector<std::vector<Detection>>& per_frame)
      : frames_(per_frame.size()), declared_(true) {
    for (std::size_t k = 0; k < per_frame.size(); ++k)
      for (const Detection& d : per_frame[k]) {
        check_detection(d, "PrecomputedDetections: frame " + std::to_string(k) + ": ");
        entries_.emplace_back(k, d);
      }
  }

  /// Reads a labels file; any malformed line is an Error naming the file and line.
  [[nodiscard]] static PrecomputedDetections load(const std::filesystem::path& path) {
    return parse(read_text_file(path, "detections file"), path.string());
  }

  /// Parses the text of a labels file; `name` is used in error messages.
  [[nodiscard]] static PrecomputedDetections parse(std::string_view text, const std::string& name = "<labels>") {
    PrecomputedDetections out;
    std::optional<std::size_t> declared;
    std::size_t line_no = 0;
    std::size_t max_frame_plus_one = 0;
    std::size_t pos = 0;
    while (pos <= text.size()) {
      const std::size_t nl = text.find('\n', pos);
      const std::string_view line = text.substr(pos, nl == std::string_view::npos ? text.size() - pos : nl - pos);
      pos = nl == std::string_view::npos ? text.size() + 1 : nl + 1;
      ++line_no;
      const auto where = [&] { return name + ":" + std::to_string(line_no) + ": "; };
      const auto tokens = detail::split_detection_fields(line);
      if (tokens.empty()) continue;
      if (tokens[0].front() == '#') {
        // `# frames N` is the only comment with a meaning; others are free text.
        std::vector<std::string_view> words = tokens;
        if (words[0] == "#") words.erase(words.begin());
        else words[0].remove_prefix(1);
        if (words.size() >= 1 && words[0] == "frames") {
          const auto n = words.size() == 2 ? detail::parse_detection_field<std::size_t>(words[1]) : std::nullopt;
          if (!n) detail::fail(where() + "'# frames' must be followed by one non-negative integer");
          if (declared && *declared != *n)
            detail::fail(where() + "'# frames " + std::to_string(*n) + "' contradicts an earlier '# frames " +
                         std::to_string(*declared) + "'");
          declared = n;
        }
        continue;
      }
      if (tokens.size() != 7)
        detail::fail(where() + "expected 7 fields '<frame> <label> <score> <x> <y> <w> <h>', got " +
                     std::to_string(tokens.size()));
      const auto frame = detail::parse_detection_field<std::size_t>(tokens[0]);
      if (!frame || *frame == std::numeric_limits<std::size_t>::max())
        detail::fail(where() + "frame '" + std::string(tokens[0]) + "' is not a non-negative integer");
      const auto label = detail::parse_detection_field<int>(tokens[1]);
      if (!label) detail::fail(where() + "label '" + std::string(tokens[1]) + "' is not an integer");
      double values[5];
      for (int k = 0; k < 5; ++k) {
        const auto v = detail::parse_detection_field<double>(tokens[static_cast<std::size_t>(2 + k)]);
        if (!v) detail::fail(where() + "field '" + std::string(tokens[static_cast<std::size_t>(2 + k)]) + "' is not a number");
        values[k] = *v;
      }
      Detection d;
      d.label = *label;
      d.score = static_cast<float>(values[0]);
      d.box = cv::Rect2f(static_cast<float>(values[1]), static_cast<float>(values[2]), static_cast<float>(values[3]),
                         static_cast<float>(values[4]));
      check_detection(d, where());
      out.entries_.emplace_back(*frame, d);
      max_frame_plus_one = std::max(max_frame_plus_one, *frame + 1);
    }
    if (declared && max_frame_plus_one > *declared)
      detail::fail(name + ": a detection of frame " + std::to_string(max_frame_plus_one - 1) +
                   " lies beyond '# frames " + std::to_string(*declared) + "'");
    // Stable: detections of one frame keep the file's order.
    std::stable_sort(out.entries_.begin(), out.entries_.end(),
                     [](const auto& a, const auto& b) { return a.first < b.first; });
    out.frames_ = declared ? *declared : max_frame_plus_one;
    out.declared_ = declared.has_value();
    return out;
  }

  /// Number of frames: as declared by `# frames N`, else one past the last frame with a
  /// detection.
  [[nodiscard]] std::size_t frames() const noexcept { return frames_; }
  /// Whether the length came from `# frames N` (else trailing empty frames are unknown).
  [[nodiscard]] bool frames_declared() const noexcept { return declared_; }
  /// Total number of detections over all frames.
  [[nodiscard]] std::size_t detections() const noexcept { return entries_.size(); }

  /// Detections of one frame. Beyond a declared length: Error. Without a declared length,
  /// a frame past the last listed one simply has no detections.
  [[nodiscard]] std::vector<Detection> at(std::size_t frame) const {
    if (declared_ && frame >= frames_)
      detail::fail("PrecomputedDetections: frame " + std::to_string(frame) + " requested, but the labels cover " +
                   std::to_string(frames_) + " frames");
    const auto lo = std::lower_bound(entries_.begin(), entries_.end(), frame,
                                     [](const auto& e, std::size_t f) { return e.first < f; });
    std::vector<Detection> out;
    for (auto it = lo; it != entries_.end() && it->first == frame; ++it) out.push_back(it->second);
    return out;
  }

  /// ObjectDetector: the detections of the next frame (the image is not looked at).
  [[nodiscard]] std::vector<Detection> detect(const cv::Mat& /*image*/) { return at(cursor_++); }

  /// The frame the next `detect` returns.
  void seek(std::size_t frame) noexcept { cursor_ = frame; }
  [[nodiscard]] std::size_t cursor() const noexcept { return cursor_; }

  /// The file text, with `# frames N` so that trailing empty frames survive a round trip.
  [[nodiscard]] std::string to_text() const {
    std::string out = "# vmap detections: <frame> <label> <score> <x> <y> <w> <h>\n# frames " +
                      std::to_string(frames_) + "\n";
    char buf[256];
    for (const auto& [frame, d] : entries_) {
      // %.9g prints a float so that it parses back to the same float.
      std::snprintf(buf, sizeof buf, "%zu %d %.9g %.9g %.9g %.9g %.9g\n", frame, d.label, static_cast<double>(d.score),
                    static_cast<double>(d.box.x), static_cast<double>(d.box.y), static_cast<double>(d.box.width),
                    static_cast<double>(d.box.height));
      out += buf;
    }
    return out;
  }

  /// Writes the labels file atomically.
  void save(const std::filesystem::path& path) const { write_file_atomically(path, to_text()); }

 private:
  static void check_detection(const Detection& d, const std::string& where) {
    if (d.label < 0) detail::fail(where + "label " + std::to_string(d.label) + " is negative");
    if (!(d.score >= 0.0f && d.score <= 1.0f))  // also rejects NaN
      detail::fail(where + "score " + std::to_string(d.score) + " is not in [0, 1]");
    const bool finite = std::isfinite(d.box.x) && std::isfinite(d.box.y) && std::isfinite(d.box.width) &&
                        std::isfinite(d.box.height);
    if (!finite || d.box.width < 0.0f || d.box.height < 0.0f)
      detail::fail(where + "box must be finite with non-negative width and height");
  }

  std::vector<std::pair<std::size_t, Detection>> entries_;  // sorted by frame
  std::size_t frames_ = 0;
  bool declared_ = false;
  std::size_t cursor_ = 0;
};

static_assert(ObjectDetector<PrecomputedDetections>);

/// Writes per-frame detections (`per_frame[k]` = frame k) as a labels file, atomically.
inline void save_detections(const std::filesystem::path& path, const std::vector<std::vector<Detection>>& per_frame) {
  PrecomputedDetections(per_frame).save(path);
}

}  // namespace vmap
