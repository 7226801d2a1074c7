#include <vmap/features/orb.hpp>
#include <vmap/geometry/fundamental.hpp>
#include <vmap/lcd/calibration.hpp>
#include <vmap/matching/brute_force.hpp>
#include <vmap/memory/stacks.hpp>
#include <vmap/memory/visual_memory.hpp>
#include <vmap/runtime/memory.hpp>
#include <vmap/runtime/policy_stack.hpp>

#include "support/frames.hpp"
#include "support/shared_data.hpp"

#include <doctest/doctest.h>

#include <cmath>
#include <string>
#include <vector>

namespace {

// -log10 P(X >= k), X ~ Binomial(n, p), summed term by term in double precision.
double tail_significance(int k, int n, double p) {
  double sum = 0.0;
  for (int i = k; i <= n; ++i)
    sum += std::exp(std::lgamma(n + 1.0) - std::lgamma(i + 1.0) - std::lgamma(n - i + 1.0)) * std::pow(p, i) *
           std::pow(1 - p, n - i);
  return -std::log10(sum);
}

// 200 foreign pairs: 196 without a weighed model, and four strong ones whose inliers
// beyond the minimal sample (7) are 10 of 40, 12 of 40, 14 of 40 and 20 of 40.
std::vector<vmap::ChanceSample> scripted_pairs() {
  std::vector<vmap::ChanceSample> s(196, vmap::ChanceSample{60, 9});
  for (const int extra : {10, 12, 14, 20}) s.push_back({47, 7 + extra});
  return s;
}

std::vector<vmap::Features> orb_features(const std::filesystem::path& input, std::size_t step) {
  vmap::OrbDescriptor orb;
  std::vector<vmap::Features> out;
  for (const vmap::Frame& f : vmap::test::grey_frames(input, step)) out.push_back(orb.extract(f.image));
  return out;
}

}  // namespace

TEST_CASE("chance calibration: the rate puts the foreign pair at the quantile at the target significance") {
  const auto pairs = scripted_pairs();
  const vmap::ChanceCalibration c = vmap::chance_rate_from(pairs, vmap::PlaceModel::fundamental);
  CHECK(c.pairs == 200);
  CHECK(c.weighed == 4);
  // The 0.99 quantile of 200 pairs is the 199th of them ascending (index 198): the second
  // strongest, 14 of 40. At the rate its significance is the target, 5.
  CHECK(tail_significance(14, 40, c.rate) == doctest::Approx(5.0).epsilon(1e-6));
  CHECK(tail_significance(14, 40, c.rate * 0.99) > 5.0);
  CHECK(c.strongest == doctest::Approx(tail_significance(20, 40, c.rate)).epsilon(1e-9));
  // The same samples give the same rate; a lower target asks for a higher rate.
  CHECK(vmap::chance_rate_from(pairs, vmap::PlaceModel::fundamental).rate == c.rate);
  const auto strict = vmap::chance_rate_from(pairs, vmap::PlaceModel::fundamental, {.significance = 3.0});
  CHECK(strict.rate > c.rate);
  CHECK(tail_significance(14, 40, strict.rate) == doctest::Approx(3.0).epsilon(1e-6));
  // An essential matrix's minimal sample is 5: the same pairs are two matches stronger.
  const auto essential = vmap::chance_rate_from(pairs, vmap::PlaceModel::essential);
  CHECK(tail_significance(16, 42, essential.rate) == doctest::Approx(5.0).epsilon(1e-6));
}

TEST_CASE("chance calibration: when almost no foreign pair makes a model, the strongest sets the rate") {
  std::vector<vmap::ChanceSample> pairs(199, vmap::ChanceSample{30, 0});
  pairs.push_back({47, 7 + 15});
  const vmap::ChanceCalibration c = vmap::chance_rate_from(pairs, vmap::PlaceModel::fundamental);
  CHECK(c.weighed == 1);
  CHECK(tail_significance(15, 40, c.rate) == doctest::Approx(5.0).epsilon(1e-6));
  CHECK(c.strongest == doctest::Approx(5.0).epsilon(1e-6));
}

