#pragma once

// Growing Cell Structures (Fritzke 1994), the network of the GCS localization paper
// (Trujillo-Romero 2024, Algorithm 1; examples/methods.md, sec. 3 step 4 gives the procedure).
// Generic over the scalar, the dimension and the metric: the same structure without
// the pose payload is a general clustering tool.
//
// Topology: a set of K-simplices (K+1 cells each). The edges are exactly the pairs of
// cells that share a simplex, and every cell lies in at least one simplex; these
// invariants (and the rest listed at check_topology) hold after every insertion and
// removal.
//
// Thread-safety: the const members (bmu, k_nearest, accessors, save) may be called from
// several threads at once; train/adapt/load need exclusive access.

#include <vmap/core/error.hpp>
#include <vmap/io/atomic_file.hpp>
#include <vmap/io/binary.hpp>
#include <vmap/som/options.hpp>
#include <vmap/som/results.hpp>

#include <Eigen/Core>

#include <algorithm>
#include <array>
#include <cmath>
#include <concepts>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <limits>
#include <numeric>
#include <random>
#include <set>
#include <string>
#include <utility>
#include <vector>

namespace vmap {

// ---- metrics ------------------------------------------------------------------------

/// `m(a, b)` is a distance (>= 0, 0 for equal vectors) between two vectors of type V.
template <class M, class V>
concept VectorMetric = std::copy_constructible<M>  // held by value
                       && requires(const M& m, const V& a, const V& b) {
                            { m(a, b) } -> std::convertible_to<double>;  // distance, const
                          };

/// ||a - b||_2, the metric of Fritzke's GCS.
struct EuclideanDistance {
  template <class V>
  double operator()(const V& a, const V& b) const {
    return static_cast<double>((a - b).norm());
  }
};

/// ||a - b||_1, e.g. for L1-normalised histograms.
struct ManhattanDistance {
  template <class V>
  double operator()(const V& a, const V& b) const {
    return static_cast<double>((a - b).template lpNorm<1>());
  }
};

static_assert(VectorMetric<EuclideanDistance, Eigen::VectorXf>);
static_assert(VectorMetric<ManhattanDistance, Eigen::VectorXd>);

// ---- options and results ------------------------------------------------------------

/// What happened to the topology; passed to a training observer.
enum class GcsEvent { inserted, removed };

/// A cell and its distance to a query.
struct CellDistance {
  std::size_t cell = 0;
  double distance = 0.0;
};

namespace detail {
inline void validate(const GcsOptions& o, int k) {
  check(std::isfinite(o.eps_b) && o.eps_b > 0.0 && o.eps_b <= 1.0,
        "GcsOptions.eps_b must be in (0, 1], got " + std::to_string(o.eps_b));
  check(std::isfinite(o.eps_n) && o.eps_n > 0.0 && o.eps_n <= 1.0,
        "GcsOptions.eps_n must be in (0, 1], got " + std::to_string(o.eps_n));
  check(std::isfinite(o.alpha) && o.alpha > 0.0 && o.alpha < 1.0,
        "GcsOptions.alpha must be in (0, 1), got " + std::to_string(o.alpha));
  check(o.lambda >= 1, "GcsOptions.lambda must be >= 1, got 0");
  check(std::isfinite(o.eta) && o.eta >= 0.0, "GcsOptions.eta must be a finite number >= 0, got " + std::to_string(o.eta));
  check(o.max_cells >= static_cast<std::size_t>(k) + 1,
        "GcsOptions.max_cells must be >= K + 1 = " + std::to_string(k + 1) + " (one K-simplex), got " +
            std::to_string(o.max_cells));
  check(o.max_epochs >= 1, "GcsOptions.max_epochs must be >= 1, got 0");
}
}  // namespace detail

// ---- the network --------------------------------------------------------------------

template <class Scalar, int Dim = Eigen::Dynamic, int K = 2, class Metric = EuclideanDistance>
  requires std::floating_point<Scalar> && (K >= 1) &&
           VectorMetric<Metric, Eigen::Matrix<Scalar, Dim, 1>>
class GrowingCellStructures {
 public:
  using Vector = Eigen::Matrix<Scalar, Dim, 1>;
  using Simplex = std::array<std::size_t, K + 1>;
  /// Called after every insertion and removal with the event and the cell concerned
  /// (for a removal: its id before it was erased).
  using Observer = std::function<void(GcsEvent, std::size_t)>;

