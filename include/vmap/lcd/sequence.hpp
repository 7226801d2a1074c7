#pragma once

// A sequence of images as evidence of a place (examples/memory.md, "A sequence of
// images"). A robot that is lost has its last few frames, not one: consecutive images
// that see consecutive key images of one place draw a line in the image-by-key matrix of
// verified candidates (SeqSLAM's line, Milford and Wyeth, ICRA 2012, at a constant speed
// of at most `max_speed` key images per image), and their evidences combine.
//
// What an image says about a place is its margin: the significance (lcd/place_decision.hpp)
// of its verified candidate as the decision weighs it (weighed_significance: 0 below
// min_inliers, lowered by a spread below full_spread) minus the most significant
// candidate it verified at another place (another chain, or more than `tolerance` key
// images away). Chance fits of a foreign image are weak and alike wherever they land, so
// their margins are near 0; an image that sees a place sees it better than any other.
//
// A line through candidate c of image i at speed v holds, from the image outwards in
// time, each image of the window whose best place (its most significant candidate, with
// a positive margin) lies within `tolerance` key images of key(c) + v (j - i), and counts
// each key image once (its best margin): a hub key image that many foreign images weakly
// match adds one image's evidence to a line, however many match it, and so do the
// near-copies of one view. The line ends, each way, at the first image that sees another
// place surely (a margin of SequenceOptions::min_margin off the line): the robot was elsewhere by
// then, or the speed is wrong. The line's evidence is Fisher's method (Fisher 1925, sec.
// 21.1) over the n images of the window that see a place (n counts images off the line
// too: they lower it), corrected for choosing the best of the L speeds tried
// (Bonferroni: - log10 L):
//   S = M - log10( sum_{j<n} (M ln 10)^j / j! ) - log10 L,   M = the sum of the margins,
// each margin at most half_significance (a neighbour that has verified its place beyond
// doubt says where the robot is, no more). Three more rules keep a line to what its
// images verified (examples/results/localize.md, "Sequences that hold", how they were
// measured):
//   - the image's own candidate has a margin of at least min_margin (2): the line
//     confirms the place the image sees best, it never moves the image elsewhere;
//   - a line holds at least min_support (2) other images at other key images than
//     the image's own, so one strong neighbour cannot draw a line at any speed;
//   - an image accepted alone keeps its key image and its confidence (a line can raise
//     it, never lower it).
// S maps to a confidence as a single image's significance does (1 - 2^(-S /
// half_significance)), and the one threshold decides.

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
  /// image alone, and so does 2 with min_support 2.
  std::size_t window = 8;
  SequenceLine line{};
  /// The least margin (significance over the image's most significant other place) at
  /// which a line places an image, and at which an image off a line ends it: 2, the
  /// image's fit to this place is a hundred times less likely by chance than its fit to
  /// any other it verified. Keep it above 0: at 0 a line can place an image at a
  /// candidate it verified with no evidence. On the shared sequences 1 and 2 answer alike, 3
  /// places one frame fewer, and none of 0-3 places a foreign image (bench_places
  /// section 12; examples/results/localize.md, "Sequences that hold"). >= 0.
  double min_margin = 2.0;
  /// The other images, at key images other than the image's own, that a line needs: 2.
  /// Through one neighbour a line can be drawn at some speed through almost any
  /// candidate, and a window of 2 stays the image alone. On the shared sequences 1
  /// places no foreign image either and one more held-out cabinet frame (trailing 8;
  /// section 12). >= 1.
  std::size_t min_support = 2;
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
/// alone, nor lowers its confidence; the others are answered with their best line.
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
  /// The query's candidate: the one it was accepted at alone, else the best line's, else
  /// its own most significant one; none when the query has no candidate with evidence.
  std::optional<std::size_t> candidate;
  double significance = 0.0;  ///< the line's combined significance or the image's own, the larger
  double confidence = 0.0;    ///< in [0, 1], from the significance
  std::size_t window = 0;     ///< queries weighed, this one included
  std::size_t weighed = 0;    ///< of those, the queries that see a place (Fisher's n), this one included
  std::size_t on_line = 0;    ///< of those, the queries on the line (1: no line, the image alone)
  std::size_t lines = 0;      ///< the speeds tried for the answer's candidate (L of the Bonferroni correction)
  /// The most significant candidate of another place (another chain, or more than
  /// `tolerance` key images away) and its own confidence.
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
  check(std::isfinite(o.min_margin) && o.min_margin >= 0.0, [&] {
    return option_name(owner, ".min_margin must be finite and >= 0, got ") + std::to_string(o.min_margin);
  });
  check(o.min_support >= 1, [&] { return option_name(owner, ".min_support must be >= 1, got 0"); });
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

