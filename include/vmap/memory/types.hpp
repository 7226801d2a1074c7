#pragma once

// The visual memory's public value types (memory/visual_memory.hpp): its options
// (memory/options.hpp, which a program that only configures a memory includes alone),
// what push() and localize() answer, its sessions and graph. Apart from the memory itself
// so that a program that only passes these around (a log of answers) does not compile
// the memory's templates.

#include <vmap/core/verification.hpp>
#include <vmap/geometry/metric_pose.hpp>
#include <vmap/geometry/pose2.hpp>
#include <vmap/keyframe/result.hpp>
#include <vmap/lcd/place_decision.hpp>
#include <vmap/memory/options.hpp>
#include <vmap/som/results.hpp>

#include <opencv2/core.hpp>
#include <opencv2/core/affine.hpp>

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <variant>
#include <vector>

namespace vmap {

/// An odometry pose given with a frame: none, SE(2) (a ground robot) or SE(3).
using OdometryPose = std::variant<std::monostate, Pose2, cv::Affine3d>;

namespace detail {
/// The default pose argument of push(). A named object rather than a `{}` temporary:
/// GCC 12 at -O2 reports copying a defaulted std::variant temporary as a read of
/// uninitialised storage (a false -Wmaybe-uninitialized).
inline const OdometryPose no_odometry_pose{};
}  // namespace detail

/// A verified match between two key images (a loop edge) or a query and a key image.
struct PlaceLink {
  std::uint32_t key = 0;        ///< the matched key image (the older one for a loop)
  double bow_score = 0.0;       ///< its rank score (place/bow.hpp), in [0, 1]
  VerificationStatus status = VerificationStatus::too_few_matches;
  /// The verified model: x_query^T F x_key = 0 for the fundamental matrix (raw pixels),
  /// or the essential matrix on normalised points (zeros unless verified).
  cv::Matx33d model = cv::Matx33d::zeros();
  PlaceModel model_kind = PlaceModel::fundamental;  ///< which of the two `model` is
  int matches = 0;                                 ///< tentative correspondences verified
  int inliers = 0;                                 ///< F-matrix inliers
  double similarity = 0.0;                         ///< eq. 5
  double confidence = 0.0;                         ///< the place decision's (lcd/place_decision.hpp)
};

/// A loop closure: key image `from` (the newer) revisits key image `link.key`.
struct LoopEdge {
  std::uint32_t from = 0;
  PlaceLink link;
};

/// A loop edge between two robots of a fleet's memory (memory/fleet.hpp): key image
/// `from_key` of robot `from_robot` (the robot that found it) shows the place of key image
/// `to_key` of robot `to_robot`.
struct FleetLoop {
  std::string from_robot;
  std::uint32_t from_key = 0;
  std::string to_robot;
  std::uint32_t to_key = 0;
  PlaceLink link;  ///< the verification (link.key is to_key)
};

/// What push() did: the selector's answer, the key image it added, the loops found.
struct MemoryStep {
  FrameResult frame;
  std::optional<std::uint32_t> new_key;  ///< index of the key image added, if any
  std::vector<LoopEdge> loops;           ///< loop edges found in this step
  /// A fleet's robot (AnyMemory on a server): loops to other robots' key images found for
  /// key images whose sync committed since the last push (those close() syncs last are
  /// in the fleet only: fleet_loops(uri)).
  std::vector<FleetLoop> fleet_loops;
};

/// What the neighbours of an image in a sequence added to its answer
/// (memory/sequence.hpp, lcd/sequence.hpp).
struct SequenceSupport {
  std::size_t window = 0;   ///< images weighed, this one included
  std::size_t weighed = 0;  ///< of those, the images that see a place (a candidate with a positive margin)
  std::size_t on_line = 0;  ///< of those, the images on the answer's line, each at a key image of its own (1: no line)
  double significance = 0.0;       ///< the line's combined significance (lcd/sequence.hpp) or the image's own, the larger
  double single_confidence = 0.0;  ///< the image's own answer, alone
  /// The key image the image alone chose (accepted or not), if it verified one.
  std::optional<std::uint32_t> single_key;
};

/// localize()'s answer: the place decision (lcd/loop_engine.hpp) and the verified key
/// images behind it.
struct MemoryLocalization {
  /// accepted, or why not: unknown place (verified candidates, none confident enough),
  /// ambiguous (two places equally likely), too little evidence (an empty memory, a
  /// query without features, no candidate verified).
  PlaceStatus status = PlaceStatus::too_little_evidence;
  DecisionReason reason_code = DecisionReason::empty_memory;  ///< why, as a value (lcd/place_decision.hpp)
  std::string reason = "the memory has no key image";         ///< why, in words with the numbers
  double confidence = 0.0;   ///< of the best key image, in [0, 1]
  PlaceEvidence evidence;    ///< of the best key image
  /// Every verified key image, most confident first (matches.front() is the decision's
  /// candidate, accepted or not).
  std::vector<PlaceLink> matches;
  std::vector<PlaceEvidence> match_evidence;  ///< the evidence of each of `matches`, in order
  std::size_t verified_candidates = 0;  ///< key images the estimator ran on
  /// The query's pose relative to the best key image (R and the direction of t), when the
  /// memory's estimator recovers one (EssentialEstimator with a calibrated camera).
  std::optional<RelativePose> relative_pose;
  /// The GCS position estimate (Algorithm 5 with the one query image), when a GCS was
  /// trained (VisualMemory::train_gcs) and the query has features; independent of the
  /// place decision.
  std::optional<Localization> position;
  /// How a sequence of images decided (memory/sequence.hpp); empty for a single image.
  std::optional<SequenceSupport> sequence;
  /// The query's camera-to-world pose in the memory's frame (memory/metric_pose.hpp):
  /// set only when the place was accepted, the memory has SE(3) poses and a camera, and
  /// the geometry holds; otherwise empty, and pose_reason_code says why.
  std::optional<MetricPose> pose;
  PoseReason pose_reason_code = PoseReason::not_accepted;  ///< posed, or why there is no pose
  std::string pose_reason = "the place was not accepted";   ///< why, in words with the numbers
  /// The metric pose at the decision's candidate (matches.front()) when the place was not
  /// accepted: what `pose` becomes when a sequence accepts the image there
  /// (memory/sequence.hpp). Not an answer: read `pose`.
  PoseAnswer candidate_pose;
  [[nodiscard]] bool ok() const noexcept { return status == PlaceStatus::accepted; }
  /// The accepted key image; nullptr unless ok().
  [[nodiscard]] const PlaceLink* best() const noexcept { return ok() && !matches.empty() ? &matches.front() : nullptr; }
};

namespace detail {

/// The metric pose of `a` after a sequence re-decided it (memory/sequence.hpp): an image
/// accepted at its own candidate keeps its pose, or takes the one its candidate had when
/// the sequence accepted it; an image `moved` to another of its verified key images has
/// none (the pose was computed at its own candidate), nor has one the sequence did not
/// accept.
inline void settle_pose(MemoryLocalization& a, bool moved) {
  if (moved) {
    a.pose.reset();
    a.candidate_pose = {};
    a.pose_reason_code = PoseReason::moved;
    a.pose_reason = "the sequence placed the image at another key image than its own answer's";
    return;
  }
  if (!a.ok()) {
    if (a.pose_reason_code != PoseReason::not_accepted)  // accepted alone: its candidate's answer
      a.candidate_pose = {std::move(a.pose), a.pose_reason_code, std::move(a.pose_reason)};
    a.pose.reset();
    a.pose_reason_code = PoseReason::not_accepted;
    a.pose_reason = "the place was not accepted";
    return;
  }
  if (!a.pose && a.pose_reason_code == PoseReason::not_accepted) {
    a.pose = std::move(a.candidate_pose.pose);
    a.pose_reason_code = a.candidate_pose.reason_code;
    a.pose_reason = std::move(a.candidate_pose.reason);
    a.candidate_pose = {};
  }
}

}  // namespace detail

/// A session: one run of the robot, its own chain of key images (consecutive key images
/// of a session are linked; the first key image of a session is not linked to the last
/// of the one before). Loops are searched across all sessions, and localization searches
/// every session.
struct MemorySession {
  std::size_t first_key = 0;    ///< its first key image (== key_images() while it has none)
  std::size_t first_frame = 0;  ///< frames pushed into the memory before it
};

/// A neighbour of a key image in the memory's graph.
struct GraphNeighbour {
  enum class Kind : std::uint8_t { link, loop };
  std::uint32_t key = 0;
  Kind kind = Kind::link;
};

/// What a file given as a memory is, by its first bytes.
enum class MemoryKind : std::uint8_t {
  store,  ///< a memory store (an SQLite file; an empty file is one whose creation was interrupted)
  file,   ///< a single-file memory (.vmem, "VMAPMEMO")
  other,  ///< neither (also anything that is not a regular file, which is never opened)
};

}  // namespace vmap
