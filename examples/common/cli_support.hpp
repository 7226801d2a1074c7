#pragma once

// What every `vmap` subcommand shares so that they behave as one tool: exit codes, usage
// errors, validators that name the option, the YAML `--config` reader, the `options`
// echo and the JSON writer, output paths checked before the work starts, the progress
// meter, and the `--camera` hook.

#include <vmap/core/error.hpp>
#include <vmap/io/atomic_file.hpp>
#include <vmap/io/calibration.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/io/image.hpp>
#include <vmap/io/postgres.hpp>
#include <vmap/io/yaml_limits.hpp>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <system_error>
#include <utility>
#include <vector>

namespace vmap::examples {

/// Exit codes of `vmap` (documented in `vmap --help` and the README).
inline constexpr int exit_ok = 0;       ///< the command ran
inline constexpr int exit_failure = 1;  ///< bad input (a file, an image) or a failed run
inline constexpr int exit_usage = 2;    ///< bad command line: unknown subcommand or option, bad value, conflict
/// A failure a script can act on, by the vmap::Error's kind (vmap::ErrorKind); any other
/// failure (a bad input value, an OpenCV error, no frame) is exit_failure.
inline constexpr int exit_not_found = 3;            ///< an input file or folder does not exist
inline constexpr int exit_corrupt = 4;              ///< an input file is damaged or not of its format
inline constexpr int exit_unsupported_version = 5;  ///< an input of a newer format than this build reads
inline constexpr int exit_policy_mismatch = 6;      ///< a memory or vocabulary of other policies
inline constexpr int exit_busy = 7;                 ///< the memory is being written by another program
inline constexpr int exit_io = 8;                   ///< a write failed (a full disk, permissions)
inline constexpr int exit_unavailable = 9;          ///< the memory's database server cannot be reached

/// The exit code of a run that stopped on a vmap::Error of kind `k`.
[[nodiscard]] constexpr int exit_code_of(vmap::ErrorKind k) noexcept {
  switch (k) {
    case vmap::ErrorKind::not_found: return exit_not_found;
    case vmap::ErrorKind::corrupt: return exit_corrupt;
    case vmap::ErrorKind::unsupported_version: return exit_unsupported_version;
    case vmap::ErrorKind::policy_mismatch: return exit_policy_mismatch;
    case vmap::ErrorKind::busy: return exit_busy;
    case vmap::ErrorKind::io: return exit_io;
    case vmap::ErrorKind::unavailable: return exit_unavailable;
    case vmap::ErrorKind::invalid_argument: break;
  }
  return exit_failure;
}

/// A command-line mistake found after parsing (conflicting options, an output that is
/// an input): exit code 2, like CLI11's own parse errors. A vmap::Error, so that code
/// which reports the library's errors (the Python module) reports these too.
class UsageError : public vmap::Error {
 public:
  using vmap::Error::Error;
};

[[noreturn]] inline void usage_error(const std::string& what) { throw UsageError(what); }

/// The inputs of the running subcommand, so that an error from deep inside OpenCV or the
/// standard library is still reported with the input it came from.
inline std::vector<std::string>& current_inputs() {
  static std::vector<std::string> inputs;
  return inputs;
}

/// " (input: a, b)" or "" (a fleet's URI without its password).
inline std::string input_note() {
  std::string s;
  for (const auto& i : current_inputs())
    if (!i.empty()) s += (s.empty() ? " (input: " : ", ") + (vmap::pg::is_uri(i) ? vmap::pg::redacted(i) : i);
  return s.empty() ? s : s + ")";
}

/// Messages on one line: newlines of OpenCV's or the library's messages become spaces.
inline std::string one_line(std::string s) {
  std::replace(s.begin(), s.end(), '\n', ' ');
  while (!s.empty() && s.back() == ' ') s.pop_back();
  return s;
}

// ---------------------------------------------------------------------------------------
// Validators: each message is printed by CLI11 as "--option: message".

namespace cli_detail {

inline bool all_digits(const std::string& s) {
  return !s.empty() && std::all_of(s.begin(), s.end(), [](unsigned char c) { return c >= '0' && c <= '9'; });
}

}  // namespace cli_detail

/// A whole number in [lo, hi] written in decimal digits: "-1" is refused as "must be >= lo"
/// instead of wrapping around to 18446744073709551615, and values above hi are refused
/// before any conversion.
inline CLI::Validator count_in(unsigned long long lo, unsigned long long hi) {
  return CLI::Validator(
      [lo, hi](std::string& s) -> std::string {
        std::string t = s;
        if (!t.empty() && t.front() == '+') t.erase(0, 1);
        if (!t.empty() && t.front() == '-') return "must be >= " + std::to_string(lo) + ", got '" + s + "'";
        if (!cli_detail::all_digits(t)) return "must be a whole number, got '" + s + "'";
        const std::string digits = t.substr(std::min(t.find_first_not_of('0'), t.size() - 1));
        const std::string max = std::to_string(hi);
        if (digits.size() > max.size() || (digits.size() == max.size() && digits > max))
          return "must be <= " + max + ", got '" + s + "'";
        const unsigned long long v = std::stoull(digits);
        if (v < lo) return "must be >= " + std::to_string(lo) + ", got '" + s + "'";
        s = digits;
        return {};
      },
      "INT in [" + std::to_string(lo) + ", " + std::to_string(hi) + "]");
}

/// A finite real number in [lo, hi] (nan and inf refused with the option's name).
inline CLI::Validator real_in(double lo, double hi, bool open_low = false) {
  char desc[96];
  std::snprintf(desc, sizeof desc, "REAL in %s%g, %g]", open_low ? "(" : "[", lo, hi);
  return CLI::Validator(
      [lo, hi, open_low](std::string& s) -> std::string {
        char* end = nullptr;
        const double v = std::strtod(s.c_str(), &end);
        if (s.empty() || end != s.c_str() + s.size()) return "must be a number, got '" + s + "'";
        if (!std::isfinite(v)) return "must be a finite number, got '" + s + "'";
        char buf[128];
        if (v < lo || (open_low && v == lo) || v > hi) {
          std::snprintf(buf, sizeof buf, "must be in %s%g, %g], got '%s'", open_low ? "(" : "[", lo, hi, s.c_str());
          return buf;
        }
        return {};
      },
      desc);
}

/// --time-offset SECONDS: added to every frame time (FrameSourceOptions::time_offset)
/// before frames are matched to poses by time; a video's times start at 0.
inline void add_time_offset_option(CLI::App& app, double& seconds) {
  app.add_option("--time-offset", seconds,
                 "Seconds added to every frame time before frames are matched to poses by time (a video starts at 0)")
      ->check(real_in(-1e12, 1e12));
}

/// The largest keypoint budget accepted by --nfeatures (documented in the README): more
/// than any image gives, small enough that the per-image buffers stay bounded.
inline constexpr unsigned long long max_nfeatures = 100000;
/// Bounds of frame indices and strides (--start, --end, --stride).
inline constexpr unsigned long long max_frame_index = 1000000000ULL;

// ---------------------------------------------------------------------------------------
// Closest subcommand for "unknown subcommand 'bild'; did you mean 'build'?".

inline std::size_t edit_distance(const std::string& a, const std::string& b) {
  std::vector<std::size_t> row(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    std::size_t diag = row[0];
    row[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j) {
      const std::size_t up = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, diag + (a[i - 1] == b[j - 1] ? 0 : 1)});
      diag = up;
    }
  }
  return row[b.size()];
}

