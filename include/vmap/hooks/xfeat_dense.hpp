#pragma once

// A detector-free front end from XFeat's dense map (examples/methods.md, sec. 5 and 7), the visual-map
// paper's "detector-free" configuration (García-Pintos et al. 2023 use LoFTR) with a
// network that runs in OpenCV 4.6 on the CPU:
//   - every cell of the 1/8 grid is a candidate, placed at its best pixel (the argmax
//     of the cell's 64 keypoint logits, the dustbin left out) and described by the
//     cell's own 64-d descriptor, L2-normalised; no detector, no threshold, no NMS;
//   - mutual nearest neighbours over the two grids (largest dot product of the unit
//     descriptors) are the correspondences;
//   - the number of cells is the denominator of eq. 5, as for LoFTR's coarse level.
// Three pieces:
//   - XFeatDenseDescriptor (a Descriptor): the grid of one image as Features, one
//     keypoint per cell in row-major order, so |D| = cells;
//   - DenseMutualMatcher (a Matcher): mutual NN of unit float descriptors by blocked
//     matrix products (Eigen), the same matches as L2 cross-checking at a fraction of
//     cv::batchDistance's cost on 4800 x 4800 candidates;
//   - XFeatDenseMatcher (a PairMatcher, for PairKeyframeSelector): both of the above on
//     an image pair, with the network outputs of the last three images cached by
//     content, so a frame goes through the network once although the selector pairs it
//     with the key image now and may make it the key image later.
// The FeatureFrontEnd<XFeatDenseDescriptor, DenseMutualMatcher, Estimator, InlierRatio>
// stack and PairFrontEnd<XFeatDenseMatcher, Estimator> select the same key images (the
// same points in the same order reach the estimator, and S = inliers / cells in both);
// the threshold sweep runs the first, the streaming selector either.
// XFeat* (hooks/xfeat_fine.hpp) refines the coarse matches to sub-pixel: the grid kept
// raw at the cells' top-left pixels (XFeatGrid::refinable), the same mutual NN on unit
// copies, then the refinement network once per pair, in XFeatRefined<Estimator> for
// the first stack and in XFeatDenseMatcher (given XFeatFineOptions) for the second.
// Eq. 5's denominator stays the number of coarse cells: a refined match is one cell
// matched and placed to sub-pixel, and matches below the refinement's confidence count
// as unverified, so S = verified refined matches / cells.

#include <vmap/core/concepts.hpp>
#include <vmap/core/error.hpp>
#include <vmap/core/features.hpp>
#include <vmap/core/numeric.hpp>
#include <vmap/hooks/pair_matcher.hpp>
#include <vmap/hooks/xfeat.hpp>
#include <vmap/hooks/xfeat_fine.hpp>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace vmap {

namespace detail {

/// Scales n floats to unit length (a zero vector stays zero).
inline void make_unit(float* p, int n) noexcept {
  float norm = 0.0f;
  for (int c = 0; c < n; ++c) norm += p[c] * p[c];
  const float inv = norm > 0.0f ? 1.0f / std::sqrt(norm) : 0.0f;
  for (int c = 0; c < n; ++c) p[c] *= inv;
}

}  // namespace detail

/// Where a cell's keypoint sits and what its descriptor is.
enum class XFeatGrid {
  /// At the cell's best pixel (argmax of its 64 keypoint logits), unit descriptor: the
  /// coarse front end, matched by DenseMutualMatcher.
  best_pixel,
  /// At the cell's top-left pixel, raw descriptor (not normalised): what XFeat*'s
  /// refinement reads (XFeatRefined, XFeatDenseMatcher with a refinement model);
  /// matched by DenseMutualMatcher with `normalise`.
  refinable,
};

struct XFeatDenseOptions {
  std::filesystem::path model;  ///< XFeat ONNX export, fixed-size or any-size (required)
  /// Network input size, as XFeatOptions::input_size: (0, 0) = the fixed-size model's
  /// own size, or the image's own resolution (centred multiple-of-32 crop) for an
  /// any-size model.
  cv::Size input_size{};
  XFeatGrid grid = XFeatGrid::best_pixel;
};

/// Every cell of XFeat's 1/8 grid as a keypoint with the cell's 64-d descriptor
/// (NORM_L2): by default at the cell's best pixel with a unit descriptor, with
/// XFeatGrid::refinable at its top-left pixel with the raw one. Keypoints are in
/// row-major cell order; response is the softmax probability of the best pixel.
/// Deep copy: a copy parses the model again (from the bytes kept in memory, not the
/// file) into its own cv::dnn::Net with its own buffers, so per-thread copies run in
/// parallel with results equal to one object's; a copy costs a model parse and the two
/// probe runs of construction (see detail::XFeatNet), so copy once per thread, not per
/// image. One object serves one thread at a time.
class XFeatDenseDescriptor {
 public:
  explicit XFeatDenseDescriptor(XFeatDenseOptions options)
      : options_(std::move(options)), net_(options_.model, options_.input_size, "XFeat dense") {}