  static constexpr int dimension_at_compile_time = Dim;
  static constexpr int simplex_dimension = K;

  explicit GrowingCellStructures(const GcsOptions& options = {}, Metric metric = {})
      : options_(options), metric_(std::move(metric)) {
    detail::validate(options_, K);
  }

  /// Trains on `data` (each vector of one dimension; with Dim = Dynamic the first
  /// network input fixes it) from a fresh network. Stops after the epoch in which
  /// max_cells cells exist, or after max_epochs epochs.
  GcsTrainStats train(const std::vector<Vector>& data, const Observer& observer = {}) {
    detail::check(data.size() >= static_cast<std::size_t>(K) + 1,
                  "GrowingCellStructures::train: needs at least K + 1 = " + std::to_string(K + 1) +
                      " training vectors, got " + std::to_string(data.size()));
    // Validate everything before touching the network, so a bad set leaves it unchanged.
    const auto dim = data.front().size();
    detail::check(dim > 0, "GrowingCellStructures::train: training vectors are empty");
    for (std::size_t i = 0; i < data.size(); ++i) {
      if (data[i].size() != dim)
        detail::fail("GrowingCellStructures::train: training vector " + std::to_string(i) + " has dimension " +
                     std::to_string(data[i].size()) + ", the first has " + std::to_string(dim));
      if (!data[i].allFinite())
        detail::fail("GrowingCellStructures::train: training vector " + std::to_string(i) + " holds a non-finite value");
    }
    dim_ = static_cast<std::size_t>(dim);
    rng_.seed(options_.seed);
    initialise(data);
    GcsTrainStats stats;
    std::vector<std::size_t> order(data.size());
    std::iota(order.begin(), order.end(), std::size_t{0});
    while (stats.epochs < options_.max_epochs) {
      std::shuffle(order.begin(), order.end(), rng_);
      for (std::size_t i : order) {
        adapt_step(data[i]);
        ++stats.steps;
        if (stats.steps % options_.lambda == 0) {
          if (w_.size() < options_.max_cells) {
            insert_cell();
            ++stats.insertions;
            if (observer) observer(GcsEvent::inserted, w_.size() - 1);
          }
          stats.removals += remove_low_density_cells(observer);
        }
      }
      ++stats.epochs;
      if (w_.size() >= options_.max_cells) break;
    }
    stats.cells = w_.size();
    double q = 0.0;
    for (const auto& x : data) q += bmu(x).distance;
    stats.mean_quantization_error = q / static_cast<double>(data.size());
    return stats;
  }

  /// The best matching unit (winner) of x.
  [[nodiscard]] CellDistance bmu(const Vector& x) const {
    check_trained("bmu");
    check_input(x, "the query vector");
    return nearest(x);
  }

  /// The k cells nearest to x, nearest first (fewer if the network is smaller).
  [[nodiscard]] std::vector<CellDistance> k_nearest(const Vector& x, std::size_t k) const {
    check_trained("k_nearest");
    check_input(x, "the query vector");
    std::vector<CellDistance> all(w_.size());
    for (std::size_t c = 0; c < w_.size(); ++c) all[c] = {c, metric_(x, w_[c])};
    k = std::min(k, all.size());
    std::partial_sort(all.begin(), all.begin() + static_cast<std::ptrdiff_t>(k), all.end(),
                      [](const CellDistance& a, const CellDistance& b) {
                        return a.distance < b.distance || (a.distance == b.distance && a.cell < b.cell);
                      });
    all.resize(k);
    return all;
  }

