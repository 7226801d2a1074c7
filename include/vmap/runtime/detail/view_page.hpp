#pragma once

// The folder of runtime/view.hpp's page, written from its model (runtime/detail/
// view_model.hpp): data.js, the key images, the loops' matches and the page's own files
// (runtime/detail/view_assets.hpp), published whole; and write_view and view_source. The
// run-time layer's own header; a program includes runtime/view.hpp.

#include <vmap/core/error.hpp>
#include <vmap/io/atomic_file.hpp>
#include <vmap/io/files.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/io/image.hpp>
#include <vmap/io/postgres.hpp>
#include <vmap/keyframe/map_io.hpp>
#include <vmap/keyframe/visual_map.hpp>
#include <vmap/memory/fleet.hpp>
#include <vmap/memory/replace.hpp>
#include <vmap/memory/store.hpp>
#include <vmap/memory/vmem.hpp>
#include <vmap/runtime/detail/view_assets.hpp>
#include <vmap/runtime/detail/view_json.hpp>
#include <vmap/runtime/detail/view_model.hpp>
#include <vmap/runtime/fleet.hpp>
#include <vmap/runtime/memory.hpp>
#include <vmap/runtime/policies.hpp>
#include <vmap/runtime/recorder.hpp>
#include <vmap/runtime/view_options.hpp>

#include <opencv2/core.hpp>
#include <opencv2/core/affine.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <system_error>
#include <utility>
#include <variant>
#include <vector>

namespace vmap {

namespace detail {

/// Loops whose matches one file of the page holds (matches/N.js holds loops 256 N ..).
inline constexpr std::size_t view_match_chunk = 256;
/// Key images per folder of the page's images (img/N/ holds key images 1000 N ..).
inline constexpr std::size_t view_image_bucket = 1000;

/// Writes `bytes` to `path` in the page's temporary folder (the folder is published whole
/// by AtomicDirectory after one syncfs: each file needs no rename of its own).
inline void view_write(const std::filesystem::path& path, std::string_view bytes) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) fail(ErrorKind::io, "cannot write '" + path.string() + "': " + os_reason(errno));
  std::size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::write(fd, bytes.data() + done, bytes.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) {
      const int e = errno;
      ::close(fd);
      fail(ErrorKind::io, "writing '" + path.string() + "' failed: " + os_reason(e));
    }
    done += static_cast<std::size_t>(n);
  }
  if (::close(fd) != 0) fail(ErrorKind::io, "writing '" + path.string() + "' failed (close): " + os_reason(errno));
}

inline void view_mkdir(const std::filesystem::path& dir) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) fail(ErrorKind::io, "cannot create the folder '" + dir.string() + "': " + ec.message());
}

/// The page's copy of a key image: at most `side` pixels on its longest side, 8-bit grey
/// or BGR, JPEG.
[[nodiscard]] inline std::string view_jpeg(const cv::Mat& image, int side, int quality) {
  cv::Mat img = image;
  if (img.depth() == CV_16U) img.convertTo(img, CV_8U, 1.0 / 256.0);
  if (img.channels() == 4) cv::cvtColor(img, img, cv::COLOR_BGRA2BGR);
  const int longest = std::max(img.cols, img.rows);
  if (longest > side) {
    const double s = static_cast<double>(side) / longest;
    cv::resize(img, img, cv::Size(std::max(1, static_cast<int>(std::lround(img.cols * s))),
                                  std::max(1, static_cast<int>(std::lround(img.rows * s)))),
               0, 0, cv::INTER_AREA);
  }
  std::vector<unsigned char> buf;
  if (!cv::imencode(".jpg", img, buf, {cv::IMWRITE_JPEG_QUALITY, quality})) fail("view: encoding a key image failed");
  return {reinterpret_cast<const char*>(buf.data()), buf.size()};
}

[[nodiscard]] inline std::uintmax_t view_folder_bytes(const std::filesystem::path& dir) {
  std::uintmax_t total = 0;
  std::error_code ec;
  for (auto it = std::filesystem::recursive_directory_iterator(dir, ec); !ec && it != std::filesystem::end(it);
       it.increment(ec))
    if (it->is_regular_file(ec)) total += it->file_size(ec);
  return total;
}

