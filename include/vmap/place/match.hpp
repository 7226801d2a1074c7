#pragma once

// One scored id: what a place query or a ranking returns. Apart from database.hpp so that
// the loop engine's rankers (lcd/place_ranking.hpp) and their scripted test doubles can
// name it without the inverted file.

#include <cstdint>

namespace vmap {

/// An image (a database id, a frame index) and its bag-of-words score, higher is more
/// similar: in (0, 1] for the database's BowScoring.
template <class Id = std::uint32_t>
struct PlaceMatch {
  Id id{};
  double score = 0.0;

  friend bool operator==(const PlaceMatch&, const PlaceMatch&) = default;
};

}  // namespace vmap