  [[nodiscard]] std::size_t size() const noexcept { return w_.size(); }
  [[nodiscard]] bool empty() const noexcept { return w_.empty(); }
  [[nodiscard]] std::size_t dimension() const noexcept { return dim_; }
  [[nodiscard]] const std::vector<Vector>& weights() const noexcept { return w_; }
  [[nodiscard]] const std::vector<double>& counters() const noexcept { return tau_; }
  [[nodiscard]] const std::vector<Simplex>& simplices() const noexcept { return simplices_; }
  [[nodiscard]] const std::vector<std::size_t>& neighbours(std::size_t cell) const { return adj_.at(cell); }
  [[nodiscard]] const GcsOptions& options() const noexcept { return options_; }
  [[nodiscard]] const Metric& metric() const noexcept { return metric_; }

  /// Every edge (a, b) with a < b, sorted.
  [[nodiscard]] std::vector<std::pair<std::size_t, std::size_t>> edges() const {
    std::vector<std::pair<std::size_t, std::size_t>> out;
    for (std::size_t a = 0; a < adj_.size(); ++a)
      for (std::size_t b : adj_[a])
        if (a < b) out.emplace_back(a, b);
    return out;
  }

  /// Estimated probability density of each cell relative to the mean: (tau_c / sum tau)
  /// / (F_c / sum F), with F_c = (mean edge length of c)^K the size of its Voronoi
  /// region as Fritzke 1994 estimates it. Cells whose value falls below eta are removed.
  [[nodiscard]] std::vector<double> relative_density() const {
    std::vector<double> out(w_.size(), 0.0);
    const double tau_sum = std::accumulate(tau_.begin(), tau_.end(), 0.0);
    double f_sum = 0.0;
    std::vector<double> f(w_.size());
    for (std::size_t c = 0; c < w_.size(); ++c) f_sum += (f[c] = region_size(c));
    if (tau_sum <= 0.0 || f_sum <= 0.0) return out;
    for (std::size_t c = 0; c < w_.size(); ++c)
      out[c] = f[c] > 0.0 ? (tau_[c] / tau_sum) / (f[c] / f_sum) : std::numeric_limits<double>::infinity();
    return out;
  }

  /// Throws vmap::Error naming the first violated invariant: K+1 distinct valid cells
  /// per simplex, no duplicate simplex, every cell in a simplex, adjacency symmetric
  /// and equal to the pairs that share a simplex, finite weights of the right
  /// dimension, counters finite and >= 0.
  void check_topology() const {
    const std::size_t n = w_.size();
    auto bad = [](const std::string& what) { detail::fail("GCS topology invariant violated: " + what); };
    if (tau_.size() != n || adj_.size() != n) bad("cell arrays differ in length");
    if (n == 0) {
      if (!simplices_.empty()) bad("simplices without cells");
      return;
    }
    if (n < static_cast<std::size_t>(K) + 1) bad("fewer than K + 1 cells");
    if (simplices_.empty()) bad("no simplex");
    std::vector<std::set<std::size_t>> expected(n);
    std::set<Simplex> seen;
    for (const auto& s : simplices_) {
      Simplex sorted = s;
      std::sort(sorted.begin(), sorted.end());
      for (std::size_t i = 0; i < sorted.size(); ++i) {
        if (sorted[i] >= n) bad("simplex refers to cell " + std::to_string(sorted[i]) + " of " + std::to_string(n));
        if (i > 0 && sorted[i] == sorted[i - 1]) bad("simplex repeats cell " + std::to_string(sorted[i]));
      }
      if (!seen.insert(sorted).second) bad("duplicate simplex");
      for (std::size_t a : sorted)
        for (std::size_t b : sorted)
          if (a != b) expected[a].insert(b);
    }
    for (std::size_t c = 0; c < n; ++c) {
      if (expected[c].empty()) bad("cell " + std::to_string(c) + " lies in no simplex");
      const std::set<std::size_t> have(adj_[c].begin(), adj_[c].end());
      if (have.size() != adj_[c].size()) bad("cell " + std::to_string(c) + " lists a neighbour twice");
      if (have != expected[c]) bad("neighbours of cell " + std::to_string(c) + " differ from its simplices");
      if (static_cast<std::size_t>(w_[c].size()) != dim_) bad("cell " + std::to_string(c) + " has the wrong dimension");
      if (!w_[c].allFinite()) bad("cell " + std::to_string(c) + " has a non-finite weight");
      if (!std::isfinite(tau_[c]) || tau_[c] < 0.0) bad("cell " + std::to_string(c) + " has an invalid counter");
    }
  }

