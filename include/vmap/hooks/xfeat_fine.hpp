#pragma once

// XFeat*'s match refinement (Potje et al., CVPR 2024, sec. 3.3 "dense matching" and the
// upstream `refine_matches`): a small MLP reads the two raw 64-d descriptors of a coarse
// cell match (image a's cell, then image b's) and gives 64 logits over the 8 x 8 pixels
// of a's cell. The front end then keeps the match when the softmax (temperature 3) has
// a peak above a confidence, and moves a's point by the softmax's expected offset.
// This is what LoFTR's fine level does for its coarse matches (Sun et al. 2021, sec.
// 3.4), with a network that runs in OpenCV 4.6.
//
// Offset convention: entry k of the logits is the pixel (k % 8, k / 8) of the cell, and
// the offset added to the cell's top-left pixel is sum_k p_k * (k % 8 - 3, k / 8 - 3).
// Upstream subtracts 4; on identical descriptors the network peaks at (3, 3), and on
// synthetic sub-pixel shifts of a real frame upstream's 4 places the refined points
// about 1 px up and left (tests/unit/hooks/test_xfeat_fine.cpp measures both; the
// median errors are in examples/hooks.md, "XFeat*"), so 3 is used.
//
// Pieces:
//   - XFeatRefiner: the network (one batched cv::dnn call per pair) and the rule;
//   - XFeatRefined<E>: an Estimator that refines the coarse matches of two refinable
//     grids (XFeatDenseDescriptor with XFeatGrid::refinable) and runs E on the kept,
//     refined points, so the Descriptor + Matcher + Estimator stack (threshold sweep,
//     `vmap build`) gets XFeat*; XFeatDenseMatcher with a refinement model does the same
//     as a PairMatcher.

#include <vmap/core/concepts.hpp>
#include <vmap/core/error.hpp>
#include <vmap/core/features.hpp>
#include <vmap/core/numeric.hpp>
#include <vmap/hooks/detail/dnn.hpp>

#include <opencv2/core.hpp>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace vmap {

struct XFeatFineOptions {
  std::filesystem::path model;  ///< XFeat*'s refinement MLP, e.g. xfeat_fine.onnx (required)
  /// XFeat*'s rule: a coarse match is kept when the largest softmax probability of its
  /// 64 offsets is above this (upstream: 0.25). In [0, 1).
  float min_confidence = 0.25f;
};

/// The refinement of one coarse match: the offset of image a's point from its cell's
/// top-left pixel, in network pixels, and the peak probability.
struct FineOffset {
  cv::Point2f offset;
  float confidence = 0.0f;
};

namespace detail {

/// XFeat*'s softmax temperature (upstream `subpix_softmax2d(..., temp=3)`).
inline constexpr float fine_temperature = 3.0f;
/// The pixel of a cell that an offset of 0 stands for (see the header comment).
inline constexpr float fine_centre = 3.0f;

/// Softmax of temperature * logits over the 64 pixels of a cell, its peak and the
/// expected offset from the cell's top-left pixel minus fine_centre.
inline FineOffset fine_offset(const float* logits) noexcept {
  float top = logits[0];
  for (int k = 1; k < 64; ++k) top = std::max(top, logits[k]);
  float p[64];
  float sum = 0.0f;
  for (int k = 0; k < 64; ++k) {
    p[k] = std::exp(fine_temperature * (logits[k] - top));
    sum += p[k];
  }
  const float inv = 1.0f / sum;
  float dx = 0.0f, dy = 0.0f, peak = 0.0f;
  for (int k = 0; k < 64; ++k) {
    const float q = p[k] * inv;
    dx += q * (static_cast<float>(k % 8) - fine_centre);
    dy += q * (static_cast<float>(k / 8) - fine_centre);
    peak = std::max(peak, q);
  }
  return {{dx, dy}, peak};
}

/// The refinement network's input for coarse matches: row i is image a's raw descriptor
/// of cell matches[i].queryIdx followed by image b's of cell matches[i].trainIdx (the
/// order the network was trained with; raw, as the dense map gives them).
inline void fine_input(const cv::Mat& raw_a, const cv::Mat& raw_b, const Matches& matches, cv::Mat& blob) {
  blob.create(static_cast<int>(matches.size()), 128, CV_32F);
  for (std::size_t i = 0; i < matches.size(); ++i) {
    float* row = blob.ptr<float>(static_cast<int>(i));
    std::memcpy(row, raw_a.ptr<float>(matches[i].queryIdx), 64 * sizeof(float));
    std::memcpy(row + 64, raw_b.ptr<float>(matches[i].trainIdx), 64 * sizeof(float));
  }
}

}  // namespace detail