/// The page's data (data.js): the model as one JSON object, key images and loops as
/// columns (one list per field), which the page reads in one JSON.parse of a string: a
/// JSON parser does less than a script's (V8's advice for large data, "The cost of
/// JavaScript in 2019").
[[nodiscard]] inline std::string view_data_js(const ViewModel& m, bool posed, const ViewUp& up) {
  ViewJson j;
  j.open('{');
  j.key("format").integer(1);
  j.key("title").str(m.title);
  j.key("run_kind").str(m.run_kind);
  j.key("summary").open('[');
  for (const auto& [label, value] : m.summary) {
    j.item().open('[');
    j.item().str(label);
    j.item().str(value);
    j.close(']');
  }
  j.close(']');
  j.key("posed").raw(posed ? "true" : "false");
  const auto axes = view_plane_axes(up);
  static constexpr const char* axis_names[] = {"x", "y", "z"};
  j.key("up").str(std::string(up.sign > 0 ? "+" : "-") + axis_names[up.axis]);
  j.key("plane").open('[');  // the world axes right and top on the page, seen from above
  j.item().integer(axes[0]);
  j.item().integer(axes[1]);
  j.close(']');
  j.key("match_chunk").integer(static_cast<long long>(view_match_chunk));
  j.key("image_bucket").integer(static_cast<long long>(view_image_bucket));
  j.list("runs", m.runs, [&](const ViewRun& r) {
    j.open('{');
    j.key("name").str(r.name);
    j.key("first").integer(static_cast<long long>(r.first));
    j.key("count").integer(static_cast<long long>(r.count));
    j.key("frames").integer(static_cast<long long>(r.frames));
    j.key("base").integer(static_cast<long long>(r.base));
    j.key("tau");
    if (r.tau) j.num(*r.tau);
    else j.raw("null");
    j.key("quality").num(r.quality, 6);
    j.key("links").integer(static_cast<long long>(r.links));
    j.key("mean_similarity").num(r.mean_similarity, 6);
    j.key("input").str(r.input);
    j.close('}');
  });
  // Key images, one list per field.
  const auto column = [&](std::string_view name, auto&& value) {
    j.key(name).open('[');
    for (const ViewKey& k : m.keys) {
      j.item();
      value(k);
    }
    j.close(']');
  };
  j.key("keys").open('{');
  j.key("n").integer(static_cast<long long>(m.keys.size()));
  column("run", [&](const ViewKey& k) { j.integer(static_cast<long long>(k.run)); });
  if (m.run_kind == "robot")  // a robot's sessions (on a memory's page, a run is a session)
    column("session", [&](const ViewKey& k) { j.integer(static_cast<long long>(k.session)); });
  column("frame", [&](const ViewKey& k) { j.integer(static_cast<long long>(k.frame)); });
  column("time", [&](const ViewKey& k) { j.num(k.time, 17); });
  column("name", [&](const ViewKey& k) { j.str(k.name); });
  column("link", [&](const ViewKey& k) { j.integer(k.link); });
  column("similarity", [&](const ViewKey& k) { j.num(k.similarity, 4); });
  column("image", [&](const ViewKey& k) { j.integer(k.image ? 1 : 0); });
  column("width", [&](const ViewKey& k) { j.integer(k.size.width); });
  column("height", [&](const ViewKey& k) { j.integer(k.size.height); });
  if (posed) {  // x y z of each key image, one list (the page takes the plane's two from it)
    j.key("position").open('[');
    for (const ViewKey& k : m.keys)
      for (int i = 0; i < 3; ++i) j.item().num((*k.position)[i], 7);
    j.close(']');
  }
  j.close('}');
  const auto loop_column = [&](std::string_view name, auto&& value) {
    j.key(name).open('[');
    for (const ViewLoop& l : m.loops) {
      j.item();
      value(l);
    }
    j.close(']');
  };
  j.key("loops").open('{');
  j.key("n").integer(static_cast<long long>(m.loops.size()));
  loop_column("from", [&](const ViewLoop& l) { j.integer(static_cast<long long>(l.from)); });
  loop_column("to", [&](const ViewLoop& l) { j.integer(static_cast<long long>(l.to)); });
  loop_column("inliers", [&](const ViewLoop& l) { j.integer(l.inliers); });
  loop_column("confidence", [&](const ViewLoop& l) { j.num(l.confidence, 4); });
  loop_column("bow", [&](const ViewLoop& l) { j.num(l.bow, 4); });
  loop_column("matched", [&](const ViewLoop& l) { j.integer(l.matched ? 1 : 0); });
  j.close('}');
  j.key("answers").open('[');
  for (std::size_t i = 0; i < m.answers.size(); ++i) {
    const ViewAnswer& a = m.answers[i];
    j.item().open('{');
    j.key("image").str(a.image);
    j.key("accepted").raw(a.accepted ? "true" : "false");
    j.key("status").str(a.status);
    j.key("reason").str(a.reason);
    j.key("confidence").num(a.confidence, 4);
    j.key("key");
    if (m.answer_keys[i]) j.integer(static_cast<long long>(*m.answer_keys[i]));
    else j.raw("null");
    j.key("robot").str(a.robot);
    j.key("pose");
    if (a.pose) {
      j.open('{');
      j.key("position").open('[');
      for (const double x : a.pose->position) j.item().num(x, 7);
      j.close(']');
      j.key("quaternion").open('[');
      for (const double x : a.pose->quaternion) j.item().num(x, 7);
      j.close(']');
      if (posed) {
        j.key("u").num(a.pose->position[static_cast<std::size_t>(axes[0])], 7);
        j.key("v").num(a.pose->position[static_cast<std::size_t>(axes[1])], 7);
      }
      j.key("figures").open('{');
      for (const auto& [name, value] : a.pose->figures) j.key(name).num(value, 6);
      j.close('}');
      j.close('}');
    } else {
      j.raw("null");
    }
    j.key("pose_reason").str(a.pose_reason);
    j.close('}');
  }
  j.close(']');
  j.close('}');
  // The JSON in a single-quoted script string: its backslashes and quotes escaped (it holds
  // no line break: ViewJson escapes control characters).
  std::string out = "window.VMAP_VIEW = JSON.parse('";
  out.reserve(j.text().size() + j.text().size() / 16 + 64);
  for (const char c : j.text()) {
    if (c == '\\' || c == '\'') out += '\\';
    out += c;
  }
  out += "');\n";
  return out;
}

