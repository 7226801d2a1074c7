#pragma once

// The one loop engine (examples/methods.md, sec. 4): "same place?" for loop closure over a stream
// of key frames and for localization of a single image, used by LoopDetector (over its
// frames) and by VisualMemory (over its key images).
//
// Per query: candidates from one of four sources -> verification of each by the stack's
// matcher and estimator -> the evidence of each verified candidate (lcd/place_decision.hpp)
// -> one decision with a status, a reason and a confidence:
//   tree         every frame of the query's leaf of the binary classified tree, after
//                backtracking to m frames (LFM-LCD, Zhu et al., Sensors 2021, sec. 3.3);
//   tree_ranked  the same frames ranked by bag-of-words score, the top k verified;
//   bow          every indexed frame ranked by bag-of-words score (no labels), the top k
//                verified (DBoW2's query; iBoW-LCD and ORB-SLAM3 verify a handful too);
//   brute_force  every frame older than the window (the reference).
//
// Loops only (not localization):
//   - the revisit rule: a loop needs the camera to have left the candidate's place and
//     come back, and geometry says so, not the vocabulary. Each frame belongs to a view
//     of the chain; the owner says when a frame starts a new one (a visual memory: every
//     key image, the selector took it because the view changed; LoopDetector: a frame
//     whose eq. 5 similarity to its view's first frame falls below the selector's tau).
//     Candidate j was left when the first frame of some view between j and the query
//     sees j (eq. 5 similarity, verified with the stack's matcher and estimator) less
//     than `left_ratio` times the query does. A camera that rests or hovers never
//     changes views (and the run is stationary); one that drives on sees j less with
//     every view, so the query does not see it better than they did; one that went
//     elsewhere, or turned away on the spot, shares nothing with j in between. Only
//     candidates confident enough to be accepted are tested (one verification per view
//     start, once per candidate: the lowest similarity is kept). The window stays as an
//     option (frames just before the query are not candidates at all).
//   - temporal consistency (DBoW2's islands, place/consistency.hpp): a loop stands when the
//     `temporal_consistency` previous queries also placed themselves near it.
//
// The engine borrows each frame's Features through a lookup (a callable id -> const
// Features&, as nanoflann's dataset adaptor), so its owner keeps them once.

#include <vmap/core/concepts.hpp>
#include <vmap/core/error.hpp>
#include <vmap/core/features.hpp>
#include <vmap/core/names.hpp>
#include <vmap/geometry/calibrated.hpp>
#include <vmap/geometry/essential.hpp>
#include <vmap/geometry/similarity.hpp>
#include <vmap/io/binary.hpp>
#include <vmap/keyframe/front_end.hpp>
#include <vmap/lcd/binary_tree.hpp>
#include <vmap/lcd/label_vector.hpp>
#include <vmap/lcd/options.hpp>
#include <vmap/lcd/place_decision.hpp>
#include <vmap/lcd/place_ranking.hpp>
#include <vmap/place/consistency.hpp>
#include <vmap/place/match.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cmath>
#include <concepts>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <type_traits>
#include <utility>
#include <vector>

namespace vmap {

/// Why one candidate frame was not the answer.
enum class CandidateStage : std::uint8_t {
  chosen,               ///< the answer's candidate (the best place)
  not_in_top_k,         ///< ranked below the top k
  below_bow_score,      ///< its bag-of-words score is below min_bow_score
  verification_failed,  ///< no geometric model
  weaker,               ///< verified, but another candidate had more confidence
  not_a_revisit,        ///< verified, but the camera never left its place
};

/// The stages' names, in words (core/names.hpp).
[[nodiscard]] constexpr auto names_of(CandidateStage) noexcept {
  using S = CandidateStage;
  return detail::NameTable<CandidateStage, 6>{{{{S::chosen, "chosen"},
                                                {S::not_in_top_k, "not in top k"},
                                                {S::below_bow_score, "below bag-of-words score"},
                                                {S::verification_failed, "verification failed"},
                                                {S::weaker, "less confidence than the chosen one"},
                                                {S::not_a_revisit, "not a revisit"}}}};
}
[[nodiscard]] constexpr std::string_view to_string(CandidateStage s) noexcept { return names_of(s).name(s); }

/// One candidate that reached the ranking or verification stage.
struct PlaceCandidate {
  std::size_t frame = 0;
  double bow_score = 0.0;  ///< 0 for unranked sources
  int inliers = 0;         ///< 0 unless verified
  double confidence = 0.0;
  CandidateStage stage = CandidateStage::not_in_top_k;
  int matches = 0;         ///< tentative correspondences verified (0 before verification)
  /// The verification's status and model (F, or E with a calibrated estimator; zeros
  /// unless verified).
  VerificationStatus status = VerificationStatus::too_few_matches;
  cv::Matx33d model = cv::Matx33d::zeros();
  PlaceEvidence evidence{};  ///< what the verification says (zeros unless verified)
};

/// The answer for one query (a frame of the stream, or an image to localize).
struct PlaceDecision {
  PlaceStatus status = PlaceStatus::too_little_evidence;
  DecisionReason reason_code = DecisionReason::no_candidates;  ///< why, as a value a program can act on
  std::string reason = "no candidates";  ///< why, in words with the numbers (e.g. "confidence 0.31 < 0.50")
  double confidence = 0.0;               ///< of the best place, in [0, 1]
  std::optional<std::size_t> best;       ///< the best place's frame (verified), if any
  PlaceEvidence evidence;                ///< of `best`
  Verification verification;             ///< of `best` (the model: F, or E with a calibrated estimator)
  /// The tentative matches of `best` that `verification` weighed (its inlier_mask is
  /// aligned with them): queryIdx indexes the query's features, trainIdx the best's.
  Matches best_matches;
  std::optional<std::size_t> second;     ///< the best other place, if verified
  double second_confidence = 0.0;
  std::size_t candidates = 0;            ///< frames the source proposed
  std::size_t not_in_top_k = 0;
  std::size_t below_bow_score = 0;
  std::size_t verifications = 0;
  std::size_t failed_verifications = 0;
  std::size_t consistent_queries = 0;    ///< loops: earlier queries that agreed (temporal consistency)
  double rank_ms = 0.0;                  ///< bag of words + ranking
  double verify_ms = 0.0;                ///< matching + verification
  double decide_ms = 0.0;                ///< evidence, revisit rule and decision
  std::vector<PlaceCandidate> considered;

