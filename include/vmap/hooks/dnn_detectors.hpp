#pragma once

// ObjectDetector adapters that run ONNX detectors through cv::dnn on the CPU: YOLOX,
// NanoDet (GFL head) and FastestDet output formats. Each has its own preprocessing and
// decoding; all share the score threshold and class-wise NMS. The decoders are public
// free functions so that a user who runs the same networks in another runtime (behind
// a callback detector) can reuse them, and so that tests can feed them hand-made
// tensors with known answers.
//
// Every adapter runs the network once when it is constructed and checks the outputs
// against its format, so a wrong or foreign model file is a vmap::Error at load time,
// not a crash or garbage boxes later.

#include <vmap/core/error.hpp>
#include <vmap/hooks/any_detector.hpp>
#include <vmap/hooks/detail/dnn.hpp>
#include <vmap/hooks/detection.hpp>
#include <vmap/hooks/nms.hpp>

#include <opencv2/core.hpp>
#include <opencv2/dnn.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <limits>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace vmap {

/// Options shared by the cv::dnn detector adapters.
struct DnnDetectorOptions {
  std::filesystem::path model;  ///< ONNX file of the adapter's format (required)
  /// Boxes scoring below are dropped before NMS, in [0, 1]. 0.5 is LFM-LCD's label
  /// threshold (Zhu et al. 2021, sec. 3.1); store detections for later with a low floor.
  float score_threshold = 0.5f;
  NmsOptions nms{};  ///< class-wise NMS after decoding
};

namespace detail {

inline void check_detector_options(const DnnDetectorOptions& o, std::string_view who) {
  check(std::isfinite(o.score_threshold) && o.score_threshold >= 0.0f && o.score_threshold <= 1.0f, [&] {
    return std::string(who) + ": DnnDetectorOptions.score_threshold must be in [0, 1], got " +
           std::to_string(o.score_threshold);
  });
  (void)nms({}, o.nms);  // validates the NMS options now rather than at the first image
}

/// A 2-D float view (rows x cols) of a network output of shape [1, rows, cols] or
/// [rows, cols]; Error when the shape is different.
inline cv::Mat as_matrix(const cv::Mat& out, int rows, int cols, std::string_view what) {
  const bool three = out.dims == 3 && out.size[0] == 1 && out.size[1] == rows && out.size[2] == cols;
  const bool two = out.dims == 2 && out.rows == rows && out.cols == cols;
  if (out.type() != CV_32F || !(three || two) || !out.isContinuous())
    fail(std::string(what) + " has shape " + shape_string(out) + " (" + cv::typeToString(out.type()) +
         "), expected 1x" + std::to_string(rows) + "x" + std::to_string(cols) + " float");
  return cv::Mat(rows, cols, CV_32F, const_cast<float*>(out.ptr<float>()));
}

/// Index and value of the largest of n floats.
inline std::pair<int, float> arg_max(const float* p, int n, int step = 1) noexcept {
  int best = 0;
  for (int k = 1; k < n; ++k)
    if (p[k * step] > p[best * step]) best = k;
  return {best, p[best * step]};
}

/// Resizes `bgr` by `scale` into the top-left corner of a side x side canvas filled
/// with `pad` (YOLOX's and NanoDet's letterbox: the aspect ratio is kept, so the network
/// sees undistorted objects; padding at the top-left keeps box coordinates a pure scale).
inline float letterbox(const cv::Mat& bgr, int side, const cv::Scalar& pad, cv::Mat& canvas, cv::Mat& resized) {
  const float scale = std::min(static_cast<float>(side) / static_cast<float>(bgr.cols),
                               static_cast<float>(side) / static_cast<float>(bgr.rows));
  const int w = std::clamp(static_cast<int>(std::lround(static_cast<float>(bgr.cols) * scale)), 1, side);
  const int h = std::clamp(static_cast<int>(std::lround(static_cast<float>(bgr.rows) * scale)), 1, side);
  canvas.create(side, side, CV_8UC3);
  canvas.setTo(pad);
  cv::resize(bgr, resized, cv::Size(w, h), 0, 0, cv::INTER_LINEAR);
  resized.copyTo(canvas(cv::Rect(0, 0, w, h)));
  return scale;
}

/// Boxes from network pixels to image pixels (divide by the per-axis scale), clipped to
/// the image; boxes left without area are dropped; then class-wise NMS.
inline std::vector<Detection> finish_detections(std::vector<Detection> dets, float scale_x, float scale_y,
                                                cv::Size image, const NmsOptions& nms_options) {
  const cv::Rect2f frame(0.0f, 0.0f, static_cast<float>(image.width), static_cast<float>(image.height));
  std::vector<Detection> inside;
  inside.reserve(dets.size());
  for (Detection d : dets) {
    d.box = cv::Rect2f(d.box.x / scale_x, d.box.y / scale_y, d.box.width / scale_x, d.box.height / scale_y) & frame;
    if (d.box.width > 0.0f && d.box.height > 0.0f) inside.push_back(d);
  }
  return nms(std::move(inside), nms_options);
}

inline float sigmoid(float x) noexcept { return 1.0f / (1.0f + std::exp(-x)); }

// exp() of a box logit: clamped so a hostile or broken model cannot produce inf boxes.
inline float safe_exp(float x) noexcept { return std::exp(std::min(x, 20.0f)); }

}  // namespace detail