/// The refinement network and XFeat*'s rule. The model is checked at load: it must take
/// N x 128 and give N x 64 (run on 1 and on 2 rows), anything else is an Error naming
/// the file. Deep copy: a copy parses the kept model bytes into its own cv::dnn::Net
/// (see detail::DnnNet); one object serves one thread at a time.
class XFeatRefiner {
 public:
  explicit XFeatRefiner(XFeatFineOptions options) : options_(std::move(options)), net_(options_.model, who) {
    detail::check(options_.min_confidence >= 0.0f && options_.min_confidence < 1.0f, [&] {
      return std::string(who) + ": XFeatFineOptions.min_confidence must be in [0, 1), got " +
             std::to_string(options_.min_confidence);
    });
    for (const int rows : {1, 2}) {
      net_.forward(cv::Mat::zeros(rows, 128, CV_32F), who, expects);
      const cv::Mat& out = net_.outputs.empty() ? cv::Mat() : net_.outputs.front();
      if (net_.outputs.size() != 1 || out.dims != 2 || out.rows != rows || out.cols != 64 || out.type() != CV_32F)
        detail::fail(std::string(who) + ": model '" + options_.model.string() +
                     "' is not XFeat*'s refinement network: on a " + std::to_string(rows) + "x128 input it gives" +
                     net_.describe_outputs() + "; expected one " + std::to_string(rows) + "x64 float output");
    }
  }

  /// Offsets and confidences of the coarse matches between cells of a and b, whose raw
  /// descriptors are the rows of raw_a and raw_b (CV_32F, 64 columns); one network call.
  void refine(const cv::Mat& raw_a, const cv::Mat& raw_b, const Matches& matches, std::vector<FineOffset>& out) {
    check_raw(raw_a, "image a");
    check_raw(raw_b, "image b");
    out.clear();
    if (matches.empty()) return;
    for (const cv::DMatch& m : matches)
      if (m.queryIdx < 0 || m.queryIdx >= raw_a.rows || m.trainIdx < 0 || m.trainIdx >= raw_b.rows)
        detail::fail(std::string(who) + ": match (" + std::to_string(m.queryIdx) + ", " + std::to_string(m.trainIdx) +
                     ") outside the grids (" + std::to_string(raw_a.rows) + " and " + std::to_string(raw_b.rows) +
                     " cells)");
    detail::fine_input(raw_a, raw_b, matches, blob_);
    net_.forward(blob_, who, expects);
    const cv::Mat& logits = net_.outputs.front();
    out.resize(matches.size());
    for (std::size_t i = 0; i < matches.size(); ++i) out[i] = detail::fine_offset(logits.ptr<float>(static_cast<int>(i)));
  }

  /// The network's raw logits for a prepared input (N x 128): for tests and tools.
  [[nodiscard]] cv::Mat logits(const cv::Mat& input) {
    net_.forward(input, who, expects);
    return net_.outputs.front().clone();
  }

  [[nodiscard]] const XFeatFineOptions& options() const noexcept { return options_; }

 private:
  static constexpr const char* who = "XFeat* refinement";
  static constexpr const char* expects = "XFeat*'s refinement MLP: pair N x 128 -> logits N x 64";

  static void check_raw(const cv::Mat& raw, const char* which) {
    if (raw.type() != CV_32F || raw.cols != 64)
      detail::fail(std::string(who) + ": " + which + "'s descriptors must be raw XFeat cells (CV_32F, 64 columns), got " +
                   cv::typeToString(raw.type()) + " with " + std::to_string(raw.cols) + " columns");
  }

  XFeatFineOptions options_;
  detail::DnnNet net_;
  cv::Mat blob_;
};

