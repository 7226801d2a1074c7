#pragma once

// Streaming a sequence into a memory (runtime/memory.hpp): every frame of a frame source
// pushed with its odometry pose, the memory store synced as its SyncPolicy says and after
// the last frame, so that a run killed half way resumes from the last sync; and what a
// memory records of the input each session was built from, so that a resumed run reads
// the same input.
//
//   auto memory = vmap::AnyMemory::create("run.vmdb", stack);
//   auto frames = vmap::FrameSource::open("rgb.txt", {.grey = true});
//   vmap::record_input(memory, "rgb.txt", frames, 1);
//   vmap::RecordResult r = vmap::record(memory, frames, {.on_frame = [](const vmap::AnyMemory& m) { ... }});

#include <vmap/core/error.hpp>
#include <vmap/geometry/pose2.hpp>
#include <vmap/io/files.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/io/poses.hpp>
#include <vmap/memory/store.hpp>
#include <vmap/memory/types.hpp>
#include <vmap/runtime/memory.hpp>
#include <vmap/runtime/stack.hpp>
#include <vmap/som/pose_io.hpp>

#include <opencv2/core/affine.hpp>

#include <chrono>
#include <cstddef>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

namespace vmap {

/// The odometry pose of each frame from a camera pose file (TUM or KITTI, as
/// load_camera_poses reads it): by order when the file has one pose per frame of the
/// sequence, else the pose nearest in time within 50 ms (TUM fr1's ground truth has gaps
/// of up to 49 ms). A frame without one is an Error naming the file and the frame.
/// `floor`: the SE(2) floor pose (som/pose_io.hpp: TUM's z-up floor, KITTI's y-down)
/// instead of the SE(3) camera pose, as the GCS localizer learns them.
class FramePoses {
 public:
  FramePoses(const std::filesystem::path& file, const FrameSource& src, bool floor = false)
      : name_(file.string()), poses_(load_camera_poses(file)), floor_(floor) {
    if (floor_) format_ = guess_camera_pose_format(read_text_file(file, "pose file"), name_);
    const auto times = src.timestamps();  // empty for a video
    by_order_ = poses_.size() == (times.empty() ? src.total().value_or(0) : times.size());
  }

  [[nodiscard]] OdometryPose operator()(const Frame& f) const {
    std::optional<std::size_t> k;
    if (by_order_)
      k = f.index;
    else
      k = associate_by_timestamp(poses_, std::vector<double>{f.timestamp}, 0.05).front();
    if (!k || *k >= poses_.size())
      detail::fail(name_ + ": no pose for frame " + std::to_string(f.index) + " (" + f.name + ", time " +
                   std::to_string(f.timestamp) + ")");
    if (floor_) return format_ == CameraPoseFormat::kitti ? floor_pose_y_down(poses_[*k]) : floor_pose_z_up(poses_[*k]);
    return cv::Affine3d(poses_[*k].rotation, poses_[*k].position);
  }