// ---- YOLOX ------------------------------------------------------------------------

/// Number of YOLOX cells for a side x side input: grids of strides 8, 16 and 32.
[[nodiscard]] constexpr int yolox_cells(int side) noexcept {
  return (side / 8) * (side / 8) + (side / 16) * (side / 16) + (side / 32) * (side / 32);
}

/// Decodes a YOLOX output (Ge et al. 2021; the ONNX export with sigmoid applied but no
/// grid decoding): `output` is 1 x N x (5 + C) with N = yolox_cells(side), one row per
/// cell of the stride-8, then 16, then 32 grid, row-major; a row is (x, y, w, h,
/// objectness, C class scores). Centre = (x + grid_x) * stride, size = exp(w) * stride;
/// score = objectness * best class score. Returns one detection per cell scoring >=
/// `score_threshold`, boxes in network-input pixels, before NMS.
[[nodiscard]] inline std::vector<Detection> decode_yolox(const cv::Mat& output, int side, float score_threshold) {
  detail::check(side >= 32 && side % 32 == 0, "decode_yolox: input side must be a positive multiple of 32, got " +
                                                  std::to_string(side));
  const int cols = output.dims == 3 ? output.size[2] : output.cols;
  if (cols < 6) detail::fail("decode_yolox: output " + detail::shape_string(output) + " has no class column");
  const cv::Mat m = detail::as_matrix(output, yolox_cells(side), cols, "YOLOX output");
  const int classes = cols - 5;
  std::vector<Detection> dets;
  int row = 0;
  for (const int stride : {8, 16, 32}) {
    const int g = side / stride;
    for (int gy = 0; gy < g; ++gy)
      for (int gx = 0; gx < g; ++gx, ++row) {
        const float* p = m.ptr<float>(row);
        const auto [label, cls] = detail::arg_max(p + 5, classes);
        const float score = p[4] * cls;
        if (!(score >= score_threshold)) continue;
        const auto s = static_cast<float>(stride);
        const float cx = (p[0] + static_cast<float>(gx)) * s, cy = (p[1] + static_cast<float>(gy)) * s;
        const float w = detail::safe_exp(p[2]) * s, h = detail::safe_exp(p[3]) * s;
        dets.push_back({label, score, cv::Rect2f(cx - 0.5f * w, cy - 0.5f * h, w, h)});
      }
  }
  return dets;
}

/// YOLOX (e.g. yolox_nano.onnx): input 1x3x416x416, BGR 0..255 without normalisation,
/// letterboxed at the top-left with grey 114 as in YOLOX's own preprocessing.
/// Deep copy: a copy parses the model again (from the bytes kept in memory, not the
/// file) into its own cv::dnn::Net with its own buffers, so per-thread copies run in
/// parallel with results equal to one object's; a copy costs a model parse (tens of
/// ms), so copy once per thread, not per image. One object serves one thread at a time.
class YoloxDetector {
 public:
  static constexpr int input_side = 416;

