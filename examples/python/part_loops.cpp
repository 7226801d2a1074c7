// Loop closure from Python: vmap.detect_loops (one run over a sequence, the run of
// `vmap loops`), vmap.LoopDetector (the same detector fed one frame at a time) and
// vmap.evaluate (precision, recall, recall at 100 % precision and the PR curve against a
// ground-truth matrix or poses, the figures `vmap loops --gt / --gt-poses` prints).

#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <limits>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <utility>
#include <vector>
#include <vmap/hooks/precomputed_detections.hpp>
#include <vmap/io/poses.hpp>
#include <vmap/lcd/evaluation.hpp>
#include <vmap/lcd/loop_detector.hpp>
#include <vmap/lcd/loop_engine.hpp>
#include <vmap/lcd/place_decision.hpp>

#include "bindings.hpp"
#include "common/lcd_run.hpp"
#include "common/policies.hpp"

namespace vmap::python {
namespace {

namespace ex = vmap::examples;

// ---------------------------------------------------------------------------------------
// Arguments

bool is_path(const py::handle& h) { return py::isinstance<py::str>(h) || py::hasattr(h, "__fspath__"); }

std::string path_of(const py::handle& h) { return py::str(py::module_::import("os").attr("fspath")(h)); }

CandidateIndex parse_rank(const std::string& rank) {
  if (rank == "tree") return CandidateIndex::tree;
  if (rank == "tree_ranked") return CandidateIndex::tree_ranked;
  if (rank == "bow") return CandidateIndex::bow;
  if (rank == "all") return CandidateIndex::brute_force;
  fail("rank: unknown '" + rank + "' (choose tree, tree_ranked, bow or all)");
}

/// The name `vmap loops` prints for a candidate source (--rank's values).
std::string rank_name(CandidateIndex c) { return c == CandidateIndex::brute_force ? "all" : std::string(to_string(c)); }

ex::DescriptorChoice descriptor_choice(const std::string& features, int nfeatures, const std::string& model,
                                       const std::string& refine_model) {
  if (nfeatures < 1 || static_cast<unsigned long long>(nfeatures) > ex::max_nfeatures)
    fail("nfeatures must be in [1, " + std::to_string(ex::max_nfeatures) + "], got " + std::to_string(nfeatures));
  return {features, nfeatures, model, refine_model};
}

ex::VocabularyChoice vocabulary_choice(std::size_t words, int depth, std::uint64_t seed) {
  ex::VocabularyChoice v;
  v.words = words;
  v.depth = depth;
  v.seed = seed;
  if (depth < 1 || depth > 16) fail("depth must be in [1, 16], got " + std::to_string(depth));
  if (words < 2) fail("words must be >= 2, got " + std::to_string(words));
  if (v.branching() > BinaryVocabularyTree::max_branching)
    fail("words=" + std::to_string(words) + " with depth=" + std::to_string(depth) + " needs a branching above " +
         std::to_string(BinaryVocabularyTree::max_branching) + "; raise depth or lower words");
  return v;
}

/// The loop engine's options from the keyword arguments, checked as the engine checks
/// them, so a bad value fails before any frame is read.
struct EngineArgs {
  std::size_t window, min_candidates, top_k;
  double min_bow_score;
  std::size_t temporal_consistency, temporal_tolerance;
  double left_ratio, min_confidence;
  int min_inliers;
  double chance_inlier_rate, half_significance;
  int spread_grid;
  double full_spread, ambiguity_ratio, label_min_score;

