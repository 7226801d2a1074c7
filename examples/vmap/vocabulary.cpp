// `vmap vocabulary`: learns a bag-of-words vocabulary tree from the features of a set of
// frames and saves it (vmap's binary format) for `vmap loops --vocabulary`.
//
//   vmap vocabulary ../shared/data/tum_fr1_rpy/rgb.txt --words 1000 --depth 3 --out voc.bin
//
// `vmap vocabulary convert INPUT OUTPUT` converts a vocabulary file of any format vmap reads
// (vmap, ORB-SLAM2/3 ORBvoc.txt, DBoW2 YAML .yml / .yml.gz, FBoW binary) to vmap's
// format, or to ORBvoc text (OUTPUT ending in .txt) or FBoW binary (OUTPUT ending in .fbow).
//
// Binary descriptors (orb, akaze) give a k-majority tree on Hamming distance, float ones
// (sift, xfeat) a k-means tree on L2. Progress goes to stderr.
#include "common/bag_options.hpp"
#include "common/cli_support.hpp"
#include "common/policies.hpp"
#include "common/vocabulary_cli.hpp"
#include "vmap/cli.hpp"

#include <vmap/place/vocabulary.hpp>
#include <vmap/runtime/loops.hpp>
#include <vmap/runtime/option_names.hpp>
#include <vmap/runtime/vocabulary.hpp>

#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <cstdio>
#include <memory>
#include <optional>
#include <string>

namespace {

namespace ex = vmap::examples;

struct VocabularyArgs {
  std::string input;
  std::string out;
  std::string convert_in;
  std::string convert_out;
  bool force = false;          ///< learning: --out may replace an existing vocabulary
  bool convert_force = false;  ///< convert: OUTPUT may replace an existing vocabulary
  ex::DescriptorChoice descriptor;
  vmap::VocabularyLearning learning;
};

int convert(const VocabularyArgs& a) {
  ex::refuse_input_as_output(a.convert_out, "OUTPUT", {a.convert_in});
  vmap::check_vocabulary_output(a.convert_out, a.convert_force, std::filesystem::path(a.convert_in), "--force");
  const auto t0 = std::chrono::steady_clock::now();
  const vmap::AnyVocabulary v = vmap::AnyVocabulary::load(a.convert_in);
  const double load_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const vmap::VocabularyFileFormat format = vmap::vocabulary_format_of(a.convert_out);
  vmap::save_vocabulary(v, a.convert_out, format, a.convert_in);
  std::printf("%s: %zu words (branching %d, depth %d, weighting %s), %s, from %s (read in %.3f s)\n", a.convert_out.c_str(),
              v.size(), v.branching(), v.depth(), std::string(vmap::to_string(v.weighting())).c_str(),
              format == vmap::VocabularyFileFormat::vmap   ? "vmap"
              : format == vmap::VocabularyFileFormat::fbow ? "FBoW binary"
                                                           : "ORB-SLAM2 text",
              a.convert_in.c_str(), load_s);
  return 0;
}

int run(const VocabularyArgs& a) {
  if (a.input.empty() || a.out.empty())
    ex::usage_error("learning needs FRAMES and --out (converting: vmap vocabulary convert INPUT OUTPUT)");
  ex::as_usage([&] { a.learning.validate(vmap::OptionNames::command_line()); });
  // Before the frames are read: a refused --out is known at once, not after the learning.
  ex::refuse_input_as_output(a.out, "--out", {a.input});
  vmap::check_vocabulary_output(a.out, a.force, std::nullopt, "--force");
  const vmap::PolicyStack stack = ex::stack_of(a.descriptor, "magsac", std::nullopt);
  std::optional<ex::Progress> progress;
  const auto features = vmap::extract_features(
      a.input, stack,
      [&](std::size_t done, std::size_t n) {
        if (!progress) progress.emplace("vmap vocabulary: features", n);
        progress->update(done);
      },
      ex::with_bag_options(a.input, ex::reporting_skips()));
  if (progress) progress->done();
  std::size_t descriptors = 0;
  for (const auto& f : features.frames) descriptors += f.size();
  if (isatty(STDERR_FILENO) != 0)
    std::fprintf(stderr, "learning: %zu descriptors of %zu frames, branching %d, depth %d...\n", descriptors,
                 features.frames.size(), a.learning.branching(), a.learning.depth);
  const auto t0 = std::chrono::steady_clock::now();
  const vmap::AnyVocabulary v = vmap::learn_vocabulary(features.frames, a.learning);
  const double learn_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  v.save(a.out);
  std::printf("%s: %zu words (branching %d, depth %d, %s), learned from %zu frames in %.1f s (features %.1f s)\n",
              a.out.c_str(), v.size(), v.branching(), v.depth(),
              v.binary() != nullptr ? "binary, Hamming" : "float, L2", features.frames.size(), learn_s,
              features.seconds);
  return 0;
}

std::function<int()> setup(CLI::App& app) {
  auto a = std::make_shared<VocabularyArgs>();
  app.add_option("FRAMES", a->input, "Frames: image folder, list file, video, TUM rgb.txt or a bag");
  ex::add_bag_options(app);
  app.add_option("--out", a->out, "The vocabulary file to write");
  app.add_flag("--force", a->force, "Replace an existing --out, only when it is a vocabulary vmap reads");
  ex::add_vocabulary_options(app, a->learning, "");
  app.add_option("--seed", a->learning.seed, "Seed of the sample and the clustering")->capture_default_str();
  app.add_option("--features", a->descriptor.name, "orb, akaze, sift or xfeat")->capture_default_str();
  app.add_option("--nfeatures", a->descriptor.features,
                 "Keypoint budget per image (ORB, SIFT; top-k for XFeat), at most " + std::to_string(ex::max_nfeatures))
      ->capture_default_str()
      ->check(ex::count_in(1, ex::max_nfeatures));
  app.add_option("--model", a->descriptor.model, "--features xfeat: the XFeat ONNX model");
  auto* c = app.add_subcommand("convert", "Convert a vocabulary file (vmap, ORBvoc.txt, DBoW2 .yml/.yml.gz, FBoW) to vmap's "
                                          "format, or to ORBvoc text (OUTPUT *.txt) or FBoW (OUTPUT *.fbow)");
  c->add_option("INPUT", a->convert_in, "Vocabulary file of any format vmap reads")->required()->check(CLI::ExistingFile);
  c->add_option("OUTPUT", a->convert_out, "File written (its extension chooses the format)")->required();
  c->add_flag("--force", a->convert_force,
              "Replace an existing OUTPUT, only when it is a vocabulary vmap reads (never INPUT, a memory or another file)");
  return [a, c] { return c->parsed() ? convert(*a) : run(*a); };
}

const bool registered =
    vmap::cli::add_command({"vocabulary", "Learn a bag-of-words vocabulary tree from frames (for vmap loops), or convert one", setup});

}  // namespace
