// `vmap localize`: learn a GCS map of images with poses and localize query images
// (Trujillo-Romero 2024, examples/methods.md, sec. 3). Either the virtual-room experiment
// (--room) or a real sequence with a pose file (--train ... --poses ...). With --memory M
// IMAGE... it answers instead from a saved visual memory (`vmap build --memory`): the key
// image(s) each query image matches and, for a memory with poses and a camera, the query's
// metric pose (common/memory_cli.hpp).
#include "common/bag_options.hpp"
#include "common/cli_support.hpp"
#include "common/error_stats.hpp"
#include "common/memory_cli.hpp"
#include "vmap/cli.hpp"

#include <vmap/features/akaze.hpp>
#include <vmap/io/atomic_file.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/io/poses.hpp>
#include <vmap/som/localizer.hpp>
#include <vmap/som/pose_io.hpp>
#include <vmap/som/virtual_room.hpp>

#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <limits>
#include <memory>
#include <numbers>
#include <numeric>
#include <optional>
#include <string>
#include <vector>

namespace {

using vmap::Pose2;
namespace ex = vmap::examples;

struct Settings {
  bool room = false;
  std::string posters;
  std::string train, poses, pose_format = "auto";
  std::string query, query_poses;
  double time_offset = 0.0;  // --time-offset: added to the frame times of --train and --query
  bool every_other = false;
  std::size_t neurons = 100, lambda = 50, max_epochs = 1000;
  std::string histogram = "bow";
  int words = 128;
  std::size_t query_images = 2;
  std::uint64_t seed = 1;
  double margin = 1.5;
  std::size_t laps = 2, images_per_lap = 82, tests = 20;
  double pan_deg = 6.0;
  std::string out;
  bool json = false;
  std::string memory;               // --memory M: answer from a saved visual memory
  std::string robot;  // --robot NAME: the robot of a fleet's memory (a postgresql:// URI)
  std::optional<double> min_confidence;  // --min-confidence: with --memory, the place decision's threshold
  ex::SequenceArgs sequence;             // --sequence, --max-speed: with --memory
  std::string trajectory;                // --trajectory FILE: with --memory, the answered poses (TUM)
  std::vector<std::string> images;  // its query images
};

/// One test position: its query images and where it really is.
struct Query {
  std::vector<cv::Mat> images;
  Pose2 truth;
};

struct Experiment {
  std::vector<cv::Mat> train_images;
  std::vector<Pose2> train_poses;  // what the map is built from (odometry in the room)
  std::vector<Query> queries;
  std::optional<double> room_size;
  std::size_t skipped = 0;  ///< unreadable frames of --train and --query
};

// The poster photos when --posters is not given: the repository's sample frames, looked
// up relative to the working folder (a checkout) and to the executable (a build tree,
// build/<preset>/examples/vmap). No source path is compiled into the program, so an
// installed vmap needs --posters.
std::string default_posters() {
  namespace fs = std::filesystem;
  const fs::path rel = "examples/data/tum_fr1_rpy_60/rgb";
  std::error_code ec;
  if (fs::is_directory(rel, ec)) return rel.string();
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (!ec) {
    const fs::path from_build = exe.parent_path() / "../../.." / rel;
    if (fs::is_directory(from_build, ec)) return from_build.lexically_normal().string();
  }
  return {};
}

Experiment room_experiment(const Settings& s) {
  if (s.posters.empty())
    ex::usage_error("--posters: no poster folder given and the repository's examples/data/tum_fr1_rpy_60/rgb was "
                    "found neither under the working folder nor beside the program (give --posters DIR with at "
                    "least 16 photos)");
  vmap::VirtualRoomOptions ro;
  vmap::VirtualRoom room(vmap::load_posters(s.posters, static_cast<std::size_t>(4 * ro.posters_per_wall)), ro);
  vmap::AkazeDescriptor akaze;
  vmap::CircuitOptions co{.margin_m = s.margin, .laps = s.laps, .images_per_lap = s.images_per_lap, .seed = s.seed};
  // record_circuit's loop (capture_view at every sample), written out for the progress line.
  const auto circuit = vmap::square_circuit(ro, co);
  // Test positions: half a step off the training samples, another noise draw.
  vmap::CircuitOptions qo = co;
  qo.laps = 1;
  qo.phase = 0.5;
  qo.seed = s.seed + 1000;
  const auto qc = vmap::square_circuit(ro, qo);
  const std::size_t n = std::min(s.tests, qc.size());
  ex::Progress progress("vmap localize: rendering the room", circuit.size() + n * s.query_images, "views");
  std::size_t views = 0;
  Experiment e;
  e.room_size = ro.size_m;
  for (const auto& sample : circuit) {
    e.train_images.push_back(vmap::capture_view(room, akaze, sample.truth).image);
    e.train_poses.push_back(sample.odometry);
    progress.update(++views);
  }
  for (std::size_t k = 0; k < n; ++k) {
    const auto& sample = qc[k * qc.size() / n];
    Query q{{}, sample.truth};
    for (std::size_t i = 0; i < s.query_images; ++i) {
      q.images.push_back(vmap::capture_view(room, akaze, sample.truth,
                                            static_cast<double>(i) * s.pan_deg * std::numbers::pi / 180.0)
                             .image);
      progress.update(++views);
    }
    e.queries.push_back(std::move(q));
  }
  progress.done();
  return e;
}

struct Sequence {
  std::vector<cv::Mat> images;
  std::vector<Pose2> poses;
};

vmap::PoseFormat format_of(const std::string& name, const std::string& file) {
  if (name == "tum") return vmap::PoseFormat::tum;
  if (name == "kitti") return vmap::PoseFormat::kitti;
  if (name == "xytheta") return vmap::PoseFormat::xytheta;
  return vmap::guess_pose_format(file);
}

// Frames and poses pair by order when the counts agree (TUM key-frame sets, KITTI, x y
// theta lists); otherwise each frame takes the pose nearest in time (TUM
// groundtruth.txt at 100 Hz against rgb.txt at 30 Hz), within 20 ms.
Sequence read_sequence(const std::string& images, const std::string& poses, const std::string& format,
                       double time_offset, std::size_t& skipped) {
  Sequence out;
  vmap::FrameSourceOptions so;
  so.time_offset = time_offset;
  so.on_skip = [](const vmap::SkippedFrame& sk) {
    std::fprintf(stderr, "vmap: skipping frame %zu (%s): %s\n", sk.index, sk.name.c_str(), sk.reason.c_str());
  };
  auto src = ex::open_frames(images, so);
  std::vector<double> stamps;
  while (auto f = src.next()) {
    out.images.push_back(f->image);
    stamps.push_back(f->timestamp);
  }
  skipped += src.skipped().size();
  const auto timed = vmap::read_poses(poses, format_of(format, poses));
  for (const auto& t : vmap::poses_for_frames(timed, stamps, poses, 0.02)) out.poses.push_back(t.pose);
  return out;
}

// Consecutive query frames form the groups of one estimate; the truth is their mean.
void add_queries(Experiment& e, const Sequence& q, const std::vector<std::size_t>& idx, std::size_t per) {
  for (std::size_t k = 0; k + per <= idx.size(); k += 1) {
    Query one;
    std::vector<Pose2> truths;
    for (std::size_t i = 0; i < per; ++i) {
      one.images.push_back(q.images[idx[k + i]]);
      truths.push_back(q.poses[idx[k + i]]);
    }
    one.truth = vmap::mean_pose(truths);
    e.queries.push_back(std::move(one));
  }
}

Experiment sequence_experiment(const Settings& s) {
  Experiment e;
  const Sequence all = read_sequence(s.train, s.poses, s.pose_format, s.time_offset, e.skipped);
  if (s.every_other) {
    std::vector<std::size_t> odd;
    for (std::size_t i = 0; i < all.images.size(); ++i) {
      if (i % 2 == 0) {
        e.train_images.push_back(all.images[i]);
        e.train_poses.push_back(all.poses[i]);
      } else {
        odd.push_back(i);
      }
    }
    add_queries(e, all, odd, s.query_images);
  } else {
    e.train_images = all.images;
    e.train_poses = all.poses;
    const Sequence q = read_sequence(s.query, s.query_poses, s.pose_format, s.time_offset, e.skipped);
    std::vector<std::size_t> idx(q.images.size());
    std::iota(idx.begin(), idx.end(), std::size_t{0});
    add_queries(e, q, idx, s.query_images);
  }
  vmap::detail::check(!e.queries.empty(), "no query group of " + std::to_string(s.query_images) + " images");
  return e;
}

struct Row {
  Pose2 truth;
  vmap::Localization estimate;
  double error = 0.0;
};

cv::Mat draw_map(const vmap::PoseMap<vmap::GcsXf>& map, const Experiment& e, const std::vector<Row>& rows) {
  // Bounds of everything drawn, with a margin.
  double x0 = 1e300, y0 = 1e300, x1 = -1e300, y1 = -1e300;
  auto grow = [&](const Pose2& p) {
    x0 = std::min(x0, p.x());
    y0 = std::min(y0, p.y());
    x1 = std::max(x1, p.x());
    y1 = std::max(y1, p.y());
  };
  for (const auto& p : e.train_poses) grow(p);
  for (const auto& r : rows) grow(r.truth), grow(r.estimate.pose);
  if (e.room_size) grow(Pose2(0, 0, 0)), grow(Pose2(*e.room_size, *e.room_size, 0));
  const double span = std::max({x1 - x0, y1 - y0, 0.5});
  const double pad = 0.08 * span;
  const int side = 800, legend = 95;
  const double scale = side / (span + 2 * pad);
  auto px = [&](const Pose2& p) {
    return cv::Point(static_cast<int>((p.x() - x0 + pad) * scale), legend + static_cast<int>((y1 + pad - p.y()) * scale));
  };
  cv::Mat img(side + legend, side, CV_8UC3, cv::Scalar(255, 255, 255));
  if (e.room_size)
    cv::rectangle(img, px(Pose2(0, *e.room_size, 0)), px(Pose2(*e.room_size, 0, 0)), cv::Scalar(0, 0, 0), 3);
  for (std::size_t i = 1; i < e.train_poses.size(); ++i)
    cv::line(img, px(e.train_poses[i - 1]), px(e.train_poses[i]), cv::Scalar(200, 200, 200), 1, cv::LINE_AA);
  const auto& cells = map.neurons();
  for (const auto& [a, b] : map.network().edges())
    if (cells[a].has_pose() && cells[b].has_pose())
      cv::line(img, px(cells[a].mean), px(cells[b].mean), cv::Scalar(235, 206, 135), 1, cv::LINE_AA);
  for (const auto& c : cells)
    if (c.has_pose())
      cv::circle(img, px(c.mean), 3 + static_cast<int>(std::min<std::size_t>(c.count, 6)), cv::Scalar(160, 80, 0), -1,
                 cv::LINE_AA);
  for (const auto& r : rows) {
    cv::line(img, px(r.truth), px(r.estimate.pose), cv::Scalar(0, 0, 220), 2, cv::LINE_AA);
    cv::circle(img, px(r.truth), 6, cv::Scalar(0, 160, 0), 2, cv::LINE_AA);
    cv::drawMarker(img, px(r.estimate.pose), cv::Scalar(0, 0, 220), cv::MARKER_CROSS, 14, 2, cv::LINE_AA);
  }
  auto text = [&](const std::string& t, int y, const cv::Scalar& c) {
    cv::putText(img, t, cv::Point(10, y), cv::FONT_HERSHEY_SIMPLEX, 0.5, c, 1, cv::LINE_AA);
  };
  text("blue dots: neurons at their mean pose (size ~ images won)", 20, cv::Scalar(120, 60, 0));
  text("light blue: GCS edges, grey: training path", 40, cv::Scalar(120, 60, 0));
  text("green circles: true query positions, red crosses: estimates (red line = error)", 60, cv::Scalar(0, 0, 180));
  text("scale: " + std::to_string(span).substr(0, 4) + " m across", 80, cv::Scalar(0, 0, 0));
  return img;
}


/// The table goes to stdout, or nowhere with --json (stdout is then the JSON alone).
template <class H>
int run_with(const Settings& s, H histogram, const CLI::App& app) {
  std::FILE* table = s.json ? nullptr : stdout;
  auto say = [&](const char* fmt, auto... v) {
    if (table) std::fprintf(table, fmt, v...);
  };
  Experiment e = s.room ? room_experiment(s) : sequence_experiment(s);
  vmap::GcsOptions go{.lambda = s.lambda, .max_cells = s.neurons, .max_epochs = s.max_epochs, .seed = s.seed};
  vmap::GcsLocalizer<vmap::AkazeDescriptor, H> loc(vmap::AkazeDescriptor{}, std::move(histogram), go);
  const auto report = loc.train(e.train_images, e.train_poses);
  say("trained on %zu images: %zu neurons (%zu with a pose), %zu epochs; GCS training %.4f s "
      "(features %.2f s, histograms %.2f s)\n",
      e.train_images.size(), report.gcs.cells, loc.map().neurons_with_pose(), report.gcs.epochs, report.gcs_seconds,
      report.feature_seconds, report.histogram_seconds);
  if (e.skipped > 0) say("skipped frames: %zu (unreadable, listed above)\n", e.skipped);
  std::vector<Row> rows;
  std::vector<double> errors;
  std::size_t non_finite = 0;
  say("%4s %8s %8s %8s %8s %7s %7s %7s  %s\n", "#", "true x", "true y", "est x", "est y", "|dx|", "|dy|", "error",
      "neurons (distance)");
  ex::Progress progress("vmap localize", e.queries.size(), "queries");
  for (std::size_t k = 0; k < e.queries.size(); ++k) {
    const auto& q = e.queries[k];
    Row r{q.truth, loc.localize(q.images), 0.0};
    r.error = r.estimate.pose.distance(r.truth);
    if (std::isfinite(r.error))
      errors.push_back(r.error);
    else
      ++non_finite;
    std::string ids;
    for (const auto& m : r.estimate.matches)
      ids += std::to_string(m.neuron) + (m.substituted ? "*" : "") + " (" + std::to_string(m.distance).substr(0, 5) + ") ";
    say("%4zu %8.3f %8.3f %8.3f %8.3f %7.3f %7.3f %7.3f  %s\n", k, r.truth.x(), r.truth.y(), r.estimate.pose.x(),
        r.estimate.pose.y(), std::abs(r.estimate.pose.x() - r.truth.x()), std::abs(r.estimate.pose.y() - r.truth.y()),
        r.error, ids.c_str());
    rows.push_back(std::move(r));
    progress.update(k + 1);
  }
  const double query_seconds = progress.seconds();
  progress.done();
  const ex::ErrorStats sum = ex::error_stats(errors);
  const bool stats_finite = std::isfinite(sum.median) && std::isfinite(sum.mean) && std::isfinite(sum.max);
  if (stats_finite && !errors.empty())
    say("position error over %zu queries of %zu image(s): median %.3f m, mean %.3f m, max %.3f m"
        " (* = winner had no pose, nearest posed neuron used)\n",
        errors.size(), s.query_images, sum.median, sum.mean, sum.max);
  else
    say("position error over %zu queries: not finite (the poses are too large to compare)\n", rows.size());
  if (non_finite > 0) say("%zu queries with a non-finite error are left out of the figures\n", non_finite);
  std::vector<std::string> written;
  if (!s.out.empty()) {
    vmap::write_image_atomically(std::filesystem::path(s.out) / "map.png", draw_map(loc.map(), e, rows));
    written.push_back("map.png");
    say("map picture: %s/map.png\n", s.out.c_str());
  }
  if (s.json) {
    nlohmann::json inputs;
    if (s.room) {
      inputs["posters"] = ex::path_string(s.posters);
    } else {
      inputs["train"] = ex::path_string(s.train);
      inputs["poses"] = ex::path_string(s.poses);
      if (!s.query.empty()) inputs["query"] = ex::path_string(s.query);
      if (!s.query_poses.empty()) inputs["query_poses"] = ex::path_string(s.query_poses);
    }
    nlohmann::json j{{"command", "localize"},
                     {"inputs", inputs},
                     {"options", ex::options_json(app)},
                     {"neurons", report.gcs.cells},
                     {"neurons_with_pose", loc.map().neurons_with_pose()},
                     {"epochs", report.gcs.epochs},
                     {"train_images", e.train_images.size()},
                     {"skipped_frames", e.skipped},
                     {"seconds", report.gcs_seconds},
                     {"feature_seconds", report.feature_seconds},
                     {"histogram_seconds", report.histogram_seconds},
                     {"query_seconds", query_seconds},
                     {"query_images", s.query_images},
                     {"queries", rows.size()},
                     {"non_finite_errors", non_finite},
                     {"median_error_m", errors.empty() ? nlohmann::json(nullptr) : ex::finite_or_null(sum.median)},
                     {"mean_error_m", errors.empty() ? nlohmann::json(nullptr) : ex::finite_or_null(sum.mean)},
                     {"max_error_m", errors.empty() ? nlohmann::json(nullptr) : ex::finite_or_null(sum.max)},
                     {"out", s.out.empty() ? nlohmann::json(nullptr) : nlohmann::json(ex::path_string(s.out))},
                     {"files", written}};
    ex::print_json(j);
  }
  return 0;
}

/// Conflicting or missing options, refused before any work.
void check_settings(const Settings& s, const CLI::App& app) {
  auto given = [&](const char* name) { return app.get_option(name)->count() > 0; };
  if (s.room) {
    for (const char* o : {"--train", "--poses", "--query", "--query-poses", "--every-other", "--pose-format", "--time-offset"})
      if (given(o)) ex::usage_error(std::string("--room and ") + o + " conflict (the room makes its own images)");
  } else {
    if (s.train.empty()) ex::usage_error("give --room, --train or --memory (see vmap localize --help)");
    for (const char* o : {"--posters", "--margin", "--laps", "--images-per-lap", "--tests", "--pan"})
      if (given(o)) ex::usage_error(std::string(o) + " is an option of --room");
  }
  for (const char* o : {"--min-confidence", "--sequence", "--max-speed", "--trajectory"})
    if (given(o)) ex::usage_error(std::string(o) + " is an option of --memory");
  if (!s.room) {
    if (s.poses.empty()) ex::usage_error("--train needs --poses");
    if (s.every_other && (!s.query.empty() || !s.query_poses.empty()))
      ex::usage_error("--every-other and --query/--query-poses conflict (--every-other takes the queries from --train)");
    if (!s.every_other && (s.query.empty() || s.query_poses.empty()))
      ex::usage_error("give --query and --query-poses, or --every-other to hold out the odd frames");
  }
}

std::function<int()> setup(CLI::App& app) {
  auto s = std::make_shared<Settings>();
  app.add_flag("--room", s->room, "Run the virtual-room experiment (6 x 6 m, posters on the walls, laps of a square)");
  app.add_option("--posters", s->posters,
                 "Room: folder of photos for the posters (16 are used); default: examples/data/tum_fr1_rpy_60/rgb "
                 "under the working folder or the build tree");
  app.add_option("--train", s->train, "Training images: video, image folder, list or TUM rgb.txt");
  app.add_option("--poses", s->poses, "Poses of the training images: TUM groundtruth, KITTI poses, or x y theta lines");
  app.add_option("--pose-format", s->pose_format, "auto | tum | kitti | xytheta")
      ->check(CLI::IsMember({"auto", "tum", "kitti", "xytheta"}));
  app.add_option("--query", s->query, "Query images (with --query-poses for their true poses)");
  app.add_option("--query-poses", s->query_poses, "True poses of the query images");
  ex::add_time_offset_option(app, s->time_offset);
  ex::add_bag_options(app);
  app.add_flag("--every-other", s->every_other, "Train on the even frames of --train, localize the odd ones");
  app.add_option("--neurons", s->neurons, "GCS cells (the paper: 100, 200, 300), at most 5000 (training time grows with the square of the cells)")
      ->check(ex::count_in(3, 5000));
  app.add_option("--lambda", s->lambda, "Insert a cell every lambda inputs")->check(ex::count_in(1, 1000000));
  app.add_option("--max-epochs", s->max_epochs, "Stop after this many epochs")->check(ex::count_in(1, 1000000));
  app.add_option("--histogram", s->histogram, "bow (bag of binary words) | grid (keypoint grid)")
      ->check(CLI::IsMember({"bow", "grid"}));
  app.add_option("--words", s->words, "Words of the bow histogram (the branching of its flat, depth-1 vocabulary)")->check(ex::count_in(2, 100000));
  app.add_option("--images-per-estimate", s->query_images, "Query images per estimate (the paper: 1 or 2)")
      ->check(ex::count_in(1, 10));
  app.add_option("--seed", s->seed, "Seed of the room's noise, the vocabulary and the GCS")
      ->check(ex::count_in(0, std::numeric_limits<std::uint64_t>::max()));
  app.add_option("--margin", s->margin, "Room: distance of the circuit from the walls (m), in (0, 3)")
      ->check(ex::real_in(0.0, 2.99, true));
  app.add_option("--laps", s->laps, "Room: laps driven for training")->check(ex::count_in(1, 100));
  app.add_option("--images-per-lap", s->images_per_lap, "Room: images per lap (2 x 82 = the paper's 164)")
      ->check(ex::count_in(4, 100000));
  app.add_option("--tests", s->tests, "Room: test positions")->check(ex::count_in(1, 100000));
  app.add_option("--pan", s->pan_deg, "Room: the second query image is panned by this many degrees")
      ->check(ex::real_in(-180.0, 180.0));
  app.add_option("--out", s->out, "Folder for map.png, a picture of the map and the estimates (created if missing)");
  app.add_flag("--json", s->json, "Print a JSON summary on stdout instead of the table (with --memory: every answer)");
  app.add_option("--memory", s->memory,
                 "Answer from a saved visual memory (vmap build --memory; a folder means DIR/memory.vmdb): the key "
                 "image each IMAGE matches, instead of training a GCS map");
  app.add_option("image", s->images, "With --memory: the query images, or folders, lists or videos of query images");
  app.add_option("--min-confidence", s->min_confidence,
                 "With --memory: accept a key image at this place-decision confidence in [0, 1] (default: the "
                 "memory's, 0.5); below it the answer is \"unknown place\"")
      ->check(ex::real_in(0.0, 1.0));
  ex::add_sequence_options(app, s->sequence);
  app.add_option("--trajectory", s->trajectory,
                 "With --memory: write the queries' metric poses (a memory built with --poses and --camera) to FILE "
                 "as a TUM trajectory, with the queries' times");
  ex::add_robot_option(app, s->robot);
  return [s, &app] {
    if (!s->memory.empty()) {
      ex::refuse_other_options(app,
                               {"--memory", "--robot", "IMAGE", "--json", "--min-confidence", "--sequence", "--max-speed",
                                "--topic", "--record-time", "--trajectory"},
                               "--memory");
      if (s->images.empty()) ex::usage_error("--memory needs query images: vmap localize --memory M IMAGE...");
      return ex::localize_from_memory(vmap::memory_path(s->memory), "--memory", s->images, s->json, s->min_confidence,
                                      s->sequence, s->robot, s->trajectory);
    }
    if (!s->images.empty())
      ex::usage_error("query images on the command line need --memory M (the GCS modes take --query or --every-other)");
    check_settings(*s, app);
    if (s->room && s->posters.empty()) s->posters = default_posters();
    ex::current_inputs() = s->room ? std::vector<std::string>{s->posters}
                                   : std::vector<std::string>{s->train, s->poses, s->query, s->query_poses};
    if (!s->room) {
      ex::check_input_file(s->poses, "--poses");
      if (!s->query_poses.empty()) ex::check_input_file(s->query_poses, "--query-poses");
    } else if (!s->posters.empty()) {
      std::error_code ec;
      if (!std::filesystem::is_directory(s->posters, ec))
        ex::usage_error("--posters: '" + s->posters + "' is not a folder");
    }
    if (!s->out.empty()) {
      std::vector<std::filesystem::path> inputs;
      for (const auto& i : ex::current_inputs()) inputs.emplace_back(i);
      ex::prepare_output_dir(s->out, "--out", inputs, {"map.png"});
    }
    if (s->histogram == "grid") return run_with(*s, vmap::GridHistogram{}, app);
    vmap::BowHistogramOptions bo;
    bo.vocabulary.branching = s->words;
    bo.vocabulary.seed = s->seed;
    return run_with(*s, vmap::BowHistogram(bo), app);
  };
}

static const bool registered =
    vmap::cli::add_command({"localize", "Learn a GCS map of images with poses and localize query images", setup});

}  // namespace
