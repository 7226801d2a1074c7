#include <vmap/io/poses.hpp>
#include <vmap/lcd/evaluation.hpp>
#include <vmap/lcd/sequence.hpp>
#include <vmap/memory/sequence.hpp>
#include <vmap/memory/stacks.hpp>
#include <vmap/memory/visual_memory.hpp>

#include "support/errors.hpp"
#include "support/frames.hpp"
#include "support/shared_data.hpp"

#include <doctest/doctest.h>

#include <cmath>
#include <cstdio>
#include <span>
#include <cstddef>
#include <string>
#include <vector>

namespace {

using vmap::SequenceQuery;

// Fisher's combined significance written out for n = 1, 2, 3: p = e^-l (1 + l + l^2/2)
// with l = S ln 10.
double fisher_by_hand(double s, int n) {
  const double l = s * std::log(10.0);
  double sum = 1.0;
  if (n >= 2) sum += l;
  if (n >= 3) sum += l * l / 2.0;
  return s - std::log10(sum);
}

const auto one_chain = [](std::size_t) { return std::size_t{0}; };

// Six queries walking along one chain two key images per query (key 10 + 2q), each with
// evidence 4 there (confidence 0.21 alone), and one distractor of evidence 3 far from
// the others.
std::vector<SequenceQuery> walking_line() {
  const std::size_t distractors[] = {200, 100, 300, 150, 250, 50};  // no two on any line
  std::vector<SequenceQuery> q(6);
  for (std::size_t i = 0; i < 6; ++i) q[i].candidates = {{distractors[i], 3.0}, {10 + 2 * i, 4.0}};
  return q;
}

double confidence_of(double significance) { return 1.0 - std::exp2(-significance / vmap::PlaceDecisionOptions{}.half_significance); }

}  // namespace

TEST_CASE("sequence evidence: Fisher's method combines significances exactly") {
  CHECK(vmap::detail::fisher_significance(0.0, 5) == 0.0);
  CHECK(vmap::detail::fisher_significance(7.5, 1) == doctest::Approx(7.5).epsilon(1e-12));
  CHECK(vmap::detail::fisher_significance(6.0, 2) == doctest::Approx(fisher_by_hand(6.0, 2)).epsilon(1e-12));
  CHECK(vmap::detail::fisher_significance(24.0, 3) == doctest::Approx(fisher_by_hand(24.0, 3)).epsilon(1e-12));
  // More tests for the same sum weigh less.
  CHECK(vmap::detail::fisher_significance(24.0, 6) < vmap::detail::fisher_significance(24.0, 3));
}

TEST_CASE("sequence evidence: a pair weighs the significance of its confidence; one image decides as alone") {
  const vmap::PlaceDecisionOptions d;
  vmap::PlaceEvidence e;
  e.inliers = 30;
  e.matches = 200;
  e.significance = 40.0;
  e.spread = 1.0;
  CHECK(vmap::weighed_significance(e, d) == 40.0);
  e.spread = 0.1;  // bunched: confidence scaled by 0.1 / 0.35
  CHECK(confidence_of(vmap::weighed_significance(e, d)) == doctest::Approx(vmap::place_confidence(e, d)).epsilon(1e-12));
  CHECK(vmap::weighed_significance(e, d) < 40.0);
  e.inliers = 11;  // below min_inliers
  CHECK(vmap::weighed_significance(e, d) == 0.0);
  // What the answer decides, for an image that alone was ambiguous or not.
  vmap::SequenceAnswer a;
  a.confidence = 0.8;
  a.on_line = 1;
  CHECK(vmap::sequence_reason(a, vmap::PlaceStatus::unknown_place, d) == vmap::DecisionReason::confident);
  CHECK(vmap::sequence_reason(a, vmap::PlaceStatus::ambiguous, d) == vmap::DecisionReason::two_places);
  a.on_line = 3;
  CHECK(vmap::sequence_reason(a, vmap::PlaceStatus::ambiguous, d) == vmap::DecisionReason::confident);
  a.second = 1;
  a.second_confidence = 0.75;  // another place's line nearly as confident
  CHECK(vmap::sequence_reason(a, vmap::PlaceStatus::ambiguous, d) == vmap::DecisionReason::two_places);
  a.confidence = 0.4;
  CHECK(vmap::sequence_reason(a, vmap::PlaceStatus::accepted, d) == vmap::DecisionReason::low_confidence);
}

