#include "calib/focus.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include <opencv2/imgproc.hpp>

#include "calib/detail/detect_common.h"
#include "core/error.h"
#include "core/srgb.h"
#include "core/stats.h"

namespace previz::calib {

namespace {

}  // namespace

FocusMeasure measureFocus(const cv::Mat& image, const std::vector<Observation>& points,
                          bool linear_light) {
  if (image.empty()) throw Error("focus: image is empty");
  cv::Mat grey;
  if (image.type() == CV_8UC1)
    grey = image;
  else if (image.type() == CV_8UC3)
    cv::cvtColor(image, grey, cv::COLOR_BGR2GRAY);
  else if (image.type() == CV_8UC4)
    cv::cvtColor(image, grey, cv::COLOR_BGRA2GRAY);
  else
    throw Error("focus: image must be 8-bit grey, BGR or BGRA");

  // Region: the convex hull of the points, one pixel in from the border (derivatives).
  cv::Mat mask(grey.size(), CV_8U, cv::Scalar(0));
  if (points.size() >= 3) {
    std::vector<cv::Point> pts, hull;
    for (const Observation& o : points)
      pts.emplace_back(static_cast<int>(std::lround(o.px.x())),
                       static_cast<int>(std::lround(o.px.y())));
    cv::convexHull(pts, hull);
    cv::fillConvexPoly(mask, hull, cv::Scalar(255));
  } else {
    mask.setTo(255);
  }
  if (grey.rows < 3 || grey.cols < 3) return {};
  mask.row(0).setTo(0);
  mask.row(grey.rows - 1).setTo(0);
  mask.col(0).setTo(0);
  mask.col(grey.cols - 1).setTo(0);

  const float* lut = srgb8ToLinear().data();
  auto lin = [&](std::uint8_t v) { return linear_light ? lut[v] : v / 255.0f; };

  FocusMeasure f;
  double ml_sum = 0, lap_sum = 0, lap_sq = 0;
  long count = 0;
  std::vector<float> ml_lin, grad_lin;
  for (int v = 1; v + 1 < grey.rows; ++v) {
    const std::uint8_t* up = grey.ptr<std::uint8_t>(v - 1);
    const std::uint8_t* row = grey.ptr<std::uint8_t>(v);
    const std::uint8_t* down = grey.ptr<std::uint8_t>(v + 1);
    const std::uint8_t* m = mask.ptr<std::uint8_t>(v);
    for (int u = 1; u + 1 < grey.cols; ++u) {
      if (!m[u]) continue;
      const int c = row[u], l = row[u - 1], r = row[u + 1], t = up[u], b = down[u];
      ml_sum += std::abs(2 * c - l - r) + std::abs(2 * c - t - b);
      const double lap = l + r + t + b - 4 * c;
      lap_sum += lap;
      lap_sq += lap * lap;
      ++count;
      const float lc = lin(row[u]), ll = lin(row[u - 1]), lr = lin(row[u + 1]), lt = lin(up[u]),
                  lb = lin(down[u]);
      ml_lin.push_back(std::abs(2 * lc - ll - lr) + std::abs(2 * lc - lt - lb));
      grad_lin.push_back(0.5f * (std::abs(lr - ll) + std::abs(lb - lt)));
    }
  }
  if (count == 0) return f;
  f.modified_laplacian = ml_sum / count;
  const double lap_mean = lap_sum / count;
  f.variance_of_laplacian = lap_sq / count - lap_mean * lap_mean;

  const double threshold = 0.25 * quantile(grad_lin, 0.99);
  if (!(threshold > 0)) return f;
  std::vector<float> flat;
  for (size_t k = 0; k < grad_lin.size(); ++k)
    if (grad_lin[k] < 0.5 * threshold) flat.push_back(ml_lin[k]);
  const double noise_floor = quantile(flat, 0.5);
  double ml_edges = 0, grad_edges = 0;
  int edges = 0;
  for (size_t k = 0; k < grad_lin.size(); ++k) {
    if (grad_lin[k] <= threshold) continue;
    ml_edges += std::max(0.0, ml_lin[k] - noise_floor);
    grad_edges += grad_lin[k];
    ++edges;
  }
  // Fewer than a few dozen edge pixels is no board region worth judging.
  if (edges < 32 || !(grad_edges > 0)) return f;
  f.sharpness = ml_edges / grad_edges;
  f.edge_pixels = edges;
  return f;
}

void FocusOptions::validate() const {
  if (!(std::isfinite(min_relative_sharpness) && min_relative_sharpness > 0 &&
        min_relative_sharpness < 1)) {
    ErrorContext context;
    context.field = "min_relative_sharpness";
    throw Error("focus: min_relative_sharpness must be in (0, 1) (got " +
                    std::to_string(min_relative_sharpness) + ")",
                context);
  }
}

double sharpnessReference(const std::vector<ViewObservations>& views) {
  std::vector<double> s;
  for (const ViewObservations& v : views)
    if (v.found() && !v.rejected) s.push_back(v.focus.sharpness);
  if (s.empty()) return 0;
  std::sort(s.begin(), s.end());
  // Upper half: s[n/2 .. n-1]; its median.
  const size_t lo = s.size() / 2, n = s.size() - lo;
  return n % 2 ? s[lo + n / 2] : 0.5 * (s[lo + n / 2 - 1] + s[lo + n / 2]);
}

int rejectSoftViews(std::vector<ViewObservations>& views, const FocusOptions& options) {
  options.validate();
  const double reference = sharpnessReference(views);
  if (!(reference > 0)) return 0;
  const double limit = options.min_relative_sharpness * reference;
  int rejected = 0;
  for (ViewObservations& v : views) {
    if (!v.found() || v.rejected || v.focus.sharpness >= limit) continue;
    v.rejected = true;
    char buf[160];
    std::snprintf(buf, sizeof buf, "soft: sharpness %.3f < %.2f x the sequence's %.3f",
                  v.focus.sharpness, options.min_relative_sharpness, reference);
    v.rejected_reason = buf;
    ++rejected;
  }
  return rejected;
}

}  // namespace previz::calib
