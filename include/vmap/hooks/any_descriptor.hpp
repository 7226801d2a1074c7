#pragma once

// A Descriptor chosen at run time (ORB, SIFT, XFeat ...) behind one type. Type erasure
// costs one indirect call per image; keypoint detection, description and every
// per-feature loop run inside the concrete policy, statically dispatched. Hosts that
// know their policy at compile time (KeyframeSelector<OrbDescriptor, ...>) need none of this.

#include <vmap/core/concepts.hpp>
#include <vmap/core/error.hpp>
#include <vmap/core/features.hpp>

#include <opencv2/core.hpp>

#include <concepts>
#include <memory>
#include <type_traits>
#include <utility>

namespace vmap {

/// Holds any Descriptor by value. Move-only: a Descriptor need only be movable
/// (concepts.hpp), so a copy cannot be promised for every policy it may hold. For one
/// descriptor per thread, copy the concrete policy (OrbDescriptor, XFeatDescriptor ...
/// deep-copy) before erasing it. A moved-from AnyDescriptor is empty and `extract` on
/// it is an Error. One object serves one thread at a time, like the policies it holds.
class AnyDescriptor {
 public:
  template <Descriptor D>
    requires(!std::same_as<std::remove_cvref_t<D>, AnyDescriptor>)
  explicit AnyDescriptor(D descriptor) : self_(std::make_unique<Model<D>>(std::move(descriptor))) {}

  AnyDescriptor(AnyDescriptor&&) noexcept = default;
  AnyDescriptor& operator=(AnyDescriptor&&) noexcept = default;

  [[nodiscard]] Features extract(const cv::Mat& image) {
    detail::check(self_ != nullptr, "AnyDescriptor: extract() on an empty (moved-from) descriptor");
    return self_->extract(image);
  }

  [[nodiscard]] bool has_value() const noexcept { return self_ != nullptr; }

  /// The held policy if it is a D, else nullptr.
  template <Descriptor D>
  [[nodiscard]] D* target() noexcept {
    auto* m = dynamic_cast<Model<D>*>(self_.get());
    return m ? &m->descriptor : nullptr;
  }

 private:
  struct Interface {
    virtual ~Interface() = default;
    virtual Features extract(const cv::Mat& image) = 0;
  };
  template <class D>
  struct Model final : Interface {
    explicit Model(D d) : descriptor(std::move(d)) {}
    Features extract(const cv::Mat& image) override { return descriptor.extract(image); }
    D descriptor;
  };
  std::unique_ptr<Interface> self_;
};

static_assert(Descriptor<AnyDescriptor>);

}  // namespace vmap
