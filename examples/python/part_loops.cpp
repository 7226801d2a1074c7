// Loop closure from Python: vmap.detect_loops (one run over a sequence, the run of
// `vmap loops`), vmap.LoopDetector (the same detector fed one frame at a time) and
// vmap.evaluate (precision, recall, recall at 100 % precision and the PR curve against a
// ground-truth matrix or poses, the figures `vmap loops --gt / --gt-poses` prints). The
// run, the detector and the evaluation are the library's (vmap/runtime/loops.hpp,
// vmap/runtime/loop_detector.hpp), which also checks every option; this part reads the
// Python arguments into them.

#include "bindings.hpp"

#include <vmap/hooks/precomputed_detections.hpp>
#include <vmap/io/poses.hpp>
#include <vmap/lcd/evaluation.hpp>
#include <vmap/lcd/loop_detector.hpp>
#include <vmap/lcd/loop_engine.hpp>
#include <vmap/lcd/place_decision.hpp>
#include <vmap/runtime/calibration.hpp>
#include <vmap/runtime/loop_detector.hpp>
#include <vmap/runtime/loops.hpp>
#include <vmap/runtime/option_names.hpp>
#include <vmap/runtime/vocabulary.hpp>

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

namespace vmap::python {
namespace {

// ---------------------------------------------------------------------------------------
// Arguments

bool is_path(const py::handle& h) { return py::isinstance<py::str>(h) || py::hasattr(h, "__fspath__"); }

std::string path_of(const py::handle& h) { return py::str(py::module_::import("os").attr("fspath")(h)); }

/// The loop engine's options from the keyword arguments (checked by the library).
struct EngineArgs {
  std::size_t window, min_candidates, top_k;
  double min_bow_score;
  std::size_t temporal_consistency, temporal_tolerance;
  double left_ratio, min_confidence;
  int min_inliers;
  std::optional<double> chance_inlier_rate;  ///< None: the rate measured for the stack
  double half_significance;
  int spread_grid;
  double full_spread, ambiguity_ratio, label_min_score;

  [[nodiscard]] LoopOptions options(const PolicyStack& stack) const {
    LoopOptions o;
    o.labels.min_score = static_cast<float>(label_min_score);
    o.window = window;
    o.min_candidates = min_candidates;
    o.top_k = top_k;
    o.min_bow_score = min_bow_score;
    o.temporal_consistency = temporal_consistency;
    o.temporal_tolerance = temporal_tolerance;
    o.left_ratio = left_ratio;
    o.decision.min_confidence = min_confidence;
    o.decision.min_inliers = min_inliers;
    o.decision.chance_inlier_rate = chance_inlier_rate.value_or(measured_chance_rate(stack));
    o.decision.half_significance = half_significance;
    o.decision.spread_grid = spread_grid;
    o.decision.full_spread = full_spread;
    o.decision.ambiguity_ratio = ambiguity_ratio;
    return o;
  }
};

/// The candidate source named by `rank`, else the default for what is given. "all", the old
/// name of brute_force, still reads for one release, with a DeprecationWarning.
CandidateIndex candidate_index(const std::optional<std::string>& rank, bool labels, bool vocabulary) {
  if (rank == "all" && PyErr_WarnEx(PyExc_DeprecationWarning,
                                    "rank='all' is now rank='brute_force'; 'all' will be removed in the next release",
                                    1) != 0)
    throw py::error_already_set();
  return rank ? parse_option<CandidateIndex>(*rank, "rank", "") : default_candidate_index(labels, vocabulary);
}

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
  if (is_path(labels)) return load_labels({path_of(labels)});
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
    return load_labels(files);
  }
  std::vector<std::vector<Detection>> per_frame;
  for (std::size_t k = 0; k < py::len(seq); ++k)
    per_frame.push_back(detections_of(seq[k], "labels[" + std::to_string(k) + "]"));
  return PrecomputedDetections(per_frame);
}

