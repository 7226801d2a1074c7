#pragma once

// What the cv::dnn adapters share: loading an ONNX file with errors that name it,
// running a forward pass with the outputs picked by name, image conversion, and
// describing tensor shapes in error messages.

#include <vmap/core/error.hpp>

#include <opencv2/core.hpp>
#include <opencv2/dnn.hpp>
#include <opencv2/imgproc.hpp>

#include <filesystem>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

namespace vmap::detail {

/// "1x3549x85" for an n-dimensional Mat.
inline std::string shape_string(const cv::Mat& m) {
  if (m.empty()) return "empty";
  std::string s;
  for (int d = 0; d < m.dims; ++d) {  // appended piecewise: GCC 12 -O3 warns falsely on "x" + to_string
    if (d) s += 'x';
    s += std::to_string(m.size[d]);
  }
  return s;
}

/// The first line of an OpenCV exception (its full text repeats file and function).
inline std::string first_line(const cv::Exception& e) {
  const std::string w = e.err.empty() ? std::string(e.what()) : e.err;
  return w.substr(0, w.find('\n'));
}

/// A network loaded from an ONNX file. `who` names the adapter in error messages.
struct DnnNet {
  cv::dnn::Net net;
  std::filesystem::path file;
  std::vector<std::string> output_names;  ///< all unconnected outputs, in the graph's order
  std::vector<cv::Mat> outputs;           ///< the last forward pass, same order

  DnnNet() = default;
  DnnNet(const std::filesystem::path& model, std::string_view who) : file(model) {
    std::error_code ec;
    if (model.empty()) fail(std::string(who) + ": no model file given (set the options' model path)");
    if (!std::filesystem::is_regular_file(model, ec))
      fail(std::string(who) + ": model file '" + model.string() + "' does not exist or is not a file");
    try {
      net = cv::dnn::readNetFromONNX(model.string());
    } catch (const cv::Exception& e) {
      fail(std::string(who) + ": cannot read '" + model.string() + "' as an ONNX model: " + first_line(e));
    }
    if (net.empty()) fail(std::string(who) + ": '" + model.string() + "' holds no network");
    net.setPreferableBackend(cv::dnn::DNN_BACKEND_OPENCV);
    net.setPreferableTarget(cv::dnn::DNN_TARGET_CPU);
    output_names = net.getUnconnectedOutLayersNames();
  }

  /// Runs the network on one input blob; a model that does not accept it is an Error
  /// naming the file and the input shape (`expects` says what the format wants).
  void forward(const cv::Mat& blob, std::string_view who, std::string_view expects) {
    try {
      net.setInput(blob);
      net.forward(outputs, output_names);
    } catch (const cv::Exception& e) {
      fail(std::string(who) + ": model '" + file.string() + "' does not run on a " + shape_string(blob) +
           " input (" + std::string(expects) + "): " + first_line(e));
    }
  }

  /// Index of the output called `name`, or -1.
  [[nodiscard]] int output_index(std::string_view name) const {
    for (std::size_t i = 0; i < output_names.size(); ++i)
      if (output_names[i] == name) return static_cast<int>(i);
    return -1;
  }

  /// "output 1x3549x85, ..." for error messages.
  [[nodiscard]] std::string describe_outputs() const {
    std::string s;
    for (std::size_t i = 0; i < output_names.size(); ++i) {
      s += (i ? ", " : "") + output_names[i];
      if (i < outputs.size()) s += " " + shape_string(outputs[i]);
    }
    return s.empty() ? "no output" : s;
  }
};

/// Any supported image (8/16-bit, grey/BGR/BGRA) as 8-bit BGR; `who` names the caller.
inline void to_bgr8(const cv::Mat& image, cv::Mat& bgr, std::string_view who) {
  if (image.empty()) fail(std::string(who) + ": the image is empty (0 x 0); was the frame read?");
  const int depth = image.depth(), channels = image.channels();
  if (depth != CV_8U && depth != CV_16U)
    fail(std::string(who) + ": unsupported image depth " + cv::typeToString(image.type()) +
         "; expected 8-bit or 16-bit unsigned");
  if (channels != 1 && channels != 3 && channels != 4)
    fail(std::string(who) + ": unsupported image with " + std::to_string(channels) + " channels (" +
         cv::typeToString(image.type()) + "); expected 1 (grey), 3 (BGR) or 4 (BGRA)");
  cv::Mat eight = image;
  if (depth == CV_16U) image.convertTo(eight, CV_MAKETYPE(CV_8U, channels), 1.0 / 257.0);
  if (channels == 3)
    bgr = eight;
  else
    cv::cvtColor(eight, bgr, channels == 1 ? cv::COLOR_GRAY2BGR : cv::COLOR_BGRA2BGR);
}

}  // namespace vmap::detail
