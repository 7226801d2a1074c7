// vmap.KeyframeSelector (the key images of García-Pintos et al. 2023, Algorithm 1 /
// eq. 6), vmap.VisualMap (its map, eq. 7's quality, map files) and vmap.sweep (the
// paper's threshold table). The descriptor, matcher and estimator are the policy stack
// the keywords name (vmap/runtime/stack_choice.hpp), as `vmap build` and `vmap sweep`
// read theirs; the selector is the library's AnySelector (vmap/runtime/selector.hpp).

#include "bindings.hpp"

#include <vmap/io/atomic_file.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/keyframe/map_io.hpp>
#include <vmap/keyframe/pipeline.hpp>
#include <vmap/keyframe/selector.hpp>
#include <vmap/keyframe/sweep.hpp>
#include <vmap/runtime/frame_range.hpp>
#include <vmap/runtime/option_names.hpp>
#include <vmap/runtime/selector.hpp>
#include <vmap/runtime/stack_choice.hpp>

#include <pybind11/stl/filesystem.h>

#include <atomic>
#include <cstddef>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <utility>
#include <vector>

namespace vmap::python {
namespace {

/// The frames of `source` in the range of the keywords (start, end: None to the end,
/// stride), decoded to grey as `vmap build` decodes them.
FrameSource open_range(const std::string& source, std::size_t start, std::optional<std::size_t> end, std::size_t stride,
                       double time_offset) {
  FrameSourceOptions o;
  o.grey = true;
  o.time_offset = time_offset;
  return FrameSource::open(source, FrameRange{start, end, stride}.apply(o));
}

/// vmap.KeyframeSelector. A selector is single-threaded (selector.hpp) while its calls
/// release the GIL, so a call from another Python thread during push() or
/// push_frames() is refused rather than left to race; the progress callback of
/// push_frames (the same thread, between two frames) may read the map.
class PySelector {
 public:
  PySelector(const PolicyStack& stack, const SelectorOptions& options)
      : selector_(stack, options, camera_name(stack, OptionNames::keywords())) {}

  FrameResult push(const py::array& image, std::optional<double> timestamp, std::optional<std::string> name) {
    const Claim claim(owner_);
    Frame f;
    f.image = image_copy(image, "image");
    // Numbered after the last frame pushed, as the library numbers a bare image.
    f.index = last_index_ ? *last_index_ + 1 : 0;
    f.timestamp = timestamp.value_or(static_cast<double>(f.index));
    f.name = name ? *name : "frame#" + std::to_string(f.index);
    FrameResult r;
    {
      const py::gil_scoped_release unlocked;
      r = selector_.push(f);
    }
    last_index_ = f.index;
    return r;
  }

  std::vector<FrameResult> push_frames(const std::string& source, std::size_t start, std::optional<std::size_t> end,
                                       std::size_t stride, double time_offset, bool single_thread,
                                       const py::object& progress, std::size_t progress_every) {
    const Claim claim(owner_);
    // The map's frame indices must keep increasing (map files require it).
    if (last_index_ && start <= *last_index_)
      fail("push_frames: this selector already saw frame " + std::to_string(*last_index_) + "; pass start=" +
           std::to_string(*last_index_ + 1) + " or more to continue the sequence, or reset() it first");
    const ProgressHook hook(progress, progress_every);
    std::vector<FrameResult> results;
    {
      const py::gil_scoped_release unlocked;
      auto src = open_range(source, start, end, stride, time_offset);
      selector_.run(src, {.pipelined = !single_thread}, [&](const FrameResult& r) {
        results.push_back(r);
        last_index_ = r.frame_index;
        hook(results.size());
      });
    }
    if (results.empty()) fail("'" + source + "' gave no frame in the requested range");
    return results;
  }

  [[nodiscard]] const VisualMap& map() const {
    check_readable();
    return selector_.map();
  }

  void save_map(const std::filesystem::path& path) const {
    // Serialized with the GIL held (no other call can start), written without it.
    const std::string bytes = serialize_map(map());
    const py::gil_scoped_release unlocked;
    write_file_atomically(path, bytes);
  }

  void reset() {
    const Claim claim(owner_);
    selector_.reset();
    last_index_.reset();
  }

