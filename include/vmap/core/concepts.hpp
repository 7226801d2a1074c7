#pragma once

// The four concepts the library is built on (examples/methods.md, sec. 5). Each big concept is
// composed of small named ones, one requirement per line, because the line a compiler
// error points to should say which requirement a policy misses.

#include <vmap/core/features.hpp>
#include <vmap/core/verification.hpp>

#include <opencv2/core.hpp>

#include <concepts>
#include <string>

namespace vmap {

// ---- Descriptor -------------------------------------------------------------------

/// `d.extract(image)` turns an image into Features. Not required to be const: OpenCV's
/// detectors keep scratch state, so one Descriptor object serves one thread at a time.
template <class D>
concept ExtractsFeatures = requires(D& d, const cv::Mat& image) {
  { d.extract(image) } -> std::same_as<Features>;
};

template <class D>
concept Descriptor = std::move_constructible<D>  // policies are held by value
                     && ExtractsFeatures<D>;     // Features extract(const cv::Mat&)

// ---- Matcher ----------------------------------------------------------------------

/// `m.match(a, b)` pairs descriptors of a with descriptors of b (queryIdx -> a,
/// trainIdx -> b). Const: a matcher holds only options, so concurrent calls are safe.
template <class M>
concept MatchesFeatures = requires(const M& m, const Features& a, const Features& b) {
  { m.match(a, b) } -> std::same_as<Matches>;
};

template <class M>
concept Matcher = std::move_constructible<M>  // held by value
                  && MatchesFeatures<M>;      // Matches match(a, b) const

// ---- Estimator --------------------------------------------------------------------

/// `e.verify(a, b, matches)` fits a two-view model to the matches; failure is a
/// Verification status, never an exception.
template <class E>
concept VerifiesMatches =
    requires(const E& e, const Features& a, const Features& b, const Matches& m) {
      { e.verify(a, b, m) } -> std::same_as<Verification>;
    };

template <class E>
concept Estimator = std::move_constructible<E>  // held by value
                    && VerifiesMatches<E>;      // Verification verify(a, b, m) const

// ---- Similarity -------------------------------------------------------------------

/// `s(a, b, verification)` scores how much two images share, in [0, 1] (eq. 5 of
/// García-Pintos et al. 2023 is the reference model).
template <class S>
concept ScoresPair =
    requires(const S& s, const Features& a, const Features& b, const Verification& v) {
      { s(a, b, v) } -> std::convertible_to<double>;
    };

/// The raw-match form of the score, an upper bound of the verified one because
/// verification only removes matches. Lets a selector skip the estimator when even
/// the bound is below its threshold.
template <class S>
concept BoundsPair = requires(const S& s, const Features& a, const Features& b, int raw) {
  { s.upper_bound(a, b, raw) } -> std::convertible_to<double>;
};

template <class S>
concept Similarity = std::move_constructible<S>  // held by value
                     && ScoresPair<S>            // double operator()(a, b, v) const
                     && BoundsPair<S>;           // double upper_bound(a, b, raw) const

// ---- What a policy may state about itself -----------------------------------------
// Not required by the four concepts; what holds state a robot keeps (a visual memory)
// uses them when a policy offers them.

/// `p.describe()` names the policy and every option that changes its results, as text
/// ("OrbDescriptor features=1000 ..."). A visual memory records it and refuses to load
/// with a policy that describes itself otherwise; a policy without it is not recorded.
template <class P>
concept DescribesItself = requires(const P& p) {
  { p.describe() } -> std::convertible_to<std::string>;
};

/// `d.layout()` is what every descriptor row it makes looks like, so features read from
/// a file can be checked against the descriptor before they are matched with its own.
template <class D>
concept StatesLayout = requires(const D& d) {
  { d.layout() } -> std::same_as<DescriptorLayout>;
};

}  // namespace vmap
