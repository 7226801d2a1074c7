// The run-time layer from outside the vmap tree, linked with the compiled stacks
// (find_package(vmap COMPONENTS stacks), vmap::stacks): a memory of the default stack
// chosen at run time, fed from the sample frames, then asked where one of them was taken.
// Its translation unit instantiates no memory; the program links the one vmap::stacks
// compiled (a missing instantiation would be a link error).
//
// usage: vmap_consumer_stacks RGB_TXT
#include <vmap/io/frame_source.hpp>
#include <vmap/runtime/memory.hpp>

#include <cstdio>

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: vmap_consumer_stacks RGB_TXT\n");
    return 2;
  }
  auto memory = vmap::AnyMemory::in_ram(vmap::PolicyStack::from_string("orb features=1000 method=magsac"));
  auto frames = vmap::FrameSource::open(argv[1], {.grey = true});
  cv::Mat query;
  while (auto frame = frames.next()) {
    memory.push(*frame);
    if (frame->index == 30) query = frame->image.clone();
  }
  const vmap::MemoryLocalization answer = memory.localize(query);
  // The 60 sample frames give 24 key images at the default tau 0.3 (examples/keyframes.md),
  // and frame 30 is among them or next to one.
  const bool ok = memory.key_images() == 24 && answer.ok();
  std::printf("vmap::stacks consumer: %zu key images, frame 30 %s: %s\n", memory.key_images(),
              answer.ok() ? "localized" : "not localized", ok ? "ok" : "unexpected result");
  return ok ? 0 : 1;
}