  [[nodiscard]] Features extract(const cv::Mat& image) {
    const detail::XFeatMaps& m = net_.run(image);
    const int plane = m.cells();
    Features f;
    f.norm = cv::NORM_L2;
    f.image_size = image.size();
    f.keypoints.reserve(static_cast<std::size_t>(plane));
    f.descriptors.create(plane, 64, CV_32F);
    const float size = 8.0f * std::max(m.scale.x, m.scale.y);
    const bool refinable = options_.grid == XFeatGrid::refinable;
    float prob[64];
    for (int cy = 0; cy < m.h8; ++cy)
      for (int cx = 0; cx < m.w8; ++cx) {
        detail::cell_softmax(m, cx, cy, prob);
        const int k = static_cast<int>(std::max_element(prob, prob + 64) - prob);  // first of equals
        const int at = refinable ? 0 : k;
        const float x = static_cast<float>(cx * 8 + at % 8), y = static_cast<float>(cy * 8 + at / 8);
        f.keypoints.emplace_back(m.to_image(x, y), size, -1.0f, prob[k]);
        const int cell = cy * m.w8 + cx;
        float* d = f.descriptors.ptr<float>(cell);
        for (int ch = 0; ch < 64; ++ch) d[ch] = m.dense[ch * plane + cell];
        if (!refinable) detail::make_unit(d, 64);
      }
    return f;
  }

  [[nodiscard]] const XFeatDenseOptions& options() const noexcept { return options_; }
  /// The name and every option, the model by its path (core/concepts.hpp, DescribesItself).
  [[nodiscard]] std::string describe() const { return describe(options_); }
  /// describe() of a descriptor with these options, without loading the model.
  [[nodiscard]] static std::string describe(const XFeatDenseOptions& o) {
    return "XFeatDenseDescriptor model=" + quote_text(o.model.string()) + " input_size=" +
           std::to_string(o.input_size.width) + "x" + std::to_string(o.input_size.height) +
           " grid=" + (o.grid == XFeatGrid::refinable ? "refinable" : "best_pixel");
  }
  [[nodiscard]] XFeatModelKind model_kind() const noexcept { return net_.kind(); }
  /// The network input size for an image of this size; its cells are (W/8) x (H/8).
  [[nodiscard]] cv::Size network_size(cv::Size image) const { return net_.network_size(image); }

 private:
  XFeatDenseOptions options_;
  detail::XFeatNet net_;
};

static_assert(Descriptor<XFeatDenseDescriptor>);

struct DenseMutualOptions {
  /// Match unit-length copies of the descriptors (for raw ones, XFeatGrid::refinable);
  /// otherwise the descriptors must already have unit length.
  bool normalise = false;
};

/// Mutual nearest neighbours of unit-length float descriptors (NORM_L2), by the largest
/// dot product, which for unit vectors is the smallest L2 distance. DMatch::distance is
/// that L2 distance. Ties go to the lower index. Holds only options: `match` is const
/// and safe to call from several threads at once.
class DenseMutualMatcher {
 public:
  DenseMutualMatcher() = default;
  explicit DenseMutualMatcher(DenseMutualOptions options) : options_(options) {}

