#pragma once

// What the page of runtime/view.hpp shows, gathered from a memory, a fleet's robots or a
// visual map into one model (ViewModel: runs, key images, loops, answers): the up axis
// of posed key images, eq. 7 per run, where the key images' pixels come from, and the
// loops' matches verified again. The run-time layer's own header; a program includes
// runtime/view.hpp.

#include <vmap/core/error.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/io/image.hpp>
#include <vmap/keyframe/visual_map.hpp>
#include <vmap/memory/replace.hpp>
#include <vmap/memory/store.hpp>
#include <vmap/memory/types.hpp>
#include <vmap/runtime/memory.hpp>
#include <vmap/runtime/policies.hpp>
#include <vmap/runtime/recorder.hpp>
#include <vmap/runtime/view_options.hpp>

#include <opencv2/core.hpp>
#include <opencv2/core/affine.hpp>
#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <string>
#include <utility>
#include <variant>
#include <vector>

namespace vmap::detail {

/// One run of the page: a session of a memory, or a robot of a fleet.
struct ViewRun {
  std::string name;             ///< "session 0", "r1"
  std::size_t first = 0;        ///< its first key image (the page's index)
  std::size_t count = 0;        ///< key images
  std::size_t frames = 0;       ///< frames it read (eq. 7's n)
  std::size_t base = 0;         ///< the page's index of its memory's key image 0
  std::optional<double> tau;    ///< the selection threshold (eq. 6), when recorded
  double quality = 0.0;         ///< eq. 7 over its key images
  double mean_similarity = 0.0;  ///< over its links
  std::size_t links = 0;        ///< links between its consecutive key images
  std::string input;            ///< the input it was built from, when recorded
};

/// One key image of the page.
struct ViewKey {
  std::size_t run = 0;
  std::size_t session = 0;  ///< within its memory
  std::size_t frame = 0;
  double time = 0.0;
  std::string name;
  std::optional<cv::Vec3d> position;  ///< the camera centre, when posed
  std::optional<cv::Matx33d> rotation;  ///< camera to world, when posed in SE(3)
  int link = -1;             ///< verified matches to the key image before it in its run (-1: none)
  double similarity = 0.0;   ///< eq. 5 to that key image
  cv::Size size;             ///< the image's size
  bool image = false;        ///< its pixels are on the page
};

/// One loop edge of the page: key image `from` (the newer) shows the place of `to`.
struct ViewLoop {
  std::size_t from = 0, to = 0;
  int inliers = 0;
  double confidence = 0.0, bow = 0.0;
  bool matched = false;  ///< its verified matches are on the page
};

/// What the page shows (see runtime/view.hpp).
struct ViewModel {
  std::string title;
  std::string run_kind = "session";  ///< session or robot
  std::vector<std::pair<std::string, std::string>> summary;
  std::vector<ViewRun> runs;
  std::vector<ViewKey> keys;
  std::vector<ViewLoop> loops;
  std::vector<ViewAnswer> answers;
  std::vector<std::optional<std::size_t>> answer_keys;  ///< the page's index of each answer's key image
};

/// The up axis of posed key images, as the world axis (0 x, 1 y, 2 z) and its sign: the
/// camera's up direction (-y of an OpenCV camera: rotation's second column, negated)
/// averaged over the key images, when they agree (the mean of the unit vectors is at
/// least half a unit long: a robot's or a hand-held camera's roll stays small); else the
/// axis along which the positions spread least (a ground robot's floor). Floor poses
/// (SE(2)) are +z.
struct ViewUp {
  int axis = 2;
  int sign = 1;
};

[[nodiscard]] inline ViewUp view_up_axis(const std::vector<ViewKey>& keys) {
  cv::Vec3d up(0, 0, 0);
  std::size_t rotations = 0;
  cv::Vec3d mean(0, 0, 0);
  std::size_t posed = 0;
  for (const auto& k : keys) {
    if (!k.position) continue;
    mean += *k.position;
    ++posed;
    if (!k.rotation) continue;
    const cv::Matx33d& r = *k.rotation;
    up += cv::Vec3d(-r(0, 1), -r(1, 1), -r(2, 1));
    ++rotations;
  }
  ViewUp out;
  if (rotations > 0 && cv::norm(up) >= 0.5 * static_cast<double>(rotations)) {
    int best = 0;
    for (int i = 1; i < 3; ++i)
      if (std::abs(up[i]) > std::abs(up[best])) best = i;
    return {best, up[best] >= 0 ? 1 : -1};
  }
  if (rotations == 0 && posed > 0) return out;  // floor poses: x, y on the floor, z up
  if (posed < 2) return out;
  mean *= 1.0 / static_cast<double>(posed);
  cv::Vec3d var(0, 0, 0);
  for (const auto& k : keys)
    if (k.position) {
      const cv::Vec3d d = *k.position - mean;
      var += d.mul(d);
    }
  int least = 0;
  for (int i = 1; i < 3; ++i)
    if (var[i] < var[least]) least = i;
  return {least, 1};
}

/// The two world axes seen from above, right and up on the page, with `up` out of the
/// page (a right-handed view: right x top = up).
[[nodiscard]] inline std::array<int, 2> view_plane_axes(const ViewUp& up) {
  const int a = (up.axis + 1) % 3, b = (up.axis + 2) % 3;
  // (a, b, up.axis) is a cyclic order, so e_a x e_b = e_up: seen from +up, a is right and
  // b is up on the page; seen from -up, the two swap.
  if (up.sign > 0) return {a, b};
  return {b, a};
}

[[nodiscard]] inline std::optional<cv::Vec3d> view_position(const OdometryPose& p, std::optional<cv::Matx33d>& rotation) {
  if (const auto* a = std::get_if<cv::Affine3d>(&p)) {
    rotation = a->rotation();
    return a->translation();
  }
  if (const auto* f = std::get_if<Pose2>(&p)) return cv::Vec3d(f->x(), f->y(), 0.0);
  return std::nullopt;
}

/// Eq. 7 (García-Pintos et al. 2023; VisualMap::quality) of `count` key images of one run
/// of `frames` frames, over its links `pairs[first .. first + count - 1)`, and the mean
/// similarity of those links.
inline void view_run_quality(ViewRun& run, const std::vector<KeyPair>& pairs, std::size_t first) {
  VisualMap slice;
  slice.frames = run.frames;
  slice.keys.resize(run.count);
  for (std::size_t k = first; k + 1 < first + run.count && k < pairs.size(); ++k) slice.pairs.push_back(pairs[k]);
  run.quality = slice.quality();
  run.links = slice.pairs.size();
  run.mean_similarity = slice.stats().mean_similarity;
}

/// "12.3 MB"
[[nodiscard]] inline std::string view_bytes_text(std::uintmax_t b) {
  char buf[48];
  if (b < 1024) std::snprintf(buf, sizeof buf, "%ju bytes", b);
  else if (b < (std::uintmax_t{1} << 20)) std::snprintf(buf, sizeof buf, "%.1f KiB (%ju bytes)", static_cast<double>(b) / 1024.0, b);
  else std::snprintf(buf, sizeof buf, "%.1f MiB (%ju bytes)", static_cast<double>(b) / 1048576.0, b);
  return buf;
}

[[nodiscard]] inline std::string view_camera_text(const PolicyStack& s) {
  if (!s.camera) return "none (raw pixels)";
  const Camera& c = *s.camera;
  char buf[200];
  std::snprintf(buf, sizeof buf, "%s %dx%d, fx %.2f fy %.2f cx %.2f cy %.2f", c.lens == LensModel::pinhole ? "pinhole" : "fisheye",
                c.image_size.width, c.image_size.height, c.fx, c.fy, c.cx, c.cy);
  return std::string(buf) + (s.camera_source.empty() ? "" : " (" + s.camera_source + ")");
}

/// The first `n` bytes of a file (fewer when it is shorter; none when it cannot be read).
[[nodiscard]] inline std::string view_head(const std::filesystem::path& file, std::size_t n) {
  std::string out(n, '\0');
  std::ifstream in(file, std::ios::binary);
  in.read(out.data(), static_cast<std::streamsize>(n));
  out.resize(in ? n : static_cast<std::size_t>(std::max<std::streamsize>(in.gcount(), 0)));
  return out;
}

/// The format a memory is kept in, with its version: a store's schema, a .vmem file's
/// format (the u32 after its magic), a fleet's schema on its server.
[[nodiscard]] inline std::string view_format_text(AnyMemory& memory) {
  if (memory.kind() == MemoryKind::file && !memory.path().empty()) {
    const std::string head = view_head(memory.path(), 12);
    std::uint32_t v = 0;
    for (int i = 0; i < 4 && 8 + i < static_cast<int>(head.size()); ++i)
      v |= static_cast<std::uint32_t>(static_cast<unsigned char>(head[static_cast<std::size_t>(8 + i)])) << (8 * i);
    return "single-file memory (.vmem), format version " + std::to_string(v);
  }
  if (memory.kind() == MemoryKind::store) {
    if (MemoryStore* store = memory.store())
      return std::string(store->on_server() ? "fleet's memory on PostgreSQL" : "memory store (SQLite)") +
             ", schema version " + std::to_string(store->version());
    return "memory store (SQLite)";
  }
  return "in RAM (not kept)";
}

/// Where key images' pixels come from (see runtime/view.hpp): `emit(page index, image)`
/// for each one found; counts what came from where.
struct ViewPixels {
  std::size_t kept = 0, read_again = 0;
  bool over_limit = false;  ///< kept pixels not decoded: more than MapLoadOptions' limits
  std::vector<std::string> inputs_missing;