  [[nodiscard]] bool accepted() const noexcept { return status == PlaceStatus::accepted; }
};

/// What a stopped run restores of the loop engine besides each frame's label vector and
/// bag of words (LoopEngine::restore): the revisit counts (queries past the window, left
/// or not) and the temporal-consistency state. Written and read here as the visual
/// memory's section "dcsn" holds it after the decision's options (examples/memory.md,
/// "The single-file format (.vmem)").
struct LoopEngineState {
  std::size_t past_window = 0;   ///< queries past the window
  std::size_t left_queries = 0;  ///< of those, queries with a candidate whose place the camera had left
  std::size_t not_revisit = 0;   ///< of those, queries whose best verified candidate was not a revisit
  ConsistencyState<std::size_t> consistency{};

  void write(detail::BinaryWriter& w) const {
    w.u64(past_window);
    w.u64(left_queries);
    w.u64(not_revisit);
    // Field by field (GCC 12 at -O2 reports a copy of the state's std::optional as
    // possibly uninitialised).
    std::uint64_t last = 0;
    if (consistency.last.has_value()) last = *consistency.last;
    w.i32(consistency.consecutive);
    w.u8(consistency.last.has_value() ? 1 : 0);
    w.u64(last);
    w.u64(consistency.island_begin);
    w.u64(consistency.island_end);
    w.u8(consistency.accepted ? 1 : 0);
  }

