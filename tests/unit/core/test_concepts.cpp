// Compile-time tests of the four concepts: every shipped policy models its concept,
// and types missing one requirement do not. Explicit instantiation of the policy
// classes makes every member compile (Sophus' practice).
#include <vmap/vmap.hpp>

#include <doctest/doctest.h>

#include <string>

namespace {

struct NoExtract {};
struct ExtractWrongType {
  cv::Mat extract(const cv::Mat& m) { return m; }
};
struct NonConstMatch {  // match must be callable on a const matcher
  vmap::Matches match(const vmap::Features&, const vmap::Features&) { return {}; }
};
struct VerifyReturnsBool {
  bool verify(const vmap::Features&, const vmap::Features&, const vmap::Matches&) const { return true; }
};
struct ScoreWithoutBound {
  double operator()(const vmap::Features&, const vmap::Features&, const vmap::Verification&) const { return 0; }
};
struct NotMovable {
  NotMovable() = default;
  NotMovable(NotMovable&&) = delete;
  vmap::Features extract(const cv::Mat&) { return {}; }
};
struct Detector {
  std::vector<vmap::Detection> detect(const cv::Mat&) { return {}; }
};
struct Pair {
  vmap::Correspondences match_pair(const cv::Mat&, const cv::Mat&) { return {}; }
};

}  // namespace

// Models.
static_assert(vmap::Descriptor<vmap::OrbDescriptor>);
static_assert(vmap::Descriptor<vmap::AkazeDescriptor>);
static_assert(vmap::Descriptor<vmap::SiftDescriptor>);
static_assert(vmap::Matcher<vmap::BruteForceMatcher>);
static_assert(vmap::Estimator<vmap::FundamentalEstimator>);
static_assert(vmap::Estimator<vmap::HomographyEstimator>);
static_assert(vmap::Similarity<vmap::InlierRatio>);
static_assert(vmap::Similarity<vmap::InlierRatioMin>);
static_assert(vmap::ObjectDetector<Detector>);
static_assert(vmap::PairMatcher<Pair>);

// Non-models, each missing exactly one requirement.
static_assert(!vmap::Descriptor<NoExtract>);
static_assert(!vmap::Descriptor<ExtractWrongType>);
static_assert(!vmap::Descriptor<NotMovable>);
static_assert(!vmap::Matcher<NonConstMatch>);
static_assert(!vmap::Estimator<VerifyReturnsBool>);
static_assert(!vmap::Similarity<ScoreWithoutBound>);
static_assert(vmap::ScoresPair<ScoreWithoutBound>);
static_assert(!vmap::ObjectDetector<Pair>);
static_assert(!vmap::PairMatcher<Detector>);

// Explicit instantiation is for templates; the policies are classes, so instead every
// member is named here, which makes a broken member a compile error in this file.
template <class T>
constexpr bool all_members_compile() {
  if constexpr (vmap::Descriptor<T>) {
    [[maybe_unused]] auto e = &T::extract;
    [[maybe_unused]] auto o = &T::options;
  }
  return true;
}
static_assert(all_members_compile<vmap::OrbDescriptor>());
static_assert(all_members_compile<vmap::AkazeDescriptor>());
static_assert(all_members_compile<vmap::SiftDescriptor>());

TEST_CASE("status strings name every outcome") {
  CHECK(vmap::to_string(vmap::VerificationStatus::verified) == "verified");
  CHECK(vmap::to_string(vmap::VerificationStatus::too_few_matches) == "too few matches");
  CHECK(vmap::to_string(vmap::VerificationStatus::no_model) == "no model");
  CHECK(vmap::to_string(vmap::VerificationStatus::too_few_inliers) == "too few inliers");
  CHECK(vmap::to_string(vmap::Degeneracy::none) == "none");
  CHECK(std::string(vmap::to_string(vmap::Degeneracy::homography)).find("homography") == 0);
}
