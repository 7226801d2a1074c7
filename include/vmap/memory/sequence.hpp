#pragma once

// Localizing a sequence of images in a visual memory (lcd/sequence.hpp gives the
// evidence): each image is localized alone (VisualMemory::localize, or AnyMemory's),
// then answered with the line its neighbours draw through the memory's key images: an
// image not accepted alone is placed at the key image it sees best when at least two
// other images see the key images of one line around it and their evidence, combined,
// reaches the decision's threshold. A session is one chain: consecutive key images of a
// session are neighbours on a line.
//
//   // a recorded sequence, each image answered with the 8 around it
//   std::vector<vmap::MemoryLocalization> answers = vmap::localize_sequence(memory, images);
//   // a live stream: keep the last answers, each new one decided with them
//   recent.push_back(memory.localize(frame));               // one verification per frame
//   vmap::MemoryLocalization now = vmap::localize_window(memory, recent);
//
// Cost: the single localizations (top-k verifications per image) and, per answer, a
// line search over the window's verified candidates (window^2 * candidates^2
// comparisons, microseconds). Memory: the window's answers.

#include <vmap/core/error.hpp>
#include <vmap/lcd/sequence.hpp>
#include <vmap/memory/types.hpp>

#include <opencv2/core.hpp>

#include <algorithm>
#include <cstdio>
#include <span>
#include <string>
#include <vector>