/// One candidate as a line weighs it.
struct SequenceCell {
  double key = 0.0;
  std::size_t chain = 0;
  double significance = 0.0;
  double margin = 0.0;  ///< significance minus the query's most significant other place
};

}  // namespace detail

/// What a sequence's answer decides for an image whose own decision was `alone`:
/// confident when its confidence reaches min_confidence, unless the image alone saw two
/// places (ambiguous) and its neighbours do not settle the tie, because no other image
/// lies on the line or another place is nearly as confident. Whether two candidates are
/// one place is the image's own decision's to say (it verifies them against each other);
/// the line only settles a tie that decision saw.
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
/// candidate c of query i with speed v (|v| <= line.max_speed) holds the other queries of
/// the window whose best place lies within line.tolerance key images of key(c) + v (j -
/// i), as the top of this file says; the speeds tried are 0 and those that pass exactly
/// through another query's best place. `decision` gives the confidence map
/// (half_significance).
template <class ChainOf>
[[nodiscard]] std::vector<SequenceAnswer> sequence_evidence(const std::vector<SequenceQuery>& queries,
                                                            const ChainOf& chain_of, const SequenceOptions& options,
                                                            const PlaceDecisionOptions& decision,
                                                            SequencePlacement placement = SequencePlacement::centred) {
  detail::check_sequence_options(options, "SequenceOptions");
  const std::size_t n = queries.size();
  const double tol = static_cast<double>(options.line.tolerance) + 1e-9;
  const double cap = decision.half_significance;
  // Each candidate's chain and margin, and each query's most significant candidate (the
  // place it sees best, when its margin is positive).
  std::vector<std::vector<detail::SequenceCell>> cells(n);
  std::vector<std::optional<std::size_t>> top(n);
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
      cells[i].push_back({static_cast<double>(c.key), static_cast<std::size_t>(chain_of(c.key)), c.significance, 0.0});
    }
    for (std::size_t c = 0; c < cells[i].size(); ++c) {
      detail::SequenceCell& x = cells[i][c];
      double other = 0.0;
      for (const detail::SequenceCell& o : cells[i])
        if (o.chain != x.chain || std::abs(o.key - x.key) > tol) other = std::max(other, o.significance);
      x.margin = x.significance > 0.0 ? x.significance - other : 0.0;
      if (x.significance > 0.0 && (!top[i] || x.significance > cells[i][*top[i]].significance)) top[i] = c;
    }
  }
  const auto sees = [&](std::size_t j) { return top[j] && cells[j][*top[j]].margin > 0.0; };
  const auto confidence = [&](double s) { return 1.0 - std::exp2(-s / decision.half_significance); };
  struct Line {
    double significance = 0.0;
    std::size_t on_line = 1;  ///< the image and its supports
    std::size_t lines = 0;    ///< speeds tried
  };
  // The best line through candidate c of query i over the queries first..last, with n
  // images that see a place; none with fewer than min_support supports. From
  // the image outwards, each query whose best place lies on the line supports it; the
  // line ends, that way, at the first query that sees another place surely (a margin of
  // min_margin off the line): the robot was elsewhere by then, or the speed is
  // wrong.
  std::vector<double> speeds;
  std::vector<std::pair<double, double>> support;  // (key, margin) of the line's other images
  const auto best_line = [&](std::size_t i, std::size_t c, std::size_t first, std::size_t last,
                             std::size_t weighed) -> std::optional<Line> {
    const detail::SequenceCell& at = cells[i][c];
    speeds.assign(1, 0.0);
    for (std::size_t j = first; j <= last; ++j) {
      if (j == i || !sees(j)) continue;
      const detail::SequenceCell& o = cells[j][*top[j]];
      const double v = (o.key - at.key) / (static_cast<double>(j) - static_cast<double>(i));
      if (o.chain == at.chain && std::abs(v) <= options.line.max_speed) speeds.push_back(v);
    }
    std::sort(speeds.begin(), speeds.end());
    speeds.erase(std::unique(speeds.begin(), speeds.end(), [](double a, double b) { return b - a < 1e-9; }), speeds.end());
    const double own = std::min(at.margin, cap);
    std::optional<Line> best;
    for (const double v : speeds) {
      support.clear();
      // Whether query j extends the line: false where the line ends.
      const auto walk = [&](std::size_t j) {
        if (!top[j]) return true;
        const detail::SequenceCell& o = cells[j][*top[j]];
        const double expected = at.key + v * (static_cast<double>(j) - static_cast<double>(i));
        const bool on = o.chain == at.chain && std::abs(o.key - expected) <= tol;
        if (!on) return o.margin < options.min_margin;
        if (o.margin <= 0.0 || o.key == at.key) return true;  // the image's own key image counts once, as the image's
        const double m = std::min(o.margin, cap);
        const auto same = std::find_if(support.begin(), support.end(), [&](const auto& s) { return s.first == o.key; });
        if (same == support.end())
          support.emplace_back(o.key, m);
        else
          same->second = std::max(same->second, m);
        return true;
      };
      for (std::size_t j = i; j > first && walk(j - 1); --j) {
      }
      for (std::size_t j = i + 1; j <= last && walk(j); ++j) {
      }
      if (support.size() < options.min_support) continue;
      double sum = own;
      for (const auto& s : support) sum += s.second;
      const double significance =
          detail::fisher_significance(sum, weighed) - std::log10(static_cast<double>(speeds.size()));
      if (!best || significance > best->significance ||
          (significance == best->significance && support.size() + 1 > best->on_line))
        best = Line{significance, support.size() + 1, speeds.size()};
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
      if (j != i && sees(j)) ++a.weighed;
    const SequenceQuery& q = queries[i];
    // The image alone: the candidate it was accepted at, else its most significant one.
    const std::optional<std::size_t> alone = q.accepted ? q.accepted : top[i];
    if (!alone) continue;  // nothing verified with evidence: the image's own answer says why
    // The best line through a candidate the image sees best.
    std::optional<std::size_t> chosen;
    Line line;
    for (std::size_t c = 0; c < cells[i].size(); ++c) {
      if (q.accepted && c != *q.accepted) continue;
      if (cells[i][c].margin < options.min_margin) continue;
      const std::optional<Line> l = best_line(i, c, first, last, a.weighed);
      if (l && (!chosen || l->significance > line.significance)) chosen = c, line = *l;
    }
    const std::size_t c = chosen.value_or(*alone);
    a.candidate = c;
    // The line can raise the image's own evidence, never lower it.
    a.significance = std::max(cells[i][c].significance, chosen ? line.significance : 0.0);
    a.on_line = chosen ? line.on_line : 1;
    a.lines = chosen ? line.lines : 0;
    a.confidence = confidence(a.significance);
    for (std::size_t o = 0; o < cells[i].size(); ++o) {
      const detail::SequenceCell& x = cells[i][o];
      if (x.significance <= 0.0 || (x.chain == cells[i][c].chain && std::abs(x.key - cells[i][c].key) <= tol)) continue;
      if (!a.second || confidence(x.significance) > a.second_confidence)
        a.second = o, a.second_confidence = confidence(x.significance);
    }
  }
  return out;
}

}  // namespace vmap
