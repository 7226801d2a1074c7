#pragma once

// XFeat learned local features (Potje et al., "XFeat: Accelerated Features for
// Lightweight Image Matching", CVPR 2024) as a Descriptor policy, run through cv::dnn
// from a fixed-size ONNX export (xfeat_320x224.onnx, xfeat_256x256.onnx). The network
// gives dense maps at 1/8 resolution; keypoint extraction and descriptor sampling
// follow XFeat's detectAndCompute and are done here in C++:
//   1. keypoint heatmap: softmax over the 65 logits of each 8x8 cell (64 positions +
//      a dustbin), the dustbin dropped, the 64 values unfolded to full resolution;
//   2. keypoints: local maxima of the heatmap in a (2r+1)^2 window above a threshold;
//   3. score = heatmap x reliability (bilinear at the keypoint); the top-k are kept;
//   4. descriptors: the 64-channel map, L2-normalised per cell, sampled bilinearly at
//      the keypoints and L2-normalised again;
//   5. keypoints are scaled from the network's input size back to the input image.
// Features carry CV_32F descriptors and NORM_L2, so BruteForceMatcher (mutual mode)
// matches them with no change, and the policy plugs into any Descriptor host.

#include <vmap/core/concepts.hpp>
#include <vmap/core/error.hpp>
#include <vmap/core/features.hpp>
#include <vmap/hooks/detail/dnn.hpp>
#include <vmap/hooks/detail/onnx_shape.hpp>

#include <opencv2/core.hpp>
#include <opencv2/dnn.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <utility>
#include <vector>

namespace vmap {

struct XFeatOptions {
  std::filesystem::path model;  ///< XFeat ONNX export with a fixed input size (required)
  /// Network input size (width x height); (0, 0) reads it from the model file. The
  /// image is resized to it (aspect ratio not kept, as XFeat's own resize does), and
  /// keypoints are scaled back.
  cv::Size input_size{};
  int top_k = 1000;                     ///< at most this many keypoints (highest scores), >= 1
  float detection_threshold = 0.05f;    ///< heatmap floor of a keypoint, XFeat's default
  int nms_radius = 2;                   ///< maxima in a (2r+1)^2 window; 2 = XFeat's 5x5 window
};

namespace detail {

/// Bilinear sample of a single-channel float map at (u, v), clamped to the border.
inline float bilinear(const cv::Mat& map, float u, float v) noexcept {
  u = std::clamp(u, 0.0f, static_cast<float>(map.cols - 1));
  v = std::clamp(v, 0.0f, static_cast<float>(map.rows - 1));
  const int x0 = static_cast<int>(u), y0 = static_cast<int>(v);
  const int x1 = std::min(x0 + 1, map.cols - 1), y1 = std::min(y0 + 1, map.rows - 1);
  const float fx = u - static_cast<float>(x0), fy = v - static_cast<float>(y0);
  const float* r0 = map.ptr<float>(y0);
  const float* r1 = map.ptr<float>(y1);
  return (1 - fy) * ((1 - fx) * r0[x0] + fx * r0[x1]) + fy * ((1 - fx) * r1[x0] + fx * r1[x1]);
}

/// Reads the fixed input size (width, height) an XFeat export declares.
inline cv::Size xfeat_input_size(const std::filesystem::path& model) {
  std::ifstream in(model, std::ios::binary);
  if (!in) fail("XFeat: cannot open the model file '" + model.string() + "'");
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const std::vector<std::int64_t> dims = onnx_first_input_shape(bytes);
  if (dims.size() != 4 || dims[1] != 3 || dims[2] <= 0 || dims[3] <= 0 || dims[2] > 8192 || dims[3] > 8192)
    fail("XFeat: model '" + model.string() +
         "' does not declare a fixed 1x3xHxW input; set XFeatOptions.input_size to the size it was exported for");
  return {static_cast<int>(dims[3]), static_cast<int>(dims[2])};
}

}  // namespace detail

/// XFeat keypoints and 64-float descriptors (NORM_L2). One object per thread
/// (cv::dnn::Net and the scratch maps are reused between images).
class XFeatDescriptor {
 public:
  explicit XFeatDescriptor(XFeatOptions options) : options_(std::move(options)) {
    const auto& o = options_;
    detail::check(o.top_k >= 1, "XFeatOptions.top_k must be >= 1, got " + std::to_string(o.top_k));
    detail::check(std::isfinite(o.detection_threshold) && o.detection_threshold >= 0.0f && o.detection_threshold < 1.0f,
                  "XFeatOptions.detection_threshold must be in [0, 1), got " + std::to_string(o.detection_threshold));
    detail::check(o.nms_radius >= 0 && o.nms_radius <= 16,
                  "XFeatOptions.nms_radius must be in [0, 16], got " + std::to_string(o.nms_radius));
    detail::check(o.input_size.width >= 0 && o.input_size.height >= 0 &&
                      (o.input_size.width > 0) == (o.input_size.height > 0),
                  "XFeatOptions.input_size must be (0, 0) or a positive size");
    net_ = detail::DnnNet(o.model, "XFeat");
    if (options_.input_size.width == 0) options_.input_size = detail::xfeat_input_size(o.model);
    const cv::Size in = options_.input_size;
    if (in.width % 8 != 0 || in.height % 8 != 0)
      detail::fail("XFeat: input size " + std::to_string(in.width) + "x" + std::to_string(in.height) +
                   " of '" + o.model.string() + "' is not a multiple of 8");
    run(cv::Mat(in, CV_8UC3, cv::Scalar::all(128)));
    identify_outputs();
  }

