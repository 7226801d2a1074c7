// The memories of bench_view.py (examples/results/view.md): a real memory, and synthetic
// memories of about N key images made from it as bench_fleet makes them
// (examples/common/synthetic_memory.hpp: its records repeated as further sessions, each
// copy moved beside the others on the map, each session noting the seed's input, so that
// `vmap view` reads their images again from it). The seed is rtabmap_loop (a robot drives
// a corridor loop twice: 83 key images, real loop edges, no poses: the page's time line)
// or tum_fr3_cabinet_kf (58 key frames circling a cabinet with their ground truth poses:
// the page's map from above).
//
//   bench_view --shared ../shared --work build/bench_view --sizes 100,10000,100000 --seed rtabmap
//
// Prints one line per memory: "memory N PATH KEY_IMAGES LOOPS".
#include "common/synthetic_memory.hpp"

#include <vmap/io/frame_source.hpp>
#include <vmap/memory/records.hpp>
#include <vmap/memory/store.hpp>
#include <vmap/memory/vmem.hpp>
#include <vmap/runtime/memory.hpp>
#include <vmap/runtime/recorder.hpp>

#include <CLI/CLI.hpp>
#include <opencv2/core/affine.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <optional>
#include <string>
#include <variant>
#include <vector>

namespace {

namespace fs = std::filesystem;

/// The seed: rtabmap_loop's frames, or the cabinet's key frames with their poses, mapped
/// into a store that notes its input.
vmap::AnyMemory seed_memory(const fs::path& shared, const std::string& seed, const fs::path& file) {
  const bool cabinet = seed == "cabinet";
  const fs::path input = cabinet ? shared / "data/tum_fr3_cabinet_kf/rgb.txt" : shared / "data/rtabmap_loop/images";
  fs::remove(file);
  auto memory = vmap::AnyMemory::create(file, vmap::PolicyStack{});
  vmap::FrameSourceOptions so;
  so.grey = true;
  auto src = vmap::FrameSource::open(input, so);
  std::optional<vmap::FramePoses> poses;
  if (cabinet) poses.emplace(shared / "data/tum_fr3_cabinet_kf/truth_cam_poses.txt", src);
  vmap::set_session_input(memory, vmap::recorded_input(input.string(), src, 1));
  vmap::RecordOptions o;
  if (poses) o.poses = [&](const vmap::Frame& f) { return (*poses)(f); };
  (void)vmap::record(memory, src, o);
  memory.close();
  return vmap::AnyMemory::open(file);
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"bench_view: the memories bench_view.py opens as pages"};
  std::string shared = "../shared", work = "build/bench_view";
  std::vector<std::size_t> sizes{100, 10000, 100000};
  std::string seed = "rtabmap";
  app.add_option("--shared", shared, "The shared data folder");
  app.add_option("--work", work, "Folder for the memories");
  app.add_option("--sizes", sizes, "Key images of each synthetic memory (about: whole copies of the seed)")->delimiter(',');
  app.add_option("--seed", seed, "rtabmap (loops, no poses) or cabinet (poses)")->check(CLI::IsMember({"rtabmap", "cabinet"}));
  CLI11_PARSE(app, argc, argv);
  try {
    fs::create_directories(work);
    auto seeded = seed_memory(shared, seed, fs::path(work) / ("seed_" + seed + ".vmdb"));
    const vmap::MemoryRecords records = seeded.records();
    const auto input = vmap::session_input(seeded, 0);
    const std::size_t per_run = records.keys.size();
    // The copies side by side: a grid in the plane of the two axes the seed spreads most.
    cv::Vec3d lo(1e300, 1e300, 1e300), hi(-1e300, -1e300, -1e300);
    for (const auto& k : records.keys)
      if (const auto* a = std::get_if<cv::Affine3d>(&k.pose))
        for (int i = 0; i < 3; ++i) lo[i] = std::min(lo[i], a->translation()[i]), hi[i] = std::max(hi[i], a->translation()[i]);
    int axes[3] = {0, 1, 2};
    std::sort(axes, axes + 3, [&](int a, int b) { return hi[a] - lo[a] > hi[b] - lo[b]; });
    const double step = 1.5 * std::max(hi[axes[0]] - lo[axes[0]], hi[axes[1]] - lo[axes[1]]);
    std::fprintf(stderr, "bench_view: seed of %zu key images, %zu loops\n", per_run, records.loops.size());
    for (const std::size_t wanted : sizes) {
      const std::size_t copies = std::max<std::size_t>(1, (wanted + per_run / 2) / per_run);
      const auto grid = static_cast<std::size_t>(std::ceil(std::sqrt(static_cast<double>(copies))));
      const auto records_n = vmap::examples::repeated_records(records, copies, [&](std::size_t c) {
        cv::Vec3d d(0, 0, 0);
        d[axes[0]] = step * static_cast<double>(c % grid);
        d[axes[1]] = step * static_cast<double>(c / grid);
        return d;
      });
      const fs::path vmem = fs::path(work) / "copies.vmem", file = fs::path(work) / ("view_" + seed + "_" + std::to_string(wanted) + ".vmdb");
      {
        std::ofstream out(vmem, std::ios::binary | std::ios::trunc);
        const std::string bytes = vmap::detail::vmem_file_bytes(records_n, records.options.images);
        out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
      }
      fs::remove(file);
      auto store = vmap::AnyMemory::copy_into_store(vmap::AnyMemory::open(vmem), file);
      store.close();
      fs::remove(vmem);
      if (input) {
        auto notes = vmap::MemoryStore::open(file, vmap::sqlite::Access::write);
        for (std::size_t s = 0; s < copies; ++s) vmap::set_session_input_of(notes, s, *input);
      }
      std::printf("memory %zu %s %zu %zu\n", wanted, file.string().c_str(), records_n.keys.size(), records_n.loops.size());
      std::fflush(stdout);
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_view: %s\n", e.what());
    return 1;
  }
  return 0;
}