  [[nodiscard]] LoopOptions options(CandidateIndex index) const {
    LoopOptions o;
    o.labels.min_score = static_cast<float>(label_min_score);
    o.window = window;
    o.min_candidates = min_candidates;
    o.index = index;
    o.top_k = top_k;
    o.min_bow_score = min_bow_score;
    o.temporal_consistency = temporal_consistency;
    o.temporal_tolerance = temporal_tolerance;
    o.left_ratio = left_ratio;
    o.decision.min_confidence = min_confidence;
    o.decision.min_inliers = min_inliers;
    o.decision.chance_inlier_rate = chance_inlier_rate;
    o.decision.half_significance = half_significance;
    o.decision.spread_grid = spread_grid;
    o.decision.full_spread = full_spread;
    o.decision.ambiguity_ratio = ambiguity_ratio;
    const auto in01 = [](double x) { return std::isfinite(x) && x >= 0.0 && x <= 1.0; };
    const auto need = [](bool ok, const std::string& what, double got) {
      if (!ok) fail(what + ", got " + std::string(py::repr(py::float_(got))));
    };
    need(min_candidates >= 1, "min_candidates must be >= 1", static_cast<double>(min_candidates));
    need(top_k >= 1 || !ranks(index), "top_k must be >= 1", static_cast<double>(top_k));
    need(std::isfinite(min_bow_score) && min_bow_score >= 0, "min_bow_score must be finite and >= 0", min_bow_score);
    need(temporal_consistency <= 1000, "temporal_consistency must be <= 1000",
         static_cast<double>(temporal_consistency));
    need(in01(left_ratio), "left_ratio must be in [0, 1]", left_ratio);
    need(in01(min_confidence), "min_confidence must be in [0, 1]", min_confidence);
    need(min_inliers >= 0, "min_inliers must be >= 0", min_inliers);
    need(std::isfinite(chance_inlier_rate) && chance_inlier_rate > 0 && chance_inlier_rate < 1,
         "chance_inlier_rate must be in (0, 1)", chance_inlier_rate);
    need(std::isfinite(half_significance) && half_significance > 0, "half_significance must be > 0", half_significance);
    need(spread_grid >= 1 && spread_grid <= 64, "spread_grid must be in 1..64", spread_grid);
    need(in01(full_spread), "full_spread must be in [0, 1]", full_spread);
    need(in01(ambiguity_ratio), "ambiguity_ratio must be in [0, 1]", ambiguity_ratio);
    need(in01(label_min_score), "label_min_score must be in [0, 1]", label_min_score);
    // The engine's own check as well, so an option it gains is never left unchecked.
    LoopEngine<BruteForceMatcher, FundamentalEstimator>::check_options(o, "LoopOptions");
    return o;
  }
};

/// A number of an index argument that must be a whole number >= 0.
std::size_t whole(const py::object& h, const std::string& what) {
  const double v = py::float_(h);
  if (!std::isfinite(v) || v < 0 || v != std::floor(v) || v > 1e15)
    fail(what + " must be a whole number >= 0, got " + std::string(py::repr(h)));
  return static_cast<std::size_t>(v);
}

/// One frame's detections: rows (label, score, x, y, w, h), a list of tuples or an
/// N x 6 array.
std::vector<Detection> detections_of(const py::handle& rows, const std::string& what) {
  std::vector<Detection> out;
  if (rows.is_none()) return out;
  std::size_t k = 0;
  for (const py::handle row : rows) {
    if (!py::isinstance<py::sequence>(row) && !py::isinstance<py::array>(row))
      fail(what + "[" + std::to_string(k) + "]: a detection is (label, score, x, y, w, h), got " +
           std::string(py::repr(row)));
    const auto r = py::reinterpret_borrow<py::sequence>(row);
    if (py::len(r) != 6)
      fail(what + "[" + std::to_string(k) + "]: a detection is (label, score, x, y, w, h), got " +
           std::to_string(py::len(r)) + " values");
    Detection d;
    const double label = py::float_(r[0]);
    if (label != std::floor(label) || label < 0 || label > std::numeric_limits<int>::max())
      fail(what + "[" + std::to_string(k) + "]: the label must be a class id >= 0, got " + std::string(py::repr(r[0])));
    d.label = static_cast<int>(label);
    d.score = static_cast<float>(py::float_(r[1]));
    d.box = cv::Rect2f(static_cast<float>(py::float_(r[2])), static_cast<float>(py::float_(r[3])),
                       static_cast<float>(py::float_(r[4])), static_cast<float>(py::float_(r[5])));
    out.push_back(d);
    ++k;
  }
  return out;
}

/// `labels` of detect_loops: a detections file, several (pooled), or per-frame detections.
std::optional<PrecomputedDetections> labels_of(const py::object& labels) {
  if (labels.is_none()) return std::nullopt;
  if (is_path(labels)) return ex::load_labels({path_of(labels)});
  if (!py::isinstance<py::sequence>(labels))
    fail("labels: a detections file, a list of them, or one list of (label, score, x, y, w, h) per frame; got " +
         std::string(py::repr(labels)));
  const auto seq = py::reinterpret_borrow<py::sequence>(labels);
  if (py::len(seq) == 0) return std::nullopt;
  if (is_path(seq[0])) {
    std::vector<std::filesystem::path> files;
    for (const py::handle f : seq) {
      if (!is_path(f)) fail("labels: a list of files holds " + std::string(py::repr(f)));
      files.emplace_back(path_of(f));
    }
    return ex::load_labels(files);
  }
  std::vector<std::vector<Detection>> per_frame;
  for (std::size_t k = 0; k < py::len(seq); ++k)
    per_frame.push_back(detections_of(seq[k], "labels[" + std::to_string(k) + "]"));
  return PrecomputedDetections(per_frame);
}

/// progress(stage, done, total), with the GIL, from a thread that released it.
using Progress = std::function<void(const char*, std::size_t, std::size_t)>;

Progress progress_of(const py::object& progress) {
  if (progress.is_none()) return {};
  if (!PyCallable_Check(progress.ptr())) fail("progress must be callable as progress(stage, done, total)");
  return [progress](const char* stage, std::size_t done, std::size_t total) {
    py::gil_scoped_acquire held;
    progress(stage, done, total);
  };
}

// ---------------------------------------------------------------------------------------
// Results

/// One loop `vmap loops` reports (its --json "loops" entries).
struct LoopEdge {
  std::size_t query = 0, match = 0;
  std::string query_name, match_name;
  double query_time = 0.0, match_time = 0.0;
  double confidence = 0.0;
  int inliers = 0, matches = 0;
  double inlier_ratio = 0.0, significance = 0.0, spread = 0.0, bow_score = 0.0;
};

/// What detect_loops returns: the run, and the frames' names and times.
struct PyLoopRun {
  ex::LoopRun run;
  std::vector<std::string> names;
  std::vector<double> times;
  std::size_t skipped = 0;
  LoopOptions options;
  std::vector<LoopEdge> loops;
};

std::vector<LoopEdge> loop_edges(const ex::LoopRun& run, const std::vector<std::string>& names,
                                 const std::vector<double>& times) {
  std::vector<LoopEdge> out;
  for (const LoopResult& r : run.results) {
    if (!r.loop()) continue;
    const std::size_t q = r.frame, m = *r.best;
    out.push_back({q, m, names[q], names[m], times[q], times[m], r.confidence, r.evidence.inliers, r.evidence.matches,
                   r.evidence.inlier_ratio, r.evidence.significance, r.evidence.spread, r.evidence.bow_score});
  }
  return out;
}

/// The evaluation's view of a run: N x 3 float64 (query, match or -1, score).
py::array_t<double> score_array(const std::vector<LoopScore>& scores) {
  py::array_t<double> out({static_cast<py::ssize_t>(scores.size()), py::ssize_t{3}});
  auto v = out.mutable_unchecked<2>();
  for (std::size_t i = 0; i < scores.size(); ++i) {
    const auto r = static_cast<py::ssize_t>(i);
    v(r, 0) = static_cast<double>(scores[i].query);
    v(r, 1) = scores[i].match ? static_cast<double>(*scores[i].match) : -1.0;
    v(r, 2) = scores[i].score;
  }
  return out;
}

// ---------------------------------------------------------------------------------------
// detect_loops

PyLoopRun detect_loops(const py::object& source, const std::string& features, int nfeatures, const std::string& model,
                       const std::string& refine_model, const py::object& labels,
                       const std::optional<std::string>& rank, const py::object& vocabulary, std::size_t words,
                       int depth, std::uint64_t seed, const EngineArgs& engine, double min_influence,
                       double max_influence, const std::optional<std::vector<int>>& label_order, std::size_t sample,
                       double time_offset, const py::object& progress) {
  ex::LoopRunConfig c;
  c.descriptor = descriptor_choice(features, nfeatures, model, refine_model);
  c.influence = {.min_influence = min_influence, .max_influence = max_influence};
  detail::check_influence_options(c.influence);
  c.label_order = label_order.value_or(std::vector<int>{});
  c.sample = sample;
  const std::optional<PrecomputedDetections> detections = labels_of(labels);
  c.detector = engine.options(parse_rank(rank.value_or(detections ? "tree_ranked" : "bow")));
  if (uses_labels(c.detector.index) && !detections)
    fail("rank=" + rank_name(c.detector.index) +
         " needs labels (a detections file or per-frame detections); rank='bow' or 'all' need none");
  const ex::VocabularyChoice words_choice = vocabulary_choice(words, depth, seed);
  std::optional<std::string> vocabulary_file;
  if (!vocabulary.is_none()) {
    if (!is_path(vocabulary))
      fail("vocabulary: a vocabulary file (of `vmap vocabulary`), got " + std::string(py::repr(vocabulary)));
    vocabulary_file = path_of(vocabulary);
    if (!std::filesystem::is_regular_file(*vocabulary_file))
      fail("vocabulary: '" + *vocabulary_file + "' is not a file");
  }
  const Progress report = progress_of(progress);

  PyLoopRun out;
  out.options = c.detector;
  ex::SequenceFeatures seq;
  // A path is read by the command line's own frame source; a list holds images (read in
  // place: `held` keeps each array alive while the GIL is released, whatever happens to
  // the list meanwhile) or Features already extracted.
  std::vector<cv::Mat> images;
  std::vector<py::object> held;
  const bool from_path = is_path(source);
  if (from_path) {
    c.input = path_of(source);
  } else {
    if (!py::isinstance<py::sequence>(source))
      fail("source: a video, an image folder, a list file or rgb.txt, or a list of images or Features; got " +
           std::string(py::repr(source)));
    const auto seq_in = py::reinterpret_borrow<py::sequence>(source);
    c.input = "<list of " + std::to_string(py::len(seq_in)) + " frames>";
    for (std::size_t k = 0; k < py::len(seq_in); ++k) {
      const py::object item = seq_in[k];
      if (py::isinstance<Features>(item)) {
        seq.frames.push_back(item.cast<const Features&>());
      } else if (py::isinstance<py::array>(item)) {
        images.push_back(image_view(item.cast<py::array>(), "source[" + std::to_string(k) + "]"));
        held.push_back(item);
      } else {
        fail("source[" + std::to_string(k) + "]: an image (NumPy array) or vmap.Features, got " +
             std::string(py::repr(item)));
      }
      seq.names.push_back(std::to_string(k));
      seq.times.push_back(static_cast<double>(k));
    }
    if (!images.empty() && !seq.frames.empty()) fail("source: give images or Features, not both");
    if (py::len(seq_in) == 0) fail("source: an empty list of frames");
  }

  {
    py::gil_scoped_release unlocked;
    if (from_path) {
      seq = ex::extract_features(
          c.input, c.descriptor,
          [&](std::size_t done, std::size_t total) {
            if (report) report("features", done, total);
          },
          time_offset);
    } else if (!images.empty()) {
      const auto t0 = std::chrono::steady_clock::now();
      ex::with_descriptor(c.descriptor, [&](auto descriptor) {
        for (const cv::Mat& image : images) {
          seq.frames.push_back(descriptor.extract(image));
          if (report) report("features", seq.frames.size(), images.size());
        }
      });
      seq.seconds = ex::seconds_since(t0);
    }
    if (seq.frames.empty()) fail("source: no frames to detect loops in ('" + c.input.string() + "')");
    if (seq.skipped > 0 && detections)
      fail(std::to_string(seq.skipped) + " frame(s) of '" + c.input.string() +
           "' could not be read; the labels are per frame, so they would be shifted");
    std::shared_ptr<const AnyVocabulary> words_tree;
    if (ranks(c.detector.index)) {
      if (vocabulary_file) {
        words_tree = std::make_shared<const AnyVocabulary>(AnyVocabulary::load(*vocabulary_file));
      } else {
        if (report) report("vocabulary", 0, 1);
        words_tree = std::make_shared<const AnyVocabulary>(ex::learn_vocabulary(seq.frames, words_choice));
        if (report) report("vocabulary", 1, 1);
      }
    }
    const std::size_t total = seq.frames.size();
    out.run =
        ex::run_loops(c, seq, detections ? *detections : PrecomputedDetections{}, words_tree, [&](const LoopResult& r) {
          if (report) report("loops", r.frame + 1, total);
        });
  }
  out.names = std::move(seq.names);
  out.times = std::move(seq.times);
  out.skipped = seq.skipped;
  out.loops = loop_edges(out.run, out.names, out.times);
  return out;
}

// ---------------------------------------------------------------------------------------
// LoopDetector, one frame at a time

/// The detector behind one type whatever the descriptor (whose matcher and estimator
/// are chosen with it, as run_loops chooses them).
class DetectorBase {
 public:
  virtual ~DetectorBase() = default;
  virtual LoopResult add(Features f, const std::vector<Detection>& detections) = 0;
  virtual LoopResult push(const cv::Mat& image, const std::vector<Detection>& detections) = 0;
  [[nodiscard]] virtual std::size_t frames() const = 0;
  [[nodiscard]] virtual std::size_t verifications() const = 0;
  [[nodiscard]] virtual bool stationary() const = 0;
  [[nodiscard]] virtual std::size_t memory_bytes() const = 0;
};

template <class D>
auto matcher_of(const D& d) {
  return ex::matcher_for(d);
}

template <class D>
auto estimator_of(const D& d, const ex::DescriptorChoice& choice) {
  return ex::estimator_for(d, choice, FundamentalEstimator(ex::LoopRunConfig{}.estimator));
}

template <class D>
class DetectorModel final : public DetectorBase {
 public:
  using Detector = LoopDetector<D, decltype(matcher_of(std::declval<const D&>())),
                                decltype(estimator_of(std::declval<const D&>(), ex::DescriptorChoice{}))>;

