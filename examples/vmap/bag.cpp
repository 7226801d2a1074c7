// `vmap bag info BAG`: what a robot bag holds (vmap::bag_info): its container, topics
// with their types and message counts, the time range of its messages, and the image
// topics a frame source can read (with --topic) and the calibration beside each.
#include "vmap/cli.hpp"

#include "common/bag_options.hpp"
#include "common/cli_support.hpp"

#include <vmap/io/bag/bag.hpp>
#include <vmap/io/timestamps.hpp>

#include <nlohmann/json.hpp>

#include <cstdio>
#include <functional>
#include <memory>
#include <string>

namespace {

namespace ex = vmap::examples;

struct BagArgs {
  std::string bag;
  bool json = false;
};

/// "1305031229.528748000".
std::string seconds_text(std::int64_t ns) {
  char buf[48];
  const bool negative = ns < 0;
  const auto u = negative ? static_cast<std::uint64_t>(-(ns + 1)) + 1 : static_cast<std::uint64_t>(ns);
  std::snprintf(buf, sizeof buf, "%s%llu.%09llu", negative ? "-" : "", static_cast<unsigned long long>(u / 1000000000ULL),
                static_cast<unsigned long long>(u % 1000000000ULL));
  return buf;
}

int info(const BagArgs& a) {
  ex::current_inputs() = {a.bag};
  const vmap::BagInfo info = vmap::bag_info(a.bag);
  // The calibration beside each image topic, as `build` would take it without --camera.
  std::vector<std::string> cameras(info.topics.size());
  for (std::size_t k = 0; k < info.topics.size(); ++k)
    if (vmap::detail::is_image_type(info.topics[k].type)) {
      std::string note;
      const auto c = vmap::detail::read_bag_camera(a.bag, info.topics,
                                                   vmap::detail::camera_info_topic_for(info.topics[k].name), {}, note);
      cameras[k] = c ? c->topic + " (" + c->camera.describe() + ")" : note;
    }
  if (a.json) {
    nlohmann::json topics = nlohmann::json::array();
    for (std::size_t k = 0; k < info.topics.size(); ++k) {
      const auto& t = info.topics[k];
      nlohmann::json j{{"name", t.name}, {"type", t.type}, {"encoding", t.encoding}, {"messages", t.messages},
                       {"image", vmap::detail::is_image_type(t.type)}};
      if (!cameras[k].empty()) j["camera"] = cameras[k];
      topics.push_back(std::move(j));
    }
    ex::print_json(nlohmann::json{{"input", ex::path_string(a.bag)},
                    {"format", std::string(vmap::to_string(info.format))},
                    {"messages", info.messages},
                    {"start_ns", info.start_ns},
                    {"end_ns", info.end_ns},
                    {"seconds", static_cast<double>(info.end_ns - info.start_ns) * 1e-9},
                    {"indexed", info.indexed},
                    {"topics", topics},
                    {"warnings", info.warnings}});
    return ex::exit_ok;
  }
  std::printf("bag:      %s\n", a.bag.c_str());
  std::printf("format:   %s%s\n", std::string(vmap::to_string(info.format)).c_str(),
              info.indexed ? "" : " (no index: read through to list it)");
  std::printf("messages: %llu\n", static_cast<unsigned long long>(info.messages));
  if (info.messages > 0)
    std::printf("time:     %s .. %s s (%.3f s, record times)\n", seconds_text(info.start_ns).c_str(),
                seconds_text(info.end_ns).c_str(), static_cast<double>(info.end_ns - info.start_ns) * 1e-9);
  std::printf("topics:   %zu\n", info.topics.size());
  for (std::size_t k = 0; k < info.topics.size(); ++k) {
    const auto& t = info.topics[k];
    std::printf("  %-40s %-36s %8llu%s\n", t.name.c_str(), t.type.c_str(), static_cast<unsigned long long>(t.messages),
                vmap::detail::is_image_type(t.type) ? "  (images)" : "");
    if (!cameras[k].empty()) std::printf("  %-40s calibration: %s\n", "", cameras[k].c_str());
  }
  for (const auto& w : info.warnings) std::printf("warning: %s\n", w.c_str());
  return ex::exit_ok;
}

std::function<int()> setup(CLI::App& app) {
  auto a = std::make_shared<BagArgs>();
  app.require_subcommand(1);
  auto* i = app.add_subcommand("info", "Topics (types, message counts) and time range of a bag (.bag, .db3, .mcap, rosbag2 folder)");
  i->add_option("bag", a->bag, "The bag: a ROS 1 .bag, a rosbag2 .db3 or its folder, an .mcap")->required();
  i->add_flag("--json", a->json, "Print one JSON object on stdout");
  return [a]() { return info(*a); };
}

[[maybe_unused]] const bool registered =
    vmap::cli::add_command({"bag", "Robot bags (ROS 1, rosbag2 sqlite3, MCAP): what they hold", setup});

}  // namespace
