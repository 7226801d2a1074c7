#pragma once

// A policy stack as a value (runtime/stack.hpp has the rest: a memory's policy records and
// the stack read back from them). In a header of its own, with the descriptor kinds, so
// that a program choosing a stack (runtime/memory.hpp's AnyMemory) does not compile the
// descriptors, the matchers and the estimators:
//
//   auto stack = vmap::PolicyStack::from_string("orb features=500 method=ransac");
//   vmap::to_string(stack);  // "orb features=500 method=ransac"

#include <vmap/core/error.hpp>
#include <vmap/core/name_table.hpp>
#include <vmap/core/names.hpp>
#include <vmap/geometry/camera.hpp>
#include <vmap/geometry/robust_method.hpp>
#include <vmap/runtime/detail/description.hpp>

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

namespace vmap {

/// The descriptors of the shipped stacks.
enum class DescriptorKind : std::uint8_t {
  orb,          ///< ORB (OrbDescriptor), binary, brute-force mutual matching
  akaze,        ///< A-KAZE (AkazeDescriptor), binary
  sift,         ///< SIFT (SiftDescriptor), float
  xfeat,        ///< XFeat's sparse keypoints (XFeatDescriptor, a model file)
  xfeat_dense,  ///< XFeat's dense 1/8 grid (XFeatDenseDescriptor), blocked mutual matching
  xfeat_star,   ///< XFeat*: the dense grid refined per pair by XFeat's fine network (XFeatRefined)
};

/// orb, akaze, sift, xfeat, xfeat-dense, xfeat-star (core/names.hpp).
[[nodiscard]] constexpr auto names_of(DescriptorKind) noexcept {
  return detail::NameTable<DescriptorKind, 6>{{{{DescriptorKind::orb, "orb"},
                                                {DescriptorKind::akaze, "akaze"},
                                                {DescriptorKind::sift, "sift"},
                                                {DescriptorKind::xfeat, "xfeat"},
                                                {DescriptorKind::xfeat_dense, "xfeat-dense"},
                                                {DescriptorKind::xfeat_star, "xfeat-star"}}}};
}
[[nodiscard]] constexpr std::string_view to_string(DescriptorKind d) noexcept { return names_of(d).name(d); }

/// The most keypoints a stack may ask of a descriptor.
inline constexpr int max_stack_features = 100000;

/// One of the shipped policy stacks, as a value (see the top of this file).
struct PolicyStack {
  DescriptorKind descriptor = DescriptorKind::orb;
  /// Keypoint budget: ORB's and SIFT's features, XFeat's top-k; in [1, 100000]. A-KAZE
  /// and the dense grid take every keypoint they find and leave it at its default.
  int features = 1000;
  std::string model;         ///< the XFeat ONNX model (xfeat, xfeat-dense, xfeat-star)
  std::string refine_model;  ///< XFeat*'s refinement network (xfeat-star)
  RobustMethod method = RobustMethod::magsac;  ///< F-matrix estimation
  /// Keypoints are undistorted before the F-matrix, and a localized query gets its pose
  /// relative to the key image; nullopt: raw pixels, as the papers do.
  std::optional<Camera> camera;
  /// Where the calibration came from (a file, or a bag's CameraInfo topic written by
  /// bag_camera_source), for messages; not part of the stack's identity (two stacks with
  /// the same camera parameters are equal).
  std::string camera_source;

  /// Whether the descriptor is a network (needs `model`).
  [[nodiscard]] bool learned() const noexcept {
    return descriptor == DescriptorKind::xfeat || descriptor == DescriptorKind::xfeat_dense ||
           descriptor == DescriptorKind::xfeat_star;
  }
  /// Whether `features` means anything to the descriptor.
  [[nodiscard]] bool budgeted() const noexcept {
    return descriptor == DescriptorKind::orb || descriptor == DescriptorKind::sift || descriptor == DescriptorKind::xfeat;
  }

