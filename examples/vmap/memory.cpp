// `vmap memory build|localize|info`: a visual memory (include/vmap/memory) kept in one
// file. `build INPUT --out M` streams a sequence into a new memory, or with --resume
// continues the memory in M after the last frame it saw; `localize M IMAGE...` answers
// the key image each query matches (verified F-matrix, inliers, pose when known);
// `info M` lists the key images and loop edges. --json prints the answers as JSON.
#include "common/cli_support.hpp"
#include "vmap/cli.hpp"

#include <vmap/memory/visual_memory.hpp>

#include <nlohmann/json.hpp>

#include <opencv2/imgcodecs.hpp>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <map>
#include <string>
#include <variant>
#include <vector>

namespace {

namespace ex = vmap::examples;

struct MemoryArgs {
  std::string input, out, memory, vocabulary;
  std::vector<std::string> images;
  bool resume = false, json = false;
  double tau = 0.3;
  std::string storage = "none";
  std::size_t start = 0, end = 0, stride = 1;
};

nlohmann::json pose_json(const vmap::OdometryPose& p) {
  if (const auto* p2 = std::get_if<vmap::Pose2>(&p)) return {{"x", p2->x()}, {"y", p2->y()}, {"theta", p2->theta()}};
  if (const auto* p3 = std::get_if<cv::Affine3d>(&p)) {
    nlohmann::json m = nlohmann::json::array();
    for (int i = 0; i < 12; ++i) m.push_back(p3->matrix.val[i]);
    return {{"se3", m}};
  }
  return nullptr;
}

nlohmann::json link_json(const vmap::OrbVisualMemory& mem, const vmap::PlaceLink& l) {
  const auto& k = mem.map().keys[l.key];
  nlohmann::json f = nlohmann::json::array();
  for (double e : l.fundamental.val) f.push_back(e);
  return {{"key", l.key},          {"frame_index", k.frame_index}, {"name", k.name},
          {"inliers", l.inliers},  {"matches", l.matches},         {"bow_score", l.bow_score},
          {"similarity", l.similarity}, {"fundamental", f},        {"pose", pose_json(mem.poses()[l.key])}};
}

int build(const MemoryArgs& a) {
  namespace fs = std::filesystem;
  std::optional<vmap::OrbVisualMemory> mem;
  vmap::FrameSourceOptions so{.start = a.start, .stride = a.stride, .grey = true};
  if (a.end > 0) so.end = a.end;
  if (a.resume) {
    mem.emplace(vmap::OrbVisualMemory::load(a.out));
    if (const auto last = mem->last_frame_index()) so.start = std::max(so.start, *last + a.stride);
    if (so.start >= so.end) vmap::detail::fail("--resume: '" + a.out + "' already holds every frame up to --end");
  } else {
    vmap::MemoryOptions o;
    o.selector.tau = a.tau;
    const std::map<std::string, vmap::ImageStorage> storage{
        {"none", vmap::ImageStorage::none}, {"png", vmap::ImageStorage::png}, {"jpeg", vmap::ImageStorage::jpeg}};
    o.images = storage.at(a.storage);
    vmap::AnyVocabulary voc;
    if (!a.vocabulary.empty()) voc = vmap::AnyVocabulary::load(a.vocabulary);
    mem.emplace(vmap::OrbDescriptor{}, vmap::BruteForceMatcher{}, vmap::FundamentalEstimator{}, vmap::InlierRatio{}, o,
                std::move(voc));
  }
  auto src = vmap::FrameSource::open(a.input, so);
  const auto t0 = std::chrono::steady_clock::now();
  std::size_t pushed = 0;
  nlohmann::json loops = nlohmann::json::array();
  while (auto f = src.next()) {
    const auto step = mem->push(*f);
    ++pushed;
    for (const auto& e : step.loops)
      loops.push_back({{"from", e.from}, {"to", e.link.key}, {"inliers", e.link.inliers}, {"bow_score", e.link.bow_score}});
  }
  const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  mem->save(a.out);
  if (a.json) {
    std::printf("%s\n", nlohmann::json{{"memory", a.out}, {"pushed", pushed}, {"frames", mem->frames()},
                                       {"key_images", mem->key_images()}, {"loops", mem->loops().size()},
                                       {"new_loops", loops}, {"last_frame_index", mem->last_frame_index().value_or(0)},
                                       {"bytes", fs::file_size(a.out)}, {"seconds", s}}
                            .dump(2)
                            .c_str());
  } else {
    std::printf("%s %zu frames (%zu in all): %zu key images, %zu loop edges (%zu new), %.1f ms per frame\n",
                a.resume ? "resumed with" : "pushed", pushed, mem->frames(), mem->key_images(), mem->loops().size(),
                loops.size(), pushed ? 1000.0 * s / static_cast<double>(pushed) : 0.0);
    std::printf("saved '%s' (%ju bytes); last frame %zu\n", a.out.c_str(), static_cast<std::uintmax_t>(fs::file_size(a.out)),
                mem->last_frame_index().value_or(0));
  }
  return 0;
}

int localize(const MemoryArgs& a) {
  auto mem = vmap::OrbVisualMemory::load(a.memory);
  nlohmann::json out = nlohmann::json::array();
  for (const auto& path : a.images) {
    const cv::Mat img = cv::imread(path, cv::IMREAD_GRAYSCALE);
    if (img.empty()) vmap::detail::fail("localize: cannot read the image '" + path + "'");
    const auto t0 = std::chrono::steady_clock::now();
    const auto answer = mem.localize(img);
    const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    nlohmann::json j{{"image", path}, {"status", std::string(vmap::to_string(answer.status))}, {"ms", ms}};
    j["matches"] = nlohmann::json::array();
    for (const auto& l : answer.matches) j["matches"].push_back(link_json(mem, l));
    out.push_back(j);
    if (!a.json) {
      if (const auto* b = answer.best())
        std::printf("%s: key %u (frame %zu, %s), %d inliers of %d matches, BoW %.3f, %.1f ms\n", path.c_str(), b->key,
                    mem.map().keys[b->key].frame_index, mem.map().keys[b->key].name.c_str(), b->inliers, b->matches,
                    b->bow_score, ms);
      else
        std::printf("%s: not localized (%s), %.1f ms\n", path.c_str(), std::string(vmap::to_string(answer.status)).c_str(), ms);
    }
  }
  if (a.json) std::printf("%s\n", out.dump(2).c_str());
  return 0;
}

int info(const MemoryArgs& a) {
  const auto mem = vmap::OrbVisualMemory::load(a.memory);
  nlohmann::json keys = nlohmann::json::array(), loops = nlohmann::json::array();
  for (std::size_t k = 0; k < mem.key_images(); ++k)
    keys.push_back({{"key", k}, {"frame_index", mem.map().keys[k].frame_index}, {"name", mem.map().keys[k].name}});
  for (const auto& e : mem.loops()) loops.push_back({{"from", e.from}, {"to", e.link.key}, {"inliers", e.link.inliers}});
  if (a.json) {
    std::printf("%s\n", nlohmann::json{{"frames", mem.frames()}, {"key_images", keys}, {"loops", loops}}.dump(2).c_str());
    return 0;
  }
  std::printf("%zu frames, %zu key images, %zu loop edges, vocabulary of %zu words, last frame %zu\n", mem.frames(),
              mem.key_images(), mem.loops().size(), mem.vocabulary().size(), mem.last_frame_index().value_or(0));
  for (const auto& e : mem.loops())
    std::printf("  loop: key %u (frame %zu) -> key %u (frame %zu), %d inliers\n", e.from, mem.map().keys[e.from].frame_index,
                e.link.key, mem.map().keys[e.link.key].frame_index, e.link.inliers);
  return 0;
}

std::function<int()> setup(CLI::App& app) {
  auto a = std::make_shared<MemoryArgs>();
  app.require_subcommand(1);
  auto* b = app.add_subcommand("build", "Stream a sequence into a memory file (or --resume one)");
  b->add_option("input", a->input, "Video, image folder, image list or TUM rgb.txt")->required();
  b->add_option("--memory", a->out, "Memory file written (read first with --resume)")->required();
  b->add_flag("--resume", a->resume, "Continue the memory in --memory after the last frame it saw (its options are kept)");
  b->add_option("--threshold,--tau", a->tau, "Similarity threshold tau: a new key image when S < tau (eq. 6)")
      ->check(ex::real_in(0.0, 1.0, true));
  b->add_option("--images", a->storage, "Key image pixels saved")->check(CLI::IsMember({"none", "png", "jpeg"}));
  b->add_option("--vocabulary", a->vocabulary, "Vocabulary file (vmap vocabulary); default: learned online");
  b->add_option("--start", a->start, "First frame index read")->check(ex::count_in(0, ex::max_frame_index));
  b->add_option("--end", a->end, "One past the last frame index read (0: all)")->check(ex::count_in(0, ex::max_frame_index));
  b->add_option("--stride", a->stride, "Read every n-th frame")->check(ex::count_in(1, ex::max_frame_index));
  b->add_flag("--json", a->json, "Print the result as JSON");
  auto* l = app.add_subcommand("localize", "The key image(s) each query image matches");
  l->add_option("memory", a->memory, "Memory file")->required();
  l->add_option("images", a->images, "Query images")->required();
  l->add_flag("--json", a->json, "Print every answer as JSON");
  auto* i = app.add_subcommand("info", "Key images and loop edges of a memory file");
  i->add_option("memory", a->memory, "Memory file")->required();
  i->add_flag("--json", a->json, "Print as JSON");
  return [a, b, l]() {
    if (b->parsed()) return build(*a);
    if (l->parsed()) return localize(*a);
    return info(*a);
  };
}

const bool registered = vmap::cli::add_command({"memory", "A visual memory file: build, resume, localize, info", setup});

}  // namespace
