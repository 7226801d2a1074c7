// The extension module vmap._vmap: vmap.Error, then every registered part in its order,
// and the conversions every part shares (bindings.hpp). The package's __init__.py
// re-exports it as `vmap`.

#include "bindings.hpp"

#include <vmap/io/calibration.hpp>
#include <vmap/io/image.hpp>
#include <vmap/runtime/stack_choice.hpp>
#include <vmap/version.hpp>

#include <algorithm>
#include <cstdint>
#include <iterator>
#include <string>
#include <vector>

namespace vmap::python {

namespace {

/// One subclass of vmap.Error per ErrorKind, also derived from the built-in exception a
/// Python program already catches for that failure (FileNotFoundError for a missing file,
/// OSError for a busy store or a full disk, ValueError for a bad or damaged input).
struct KindClass {
  ErrorKind kind;
  const char* name;
  PyObject* builtin;
  const char* doc;
};

/// The new class; its reference is never released (the class lives as long as the
/// process, and a static py::object would be released after the interpreter stopped).
PyObject* make_kind_class(py::module_& m, const py::object& base, const KindClass& k) {
  const std::string qualified = "vmap._vmap." + std::string(k.name);
  py::tuple bases = py::make_tuple(base, py::handle(k.builtin));
  PyObject* cls = PyErr_NewExceptionWithDoc(qualified.c_str(), k.doc, bases.ptr(), nullptr);
  if (!cls) throw py::error_already_set();
  py::handle out(cls);
  out.attr("kind") = std::string(to_string(k.kind));
  m.attr(k.name) = out;
  return cls;
}

}  // namespace

void bind_errors(py::module_& m) {
  static py::exception<vmap::Error> error(m, "Error", PyExc_RuntimeError);
  error.doc() = "A bad input (a file, an image, an option value) or a failed step, with vmap's message. "
                "Its subclasses say which kind of failure it is (their attribute `kind`).";
  static const KindClass kinds[] = {
      {ErrorKind::invalid_argument, "InvalidArgumentError", PyExc_ValueError,
       "A bad option, value or call: the caller must change it."},
      {ErrorKind::not_found, "NotFoundError", PyExc_FileNotFoundError, "A file or folder that does not exist."},
      {ErrorKind::corrupt, "CorruptError", PyExc_ValueError,
       "A file that exists but is damaged or is not of its format."},
      {ErrorKind::unsupported_version, "UnsupportedVersionError", PyExc_ValueError,
       "A file of a newer format version than this build reads."},
      {ErrorKind::policy_mismatch, "PolicyMismatchError", PyExc_ValueError,
       "A memory or vocabulary made with other policies (descriptor, stack, options)."},
      {ErrorKind::busy, "BusyError", PyExc_OSError, "A memory store another program writes (one writer at a time)."},
      {ErrorKind::io, "IoError", PyExc_OSError, "A write, flush or rename the system refused (a full disk, permissions)."},
      {ErrorKind::unavailable, "UnavailableError", PyExc_ConnectionError,
       "A database server (a fleet's memory) that cannot be reached or went away: try again later."},
  };
  // Kept for the translator, which runs after this function returned (as `error` is).
  static std::vector<PyObject*> classes;
  for (const KindClass& k : kinds) classes.push_back(make_kind_class(m, error, k));
  // vmap::Error (the library's checks of every argument it is given) as the subclass of
  // its kind, and OpenCV's own exceptions as vmap.Error.
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const vmap::Error& e) {
      for (std::size_t i = 0; i < std::size(kinds); ++i)
        if (kinds[i].kind == e.kind()) {
          PyErr_SetString(classes[i], e.what());
          return;
        }
      error(e.what());
    } catch (const cv::Exception& e) {
      error(("OpenCV: " + e.msg).c_str());
    }
  });
}

PolicyStack policy_stack(const std::string& features, int nfeatures, const std::string& model,
                         const std::string& refine_model, const std::string& estimator,
                         const std::optional<std::string>& camera) {
  StackChoice c{.descriptor = features, .features = nfeatures, .model = model, .refine_model = refine_model,
                .method = estimator};
  if (camera) {
    try {
      c.camera = read_camera(*camera);
    } catch (const vmap::Error& e) {
      fail(std::string("camera: ") + e.what());
    }
    c.camera_source = *camera;
  }
  return stack_of(c);
}