/// The candidate nearest to `word` within an edit distance of 3 (or one it starts), if any.
inline std::optional<std::string> closest(const std::string& word, const std::vector<std::string>& candidates) {
  std::optional<std::string> best;
  std::size_t best_d = 4;
  for (const auto& c : candidates) {
    const std::size_t d = c.rfind(word, 0) == 0 && !word.empty() ? 1 : edit_distance(word, c);
    if (d < best_d) best_d = d, best = c;
  }
  return best;
}

// ---------------------------------------------------------------------------------------
// "--name" arguments checked before CLI11 parses them, so that a misspelt option gets
// "unknown option '--treshold'; did you mean '--threshold'?" and an option of another
// subcommand says which subcommands take it (CLI11 would say "The following arguments
// were not expected" and list them in reverse).

namespace cli_detail {

/// Long option names of `app` and of its nested subcommands (`vmap memory build`).
inline void long_names(const CLI::App& app, std::vector<std::string>& out) {
  for (const CLI::Option* o : app.get_options())
    for (const auto& n : o->get_lnames()) out.push_back(n);
  for (const CLI::App* sub : app.get_subcommands([](const CLI::App*) { return true; })) long_names(*sub, out);
}

}  // namespace cli_detail

/// Fails (usage error) on the first "--name" of argv[1..argc) that is neither an option of
/// `sub` nor of the main program `main` ("--" ends the options).
inline void check_option_names(const CLI::App& main, const CLI::App& sub, int argc, char** argv) {
  std::vector<std::string> known;
  cli_detail::long_names(sub, known);
  for (const CLI::Option* o : main.get_options())
    for (const auto& n : o->get_lnames()) known.push_back(n);
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--") break;
    if (a.size() <= 2 || a.rfind("--", 0) != 0) continue;
    const std::string name = a.substr(2, a.find('=') == std::string::npos ? std::string::npos : a.find('=') - 2);
    if (std::find(known.begin(), known.end(), name) != known.end()) continue;
    std::string owners;
    for (const CLI::App* other : main.get_subcommands([](const CLI::App*) { return true; })) {
      std::vector<std::string> theirs;
      cli_detail::long_names(*other, theirs);
      if (std::find(theirs.begin(), theirs.end(), name) != theirs.end())
        owners += (owners.empty() ? "" : ", ") + other->get_name();
    }
    const std::string where = "vmap " + sub.get_name();
    if (!owners.empty())
      usage_error("option '--" + name + "' is not an option of '" + where + "'; it belongs to: " + owners);
    if (const auto near = closest(name, known))
      usage_error("unknown option '--" + name + "'; did you mean '--" + *near + "'?");
    usage_error("unknown option '--" + name + "' (see " + where + " --help)");
  }
}

