#pragma once

// A sequence of images as evidence of a place (examples/memory.md, "A sequence of
// images"). A robot that is lost has its last few frames, not one: consecutive queries
// that agree on consecutive key images of one place draw a line in the query-by-key
// matrix of verified candidates (SeqSLAM's line, Milford and Wyeth, ICRA 2012, at a
// constant speed of at most `max_speed` key images per query), and their independent
// evidences combine; a query whose candidate lies off its neighbours' line gains nothing
// from them and counts against the line it does not join.
//
// The evidence of one verified candidate is its significance (lcd/place_decision.hpp) as
// the decision weighs it: the significance of its confidence, which is 0 below
// min_inliers and lowered by a spread below full_spread (weighed_significance). A line's
// evidence is Fisher's method (Fisher 1925, sec. 21.1) over the queries of the window
// that have any evidence: with p_i = 10^(-s_i) and S = sum of the s_i on the line,
// -2 sum ln p_i follows chi-square with 2n degrees of freedom under chance, so the
// combined significance is
//   S - log10( sum_{j<n} (S ln 10)^j / j! ),
// n counting every query of the window that verified a candidate somewhere (a query off
// the line adds 0 to S and 1 to n: it lowers the line). Queries that verified nothing
// (a blurred frame) neither raise nor lower it. With n = 1 the combined significance is
// the query's own. The combined significance maps to a confidence as a single image's
// does (1 - 2^(-S / half_significance)), and the one threshold decides.
//
// Two rules keep one strong image from deciding for the others (examples/results/
// localize.md, "Sequences as evidence", how the choices were made): a neighbour adds no
// more than the image's own evidence, and an image accepted alone keeps its key image
// (the sequence can lower it, never move it).

#include <vmap/core/error.hpp>
#include <vmap/lcd/options.hpp>
#include <vmap/lcd/place_decision.hpp>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace vmap {

/// The most queries one answer may weigh (SequenceOptions::window).
inline constexpr std::size_t max_sequence_window = 100;

/// What a line is.
struct SequenceLine {
  /// The fastest line, in key images per query, either way: a robot queried at its
  /// frame rate passes a key image every few frames (below 1), one queried every few
  /// frames of a memory that keeps most frames moves several.
  double max_speed = 5.0;
  /// How far a query's candidate may lie off the line, in key images.
  std::size_t tolerance = 1;
};

struct SequenceOptions {
  /// Queries whose evidence one answer weighs (this one included), 1..100; 1 answers each
  /// image alone.
  std::size_t window = 8;
  SequenceLine line{};
};

/// Which queries an answer weighs: the window around it (a recorded sequence: the
/// frames after it count too), or the window that ends at it (a live stream).
enum class SequencePlacement : std::uint8_t { centred, trailing };

/// One verified candidate of one query: its key image and its weighed significance.
struct SequenceCandidate {
  std::size_t key = 0;
  double significance = 0.0;  ///< weighed_significance of its evidence, >= 0
};

/// One query: its verified candidates (each key once), and the one it was accepted at
/// alone, if it was. A sequence never moves an image from the place it was accepted at
/// alone (it can only lower its confidence); the others are answered with their best
/// line.
struct SequenceQuery {
  std::vector<SequenceCandidate> candidates;
  std::optional<std::size_t> accepted;  ///< an index into candidates
};

/// The significance of a verified pair as a sequence weighs it: the significance whose
/// confidence is the pair's place_confidence, so that bunched inliers (a spread below
/// full_spread) count less, a pair below min_inliers counts 0, and a sequence of one
/// image decides as the image alone does.
[[nodiscard]] inline double weighed_significance(const PlaceEvidence& e, const PlaceDecisionOptions& o) {
  if (e.inliers < o.min_inliers || e.inliers <= 0) return 0.0;
  const double spread = o.full_spread > 0 ? std::min(1.0, e.spread / o.full_spread) : 1.0;
  if (spread >= 1.0) return e.significance;
  // 1 - confidence = 1 - (1 - 2^(-s/h)) * spread >= 1 - spread > 0: no rounding to 1.
  return -o.half_significance * std::log2(1.0 - (1.0 - std::exp2(-e.significance / o.half_significance)) * spread);
}

