// `vmap detect`: run an ONNX object detector (YOLOX, NanoDet, FastestDet) through
// cv::dnn on images or a sequence; print the detections, draw them, or store them
// unfiltered in the precomputed-detections format for the loop-closure tools.
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
#include <string>
#include <vector>

namespace {

struct DetectArgs {
  std::vector<std::string> images;
  std::string sequence;
  std::string detector = "yolox";
  std::string model;
  std::string names;
  float score = 0.5f;
  std::string draw;
  bool json = false;
  std::string labels_out;
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

/// OUT.png for one image; OUT_<frame>.png for several.
std::filesystem::path draw_path(const std::string& out, std::size_t frame, bool several) {
  std::filesystem::path p(out);
  if (!several) return p;
  return p.parent_path() / (p.stem().string() + "_" + std::to_string(frame) + p.extension().string());
}

int run_detect(const DetectArgs& a) {
  if (a.images.empty() == a.sequence.empty())
    vmap::detail::fail("detect: give either images or --sequence PATH (not both)");
  vmap::detail::check(a.labels_floor >= 0.0f && a.labels_floor <= 1.0f, "--labels-floor must be in [0, 1]");
  const std::vector<std::string> names = a.names.empty() ? std::vector<std::string>{} : vmap::read_class_names(a.names);
  // Detections for --labels-out are stored unfiltered (down to the floor); the printed
  // and drawn ones use --score.
  const float threshold = a.labels_out.empty() ? a.score : std::min(a.score, a.labels_floor);
  vmap::AnyDetector detector = vmap::make_dnn_detector(
      vmap::parse_detector_format(a.detector), {.model = a.model, .score_threshold = threshold});

  struct Item {
    std::size_t frame;
    std::string name;
    cv::Mat image;
  };
  std::vector<std::filesystem::path> files(a.images.begin(), a.images.end());
  std::optional<vmap::FrameSource> source;
  if (!a.sequence.empty()) source.emplace(vmap::FrameSource::open(a.sequence));
  std::size_t next_file = 0;
  auto next = [&]() -> std::optional<Item> {
    if (source) {
      auto f = source->next();
      if (!f) return std::nullopt;
      return Item{f->index, f->name, std::move(f->image)};
    }
    if (next_file >= files.size()) return std::nullopt;
    const auto& p = files[next_file];
    cv::Mat img = cv::imread(p.string(), cv::IMREAD_COLOR);
    if (img.empty()) vmap::detail::fail("detect: cannot read the image '" + p.string() + "'");
    return Item{next_file++, p.string(), std::move(img)};
  };
  const bool several = source.has_value() || files.size() > 1;

  nlohmann::json out = nlohmann::json::array();
  std::string labels;
  std::size_t frames = 0;
  while (auto item = next()) {
    frames = std::max(frames, item->frame + 1);
    const std::vector<vmap::Detection> all = detector.detect(item->image);
    std::vector<vmap::Detection> shown;
    for (const auto& d : all) {
      if (d.score >= a.score) shown.push_back(d);
      if (!a.labels_out.empty()) {
        char line[160];
        std::snprintf(line, sizeof line, "%zu %d %.4f %.1f %.1f %.1f %.1f\n", item->frame, d.label,
                      static_cast<double>(d.score), static_cast<double>(d.box.x), static_cast<double>(d.box.y),
                      static_cast<double>(d.box.width), static_cast<double>(d.box.height));
        labels += line;
      }
    }
    if (a.json) {
      nlohmann::json dets = nlohmann::json::array();
      for (const auto& d : shown)
        dets.push_back({{"label", d.label},
                        {"name", vmap::class_name(names, d.label)},
                        {"score", d.score},
                        {"box", {d.box.x, d.box.y, d.box.width, d.box.height}}});
      out.push_back({{"image", item->name}, {"detections", dets}});
    } else {
      std::printf("%s: %zu detection%s\n", item->name.c_str(), shown.size(), shown.size() == 1 ? "" : "s");
      for (const auto& d : shown)
        std::printf("  %-14s %.3f  box %.1f %.1f %.1f %.1f\n", vmap::class_name(names, d.label).c_str(),
                    static_cast<double>(d.score), static_cast<double>(d.box.x), static_cast<double>(d.box.y),
                    static_cast<double>(d.box.width), static_cast<double>(d.box.height));
    }
    if (!a.draw.empty())
      vmap::write_image_atomically(draw_path(a.draw, item->frame, several),
                                   draw_detections(item->image, shown, names));
  }
  if (a.json) std::printf("%s\n", out.dump(2).c_str());
  if (!a.labels_out.empty()) {
    char floor[32];
    std::snprintf(floor, sizeof floor, "%.2f", static_cast<double>(threshold));
    const std::string header = "# vmap detect --detector " + a.detector + " --model " +
                               std::filesystem::path(a.model).filename().string() + ", scores >= " + floor +
                               "\n# frame label score x y w h\n# frames " + std::to_string(frames) + "\n";
    vmap::write_file_atomically(a.labels_out, header + labels);
  }
  return 0;
}

std::function<int()> setup(CLI::App& app) {
  auto args = std::make_shared<DetectArgs>();
  app.add_option("images", args->images, "Image files; frame k is the k-th (0-based) file given");
  app.add_option("--sequence", args->sequence,
                 "Instead of images: a folder (natural order), an image list, a TUM rgb.txt or a video");
  app.add_option("--detector", args->detector, "Output format of the model: yolox, nanodet or fastestdet")
      ->capture_default_str();
  app.add_option("--model", args->model, "ONNX model file")->required();
  app.add_option("--names", args->names, "Class names, one a line in output order (e.g. coco80.names)");
  app.add_option("--score", args->score, "Print and draw detections scoring at least this")->capture_default_str();
  app.add_option("--draw", args->draw, "Write the image with boxes and labels (OUT_<frame>.png for several images)");
  app.add_flag("--json", args->json, "Print a JSON list of {image, detections: [{label, name, score, box}]}");
  app.add_option("--labels-out", args->labels_out,
                 "Store every detection scoring at least --labels-floor in the precomputed-detections format");
  app.add_option("--labels-floor", args->labels_floor, "Lowest score stored by --labels-out")->capture_default_str();
  return [args] { return run_detect(*args); };
}

const bool registered = vmap::cli::add_command({"detect", "Detect objects with an ONNX detector (cv::dnn)", setup});

}  // namespace
