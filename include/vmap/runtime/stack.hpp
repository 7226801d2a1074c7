#pragma once

// The shipped policy stacks: which of them a program runs, chosen at run time (a command
// line, a configuration file, the Python module) instead of at compile time. The stack
// (runtime/policy_stack.hpp, PolicyStack) names the descriptor (ORB, A-KAZE, SIFT, XFeat,
// XFeat's dense grid or XFeat*) with its keypoint budget and model files, the F-matrix
// method, and the camera; the matcher and the estimator wrapper follow from the
// descriptor (runtime/policies.hpp builds the policies).
//
// A memory records its stack once, as its policies' own descriptions (VisualMemory's
// policy records, each policy's describe()): policy_records(stack) gives them without
// loading a model, and stack_of_policies(records) reads the stack back from a memory,
// refusing policies that are not one of the shipped stacks. Memories written before
// vmap's XFeat policies described themselves kept the stack in a note of their store;
// stack_of_legacy_note reads it.

#include <vmap/core/error.hpp>
#include <vmap/core/names.hpp>
#include <vmap/core/numeric.hpp>
#include <vmap/features/akaze.hpp>
#include <vmap/features/orb.hpp>
#include <vmap/features/sift.hpp>
#include <vmap/geometry/calibrated.hpp>
#include <vmap/geometry/camera.hpp>
#include <vmap/geometry/fundamental.hpp>
#include <vmap/geometry/similarity.hpp>
#include <vmap/hooks/xfeat.hpp>
#include <vmap/hooks/xfeat_dense.hpp>
#include <vmap/hooks/xfeat_fine.hpp>
#include <vmap/matching/brute_force.hpp>
#include <vmap/runtime/detail/description.hpp>
#include <vmap/runtime/policy_stack.hpp>

#include <array>
#include <cctype>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace vmap {

namespace detail {

/// The estimator options of each use of a stack (runtime/policies.hpp): F-matrix at 1 px
/// and 0.99; the key-image selection and the offline loop run skip the homography
/// degeneracy test (neither uses it), a memory runs it (its place decision reads it).
[[nodiscard]] inline FundamentalOptions stack_fundamental_options(RobustMethod method, bool check_degeneracy) {
  FundamentalOptions o;
  o.method = method;
  o.check_degeneracy = check_degeneracy;
  return o;
}

}  // namespace detail

/// The four policy records (descriptor, matcher, estimator, similarity) a memory of this
/// stack records (VisualMemory::policy_records), computed without loading a model. The
/// estimator is the memory's: with the homography degeneracy test.
[[nodiscard]] inline std::array<std::string, 4> policy_records(const PolicyStack& s) {
  s.validate();
  const FundamentalOptions fo = detail::stack_fundamental_options(s.method, true);
  const std::string estimator = Calibrated<FundamentalEstimator>(s.camera, FundamentalEstimator(fo)).describe();
  const std::string similarity = InlierRatio{}.describe();
  switch (s.descriptor) {
    case DescriptorKind::orb:
      return {OrbDescriptor({.features = s.features}).describe(), BruteForceMatcher({.mode = MatchMode::mutual}).describe(),
              estimator, similarity};
    case DescriptorKind::akaze:
      return {AkazeDescriptor{}.describe(), BruteForceMatcher({.mode = MatchMode::mutual}).describe(), estimator,
              similarity};
    case DescriptorKind::sift:
      return {SiftDescriptor({.features = s.features}).describe(), BruteForceMatcher({.mode = MatchMode::mutual}).describe(),
              estimator, similarity};
    case DescriptorKind::xfeat:
      return {XFeatDescriptor::describe({.model = s.model, .top_k = s.features}),
              BruteForceMatcher({.mode = MatchMode::mutual}).describe(), estimator, similarity};
    case DescriptorKind::xfeat_dense:
      return {XFeatDenseDescriptor::describe({.model = s.model}), DenseMutualMatcher({.normalise = false}).describe(),
              XFeatRefined<FundamentalEstimator>::describe(std::nullopt, estimator), similarity};
    case DescriptorKind::xfeat_star:
      return {XFeatDenseDescriptor::describe({.model = s.model, .grid = XFeatGrid::refinable}),
              DenseMutualMatcher({.normalise = true}).describe(),
              XFeatRefined<FundamentalEstimator>::describe(XFeatFineOptions{.model = s.refine_model}, estimator),
              similarity};
  }
  detail::fail("policy_records: unknown descriptor");
}

