// A program outside the vmap tree, built against the installed package: it must find
// the headers, OpenCV and Eigen through vmap::vmap alone.
#include <vmap/vmap.hpp>

#include <opencv2/imgproc.hpp>

#include <cstdio>

int main() {
  cv::Mat image(240, 320, CV_8UC1, cv::Scalar(0));
  cv::RNG rng(7);
  for (int i = 0; i < 300; ++i)
    cv::circle(image, {rng.uniform(0, 320), rng.uniform(0, 240)}, rng.uniform(2, 9), cv::Scalar(rng.uniform(60, 255)), -1);
  vmap::OrbDescriptor orb;
  vmap::BruteForceMatcher matcher;
  vmap::FundamentalEstimator estimator;
  const vmap::Features f = orb.extract(image);
  const vmap::Matches m = matcher.match(f, f);
  const vmap::Verification v = estimator.verify(f, f, m);
  std::printf("vmap %d.%d.%d: %zu features, %zu self-matches, status %s\n", vmap::version_major,
              vmap::version_minor, vmap::version_patch, f.size(), m.size(), std::string(vmap::to_string(v.status)).c_str());
  // Every keypoint matches itself: the result is exact.
  return (f.size() > 100 && m.size() == f.size()) ? 0 : 1;
}