  // ---- persistence ----------------------------------------------------------------

  static constexpr std::uint32_t file_version = 1;

  /// The network as bytes, in io/binary.hpp's little-endian encoding (Scalar must be
  /// float or double):
  ///   u8[8] magic "VMAPGCS\n"; u32 version (1); u32 byte-order tag 0x01020304;
  ///   u32 scalar size (4 or 8); u32 K; u64 dimension d;
  ///   f64 eps_b, f64 eps_n, f64 alpha, u64 lambda, f64 eta, u64 max_cells,
  ///   u64 max_epochs, u64 seed (the options);
  ///   u64 cells n; u64 simplices s;
  ///   n x d weights (f32 or f64, cell by cell); n x f64 counters;
  ///   s x (K + 1) u64 cell ids.
  /// Earlier builds wrote the host's byte order and recorded it in the tag: their files
  /// from little-endian machines are these same bytes (so still version 1), and one
  /// from a big-endian machine is refused (its version reads as 0x01000000).
  [[nodiscard]] std::string serialize() const {
    static_assert(std::same_as<Scalar, float> || std::same_as<Scalar, double>,
                  "GCS files store float or double weights");
    detail::BinaryWriter out;
    out.bytes(magic());
    out.u32(file_version);
    out.u32(endian_tag);
    out.u32(sizeof(Scalar));
    out.u32(static_cast<std::uint32_t>(K));
    out.u64(dim_);
    out.f64(options_.eps_b);
    out.f64(options_.eps_n);
    out.f64(options_.alpha);
    out.u64(options_.lambda);
    out.f64(options_.eta);
    out.u64(options_.max_cells);
    out.u64(options_.max_epochs);
    out.u64(options_.seed);
    out.u64(w_.size());
    out.u64(simplices_.size());
    for (const auto& w : w_)
      for (Eigen::Index i = 0; i < w.size(); ++i) {
        if constexpr (std::same_as<Scalar, float>)
          out.f32(w[i]);
        else
          out.f64(w[i]);
      }
    for (double t : tau_) out.f64(t);
    for (const auto& s : simplices_)
      for (std::size_t c : s) out.u64(c);
    return std::move(out).take();
  }

  /// Writes serialize() to `path` atomically.
  void save(const std::filesystem::path& path) const { write_file_atomically(path, serialize()); }

