#pragma once

// Subcommand registry of the `vmap` program. Each examples/vmap/<name>.cpp defines one
// subcommand and registers it at static-initialisation time, so adding a subcommand
// touches no other file:
//
//   static const bool registered = vmap::cli::add_command({"build", "Build a visual map", setup});
//
// `setup` adds the subcommand's options to the CLI11 app it is given and returns the
// function that runs it (after parsing) and returns the process exit code.

#include <CLI/CLI.hpp>

#include <functional>
#include <string>
#include <vector>

namespace vmap::cli {

struct Command {
  std::string name;
  std::string description;
  std::function<std::function<int()>(CLI::App&)> setup;
};

inline std::vector<Command>& commands() {
  static std::vector<Command> all;
  return all;
}

inline bool add_command(Command c) {
  commands().push_back(std::move(c));
  return true;
}

}  // namespace vmap::cli