  DetectorModel(D descriptor, const ex::DescriptorChoice& choice, LabelSchema schema, const LoopOptions& options,
                const std::shared_ptr<const AnyVocabulary>& vocabulary)
      : detector_(make(std::move(descriptor), choice, std::move(schema), options, vocabulary)) {}

  LoopResult add(Features f, const std::vector<Detection>& detections) override {
    return detector_.add(std::move(f), detections);
  }
  LoopResult push(const cv::Mat& image, const std::vector<Detection>& detections) override {
    return detector_.push(image, detections);
  }
  [[nodiscard]] std::size_t frames() const override { return detector_.frames(); }
  [[nodiscard]] std::size_t verifications() const override { return detector_.verifications(); }
  [[nodiscard]] bool stationary() const override { return detector_.stationary(); }
  [[nodiscard]] std::size_t memory_bytes() const override { return detector_.memory_bytes(); }

 private:
  // The matcher and estimator are made from the descriptor before it moves into the
  // detector: a descriptor need only be movable.
  static Detector make(D descriptor, const ex::DescriptorChoice& choice, LabelSchema schema, const LoopOptions& options,
                       const std::shared_ptr<const AnyVocabulary>& vocabulary) {
    auto matcher = matcher_of(descriptor);
    auto estimator = estimator_of(descriptor, choice);
    return Detector(std::move(schema), std::move(descriptor), std::move(matcher), std::move(estimator), options,
                    PlaceRanker(vocabulary, vocabulary ? vocabulary->scoring() : BowScoring::l1));
  }