  [[nodiscard]] std::string text(std::size_t keys) const {
    if (keys == 0) return "no key image";
    if (kept + read_again == 0)
      return std::string("none (") +
             (over_limit ? "the memory's pixels are more than the loading limits"
                         : "the memory keeps no pixels: build it with --images png or jpeg") +
             (inputs_missing.empty() ? std::string(", and no recorded input was read again")
                                     : ", and its recorded input '" + inputs_missing.front() + "' cannot be read") +
             ")";
    std::string out;
    if (kept > 0) out += std::to_string(kept) + " kept in the memory";
    if (read_again > 0) out += (out.empty() ? "" : ", ") + std::to_string(read_again) + " read again from the recorded input";
    if (kept + read_again < keys) out += ", " + std::to_string(keys - kept - read_again) + " without pixels";
    return out;
  }
};

/// The key images [first, first + count) of `map` (page indices from `base`) read again
/// from `input` (a session's recorded input): image files by their path, checked by name;
/// a video or bag decoded in order up to the last one.
template <class Emit>
void view_read_again(const VisualMap& map, const std::vector<std::size_t>& wanted, const RecordedInput& input,
                     std::size_t base, ViewPixels& counts, Emit&& emit) {
  std::error_code ec;
  if (wanted.empty()) return;
  if (input.input.empty() || !std::filesystem::exists(input.input, ec)) {
    counts.inputs_missing.push_back(input.input);
    return;
  }
  FrameSourceOptions o;
  o.grey = false;
  o.topic = input.topic;
  try {
    auto src = FrameSource::open(input.input, o);
    const auto paths = src.paths();
    if (!paths.empty()) {
      for (const std::size_t k : wanted) {
        const KeyImage& key = map.keys[k];
        if (key.frame_index >= paths.size() || paths[key.frame_index].filename().string() != key.name) continue;
        try {
          emit(base + k, vmap::read_image(paths[key.frame_index], {.flags = cv::IMREAD_COLOR}));
          ++counts.read_again;
        } catch (const Error&) {
        }
      }
      return;
    }
    if (src.kind() == SourceKind::live) return;  // a stream is not read again
    std::map<std::size_t, std::size_t> by_frame;
    for (const std::size_t k : wanted) by_frame[map.keys[k].frame_index] = k;
    o.start = by_frame.begin()->first;
    o.end = by_frame.rbegin()->first + 1;
    auto again = FrameSource::open(input.input, o);
    while (auto f = again.next()) {
      const auto it = by_frame.find(f->index);
      if (it == by_frame.end() || f->name != map.keys[it->second].name) continue;
      emit(base + it->second, f->image);
      ++counts.read_again;
    }
  } catch (const Error&) {
    counts.inputs_missing.push_back(input.input);
  } catch (const cv::Exception&) {
    counts.inputs_missing.push_back(input.input);
  }
}

/// A snapshot of `memory` with its key images' pixels decoded, when it keeps pixels it was
/// opened without (a reader opened without them: AnyMemory::open's `pixels`) and they fit
/// MapLoadOptions' limits together; `location` opens it again (a fleet's URI with its
/// password; empty: memory.path()).
[[nodiscard]] inline std::optional<AnyMemory> view_with_pixels(AnyMemory& memory, const std::string& location,
                                                              ViewPixels& counts) {
  if (memory.options().images == ImageStorage::none || memory.kind() == MemoryKind::other || memory.path().empty())
    return std::nullopt;
  std::uint64_t pixels = 0;
  bool missing = false;
  for (const KeyImage& k : memory.map().keys) {
    missing = missing || k.image.empty();
    pixels += static_cast<std::uint64_t>(k.features.image_size.area());
  }
  if (!missing) return std::nullopt;
  if (pixels > MapLoadOptions{}.max_total_image_pixels) {
    counts.over_limit = true;
    return std::nullopt;
  }
  try {
    return AnyMemory::open(location.empty() ? memory.path() : std::filesystem::path(location),
                           {.robot = memory.robot(), .pixels = true});
  } catch (const Error&) {
    return std::nullopt;  // gone or changed since: the recorded input, else no image
  }
}

/// The pixels of `memory`'s key images (page indices from `base`): kept (decoded, or read
/// through view_with_pixels), or read again from the recorded input.
template <class Emit>
void view_memory_pixels(AnyMemory& memory, std::size_t base, ViewPixels& counts, Emit&& emit,
                        const std::string& location = {}) {
  const std::optional<AnyMemory> decoded = view_with_pixels(memory, location, counts);
  const VisualMap& map = memory.map();
  const VisualMap& kept = decoded ? decoded->map() : map;
  const auto& sessions = memory.sessions();
  for (std::size_t s = 0; s < sessions.size(); ++s) {
    const std::size_t first = sessions[s].first_key;
    const std::size_t end = s + 1 < sessions.size() ? sessions[s + 1].first_key : memory.key_images();
    std::vector<std::size_t> wanted;
    for (std::size_t k = first; k < end; ++k) {
      // A snapshot taken later holds the same key images first (a memory only grows).
      const cv::Mat& image = k < kept.keys.size() && kept.keys[k].name == map.keys[k].name ? kept.keys[k].image
                                                                                         : map.keys[k].image;
      if (!image.empty()) {
        emit(base + k, image);
        ++counts.kept;
      } else {
        wanted.push_back(k);
      }
    }
    if (wanted.empty()) continue;
    std::optional<RecordedInput> input;
    try {
      input = session_input(memory, s);
    } catch (const Error&) {
    }
    if (input) view_read_again(map, wanted, *input, base, counts, emit);
  }
}

/// A loop edge's two key images' features (`from`, the newer, and `to`) and the inliers
/// its verification counted.
struct ViewLoopFeatures {
  Features from, to;
  int inliers = 0;
};

/// The matches of loop edges verified again by the stack's matcher and estimator (the
/// policies made once): for i = 0 .. loops - 1 in order, `features(i)` gives the loop's
/// ViewLoopFeatures (nothing to skip it) and `emit(i, inliers)` receives the inliers'
/// keypoints, x y in `from` then x y in `to`, pixels, when the verification holds. A loop
/// was verified with the newer key image as the query (the loop engine,
/// lcd/loop_engine.hpp), or with the two ordered by content (a link between runs,
/// VisualMemory::link_pair), and the two orders count a few inliers apart: the newer
/// first is tried first, the other when it does not count the loop's own inliers.
template <class FeaturesOf, class Emit>
void view_verify_loops(const PolicyStack& stack, std::size_t loops, FeaturesOf&& features, Emit&& emit) {
  if (loops == 0) return;
  with_policies(stack, StackUse::memory, [&](auto, auto matcher, auto estimator) {
    const auto verify = [&](const Features& q, const Features& c, bool flip) {
      const Matches matches = matcher.match(q, c);
      const Verification v = estimator.verify(q, c, matches);
      std::vector<float> out;
      if (!v.ok()) return out;
      for (std::size_t j = 0; j < matches.size() && j < v.inlier_mask.size(); ++j) {
        if (v.inlier_mask[j] == 0) continue;
        const auto& p = q.keypoints[static_cast<std::size_t>(matches[j].queryIdx)].pt;
        const auto& r = c.keypoints[static_cast<std::size_t>(matches[j].trainIdx)].pt;
        if (flip) out.insert(out.end(), {r.x, r.y, p.x, p.y});
        else out.insert(out.end(), {p.x, p.y, r.x, r.y});
      }
      return out;
    };
    for (std::size_t i = 0; i < loops; ++i) {
      const std::optional<ViewLoopFeatures> l = features(i);
      if (!l || l->from.empty() || l->to.empty()) continue;
      std::vector<float> out = verify(l->from, l->to, false);
      if (static_cast<int>(out.size() / 4) != l->inliers && features_before(l->to, l->from)) {
        std::vector<float> other = verify(l->to, l->from, true);
        if (static_cast<int>(other.size() / 4) == l->inliers) out = std::move(other);
      }
      if (!out.empty()) emit(i, out);
    }
  });
}

/// The page's run and key images of `memory` (runs one per session, or one for the whole
/// memory named `robot`), appended to `m`.
inline void view_add_memory(ViewModel& m, AnyMemory& memory, const std::string& robot = {}) {
  const VisualMap& map = memory.map();
  const auto& sessions = memory.sessions();
  const std::size_t base = m.keys.size();
  const std::size_t run0 = m.runs.size();
  const std::optional<double> tau = memory.options().selector.tau;
  const auto frames_of = [&](std::size_t s) {
    return (s + 1 < sessions.size() ? sessions[s + 1].first_frame : memory.frames()) - sessions[s].first_frame;
  };
  if (robot.empty()) {
    for (std::size_t s = 0; s < sessions.size(); ++s) {
      ViewRun r;
      r.name = "session " + std::to_string(s);
      r.first = base + sessions[s].first_key;
      r.count = (s + 1 < sessions.size() ? sessions[s + 1].first_key : memory.key_images()) - sessions[s].first_key;
      r.frames = frames_of(s);
      r.base = base;
      r.tau = tau;
      view_run_quality(r, map.pairs, sessions[s].first_key);
      try {
        if (auto in = session_input(memory, s)) r.input = in->text();
      } catch (const Error&) {
      }
      m.runs.push_back(std::move(r));
    }
  } else {
    ViewRun r;
    r.name = robot;
    r.first = base;
    r.count = memory.key_images();
    r.frames = memory.frames();
    r.base = base;
    r.tau = tau;
    // Eq. 7 over the links within its sessions (the first key image of a session is not
    // linked to the one before).
    VisualMap slice;
    slice.frames = r.frames;
    slice.keys.resize(r.count);
    for (std::size_t k = 0; k + 1 < memory.key_images() && k < map.pairs.size(); ++k)
      if (memory.session_of(k) == memory.session_of(k + 1)) slice.pairs.push_back(map.pairs[k]);
    r.quality = slice.quality();
    r.links = slice.pairs.size();
    r.mean_similarity = slice.stats().mean_similarity;
    r.input = std::to_string(sessions.size()) + (sessions.size() == 1 ? " session" : " sessions");
    m.runs.push_back(std::move(r));
  }
  for (std::size_t k = 0; k < memory.key_images(); ++k) {
    const KeyImage& key = map.keys[k];
    ViewKey v;
    v.session = memory.session_of(k);
    v.run = robot.empty() ? run0 + v.session : run0;
    v.frame = key.frame_index;
    v.time = key.timestamp;
    v.name = key.name;
    v.position = view_position(memory.poses()[k], v.rotation);
    if (k > 0 && memory.session_of(k - 1) == v.session && k - 1 < map.pairs.size()) {
      v.link = map.pairs[k - 1].inliers;
      v.similarity = map.pairs[k - 1].similarity;
    }
    v.size = !key.image.empty() ? key.image.size() : key.features.image_size;
    m.keys.push_back(std::move(v));
  }
  for (const LoopEdge& e : memory.loops())
    m.loops.push_back({base + e.from, base + e.link.key, e.link.inliers, e.link.confidence, e.link.bow_score, false});
}

inline void view_add_summary_of(ViewModel& m, AnyMemory& memory) {
  m.summary.emplace_back("stack", to_string(memory.stack()));
  m.summary.emplace_back("camera", view_camera_text(memory.stack()));
  m.summary.emplace_back("format", view_format_text(memory));
  if (memory.kind() != MemoryKind::other && !memory.path().empty() && !pg::is_uri(memory.path().native())) {
    std::error_code ec;
    const auto bytes = std::filesystem::file_size(memory.path(), ec);
    if (!ec) m.summary.emplace_back("size", view_bytes_text(bytes));
  }
}

/// Resolves the answers' key images to the page's (a robot's through its run): an answer
/// of a key image or robot the page does not show is an Error (answers of another memory).
inline void view_place_answers(ViewModel& m, const std::vector<ViewAnswer>& answers, bool fleet) {
  m.answers = answers;
  m.answer_keys.assign(answers.size(), std::nullopt);
  for (std::size_t i = 0; i < answers.size(); ++i) {
    const ViewAnswer& a = answers[i];
    if (!a.key) continue;
    std::size_t base = 0, count = m.keys.size();
    if (fleet || !a.robot.empty()) {
      const auto run = std::find_if(m.runs.begin(), m.runs.end(), [&](const ViewRun& r) { return r.name == a.robot; });
      if (!fleet || run == m.runs.end())
        fail(ErrorKind::invalid_argument, "answer of query '" + a.image + "': robot '" + a.robot + "' is not on this page" +
                                              (fleet ? "" : " (its answers are a fleet's: view the fleet's memory whole)"));
      base = run->first;
      count = run->count;
    }
    if (*a.key >= count)
      fail(ErrorKind::invalid_argument, "answer of query '" + a.image + "': key image " + std::to_string(*a.key) +
                                            " is not in the memory, which has " + std::to_string(count) +
                                            " (answers of another memory?)");
    m.answer_keys[i] = base + *a.key;
  }
}

}  // namespace vmap::detail