  [[nodiscard]] const SelectorOptions& options() const noexcept { return selector_.options(); }
  [[nodiscard]] const PolicyStack& stack() const noexcept { return selector_.stack(); }

 private:
  /// Marks the selector in use by this thread for a call that changes it.
  class Claim {
   public:
    explicit Claim(std::atomic<std::thread::id>& owner) : owner_(owner) {
      std::thread::id idle;
      if (!owner_.compare_exchange_strong(idle, std::this_thread::get_id()))
        fail("KeyframeSelector: busy with another call (a selector is single-threaded; use one per thread)");
    }
    Claim(const Claim&) = delete;
    Claim& operator=(const Claim&) = delete;
    ~Claim() { owner_ = std::thread::id(); }

   private:
    std::atomic<std::thread::id>& owner_;
  };

  void check_readable() const {
    const auto owner = owner_.load();
    if (owner != std::thread::id() && owner != std::this_thread::get_id())
      fail("KeyframeSelector: busy in another thread (a selector is single-threaded; use one per thread)");
  }

  AnySelector selector_;
  std::optional<std::size_t> last_index_;  ///< the last frame pushed
  std::atomic<std::thread::id> owner_{};
};

py::array_t<double> matx_array(const cv::Matx33d& m) {
  py::array_t<double> out({py::ssize_t{3}, py::ssize_t{3}});
  auto v = out.mutable_unchecked<2>();
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) v(r, c) = m(r, c);
  return out;
}

py::dict stats_dict(const MapStats& s) {
  py::dict d;
  d["frames"] = s.frames;
  d["key_images"] = s.key_images;
  d["min_matches"] = s.min_matches;
  d["max_matches"] = s.max_matches;
  d["mean_matches"] = s.mean_matches;
  d["mean_similarity"] = s.mean_similarity;
  d["quality"] = s.quality;
  return d;
}

QualityForm parse_form(const std::string& form) {
  if (form == "mean_over_pairs") return QualityForm::mean_over_pairs;
  if (form == "paper_literal") return QualityForm::paper_literal;
  fail("quality: form must be 'mean_over_pairs' or 'paper_literal', not '" + form + "'");
}

/// `vmap sweep`: every threshold over `source` in one pass, the paper's table as rows.
py::list sweep(const std::string& source, std::vector<double> taus, const std::string& features, int nfeatures,
               const std::string& model, const std::string& refine_model, const std::string& estimator,
               const std::string& rule, const std::optional<std::string>& camera, std::size_t start,
               std::optional<std::size_t> end, std::size_t stride, double time_offset, bool single_thread,
               const py::object& progress, std::size_t progress_every) {
  const PolicyStack stack = policy_stack(features, nfeatures, model, refine_model, estimator, camera);
  const ProgressHook hook(progress, progress_every);
  const SweepOptions so{.taus = std::move(taus),
                        .rule = parse_option<KeyRule>(rule, "rule", "rule"),
                        .pipelined = !single_thread,
                        .on_frame = [&hook](std::size_t done) { hook(done); }};
  SweepResult r;
  {
    const py::gil_scoped_release unlocked;
    auto src = open_range(source, start, end, stride, time_offset);
    r = sweep_thresholds(src, stack, so, camera_name(stack, OptionNames::keywords()));
  }
  if (r.frames == 0) fail("'" + source + "' gave no frame in the requested range");
  py::list rows;
  for (std::size_t k = 0; k < r.rows.size(); ++k) {
    py::dict row = stats_dict(r.rows[k].stats);
    row["threshold"] = r.rows[k].threshold;
    row["key_frames"] = r.rows[k].key_frames;
    row["best"] = k == r.best;
    rows.append(row);
  }
  return rows;
}

std::string result_repr(const FrameResult& r) {
  std::string out = "<vmap.FrameResult frame " + std::to_string(r.frame_index) + ", S " +
                    (r.exact ? "= " : "<= ") + std::to_string(r.similarity);
  if (r.key_taken) out += ", key image " + std::to_string(r.key_frame.value_or(0));
  return out + " (" + std::string(to_string(r.reason)) + ")>";
}

void bind(py::module_& m) {
  py::class_<FrameResult>(m, "FrameResult", "What KeyframeSelector.push() did with one frame.")
      .def_readonly("frame_index", &FrameResult::frame_index, "the frame's index in its sequence")
      .def_readonly("similarity", &FrameResult::similarity,
                    "S(K, I_j) against the key image that was current when the frame arrived; when `exact` is\n"
                    "False the estimator was skipped and this is the upper bound (< tau)")
      .def_readonly("exact", &FrameResult::exact, "whether `similarity` is S itself (the estimator ran)")
      .def_readonly("raw_matches", &FrameResult::raw_matches, "correspondences before verification")
      .def_readonly("verified_matches", &FrameResult::verified_matches,
                    "inliers (0 if verification failed or was skipped)")
      .def_property_readonly("status", [](const FrameResult& r) { return std::string(to_string(r.status)); },
                             "of the verification (meaningful when `exact`): verified, too few matches, no model or\n"
                             "too few inliers")
      .def_readonly("key_taken", &FrameResult::key_taken, "whether a key image was taken at this frame")
      .def_readonly("key_frame", &FrameResult::key_frame,
                    "the frame that became a key image (this one or the previous one, eq. 6), else None")
      .def_property_readonly("reason", [](const FrameResult& r) { return std::string(to_string(r.reason)); },
                             "why a key image was or was not taken, in words: similar to the key image, first frame,\n"
                             "similarity below tau, match bound below tau (verification skipped) or verification\n"
                             "failed (no F-matrix)")
      .def("__repr__", &result_repr);

  py::class_<KeyImage>(m, "KeyImage", "One key image of a visual map.")
      .def_readonly("frame_index", &KeyImage::frame_index, "position in the input sequence (the frame's index)")
      .def_readonly("name", &KeyImage::name, "source name (file name, '<video>#<index>', 'frame#<index>')")
      .def_readonly("timestamp", &KeyImage::timestamp, "seconds")
      .def_readonly("features", &KeyImage::features, "the features it was compared with")
      .def_property_readonly(
          "image", [](const KeyImage& k) -> py::object { return k.image.empty() ? py::none() : py::object(to_array(k.image)); },
          "the image when the selector keeps images (keep_images=True), else None")
      .def("__repr__", [](const KeyImage& k) {
        return "<vmap.KeyImage frame " + std::to_string(k.frame_index) + " '" + k.name + "'>";
      });

  py::class_<KeyPair>(m, "KeyPair", "The link between key image i and key image i+1.")
      .def_property_readonly("status", [](const KeyPair& p) { return std::string(to_string(p.status)); },
                             "verified, too few matches, no model or too few inliers")
      .def_property_readonly("fundamental", [](const KeyPair& p) { return matx_array(p.fundamental); },
                             "3 x 3 float64 F with x_{i+1}^T F x_i = 0 (zeros unless verified)")
      .def_readonly("matches", &KeyPair::matches, "raw correspondences")
      .def_readonly("inliers", &KeyPair::inliers, "verified matches (f_match of eq. 5)")
      .def_readonly("similarity", &KeyPair::similarity, "S(K_i, K_i+1), eq. 5")
      .def("__repr__", [](const KeyPair& p) {
        return "<vmap.KeyPair " + std::string(to_string(p.status)) + ", " + std::to_string(p.inliers) + " of " +
               std::to_string(p.matches) + " matches, S = " + std::to_string(p.similarity) + ">";
      });

  py::class_<VisualMap>(m, "VisualMap",
                        "The visual map of García-Pintos et al. 2023: the key images chosen from a video of n frames\n"
                        "and, for each consecutive pair, the fundamental matrix that links them, its inlier count and\n"
                        "the similarity (eq. 5). A snapshot: KeyframeSelector.map returns a copy.")
      .def_readonly("frames", &VisualMap::frames, "n: frames the selector saw")
      .def_readonly("keys", &VisualMap::keys, "the key images K_1..K_m (a list of KeyImage)")
      .def_readonly("pairs", &VisualMap::pairs, "pairs[i] links keys[i] and keys[i+1]; m-1 of them (KeyPair)")
      .def_property_readonly("key_frames", &VisualMap::key_indices, "frame indices of the key images, in order")
      .def_property_readonly(
          "fundamentals",
          [](const VisualMap& map) {
            py::list out;
            for (const auto& p : map.pairs) out.append(matx_array(p.fundamental));
            return out;
          },
          "the F-matrices between consecutive key images, 3 x 3 float64 (zeros for an unverified link)")
      .def_property_readonly(
          "similarities",
          [](const VisualMap& map) {
            std::vector<double> out;
            for (const auto& p : map.pairs) out.push_back(p.similarity);
            return out;
          },
          "S(K_i, K_i+1) of the consecutive key images (eq. 5)")
      .def(
          "quality", [](const VisualMap& map, const std::string& form) { return map.quality(parse_form(form)); },
          py::arg("form") = "mean_over_pairs",
          "Eq. 7: Q = 1/2 ((1 - m/n) + mean of S(K_i, K_i+1)). form 'mean_over_pairs' (the default) averages\n"
          "over the m-1 pairs; 'paper_literal' divides their sum by m as the paper prints it. 0 for an empty map.")
      .def(
          "stats", [](const VisualMap& map) { return stats_dict(map.stats()); },
          "The paper's table columns: frames, key_images, min/max/mean_matches (verified matches between\n"
          "consecutive key images, 0 if m < 2), mean_similarity and quality (eq. 7).")
      .def("__len__", [](const VisualMap& map) { return map.keys.size(); })
      .def(
          "__eq__",
          [](const VisualMap& a, const VisualMap& b) {
            // Equal maps have equal files: one comparison of every field the file holds.
            return serialize_map(a) == serialize_map(b);
          },
          py::is_operator())
      .def("__repr__", [](const VisualMap& map) {
        return "<vmap.VisualMap " + std::to_string(map.keys.size()) + " key images of " + std::to_string(map.frames) +
               " frames, quality " + std::to_string(map.quality()) + ">";
      });

  m.def(
      "save_map",
      [](const VisualMap& map, const std::filesystem::path& path) {
        const std::string bytes = serialize_map(map);
        const py::gil_scoped_release unlocked;
        write_file_atomically(path, bytes);
      },
      py::arg("map"), py::arg("path"),
      "Writes the map file (format version 1, keyframe/map_io.hpp) atomically: a temporary file renamed over\n"
      "`path`, so a reader never sees half a file.");

  m.def(
      "load_map",
      [](const std::filesystem::path& path) {
        const py::gil_scoped_release unlocked;
        return load_map(path);
      },
      py::arg("path"),
      "Reads a map file. A missing, unreadable, corrupt or oversized file raises vmap.Error naming it.");

  const SelectorOptions defaults;
  py::class_<PySelector>(m, "KeyframeSelector",
                         "Streaming key-image selection (García-Pintos et al. 2023, Algorithm 1 / eq. 6): a new key\n"
                         "image when the similarity S (eq. 5: F-matrix inliers / matches) of a frame to the current\n"
                         "key image falls below tau. The descriptor (orb, akaze, sift, xfeat, xfeat-dense,\n"
                         "xfeat-star), the matcher and the F-matrix method (magsac, ransac, lmeds, 8point) are\n"
                         "chosen as `vmap build` chooses them; camera is a calibration file whose model undistorts\n"
                         "the keypoints first. rule 'previous' takes I_{j-1} as the new key image (eq. 6),\n"
                         "'current' takes I_j (Algorithm 1 as printed). skip_by_upper_bound skips the estimator\n"
                         "when the raw matches already bound S below tau (never changes the key images);\n"
                         "keep_images keeps each key image's pixels in the map.")
      .def(py::init([](const std::string& features, int nfeatures, const std::string& model,
                       const std::string& refine_model, const std::string& estimator,
                       const std::optional<std::string>& camera, double tau, const std::string& rule,
                       bool skip_by_upper_bound, bool keep_images) {
             const SelectorOptions options{.tau = tau,
                                           .rule = parse_option<KeyRule>(rule, "rule", "rule"),
                                           .skip_by_upper_bound = skip_by_upper_bound,
                                           .keep_images = keep_images};
             return std::make_unique<PySelector>(
                 policy_stack(features, nfeatures, model, refine_model, estimator, camera), options);
           }),
           py::arg("features") = "orb", py::kw_only(), py::arg("nfeatures") = 1000, py::arg("model") = "",
           py::arg("refine_model") = "", py::arg("estimator") = "magsac", py::arg("camera") = py::none(),
           py::arg("tau") = defaults.tau, py::arg("rule") = "previous",
           py::arg("skip_by_upper_bound") = defaults.skip_by_upper_bound,
           py::arg("keep_images") = defaults.keep_images)
      .def("push", &PySelector::push, py::arg("image"), py::arg("timestamp") = py::none(), py::arg("name") = py::none(),
           "Pushes one frame (a uint8/uint16 array, read in place) and returns what was done with it\n"
           "(FrameResult). Its index follows the last frame pushed; timestamp defaults to the index and name\n"
           "to 'frame#<index>'.")
      .def("push_frames", &PySelector::push_frames, py::arg("source"), py::kw_only(), py::arg("start") = 0,
           py::arg("end") = py::none(), py::arg("stride") = 1, py::arg("time_offset") = 0.0,
           py::arg("single_thread") = false, py::arg("progress") = py::none(), py::arg("progress_every") = 50,
           "Pushes every frame of a video, image folder, image list, TUM rgb.txt or EuRoC folder, decoded to\n"
           "grey and read in C++ with the GIL released (decoding and extraction on other threads unless\n"
           "single_thread), exactly as `vmap build` does; frames keep the source's indices (start, end, stride\n"
           "as vmap.frames), so start must follow the frames already pushed. progress(frames_done) is called\n"
           "every progress_every frames with the GIL held (Ctrl-C stops the run there; the frames pushed\n"
           "so far stay in the map). Returns the FrameResult of every frame.")
      .def_property_readonly(
          "map", [](const PySelector& s) { return s.map(); },
          "The visual map so far (a VisualMap copy: later pushes do not change it).")
      .def("save_map", &PySelector::save_map, py::arg("path"),
           "Writes the map so far to `path` atomically (as vmap.save_map).")
      .def("reset", &PySelector::reset, "Starts a new sequence: an empty map, the next frame is K_1.")
      .def_property_readonly("tau", [](const PySelector& s) { return s.options().tau; },
                             "a new key image is taken when S(K_i, I_j) < tau; in (0, 1]")
      .def_property_readonly(
          "rule", [](const PySelector& s) { return std::string(to_string(s.options().rule)); },
          "previous (eq. 6: I_{j-1} becomes the key image) or current (Algorithm 1: I_j)")
      .def_property_readonly(
          "features", [](const PySelector& s) { return std::string(to_string(s.stack().descriptor)); },
          "the descriptor's name")
      .def_property_readonly(
          "estimator", [](const PySelector& s) { return std::string(to_string(s.stack().method)); },
          "the F-matrix method: magsac, ransac, lmeds or 8point")
      .def("__repr__", [](const PySelector& s) {
        return "<vmap.KeyframeSelector " + std::string(to_string(s.stack().descriptor)) + " + mutual NN + " +
               std::string(to_string(s.stack().method)) + ", tau " + std::to_string(s.options().tau) + ", " +
               std::to_string(s.map().keys.size()) + " key images>";
      });

  m.def("sweep", &sweep, py::arg("source"), py::arg("taus") = SweepOptions{}.taus, py::kw_only(),
        py::arg("features") = "orb", py::arg("nfeatures") = 1000, py::arg("model") = "", py::arg("refine_model") = "",
        py::arg("estimator") = "magsac", py::arg("rule") = "previous", py::arg("camera") = py::none(),
        py::arg("start") = 0, py::arg("end") = py::none(), py::arg("stride") = 1, py::arg("time_offset") = 0.0,
        py::arg("single_thread") = false, py::arg("progress") = py::none(), py::arg("progress_every") = 50,
        "Threshold sweep (García-Pintos et al. 2023, the tables of sec. 4), as `vmap sweep`: the source's\n"
        "frames selected at every tau in one pass (features extracted once, pair scores shared), with the GIL\n"
        "released. Returns one dict per tau, in order, with the columns of `vmap sweep --json`: threshold,\n"
        "frames, key_images, min_matches, max_matches, mean_matches (verified matches between consecutive key\n"
        "images), quality (eq. 7), key_frames, plus mean_similarity and best (the highest quality, the first\n"
        "of equals). progress(frames_done) as in KeyframeSelector.push_frames.");
}

const RegisterPart part{order_keyframes, &bind};

}  // namespace
}  // namespace vmap::python
