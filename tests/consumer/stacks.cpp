// The run-time layer from outside the vmap tree, linked with the compiled stacks
// (find_package(vmap COMPONENTS stacks), vmap::stacks): a memory store of the default
// stack chosen at run time, started when it does not exist (the error kind tells a
// missing memory from a damaged one: examples/library.md), fed from the sample frames,
// then opened again and asked where one of them was taken. Its translation unit
// instantiates no memory; the program links the ones vmap::stacks compiled (a missing
// instantiation would be a link error).
//
// usage: vmap_consumer_stacks RGB_TXT MEMORY_FILE
#include <vmap/io/frame_source.hpp>
#include <vmap/runtime/memory.hpp>

#include <cstdio>
#include <filesystem>

namespace {

// ---- examples/library.md, "Errors" ----
vmap::AnyMemory open_or_start(const std::filesystem::path& path, const vmap::PolicyStack& stack) {
  try {
    return vmap::AnyMemory::open(path, {.write = true, .new_session = true});
  } catch (const vmap::Error& e) {
    if (e.kind() != vmap::ErrorKind::not_found) throw;  // corrupt, busy, ...: a person decides
    return vmap::AnyMemory::create(path, stack);
  }
}
// ---- end of the example ----

}  // namespace

int main(int argc, char** argv) {
  if (argc != 3) {
    std::fprintf(stderr, "usage: vmap_consumer_stacks RGB_TXT MEMORY_FILE\n");
    return 2;
  }
  const std::filesystem::path file = argv[2];
  std::filesystem::remove(file);
  const auto stack = vmap::PolicyStack::from_string("orb features=1000 method=magsac");
  cv::Mat query;
  {
    vmap::AnyMemory memory = open_or_start(file, stack);  // none yet: started
    auto frames = vmap::FrameSource::open(argv[1], {.grey = true});
    while (auto frame = frames.next()) {
      memory.push(*frame);
      if (frame->index == 30) query = frame->image.clone();
    }
    memory.close();
  }
  vmap::AnyMemory memory = open_or_start(file, stack);  // opened, a second session
  const vmap::MemoryLocalization answer = memory.localize(query);
  // The 60 sample frames give 24 key images at the default tau 0.3 (examples/keyframes.md),
  // and frame 30 is among them or next to one.
  const bool ok = memory.key_images() == 24 && memory.sessions().size() == 2 && answer.ok();
  std::printf("vmap::stacks consumer: %zu key images, %zu sessions, frame 30 %s: %s\n", memory.key_images(),
              memory.sessions().size(), answer.ok() ? "localized" : "not localized", ok ? "ok" : "unexpected result");
  return ok ? 0 : 1;
}
