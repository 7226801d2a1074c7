#pragma once

// XFeat learned local features (Potje et al., "XFeat: Accelerated Features for
// Lightweight Image Matching", CVPR 2024) as a Descriptor policy, run through cv::dnn.
// Two kinds of ONNX export work (../shared/models/README.md):
//   - fixed-size files (xfeat_320x224.onnx, xfeat_640x480.onnx, xfeat_1216x352.onnx):
//     they run only at the input size they declare; the image is resized to it and
//     keypoints are mapped back through the resize;
//   - any-size files (xfeat_anysize.onnx): any input whose sides are multiples of 32.
//     By default the network runs at the image's own resolution: the largest multiple
//     of 32 not above each side, taken as a centred crop (not a resize), so every
//     keypoint is an exact pixel of the input image (a resize by a non-integer factor
//     would interpolate the image and put keypoints between pixels, anisotropically
//     for KITTI's 1226x370 -> 1216x352). The crop loses at most 31 px per axis, split
//     between the two borders, where XFeat's 1/8 grid and NMS find few keypoints anyway.
//     A size set in the options is used as a resize instead (e.g. to run faster).
// The kind is found by running the model: at its declared size it must give XFeat's
// three maps, and it is any-size if it also runs at a second multiple-of-32 size. A
// model that gives other outputs is an Error naming the file.
//
// The network gives dense maps at 1/8 resolution; keypoint extraction and descriptor
// sampling follow XFeat's detectAndCompute and are done here in C++:
//   1. keypoint heatmap: softmax over the 65 logits of each 8x8 cell (64 positions +
//      a dustbin), the dustbin dropped, the 64 values unfolded to full resolution;
//   2. keypoints: local maxima of the heatmap in a (2r+1)^2 window above a threshold;
//   3. score = heatmap x reliability (bilinear at the keypoint); the top-k are kept;
//   4. descriptors: the 64-channel map, L2-normalised per cell, sampled bilinearly at
//      the keypoints and L2-normalised again;
//   5. keypoints are mapped from the network's input back to the input image.
// Features carry CV_32F descriptors and NORM_L2, so BruteForceMatcher (mutual mode)
// matches them with no change, and the policy plugs into any Descriptor host.
// hooks/xfeat_dense.hpp builds the detector-free front end on the same network.

#include <vmap/core/concepts.hpp>
#include <vmap/core/error.hpp>
#include <vmap/core/features.hpp>
#include <vmap/core/numeric.hpp>
#include <vmap/hooks/detail/dnn.hpp>
#include <vmap/hooks/detail/onnx_shape.hpp>

#include <opencv2/core.hpp>
#include <opencv2/core/utils/logger.hpp>
#include <opencv2/dnn.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace vmap {

struct XFeatOptions {
  std::filesystem::path model;  ///< XFeat ONNX export, fixed-size or any-size (required)
  /// Network input size (width x height). (0, 0), the default: a fixed-size model's own
  /// size (the image is resized to it), or for an any-size model the image's own
  /// resolution (the largest multiple of 32 not above each side, a centred crop). Set:
  /// the image is resized to it (aspect ratio not kept, as XFeat's own resize does);
  /// it must be the declared size of a fixed-size model, or multiples of 32 for an
  /// any-size one.
  cv::Size input_size{};
  /// At most this many keypoints (highest scores), >= 1. Capped at the number of 1/8
  /// cells of the network input (80x60 = 4800 at 640x480): with NMS radius >= 4 that is
  /// XFeat's semi-dense setting, one keypoint per cell at most.
  int top_k = 1000;
  float detection_threshold = 0.05f;    ///< heatmap floor of a keypoint, in [0, 1); XFeat's default
  int nms_radius = 2;                   ///< maxima in a (2r+1)^2 window, in [0, 16]; 2 = XFeat's 5x5 window
};

