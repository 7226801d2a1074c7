// `vmap view MEMORY --out DIR`: a page that shows a memory (a store, a .vmem file, a
// fleet's memory, or the visual map of `vmap build --out`), written by the library's
// run-time layer (include/vmap/runtime/view.hpp): DIR/index.html with its files beside
// it, opened from the file system in a browser. --answers FILE places the queries of
// `vmap localize --memory ... --json` on their key images.
#include "common/cli_support.hpp"
#include "vmap/cli.hpp"

#include <vmap/io/files.hpp>
#include <vmap/io/postgres.hpp>
#include <vmap/runtime/view.hpp>

#include <nlohmann/json.hpp>

#include <cstdio>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace {

namespace ex = vmap::examples;

struct ViewArgs {
  std::string memory, out, answers, robot, title;
  int image_side = vmap::ViewOptions{}.image_side;
  bool no_matches = false, json = false;
};

/// The answers file's size limit: the JSON of a long --sequence run, with room.
constexpr std::uintmax_t max_answers_bytes = std::uintmax_t{256} << 20;

/// The queries of `vmap localize --memory ... --json` (single images, --sequence, or a
/// fleet's, whose queries name the robot that answered), with the metric pose where the
/// answer has one ("pose": {"position": [x, y, z], "quaternion": [qx, qy, qz, qw], and
/// figures}, or null with "pose_reason"). A file that is not such JSON is corrupt.
std::vector<vmap::ViewAnswer> read_answers(const std::string& file) {
  ex::check_input_file(file, "--answers");
  const std::string text = vmap::read_file(file, max_answers_bytes, "answers file");
  const auto bad = [&](const std::string& what) -> void {
    vmap::detail::fail(vmap::ErrorKind::corrupt, "--answers '" + file + "' is not the JSON of vmap localize --json: " + what);
  };
  const nlohmann::json j = nlohmann::json::parse(text, nullptr, false);
  if (j.is_discarded()) bad("it does not parse as JSON");
  if (!j.is_object() || !j.contains("queries") || !j["queries"].is_array()) bad("it has no list 'queries'");
  std::vector<vmap::ViewAnswer> out;
  for (std::size_t i = 0; i < j["queries"].size(); ++i) {
    const nlohmann::json& q = j["queries"][i];
    const std::string at = "query " + std::to_string(i);
    if (!q.is_object()) bad(at + " is not an object");
    const auto field = [&](const char* name, bool (nlohmann::json::*is)() const noexcept) -> const nlohmann::json& {
      if (!q.contains(name) || !(q[name].*is)()) bad(at + ": '" + name + "' is missing or of another type");
      return q[name];
    };
    vmap::ViewAnswer a;
    a.image = field("image", &nlohmann::json::is_string).get<std::string>();
    a.status = field("status", &nlohmann::json::is_string).get<std::string>();
    a.reason = field("reason", &nlohmann::json::is_string).get<std::string>();
    a.confidence = field("confidence", &nlohmann::json::is_number).get<double>();
    a.accepted = field("localized", &nlohmann::json::is_boolean).get<bool>();
    if (q.contains("key") && !q["key"].is_null()) {
      if (!q["key"].is_number_unsigned()) bad(at + ": 'key' is not a key image's index");
      a.key = q["key"].get<std::uint32_t>();
    }
    if (a.accepted != a.key.has_value()) bad(at + ": 'localized' and 'key' disagree");
    if (q.contains("robot")) a.robot = field("robot", &nlohmann::json::is_string).get<std::string>();
    if (q.contains("pose_reason") && q["pose_reason"].is_string()) a.pose_reason = q["pose_reason"].get<std::string>();
    if (q.contains("pose") && !q["pose"].is_null()) {
      const nlohmann::json& p = q["pose"];
      const auto numbers = [&](const char* name, std::size_t n) {
        if (!p.is_object() || !p.contains(name) || !p[name].is_array() || p[name].size() != n)
          bad(at + ": the pose's '" + name + "' is not a list of " + std::to_string(n) + " numbers");
        std::vector<double> v;
        for (const auto& x : p[name]) {
          if (!x.is_number()) bad(at + ": the pose's '" + name + "' is not a list of numbers");
          v.push_back(x.get<double>());
        }
        return v;
      };
      vmap::ViewPose pose;
      const auto position = numbers("position", 3), quaternion = numbers("quaternion", 4);
      std::copy(position.begin(), position.end(), pose.position.begin());
      std::copy(quaternion.begin(), quaternion.end(), pose.quaternion.begin());
      for (const auto& [name, value] : p.items())
        if (value.is_number()) pose.figures.emplace_back(name, value.get<double>());
      a.pose = pose;
    }
    out.push_back(std::move(a));
  }
  return out;
}