 private:
  std::string name_;
  std::vector<CameraPose> poses_;
  bool floor_ = false;
  CameraPoseFormat format_ = CameraPoseFormat::tum;
  bool by_order_ = false;
};

/// How record() streams.
struct RecordOptions {
  /// Each frame's odometry pose (e.g. a FramePoses); none: frames without a pose.
  std::function<OdometryPose(const Frame&)> poses{};
  /// Called after each frame pushed, with the memory (e.g. for progress).
  std::function<void(const AnyMemory&)> on_frame{};
  /// Numbers the frames after the last one the memory's current session holds where the
  /// source's own indices would not follow it (all shifted by one offset, so the source's
  /// gaps stay): a second run into the same session, or one that starts earlier in its
  /// source, then continues the session instead of being refused for indices that go
  /// backwards. Off, frames keep the source's indices, which line up with its ground
  /// truth (--resume reads on after the last frame instead).
  bool number_after_pushed = false;
};

/// What record() did.
struct RecordResult {
  std::size_t pushed = 0;       ///< frames pushed in this run
  std::size_t syncs = 0;        ///< syncs into the store (one transaction each)
  double seconds = 0.0;         ///< pushing (without the syncs)
  /// The pushing thread's time in the syncs: encoding the rows and waiting for the
  /// previous commit (the commit itself runs in the store's writer thread).
  double sync_seconds = 0.0;
  std::vector<LoopEdge> loops;  ///< loop edges found in this run
};

/// Pushes every frame of `src` into `memory` (AnyMemory::push: a store synced as its
/// SyncPolicy says), then syncs what is left and waits for the commit: when record()
/// returns, the store holds every frame pushed.
inline RecordResult record(AnyMemory& memory, FrameSource& src, const RecordOptions& options = {}) {
  using clock = std::chrono::steady_clock;
  RecordResult r;
  const auto seconds = [](clock::time_point t0) { return std::chrono::duration<double>(clock::now() - t0).count(); };
  std::optional<std::size_t> shift;
  while (auto f = src.next()) {
    const OdometryPose pose = options.poses ? options.poses(*f) : OdometryPose{};
    if (options.number_after_pushed) {
      if (!shift) {
        const auto& sessions = memory.sessions();
        const bool fresh = sessions.empty() || sessions.back().first_frame == memory.frames();
        const auto last = fresh ? std::nullopt : memory.last_frame_index();
        shift = last && f->index <= *last ? *last + 1 - f->index : 0;
      }
      f->index += *shift;
    }
    const auto t0 = clock::now();
    const std::size_t before = memory.syncs();
    const double synced_before = memory.sync_seconds();
    MemoryStep step = memory.push(*f, pose);
    r.seconds += seconds(t0) - (memory.sync_seconds() - synced_before);
    r.syncs += memory.syncs() - before;
    ++r.pushed;
    r.loops.insert(r.loops.end(), step.loops.begin(), step.loops.end());
    if (options.on_frame) options.on_frame(memory);
  }
  const std::size_t before = memory.syncs();
  memory.sync_pending();
  memory.flush();
  r.syncs += memory.syncs() - before;
  r.sync_seconds = memory.sync_seconds();
  return r;
}

/// What a memory records of the input a session was built from: the input's path (made
/// absolute), its first frame's name (lists and folders), the stride and, for a bag, the
/// image topic read. A resumed run reads the same input (the command line refuses another).
struct RecordedInput {
  std::string input;
  std::string first_frame;
  std::size_t stride = 1;
  std::string topic{};  ///< a bag's image topic; empty for other inputs

  friend bool operator==(const RecordedInput&, const RecordedInput&) = default;