/// How an XFeat model file takes its input.
enum class XFeatModelKind : std::uint8_t {
  fixed_size,  ///< runs only at the size it declares
  any_size,    ///< runs at any size whose sides are multiples of 32
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

/// The input size (width, height) an ONNX file declares for a 1x3xHxW input; (0, 0)
/// when its height and width are symbolic. Anything else is an Error naming the file.
inline cv::Size xfeat_declared_size(const std::filesystem::path& model) {
  const std::string bytes = read_model_file(model, "XFeat");
  const std::vector<std::int64_t> dims = onnx_first_input_shape(bytes);
  if (dims.size() != 4 || dims[1] != 3 || dims[2] > 8192 || dims[3] > 8192)
    fail("XFeat: model '" + model.string() +
         "' does not declare a 1x3xHxW input; it is not an XFeat export (fixed-size or any-size)");
  if (dims[2] <= 0 || dims[3] <= 0) return {};
  return {static_cast<int>(dims[3]), static_cast<int>(dims[2])};
}

/// "1x3x480x640" for a network input of the given size.
inline std::string blob_shape(cv::Size s) {
  return "1x3x" + std::to_string(s.height) + "x" + std::to_string(s.width);
}

/// XFeat's three maps for one image, at 1/8 of the network input, and how a network
/// pixel maps back to the image.
struct XFeatMaps {
  cv::Size input;                    ///< network input size (W x H)
  int h8 = 0, w8 = 0;                ///< map size: H/8 x W/8
  const float* logits = nullptr;     ///< 65 planes of h8 x w8: keypoint logits
  const float* dense = nullptr;      ///< 64 planes of h8 x w8: descriptors (not normalised)
  const float* reliability = nullptr;  ///< 1 plane of h8 x w8
  /// Network pixel (x, y) -> image pixel ((x + 0.5) sx - 0.5 + ox, ...): pixel centres
  /// map onto pixel centres through a resize; a crop has scale 1 and its offset, so
  /// whole network pixels are whole image pixels.
  cv::Point2f scale{1.0f, 1.0f};
  cv::Point2f offset{0.0f, 0.0f};

  [[nodiscard]] cv::Point2f to_image(float x, float y) const noexcept {
    return {(x + 0.5f) * scale.x - 0.5f + offset.x, (y + 0.5f) * scale.y - 0.5f + offset.y};
  }
  [[nodiscard]] int cells() const noexcept { return h8 * w8; }
};

/// An XFeat ONNX model in cv::dnn: finds its kind (fixed-size or any-size), picks the
/// network size for each image, runs it and tells the three outputs apart. Deep copy
/// (a copy has its own cv::dnn::Net, see DnnNet, and its own scratch images); one
/// object serves one thread at a time.
class XFeatNet {
 public:
  XFeatNet() = default;
  /// `who` names the policy in error messages; `input_size` as XFeatOptions::input_size.
  XFeatNet(const std::filesystem::path& model, cv::Size input_size, std::string_view who)
      : who_(who), user_size_(input_size) {
    check(input_size.width >= 0 && input_size.height >= 0 && (input_size.width > 0) == (input_size.height > 0),
          [&] { return std::string(who) + ": XFeatOptions.input_size must be (0, 0) or a positive size"; });
    declared_ = xfeat_declared_size(model);
    net_ = DnnNet(model, who);
    // A size that is not a multiple of 8 cannot be an XFeat input (stride-8 maps).
    if (declared_.width % 8 != 0 || declared_.height % 8 != 0)
      fail(std::string(who) + ": model '" + model.string() + "' declares a " + blob_shape(declared_) +
           " input, not a multiple of 8: not an XFeat export");
    // Run at the declared size (or a small multiple of 32 when it declares none): the
    // model must give XFeat's maps there; then a second size tells the kinds apart.
    const cv::Size first = first_size();
    if (!probe())
      fail(std::string(who) + ": model '" + model.string() + "' is neither a fixed-size nor an any-size XFeat export: on a " +
           blob_shape(first) + " input it gives " + net_.describe_outputs() +
           "; an XFeat model gives 1x64xH/8xW/8 descriptors, 1x65xH/8xW/8 keypoint logits and a 1x1xH/8xW/8 "
           "reliability map");
    if (kind_ == XFeatModelKind::fixed_size && declared_.width == 0)
      fail(std::string(who) + ": model '" + model.string() +
           "' declares no input size and does not run at every multiple of 32; export it with a fixed size");
    if (user_size_.width > 0) {
      if (kind_ == XFeatModelKind::fixed_size && user_size_ != declared_)
        fail(std::string(who) + ": model '" + model.string() + "' is a fixed-size export for " +
             blob_shape(declared_) + " and does not run on a " + blob_shape(user_size_) +
             " input (XFeatOptions.input_size); leave input_size (0, 0) or use an any-size export");
      if (kind_ == XFeatModelKind::any_size && (user_size_.width % 32 != 0 || user_size_.height % 32 != 0))
        fail(std::string(who) + ": XFeatOptions.input_size " + std::to_string(user_size_.width) + "x" +
             std::to_string(user_size_.height) + " for the any-size model '" + model.string() +
             "' must have sides that are multiples of 32");
    }
  }

