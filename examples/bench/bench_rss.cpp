// Peak resident memory (VmHWM of /proc/self/status) of the threshold sweep
// (keyframe/sweep.hpp, what `vmap sweep` runs) and of the visual memory
// (memory/visual_memory.hpp, OrbVisualMemory, no images kept), per frame and per key
// image, on a real sequence and on a long synthetic stream.
//
//   bench_rss stream --out FILE.avi [--minutes 30] [--fps 30] [--seed 1] [--shared DIR]
//       writes the synthetic stream (MJPEG): tum_fr1_rpy's frames played forwards, then
//       backwards, over and over, each shifted by a random (dx, dy) in [-2, 2] px and its
//       brightness scaled by [0.9, 1.1] and offset by [-12, 12] (seeded), so that no two
//       frames are equal and the selector keeps taking new key images.
//   bench_rss sweep INPUT [--end N] [--sample-every 250]
//   bench_rss memory INPUT [--end N] [--sample-every 250]
//       run one configuration and print the peak resident memory before the first frame
//       and after the last, the peak growth per frame, and the slope of the peak over
//       the second half of the run (bytes per frame; per key image for the memory).
//
// Peak memory only grows, so each configuration is its own process. The "before" figure
// of the sweep (the version that cached every frame's features) is this file compiled
// against that version's headers; examples/results/memory.md gives the commands and the figures.
#include <vmap/keyframe/sweep.hpp>
#include <vmap/memory/stacks.hpp>
#include <vmap/memory/visual_memory.hpp>

#include <CLI/CLI.hpp>

#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <vector>

namespace {

using Clock = std::chrono::steady_clock;

/// A field of /proc/self/status in bytes ("VmHWM", "VmRSS"); 0 where it is missing.
double status_bytes(const std::string& field) {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind(field + ":", 0) == 0) return 1024.0 * std::stod(line.substr(field.size() + 1));
  return 0.0;
}

struct Sample {
  double frames = 0, keys = 0, peak = 0;
};

/// Least-squares slope of the peak over x (frames or key images) on the second half of
/// the samples: the growth rate once start-up allocations are done.
double slope(const std::vector<Sample>& s, double Sample::*x) {
  const std::size_t from = s.size() / 2;
  double n = 0, sx = 0, sy = 0, sxx = 0, sxy = 0;
  for (std::size_t i = from; i < s.size(); ++i) {
    const double a = s[i].*x, b = s[i].peak;
    n += 1;
    sx += a;
    sy += b;
    sxx += a * a;
    sxy += a * b;
  }
  const double d = n * sxx - sx * sx;
  return n >= 2 && d > 0 ? (n * sxy - sx * sy) / d : 0.0;
}

void report(const char* what, const std::vector<Sample>& s, double base, double seconds) {
  const Sample& last = s.back();
  const double mb = 1024.0 * 1024.0;
  std::printf("%s: %.0f frames in %.1f s (%.1f frames/s), %.0f key images\n", what, last.frames, seconds,
              last.frames / seconds, last.keys);
  std::printf("  peak RSS before the first frame %.1f MB, after the last %.1f MB\n", base / mb, last.peak / mb);
  std::printf("  peak growth per frame %.0f B (whole run), slope %.0f B per frame (second half)\n",
              (last.peak - base) / last.frames, slope(s, &Sample::frames));
  // The sweep's key images are known only at the end (its selectors are internal): no slope.
  if (s.size() > 1 && s[s.size() - 2].keys > 0)
    std::printf("  per key image: %.0f B (whole run), slope %.0f B per key image (second half)\n",
                (last.peak - base) / last.keys, slope(s, &Sample::keys));
  else if (last.keys > 0)
    std::printf("  per key image: %.0f B (whole run)\n", (last.peak - base) / last.keys);
  std::printf("  samples (frames, key images, peak MB):");
  for (std::size_t i = 0; i + 1 < s.size(); i += std::max<std::size_t>(1, s.size() / 12))
    std::printf(" (%.0f, %.0f, %.1f)", s[i].frames, s[i].keys, s[i].peak / mb);
  std::printf(" (%.0f, %.0f, %.1f)\n", last.frames, last.keys, last.peak / mb);
}

vmap::FrameSource open(const std::string& input, std::size_t end) {
  vmap::FrameSourceOptions o{.grey = true};
  if (end > 0) o.end = end;
  return vmap::FrameSource::open(input, o);
}

int write_stream(const std::filesystem::path& shared, const std::filesystem::path& out, double minutes, double fps,
                 std::uint64_t seed) {
  std::vector<cv::Mat> real;
  auto src = open((shared / "data/tum_fr1_rpy/rgb.txt").string(), 0);
  while (auto f = src.next()) real.push_back(f->image);
  vmap::detail::check(real.size() >= 2, "bench_rss stream: tum_fr1_rpy has fewer than 2 frames");
  const auto frames = static_cast<std::size_t>(minutes * 60.0 * fps);
  // Written under a temporary name, renamed when complete (the writer picks the container
  // by the extension, so the name keeps it).
  const std::filesystem::path part = out.parent_path() / (out.stem().string() + ".part" + out.extension().string());
  cv::VideoWriter writer(part.string(), cv::CAP_OPENCV_MJPEG, cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), fps,
                         real.front().size(), true);  // OpenCV 4.6's MJPEG writer fails on grey frames
  vmap::detail::check(writer.isOpened(), "bench_rss stream: cannot write '" + part.string() + "'");
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> shift(-2.0, 2.0), gain(0.9, 1.1), offset(-12.0, 12.0);
  const std::size_t period = 2 * real.size() - 2;  // forwards, then backwards
  cv::Mat moved, adjusted, out_frame;
  for (std::size_t k = 0; k < frames; ++k) {
    const std::size_t p = k % period;
    const cv::Mat& img = real[p < real.size() ? p : period - p];
    const cv::Matx23d warp(1, 0, shift(rng), 0, 1, shift(rng));
    cv::warpAffine(img, moved, warp, img.size(), cv::INTER_LINEAR, cv::BORDER_REPLICATE);
    const double g = gain(rng), o = offset(rng);
    moved.convertTo(adjusted, CV_8U, g, o);
    cv::cvtColor(adjusted, out_frame, cv::COLOR_GRAY2BGR);
    writer.write(out_frame);
  }
  writer.release();
  std::filesystem::rename(part, out);
  std::printf("wrote %s: %zu frames (%.1f minutes at %.0f fps) from %zu real frames, seed %llu\n", out.string().c_str(),
              frames, minutes, fps, real.size(), static_cast<unsigned long long>(seed));
  return 0;
}

