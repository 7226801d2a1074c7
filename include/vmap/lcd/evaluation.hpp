#pragma once

// Evaluation of loop closure against ground truth (Zhu et al., Sensors 2021, sec. 4;
// examples/methods.md, sec. 2 step 6): precision = TP / (TP + FP), recall = TP / (TP + FN), the
// precision-recall curve over the decision threshold, and the recall at 100 % precision,
// the headline figure of the loop-closure literature (a false loop corrupts a map, a
// missed one only delays its correction).
//
// Counting (the same as ../shared/baselines/lcd_bruteforce.cpp): each query frame
// proposes at most one loop, its best-scoring candidate. At threshold t, a query whose
// best score is >= t is a detection; it is a true positive when the ground truth marks
// (query, candidate), else a false positive. Positives are the query frames whose
// ground-truth row holds any loop; FN = positives - TP.

#include <vmap/core/error.hpp>
#include <vmap/io/atomic_file.hpp>
#include <vmap/io/detail/lines.hpp>
#include <vmap/io/poses.hpp>

#include <opencv2/core.hpp>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <limits>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace vmap {

/// A square 0/1 matrix over the frames of a sequence: `(q, j)` is true when query frame
/// q closes a loop with frame j.
class LoopGroundTruth {
 public:
  /// The largest matrix `parse` accepts (frames per side): 4e8 cells at most.
  static constexpr std::size_t max_frames = 20000;

  LoopGroundTruth() = default;

  /// An all-zero matrix over `frames` frames.
  explicit LoopGroundTruth(std::size_t frames) : frames_(frames) {
    detail::check(frames <= max_frames, [&] {
      return "LoopGroundTruth: " + std::to_string(frames) + " frames exceed the limit of " + std::to_string(max_frames);
    });
    cells_.assign(frames * frames, 0);
  }

  /// Parses rows of whitespace-separated 0/1 values (one row per query frame, as in
  /// rtabmap_loop/gt_loop_matrix_84x84.txt). `expected_frames` (when given) must match.
  [[nodiscard]] static LoopGroundTruth parse(std::string_view text, const std::string& name = "<ground truth>",
                                             std::optional<std::size_t> expected_frames = std::nullopt) {
    std::vector<std::vector<std::uint8_t>> rows;
    detail::for_each_line(text, [&](std::string_view line, std::size_t line_no) {
      std::vector<std::uint8_t> row;
      for (char ch : line) {
        if (ch == '0' || ch == '1') {
          row.push_back(static_cast<std::uint8_t>(ch - '0'));
        } else if (ch != ' ' && ch != '\t' && ch != '\r' && ch != ',') {
          detail::fail(name + ":" + std::to_string(line_no) + ": ground-truth values must be 0 or 1, found '" +
                       std::string(1, ch) + "'");
        }
        // A value is one character: "01" would read as two cells, so reject adjacency.
        if (row.size() > max_frames) detail::fail(name + ":" + std::to_string(line_no) + ": row is too long");
      }
      if (line.find("00") != std::string_view::npos || line.find("01") != std::string_view::npos ||
          line.find("10") != std::string_view::npos || line.find("11") != std::string_view::npos)
        detail::fail(name + ":" + std::to_string(line_no) + ": values must be separated by whitespace");
      if (row.empty()) return;
      if (rows.size() >= max_frames) detail::fail(name + ": more than " + std::to_string(max_frames) + " rows");
      rows.push_back(std::move(row));
    });
    for (std::size_t r = 0; r < rows.size(); ++r)
      if (rows[r].size() != rows.size())
        detail::fail(name + ": the ground-truth matrix is not square (" + std::to_string(rows.size()) + " rows, row " +
                     std::to_string(r + 1) + " has " + std::to_string(rows[r].size()) + " values)");
    if (expected_frames && rows.size() != *expected_frames)
      detail::fail(name + ": the ground truth covers " + std::to_string(rows.size()) + " frames but the sequence has " +
                   std::to_string(*expected_frames));
    LoopGroundTruth gt(rows.size());
    for (std::size_t q = 0; q < rows.size(); ++q)
      for (std::size_t j = 0; j < rows.size(); ++j) gt.set(q, j, rows[q][j] != 0);
    return gt;
  }

  /// Reads a ground-truth file (format: parse). Errors (vmap::Error naming the file):
  /// missing, a folder or device, unreadable, larger than the largest matrix's text, or
  /// malformed ("file:line").
  [[nodiscard]] static LoopGroundTruth load(const std::filesystem::path& path,
                                            std::optional<std::size_t> expected_frames = std::nullopt) {
    // The largest matrix takes two characters a cell ("0 "), plus line ends ("\r\n").
    constexpr std::uintmax_t max_bytes = std::uintmax_t{2} * max_frames * max_frames + 2 * max_frames;
    return parse(read_text_file(path, "ground truth file", max_bytes), path.string(), expected_frames);
  }