  /// Deep copy: a network of its own (DnnNet parses the kept model bytes again) that
  /// replays the construction's two probe runs. cv::dnn computes slightly differently
  /// (about 1e-4 in the maps) once a net has been planned for a second input size, and
  /// every constructed XFeatNet has been (the probe); without the replay a copy would not
  /// give the original's keypoints exactly. A copy costs a parse and the two runs.
  XFeatNet(const XFeatNet& other)
      : who_(other.who_),
        user_size_(other.user_size_),
        declared_(other.declared_),
        kind_(other.kind_),
        net_(other.net_),
        descriptor_index_(other.descriptor_index_),
        keypoint_index_(other.keypoint_index_),
        reliability_index_(other.reliability_index_) {
    if (!net_.net.empty() && !probe())
      fail(who_ + ": the copy of model '" + net_.file.string() + "' no longer gives XFeat's maps");
  }
  XFeatNet& operator=(const XFeatNet& other) {
    if (this != &other) *this = XFeatNet(other);
    return *this;
  }
  XFeatNet(XFeatNet&&) noexcept = default;
  XFeatNet& operator=(XFeatNet&&) noexcept = default;
  ~XFeatNet() = default;

  [[nodiscard]] XFeatModelKind kind() const noexcept { return kind_; }
  /// The size the file declares ((0, 0) if symbolic).
  [[nodiscard]] cv::Size declared_size() const noexcept { return declared_; }
  [[nodiscard]] const std::filesystem::path& file() const noexcept { return net_.file; }

  /// The network input size for an image of `image` size (see XFeatOptions::input_size).
  [[nodiscard]] cv::Size network_size(cv::Size image) const {
    if (user_size_.width > 0) return user_size_;
    if (kind_ == XFeatModelKind::fixed_size) return declared_;
    const cv::Size s(image.width / 32 * 32, image.height / 32 * 32);
    if (s.width == 0 || s.height == 0)
      fail(who_ + ": image of " + std::to_string(image.width) + "x" + std::to_string(image.height) +
           " is smaller than 32x32, the smallest input of the any-size model '" + net_.file.string() + "'");
    return s;
  }