/// The folder of a page: written in a temporary folder beside `dir`, published whole.
class ViewFolder {
 public:
  explicit ViewFolder(const std::filesystem::path& dir) : set_(dir) {}
  [[nodiscard]] const std::filesystem::path& path() const noexcept { return set_.path(); }
  /// Every file flushed to disk at once (syncfs), then the folder renamed into place.
  void commit() {
    const int fd = ::open(set_.path().c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (fd >= 0) {
      const int r = ::syncfs(fd);
      const int e = errno;
      ::close(fd);
      if (r != 0) fail(ErrorKind::io, "writing the page '" + set_.target().string() + "' failed (syncfs): " + os_reason(e));
    }
    set_.commit();
  }
  [[nodiscard]] const std::filesystem::path& target() const noexcept { return set_.target(); }

 private:
  AtomicDirectory set_;
};

/// The pixels of the page's key images, and the matches of its loops.
struct ViewSources {
  using PixelSink = std::function<void(std::size_t, const cv::Mat&)>;
  using MatchSink = std::function<void(std::size_t, const std::vector<float>&)>;
  /// Calls the sink with (page index, image) for every key image whose pixels are found.
  std::function<void(const PixelSink&)> pixels;
  /// Calls the sink with (loop, inliers: view_verify_loops) for the loops verified again,
  /// in increasing order.
  std::function<void(const MatchSink&)> matches;
  std::string images_from;  ///< set by pixels()
};

/// Writes the page of `m` into `dir` (see runtime/view.hpp).
inline ViewResult write_view_model(ViewModel& m, const std::filesystem::path& dir, const ViewOptions& options,
                                   ViewSources& sources) {
  check(options.image_side >= 0, "view: image_side must be >= 0");
  check(options.jpeg_quality >= 1 && options.jpeg_quality <= 100, "view: jpeg_quality must be in [1, 100]");
  const auto t0 = std::chrono::steady_clock::now();
  ViewFolder folder(dir);
  const std::filesystem::path& out = folder.path();
  ViewResult result;
  // The key images' pixels, one file each, in folders of view_image_bucket.
  if (options.image_side > 0 && sources.pixels) {
    std::size_t made_bucket = static_cast<std::size_t>(-1);
    sources.pixels([&](std::size_t k, const cv::Mat& image) {
      if (k >= m.keys.size() || image.empty() || m.keys[k].image) return;
      const std::size_t bucket = k / view_image_bucket;
      if (bucket != made_bucket) {
        view_mkdir(out / "img" / std::to_string(bucket));
        made_bucket = bucket;
      }
      view_write(out / "img" / std::to_string(bucket) / (std::to_string(k) + ".jpg"),
                 view_jpeg(image, options.image_side, options.jpeg_quality));
      if (m.keys[k].size.empty()) m.keys[k].size = image.size();
      m.keys[k].image = true;
      ++result.images;
    });
  }
  if (options.image_side == 0) sources.images_from = "not written (image side 0)";
  // The loops' verified matches, in files of view_match_chunk loops.
  if (options.matches && sources.matches && !m.loops.empty()) {
    view_mkdir(out / "matches");
    std::optional<std::size_t> chunk;
    ViewJson j;
    const auto flush = [&] {
      if (!chunk) return;
      j.close('}').raw(");\n");
      view_write(out / "matches" / (std::to_string(*chunk) + ".js"), j.text());
      j = ViewJson();
      chunk.reset();
    };
    sources.matches([&](std::size_t i, const std::vector<float>& pts) {
      if (i >= m.loops.size()) return;
      if (chunk && *chunk != i / view_match_chunk) flush();
      if (!chunk) {
        chunk = i / view_match_chunk;
        j.raw("window.vmapMatches(").integer(static_cast<long long>(*chunk)).raw(", ").open('{');
      }
      j.key(std::to_string(i)).open('[');
      for (const float x : pts) j.item().integer(std::lround(x * 10.0f));  // tenths of a pixel
      j.close(']');
      m.loops[i].matched = true;
      ++result.matched_loops;
    });
    flush();
  }
  bool posed = !m.keys.empty();
  for (const auto& k : m.keys) posed = posed && k.position.has_value();
  const ViewUp up = posed ? view_up_axis(m.keys) : ViewUp{};
  m.summary.emplace_back(m.run_kind == "robot" ? "robots" : "sessions", std::to_string(m.runs.size()));
  m.summary.emplace_back("key images", std::to_string(m.keys.size()));
  m.summary.emplace_back("loop edges", std::to_string(m.loops.size()));
  m.summary.emplace_back("images", sources.images_from.empty() ? std::string("none") : sources.images_from);
  if (posed) {
    static constexpr const char* names[] = {"x", "y", "z"};
    m.summary.emplace_back("map", std::string("seen from above: up is ") + (up.sign > 0 ? "+" : "-") + names[up.axis] +
                                      " (chosen from the poses)");
  } else {
    std::size_t with = 0;
    for (const auto& k : m.keys) with += k.position ? 1 : 0;
    m.summary.emplace_back("map", with == 0 ? std::string("time line (no poses)")
                                            : "time line (" + std::to_string(with) + " of " + std::to_string(m.keys.size()) +
                                                  " key images have a pose)");
  }
  view_write(out / "data.js", view_data_js(m, posed, up));
  view_write(out / "index.html", view_index_html);
  view_write(out / "view.js", view_script);
  view_write(out / "view.css", view_style);
  folder.commit();
  result.index = dir / "index.html";
  result.key_images = m.keys.size();
  result.loops = m.loops.size();
  result.runs = m.runs.size();
  result.answers = m.answers.size();
  for (const auto& k : m.answer_keys) result.placed += k ? 1 : 0;
  result.posed = posed;
  result.images_from = sources.images_from;
  result.bytes = view_folder_bytes(dir);
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return result;
}

/// write_view of one memory; `location` opens it again for its pixels (view_with_pixels).
inline ViewResult write_memory_view(AnyMemory& memory, const std::filesystem::path& dir, const ViewOptions& options,
                                    const std::string& location) {
  ViewModel m;
  m.title = options.title.empty() ? memory.name() : options.title;
  view_add_summary_of(m, memory);
  if (!memory.robot().empty()) m.summary.emplace_back("robot", memory.robot());
  view_add_memory(m, memory);
  // One robot's page shows the answers of that robot's memory (a fleet's answers name it).
  std::vector<ViewAnswer> answers = options.answers;
  for (ViewAnswer& a : answers) {
    if (!a.robot.empty() && a.robot != memory.robot())
      fail(ErrorKind::invalid_argument,
           "answer of query '" + a.image + "': robot '" + a.robot + "' is not on this page (" + memory.name() + ")");
    a.robot.clear();
  }
  view_place_answers(m, answers, false);
  ViewSources sources;
  ViewPixels counts;
  sources.pixels = [&](const std::function<void(std::size_t, const cv::Mat&)>& emit) {
    view_memory_pixels(memory, 0, counts, emit, location);
    sources.images_from = counts.text(memory.key_images());
  };
  sources.matches = [&](const ViewSources::MatchSink& emit) {
    const auto& loops = memory.loops();
    view_verify_loops(
        memory.stack(), loops.size(),
        [&](std::size_t i) {
          return std::optional(ViewLoopFeatures{memory.key_features(loops[i].from),
                                                memory.key_features(loops[i].link.key), loops[i].link.inliers});
        },
        emit);
  };
  return write_view_model(m, dir, options, sources);
}

}  // namespace detail

