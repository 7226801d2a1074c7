#pragma once

// A shared sequence's frames for the real-data tests.

#include <vmap/io/frame_source.hpp>

#include <cstddef>
#include <filesystem>
#include <vector>

namespace vmap::test {

/// Every `step`-th frame of `input` (by its frame index), grey.
inline std::vector<vmap::Frame> grey_frames(const std::filesystem::path& input, std::size_t step = 1) {
  auto src = vmap::FrameSource::open(input, {.grey = true});
  std::vector<vmap::Frame> out;
  while (auto f = src.next())
    if (f->index % step == 0) out.push_back(std::move(*f));
  return out;
}

}  // namespace vmap::test