  /// Reads write()'s bytes for an engine that has checked `frames` frames (the key
  /// images a memory's database holds): the counts and the state must fit them.
  [[nodiscard]] static LoopEngineState read(detail::BinaryReader& r, std::size_t frames) {
    LoopEngineState s;
    s.past_window = static_cast<std::size_t>(r.u64("queries past the window"));
    s.left_queries = static_cast<std::size_t>(r.u64("queries that left"));
    s.not_revisit = static_cast<std::size_t>(r.u64("queries not revisits"));
    if (s.past_window > frames || s.left_queries + s.not_revisit > s.past_window)
      r.corrupt("query counts do not fit the key images checked");
    s.consistency.consecutive = r.i32("consistent queries");
    const std::uint8_t has_last = r.u8("consistency flag");
    if (has_last > 1) r.corrupt("consistency flag is not 0 or 1");
    const std::uint64_t last = r.u64("consistency last");
    if (has_last == 1) s.consistency.last = static_cast<std::size_t>(last);
    s.consistency.island_begin = static_cast<std::size_t>(r.u64("island begin"));
    s.consistency.island_end = static_cast<std::size_t>(r.u64("island end"));
    const std::uint8_t accepted = r.u8("consistency accepted");
    if (accepted > 1) r.corrupt("consistency accepted flag is not 0 or 1");
    s.consistency.accepted = accepted == 1;
    if (s.consistency.consecutive < 0 || static_cast<std::size_t>(s.consistency.consecutive) > frames ||
        s.consistency.island_begin > s.consistency.island_end || s.consistency.island_end > frames ||
        (s.consistency.last && *s.consistency.last >= frames))
      r.corrupt("invalid temporal-consistency state");
    return s;
  }
};

/// Every LoopOptions value the engine accepts; an Error naming `owner` ("LoopOptions") and
/// the option otherwise. The engine checks its options when it is made; a front end checks
/// them before any frame is read.
inline void check_loop_options(const LoopOptions& o, std::string_view owner) {
  detail::check_label_min_score(o.labels.min_score);
  detail::check_place_decision_options(o.decision, owner);
  detail::check(std::isfinite(o.min_bow_score) && o.min_bow_score >= 0,
                [&] { return detail::option_name(owner, ".min_bow_score must be finite and >= 0"); });
  detail::check(std::isfinite(o.left_ratio) && o.left_ratio >= 0 && o.left_ratio <= 1,
                [&] { return detail::option_name(owner, ".left_ratio must be in [0, 1]"); });
  detail::check(o.index <= CandidateIndex::brute_force,
                [&] { return detail::option_name(owner, ".index is not a candidate source"); });
  // The consistency counts queries in an int; a memory's reader applies this same check.
  detail::check(o.temporal_consistency <= max_temporal_consistency, [&] {
    return detail::option_name(owner, ".temporal_consistency must be <= 1000, got ") +
           std::to_string(o.temporal_consistency);
  });
  if (ranks(o.index))
    detail::check(o.top_k >= 1, [&] {
      return detail::option_name(owner, ".top_k must be >= 1 for the ") + std::string(to_string(o.index)) +
             " candidate source";
    });
}

namespace detail {

/// LoopOptions whole, as a saved memory keeps them (memory/detail/record_codecs.hpp):
/// eq. 3's threshold, the window, m, the candidate source, the top k, the BoW floor, the
/// temporal and revisit rules, and the place decision's options. The reader checks
/// them with check_loop_options, as the engine's constructor does.
inline void write_loop_options(BinaryWriter& w, const LoopOptions& o) {
  static_assert(field_count<LoopOptions>() == 10 && field_count<PlaceDecisionOptions>() == 7 &&
                    field_count<LabelVectorOptions>() == 1,
                "a new loop or decision option must be written and read here");
  w.f32(o.labels.min_score);
  w.u64(o.window);
  w.u64(o.min_candidates);
  w.u8(static_cast<std::uint8_t>(o.index));
  w.u64(o.top_k);
  w.f64(o.min_bow_score);
  w.u64(o.temporal_consistency);
  w.u64(o.temporal_tolerance);
  w.f64(o.left_ratio);
  const PlaceDecisionOptions& d = o.decision;
  w.f64(d.min_confidence);
  w.i32(d.min_inliers);
  w.f64(d.chance_inlier_rate);
  w.f64(d.half_significance);
  w.i32(d.spread_grid);
  w.f64(d.full_spread);
  w.f64(d.ambiguity_ratio);
}

/// Reads write_loop_options()'s bytes, checked (check_loop_options) as `owner`.
[[nodiscard]] inline LoopOptions read_loop_options(BinaryReader& r, std::string_view owner) {
  LoopOptions o;
  o.labels.min_score = r.f32("label min_score");
  o.window = static_cast<std::size_t>(r.u64("window"));
  o.min_candidates = static_cast<std::size_t>(r.u64("min_candidates"));
  const std::uint8_t index = r.u8("candidate source");
  if (index > static_cast<std::uint8_t>(CandidateIndex::brute_force)) r.corrupt("unknown candidate source");
  o.index = static_cast<CandidateIndex>(index);
  o.top_k = static_cast<std::size_t>(r.u64("top k"));
  o.min_bow_score = r.f64("min_bow_score");
  o.temporal_consistency = static_cast<std::size_t>(r.u64("temporal_consistency"));
  o.temporal_tolerance = static_cast<std::size_t>(r.u64("temporal_tolerance"));
  o.left_ratio = r.f64("left_ratio");
  PlaceDecisionOptions& d = o.decision;
  d.min_confidence = r.f64("min_confidence");
  d.min_inliers = r.i32("min_inliers");
  d.chance_inlier_rate = r.f64("chance_inlier_rate");
  d.half_significance = r.f64("half_significance");
  d.spread_grid = r.i32("spread_grid");
  d.full_spread = r.f64("full_spread");
  d.ambiguity_ratio = r.f64("ambiguity_ratio");
  try {
    check_loop_options(o, owner);
  } catch (const Error& e) {
    r.corrupt(e.what());
  }
  return o;
}

template <class E>
struct fits_essential : std::false_type {};
template <>
struct fits_essential<EssentialEstimator> : std::true_type {};
template <class Inner>
struct fits_essential<Calibrated<Inner>> : fits_essential<Inner> {};
}  // namespace detail

/// The geometric model an estimator fits: essential for EssentialEstimator (bare or
/// behind Calibrated), fundamental otherwise.
template <class E>
[[nodiscard]] constexpr PlaceModel place_model_of() noexcept {
  return detail::fits_essential<E>::value ? PlaceModel::essential : PlaceModel::fundamental;
}

/// Borrowed features of frame `id`, valid until the lookup's next call (a visual memory
/// that bounds its RAM reads a released key image into one buffer): the engine holds one
/// reference at a time.
template <class L>
concept FeatureLookup = requires(const L& l, std::size_t id) {
  { l(id) } -> std::convertible_to<const Features&>;
};

/// The engine over frames 0, 1, 2, ... added in order. Not thread-safe for add(); one
/// engine per stream.
template <Matcher M, Estimator E, PlaceRanking Rank = PlaceRanker>
class LoopEngine {
 public:
  /// `schema` is needed by the label sources only; `ranker` by the ranked ones.
  LoopEngine(M matcher, E estimator, const LoopOptions& options, Rank ranker = {}, LabelSchema schema = {},
             PlaceModel model = place_model_of<E>())
      : matcher_(std::move(matcher)),
        estimator_(std::move(estimator)),
        ranker_(std::move(ranker)),
        options_(options),
        schema_(std::move(schema)),
        model_(model),
        tree_(schema_.size()),
        consistency_({.required = static_cast<int>(options_.temporal_consistency) + 1,
                      .tolerance = options_.temporal_tolerance}) {
    check_options(options_, "LoopOptions");
    if (ranks(options_.index))
      detail::check(static_cast<bool>(ranker_.ready()), [&] {
        return "LoopOptions.index " + std::string(to_string(options_.index)) +
               " ranks by bag of words and needs a vocabulary; give a ranker with one, or choose the tree or "
               "brute_force source";
      });
  }