/// The answer for one query.
struct SequenceAnswer {
  /// The query's candidate on the best line (an index into its candidates): the one it
  /// was accepted at alone, else the best line's among those with evidence; none when
  /// the query has no candidate with evidence.
  std::optional<std::size_t> candidate;
  double significance = 0.0;  ///< the line's combined significance
  double confidence = 0.0;    ///< in [0, 1], from the combined significance
  std::size_t window = 0;     ///< queries weighed, this one included
  std::size_t weighed = 0;    ///< of those, the queries with evidence (Fisher's n)
  std::size_t on_line = 0;    ///< of those, the queries whose evidence lies on the line
  /// The best candidate of another place (another chain, or more than `tolerance` key
  /// images away) and the confidence of its own line.
  std::optional<std::size_t> second;
  double second_confidence = 0.0;
};

namespace detail {

inline void check_sequence_options(const SequenceOptions& o, std::string_view owner) {
  check(o.window >= 1 && o.window <= max_sequence_window, [&] {
    return option_name(owner, ".window must be in 1..100, got ") + std::to_string(o.window);
  });
  check(std::isfinite(o.line.max_speed) && o.line.max_speed >= 0.0, [&] {
    return option_name(owner, ".line.max_speed must be finite and >= 0, got ") + std::to_string(o.line.max_speed);
  });
}

/// Fisher's combined significance of n independent tests whose significances sum to s.
[[nodiscard]] inline double fisher_significance(double s, std::size_t n) {
  if (s <= 0.0 || n == 0) return 0.0;
  const double log_lambda = std::log(s * std::log(10.0));
  // log of sum_{j<n} lambda^j / j!, from its largest term.
  const auto term = [&](std::size_t j) { return static_cast<double>(j) * log_lambda - std::lgamma(static_cast<double>(j) + 1.0); };
  double top = term(0);
  for (std::size_t j = 1; j < n; ++j) top = std::max(top, term(j));
  double sum = 0.0;
  for (std::size_t j = 0; j < n; ++j) sum += std::exp(term(j) - top);
  return std::max(0.0, s - (top + std::log(sum)) / std::log(10.0));
}

}  // namespace detail

/// What a sequence's answer decides for an image whose own decision was `alone`:
/// confident when its confidence reaches min_confidence, unless the image alone saw two
/// places (ambiguous) and its neighbours do not settle the tie, because no other image
/// lies on the line or another place's line is nearly as confident. Whether two
/// candidates are one place is the image's own decision's to say (it verifies them
/// against each other); the line only settles a tie that decision saw.
[[nodiscard]] inline DecisionReason sequence_reason(const SequenceAnswer& a, PlaceStatus alone,
                                                    const PlaceDecisionOptions& d) {
  if (a.confidence < d.min_confidence) return DecisionReason::low_confidence;
  if (alone == PlaceStatus::ambiguous &&
      (a.on_line < 2 || (a.second && a.second_confidence >= std::max(d.min_confidence, d.ambiguity_ratio * a.confidence))))
    return DecisionReason::two_places;
  return DecisionReason::confident;
}

