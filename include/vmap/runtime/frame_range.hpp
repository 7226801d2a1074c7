#pragma once

// The frames of a sequence a program reads: the first index, one past the last, and a
// stride, as a user gives them (`vmap build --start 10 --end 50`, Python's start=10,
// end=50), checked once for every front end with messages that name the inputs as the
// front end does (runtime/option_names.hpp).
//
//   vmap::FrameRange range{.start = 10, .end = 50, .stride = 2};
//   auto frames = vmap::FrameSource::open("rgb.txt", range.apply({.grey = true}));

#include <vmap/core/error.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/runtime/option_names.hpp>

#include <cstddef>
#include <optional>
#include <string>

namespace vmap {

/// Frame indices [start, end) in steps of stride (see the top of this file).
struct FrameRange {
  std::size_t start = 0;
  std::optional<std::size_t> end{};  ///< one past the last index; nullopt: to the end
  std::size_t stride = 1;          ///< >= 1

  /// An Error naming the inputs when the range is empty by construction (end <= start) or
  /// the stride is 0: found before any frame is read.
  void validate(const OptionNames& names = OptionNames::keywords()) const {
    detail::check(stride >= 1, [&] { return names("stride") + ": must be >= 1"; });
    detail::check(!end || *end > start, [&] {
      return names("end") + ": must be > " + names("start") + " (" + std::to_string(start) + "), got " +
             std::to_string(*end);
    });
  }

  /// `o` reading this range (validated).
  [[nodiscard]] FrameSourceOptions apply(FrameSourceOptions o, const OptionNames& names = OptionNames::keywords()) const {
    validate(names);
    o.start = start;
    if (end) o.end = *end;
    o.stride = stride;
    return o;
  }
};

}  // namespace vmap