inline ViewResult write_view(AnyMemory& memory, const std::filesystem::path& dir, const ViewOptions& options) {
  return detail::write_memory_view(memory, dir, options, {});
}

namespace detail {

/// write_view of a fleet; `uri` opens its robots again for their pixels (view_with_pixels).
inline ViewResult write_fleet_view(FleetMemory& fleet, const std::vector<FleetLoop>& between,
                                   const std::filesystem::path& dir, const ViewOptions& options, const std::string& uri) {
  ViewModel m;
  m.run_kind = "robot";
  const auto& robots = fleet.robots();
  m.title = options.title.empty() ? (robots.empty() ? std::string("fleet") : fleet.memory(0).path().string()) : options.title;
  if (!robots.empty()) {
    AnyMemory& first = fleet.memory(0);
    m.summary.emplace_back("stack", to_string(first.stack()));
    m.summary.emplace_back("camera", view_camera_text(first.stack()));
    m.summary.emplace_back("format", view_format_text(first));
  }
  std::vector<std::size_t> bases;
  for (std::size_t r = 0; r < robots.size(); ++r) {
    bases.push_back(m.keys.size());
    view_add_memory(m, fleet.memory(r), robots[r]);
  }
  const auto robot_index = [&](const std::string& name) -> std::optional<std::size_t> {
    const auto it = std::find(robots.begin(), robots.end(), name);
    if (it == robots.end()) return std::nullopt;
    return static_cast<std::size_t>(it - robots.begin());
  };
  for (const FleetLoop& l : between) {
    const auto a = robot_index(l.from_robot), b = robot_index(l.to_robot);
    // A loop of a robot that joined after the snapshot (FleetMemory::open) is not shown.
    if (!a || !b || l.from_key >= fleet.memory(*a).key_images() || l.to_key >= fleet.memory(*b).key_images()) continue;
    m.loops.push_back({bases[*a] + l.from_key, bases[*b] + l.to_key, l.link.inliers, l.link.confidence, l.link.bow_score, false});
  }
  view_place_answers(m, options.answers, true);
  ViewSources sources;
  ViewPixels counts;
  sources.pixels = [&](const std::function<void(std::size_t, const cv::Mat&)>& emit) {
    for (std::size_t r = 0; r < robots.size(); ++r) view_memory_pixels(fleet.memory(r), bases[r], counts, emit, uri);
    sources.images_from = counts.text(m.keys.size());
  };
  sources.matches = [&](const ViewSources::MatchSink& emit) {
    if (robots.empty()) return;
    const auto local = [&](std::size_t k) {
      const std::size_t r = static_cast<std::size_t>(std::upper_bound(bases.begin(), bases.end(), k) - bases.begin()) - 1;
      return std::pair{r, static_cast<std::uint32_t>(k - bases[r])};
    };
    // One stack verifies: the loops of robots of another stack are not drawn.
    const PolicyStack& stack = fleet.memory(0).stack();
    view_verify_loops(
        stack, m.loops.size(),
        [&](std::size_t i) -> std::optional<ViewLoopFeatures> {
          const auto [ra, ka] = local(m.loops[i].from);
          const auto [rb, kb] = local(m.loops[i].to);
          if (!(fleet.memory(ra).stack() == stack) || !(fleet.memory(rb).stack() == stack)) return std::nullopt;
          return ViewLoopFeatures{fleet.memory(ra).key_features(ka), fleet.memory(rb).key_features(kb),
                                  m.loops[i].inliers};
        },
        emit);
  };
  return write_view_model(m, dir, options, sources);
}

}  // namespace detail