// ---------------------------------------------------------------------------------------
// --config FILE: a YAML cv::FileStorage file whose keys are the long option names
// ("features: akaze", "nfeatures: 500", "taus: [0.2, 0.3]", "json: 1", "input: rgb.txt").
// Keys may be at the top level or under a section named after the subcommand; "-" and
// "_" are interchangeable in keys. Values given on the command line win (CLI11 applies a
// config value only to an option that was not given).

class YamlConfig : public CLI::Config {
 public:
  /// `subcommands`: every subcommand's name, the only keys whose value may be a map
  /// (that subcommand's section); a map under any other key is an error, not ignored.
  explicit YamlConfig(std::string subcommand, std::vector<std::string> subcommands = {})
      : subcommand_(std::move(subcommand)), subcommands_(std::move(subcommands)) {}

  std::string to_config(const CLI::App*, bool, bool, std::string) const override { return {}; }

  std::vector<CLI::ConfigItem> from_config(std::istream& in) const override {
    std::string text(max_yaml_bytes + 1, '\0');
    in.read(text.data(), static_cast<std::streamsize>(text.size()));
    text.resize(static_cast<std::size_t>(in.gcount()));
    cv::FileStorage fs;
    try {
      fs = vmap::detail::open_yaml_text(text, "--config");  // bounded, PyYAML's lists indented
    } catch (const vmap::Error& e) {
      throw CLI::ConfigError(e.what());
    }
    cv::FileNode root = fs.root();  // a map: open_yaml_text checks it
    const cv::FileNode section = root[subcommand_];
    std::vector<CLI::ConfigItem> found;
    auto add = [&](const cv::FileNode& map, bool top) {
      for (const auto& node : map) {
        if (node.isMap()) {
          if (top && std::find(subcommands_.begin(), subcommands_.end(), node.name()) != subcommands_.end())
            continue;  // a subcommand's section
          throw CLI::ConfigError("--config: the value of '" + node.name() +
                                 "' is a map; an option takes a number, a string or a list of them" +
                                 (top ? " (a map is allowed only as a section named after a subcommand)" : ""));
        }
        CLI::ConfigItem item;
        if (!subcommand_.empty()) item.parents = {subcommand_};
        item.name = node.name();
        std::replace(item.name.begin(), item.name.end(), '_', '-');
        if (node.isSeq()) {
          for (const auto& v : node) item.inputs.push_back(scalar(v, item.name));
        } else {
          item.inputs.push_back(scalar(node, item.name));
        }
        found.push_back(std::move(item));
      }
    };
    add(root, true);
    if (section.isMap()) add(section, false);
    return found;
  }

 private:
  static std::string scalar(const cv::FileNode& n, const std::string& key) {
    if (n.isInt()) return std::to_string(static_cast<int>(n));
    if (n.isReal()) {
      char buf[40];
      std::snprintf(buf, sizeof buf, "%.17g", static_cast<double>(n));
      return buf;
    }
    if (n.isString()) return static_cast<std::string>(n);
    throw CLI::ConfigError("--config: the value of '" + key + "' must be a number, a string or a list of them");
  }
  std::string subcommand_;
  std::vector<std::string> subcommands_;
};