  [[nodiscard]] Matches match(const Features& a, const Features& b) const {
    Matches out;
    if (a.descriptors.empty() || b.descriptors.empty()) return out;
    check(a);
    check(b);
    detail::check(a.descriptors.cols == b.descriptors.cols,
                  "DenseMutualMatcher: descriptors differ in length (" + std::to_string(a.descriptors.cols) + " vs " +
                      std::to_string(b.descriptors.cols) + ")");
    using RowMajor = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
    const cv::Mat da = unit(a.descriptors), db = unit(b.descriptors);
    const int na = da.rows, nb = db.rows, dim = da.cols;
    const Eigen::Map<const RowMajor> A(da.ptr<float>(), na, dim), B(db.ptr<float>(), nb, dim);
    std::vector<float> row_best(static_cast<std::size_t>(na)), col_best(static_cast<std::size_t>(nb),
                                                                        -std::numeric_limits<float>::infinity());
    std::vector<int> row_arg(static_cast<std::size_t>(na), -1), col_arg(static_cast<std::size_t>(nb), -1);
    // Blocks of rows of a against all of b: the block's products stay in cache, and each
    // column of the (column-major) block is scanned once for both maxima.
    constexpr int block = 256;
    Eigen::MatrixXf s;
    for (int r0 = 0; r0 < na; r0 += block) {
      const int n = std::min(block, na - r0);
      s.noalias() = A.middleRows(r0, n) * B.transpose();
      float* rb = row_best.data() + r0;
      int* ra = row_arg.data() + r0;
      std::fill(rb, rb + n, -std::numeric_limits<float>::infinity());
      for (int j = 0; j < nb; ++j) {
        const float* col = s.data() + static_cast<std::ptrdiff_t>(j) * n;
        float best = col_best[static_cast<std::size_t>(j)];
        int arg = col_arg[static_cast<std::size_t>(j)];
        for (int i = 0; i < n; ++i) {
          const float v = col[i];
          if (v > best) {
            best = v;
            arg = r0 + i;
          }
          if (v > rb[i]) {
            rb[i] = v;
            ra[i] = j;
          }
        }
        col_best[static_cast<std::size_t>(j)] = best;
        col_arg[static_cast<std::size_t>(j)] = arg;
      }
    }
    for (int i = 0; i < na; ++i) {
      const int j = row_arg[static_cast<std::size_t>(i)];
      if (j < 0 || col_arg[static_cast<std::size_t>(j)] != i) continue;
      // |x - y|^2 = 2 - 2 x.y for unit vectors.
      const float d2 = std::max(0.0f, 2.0f - 2.0f * row_best[static_cast<std::size_t>(i)]);
      out.emplace_back(i, j, std::sqrt(d2));
    }
    return out;
  }

  [[nodiscard]] const DenseMutualOptions& options() const noexcept { return options_; }
  /// The name and its option (core/concepts.hpp, DescribesItself).
  [[nodiscard]] std::string describe() const {
    return std::string("DenseMutualMatcher normalise=") + (options_.normalise ? "1" : "0");
  }

 private:
  /// Continuous rows, of unit length when the options say to normalise.
  [[nodiscard]] cv::Mat unit(const cv::Mat& d) const {
    if (!options_.normalise) return d.isContinuous() ? d : d.clone();
    cv::Mat u = d.clone();
    for (int r = 0; r < u.rows; ++r) detail::make_unit(u.ptr<float>(r), u.cols);
    return u;
  }

  static void check(const Features& f) {
    if (f.descriptors.type() != CV_32F || f.norm != cv::NORM_L2)
      detail::fail("DenseMutualMatcher: needs CV_32F descriptors compared with NORM_L2 (unit vectors), got " +
                   cv::typeToString(f.descriptors.type()) + " with norm " + std::to_string(f.norm));
    if (f.descriptors.rows != static_cast<int>(f.keypoints.size()))
      detail::fail("DenseMutualMatcher: descriptor rows and keypoint count differ");
  }

  DenseMutualOptions options_;
};

static_assert(Matcher<DenseMutualMatcher>);

/// The dense front end as a PairMatcher: grids of both images (each image through the
/// network once while it is among the last three seen), mutual NN, and
/// Correspondences::cells = the larger grid (eq. 5's denominator). With refinement
/// options it is XFeat*: the grids are refinable (XFeatGrid::refinable, whatever the
/// options' grid says), each pair's coarse matches go through the refinement network
/// once (detail::refine_matches, as XFeatRefined), those below the confidence are
/// dropped, image a's points are refined, and the confidence is the refinement's peak
/// probability; `cells` stays the coarse grid.
/// Deep copy: the copy has its own networks (as XFeatDenseDescriptor, XFeatRefiner)
/// and its own copy of the cache of the last three images (pixels and features cloned,
/// nothing shared with the original), so it answers exactly as the original would and
/// continues its network_runs count. One object serves one thread at a time.
class XFeatDenseMatcher {
 public:
  explicit XFeatDenseMatcher(XFeatDenseOptions options, std::optional<XFeatFineOptions> fine = std::nullopt)
      : descriptor_(grid_for(std::move(options), fine.has_value())),
        matcher_(DenseMutualOptions{.normalise = fine.has_value()}) {
    if (fine) refiner_.emplace(std::move(*fine));
  }

  XFeatDenseMatcher(const XFeatDenseMatcher& other)
      : descriptor_(other.descriptor_),
        matcher_(other.matcher_),
        refiner_(other.refiner_),
        born_(other.born_),
        runs_(other.runs_) {
    cache_.reserve(capacity);
    for (const Entry& e : other.cache_) {
      Features f = *e.features;
      f.descriptors = f.descriptors.clone();
      cache_.push_back({e.image.clone(), std::make_shared<const Features>(std::move(f)), e.born});
    }
  }
  XFeatDenseMatcher& operator=(const XFeatDenseMatcher& other) {
    if (this != &other) *this = XFeatDenseMatcher(other);
    return *this;
  }
  XFeatDenseMatcher(XFeatDenseMatcher&&) noexcept = default;
  XFeatDenseMatcher& operator=(XFeatDenseMatcher&&) noexcept = default;
  ~XFeatDenseMatcher() = default;

