#pragma once

// The command line's policy options (--features, --nfeatures, --model, --refine-model,
// --estimator, --camera) read into the library's PolicyStack (vmap/runtime/stack_choice.hpp),
// which checks them and names the options in its messages; a value it refuses is a usage
// error (exit 2).

#include "common/cli_support.hpp"

#include <vmap/core/error.hpp>
#include <vmap/geometry/fundamental.hpp>
#include <vmap/runtime/option_names.hpp>
#include <vmap/runtime/policies.hpp>
#include <vmap/runtime/stack.hpp>
#include <vmap/runtime/stack_choice.hpp>

#include <optional>
#include <string>
#include <utility>

namespace vmap::examples {

/// The descriptor options as the command line reads them.
struct DescriptorChoice {
  std::string name = "orb";  ///< --features: orb, akaze, sift, xfeat, xfeat-dense, xfeat-star
  int features = 1000;       ///< --nfeatures: keypoint budget (ORB, SIFT; XFeat's top-k)
  std::string model;         ///< model file, for learned descriptors
  std::string refine_model;  ///< XFeat*'s refinement network (xfeat-star)
};

/// The library's check of what the user typed: its Error becomes a usage error.
template <class F>
decltype(auto) as_usage(F&& f) {
  try {
    return std::forward<F>(f)();
  } catch (const UsageError&) {
    throw;
  } catch (const vmap::Error& e) {
    usage_error(e.what());
  }
}

/// The stack of the options; `names` spells them (`vmap loops` reads the descriptor's
/// model as --features-model).
inline PolicyStack stack_of(const DescriptorChoice& d, const std::string& method, const std::optional<CameraOption>& camera,
                            const OptionNames& names = OptionNames::command_line()) {
  return as_usage([&] {
    return vmap::stack_of({.descriptor = d.name,
                           .features = d.features,
                           .model = d.model,
                           .refine_model = d.refine_model,
                           .method = method,
                           .camera = camera ? std::optional<Camera>(camera->camera) : std::nullopt,
                           .camera_source = camera ? camera->file.string() : std::string()},
                          names);
  });
}

/// --estimator's method.
inline RobustMethod parse_method(const std::string& name) { return stack_of({}, name, std::nullopt).method; }

}  // namespace vmap::examples