/// progress(stage, done, total) with the GIL, from the run that released it.
std::function<void(LoopStage, std::size_t, std::size_t)> progress_of(const py::object& progress) {
  if (progress.is_none()) return {};
  if (!PyCallable_Check(progress.ptr())) fail("progress must be callable as progress(stage, done, total)");
  return [progress](LoopStage stage, std::size_t done, std::size_t total) {
    py::gil_scoped_acquire held;
    progress(std::string(to_string(stage)), done, total);
  };
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

LoopRun detect_loops(const py::object& source, const std::string& features, int nfeatures, const std::string& model,
                     const std::string& refine_model, const py::object& labels, const std::optional<std::string>& rank,
                     const py::object& vocabulary, std::size_t words, int depth, std::uint64_t seed,
                     const EngineArgs& engine, double min_influence, double max_influence,
                     const std::optional<std::vector<int>>& label_order, std::size_t sample, double time_offset,
                     const py::object& progress) {
  LoopRunOptions o;
  o.stack = policy_stack(features, nfeatures, model, refine_model);
  o.influence = {.min_influence = min_influence, .max_influence = max_influence};
  o.label_order = label_order.value_or(std::vector<int>{});
  o.sample = sample;
  const std::optional<PrecomputedDetections> detections = labels_of(labels);
  o.detector = engine.options(o.stack);
  o.detector.index = candidate_index(rank, detections.has_value(), true);
  check_candidate_source(o.detector.index, detections.has_value(), true);
  o.vocabulary.learning = {.words = words, .depth = depth, .seed = seed};
  if (!vocabulary.is_none()) {
    if (!is_path(vocabulary))
      fail("vocabulary: a vocabulary file (of `vmap vocabulary`), got " + std::string(py::repr(vocabulary)));
    o.vocabulary.file = path_of(vocabulary);
  }
  o.validate();
  const LoopRunCallbacks callbacks{.progress = progress_of(progress), .on_result = {}};
  const PrecomputedDetections* given = detections ? &*detections : nullptr;

  // A path is read by the library's frame source; a list holds images (read in place:
  // `held` keeps each array alive while the GIL is released, whatever happens to the
  // list meanwhile) or Features already extracted.
  if (is_path(source)) {
    const std::string input = path_of(source);
    py::gil_scoped_release unlocked;
    return vmap::detect_loops(input, o, given, callbacks, {.time_offset = time_offset});
  }
  if (!py::isinstance<py::sequence>(source))
    fail("source: a video, an image folder, a list file or rgb.txt, or a list of images or Features; got " +
         std::string(py::repr(source)));
  const auto items = py::reinterpret_borrow<py::sequence>(source);
  if (py::len(items) == 0) fail("source: an empty list of frames");
  std::vector<cv::Mat> images;
  std::vector<Features> given_features;
  std::vector<py::object> held;
  for (std::size_t k = 0; k < py::len(items); ++k) {
    const py::object item = items[k];
    if (py::isinstance<Features>(item)) {
      given_features.push_back(item.cast<const Features&>());
    } else if (py::isinstance<py::array>(item)) {
      images.push_back(image_view(item.cast<py::array>(), "source[" + std::to_string(k) + "]"));
      held.push_back(item);
    } else {
      fail("source[" + std::to_string(k) + "]: an image (NumPy array) or vmap.Features, got " +
           std::string(py::repr(item)));
    }
  }
  if (!images.empty() && !given_features.empty()) fail("source: give images or Features, not both");
  py::gil_scoped_release unlocked;
  const SequenceFeatures sequence =
      images.empty()
          ? SequenceFeatures::of(std::move(given_features), "<list of " + std::to_string(py::len(items)) + " frames>")
          : extract_features(images, o.stack, [&](std::size_t done, std::size_t total) {
              if (callbacks.progress) callbacks.progress(LoopStage::features, done, total);
            });
  return vmap::detect_loops(sequence, o, given, callbacks);
}

// ---------------------------------------------------------------------------------------
// LoopDetector, one frame at a time

/// vmap.LoopDetector: the library's AnyLoopDetector behind a lock. Its calls release the
/// GIL, so two Python threads could reach one detector; the mutex keeps its frames in
/// order (taken after the GIL is let go: no deadlock).
class PyLoopDetector {
 public:
  PyLoopDetector(const std::string& features, int nfeatures, const std::string& model, const std::string& refine_model,
                 const py::object& vocabulary, std::size_t words, int depth, std::uint64_t seed,
                 const std::optional<std::vector<int>>& label_order, const std::optional<std::string>& rank,
                 const EngineArgs& engine)
      : detector_(make(features, nfeatures, model, refine_model, vocabulary, words, depth, seed, label_order, rank,
                       engine)) {}

  LoopResult add(const py::object& frame, const py::object& detections) {
    const std::vector<Detection> found = detections_of(detections, "detections");
    if (py::isinstance<Features>(frame)) {
      Features f = frame.cast<const Features&>();
      py::gil_scoped_release unlocked;
      const std::lock_guard<std::mutex> one_at_a_time(mutex_);
      return detector_.add(std::move(f), found);
    }
    if (!py::isinstance<py::array>(frame))
      fail("add: an image (NumPy array) or vmap.Features, got " + std::string(py::repr(frame)));
    const cv::Mat view = image_copy(frame.cast<py::array>(), "image");
    py::gil_scoped_release unlocked;
    const std::lock_guard<std::mutex> one_at_a_time(mutex_);
    return detector_.push(view, found);
  }

  /// f(detector) under the mutex: another thread may be adding a frame (without the GIL).
  template <class F>
  auto read(F f) const {
    const std::lock_guard<std::mutex> one_at_a_time(mutex_);
    return f(detector_);
  }

 private:
  static AnyLoopDetector make(const std::string& features, int nfeatures, const std::string& model,
                              const std::string& refine_model, const py::object& vocabulary, std::size_t words,
                              int depth, std::uint64_t seed, const std::optional<std::vector<int>>& label_order,
                              const std::optional<std::string>& rank, const EngineArgs& engine) {
    const PolicyStack stack = policy_stack(features, nfeatures, model, refine_model);
    const VocabularyLearning learning{.words = words, .depth = depth, .seed = seed};
    std::shared_ptr<const AnyVocabulary> words_tree;
    if (!vocabulary.is_none()) {
      if (is_path(vocabulary)) {
        words_tree = std::make_shared<const AnyVocabulary>(AnyVocabulary::load(path_of(vocabulary)));
      } else {
        std::vector<Features> learn_from;
        for (const py::handle f : vocabulary) {
          if (!py::isinstance<Features>(f))
            fail("vocabulary: a vocabulary file or a list of vmap.Features to learn one from; the list holds " +
                 std::string(py::repr(f)));
          learn_from.push_back(f.cast<const Features&>());
        }
        learning.validate();
        py::gil_scoped_release unlocked;
        words_tree = std::make_shared<const AnyVocabulary>(learn_vocabulary(learn_from, learning));
      }
    }
    const bool have_labels = label_order && !label_order->empty();
    LoopOptions options = engine.options(stack);
    options.index = candidate_index(rank, have_labels, words_tree != nullptr);
    check_candidate_source(options.index, have_labels, words_tree != nullptr,
                           OptionNames{.style = OptionNames::Style::keyword,
                                       .renamed = {{"labels", "label_order (the label ids of the tree, large objects first)"},
                                                   {"vocabulary", "vocabulary (a file, or a list of Features to learn one from)"}}});
    return AnyLoopDetector(stack, LabelSchema(have_labels ? *label_order : std::vector<int>{}), options,
                           std::move(words_tree));
  }

  AnyLoopDetector detector_;
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

LoopEvaluation evaluate(const py::object& loops, const py::object& ground_truth, const py::object& poses,
                        double max_distance, double max_angle, std::optional<std::size_t> window,
                        std::optional<double> min_confidence) {
  if (ground_truth.is_none() == poses.is_none())
    fail("evaluate: give one of ground_truth (an N x N 0/1 matrix or its file) and poses");
  const LoopRun* run = py::isinstance<LoopRun>(loops) ? &loops.cast<const LoopRun&>() : nullptr;
  const double threshold =
      min_confidence.value_or(run ? run->options.decision.min_confidence : PlaceDecisionOptions{}.min_confidence);
  const PoseLoopOptions by_pose{.max_distance = max_distance,
                                .max_angle_deg = max_angle,
                                .window = window.value_or(run ? run->options.window : LoopOptions{}.window)};
  LoopGroundTruth gt;
  if (!ground_truth.is_none())
    gt = ground_truth_of(ground_truth);
  else if (is_path(poses))
    // One pose per frame of a run, as `vmap loops --gt-poses` associates them.
    gt = ground_truth_from_poses(run ? frame_poses(path_of(poses), run->times) : load_camera_poses(path_of(poses)),
                                 by_pose);
  else
    gt = ground_truth_from_poses(poses_of_array(poses), by_pose);
  if (run) return evaluate_loop_run(*run, std::move(gt), threshold, ground_truth.is_none() ? "poses" : "ground_truth");
  return evaluate_loop_scores(scores_of(loops), std::move(gt), threshold);
}

// ---------------------------------------------------------------------------------------
// Bindings

py::object optional_index(const std::optional<std::size_t>& i) { return i ? py::cast(*i) : py::none(); }

void bind_results(py::module_& m) {
  py::class_<DetectedLoop>(m, "Loop", "One loop found: query frame -> matched (older) frame, with its evidence.")
      .def_readonly("query", &DetectedLoop::query, "index of the query frame")
      .def_readonly("match", &DetectedLoop::match, "index of the older frame it closes a loop with")
      .def_readonly("query_name", &DetectedLoop::query_name, "the query frame's file name (its index for a list)")
      .def_readonly("match_name", &DetectedLoop::match_name, "the older frame's file name (its index for a list)")
      .def_readonly("query_time", &DetectedLoop::query_time, "the query frame's time, seconds")
      .def_readonly("match_time", &DetectedLoop::match_time, "the older frame's time, seconds")
      .def_readonly("confidence", &DetectedLoop::confidence,
                    "in [0, 1]: 1 - 2^(-significance / half_significance), "
                    "scaled down when the inliers are bunched")
      .def_property_readonly(
          "inliers", [](const DetectedLoop& l) { return l.evidence.inliers; }, "matches the geometric model explains")
      .def_property_readonly(
          "matches", [](const DetectedLoop& l) { return l.evidence.matches; },
          "tentative correspondences the model was fitted to (for XFeat*: the refined ones)")
      .def_property_readonly(
          "inlier_ratio", [](const DetectedLoop& l) { return l.evidence.inlier_ratio; }, "inliers / matches")
      .def_property_readonly(
          "significance", [](const DetectedLoop& l) { return l.evidence.significance; },
          "-log10 P(at least `inliers` of `matches` fit by chance)")
      .def_property_readonly(
          "spread", [](const DetectedLoop& l) { return l.evidence.spread; },
          "fraction of grid cells with an inlier, the smaller view")
      .def_property_readonly(
          "bow_score", [](const DetectedLoop& l) { return l.evidence.bow_score; },
          "the match's bag-of-words score (0 when not ranked)")
      .def("__repr__", [](const DetectedLoop& l) {
        char buf[200];
        std::snprintf(buf, sizeof buf, "<vmap.Loop %zu -> %zu confidence %.3f inliers %d of %d bow %.3f>", l.query,
                      l.match, l.confidence, l.evidence.inliers, l.evidence.matches, l.evidence.bow_score);
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
      .def_property_readonly(
          "reason_code", [](const LoopResult& r) { return std::string(to_string(r.reason_code)); },
          "why, one name per case (vmap::DecisionReason: 'no candidates', 'too few inliers', 'not yet confirmed', ...)")
      .def_readonly("confidence", &LoopResult::confidence, "of the best place, in [0, 1]")
      .def_property_readonly(
          "best", [](const LoopResult& r) { return optional_index(r.best); },
          "the best place's frame (verified), or None")
      .def_property_readonly(
          "second", [](const LoopResult& r) { return optional_index(r.second); },
          "the best other place, if verified, or None")
      .def_readonly("second_confidence", &LoopResult::second_confidence,
                    "the confidence of the best other place (the ambiguity test compares the two)")
      .def_property_readonly(
          "inliers", [](const LoopResult& r) { return r.evidence.inliers; }, "of the best place")
      .def_property_readonly(
          "matches", [](const LoopResult& r) { return r.evidence.matches; }, "of the best place")
      .def_property_readonly("inlier_ratio", [](const LoopResult& r) { return r.evidence.inlier_ratio; }, "inliers / matches")
      .def_property_readonly("significance", [](const LoopResult& r) { return r.evidence.significance; },
                             "-log10 of the probability that at least that many inliers come by chance")
      .def_property_readonly("spread", [](const LoopResult& r) { return r.evidence.spread; },
                             "the fraction of grid cells holding an inlier (the smaller of the two views)")
      .def_property_readonly("bow_score", [](const LoopResult& r) { return r.evidence.bow_score; },
                             "the bag-of-words score of the best place (0 without a vocabulary)")
      .def_readonly("candidates", &LoopResult::candidates, "frames the candidate source proposed")
      .def_readonly("verifications", &LoopResult::verifications, "candidates verified by the F-matrix for this frame")
      .def_readonly("failed_verifications", &LoopResult::failed_verifications,
                    "verifications that found no model (too few matches or a degenerate fit)")
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

  py::class_<LoopRun>(m, "LoopRun",
                      "The result of vmap.detect_loops: the loops, every frame's decision and the run's figures.")
      .def_readonly("loops", &LoopRun::loops, "the accepted loops (vmap.Loop), in frame order")
      .def_readonly("decisions", &LoopRun::results, "one vmap.LoopDecision per frame")
      .def_property_readonly("frames", [](const LoopRun& r) { return r.results.size(); }, "frames the run decided on")
      .def_readonly("names", &LoopRun::names, "per frame: its file name (its index for a list)")
      .def_readonly("times", &LoopRun::times, "per frame: its time in seconds")
      .def_readonly("skipped_frames", &LoopRun::skipped, "unreadable frames (not in the run)")
      .def_property_readonly(
          "rank", [](const LoopRun& r) { return std::string(to_string(r.options.index)); },
          "the candidate source: tree, tree_ranked, bow or brute_force")
      .def_property_readonly("min_confidence", [](const LoopRun& r) { return r.options.decision.min_confidence; },
                             "the confidence a loop needed")
      .def_property_readonly("chance_inlier_rate", [](const LoopRun& r) { return r.options.decision.chance_inlier_rate; },
                             "the decision's chance-inlier rate (the stack's measured one unless given)")
      .def_property_readonly("window", [](const LoopRun& r) { return r.options.window; },
                             "frames just before a query that are never its candidates")
      .def_readonly("verifications", &LoopRun::verifications, "F-matrix verifications over the whole run")
      .def_readonly("stationary", &LoopRun::stationary, "the camera never left its place: no frame is a revisit")
      .def_readonly("seconds", &LoopRun::seconds, "feature extraction + the detector over the sequence")
      .def_property_readonly(
          "labels_kept", [](const LoopRun& r) { return r.schema.labels(); },
          "the label tree's labels, large objects first")
      .def_property_readonly(
          "scores", [](const LoopRun& r) { return score_array(r.scores()); },
          "the evaluation's view, N x 3 float64: query, best match (-1: none), score (the confidence\n"
          "of the decisions the threshold alone decides, accepted or unknown place; 0 otherwise)")
      .def("__len__", [](const LoopRun& r) { return r.loops.size(); })
      .def("__repr__", [](const LoopRun& r) {
        return "<vmap.LoopRun " + std::to_string(r.results.size()) + " frames, " + std::to_string(r.loops.size()) +
               " loops, rank " + std::string(to_string(r.options.index)) + ">";
      });

  py::class_<LoopEvaluation>(
      m, "Evaluation",
      "Precision and recall of loop closure against ground truth (lcd/evaluation.hpp): each query\n"
      "proposes its best candidate; at threshold t a query scoring >= t is a detection, true when the\n"
      "ground truth marks (query, candidate). Positives are the query frames with a ground-truth loop.")
      .def_property_readonly(
          "precision", [](const LoopEvaluation& e) { return e.at_threshold.precision; },
          "TP / (TP + FP) at `threshold` (1 when nothing is detected)")
      .def_property_readonly(
          "recall", [](const LoopEvaluation& e) { return e.at_threshold.recall; },
          "TP / positives at `threshold` (0 when the ground truth has no loop)")
      .def_property_readonly("true_positives", [](const LoopEvaluation& e) { return e.at_threshold.true_positives; },
                             "loops accepted that the ground truth has")
      .def_property_readonly("false_positives", [](const LoopEvaluation& e) { return e.at_threshold.false_positives; },
                             "loops accepted that the ground truth does not have")
      .def_property_readonly("false_negatives", [](const LoopEvaluation& e) { return e.at_threshold.false_negatives; },
                             "query frames with a ground-truth loop and no accepted one")
      .def_readonly("positives", &LoopEvaluation::positives, "query frames with a ground-truth loop")
      .def_readonly("frames", &LoopEvaluation::frames, "query frames evaluated")
      .def_readonly("threshold", &LoopEvaluation::threshold, "the decision threshold precision and recall are taken at")
      .def_property_readonly(
          "recall_at_100_precision", [](const LoopEvaluation& e) { return e.at_full_precision.recall; },
          "the best recall among the curve's points without a false positive")
      .def_property_readonly(
          "threshold_at_100_precision",
          [](const LoopEvaluation& e) -> py::object {
            if (e.at_full_precision.true_positives == 0) return py::none();
            return py::float_(e.at_full_precision.threshold);
          },
          "the lowest threshold that reaches recall_at_100_precision (None when every point has a false positive)")
      .def_property_readonly(
          "curve",
          [](const LoopEvaluation& e) {
            const auto& c = e.curve;
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
          [](const LoopEvaluation& e) {
            const auto n = static_cast<py::ssize_t>(e.ground_truth.frames());
            py::array_t<bool> out({n, n});
            auto v = out.mutable_unchecked<2>();
            for (py::ssize_t q = 0; q < n; ++q)
              for (py::ssize_t j = 0; j < n; ++j)
                v(q, j) = e.ground_truth(static_cast<std::size_t>(q), static_cast<std::size_t>(j));
            return out;
          },
          "the N x N bool ground-truth matrix evaluated against (derived from the poses when given)")
      .def("__repr__", [](const LoopEvaluation& e) {
        char buf[200];
        std::snprintf(buf, sizeof buf,
                      "<vmap.Evaluation precision %.3f recall %.3f recall@100%%P %.3f (TP %zu, FP %zu, %zu positives)>",
                      e.at_threshold.precision, e.at_threshold.recall, e.at_full_precision.recall,
                      e.at_threshold.true_positives, e.at_threshold.false_positives, e.positives);
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
    "without), brute_force (every frame older than the window).\n"
    "window: frames this recent are never candidates. min_candidates: m, backtrack up the tree until this many.\n"
    "top_k / min_bow_score: ranked sources verify this many best-ranked candidates, none below the score.\n"
    "temporal_consistency: accept a loop only when this many previous frames matched a nearby place (within\n"
    "temporal_tolerance frames); 0: off. left_ratio: the revisit rule, a candidate's place was left when a view in\n"
    "between began with a frame whose similarity to it (eq. 5) is below this fraction of the query's.\n"
    "min_confidence: the decision threshold on a loop's confidence in [0, 1]; min_inliers: below this a candidate\n"
    "is not weighed; chance_inlier_rate (None: vmap.measured_chance_rate(features)), half_significance, spread_grid, full_spread, ambiguity_ratio: the\n"
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
         std::optional<double> chance_inlier_rate, double half_significance, int spread_grid, double full_spread,
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
      py::arg("temporal_consistency") = 0, py::arg("temporal_tolerance") = 3, py::arg("left_ratio") = 0.5,
      py::arg("min_confidence") = 0.5, py::arg("min_inliers") = 12, py::arg("chance_inlier_rate") = py::none(),
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
      "vocabulary, bow with a vocabulary, tree with labels, else brute_force. The other options are detect_loops'.")
      .def(py::init([](const std::string& features, int nfeatures, const std::string& model,
                       const std::string& refine_model, const py::object& vocabulary, std::size_t words, int depth,
                       std::uint64_t seed, const std::optional<std::vector<int>>& label_order,
                       const std::optional<std::string>& rank, std::size_t window, std::size_t min_candidates,
                       std::size_t top_k, double min_bow_score, std::size_t temporal_consistency,
                       std::size_t temporal_tolerance, double left_ratio, double min_confidence, int min_inliers,
                       std::optional<double> chance_inlier_rate, double half_significance, int spread_grid, double full_spread,
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
           py::arg("temporal_consistency") = 0, py::arg("temporal_tolerance") = 3, py::arg("left_ratio") = 0.5,
           py::arg("min_confidence") = 0.5, py::arg("min_inliers") = 12, py::arg("chance_inlier_rate") = py::none(),
           py::arg("half_significance") = 12.0, py::arg("spread_grid") = 4, py::arg("full_spread") = 0.35,
           py::arg("ambiguity_ratio") = 0.9, py::arg("label_min_score") = 0.5)
      .def("add", &PyLoopDetector::add, py::arg("frame"), py::arg("detections") = py::none(),
           "The decision for the next frame (an image, whose features are extracted with the detector's descriptor,\n"
           "or vmap.Features made by the same kind of descriptor), with its detections (label, score, x, y, w, h)\n"
           "for the label tree; the frame is then indexed.")
      .def_property_readonly(
          "frames", [](const PyLoopDetector& d) { return d.read([](const AnyLoopDetector& b) { return b.frames(); }); },
          "frames pushed so far")
      .def_property_readonly(
          "verifications",
          [](const PyLoopDetector& d) { return d.read([](const AnyLoopDetector& b) { return b.verifications(); }); },
          "verifications spent over all frames so far")
      .def_property_readonly(
          "stationary",
          [](const PyLoopDetector& d) { return d.read([](const AnyLoopDetector& b) { return b.stationary(); }); },
          "the camera never left its place (needs a vocabulary)")
      .def_property_readonly(
          "memory_bytes",
          [](const PyLoopDetector& d) { return d.read([](const AnyLoopDetector& b) { return b.memory_bytes(); }); },
          "bytes held for the frames: keypoints, descriptors, label vectors, the ranker's index")
      .def_property_readonly(
          "rank",
          [](const PyLoopDetector& d) {
            return d.read([](const AnyLoopDetector& b) { return std::string(to_string(b.options().index)); });
          },
          "tree, tree_ranked, bow or brute_force")
      .def_property_readonly(
          "features",
          [](const PyLoopDetector& d) {
            return d.read([](const AnyLoopDetector& b) { return std::string(to_string(b.stack().descriptor)); });
          },
          "the descriptor's name")
      .def_property_readonly(
          "window", [](const PyLoopDetector& d) { return d.read([](const AnyLoopDetector& b) { return b.options().window; }); },
          "frames just before a query that are never its candidates")
      .def_property_readonly("min_confidence",
                             [](const PyLoopDetector& d) {
                               return d.read([](const AnyLoopDetector& b) { return b.options().decision.min_confidence; });
                             },
                             "the confidence a loop needs")
      .def_property_readonly("chance_inlier_rate",
                             [](const PyLoopDetector& d) {
                               return d.read(
                                   [](const AnyLoopDetector& b) { return b.options().decision.chance_inlier_rate; });
                             },
                             "the decision's chance-inlier rate (the stack's measured one unless given)")
      .def("__len__", [](const PyLoopDetector& d) { return d.read([](const AnyLoopDetector& b) { return b.frames(); }); })
      .def("__repr__", [](const PyLoopDetector& d) {
        return d.read([](const AnyLoopDetector& b) {
          return "<vmap.LoopDetector " + std::string(to_string(b.stack().descriptor)) + ", rank " +
                 std::string(to_string(b.options().index)) + ", " + std::to_string(b.frames()) + " frames>";
        });
      });

  py::class_<ChanceCalibration>(m, "ChanceCalibration",
                                "A stack's chance rate measured on foreign pairs (vmap.calibrate_chance_rate).")
      .def_readonly("rate", &ChanceCalibration::rate, "the chance-inlier rate: give it as chance_inlier_rate")
      .def_readonly("pairs", &ChanceCalibration::pairs, "foreign pairs verified")
      .def_readonly("weighed", &ChanceCalibration::weighed, "of those, with at least 12 inliers")
      .def_readonly("strongest_significance", &ChanceCalibration::strongest,
                    "the strongest foreign pair's significance at the rate")
      .def("__repr__", [](const ChanceCalibration& c) {
        return "<vmap.ChanceCalibration rate " + std::to_string(c.rate) + " from " + std::to_string(c.pairs) + " pairs>";
      });
  m.def(
      "calibrate_chance_rate",
      [](const std::vector<py::object>& places, const std::string& features, int nfeatures, const std::string& model,
         const std::string& refine_model, const std::string& estimator, std::size_t pairs, std::uint64_t seed) {
        const PolicyStack stack = policy_stack(features, nfeatures, model, refine_model, estimator);
        std::vector<std::string> paths;
        for (const py::object& p : places) {
          if (!is_path(p)) fail("places: paths of image folders, list files or videos, got " + std::string(py::repr(p)));
          paths.push_back(path_of(p));
        }
        if (pairs < 100) fail("pairs: at least 100 (the 99th percentile needs them), got " + std::to_string(pairs));
        py::gil_scoped_release unlocked;
        std::vector<SequenceFeatures> features_of;
        for (const std::string& p : paths) features_of.push_back(extract_features(p, stack));
        return calibrate_chance_rate(stack, std::move(features_of), {.pairs = pairs, .seed = seed});
      },
      py::arg("places"), py::kw_only(), py::arg("features") = "orb", py::arg("nfeatures") = 1000, py::arg("model") = "",
      py::arg("refine_model") = "", py::arg("estimator") = "magsac", py::arg("pairs") = 200, py::arg("seed") = 1,
      "The place decision's chance rate for a stack, measured on two or more places that share nothing (image\n"
      "folders, list files or videos): seeded pairs of images of two different places verified with the stack's\n"
      "matcher and estimator, as `vmap calibrate` does. Give its rate as chance_inlier_rate.");
  m.def(
      "measured_chance_rate",
      [](const std::string& features) {
        PolicyStack s;
        s.descriptor = parse<DescriptorKind>(features, "features");
        return measured_chance_rate(s);
      },
      py::arg("features") = "orb",
      "The place decision's chance-inlier rate measured for a descriptor (orb, akaze, sift, xfeat, xfeat-dense,\n"
      "xfeat-star) with its own matcher and MAGSAC++ at 1 px: the default of chance_inlier_rate=None.");
  m.def("evaluate", &evaluate, py::arg("loops"), py::arg("ground_truth") = py::none(), py::kw_only(),
        py::arg("poses") = py::none(), py::arg("max_distance") = 0.5, py::arg("max_angle") = 30.0,
        py::arg("window") = py::none(), py::arg("min_confidence") = py::none(), evaluate_doc);
}

const RegisterPart part{order_loops, &bind};

}  // namespace
}  // namespace vmap::python
