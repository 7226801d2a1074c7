#pragma once

// A page that shows a memory: `vmap view MEMORY --out DIR` and Python's memory.view(folder)
// both call write_view, which writes DIR/index.html with its assets beside it. The page
// opens from the file system in a browser, with no server and no network (its script and
// style are this library's own, runtime/detail/view_assets.hpp), and shows:
//
//   - a summary: the stack, the camera, the sessions or robots, key images, loop edges,
//     the file's size and format version;
//   - the map: with poses, the key images' positions seen from above (the up axis chosen
//     from the poses, view_up_axis), one colour per session or robot, loop edges as lines;
//     without poses, the key-image chain as a time line with loop edges as arcs;
//   - a key image on click: its image, time, session, inliers to its neighbours, and its
//     loops with both images side by side and the verified matches drawn;
//   - the loops as a table (sortable), the similarity of consecutive key images along the
//     run against the selection threshold tau (eq. 5, García-Pintos et al. 2023) and the
//     map's quality (eq. 7) per session or robot;
//   - the answers of localize (ViewAnswer, e.g. read from `vmap localize --json`): each
//     query on its key image (with its metric pose where one was answered), or unknown
//     with the reason.
//
//   auto memory = vmap::AnyMemory::open("run.vmdb");
//   vmap::ViewResult page = vmap::write_view(memory, "run_page");   // run_page/index.html
//
// Large memories stay usable: the key images' pixels are separate files the page loads
// when one is shown, the marks are drawn on a canvas, and the loops' matches are files
// of 256 loops loaded when a loop is shown (examples/results/view.md has the times).
//
// Where the pixels come from: the memory's own (a memory kept with images png or jpeg,
// opened with its pixels), else each session's recorded input read again (a list, a
// folder, a video or a bag the store noted, `vmap build --memory`) when it is still there
// and still holds the key images' frames (checked by name); else the page says there is
// no image. The folder is written atomically (io/atomic_file.hpp, AtomicDirectory): built
// beside DIR and renamed into place, and DIR must be new, empty or an earlier vmap output
// holding only its own files. A program that includes this header reads frames
// (FrameSource): link vmap::videoio.

#include <vmap/core/error.hpp>
#include <vmap/keyframe/visual_map.hpp>
#include <vmap/memory/types.hpp>
#include <vmap/runtime/fleet.hpp>
#include <vmap/runtime/memory.hpp>
#include <vmap/runtime/view_options.hpp>

#include <cstdint>
#include <filesystem>
#include <string>
#include <utility>
#include <vector>

namespace vmap {

/// The page of `memory` (any AnyMemory: a store, a .vmem file, a robot of a fleet, in RAM)
/// written into the folder `dir` (see the top of this file).
inline ViewResult write_view(AnyMemory& memory, const std::filesystem::path& dir, const ViewOptions& options = {});

/// The page of every robot of a fleet's memory (FleetMemory) and the loops between them
/// (fleet_loops of its URI): one colour per robot.
inline ViewResult write_view(FleetMemory& fleet, const std::vector<FleetLoop>& between, const std::filesystem::path& dir,
                             const ViewOptions& options = {});

/// The page of a visual map (`vmap build --out`'s map.vmap, keyframe/map_io.hpp): its
/// key images on the time line, no loops.
inline ViewResult write_view(const VisualMap& map, const std::filesystem::path& dir, const ViewOptions& options = {});

/// What `source` is (see ViewSourceKind) and the file to open. A path that does not exist
/// is an Error of kind not_found; a file or folder that is neither kind, corrupt.
[[nodiscard]] inline std::pair<ViewSourceKind, std::filesystem::path> view_source_kind(const std::string& source);

/// Opens `source` (view_source_kind) and writes its page into `dir`: a fleet's memory is
/// shown whole, or robot `robot`'s memory alone when one is named. A memory is opened to
/// read (also while another program writes it); its pixels are decoded when it keeps them
/// and they fit MapLoadOptions' limits, else read from its recorded input.
inline ViewResult view_source(const std::string& source, const std::filesystem::path& dir,
                              const ViewOptions& options = {}, const std::string& robot = {});

}  // namespace vmap

#include <vmap/runtime/detail/view_page.hpp>
