#pragma once

// A PlaceRanking for the loop-engine tests: the bag of words is the frame's index and the
// score of a pair is the test's function, so the engine's ranking, revisit and
// ambiguity logic is tested apart from any vocabulary.

#include <vmap/lcd/place_ranking.hpp>

#include <doctest/doctest.h>

#include <algorithm>
#include <cstddef>
#include <functional>
#include <utility>
#include <vector>

namespace vmap::test {

class ScriptedRanker {
 public:
  using Bow = std::size_t;
  ScriptedRanker() = default;
  explicit ScriptedRanker(std::function<double(std::size_t, std::size_t)> score) : score_(std::move(score)) {}
  [[nodiscard]] bool ready() const { return static_cast<bool>(score_); }
  [[nodiscard]] Bow describe(const vmap::Features&) const { return next_++; }
  void add(std::size_t id, Bow bow) {
    CHECK(id == bow);  // the detector adds frame j with the bag of words it described for j
    indexed_.push_back(id);
  }
  [[nodiscard]] std::vector<vmap::PlaceMatch<std::size_t>> rank(Bow query, std::size_t top_k,
                                                                 const std::vector<std::size_t>* only,
                                                                 std::size_t before = static_cast<std::size_t>(-1),
                                                                 std::size_t from = 0) const {
    std::vector<vmap::PlaceMatch<std::size_t>> out;
    for (std::size_t id : only ? *only : indexed_)
      if (only || (id < before && id >= from)) out.push_back({id, score_(query, id)});
    std::stable_sort(out.begin(), out.end(), [](const auto& a, const auto& b) { return a.score > b.score; });
    if (out.size() > top_k) out.resize(top_k);
    return out;
  }
  // The bag of words is the frame index, so one overload scores a query and two frames alike.
  [[nodiscard]] double similarity(std::size_t a, std::size_t b) const { return score_(a, b); }
  [[nodiscard]] std::size_t memory_bytes() const { return indexed_.size() * sizeof(std::size_t); }
  [[nodiscard]] const std::vector<std::size_t>& indexed() const { return indexed_; }

 private:
  std::function<double(std::size_t, std::size_t)> score_;
  mutable std::size_t next_ = 0;
  std::vector<std::size_t> indexed_;
};
static_assert(vmap::PlaceRanking<ScriptedRanker>);

}  // namespace vmap::test