int run_sweep(const std::string& input, std::size_t end, std::size_t every) {
  auto src = open(input, end);
  std::vector<Sample> samples;
  const double base = status_bytes("VmHWM");
  const auto t = Clock::now();
  vmap::SweepOptions o;
  o.on_frame = [&](std::size_t done) {
    if (done % every == 0) samples.push_back({static_cast<double>(done), 0.0, status_bytes("VmHWM")});
  };
  const auto r = vmap::sweep_thresholds(src, vmap::OrbDescriptor{}, vmap::BruteForceMatcher{},
                                        vmap::FundamentalEstimator({.check_degeneracy = false}), vmap::InlierRatio{}, o);
  const double seconds = std::chrono::duration<double>(Clock::now() - t).count();
  std::size_t keys = 0;
  for (const auto& row : r.rows) keys += row.stats.key_images;
  samples.push_back({static_cast<double>(r.frames), static_cast<double>(keys), status_bytes("VmHWM")});
  report("sweep (9 thresholds; key images summed over them)", samples, base, seconds);
  std::printf("  key images per threshold:");
  for (const auto& row : r.rows) std::printf(" %.1f:%zu", row.threshold, row.stats.key_images);
  std::printf("\n");
  // SweepResult::frames_held exists since the sweep streams (not in the "before" build).
  [](const auto& res) {
    if constexpr (requires { res.frames_held; })
      std::printf("  most frames' features held at once: %zu\n", res.frames_held);
  }(r);
  std::printf("  sizes: cv::KeyPoint %zu B, cv::DMatch %zu B, vmap::PairScore %zu B, vmap::KeyPair %zu B, "
              "vmap::KeyImage %zu B\n",
              sizeof(cv::KeyPoint), sizeof(cv::DMatch), sizeof(vmap::PairScore), sizeof(vmap::KeyPair),
              sizeof(vmap::KeyImage));
  return 0;
}

int run_memory(const std::string& input, std::size_t end, std::size_t every) {
  auto src = open(input, end);
  vmap::MemoryOptions o;
  o.images = vmap::ImageStorage::none;
  vmap::OrbVisualMemory mem(o);
  std::vector<Sample> samples;
  const double base = status_bytes("VmHWM");
  const auto t = Clock::now();
  std::size_t n = 0;
  while (auto f = src.next()) {
    mem.push(*f);
    if (++n % every == 0)
      samples.push_back({static_cast<double>(n), static_cast<double>(mem.key_images()), status_bytes("VmHWM")});
  }
  const double seconds = std::chrono::duration<double>(Clock::now() - t).count();
  samples.push_back({static_cast<double>(n), static_cast<double>(mem.key_images()), status_bytes("VmHWM")});
  report("visual memory (OrbVisualMemory, tau 0.3, images none)", samples, base, seconds);
  std::printf("  loop edges %zu\n", mem.loops().size());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Peak resident memory of the threshold sweep and of the visual memory, per frame"};
  app.require_subcommand(1);
  std::string shared = VMAP_SHARED_DIR, out, input;
  double minutes = 30.0, fps = 30.0;
  std::uint64_t seed = 1;
  std::size_t end = 0, every = 250;
  auto* stream = app.add_subcommand("stream", "Write the synthetic stream (repeated, perturbed tum_fr1_rpy frames)");
  stream->add_option("--out", out, "The video to write (MJPEG .avi)")->required();
  stream->add_option("--minutes", minutes, "Length of the stream in minutes")->check(CLI::PositiveNumber);
  stream->add_option("--fps", fps, "Frames per second")->check(CLI::PositiveNumber);
  stream->add_option("--seed", seed, "Seed of the shifts and brightness changes");
  stream->add_option("--shared", shared, "The shared data folder");
  for (auto* sub : {app.add_subcommand("sweep", "Peak memory of sweep_thresholds (tau 0.1..0.9, ORB 1000, MAGSAC)"),
                    app.add_subcommand("memory", "Peak memory of OrbVisualMemory (images none)")}) {
    sub->add_option("input", input, "A video, image folder or list")->required();
    sub->add_option("--end", end, "Read frames [0, end) only (0: all)");
    sub->add_option("--sample-every", every, "Read the peak every n frames")->check(CLI::PositiveNumber);
  }
  CLI11_PARSE(app, argc, argv);
  try {
    if (stream->parsed()) return write_stream(shared, out, minutes, fps, seed);
    if (app.got_subcommand("sweep")) return run_sweep(input, end, every);
    return run_memory(input, end, every);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_rss: %s\n", e.what());
    return 1;
  }
}
