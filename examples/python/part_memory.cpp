// vmap.VisualMemory: a visual memory (include/vmap/memory) in RAM, in a memory store
// (memory/store.hpp: SQLite, synced at every key image, bounded in RAM, several sessions)
// or read from a .vmem file. The memory is built with the command line's policy stacks
// (examples/common/memory_cli.hpp) and records its stack in the store the same way, so a
// memory written from Python is read by `vmap memory ...` and the other way round.

#include "bindings.hpp"

#include "common/keyframe_cli.hpp"
#include "common/memory_cli.hpp"
#include "common/memory_export.hpp"

#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace vmap::python {
namespace {

namespace ex = vmap::examples;
namespace fs = std::filesystem;

/// What push_frames did.
struct PushSummary {
  std::size_t pushed = 0;
  std::size_t new_keys = 0;
  std::vector<LoopEdge> loops;
  double seconds = 0.0;
};

/// The memory behind the Python object, whatever its policy stack: one MemoryOf<D, M, E>
/// per descriptor type (as the command line instantiates them), erased here so that
/// Python sees one class. Every call goes to the concrete memory; nothing per feature
/// crosses this interface.
class MemoryHandle {
 public:
  virtual ~MemoryHandle() = default;
  virtual MemoryStep push(const cv::Mat& image, std::optional<double> timestamp, const std::optional<std::string>& name,
                          const OdometryPose& pose) = 0;
  virtual PushSummary push_frames(FrameSource& src, const std::optional<ex::FramePoses>& poses,
                                  const std::function<void(std::size_t)>& on_frame) = 0;
  virtual MemoryLocalization localize(const cv::Mat& image, const PlaceDecisionOptions& decision) = 0;
  [[nodiscard]] virtual PlaceDecisionOptions decision() const = 0;
  virtual void sync() = 0;
  virtual void close() = 0;
  virtual void start_session() = 0;
  virtual void save(const fs::path& file, std::optional<ImageStorage> images) const = 0;
  [[nodiscard]] virtual std::vector<std::string> export_to(const fs::path& dir) const = 0;
  [[nodiscard]] virtual const VisualMap& map() const = 0;
  [[nodiscard]] virtual const std::vector<LoopEdge>& loops() const = 0;
  [[nodiscard]] virtual const std::vector<MemorySession>& sessions() const = 0;
  [[nodiscard]] virtual const std::vector<OdometryPose>& poses() const = 0;
  [[nodiscard]] virtual std::size_t session_of(std::size_t key) const = 0;
  [[nodiscard]] virtual std::optional<std::size_t> last_frame_index() const = 0;
  [[nodiscard]] virtual bool stationary() const = 0;
  [[nodiscard]] virtual std::size_t vocabulary_words() const = 0;
  [[nodiscard]] virtual Features key_features(std::uint32_t key) const = 0;
  [[nodiscard]] virtual std::vector<GraphNeighbour> neighbours(std::uint32_t key) const = 0;
};

template <class Memory>
class MemoryModel final : public MemoryHandle {
 public:
  /// A memory in RAM (no store), or one held by `store` (synced at every key image).
  MemoryModel(Memory memory, std::optional<MemoryStore> store, std::size_t working_memory, bool read_only)
      : memory_(std::move(memory)), store_(std::move(store)), read_only_(read_only) {
    if (store_ && !read_only_ && working_memory > 0) store_->bound(memory_, working_memory);
  }

  MemoryStep push(const cv::Mat& image, std::optional<double> timestamp, const std::optional<std::string>& name,
                  const OdometryPose& pose) override {
    writable();
    // A named frame is the bare image the memory would make (index: frames pushed so
    // far), with its name kept in the key images (as a frame source's file name is).
    auto step = name ? memory_.push(Frame{image, memory_.frames(), *name,
                                          timestamp.value_or(static_cast<double>(memory_.frames()))},
                                    pose)
                     : memory_.push(image, timestamp, pose);
    // As the command line's stream_into: a key image or a loop edge is on disk before
    // push() returns, so a program killed after it resumes from there.
    if (store_ && (step.new_key || !step.loops.empty())) store_->sync(memory_);
    return step;
  }