inline ViewResult write_view(FleetMemory& fleet, const std::vector<FleetLoop>& between, const std::filesystem::path& dir,
                             const ViewOptions& options) {
  return detail::write_fleet_view(fleet, between, dir, options, {});
}

inline ViewResult write_view(const VisualMap& map, const std::filesystem::path& dir, const ViewOptions& options) {
  detail::ViewModel m;
  m.title = options.title.empty() ? std::string("visual map") : options.title;
  m.summary.emplace_back("format", "visual map file, format version " + std::to_string(map_format_version));
  detail::ViewRun r;
  r.name = "map";
  r.count = map.keys.size();
  r.frames = map.frames;
  detail::view_run_quality(r, map.pairs, 0);
  m.runs.push_back(r);
  for (std::size_t k = 0; k < map.keys.size(); ++k) {
    const KeyImage& key = map.keys[k];
    detail::ViewKey v;
    v.frame = key.frame_index;
    v.time = key.timestamp;
    v.name = key.name;
    if (k > 0 && k - 1 < map.pairs.size()) {
      v.link = map.pairs[k - 1].inliers;
      v.similarity = map.pairs[k - 1].similarity;
    }
    v.size = !key.image.empty() ? key.image.size() : key.features.image_size;
    m.keys.push_back(std::move(v));
  }
  detail::view_place_answers(m, options.answers, false);
  detail::ViewSources sources;
  sources.pixels = [&](const std::function<void(std::size_t, const cv::Mat&)>& emit) {
    std::size_t n = 0;
    for (std::size_t k = 0; k < map.keys.size(); ++k)
      if (!map.keys[k].image.empty()) {
        emit(k, map.keys[k].image);
        ++n;
      }
    sources.images_from = n == 0 ? std::string("none: the map keeps no pixels") : std::to_string(n) + " kept in the map";
  };
  return detail::write_view_model(m, dir, options, sources);
}