/// The --config FILE of the command line (CLI11 reads it later, with no limit): it must
/// be a regular file of at most `max_yaml_bytes`, so /dev/zero or a FIFO is refused
/// before anything is read. An empty name is a usage error.
inline void check_config_argument(int argc, char** argv) {
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    std::optional<std::string> file;
    if (a == "--config" && i + 1 < argc) file = argv[++i];
    else if (a.rfind("--config=", 0) == 0) file = a.substr(9);
    if (!file) continue;
    if (file->empty()) usage_error("--config: the file name is empty");
    struct stat st {};
    if (::stat(file->c_str(), &st) != 0)
      usage_error("--config: '" + *file + "' does not exist");
    if (S_ISDIR(st.st_mode)) usage_error("--config: '" + *file + "' is a folder, not a file");
    if (!S_ISREG(st.st_mode))
      usage_error("--config: '" + *file + "' is not a regular file (a device, FIFO or socket cannot be read as one)");
    if (static_cast<std::uintmax_t>(st.st_size) > max_yaml_bytes)
      usage_error("--config: '" + *file + "' is " + std::to_string(st.st_size) + " bytes, more than the " +
                  std::to_string(max_yaml_bytes) + " a settings file may have");
  }
}

/// Refuses an empty value ("", from the command line or --config) of any option or
/// positional input of `app`: an empty path would otherwise mean "no file" silently
/// (`--memory ""` running with no memory).
inline void check_no_empty_values(const CLI::App& app) {
  for (const CLI::Option* opt : app.get_options()) {
    if (opt->get_expected_max() == 0) continue;  // a flag
    for (const auto& v : opt->results())
      if (v.empty()) {
        const std::string name = opt->get_lnames().empty() ? opt->get_name() : "--" + opt->get_lnames().front();
        usage_error(name + ": the value is empty");
      }
  }
}

// ---------------------------------------------------------------------------------------
// JSON.

/// A file name for JSON: valid UTF-8 stays as it is; other bytes become U+FFFD when the
/// object is dumped (see dump_json), so a Latin-1 name never aborts --json. A fleet's
/// URI is shown without its password (pg::redacted: every URI the command line shows
/// goes through it).
inline std::string path_string(const std::filesystem::path& p) {
  return vmap::pg::is_uri(p.native()) ? vmap::pg::redacted(p.native()) : p.string();
}

/// One JSON document on stdout; invalid UTF-8 in strings is replaced, not an exception.
inline void print_json(const nlohmann::json& j) {
  const std::string s = j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace);
  std::printf("%s\n", s.c_str());
  std::fflush(stdout);
}

namespace cli_detail {

inline nlohmann::json typed_value(const std::string& s) {
  if (vmap::pg::is_uri(s)) return vmap::pg::redacted(s);  // a fleet's URI, never with its password
  if (s == "true") return true;
  if (s == "false") return false;
  if (!s.empty()) {
    char* end = nullptr;
    const double v = std::strtod(s.c_str(), &end);
    if (end == s.c_str() + s.size() && std::isfinite(v) &&
        s.find_first_not_of("0123456789+-.eE") == std::string::npos) {
      if (s.find_first_of(".eE") == std::string::npos && std::abs(v) < 9e15) return static_cast<long long>(v);
      return v;
    }
  }
  return s;
}

}  // namespace cli_detail