  /// Runs the network on an image (8/16-bit, grey/BGR/BGRA); the maps stay valid until
  /// the next call.
  const XFeatMaps& run(const cv::Mat& image) {
    to_bgr8(image, buf_->bgr, who_ + " extract");
    const cv::Size in = network_size(buf_->bgr.size());
    XFeatMaps& m = buf_->maps;
    m.scale = {1.0f, 1.0f};
    m.offset = {0.0f, 0.0f};
    cv::Mat input = buf_->bgr;
    if (user_size_.width == 0 && kind_ == XFeatModelKind::any_size) {
      // Centred crop to whole multiples of 32: network pixels are image pixels.
      const int ox = (buf_->bgr.cols - in.width) / 2, oy = (buf_->bgr.rows - in.height) / 2;
      input = buf_->bgr(cv::Rect(ox, oy, in.width, in.height));
      m.offset = {static_cast<float>(ox), static_cast<float>(oy)};
    } else if (buf_->bgr.size() != in) {
      cv::resize(buf_->bgr, buf_->resized, in, 0, 0, cv::INTER_AREA);
      input = buf_->resized;
      m.scale = {static_cast<float>(buf_->bgr.cols) / static_cast<float>(in.width),
                 static_cast<float>(buf_->bgr.rows) / static_cast<float>(in.height)};
    }
    forward(input);
    // A new size re-plans the network (cv::dnn does it in forward); the outputs are
    // told apart again at that size.
    if (in != buf_->planned && !identify_outputs(in))
      fail(who_ + ": model '" + net_.file.string() + "' gives " + net_.describe_outputs() + " on a " +
           blob_shape(in) + " input, not XFeat's three maps");
    m.input = in;
    m.h8 = in.height / 8;
    m.w8 = in.width / 8;
    m.logits = net_.outputs[static_cast<std::size_t>(keypoint_index_)].ptr<float>();
    m.dense = net_.outputs[static_cast<std::size_t>(descriptor_index_)].ptr<float>();
    m.reliability = net_.outputs[static_cast<std::size_t>(reliability_index_)].ptr<float>();
    return m;
  }

 private:
  [[nodiscard]] cv::Size first_size() const noexcept { return declared_.width > 0 ? declared_ : cv::Size(64, 64); }

  /// Runs the model at first_size() (false when it does not give XFeat's maps there),
  /// then at a second multiple-of-32 size, which finds the kind.
  bool probe() {
    const cv::Size first = first_size();
    if (!try_size(first, true)) return false;
    const cv::Size second = first == cv::Size(64, 64) ? cv::Size(96, 96) : cv::Size(64, 64);
    // A fixed-size model fails this run by design; cv::dnn would log that failure as an
    // error on stderr, so its log is silenced for the probe (process-wide, for the few
    // milliseconds of a 64x64 run).
    const auto level = cv::utils::logging::getLogLevel();
    cv::utils::logging::setLogLevel(cv::utils::logging::LOG_LEVEL_SILENT);
    try {
      kind_ = try_size(second, false) ? XFeatModelKind::any_size : XFeatModelKind::fixed_size;
    } catch (...) {
      cv::utils::logging::setLogLevel(level);
      throw;
    }
    cv::utils::logging::setLogLevel(level);
    return true;
  }

  void forward(const cv::Mat& input) {
    // Grey conversion and instance normalisation are inside the exported graph.
    cv::dnn::blobFromImage(input, buf_->blob, 1.0 / 255.0, cv::Size(), cv::Scalar(), false, false, CV_32F);
    net_.forward(buf_->blob, who_,
                 kind_ == XFeatModelKind::fixed_size ? "a fixed-size XFeat export runs only at the size it declares"
                                                     : "an any-size XFeat export needs sides that are multiples of 32");
  }

  /// Runs a grey image of `size` and tells the three outputs apart by their channel
  /// count (their names are graph-internal numbers): 64 descriptors, 65 keypoint
  /// logits, 1 reliability, all at 1/8 of the input. False when the model does not run
  /// at that size or gives other outputs; with `rethrow`, a model that does not run is
  /// an Error (naming the file) instead.
  bool try_size(cv::Size size, bool rethrow) {
    buf_->planned = {};
    try {
      forward(cv::Mat(size, CV_8UC3, cv::Scalar::all(128)));
    } catch (const Error&) {
      if (rethrow) throw;
      return false;
    }
    return identify_outputs(size);
  }

