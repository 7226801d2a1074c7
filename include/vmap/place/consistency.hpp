#pragma once

// Temporal consistency of place matches (DBoW2's temporal consistency over islands,
// Gálvez-López and Tardós, T-RO 2012, sec. VI-B; iBoW-LCD's islands, Garcia-Fidalgo and
// Ortiz, RA-L 2018): a loop is accepted only when `required` consecutive queries matched
// places that lie close together (within `tolerance` ids of the previous match), i.e.
// the robot is retracing a stretch of the map, not glimpsing one look-alike frame.

#include <vmap/core/error.hpp>

#include <concepts>
#include <cstdint>
#include <optional>
#include <string>

namespace vmap {

struct TemporalConsistencyOptions {
  int required = 3;             ///< consecutive consistent queries (this one included) to accept, >= 1
  std::uint64_t tolerance = 3;  ///< max id distance between consecutive matches of one island
};

/// What one update says: whether the match is accepted, how many consecutive queries
/// (this one included) matched the current island, and the island's span of matched ids.
template <class Id = std::uint32_t>
struct ConsistencyState {
  bool accepted = false;
  int consecutive = 0;  ///< 0 after a query with no match
  Id island_begin{};    ///< smallest matched id of the island (meaningless when consecutive == 0)
  Id island_end{};      ///< largest matched id of the island
  std::optional<Id> last{};  ///< the previous query's best match, if any

  friend bool operator==(const ConsistencyState&, const ConsistencyState&) = default;
};

/// Feeds each query's best match (or none) in order; the state is a small value, so a
/// saved session restores it with `TemporalConsistency(options, state)` (or starts a
/// fresh one: it only delays the first acceptance by `required - 1` queries).
///
/// Not thread-safe for updates (one sequence of queries); `state()` is const.
template <std::integral Id = std::uint32_t>
class TemporalConsistency {
 public:
  explicit TemporalConsistency(const TemporalConsistencyOptions& options = {}, ConsistencyState<Id> state = {})
      : options_(options), state_(state) {
    detail::check(options_.required >= 1, [&] {
      return "TemporalConsistencyOptions.required must be >= 1, got " + std::to_string(options_.required);
    });
  }

  /// The next query's best match: consistent when within `tolerance` ids of the previous
  /// query's best match (then the island grows to include it), otherwise it starts a new
  /// island; no match empties the state.
  ConsistencyState<Id> update(std::optional<Id> best) {
    if (!best) {
      state_ = {};
      return state_;
    }
    const Id b = *best;
    if (state_.last && distance(*state_.last, b) <= options_.tolerance) {
      ++state_.consecutive;
      if (b < state_.island_begin) state_.island_begin = b;
      if (state_.island_end < b) state_.island_end = b;
    } else {
      state_.consecutive = 1;
      state_.island_begin = b;
      state_.island_end = b;
    }
    state_.last = b;
    state_.accepted = state_.consecutive >= options_.required;
    return state_;
  }

  void reset() { state_ = {}; }
  [[nodiscard]] const ConsistencyState<Id>& state() const noexcept { return state_; }
  [[nodiscard]] const TemporalConsistencyOptions& options() const noexcept { return options_; }

 private:
  static std::uint64_t distance(Id a, Id b) noexcept {
    // In the unsigned 64-bit domain: no overflow for any integral Id.
    const auto wa = static_cast<std::uint64_t>(a);
    const auto wb = static_cast<std::uint64_t>(b);
    return a < b ? wb - wa : wa - wb;
  }

  TemporalConsistencyOptions options_;
  ConsistencyState<Id> state_;
};

}  // namespace vmap
