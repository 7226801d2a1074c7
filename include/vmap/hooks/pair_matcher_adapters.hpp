#pragma once

// Adapters for the PairMatcher hook (examples/methods.md, sec. 5 and 7), for detector-free matchers of
// the LoFTR family (Sun et al., CVPR 2021), which match an image pair directly:
//  - CallbackPairMatcher wraps any callable (ONNX Runtime, TensorRT, LibTorch, a
//    service) and checks what it returns;
//  - DnnPairMatcher runs a LoFTR-style ONNX export through cv::dnn whose output is the
//    coarse confidence matrix, and decodes it with decode_coarse_matches: mutual nearest
//    neighbours above a threshold (LoFTR sec. 3.3, coarse-level matching), cell centres
//    mapped back to the pixels of the input images.
// The eq. 5 denominator (García-Pintos et al. 2023) of such a matcher is its number of
// coarse cells, max(cells of a, cells of b): the largest number of matches it can give.

#include <vmap/core/error.hpp>
#include <vmap/hooks/detail/dnn.hpp>
#include <vmap/hooks/pair_matcher.hpp>

#include <opencv2/core.hpp>
#include <opencv2/dnn.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <concepts>
#include <filesystem>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

namespace vmap {

/// How a coarse grid maps to an image: `cells` (columns x rows, row-major flattening)
/// cover `image` (width x height in pixels) uniformly, so cell (c, r) has its centre at
/// ((c + 0.5) image.width / cells.width, (r + 0.5) image.height / cells.height). With a
/// network input of the image's own size and stride s, cells = image / s.
struct CoarseGrid {
  cv::Size cells;
  cv::Size image;
};

/// Decodes a coarse confidence matrix (rows: cells of image a, columns: cells of image
/// b, CV_32F, 2-D or 1 x rows x cols): (i, j) is a match when conf(i, j) is the largest
/// of its row and of its column (mutual nearest neighbours) and >= `threshold`. Points
/// are cell centres in the pixels of each image; `cells` = max(rows, cols), the eq. 5
/// denominator. Ties in a row or column keep the lowest index (deterministic).
[[nodiscard]] inline Correspondences decode_coarse_matches(const cv::Mat& confidence, const CoarseGrid& a,
                                                           const CoarseGrid& b, float threshold) {
  detail::check(std::isfinite(threshold) && threshold >= 0.0f && threshold <= 1.0f,
                "decode_coarse_matches: threshold must be in [0, 1], got " + std::to_string(threshold));
  const int rows = a.cells.area(), cols = b.cells.area();
  detail::check(a.cells.width > 0 && a.cells.height > 0 && b.cells.width > 0 && b.cells.height > 0 &&
                    a.image.width > 0 && a.image.height > 0 && b.image.width > 0 && b.image.height > 0,
                "decode_coarse_matches: grids and image sizes must be positive");
  const bool three = confidence.dims == 3 && confidence.size[0] == 1 && confidence.size[1] == rows &&
                     confidence.size[2] == cols;
  const bool two = confidence.dims == 2 && confidence.rows == rows && confidence.cols == cols;
  if (confidence.type() != CV_32F || !(two || three) || !confidence.isContinuous())
    detail::fail("decode_coarse_matches: confidence matrix " + detail::shape_string(confidence) + " (" +
                 cv::typeToString(confidence.type()) + ") is not " + std::to_string(rows) + "x" +
                 std::to_string(cols) + " float, the cells of the two grids");
  const cv::Mat m(rows, cols, CV_32F, const_cast<float*>(confidence.ptr<float>()));
  std::vector<int> col_best(static_cast<std::size_t>(cols), 0);
  for (int i = 1; i < rows; ++i) {
    const float* p = m.ptr<float>(i);
    for (int j = 0; j < cols; ++j)
      if (p[j] > m.at<float>(col_best[static_cast<std::size_t>(j)], j)) col_best[static_cast<std::size_t>(j)] = i;
  }
  const auto centre = [](const CoarseGrid& g, int index) {
    const int c = index % g.cells.width, r = index / g.cells.width;
    return cv::Point2f((static_cast<float>(c) + 0.5f) * static_cast<float>(g.image.width) / static_cast<float>(g.cells.width),
                       (static_cast<float>(r) + 0.5f) * static_cast<float>(g.image.height) / static_cast<float>(g.cells.height));
  };
  Correspondences out;
  out.cells = std::max(rows, cols);
  for (int i = 0; i < rows; ++i) {
    const float* p = m.ptr<float>(i);
    const int j = static_cast<int>(std::max_element(p, p + cols) - p);
    if (!(p[j] >= threshold) || col_best[static_cast<std::size_t>(j)] != i) continue;
    out.points_a.push_back(centre(a, i));
    out.points_b.push_back(centre(b, j));
    out.confidence.push_back(p[j]);
  }
  return out;
}

namespace detail {

/// What every PairMatcher must return: three parallel lists, confidences in [0, 1],
/// and at least as many cells as correspondences (eq. 5 stays <= 1).
inline void check_correspondences(const Correspondences& c, const std::string& who) {
  if (c.points_b.size() != c.points_a.size() || c.confidence.size() != c.points_a.size())
    fail(who + ": points_a, points_b and confidence differ in length (" + std::to_string(c.points_a.size()) + ", " +
         std::to_string(c.points_b.size()) + ", " + std::to_string(c.confidence.size()) + ")");
  if (c.cells < static_cast<int>(c.size()))
    fail(who + ": cells (" + std::to_string(c.cells) + ") is smaller than the number of correspondences (" +
         std::to_string(c.size()) + "); it is the eq. 5 denominator, the matcher's number of coarse cells");
  for (const float v : c.confidence)
    if (!(v >= 0.0f && v <= 1.0f)) fail(who + ": a confidence is outside [0, 1]: " + std::to_string(v));
}

}  // namespace detail

/// A PairMatcher over any callable `Correspondences(const cv::Mat& a, const cv::Mat& b)`,
/// e.g. a lambda around another runtime. The result is checked (equal list lengths,
/// confidences in [0, 1], cells >= matches); a broken callback is a vmap::Error.
/// Thread-safety is the callable's.
template <class F>
  requires std::invocable<F&, const cv::Mat&, const cv::Mat&> &&
           std::same_as<std::invoke_result_t<F&, const cv::Mat&, const cv::Mat&>, Correspondences>
class CallbackPairMatcher {
 public:
  explicit CallbackPairMatcher(F callback) : callback_(std::move(callback)) {}

