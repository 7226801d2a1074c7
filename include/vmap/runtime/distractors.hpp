#pragma once

// Distractor key frames for scale tests of loop closure: distinct real images made from
// the frames of other sequences (seeded crops, scales, rotations, brightness and contrast
// changes), so a place-recognition database can be filled with tens of thousands of key
// frames that look like real ones but never show the query's places. Given to run_loops
// (runtime/loops.hpp) as older key frames, a loop with one of them counts as false.
//
//   const auto sources = vmap::load_distractor_sources({"other/rgb.txt"});
//   for (std::size_t i = 0; i < n; ++i) distractors.push_back(orb.extract(vmap::make_distractor(sources, i)));

#include <vmap/core/error.hpp>
#include <vmap/io/frame_source.hpp>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <random>
#include <string>
#include <vector>

namespace vmap {

struct DistractorOptions {
  cv::Size size{256, 192};  ///< output image size (small: the benchmark extracts tens of thousands)
  double min_crop = 0.35;   ///< crop side as a share of the source's shorter side, lower bound
  double max_crop = 0.95;   ///< and upper bound
  double max_rotation_deg = 25.0;
  std::uint64_t seed = 1;
};

/// Source frames (grey) for the distractors: every frame of each FrameSource input,
/// downscaled so the longer side is at most `max_side` (keeps 10^3 frames in memory).
inline std::vector<cv::Mat> load_distractor_sources(const std::vector<std::filesystem::path>& inputs, int max_side = 640) {
  std::vector<cv::Mat> out;
  for (const auto& in : inputs) {
    auto source = FrameSource::open(in, {.grey = true});
    while (auto f = source.next()) {
      cv::Mat img = f->image;
      const int side = std::max(img.cols, img.rows);
      if (side > max_side) {
        const double s = static_cast<double>(max_side) / side;
        cv::resize(img, img, cv::Size(), s, s, cv::INTER_AREA);
      }
      out.push_back(img.clone());
    }
  }
  detail::check(!out.empty(), "load_distractor_sources: the inputs hold no frame");
  return out;
}

/// Distractor number `index` (deterministic in seed and index, independent of any other):
/// a random source frame, rotated about a random point, cropped at a random scale and
/// position, resized to `size`, with a random gain and offset of the intensities.
inline cv::Mat make_distractor(const std::vector<cv::Mat>& sources, std::size_t index, const DistractorOptions& o = {}) {
  detail::check(!sources.empty(), "make_distractor: no source frames");
  std::mt19937_64 rng(o.seed * 0x9E3779B97F4A7C15ULL + index);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  const cv::Mat& src = sources[static_cast<std::size_t>(unit(rng) * static_cast<double>(sources.size())) % sources.size()];
  const double aspect = static_cast<double>(o.size.width) / o.size.height;
  const double share = o.min_crop + unit(rng) * (o.max_crop - o.min_crop);
  const double crop_w = std::min(static_cast<double>(src.cols) - 1.0, share * std::min(src.rows, src.cols) * aspect);
  const double ch = crop_w / aspect;
  const double cx = crop_w / 2 + unit(rng) * (src.cols - crop_w);
  const double cy = ch / 2 + unit(rng) * (src.rows - ch);
  const double angle = (2 * unit(rng) - 1) * o.max_rotation_deg;
  // One affine map: rotate about the crop centre, scale the crop to the output, and move
  // the centre to the output's centre.
  const double scale = o.size.width / crop_w;
  cv::Mat m = cv::getRotationMatrix2D(cv::Point2f(static_cast<float>(cx), static_cast<float>(cy)), angle, scale);
  m.at<double>(0, 2) += o.size.width / 2.0 - cx;
  m.at<double>(1, 2) += o.size.height / 2.0 - cy;
  cv::Mat out;
  cv::warpAffine(src, out, m, o.size, cv::INTER_AREA, cv::BORDER_REFLECT);
  const double gain = 0.6 + 0.8 * unit(rng);
  const double offset = -40.0 + 80.0 * unit(rng);
  out.convertTo(out, -1, gain, offset);
  return out;
}

}  // namespace vmap
