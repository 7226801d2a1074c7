// The detector-free XFeat front end (hooks/xfeat_dense.hpp): the mutual matcher against
// brute force, a synthetic pair with a known shift, the PairMatcher's cache, the two
// selector front ends agreeing, and determinism of every key-image configuration.
#include <vmap/hooks/xfeat_dense.hpp>
#include <vmap/io/frame_source.hpp>
#include <vmap/keyframe/selector.hpp>
#include <vmap/matching/brute_force.hpp>

#include "support/errors.hpp"
#include "support/sample_memory.hpp"
#include "support/shared_data.hpp"

#include <doctest/doctest.h>
#include <opencv2/imgcodecs.hpp>

#include <cmath>
#include <string>
#include <vector>

namespace {

using vmap::test::error_of;

/// n random unit vectors of 64 floats (seeded).
vmap::Features unit_vectors(int n, std::uint64_t seed) {
  vmap::Features f;
  f.norm = cv::NORM_L2;
  f.descriptors.create(n, 64, CV_32F);
  cv::RNG rng(seed);
  rng.fill(f.descriptors, cv::RNG::NORMAL, 0.0, 1.0);
  for (int i = 0; i < n; ++i) {
    cv::Mat r = f.descriptors.row(i);
    r /= cv::norm(r);
    f.keypoints.emplace_back(cv::Point2f(static_cast<float>(i), 0.0f), 1.0f);
  }
  return f;
}

using vmap::test::memory_estimator;
using vmap::test::sample_images;

template <class Selector>
std::vector<std::size_t> keys_of(Selector&& sel, const std::vector<cv::Mat>& frames) {
  for (const cv::Mat& f : frames) sel.push(f);
  return sel.map().key_indices();
}

}  // namespace

static_assert(vmap::Descriptor<vmap::XFeatDenseDescriptor>);
static_assert(vmap::Matcher<vmap::DenseMutualMatcher>);
static_assert(vmap::PairMatcher<vmap::XFeatDenseMatcher>);
static_assert(!vmap::PairMatcher<vmap::XFeatDenseDescriptor>);

TEST_CASE("DenseMutualMatcher gives brute force's mutual L2 matches on unit vectors") {
  const vmap::Features a = unit_vectors(700, 1), b = unit_vectors(600, 2);
  vmap::Features b_near = b;  // b plus a few near-copies of a's vectors, so there are real pairs
  for (int i = 0; i < 50; ++i) {
    cv::Mat r = a.descriptors.row(i * 13) + 0.05 * b.descriptors.row(i);
    r /= cv::norm(r);
    r.copyTo(b_near.descriptors.row(i * 11));
  }
  const vmap::Matches dense = vmap::DenseMutualMatcher{}.match(a, b_near);
  const vmap::Matches brute = vmap::BruteForceMatcher({.mode = vmap::MatchMode::mutual}).match(a, b_near);
  REQUIRE(dense.size() == brute.size());
  CHECK(dense.size() >= 50);
  for (std::size_t i = 0; i < dense.size(); ++i) {
    CHECK(dense[i].queryIdx == brute[i].queryIdx);
    CHECK(dense[i].trainIdx == brute[i].trainIdx);
    CHECK(dense[i].distance == doctest::Approx(brute[i].distance).epsilon(1e-4));
  }
  // Each planted pair is found (row i*13 of a <-> row i*11 of b).
  int planted = 0;
  for (const auto& m : dense) planted += (m.queryIdx % 13 == 0 && m.trainIdx == m.queryIdx / 13 * 11) ? 1 : 0;
  CHECK(planted == 50);
  CHECK(vmap::DenseMutualMatcher{}.match(a, vmap::Features{}).empty());
  vmap::Features binary;
  binary.norm = cv::NORM_HAMMING;
  binary.descriptors = cv::Mat::zeros(3, 32, CV_8U);
  binary.keypoints.resize(3);
  CHECK(error_of([&] { (void)vmap::DenseMutualMatcher{}.match(binary, binary); }).find("CV_32F") !=
        std::string::npos);
}

