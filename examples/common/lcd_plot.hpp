#pragma once

// The precision-recall curve of a loop-closure run drawn with OpenCV: axes from 0 to 1
// with ticks every 0.1, axis labels, a title, and the curve as a step line with a dot
// per threshold.

#include <vmap/lcd/evaluation.hpp>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <cstdio>
#include <string>
#include <vector>

namespace vmap::examples {

/// One curve of the plot.
struct PrCurveSeries {
  std::vector<PrecisionRecall> points;
  std::string name;
  cv::Scalar colour{200, 80, 0};
};

/// White canvas, recall on x, precision on y.
inline cv::Mat draw_pr_curves(const std::vector<PrCurveSeries>& series, const std::string& title,
                              cv::Size size = {640, 520}) {
  cv::Mat canvas(size, CV_8UC3, cv::Scalar::all(255));
  const int left = 70, right = 20, top = 40, bottom = 60;
  const int w = size.width - left - right, h = size.height - top - bottom;
  const auto at = [&](double recall, double precision) {
    return cv::Point(left + static_cast<int>(recall * w + 0.5), top + h - static_cast<int>(precision * h + 0.5));
  };
  const auto font = cv::FONT_HERSHEY_SIMPLEX;
  const cv::Scalar ink(0, 0, 0), grid(225, 225, 225);
  char buf[32];
  for (int k = 0; k <= 10; ++k) {
    const double v = k / 10.0;
    cv::line(canvas, at(v, 0), at(v, 1), grid, 1);
    cv::line(canvas, at(0, v), at(1, v), grid, 1);
    cv::line(canvas, at(v, 0), at(v, 0) + cv::Point(0, 5), ink, 1);
    cv::line(canvas, at(0, v), at(0, v) - cv::Point(5, 0), ink, 1);
    std::snprintf(buf, sizeof buf, "%.1f", v);
    cv::putText(canvas, buf, at(v, 0) + cv::Point(-11, 20), font, 0.4, ink, 1, cv::LINE_AA);
    cv::putText(canvas, buf, at(0, v) + cv::Point(-35, 4), font, 0.4, ink, 1, cv::LINE_AA);
  }
  cv::rectangle(canvas, at(0, 1), at(1, 0), ink, 1);
  cv::putText(canvas, "recall", cv::Point(left + w / 2 - 25, size.height - 15), font, 0.55, ink, 1, cv::LINE_AA);
  // The y label, rotated: drawn on its own canvas and turned by 90 degrees.
  cv::Mat ylabel(24, 100, CV_8UC3, cv::Scalar::all(255));
  cv::putText(ylabel, "precision", cv::Point(5, 17), font, 0.55, ink, 1, cv::LINE_AA);
  cv::rotate(ylabel, ylabel, cv::ROTATE_90_COUNTERCLOCKWISE);
  ylabel.copyTo(canvas(cv::Rect(4, top + h / 2 - 50, ylabel.cols, ylabel.rows)));
  // The title starts at the plot's left edge; a long one is drawn smaller so it fits.
  double title_scale = 0.55;
  int base = 0;
  while (title_scale > 0.3 && cv::getTextSize(title, font, title_scale, 1, &base).width > size.width - left - 5)
    title_scale -= 0.025;
  cv::putText(canvas, title, cv::Point(left, 25), font, title_scale, ink, 1, cv::LINE_AA);
  int legend_y = top + 20;
  for (const PrCurveSeries& s : series) {
    cv::Point prev;
    bool first = true;
    for (const PrecisionRecall& p : s.points) {
      const cv::Point q = at(p.recall, p.precision);
      if (!first) {
        cv::line(canvas, prev, cv::Point(q.x, prev.y), s.colour, 2, cv::LINE_AA);
        cv::line(canvas, cv::Point(q.x, prev.y), q, s.colour, 2, cv::LINE_AA);
      }
      cv::circle(canvas, q, 3, s.colour, cv::FILLED, cv::LINE_AA);
      prev = q;
      first = false;
    }
    cv::line(canvas, cv::Point(left + 15, legend_y + h / 2), cv::Point(left + 45, legend_y + h / 2), s.colour, 2);
    cv::putText(canvas, s.name, cv::Point(left + 52, legend_y + h / 2 + 5), font, 0.45, ink, 1, cv::LINE_AA);
    legend_y += 20;
  }
  return canvas;
}

}  // namespace vmap::examples