  /// check_loop_options (an Error naming `owner` and the option).
  static void check_options(const LoopOptions& o, std::string_view owner) { check_loop_options(o, owner); }

  /// Frame `frames()` (its features `f`, its label vector for the label sources): its
  /// loop decision against the frames before it, then it is indexed. `view` says whether
  /// it starts a new view of the chain (the revisit rule) or stays in the last frame's; a
  /// session's first frame always starts one.
  template <FeatureLookup L>
  PlaceDecision add(const Features& f, const LabelVector& labels, const L& lookup, ViewStep view = ViewStep::new_view) {
    const std::size_t q = frames_;
    views_.push_back(q == 0 ? 0
                     : view == ViewStep::new_view || q == session_start_ ? views_.back() + 1
                                                                          : views_.back());
    PlaceDecision d;
    const auto t0 = std::chrono::steady_clock::now();
    std::optional<typename Rank::Bow> bow;
    if (ranker_.ready()) bow = ranker_.describe(f);
    const std::size_t older = candidates_below(q);
    const std::size_t first = std::min(session_start_, older);  // candidates are frames [first, older)
    // Frames that just left the window become tree candidates.
    if (uses_labels(options_.index))
      while (tree_next_ < older) tree_.insert(labels_[tree_next_], tree_next_), ++tree_next_;

    std::vector<std::pair<std::size_t, double>> to_verify;
    switch (options_.index) {
      case CandidateIndex::tree:
        for (std::size_t j : tree_.candidates(labels, options_.min_candidates)) to_verify.emplace_back(j, 0.0);
        d.candidates = to_verify.size();
        break;
      case CandidateIndex::brute_force:
        for (std::size_t j = first; j < older; ++j) to_verify.emplace_back(j, 0.0);
        d.candidates = to_verify.size();
        break;
      case CandidateIndex::tree_ranked:
      case CandidateIndex::bow: {
        std::vector<std::size_t> leaf;
        if (options_.index == CandidateIndex::tree_ranked) {
          leaf = tree_.candidates(labels, options_.min_candidates);
          d.candidates = leaf.size();
        } else {
          d.candidates = older - first;
        }
        if (d.candidates == 0) break;
        const std::vector<PlaceMatch<std::size_t>> ranked = ranker_.rank(
            *bow, options_.top_k, options_.index == CandidateIndex::tree_ranked ? &leaf : nullptr, older, first);
        d.not_in_top_k = d.candidates - std::min(d.candidates, ranked.size());
        for (const PlaceMatch<std::size_t>& r : ranked) {
          if (r.score < options_.min_bow_score) {
            ++d.below_bow_score;
            d.considered.push_back({r.id, r.score, 0, 0.0, CandidateStage::below_bow_score});
            continue;
          }
          to_verify.emplace_back(r.id, r.score);
        }
        break;
      }
    }
    d.rank_ms = ms_since(t0);
    std::vector<Verified> verified = verify(d, f, to_verify, lookup, options_.decision);
    const auto td = std::chrono::steady_clock::now();
    const bool stayed = filter_revisits(d, verified, f, lookup);
    choose(d, verified, lookup, stayed, !to_verify.empty(), options_.decision);
    apply_temporal_consistency(d);
    d.decide_ms = ms_since(td);

    labels_.push_back(uses_labels(options_.index) ? labels : LabelVector{});
    if (bow) ranker_.add(q, *bow);
    ++frames_;
    verifications_ += d.verifications;
    return d;
  }