  /// After a forward pass at `size`: the indices of the three outputs; false when the
  /// outputs are not XFeat's.
  bool identify_outputs(cv::Size size) {
    buf_->planned = {};
    const int h8 = size.height / 8, w8 = size.width / 8;
    descriptor_index_ = keypoint_index_ = reliability_index_ = -1;
    for (std::size_t i = 0; i < net_.outputs.size(); ++i) {
      const cv::Mat& o = net_.outputs[i];
      if (o.dims != 4 || o.size[0] != 1 || o.size[2] != h8 || o.size[3] != w8 || o.type() != CV_32F) continue;
      if (o.size[1] == 64) descriptor_index_ = static_cast<int>(i);
      if (o.size[1] == 65) keypoint_index_ = static_cast<int>(i);
      if (o.size[1] == 1) reliability_index_ = static_cast<int>(i);
    }
    if (net_.outputs.size() != 3 || descriptor_index_ < 0 || keypoint_index_ < 0 || reliability_index_ < 0)
      return false;
    buf_->planned = size;
    return true;
  }

  // What a copy needs to run the same network on its own (DnnNet copies deeply).
  std::string who_ = "XFeat";
  cv::Size user_size_, declared_;
  XFeatModelKind kind_ = XFeatModelKind::fixed_size;
  DnnNet net_;
  int descriptor_index_ = -1, keypoint_index_ = -1, reliability_index_ = -1;
  // Per-object state of the last run. A copy starts without it: its own net has not
  // been planned at any size yet (so it checks the outputs again on its first image),
  // and the maps point into the original's outputs.
  struct Buffers {
    cv::Size planned;  // the size the outputs were last told apart at
    XFeatMaps maps;
    cv::Mat bgr, resized, blob;
  };
  Scratch<Buffers> buf_;
};

/// Softmax over the 65 logits of cell (cx, cy); writes the 64 position probabilities
/// (dustbin dropped) to `out` and returns nothing else. Channel k is pixel
/// (8 cx + k % 8, 8 cy + k / 8) of the cell (XFeat's get_kpts_heatmap unfolding).
inline void cell_softmax(const XFeatMaps& m, int cx, int cy, float* out) noexcept {
  const int plane = m.cells();
  const float* p = m.logits + cy * m.w8 + cx;  // channel k at p[k * plane]
  float top = p[0];
  for (int k = 1; k < 65; ++k) top = std::max(top, p[k * plane]);
  float sum = 0.0f;
  for (int k = 0; k < 65; ++k) sum += std::exp(p[k * plane] - top);
  const float inv = 1.0f / sum;
  for (int k = 0; k < 64; ++k) out[k] = std::exp(p[k * plane] - top) * inv;
}

/// The dense descriptor map as 64 planes of h8 x w8, each cell's 64-vector
/// L2-normalised (XFeat normalises the map before sampling it).
inline void normalise_cells(const XFeatMaps& m, std::vector<cv::Mat>& cells, std::vector<float>& norms) {
  cells.resize(64);
  const int plane = m.cells();
  const float* base = m.dense;
  norms.assign(static_cast<std::size_t>(plane), 0.0f);
  for (int ch = 0; ch < 64; ++ch)
    for (int i = 0; i < plane; ++i) norms[static_cast<std::size_t>(i)] += base[ch * plane + i] * base[ch * plane + i];
  for (auto& v : norms) v = v > 0.0f ? 1.0f / std::sqrt(v) : 0.0f;
  for (int ch = 0; ch < 64; ++ch) {
    cv::Mat& c = cells[static_cast<std::size_t>(ch)];
    c.create(m.h8, m.w8, CV_32F);
    float* dst = c.ptr<float>();
    for (int i = 0; i < plane; ++i) dst[i] = base[ch * plane + i] * norms[static_cast<std::size_t>(i)];
  }
}

}  // namespace detail