  [[nodiscard]] Features extract(const cv::Mat& image) {
    detail::to_bgr8(image, bgr_, "XFeat extract");
    const cv::Size in = options_.input_size;
    cv::resize(bgr_, resized_, in, 0, 0, cv::INTER_AREA);
    run(resized_);
    const int h8 = in.height / 8, w8 = in.width / 8;
    const cv::Mat& logits = net_.outputs[static_cast<std::size_t>(keypoint_index_)];
    const cv::Mat& dense = net_.outputs[static_cast<std::size_t>(descriptor_index_)];
    const cv::Mat reliability(h8, w8, CV_32F,
                              const_cast<float*>(net_.outputs[static_cast<std::size_t>(reliability_index_)].ptr<float>()));
    heatmap(logits, h8, w8);
    select_keypoints(reliability);

    Features f;
    f.norm = cv::NORM_L2;
    f.image_size = bgr_.size();
    const float sx = static_cast<float>(bgr_.cols) / static_cast<float>(in.width);
    const float sy = static_cast<float>(bgr_.rows) / static_cast<float>(in.height);
    const int n = static_cast<int>(candidates_.size());
    f.keypoints.reserve(candidates_.size());
    f.descriptors.create(n, 64, CV_32F);
    normalise_cells(dense, h8, w8);
    const float kx = static_cast<float>(w8) / static_cast<float>(in.width - 1);
    const float ky = static_cast<float>(h8) / static_cast<float>(in.height - 1);
    for (int i = 0; i < n; ++i) {
      const Candidate& c = candidates_[static_cast<std::size_t>(i)];
      f.keypoints.emplace_back(cv::Point2f(static_cast<float>(c.x) * sx, static_cast<float>(c.y) * sy),
                               8.0f * std::max(sx, sy), -1.0f, c.score);
      // XFeat samples with grid_sample(align_corners=False) after mapping pixel x to
      // [-1, 1] by 2x/(W-1) - 1: on the 1/8 map that is x * w8/(W-1) - 0.5.
      const float u = static_cast<float>(c.x) * kx - 0.5f, v = static_cast<float>(c.y) * ky - 0.5f;
      float* d = f.descriptors.ptr<float>(i);
      float norm = 0.0f;
      for (int ch = 0; ch < 64; ++ch) {
        d[ch] = detail::bilinear(cells_[static_cast<std::size_t>(ch)], u, v);
        norm += d[ch] * d[ch];
      }
      const float inv = norm > 0.0f ? 1.0f / std::sqrt(norm) : 0.0f;
      for (int ch = 0; ch < 64; ++ch) d[ch] *= inv;
    }
    return f;
  }

  [[nodiscard]] const XFeatOptions& options() const noexcept { return options_; }

 private:
  struct Candidate {
    int x, y;
    float score;
  };

  void run(const cv::Mat& input) {
    // Grey conversion and instance normalisation are inside the exported graph.
    cv::dnn::blobFromImage(input, blob_, 1.0 / 255.0, cv::Size(), cv::Scalar(), false, false, CV_32F);
    net_.forward(blob_, "XFeat",
                 "input size " + std::to_string(options_.input_size.width) + "x" +
                     std::to_string(options_.input_size.height) +
                     "; an XFeat export runs only at the size it was exported for");
  }

  /// Tells the three outputs apart by their channel count (their names are
  /// graph-internal numbers): 64 descriptors, 65 keypoint logits, 1 reliability.
  void identify_outputs() {
    const int h8 = options_.input_size.height / 8, w8 = options_.input_size.width / 8;
    for (std::size_t i = 0; i < net_.outputs.size(); ++i) {
      const cv::Mat& o = net_.outputs[i];
      if (o.dims != 4 || o.size[0] != 1 || o.size[2] != h8 || o.size[3] != w8 || o.type() != CV_32F) continue;
      if (o.size[1] == 64) descriptor_index_ = static_cast<int>(i);
      if (o.size[1] == 65) keypoint_index_ = static_cast<int>(i);
      if (o.size[1] == 1) reliability_index_ = static_cast<int>(i);
    }
    if (net_.outputs.size() != 3 || descriptor_index_ < 0 || keypoint_index_ < 0 || reliability_index_ < 0)
      detail::fail("XFeat: model '" + options_.model.string() + "' gives " + net_.describe_outputs() +
                   "; an XFeat model gives 1x64xH/8xW/8 descriptors, 1x65xH/8xW/8 keypoint logits and a "
                   "1x1xH/8xW/8 reliability map (H/8 = " + std::to_string(h8) + ", W/8 = " + std::to_string(w8) + ")");
  }

