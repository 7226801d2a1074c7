#pragma once

// --words and --depth of a vocabulary learned by a subcommand (`vmap vocabulary`, `vmap
// loops` without --vocabulary), with the bounds of vmap::VocabularyLearning (whose
// validate() also refuses a pair that needs a branching above the tree's).

#include "common/cli_support.hpp"

#include <vmap/runtime/vocabulary.hpp>

#include <CLI/CLI.hpp>

#include <string>

namespace vmap::examples {

inline void add_vocabulary_options(CLI::App& app, VocabularyLearning& v, const std::string& context) {
  app.add_option("--words", v.words, context + "at most this many words (branching k: smallest with k^depth >= words)")
      ->capture_default_str()
      ->check(count_in(2, VocabularyLearning::max_words));
  app.add_option("--depth", v.depth, context + "depth L of the tree")
      ->capture_default_str()
      ->check(count_in(1, VocabularyLearning::max_depth));
}

}  // namespace vmap::examples