  /// Reads a network written by save(); a file of another version, scalar type, K or
  /// (for a fixed Dim) dimension, or a truncated / corrupt one is a vmap::Error.
  static GrowingCellStructures deserialize(std::string_view bytes, const std::string& what = "GCS data",
                                           Metric metric = {}) {
    static_assert(std::same_as<Scalar, float> || std::same_as<Scalar, double>,
                  "GCS files store float or double weights");
    detail::BinaryReader in(bytes, what);
    if (in.bytes(magic().size(), "the magic") != magic()) in.corrupt("not a vmap GCS file (bad magic)");
    const auto version = in.u32("the version");
    if (version != file_version)
      in.fail_here(version > file_version ? ErrorKind::unsupported_version : ErrorKind::corrupt,
                   "unsupported GCS file version " + std::to_string(version) + " (this build reads " +
                       std::to_string(file_version) + ")");
    if (in.u32("the byte-order tag") != endian_tag)
      in.corrupt("bad byte-order tag (corrupt, or written in another byte order)");
    const auto scalar = in.u32("the scalar size");
    if (scalar != sizeof(Scalar))
      in.corrupt("holds " + std::to_string(scalar * 8) + "-bit weights, this network uses " +
                 std::to_string(sizeof(Scalar) * 8) + "-bit");
    const auto k = in.u32("K");
    if (k != static_cast<std::uint32_t>(K))
      in.corrupt("holds " + std::to_string(k) + "-simplices, this network uses K = " + std::to_string(K));
    const auto dim = in.u64("the dimension");
    if (Dim != Eigen::Dynamic && dim != static_cast<std::uint64_t>(Dim))
      in.corrupt("dimension " + std::to_string(dim) + " does not fit this network (Dim = " + std::to_string(Dim) + ")");
    GcsOptions o;
    o.eps_b = in.f64("eps_b");
    o.eps_n = in.f64("eps_n");
    o.alpha = in.f64("alpha");
    o.lambda = in.u64("lambda");
    o.eta = in.f64("eta");
    o.max_cells = in.u64("max_cells");
    o.max_epochs = in.u64("max_epochs");
    o.seed = in.u64("seed");
    try {
      detail::validate(o, K);
    } catch (const Error& e) {
      in.corrupt(std::string("corrupt options (") + e.what() + ")");
    }
    GrowingCellStructures g(o, std::move(metric));
    const auto n = in.u64("the cell count");
    const auto ns = in.u64("the simplex count");
    // An untrained network has no cells (and, if dynamic, no dimension yet); cells need
    // one. The bound on dim keeps the size of one cell below from overflowing.
    if (n > 0 && dim == 0) in.corrupt("cells of dimension 0");
    if (dim > std::numeric_limits<std::uint64_t>::max() / 4 / sizeof(Scalar))
      in.corrupt("dimension " + std::to_string(dim) + " is impossible");
    in.require_items(n, dim * sizeof(Scalar) + sizeof(double), "the cell count");
    // Bounds on what the file makes us build besides the weights (per-cell vectors,
    // adjacency, the topology check's sets cost ~100 bytes a cell and ~250 a simplex,
    // far more than the 12 and 24 bytes they take in the file): training never makes
    // more cells than max_cells, nor many more simplices than K per cell.
    if (n > o.max_cells)
      in.corrupt("holds " + std::to_string(n) + " cells, more than its max_cells " + std::to_string(o.max_cells));
    if (n > max_load_cells)
      in.corrupt("holds " + std::to_string(n) + " cells, more than the " + std::to_string(max_load_cells) +
                 " a GCS file may hold");
    if (ns > max_simplices_per_cell * n)
      in.corrupt("holds " + std::to_string(ns) + " simplices for " + std::to_string(n) + " cells (at most " +
                 std::to_string(max_simplices_per_cell) + " a cell)");
    g.dim_ = static_cast<std::size_t>(dim);
    g.w_.reserve(static_cast<std::size_t>(n));
    for (std::uint64_t c = 0; c < n; ++c) {
      Vector w(static_cast<Eigen::Index>(dim));
      for (Eigen::Index i = 0; i < w.size(); ++i) {
        if constexpr (std::same_as<Scalar, float>)
          w[i] = in.f32("the weights");
        else
          w[i] = in.f64("the weights");
      }
      g.w_.push_back(std::move(w));
    }
    g.tau_.resize(static_cast<std::size_t>(n));
    for (auto& t : g.tau_) t = in.f64("the counters");
    in.require_items(ns, sizeof(std::uint64_t) * (K + 1), "the simplex count");
    g.simplices_.resize(static_cast<std::size_t>(ns));
    for (auto& s : g.simplices_)
      for (auto& c : s) {
        const auto v = in.u64("the simplices");
        if (v >= n) in.corrupt("corrupt: a simplex refers to cell " + std::to_string(v) + " of " + std::to_string(n));
        c = static_cast<std::size_t>(v);
      }
    in.expect_end("the simplices");
    g.rebuild_adjacency();
    try {
      g.check_topology();
    } catch (const Error& e) {
      detail::fail(ErrorKind::corrupt, what + ": corrupt (" + e.what() + ")");
    }
    return g;
  }

  /// Largest network `deserialize` / `load` accept: 2^20 cells (a map of a building
  /// has hundreds), with at most 64 simplices a cell.
  static constexpr std::uint64_t max_load_cells = std::uint64_t{1} << 20;
  static constexpr std::uint64_t max_simplices_per_cell = 64;

  /// Reads a network written by save(). Errors (vmap::Error naming the file): missing,
  /// a folder or device, unreadable, corrupt, above the limits above.
  static GrowingCellStructures load(const std::filesystem::path& path, Metric metric = {}) {
    return deserialize(read_file(path, default_max_file_bytes, "GCS file"), "GCS file '" + path.string() + "'", std::move(metric));
  }