TEST_CASE("chance calibration: too few pairs, no weighed pair, impossible samples and bad options are errors") {
  const auto pairs = scripted_pairs();
  const std::vector<vmap::ChanceSample> few(pairs.begin(), pairs.begin() + 50);
  CHECK_THROWS_WITH_AS(static_cast<void>(vmap::chance_rate_from(few, vmap::PlaceModel::fundamental)),
                       doctest::Contains("50 foreign pairs, at least 100"), vmap::Error);
  const std::vector<vmap::ChanceSample> none(200, vmap::ChanceSample{40, 11});
  CHECK_THROWS_WITH_AS(static_cast<void>(vmap::chance_rate_from(none, vmap::PlaceModel::fundamental)),
                       doctest::Contains("none of 200 foreign pairs has 12 inliers"), vmap::Error);
  // Pairs of one place given twice: nearly every match fits, no rate makes that chance.
  const std::vector<vmap::ChanceSample> same(200, vmap::ChanceSample{100, 95});
  CHECK_THROWS_WITH_AS(static_cast<void>(vmap::chance_rate_from(same, vmap::PlaceModel::fundamental)),
                       doctest::Contains("the places share views"), vmap::Error);
  auto bad = pairs;
  bad[3] = {20, 21};
  CHECK_THROWS_WITH_AS(static_cast<void>(vmap::chance_rate_from(bad, vmap::PlaceModel::fundamental)),
                       doctest::Contains("21 inliers of 20 fitted matches"), vmap::Error);
  CHECK_THROWS_WITH_AS(static_cast<void>(vmap::chance_rate_from(pairs, vmap::PlaceModel::fundamental, {.quantile = 1.0})),
                       doctest::Contains("quantile must be in (0, 1)"), vmap::Error);
  const std::vector<std::vector<vmap::Features>> one_place(1, std::vector<vmap::Features>(3));
  CHECK_THROWS_WITH_AS(static_cast<void>(vmap::calibrate_chance_rate(vmap::BruteForceMatcher{},
                                                                     vmap::FundamentalEstimator{}, one_place)),
                       doctest::Contains("needs at least two places"), vmap::Error);
}

TEST_CASE("chance calibration: the named stacks' rates, and a memory keeps the rate it was made with") {
  vmap::PolicyStack s;
  CHECK(vmap::measured_chance_rate(s) == 0.1);
  s.descriptor = vmap::DescriptorKind::sift;
  CHECK(vmap::measured_chance_rate(s) < 0.05);  // SIFT's mutual matches fit by chance far less often
  s.descriptor = vmap::DescriptorKind::xfeat_star;
  CHECK(vmap::measured_chance_rate(s) < 0.05);  // XFeat*'s refined matches, likewise
  // Stored with the memory: created with a rate, reopened with it, bit for bit.
  const auto dir = vmap::test::scratch_dir("chance_rate");
  vmap::MemoryOptions o;
  o.loops.decision.chance_inlier_rate = 0.0319;
  {
    auto mem = vmap::AnyMemory::create(dir / "m.vmdb", vmap::PolicyStack{}, o);
    mem.close();
  }
  const auto back = vmap::AnyMemory::open(dir / "m.vmdb", {});
  CHECK(back.options().loops.decision.chance_inlier_rate == 0.0319);
}

TEST_SUITE("data") {
  TEST_CASE("chance calibration: ORB's rate on foreign pairs of the shared sequences is near the decision's 0.1") {
    const std::vector<std::vector<vmap::Features>> places{orb_features(vmap::test::data_path("rtabmap_loop/images"), 2),
                                                          orb_features(vmap::test::data_path("kitti07_160/image_0"), 4),
                                                          orb_features(vmap::test::data_path("tum_fr3_cabinet_kf/rgb.txt"), 2)};
    const vmap::BruteForceMatcher matcher{};
    const vmap::FundamentalEstimator estimator{};
    const auto c = vmap::calibrate_chance_rate(matcher, estimator, places);
    MESSAGE("ORB chance rate " << c.rate << ", " << c.weighed << " of " << c.pairs << " pairs weighed");
    CHECK(c.pairs == 200);
    CHECK(c.weighed > 100);
    CHECK(c.rate > 0.07);
    CHECK(c.rate < 0.16);  // the rate moves with the places drawn (examples/results/loops.md)
    // The same places and seed give the same rate; another seed draws other pairs.
    CHECK(vmap::calibrate_chance_rate(matcher, estimator, places).rate == c.rate);
    CHECK(vmap::calibrate_chance_rate(matcher, estimator, places, {.seed = 2}).rate != c.rate);
  }
}