inline std::pair<ViewSourceKind, std::filesystem::path> view_source_kind(const std::string& source) {
  namespace fs = std::filesystem;
  if (pg::is_uri(source)) return {ViewSourceKind::fleet, fs::path(source)};
  std::error_code ec;
  const fs::path p(source);
  if (fs::is_directory(p, ec)) {
    if (fs::exists(p / memory_file_name, ec)) return {ViewSourceKind::memory, p / memory_file_name};
    if (fs::exists(p / "map.vmap", ec)) return {ViewSourceKind::visual_map, p / "map.vmap"};
    detail::fail(ErrorKind::not_found, "'" + source + "' is a folder that holds neither a memory (" +
                                           memory_file_name + ") nor a visual map (map.vmap)");
  }
  if (!fs::exists(p, ec)) detail::fail(ErrorKind::not_found, "'" + source + "' does not exist");
  if (!fs::is_regular_file(p, ec)) detail::fail(ErrorKind::invalid_argument, "'" + source + "' is not a regular file");
  if (memory_kind(p) != MemoryKind::other) return {ViewSourceKind::memory, p};
  const std::string head = detail::view_head(p, sizeof detail::map_magic);
  if (head == std::string_view(detail::map_magic, sizeof detail::map_magic)) return {ViewSourceKind::visual_map, p};
  detail::fail(ErrorKind::corrupt, "'" + source + "' is neither a vmap memory (a memory store or a .vmem memory file) nor "
                                   "a visual map (map.vmap)");
}

inline ViewResult view_source(const std::string& source, const std::filesystem::path& dir, const ViewOptions& options,
                              const std::string& robot) {
  const auto [kind, path] = view_source_kind(source);
  if (kind == ViewSourceKind::visual_map) {
    if (!robot.empty()) detail::fail("view: a robot is named, but '" + source + "' is a visual map, not a fleet's memory");
    ViewOptions o = options;
    if (o.title.empty()) o.title = path.string();
    return write_view(load_map(path), dir, o);
  }
  if (kind == ViewSourceKind::fleet && robot.empty()) {
    auto fleet = FleetMemory::open(source);
    ViewOptions o = options;
    if (o.title.empty()) o.title = pg::redacted(source);
    return detail::write_fleet_view(fleet, fleet_loops(source), dir, o, source);
  }
  if (kind == ViewSourceKind::memory && !robot.empty())
    detail::fail("view: a robot is named, but '" + source + "' is a memory file, not a fleet's memory");
  // Read without pixels (bounded whatever the memory's size): write_view decodes them
  // apart when the memory keeps them (view_with_pixels).
  auto memory = AnyMemory::open(path, {.robot = robot});
  return detail::write_memory_view(memory, dir, options, source);
}

}  // namespace vmap