  explicit YoloxDetector(DnnDetectorOptions options) : options_(std::move(options)) {
    detail::check_detector_options(options_, "YOLOX");
    net_ = detail::DnnNet(options_.model, "YOLOX");
    run(cv::Mat(input_side, input_side, CV_8UC3, cv::Scalar::all(114)));
    const cv::Mat out = net_.outputs.size() == 1 ? net_.outputs.front() : cv::Mat();
    if (out.dims != 3 || out.size[0] != 1 || out.size[1] != yolox_cells(input_side) ||
        out.size[2] < 6)
      detail::fail("YOLOX: model '" + options_.model.string() + "' gives " + net_.describe_outputs() +
                   "; a YOLOX model gives one output 1x" + std::to_string(yolox_cells(input_side)) +
                   "x(5+classes) for a 416x416 input");
    classes_ = out.size[2] - 5;
  }

  [[nodiscard]] std::vector<Detection> detect(const cv::Mat& image) {
    detail::to_bgr8(image, buf_->bgr, "YOLOX detect");
    const float scale = detail::letterbox(buf_->bgr, input_side, cv::Scalar::all(114), buf_->canvas, buf_->resized);
    run(buf_->canvas);
    return detail::finish_detections(decode_yolox(net_.outputs.front(), input_side, options_.score_threshold),
                                     scale, scale, buf_->bgr.size(), options_.nms);
  }

  [[nodiscard]] int classes() const noexcept { return classes_; }
  [[nodiscard]] const DnnDetectorOptions& options() const noexcept { return options_; }

 private:
  void run(const cv::Mat& canvas) {
    cv::dnn::blobFromImage(canvas, buf_->blob, 1.0, cv::Size(), cv::Scalar(), false, false, CV_32F);
    net_.forward(buf_->blob, "YOLOX", "YOLOX takes 1x3x416x416 BGR");
  }

  DnnDetectorOptions options_;
  detail::DnnNet net_;
  int classes_ = 0;
  struct Buffers {
    cv::Mat bgr, canvas, resized, blob;
  };
  detail::Scratch<Buffers> buf_;  // reused between images; a copy gets its own
};

static_assert(ObjectDetector<YoloxDetector>);

// ---- NanoDet ----------------------------------------------------------------------

/// Decodes NanoDet-m's GFL head (Li et al. 2020, generalized focal loss): per stride s
/// in (8, 16, 32) a class map `cls[k]` of 1 x N x C (sigmoid applied) and a distance map
/// `dis[k]` of 1 x N x 4(R+1), N = ceil(side/s)^2 cells row-major. Each side (left, top,
/// right, bottom) is a softmax over R+1 bins; its distance is the expected bin times s,
/// measured from the cell centre ((x + 0.5) s, (y + 0.5) s). Score = best class score.
/// Boxes in network-input pixels, before NMS.
[[nodiscard]] inline std::vector<Detection> decode_nanodet(const std::array<cv::Mat, 3>& cls,
                                                           const std::array<cv::Mat, 3>& dis, int side,
                                                           float score_threshold) {
  detail::check(side >= 32, "decode_nanodet: input side must be >= 32, got " + std::to_string(side));
  std::vector<Detection> dets;
  std::vector<float> prob;
  for (int k = 0; k < 3; ++k) {
    const int stride = 8 << k;
    const int g = (side + stride - 1) / stride;
    const int n = g * g;
    const int classes = cls[static_cast<std::size_t>(k)].dims == 3 ? cls[static_cast<std::size_t>(k)].size[2] : 0;
    const int bins4 = dis[static_cast<std::size_t>(k)].dims == 3 ? dis[static_cast<std::size_t>(k)].size[2] : 0;
    const std::string name = std::to_string(stride);
    if (classes < 1) detail::fail("NanoDet cls_pred_stride_" + name + " has shape " +
                                  detail::shape_string(cls[static_cast<std::size_t>(k)]) + ", expected 1xNxclasses");
    if (bins4 < 4 || bins4 % 4 != 0)
      detail::fail("NanoDet dis_pred_stride_" + name + " has shape " +
                   detail::shape_string(dis[static_cast<std::size_t>(k)]) + ", expected 1xNx(4*bins)");
    const cv::Mat c = detail::as_matrix(cls[static_cast<std::size_t>(k)], n, classes, "NanoDet cls_pred_stride_" + name);
    const cv::Mat d = detail::as_matrix(dis[static_cast<std::size_t>(k)], n, bins4, "NanoDet dis_pred_stride_" + name);
    const int bins = bins4 / 4;
    prob.resize(static_cast<std::size_t>(bins));
    const auto s = static_cast<float>(stride);
    for (int i = 0; i < n; ++i) {
      const auto [label, score] = detail::arg_max(c.ptr<float>(i), classes);
      if (!(score >= score_threshold)) continue;
      std::array<float, 4> dist{};
      const float* q = d.ptr<float>(i);
      for (int side_k = 0; side_k < 4; ++side_k) {
        const float* logits = q + side_k * bins;
        const float top = *std::max_element(logits, logits + bins);
        float sum = 0.0f, expect = 0.0f;
        for (int b = 0; b < bins; ++b) {
          const float e = std::exp(logits[b] - top);  // shifted: no overflow
          sum += e;
          expect += e * static_cast<float>(b);
        }
        dist[static_cast<std::size_t>(side_k)] = expect / sum * s;
      }
      const float cx = (static_cast<float>(i % g) + 0.5f) * s, cy = (static_cast<float>(i / g) + 0.5f) * s;
      dets.push_back({label, score,
                      cv::Rect2f(cx - dist[0], cy - dist[1], dist[0] + dist[2], dist[1] + dist[3])});
    }
  }
  return dets;
}

