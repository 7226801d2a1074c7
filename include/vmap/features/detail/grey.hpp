#pragma once

#include <vmap/core/error.hpp>
#include <vmap/core/features.hpp>

#include <opencv2/core.hpp>
#include <opencv2/features2d.hpp>
#include <opencv2/imgproc.hpp>

#include <string>
#include <string_view>

namespace vmap::detail {

/// Human-readable cv::Mat type ("CV_8UC2") for error messages.
inline std::string type_name(int type) { return cv::typeToString(type); }

/// Drops `buffer` unless this object alone owns its memory. A policy's scratch buffer
/// may still be an earlier input image (an 8-bit grey image is used as is, without a
/// copy); converting the next image into it would write over the caller's pixels.
inline void release_if_shared(cv::Mat& buffer) noexcept {
  if (buffer.u == nullptr || buffer.u->refcount > 1) buffer.release();
}

/// Converts any supported image to the 8-bit single-channel image the detectors want.
/// Supported: 8-bit or 16-bit, 1 (grey), 3 (BGR) or 4 (BGRA) channels. 16-bit is scaled
/// by 1/257 so 65535 maps to 255. `who` names the caller for the error message.
inline void to_grey8(const cv::Mat& image, cv::Mat& grey, std::string_view who) {
  if (image.empty())
    fail(std::string(who) + ": the image is empty (0 x 0); was the frame read?");
  const int depth = image.depth();
  const int channels = image.channels();
  if (depth != CV_8U && depth != CV_16U)
    fail(std::string(who) + ": unsupported image depth " + type_name(image.type()) +
         "; expected 8-bit or 16-bit unsigned");
  if (channels != 1 && channels != 3 && channels != 4)
    fail(std::string(who) + ": unsupported image with " + std::to_string(channels) +
         " channels (" + type_name(image.type()) + "); expected 1 (grey), 3 (BGR) or 4 (BGRA)");
  cv::Mat eight;
  if (depth == CV_16U)
    image.convertTo(eight, CV_MAKETYPE(CV_8U, channels), 1.0 / 257.0);
  else
    eight = image;
  if (channels == 1) {
    grey = eight;
  } else {
    release_if_shared(grey);
    cv::cvtColor(eight, grey, channels == 3 ? cv::COLOR_BGR2GRAY : cv::COLOR_BGRA2GRAY);
  }
}

/// Smallest image side the descriptors accept (an image below it is an Error).
inline constexpr int min_feature_image_side = 8;

/// The body every OpenCV-backed Descriptor shares: convert, detect and describe.
/// `grey` is the caller's buffer, reused between frames.
inline Features detect_and_compute(cv::Feature2D& detector, const cv::Mat& image, cv::Mat& grey, int norm,
                                   std::string_view who) {
  to_grey8(image, grey, who);
  Features f;
  f.norm = norm;
  f.image_size = grey.size();
  // OpenCV's pyramids assert on tiny images (ORB: "inv_scale_x > 0" in resize.cpp for
  // 1x1); say what was wrong with the image instead.
  if (grey.cols < min_feature_image_side || grey.rows < min_feature_image_side)
    fail(std::string(who) + ": the image is " + std::to_string(grey.cols) + "x" + std::to_string(grey.rows) +
         " pixels, too small to detect features in (at least " + std::to_string(min_feature_image_side) + "x" +
         std::to_string(min_feature_image_side) + ")");
  try {
    detector.detectAndCompute(grey, cv::noArray(), f.keypoints, f.descriptors);
  } catch (const cv::Exception& e) {
    fail(std::string(who) + ": OpenCV failed on a " + std::to_string(grey.cols) + "x" + std::to_string(grey.rows) +
         " image: " + e.err);
  }
  return f;
}

}  // namespace vmap::detail
