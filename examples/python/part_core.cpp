// vmap.frames (every frame source the command line reads), vmap.image_address (where the
// library reads an array's pixels), descriptors, features and matches as NumPy arrays.

#include "bindings.hpp"

#include <vmap/hooks/any_descriptor.hpp>
#include <vmap/io/bag/bag.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/matching/brute_force.hpp>
#include <vmap/runtime/policies.hpp>
#include <vmap/runtime/stack.hpp>

#include <cstdint>
#include <limits>
#include <memory>
#include <optional>
#include <string>

namespace vmap::python {

FrameSourceOptions frame_options(bool grey, std::size_t start, std::optional<std::size_t> end, std::size_t stride,
                                 std::optional<std::pair<int, int>> resize, double time_offset, const std::string& topic,
                                 bool record_time) {
  FrameSourceOptions o;
  o.grey = grey;
  o.start = start;
  o.end = end.value_or(std::numeric_limits<std::size_t>::max());
  o.stride = stride;
  if (resize) o.resize = cv::Size(resize->first, resize->second);
  o.time_offset = time_offset;
  o.topic = topic;
  o.record_time = record_time;
  return o;
}

namespace {

/// The Python iterator over a FrameSource: (image, timestamp, name) per frame.
class Frames {
 public:
  Frames(const std::string& source, bool grey, std::size_t start, std::optional<std::size_t> end, std::size_t stride,
         std::optional<std::pair<int, int>> resize, double time_offset, const std::string& topic, bool record_time)
      : source_(FrameSource::open(source, frame_options(grey, start, end, stride, resize, time_offset, topic, record_time))) {}

  py::tuple next() {
    std::optional<Frame> f;
    {
      py::gil_scoped_release unlocked;  // decoding an image is the long part
      f = source_.next();
    }
    if (!f) throw py::stop_iteration();
    return py::make_tuple(to_array(f->image), f->timestamp, f->name);
  }

  [[nodiscard]] const FrameSource& source() const noexcept { return source_; }

 private:

  FrameSource source_;
};

const char* kind_name(SourceKind k) {
  switch (k) {
    case SourceKind::video: return "video";
    case SourceKind::image_folder: return "image_folder";
    case SourceKind::image_list: return "image_list";
    case SourceKind::tum_rgb: return "tum_rgb";
    case SourceKind::live: return "live";
    case SourceKind::euroc: return "euroc";
    case SourceKind::bag: return "bag";
  }
  return "unknown";
}

/// Keypoints as an N x 6 float32 array: x, y, size, angle, response, octave.
py::array_t<float> keypoint_array(const std::vector<cv::KeyPoint>& kps) {
  py::array_t<float> out({static_cast<py::ssize_t>(kps.size()), py::ssize_t{6}});
  auto v = out.mutable_unchecked<2>();
  for (std::size_t i = 0; i < kps.size(); ++i) {
    const auto r = static_cast<py::ssize_t>(i);
    v(r, 0) = kps[i].pt.x;
    v(r, 1) = kps[i].pt.y;
    v(r, 2) = kps[i].size;
    v(r, 3) = kps[i].angle;
    v(r, 4) = kps[i].response;
    v(r, 5) = static_cast<float>(kps[i].octave);
  }
  return out;
}

/// A descriptor chosen by name, as the command line's --features / --nfeatures / --model.
class PyDescriptor {
 public:
  PyDescriptor(const std::string& features, int nfeatures, const std::string& model, const std::string& refine_model)
      : stack_(policy_stack(features, nfeatures, model, refine_model)),
        descriptor_(with_descriptor(stack_, [](auto d) { return AnyDescriptor(std::move(d)); })) {}

  Features extract(const py::array& image) {
    const cv::Mat view = image_copy(image, "image");
    py::gil_scoped_release unlocked;
    return descriptor_.extract(view);
  }

  [[nodiscard]] const PolicyStack& stack() const noexcept { return stack_; }