/// NanoDet-m (e.g. nanodet_m_320.onnx): input 1x3x320x320, BGR normalised by
/// (x - [103.53, 116.28, 123.675]) / [57.375, 57.12, 58.395], letterboxed at the
/// top-left (padding = the mean colour, i.e. 0 after normalisation). Outputs
/// cls_pred_stride_{8,16,32} and dis_pred_stride_{8,16,32}.
/// Deep copy: a copy parses the model again (from the bytes kept in memory, not the
/// file) into its own cv::dnn::Net with its own buffers, so per-thread copies run in
/// parallel with results equal to one object's; a copy costs a model parse (tens of
/// ms), so copy once per thread, not per image. One object serves one thread at a time.
class NanoDetDetector {
 public:
  static constexpr int input_side = 320;

  explicit NanoDetDetector(DnnDetectorOptions options) : options_(std::move(options)) {
    detail::check_detector_options(options_, "NanoDet");
    net_ = detail::DnnNet(options_.model, "NanoDet");
    for (int k = 0; k < 3; ++k) {
      const std::string s = std::to_string(8 << k);
      cls_index_[static_cast<std::size_t>(k)] = net_.output_index("cls_pred_stride_" + s);
      dis_index_[static_cast<std::size_t>(k)] = net_.output_index("dis_pred_stride_" + s);
      if (cls_index_[static_cast<std::size_t>(k)] < 0 || dis_index_[static_cast<std::size_t>(k)] < 0)
        detail::fail("NanoDet: model '" + options_.model.string() + "' has outputs (" + net_.describe_outputs() +
                     "); a NanoDet model has cls_pred_stride_{8,16,32} and dis_pred_stride_{8,16,32}");
    }
    run(cv::Mat(input_side, input_side, CV_8UC3, mean()));
    try {  // decoding with an unreachable threshold checks every output's shape
      (void)decode_nanodet(outputs(cls_index_), outputs(dis_index_), input_side,
                           std::numeric_limits<float>::infinity());
    } catch (const Error& e) {
      detail::fail("NanoDet: model '" + options_.model.string() + "' gives outputs of the wrong shape: " + e.what());
    }
    classes_ = net_.outputs[static_cast<std::size_t>(cls_index_[0])].size[2];
  }

  [[nodiscard]] std::vector<Detection> detect(const cv::Mat& image) {
    detail::to_bgr8(image, buf_->bgr, "NanoDet detect");
    const float scale = detail::letterbox(buf_->bgr, input_side, mean(), buf_->canvas, buf_->resized);
    run(buf_->canvas);
    return detail::finish_detections(
        decode_nanodet(outputs(cls_index_), outputs(dis_index_), input_side, options_.score_threshold), scale, scale,
        buf_->bgr.size(), options_.nms);
  }

