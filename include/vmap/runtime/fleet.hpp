#pragma once

// A fleet's memory read as one (a PostgreSQL server; memory/store.hpp given a
// postgresql:// URI): a client that is no robot of the fleet, or a new robot on its first
// frame, localizes among the key images every robot mapped.
//
//   auto fleet = vmap::FleetMemory::open("postgresql://vmap@db/fleet");
//   vmap::FleetLocalization where = fleet.localize(image);   // where.robot, where.answer
//
// FleetMemory holds a snapshot of each robot's memory (AnyMemory opened to read, each
// with the stack it recorded), taken when it is opened; open it again to see what the
// robots mapped since. localize() asks each robot's memory (its place database ranks
// its key images, the best are verified: memory/visual_memory.hpp) and answers the
// most confident accepted place; when no memory accepts one, the most confident answer
// says why. Its RAM is that of the robots' memories: a reader that must stay small opens
// one robot (AnyMemory::open with MemoryOpenOptions::robot).

#include <vmap/core/error.hpp>
#include <vmap/io/postgres.hpp>
#include <vmap/memory/store.hpp>
#include <vmap/memory/types.hpp>
#include <vmap/runtime/memory.hpp>

#include <opencv2/core.hpp>

#include <cstddef>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace vmap {

/// Where a query image was taken in a fleet's memory: the robot whose memory answered,
/// and its answer (MemoryLocalization: its key image, confidence, or "unknown place").
struct FleetLocalization {
  std::string robot;  ///< the robot whose memory answered (empty when no robot has a key image)
  std::size_t index = 0;  ///< its place in FleetMemory::robots()
  MemoryLocalization answer;
};

/// Every robot's memory of a fleet's memory, read (see the top of this file). Move-only.
class FleetMemory {
 public:
  /// Opens every robot of the fleet's memory at `uri` to read. An Error when the database
  /// holds no vmap memory (not_found), or the server cannot be reached (unavailable).
  [[nodiscard]] static FleetMemory open(const std::string& uri, const MemoryOpenOptions& options = {}) {
    FleetMemory f;
    f.robots_ = MemoryStore::robots(uri);
    if (f.robots_.empty())
      detail::fail(ErrorKind::not_found, "memory '" + pg::redacted(uri) + "' does not exist: the database holds no robot's memory");
    for (const std::string& r : f.robots_) {
      MemoryOpenOptions o = options;
      o.robot = r;
      o.write = false;
      o.new_session = false;
      f.memories_.push_back(AnyMemory::open(uri, o));
    }
    return f;
  }

  [[nodiscard]] const std::vector<std::string>& robots() const noexcept { return robots_; }
  [[nodiscard]] AnyMemory& memory(std::size_t i) { return memories_.at(i); }
  [[nodiscard]] const AnyMemory& memory(std::size_t i) const { return memories_.at(i); }

  /// The most confident accepted place among the robots' answers, or else the most
  /// confident answer. Each robot's memory decides with its own options, at
  /// `min_confidence` when one is given.
  [[nodiscard]] FleetLocalization localize(const cv::Mat& image, std::optional<double> min_confidence = std::nullopt) {
    FleetLocalization best;
    bool have = false;
    for (std::size_t i = 0; i < memories_.size(); ++i) {
      PlaceDecisionOptions decision = memories_[i].options().loops.decision;
      if (min_confidence) decision.min_confidence = *min_confidence;
      MemoryLocalization a = memories_[i].localize(image, &decision);
      const bool better = !have || (a.ok() && !best.answer.ok()) ||
                          (a.ok() == best.answer.ok() && a.confidence > best.answer.confidence);
      if (better) {
        best = {robots_[i], i, std::move(a)};
        have = true;
      }
    }
    return best;
  }

 private:
  FleetMemory() = default;
  std::vector<std::string> robots_;
  std::vector<AnyMemory> memories_;
};

}  // namespace vmap
