// vmap.VisualMemory: a visual memory of one of vmap's policy stacks, in RAM, in a memory
// store (SQLite: synced at every key image, bounded in RAM, several sessions) or read from
// a .vmem file: the library's vmap::AnyMemory (include/vmap/runtime/memory.hpp), bound as
// it is. A memory written from Python is read by `vmap memory ...` and the other way round.
//
// Threads: every call on one memory holds the memory's lock (taken after the GIL is
// released, so a call waiting for it never blocks a thread that needs the GIL), so two
// Python threads calling one memory take turns; a call made from inside the memory's own
// progress callback is refused (it would wait for itself). Arrays are read in place for
// the length of a call: the call holds a reference to them.

#include "bindings.hpp"

#include <vmap/io/calibration.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/io/postgres.hpp>
#include <vmap/memory/fleet.hpp>
#include <vmap/memory/replace.hpp>
#include <vmap/memory/sequence.hpp>
#include <vmap/runtime/exports.hpp>
#include <vmap/runtime/memory.hpp>
#include <vmap/runtime/recorder.hpp>
#include <vmap/runtime/stack.hpp>
#include <vmap/runtime/view.hpp>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <thread>
#include <utility>
#include <vector>

namespace vmap::python {
namespace {

namespace fs = std::filesystem;

/// What push_frames did.
struct PushSummary {
  std::size_t pushed = 0;
  std::size_t new_keys = 0;
  std::vector<LoopEdge> loops;
  double seconds = 0.0;
};

/// The Python object: the memory and the lock its calls take (see the top of this file).
class PyMemory {
 public:
  explicit PyMemory(AnyMemory memory) : memory_(std::move(memory)) {}

  /// Runs f(memory) with the GIL released and the memory's lock held.
  template <class F>
  decltype(auto) locked(F&& f) {
    if (owner_ == std::this_thread::get_id())
      fail("this memory is busy in the same thread (a call from inside its own progress callback): call it after "
           "push_frames returns");
    const py::gil_scoped_release unlocked;
    const std::lock_guard lock(mutex_);
    struct Owner {
      std::atomic<std::thread::id>& id;
      explicit Owner(std::atomic<std::thread::id>& i) : id(i) { id = std::this_thread::get_id(); }
      ~Owner() { id = std::thread::id(); }
    } owner(owner_);
    return f(memory_);
  }

