#pragma once

// What the cv::dnn adapters share: loading an ONNX file with errors that name it,
// running a forward pass with the outputs picked by name, image conversion, and
// describing tensor shapes in error messages.

#include <vmap/core/error.hpp>
#include <vmap/features/detail/grey.hpp>
#include <vmap/io/files.hpp>

#include <opencv2/core.hpp>
#include <opencv2/dnn.hpp>
#include <opencv2/imgproc.hpp>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <memory>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

namespace vmap {

/// Largest ONNX model file read. The models vmap runs are 1-50 MB (XFeat 1-4 MB, YOLO
/// exports up to ~250 MB for the largest); a path recorded in a memory can name anything,
/// and a larger file (or /dev/zero, which never ends) is not a model to read whole.
inline constexpr std::uintmax_t max_model_file_bytes = std::uintmax_t{1} << 30;  // 1 GiB

}  // namespace vmap

namespace vmap::detail {

/// The bytes of a model file, refused by name before it is opened when it is missing, a
/// folder, not a regular file (a device such as /dev/zero, a FIFO) or larger than
/// `max_model_file_bytes`. `who` names the adapter reading it.
inline std::string read_model_file(const std::filesystem::path& model, std::string_view who) {
  if (model.empty()) fail(std::string(who) + ": no model file given (set the options' model path)");
  try {
    return read_file(model, max_model_file_bytes, "model file");
  } catch (const Error& e) {
    fail(e.kind(), std::string(who) + ": " + e.what());
  }
}

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

/// Per-object working memory (images, blobs, candidate lists, last outputs) that a
/// policy reuses between calls. A copy starts empty instead of sharing it: a cv::Mat
/// copy shares its pixels, so a defaulted copy of a policy would have two objects, and
/// so two threads, writing one buffer. Moves keep it.
template <class T>
struct Scratch {
  T value{};

  Scratch() = default;
  Scratch(const Scratch&) {}
  Scratch& operator=(const Scratch&) {
    value = T{};
    return *this;
  }
  Scratch(Scratch&&) noexcept = default;
  Scratch& operator=(Scratch&&) noexcept = default;
  ~Scratch() = default;

  T* operator->() noexcept { return &value; }
  const T* operator->() const noexcept { return &value; }
  T& operator*() noexcept { return value; }
  const T& operator*() const noexcept { return value; }
};

/// A network loaded from an ONNX file. `who` names the adapter in error messages.
///
/// Deep copy: cv::dnn::Net is a shared handle (its copies run one network with one set
/// of buffers, so two threads using two copies race) and has no clone, so a copy parses
/// the model again into its own Net. The file's bytes are kept in memory (shared,
/// immutable, about the size of the file: 1-4 MB for the models in ../shared/models) so
/// that a copy neither re-reads a file that may have changed or gone nor can fail on
/// it: every copy runs exactly the network the original loaded. Moves are cheap and
/// leave the moved-from object fit only for assignment or destruction.
struct DnnNet {
  cv::dnn::Net net;
  std::filesystem::path file;
  std::shared_ptr<const std::string> bytes;  ///< the model file's contents, shared by copies
  std::vector<std::string> output_names;     ///< all unconnected outputs, in the graph's order
  std::vector<cv::Mat> outputs;              ///< the last forward pass, same order (not copied)

  DnnNet() = default;
  DnnNet(const std::filesystem::path& model, std::string_view who) : file(model) {
    bytes = std::make_shared<const std::string>(read_model_file(model, who));
    net = parse(who);
    output_names = net.getUnconnectedOutLayersNames();
  }

  DnnNet(const DnnNet& other)
      : file(other.file), bytes(other.bytes), output_names(other.output_names) {
    if (bytes) net = parse("copy of a network");
  }
  DnnNet& operator=(const DnnNet& other) {
    if (this != &other) *this = DnnNet(other);
    return *this;
  }
  DnnNet(DnnNet&&) noexcept = default;
  DnnNet& operator=(DnnNet&&) noexcept = default;
  ~DnnNet() = default;

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

  /// A new cv::dnn::Net from `bytes`, on OpenCV's own CPU backend.
  [[nodiscard]] cv::dnn::Net parse(std::string_view who) const {
    cv::dnn::Net n;
    try {
      n = cv::dnn::readNetFromONNX(bytes->data(), bytes->size());
    } catch (const cv::Exception& e) {
      fail(std::string(who) + ": cannot read '" + file.string() + "' as an ONNX model: " + first_line(e));
    }
    if (n.empty()) fail(std::string(who) + ": '" + file.string() + "' holds no network");
    n.setPreferableBackend(cv::dnn::DNN_BACKEND_OPENCV);
    n.setPreferableTarget(cv::dnn::DNN_TARGET_CPU);
    return n;
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
  if (channels == 3) {
    bgr = eight;
  } else {
    release_if_shared(bgr);  // bgr may still be the caller's previous BGR image
    cv::cvtColor(eight, bgr, channels == 1 ? cv::COLOR_GRAY2BGR : cv::COLOR_BGRA2BGR);
  }
}

}  // namespace vmap::detail
