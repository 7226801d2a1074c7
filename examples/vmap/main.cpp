// `vmap`: the command line over the library. Subcommands live in the other files of
// this folder and register themselves (cli.hpp).
#include "vmap/cli.hpp"

#include <vmap/core/error.hpp>
#include <vmap/version.hpp>

#include <opencv2/core.hpp>

#include <algorithm>
#include <cstdio>
#include <exception>
#include <functional>
#include <map>
#include <string>

int main(int argc, char** argv) {
  CLI::App app{"vmap: visual memory for robots (key images, loop closure, localization)", "vmap"};
  app.set_version_flag("--version", std::to_string(vmap::version_major) + "." + std::to_string(vmap::version_minor) +
                                        "." + std::to_string(vmap::version_patch));
  app.require_subcommand(1);
  auto& cmds = vmap::cli::commands();
  std::sort(cmds.begin(), cmds.end(), [](const auto& a, const auto& b) { return a.name < b.name; });
  std::map<const CLI::App*, std::function<int()>> runners;
  for (const auto& c : cmds) {
    CLI::App* sub = app.add_subcommand(c.name, c.description);
    runners[sub] = c.setup(*sub);
  }
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  try {
    for (const auto& [sub, run] : runners)
      if (sub->parsed()) return run();
  } catch (const vmap::Error& e) {
    std::fprintf(stderr, "vmap: error: %s\n", e.what());
    return 1;
  } catch (const cv::Exception& e) {
    std::fprintf(stderr, "vmap: OpenCV error: %s\n", e.what());
    return 1;
  }
  return 1;
}
