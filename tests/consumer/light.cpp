// The compile-time probe's program (SHARED/bench/compile/consumer.cpp: a memory fed from a
// folder of images, one localization) on the run-time layer: a memory of the default
// stack (ORB, MAGSAC F-matrix) held by AnyMemory, whose header declares it only. Linked
// with vmap::stacks, its translation unit parses no VisualMemory
// (examples/bench/compile_time.sh times it against the probe).
//
// usage: vmap_consumer_light FRAMES QUERY_IMAGE  (exits 0 when the query is localized)
#include <vmap/io/frame_source.hpp>
#include <vmap/runtime/memory.hpp>

#include <opencv2/imgcodecs.hpp>

#include <cstdio>

int main(int argc, char** argv) {
  if (argc < 3) return 2;
  auto memory = vmap::AnyMemory::in_ram(vmap::PolicyStack{});
  auto frames = vmap::FrameSource::open(argv[1], {.grey = true});
  while (auto f = frames.next()) memory.push(*f);
  auto answer = memory.localize(cv::imread(argv[2], cv::IMREAD_GRAYSCALE));
  std::printf("%zu key images; %s\n", memory.key_images(), answer.ok() ? "localized" : "unknown place");
  return answer.ok() ? 0 : 1;
}
