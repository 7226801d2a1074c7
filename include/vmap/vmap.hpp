#pragma once

// Umbrella header: everything vmap offers but the run-time layer (runtime/*.hpp, the
// stacks chosen at run time, which a program without vmap::stacks would instantiate in
// every file that includes them). Including the area headers directly instead keeps
// compile times down.

#include <vmap/version.hpp>

#include <vmap/core/concepts.hpp>
#include <vmap/core/error.hpp>
#include <vmap/core/features.hpp>
#include <vmap/core/numeric.hpp>
#include <vmap/core/verification.hpp>

#include <vmap/features/akaze.hpp>
#include <vmap/features/budget.hpp>
#include <vmap/features/orb.hpp>
#include <vmap/features/sift.hpp>

#include <vmap/matching/brute_force.hpp>

#include <vmap/geometry/calibrated.hpp>
#include <vmap/geometry/camera.hpp>
#include <vmap/geometry/essential.hpp>
#include <vmap/geometry/fundamental.hpp>
#include <vmap/geometry/homography.hpp>
#include <vmap/geometry/pose2.hpp>
#include <vmap/geometry/robust_method.hpp>
#include <vmap/geometry/similarity.hpp>

#include <vmap/io/atomic_file.hpp>
#include <vmap/io/files.hpp>
#include <vmap/io/bag/bag.hpp>
#include <vmap/io/calibration.hpp>
#include <vmap/io/exports.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/io/image.hpp>
#include <vmap/io/poses.hpp>

#include <vmap/hooks/any_descriptor.hpp>
#include <vmap/hooks/any_detector.hpp>
#include <vmap/hooks/callback_detector.hpp>
#include <vmap/hooks/class_names.hpp>
#include <vmap/hooks/detection.hpp>
#include <vmap/hooks/dnn_detectors.hpp>
#include <vmap/hooks/nms.hpp>
#include <vmap/hooks/pair_matcher.hpp>
#include <vmap/hooks/pair_matcher_adapters.hpp>
#include <vmap/hooks/precomputed_detections.hpp>
#include <vmap/hooks/xfeat.hpp>
#include <vmap/hooks/xfeat_dense.hpp>
#include <vmap/hooks/xfeat_fine.hpp>

#include <vmap/place/bow.hpp>
#include <vmap/place/consistency.hpp>
#include <vmap/place/database.hpp>
#include <vmap/place/match.hpp>
#include <vmap/place/vocabulary.hpp>

#include <vmap/keyframe/front_end.hpp>
#include <vmap/keyframe/map_io.hpp>
#include <vmap/keyframe/pipeline.hpp>
#include <vmap/keyframe/result.hpp>
#include <vmap/keyframe/selector.hpp>
#include <vmap/keyframe/stacks.hpp>
#include <vmap/keyframe/sweep.hpp>
#include <vmap/keyframe/visual_map.hpp>

#include <vmap/lcd/binary_tree.hpp>
#include <vmap/lcd/calibration.hpp>
#include <vmap/lcd/evaluation.hpp>
#include <vmap/lcd/influence.hpp>
#include <vmap/lcd/label_sources.hpp>
#include <vmap/lcd/label_vector.hpp>
#include <vmap/lcd/loop_detector.hpp>
#include <vmap/lcd/sequence.hpp>

#include <vmap/som/gcs.hpp>
#include <vmap/som/histogram.hpp>
#include <vmap/som/localizer.hpp>
#include <vmap/som/nearest_wall.hpp>
#include <vmap/som/pose_io.hpp>
#include <vmap/som/pose_map.hpp>
#include <vmap/som/results.hpp>
#include <vmap/som/virtual_room.hpp>

// memory/: the visual memory a robot keeps (key images, loops, localization, resume)
#include <vmap/memory/replace.hpp>
#include <vmap/memory/sequence.hpp>
#include <vmap/memory/stacks.hpp>
#include <vmap/memory/store.hpp>
#include <vmap/memory/types.hpp>
#include <vmap/memory/visual_memory.hpp>
