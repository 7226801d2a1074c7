// The streaming threshold sweep (keyframe/sweep.hpp keeps only the features a selector
// can still read) against golden lists recorded at commit 6af038d: for each tau, the key
// frames and the min and max matches that `vmap sweep --json` printed when built at that
// commit (then the sweep cached every frame's features). This test does not run a
// caching sweep; it compares today's sweep with those recorded lists, on the sample
// frames (self-contained) and on a 120-frame prefix of ../shared/data/tum_fr1_rpy (suite
// "data"). The stack is the CLI's default: ORB 1000, mutual NN, MAGSAC 1 px without the
// degeneracy check, eq. 5.
#include "support/shared_data.hpp"

#include <vmap/keyframe/sweep.hpp>

#include <doctest/doctest.h>

#include <cstddef>
#include <filesystem>
#include <sstream>
#include <string>
#include <vector>

namespace {

struct Recorded {
  double tau;
  int min_matches;
  int max_matches;
  const char* key_frames;  ///< "0-5,7,9": ranges of frame indices
};

std::vector<std::size_t> expand(const std::string& ranges) {
  std::vector<std::size_t> out;
  std::stringstream in(ranges);
  std::string part;
  while (std::getline(in, part, ',')) {
    const auto dash = part.find('-');
    const std::size_t a = std::stoul(part.substr(0, dash));
    const std::size_t b = dash == std::string::npos ? a : std::stoul(part.substr(dash + 1));
    for (std::size_t i = a; i <= b; ++i) out.push_back(i);
  }
  return out;
}

void check_against(const std::filesystem::path& list, std::size_t end, const std::vector<Recorded>& recorded) {
  auto src = vmap::FrameSource::open(list, {.end = end, .grey = true});
  std::vector<double> taus;
  for (const auto& r : recorded) taus.push_back(r.tau);
  const auto sweep = vmap::sweep_thresholds(src, vmap::OrbDescriptor{}, vmap::BruteForceMatcher{},
                                            vmap::FundamentalEstimator({.check_degeneracy = false}),
                                            vmap::InlierRatio{}, {.taus = taus});
  CHECK(sweep.frames == end);
  // Streaming: the key images of the nine thresholds, I_{j-1} and I_j at most.
  CHECK(sweep.frames_held >= 2);
  CHECK(sweep.frames_held <= taus.size() + 2);
  REQUIRE(sweep.rows.size() == recorded.size());
  for (std::size_t k = 0; k < recorded.size(); ++k) {
    CAPTURE(recorded[k].tau);
    const auto expected = expand(recorded[k].key_frames);
    CHECK(sweep.rows[k].key_frames == expected);
    CHECK(sweep.rows[k].stats.key_images == expected.size());
    CHECK(sweep.rows[k].stats.min_matches == recorded[k].min_matches);
    CHECK(sweep.rows[k].stats.max_matches == recorded[k].max_matches);
  }
}

}  // namespace

TEST_CASE("sample frames: the sweep gives the golden lists recorded at commit 6af038d") {
  check_against(vmap::test::source_dir() / "examples/data/tum_fr1_rpy_60/rgb.txt", 60,
                {
                    {0.1, 100, 116, "0,7,16,32,40"},
                    {0.2, 202, 271, "0,3,6,9,14,28,33,38,42,52,56"},
                    {0.3, 165, 466, "0-5,7,9,12,16,27,31,33,36,39,41-42,44,50-53,56,58"},
                    {0.4, 165, 581, "0-10,13,16,22,27,29,31-34,37-43,50-58"},
                    {0.5, 165, 680, "0-13,15,19,22,26-44,49-58"},
                    {0.6, 165, 680, "0-19,21,23-44,49-58"},
                    {0.7, 165, 732, "0-45,48-58"},
                    {0.8, 165, 711, "0-59"},
                    {0.9, 165, 711, "0-59"},
                });
}

TEST_SUITE("data") {
  TEST_CASE("tum_fr1_rpy prefix: the sweep gives the golden lists recorded at commit 6af038d") {
    check_against(vmap::test::data_path("tum_fr1_rpy/rgb.txt"), 120,
                  {
                      {0.1, 58, 154, "0,7,16,32,40,59,74,82,99,112-113,116-117"},
                      {0.2, 64, 374, "0,3,6,9,14,28,33,38,42,52,56,59,69,77,82,84,99,106,108,111-118"},
                      {0.3, 64, 624, "0-5,7,9,12,16,27,31,33,36,39,41-42,44,50-53,56,58,62,69,73,78,81,84-85,95,100,104-118"},
                      {0.4, 64, 624, "0-10,13,16,22,27,29,31-34,37-43,50-58,60,65,68,71,73,77,80-86,91,95,100-101,104-118"},
                      {0.5, 64, 680, "0-13,15,19,22,26-44,49-61,64-87,89,91-101,103-118"},
                      {0.6, 64, 680, "0-19,21,23-44,49-101,103-118"},
                      {0.7, 64, 732, "0-45,48-118"},
                      {0.8, 64, 711, "0-119"},
                      {0.9, 64, 711, "0-119"},
                  });
  }
}