  [[nodiscard]] int classes() const noexcept { return classes_; }
  [[nodiscard]] const DnnDetectorOptions& options() const noexcept { return options_; }

 private:
  static cv::Scalar mean() noexcept { return {103.53, 116.28, 123.675}; }

  void run(const cv::Mat& canvas) {
    canvas.convertTo(buf_->normalised, CV_32FC3);
    cv::subtract(buf_->normalised, mean(), buf_->normalised);
    cv::multiply(buf_->normalised, cv::Scalar(1.0 / 57.375, 1.0 / 57.12, 1.0 / 58.395), buf_->normalised);
    cv::dnn::blobFromImage(buf_->normalised, buf_->blob, 1.0, cv::Size(), cv::Scalar(), false, false, CV_32F);
    net_.forward(buf_->blob, "NanoDet", "NanoDet-m takes 1x3x320x320 normalised BGR");
  }

  [[nodiscard]] std::array<cv::Mat, 3> outputs(const std::array<int, 3>& index) const {
    return {net_.outputs[static_cast<std::size_t>(index[0])], net_.outputs[static_cast<std::size_t>(index[1])],
            net_.outputs[static_cast<std::size_t>(index[2])]};
  }

  DnnDetectorOptions options_;
  detail::DnnNet net_;
  std::array<int, 3> cls_index_{}, dis_index_{};
  int classes_ = 0;
  struct Buffers {
    cv::Mat bgr, canvas, resized, normalised, blob;
  };
  detail::Scratch<Buffers> buf_;  // reused between images; a copy gets its own
};

static_assert(ObjectDetector<NanoDetDetector>);

// ---- FastestDet -------------------------------------------------------------------

/// Decodes FastestDet's single-scale output: `output` is 1 x (5 + C) x H x W, per cell
/// (objectness (sigmoid applied), x, y, w, h, C class scores (softmax applied)).
/// Score = obj^0.6 * cls^0.4 (FastestDet's own weighting); centre = (tanh(x) + grid_x) / W
/// of the image width (likewise y), size = sigmoid(w) of the image width (likewise h).
/// Boxes are relative to the whole image, so they are returned in the pixels of
/// `image` directly, before NMS.
[[nodiscard]] inline std::vector<Detection> decode_fastestdet(const cv::Mat& output, cv::Size image,
                                                              float score_threshold) {
  if (output.dims != 4 || output.size[0] != 1 || output.size[1] < 6 || output.type() != CV_32F ||
      !output.isContinuous())
    detail::fail("FastestDet output has shape " + detail::shape_string(output) + " (" +
                 cv::typeToString(output.type()) + "), expected 1x(5+classes)xHxW float");
  detail::check(image.width > 0 && image.height > 0, "decode_fastestdet: image size must be positive");
  const int channels = output.size[1], gh = output.size[2], gw = output.size[3];
  const int plane = gh * gw;
  const float* base = output.ptr<float>();
  const auto iw = static_cast<float>(image.width), ih = static_cast<float>(image.height);
  std::vector<Detection> dets;
  for (int gy = 0; gy < gh; ++gy)
    for (int gx = 0; gx < gw; ++gx) {
      const float* p = base + gy * gw + gx;  // channel c at p[c * plane]
      const float obj = std::max(p[0], 0.0f);
      const auto [label, cls] = detail::arg_max(p + 5 * plane, channels - 5, plane);
      const float score = std::pow(obj, 0.6f) * std::pow(std::max(cls, 0.0f), 0.4f);
      if (!(score >= score_threshold)) continue;
      const float cx = (std::tanh(p[plane]) + static_cast<float>(gx)) / static_cast<float>(gw) * iw;
      const float cy = (std::tanh(p[2 * plane]) + static_cast<float>(gy)) / static_cast<float>(gh) * ih;
      const float w = detail::sigmoid(p[3 * plane]) * iw, h = detail::sigmoid(p[4 * plane]) * ih;
      dets.push_back({label, score, cv::Rect2f(cx - 0.5f * w, cy - 0.5f * h, w, h)});
    }
  return dets;
}