TEST_CASE("sequence evidence: queries on a line raise each other above the threshold") {
  const vmap::PlaceDecisionOptions d;
  const auto answers = vmap::sequence_evidence(walking_line(), one_chain, {.window = 6}, d);
  REQUIRE(answers.size() == 6);
  for (std::size_t i = 0; i < 6; ++i) {
    CAPTURE(i);
    REQUIRE(answers[i].candidate.has_value());
    CHECK(*answers[i].candidate == 1);  // the key on the line, not the distractor
    CHECK(answers[i].window == 6);
    CHECK(answers[i].weighed == 6);
    CHECK(answers[i].on_line == 6);
    // Each neighbour vouches with its own 4: S = 24 over n = 6.
    CHECK(answers[i].significance == doctest::Approx(vmap::detail::fisher_significance(24.0, 6)).epsilon(1e-12));
    CHECK(answers[i].confidence == doctest::Approx(confidence_of(answers[i].significance)).epsilon(1e-12));
    CHECK(answers[i].confidence >= d.min_confidence);
    CHECK(confidence_of(4.0) < d.min_confidence);  // alone, none would be accepted
  }
  // The same line moving faster than max_speed is no line: each query stands alone among six.
  const auto slow = vmap::sequence_evidence(walking_line(), one_chain, {.window = 6, .line = {.max_speed = 1.0}}, d);
  for (const auto& a : slow) {
    CHECK(a.on_line == 1);
    CHECK(a.significance == doctest::Approx(vmap::detail::fisher_significance(4.0, 6)).epsilon(1e-12));
  }
}

TEST_CASE("sequence evidence: an image off its neighbours' line is lowered, and lowers the line") {
  auto q = walking_line();
  q[3].candidates = {{80, 6.0}};  // query 3 sees another place, more strongly than the line's queries
  const auto answers = vmap::sequence_evidence(q, one_chain, {.window = 6}, {});
  REQUIRE(answers[3].candidate == 0);
  CHECK(answers[3].on_line == 1);
  CHECK(answers[3].significance == doctest::Approx(vmap::detail::fisher_significance(6.0, 6)).epsilon(1e-12));
  CHECK(answers[3].significance < 6.0);  // below what it says alone
  for (std::size_t i : {0, 1, 2, 4, 5}) {
    CAPTURE(i);
    CHECK(answers[i].on_line == 5);
    CHECK(answers[i].significance == doctest::Approx(vmap::detail::fisher_significance(20.0, 6)).epsilon(1e-12));
  }
  // A query that verified nothing neither raises nor lowers the line.
  q[3].candidates.clear();
  const auto gap = vmap::sequence_evidence(q, one_chain, {.window = 6}, {});
  CHECK_FALSE(gap[3].candidate.has_value());
  CHECK(gap[0].weighed == 5);
  CHECK(gap[0].significance == doctest::Approx(vmap::detail::fisher_significance(20.0, 5)).epsilon(1e-12));
}

TEST_CASE("sequence evidence: two places, a neighbour vouches no more than the image, an accepted image stays") {
  // Two chains (a memory's two sessions) seen along equally strong lines.
  std::vector<SequenceQuery> q(4);
  for (std::size_t i = 0; i < 4; ++i) q[i].candidates = {{10 + i, 5.0}, {110 + i, 5.0}};
  const auto chain = [](std::size_t key) { return key >= 100 ? std::size_t{1} : std::size_t{0}; };
  auto tie = vmap::sequence_evidence(q, chain, {.window = 4}, {});
  for (const auto& a : tie) {
    REQUIRE(a.second.has_value());
    CHECK(a.second_confidence == doctest::Approx(a.confidence).epsilon(1e-12));
  }
  // Without the chains the keys 10 + i and 110 + i would still be 100 key images apart:
  // the line through one never holds the other.
  CHECK(tie[0].on_line == 4);
  for (auto& x : q) x.candidates[1].significance = 8.0;  // the second place is seen better
  const auto won = vmap::sequence_evidence(q, chain, {.window = 4}, {});
  for (const auto& a : won) {
    CHECK(a.candidate == 1);
    CHECK(a.second == 0);
    CHECK(a.second_confidence < a.confidence);
  }
  // A strong neighbour adds no more than the weak image's own evidence.
  std::vector<SequenceQuery> strong(2);
  strong[0].candidates = {{10, 2.0}};
  strong[1].candidates = {{11, 300.0}};
  const auto capped = vmap::sequence_evidence(strong, chain, {.window = 2}, {});
  CHECK(capped[0].significance == doctest::Approx(vmap::detail::fisher_significance(4.0, 2)).epsilon(1e-12));
  // An image accepted alone keeps its key image even where a line passes another.
  auto fixed = walking_line();
  fixed[2].candidates[0].significance = 40.0;
  fixed[2].accepted = 0;
  const auto kept = vmap::sequence_evidence(fixed, one_chain, {.window = 6}, {});
  CHECK(kept[2].candidate == 0);
  CHECK(kept[1].candidate == 1);
}