  /// The matrix as text, one row per line (the format `parse` reads).
  [[nodiscard]] std::string to_text() const {
    std::string out;
    out.reserve(frames_ * frames_ * 2);
    for (std::size_t q = 0; q < frames_; ++q) {
      for (std::size_t j = 0; j < frames_; ++j) {
        if (j) out += ' ';
        out += (*this)(q, j) ? '1' : '0';
      }
      out += '\n';
    }
    return out;
  }

  void save(const std::filesystem::path& path) const { write_file_atomically(path, to_text()); }

  [[nodiscard]] std::size_t frames() const noexcept { return frames_; }
  [[nodiscard]] bool operator()(std::size_t query, std::size_t frame) const {
    check_index(query, frame);
    return cells_[query * frames_ + frame] != 0;
  }
  void set(std::size_t query, std::size_t frame, bool loop) {
    check_index(query, frame);
    cells_[query * frames_ + frame] = loop ? 1 : 0;
  }
  /// Whether the query frame's row holds any loop (a positive of the recall).
  [[nodiscard]] bool has_loop(std::size_t query) const {
    check_index(query, 0);
    const auto row = cells_.begin() + static_cast<std::ptrdiff_t>(query * frames_);
    return std::any_of(row, row + static_cast<std::ptrdiff_t>(frames_), [](std::uint8_t c) { return c != 0; });
  }
  /// Number of query frames with a loop.
  [[nodiscard]] std::size_t loop_frames() const {
    std::size_t n = 0;
    for (std::size_t q = 0; q < frames_; ++q) n += has_loop(q) ? 1 : 0;
    return n;
  }

 private:
  void check_index(std::size_t query, std::size_t frame) const {
    if (query >= frames_ || (frame >= frames_ && frames_ > 0) || frames_ == 0)
      detail::fail("LoopGroundTruth: cell (" + std::to_string(query) + ", " + std::to_string(frame) +
                   ") outside a matrix of " + std::to_string(frames_) + " frames");
  }

  std::size_t frames_ = 0;
  std::vector<std::uint8_t> cells_;
};

/// When two poses count as the same place.
struct PoseLoopOptions {
  double max_distance = 0.5;   ///< metres between camera centres
  double max_angle_deg = 30.0; ///< degrees between optical axes
  /// Only frames j with j + window < q are loops of q: nearer frames are trivially
  /// similar, and a detector excludes them (the same window as LoopDetectorOptions).
  std::size_t window = 10;
};

/// Ground truth from poses: (q, j) is a loop when j + window < q, the camera centres lie
/// within max_distance and the viewing directions within max_angle_deg.
[[nodiscard]] inline LoopGroundTruth ground_truth_from_poses(const std::vector<CameraPose>& poses,
                                                             const PoseLoopOptions& options = {}) {
  detail::check(std::isfinite(options.max_distance) && options.max_distance >= 0,
                "PoseLoopOptions.max_distance must be finite and >= 0");
  detail::check(std::isfinite(options.max_angle_deg) && options.max_angle_deg >= 0 && options.max_angle_deg <= 180,
                "PoseLoopOptions.max_angle_deg must be in [0, 180]");
  LoopGroundTruth gt(poses.size());
  const double cos_max = std::cos(options.max_angle_deg * CV_PI / 180.0);
  for (std::size_t q = 0; q < poses.size(); ++q)
    for (std::size_t j = 0; j + options.window < q; ++j) {
      const double d = cv::norm(poses[q].position - poses[j].position);
      const double c = poses[q].viewing_direction().dot(poses[j].viewing_direction());
      gt.set(q, j, d <= options.max_distance && c >= cos_max - 1e-12);
    }
  return gt;
}

/// A detector's answer for one query frame: its best candidate (none when nothing was
/// verified) and that candidate's score (e.g. inlier count); higher = more confident.
struct LoopScore {
  std::size_t query = 0;
  std::optional<std::size_t> match;
  double score = 0.0;
};

/// One point of the precision-recall curve.
struct PrecisionRecall {
  double threshold = 0.0;  ///< detections are the queries with score >= threshold
  std::size_t true_positives = 0;
  std::size_t false_positives = 0;
  std::size_t false_negatives = 0;
  std::size_t positives = 0;  ///< query frames with a ground-truth loop
  double precision = 1.0;     ///< 1 when nothing is detected (no claim, no error)
  double recall = 0.0;        ///< 0 when the ground truth has no loop
};