/// Coarse matches of two refinable grids, refined and filtered by the confidence rule.
struct RefinedMatches {
  std::vector<cv::Point2f> points_a;  ///< image a's refined points
  std::vector<cv::Point2f> points_b;  ///< image b's cell points, unmoved
  std::vector<float> confidence;      ///< the peak probability
  std::vector<std::size_t> original;  ///< kept[k] is matches[original[k]]
};

namespace detail {

/// The image-pixel size of one network pixel along x and y of a refinable grid (its
/// keypoints are the cells' top-left pixels in row-major order, 8 network pixels apart).
inline cv::Point2f grid_pixel(const Features& f) {
  const auto& k = f.keypoints;
  if (k.size() < 2) return {1.0f, 1.0f};
  float px = 0.0f, py = 0.0f;
  std::size_t row = 1;
  while (row < k.size() && k[row].pt.y == k[0].pt.y) ++row;
  px = row > 1 ? (k[1].pt.x - k[0].pt.x) / 8.0f : 0.0f;
  py = row < k.size() ? (k[row].pt.y - k[0].pt.y) / 8.0f : 0.0f;
  // A grid of one row or one column: the other axis has the same scale.
  if (px <= 0.0f) px = py;
  if (py <= 0.0f) py = px;
  return {px, py};
}

inline void check_refinable(const Features& f, const char* which) {
  if (f.descriptors.type() != CV_32F || f.descriptors.cols != 64 ||
      f.descriptors.rows != static_cast<int>(f.keypoints.size()))
    fail(std::string("XFeatRefined: ") + which +
         " must be a refinable XFeat grid (XFeatDenseDescriptor with XFeatGrid::refinable: one raw CV_32F 64-d "
         "descriptor per cell), got " +
         std::to_string(f.descriptors.rows) + " x " + std::to_string(f.descriptors.cols) + " " +
         cv::typeToString(f.descriptors.type()) + " descriptors for " + std::to_string(f.keypoints.size()) +
         " keypoints");
}

/// Refines `matches` between grids a and b with `refiner` and keeps those above the
/// confidence: a's point moves by the offset (network pixels scaled to the image), b's
/// stays at its cell. `offsets` is scratch.
inline void refine_matches(XFeatRefiner& refiner, const Features& a, const Features& b, const Matches& matches,
                           std::vector<FineOffset>& offsets, RefinedMatches& out) {
  check_refinable(a, "image a");
  check_refinable(b, "image b");
  refiner.refine(a.descriptors, b.descriptors, matches, offsets);
  const cv::Point2f s = grid_pixel(a);
  const float min_confidence = refiner.options().min_confidence;
  out.points_a.clear();
  out.points_b.clear();
  out.confidence.clear();
  out.original.clear();
  for (std::size_t i = 0; i < matches.size(); ++i) {
    const FineOffset& o = offsets[i];
    if (!(o.confidence > min_confidence)) continue;
    const cv::Point2f pa = a.keypoints[static_cast<std::size_t>(matches[i].queryIdx)].pt;
    out.points_a.emplace_back(pa.x + o.offset.x * s.x, pa.y + o.offset.y * s.y);
    out.points_b.push_back(b.keypoints[static_cast<std::size_t>(matches[i].trainIdx)].pt);
    out.confidence.push_back(o.confidence);
    out.original.push_back(i);
  }
}

}  // namespace detail

/// An Estimator that first refines XFeat's coarse cell matches (XFeat*) and then runs
/// E on the kept, refined points. a and b must be refinable grids
/// (XFeatDenseDescriptor with XFeatGrid::refinable); the Verification's inlier_mask is
/// aligned with the given coarse matches (matches below the confidence are outliers)
/// and `matches` counts all of them, so S = inliers / cells keeps eq. 5's coarse
/// denominator, while `fitted` counts the kept ones (the place decision weighs its
/// inliers against those: the coarse cells the refinement drops were never candidates
/// of the model). Without refinement options it is E unchanged (one type for a command
/// line that chooses at run time).
/// verify() is const and thread-safe: the refinement networks are a pool, each call
/// borrows one (a second network is parsed the first time two calls overlap), and every
/// network of the pool gives the same logits. A copy has a pool of its own.
template <Estimator E>
class XFeatRefined {
 public:
  XFeatRefined(std::optional<XFeatFineOptions> fine, E estimator) : estimator_(std::move(estimator)), fine_(fine) {
    if (fine) pool_ = std::make_shared<Pool>(XFeatRefiner(std::move(*fine)));
  }
  XFeatRefined(const XFeatRefined& other) : estimator_(other.estimator_), fine_(other.fine_) {
    if (other.pool_) pool_ = std::make_shared<Pool>(other.pool_->prototype);
  }
  XFeatRefined& operator=(const XFeatRefined& other) {
    if (this != &other) *this = XFeatRefined(other);
    return *this;
  }
  XFeatRefined(XFeatRefined&&) noexcept = default;
  XFeatRefined& operator=(XFeatRefined&&) noexcept = default;
  ~XFeatRefined() = default;