 private:
  PolicyStack stack_;
  AnyDescriptor descriptor_;
};

/// Matches as an M x 3 array: query index, train index, distance (float32).
py::array_t<float> match_array(const Matches& ms) {
  py::array_t<float> out({static_cast<py::ssize_t>(ms.size()), py::ssize_t{3}});
  auto v = out.mutable_unchecked<2>();
  for (std::size_t i = 0; i < ms.size(); ++i) {
    const auto r = static_cast<py::ssize_t>(i);
    v(r, 0) = static_cast<float>(ms[i].queryIdx);
    v(r, 1) = static_cast<float>(ms[i].trainIdx);
    v(r, 2) = ms[i].distance;
  }
  return out;
}

void bind(py::module_& m) {
  py::class_<Frames>(m, "Frames", "The frames of a source, as (image, timestamp, name) tuples (vmap.frames).")
      .def("__iter__", [](Frames& f) -> Frames& { return f; })
      .def("__next__", &Frames::next)
      .def_property_readonly("kind", [](const Frames& f) { return kind_name(f.source().kind()); },
                             "video, image_folder, image_list, tum_rgb, live, euroc or bag")
      .def_property_readonly("total", [](const Frames& f) { return f.source().total(); },
                             "frames in the underlying sequence when known (lists, folders, videos that report\n"
                             "a count), before start/end/stride; None for a camera")
      .def_property_readonly("delivered", [](const Frames& f) { return f.source().delivered(); },
                             "frames delivered so far")
      .def_property_readonly(
          "skipped",
          [](const Frames& f) {
            py::list out;
            for (const auto& s : f.source().skipped()) out.append(py::make_tuple(s.index, s.name, s.reason));
            return out;
          },
          "frames that could not be decoded and were skipped, as (index, name, reason)")
      .def_property_readonly(
          "topic", [](const Frames& f) -> std::optional<std::string> {
            const auto t = f.source().bag_topic();
            return t ? std::optional<std::string>(t->name) : std::nullopt;
          },
          "a bag's image topic read; None for other sources")
      .def_property_readonly(
          "camera",
          [](const Frames& f) -> py::object {
            const auto& c = f.source().camera();
            if (!c) return py::none();
            py::dict d;
            d["lens"] = c->camera.lens == LensModel::fisheye ? "fisheye" : "pinhole";
            d["fx"] = c->camera.fx;
            d["fy"] = c->camera.fy;
            d["cx"] = c->camera.cx;
            d["cy"] = c->camera.cy;
            d["distortion"] = c->camera.distortion;
            d["image_size"] = py::make_tuple(c->camera.image_size.width, c->camera.image_size.height);
            d["source"] = c->source;
            return d;
          },
          "a bag's calibration from the CameraInfo topic beside the image topic, as a dict (lens, fx, fy, cx, cy,\n"
          "distortion, image_size, source); None without one")
      .def_property_readonly("warnings", [](const Frames& f) { return f.source().warnings(); },
                             "damage found in a bag so far (a truncated file, a corrupt chunk), each naming its byte")
      .def("__repr__", [](const Frames& f) {
        const auto total = f.source().total();
        return "<vmap.Frames " + std::string(kind_name(f.source().kind())) + ", " +
               std::to_string(f.source().delivered()) + " delivered" +
               (total ? " of " + std::to_string(*total) : std::string()) + ">";
      });

  m.def(
      "frames",
      [](const std::string& source, bool grey, std::size_t start, std::optional<std::size_t> end, std::size_t stride,
         std::optional<std::pair<int, int>> resize, double time_offset, std::optional<std::string> topic, bool record_time) {
        return Frames(source, grey, start, end, stride, resize, time_offset, topic.value_or(""), record_time);
      },
      py::arg("source"), py::kw_only(), py::arg("grey") = false, py::arg("start") = 0, py::arg("end") = py::none(),
      py::arg("stride") = 1, py::arg("resize") = py::none(), py::arg("time_offset") = 0.0, py::arg("topic") = py::none(),
      py::arg("record_time") = false,
      "Frames of a video file, an image folder, an image list, a TUM rgb.txt, a EuRoC mav0/cam0 folder, a robot bag\n"
      "(ROS 1 .bag, rosbag2 .db3 or its folder, .mcap) or a camera (\"0\"): an iterator of (image, timestamp, name),\n"
      "images as uint8 NumPy arrays (H x W grey or H x W x 3 BGR) that view the decoded frame without a copy.\n"
      "start/end/stride pick frame indices; resize is (width, height). A bag: topic picks its image topic (needed\n"
      "when it has several), record_time times frames by their record time instead of their header stamp.");

  m.def(
      "bag_info",
      [](const std::string& bag) {
        const BagInfo info = vmap::bag_info(bag);
        py::list topics;
        for (const auto& t : info.topics) {
          py::dict d;
          d["name"] = t.name;
          d["type"] = t.type;
          d["encoding"] = t.encoding;
          d["messages"] = t.messages;
          topics.append(d);
        }
        py::dict out;
        out["format"] = std::string(to_string(info.format));
        out["messages"] = info.messages;
        out["start_ns"] = info.start_ns;
        out["end_ns"] = info.end_ns;
        out["indexed"] = info.indexed;
        out["topics"] = topics;
        out["warnings"] = info.warnings;
        return out;
      },
      py::arg("bag"),
      "What a robot bag holds: format, messages, start_ns / end_ns (record times), indexed, topics (name, type,\n"
      "encoding, messages) and warnings (damage found).");

  m.def(
      "image_address", [](const py::array& image) { return reinterpret_cast<std::uintptr_t>(image_view(image, "image").data); },
      py::arg("image"),
      "The address of the first pixel vmap reads for `image`: the array's own buffer (image.ctypes.data) when it\n"
      "is read in place (uint8/uint16, pixels contiguous within each row); another address when it is copied.");

  py::class_<Features>(m, "Features", "Keypoints and their descriptors, as NumPy arrays.")
      .def_property_readonly("keypoints", [](const Features& f) { return keypoint_array(f.keypoints); },
                             "N x 6 float32: x, y, size, angle, response, octave")
      .def_property_readonly("descriptors", [](const Features& f) { return to_array(f.descriptors); },
                             "N x D: uint8 for binary descriptors, float32 for float ones (a view, no copy)")
      .def_property_readonly("norm", [](const Features& f) { return f.norm == cv::NORM_HAMMING ? "hamming" : "l2"; },
                             "how two descriptors are compared: hamming or l2")
      .def_property_readonly("image_size", [](const Features& f) { return py::make_tuple(f.image_size.width, f.image_size.height); },
                             "(width, height) of the image they were extracted from")
      .def("__len__", &Features::size)
      .def("__repr__", [](const Features& f) {
        return "<vmap.Features " + std::to_string(f.size()) + " keypoints, " + std::to_string(f.descriptors.cols) +
               (f.norm == cv::NORM_HAMMING ? " bytes each>" : " floats each>");
      });

  py::class_<PyDescriptor>(m, "Descriptor",
                           "A feature descriptor chosen by name: orb, akaze, sift (OpenCV's), xfeat, xfeat-dense or\n"
                           "xfeat-star (learned; `model` is the ONNX file, `refine_model` XFeat*'s refinement network).")
      .def(py::init<const std::string&, int, const std::string&, const std::string&>(), py::arg("features") = "orb", py::kw_only(),
           py::arg("nfeatures") = 1000, py::arg("model") = "", py::arg("refine_model") = "")
      .def("extract", &PyDescriptor::extract, py::arg("image"), "The image's keypoints and descriptors (Features).")
      .def_property_readonly(
          "name", [](const PyDescriptor& d) { return std::string(to_string(d.stack().descriptor)); },
          "orb, akaze, sift, xfeat, xfeat-dense or xfeat-star")
      .def_property_readonly(
          "nfeatures", [](const PyDescriptor& d) { return d.stack().features; },
          "the keypoint budget (ORB, SIFT; XFeat's top-k)")
      .def("__repr__", [](const PyDescriptor& d) {
        std::string out = "<vmap.Descriptor " + std::string(to_string(d.stack().descriptor));
        if (d.stack().budgeted()) out += ", " + std::to_string(d.stack().features) + " features";
        if (!d.stack().model.empty()) out += ", model " + d.stack().model;
        return out + ">";
      });

  m.def(
      "match",
      [](const Features& a, const Features& b, const std::string& mode, float ratio) {
        if (mode != "mutual" && mode != "ratio") fail("match: mode must be 'mutual' or 'ratio', not '" + mode + "'");
        const BruteForceMatcher matcher({.mode = mode == "mutual" ? MatchMode::mutual : MatchMode::ratio, .ratio = ratio});
        Matches ms;
        {
          py::gil_scoped_release unlocked;
          ms = matcher.match(a, b);
        }
        return match_array(ms);
      },
      py::arg("a"), py::arg("b"), py::kw_only(), py::arg("mode") = "mutual", py::arg("ratio") = 0.8,
      "Brute-force matches from a to b, mutual nearest neighbours (cross-check) or Lowe's ratio test, as an\n"
      "M x 3 float32 array: index in a, index in b, distance.");
}

const RegisterPart part{order_core, &bind};

}  // namespace
}  // namespace vmap::python