  /// Where image features `q` were taken, among every frame added: the best `top_k` frames
  /// by bag-of-words score are verified and decided; without a ranker every one of the
  /// `unranked` frames the lookup knows (default: the frames added). No revisit rule, no
  /// temporal consistency: a single image. `decision` overrides the options' decision for
  /// this query.
  template <FeatureLookup L>
  PlaceDecision localize(const Features& q, std::size_t top_k, const L& lookup,
                         std::optional<std::size_t> unranked = std::nullopt,
                         const PlaceDecisionOptions* decision = nullptr) const {
    const PlaceDecisionOptions& dec = decision ? *decision : options_.decision;
    if (decision) detail::check_place_decision_options(*decision, "LoopEngine::localize");
    detail::check(top_k >= 1, "LoopEngine::localize: top_k must be >= 1");
    PlaceDecision d;
    const auto t0 = std::chrono::steady_clock::now();
    std::vector<std::pair<std::size_t, double>> to_verify;
    std::optional<typename Rank::Bow> bow;
    if (ranker_.ready()) {
      bow = ranker_.describe(q);
      for (const PlaceMatch<std::size_t>& r : ranker_.rank(*bow, top_k, nullptr)) to_verify.emplace_back(r.id, r.score);
      d.candidates = frames_;
      d.not_in_top_k = frames_ - std::min(frames_, to_verify.size());
    } else {
      d.candidates = unranked.value_or(frames_);
      for (std::size_t j = 0; j < d.candidates; ++j) to_verify.emplace_back(j, 0.0);
    }
    d.rank_ms = ms_since(t0);
    decide_among(d, q, to_verify, lookup, dec);
    return d;
  }

  /// Where image features `q` were taken among the candidates `ranked` (an id the lookup
  /// knows and its bag-of-words score, best first), ranked elsewhere: each is verified
  /// and the place decided as localize() decides (a single image: no revisit rule, no
  /// temporal consistency). The place rule between runs decides each pair with it, a
  /// single candidate at a time (VisualMemory::link_pair).
  template <FeatureLookup L>
  PlaceDecision decide(const Features& q, const std::vector<std::pair<std::size_t, double>>& ranked, const L& lookup,
                       const PlaceDecisionOptions* decision = nullptr) const {
    const PlaceDecisionOptions& dec = decision ? *decision : options_.decision;
    if (decision) detail::check_place_decision_options(*decision, "LoopEngine::decide");
    PlaceDecision d;
    d.candidates = ranked.size();
    decide_among(d, q, ranked, lookup, dec, false);
    return d;
  }

  /// The state a saved run ended with: the label vector of each frame indexed so far
  /// (the ranker already holds their bags of words), the revisit counts and the
  /// temporal-consistency state, and the first frame of the last frame's session
  /// (begin_session). The tree is rebuilt exactly: the frames the last query had
  /// inserted, in order. Every restored frame is a view of its own, as a visual memory's
  /// key images are (add()).
  void restore(std::vector<LabelVector> labels, const LoopEngineState& state, std::size_t session_start = 0) {
    const std::size_t past_window = state.past_window, left_queries = state.left_queries,
                      not_revisit = state.not_revisit;
    detail::check(frames_ == 0, "LoopEngine::restore: frames were added already");
    detail::check(session_start <= labels.size(), "LoopEngine::restore: the session starts after the last frame");
    detail::check(not_revisit + left_queries <= past_window && past_window <= labels.size(),
                  "LoopEngine::restore: inconsistent revisit counts");
    for (const LabelVector& v : labels)
      detail::check(!uses_labels(options_.index) || v.size() == schema_.size(),
                    "LoopEngine::restore: a label vector does not fit the schema");
    labels_ = std::move(labels);
    frames_ = labels_.size();
    views_.resize(frames_);
    for (std::size_t k = 0; k < frames_; ++k) views_[k] = static_cast<std::uint32_t>(k);
    past_window_ = past_window;
    left_queries_ = left_queries;
    not_revisit_ = not_revisit;
    set_consistency(state.consistency);
    session_start_ = session_start;
    tree_next_ = session_start;
    if (uses_labels(options_.index) && frames_ > 0)
      while (tree_next_ < candidates_below(frames_ - 1)) tree_.insert(labels_[tree_next_], tree_next_), ++tree_next_;
  }

  /// The next frame starts a session (another run of the robot, memory/visual_memory.hpp):
  /// from it on, a query's candidates are the frames of its own session, as if the engine
  /// started with it (the tree holds them only). What joins two sessions is the place
  /// rule between them, which the owner applies (VisualMemory::link_pair), since a
  /// session's frames have no order in time with another's. Idempotent.
  void begin_session() {
    if (session_start_ == frames_) return;
    session_start_ = frames_;
    tree_.clear();
    tree_next_ = frames_;
    consistency_ = TemporalConsistency<std::size_t>(consistency_.options());
  }
  /// The first frame of the current session (0 for one session).
  [[nodiscard]] std::size_t session_start() const noexcept { return session_start_; }

  /// A new decision (e.g. another confidence threshold) for the queries from now on.
  void set_decision(const PlaceDecisionOptions& decision) {
    detail::check_place_decision_options(decision, "LoopOptions");
    options_.decision = decision;
  }