/// Every option of a subcommand with its value (given on the command line, in --config,
/// or the default), keyed by its long name with "_" for "-": the JSON's `options`.
/// Positional inputs, --help, --config and --json itself are not options of the run, and
/// an old spelling (a hidden option) is not one apart from the option it names.
inline nlohmann::json options_json(const CLI::App& app) {
  nlohmann::json out = nlohmann::json::object();
  for (const CLI::Option* opt : app.get_options()) {
    if (opt->get_lnames().empty()) continue;  // positional
    const std::string name = opt->get_lnames().front();
    if (name == "help" || name == "config" || name == "json") continue;
    if (opt->get_group().empty()) continue;  // a hidden old spelling: its value is under the new name
    std::string key = name;
    std::replace(key.begin(), key.end(), '-', '_');
    if (opt->get_expected_max() == 0) {  // a flag
      out[key] = opt->count() > 0 && opt->as<bool>();
      continue;
    }
    std::vector<std::string> values = opt->results();
    if (values.empty()) {
      const std::string d = opt->get_default_str();
      if (d.empty()) {
        out[key] = nullptr;
        continue;
      }
      // Vector defaults print as "[0.1,0.2]".
      std::string inner = d;
      if (inner.size() >= 2 && inner.front() == '[' && inner.back() == ']') inner = inner.substr(1, inner.size() - 2);
      values.clear();
      std::stringstream ss(inner);
      std::string v;
      const bool list = opt->get_expected_max() > 1;
      if (list)
        while (std::getline(ss, v, ',')) values.push_back(v);
      else
        values.push_back(d);
    }
    if (opt->get_expected_max() > 1) {
      nlohmann::json arr = nlohmann::json::array();
      for (const auto& v : values) arr.push_back(cli_detail::typed_value(v));
      out[key] = arr;
    } else {
      out[key] = cli_detail::typed_value(values.back());
    }
  }
  return out;
}

// ---------------------------------------------------------------------------------------
// Inputs and outputs, checked before any work starts.

namespace cli_detail {

inline std::filesystem::path resolved(const std::filesystem::path& p) {
  std::error_code ec;
  auto r = std::filesystem::weakly_canonical(p, ec);
  if (ec) r = std::filesystem::absolute(p, ec).lexically_normal();
  return r;
}

/// a == b or a lies inside folder b.
inline bool inside(const std::filesystem::path& a, const std::filesystem::path& b) {
  auto ia = a.begin();
  for (auto ib = b.begin(); ib != b.end(); ++ib, ++ia) {
    if (ib->empty()) continue;  // trailing "/"
    if (ia == a.end() || *ia != *ib) return false;
  }
  return true;
}

/// Folders created for outputs by this process, deepest first: removed again when they
/// are still empty after a refused or failed run (remove_unused_output_folders).
inline std::vector<std::filesystem::path>& created_folders() {
  static std::vector<std::filesystem::path> folders;
  return folders;
}

/// The folder an input's frames live in when it is a folder, else nothing.
inline bool is_folder(const std::filesystem::path& p) {
  std::error_code ec;
  return std::filesystem::is_directory(p, ec);
}

}  // namespace cli_detail

/// Refuses (a usage error) an output file that is one of the inputs, after resolving
/// symbolic links and "..".
inline void refuse_input_as_output(const std::filesystem::path& out, const std::string& option,
                                   const std::vector<std::filesystem::path>& inputs) {
  const std::filesystem::path r = cli_detail::resolved(out);
  for (const auto& in : inputs)
    if (!in.empty() && cli_detail::resolved(in) == r)
      usage_error(option + ": '" + out.string() + "' is also an input; refusing to overwrite it");
}

/// Refuses an output file that is one of the inputs (refuse_input_as_output) or a
/// symbolic link (outputs are replaced by rename, which would replace the link itself,
/// not write through it: give the link's target instead), or an existing folder.
inline void check_output_file(const std::filesystem::path& out, const std::string& option,
                              const std::vector<std::filesystem::path>& inputs) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (fs::is_symlink(out, ec))
    usage_error(option + ": '" + out.string() +
                "' is a symbolic link; vmap replaces output files by rename and does not write through links "
                "(give the link's target)");
  refuse_input_as_output(out, option, inputs);
  if (fs::is_directory(out, ec)) usage_error(option + ": '" + out.string() + "' is a folder, not a file");
}