 private:
  static constexpr std::uint32_t endian_tag = 0x01020304u;
  static std::string_view magic() { return {"VMAPGCS\n", 8}; }

  [[nodiscard]] CellDistance nearest(const Vector& x) const {
    CellDistance best{0, std::numeric_limits<double>::infinity()};
    for (std::size_t c = 0; c < w_.size(); ++c) {
      const double d = metric_(x, w_[c]);
      if (d < best.distance) best = {c, d};
    }
    return best;
  }

  void check_trained(const char* fn) const {
    if (w_.empty()) detail::fail(std::string("GrowingCellStructures::") + fn + ": the network is not trained");
  }

  void check_input(const Vector& x, const std::string& what) const {
    if (static_cast<std::size_t>(x.size()) != dim_)
      detail::fail("GrowingCellStructures: " + what + " has dimension " + std::to_string(x.size()) +
                   ", the network has " + std::to_string(dim_));
    if (!x.allFinite()) detail::fail("GrowingCellStructures: " + what + " holds a non-finite value");
  }

  // Start: K + 1 cells forming one K-simplex, weights drawn from distinct data vectors.
  void initialise(const std::vector<Vector>& data) {
    std::vector<std::size_t> idx(data.size());
    std::iota(idx.begin(), idx.end(), std::size_t{0});
    std::shuffle(idx.begin(), idx.end(), rng_);
    w_.clear();
    tau_.assign(K + 1, 0.0);
    Simplex s{};
    for (int i = 0; i <= K; ++i) {
      w_.push_back(data[idx[static_cast<std::size_t>(i)]]);
      s[static_cast<std::size_t>(i)] = static_cast<std::size_t>(i);
    }
    simplices_.assign(1, s);
    rebuild_adjacency();
  }

  // One adaptation step (Algorithm 1): the winner moves by eps_b, its direct neighbours
  // by eps_n, its signal counter grows by one, and all counters decay by alpha.
  void adapt_step(const Vector& x) {
    const std::size_t s = nearest(x).cell;
    w_[s] += static_cast<Scalar>(options_.eps_b) * (x - w_[s]);
    for (std::size_t nb : adj_[s]) w_[nb] += static_cast<Scalar>(options_.eps_n) * (x - w_[nb]);
    tau_[s] += 1.0;
    const double keep = 1.0 - options_.alpha;
    for (double& t : tau_) t *= keep;
  }

  [[nodiscard]] double mean_edge_length(std::size_t c) const {
    if (adj_[c].empty()) return 0.0;
    double sum = 0.0;
    for (std::size_t nb : adj_[c]) sum += metric_(w_[c], w_[nb]);
    return sum / static_cast<double>(adj_[c].size());
  }

  // Fritzke's estimate of the size of a cell's Voronoi region: the mean edge length to
  // the power of the structure's dimension K (the input dimension of a histogram is in
  // the hundreds, where that power would under- or overflow).
  [[nodiscard]] double region_size(std::size_t c) const { return std::pow(mean_edge_length(c), K); }

  // Every lambda steps: a new cell r halfway between q (largest counter) and f (q's
  // farthest direct neighbour). Each simplex holding the edge q-f is split in two (f
  // replaced by r, and q replaced by r), so r joins q, f and their common simplex
  // neighbours and the structure stays made of K-simplices. Counters are then
  // redistributed by the change of the neighbours' Voronoi regions (paper's steps
  // 17-18): each neighbour c gives r the fraction (F_c_old - F_c_new) / F_c_old of its
  // counter.
  void insert_cell() {
    const auto q = static_cast<std::size_t>(std::max_element(tau_.begin(), tau_.end()) - tau_.begin());
    std::size_t f = adj_[q].front();
    double far = -1.0;
    for (std::size_t nb : adj_[q]) {
      const double d = metric_(w_[q], w_[nb]);
      if (d > far) {
        far = d;
        f = nb;
      }
    }
    const std::size_t r = w_.size();
    std::set<std::size_t> touched{q, f};
    const std::size_t existing = simplices_.size();
    for (std::size_t i = 0; i < existing; ++i) {
      Simplex& s = simplices_[i];
      auto iq = std::find(s.begin(), s.end(), q);
      auto jf = std::find(s.begin(), s.end(), f);
      if (iq == s.end() || jf == s.end()) continue;
      for (std::size_t c : s) touched.insert(c);
      Simplex other = s;
      other[static_cast<std::size_t>(iq - s.begin())] = r;
      *jf = r;
      simplices_.push_back(other);
    }
    std::vector<std::pair<std::size_t, double>> before;
    for (std::size_t c : touched) before.emplace_back(c, region_size(c));
    w_.push_back(Scalar(0.5) * (w_[q] + w_[f]));
    tau_.push_back(0.0);
    rebuild_adjacency();
    for (const auto& [c, f_old] : before) {
      if (f_old <= 0.0) continue;
      const double share = std::clamp((f_old - region_size(c)) / f_old, 0.0, 1.0);
      tau_[r] += share * tau_[c];
      tau_[c] -= share * tau_[c];
    }
  }