  [[nodiscard]] std::size_t frames() const noexcept { return frames_; }
  [[nodiscard]] std::size_t verifications() const noexcept { return verifications_; }
  /// The label vector of each frame added (empty vectors for the sources without labels).
  [[nodiscard]] const std::vector<LabelVector>& labels() const noexcept { return labels_; }
  [[nodiscard]] const LoopOptions& options() const noexcept { return options_; }
  [[nodiscard]] const LabelSchema& schema() const noexcept { return schema_; }
  [[nodiscard]] const BinaryClassifiedTree<std::size_t>& tree() const noexcept { return tree_; }
  [[nodiscard]] const Rank& ranker() const noexcept { return ranker_; }
  [[nodiscard]] const M& matcher() const noexcept { return matcher_; }
  [[nodiscard]] const E& estimator() const noexcept { return estimator_; }
  /// The model its verifications fit (F, or E for an essential-matrix estimator).
  [[nodiscard]] PlaceModel model() const noexcept { return model_; }
  [[nodiscard]] const ConsistencyState<std::size_t>& consistency() const noexcept { return consistency_.state(); }
  /// What restore() takes back besides the label vectors.
  [[nodiscard]] LoopEngineState state() const {
    return {past_window_, left_queries_, not_revisit_, consistency_.state()};
  }
  /// Restores the temporal-consistency state (a resumed stream).
  void set_consistency(const ConsistencyState<std::size_t>& s) {
    consistency_ = TemporalConsistency<std::size_t>(consistency_.options(), s);
  }
  /// Queries past the window whose best verified candidate was not a revisit, and all
  /// queries past the window: a camera that never left its place has the two equal.
  [[nodiscard]] std::size_t not_a_revisit_queries() const noexcept { return not_revisit_; }
  [[nodiscard]] std::size_t queries_past_window() const noexcept { return past_window_; }
  /// Queries past the window with a candidate whose place the camera had left.
  [[nodiscard]] std::size_t left_queries() const noexcept { return left_queries_; }
  /// True when at least `window` frames were queried past the window and the current
  /// session's chain never changed views (add()'s ViewStep): the camera
  /// rests or hovers. A stationary sequence is reported as such instead of loops. The
  /// rule is the chain's, so it holds whatever the vocabulary (or without one).
  [[nodiscard]] bool stationary() const noexcept {
    if (frames_ == 0 || past_window_ < std::max<std::size_t>(options_.window, 1)) return false;
    return views_.back() == views_[std::min(session_start_, frames_ - 1)];
  }

  /// The view of frame `j` (add()'s ViewStep): 0 for the first, one more at each change.
  [[nodiscard]] std::size_t view_of(std::size_t j) const {
    detail::check(j < frames_, [&] {
      return "LoopEngine::view_of: frame " + std::to_string(j) + " of " + std::to_string(frames_);
    });
    return views_[j];
  }

  /// Bytes of the engine's own state: label vectors, revisit caches, ranker's index.
  [[nodiscard]] std::size_t memory_bytes() const {
    std::size_t bytes = labels_.capacity() * sizeof(LabelVector) + views_.capacity() * sizeof(std::uint32_t) +
                        left_.capacity() * sizeof(LeftCache) +
                        static_cast<std::size_t>(ranker_.memory_bytes());
    for (const LabelVector& v : labels_) bytes += v.capacity() / 8;
    return bytes;
  }

 private:
  static double ms_since(std::chrono::steady_clock::time_point t0) {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  }

  /// Frames session_start_ <= j < candidates_below(q) are candidates of query q: of its
  /// session, older than the window.
  [[nodiscard]] std::size_t candidates_below(std::size_t q) const noexcept {
    return q > options_.window ? q - options_.window : 0;
  }

  /// What the revisit rule has checked of the view starts after j: every one before
  /// `until`, and `probed` (0: none) beyond it; the lowest eq. 5 similarity any of them
  /// had to j. The query only moves the bar, so a view start is verified against j at
  /// most once.
  struct LeftCache {
    std::size_t until = 0;
    std::size_t probed = 0;
    double lowest = 2.0;
  };

  /// The revisit rule for candidate j of query q, whose eq. 5 similarity to j is
  /// `query_similarity`: some view start between them saw j less than left_ratio times
  /// that. The view start halfway between them is verified first: where the camera went
  /// away and came back, it is the one least likely to see j, so a revisit costs one
  /// verification; otherwise every view start is checked in order.
  template <FeatureLookup L>
  bool left_place(std::size_t j, std::size_t q, double query_similarity, const L& lookup) {
    if (left_.size() < frames_) left_.resize(frames_);
    LeftCache& c = left_[j];
    if (c.until < j + 1) c.until = j + 1;
    const double bar = options_.left_ratio * query_similarity;
    std::optional<Features> candidate;  // j's features, kept: each view start is a lookup too
    const auto similarity_to_j = [&](std::size_t k) {
      if (!candidate) candidate = lookup(j);
      return score_pair(matcher_, estimator_, InlierRatio{}, *candidate, lookup(k), 0.0).similarity;
    };
    if (c.lowest >= bar && c.probed == 0) {
      std::size_t mid = j + (q - j) / 2;
      while (mid > c.until && views_[mid] == views_[mid - 1]) --mid;  // back to its view's start
      if (mid >= c.until && mid < q && views_[mid] != views_[mid - 1]) {
        c.probed = mid;
        c.lowest = std::min(c.lowest, similarity_to_j(mid));
      }
    }
    for (; c.lowest >= bar && c.until < q; ++c.until) {
      const std::size_t k = c.until;
      if (views_[k] == views_[k - 1] || k == c.probed) continue;  // not a view start, or checked
      c.lowest = std::min(c.lowest, similarity_to_j(k));
    }
    return c.lowest < bar;
  }