int run(const ViewArgs& a) {
  namespace fs = std::filesystem;
  const bool fleet = vmap::pg::is_uri(a.memory);
  ex::current_inputs() = {fleet ? vmap::pg::redacted(a.memory) : a.memory};
  if (!fleet && !a.robot.empty()) ex::usage_error("--robot needs a fleet's memory (a postgresql:// URI)");
  std::vector<fs::path> inputs;
  if (!fleet) inputs.emplace_back(a.memory);
  if (!a.answers.empty()) inputs.emplace_back(a.answers);
  // The page's folder, checked before any work: not an input, new, empty or an earlier
  // vmap output (the library writes it whole, io/atomic_file.hpp's AtomicDirectory).
  ex::prepare_output_dir(a.out, "--out", inputs);
  try {
    vmap::AtomicDirectory::check(a.out);
  } catch (const vmap::Error& e) {
    ex::usage_error("--out: " + std::string(e.what()));
  }
  vmap::ViewOptions o;
  if (!a.answers.empty()) o.answers = read_answers(a.answers);
  o.image_side = a.image_side;
  o.matches = !a.no_matches;
  o.title = a.title;
  const vmap::ViewResult r = vmap::view_source(a.memory, a.out, o, a.robot);
  if (a.json) {
    ex::print_json({{"memory", ex::current_inputs().front()},
                    {"out", ex::path_string(a.out)},
                    {"index", ex::path_string(r.index)},
                    {"key_images", r.key_images},
                    {"loops", r.loops},
                    {"runs", r.runs},
                    {"images", r.images},
                    {"images_from", r.images_from},
                    {"matched_loops", r.matched_loops},
                    {"answers", r.answers},
                    {"placed", r.placed},
                    {"posed", r.posed},
                    {"bytes", r.bytes},
                    {"seconds", r.seconds}});
    return 0;
  }
  std::printf("%zu key images in %zu %s, %zu loop edges (%zu with their matches drawn), %s map\n", r.key_images, r.runs,
              fleet && a.robot.empty() ? "robots" : "sessions", r.loops, r.matched_loops,
              r.posed ? "a posed" : "a time-line");
  std::printf("images: %s\n", r.images_from.c_str());
  if (r.answers > 0) std::printf("%zu queries, %zu placed on their key images\n", r.answers, r.placed);
  std::printf("wrote %s (%s, %.2f s): open it in a browser\n", r.index.string().c_str(),
              vmap::detail::view_bytes_text(r.bytes).c_str(), r.seconds);
  return 0;
}

std::function<int()> setup(CLI::App& app) {
  auto a = std::make_shared<ViewArgs>();
  app.add_option("memory", a->memory,
                 "Memory store or .vmem file (a folder: DIR/memory.vmdb), a fleet's memory (postgresql://...), or a "
                 "visual map (map.vmap, or the --out folder of vmap build)")
      ->required();
  app.add_option("--out", a->out, "Folder written: index.html with its files beside it (new, empty or an earlier page)")
      ->required();
  app.add_option("--answers", a->answers,
                 "JSON of vmap localize --memory ... --json (or --sequence): each query placed on its key image, or "
                 "why not");
  app.add_option("--robot", a->robot, "With a fleet's memory: show this robot's memory alone (default: every robot)");
  app.add_option("--image-side", a->image_side, "Longest side of the key images on the page, pixels (0: no image)")
      ->check(ex::count_in(0, 16384));
  app.add_flag("--no-matches", a->no_matches, "Do not verify the loops again to draw their matches (faster)");
  app.add_option("--title", a->title, "The page's title (default: the memory's name)");
  app.add_flag("--json", a->json, "Print what was written as JSON");
  return [a]() { return run(*a); };
}

const bool registered = vmap::cli::add_command(
    {"view", "A page that shows a memory (map, key images, loops, answers), opened from the file system in a browser",
     setup});

}  // namespace