 private:
  AnyMemory memory_;
  std::mutex mutex_;
  /// The thread inside a call, while one runs (read by other threads: atomic).
  std::atomic<std::thread::id> owner_{};
};

MemoryOptions options_of(const PolicyStack& stack, double tau, const std::string& rule, const std::string& images,
                         std::size_t vocabulary_after, double min_confidence, std::optional<double> chance_inlier_rate) {
  MemoryOptions o;
  o.selector.tau = tau;
  if (rule == "previous")
    o.selector.rule = KeyRule::previous_frame;
  else if (rule == "current")
    o.selector.rule = KeyRule::current_frame;
  else
    fail("rule: unknown rule '" + rule + "' (choose previous or current)");
  if (images == "none")
    o.images = ImageStorage::none;
  else if (images == "png")
    o.images = ImageStorage::png;
  else if (images == "jpeg")
    o.images = ImageStorage::jpeg;
  else
    fail("images: unknown storage '" + images + "' (choose none, png or jpeg)");
  o.vocabulary_after = vocabulary_after;
  o.loops.decision.min_confidence = min_confidence;
  o.loops.decision.chance_inlier_rate = chance_inlier_rate.value_or(measured_chance_rate(stack));
  return o;
}

AnyVocabulary vocabulary_of(const std::optional<std::string>& file) {
  return file ? AnyVocabulary::load(*file) : AnyVocabulary{};
}

/// A new memory store at `path`; an existing memory is replaced with force (by the
/// library, when the new one is closed), any other existing file refused (by the
/// library: AnyMemory::create, which knows a memory by its own records).
std::unique_ptr<PyMemory> create_memory(const std::string& given, const PolicyStack& stack, const MemoryOptions& o,
                                        AnyVocabulary vocabulary, bool force, std::size_t working_memory,
                                        const std::optional<std::string>& robot) {
  const fs::path path = memory_path(given);
  if (pg::is_uri(given)) {
    if (!robot) fail("create: a fleet's memory (a postgresql:// URI) holds one memory per robot: give robot='NAME'");
    return std::make_unique<PyMemory>(AnyMemory::create(path, stack, o, std::move(vocabulary),
                                                        {.robot = *robot, .working_memory = working_memory, .replace = force}));
  }
  if (robot) fail("create: robot= needs a fleet's memory (a postgresql:// URI as path)");
  std::error_code ec;
  if (!force && fs::exists(path, ec) && memory_kind(path) != MemoryKind::other)
    fail("path: the memory '" + path.string() + "' exists: give force=True to replace it");
  return std::make_unique<PyMemory>(AnyMemory::create(path, stack, o, std::move(vocabulary),
                                                      {.working_memory = working_memory, .replace = force}));
}

/// None, (x, y, theta) for SE(2), or a 4 x 4 / 3 x 4 [R | t] for SE(3).
OdometryPose pose_of(const py::object& pose) {
  if (pose.is_none()) return {};
  const auto a = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(pose);
  if (!a) fail("pose: expected None, (x, y, theta) or a 4 x 4 / 3 x 4 matrix [R | t]");
  if (a.ndim() == 1 && a.shape(0) == 3) {
    try {
      return Pose2(a.at(0), a.at(1), a.at(2));
    } catch (const Error& e) {
      fail(std::string("pose: ") + e.what());
    }
  }
  if (a.ndim() == 2 && (a.shape(0) == 3 || a.shape(0) == 4) && a.shape(1) == 4) {
    // A 4 x 4 is homogeneous: its last row is 0 0 0 1 (anything else is no rigid motion).
    if (a.shape(0) == 4 && (a.at(3, 0) != 0.0 || a.at(3, 1) != 0.0 || a.at(3, 2) != 0.0 || a.at(3, 3) != 1.0))
      fail("pose: the last row of a 4 x 4 pose must be 0 0 0 1, got " + std::to_string(a.at(3, 0)) + " " +
           std::to_string(a.at(3, 1)) + " " + std::to_string(a.at(3, 2)) + " " + std::to_string(a.at(3, 3)));
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

py::dict stack_dict(const PolicyStack& s) {
  py::dict d;
  d["features"] = std::string(to_string(s.descriptor));
  d["nfeatures"] = s.features;
  d["model"] = s.model;
  d["refine_model"] = s.refine_model;
  d["estimator"] = std::string(to_string(s.method));
  if (s.camera) {
    py::dict c;
    c["file"] = s.camera_source;
    c["lens"] = s.camera->lens == LensModel::pinhole ? "pinhole" : "fisheye";
    c["fx"] = s.camera->fx;
    c["fy"] = s.camera->fy;
    c["cx"] = s.camera->cx;
    c["cy"] = s.camera->cy;
    c["distortion"] = s.camera->distortion;
    c["width"] = s.camera->image_size.width;
    c["height"] = s.camera->image_size.height;
    d["camera"] = c;
  } else {
    d["camera"] = py::none();
  }
  return d;
}

/// The memory's place decision, with `min_confidence` when given (localize's keyword).
PlaceDecisionOptions decision_with(const AnyMemory& mem, std::optional<double> min_confidence) {
  PlaceDecisionOptions d = mem.options().loops.decision;
  if (min_confidence) d.min_confidence = *min_confidence;
  return d;
}

/// "list[i]": an item of a list argument, as errors name it.
std::string item_name(const char* list, std::size_t i) { return std::string(list) + "[" + std::to_string(i) + "]"; }

/// The options of a page (runtime/view.hpp) from view()'s keywords: `answers` is a list of
/// Localization, or of (query name, Localization) pairs.
ViewOptions view_options(const py::object& answers, int image_side, bool matches, const std::optional<std::string>& title) {
  ViewOptions o;
  o.image_side = image_side;
  o.matches = matches;
  o.title = title.value_or("");
  if (answers.is_none()) return o;
  std::size_t i = 0;
  for (const py::handle item : answers) {
    if (py::isinstance<MemoryLocalization>(item)) {
      o.answers.push_back(view_answer("query " + std::to_string(i), item.cast<MemoryLocalization>()));
    } else if (py::isinstance<py::tuple>(item) && py::len(item) == 2 && py::isinstance<MemoryLocalization>(item[py::int_(1)])) {
      o.answers.push_back(view_answer(py::str(item[py::int_(0)]), item[py::int_(1)].cast<MemoryLocalization>()));
    } else {
      fail("view: " + item_name("answers", i) + " is neither a Localization nor a (name, Localization) pair");
    }
    ++i;
  }
  return o;
}

py::dict view_result(const ViewResult& r) {
  py::dict d;
  d["index"] = r.index.string();
  d["key_images"] = r.key_images;
  d["loops"] = r.loops;
  d["runs"] = r.runs;
  d["images"] = r.images;
  d["images_from"] = r.images_from;
  d["matched_loops"] = r.matched_loops;
  d["answers"] = r.answers;
  d["placed"] = r.placed;
  d["posed"] = r.posed;
  d["bytes"] = r.bytes;
  d["seconds"] = r.seconds;
  return d;
}

std::string text_of(const PlaceEvidence& e) {
  char buf[160];
  std::snprintf(buf, sizeof buf, "%d/%d inliers, significance %.1f, spread %.2f, BoW %.3f, %s", e.inliers, e.matches,
                e.significance, e.spread, e.bow_score, std::string(to_string(e.model)).c_str());
  return buf;
}

void bind(py::module_& m) {
  py::class_<PlaceEvidence>(m, "PlaceEvidence",
                            "What a place decision weighed for one candidate (lcd/place_decision.hpp).")
      .def_readonly("matches", &PlaceEvidence::matches, "tentative correspondences the model was fitted to (for XFeat*: the refined ones)")
      .def_readonly("inliers", &PlaceEvidence::inliers, "those the model explains")
      .def_readonly("inlier_ratio", &PlaceEvidence::inlier_ratio, "inliers / matches")
      .def_readonly("significance", &PlaceEvidence::significance,
                    "-log10 of the chance that this many matches fit the model by accident")
      .def_readonly("spread", &PlaceEvidence::spread, "fraction of grid cells holding an inlier")
      .def_readonly("bow_score", &PlaceEvidence::bow_score, "the candidate's bag-of-words score")
      .def_property_readonly("model", [](const PlaceEvidence& e) { return std::string(to_string(e.model)); },
                             "fundamental or essential")
      .def("__repr__", [](const PlaceEvidence& e) { return "<vmap.PlaceEvidence " + text_of(e) + ">"; });

  py::class_<PlaceLink>(m, "PlaceLink", "A verified match between a query (or a newer key image) and a key image.")
      .def_readonly("key", &PlaceLink::key, "the matched key image")
      .def_readonly("bow_score", &PlaceLink::bow_score, "its bag-of-words rank score, in [0, 1]")
      .def_property_readonly("status", [](const PlaceLink& l) { return std::string(to_string(l.status)); },
                             "the verification's status (verified, too_few_matches, ...)")
      .def_property_readonly("model", [](const PlaceLink& l) { return matx_array(l.model); },
                             "3 x 3 verified model: F with x_query^T F x_key = 0, or E on normalised points (zeros "
                             "unless verified)")
      .def_property_readonly("model_kind", [](const PlaceLink& l) { return std::string(to_string(l.model_kind)); },
                             "which model `model` is: fundamental or essential")
      .def_readonly("matches", &PlaceLink::matches, "tentative correspondences verified")
      .def_readonly("inliers", &PlaceLink::inliers, "inliers of the model")
      .def_readonly("similarity", &PlaceLink::similarity, "eq. 5: inliers over the larger feature count")
      .def_readonly("confidence", &PlaceLink::confidence, "the place decision's confidence, in [0, 1]")
      .def("__repr__", [](const PlaceLink& l) {
        return "<vmap.PlaceLink key " + std::to_string(l.key) + ", " + std::string(to_string(l.status)) + ", " +
               std::to_string(l.inliers) + "/" + std::to_string(l.matches) + " inliers, confidence " +
               std::to_string(l.confidence) + ">";
      });

  py::class_<LoopEdge>(m, "LoopEdge", "A loop closure: key image `key_from` (the newer) revisits key image `key_to`.")
      .def_readonly("key_from", &LoopEdge::from, "the newer key image")
      .def_property_readonly("key_to", [](const LoopEdge& e) { return e.link.key; }, "the older key image it revisits")
      .def_readonly("link", &LoopEdge::link, "the verified match (PlaceLink)")
      .def("__repr__", [](const LoopEdge& e) {
        return "<vmap.LoopEdge " + std::to_string(e.from) + " -> " + std::to_string(e.link.key) + ", " +
               std::to_string(e.link.inliers) + " inliers, confidence " + std::to_string(e.link.confidence) + ">";
      });

  py::class_<FleetLoop>(m, "FleetLoop",
                        "A loop between two robots of a fleet's memory: key image `from_key` of robot `from_robot` "
                        "shows the place of key image `to_key` of robot `to_robot`.")
      .def_readonly("from_robot", &FleetLoop::from_robot, "the robot that found it")
      .def_readonly("from_key", &FleetLoop::from_key, "its key image")
      .def_readonly("to_robot", &FleetLoop::to_robot, "the other robot")
      .def_readonly("to_key", &FleetLoop::to_key, "the other robot's key image")
      .def_readonly("link", &FleetLoop::link, "the verified match (PlaceLink)")
      .def("__repr__", [](const FleetLoop& e) {
        return "<vmap.FleetLoop " + e.from_robot + " " + std::to_string(e.from_key) + " -> " + e.to_robot + " " +
               std::to_string(e.to_key) + ", " + std::to_string(e.link.inliers) + " inliers, confidence " +
               std::to_string(e.link.confidence) + ">";
      });

  py::class_<FleetRobotSummary>(m, "FleetRobot", "What a robot of a fleet's memory holds (vmap.fleet_robots).")
      .def_readonly("robot", &FleetRobotSummary::robot, "its name")
      .def_readonly("frames", &FleetRobotSummary::frames, "frames pushed")
      .def_readonly("key_images", &FleetRobotSummary::key_images, "key images")
      .def_readonly("sessions", &FleetRobotSummary::sessions, "sessions (runs)")
      .def_readonly("loops", &FleetRobotSummary::loops, "loop edges within its own memory")
      .def_readonly("fleet_loops", &FleetRobotSummary::fleet_loops, "loop edges to other robots' key images");

  m.def(
      "view",
      [](const std::string& source, const std::string& folder, const std::optional<std::string>& robot, int image_side,
         bool matches, const std::optional<std::string>& title) {
        const ViewOptions o = view_options(py::none(), image_side, matches, title);
        const ViewResult r = [&] {
          py::gil_scoped_release unlocked;
          return view_source(source, folder, o, robot.value_or(""));
        }();
        return view_result(r);
      },
      py::arg("source"), py::arg("folder"), py::kw_only(), py::arg("robot") = py::none(),
      py::arg("image_side") = ViewOptions{}.image_side, py::arg("matches") = true, py::arg("title") = py::none(),
      "Writes the page of `source` into `folder` (folder/index.html), as `vmap view` does: a memory store or .vmem\n"
      "file, a fleet's memory (a postgresql:// URI: every robot, or `robot` alone), or a visual map (map.vmap).\n"
      "Returns what was written (a dict: index, key_images, loops, images, ...).");
  m.def("fleet_robots", [](const std::string& uri) {
    py::gil_scoped_release unlocked;
    return fleet_summary(uri);
  }, py::arg("uri"), "Each robot of the fleet's memory at `uri` (a postgresql:// URI), in the order they joined.");
  m.def("fleet_loops", [](const std::string& uri) {
    py::gil_scoped_release unlocked;
    return fleet_loops(uri);
  }, py::arg("uri"), "Every loop edge between two robots of the fleet's memory at `uri`.");

  py::class_<RelativePose>(m, "RelativePose", "The query's camera relative to a key image's: X_key = R X_query + t, |t| = 1.")
      .def_property_readonly("rotation", [](const RelativePose& p) { return matx_array(p.rotation); }, "3 x 3 R")
      .def_property_readonly("translation", [](const RelativePose& p) {
        return to_array(cv::Mat(cv::Vec3d(p.translation), true).reshape(1, 1));
      }, "the unit direction of t (3,)")
      .def_property_readonly("rotation_degrees", &RelativePose::rotation_degrees, "the rotation's angle")
      .def_readonly("points_in_front", &RelativePose::points_in_front,
                    "inliers triangulated in front of both cameras (cheirality)")
      .def("__repr__", [](const RelativePose& p) {
        char buf[160];
        std::snprintf(buf, sizeof buf, "<vmap.RelativePose rotation %.2f deg, direction (%.3f, %.3f, %.3f)>",
                      p.rotation_degrees(), p.translation[0], p.translation[1], p.translation[2]);
        return std::string(buf);
      });

  py::class_<SequenceSupport>(m, "SequenceSupport",
                              "What the neighbours of an image in a sequence added to its answer (localize_sequence,\n"
                              "localize_window).")
      .def_readonly("window", &SequenceSupport::window, "images weighed, this one included")
      .def_readonly("weighed", &SequenceSupport::weighed,
                    "of those, the images that see a place (a candidate better than any other place they verified)")
      .def_readonly("on_line", &SequenceSupport::on_line,
                    "of those, the images on the answer's line, each at a key image of its own (1: no line)")
      .def_readonly("significance", &SequenceSupport::significance,
                    "the line's combined significance (Fisher's method less the choice of line), or the image's own")
      .def_readonly("single_confidence", &SequenceSupport::single_confidence, "the image's own answer, alone")
      .def_readonly("single_key", &SequenceSupport::single_key, "the key image the image alone chose, or None")
      .def("__repr__", [](const SequenceSupport& s) {
        char buf[128];
        std::snprintf(buf, sizeof buf, "<vmap.SequenceSupport %zu of %zu on the line, window %zu, alone %.2f>", s.on_line,
                      s.weighed, s.window, s.single_confidence);
        return std::string(buf);
      });

  py::class_<MemoryLocalization>(m, "Localization",
                                 "localize()'s answer: status 'accepted', or why not ('unknown place', 'ambiguous',\n"
                                 "'too little evidence'), with the verified key images behind it.")
      .def_property_readonly("status", [](const MemoryLocalization& l) { return std::string(to_string(l.status)); },
                             "accepted, unknown place, ambiguous, too little evidence or not a revisit")
      .def_readonly("reason", &MemoryLocalization::reason, "why, in words")
      .def_property_readonly(
          "reason_code", [](const MemoryLocalization& l) { return std::string(to_string(l.reason_code)); },
          "why, one name per case (vmap::DecisionReason: 'the memory has no key image', 'confidence below the "
          "threshold', ...)")
      .def_readonly("confidence", &MemoryLocalization::confidence, "of the best key image, in [0, 1]")
      .def_readonly("evidence", &MemoryLocalization::evidence, "of the best key image (PlaceEvidence)")
      .def_property_readonly("ok", &MemoryLocalization::ok, "whether the place was accepted")
      .def_property_readonly("key", [](const MemoryLocalization& l) -> std::optional<std::uint32_t> {
        if (const auto* b = l.best()) return b->key;
        return std::nullopt;
      }, "the accepted key image, or None")
      .def_readonly("matches", &MemoryLocalization::matches,
                    "every verified key image (PlaceLink), the decision's first, then by confidence")
      .def_readonly("match_evidence", &MemoryLocalization::match_evidence, "the evidence of each of matches, in order")
      .def_readonly("sequence", &MemoryLocalization::sequence,
                    "what the sequence's other images added (SequenceSupport), None for an image alone")
      .def_readonly("verified_candidates", &MemoryLocalization::verified_candidates, "key images the estimator ran on")
      .def_readonly("relative_pose", &MemoryLocalization::relative_pose,
                    "the query's pose relative to the best key image when the memory has a camera, else None")
      .def_property_readonly(
          "pose",
          [](const MemoryLocalization& l) -> py::object {
            if (!l.pose) return py::none();
            return to_array(cv::Mat(cv::Matx44d(l.pose->camera_to_world.matrix), true));
          },
          "the query's camera-to-world pose in the memory's frame (4 x 4 [R | t; 0 0 0 1]) when the place was\n"
          "accepted, the memory has SE(3) poses and a camera, and the geometry holds; else None (pose_reason says why)")
      .def_property_readonly(
          "pose_covariance",
          [](const MemoryLocalization& l) -> py::object {
            if (!l.pose) return py::none();
            return to_array(cv::Mat(l.pose->covariance, true));
          },
          "the pose's 6 x 6 covariance (position x y z, then a world-frame rotation vector), or None")
      .def_property_readonly(
          "pose_inliers", [](const MemoryLocalization& l) -> std::optional<int> {
            if (!l.pose) return std::nullopt;
            return l.pose->inliers;
          },
          "the PnP's inliers behind the pose, or None")
      .def_readonly("pose_reason", &MemoryLocalization::pose_reason, "why there is a pose or none, in words")
      .def_property_readonly(
          "pose_reason_code", [](const MemoryLocalization& l) { return std::string(to_string(l.pose_reason_code)); },
          "one name per case (vmap::PoseReason: 'posed', 'no camera', 'no baseline', 'too few points', ...)")
      .def("__bool__", &MemoryLocalization::ok)
      .def("__repr__", [](const MemoryLocalization& l) {
        return "<vmap.Localization " + std::string(to_string(l.status)) +
               (l.best() ? " key " + std::to_string(l.best()->key) : std::string()) + ": " + l.reason + ">";
      });

  py::class_<MemoryStep>(m, "MemoryStep", "What push() did: the selector's answer, the key image added, the loops found.")
      .def_property_readonly("frame_index", [](const MemoryStep& s) { return s.frame.frame_index; }, "the frame pushed")
      .def_property_readonly("similarity", [](const MemoryStep& s) { return s.frame.similarity; },
                             "S(K, I_j) against the current key image (eq. 5)")
      .def_property_readonly("key_taken", [](const MemoryStep& s) { return s.frame.key_taken; },
                             "whether a key image was taken")
      .def_property_readonly("key_frame", [](const MemoryStep& s) { return s.frame.key_frame; },
                             "the frame that became a key image (j-1 or j), or None")
      .def_readonly("new_key", &MemoryStep::new_key, "index of the key image added, or None")
      .def_readonly("loops", &MemoryStep::loops, "loop edges found in this step")
      .def_readonly("fleet_loops", &MemoryStep::fleet_loops,
                    "a fleet's robot: loops to other robots' key images found when this step was synced")
      .def("__repr__", [](const MemoryStep& s) {
        return "<vmap.MemoryStep frame " + std::to_string(s.frame.frame_index) +
               (s.new_key ? ", key image " + std::to_string(*s.new_key) : std::string(", no key image")) + ", " +
               std::to_string(s.loops.size()) + " loop edges>";
      });

  py::class_<PushSummary>(m, "PushSummary", "What push_frames did.")
      .def_readonly("pushed", &PushSummary::pushed, "frames pushed")
      .def_readonly("new_keys", &PushSummary::new_keys, "key images added")
      .def_readonly("loops", &PushSummary::loops, "loop edges found")
      .def_readonly("seconds", &PushSummary::seconds, "wall time of the call")
      .def("__repr__", [](const PushSummary& s) {
        return "<vmap.PushSummary " + std::to_string(s.pushed) + " frames pushed, " + std::to_string(s.new_keys) +
               " new key images, " + std::to_string(s.loops.size()) + " loop edges>";
      });

  py::class_<PyMemory>(m, "VisualMemory",
                       "A visual memory: key images of a camera stream (eq. 5-6), loop closures between them and\n"
                       "localization of new images, in RAM (VisualMemory(...)), in a memory store written key image\n"
                       "by key image (VisualMemory.create / open) or read from a .vmem file (open). Its policy stack\n"
                       "(features, estimator, camera) is recorded in it and read back by every reader.")
      .def(py::init([](const std::string& features, int nfeatures, const std::string& model,
                       const std::string& refine_model, const std::string& estimator,
                       const std::optional<std::string>& camera, double tau, const std::string& rule,
                       const std::string& images, const std::optional<std::string>& vocabulary,
                       std::size_t vocabulary_after, double min_confidence, std::optional<double> chance_inlier_rate) {
             const PolicyStack stack = policy_stack(features, nfeatures, model, refine_model, estimator, camera);
             return std::make_unique<PyMemory>(AnyMemory::in_ram(
                 stack, options_of(stack, tau, rule, images, vocabulary_after, min_confidence, chance_inlier_rate),
                 vocabulary_of(vocabulary)));
           }),
           py::arg("features") = "orb", py::kw_only(), py::arg("nfeatures") = 1000, py::arg("model") = "",
           py::arg("refine_model") = "", py::arg("estimator") = "magsac", py::arg("camera") = py::none(),
           py::arg("tau") = 0.3, py::arg("rule") = "previous", py::arg("images") = "none",
           py::arg("vocabulary") = py::none(), py::arg("vocabulary_after") = MemoryOptions{}.vocabulary_after,
           py::arg("min_confidence") = PlaceDecisionOptions{}.min_confidence,
           py::arg("chance_inlier_rate") = py::none(),
           "A new memory in RAM. features: orb, akaze, sift, xfeat, xfeat-dense, xfeat-star (model: the ONNX\n"
           "file); estimator: magsac, ransac, lmeds, 8point; camera: a calibration file (F on undistorted\n"
           "points and a relative pose per localization); tau: eq. 6's threshold; rule: previous (eq. 6) or\n"
           "current (Algorithm 1); images: none, png or jpeg (key images' pixels kept); vocabulary: a\n"
           "vocabulary file, else one is learned from the first vocabulary_after key images;\n"
           "min_confidence: the place decision's threshold; chance_inlier_rate: its chance model (None: the rate\n"
           "measured for the descriptor, vmap.measured_chance_rate).")
      .def_static(
          "create",
          [](const std::string& path, const std::string& features, int nfeatures, const std::string& model,
             const std::string& refine_model, const std::string& estimator, const std::optional<std::string>& camera,
             double tau, const std::string& rule, const std::string& images, const std::optional<std::string>& vocabulary,
             std::size_t vocabulary_after, double min_confidence, std::optional<double> chance_inlier_rate, bool force,
             std::size_t working_memory, const std::optional<std::string>& robot) {
            const PolicyStack stack = policy_stack(features, nfeatures, model, refine_model, estimator, camera);
            return create_memory(path, stack,
                                 options_of(stack, tau, rule, images, vocabulary_after, min_confidence, chance_inlier_rate),
                                 vocabulary_of(vocabulary), force, working_memory, robot);
          },
          py::arg("path"), py::kw_only(), py::arg("features") = "orb", py::arg("nfeatures") = 1000,
          py::arg("model") = "", py::arg("refine_model") = "", py::arg("estimator") = "magsac",
          py::arg("camera") = py::none(), py::arg("tau") = 0.3, py::arg("rule") = "previous",
          py::arg("images") = "none", py::arg("vocabulary") = py::none(),
          py::arg("vocabulary_after") = MemoryOptions{}.vocabulary_after,
          py::arg("min_confidence") = PlaceDecisionOptions{}.min_confidence, py::arg("chance_inlier_rate") = py::none(),
          py::arg("force") = false,
          py::arg("working_memory") = std::size_t{200}, py::arg("robot") = py::none(),
          "A new memory store at `path` (a folder means path/memory.vmdb), synced at every key image and loop\n"
          "edge, holding the features of its `working_memory` newest key images in RAM (0: all). An existing\n"
          "memory is replaced only with force=True, when the new one is closed (close() or the end of a with\n"
          "block): until then readers see the old one, which stays if the new one is never closed or its with\n"
          "block ends in an exception; refused while another program writes it. Any other existing file is\n"
          "refused. A postgresql:// URI as path is a fleet's memory on that server: the memory is robot\n"
          "`robot`'s there (a new robot; the fleet's schema is made on first use).")
      .def_static(
          "open",
          [](const std::string& path, bool read_only, bool new_session, std::size_t working_memory,
             const std::optional<std::string>& robot) {
            if (new_session && read_only) fail("open: new_session and read_only conflict (a new session writes the memory)");
            if (pg::is_uri(path) && !robot)
              fail("open: a fleet's memory (a postgresql:// URI) holds one memory per robot: give robot='NAME'");
            if (!pg::is_uri(path) && robot) fail("open: robot= needs a fleet's memory (a postgresql:// URI as path)");
            return std::make_unique<PyMemory>(AnyMemory::open(
                memory_path(path), {.robot = robot.value_or(""), .write = !read_only, .new_session = new_session,
                                    .pixels = !read_only, .working_memory = working_memory}));
          },
          py::arg("path"), py::kw_only(), py::arg("read_only") = false, py::arg("new_session") = false,
          py::arg("working_memory") = std::size_t{200}, py::arg("robot") = py::none(),
          "An existing memory: a store continued where it stopped (new_session=True: a new run), or\n"
          "read while another program writes it (read_only=True: a snapshot; push refused); or a .vmem\n"
          "file, read into RAM. Its policy stack is the one it records. A postgresql:// URI as path opens\n"
          "robot `robot`'s memory in that fleet's memory.")
      .def(
          "push",
          [](PyMemory& self, const py::array& image, std::optional<double> timestamp,
             const std::optional<std::string>& name, const py::object& pose) {
            const cv::Mat view = image_copy(image, "image");
            const OdometryPose p = pose_of(pose);
            return self.locked([&](AnyMemory& mem) {
              Frame f;
              f.image = view;
              f.index = mem.last_frame_index() ? *mem.last_frame_index() + 1 : mem.frames();
              f.name = name.value_or("frame#" + std::to_string(f.index));
              f.timestamp = timestamp.value_or(static_cast<double>(f.index));
              f.time_ns = frame_time_ns(f.timestamp, "push: timestamp");
              return mem.push(f, p);
            });
          },
          py::arg("image"), py::kw_only(), py::arg("timestamp") = py::none(), py::arg("name") = py::none(),
          py::arg("pose") = py::none(),
          "Pushes one frame (uint8 grey or BGR, read in place), numbered after the frames pushed so far.\n"
          "timestamp defaults to that number, name to 'frame#<number>'; pose: None, (x, y, theta) or [R | t].\n"
          "A key image or loop edge is in the store when push returns.")
      .def(
          "push_frames",
          [](PyMemory& self, const std::string& source, bool grey, std::size_t start, std::optional<std::size_t> end,
             std::size_t stride, std::optional<std::pair<int, int>> resize, double time_offset,
             const std::optional<std::string>& topic, bool record_time, const std::optional<std::string>& poses, const py::object& progress,
             std::size_t progress_every) {
            auto src = FrameSource::open(source,
                                         frame_options(grey, start, end, stride, resize, time_offset, topic.value_or(""), record_time));
            std::optional<FramePoses> frame_poses;
            if (poses) frame_poses.emplace(*poses, src);
            const ProgressHook hook(progress, progress_every);
            return self.locked([&](AnyMemory& mem) {
              const std::size_t keys_before = mem.key_images();
              const auto t0 = std::chrono::steady_clock::now();
              RecordOptions o;
              if (frame_poses) o.poses = [&](const Frame& f) { return (*frame_poses)(f); };
              std::size_t pushed = 0;
              o.on_frame = [&](const AnyMemory&) { hook(++pushed); };
              o.number_after_pushed = true;
              RecordResult r = record(mem, src, o);
              return PushSummary{r.pushed, mem.key_images() - keys_before, std::move(r.loops),
                                 std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count()};
            });
          },
          py::arg("source"), py::kw_only(), py::arg("grey") = true, py::arg("start") = 0, py::arg("end") = py::none(),
          py::arg("stride") = 1, py::arg("resize") = py::none(), py::arg("time_offset") = 0.0, py::arg("topic") = py::none(),
          py::arg("record_time") = false, py::arg("poses") = py::none(), py::arg("progress") = py::none(),
          py::arg("progress_every") = 50,
          "Pushes every frame of a source (as vmap.frames reads it, with the same keywords) in C++, with the frame's pose from a TUM\n"
          "or KITTI pose file when `poses` is given. Frames keep the source's indices where they follow the frames already\n"
          "pushed (a new memory or session), and are shifted to follow them otherwise (the source's gaps kept); progress(frames) is called every progress_every frames\n"
          "with the GIL held (Ctrl-C, or an exception it raises, stops the run there; what was pushed stays).\n"
          "Returns a PushSummary.")
      .def(
          "localize",
          [](PyMemory& self, const py::array& image, std::optional<double> min_confidence) {
            const cv::Mat view = image_copy(image, "image");
            return self.locked([&](AnyMemory& mem) {
              const PlaceDecisionOptions d = decision_with(mem, min_confidence);
              return mem.localize(view, &d);
            });
          },
          py::arg("image"), py::kw_only(), py::arg("min_confidence") = py::none(),
          "Where the image was taken: the place decision over the best key images by bag of words,\n"
          "verified by the F-matrix (Localization; status 'accepted' or why not).")
      .def(
          "localize_sequence",
          [](PyMemory& self, const std::vector<py::array>& images, std::size_t window, double max_speed,
             std::size_t tolerance, std::optional<double> min_confidence) {
            std::vector<cv::Mat> views;
            for (std::size_t i = 0; i < images.size(); ++i) views.push_back(image_copy(images[i], item_name("images", i)));
            return self.locked([&](AnyMemory& mem) {
              const PlaceDecisionOptions d = decision_with(mem, min_confidence);
              return localize_sequence(mem, views, {.window = window, .line = {max_speed, tolerance}}, &d);
            });
          },
          py::arg("images"), py::kw_only(), py::arg("window") = SequenceOptions{}.window,
          py::arg("max_speed") = SequenceLine{}.max_speed, py::arg("tolerance") = SequenceLine{}.tolerance,
          py::arg("min_confidence") = py::none(),
          "Each of a sequence of images (consecutive, in order) localized with the evidence of the `window` images\n"
          "around it: an image not placed alone is placed at the key image it sees best when at least two other\n"
          "images see key images on one line with it and their margins, combined, reach the threshold; an image\n"
          "placed alone keeps its answer (a list of Localization, each with .sequence). max_speed: the fastest the\n"
          "images move along the key images, per image; tolerance: key images off the line.")
      .def(
          "localize_window",
          [](PyMemory& self, const py::list& recent, double max_speed, std::size_t tolerance,
             std::optional<double> min_confidence) {
            // Answers are decided as they are; images are localized first.
            std::vector<MemoryLocalization> answers;
            std::vector<cv::Mat> images;
            for (std::size_t i = 0; i < recent.size(); ++i) {
              const py::handle item = recent[i];
              if (py::isinstance<MemoryLocalization>(item))
                answers.push_back(item.cast<MemoryLocalization>());
              else
                images.push_back(image_copy(item.cast<py::array>(), item_name("recent", i)));
            }
            if (!answers.empty() && !images.empty())
              vmap::detail::fail("localize_window: `recent` mixes Localization answers and images; give one kind");
            return self.locked([&](AnyMemory& mem) {
              const PlaceDecisionOptions d = decision_with(mem, min_confidence);
              if (!images.empty()) return localize_window(mem, std::span<const cv::Mat>(images), {max_speed, tolerance}, &d);
              return localize_window(mem, std::span<const MemoryLocalization>(answers), {max_speed, tolerance}, &d);
            });
          },
          py::arg("recent"), py::kw_only(), py::arg("max_speed") = SequenceLine{}.max_speed,
          py::arg("tolerance") = SequenceLine{}.tolerance, py::arg("min_confidence") = py::none(),
          "The last of `recent`, consecutive and oldest first, decided with the evidence of all of them. `recent`\n"
          "holds localize()'s answers (nothing is verified again: a robot keeps its last few answers and calls this\n"
          "for each new one), or images (each localized first).")
      .def("sync", [](PyMemory& self) { self.locked([](AnyMemory& mem) { mem.sync(); mem.flush(); }); },
           "Writes what the memory made since the last sync into its store and waits until it is committed\n"
           "(a no-op in RAM). push() syncs at every key image and loop edge without waiting.")
      .def("close", [](PyMemory& self) { self.locked([](AnyMemory& mem) { mem.close(); }); },
           "Syncs and closes the store; the memory is read-only afterwards.")
      .def("__enter__", [](PyMemory& self) -> PyMemory& { return self; })
      .def("__exit__", [](PyMemory& self, const py::object& type, const py::object&, const py::object&) {
        // A block left by an exception is a failed run: a memory created with force=True
        // then leaves the one it was to replace.
        self.locked([&](AnyMemory& mem) {
          if (!type.is_none()) mem.abandon();
          mem.close();
        });
      })
      .def("start_session", [](PyMemory& self) { self.locked([](AnyMemory& mem) { mem.start_session(); }); },
           "Starts a new session (a new run of the robot: its first key image is not linked to the last).")
      .def(
          "save",
          [](PyMemory& self, const std::string& path, const std::optional<std::string>& images) {
            const auto storage = storage_of(images);
            self.locked([&](AnyMemory& mem) { mem.save(path, storage); });
          },
          py::arg("path"), py::kw_only(), py::arg("images") = py::none(),
          "Writes the whole memory as one .vmem file, atomically (images: none, png, jpeg; default: as kept).\n"
          "An existing file there is replaced only when it is a .vmem memory file: a memory store (the\n"
          "memory's own included), another file or a folder is refused.")
      .def(
          "export",
          [](PyMemory& self, const std::string& folder) {
            return self.locked([&](AnyMemory& mem) { return export_memory_folder(mem, folder); });
          },
          py::arg("folder"),
          "Writes key_images.txt, loops.txt and, with poses, key_images.tum and loops.g2o as the folder\n"
          "`folder`, replaced as a whole (as `vmap memory export --out`): it must be new, empty or an earlier\n"
          "export holding only its own files; times exact to the nanosecond. Returns the names written.")
      .def(
          "view",
          [](PyMemory& self, const std::string& folder, const py::object& answers, int image_side, bool matches,
             const std::optional<std::string>& title) {
            const ViewOptions o = view_options(answers, image_side, matches, title);
            return view_result(self.locked([&](AnyMemory& mem) { return write_view(mem, folder, o); }));
          },
          py::arg("folder"), py::kw_only(), py::arg("answers") = py::none(),
          py::arg("image_side") = ViewOptions{}.image_side, py::arg("matches") = true, py::arg("title") = py::none(),
          "Writes a page that shows the memory into `folder` (folder/index.html, opened from the file system in a\n"
          "browser): the map (from above with poses, else a time line), each key image with its loops and their\n"
          "matches, the loops, eq. 5's similarity against tau and eq. 7's quality. answers: localize()'s answers\n"
          "(Localization, or (name, Localization) pairs), placed on their key images. `folder` is written whole\n"
          "(new, empty or an earlier page). Returns what was written (a dict: index, key_images, loops, images, ...).")
      .def_property_readonly("path", [](PyMemory& self) -> py::object {
        const std::string p = self.locked([](AnyMemory& mem) { return mem.path().string(); });
        return p.empty() ? py::object(py::none()) : py::object(py::str(p));
      }, "the file it was opened from or created at (a fleet's URI without its password), or None in RAM")
      .def_property_readonly("robot", [](PyMemory& self) -> py::object {
        const std::string r = self.locked([](AnyMemory& mem) { return mem.robot(); });
        return r.empty() ? py::object(py::none()) : py::object(py::str(r));
      }, "the robot whose memory it is in a fleet's memory, or None")
      .def_property_readonly("read_only", [](PyMemory& self) { return self.locked([](AnyMemory& mem) { return mem.read_only(); }); },
                             "whether it was opened read-only (push and the other changes refused)")
      .def_property_readonly("stack", [](PyMemory& self) {
        return stack_dict(self.locked([](AnyMemory& mem) { return mem.stack(); }));
      }, "the policy stack: features, nfeatures, model, refine_model, estimator, camera")
      .def_property_readonly("stack_text", [](PyMemory& self) {
        return self.locked([](AnyMemory& mem) { return to_string(mem.stack()); });
      }, "the policy stack as text (vmap.PolicyStack's to_string)")
      .def_property_readonly("frames", [](PyMemory& self) { return self.locked([](AnyMemory& mem) { return mem.frames(); }); },
                             "frames pushed")
      .def_property_readonly("key_images",
                             [](PyMemory& self) { return self.locked([](AnyMemory& mem) { return mem.key_images(); }); },
                             "key images kept")
      .def_property_readonly("last_frame_index", [](PyMemory& self) {
        return self.locked([](AnyMemory& mem) { return mem.last_frame_index(); });
      }, "the index of the last frame pushed, or None")
      .def_property_readonly("stationary", [](PyMemory& self) {
        return self.locked([](AnyMemory& mem) { return mem.stationary(); });
      }, "whether the camera never left its place (no key image is a revisit)")
      .def_property_readonly("vocabulary_words", [](PyMemory& self) {
        return self.locked([](AnyMemory& mem) { return mem.vocabulary().size(); });
      }, "0 until the vocabulary is learned")
      .def_property_readonly("loops", [](PyMemory& self) {
        return self.locked([](AnyMemory& mem) { return mem.loops(); });
      }, "every loop edge (LoopEdge)")
      .def_property_readonly(
          "sessions",
          [](PyMemory& self) {
            const auto sessions = self.locked([](AnyMemory& mem) { return mem.sessions(); });
            py::list out;
            for (const auto& s : sessions) {
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
          [](PyMemory& self) {
            struct Key {
              std::size_t frame_index, session;
              std::string name;
              double timestamp;
              std::int64_t time_ns;
              OdometryPose pose;
            };
            const auto keys = self.locked([](AnyMemory& mem) {
              std::vector<Key> out;
              for (std::size_t k = 0; k < mem.key_images(); ++k) {
                const KeyImage& key = mem.map().keys[k];
                out.push_back({key.frame_index, mem.session_of(k), key.name, key.timestamp, key.time_ns, mem.poses()[k]});
              }
              return out;
            });
            py::list out;
            for (std::size_t k = 0; k < keys.size(); ++k) {
              py::dict d;
              d["key"] = k;
              d["frame_index"] = keys[k].frame_index;
              d["name"] = keys[k].name;
              d["timestamp"] = keys[k].timestamp;
              d["time_ns"] = keys[k].time_ns;
              d["session"] = keys[k].session;
              d["pose"] = pose_object(keys[k].pose);
              out.append(d);
            }
            return out;
          },
          "one dict per key image: key, frame_index, name, timestamp (s), time_ns, session, pose")
      .def(
          "key_image",
          [](PyMemory& self, std::size_t key) -> py::object {
            const cv::Mat image = self.locked([&](AnyMemory& mem) {
              if (key >= mem.key_images())
                vmap::detail::fail("key_image: no key image " + std::to_string(key) + " (the memory has " +
                                   std::to_string(mem.key_images()) + ")");
              return mem.map().keys[key].image;
            });
            if (image.empty()) return py::none();
            return to_array(image);
          },
          py::arg("key"), "The key image's pixels when the memory keeps them (images='png' or 'jpeg'), else None.")
      .def(
          "key_features",
          [](PyMemory& self, std::size_t key) {
            return self.locked([&](AnyMemory& mem) {
              if (key >= mem.key_images())
                vmap::detail::fail("key_features: no key image " + std::to_string(key) + " (the memory has " +
                                   std::to_string(mem.key_images()) + ")");
              return mem.key_features(static_cast<std::uint32_t>(key));
            });
          },
          py::arg("key"), "The key image's features (read from the store when outside the working memory).")
      .def(
          "neighbours",
          [](PyMemory& self, std::size_t key) {
            const auto neighbours = self.locked([&](AnyMemory& mem) {
              if (key >= mem.key_images())
                vmap::detail::fail("neighbours: no key image " + std::to_string(key) + " (the memory has " +
                                   std::to_string(mem.key_images()) + ")");
              return mem.neighbours(static_cast<std::uint32_t>(key));
            });
            py::list out;
            for (const auto& n : neighbours)
              out.append(py::make_tuple(n.key, n.kind == GraphNeighbour::Kind::link ? "link" : "loop"));
            return out;
          },
          py::arg("key"), "The key image's neighbours in the memory's graph, as (key, 'link' or 'loop').")
      .def("__repr__", [](PyMemory& self) {
        return self.locked([](AnyMemory& mem) {
          return "<vmap.VisualMemory " + std::to_string(mem.frames()) + " frames, " + std::to_string(mem.key_images()) +
                 " key images, " + std::to_string(mem.loops().size()) + " loop edges (" + summary(mem.stack()) + ")" +
                 (mem.path().empty() ? std::string(", in RAM") : ", " + mem.path().string()) + ">";
        });
      });
}

const RegisterPart part{order_memory, &bind};

}  // namespace
}  // namespace vmap::python
