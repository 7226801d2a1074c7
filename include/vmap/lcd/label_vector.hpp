#pragma once

// Binary label vectors of LFM-LCD (Zhu et al., Sensors 2021, sec. 3.2, eq. 3-4): a key
// frame is described by which object labels a detector found in it, c(i) = 1 when label
// l_i is present with a score of at least 0.5. The labels are ordered from large to small
// objects, so the first levels of the tree split on the objects that are seen from
// farthest away and survive viewpoint change best.

#include <vmap/core/error.hpp>
#include <vmap/hooks/detection.hpp>
#include <vmap/lcd/options.hpp>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <map>
#include <string>
#include <utility>
#include <vector>

namespace vmap {

/// c(i) in {0, 1} for each label of a LabelSchema, in the schema's order (eq. 3-4).
using LabelVector = std::vector<std::uint8_t>;

namespace detail {

inline void check_label_min_score(float min_score) {
  check(min_score >= 0.0f && min_score <= 1.0f,
        [&] { return "LabelVectorOptions.min_score must be in [0, 1], got " + std::to_string(min_score); });
}

inline void check_detection_score(const Detection& d) {
  if (!(d.score >= 0.0f && d.score <= 1.0f))  // also rejects NaN
    fail("detection of label " + std::to_string(d.label) + " has score " + std::to_string(d.score) +
         ", not in [0, 1]");
}

}  // namespace detail

/// The distinct labels of `detections` whose score is at least `min_score`, ascending.
/// A score that is NaN or outside [0, 1] is an Error (a broken detector, not a label).
[[nodiscard]] inline std::vector<int> present_labels(const std::vector<Detection>& detections, float min_score) {
  detail::check_label_min_score(min_score);
  std::vector<int> out;
  for (const Detection& d : detections) {
    detail::check_detection_score(d);
    if (d.score >= min_score) out.push_back(d.label);
  }
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

/// The ordered label list that gives a LabelVector its meaning: `labels()[i]` is the
/// label of c(i) and of tree level i (large objects first). Immutable once built.
class LabelSchema {
 public:
  LabelSchema() = default;

  /// `labels`: distinct label ids, large objects first.
  explicit LabelSchema(std::vector<int> labels) : labels_(std::move(labels)) {
    std::vector<int> sorted = labels_;
    std::sort(sorted.begin(), sorted.end());
    detail::check(std::adjacent_find(sorted.begin(), sorted.end()) == sorted.end(),
                  "LabelSchema: a label appears twice in the label order");
    detail::check(sorted.empty() || sorted.front() >= 0, "LabelSchema: label ids must be non-negative");
  }

  [[nodiscard]] const std::vector<int>& labels() const noexcept { return labels_; }
  [[nodiscard]] std::size_t size() const noexcept { return labels_.size(); }

  /// Eq. 3-4: c(i) = 1 when labels()[i] is among `present` (any order, duplicates fine).
  [[nodiscard]] LabelVector vector_of(const std::vector<int>& present) const {
    LabelVector c(labels_.size(), 0);
    for (std::size_t i = 0; i < labels_.size(); ++i)
      c[i] = std::find(present.begin(), present.end(), labels_[i]) != present.end() ? 1 : 0;
    return c;
  }

  /// Eq. 3-4 from raw detections: labels with score >= options.min_score.
  [[nodiscard]] LabelVector vector(const std::vector<Detection>& detections,
                                   const LabelVectorOptions& options = {}) const {
    return vector_of(present_labels(detections, options.min_score));
  }

 private:
  std::vector<int> labels_;
};

/// Statistics of a sample of frames' detections: per label, in how many frames it was
/// present (p(i) of eq. 5) and its mean box area, the data-driven "large to small" order
/// when the user gives none.
class LabelStatistics {
 public:
  explicit LabelStatistics(const LabelVectorOptions& options = {}) : options_(options) {
    detail::check_label_min_score(options_.min_score);
  }

  /// Adds one frame of the sample.
  void observe(const std::vector<Detection>& detections) {
    const std::vector<int> present = present_labels(detections, options_.min_score);
    for (const Detection& d : detections) {
      if (d.score < options_.min_score) continue;
      const double area = static_cast<double>(d.box.width) * static_cast<double>(d.box.height);
      detail::check(std::isfinite(area) && area >= 0.0, [&] {
        return "detection of label " + std::to_string(d.label) + " has a non-finite or negative box";
      });
      auto& s = per_label_[d.label];
      s.area_sum += area;
      ++s.boxes;
    }
    for (int l : present) ++per_label_[l].frames;
    ++samples_;
  }

  /// M: frames observed.
  [[nodiscard]] std::size_t samples() const noexcept { return samples_; }
  /// p(i): frames in which `label` was present.
  [[nodiscard]] std::size_t presence(int label) const {
    const auto it = per_label_.find(label);
    return it == per_label_.end() ? 0 : it->second.frames;
  }
  /// Mean area (pixels^2) of the label's boxes; 0 when never seen.
  [[nodiscard]] double mean_area(int label) const {
    const auto it = per_label_.find(label);
    return it == per_label_.end() || it->second.boxes == 0 ? 0.0
                                                           : it->second.area_sum / static_cast<double>(it->second.boxes);
  }
  /// Every label seen, large objects first (mean box area descending, ties by id).
  [[nodiscard]] std::vector<int> labels_by_area() const {
    std::vector<int> out;
    for (const auto& [label, s] : per_label_) out.push_back(label);
    std::stable_sort(out.begin(), out.end(), [&](int a, int b) { return mean_area(a) > mean_area(b); });
    return out;
  }
  [[nodiscard]] const LabelVectorOptions& options() const noexcept { return options_; }

 private:
  struct PerLabel {
    std::size_t frames = 0;
    std::size_t boxes = 0;
    double area_sum = 0.0;
  };
  LabelVectorOptions options_;
  std::map<int, PerLabel> per_label_;
  std::size_t samples_ = 0;
};

}  // namespace vmap