/// Prepares the --out folder: refuses a folder that is an input or inside an input folder
/// (so `build DIR --out DIR` cannot add its pictures to the frames it reads), an existing
/// non-folder, and an unwritable folder; creates it when missing. A symbolic link to a
/// folder is followed (the files are written inside the target folder); each of `files`
/// (the names the command will write there) must pass check_output_file. Returns the path.
inline std::filesystem::path prepare_output_dir(const std::filesystem::path& dir, const std::string& option,
                                                const std::vector<std::filesystem::path>& inputs,
                                                const std::vector<std::string>& files = {}) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::path r = cli_detail::resolved(dir);
  for (const auto& in : inputs) {
    if (in.empty()) continue;
    const fs::path ri = cli_detail::resolved(in);
    if (ri == r) usage_error(option + ": '" + dir.string() + "' is also an input; refusing to write into it");
    if (cli_detail::is_folder(in) && cli_detail::inside(r, ri))
      usage_error(option + ": '" + dir.string() + "' is inside the input folder '" + in.string() +
                  "'; its files would become frames of the next run (give another folder)");
  }
  if (fs::exists(dir, ec) && !fs::is_directory(dir, ec))
    usage_error(option + ": '" + dir.string() + "' exists and is not a folder");
  if (!fs::exists(dir, ec)) {
    std::vector<fs::path> missing;  // dir and its missing parents, deepest first
    for (fs::path p = fs::absolute(dir, ec).lexically_normal(); !p.empty() && !fs::exists(p, ec); p = p.parent_path()) {
      if (p.filename().empty()) continue;  // "out/" names the same folder as "out"
      missing.push_back(p);
      if (p == p.parent_path()) break;
    }
    fs::create_directories(dir, ec);
    if (ec)
      vmap::detail::fail(vmap::ErrorKind::io, option + ": cannot create the folder '" + dir.string() + "': " + ec.message());
    auto& created = cli_detail::created_folders();
    created.insert(created.begin(), missing.begin(), missing.end());
  }
  for (const auto& f : files) check_output_file(dir / f, option, inputs);
  // Writable: create and remove a file, as the atomic writes will.
  std::string probe = (dir / ".vmap-write-test-XXXXXX").string();
  const int fd = ::mkstemp(probe.data());
  if (fd < 0)
    vmap::detail::fail(vmap::ErrorKind::io, option + ": cannot write into the folder '" + dir.string() + "': " +
                       std::error_code(errno, std::generic_category()).message());
  ::close(fd);
  ::unlink(probe.c_str());
  return dir;
}

/// After a refused or failed run: removes the output folders this process created that
/// are still empty (rmdir removes nothing else), so no empty folder is left behind.
inline void remove_unused_output_folders() noexcept {
  for (const auto& d : cli_detail::created_folders()) (void)::rmdir(d.c_str());
  cli_detail::created_folders().clear();
}

/// The --out folder of a command that writes several files (build, loops, detect): the
/// files are written into a temporary folder that replaces DIR in one step when the
/// command succeeds (vmap::AtomicDirectory), so after a crash or kill -9 a reader sees
/// the whole old set or the whole new set, never a mix. Checked before the work starts;
/// an existing folder is replaced only when it is empty or an earlier vmap output.
class OutputFolder {
 public:
  OutputFolder(const std::filesystem::path& dir, const std::string& option,
               const std::vector<std::filesystem::path>& inputs, const std::vector<std::string>& files)
      : dir_(dir) {
    prepare_output_dir(dir, option, inputs, files);
    try {
      vmap::AtomicDirectory::check(dir);
    } catch (const vmap::Error& e) {
      usage_error(option + ": " + e.what());
    }
    set_.emplace(dir);  // a failure here (a full disk) is the run's, not the options'
  }
  /// Where to write the file `name` of the set until commit().
  [[nodiscard]] std::filesystem::path operator/(const std::string& name) const { return set_->path() / name; }
  [[nodiscard]] const std::filesystem::path& dir() const noexcept { return dir_; }
  /// The temporary folder the set is written into until commit().
  [[nodiscard]] const std::filesystem::path& path() const noexcept { return set_->path(); }
  void commit() { set_->commit(); }

 private:
  std::filesystem::path dir_;
  std::optional<vmap::AtomicDirectory> set_;
};

/// An input file that must exist and be a readable regular file (not a folder or device).
inline void check_input_file(const std::filesystem::path& p, const std::string& option) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const auto st = fs::status(p, ec);
  if (ec || !fs::exists(st)) usage_error(option + ": '" + p.string() + "' does not exist");
  if (fs::is_directory(st)) usage_error(option + ": '" + p.string() + "' is a folder, not a file");
  if (!fs::is_regular_file(st)) usage_error(option + ": '" + p.string() + "' is not a regular file");
  // Asked without opening it: a descriptor closed here would drop the locks of a
  // memory store this process reads (io/database_files.hpp).
  if (::faccessat(AT_FDCWD, p.c_str(), R_OK, AT_EACCESS) != 0)
    vmap::detail::fail(option + ": '" + p.string() + "' cannot be read (permission?)");
}

