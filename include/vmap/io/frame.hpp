#pragma once

// One frame of a sequence, as every consumer of frames takes it (the key-image selector,
// the memory). Apart from io/frame_source.hpp, which reads frames from videos, image
// folders, lists and bags, so that code which only takes frames includes neither
// OpenCV's videoio nor the readers.

#include <opencv2/core.hpp>

#include <cstddef>
#include <cstdint>
#include <string>

namespace vmap {

/// One frame of a sequence. `index` is the frame's position in the whole sequence
/// (before start/stride are applied), so it lines up with ground-truth files.
struct Frame {
  cv::Mat image;
  std::size_t index = 0;
  std::string name;        ///< file name, or "<video>#<index>"
  double timestamp = 0.0;  ///< seconds (io/frame_source.hpp says where from; + FrameSourceOptions::time_offset)
  /// The same time in whole nanoseconds (io/timestamps.hpp): exact where the source
  /// states nanoseconds or decimal seconds, else `timestamp` rounded.
  std::int64_t time_ns = 0;
};

}  // namespace vmap