  [[nodiscard]] Correspondences match_pair(const cv::Mat& a, const cv::Mat& b) {
    Correspondences c = callback_(a, b);
    detail::check_correspondences(c, "CallbackPairMatcher");
    return c;
  }

 private:
  F callback_;
};

struct DnnPairMatcherOptions {
  std::filesystem::path model;  ///< LoFTR-style ONNX export (required)
  /// The export's fixed input size (width x height); both images are resized to it.
  /// 640x480 is the common LoFTR export size.
  cv::Size input_size{640, 480};
  std::array<std::string, 2> input_names{"image0", "image1"};  ///< LoFTR exports' input names
  int coarse_stride = 8;    ///< input pixels per coarse cell (LoFTR's coarse level is 1/8)
  float threshold = 0.2f;   ///< coarse confidence floor, LoFTR's default match threshold
};

/// Runs a LoFTR-style ONNX export: two inputs 1x1xHxW (grey / 255), one output, the
/// coarse confidence matrix 1 x N x N with N = (H/s)(W/s). The model is run once at
/// construction to check that: a model of another shape is a vmap::Error naming the
/// file and what was wrong.
/// Deep copy: a copy parses the model again (from the bytes kept in memory, not the
/// file) into its own cv::dnn::Net with its own buffers, so per-thread copies run in
/// parallel with results equal to one object's; a copy costs a model parse (tens of
/// ms), so copy once per thread, not per image. One object serves one thread at a time.
class DnnPairMatcher {
 public:
  explicit DnnPairMatcher(DnnPairMatcherOptions options) : options_(std::move(options)) {
    const auto& o = options_;
    detail::check(o.coarse_stride >= 1, "DnnPairMatcherOptions.coarse_stride must be >= 1");
    detail::check(o.input_size.width > 0 && o.input_size.height > 0 && o.input_size.width % o.coarse_stride == 0 &&
                      o.input_size.height % o.coarse_stride == 0,
                  "DnnPairMatcherOptions.input_size must be positive multiples of coarse_stride");
    detail::check(std::isfinite(o.threshold) && o.threshold >= 0.0f && o.threshold <= 1.0f,
                  "DnnPairMatcherOptions.threshold must be in [0, 1]");
    net_ = detail::DnnNet(o.model, "DnnPairMatcher");
    const cv::Mat zero(o.input_size, CV_8UC1, cv::Scalar::all(0));
    run(zero, zero);
    const int n = grid_cells().area();
    const cv::Mat out = net_.outputs.empty() ? cv::Mat() : net_.outputs.front();
    const bool ok = net_.outputs.size() == 1 && out.type() == CV_32F &&
                    ((out.dims == 3 && out.size[0] == 1 && out.size[1] == n && out.size[2] == n) ||
                     (out.dims == 2 && out.rows == n && out.cols == n));
    if (!ok)
      detail::fail("DnnPairMatcher: model '" + o.model.string() + "' gives " + net_.describe_outputs() +
                   "; a LoFTR-style coarse matcher gives one confidence matrix 1x" + std::to_string(n) + "x" +
                   std::to_string(n) + " for two " + std::to_string(o.input_size.width) + "x" +
                   std::to_string(o.input_size.height) + " inputs at stride " + std::to_string(o.coarse_stride));
  }