  [[nodiscard]] Verification verify(const Features& a, const Features& b, const Matches& matches) const {
    if (!pool_) return estimator_.verify(a, b, matches);
    RefinedMatches r;
    {
      Lease lease(*pool_);
      std::vector<FineOffset> offsets;
      detail::refine_matches(*lease.refiner, a, b, matches, offsets, r);
    }
    Features fa, fb;
    fa.norm = fb.norm = cv::NORM_L2;
    fa.image_size = a.image_size;
    fb.image_size = b.image_size;
    Matches kept(r.original.size());
    fa.keypoints.resize(kept.size());
    fb.keypoints.resize(kept.size());
    for (std::size_t k = 0; k < kept.size(); ++k) {
      fa.keypoints[k] = cv::KeyPoint(r.points_a[k], 1.0f);
      fb.keypoints[k] = cv::KeyPoint(r.points_b[k], 1.0f);
      kept[k] = cv::DMatch(static_cast<int>(k), static_cast<int>(k), 1.0f - r.confidence[k]);
    }
    Verification v = estimator_.verify(fa, fb, kept);
    v.matches = static_cast<int>(matches.size());
    v.fitted = static_cast<int>(kept.size());
    if (!v.inlier_mask.empty()) {
      std::vector<std::uint8_t> mask(matches.size(), 0);
      for (std::size_t k = 0; k < kept.size(); ++k) mask[r.original[k]] = v.inlier_mask[k];
      v.inlier_mask = std::move(mask);
    }
    return v;
  }

  [[nodiscard]] bool refines() const noexcept { return pool_ != nullptr; }
  [[nodiscard]] const E& estimator() const noexcept { return estimator_; }

  /// The refinement (model by its path, threshold) and the wrapped estimator
  /// (core/concepts.hpp, DescribesItself); without a refinement model it verifies as the
  /// wrapped estimator does, and describes itself as that.
  [[nodiscard]] std::string describe() const
    requires DescribesItself<E>
  {
    return describe(fine_, std::string(estimator_.describe()));
  }
  /// describe() of a refinement with these options around an estimator so described.
  [[nodiscard]] static std::string describe(const std::optional<XFeatFineOptions>& fine, const std::string& estimator) {
    if (!fine) return estimator;
    return "XFeatRefined model=" + quote_text(fine->model.string()) + " min_confidence=" +
           exact_text(fine->min_confidence) + " estimator=(" + estimator + ")";
  }

 private:
  struct Pool {
    explicit Pool(XFeatRefiner p) : prototype(std::move(p)) {}
    XFeatRefiner prototype;  // never run: copied into `idle` on demand
    std::mutex mutex;
    std::vector<std::unique_ptr<XFeatRefiner>> idle;
  };
  struct Lease {
    explicit Lease(Pool& p) : pool(p) {
      const std::lock_guard<std::mutex> lock(pool.mutex);
      if (pool.idle.empty()) {
        refiner = std::make_unique<XFeatRefiner>(pool.prototype);
      } else {
        refiner = std::move(pool.idle.back());
        pool.idle.pop_back();
      }
    }
    ~Lease() {
      const std::lock_guard<std::mutex> lock(pool.mutex);
      pool.idle.push_back(std::move(refiner));
    }
    Lease(const Lease&) = delete;
    Lease& operator=(const Lease&) = delete;
    Pool& pool;
    std::unique_ptr<XFeatRefiner> refiner;
  };

  E estimator_;
  std::optional<XFeatFineOptions> fine_;  ///< as constructed (describe())
  std::shared_ptr<Pool> pool_;
};

}  // namespace vmap