/// XFeat keypoints and 64-float descriptors (NORM_L2).
/// Deep copy: a copy parses the model again (from the bytes kept in memory, not the
/// file) into its own cv::dnn::Net with its own buffers, so per-thread copies run in
/// parallel with results equal to one object's; a copy costs a model parse and the two
/// probe runs of construction (see detail::XFeatNet), so copy once per thread, not per
/// image. One object serves one thread at a time.
class XFeatDescriptor {
 public:
  explicit XFeatDescriptor(XFeatOptions options) : options_(std::move(options)) {
    const auto& o = options_;
    detail::check(o.top_k >= 1, "XFeatOptions.top_k must be >= 1, got " + std::to_string(o.top_k));
    detail::check(std::isfinite(o.detection_threshold) && o.detection_threshold >= 0.0f && o.detection_threshold < 1.0f,
                  "XFeatOptions.detection_threshold must be in [0, 1), got " + std::to_string(o.detection_threshold));
    detail::check(o.nms_radius >= 0 && o.nms_radius <= 16,
                  "XFeatOptions.nms_radius must be in [0, 16], got " + std::to_string(o.nms_radius));
    net_ = detail::XFeatNet(o.model, o.input_size, "XFeat");
  }

  [[nodiscard]] Features extract(const cv::Mat& image) {
    const detail::XFeatMaps& m = net_.run(image);
    heatmap(m);
    select_keypoints(m);

    Features f;
    f.norm = cv::NORM_L2;
    f.image_size = image.size();
    const int n = static_cast<int>(buf_->candidates.size());
    f.keypoints.reserve(buf_->candidates.size());
    f.descriptors.create(n, 64, CV_32F);
    detail::normalise_cells(m, buf_->cells, buf_->norms);
    const float kx = static_cast<float>(m.w8) / static_cast<float>(m.input.width - 1);
    const float ky = static_cast<float>(m.h8) / static_cast<float>(m.input.height - 1);
    const float size = 8.0f * std::max(m.scale.x, m.scale.y);
    for (int i = 0; i < n; ++i) {
      const Candidate& c = buf_->candidates[static_cast<std::size_t>(i)];
      f.keypoints.emplace_back(m.to_image(static_cast<float>(c.x), static_cast<float>(c.y)), size, -1.0f, c.score);
      // XFeat samples with grid_sample(align_corners=False) after mapping pixel x to
      // [-1, 1] by 2x/(W-1) - 1: on the 1/8 map that is x * w8/(W-1) - 0.5.
      const float u = static_cast<float>(c.x) * kx - 0.5f, v = static_cast<float>(c.y) * ky - 0.5f;
      float* d = f.descriptors.ptr<float>(i);
      float norm = 0.0f;
      for (int ch = 0; ch < 64; ++ch) {
        d[ch] = detail::bilinear(buf_->cells[static_cast<std::size_t>(ch)], u, v);
        norm += d[ch] * d[ch];
      }
      const float inv = norm > 0.0f ? 1.0f / std::sqrt(norm) : 0.0f;
      for (int ch = 0; ch < 64; ++ch) d[ch] *= inv;
    }
    return f;
  }

  [[nodiscard]] const XFeatOptions& options() const noexcept { return options_; }

  /// The name and every option, the model by its path (core/concepts.hpp,
  /// DescribesItself): a memory records it, and is read with the model it names.
  [[nodiscard]] std::string describe() const { return describe(options_); }
  /// describe() of a descriptor with these options, without loading the model.
  [[nodiscard]] static std::string describe(const XFeatOptions& o) {
    return "XFeatDescriptor model=" + quote_text(o.model.string()) + " input_size=" + std::to_string(o.input_size.width) +
           "x" + std::to_string(o.input_size.height) + " top_k=" + std::to_string(o.top_k) +
           " detection_threshold=" + exact_text(o.detection_threshold) + " nms_radius=" + std::to_string(o.nms_radius);
  }

