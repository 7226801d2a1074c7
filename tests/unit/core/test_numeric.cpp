// Boundary checks of numbers: negative input for unsigned options, junk,
// non-finite values, all named by the option; non-finite figures printed as words.
#include <vmap/core/numeric.hpp>
#include <vmap/features/orb.hpp>
#include <vmap/features/sift.hpp>

#include "support/errors.hpp"

#include <doctest/doctest.h>

#include <limits>
#include <string>

using vmap::test::error_of;

TEST_CASE("parse_count rejects negatives, junk and overflow, naming the option") {
  CHECK(vmap::parse_count("0", "--start") == 0);
  CHECK(vmap::parse_count("18446744073709551615", "--stride") == std::numeric_limits<std::uint64_t>::max());
  CHECK(error_of([] { (void)vmap::parse_count("-1", "--start"); }) == "--start: '-1' is negative; a whole number >= 0 is expected");
  CHECK(error_of([] { (void)vmap::parse_count("18446744073709551616", "--stride"); }) == "--stride: '18446744073709551616' is too large");
  CHECK(error_of([] { (void)vmap::parse_count("12x", "--end"); }) == "--end: '12x' is not a whole number >= 0");
  CHECK(error_of([] { (void)vmap::parse_count("", "--end"); }) == "--end: '' is not a whole number >= 0");
  CHECK(error_of([] { (void)vmap::parse_count("11", "--k", 10); }) == "--k: '11' is above the limit of 10");
}

TEST_CASE("parse_finite and check_finite name the option") {
  CHECK(vmap::parse_finite("-2.5", "--pan") == -2.5);
  CHECK(vmap::parse_finite("+3", "--pan") == 3.0);
  CHECK(error_of([] { (void)vmap::parse_finite("nan", "--pan"); }) == "--pan: 'nan' is not a finite number");
  CHECK(error_of([] { (void)vmap::parse_finite("inf", "--margin"); }) == "--margin: 'inf' is not a finite number");
  CHECK(error_of([] { (void)vmap::parse_finite("1,5", "--margin"); }) == "--margin: '1,5' is not a number");
  CHECK(error_of([] { vmap::check_finite(std::numeric_limits<double>::quiet_NaN(), "--pan"); }).find("--pan must be a finite number") == 0);
  CHECK(error_of([] { vmap::check_in_range(2.0, 0.0, 1.0, "--tau"); }).find("--tau must be in [0.000000, 1.000000]") == 0);
}

TEST_CASE("figure prints non-finite values as words") {
  CHECK(vmap::figure(1.23456, 2) == "1.23");
  CHECK(vmap::figure(std::numeric_limits<double>::infinity()) == "not finite (overflow)");
  CHECK(vmap::figure(std::numeric_limits<double>::quiet_NaN()) == "undefined (NaN)");
}

TEST_CASE("keypoint budgets have a documented maximum instead of a bad_alloc") {
  CHECK(error_of([] { vmap::OrbDescriptor d({.features = 1000000000}); }) ==
        "OrbOptions.features must be in [1, 1048576], got 1000000000");
  CHECK(error_of([] { vmap::SiftDescriptor d({.features = 2000000000}); }) ==
        "SiftOptions.features must be in [0, 1048576], got 2000000000");
  CHECK(error_of([] { vmap::OrbDescriptor d({.features = vmap::max_keypoint_budget}); }) == "no error");
}

TEST_CASE("a 1x1 image is a clear error from every descriptor, not an OpenCV assertion") {
  const cv::Mat one(1, 1, CV_8UC1, cv::Scalar(7));
  vmap::OrbDescriptor orb;
  vmap::SiftDescriptor sift;
  const auto e = error_of([&] { (void)orb.extract(one); });
  CHECK(e == "ORB extract: the image is 1x1 pixels, too small to detect features in (at least 8x8)");
  CHECK(error_of([&] { (void)sift.extract(one); }).find("1x1 pixels, too small") != std::string::npos);
  const cv::Mat eight(8, 8, CV_8UC1, cv::Scalar(7));
  CHECK(error_of([&] { (void)orb.extract(eight); }) == "no error");
}