TEST_CASE("sequence evidence: a trailing window weighs only the queries before") {
  const auto answers =
      vmap::sequence_evidence(walking_line(), one_chain, {.window = 3}, {}, vmap::SequencePlacement::trailing);
  CHECK(answers[0].window == 1);
  CHECK(answers[0].significance == doctest::Approx(4.0).epsilon(1e-12));
  CHECK(answers[1].window == 2);
  CHECK(answers[5].window == 3);
  CHECK(answers[5].significance == doctest::Approx(fisher_by_hand(12.0, 3)).epsilon(1e-12));
  const auto centred = vmap::sequence_evidence(walking_line(), one_chain, {.window = 3}, {});
  CHECK(centred[0].window == 3);  // the first query's window is the first three
}

TEST_CASE("sequence evidence: bad options and candidates are errors naming them") {
  const auto q = walking_line();
  CHECK(vmap::test::error_of([&] { (void)vmap::sequence_evidence(q, one_chain, {.window = 0}, {}); })
            .find("SequenceOptions.window must be in 1..100, got 0") != std::string::npos);
  CHECK(vmap::test::error_of([&] { (void)vmap::sequence_evidence(q, one_chain, {.window = 101}, {}); })
            .find("got 101") != std::string::npos);
  CHECK(vmap::test::error_of([&] { (void)vmap::sequence_evidence(q, one_chain, {.line = {.max_speed = -1.0}}, {}); })
            .find("SequenceOptions.line.max_speed must be finite and >= 0") != std::string::npos);
  auto bad = q;
  bad[2].candidates[1].significance = -1.0;
  CHECK(vmap::test::error_of([&] { (void)vmap::sequence_evidence(bad, one_chain, {}, {}); })
            .find("query 2 has a candidate with significance -1") != std::string::npos);
  bad = q;
  bad[4].accepted = 2;
  CHECK(vmap::test::error_of([&] { (void)vmap::sequence_evidence(bad, one_chain, {}, {}); })
            .find("query 4 was accepted at candidate 2 of 2") != std::string::npos);
}

TEST_CASE("sequence evidence in a memory: answers are rewritten with the line's key image and status") {
  const vmap::PlaceDecisionOptions d;
  // Three images alone: unknown places (evidence 5 each, 40 inliers, full spread), the
  // line's key image second in the middle one's matches.
  std::vector<vmap::MemoryLocalization> singles(3);
  const auto add = [](vmap::MemoryLocalization& a, std::uint32_t key, double significance) {
    vmap::PlaceLink l;
    l.key = key;
    l.inliers = 40;
    l.confidence = confidence_of(significance);
    a.matches.push_back(l);
    vmap::PlaceEvidence e;
    e.inliers = 40;
    e.matches = 200;
    e.significance = significance;
    e.spread = 1.0;
    a.match_evidence.push_back(e);
  };
  for (std::size_t i = 0; i < 3; ++i) {
    singles[i].status = vmap::PlaceStatus::unknown_place;
    singles[i].reason_code = vmap::DecisionReason::low_confidence;
  }
  add(singles[0], 20, 5.0);
  add(singles[1], 60, 5.5);  // a look-alike, slightly stronger alone
  add(singles[1], 21, 5.0);
  add(singles[2], 22, 5.0);
  for (auto& a : singles) a.confidence = a.matches.front().confidence, a.evidence = a.match_evidence.front();
  const std::vector<vmap::MemorySession> sessions{{0, 0}};
  const auto answers = vmap::with_sequence_evidence(singles, sessions, {.window = 3}, d);
  REQUIRE(answers[1].sequence.has_value());
  CHECK(answers[1].ok());
  CHECK(answers[1].best()->key == 21);
  CHECK(answers[1].matches[1].key == 60);
  CHECK(answers[1].evidence.significance == 5.0);
  CHECK(answers[1].sequence->single_key == 60);
  CHECK(answers[1].sequence->single_confidence == doctest::Approx(confidence_of(5.5)).epsilon(1e-12));
  CHECK(answers[1].sequence->on_line == 3);
  CHECK(answers[1].confidence == doctest::Approx(confidence_of(fisher_by_hand(15.0, 3))).epsilon(1e-12));
  char reason[96];
  std::snprintf(reason, sizeof reason, "3 of 3 images with evidence on the line: confidence %.2f >= 0.50",
                answers[1].confidence);
  CHECK(answers[1].reason == reason);
  // A window of 1 is each image alone.
  const auto alone = vmap::with_sequence_evidence(singles, sessions, {.window = 1}, d);
  CHECK_FALSE(alone[1].sequence.has_value());
  CHECK(alone[1].matches.front().key == 60);
  // localize_window over answers decides the last one with all of them.
  struct Sessions {
    std::vector<vmap::MemorySession> s;
    vmap::MemoryOptions o;
    const std::vector<vmap::MemorySession>& sessions() const { return s; }
    const vmap::MemoryOptions& options() const { return o; }
  } memory{sessions, {}};
  const vmap::MemoryLocalization last = vmap::localize_window(memory, std::span<const vmap::MemoryLocalization>(singles));
  CHECK(last.sequence->window == 3);
  CHECK(last.confidence == doctest::Approx(confidence_of(fisher_by_hand(15.0, 3))).epsilon(1e-12));
  // Answers whose evidence does not match their matches are refused.
  auto broken = singles;
  broken[2].match_evidence.clear();
  CHECK(vmap::test::error_of([&] { (void)vmap::with_sequence_evidence(broken, sessions, {.window = 3}, d); })
            .find("answer 2 has 1 matches but evidence for 0") != std::string::npos);
}

