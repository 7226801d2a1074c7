#pragma once

// How a front end names what its user gave, for the messages of the run-time layer's
// checks. The layer checks a user's inputs (a descriptor's name, a vocabulary's size, a
// candidate source) once for every front end, and its messages name each input the way
// the front end that read it does:
//
//   const auto cli = vmap::OptionNames::command_line();
//   cli("nfeatures");                       // "--nfeatures"
//   cli.with_value("rank", "tree");         // "--rank tree"
//   const auto py = vmap::OptionNames::keywords();
//   py.with_value("rank", "tree");          // "rank=tree"
//   vmap::parse_option<vmap::KeyRule>("current", "rule", "rule", py);  // KeyRule::current_frame
//
// An input is known by its keyword (the Python module's argument, "refine_model"); a
// command line writes it as a long option ("--refine-model"). `renamed` gives a front
// end's own name where it differs (`vmap loops` reads the descriptor's model file as
// --features-model, its --model being the object detector's).

#include <vmap/core/error.hpp>
#include <vmap/core/names.hpp>

#include <cstdint>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace vmap {

/// The names of a front end's inputs (see the top of this file). A value: copy it freely.
struct OptionNames {
  enum class Style : std::uint8_t {
    keyword,  ///< `top_k`, `top_k=3` (Python keywords, configuration files)
    flag,     ///< `--top-k`, `--top-k 3` (a command line)
  };
  Style style = Style::keyword;
  /// keyword -> the front end's own full name ("model" -> "--features-model").
  std::vector<std::pair<std::string, std::string>> renamed{};

  [[nodiscard]] static OptionNames keywords() { return {}; }
  [[nodiscard]] static OptionNames command_line(std::vector<std::pair<std::string, std::string>> renamed = {}) {
    return {Style::flag, std::move(renamed)};
  }

  /// The name of the input `keyword`: "top_k" or "--top-k".
  [[nodiscard]] std::string operator()(std::string_view keyword) const {
    for (const auto& [k, name] : renamed)
      if (k == keyword) return name;
    if (style == Style::keyword) return std::string(keyword);
    std::string out = "--";
    for (char c : keyword) out += c == '_' ? '-' : c;
    return out;
  }

  /// The input given a value, as the user wrote it: "top_k=3" or "--top-k 3".
  [[nodiscard]] std::string with_value(std::string_view keyword, std::string_view value) const {
    return (*this)(keyword) + (style == Style::keyword ? "=" : " ") + std::string(value);
  }
};

/// The value of T named `text` (core/names.hpp, from_string) given for the input
/// `keyword`; otherwise an Error "NAME: unknown NOUN 'text' (choose ...)" with the input
/// named as `names` spells it (`noun` may be empty: "rank: unknown 'fast' ...").
template <class T>
[[nodiscard]] T parse_option(std::string_view text, std::string_view keyword, std::string_view noun,
                             const OptionNames& names = OptionNames::keywords()) {
  if (const auto v = from_string<T>(text)) return *v;
  detail::fail(names(keyword) + ": unknown " + std::string(noun) + (noun.empty() ? "'" : " '") + std::string(text) +
               "' (choose " + names_of(T{}).choices() + ")");
}

}  // namespace vmap