/// The sequence's answer for each query, in order. `chain_of(key)` names the chain a key
/// image belongs to (a memory's session): a line stays on one chain. A line through
/// candidate c of query i with speed v (|v| <= line.max_speed) holds, for each other
/// query j of the window, its most significant candidate within line.tolerance key images
/// of key(c) + v (j - i); the speeds tried are 0 and those
/// that pass exactly through another query's candidate. `decision` gives the confidence
/// map (half_significance).
template <class ChainOf>
[[nodiscard]] std::vector<SequenceAnswer> sequence_evidence(const std::vector<SequenceQuery>& queries,
                                                            const ChainOf& chain_of, const SequenceOptions& options,
                                                            const PlaceDecisionOptions& decision,
                                                            SequencePlacement placement = SequencePlacement::centred) {
  detail::check_sequence_options(options, "SequenceOptions");
  const std::size_t n = queries.size();
  std::vector<std::vector<std::size_t>> chain(n);
  std::vector<char> has_evidence(n, 0);
  for (std::size_t i = 0; i < n; ++i) {
    const SequenceQuery& q = queries[i];
    detail::check(!q.accepted || *q.accepted < q.candidates.size(), [&] {
      return "sequence_evidence: query " + std::to_string(i) + " was accepted at candidate " +
             std::to_string(*q.accepted) + " of " + std::to_string(q.candidates.size());
    });
    for (const SequenceCandidate& c : q.candidates) {
      detail::check(std::isfinite(c.significance) && c.significance >= 0.0, [&] {
        return "sequence_evidence: query " + std::to_string(i) + " has a candidate with significance " +
               std::to_string(c.significance) + " (must be finite and >= 0)";
      });
      chain[i].push_back(static_cast<std::size_t>(chain_of(c.key)));
      if (c.significance > 0.0) has_evidence[i] = 1;
    }
  }
  const auto key = [&](std::size_t j, std::size_t c) { return static_cast<double>(queries[j].candidates[c].key); };
  const auto sig = [&](std::size_t j, std::size_t c) { return queries[j].candidates[c].significance; };
  struct Line {
    double sum = 0.0;
    std::size_t cells = 0;  ///< queries with evidence on the line
  };
  const auto better = [](const Line& a, const Line& b) { return a.sum > b.sum || (a.sum == b.sum && a.cells > b.cells); };
  const double tol = static_cast<double>(options.line.tolerance) + 1e-9;
  // The best line through candidate c of query i over the queries first..last.
  const auto best_line = [&](std::size_t i, std::size_t c, std::size_t first, std::size_t last) {
    std::vector<double> speeds{0.0};
    for (std::size_t j = first; j <= last; ++j) {
      if (j == i) continue;
      const double dj = static_cast<double>(j) - static_cast<double>(i);
      for (std::size_t cj = 0; cj < queries[j].candidates.size(); ++cj) {
        const double v = (key(j, cj) - key(i, c)) / dj;
        if (chain[j][cj] == chain[i][c] && sig(j, cj) > 0.0 && std::abs(v) <= options.line.max_speed) speeds.push_back(v);
      }
    }
    Line best{sig(i, c), sig(i, c) > 0.0 ? std::size_t{1} : 0};
    for (const double v : speeds) {
      Line line{sig(i, c), sig(i, c) > 0.0 ? std::size_t{1} : 0};
      for (std::size_t j = first; j <= last; ++j) {
        if (j == i) continue;
        const double at = key(i, c) + v * (static_cast<double>(j) - static_cast<double>(i));
        double here = 0.0;
        for (std::size_t cj = 0; cj < queries[j].candidates.size(); ++cj)
          if (chain[j][cj] == chain[i][c] && std::abs(key(j, cj) - at) <= tol) here = std::max(here, sig(j, cj));
        here = std::min(here, sig(i, c));  // a neighbour vouches for this image's place no more than the image does
        line.sum += here;
        line.cells += here > 0.0 ? 1 : 0;
      }
      if (better(line, best)) best = line;
    }
    return best;
  };
  std::vector<SequenceAnswer> out(n);
  const std::size_t w = std::min(options.window, n);
  for (std::size_t i = 0; i < n; ++i) {
    std::size_t first = 0;
    if (placement == SequencePlacement::trailing)
      first = i + 1 >= w ? i + 1 - w : 0;
    else
      first = std::min(i >= (w - 1) / 2 ? i - (w - 1) / 2 : 0, n - w);
    const std::size_t last = placement == SequencePlacement::trailing ? i : first + w - 1;
    SequenceAnswer& a = out[i];
    a.window = last - first + 1;
    a.weighed = 1;
    for (std::size_t j = first; j <= last; ++j)
      if (j != i && has_evidence[j]) ++a.weighed;
    const SequenceQuery& q = queries[i];
    std::vector<Line> lines(q.candidates.size());
    for (std::size_t c = 0; c < q.candidates.size(); ++c) {
      if (sig(i, c) <= 0.0) continue;  // an image is answered only where it has evidence of its own
      lines[c] = best_line(i, c, first, last);
      if (!q.accepted && (!a.candidate || better(lines[c], lines[*a.candidate]))) a.candidate = c;
    }
    if (q.accepted) a.candidate = q.accepted;
    if (!a.candidate) continue;
    const std::size_t best = *a.candidate;
    if (sig(i, best) <= 0.0) lines[best] = best_line(i, best, first, last);
    const auto confidence = [&](double s) { return 1.0 - std::exp2(-s / decision.half_significance); };
    a.significance = detail::fisher_significance(lines[best].sum, a.weighed);
    a.confidence = confidence(a.significance);
    a.on_line = lines[best].cells;
    for (std::size_t c = 0; c < q.candidates.size(); ++c) {
      if (sig(i, c) <= 0.0) continue;
      // The same place: one chain, within the tolerance.
      if (chain[i][c] == chain[i][best] && std::abs(key(i, c) - key(i, best)) <= tol) continue;
      const double conf = confidence(detail::fisher_significance(lines[c].sum, a.weighed));
      if (!a.second || conf > a.second_confidence) a.second = c, a.second_confidence = conf;
    }
  }
  return out;
}

}  // namespace vmap