/// The shipped stack whose memory records these policies (policy_records); an Error
/// naming `who` when they are not one (a memory built with other policies, to be loaded
/// with them through VisualMemory). Records a policy did not write ("") are not read: a
/// memory whose descriptor record is empty has no stack here (stack_of_legacy_note).
[[nodiscard]] inline PolicyStack stack_of_policies(const std::array<std::string, 4>& records, const std::string& who) {
  const auto refuse = [&](const std::string& why) -> PolicyStack {
    detail::fail(ErrorKind::policy_mismatch,
                 who + ": its policies are not one of vmap's stacks (" + why + "; descriptor '" + records[0] +
                     "', estimator '" + records[2] + "'); load it with VisualMemory and the policies it was built with");
  };
  const auto descriptor = detail::read_description(records[0]);
  if (!descriptor) return refuse("an unreadable descriptor record");
  PolicyStack s;
  // The estimator: [XFeatRefined model=.. min_confidence=.. estimator=(E)] where E is
  // [Calibrated camera=(CAMERA) ]FundamentalEstimator method=N ...
  std::string_view rest = records[2];
  std::string inner;
  if (rest.starts_with("XFeatRefined ")) {
    const auto refined = detail::read_description(rest);
    if (!refined || !refined->get("estimator")) return refuse("an unreadable refinement record");
    s.refine_model = refined->get("model").value_or("");
    inner = *refined->get("estimator");
    rest = inner;
  }
  if (rest.starts_with("Calibrated camera=(")) {
    const std::size_t close = rest.find(") ");
    if (close == std::string_view::npos) return refuse("an unreadable camera");
    s.camera = detail::camera_of_description(rest.substr(19, close - 19));
    if (!s.camera) return refuse("an unreadable camera");
    rest = rest.substr(close + 2);
  }
  const auto fundamental = detail::read_description(rest);
  if (!fundamental || fundamental->name != "FundamentalEstimator") return refuse("not an F-matrix estimator");
  const auto method = detail::integer_of(fundamental->get("method").value_or(""));
  if (!method || *method < 0 || *method > static_cast<int>(RobustMethod::eight_point)) return refuse("an unknown method");
  s.method = static_cast<RobustMethod>(*method);

  const std::string& name = descriptor->name;
  const auto budget = [&](const char* key) { return detail::integer_of(descriptor->get(key).value_or("")).value_or(0); };
  if (name == "OrbDescriptor") {
    s.descriptor = DescriptorKind::orb;
    s.features = static_cast<int>(budget("features"));
  } else if (name == "AkazeDescriptor") {
    s.descriptor = DescriptorKind::akaze;
  } else if (name == "SiftDescriptor") {
    s.descriptor = DescriptorKind::sift;
    s.features = static_cast<int>(budget("features"));
  } else if (name == "XFeatDescriptor") {
    s.descriptor = DescriptorKind::xfeat;
    s.features = static_cast<int>(budget("top_k"));
    s.model = descriptor->get("model").value_or("");
  } else if (name == "XFeatDenseDescriptor") {
    s.descriptor = s.refine_model.empty() ? DescriptorKind::xfeat_dense : DescriptorKind::xfeat_star;
    s.model = descriptor->get("model").value_or("");
  } else {
    return refuse("an unknown descriptor");
  }
  try {
    s.validate(who);
    // Every option not in the stack must be the stack's: the records read back whole.
    if (policy_records(s) == records) return s;
  } catch (const Error&) {
  }
  return refuse("options the stack does not set");
}

/// The stack of a memory store written before the XFeat policies described themselves:
/// the store's note "stack", one flat JSON object
/// {"camera":null|{...},"estimator":"magsac","features":"orb","model":"","nfeatures":1000,"refine_model":""}
/// (the camera: "distortion":[...],"file","fx","fy","cx","cy","height","lens","width").
/// An Error naming `who` when the note is not one.
[[nodiscard]] inline PolicyStack stack_of_legacy_note(std::string_view note, const std::string& who);

namespace detail {

/// A reader of the legacy note's JSON: objects, arrays of numbers, strings with the
/// escapes JSON writers use for paths, numbers and null. Nothing else is needed.
class LegacyJson {
 public:
  LegacyJson(std::string_view text, std::string who) : text_(text), who_(std::move(who)) {}

  struct Value {
    enum class Kind : std::uint8_t { null, number, string, array, object } kind = Kind::null;
    double number = 0.0;
    std::string string;
    std::vector<double> array;
    std::vector<std::pair<std::string, Value>> object;
    [[nodiscard]] const Value* get(std::string_view key) const {
      for (const auto& [k, v] : object)
        if (k == key) return &v;
      return nullptr;
    }
  };

  Value document() {
    Value v = value(0);
    space();
    if (at_ != text_.size()) bad("text after the object");
    return v;
  }