namespace vmap {

namespace detail {

/// The session of key image `key` (sessions sorted by first_key, the first at 0).
[[nodiscard]] inline std::size_t session_of_key(const std::vector<MemorySession>& sessions, std::size_t key) {
  const auto it = std::upper_bound(sessions.begin(), sessions.end(), key,
                                   [](std::size_t k, const MemorySession& s) { return k < s.first_key; });
  return it == sessions.begin() ? 0 : static_cast<std::size_t>(it - sessions.begin() - 1);
}

/// localize_window's `recent`: 1..max_sequence_window `what` (answers or images).
inline void check_window(std::size_t n, const char* what) {
  check(n >= 1, [&] { return std::string("localize_window: no ") + what + " given"; });
  check(n <= max_sequence_window, [&] {
    return "localize_window: " + std::to_string(n) + " " + what + ", at most " + std::to_string(max_sequence_window);
  });
}

/// One answer rewritten with its sequence's evidence.
inline void apply_sequence_answer(MemoryLocalization& a, const SequenceAnswer& s, const PlaceDecisionOptions& d) {
  SequenceSupport support{.window = s.window, .weighed = s.weighed, .on_line = s.on_line,
                          .significance = s.significance, .single_confidence = a.confidence, .single_key = {}};
  if (!a.matches.empty()) support.single_key = a.matches.front().key;
  a.sequence = support;
  if (!s.candidate) return;  // nothing verified: the image's own answer says why
  const std::size_t c = *s.candidate;
  if (c != 0) {
    // The line's candidate first; the others keep their order.
    std::rotate(a.matches.begin(), a.matches.begin() + static_cast<std::ptrdiff_t>(c),
                a.matches.begin() + static_cast<std::ptrdiff_t>(c) + 1);
    std::rotate(a.match_evidence.begin(), a.match_evidence.begin() + static_cast<std::ptrdiff_t>(c),
                a.match_evidence.begin() + static_cast<std::ptrdiff_t>(c) + 1);
    a.relative_pose.reset();  // recovered for the image's own best candidate only
  }
  a.evidence = a.match_evidence.front();
  a.confidence = s.confidence;
  char buf[160];
  const int lead = std::snprintf(buf, sizeof buf, "%zu of %zu images that see a place on the line: ", s.on_line, s.weighed);
  const std::size_t at = static_cast<std::size_t>(std::max(lead, 0));
  a.reason_code = sequence_reason(s, a.status, d);
  a.status = status_of(a.reason_code);
  if (a.reason_code == DecisionReason::low_confidence)
    std::snprintf(buf + at, sizeof buf - at, "confidence %.2f < %.2f", s.confidence, d.min_confidence);
  else if (a.reason_code == DecisionReason::two_places)
    std::snprintf(buf + at, sizeof buf - at, "key image %u alone saw two places, and the line does not settle them",
                  a.matches.front().key);
  else
    std::snprintf(buf + at, sizeof buf - at, "confidence %.2f >= %.2f", s.confidence, d.min_confidence);
  a.reason = buf;
  settle_pose(a, c != 0);
}

/// The sequence's answer for each of `singles` (localize()'s answers, in order).
[[nodiscard]] inline std::vector<SequenceAnswer> sequence_answers(std::span<const MemoryLocalization> singles,
                                                                  const std::vector<MemorySession>& sessions,
                                                                  const SequenceOptions& options,
                                                                  const PlaceDecisionOptions& decision,
                                                                  SequencePlacement placement) {
  std::vector<SequenceQuery> queries(singles.size());
  for (std::size_t i = 0; i < singles.size(); ++i) {
    const MemoryLocalization& a = singles[i];
    check(a.match_evidence.size() == a.matches.size(), [&] {
      return "with_sequence_evidence: answer " + std::to_string(i) + " has " + std::to_string(a.matches.size()) +
             " matches but evidence for " + std::to_string(a.match_evidence.size());
    });
    for (std::size_t m = 0; m < a.matches.size(); ++m)
      queries[i].candidates.push_back({a.matches[m].key, weighed_significance(a.match_evidence[m], decision)});
    if (a.ok()) queries[i].accepted = 0;  // best(): the decision's candidate comes first
  }
  return sequence_evidence(
      queries, [&](std::size_t key) { return session_of_key(sessions, key); }, options, decision, placement);
}

}  // namespace detail

/// `singles` (one answer per image of a sequence, in order, as localize() gave them)
/// answered with the sequence's evidence: the window of `options.window` answers around
/// each (centred: a recorded sequence) or ending at it (trailing: a live stream). With a
/// window of 1 the answers are returned as they are. `sessions` are the memory's
/// (sessions()); `decision` the one the answers were decided with.
[[nodiscard]] inline std::vector<MemoryLocalization> with_sequence_evidence(
    std::vector<MemoryLocalization> singles, const std::vector<MemorySession>& sessions, const SequenceOptions& options,
    const PlaceDecisionOptions& decision, SequencePlacement placement = SequencePlacement::centred) {
  detail::check_sequence_options(options, "SequenceOptions");
  if (options.window == 1) return singles;
  const std::vector<SequenceAnswer> answers = detail::sequence_answers(singles, sessions, options, decision, placement);
  for (std::size_t i = 0; i < singles.size(); ++i) detail::apply_sequence_answer(singles[i], answers[i], decision);
  return singles;
}

/// The decision `memory` localizes with, or `decision` when given.
template <class Memory>
[[nodiscard]] const PlaceDecisionOptions& decision_of(const Memory& memory, const PlaceDecisionOptions* decision) {
  return decision ? *decision : memory.options().loops.decision;
}

/// Each of `images` (consecutive, in order) localized in `memory` (a VisualMemory or an
/// AnyMemory) with the evidence of the `options.window` images around it.
template <class Memory>
[[nodiscard]] std::vector<MemoryLocalization> localize_sequence(Memory& memory, std::span<const cv::Mat> images,
                                                                const SequenceOptions& options = {},
                                                                const PlaceDecisionOptions* decision = nullptr) {
  detail::check_sequence_options(options, "SequenceOptions");
  std::vector<MemoryLocalization> singles;
  singles.reserve(images.size());
  for (const cv::Mat& image : images) singles.push_back(memory.localize(image, decision));
  return with_sequence_evidence(std::move(singles), memory.sessions(), options, decision_of(memory, decision));
}

/// The last of `recent` (localize()'s answers for consecutive images, oldest first)
/// decided with the evidence of all of them: a robot keeps its last few answers and
/// verifies nothing again. At most max_sequence_window answers.
template <class Memory>
[[nodiscard]] MemoryLocalization localize_window(const Memory& memory, std::span<const MemoryLocalization> recent,
                                                 const SequenceLine& line = {},
                                                 const PlaceDecisionOptions* decision = nullptr) {
  detail::check_window(recent.size(), "answers");
  const PlaceDecisionOptions& d = decision_of(memory, decision);
  const SequenceOptions options{.window = recent.size(), .line = line};
  detail::check_sequence_options(options, "SequenceOptions");
  // Only the newest answer is rewritten: the others are not copied.
  MemoryLocalization newest = recent.back();
  if (recent.size() == 1) return newest;  // a window of 1: the image alone, as with_sequence_evidence
  detail::apply_sequence_answer(
      newest, detail::sequence_answers(recent, memory.sessions(), options, d, SequencePlacement::trailing).back(), d);
  return newest;
}

/// The last of `recent` (consecutive images, oldest first) localized in `memory` with the
/// evidence of all of them; every image is localized (a stream that keeps its answers
/// calls the overload above instead).
template <class Memory>
[[nodiscard]] MemoryLocalization localize_window(Memory& memory, std::span<const cv::Mat> recent,
                                                 const SequenceLine& line = {},
                                                 const PlaceDecisionOptions* decision = nullptr) {
  detail::check_window(recent.size(), "images");  // before any image is localized
  std::vector<MemoryLocalization> singles;
  for (const cv::Mat& image : recent) singles.push_back(memory.localize(image, decision));
  return localize_window(memory, std::span<const MemoryLocalization>(singles), line, decision);
}

}  // namespace vmap