  Detector detector_;
};

class PyLoopDetector {
 public:
  PyLoopDetector(const std::string& features, int nfeatures, const std::string& model, const std::string& refine_model,
                 const py::object& vocabulary, std::size_t words, int depth, std::uint64_t seed,
                 const std::optional<std::vector<int>>& label_order, const std::optional<std::string>& rank,
                 const EngineArgs& engine) {
    choice_ = descriptor_choice(features, nfeatures, model, refine_model);
    const ex::VocabularyChoice words_choice = vocabulary_choice(words, depth, seed);
    std::shared_ptr<const AnyVocabulary> words_tree;
    std::vector<Features> learn_from;
    if (!vocabulary.is_none()) {
      if (is_path(vocabulary)) {
        words_tree = std::make_shared<const AnyVocabulary>(AnyVocabulary::load(path_of(vocabulary)));
      } else {
        for (const py::handle f : vocabulary) {
          if (!py::isinstance<Features>(f))
            fail("vocabulary: a vocabulary file or a list of vmap.Features to learn one from; the list holds " +
                 std::string(py::repr(f)));
          learn_from.push_back(f.cast<const Features&>());
        }
        py::gil_scoped_release unlocked;
        words_tree = std::make_shared<const AnyVocabulary>(ex::learn_vocabulary(learn_from, words_choice));
      }
    }
    const bool have_labels = label_order && !label_order->empty();
    const std::string default_rank =
        words_tree ? (have_labels ? "tree_ranked" : "bow") : (have_labels ? "tree" : "all");
    const LoopOptions options = engine.options(parse_rank(rank.value_or(default_rank)));
    if (uses_labels(options.index) && !have_labels)
      fail("rank=" + rank_name(options.index) + " needs label_order (the label ids of the tree, large objects first)");
    if (ranks(options.index) && !words_tree)
      fail("rank=" + rank_name(options.index) +
           " ranks by bag of words: give vocabulary (a file, or a list of Features to learn one from)");
    rank_ = rank_name(options.index);
    LabelSchema schema(have_labels ? *label_order : std::vector<int>{});
    detector_ = ex::with_descriptor(choice_, [&](auto descriptor) -> std::unique_ptr<DetectorBase> {
      return std::make_unique<DetectorModel<decltype(descriptor)>>(std::move(descriptor), choice_, std::move(schema),
                                                                   options, words_tree);
    });
    options_ = options;
  }

  LoopResult add(const py::object& frame, const py::object& detections) {
    const std::vector<Detection> found = detections_of(detections, "detections");
    // The GIL is released for the work, so two Python threads could reach one detector;
    // the mutex keeps its frames in order (taken after the GIL is let go: no deadlock).
    if (py::isinstance<Features>(frame)) {
      Features f = frame.cast<const Features&>();
      py::gil_scoped_release unlocked;
      const std::lock_guard<std::mutex> one_at_a_time(mutex_);
      return detector_->add(std::move(f), found);
    }
    if (!py::isinstance<py::array>(frame))
      fail("add: an image (NumPy array) or vmap.Features, got " + std::string(py::repr(frame)));
    const cv::Mat view = image_view(frame.cast<py::array>(), "image");
    py::gil_scoped_release unlocked;
    const std::lock_guard<std::mutex> one_at_a_time(mutex_);
    return detector_->push(view, found);
  }

  // Read under the mutex: another thread may be adding a frame (without the GIL).
  template <class F>
  auto read(F f) const {
    const std::lock_guard<std::mutex> one_at_a_time(mutex_);
    return f(static_cast<const DetectorBase&>(*detector_));
  }
  [[nodiscard]] const LoopOptions& options() const noexcept { return options_; }
  [[nodiscard]] const std::string& rank() const noexcept { return rank_; }
  [[nodiscard]] const ex::DescriptorChoice& choice() const noexcept { return choice_; }