 private:
  [[noreturn]] void bad(const std::string& what) const {
    fail(who_ + " is not valid: " + what + " at offset " + std::to_string(at_));
  }
  void space() {
    while (at_ < text_.size() && std::isspace(static_cast<unsigned char>(text_[at_])) != 0) ++at_;
  }
  bool eat(char c) {
    space();
    if (at_ < text_.size() && text_[at_] == c) {
      ++at_;
      return true;
    }
    return false;
  }
  Value value(int depth) {
    if (depth > 4) bad("nested too deep");
    space();
    if (at_ >= text_.size()) bad("unexpected end");
    Value v;
    const char c = text_[at_];
    if (c == '{') {
      ++at_;
      v.kind = Value::Kind::object;
      if (eat('}')) return v;
      do {
        space();
        std::string key = string();
        if (!eat(':')) bad("':' expected");
        v.object.emplace_back(std::move(key), value(depth + 1));
      } while (eat(','));
      if (!eat('}')) bad("'}' expected");
    } else if (c == '[') {
      ++at_;
      v.kind = Value::Kind::array;
      if (eat(']')) return v;
      do {
        const Value x = value(depth + 1);
        if (x.kind != Value::Kind::number) bad("a number expected in the list");
        v.array.push_back(x.number);
      } while (eat(','));
      if (!eat(']')) bad("']' expected");
    } else if (c == '"') {
      v.kind = Value::Kind::string;
      v.string = string();
    } else if (text_.substr(at_, 4) == "null") {
      at_ += 4;
    } else {
      std::size_t end = at_;
      while (end < text_.size() && std::string_view("+-.0123456789eE").find(text_[end]) != std::string_view::npos) ++end;
      const auto x = real_of(text_.substr(at_, end - at_));
      if (!x) bad("a value expected");
      v.kind = Value::Kind::number;
      v.number = *x;
      at_ = end;
    }
    return v;
  }
  std::string string() {
    if (at_ >= text_.size() || text_[at_] != '"') bad("'\"' expected");
    ++at_;
    std::string out;
    while (at_ < text_.size() && text_[at_] != '"') {
      char c = text_[at_++];
      if (c == '\\') {
        if (at_ >= text_.size()) break;
        const char e = text_[at_++];
        if (e == 'n') c = '\n';
        else if (e == 't') c = '\t';
        else if (e == 'u') bad("\\u escapes are not in a stack note");
        else c = e;
      }
      out += c;
    }
    if (at_ >= text_.size()) bad("unterminated string");
    ++at_;
    return out;
  }

  std::string_view text_;
  std::string who_;
  std::size_t at_ = 0;
};

}  // namespace detail

inline PolicyStack stack_of_legacy_note(std::string_view note, const std::string& who) {
  using Kind = detail::LegacyJson::Value::Kind;
  const auto j = detail::LegacyJson(note, who).document();
  const auto field = [&](const char* key, Kind kind) -> const detail::LegacyJson::Value& {
    const auto* v = j.get(key);
    if (!v || v->kind != kind) detail::fail(who + " is not valid: its '" + key + "' is missing or of another type");
    return *v;
  };
  PolicyStack s;
  s.descriptor = parse<DescriptorKind>(field("features", Kind::string).string, who + ": its descriptor");
  const double n = field("nfeatures", Kind::number).number;
  if (!(n >= 1 && n <= max_stack_features) || n != static_cast<double>(static_cast<int>(n)))
    detail::fail(who + " is not valid: nfeatures must be a whole number in [1, " + std::to_string(max_stack_features) + "]");
  s.features = static_cast<int>(n);
  s.model = field("model", Kind::string).string;
  s.refine_model = field("refine_model", Kind::string).string;
  s.method = parse<RobustMethod>(field("estimator", Kind::string).string, who + ": its estimator");
  if (const auto* c = j.get("camera"); c && c->kind == Kind::object) {
    Camera cam;
    const auto number = [&](const char* key) {
      const auto* v = c->get(key);
      if (!v || v->kind != Kind::number) detail::fail(who + " is not valid: its camera's '" + key + "' is missing");
      return v->number;
    };
    const auto* lens = c->get("lens");
    if (!lens || lens->kind != Kind::string || (lens->string != "pinhole" && lens->string != "fisheye"))
      detail::fail(who + " is not valid: its camera's lens is not pinhole or fisheye");
    cam.lens = lens->string == "pinhole" ? LensModel::pinhole : LensModel::fisheye;
    cam.fx = number("fx");
    cam.fy = number("fy");
    cam.cx = number("cx");
    cam.cy = number("cy");
    const double w = number("width"), h = number("height");
    if (!(w >= 0 && h >= 0 && w <= Camera::max_image_side && h <= Camera::max_image_side))
      detail::fail(who + " is not valid: its camera's image size is out of range");
    cam.image_size = {static_cast<int>(w), static_cast<int>(h)};
    const auto* d = c->get("distortion");
    if (!d || d->kind != Kind::array) detail::fail(who + " is not valid: its camera's distortion is missing");
    cam.distortion = d->array;
    s.camera = cam;
    if (const auto* f = c->get("file"); f && f->kind == Kind::string) s.camera_source = f->string;
  } else if (c && c->kind != Kind::null) {
    detail::fail(who + " is not valid: its camera is neither null nor an object");
  }
  s.validate(who);
  return s;
}

}  // namespace vmap
