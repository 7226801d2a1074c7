// `vmap`: the command line over the library. Subcommands live in the other files of
// this folder and register themselves (cli.hpp).
#include "vmap/cli.hpp"

#include "common/cli_support.hpp"

#include <vmap/core/error.hpp>
#include <vmap/version.hpp>

#include <opencv2/core.hpp>

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <exception>
#include <functional>
#include <map>
#include <new>
#include <string>
#include <vector>

namespace {

namespace ex = vmap::examples;

constexpr const char* exit_codes_text =
    "Exit codes: 0 ok; 1 bad input or failed run (a file that cannot be read, no frame, ...);\n"
    "2 usage (unknown subcommand or option, bad option value, conflicting options, an output\n"
    "that is an input); 3 an input does not exist; 4 an input is damaged (corrupt); 5 an input\n"
    "of a newer format version; 6 a memory or vocabulary of other policies; 7 the memory is\n"
    "being written by another program; 8 a write failed (a full disk); 9 the memory's database\n"
    "server cannot be reached. Every subcommand takes --config FILE: a YAML file (OpenCV FileStorage)\n"
    "whose keys are the long option names, e.g. \"features: akaze\"; the command line wins.";

/// The subcommand named on the command line: the first argument that is not an option.
std::string subcommand_of(int argc, char** argv) {
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a.empty() || a[0] != '-') return a;
    if (a == "--config") ++i;  // its value
  }
  return {};
}

/// Where the subcommand named on the command line is (subcommand_of), or argc.
int subcommand_at(int argc, char** argv) {
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a.empty() || a[0] != '-') return i;
    if (a == "--config") ++i;
  }
  return argc;
}

/// `vmap memory build ...` is `vmap build ...` (one command builds a memory: `vmap build
/// INPUT --memory M`, documented as such): the arguments with "memory build" made "build".
std::vector<char*> without_memory_build(int argc, char** argv) {
  std::vector<char*> args(argv, argv + argc);
  const int at = subcommand_at(argc, argv);
  if (at + 1 < argc && std::string(argv[at]) == "memory" && std::string(argv[at + 1]) == "build")
    args.erase(args.begin() + at);
  return args;
}

}  // namespace

