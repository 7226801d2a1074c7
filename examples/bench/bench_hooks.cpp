// bench_hooks: per-image time of the cv::dnn detector adapters and of XFeat on 640x480
// tum_fr1_rpy frames on one core, each against its baseline measured in the same run:
//   - a detector adapter (preprocessing + network + decoding + NMS) against the bare
//     network forward pass on a prepared blob (so the ratio is the adapter's overhead);
//   - XFeat (network + keypoints + descriptors) against ORB with 1000 features (the
//     visual-map paper's descriptor), and the bare XFeat forward pass.
// Then the detections (score >= 0.5) of each detector on a handful of frames of
// tum_fr1_rpy and rtabmap_loop, to be checked by eye against the images.
#include <vmap/features/orb.hpp>
#include <vmap/hooks/class_names.hpp>
#include <vmap/hooks/dnn_detectors.hpp>
#include <vmap/hooks/xfeat.hpp>
#include <vmap/io/frame_source.hpp>

#include <CLI/CLI.hpp>
#include <opencv2/core.hpp>
#include <opencv2/dnn.hpp>
#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <utility>
#include <string>
#include <vector>

namespace {

using Clock = std::chrono::steady_clock;

struct Timing {
  double median_ms = 0.0;
  double mean_ms = 0.0;
};

/// Runs `f(i)` and `g(i)` alternately over every frame, `repeat` times (after one
/// warm-up call of each), and returns the median and mean time of one call of each.
/// Interleaving exposes both to the same machine load, which matters on a shared host.
std::pair<Timing, Timing> time_pair(std::size_t frames, int repeat, const std::function<void(std::size_t)>& f,
                                    const std::function<void(std::size_t)>& g) {
  f(0);
  g(0);
  std::vector<double> ms_f, ms_g;
  const auto timed = [](const std::function<void(std::size_t)>& h, std::size_t i) {
    const auto t0 = Clock::now();
    h(i);
    return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
  };
  for (int r = 0; r < repeat; ++r)
    for (std::size_t i = 0; i < frames; ++i) {
      ms_f.push_back(timed(f, i));
      ms_g.push_back(timed(g, i));
    }
  const auto summary = [](std::vector<double> ms) {
    Timing t;
    for (const double v : ms) t.mean_ms += v;
    t.mean_ms /= static_cast<double>(ms.size());
    std::nth_element(ms.begin(), ms.begin() + static_cast<std::ptrdiff_t>(ms.size() / 2), ms.end());
    t.median_ms = ms[ms.size() / 2];
    return t;
  };
  return {summary(std::move(ms_f)), summary(std::move(ms_g))};
}

std::vector<cv::Mat> load_every(const std::filesystem::path& input, std::size_t stride, std::size_t count) {
  auto source = vmap::FrameSource::open(input, {.stride = stride});
  std::vector<cv::Mat> out;
  while (out.size() < count) {
    auto f = source.next();
    if (!f) break;
    out.push_back(f->image);
  }
  return out;
}

/// The bare network on a blob prepared outside the timed region.
struct BareNet {
  cv::dnn::Net net;
  std::vector<std::string> names;
  std::vector<cv::Mat> outs;
  void run(const cv::Mat& blob) {
    net.setInput(blob);
    net.forward(outs, names);
  }
};

BareNet bare(const std::filesystem::path& model) {
  BareNet b{cv::dnn::readNetFromONNX(model.string()), {}, {}};
  b.names = b.net.getUnconnectedOutLayersNames();
  return b;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"bench_hooks: cv::dnn detector adapters and XFeat, one core"};
  std::string shared = VMAP_SHARED_DIR;
  std::size_t frames = 20;
  int repeat = 2;
  app.add_option("--shared", shared, "The shared folder (data/, models/)")->capture_default_str();
  app.add_option("--frames", frames, "tum_fr1_rpy frames timed (every 30th)")->capture_default_str();
  app.add_option("--repeat", repeat, "Passes over the frames")->capture_default_str();
  CLI11_PARSE(app, argc, argv);
  if (shared.empty()) {
    std::fprintf(stderr, "bench_hooks: no shared folder (pass --shared)\n");
    return 1;
  }
  cv::setNumThreads(1);  // per-image time on one core
  const std::filesystem::path data = std::filesystem::path(shared) / "data";
  const std::filesystem::path models = std::filesystem::path(shared) / "models";
  try {
    const auto names = vmap::read_class_names(models / "coco80.names");
    const std::vector<cv::Mat> tum = load_every(data / "tum_fr1_rpy" / "rgb", 30, frames);
    std::printf("bench_hooks: %zu tum_fr1_rpy frames (%dx%d), %d passes, cv::setNumThreads(1), OpenCV %s\n\n",
                tum.size(), tum.front().cols, tum.front().rows, repeat, CV_VERSION);

    std::printf("%-12s %14s %14s %16s %8s\n", "model", "vmap ms/img", "baseline", "baseline ms/img", "ratio");
    struct DetectorCase {
      const char* name;
      vmap::DetectorFormat format;
      const char* file;
      int side;
      double scale;  // blob scaling of the bare-network baseline (only its time matters)
    };
    const DetectorCase cases[] = {{"yolox", vmap::DetectorFormat::yolox, "yolox_nano.onnx", 416, 1.0},
                                  {"nanodet", vmap::DetectorFormat::nanodet, "nanodet_m_320.onnx", 320, 1.0 / 57.0},
                                  {"fastestdet", vmap::DetectorFormat::fastestdet, "FastestDet.onnx", 352, 1.0 / 255}};
    for (const auto& c : cases) {
      vmap::AnyDetector det = vmap::make_dnn_detector(c.format, {.model = models / c.file});
      BareNet b = bare(models / c.file);
      std::vector<cv::Mat> blobs;
      for (const auto& img : tum) blobs.push_back(cv::dnn::blobFromImage(img, c.scale, cv::Size(c.side, c.side)));
      const auto [t, tb] = time_pair(
          tum.size(), repeat, [&](std::size_t i) { (void)det.detect(tum[i]); }, [&](std::size_t i) { b.run(blobs[i]); });
      std::printf("%-12s %14.1f %14s %16.1f %8.2f\n", c.name, t.median_ms, "net.forward", tb.median_ms,
                  t.median_ms / tb.median_ms);
    }
    {
      vmap::XFeatDescriptor xfeat({.model = models / "xfeat_320x224.onnx"});
      vmap::OrbDescriptor orb({.features = 1000});
      BareNet b = bare(models / "xfeat_320x224.onnx");
      std::vector<cv::Mat> blobs;
      for (const auto& img : tum) blobs.push_back(cv::dnn::blobFromImage(img, 1.0 / 255, cv::Size(320, 224)));
      std::size_t keypoints = 0, orb_keypoints = 0;
      const auto xfeat_once = [&](std::size_t i) { keypoints += xfeat.extract(tum[i]).size(); };
      const auto [t, tb] = time_pair(tum.size(), repeat, xfeat_once, [&](std::size_t i) { b.run(blobs[i]); });
      const auto [t2, to] = time_pair(tum.size(), repeat, xfeat_once,
                                      [&](std::size_t i) { orb_keypoints += orb.extract(tum[i]).size(); });
      std::printf("%-12s %14.1f %14s %16.1f %8.2f\n", "xfeat", t.median_ms, "net.forward", tb.median_ms,
                  t.median_ms / tb.median_ms);
      std::printf("%-12s %14.1f %14s %16.1f %8.2f\n", "xfeat", t2.median_ms, "ORB-1000", to.median_ms,
                  t2.median_ms / to.median_ms);
      const auto calls = static_cast<double>(2 * (tum.size() * static_cast<std::size_t>(repeat) + 1));
      std::printf("(keypoints per image: XFeat %.0f, ORB %.0f)\n", static_cast<double>(keypoints) / calls,
                  2.0 * static_cast<double>(orb_keypoints) / calls);
    }
    std::printf("(median of per-image times; the machine is shared, so figures are noisy)\n\n");

    // What each detector finds on a handful of frames (score >= 0.5).
    struct Shown {
      std::string sequence;
      std::filesystem::path file;
    };
    std::vector<Shown> shown;
    {
      auto tum_all = vmap::FrameSource::open(data / "tum_fr1_rpy" / "rgb");
      const auto paths = tum_all.paths();
      for (const std::size_t k : {0u, 180u, 360u, 540u, 720u}) shown.push_back({"tum_fr1_rpy", paths.at(k)});
      for (const int k : {1, 20, 30, 60, 70}) shown.push_back({"rtabmap_loop", data / "rtabmap_loop" / "images" / (std::to_string(k) + ".jpg")});
    }
    for (const auto& c : cases) {
      vmap::AnyDetector det = vmap::make_dnn_detector(c.format, {.model = models / c.file});
      std::printf("%s (score >= 0.5):\n", c.name);
      for (const auto& s : shown) {
        const cv::Mat img = cv::imread(s.file.string());
        std::string list;
        for (const auto& d : det.detect(img)) {
          char item[64];
          std::snprintf(item, sizeof item, "%s%s %.2f", list.empty() ? "" : ", ", vmap::class_name(names, d.label).c_str(),
                        static_cast<double>(d.score));
          list += item;
        }
        std::printf("  %-13s %-24s %s\n", s.sequence.c_str(), s.file.filename().string().c_str(),
                    list.empty() ? "-" : list.c_str());
      }
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_hooks: %s\n", e.what());
    return 1;
  }
  return 0;
}