  /// 64 floats of unit length, L2.
  [[nodiscard]] static DescriptorLayout layout() noexcept { return {CV_32FC1, 64, cv::NORM_L2}; }
  /// Whether the model runs only at its declared size or at any multiple of 32.
  [[nodiscard]] XFeatModelKind model_kind() const noexcept { return net_.kind(); }
  /// The size the model file declares ((0, 0) if symbolic).
  [[nodiscard]] cv::Size declared_size() const noexcept { return net_.declared_size(); }
  /// The network input size used for an image of this size.
  [[nodiscard]] cv::Size network_size(cv::Size image) const { return net_.network_size(image); }

 private:
  struct Candidate {
    int x, y;
    float score;
  };

  /// Step 1: the 64 position probabilities of every cell, unfolded to full resolution.
  void heatmap(const detail::XFeatMaps& m) {
    cv::Mat& heat = buf_->heat;
    heat.create(m.h8 * 8, m.w8 * 8, CV_32F);
    float prob[64];
    for (int cy = 0; cy < m.h8; ++cy)
      for (int cx = 0; cx < m.w8; ++cx) {
        detail::cell_softmax(m, cx, cy, prob);
        for (int k = 0; k < 64; ++k) heat.at<float>(cy * 8 + k / 8, cx * 8 + k % 8) = prob[k];
      }
  }

  /// Steps 2-3: local maxima above the threshold, scored by heatmap x reliability,
  /// top-k by score (ties by position, so the result is deterministic).
  void select_keypoints(const detail::XFeatMaps& m) {
    const int r = options_.nms_radius;
    const cv::Mat& heat = buf_->heat;
    cv::dilate(heat, buf_->local_max, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(2 * r + 1, 2 * r + 1)));
    std::vector<Candidate>& candidates = buf_->candidates;
    candidates.clear();
    const cv::Mat reliability(m.h8, m.w8, CV_32F, const_cast<float*>(m.reliability));
    // Same pixel -> 1/8-map mapping as the descriptors (see extract).
    const float rx = static_cast<float>(m.w8) / static_cast<float>(heat.cols - 1);
    const float ry = static_cast<float>(m.h8) / static_cast<float>(heat.rows - 1);
    for (int y = 0; y < heat.rows; ++y) {
      const float* h = heat.ptr<float>(y);
      const float* lm = buf_->local_max.ptr<float>(y);
      for (int x = 0; x < heat.cols; ++x)
        if (h[x] > options_.detection_threshold && h[x] >= lm[x]) {
          const float rel =
              detail::bilinear(reliability, static_cast<float>(x) * rx - 0.5f, static_cast<float>(y) * ry - 0.5f);
          candidates.push_back({x, y, h[x] * rel});
        }
    }
    const auto better = [](const Candidate& a, const Candidate& b) {
      if (a.score != b.score) return a.score > b.score;
      return a.y != b.y ? a.y < b.y : a.x < b.x;
    };
    // Top-k, at most one keypoint per cell on average (the semi-dense budget).
    const auto k = std::min({candidates.size(), static_cast<std::size_t>(options_.top_k),
                             static_cast<std::size_t>(m.cells())});
    std::partial_sort(candidates.begin(), candidates.begin() + static_cast<std::ptrdiff_t>(k), candidates.end(),
                      better);
    candidates.resize(k);
  }

  XFeatOptions options_;
  detail::XFeatNet net_;
  // Scratch reused between images; a copy gets its own.
  struct Buffers {
    cv::Mat heat, local_max;
    std::vector<Candidate> candidates;
    std::vector<cv::Mat> cells;
    std::vector<float> norms;
  };
  detail::Scratch<Buffers> buf_;
};

static_assert(Descriptor<XFeatDescriptor>);

}  // namespace vmap
