// Real frames: ORB bags of words of rtabmap_loop rank a true loop frame (from the
// ground-truth matrix) among the first 3 for most loop queries, with a vocabulary
// learned on the sequence itself and one learned on other data (tum_fr1_rpy).

#include <vmap/features/orb.hpp>
#include <vmap/features/sift.hpp>
#include <vmap/lcd/evaluation.hpp>
#include <vmap/place/database.hpp>
#include <vmap/place/vocabulary.hpp>

#include "place_support.hpp"

#include <doctest/doctest.h>

#include <opencv2/imgcodecs.hpp>

#include <filesystem>
#include <string>
#include <vector>

namespace {

template <class D>
std::vector<cv::Mat> descriptors_of(const std::vector<std::filesystem::path>& images, D descriptor) {
  std::vector<cv::Mat> out;
  for (const auto& p : images) {
    const cv::Mat img = cv::imread(p.string(), cv::IMREAD_GRAYSCALE);
    REQUIRE_MESSAGE(!img.empty(), "cannot read " << p.string());
    out.push_back(descriptor.extract(img).descriptors);
  }
  return out;
}

std::vector<cv::Mat> orb_descriptors(const std::vector<std::filesystem::path>& images) {
  return descriptors_of(images, vmap::OrbDescriptor({.features = 1000}));
}

std::vector<std::filesystem::path> rtabmap_frames() {
  std::vector<std::filesystem::path> seq;
  for (int i = 1; i <= 84; ++i) seq.push_back(vmap::test::data_path("rtabmap_loop/images/" + std::to_string(i) + ".jpg"));
  return seq;
}

/// Share of the loop queries (frames with a ground-truth loop) whose top 3 among the
/// frames older than `window` frames hold a true loop frame.
template <class Vocabulary>
double top3_hit_rate(const Vocabulary& voc, const std::vector<cv::Mat>& frames,
                     const vmap::LoopGroundTruth& gt, std::size_t window, std::size_t& queries) {
  vmap::PlaceDatabase<std::uint32_t> db(voc.size());
  std::size_t hits = 0;
  queries = 0;
  for (std::size_t q = 0; q < frames.size(); ++q) {
    const vmap::BowVector b = voc.transform(frames[q]);
    if (gt.has_loop(q) && q > window) {
      ++queries;
      const auto top = db.query(b, 3, {.before = static_cast<std::uint32_t>(q - window)});
      for (const auto& m : top)
        if (gt(q, m.id)) {
          ++hits;
          break;
        }
    }
    db.add(static_cast<std::uint32_t>(q), b);
  }
  return queries == 0 ? 0.0 : static_cast<double>(hits) / static_cast<double>(queries);
}

}  // namespace

TEST_SUITE("data") {
  TEST_CASE("rtabmap_loop: the bag of words ranks a true loop frame in the top 3") {
    const auto frames = orb_descriptors(rtabmap_frames());
    const auto gt = vmap::LoopGroundTruth::load(vmap::test::data_path("rtabmap_loop/gt_loop_matrix_84x84.txt"), 84);

    // a vocabulary learned on the sequence itself (k = 10, L = 3)
    const auto own = vmap::BinaryVocabularyTree::learn(frames, {.branching = 10, .depth = 3, .seed = 1});
    CHECK(own.size() > 500);
    std::size_t queries = 0;
    const double own_rate = top3_hit_rate(own, frames, gt, 10, queries);
    MESSAGE("own vocabulary (" << own.size() << " words): top-3 hit rate " << own_rate << " over " << queries << " loop queries");
    CHECK(queries >= 40);
    CHECK(own_rate >= 0.9);  // measured 43 of 44 (0.977)

    // a vocabulary learned on other images (every 8th frame of tum_fr1_rpy)
    std::vector<std::filesystem::path> other;
    for (const auto& e : std::filesystem::directory_iterator(vmap::test::data_path("tum_fr1_rpy/rgb"))) other.push_back(e.path());
    std::sort(other.begin(), other.end());
    std::vector<std::filesystem::path> every8;
    for (std::size_t i = 0; i < other.size(); i += 8) every8.push_back(other[i]);
    const auto foreign = vmap::BinaryVocabularyTree::learn(orb_descriptors(every8), {.branching = 10, .depth = 3, .seed = 1});
    auto with_own_idf = foreign;
    with_own_idf.learn_idf(frames);  // the idf of the map being built, as a running system would
    const double foreign_rate = top3_hit_rate(foreign, frames, gt, 10, queries);
    const double foreign_idf_rate = top3_hit_rate(with_own_idf, frames, gt, 10, queries);
    MESSAGE("tum_fr1_rpy vocabulary (" << foreign.size() << " words): top-3 hit rate " << foreign_rate
                                       << ", with the sequence's idf " << foreign_idf_rate);
    CHECK(foreign_rate >= 0.85);  // measured 0.977
    CHECK(foreign_idf_rate >= 0.85);  // measured 0.932
  }

  TEST_CASE("rtabmap_loop: a float (SIFT) vocabulary ranks a true loop frame in the top 3") {
    const auto frames = descriptors_of(rtabmap_frames(), vmap::SiftDescriptor({.features = 500}));
    const auto gt = vmap::LoopGroundTruth::load(vmap::test::data_path("rtabmap_loop/gt_loop_matrix_84x84.txt"), 84);
    const auto voc = vmap::FloatVocabularyTree::learn(frames, {.branching = 10, .depth = 3, .seed = 1});
    CHECK(voc.descriptor_cols() == 128);
    CHECK(voc.size() > 500);
    std::size_t queries = 0;
    const double rate = top3_hit_rate(voc, frames, gt, 10, queries);
    MESSAGE("SIFT 500, own vocabulary (" << voc.size() << " words): top-3 hit rate " << rate << " over " << queries
                                         << " loop queries");
    CHECK(queries >= 40);
    CHECK(rate >= 0.85);  // measured 42 of 44 (0.955)
  }
}
