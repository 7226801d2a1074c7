#pragma once

// What every part of the Python module shares: the registry of parts (each
// part_*.cpp registers one layer's classes and functions, as each examples/vmap/*.cpp
// registers one subcommand), vmap.Error, and NumPy arrays <-> cv::Mat without copies.
//
// Images: a C-contiguous (or row-strided) uint8 or uint16 array, H x W (grey) or
// H x W x C (C = 1, 3 BGR or 4), is read in place: the cv::Mat the library sees points
// at the array's buffer (image_address() shows it). An array whose pixels are not
// contiguous within a row (a column slice, a transposed view) is copied once. Any other
// dtype (float, int32, bool) or shape is refused with vmap.Error naming the argument:
// converting it would be a guess about its range. Arrays returned by the module (images,
// descriptors) own a reference to the cv::Mat they view, so they are not copied either.

#include <vmap/core/error.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/runtime/stack.hpp>

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <opencv2/core.hpp>

#include <optional>
#include <string>
#include <vector>

namespace vmap::python {

namespace py = pybind11;

/// One layer's bindings. Parts run in ascending `order`: a part whose signatures name
/// another part's classes registers after it (so docstrings show Python names).
struct Part {
  int order = 0;
  void (*bind)(py::module_&) = nullptr;
};

inline std::vector<Part>& parts() {
  static std::vector<Part> all;
  return all;
}

/// `static const vmap::python::RegisterPart part{order, &bind};` in a part's file.
struct RegisterPart {
  RegisterPart(int order, void (*bind)(py::module_&)) { parts().push_back({order, bind}); }
};

/// Order of the parts (frames and features first: the others' signatures use them).
inline constexpr int order_core = 0;
inline constexpr int order_keyframes = 10;
inline constexpr int order_place = 20;
inline constexpr int order_loops = 30;
inline constexpr int order_memory = 40;

/// vmap.Error (a RuntimeError): vmap::Error and OpenCV's exceptions, with their message.
void bind_errors(py::module_& m);

/// Raises vmap.Error with `what` (for checks made by the bindings themselves).
[[noreturn]] inline void fail(const std::string& what) { vmap::detail::fail(what); }

/// The policy stack of the keyword arguments every part reads alike (features, nfeatures,
/// model, refine_model, estimator, camera: a calibration file), checked by the library
/// (runtime/stack_choice.hpp) with messages that name the keywords.
PolicyStack policy_stack(const std::string& features, int nfeatures, const std::string& model,
                         const std::string& refine_model, const std::string& estimator = "magsac",
                         const std::optional<std::string>& camera = std::nullopt);

/// The frame source options of the keywords vmap.frames and VisualMemory.push_frames read
/// alike (grey, start, end, stride, resize, time_offset, topic, record_time).
FrameSourceOptions frame_options(bool grey, std::size_t start, std::optional<std::size_t> end, std::size_t stride,
                                 std::optional<std::pair<int, int>> resize, double time_offset, const std::string& topic,
                                 bool record_time);

/// A cv::Mat over `a`'s pixels (see the top of this file); `what` names the argument in
/// errors ("image"). The array must outlive the Mat (the caller holds it for the call).
cv::Mat image_view(const py::array& a, const std::string& what);

/// image_view's pixels in a buffer of their own: for the calls that release the GIL
/// while they read the image, since another thread may then resize or free the array
/// (NumPy's resize(refcheck=False) moves the buffer under any view of it).
cv::Mat image_copy(const py::array& a, const std::string& what);

/// An array viewing `m` without copying it: the array holds a reference to m's buffer.
/// 2-D for one channel, 3-D (H x W x C) otherwise; uint8, uint16, int32, float32 or float64.
py::array to_array(const cv::Mat& m);

/// Calls `progress(done)` with the GIL held every `every` frames of a run that released
/// it, and lets Ctrl-C (or any pending signal handler's exception) stop the run there.
class ProgressHook {
 public:
  ProgressHook(const py::object& progress, std::size_t every) : progress_(progress), every_(every) {
    if (every_ < 1) fail("progress_every: must be >= 1");
  }

  void operator()(std::size_t done) const {
    if (done % every_ != 0) return;
    const py::gil_scoped_acquire held;
    if (PyErr_CheckSignals() != 0) throw py::error_already_set();
    if (!progress_.is_none()) progress_(done);
  }

 private:
  const py::object& progress_;
  std::size_t every_;
};

}  // namespace vmap::python
