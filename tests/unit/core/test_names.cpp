// Every enum that has a to_string reads its names back with from_string (core/names.hpp):
// each enumerator with the text files, JSON and messages print for it, and nothing else.

#include <vmap/core/names.hpp>
#include <vmap/core/verification.hpp>
#include <vmap/geometry/camera.hpp>
#include <vmap/io/bag/types.hpp>
#include <vmap/keyframe/selector.hpp>
#include <vmap/lcd/loop_engine.hpp>
#include <vmap/lcd/place_decision.hpp>
#include <vmap/matching/hamming.hpp>
#include <vmap/place/bow.hpp>
#include <vmap/som/nearest_wall.hpp>

#include <doctest/doctest.h>

#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace {

/// Each enumerator of T with its text: to_string writes exactly that text, from_string
/// reads it back, and the table holds no other value.
template <class T>
void round_trip(const std::vector<std::pair<T, std::string_view>>& expected) {
  for (const auto& [value, text] : expected) {
    INFO("text: " << std::string(text));
    CHECK(std::string_view(vmap::to_string(value)) == text);
    CHECK(vmap::from_string<T>(text) == value);
    CHECK_FALSE(vmap::from_string<T>(std::string(text) + "x").has_value());
  }
  for (const auto& [value, text] : vmap::names_of(T{}).entries) {
    bool listed = false;
    for (const auto& e : expected) listed = listed || e.first == value;
    CHECK_MESSAGE(listed, "a value of the table is not in the test: " << std::string(text));
  }
  CHECK_FALSE(vmap::from_string<T>("").has_value());
  CHECK_FALSE(vmap::from_string<T>("no such name").has_value());
}

}  // namespace

TEST_CASE("names: to_string and from_string agree for every enumerator") {
  using vmap::HammingLevel;
  round_trip<HammingLevel>({{HammingLevel::portable, "portable"},
                            {HammingLevel::popcnt, "popcnt"},
                            {HammingLevel::avx2, "avx2"},
                            {HammingLevel::avx512, "avx512"}});
  using vmap::BowScoring;
  round_trip<BowScoring>({{BowScoring::l1, "l1"}, {BowScoring::l2, "l2"}, {BowScoring::cosine, "cosine"}});
  using vmap::WallSide;
  round_trip<WallSide>({{WallSide::left, "left"}, {WallSide::right, "right"}});
  using vmap::PlaceModel;
  round_trip<PlaceModel>({{PlaceModel::fundamental, "fundamental"}, {PlaceModel::essential, "essential"}});
  using vmap::PlaceStatus;
  round_trip<PlaceStatus>({{PlaceStatus::accepted, "accepted"},
                           {PlaceStatus::unknown_place, "unknown place"},
                           {PlaceStatus::ambiguous, "ambiguous"},
                           {PlaceStatus::too_little_evidence, "too little evidence"},
                           {PlaceStatus::not_a_revisit, "not a revisit"}});
  using vmap::CandidateStage;
  round_trip<CandidateStage>({{CandidateStage::chosen, "chosen"},
                              {CandidateStage::not_in_top_k, "not in top k"},
                              {CandidateStage::below_bow_score, "below bag-of-words score"},
                              {CandidateStage::verification_failed, "verification failed"},
                              {CandidateStage::weaker, "less confidence than the chosen one"},
                              {CandidateStage::not_a_revisit, "not a revisit"}});
  using vmap::CandidateIndex;
  round_trip<CandidateIndex>({{CandidateIndex::tree, "tree"},
                              {CandidateIndex::tree_ranked, "tree_ranked"},
                              {CandidateIndex::bow, "bow"},
                              {CandidateIndex::brute_force, "brute_force"}});
  using vmap::LensModel;
  round_trip<LensModel>({{LensModel::pinhole, "pinhole (radial-tangential)"},
                         {LensModel::fisheye, "fisheye (equidistant, Kannala-Brandt)"}});
  using vmap::BagFormat;
  round_trip<BagFormat>({{BagFormat::ros1, "ROS 1 bag 2.0"},
                         {BagFormat::rosbag2_sqlite, "rosbag2 sqlite3"},
                         {BagFormat::mcap, "MCAP"}});
  using vmap::VerificationStatus;
  round_trip<VerificationStatus>({{VerificationStatus::verified, "verified"},
                                  {VerificationStatus::too_few_matches, "too few matches"},
                                  {VerificationStatus::no_model, "no model"},
                                  {VerificationStatus::too_few_inliers, "too few inliers"}});
  using vmap::Degeneracy;
  round_trip<Degeneracy>(
      {{Degeneracy::none, "none"}, {Degeneracy::homography, "homography (planar scene or pure rotation)"}});
  using vmap::KeyReason;
  round_trip<KeyReason>({{KeyReason::none, "similar to the key image"},
                         {KeyReason::first_frame, "first frame"},
                         {KeyReason::below_threshold, "similarity below tau"},
                         {KeyReason::bound_below_threshold, "match bound below tau (verification skipped)"},
                         {KeyReason::verification_failed, "verification failed"}});
}

TEST_CASE("names: an old spelling reads back but is neither written nor offered") {
  CHECK(vmap::from_string<vmap::CandidateIndex>("all") == vmap::CandidateIndex::brute_force);
  CHECK(vmap::names_of(vmap::CandidateIndex{}).choices() == "tree, tree_ranked, bow or brute_force");
  CHECK(vmap::names_of(vmap::WallSide{}).choices() == "left or right");
}