cv::Mat image_view(const py::array& a, const std::string& what) {
  const auto dtype = a.dtype();
  int depth = -1;
  if (dtype.is(py::dtype::of<std::uint8_t>())) depth = CV_8U;
  if (dtype.is(py::dtype::of<std::uint16_t>())) depth = CV_16U;
  if (depth < 0)
    fail(what + ": a " + std::string(py::str(py::handle(dtype))) +
         " array; vmap reads uint8 or uint16 images (grey H x W, or H x W x C with C = 1, 3 or 4): convert it first, "
         "e.g. (a * 255).clip(0, 255).astype(numpy.uint8) for floats in [0, 1]");
  const auto nd = a.ndim();
  const int channels = nd == 3 ? static_cast<int>(a.shape(2)) : 1;
  if ((nd != 2 && nd != 3) || (nd == 3 && channels != 1 && channels != 3 && channels != 4))
    fail(what + ": an array of shape " + std::string(py::str(a.attr("shape"))) + "; vmap reads H x W (grey) or H x W x C images with C = 1, 3 (BGR) or 4");
  if (a.shape(0) == 0 || a.shape(1) == 0) fail(what + ": an empty image (" + std::to_string(a.shape(0)) + " x " +
                                                std::to_string(a.shape(1)) + ")");
  // Bounded before any copy: a frame source's limit (io/image.hpp), which the library
  // checks again where a frame enters a memory.
  const auto pixels = static_cast<std::uint64_t>(a.shape(0)) * static_cast<std::uint64_t>(a.shape(1));
  if (pixels > default_max_image_pixels)
    fail(what + ": an image of " + std::to_string(a.shape(1)) + " x " + std::to_string(a.shape(0)) +
         " pixels, more than the limit of " + std::to_string(default_max_image_pixels));
  const auto item = static_cast<py::ssize_t>(a.itemsize());
  // In place when each row's pixels are contiguous (cv::Mat has a row step, not a
  // column step) and the rows do not overlap; copied once otherwise.
  const bool rows_contiguous = (nd == 2 || a.strides(2) == item) && a.strides(1) == item * channels &&
                               a.strides(0) >= item * channels * a.shape(1);
  const int type = CV_MAKETYPE(depth, channels);
  if (rows_contiguous)
    return cv::Mat(static_cast<int>(a.shape(0)), static_cast<int>(a.shape(1)), type, const_cast<void*>(a.data()),
                   static_cast<std::size_t>(a.strides(0)));
  const py::array copy = py::array::ensure(a, py::array::c_style);
  return cv::Mat(static_cast<int>(a.shape(0)), static_cast<int>(a.shape(1)), type, const_cast<void*>(copy.data()))
      .clone();
}

cv::Mat image_copy(const py::array& a, const std::string& what) {
  cv::Mat m = image_view(a, what);
  return m.data == a.data() ? m.clone() : m;
}

py::array to_array(const cv::Mat& m) {
  py::dtype dtype;
  switch (m.depth()) {
    case CV_8U: dtype = py::dtype::of<std::uint8_t>(); break;
    case CV_16U: dtype = py::dtype::of<std::uint16_t>(); break;
    case CV_32S: dtype = py::dtype::of<std::int32_t>(); break;
    case CV_32F: dtype = py::dtype::of<float>(); break;
    case CV_64F: dtype = py::dtype::of<double>(); break;
    default: fail("to_array: unsupported cv::Mat depth " + std::to_string(m.depth()));
  }
  if (m.empty()) return py::array(dtype, std::vector<py::ssize_t>{0, m.cols > 0 ? m.cols : 0});
  // The capsule owns a cv::Mat header sharing m's buffer (a reference count, no copy).
  auto* held = new cv::Mat(m);
  py::capsule owner(held, [](void* p) { delete static_cast<cv::Mat*>(p); });
  const auto item = static_cast<py::ssize_t>(m.elemSize1());
  std::vector<py::ssize_t> shape{m.rows, m.cols};
  std::vector<py::ssize_t> strides{static_cast<py::ssize_t>(m.step[0]), static_cast<py::ssize_t>(m.elemSize())};
  if (m.channels() > 1) {
    shape.push_back(m.channels());
    strides.push_back(item);
  }
  return py::array(dtype, shape, strides, held->data, owner);
}

}  // namespace vmap::python

PYBIND11_MODULE(_vmap, m) {
  namespace vp = vmap::python;
  m.doc() = "vmap: a visual memory for robots (key images, loop closure, localization).";
  m.attr("__version__") = std::to_string(VMAP_VERSION_MAJOR) + "." + std::to_string(VMAP_VERSION_MINOR) + "." +
                          std::to_string(VMAP_VERSION_PATCH);
  vp::bind_errors(m);
  auto parts = vp::parts();
  std::stable_sort(parts.begin(), parts.end(), [](const vp::Part& a, const vp::Part& b) { return a.order < b.order; });
  for (const auto& p : parts) p.bind(m);
}