  [[nodiscard]] Correspondences match_pair(const cv::Mat& a, const cv::Mat& b) {
    // Both lookups before any insertion, so neither image evicts the other; the
    // entries never move (capacity reserved up front; a copied matcher may lack it).
    cache_.reserve(capacity);
    Entry* ea = find(a);
    Entry* eb = find(b);
    if (!ea) ea = insert(a, eb);
    if (!eb) eb = insert(b, ea);
    const std::shared_ptr<const Features> fa = ea->features, fb = eb->features;
    const Matches m = matcher_.match(*fa, *fb);
    Correspondences c;
    c.cells = static_cast<int>(std::max(fa->size(), fb->size()));
    if (refiner_) {
      detail::refine_matches(*refiner_, *fa, *fb, m, offsets_, refined_);
      c.points_a = refined_.points_a;
      c.points_b = refined_.points_b;
      c.confidence = refined_.confidence;
      return c;
    }
    c.points_a.reserve(m.size());
    c.points_b.reserve(m.size());
    c.confidence.reserve(m.size());
    for (const cv::DMatch& d : m) {
      c.points_a.push_back(fa->keypoints[static_cast<std::size_t>(d.queryIdx)].pt);
      c.points_b.push_back(fb->keypoints[static_cast<std::size_t>(d.trainIdx)].pt);
      // The cosine of the two descriptors: 1 - |x - y|^2 / 2.
      c.confidence.push_back(std::clamp(1.0f - 0.5f * d.distance * d.distance, 0.0f, 1.0f));
    }
    return c;
  }

  /// The grid of one image as Features (cached as in match_pair).
  [[nodiscard]] const Features& features(const cv::Mat& image) {
    cache_.reserve(capacity);
    Entry* e = find(image);
    return *(e ? e : insert(image, nullptr))->features;
  }

  /// Images run through the network so far (cache misses).
  [[nodiscard]] std::size_t network_runs() const noexcept { return runs_; }
  [[nodiscard]] const XFeatDenseDescriptor& descriptor() const noexcept { return descriptor_; }
  [[nodiscard]] bool refines() const noexcept { return refiner_.has_value(); }

 private:
  static XFeatDenseOptions grid_for(XFeatDenseOptions o, bool refine) {
    if (refine) o.grid = XFeatGrid::refinable;
    return o;
  }

  struct Entry {
    cv::Mat image;  // a copy: the caller may reuse its buffer
    std::shared_ptr<const Features> features;
    std::uint64_t born = 0;  // insertion order
  };

  // The selector's live images: the key image, the previous frame (eq. 6 makes it the
  // next key image) and the current frame. The oldest insertion that is not the other
  // image of the pair is evicted: the key image, inserted long ago, stays while it is
  // paired, and the two newest frames stay.
  static constexpr std::size_t capacity = 3;

  static bool same_pixels(const cv::Mat& x, const cv::Mat& y) {
    if (x.size() != y.size() || x.type() != y.type()) return false;
    const std::size_t row = static_cast<std::size_t>(x.cols) * x.elemSize();
    for (int r = 0; r < x.rows; ++r)
      if (std::memcmp(x.ptr(r), y.ptr(r), row) != 0) return false;
    return true;
  }

  Entry* find(const cv::Mat& image) {
    detail::check(!image.empty(), "XFeatDenseMatcher: the image is empty (0 x 0)");
    for (Entry& e : cache_)
      if (same_pixels(e.image, image)) return &e;
    return nullptr;
  }

  /// Runs the network on `image` and caches it, never evicting `keep`.
  Entry* insert(const cv::Mat& image, const Entry* keep) {
    Entry fresh{image.clone(), std::make_shared<const Features>(descriptor_.extract(image)), ++born_};
    ++runs_;
    if (cache_.size() < capacity) {
      cache_.push_back(std::move(fresh));
      return &cache_.back();
    }
    Entry* oldest = nullptr;
    for (Entry& e : cache_)
      if (&e != keep && (!oldest || e.born < oldest->born)) oldest = &e;
    *oldest = std::move(fresh);
    return oldest;
  }

  XFeatDenseDescriptor descriptor_;
  DenseMutualMatcher matcher_;
  std::optional<XFeatRefiner> refiner_;
  std::vector<FineOffset> offsets_;  // scratch of the refinement
  RefinedMatches refined_;
  std::vector<Entry> cache_;  // at most `capacity`, reserved: entry addresses stay valid
  std::uint64_t born_ = 0;
  std::size_t runs_ = 0;
};

static_assert(PairMatcher<XFeatDenseMatcher>);

}  // namespace vmap