  /// `frames`: the ids are this engine's frames (their views and distances in the stream
  /// tell one place); otherwise only a verification of two candidates does.
  template <FeatureLookup L>
  void decide_among(PlaceDecision& d, const Features& q, const std::vector<std::pair<std::size_t, double>>& to_verify,
                    const L& lookup, const PlaceDecisionOptions& dec, bool frames = true) const {
    std::vector<Verified> verified = verify(d, q, to_verify, lookup, dec);
    const auto td = std::chrono::steady_clock::now();
    choose(d, verified, lookup, false, !to_verify.empty(), dec, frames);
    d.decide_ms = ms_since(td);
  }

  struct Verified {
    std::size_t frame;
    double confidence;
    PlaceEvidence evidence;
    Verification verification;
    std::size_t considered;  ///< its entry in PlaceDecision::considered
    Matches matches;         ///< what `verification` weighed
  };

  /// Matches and verifies each candidate; the verified ones with their evidence.
  template <FeatureLookup L>
  std::vector<Verified> verify(PlaceDecision& d, const Features& f,
                               const std::vector<std::pair<std::size_t, double>>& to_verify, const L& lookup,
                               const PlaceDecisionOptions& dec) const {
    const auto t0 = std::chrono::steady_clock::now();
    std::vector<Verified> verified;
    for (const auto& [j, score] : to_verify) {
      const Features& old = lookup(j);
      Matches matches = matcher_.match(f, old);
      Verification v = estimator_.verify(f, old, matches);
      ++d.verifications;
      if (!v.ok()) {
        ++d.failed_verifications;
        d.considered.push_back({j, score, 0, 0.0, CandidateStage::verification_failed, static_cast<int>(matches.size()),
                                v.status, cv::Matx33d::zeros()});
        continue;
      }
      PlaceEvidence e = measure_place_evidence(f, old, matches, v, model_, dec);
      e.bow_score = score;
      const double conf = place_confidence(e, dec);
      d.considered.push_back({j, score, e.inliers, conf, CandidateStage::weaker, e.matches, v.status, v.model, e});
      verified.push_back({j, conf, e, std::move(v), d.considered.size() - 1, std::move(matches)});
    }
    d.verify_ms = ms_since(t0);
    return verified;
  }

  /// The revisit rule over the verified candidates of loop query `frames_` (features
  /// `f`) confident enough to be accepted: drops those whose place the camera never left;
  /// true when it dropped any. The others cannot be a loop and are kept as they are.
  /// Counts the queries past the window that left or stayed.
  template <FeatureLookup L>
  bool filter_revisits(PlaceDecision& d, std::vector<Verified>& verified, const Features& f, const L& lookup) {
    bool any_left = false, any_stayed = false;
    std::erase_if(verified, [&](const Verified& c) {
      if (c.confidence < options_.decision.min_confidence) return false;
      if (left_place(c.frame, frames_, InlierRatio{}(f, lookup(c.frame), c.verification), lookup)) {
        any_left = true;
        return false;
      }
      any_stayed = true;
      d.considered[c.considered].stage = CandidateStage::not_a_revisit;
      return true;
    });
    if (frames_ > options_.window) {
      ++past_window_;
      if (any_stayed && !any_left) ++not_revisit_;
      if (any_left) ++left_queries_;
    }
    return any_stayed;
  }

  /// Whether verified candidates `a` and `b` show one place: neighbours in the stream
  /// (within the window or the temporal tolerance) or in the chain (the same or the next
  /// view), or, when `b` competes with `a` (it could make the decision ambiguous), the
  /// decision itself accepts the pair `a`, `b` (one verification, no vocabulary). A
  /// place seen on two earlier laps is so one place, not two.
  /// `frames` false: the candidates are no frames of this engine (LoopEngine::decide),
  /// so only the verification of the pair tells. A frame the engine never added
  /// (localization before any vocabulary, every key image verified by an engine that
  /// holds none) is a view of its own.
  template <FeatureLookup L>
  [[nodiscard]] bool one_place(const Verified& a, const Verified& b, bool competes, const L& lookup,
                               const PlaceDecisionOptions& dec, bool frames = true) const {
    if (frames) {
      const std::size_t gap = a.frame > b.frame ? a.frame - b.frame : b.frame - a.frame;
      if (gap <= std::max(options_.window, options_.temporal_tolerance)) return true;
      const auto view = [&](std::size_t j) { return j < views_.size() ? std::size_t{views_[j]} : j; };
      const std::size_t va = view(a.frame), vb = view(b.frame);
      if ((va > vb ? va - vb : vb - va) <= 1) return true;
    }
    if (!competes) return false;
    const Features fa = lookup(a.frame);  // a copy: the next lookup may replace it
    const Features& fb = lookup(b.frame);
    const Matches matches = matcher_.match(fa, fb);
    const Verification v = estimator_.verify(fa, fb, matches);
    if (!v.ok()) return false;
    return place_confidence(measure_place_evidence(fa, fb, matches, v, model_, dec), dec) >= dec.min_confidence;
  }

