// `vmap detect`: run an ONNX object detector (YOLOX, NanoDet, FastestDet) through
// cv::dnn on images or a sequence; print the detections, draw them, or store them
// unfiltered in the precomputed-detections format for the loop-closure tools.
#include "common/bag_options.hpp"
#include "common/cli_support.hpp"
#include "vmap/cli.hpp"

#include <vmap/core/error.hpp>
#include <vmap/hooks/class_names.hpp>
#include <vmap/hooks/dnn_detectors.hpp>
#include <vmap/io/atomic_file.hpp>
#include <vmap/io/frame_source.hpp>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <optional>
#include <set>
#include <string>
#include <vector>

namespace {

namespace ex = vmap::examples;

struct DetectArgs {
  std::vector<std::string> images;
  std::string sequence;
  std::string detector = "yolox";
  std::string model;
  std::string names;
  float score = 0.5f;
  std::string out;
  bool draw = false;
  bool json = false;
  float labels_floor = 0.1f;
};

cv::Scalar colour_of(int label) {
  // A fixed, well-spread hue per label so one class keeps its colour across frames.
  cv::Mat hsv(1, 1, CV_8UC3, cv::Scalar((label * 47) % 180, 220, 230)), bgr;
  cv::cvtColor(hsv, bgr, cv::COLOR_HSV2BGR);
  const auto c = bgr.at<cv::Vec3b>(0, 0);
  return {static_cast<double>(c[0]), static_cast<double>(c[1]), static_cast<double>(c[2])};
}

cv::Mat draw_detections(const cv::Mat& image, const std::vector<vmap::Detection>& dets,
                        const std::vector<std::string>& names) {
  cv::Mat canvas;
  if (image.channels() == 1)
    cv::cvtColor(image, canvas, cv::COLOR_GRAY2BGR);
  else
    canvas = image.clone();
  for (const auto& d : dets) {
    const cv::Scalar c = colour_of(d.label);
    const cv::Rect box(cv::Point(cvRound(d.box.x), cvRound(d.box.y)),
                       cv::Point(cvRound(d.box.x + d.box.width), cvRound(d.box.y + d.box.height)));
    cv::rectangle(canvas, box, c, 2, cv::LINE_AA);
    char text[96];
    std::snprintf(text, sizeof text, "%s %.2f", vmap::class_name(names, d.label).c_str(), static_cast<double>(d.score));
    int base = 0;
    const cv::Size ts = cv::getTextSize(text, cv::FONT_HERSHEY_SIMPLEX, 0.5, 1, &base);
    const cv::Point org(box.x, std::max(ts.height + 2, box.y - 3));
    cv::rectangle(canvas, cv::Rect(org.x, org.y - ts.height - 2, ts.width + 4, ts.height + base + 2), c, cv::FILLED);
    cv::putText(canvas, text, {org.x + 2, org.y}, cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar::all(0), 1, cv::LINE_AA);
  }
  return canvas;
}

/// The picture's name in --out: the image's own stem ("frame_<k>" for video frames), made
/// unique with the frame index when two frames share a stem.
std::string draw_name(const std::string& frame_name, std::size_t frame, std::set<std::string>& used) {
  std::string stem = frame_name.find('#') != std::string::npos ? "frame_" + std::to_string(frame)
                                                                : std::filesystem::path(frame_name).stem().string();
  if (stem.empty()) stem = "frame_" + std::to_string(frame);
  if (!used.insert(stem).second) {
    stem += "_" + std::to_string(frame);
    used.insert(stem);
  }
  return stem + ".png";
}

int run_detect(const DetectArgs& a, const CLI::App& app) {
  if (a.images.empty() == a.sequence.empty())
    ex::usage_error("give either images or --sequence PATH (not both)");
  if (a.draw && a.out.empty()) ex::usage_error("--draw writes into --out DIR: give --out");
  std::vector<std::filesystem::path> inputs(a.images.begin(), a.images.end());
  if (!a.sequence.empty()) inputs.push_back(a.sequence);
  ex::current_inputs().assign(a.images.begin(), a.images.end());
  if (!a.sequence.empty()) ex::current_inputs().push_back(a.sequence);
  ex::check_input_file(a.model, "--model");
  if (!a.names.empty()) ex::check_input_file(a.names, "--names");
  inputs.push_back(a.model);
  if (!a.names.empty()) inputs.push_back(a.names);
  std::optional<ex::OutputFolder> out_dir;
  if (!a.out.empty()) out_dir.emplace(a.out, "--out", inputs, std::vector<std::string>{"detections.txt"});
  const std::vector<std::string> names = a.names.empty() ? std::vector<std::string>{} : vmap::read_class_names(a.names);
  // Detections for detections.txt are stored unfiltered (down to the floor); the printed
  // and drawn ones use --score.
  const float threshold = a.out.empty() ? a.score : std::min(a.score, a.labels_floor);
  vmap::AnyDetector detector = vmap::make_dnn_detector(
      vmap::parse_detector_format(a.detector), {.model = a.model, .score_threshold = threshold});

  struct Item {
    std::size_t frame;
    std::string name;
    cv::Mat image;
  };
  std::vector<std::filesystem::path> files(a.images.begin(), a.images.end());
  std::optional<vmap::FrameSource> source;
  if (!a.sequence.empty()) source.emplace(ex::open_frames(a.sequence, ex::reporting_skips()));
  std::size_t next_file = 0;
  auto next = [&]() -> std::optional<Item> {
    if (source) {
      auto f = source->next();
      if (!f) return std::nullopt;
      return Item{f->index, f->name, std::move(f->image)};
    }
    if (next_file >= files.size()) return std::nullopt;
    const auto& p = files[next_file];
    cv::Mat img = vmap::read_image(p, {.flags = cv::IMREAD_COLOR});
    return Item{next_file++, p.string(), std::move(img)};
  };

  nlohmann::json out = nlohmann::json::array();
  std::string labels;
  std::size_t frames = 0, done = 0;
  std::set<std::string> used;
  std::vector<std::string> written;
  ex::Progress progress("vmap detect", source ? source->total() : std::optional<std::size_t>(files.size()));
  while (auto item = next()) {
    frames = std::max(frames, item->frame + 1);
    const std::vector<vmap::Detection> all = detector.detect(item->image);
    std::vector<vmap::Detection> shown;
    for (const auto& d : all) {
      if (d.score >= a.score) shown.push_back(d);
      if (!a.out.empty()) {
        char line[160];
        std::snprintf(line, sizeof line, "%zu %d %.4f %.1f %.1f %.1f %.1f\n", item->frame, d.label,
                      static_cast<double>(d.score), static_cast<double>(d.box.x), static_cast<double>(d.box.y),
                      static_cast<double>(d.box.width), static_cast<double>(d.box.height));
        labels += line;
      }
    }
    std::string drawn;
    if (a.draw) {
      drawn = draw_name(item->name, item->frame, used);
      vmap::write_image_atomically((*out_dir) / drawn, draw_detections(item->image, shown, names));
      written.push_back(drawn);
    }
    if (a.json) {
      nlohmann::json dets = nlohmann::json::array();
      for (const auto& d : shown)
        dets.push_back({{"label", d.label},
                        {"name", vmap::class_name(names, d.label)},
                        {"score", d.score},
                        {"box", {d.box.x, d.box.y, d.box.width, d.box.height}}});
      out.push_back({{"image", ex::path_string(item->name)},
                     {"frame", item->frame},
                     {"detections", dets},
                     {"drawn", drawn.empty() ? nlohmann::json(nullptr) : nlohmann::json(drawn)}});
    } else {
      std::printf("%s: %zu detection%s\n", item->name.c_str(), shown.size(), shown.size() == 1 ? "" : "s");
      for (const auto& d : shown)
        std::printf("  %-14s %.3f  box %.1f %.1f %.1f %.1f\n", vmap::class_name(names, d.label).c_str(),
                    static_cast<double>(d.score), static_cast<double>(d.box.x), static_cast<double>(d.box.y),
                    static_cast<double>(d.box.width), static_cast<double>(d.box.height));
    }
    progress.update(++done);
  }
  const double seconds = progress.seconds();
  const std::size_t skipped = source ? source->skipped().size() : 0;
  progress.done(std::to_string(skipped) + " skipped");
  if (!a.out.empty()) {
    char floor[32];
    std::snprintf(floor, sizeof floor, "%.2f", static_cast<double>(threshold));
    const std::string header = "# vmap detect --detector " + a.detector + " --model " +
                               std::filesystem::path(a.model).filename().string() + ", scores >= " + floor +
                               "\n# frame label score x y w h\n# frames " + std::to_string(frames) + "\n";
    vmap::write_file_atomically((*out_dir) / "detections.txt", header + labels);
    out_dir->commit();
    written.insert(written.begin(), "detections.txt");
  }
  if (a.json) {
    nlohmann::json inputs_json = nlohmann::json::array();
    for (const auto& i : a.images) inputs_json.push_back(ex::path_string(i));
    nlohmann::json j{{"command", "detect"},
                     {"inputs", inputs_json},
                     {"sequence", a.sequence.empty() ? nlohmann::json(nullptr) : nlohmann::json(ex::path_string(a.sequence))},
                     {"options", ex::options_json(app)},
                     {"frames", done},
                     {"skipped_frames", skipped},
                     {"seconds", seconds},
                     {"fps", seconds > 0 ? static_cast<double>(done) / seconds : 0.0},
                     {"images", out},
                     {"out", a.out.empty() ? nlohmann::json(nullptr) : nlohmann::json(ex::path_string(a.out))},
                     {"files", written}};
    ex::print_json(j);
  } else {
    if (skipped > 0) std::printf("skipped frames: %zu (unreadable, listed above)\n", skipped);
    if (!a.out.empty())
      std::printf("wrote %s/detections.txt%s\n", a.out.c_str(),
                  a.draw ? (" and " + std::to_string(written.size() - 1) + " pictures").c_str() : "");
  }
  return 0;
}

std::function<int()> setup(CLI::App& app) {
  auto args = std::make_shared<DetectArgs>();
  app.add_option("images", args->images, "Image files; frame k is the k-th (0-based) file given");
  ex::add_bag_options(app);
  app.add_option("--sequence", args->sequence,
                 "Instead of images: a folder (natural order), an image list, a TUM rgb.txt or a video");
  app.add_option("--detector", args->detector, "Output format of the model: yolox, nanodet or fastestdet")
      ->check(CLI::IsMember({"yolox", "nanodet", "fastestdet"}));
  app.add_option("--model", args->model, "ONNX model file")->required();
  app.add_option("--names", args->names, "Class names, one a line in output order (e.g. coco80.names)");
  app.add_option("--score", args->score, "Print and draw detections scoring at least this")
      ->check(ex::real_in(0.0, 1.0));
  app.add_option("--out", args->out,
                 "Folder for detections.txt (every detection scoring at least --labels-floor, the "
                 "precomputed-detections format of vmap loops --labels) and, with --draw, the pictures");
  app.add_flag("--draw", args->draw, "Write each image with boxes and labels into --out as <image name>.png");
  app.add_flag("--json", args->json, "Print one JSON object on stdout (per image: detections scoring >= --score)");
  app.add_option("--labels-floor", args->labels_floor, "Lowest score stored in detections.txt")
      ->check(ex::real_in(0.0, 1.0));
  return [args, &app] { return run_detect(*args, app); };
}

const bool registered = vmap::cli::add_command({"detect", "Detect objects with an ONNX detector (cv::dnn)", setup});

}  // namespace