TEST_SUITE("data") {
  TEST_CASE("XFeat dense on a synthetic pair with a known shift: every cell a candidate, matches follow the shift") {
    const cv::Mat frame =
        cv::imread(vmap::test::data_path("tum_fr1_rpy/rgb/1305031253.529706.jpg").string(), cv::IMREAD_GRAYSCALE);
    vmap::XFeatDenseDescriptor grid({.model = vmap::test::model_path("xfeat_anysize.onnx")});
    CHECK(grid.model_kind() == vmap::XFeatModelKind::any_size);
    vmap::XFeatDenseMatcher pair({.model = vmap::test::model_path("xfeat_anysize.onnx")});
    // Two 608x448 windows of one frame, the second (dx, dy) right and down: scene point
    // (x, y) of window a is (x - dx, y - dy) in window b.
    struct Case {
      int dx, dy;
      double px;        // tolerance
      double fraction;  // of the mutual matches within it
    };
    // (16, 8) is a whole number of cells: both grids cut the scene alike, each cell's
    // best pixel is the same scene point, and the shift comes back to the pixel.
    // (13, 6) is not: a cell of b holds parts of four cells of a, so a match is right
    // to the cell (a correspondence is a cell, as at LoFTR's coarse level) and its best
    // pixels agree only where one keypoint dominates both cells.
    for (const Case t : {Case{16, 8, 1.0, 0.9}, Case{13, 6, 12.0, 0.9}, Case{13, 6, 8.0, 0.65}}) {
      CAPTURE(t.dx);
      CAPTURE(t.px);
      const cv::Mat a = frame(cv::Rect(0, 0, 608, 448)).clone(), b = frame(cv::Rect(t.dx, t.dy, 608, 448)).clone();
      const vmap::Features fa = grid.extract(a);
      REQUIRE(fa.size() == 76 * 56);  // one keypoint per 1/8 cell: the eq. 5 denominator
      for (int i = 0; i < static_cast<int>(fa.size()); i += 97) {
        const cv::Point2f p = fa.keypoints[static_cast<std::size_t>(i)].pt;
        CHECK(static_cast<int>(p.x) / 8 == i % 76);  // each keypoint inside its own cell, a whole pixel
        CHECK(static_cast<int>(p.y) / 8 == i / 76);
        CHECK(p.x == std::round(p.x));
        CHECK(cv::norm(fa.descriptors.row(i)) == doctest::Approx(1.0).epsilon(1e-5));
      }
      const vmap::Correspondences c = pair.match_pair(a, b);
      CHECK(c.cells == 76 * 56);
      REQUIRE(c.size() == c.points_b.size());
      REQUIRE(c.size() == c.confidence.size());
      int within = 0;
      for (std::size_t i = 0; i < c.size(); ++i) {
        const double e = std::hypot(c.points_a[i].x - t.dx - c.points_b[i].x, c.points_a[i].y - t.dy - c.points_b[i].y);
        within += e <= t.px ? 1 : 0;
        CHECK(c.confidence[i] >= 0.0f);
        CHECK(c.confidence[i] <= 1.0f);
      }
      const double f = static_cast<double>(within) / static_cast<double>(c.size());
      MESSAGE("dense shift (" << t.dx << ", " << t.dy << "): " << c.size() << " mutual matches of " << c.cells
                              << " cells, " << f * 100.0 << " % within " << t.px << " px of the shift");
      CHECK(c.size() > 3000);
      CHECK(f > t.fraction);
    }
  }

  TEST_CASE("XFeatDenseMatcher: the grids of Descriptor + Matcher, each image through the network once") {
    const std::vector<cv::Mat> frames = sample_images(4);
    vmap::XFeatDenseMatcher pair({.model = vmap::test::model_path("xfeat_anysize.onnx")});
    vmap::XFeatDenseDescriptor grid({.model = vmap::test::model_path("xfeat_anysize.onnx")});
    const vmap::Features f0 = grid.extract(frames[0]), f1 = grid.extract(frames[1]);
    const vmap::Matches m = vmap::DenseMutualMatcher{}.match(f0, f1);
    const vmap::Correspondences c = pair.match_pair(frames[0], frames[1]);
    CHECK(c.cells == 80 * 60);
    REQUIRE(c.size() == m.size());
    for (std::size_t i = 0; i < m.size(); i += 7) {
      CHECK(c.points_a[i] == f0.keypoints[static_cast<std::size_t>(m[i].queryIdx)].pt);
      CHECK(c.points_b[i] == f1.keypoints[static_cast<std::size_t>(m[i].trainIdx)].pt);
    }
    CHECK(pair.network_runs() == 2);
    // The selector's pattern: the key image against each new frame. A copy of a frame
    // (another buffer, same pixels) is recognised by content.
    (void)pair.match_pair(frames[0].clone(), frames[2]);
    CHECK(pair.network_runs() == 3);
    (void)pair.match_pair(frames[1], frames[3]);  // eq. 6: the previous frame became the key
    CHECK(pair.network_runs() == 4);
    (void)pair.match_pair(frames[1], frames[3]);
    CHECK(pair.network_runs() == 4);
    (void)pair.match_pair(frames[0], frames[1]);  // frame 0 fell out of the three cached
    CHECK(pair.network_runs() == 5);
  }

  TEST_CASE("XFeat dense: PairKeyframeSelector and the Descriptor stack keep the same key images") {
    const std::vector<cv::Mat> frames = sample_images(30);
    const auto model = vmap::test::model_path("xfeat_anysize.onnx");
    const vmap::SelectorOptions o{.tau = 0.35};
    vmap::PairKeyframeSelector pair_sel(vmap::XFeatDenseMatcher({.model = model}), memory_estimator(7), o);
    vmap::KeyframeSelector feature_sel(vmap::XFeatDenseDescriptor({.model = model}), vmap::DenseMutualMatcher{},
                                       memory_estimator(7), vmap::InlierRatio{}, o);
    const auto a = keys_of(pair_sel, frames), b = keys_of(feature_sel, frames);
    CHECK(a == b);
    CHECK(a.size() > 2);
    CHECK(a.size() < frames.size());
    REQUIRE(pair_sel.map().pairs.size() == feature_sel.map().pairs.size());
    for (std::size_t k = 0; k < pair_sel.map().pairs.size(); ++k) {
      CHECK(pair_sel.map().pairs[k].inliers == feature_sel.map().pairs[k].inliers);
      CHECK(pair_sel.map().pairs[k].similarity == feature_sel.map().pairs[k].similarity);
    }
    // Each frame went through the network once, plus the re-runs of frames that fell
    // out of the cache of three (none on this sequence).
    const std::size_t runs = pair_sel.front_end().matcher().network_runs();
    MESSAGE("30 frames, " << a.size() << " key images, " << runs << " network runs");
    CHECK(runs == frames.size());
  }

  TEST_CASE("key images are deterministic for ORB, XFeat native and XFeat dense (same input, same seed)") {
    const std::vector<cv::Mat> frames = sample_images(30);
    const auto model = vmap::test::model_path("xfeat_anysize.onnx");
    const vmap::SelectorOptions o{.tau = 0.3};
    auto orb = [&] {
      return keys_of(vmap::KeyframeSelector(vmap::OrbDescriptor{}, vmap::BruteForceMatcher{}, memory_estimator(7),
                                            vmap::InlierRatio{}, o),
                     frames);
    };
    auto native = [&] {
      return keys_of(vmap::KeyframeSelector(vmap::XFeatDescriptor({.model = model}), vmap::BruteForceMatcher{},
                                            memory_estimator(7), vmap::InlierRatio{}, o),
                     frames);
    };
    auto dense = [&] {
      return keys_of(vmap::PairKeyframeSelector(vmap::XFeatDenseMatcher({.model = model}), memory_estimator(7), o), frames);
    };
    const auto orb1 = orb(), native1 = native(), dense1 = dense();
    CHECK(orb1 == orb());
    CHECK(native1 == native());
    CHECK(dense1 == dense());
    MESSAGE("30 frames, tau 0.3: ORB " << orb1.size() << ", XFeat native " << native1.size() << ", XFeat dense "
                                       << dense1.size() << " key images");
    for (const auto* keys : {&orb1, &native1, &dense1}) CHECK(keys->size() >= 2);
  }

  TEST_CASE("XFeat dense: a model that is not XFeat is an error naming the file") {
    for (const char* file : {"yolox_nano.onnx", "FastestDet.onnx"}) {
      const std::string e =
          error_of([&] { vmap::XFeatDenseDescriptor d({.model = vmap::test::model_path(file)}); });
      CHECK(e.find(file) != std::string::npos);
      CHECK(e.find("neither a fixed-size nor an any-size XFeat") != std::string::npos);
      CHECK(error_of([&] { vmap::XFeatDenseMatcher d({.model = vmap::test::model_path(file)}); }).find(file) !=
            std::string::npos);
    }
    CHECK(error_of([] { vmap::XFeatDenseDescriptor d({.model = "/nonexistent/x.onnx"}); }).find("/nonexistent/x.onnx") !=
          std::string::npos);
  }
}