  PushSummary push_frames(FrameSource& src, const std::optional<ex::FramePoses>& poses,
                          const std::function<void(std::size_t)>& on_frame) override {
    writable();
    const std::size_t keys_before = memory_.key_images();
    PushSummary s;
    const auto t0 = std::chrono::steady_clock::now();
    if (store_) {
      // The command line's loop itself (sync at every key image and loop edge, and after
      // the last frame), on a writer that borrows the store and memory for the call.
      ex::MemoryWriter<Memory> w{std::move(*store_), std::move(memory_)};
      struct Restore {
        MemoryModel* self;
        ex::MemoryWriter<Memory>* w;
        ~Restore() {
          self->store_.emplace(std::move(w->store));
          self->memory_ = std::move(w->memory);
        }
      } restore{this, &w};
      auto r = ex::stream_into(w, src, 0, 0, poses, [&](const Memory& m) { on_frame(m.frames()); });
      s.pushed = r.pushed;
      s.loops = std::move(r.loops);
    } else {
      while (auto f = src.next()) {
        auto step = memory_.push(*f, poses ? (*poses)(*f) : OdometryPose{});
        ++s.pushed;
        s.loops.insert(s.loops.end(), step.loops.begin(), step.loops.end());
        on_frame(memory_.frames());
      }
    }
    s.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    s.new_keys = memory_.key_images() - keys_before;
    return s;
  }

  MemoryLocalization localize(const cv::Mat& image, const PlaceDecisionOptions& decision) override {
    return memory_.localize(image, &decision);
  }
  [[nodiscard]] PlaceDecisionOptions decision() const override { return memory_.options().loops.decision; }

  void sync() override {
    if (!store_ || read_only_) return;
    // Committed when sync() returns (a reader opened next sees it); push() leaves its
    // syncs to the store's writer thread instead, so that mapping never waits for the disk.
    store_->sync(memory_);
    store_->flush();
  }

  void close() override {
    if (!store_) return;
    if (!read_only_) {
      store_->sync(memory_);
      store_->checkpoint();
    }
    store_.reset();
    closed_ = true;
  }

  void start_session() override {
    writable();
    memory_.start_session();
    if (store_) store_->sync(memory_);
  }

  void save(const fs::path& file, std::optional<ImageStorage> images) const override { memory_.save(file, images); }
  [[nodiscard]] std::vector<std::string> export_to(const fs::path& dir) const override {
    std::error_code ec;
    fs::create_directories(dir, ec);
    if (ec) fail("export: cannot create the folder '" + dir.string() + "': " + ec.message());
    return ex::export_memory(memory_, dir);
  }
  [[nodiscard]] const VisualMap& map() const override { return memory_.map(); }
  [[nodiscard]] const std::vector<LoopEdge>& loops() const override { return memory_.loops(); }
  [[nodiscard]] const std::vector<MemorySession>& sessions() const override { return memory_.sessions(); }
  [[nodiscard]] const std::vector<OdometryPose>& poses() const override { return memory_.poses(); }
  [[nodiscard]] std::size_t session_of(std::size_t key) const override { return memory_.session_of(key); }
  [[nodiscard]] std::optional<std::size_t> last_frame_index() const override { return memory_.last_frame_index(); }
  [[nodiscard]] bool stationary() const override { return memory_.stationary(); }
  [[nodiscard]] std::size_t vocabulary_words() const override { return memory_.vocabulary().size(); }
  [[nodiscard]] Features key_features(std::uint32_t key) const override { return memory_.key_features(key); }
  [[nodiscard]] std::vector<GraphNeighbour> neighbours(std::uint32_t key) const override {
    return memory_.neighbours(key);
  }

 private:
  void writable() const {
    if (closed_) fail("the memory was closed");
    if (read_only_) fail("the memory was opened read-only (VisualMemory.open(..., read_only=True)): it cannot be changed");
  }

  Memory memory_;
  std::optional<MemoryStore> store_;
  bool read_only_ = false;
  bool closed_ = false;
};

/// The Python object: the erased memory, where it lives, and the stack it was built with.
class PyMemory {
 public:
  PyMemory(std::unique_ptr<MemoryHandle> h, ex::MemoryStack stack, std::optional<fs::path> path, bool read_only)
      : h_(std::move(h)), stack_(std::move(stack)), path_(std::move(path)), read_only_(read_only) {}