/// Frame-source options that report each skipped (unreadable) frame on stderr; the count
/// is in the summary and the JSON (FrameSource::skipped()).
inline vmap::FrameSourceOptions reporting_skips(vmap::FrameSourceOptions o = {}) {
  o.on_skip = [](const vmap::SkippedFrame& s) {
    std::fprintf(stderr, "vmap: skipping frame %zu (%s): %s\n", s.index, s.name.c_str(), s.reason.c_str());
  };
  return o;
}

/// The --camera option: the calibration file read by vmap::read_camera (ORB-SLAM /
/// TUM YAML, ROS camera_info, KITTI calib.txt), after the checks every input file gets.
struct CameraOption {
  std::filesystem::path file;
  vmap::Camera camera;
};

inline std::optional<CameraOption> load_camera_option(const std::string& path) {
  if (path.empty()) return std::nullopt;
  check_input_file(path, "--camera");
  return CameraOption{path, vmap::read_camera(path)};
}

// ---------------------------------------------------------------------------------------
// Progress on stderr: "build  120/723 frames  25.1 fps  ETA 24 s", rewritten in place when
// stderr is a terminal; otherwise one summary line at the end for runs over a second.

class Progress {
 public:
  Progress(std::string label, std::optional<std::size_t> total, std::string unit = "frames")
      : label_(std::move(label)), unit_(std::move(unit)), total_(total), tty_(isatty(STDERR_FILENO) != 0),
        t0_(clock::now()), last_(t0_) {}
  Progress(const Progress&) = delete;
  Progress& operator=(const Progress&) = delete;

  /// `done` items so far; `extra` is appended ("19 key images").
  void update(std::size_t done, const std::string& extra = {}) {
    done_ = done;
    if (!tty_) return;
    const auto now = clock::now();
    if (now - last_ < std::chrono::milliseconds(200) && !(total_ && done == *total_)) return;
    last_ = now;
    const double s = seconds();
    const double rate = s > 0 ? static_cast<double>(done) / s : 0.0;
    char line[256];
    if (total_ && *total_ > 0) {
      const double eta = rate > 0 ? static_cast<double>(*total_ - std::min(done, *total_)) / rate : 0.0;
      std::snprintf(line, sizeof line, "\r%s  %zu/%zu %s  %.1f/s  ETA %.0f s%s%s ", label_.c_str(), done, *total_,
                    unit_.c_str(), rate, eta, extra.empty() ? "" : "  ", extra.c_str());
    } else {
      std::snprintf(line, sizeof line, "\r%s  %zu %s  %.1f/s%s%s ", label_.c_str(), done, unit_.c_str(), rate,
                    extra.empty() ? "" : "  ", extra.c_str());
    }
    std::fputs(line, stderr);
    std::fflush(stderr);
    width_ = std::max(width_, std::string(line).size());
  }

  /// Clears the line (terminal) or prints the summary line (not a terminal, runs >= 1 s).
  void done(const std::string& extra = {}) {
    if (finished_) return;
    finished_ = true;
    if (tty_) {
      if (width_ > 0) std::fprintf(stderr, "\r%*s\r", static_cast<int>(width_), "");
      return;
    }
    const double s = seconds();
    if (s < 1.0) return;
    std::fprintf(stderr, "%s: %zu %s in %.1f s (%.1f/s)%s%s\n", label_.c_str(), done_, unit_.c_str(), s,
                 static_cast<double>(done_) / s, extra.empty() ? "" : ", ", extra.c_str());
  }
  ~Progress() {
    if (tty_ && !finished_ && width_ > 0) std::fprintf(stderr, "\r%*s\r", static_cast<int>(width_), "");
  }

  [[nodiscard]] double seconds() const { return std::chrono::duration<double>(clock::now() - t0_).count(); }

 private:
  using clock = std::chrono::steady_clock;
  std::string label_, unit_;
  std::optional<std::size_t> total_;
  bool tty_;
  clock::time_point t0_, last_;
  std::size_t done_ = 0;
  std::size_t width_ = 0;
  bool finished_ = false;
};

/// "DIR/{a, b}": the files a command wrote into its output folder, for its last line.
inline std::string written_files(const std::string& dir, const std::vector<std::string>& files) {
  std::string out = dir;
  out += "/{";
  for (std::size_t k = 0; k < files.size(); ++k) {
    if (k > 0) out += ", ";
    out += files[k];
  }
  out += '}';
  return out;
}

/// A figure for JSON: finite numbers as numbers, inf/NaN as null (and `ok` says so).
inline nlohmann::json finite_or_null(double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); }

}  // namespace vmap::examples