  // Removes cells whose relative density is below eta (lowest first, one at a time,
  // re-estimating after each), with the simplices they belong to and any cell left in
  // no simplex. A removal that would leave fewer than K + 1 cells or no simplex is not
  // made.
  std::size_t remove_low_density_cells(const Observer& observer) {
    if (options_.eta <= 0.0) return 0;
    std::size_t removed = 0;
    for (;;) {
      const auto rho = relative_density();
      std::vector<std::size_t> order(w_.size());
      std::iota(order.begin(), order.end(), std::size_t{0});
      std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return rho[a] < rho[b]; });
      std::size_t n = 0;
      for (std::size_t c : order) {
        if (rho[c] >= options_.eta) break;
        if ((n = try_remove(c, observer)) > 0) break;
      }
      if (n == 0) return removed;
      removed += n;
    }
  }

  // Removes cell c if that leaves a valid structure; returns the number of cells removed.
  std::size_t try_remove(std::size_t c, const Observer& observer) {
    std::vector<Simplex> kept;
    for (const auto& s : simplices_)
      if (std::find(s.begin(), s.end(), c) == s.end()) kept.push_back(s);
    std::vector<char> used(w_.size(), 0);
    for (const auto& s : kept)
      for (std::size_t v : s) used[v] = 1;
    const auto survivors = static_cast<std::size_t>(std::count(used.begin(), used.end(), char{1}));
    if (kept.empty() || survivors < static_cast<std::size_t>(K) + 1) return 0;
    simplices_ = std::move(kept);
    // Erase from the highest id down so the ids still to be erased stay valid; the
    // observer hears of the removals once the structure is whole again.
    std::vector<std::size_t> gone;
    for (std::size_t v = w_.size(); v-- > 0;)
      if (!used[v]) {
        erase_cell(v);
        gone.push_back(v);
      }
    rebuild_adjacency();
    if (observer)
      for (std::size_t v : gone) observer(GcsEvent::removed, v);
    return gone.size();
  }

  void erase_cell(std::size_t v) {
    w_.erase(w_.begin() + static_cast<std::ptrdiff_t>(v));
    tau_.erase(tau_.begin() + static_cast<std::ptrdiff_t>(v));
    for (auto& s : simplices_)
      for (auto& c : s)
        if (c > v) --c;
  }

  void rebuild_adjacency() {
    adj_.assign(w_.size(), {});
    for (const auto& s : simplices_)
      for (std::size_t a : s)
        for (std::size_t b : s)
          if (a != b) adj_[a].push_back(b);
    for (auto& a : adj_) {
      std::sort(a.begin(), a.end());
      a.erase(std::unique(a.begin(), a.end()), a.end());
    }
  }

  GcsOptions options_;
  Metric metric_;
  std::size_t dim_ = Dim == Eigen::Dynamic ? 0 : static_cast<std::size_t>(Dim);
  std::vector<Vector> w_;
  std::vector<double> tau_;
  std::vector<Simplex> simplices_;
  std::vector<std::vector<std::size_t>> adj_;
  std::mt19937_64 rng_{1};
};

/// The common instantiations: histograms of images (float, any length) and 2-D points.
using GcsXf = GrowingCellStructures<float>;
using Gcs2d = GrowingCellStructures<double, 2>;

}  // namespace vmap