  MemoryHandle& operator*() const { return *h_; }
  MemoryHandle* operator->() const { return h_.get(); }
  [[nodiscard]] const ex::MemoryStack& stack() const noexcept { return stack_; }
  [[nodiscard]] const std::optional<fs::path>& path() const noexcept { return path_; }
  [[nodiscard]] bool read_only() const noexcept { return read_only_; }

 private:
  std::unique_ptr<MemoryHandle> h_;
  ex::MemoryStack stack_;
  std::optional<fs::path> path_;
  bool read_only_ = false;
};

ex::MemoryStack stack_of(const std::string& features, int nfeatures, const std::string& model,
                         const std::string& refine_model, const std::string& estimator,
                         const std::optional<std::string>& camera) {
  return ex::stack_of_args({features, nfeatures, model, refine_model}, estimator, camera.value_or(""));
}

ex::NewMemory new_options(double tau, const std::string& rule, const std::string& images,
                          const std::optional<std::string>& vocabulary, std::size_t vocabulary_after,
                          double min_confidence) {
  ex::NewMemory n;
  n.tau = tau;
  n.rule = ex::parse_rule(rule);
  n.images = images;
  n.vocabulary = vocabulary.value_or("");
  n.vocabulary_after = vocabulary_after;
  n.min_confidence = min_confidence;
  return n;
}

/// A new memory with the stack's policies, in RAM or in a new store at `path`.
PyMemory make_memory(const ex::MemoryStack& stack, const ex::NewMemory& n, const std::optional<fs::path>& path,
                     bool force, std::size_t working_memory) {
  if (path) ex::prepare_memory_output(*path, "path", {}, false, force);
  std::unique_ptr<MemoryHandle> h;
  ex::with_stack(stack, [&](auto descriptor, auto matcher, auto estimator) -> int {
    auto mem = ex::new_memory(n, std::move(descriptor), std::move(matcher), std::move(estimator));
    using Memory = decltype(mem);
    if (!path) {
      h = std::make_unique<MemoryModel<Memory>>(std::move(mem), std::nullopt, 0, false);
      return 0;
    }
    auto w = ex::create_memory(*path, force, std::move(mem), stack);
    h = std::make_unique<MemoryModel<Memory>>(std::move(w.memory), std::move(w.store), working_memory, false);
    return 0;
  });
  return PyMemory(std::move(h), stack, path, false);
}

/// An existing memory: a store (continued, or read while another program writes it) or a
/// .vmem file (read into RAM; save() writes it back).
PyMemory open_memory(const std::string& path, bool read_only, bool new_session, std::size_t working_memory) {
  const fs::path file = ex::memory_file(path);
  ex::check_input_file(file, "path");
  ex::check_memory_file(file);
  const bool is_store = ex::memory_file_kind(file) == ex::MemoryFileKind::store;
  if (new_session && read_only) fail("open: new_session and read_only conflict (a new session writes the memory)");
  const ex::MemoryStack stack = ex::memory_stack(file, "path");
  std::unique_ptr<MemoryHandle> h;
  ex::with_stack(stack, [&](auto descriptor, auto matcher, auto estimator) -> int {
    using Memory = ex::MemoryOf<decltype(descriptor), decltype(matcher), decltype(estimator)>;
    if (!is_store) {
      auto mem = ex::load_memory_with(file, "path", true, std::move(descriptor), std::move(matcher), std::move(estimator));
      if (new_session) mem.start_session();
      h = std::make_unique<MemoryModel<Memory>>(std::move(mem), std::nullopt, 0, read_only);
      return 0;
    }
    auto store = MemoryStore::open(file, read_only ? sqlite::Access::read : sqlite::Access::write);
    if (!store.synced())
      fail("memory '" + file.string() + "' holds nothing yet (its first run stopped before its first key image was written)");
    auto mem = working_memory > 0
                   ? store.load_bounded<Memory>(working_memory, std::move(descriptor), std::move(matcher),
                                                std::move(estimator), InlierRatio{})
                   : store.load<Memory>(std::move(descriptor), std::move(matcher), std::move(estimator), InlierRatio{});
    if (new_session) mem.start_session();
    auto model = std::make_unique<MemoryModel<Memory>>(std::move(mem), std::move(store), working_memory, read_only);
    if (new_session) model->sync();
    h = std::move(model);
    return 0;
  });
  return PyMemory(std::move(h), stack, file, read_only);
}

/// None, (x, y, theta) for SE(2), or a 4 x 4 / 3 x 4 [R | t] for SE(3).
OdometryPose pose_of(const py::object& pose) {
  if (pose.is_none()) return {};
  const auto a = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(pose);
  if (!a) fail("pose: expected None, (x, y, theta) or a 4 x 4 / 3 x 4 matrix [R | t]");
  if (a.ndim() == 1 && a.shape(0) == 3) return Pose2(a.at(0), a.at(1), a.at(2));
  if (a.ndim() == 2 && (a.shape(0) == 3 || a.shape(0) == 4) && a.shape(1) == 4) {
    cv::Matx33d R;
    cv::Vec3d t;
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) R(r, c) = a.at(r, c);
      t[r] = a.at(r, 3);
    }
    return cv::Affine3d(R, t);
  }
  fail("pose: an array of shape " + std::string(py::str(a.attr("shape"))) +
       "; expected (x, y, theta) or a 4 x 4 / 3 x 4 matrix [R | t]");
}

