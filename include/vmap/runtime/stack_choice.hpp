#pragma once

// A policy stack from the words a user gives: a descriptor and an F-matrix method by
// name, a keypoint budget, model files and a camera. Every front end reads the same words
// (`vmap build --features xfeat --model m.onnx`, `vmap.KeyframeSelector("xfeat",
// model="m.onnx")`), and this is where they are checked, once, with messages that name
// each input as the front end does (runtime/option_names.hpp):
//
//   vmap::StackChoice c{.descriptor = "sift", .features = 500, .method = "ransac"};
//   vmap::PolicyStack s = vmap::stack_of(c, vmap::OptionNames::keywords());
//
// The camera is read by the front end (a calibration file: io/calibration.hpp,
// read_camera) so that a file it cannot read is named as the front end names its inputs.

#include <vmap/core/error.hpp>
#include <vmap/core/names.hpp>
#include <vmap/geometry/camera.hpp>
#include <vmap/geometry/fundamental.hpp>
#include <vmap/io/bag/types.hpp>
#include <vmap/runtime/option_names.hpp>
#include <vmap/runtime/stack.hpp>

#include <optional>
#include <string>
#include <utility>

namespace vmap {

/// The words of a policy stack, as a user gives them (see the top of this file). The
/// names in errors are the keywords: features, nfeatures, model, refine_model, estimator,
/// camera.
struct StackChoice {
  std::string descriptor = "orb";  ///< features: orb, akaze, sift, xfeat, xfeat-dense, xfeat-star
  int features = 1000;             ///< nfeatures: ORB's and SIFT's keypoint budget, XFeat's top-k
  std::string model{};             ///< model: the XFeat ONNX file of a learned descriptor
  std::string refine_model{};      ///< refine_model: XFeat*'s refinement network (xfeat-star)
  std::string method = "magsac";   ///< estimator: magsac, ransac, lmeds or 8point
  std::optional<Camera> camera{};  ///< camera: undistort the keypoints first; nullopt: raw pixels
  std::string camera_source{};     ///< where the camera came from (its file), for messages
};

/// The name of the stack's camera in the errors of its estimator: the option that gave
/// its file ("--camera tum.yaml", "camera=tum.yaml"), the CameraInfo topic of a bag it
/// came from without one (bag_camera_source: "the CameraInfo of bag 'x.bag', topic
/// '/cam/camera_info'"), or "camera" without a source.
[[nodiscard]] inline std::string camera_name(const PolicyStack& s, const OptionNames& names) {
  if (s.camera_source.empty()) return "camera";
  if (const auto bag = parse_bag_camera_source(s.camera_source))
    return "the CameraInfo of bag '" + bag->first + "', topic '" + bag->second + "'";
  return names.with_value("camera", s.camera_source);
}

/// The stack the words name; an Error naming the input (as `names` spells it) and what is
/// wrong with it: an unknown descriptor or method, a budget outside [1, 100000], a
/// learned descriptor without its model file (XFeat* without its refinement network), a
/// model file for a descriptor that takes none.
[[nodiscard]] inline PolicyStack stack_of(const StackChoice& c, const OptionNames& names = OptionNames::keywords()) {
  PolicyStack s;
  s.descriptor = parse_option<DescriptorKind>(c.descriptor, "features", "descriptor", names);
  s.method = parse_option<RobustMethod>(c.method, "estimator", "method", names);
  detail::check(c.features >= 1 && c.features <= max_stack_features, [&] {
    return names("nfeatures") + ": must be in [1, " + std::to_string(max_stack_features) + "], got " +
           std::to_string(c.features);
  });
  s.features = c.features;
  // A learned model is never looked up or downloaded: the user names the file.
  if (s.learned()) {
    detail::check(!c.model.empty(), [&] {
      return names.with_value("features", c.descriptor) + " needs " + names("model") + " PATH (an XFeat ONNX export such as " +
             (s.descriptor == DescriptorKind::xfeat ? "xfeat_320x224.onnx" : "xfeat_anysize.onnx") + ")";
    });
  } else {
    detail::check(c.model.empty(), [&] {
      return names("model") + ": " + c.descriptor + " takes no model file (only xfeat, xfeat-dense and xfeat-star do)";
    });
  }
  if (s.descriptor == DescriptorKind::xfeat_star)
    detail::check(!c.refine_model.empty(), [&] {
      return names.with_value("features", c.descriptor) + " needs " + names("refine_model") +
             " PATH (XFeat*'s refinement network, xfeat_fine.onnx)";
    });
  else
    detail::check(c.refine_model.empty(),
                  [&] { return names("refine_model") + ": only xfeat-star takes a refinement network"; });
  s.model = c.model;
  s.refine_model = c.refine_model;
  s.camera = c.camera;
  s.camera_source = c.camera_source;
  s.validate(names("camera"));
  return s;
}

}  // namespace vmap