/// FastestDet (FastestDet.onnx): input 1x3x352x352, BGR / 255, the whole image resized
/// to 352x352 without keeping the aspect ratio (as FastestDet was trained); output
/// 1x85x22x22.
/// Deep copy: a copy parses the model again (from the bytes kept in memory, not the
/// file) into its own cv::dnn::Net with its own buffers, so per-thread copies run in
/// parallel with results equal to one object's; a copy costs a model parse (tens of
/// ms), so copy once per thread, not per image. One object serves one thread at a time.
class FastestDetDetector {
 public:
  static constexpr int input_side = 352;

  explicit FastestDetDetector(DnnDetectorOptions options) : options_(std::move(options)) {
    detail::check_detector_options(options_, "FastestDet");
    net_ = detail::DnnNet(options_.model, "FastestDet");
    run(cv::Mat(input_side, input_side, CV_8UC3, cv::Scalar::all(0)));
    const cv::Mat out = net_.outputs.size() == 1 ? net_.outputs.front() : cv::Mat();
    if (out.dims != 4 || out.size[0] != 1 || out.size[1] < 6 ||
        out.size[2] != input_side / 16 || out.size[3] != input_side / 16)
      detail::fail("FastestDet: model '" + options_.model.string() + "' gives " + net_.describe_outputs() +
                   "; a FastestDet model gives one output 1x(5+classes)x22x22 for a 352x352 input");
    classes_ = out.size[1] - 5;
  }

  [[nodiscard]] std::vector<Detection> detect(const cv::Mat& image) {
    detail::to_bgr8(image, buf_->bgr, "FastestDet detect");
    cv::resize(buf_->bgr, buf_->resized, cv::Size(input_side, input_side), 0, 0, cv::INTER_LINEAR);
    run(buf_->resized);
    const cv::Size size = buf_->bgr.size();
    return detail::finish_detections(decode_fastestdet(net_.outputs.front(), size, options_.score_threshold), 1.0f,
                                     1.0f, size, options_.nms);
  }

  [[nodiscard]] int classes() const noexcept { return classes_; }
  [[nodiscard]] const DnnDetectorOptions& options() const noexcept { return options_; }

 private:
  void run(const cv::Mat& input) {
    cv::dnn::blobFromImage(input, buf_->blob, 1.0 / 255.0, cv::Size(), cv::Scalar(), false, false, CV_32F);
    net_.forward(buf_->blob, "FastestDet", "FastestDet takes 1x3x352x352 BGR/255");
  }

  DnnDetectorOptions options_;
  detail::DnnNet net_;
  int classes_ = 0;
  struct Buffers {
    cv::Mat bgr, resized, blob;
  };
  detail::Scratch<Buffers> buf_;  // reused between images; a copy gets its own
};

static_assert(ObjectDetector<FastestDetDetector>);

// ---- run-time choice --------------------------------------------------------------

enum class DetectorFormat { yolox, nanodet, fastestdet };

/// "yolox", "nanodet" or "fastestdet"; anything else is an Error listing the choices.
[[nodiscard]] inline DetectorFormat parse_detector_format(std::string_view name) {
  if (name == "yolox") return DetectorFormat::yolox;
  if (name == "nanodet") return DetectorFormat::nanodet;
  if (name == "fastestdet") return DetectorFormat::fastestdet;
  detail::fail("unknown detector '" + std::string(name) + "' (choose yolox, nanodet or fastestdet)");
}

/// The cv::dnn adapter of `format` over `options.model`, behind AnyDetector.
[[nodiscard]] inline AnyDetector make_dnn_detector(DetectorFormat format, const DnnDetectorOptions& options) {
  switch (format) {
    case DetectorFormat::yolox: return AnyDetector(YoloxDetector(options));
    case DetectorFormat::nanodet: return AnyDetector(NanoDetDetector(options));
    case DetectorFormat::fastestdet: return AnyDetector(FastestDetDetector(options));
  }
  detail::fail("make_dnn_detector: invalid DetectorFormat");
}

}  // namespace vmap