py::object pose_object(const OdometryPose& p) {
  if (const auto* p2 = std::get_if<Pose2>(&p)) return py::make_tuple(p2->x(), p2->y(), p2->theta());
  if (const auto* p3 = std::get_if<cv::Affine3d>(&p)) return to_array(cv::Mat(cv::Matx44d(p3->matrix), true));
  return py::none();
}

std::optional<ImageStorage> storage_of(const std::optional<std::string>& name) {
  if (!name) return std::nullopt;
  if (*name == "none") return ImageStorage::none;
  if (*name == "png") return ImageStorage::png;
  if (*name == "jpeg") return ImageStorage::jpeg;
  fail("images: unknown storage '" + *name + "' (choose none, png or jpeg)");
}

py::array matx_array(const cv::Matx33d& m) { return to_array(cv::Mat(m, true)); }

void bind(py::module_& m) {
  py::class_<PlaceEvidence>(m, "PlaceEvidence", "What a place decision weighed (lcd/place_decision.hpp).")
      .def_readonly("matches", &PlaceEvidence::matches)
      .def_readonly("inliers", &PlaceEvidence::inliers)
      .def_readonly("inlier_ratio", &PlaceEvidence::inlier_ratio)
      .def_readonly("significance", &PlaceEvidence::significance)
      .def_readonly("spread", &PlaceEvidence::spread)
      .def_readonly("bow_score", &PlaceEvidence::bow_score)
      .def_property_readonly("model", [](const PlaceEvidence& e) { return std::string(to_string(e.model)); });

  py::class_<PlaceLink>(m, "PlaceLink", "A verified match between a query (or a newer key image) and a key image.")
      .def_readonly("key", &PlaceLink::key, "the matched key image")
      .def_readonly("bow_score", &PlaceLink::bow_score, "its bag-of-words rank score, in [0, 1]")
      .def_property_readonly("status", [](const PlaceLink& l) { return std::string(to_string(l.status)); },
                             "the F-matrix verification's status (verified, too_few_matches, ...)")
      .def_property_readonly("fundamental", [](const PlaceLink& l) { return matx_array(l.fundamental); },
                             "3 x 3 F with x_query^T F x_key = 0 (zeros unless verified)")
      .def_readonly("matches", &PlaceLink::matches, "raw correspondences")
      .def_readonly("inliers", &PlaceLink::inliers, "F-matrix inliers")
      .def_readonly("similarity", &PlaceLink::similarity, "eq. 5")
      .def_readonly("confidence", &PlaceLink::confidence, "the place decision's confidence, in [0, 1]")
      .def("__repr__", [](const PlaceLink& l) {
        return "<vmap.PlaceLink key " + std::to_string(l.key) + ", " + std::string(to_string(l.status)) + ", " +
               std::to_string(l.inliers) + "/" + std::to_string(l.matches) + " inliers, confidence " +
               std::to_string(l.confidence) + ">";
      });

  py::class_<LoopEdge>(m, "LoopEdge", "A loop closure: key image `key_from` (the newer) revisits key image `key_to`.")
      .def_readonly("key_from", &LoopEdge::from)
      .def_property_readonly("key_to", [](const LoopEdge& e) { return e.link.key; })
      .def_readonly("link", &LoopEdge::link, "the verified match (PlaceLink)")
      .def("__repr__", [](const LoopEdge& e) {
        return "<vmap.LoopEdge " + std::to_string(e.from) + " -> " + std::to_string(e.link.key) + ", " +
               std::to_string(e.link.inliers) + " inliers>";
      });

  py::class_<RelativePose>(m, "RelativePose", "The query's camera relative to a key image's: X_key = R X_query + t, |t| = 1.")
      .def_property_readonly("rotation", [](const RelativePose& p) { return matx_array(p.rotation); }, "3 x 3 R")
      .def_property_readonly("translation", [](const RelativePose& p) {
        return to_array(cv::Mat(cv::Vec3d(p.translation), true).reshape(1, 1));
      }, "the unit direction of t (3,)")
      .def_property_readonly("rotation_degrees", [](const RelativePose& p) { return ex::rotation_degrees(p.rotation); })
      .def_readonly("points_in_front", &RelativePose::points_in_front);

  py::class_<MemoryLocalization>(m, "Localization",
                                 "localize()'s answer: status 'accepted', or why not ('unknown place', 'ambiguous',\n"
                                 "'too little evidence'), with the verified key images behind it.")
      .def_property_readonly("status", [](const MemoryLocalization& l) { return std::string(to_string(l.status)); })
      .def_readonly("reason", &MemoryLocalization::reason)
      .def_readonly("confidence", &MemoryLocalization::confidence, "of the best key image, in [0, 1]")
      .def_readonly("evidence", &MemoryLocalization::evidence)
      .def_property_readonly("ok", &MemoryLocalization::ok, "whether the place was accepted")
      .def_property_readonly("key", [](const MemoryLocalization& l) -> std::optional<std::uint32_t> {
        if (const auto* b = l.best()) return b->key;
        return std::nullopt;
      }, "the accepted key image, or None")
      .def_readonly("matches", &MemoryLocalization::matches, "every verified key image, most confident first")
      .def_readonly("verified_candidates", &MemoryLocalization::verified_candidates)
      .def_readonly("relative_pose", &MemoryLocalization::relative_pose,
                    "the query's pose relative to the best key image when the memory has a camera, else None")
      .def("__bool__", &MemoryLocalization::ok)
      .def("__repr__", [](const MemoryLocalization& l) {
        return "<vmap.Localization " + std::string(to_string(l.status)) +
               (l.best() ? " key " + std::to_string(l.best()->key) : std::string()) + ": " + l.reason + ">";
      });

  py::class_<MemoryStep>(m, "MemoryStep", "What push() did: the selector's answer, the key image added, the loops found.")
      .def_property_readonly("frame_index", [](const MemoryStep& s) { return s.frame.frame_index; })
      .def_property_readonly("similarity", [](const MemoryStep& s) { return s.frame.similarity; },
                             "S(K, I_j) against the current key image (eq. 5)")
      .def_property_readonly("key_taken", [](const MemoryStep& s) { return s.frame.key_taken; })
      .def_property_readonly("key_frame", [](const MemoryStep& s) { return s.frame.key_frame; },
                             "the frame that became a key image (j-1 or j), or None")
      .def_readonly("new_key", &MemoryStep::new_key, "index of the key image added, or None")
      .def_readonly("loops", &MemoryStep::loops, "loop edges found in this step");

  py::class_<PyMemory>(m, "VisualMemory",
                       "A visual memory: key images of a camera stream (eq. 5-6), loop closures between them and\n"
                       "localization of new images, in RAM (VisualMemory(...)), in a memory store written key image\n"
                       "by key image (VisualMemory.create / open) or read from a .vmem file (open).\n"
                       "The policy stack (features, estimator, camera) is the command line's, recorded in the store.")
      .def(py::init([](const std::string& features, int nfeatures, const std::string& model,
                       const std::string& refine_model, const std::string& estimator,
                       const std::optional<std::string>& camera, double tau, const std::string& rule,
                       const std::string& images, const std::optional<std::string>& vocabulary,
                       std::size_t vocabulary_after, double min_confidence) {
             return make_memory(stack_of(features, nfeatures, model, refine_model, estimator, camera),
                                new_options(tau, rule, images, vocabulary, vocabulary_after, min_confidence),
                                std::nullopt, false, 0);
           }),
           py::arg("features") = "orb", py::kw_only(), py::arg("nfeatures") = 1000, py::arg("model") = "",
           py::arg("refine_model") = "", py::arg("estimator") = "magsac", py::arg("camera") = py::none(),
           py::arg("tau") = 0.3, py::arg("rule") = "previous", py::arg("images") = "none",
           py::arg("vocabulary") = py::none(), py::arg("vocabulary_after") = MemoryOptions{}.vocabulary_after,
           py::arg("min_confidence") = PlaceDecisionOptions{}.min_confidence,
           "A new memory in RAM. features: orb, akaze, sift, xfeat, xfeat-dense, xfeat-star (model: the ONNX\n"
           "file); estimator: magsac, ransac, lmeds, 8point; camera: a calibration file (F on undistorted\n"
           "points and a relative pose per localization); tau: eq. 6's threshold; rule: previous (eq. 6) or\n"
           "current (Algorithm 1); images: none, png or jpeg (key images' pixels kept); vocabulary: a\n"
           "vocabulary file, else one is learned from the first vocabulary_after key images;\n"
           "min_confidence: the place decision's threshold.")
      .def_static(
          "create",
          [](const std::string& path, const std::string& features, int nfeatures, const std::string& model,
             const std::string& refine_model, const std::string& estimator, const std::optional<std::string>& camera,
             double tau, const std::string& rule, const std::string& images, const std::optional<std::string>& vocabulary,
             std::size_t vocabulary_after, double min_confidence, bool force, std::size_t working_memory) {
            return make_memory(stack_of(features, nfeatures, model, refine_model, estimator, camera),
                               new_options(tau, rule, images, vocabulary, vocabulary_after, min_confidence),
                               ex::memory_file(path), force, working_memory);
          },
          py::arg("path"), py::kw_only(), py::arg("features") = "orb", py::arg("nfeatures") = 1000,
          py::arg("model") = "", py::arg("refine_model") = "", py::arg("estimator") = "magsac",
          py::arg("camera") = py::none(), py::arg("tau") = 0.3, py::arg("rule") = "previous",
          py::arg("images") = "none", py::arg("vocabulary") = py::none(),
          py::arg("vocabulary_after") = MemoryOptions{}.vocabulary_after,
          py::arg("min_confidence") = PlaceDecisionOptions{}.min_confidence, py::arg("force") = false,
          py::arg("working_memory") = ex::default_working_memory,
          "A new memory store at `path` (a folder means path/memory.vmdb), synced at every key image and loop\n"
          "edge, holding the features of its `working_memory` newest key images in RAM (0: all). An existing\n"
          "memory is replaced only with force=True; any other existing file is refused.")
      .def_static("open", &open_memory, py::arg("path"), py::kw_only(), py::arg("read_only") = false,
                  py::arg("new_session") = false, py::arg("working_memory") = ex::default_working_memory,
                  "An existing memory: a store continued where it stopped (new_session=True: a new run), or\n"
                  "read while another program writes it (read_only=True: a snapshot; push refused); or a .vmem\n"
                  "file, read into RAM. Its policy stack is the one it records.")
      .def(
          "push",
          [](PyMemory& self, const py::array& image, std::optional<double> timestamp,
             const std::optional<std::string>& name, const py::object& pose) {
            const cv::Mat view = image_view(image, "image");
            const OdometryPose p = pose_of(pose);
            py::gil_scoped_release unlocked;
            return self->push(view, timestamp, name, p);
          },
          py::arg("image"), py::kw_only(), py::arg("timestamp") = py::none(), py::arg("name") = py::none(),
          py::arg("pose") = py::none(),
          "Pushes one frame (uint8 grey or BGR, read in place). timestamp defaults to the frame's index\n"
          "(frames pushed so far), name to 'frame#<index>'; pose: None, (x, y, theta) or [R | t].\n"
          "A key image or loop edge is in the store when push returns.")
      .def(
          "push_frames",
          [](PyMemory& self, const std::string& source, bool grey, std::size_t start, std::optional<std::size_t> end,
             std::size_t stride, const std::optional<std::string>& poses, const py::object& progress,
             std::size_t progress_every) {
            FrameSourceOptions so;
            so.grey = grey;
            so.start = start;
            if (end) so.end = *end;
            so.stride = stride;
            auto src = FrameSource::open(source, so);
            std::optional<ex::FramePoses> frame_poses;
            if (poses) frame_poses.emplace(*poses, src);
            const ProgressHook hook(progress, progress_every);
            const std::function<void(std::size_t)> on_frame = [&](std::size_t frames) { hook(frames); };
            py::gil_scoped_release unlocked;
            return self->push_frames(src, frame_poses, on_frame);
          },
          py::arg("source"), py::kw_only(), py::arg("grey") = true, py::arg("start") = 0, py::arg("end") = py::none(),
          py::arg("stride") = 1, py::arg("poses") = py::none(), py::arg("progress") = py::none(),
          py::arg("progress_every") = 50,
          "Pushes every frame of a source (as vmap.frames reads it) in C++, with the frame's pose from a TUM\n"
          "or KITTI pose file when `poses` is given; progress(frames) is called every progress_every frames\n"
          "with the GIL held (Ctrl-C, or an exception it raises, stops the run there; what was pushed stays).\n"
          "Returns {pushed, new_keys, loops, seconds}.")
      .def(
          "localize",
          [](PyMemory& self, const py::array& image, std::optional<double> min_confidence) {
            const cv::Mat view = image_view(image, "image");
            PlaceDecisionOptions d = self->decision();
            if (min_confidence) d.min_confidence = *min_confidence;
            py::gil_scoped_release unlocked;
            return self->localize(view, d);
          },
          py::arg("image"), py::kw_only(), py::arg("min_confidence") = py::none(),
          "Where the image was taken: the place decision over the best key images by bag of words,\n"
          "verified by the F-matrix (Localization; status 'accepted' or why not).")
      .def("sync", [](PyMemory& self) { py::gil_scoped_release unlocked; self->sync(); },
           "Writes what the memory made since the last sync into its store and waits until it is committed\n"
           "(a no-op in RAM). push() syncs at every key image and loop edge without waiting.")
      .def("close", [](PyMemory& self) { py::gil_scoped_release unlocked; self->close(); },
           "Syncs and closes the store; the memory is read-only afterwards.")
      .def("__enter__", [](PyMemory& self) -> PyMemory& { return self; })
      .def("__exit__", [](PyMemory& self, const py::object&, const py::object&, const py::object&) { self->close(); })
      .def("start_session", [](PyMemory& self) { self->start_session(); },
           "Starts a new session (a new run of the robot: its first key image is not linked to the last).")
      .def(
          "save", [](const PyMemory& self, const std::string& path, const std::optional<std::string>& images) {
            py::gil_scoped_release unlocked;
            self->save(path, storage_of(images));
          },
          py::arg("path"), py::kw_only(), py::arg("images") = py::none(),
          "Writes the whole memory as one .vmem file, atomically (images: none, png, jpeg; default: as kept).")
      .def(
          "export", [](const PyMemory& self, const std::string& folder) { return self->export_to(folder); },
          py::arg("folder"),
          "Writes key_images.txt, loops.txt and, with poses, key_images.tum and loops.g2o into `folder`\n"
          "(each atomically); returns the names written.")
      .def_property_readonly("path", [](const PyMemory& self) -> py::object {
        return self.path() ? py::object(py::str(self.path()->string())) : py::object(py::none());
      })
      .def_property_readonly("read_only", &PyMemory::read_only)
      .def_property_readonly("stack", [](const PyMemory& self) { return ex::stack_json(self.stack()).dump(); },
                             "the policy stack, as the JSON the store records")
      .def_property_readonly("frames", [](const PyMemory& self) { return self->map().frames; })
      .def_property_readonly("key_images", [](const PyMemory& self) { return self->map().keys.size(); })
      .def_property_readonly("last_frame_index", [](const PyMemory& self) { return self->last_frame_index(); })
      .def_property_readonly("stationary", [](const PyMemory& self) { return self->stationary(); },
                             "whether the camera never left its place (no key image is a revisit)")
      .def_property_readonly("vocabulary_words", [](const PyMemory& self) { return self->vocabulary_words(); },
                             "0 until the vocabulary is learned")
      .def_property_readonly("loops", [](const PyMemory& self) { return self->loops(); })
      .def_property_readonly(
          "sessions",
          [](const PyMemory& self) {
            py::list out;
            for (const auto& s : self->sessions()) {
              py::dict d;
              d["first_key"] = s.first_key;
              d["first_frame"] = s.first_frame;
              out.append(d);
            }
            return out;
          },
          "one dict per session: first_key, first_frame")
      .def_property_readonly(
          "keys",
          [](const PyMemory& self) {
            py::list out;
            const auto& keys = self->map().keys;
            for (std::size_t k = 0; k < keys.size(); ++k) {
              py::dict d;
              d["key"] = k;
              d["frame_index"] = keys[k].frame_index;
              d["name"] = keys[k].name;
              d["timestamp"] = keys[k].timestamp;
              d["session"] = self->session_of(k);
              d["pose"] = pose_object(self->poses()[k]);
              out.append(d);
            }
            return out;
          },
          "one dict per key image: key, frame_index, name, timestamp, session, pose")
      .def(
          "key_image",
          [](const PyMemory& self, std::size_t key) -> py::object {
            const auto& keys = self->map().keys;
            if (key >= keys.size()) fail("key_image: no key image " + std::to_string(key) + " (the memory has " +
                                         std::to_string(keys.size()) + ")");
            if (keys[key].image.empty()) return py::none();
            return to_array(keys[key].image);
          },
          py::arg("key"), "The key image's pixels when the memory keeps them (images='png' or 'jpeg'), else None.")
      .def(
          "key_features",
          [](const PyMemory& self, std::size_t key) {
            if (key >= self->map().keys.size())
              fail("key_features: no key image " + std::to_string(key) + " (the memory has " +
                   std::to_string(self->map().keys.size()) + ")");
            return self->key_features(static_cast<std::uint32_t>(key));
          },
          py::arg("key"), "The key image's features (read from the store when outside the working memory).")
      .def(
          "neighbours",
          [](const PyMemory& self, std::size_t key) {
            if (key >= self->map().keys.size())
              fail("neighbours: no key image " + std::to_string(key) + " (the memory has " +
                   std::to_string(self->map().keys.size()) + ")");
            py::list out;
            for (const auto& n : self->neighbours(static_cast<std::uint32_t>(key)))
              out.append(py::make_tuple(n.key, n.kind == GraphNeighbour::Kind::link ? "link" : "loop"));
            return out;
          },
          py::arg("key"), "The key image's neighbours in the memory's graph, as (key, 'link' or 'loop').")
      .def("__repr__", [](const PyMemory& self) {
        return "<vmap.VisualMemory " + std::to_string(self->map().frames) + " frames, " +
               std::to_string(self->map().keys.size()) + " key images, " + std::to_string(self->loops().size()) +
               " loop edges (" + ex::stack_text(self.stack()) + ")" +
               (self.path() ? ", " + self.path()->string() : std::string(", in RAM")) + ">";
      });

  py::class_<PushSummary>(m, "PushSummary", "What push_frames did.")
      .def_readonly("pushed", &PushSummary::pushed, "frames pushed")
      .def_readonly("new_keys", &PushSummary::new_keys, "key images added")
      .def_readonly("loops", &PushSummary::loops, "loop edges found")
      .def_readonly("seconds", &PushSummary::seconds, "wall time of the call");
}

const RegisterPart part{order_memory, &bind};

}  // namespace
}  // namespace vmap::python