  /// Throws an Error naming `who` when the stack cannot be built: a budget outside [1,
  /// 100000], a learned descriptor without its model (or XFeat* without its refinement
  /// network), a model for a descriptor that takes none, an invalid camera. Files are
  /// not opened here (their loaders check them).
  void validate(const std::string& who = "policy stack") const {
    const std::string name(to_string(descriptor));
    detail::check(features >= 1 && features <= max_stack_features, [&] {
      return who + ": features must be in [1, " + std::to_string(max_stack_features) + "], got " + std::to_string(features);
    });
    if (learned())
      detail::check(!model.empty(), [&] {
        return who + ": " + name + " needs a model file (an XFeat ONNX export such as " +
               (descriptor == DescriptorKind::xfeat ? "xfeat_320x224.onnx" : "xfeat_anysize.onnx") + ")";
      });
    else
      detail::check(model.empty(), [&] { return who + ": " + name + " takes no model file"; });
    if (descriptor == DescriptorKind::xfeat_star)
      detail::check(!refine_model.empty(),
                    [&] { return who + ": xfeat-star needs a refinement model (XFeat*'s network, xfeat_fine.onnx)"; });
    else
      detail::check(refine_model.empty(), [&] { return who + ": only xfeat-star takes a refinement model"; });
    if (camera) camera->validate(who + "'s camera" + (camera_source.empty() ? "" : " (from " + camera_source + ")"));
  }

  /// Equal policies: every field but camera_source.
  friend bool operator==(const PolicyStack& a, const PolicyStack& b) {
    const auto same_camera = [](const std::optional<Camera>& x, const std::optional<Camera>& y) {
      if (!x || !y) return x.has_value() == y.has_value();
      return x->describe() == y->describe();
    };
    return a.descriptor == b.descriptor && a.features == b.features && a.model == b.model &&
           a.refine_model == b.refine_model && a.method == b.method && same_camera(a.camera, b.camera);
  }