static int run_vmap(int argc, char** argv) {
  std::string where = "vmap";
  try {
    CLI::App app{"vmap: visual memory for robots (key images, loop closure, localization)", "vmap"};
    app.set_version_flag("--version", std::to_string(vmap::version_major) + "." +
                                          std::to_string(vmap::version_minor) + "." +
                                          std::to_string(vmap::version_patch));
    app.require_subcommand(1);
    app.footer(exit_codes_text);
    // Options a subcommand does not know go to the main program, which owns --config.
    app.fallthrough();
    app.allow_config_extras(CLI::config_extras_mode::error);  // a misspelt key is an error
    auto& cmds = vmap::cli::commands();
    std::sort(cmds.begin(), cmds.end(), [](const auto& a, const auto& b) { return a.name < b.name; });
    std::vector<std::string> names;
    for (const auto& c : cmds) names.push_back(c.name);

    const std::string sub_name = subcommand_of(argc, argv);
    if (!sub_name.empty() && std::find(names.begin(), names.end(), sub_name) == names.end()) {
      const auto near = ex::closest(sub_name, names);
      std::string list;
      for (const auto& n : names) list += (list.empty() ? "" : ", ") + n;
      std::fprintf(stderr, "vmap: unknown subcommand '%s'; %s\n", sub_name.c_str(),
                   near ? ("did you mean '" + *near + "'?").c_str() : ("choose one of: " + list).c_str());
      return ex::exit_usage;
    }
    if (!sub_name.empty()) where = "vmap " + sub_name;
    ex::check_config_argument(argc, argv);
    app.set_config("--config", "", "YAML file (OpenCV FileStorage) of option values; the command line wins");
    app.config_formatter(std::make_shared<ex::YamlConfig>(sub_name, names));

    std::map<const CLI::App*, std::function<int()>> runners;
    for (const auto& c : cmds) {
      CLI::App* sub = app.add_subcommand(c.name, c.description);
      sub->option_defaults()->always_capture_default();
      sub->footer(exit_codes_text);
      runners[sub] = c.setup(*sub);
    }
    if (!sub_name.empty()) {
      // A subcommand of a subcommand (vmap memory info) misspelt: named with the nearest.
      const CLI::App* sub = app.get_subcommand(sub_name);
      const int at = subcommand_at(argc, argv);
      std::vector<std::string> inner;
      for (const CLI::App* c : sub->get_subcommands([](const CLI::App*) { return true; })) inner.push_back(c->get_name());
      if (!inner.empty() && sub->get_require_subcommand_min() > 0 && at + 1 < argc && argv[at + 1][0] != '-' &&
          std::find(inner.begin(), inner.end(), std::string(argv[at + 1])) == inner.end()) {
        const auto near = ex::closest(argv[at + 1], inner);
        std::string list;
        for (const auto& n : inner) list += (list.empty() ? "" : ", ") + n;
        std::fprintf(stderr, "%s: unknown subcommand '%s'; %s\n", where.c_str(), argv[at + 1],
                     near ? ("did you mean '" + sub_name + " " + *near + "'?").c_str() : ("choose one of: " + list).c_str());
        return ex::exit_usage;
      }
      ex::check_option_names(app, *sub, argc, argv);
    }
    try {
      app.parse(argc, argv);
    } catch (const CLI::CallForHelp& e) {
      return app.exit(e);
    } catch (const CLI::CallForAllHelp& e) {
      return app.exit(e);
    } catch (const CLI::CallForVersion& e) {
      return app.exit(e);
    } catch (const CLI::ParseError& e) {
      std::string what = e.what();
      const std::string extras = "INI was not able to parse ";
      if (what.rfind(extras, 0) == 0) {  // CLI11's words for a config key that is no option
        std::string key = what.substr(extras.size());
        if (key.rfind(sub_name + ".", 0) == 0) key = key.substr(sub_name.size() + 1);
        what = "--config: '" + key + "' is not an option of " + where;
      }
      std::fprintf(stderr, "%s: usage error: %s\n(see %s --help)\n", where.c_str(), what.c_str(), where.c_str());
      return ex::exit_usage;
    }
    for (const auto& [sub, run] : runners)
      if (sub->parsed()) {
        ex::check_no_empty_values(*sub);
        return run();
      }
    return ex::exit_usage;
  } catch (const ex::UsageError& e) {
    std::fprintf(stderr, "%s: usage error: %s\n", where.c_str(), e.what());
    return ex::exit_usage;
  } catch (const CLI::ParseError& e) {  // option values read again after parsing
    std::fprintf(stderr, "%s: usage error: %s\n", where.c_str(), e.what());
    return ex::exit_usage;
  } catch (const vmap::Error& e) {
    std::fprintf(stderr, "%s: error: %s\n", where.c_str(), ex::one_line(e.what()).c_str());
    return ex::exit_code_of(e.kind());
  } catch (const cv::Exception& e) {
    std::fprintf(stderr, "%s: OpenCV error: %s (in %s)%s\n", where.c_str(), ex::one_line(e.err).c_str(),
                 e.func.c_str(), ex::input_note().c_str());
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr, "%s: error: out of memory (an input or an option asks for too much)%s\n", where.c_str(),
                 ex::input_note().c_str());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s: error: %s%s\n", where.c_str(), ex::one_line(e.what()).c_str(), ex::input_note().c_str());
  } catch (...) {
    std::fprintf(stderr, "%s: error: unknown exception%s\n", where.c_str(), ex::input_note().c_str());
  }
  return ex::exit_failure;
}

int main(int argc, char** argv) {
  std::vector<char*> args = without_memory_build(argc, argv);
  const int code = run_vmap(static_cast<int>(args.size()), args.data());
  if (code != ex::exit_ok) ex::remove_unused_output_folders();
  return code;
}