 private:
  ex::DescriptorChoice choice_;
  LoopOptions options_;
  std::string rank_;
  std::unique_ptr<DetectorBase> detector_;
  mutable std::mutex mutex_;
};

// ---------------------------------------------------------------------------------------
// evaluate

/// A ground-truth matrix from `ground_truth`: a 0/1 file, or an N x N bool / integer array.
LoopGroundTruth ground_truth_of(const py::object& ground_truth) {
  if (is_path(ground_truth)) return LoopGroundTruth::load(path_of(ground_truth));
  if (!py::isinstance<py::array>(ground_truth) && !py::isinstance<py::sequence>(ground_truth))
    fail("ground_truth: a 0/1 matrix file or an N x N bool/uint8 array, got " + std::string(py::repr(ground_truth)));
  const auto a = py::array::ensure(ground_truth);
  if (!a) fail("ground_truth: not convertible to an array");
  const char kind = a.dtype().kind();
  if (kind != 'b' && kind != 'u' && kind != 'i')
    fail("ground_truth: a " + std::string(py::str(py::handle(a.dtype()))) +
         " array; give a bool or uint8 0/1 matrix (row = query frame, column = the frame it closes a loop with)");
  if (a.ndim() != 2 || a.shape(0) != a.shape(1))
    fail("ground_truth: an array of shape " + std::string(py::str(a.attr("shape"))) +
         "; the ground truth is a square N x N matrix over the N frames (row = query frame)");
  const auto n = static_cast<std::size_t>(a.shape(0));
  if (n > LoopGroundTruth::max_frames)
    fail("ground_truth: " + std::to_string(n) + " frames exceed the limit of " +
         std::to_string(LoopGroundTruth::max_frames));
  // Any bool or integer dtype, read as int64 (0/1 checked cell by cell).
  const auto cells = py::array_t<std::int64_t, py::array::c_style | py::array::forcecast>::ensure(a);
  const auto v = cells.unchecked<2>();
  LoopGroundTruth gt(n);
  for (py::ssize_t q = 0; q < v.shape(0); ++q)
    for (py::ssize_t j = 0; j < v.shape(1); ++j) {
      const std::int64_t x = v(q, j);
      if (x != 0 && x != 1)
        fail("ground_truth: cell (" + std::to_string(q) + ", " + std::to_string(j) + ") is " + std::to_string(x) +
             "; values must be 0 or 1");
      gt.set(static_cast<std::size_t>(q), static_cast<std::size_t>(j), x == 1);
    }
  return gt;
}

/// Poses from an N x 3 (positions: distance only) or N x 7 (x y z qx qy qz qw, TUM's
/// order) array.
std::vector<CameraPose> poses_of_array(const py::object& poses) {
  const auto a = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(poses);
  if (!a) fail("poses: not convertible to a float array, got " + std::string(py::repr(poses)));
  if (a.ndim() != 2 || (a.shape(1) != 3 && a.shape(1) != 7))
    fail("poses: an array of shape " + std::string(py::str(a.attr("shape"))) +
         "; give N x 3 positions (distance only) or N x 7 (x, y, z, qx, qy, qz, qw)");
  const auto v = a.unchecked<2>();
  std::vector<CameraPose> out(static_cast<std::size_t>(v.shape(0)));
  for (py::ssize_t k = 0; k < v.shape(0); ++k) {
    for (py::ssize_t c = 0; c < v.shape(1); ++c)
      if (!std::isfinite(v(k, c))) fail("poses: row " + std::to_string(k) + " holds a non-finite value");
    CameraPose& p = out[static_cast<std::size_t>(k)];
    p.timestamp = static_cast<double>(k);
    p.position = {v(k, 0), v(k, 1), v(k, 2)};
    // Without orientations every viewing direction is the same, so the angle test passes.
    if (v.shape(1) == 7) p.rotation = rotation_from_quaternion(v(k, 3), v(k, 4), v(k, 5), v(k, 6));
  }
  return out;
}

/// The evaluation of one run (the figures `vmap loops` prints with a ground truth).
struct Evaluation {
  ex::LoopSummary summary;
  double threshold = 0.5;
  LoopGroundTruth gt;
};

/// Scores from `loops`: rows (query, match, score), match None or negative for a query
/// without a candidate.
std::vector<LoopScore> scores_of(const py::object& loops) {
  std::vector<LoopScore> out;
  std::size_t k = 0;
  for (const py::handle row : loops) {
    const std::string what = "loops[" + std::to_string(k++) + "]";
    if (!py::isinstance<py::sequence>(row) && !py::isinstance<py::array>(row))
      fail(what + ": a row is (query, match, score), got " + std::string(py::repr(row)));
    const auto r = py::reinterpret_borrow<py::sequence>(row);
    if (py::len(r) != 3) fail(what + ": a row is (query, match, score), got " + std::to_string(py::len(r)) + " values");
    LoopScore s;
    s.query = whole(r[0], what + " query");
    const py::object match = r[1];
    if (!match.is_none() && py::float_(match).cast<double>() >= 0) s.match = whole(match, what + " match");
    s.score = py::float_(r[2]);
    out.push_back(s);
  }
  return out;
}

Evaluation evaluate(const py::object& loops, const py::object& ground_truth, const py::object& poses,
                    double max_distance, double max_angle, std::optional<std::size_t> window,
                    std::optional<double> min_confidence) {
  if (ground_truth.is_none() == poses.is_none())
    fail("evaluate: give one of ground_truth (an N x N 0/1 matrix or its file) and poses");
  if (!std::isfinite(max_distance) || max_distance <= 0) fail("max_distance must be finite and > 0");
  if (!std::isfinite(max_angle) || max_angle <= 0 || max_angle > 180) fail("max_angle must be in (0, 180]");
  const PyLoopRun* run = py::isinstance<PyLoopRun>(loops) ? &loops.cast<const PyLoopRun&>() : nullptr;
  Evaluation e;
  e.threshold =
      min_confidence.value_or(run ? run->options.decision.min_confidence : PlaceDecisionOptions{}.min_confidence);
  if (!std::isfinite(e.threshold)) fail("min_confidence must be finite");
  if (run && run->skipped > 0)
    fail(std::to_string(run->skipped) +
         " frame(s) of the run could not be read; the ground truth is per frame, so the evaluation would be shifted");
  const std::size_t gap = window.value_or(run ? run->options.window : LoopOptions{}.window);
  if (!ground_truth.is_none()) {
    e.gt = ground_truth_of(ground_truth);
  } else if (is_path(poses)) {
    // One pose per frame: by order when the counts agree, else the nearest in time within
    // 50 ms, as `vmap loops --gt-poses` associates them.
    const std::string file = path_of(poses);
    std::vector<CameraPose> all = load_camera_poses(file);
    if (run) all = poses_for_frames(all, run->times, file, 0.05);
    e.gt = ground_truth_from_poses(all, {.max_distance = max_distance, .max_angle_deg = max_angle, .window = gap});
  } else {
    e.gt = ground_truth_from_poses(poses_of_array(poses),
                                   {.max_distance = max_distance, .max_angle_deg = max_angle, .window = gap});
  }
  if (run) {
    if (e.gt.frames() != run->run.results.size())
      fail(std::string(ground_truth.is_none() ? "poses" : "ground_truth") + ": covers " +
           std::to_string(e.gt.frames()) + " frames but the run has " + std::to_string(run->run.results.size()));
    e.summary = ex::summarize(run->run, e.gt, e.threshold);
    return e;
  }
  const std::vector<LoopScore> scores = scores_of(loops);
  e.summary.frames = e.gt.frames();
  e.summary.loops_gt = e.gt.loop_frames();
  e.summary.at_decision = evaluate_loops(scores, e.gt, e.threshold);
  e.summary.curve = precision_recall_curve(scores, e.gt);
  e.summary.at_full_precision = recall_at_full_precision(e.summary.curve);
  return e;
}

// ---------------------------------------------------------------------------------------
// Bindings

py::object optional_index(const std::optional<std::size_t>& i) { return i ? py::cast(*i) : py::none(); }

void bind_results(py::module_& m) {
  py::class_<LoopEdge>(m, "Loop", "One loop found: query frame -> matched (older) frame, with its evidence.")
      .def_readonly("query", &LoopEdge::query, "index of the query frame")
      .def_readonly("match", &LoopEdge::match, "index of the older frame it closes a loop with")
      .def_readonly("query_name", &LoopEdge::query_name, "the query frame's file name (its index for a list)")
      .def_readonly("match_name", &LoopEdge::match_name)
      .def_readonly("query_time", &LoopEdge::query_time, "the query frame's time, seconds")
      .def_readonly("match_time", &LoopEdge::match_time)
      .def_readonly("confidence", &LoopEdge::confidence,
                    "in [0, 1]: 1 - 2^(-significance / half_significance), "
                    "scaled down when the inliers are bunched")
      .def_readonly("inliers", &LoopEdge::inliers, "matches the geometric model explains")
      .def_readonly("matches", &LoopEdge::matches, "tentative correspondences given to the estimator")
      .def_readonly("inlier_ratio", &LoopEdge::inlier_ratio, "inliers / matches")
      .def_readonly("significance", &LoopEdge::significance, "-log10 P(at least `inliers` of `matches` fit by chance)")
      .def_readonly("spread", &LoopEdge::spread, "fraction of grid cells with an inlier, the smaller view")
      .def_readonly("bow_score", &LoopEdge::bow_score, "the match's bag-of-words score (0 when not ranked)")
      .def("__repr__", [](const LoopEdge& l) {
        char buf[200];
        std::snprintf(buf, sizeof buf, "<vmap.Loop %zu -> %zu confidence %.3f inliers %d of %d bow %.3f>", l.query,
                      l.match, l.confidence, l.inliers, l.matches, l.bow_score);
        return std::string(buf);
      });

  py::class_<LoopResult>(m, "LoopDecision",
                         "The loop engine's answer for one frame: the status (accepted, unknown place, ambiguous, too\n"
                         "little evidence, not a revisit), why, the confidence and the best verified frame.")
      .def_readonly("frame", &LoopResult::frame, "index of the frame")
      .def_property_readonly("loop", &LoopResult::loop, "True when a loop was accepted")
      .def_property_readonly(
          "status", [](const LoopResult& r) { return std::string(to_string(r.status)); },
          "accepted, unknown place, ambiguous, too little evidence or not a revisit")
      .def_readonly("reason", &LoopResult::reason, "why, in words (e.g. 'confidence 0.31 < 0.50')")
      .def_readonly("confidence", &LoopResult::confidence, "of the best place, in [0, 1]")
      .def_property_readonly(
          "best", [](const LoopResult& r) { return optional_index(r.best); },
          "the best place's frame (verified), or None")
      .def_property_readonly(
          "second", [](const LoopResult& r) { return optional_index(r.second); },
          "the best other place, if verified, or None")
      .def_readonly("second_confidence", &LoopResult::second_confidence)
      .def_property_readonly(
          "inliers", [](const LoopResult& r) { return r.evidence.inliers; }, "of the best place")
      .def_property_readonly(
          "matches", [](const LoopResult& r) { return r.evidence.matches; }, "of the best place")
      .def_property_readonly("inlier_ratio", [](const LoopResult& r) { return r.evidence.inlier_ratio; })
      .def_property_readonly("significance", [](const LoopResult& r) { return r.evidence.significance; })
      .def_property_readonly("spread", [](const LoopResult& r) { return r.evidence.spread; })
      .def_property_readonly("bow_score", [](const LoopResult& r) { return r.evidence.bow_score; })
      .def_readonly("candidates", &LoopResult::candidates, "frames the candidate source proposed")
      .def_readonly("verifications", &LoopResult::verifications)
      .def_readonly("failed_verifications", &LoopResult::failed_verifications)
      .def_readonly("consistent_queries", &LoopResult::consistent_queries,
                    "earlier queries that agreed (temporal consistency)")
      .def_property_readonly(
          "labels", [](const LoopResult& r) { return std::vector<int>(r.labels.begin(), r.labels.end()); },
          "the frame's label vector (eq. 3-4; empty without labels)")
      .def_property_readonly(
          "considered",
          [](const LoopResult& r) {
            py::list out;
            for (const PlaceCandidate& c : r.considered)
              out.append(
                  py::make_tuple(c.frame, c.bow_score, c.inliers, c.confidence, std::string(to_string(c.stage))));
            return out;
          },
          "each candidate that reached ranking or verification: (frame, bow_score, inliers, confidence, stage)")
      .def_readonly("rank_ms", &LoopResult::rank_ms, "bag of words + ranking")
      .def_readonly("verify_ms", &LoopResult::verify_ms, "matching + verification")
      .def_readonly("decide_ms", &LoopResult::decide_ms, "evidence, revisit rule and decision")
      .def("__repr__", [](const LoopResult& r) {
        return "<vmap.LoopDecision frame " + std::to_string(r.frame) + ": " + std::string(to_string(r.status)) + " (" +
               r.reason + ")" + (r.best ? ", best " + std::to_string(*r.best) : std::string()) + ">";
      });

  py::class_<PyLoopRun>(m, "LoopRun",
                        "The result of vmap.detect_loops: the loops, every frame's decision and the run's figures.")
      .def_readonly("loops", &PyLoopRun::loops, "the accepted loops (vmap.Loop), in frame order")
      .def_property_readonly(
          "decisions", [](const PyLoopRun& r) { return r.run.results; }, "one vmap.LoopDecision per frame")
      .def_property_readonly("frames", [](const PyLoopRun& r) { return r.run.results.size(); })
      .def_readonly("names", &PyLoopRun::names, "per frame: its file name (its index for a list)")
      .def_readonly("times", &PyLoopRun::times, "per frame: its time in seconds")
      .def_readonly("skipped_frames", &PyLoopRun::skipped, "unreadable frames (not in the run)")
      .def_property_readonly(
          "rank", [](const PyLoopRun& r) { return rank_name(r.options.index); },
          "the candidate source: tree, tree_ranked, bow or all")
      .def_property_readonly("min_confidence", [](const PyLoopRun& r) { return r.options.decision.min_confidence; })
      .def_property_readonly("window", [](const PyLoopRun& r) { return r.options.window; })
      .def_property_readonly("verifications", [](const PyLoopRun& r) { return r.run.verifications; })
      .def_property_readonly(
          "stationary", [](const PyLoopRun& r) { return r.run.stationary; },
          "the camera never left its place: no frame is a revisit")
      .def_property_readonly(
          "seconds", [](const PyLoopRun& r) { return r.run.seconds; },
          "feature extraction + the detector over the sequence")
      .def_property_readonly(
          "labels_kept", [](const PyLoopRun& r) { return r.run.schema.labels(); },
          "the label tree's labels, large objects first")
      .def_property_readonly(
          "scores", [](const PyLoopRun& r) { return score_array(r.run.scores()); },
          "the evaluation's view, N x 3 float64: query, best match (-1: none), score (the confidence\n"
          "of the decisions the threshold alone decides, accepted or unknown place; 0 otherwise)")
      .def("__len__", [](const PyLoopRun& r) { return r.loops.size(); })
      .def("__repr__", [](const PyLoopRun& r) {
        return "<vmap.LoopRun " + std::to_string(r.run.results.size()) + " frames, " + std::to_string(r.loops.size()) +
               " loops, rank " + rank_name(r.options.index) + ">";
      });

  py::class_<Evaluation>(
      m, "Evaluation",
      "Precision and recall of loop closure against ground truth (lcd/evaluation.hpp): each query\n"
      "proposes its best candidate; at threshold t a query scoring >= t is a detection, true when the\n"
      "ground truth marks (query, candidate). Positives are the query frames with a ground-truth loop.")
      .def_property_readonly(
          "precision", [](const Evaluation& e) { return e.summary.at_decision.precision; },
          "TP / (TP + FP) at `threshold` (1 when nothing is detected)")
      .def_property_readonly(
          "recall", [](const Evaluation& e) { return e.summary.at_decision.recall; },
          "TP / positives at `threshold` (0 when the ground truth has no loop)")
      .def_property_readonly("true_positives", [](const Evaluation& e) { return e.summary.at_decision.true_positives; })
      .def_property_readonly("false_positives",
                             [](const Evaluation& e) { return e.summary.at_decision.false_positives; })
      .def_property_readonly("false_negatives",
                             [](const Evaluation& e) { return e.summary.at_decision.false_negatives; })
      .def_property_readonly(
          "positives", [](const Evaluation& e) { return e.summary.loops_gt; }, "query frames with a ground-truth loop")
      .def_property_readonly("frames", [](const Evaluation& e) { return e.gt.frames(); })
      .def_readonly("threshold", &Evaluation::threshold, "the decision threshold precision and recall are taken at")
      .def_property_readonly(
          "recall_at_100_precision", [](const Evaluation& e) { return e.summary.at_full_precision.recall; },
          "the best recall among the curve's points without a false positive")
      .def_property_readonly(
          "threshold_at_100_precision",
          [](const Evaluation& e) -> py::object {
            if (e.summary.at_full_precision.true_positives == 0) return py::none();
            return py::float_(e.summary.at_full_precision.threshold);
          },
          "the lowest threshold that reaches recall_at_100_precision (None when every point has a false positive)")
      .def_property_readonly(
          "curve",
          [](const Evaluation& e) {
            const auto& c = e.summary.curve;
            py::array_t<double> out({static_cast<py::ssize_t>(c.size()), py::ssize_t{5}});
            auto v = out.mutable_unchecked<2>();
            for (std::size_t i = 0; i < c.size(); ++i) {
              const auto r = static_cast<py::ssize_t>(i);
              v(r, 0) = c[i].threshold;
              v(r, 1) = c[i].precision;
              v(r, 2) = c[i].recall;
              v(r, 3) = static_cast<double>(c[i].true_positives);
              v(r, 4) = static_cast<double>(c[i].false_positives);
            }
            return out;
          },
          "the PR curve, K x 5 float64: threshold, precision, recall, true positives, false positives; one row per\n"
          "distinct score of the queries that propose a loop, from the highest threshold to the lowest")
      .def_property_readonly(
          "ground_truth",
          [](const Evaluation& e) {
            const auto n = static_cast<py::ssize_t>(e.gt.frames());
            py::array_t<bool> out({n, n});
            auto v = out.mutable_unchecked<2>();
            for (py::ssize_t q = 0; q < n; ++q)
              for (py::ssize_t j = 0; j < n; ++j)
                v(q, j) = e.gt(static_cast<std::size_t>(q), static_cast<std::size_t>(j));
            return out;
          },
          "the N x N bool ground-truth matrix evaluated against (derived from the poses when given)")
      .def("__repr__", [](const Evaluation& e) {
        char buf[200];
        std::snprintf(buf, sizeof buf,
                      "<vmap.Evaluation precision %.3f recall %.3f recall@100%%P %.3f (TP %zu, FP %zu, %zu positives)>",
                      e.summary.at_decision.precision, e.summary.at_decision.recall, e.summary.at_full_precision.recall,
                      e.summary.at_decision.true_positives, e.summary.at_decision.false_positives, e.summary.loops_gt);
        return std::string(buf);
      });
}

constexpr const char* detect_loops_doc =
    "Loop closure over a sequence, as `vmap loops` runs it: the features of every frame, the labels' tree (from\n"
    "`labels`), a vocabulary (a file, else learned on the sequence itself) for the ranked candidate sources, then\n"
    "the loop detector over every frame. Returns a vmap.LoopRun (the loops, every frame's decision).\n\n"
    "source: a video, an image folder, a list file or a TUM rgb.txt (read as the command line reads it), or a\n"
    "list of images (NumPy arrays, read in place) or of vmap.Features.\n"
    "labels: a detections file (frame label score x y w h, e.g. of `vmap detect --out`), a list of them (pooled),\n"
    "or per frame a list of (label, score, x, y, w, h).\n"
    "rank: tree (LFM-LCD: every frame of the label tree's leaf), tree_ranked (the leaf ranked by bag-of-words\n"
    "score, top_k verified; the default with labels), bow (every older frame ranked, no labels; the default\n"
    "without), all (every frame older than the window: brute force).\n"
    "window: frames this recent are never candidates. min_candidates: m, backtrack up the tree until this many.\n"
    "top_k / min_bow_score: ranked sources verify this many best-ranked candidates, none below the score.\n"
    "temporal_consistency: accept a loop only when this many previous frames matched a nearby place (within\n"
    "temporal_tolerance frames); 0: off. left_ratio: the revisit rule, a candidate's place was left when a frame\n"
    "in between scored below this fraction of the query's bag-of-words score against it.\n"
    "min_confidence: the decision threshold on a loop's confidence in [0, 1]; min_inliers: below this a candidate\n"
    "is not weighed; chance_inlier_rate, half_significance, spread_grid, full_spread, ambiguity_ratio: the\n"
    "evidence's model (lcd/place_decision.hpp). label_min_score: detections below it are ignored.\n"
    "min_influence / max_influence: drop labels present in fewer / more frames of the sample (eq. 5);\n"
    "label_order: label ids large to small (default: by mean box area); sample: frames of the eq. 5 sample (0: all).\n"
    "words / depth / seed: the vocabulary learned without `vocabulary`. time_offset: seconds added to every frame\n"
    "time of a path source (a list's frames are named and timed by their index).\n"
    "progress(stage, done, total): called with stage 'features', 'vocabulary' or 'loops' as the run advances.";

constexpr const char* evaluate_doc =
    "Precision, recall, recall at 100 % precision and the PR curve of loop closure (vmap.Evaluation), the figures\n"
    "`vmap loops --gt / --gt-poses` prints.\n\n"
    "loops: a vmap.LoopRun (its decisions, evaluated as the command line does: threshold and window default to\n"
    "the run's), or rows (query, match, score), match None or negative for a query without a candidate.\n"
    "ground_truth: an N x N bool or integer 0/1 array (row = query frame, column = the older frame it closes a\n"
    "loop with) or a file of such rows.\n"
    "poses (instead of ground_truth): a pose file (TUM, KITTI or EuRoC; associated to a run's frame times within\n"
    "50 ms unless there is one per frame), or an N x 3 (positions: distance only) or N x 7 (x, y, z, qx, qy, qz,\n"
    "qw) array; (q, j) is a loop when j + window < q, the camera centres lie within max_distance metres and the\n"
    "viewing directions within max_angle degrees.\n"
    "min_confidence: the decision threshold (default: the run's, else 0.5).";

void bind(py::module_& m) {
  bind_results(m);

  m.def(
      "detect_loops",
      [](const py::object& source, const std::string& features, int nfeatures, const std::string& model,
         const std::string& refine_model, const py::object& labels, const std::optional<std::string>& rank,
         const py::object& vocabulary, std::size_t words, int depth, std::uint64_t seed, std::size_t window,
         std::size_t min_candidates, std::size_t top_k, double min_bow_score, std::size_t temporal_consistency,
         std::size_t temporal_tolerance, double left_ratio, double min_confidence, int min_inliers,
         double chance_inlier_rate, double half_significance, int spread_grid, double full_spread,
         double ambiguity_ratio, double label_min_score, double min_influence, double max_influence,
         const std::optional<std::vector<int>>& label_order, std::size_t sample, double time_offset,
         const py::object& progress) {
        const EngineArgs engine{
            window,      min_candidates,  top_k,          min_bow_score,      temporal_consistency, temporal_tolerance,
            left_ratio,  min_confidence,  min_inliers,    chance_inlier_rate, half_significance,    spread_grid,
            full_spread, ambiguity_ratio, label_min_score};
        return detect_loops(source, features, nfeatures, model, refine_model, labels, rank, vocabulary, words, depth,
                            seed, engine, min_influence, max_influence, label_order, sample, time_offset, progress);
      },
      py::arg("source"), py::kw_only(), py::arg("features") = "orb", py::arg("nfeatures") = 1000, py::arg("model") = "",
      py::arg("refine_model") = "", py::arg("labels") = py::none(), py::arg("rank") = py::none(),
      py::arg("vocabulary") = py::none(), py::arg("words") = 1000, py::arg("depth") = 3, py::arg("seed") = 1,
      py::arg("window") = 10, py::arg("min_candidates") = 5, py::arg("top_k") = 2, py::arg("min_bow_score") = 0.0,
      py::arg("temporal_consistency") = 0, py::arg("temporal_tolerance") = 3, py::arg("left_ratio") = 0.2,
      py::arg("min_confidence") = 0.5, py::arg("min_inliers") = 12, py::arg("chance_inlier_rate") = 0.1,
      py::arg("half_significance") = 12.0, py::arg("spread_grid") = 4, py::arg("full_spread") = 0.35,
      py::arg("ambiguity_ratio") = 0.9, py::arg("label_min_score") = 0.5, py::arg("min_influence") = 0.05,
      py::arg("max_influence") = 0.95, py::arg("label_order") = py::none(), py::arg("sample") = 0,
      py::arg("time_offset") = 0.0, py::arg("progress") = py::none(), detect_loops_doc);

  py::class_<PyLoopDetector>(
      m, "LoopDetector",
      "The loop detector fed one frame at a time (lcd/loop_detector.hpp): each add() decides whether the frame\n"
      "closes a loop with an older one, then indexes it. The same engine as vmap.detect_loops: fed a sequence's\n"
      "Features with the vocabulary learned from them, it gives the same decisions.\n\n"
      "vocabulary: a vocabulary file, or a list of vmap.Features to learn one from (words, depth, seed as in\n"
      "detect_loops); needed by the ranked sources (bow, tree_ranked). label_order: the label tree's label ids,\n"
      "large objects first (needed by tree and tree_ranked). rank: default tree_ranked with labels and a\n"
      "vocabulary, bow with a vocabulary, tree with labels, else all. The other options are detect_loops'.")
      .def(py::init([](const std::string& features, int nfeatures, const std::string& model,
                       const std::string& refine_model, const py::object& vocabulary, std::size_t words, int depth,
                       std::uint64_t seed, const std::optional<std::vector<int>>& label_order,
                       const std::optional<std::string>& rank, std::size_t window, std::size_t min_candidates,
                       std::size_t top_k, double min_bow_score, std::size_t temporal_consistency,
                       std::size_t temporal_tolerance, double left_ratio, double min_confidence, int min_inliers,
                       double chance_inlier_rate, double half_significance, int spread_grid, double full_spread,
                       double ambiguity_ratio, double label_min_score) {
             const EngineArgs engine{window,
                                     min_candidates,
                                     top_k,
                                     min_bow_score,
                                     temporal_consistency,
                                     temporal_tolerance,
                                     left_ratio,
                                     min_confidence,
                                     min_inliers,
                                     chance_inlier_rate,
                                     half_significance,
                                     spread_grid,
                                     full_spread,
                                     ambiguity_ratio,
                                     label_min_score};
             return std::make_unique<PyLoopDetector>(features, nfeatures, model, refine_model, vocabulary, words, depth,
                                                     seed, label_order, rank, engine);
           }),
           py::kw_only(), py::arg("features") = "orb", py::arg("nfeatures") = 1000, py::arg("model") = "",
           py::arg("refine_model") = "", py::arg("vocabulary") = py::none(), py::arg("words") = 1000,
           py::arg("depth") = 3, py::arg("seed") = 1, py::arg("label_order") = py::none(), py::arg("rank") = py::none(),
           py::arg("window") = 10, py::arg("min_candidates") = 5, py::arg("top_k") = 2, py::arg("min_bow_score") = 0.0,
           py::arg("temporal_consistency") = 0, py::arg("temporal_tolerance") = 3, py::arg("left_ratio") = 0.2,
           py::arg("min_confidence") = 0.5, py::arg("min_inliers") = 12, py::arg("chance_inlier_rate") = 0.1,
           py::arg("half_significance") = 12.0, py::arg("spread_grid") = 4, py::arg("full_spread") = 0.35,
           py::arg("ambiguity_ratio") = 0.9, py::arg("label_min_score") = 0.5)
      .def("add", &PyLoopDetector::add, py::arg("frame"), py::arg("detections") = py::none(),
           "The decision for the next frame (an image, whose features are extracted with the detector's descriptor,\n"
           "or vmap.Features made by the same kind of descriptor), with its detections (label, score, x, y, w, h)\n"
           "for the label tree; the frame is then indexed.")
      .def_property_readonly(
          "frames", [](const PyLoopDetector& d) { return d.read([](const DetectorBase& b) { return b.frames(); }); })
      .def_property_readonly(
          "verifications",
          [](const PyLoopDetector& d) { return d.read([](const DetectorBase& b) { return b.verifications(); }); },
          "verifications spent over all frames so far")
      .def_property_readonly(
          "stationary",
          [](const PyLoopDetector& d) { return d.read([](const DetectorBase& b) { return b.stationary(); }); },
          "the camera never left its place (needs a vocabulary)")
      .def_property_readonly(
          "memory_bytes",
          [](const PyLoopDetector& d) { return d.read([](const DetectorBase& b) { return b.memory_bytes(); }); },
          "bytes held for the frames: keypoints, descriptors, label vectors, the ranker's index")
      .def_property_readonly("rank", &PyLoopDetector::rank, "tree, tree_ranked, bow or all")
      .def_property_readonly("features", [](const PyLoopDetector& d) { return d.choice().name; })
      .def_property_readonly("window", [](const PyLoopDetector& d) { return d.options().window; })
      .def_property_readonly("min_confidence",
                             [](const PyLoopDetector& d) { return d.options().decision.min_confidence; })
      .def("__len__", [](const PyLoopDetector& d) { return d.read([](const DetectorBase& b) { return b.frames(); }); })
      .def("__repr__", [](const PyLoopDetector& d) {
        return "<vmap.LoopDetector " + d.choice().name + ", rank " + d.rank() + ", " +
               std::to_string(d.read([](const DetectorBase& b) { return b.frames(); })) + " frames>";
      });

  m.def("evaluate", &evaluate, py::arg("loops"), py::arg("ground_truth") = py::none(), py::kw_only(),
        py::arg("poses") = py::none(), py::arg("max_distance") = 0.5, py::arg("max_angle") = 30.0,
        py::arg("window") = py::none(), py::arg("min_confidence") = py::none(), evaluate_doc);
}

const RegisterPart part{order_loops, &bind};

}  // namespace
}  // namespace vmap::python