  /// The stack to_string wrote; an Error naming the text and what is wrong with it.
  [[nodiscard]] static PolicyStack from_string(std::string_view text);
};

/// "orb features=1000 method=magsac": the descriptor, then the fields that differ from
/// the defaults' (models and the calibration's source quoted, the camera as its
/// describe()), which from_string reads back.
[[nodiscard]] inline std::string to_string(const PolicyStack& s) {
  const PolicyStack defaults;
  std::string out(to_string(s.descriptor));
  if (s.features != defaults.features) out += " features=" + std::to_string(s.features);
  if (!s.model.empty()) out += " model=" + quote_text(s.model);
  if (!s.refine_model.empty()) out += " refine_model=" + quote_text(s.refine_model);
  out += " method=" + std::string(to_string(s.method));
  if (s.camera) out += " camera=(" + s.camera->describe() + ")";
  if (s.camera && !s.camera_source.empty()) out += " camera_source=" + quote_text(s.camera_source);
  return out;
}

/// The place decision's chance-inlier rate measured for the stack's descriptor with its
/// own matcher and MAGSAC++'s F-matrix at 1 px (lcd/calibration.hpp, on foreign pairs of
/// the shared sequences: examples/results/loops.md, "The chance rate of each stack").
/// Set PlaceDecisionOptions::chance_inlier_rate to it, or to a rate measured on your own
/// images (calibrate_chance_rate), so that a confidence means the same for each stack.
/// ORB keeps the 0.1 the decision was built with, which is what it measures. Another
/// method or a camera's essential matrix is given the descriptor's rate: not measured
/// apart.
[[nodiscard]] constexpr double measured_chance_rate(const PolicyStack& s) noexcept {
  switch (s.descriptor) {
    case DescriptorKind::orb: return 0.1;
    case DescriptorKind::akaze: return 0.033;
    case DescriptorKind::sift: return 0.032;
    case DescriptorKind::xfeat: return 0.059;
    case DescriptorKind::xfeat_dense: return 0.051;
    case DescriptorKind::xfeat_star: return 0.035;
  }
  return 0.1;
}

/// "ORB 1000, magsac, raw pixels" / "xfeat-star, magsac, camera tum.yaml": for summaries.
[[nodiscard]] inline std::string summary(const PolicyStack& s) {
  std::string out(to_string(s.descriptor));
  if (s.budgeted()) out += " " + std::to_string(s.features);
  out += ", " + std::string(to_string(s.method));
  if (!s.camera) return out + ", raw pixels";
  return out + ", camera " + (s.camera_source.empty() ? s.camera->describe() : s.camera_source);
}

namespace detail {

/// A Camera from its describe() text ("pinhole fx=517.3 ... size=640x480"); nullopt when
/// the text is not one.
[[nodiscard]] inline std::optional<Camera> camera_of_description(std::string_view text) {
  const auto d = read_description(text);
  if (!d || (d->name != "pinhole" && d->name != "fisheye") || d->fields.size() != 6) return std::nullopt;
  Camera c;
  c.lens = d->name == "pinhole" ? LensModel::pinhole : LensModel::fisheye;
  double* values[4] = {&c.fx, &c.fy, &c.cx, &c.cy};
  const char* keys[4] = {"fx", "fy", "cx", "cy"};
  for (int i = 0; i < 4; ++i) {
    const auto v = d->get(keys[i]);
    const auto x = v ? real_of(*v) : std::nullopt;
    if (!x) return std::nullopt;
    *values[i] = *x;
  }
  const auto distortion = d->get("distortion");
  if (!distortion) return std::nullopt;
  std::string_view rest = *distortion;
  while (!rest.empty()) {
    const std::size_t space = rest.find(' ');
    const auto x = real_of(rest.substr(0, space));
    if (!x) return std::nullopt;
    c.distortion.push_back(*x);
    rest = space == std::string_view::npos ? std::string_view() : rest.substr(space + 1);
  }
  const auto size = d->get("size");
  if (!size) return std::nullopt;
  const std::size_t x = size->find('x');
  const auto w = x == std::string::npos ? std::nullopt : integer_of(std::string_view(*size).substr(0, x));
  const auto h = x == std::string::npos ? std::nullopt : integer_of(std::string_view(*size).substr(x + 1));
  if (!w || !h || *w < 0 || *h < 0 || *w > Camera::max_image_side || *h > Camera::max_image_side) return std::nullopt;
  c.image_size = {static_cast<int>(*w), static_cast<int>(*h)};
  if (c.describe() != text) return std::nullopt;  // only what describe() writes
  return c;
}

}  // namespace detail

inline PolicyStack PolicyStack::from_string(std::string_view text) {
  const std::string who = "policy stack '" + std::string(text) + "'";
  const auto d = detail::read_description(text);
  if (!d) detail::fail(who + ": not 'DESCRIPTOR key=value ...'");
  PolicyStack s;
  s.descriptor = parse<DescriptorKind>(d->name, who + ": the descriptor");
  for (const auto& [key, value] : d->fields) {
    if (key == "features") {
      const auto n = detail::integer_of(value);
      if (!n || *n < 1 || *n > max_stack_features)
        detail::fail(who + ": features must be a whole number in [1, " + std::to_string(max_stack_features) + "]");
      s.features = static_cast<int>(*n);
    } else if (key == "model") {
      s.model = value;
    } else if (key == "refine_model") {
      s.refine_model = value;
    } else if (key == "method") {
      s.method = parse<RobustMethod>(value, who + ": the method");
    } else if (key == "camera") {
      s.camera = detail::camera_of_description(value);
      if (!s.camera) detail::fail(who + ": the camera is not 'pinhole|fisheye fx=.. fy=.. cx=.. cy=.. distortion=[..] size=WxH'");
    } else if (key == "camera_source") {
      s.camera_source = value;
    } else {
      detail::fail(who + ": unknown field '" + key + "' (features, model, refine_model, method, camera, camera_source)");
    }
  }
  s.validate(who);
  return s;
}

}  // namespace vmap
