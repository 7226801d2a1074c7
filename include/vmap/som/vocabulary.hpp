#pragma once

// A vocabulary of binary words learned from binary descriptors (A-KAZE M-LDB, ORB) by
// k-majority: k-means where distances are Hamming distances and each centre is the
// bitwise majority vote of its members (Grana et al. 2013). The words of the
// bag-of-binary-words histogram (histogram.hpp).

#include <vmap/core/error.hpp>

#include <opencv2/core.hpp>
#include <opencv2/features2d.hpp>

#include <algorithm>
#include <cstdint>
#include <numeric>
#include <random>
#include <string>
#include <utility>
#include <vector>

namespace vmap {

struct VocabularyOptions {
  int words = 64;                        ///< vocabulary size k, >= 1
  int iterations = 8;                    ///< k-majority rounds, >= 1
  std::size_t max_descriptors = 20000;   ///< random sample learned from, >= words (bounds the time)
  std::uint64_t seed = 1;                ///< sample, initial centres, re-seeded empty clusters
};

/// Binary words (CV_8U rows, one word a row). Assignment is const and thread-safe.
class BinaryVocabulary {
 public:
  BinaryVocabulary() = default;

  /// Learns from the descriptor matrices of a set of images (CV_8U, equal widths).
  /// Fewer distinct descriptors than words is an Error naming the counts.
  static BinaryVocabulary learn(const std::vector<cv::Mat>& descriptor_sets, const VocabularyOptions& o = {}) {
    detail::check(o.words >= 1, "VocabularyOptions.words must be >= 1, got " + std::to_string(o.words));
    detail::check(o.iterations >= 1, "VocabularyOptions.iterations must be >= 1, got " + std::to_string(o.iterations));
    detail::check(o.max_descriptors >= static_cast<std::size_t>(o.words),
                  "VocabularyOptions.max_descriptors must be >= words");
    int cols = -1;
    std::vector<const uchar*> rows;
    for (std::size_t i = 0; i < descriptor_sets.size(); ++i) {
      const cv::Mat& d = descriptor_sets[i];
      if (d.empty()) continue;
      detail::check(d.type() == CV_8UC1, "BinaryVocabulary::learn: descriptors of image " + std::to_string(i) +
                                             " are not binary (CV_8UC1)");
      if (cols < 0) cols = d.cols;
      detail::check(d.cols == cols, "BinaryVocabulary::learn: descriptors of image " + std::to_string(i) + " have " +
                                        std::to_string(d.cols) + " bytes, earlier ones " + std::to_string(cols));
      for (int r = 0; r < d.rows; ++r) rows.push_back(d.ptr<uchar>(r));
    }
    detail::check(rows.size() >= static_cast<std::size_t>(o.words),
                  "BinaryVocabulary::learn: " + std::to_string(rows.size()) + " descriptors cannot make " +
                      std::to_string(o.words) + " words");
    std::mt19937_64 rng(o.seed);
    std::shuffle(rows.begin(), rows.end(), rng);
    if (rows.size() > o.max_descriptors) rows.resize(o.max_descriptors);
    cv::Mat sample(static_cast<int>(rows.size()), cols, CV_8UC1);
    for (std::size_t r = 0; r < rows.size(); ++r)
      std::copy(rows[r], rows[r] + cols, sample.ptr<uchar>(static_cast<int>(r)));

    BinaryVocabulary v;
    v.words_ = sample.rowRange(0, o.words).clone();  // the sample is shuffled: random distinct rows
    std::vector<int> label;
    for (int it = 0; it < o.iterations; ++it) {
      label = v.assign(sample);
      std::vector<std::vector<int>> ones(static_cast<std::size_t>(o.words), std::vector<int>(static_cast<std::size_t>(cols) * 8, 0));
      std::vector<int> members(static_cast<std::size_t>(o.words), 0);
      for (int r = 0; r < sample.rows; ++r) {
        auto& acc = ones[static_cast<std::size_t>(label[static_cast<std::size_t>(r)])];
        ++members[static_cast<std::size_t>(label[static_cast<std::size_t>(r)])];
        const uchar* p = sample.ptr<uchar>(r);
        for (int b = 0; b < cols; ++b)
          for (int bit = 0; bit < 8; ++bit) acc[static_cast<std::size_t>(b * 8 + bit)] += (p[b] >> bit) & 1;
      }
      std::uniform_int_distribution<int> pick(0, sample.rows - 1);
      for (int w = 0; w < o.words; ++w) {
        uchar* out = v.words_.ptr<uchar>(w);
        const int m = members[static_cast<std::size_t>(w)];
        if (m == 0) {  // an empty cluster restarts from a random descriptor
          sample.row(pick(rng)).copyTo(v.words_.row(w));
          continue;
        }
        const auto& acc = ones[static_cast<std::size_t>(w)];
        for (int b = 0; b < cols; ++b) {
          uchar byte = 0;
          for (int bit = 0; bit < 8; ++bit)
            if (2 * acc[static_cast<std::size_t>(b * 8 + bit)] > m) byte = static_cast<uchar>(byte | (1u << bit));
          out[b] = byte;
        }
      }
    }
    return v;
  }

  /// Builds a vocabulary from given words (CV_8UC1, one a row).
  explicit BinaryVocabulary(cv::Mat words) : words_(std::move(words)) {
    detail::check(!words_.empty() && words_.type() == CV_8UC1, "BinaryVocabulary: words must be a non-empty CV_8UC1 matrix");
  }

  /// The nearest word (Hamming) of each descriptor row.
  [[nodiscard]] std::vector<int> assign(const cv::Mat& descriptors) const {
    detail::check(!words_.empty(), "BinaryVocabulary::assign: the vocabulary is empty (learn it first)");
    std::vector<int> out;
    if (descriptors.empty()) return out;
    detail::check(descriptors.type() == CV_8UC1 && descriptors.cols == words_.cols,
                  "BinaryVocabulary::assign: descriptors must be CV_8UC1 with " + std::to_string(words_.cols) +
                      " bytes a row, got " + std::to_string(descriptors.cols));
    std::vector<cv::DMatch> m;
    cv::BFMatcher(cv::NORM_HAMMING, false).match(descriptors, words_, m);
    out.resize(static_cast<std::size_t>(descriptors.rows), 0);
    for (const auto& d : m) out[static_cast<std::size_t>(d.queryIdx)] = d.trainIdx;
    return out;
  }

  [[nodiscard]] int size() const noexcept { return words_.rows; }
  [[nodiscard]] const cv::Mat& words() const noexcept { return words_; }

 private:
  cv::Mat words_;
};

}  // namespace vmap