  [[nodiscard]] Correspondences match_pair(const cv::Mat& a, const cv::Mat& b) {
    detail::to_bgr8(a, buf_->bgr_a, "DnnPairMatcher image a");
    detail::to_bgr8(b, buf_->bgr_b, "DnnPairMatcher image b");
    cv::cvtColor(buf_->bgr_a, buf_->grey_a, cv::COLOR_BGR2GRAY);
    cv::cvtColor(buf_->bgr_b, buf_->grey_b, cv::COLOR_BGR2GRAY);
    cv::resize(buf_->grey_a, buf_->small_a, options_.input_size, 0, 0, cv::INTER_AREA);
    cv::resize(buf_->grey_b, buf_->small_b, options_.input_size, 0, 0, cv::INTER_AREA);
    run(buf_->small_a, buf_->small_b);
    return decode_coarse_matches(net_.outputs.front(), {grid_cells(), a.size()}, {grid_cells(), b.size()},
                                 options_.threshold);
  }

  [[nodiscard]] const DnnPairMatcherOptions& options() const noexcept { return options_; }

 private:
  [[nodiscard]] cv::Size grid_cells() const noexcept {
    return {options_.input_size.width / options_.coarse_stride, options_.input_size.height / options_.coarse_stride};
  }

  void run(const cv::Mat& grey_a, const cv::Mat& grey_b) {
    cv::dnn::blobFromImage(grey_a, buf_->blob_a, 1.0 / 255.0, cv::Size(), cv::Scalar(), false, false, CV_32F);
    cv::dnn::blobFromImage(grey_b, buf_->blob_b, 1.0 / 255.0, cv::Size(), cv::Scalar(), false, false, CV_32F);
    try {
      net_.net.setInput(buf_->blob_a, options_.input_names[0]);
      net_.net.setInput(buf_->blob_b, options_.input_names[1]);
      net_.net.forward(net_.outputs, net_.output_names);
    } catch (const cv::Exception& e) {
      detail::fail("DnnPairMatcher: model '" + options_.model.string() + "' does not run on two 1x1x" +
                   std::to_string(options_.input_size.height) + "x" + std::to_string(options_.input_size.width) +
                   " inputs named '" + options_.input_names[0] + "' and '" + options_.input_names[1] +
                   "': " + detail::first_line(e));
    }
  }

  DnnPairMatcherOptions options_;
  detail::DnnNet net_;
  struct Buffers {
    cv::Mat bgr_a, bgr_b, grey_a, grey_b, small_a, small_b, blob_a, blob_b;
  };
  detail::Scratch<Buffers> buf_;  // reused between pairs; a copy gets its own
};

static_assert(PairMatcher<DnnPairMatcher>);

}  // namespace vmap
