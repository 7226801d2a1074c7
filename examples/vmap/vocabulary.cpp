// `vmap vocabulary`: learns a bag-of-words vocabulary tree from the features of a set of
// frames and saves it (vmap's binary format) for `vmap loops --vocabulary`.
//
//   vmap vocabulary ../shared/data/tum_fr1_rpy/rgb.txt --words 1000 --depth 3 --out voc.bin
//
// Binary descriptors (orb, akaze) give a k-majority tree on Hamming distance, float ones
// (sift, xfeat) a k-means tree on L2. Progress goes to stderr.
#include "common/lcd_run.hpp"
#include "vmap/cli.hpp"

#include <chrono>
#include <cstdio>
#include <memory>
#include <string>

namespace {

struct VocabularyArgs {
  std::string input;
  std::string out;
  vmap::examples::DescriptorChoice descriptor;
  vmap::examples::VocabularyChoice vocabulary;
};

int run(const VocabularyArgs& a) {
  const int branching = a.vocabulary.branching();
  const auto features = vmap::examples::extract_features(a.input, a.descriptor, [](std::size_t done, std::size_t n) {
    if (done == n || done % 10 == 0) std::fprintf(stderr, "\rfeatures: frame %zu/%zu", done, n);
    if (done == n) std::fprintf(stderr, "\n");
  });
  std::size_t descriptors = 0;
  for (const auto& f : features.frames) descriptors += f.size();
  std::fprintf(stderr, "learning: %zu descriptors of %zu frames, branching %d, depth %d...\n", descriptors,
               features.frames.size(), branching, a.vocabulary.depth);
  const auto t0 = std::chrono::steady_clock::now();
  const vmap::AnyVocabulary v = vmap::examples::learn_vocabulary(features.frames, a.vocabulary);
  const double learn_s = vmap::examples::seconds_since(t0);
  v.save(a.out);
  std::printf("%s: %zu words (branching %d, depth %d, %s), learned from %zu frames in %.1f s (features %.1f s)\n",
              a.out.c_str(), v.size(), v.branching(), v.depth(),
              v.binary() != nullptr ? "binary, Hamming" : "float, L2", features.frames.size(), learn_s,
              features.seconds);
  return 0;
}

std::function<int()> setup(CLI::App& app) {
  auto a = std::make_shared<VocabularyArgs>();
  app.add_option("FRAMES", a->input, "Frames: image folder, list file, video or TUM rgb.txt")->required();
  app.add_option("--out", a->out, "The vocabulary file to write")->required();
  app.add_option("--words", a->vocabulary.words, "At most this many words (branching k: smallest with k^depth >= words)")
      ->capture_default_str();
  app.add_option("--depth", a->vocabulary.depth, "Depth L of the tree")->capture_default_str();
  app.add_option("--seed", a->vocabulary.seed, "Seed of the sample and the clustering")->capture_default_str();
  app.add_option("--features", a->descriptor.name, "orb, akaze, sift or xfeat")->capture_default_str();
  app.add_option("--nfeatures", a->descriptor.features, "Keypoint budget per image (ORB, SIFT; top-k for XFeat)")
      ->capture_default_str();
  app.add_option("--model", a->descriptor.model, "--features xfeat: the XFeat ONNX model");
  return [a] { return run(*a); };
}

const bool registered =
    vmap::cli::add_command({"vocabulary", "Learn a bag-of-words vocabulary tree from frames (for vmap loops)", setup});

}  // namespace
