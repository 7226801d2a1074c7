#pragma once

// Pictures a person can look at: verified matches side by side (inliers green,
// outliers blue, as in the visual-map paper's figures) and contact sheets.

#include <vmap/core/features.hpp>
#include <vmap/core/verification.hpp>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <string>
#include <vector>

namespace vmap::examples {

inline cv::Mat as_bgr(const cv::Mat& image) {
  cv::Mat out;
  cv::Mat eight = image;
  if (image.depth() == CV_16U) image.convertTo(eight, CV_MAKETYPE(CV_8U, image.channels()), 1.0 / 257.0);
  if (eight.channels() == 1)
    cv::cvtColor(eight, out, cv::COLOR_GRAY2BGR);
  else if (eight.channels() == 4)
    cv::cvtColor(eight, out, cv::COLOR_BGRA2BGR);
  else
    out = eight.clone();
  return out;
}

/// Image a | image b with a line per match: green for inliers of `v`, blue for the rest.
inline cv::Mat draw_verified_matches(const cv::Mat& image_a, const Features& a, const cv::Mat& image_b,
                                     const Features& b, const Matches& matches, const Verification& v) {
  const cv::Mat ca = as_bgr(image_a), cb = as_bgr(image_b);
  cv::Mat canvas(std::max(ca.rows, cb.rows), ca.cols + cb.cols, CV_8UC3, cv::Scalar::all(0));
  ca.copyTo(canvas(cv::Rect(0, 0, ca.cols, ca.rows)));
  cb.copyTo(canvas(cv::Rect(ca.cols, 0, cb.cols, cb.rows)));
  const cv::Point2f shift(static_cast<float>(ca.cols), 0.0f);
  for (int pass = 0; pass < 2; ++pass)  // outliers first so inliers stay visible on top
    for (std::size_t k = 0; k < matches.size(); ++k) {
      const bool inlier = k < v.inlier_mask.size() && v.inlier_mask[k] != 0;
      if (inlier != (pass == 1)) continue;
      const cv::Point2f p = a.keypoints[static_cast<std::size_t>(matches[k].queryIdx)].pt;
      const cv::Point2f q = b.keypoints[static_cast<std::size_t>(matches[k].trainIdx)].pt + shift;
      const cv::Scalar colour = inlier ? cv::Scalar(0, 200, 0) : cv::Scalar(255, 80, 0);
      cv::line(canvas, p, q, colour, 1, cv::LINE_AA);
      cv::circle(canvas, p, 2, colour, -1, cv::LINE_AA);
      cv::circle(canvas, q, 2, colour, -1, cv::LINE_AA);
    }
  return canvas;
}

/// A grid of thumbnails with a caption under each.
inline cv::Mat contact_sheet(const std::vector<cv::Mat>& images, const std::vector<std::string>& captions,
                             int columns = 6, int thumb_width = 200) {
  if (images.empty()) return {};
  columns = std::max(1, std::min(columns, static_cast<int>(images.size())));
  const int rows = (static_cast<int>(images.size()) + columns - 1) / columns;
  const double aspect = static_cast<double>(images[0].rows) / std::max(1, images[0].cols);
  const int thumb_h = static_cast<int>(thumb_width * aspect);
  const int cell_h = thumb_h + 22;
  cv::Mat sheet(rows * cell_h, columns * thumb_width, CV_8UC3, cv::Scalar::all(255));
  for (std::size_t i = 0; i < images.size(); ++i) {
    const int r = static_cast<int>(i) / columns, c = static_cast<int>(i) % columns;
    cv::Mat t;
    cv::resize(as_bgr(images[i]), t, cv::Size(thumb_width, thumb_h), 0, 0, cv::INTER_AREA);
    t.copyTo(sheet(cv::Rect(c * thumb_width, r * cell_h, thumb_width, thumb_h)));
    if (i < captions.size())
      cv::putText(sheet, captions[i], {c * thumb_width + 4, r * cell_h + thumb_h + 16}, cv::FONT_HERSHEY_SIMPLEX,
                  0.45, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  }
  return sheet;
}

/// The image with a white band above it holding `caption` (shrunk to fit the width).
inline cv::Mat captioned(const cv::Mat& image, const std::string& caption) {
  const cv::Mat img = as_bgr(image);
  const int band = 30;
  cv::Mat out(img.rows + band, img.cols, CV_8UC3, cv::Scalar::all(255));
  img.copyTo(out(cv::Rect(0, band, img.cols, img.rows)));
  double scale = 0.6;
  int base = 0;
  while (scale > 0.3 && cv::getTextSize(caption, cv::FONT_HERSHEY_SIMPLEX, scale, 1, &base).width > img.cols - 10)
    scale -= 0.05;
  cv::putText(out, caption, {5, band - 9}, cv::FONT_HERSHEY_SIMPLEX, scale, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  return out;
}

/// Panels one above the other, left-aligned on white.
inline cv::Mat stack_vertically(const std::vector<cv::Mat>& panels, int gap = 8) {
  int width = 0, height = 0;
  for (const auto& p : panels) width = std::max(width, p.cols), height += p.rows + gap;
  if (panels.empty()) return {};
  cv::Mat out(height - gap, width, CV_8UC3, cv::Scalar::all(255));
  int y = 0;
  for (const auto& p : panels) {
    as_bgr(p).copyTo(out(cv::Rect(0, y, p.cols, p.rows)));
    y += p.rows + gap;
  }
  return out;
}

}  // namespace vmap::examples