TEST_SUITE("data") {
  TEST_CASE("sequence evidence: held-out runs of tum_fr3_cabinet_kf are placed where single images are not") {
    // The memory of the nearly textureless cabinet without every 5th frame; the held-out
    // frames in order, alone and as a sequence (examples/results/localize.md).
    const auto frames = vmap::test::grey_frames(vmap::test::data_path("tum_fr3_cabinet_kf/rgb.txt"));
    vmap::OrbVisualMemory memory;
    std::vector<cv::Mat> held;
    std::vector<std::size_t> held_index;
    for (const vmap::Frame& f : frames) {
      if (f.index % 5 == 2) {
        held.push_back(f.image);
        held_index.push_back(f.index);
      } else {
        memory.push(f);
      }
    }
    REQUIRE(held.size() == 12);
    const vmap::LoopGroundTruth same = vmap::ground_truth_from_poses(
        vmap::load_tum_poses(vmap::test::data_path("tum_fr3_cabinet_kf/truth_cam_poses.txt")),
        {.max_distance = 0.5, .max_angle_deg = 30, .window = 0});
    const auto right = [&](const vmap::MemoryLocalization& a, std::size_t frame) {
      const std::size_t k = memory.map().keys[a.best()->key].frame_index;
      return frame == k || same(std::max(frame, k), std::min(frame, k));
    };
    std::size_t alone = 0, placed = 0;
    for (std::size_t i = 0; i < held.size(); ++i) alone += memory.localize(held[i]).ok() ? 1 : 0;
    const auto answers = vmap::localize_sequence(memory, std::span<const cv::Mat>(held));
    for (std::size_t i = 0; i < answers.size(); ++i) {
      CAPTURE(held_index[i]);
      REQUIRE(answers[i].sequence.has_value());
      if (!answers[i].ok()) continue;
      ++placed;
      CHECK(right(answers[i], held_index[i]));
    }
    // Measured: 7 of 12 alone, 10 of 12 as a sequence (window 8), every one right.
    CHECK(alone <= 8);
    CHECK(placed >= 9);
    CHECK(placed > alone);
    // The same window trailing, as a robot decides its newest frame, from its answers.
    std::vector<vmap::MemoryLocalization> singles;
    for (const cv::Mat& image : held) singles.push_back(memory.localize(image));
    const auto streamed = vmap::with_sequence_evidence(singles, memory.sessions(), {.window = 8}, memory.options().loops.decision,
                                                       vmap::SequencePlacement::trailing);
    const std::span<const vmap::MemoryLocalization> last8(singles.data() + 4, 8);
    const vmap::MemoryLocalization newest = vmap::localize_window(memory, last8);
    CHECK(newest.status == streamed.back().status);
    CHECK(newest.confidence == streamed.back().confidence);
    // A foreign sequence (every 10th frame of rtabmap_loop, in order) is placed nowhere.
    const auto foreign = vmap::test::grey_frames(vmap::test::data_path("rtabmap_loop/images"), 10);
    std::vector<cv::Mat> theirs;
    for (const vmap::Frame& f : foreign) theirs.push_back(f.image);
    for (const auto& a : vmap::localize_sequence(memory, std::span<const cv::Mat>(theirs))) CHECK_FALSE(a.ok());
  }
}