  /// "'rgb.txt' (first frame 'a.png', stride 1)": for messages.
  [[nodiscard]] std::string text() const {
    return "'" + input + "' (" + (topic.empty() ? std::string() : "topic " + topic + ", ") + "first frame '" +
           first_frame + "', stride " + std::to_string(stride) + ")";
  }
};

/// The RecordedInput of a run reading `input` through `src` with `stride`.
[[nodiscard]] inline RecordedInput recorded_input(const std::string& input, const FrameSource& src, std::size_t stride) {
  std::error_code ec;
  const auto canonical = std::filesystem::weakly_canonical(input, ec);
  const auto paths = src.paths();
  const auto topic = src.bag_topic();
  return {ec ? input : canonical.string(), paths.empty() ? std::string() : paths.front().filename().string(), stride,
          topic ? topic->name : std::string()};
}

/// For a run that resumes `memory` from `src`: why the source no longer holds the frames
/// the memory read, or nullopt when it does (or cannot tell: a video, bag or camera has
/// no names by index). The memory's last key image is compared, by name, with the frame
/// the source now has at its index, so a list or folder edited since the run stopped
/// (same path, first frame and stride, other frames later) is caught before its frames
/// are numbered as if they followed the memory's.
[[nodiscard]] inline std::optional<std::string> changed_input(const AnyMemory& memory, const FrameSource& src) {
  const auto& keys = memory.map().keys;
  if (keys.empty()) return std::nullopt;
  const auto paths = src.paths();
  if (paths.empty()) return std::nullopt;
  const KeyImage& last = keys.back();
  if (last.frame_index >= paths.size())
    return "it now has " + std::to_string(paths.size()) + " frames, but the memory's key image '" + last.name +
           "' is frame " + std::to_string(last.frame_index);
  const std::string now = paths[last.frame_index].filename().string();
  if (now != last.name)
    return "its frame " + std::to_string(last.frame_index) + " is now '" + now + "', but the memory made key image '" +
           last.name + "' from it";
  return std::nullopt;
}

namespace detail {

/// The store note of session s's input ("input" for the first, "input 1", ...), kept as
/// the flat JSON object the command line has always written.
[[nodiscard]] inline std::string session_input_note(std::size_t session) {
  return session == 0 ? std::string("input") : "input " + std::to_string(session);
}

inline std::string json_string(const std::string& s) {
  std::string out = "\"";
  for (char c : s) {
    if (c == '"' || c == '\\') out += '\\';
    if (c == '\n') {
      out += "\\n";
      continue;
    }
    out += c;
  }
  return out + '"';
}

}  // namespace detail

/// session_input() of a store opened by the caller.
[[nodiscard]] inline std::optional<RecordedInput> session_input_of(MemoryStore& store, std::size_t session) {
  const auto note = store.note(detail::session_input_note(session));
  if (!note) return std::nullopt;
  RecordedInput out;
  try {
    using Kind = detail::LegacyJson::Value::Kind;
    const auto j = detail::LegacyJson(*note, "note").document();
    const auto* input = j.get("input");
    const auto* first = j.get("first_frame");
    const auto* stride = j.get("stride");
    const auto* topic = j.get("topic");
    if (!input || input->kind != Kind::string) return RecordedInput{*note, {}, 0};
    out.input = input->string;
    if (first && first->kind == Kind::string) out.first_frame = first->string;
    if (stride && stride->kind == Kind::number && stride->number >= 0) out.stride = static_cast<std::size_t>(stride->number);
    if (topic && topic->kind == Kind::string) out.topic = topic->string;
  } catch (const Error&) {
    return RecordedInput{*note, {}, 0};  // a note another program wrote as plain text
  }
  return out;
}

/// The input session `session` of a memory store was built from, if it recorded one
/// (nullopt for a memory without a store, or written by a program that did not).
[[nodiscard]] inline std::optional<RecordedInput> session_input(AnyMemory& memory, std::size_t session) {
  MemoryStore* store = memory.store();
  if (!store) {
    if (memory.kind() != MemoryKind::store || memory.path().empty()) return std::nullopt;
    auto reader = MemoryStore::open(memory.path(), sqlite::Access::read);
    return session_input_of(reader, session);
  }
  return session_input_of(*store, session);
}

/// Records `input` as the input session `session` of a store was built from.
inline void set_session_input_of(MemoryStore& store, std::size_t session, const RecordedInput& input) {
  store.set_note(detail::session_input_note(session),
                 "{\"first_frame\":" + detail::json_string(input.first_frame) + ",\"input\":" +
                     detail::json_string(input.input) + ",\"stride\":" + std::to_string(input.stride) +
                     (input.topic.empty() ? std::string() : ",\"topic\":" + detail::json_string(input.topic)) + "}");
}

/// Records `input` as the input of the memory's last session (a store's note; a no-op
/// for a memory without a store).
inline void set_session_input(AnyMemory& memory, const RecordedInput& input) {
  if (MemoryStore* store = memory.store()) set_session_input_of(*store, memory.sessions().size() - 1, input);
}

}  // namespace vmap