  /// Step 1: softmax over 65 channels per cell; channel k of cell (cx, cy) is pixel
  /// (8 cx + k % 8, 8 cy + k / 8) (XFeat's get_kpts_heatmap unfolding).
  void heatmap(const cv::Mat& logits, int h8, int w8) {
    heat_.create(h8 * 8, w8 * 8, CV_32F);
    const int plane = h8 * w8;
    const float* base = logits.ptr<float>();
    for (int cy = 0; cy < h8; ++cy)
      for (int cx = 0; cx < w8; ++cx) {
        const float* p = base + cy * w8 + cx;  // channel k at p[k * plane]
        float top = p[0];
        for (int k = 1; k < 65; ++k) top = std::max(top, p[k * plane]);
        float sum = 0.0f;
        for (int k = 0; k < 65; ++k) sum += std::exp(p[k * plane] - top);
        const float inv = 1.0f / sum;
        for (int k = 0; k < 64; ++k) heat_.at<float>(cy * 8 + k / 8, cx * 8 + k % 8) = std::exp(p[k * plane] - top) * inv;
      }
  }

  /// Steps 2-3: local maxima above the threshold, scored by heatmap x reliability,
  /// top-k by score (ties by position, so the result is deterministic).
  void select_keypoints(const cv::Mat& reliability) {
    const int r = options_.nms_radius;
    cv::dilate(heat_, local_max_, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(2 * r + 1, 2 * r + 1)));
    candidates_.clear();
    // Same pixel -> 1/8-map mapping as the descriptors (see extract).
    const float rx = static_cast<float>(reliability.cols) / static_cast<float>(heat_.cols - 1);
    const float ry = static_cast<float>(reliability.rows) / static_cast<float>(heat_.rows - 1);
    for (int y = 0; y < heat_.rows; ++y) {
      const float* h = heat_.ptr<float>(y);
      const float* m = local_max_.ptr<float>(y);
      for (int x = 0; x < heat_.cols; ++x)
        if (h[x] > options_.detection_threshold && h[x] >= m[x]) {
          const float rel =
              detail::bilinear(reliability, static_cast<float>(x) * rx - 0.5f, static_cast<float>(y) * ry - 0.5f);
          candidates_.push_back({x, y, h[x] * rel});
        }
    }
    const auto better = [](const Candidate& a, const Candidate& b) {
      if (a.score != b.score) return a.score > b.score;
      return a.y != b.y ? a.y < b.y : a.x < b.x;
    };
    const auto k = std::min(candidates_.size(), static_cast<std::size_t>(options_.top_k));
    std::partial_sort(candidates_.begin(), candidates_.begin() + static_cast<std::ptrdiff_t>(k), candidates_.end(),
                      better);
    candidates_.resize(k);
  }

  /// Step 4, first half: the dense descriptor map as 64 planes, each cell's 64-vector
  /// L2-normalised (XFeat normalises the map before sampling it).
  void normalise_cells(const cv::Mat& dense, int h8, int w8) {
    cells_.resize(64);
    const int plane = h8 * w8;
    const float* base = dense.ptr<float>();
    norms_.assign(static_cast<std::size_t>(plane), 0.0f);
    for (int ch = 0; ch < 64; ++ch)
      for (int i = 0; i < plane; ++i) norms_[static_cast<std::size_t>(i)] += base[ch * plane + i] * base[ch * plane + i];
    for (auto& v : norms_) v = v > 0.0f ? 1.0f / std::sqrt(v) : 0.0f;
    for (int ch = 0; ch < 64; ++ch) {
      cv::Mat& c = cells_[static_cast<std::size_t>(ch)];
      c.create(h8, w8, CV_32F);
      float* dst = c.ptr<float>();
      for (int i = 0; i < plane; ++i) dst[i] = base[ch * plane + i] * norms_[static_cast<std::size_t>(i)];
    }
  }

  XFeatOptions options_;
  detail::DnnNet net_;
  int descriptor_index_ = -1, keypoint_index_ = -1, reliability_index_ = -1;
  // Scratch reused between images.
  cv::Mat bgr_, resized_, blob_, heat_, local_max_;
  std::vector<Candidate> candidates_;
  std::vector<cv::Mat> cells_;
  std::vector<float> norms_;
};

static_assert(Descriptor<XFeatDescriptor>);

}  // namespace vmap