  /// The decision from the verified candidates (best confidence first).
  template <FeatureLookup L>
  void choose(PlaceDecision& d, std::vector<Verified>& verified, const L& lookup, bool stayed, bool any_verified,
              const PlaceDecisionOptions& dec, bool frames = true) const {
    std::stable_sort(verified.begin(), verified.end(),
                     [](const Verified& a, const Verified& b) { return a.confidence > b.confidence; });
    const double need = dec.min_confidence;
    char buf[96];
    // The revisit rule dropped every candidate that could have been accepted.
    if (verified.empty() || (stayed && verified.front().confidence < need)) {
      if (stayed) {
        d.status = PlaceStatus::not_a_revisit;
        d.reason_code = DecisionReason::camera_stayed;
        d.reason = "the camera never left the candidates' place";
      } else {
        d.status = PlaceStatus::too_little_evidence;
        d.reason_code = d.candidates == 0 ? DecisionReason::no_candidates
                        : !any_verified   ? DecisionReason::below_bow_score
                                          : DecisionReason::not_verified;
        d.reason = d.candidates == 0 ? "no candidates"
                   : !any_verified   ? "every candidate below the bag-of-words score"
                                     : "no candidate verified";
      }
      return;
    }
    const Verified& b = verified.front();
    d.best = b.frame;
    d.confidence = b.confidence;
    d.evidence = b.evidence;
    d.verification = b.verification;
    d.best_matches = b.matches;
    d.considered[b.considered].stage = CandidateStage::chosen;
    // The best other place: the most confident verified candidate that is not the best
    // one's place (one_place).
    for (std::size_t i = 1; i < verified.size(); ++i) {
      const Verified& o = verified[i];
      const bool competes = o.confidence >= need && o.confidence >= dec.ambiguity_ratio * b.confidence;
      if (!one_place(b, o, competes, lookup, dec, frames)) {
        d.second = o.frame;
        d.second_confidence = o.confidence;
        break;
      }
    }
    if (b.evidence.inliers < dec.min_inliers) {
      d.status = PlaceStatus::too_little_evidence;
      d.reason_code = DecisionReason::too_few_inliers;
      std::snprintf(buf, sizeof buf, "%d inliers < %d", b.evidence.inliers, dec.min_inliers);
    } else if (b.confidence < need) {
      d.status = PlaceStatus::unknown_place;
      d.reason_code = DecisionReason::low_confidence;
      std::snprintf(buf, sizeof buf, "confidence %.2f < %.2f", b.confidence, need);
    } else if (d.second && d.second_confidence >= need &&
               d.second_confidence >= dec.ambiguity_ratio * b.confidence) {
      d.status = PlaceStatus::ambiguous;
      d.reason_code = DecisionReason::two_places;
      std::snprintf(buf, sizeof buf, "frames %zu and %zu: confidence %.2f and %.2f", b.frame, *d.second, b.confidence,
                    d.second_confidence);
    } else {
      d.status = PlaceStatus::accepted;
      d.reason_code = DecisionReason::confident;
      std::snprintf(buf, sizeof buf, "confidence %.2f >= %.2f", b.confidence, need);
    }
    d.reason = buf;
  }

  /// Temporal consistency (place/consistency.hpp): the query's place is its best
  /// candidate when accepted, none otherwise; the loop stands when this query and the k
  /// before it matched places within the tolerance.
  void apply_temporal_consistency(PlaceDecision& d) {
    if (options_.temporal_consistency == 0) return;
    const bool candidate = d.accepted();
    const ConsistencyState<std::size_t> s = consistency_.update(candidate ? d.best : std::nullopt);
    d.consistent_queries = s.consecutive > 0 ? static_cast<std::size_t>(s.consecutive - 1) : 0;
    if (candidate && !s.accepted) {
      d.status = PlaceStatus::too_little_evidence;
      d.reason_code = DecisionReason::not_yet_confirmed;
      d.reason = "not yet confirmed: " + std::to_string(d.consistent_queries) + " of " +
                 std::to_string(options_.temporal_consistency) + " earlier queries agree";
    }
  }

  M matcher_;
  E estimator_;
  Rank ranker_;
  LoopOptions options_;
  LabelSchema schema_;
  PlaceModel model_;
  BinaryClassifiedTree<std::size_t> tree_;
  TemporalConsistency<std::size_t> consistency_;
  std::vector<LabelVector> labels_;
  std::vector<std::uint32_t> views_;  ///< each frame's view in the chain (add()'s ViewStep)
  std::vector<LeftCache> left_;       ///< the revisit rule's scan of each frame's later view starts
  std::size_t frames_ = 0;
  std::size_t tree_next_ = 0;
  std::size_t session_start_ = 0;  ///< first frame of the current session
  std::size_t verifications_ = 0;
  std::size_t past_window_ = 0;
  std::size_t not_revisit_ = 0;
  std::size_t left_queries_ = 0;
};

}  // namespace vmap