namespace detail {

inline void check_loop_scores(const std::vector<LoopScore>& scores, const LoopGroundTruth& gt) {
  for (const LoopScore& s : scores) {
    if (s.query >= gt.frames())
      fail("loop evaluation: query frame " + std::to_string(s.query) + " outside the ground truth of " +
           std::to_string(gt.frames()) + " frames (does the ground truth match the sequence?)");
    if (s.match && *s.match >= gt.frames())
      fail("loop evaluation: candidate frame " + std::to_string(*s.match) + " outside the ground truth");
    if (!std::isfinite(s.score)) fail("loop evaluation: query " + std::to_string(s.query) + " has a non-finite score");
  }
}

}  // namespace detail

namespace detail {

/// Precision and recall from the counts at one threshold (shared by evaluate_loops and
/// the curve, so both give bit-identical figures).
[[nodiscard]] inline PrecisionRecall precision_recall_from_counts(double threshold, std::size_t positives,
                                                                   std::size_t true_positives,
                                                                   std::size_t false_positives) {
  PrecisionRecall pr;
  pr.threshold = threshold;
  pr.positives = positives;
  pr.true_positives = true_positives;
  pr.false_positives = false_positives;
  pr.false_negatives = pr.positives - std::min(pr.positives, pr.true_positives);
  const std::size_t detected = pr.true_positives + pr.false_positives;
  pr.precision = detected == 0 ? 1.0 : static_cast<double>(pr.true_positives) / static_cast<double>(detected);
  pr.recall = pr.positives == 0 ? 0.0 : static_cast<double>(pr.true_positives) / static_cast<double>(pr.positives);
  return pr;
}

}  // namespace detail

/// Precision and recall at one decision threshold. Positives are counted over the whole
/// ground truth, so a frame the detector never saw counts as a miss.
[[nodiscard]] inline PrecisionRecall evaluate_loops(const std::vector<LoopScore>& scores, const LoopGroundTruth& gt,
                                                    double threshold) {
  detail::check_loop_scores(scores, gt);
  std::size_t tp = 0, fp = 0;
  for (const LoopScore& s : scores) {
    if (!s.match || s.score < threshold) continue;
    if (gt(s.query, *s.match))
      ++tp;
    else
      ++fp;
  }
  return detail::precision_recall_from_counts(threshold, gt.loop_frames(), tp, fp);
}

/// The PR curve: one point per distinct score of the queries that propose a loop, from
/// the highest threshold (fewest detections) to the lowest. The proposals are sorted
/// once by score and counted cumulatively while the threshold descends: O(n log n)
/// instead of one pass over all scores per threshold, with the same points as calling
/// evaluate_loops at every threshold.
[[nodiscard]] inline std::vector<PrecisionRecall> precision_recall_curve(const std::vector<LoopScore>& scores,
                                                                         const LoopGroundTruth& gt) {
  detail::check_loop_scores(scores, gt);
  struct Proposal {
    double score;
    bool correct;
  };
  std::vector<Proposal> proposals;
  std::vector<double> thresholds;
  for (const LoopScore& s : scores)
    if (s.match) {
      proposals.push_back({s.score, gt(s.query, *s.match)});
      thresholds.push_back(s.score);
    }
  std::sort(proposals.begin(), proposals.end(), [](const Proposal& a, const Proposal& b) { return a.score > b.score; });
  std::sort(thresholds.begin(), thresholds.end(), std::greater<>());
  thresholds.erase(std::unique(thresholds.begin(), thresholds.end()), thresholds.end());
  const std::size_t positives = gt.loop_frames();
  std::vector<PrecisionRecall> curve;
  curve.reserve(thresholds.size());
  std::size_t next = 0, tp = 0, fp = 0;
  for (double t : thresholds) {
    // A proposal counts at threshold t when its score is not below t, as in evaluate_loops.
    for (; next < proposals.size() && !(proposals[next].score < t); ++next) {
      if (proposals[next].correct)
        ++tp;
      else
        ++fp;
    }
    curve.push_back(detail::precision_recall_from_counts(t, positives, tp, fp));
  }
  return curve;
}

/// The best recall among the curve's points without a false positive, and the lowest
/// threshold that reaches it; recall 0 (threshold +inf) when every point has one.
struct RecallAtFullPrecision {
  double recall = 0.0;
  double threshold = std::numeric_limits<double>::infinity();
  std::size_t true_positives = 0;
};

[[nodiscard]] inline RecallAtFullPrecision recall_at_full_precision(const std::vector<PrecisionRecall>& curve) {
  RecallAtFullPrecision best;
  for (const PrecisionRecall& p : curve)
    if (p.false_positives == 0 && p.true_positives > 0 && (p.recall > best.recall ||
                                                           (p.recall == best.recall && p.threshold < best.threshold))) {
      best.recall = p.recall;
      best.threshold = p.threshold;
      best.true_positives = p.true_positives;
    }
  return best;
}

}  // namespace vmap
