#include "calib/report.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include <opencv2/imgproc.hpp>

#include "calib/detail/projection.h"
#include "core/io.h"
#include "core/rig.h"

namespace previz::calib {

namespace {

const cv::Scalar kBackground(24, 24, 24);
const cv::Scalar kText(230, 230, 230);
const cv::Scalar kGood(90, 200, 90);
const cv::Scalar kBad(60, 60, 230);
const cv::Scalar kAxis(120, 120, 120);

std::string fmt(const char* format, double v) {
  char buffer[64];
  std::snprintf(buffer, sizeof(buffer), format, v);
  return buffer;
}

void text(cv::Mat& image, const std::string& s, cv::Point at, double scale = 0.5,
          cv::Scalar colour = kText) {
  cv::putText(image, s, at, cv::FONT_HERSHEY_SIMPLEX, scale, colour, 1, cv::LINE_AA);
}

double canvasScale(cv::Size image, int max_side) {
  return std::min(1.0, static_cast<double>(max_side) / std::max(image.width, image.height));
}

// A vertical colour bar for [0, max_value] with ticks, to the right of a map.
void colourBar(cv::Mat& canvas, cv::Rect area, double max_value, const std::string& unit, int colormap) {
  cv::Mat ramp(area.height, 1, CV_8U);
  for (int y = 0; y < area.height; ++y) ramp.at<std::uint8_t>(y) = static_cast<std::uint8_t>(255 - 255 * y / std::max(1, area.height - 1));
  cv::Mat coloured;
  cv::applyColorMap(ramp, coloured, colormap);
  cv::resize(coloured, coloured, area.size(), 0, 0, cv::INTER_NEAREST);
  coloured.copyTo(canvas(area));
  for (int k = 0; k <= 4; ++k) {
    const int y = area.y + area.height - 1 - k * (area.height - 1) / 4;
    text(canvas, fmt("%.3g", max_value * k / 4.0) + (k == 4 ? " " + unit : ""),
         cv::Point(area.x + area.width + 6, y + 5), 0.45);
  }
}

struct ViewRow {
  std::string name;
  bool used = false;
  double rms = 0;
  int rejected_points = 0;
  std::string reason;
};

std::vector<ViewRow> viewRows(const IntrinsicsResult& result, const std::vector<ViewObservations>& views,
                              const std::vector<int>& selected) {
  std::vector<ViewRow> rows;
  auto fromResult = [](const ViewResult& vr) {
    ViewRow row;
    row.name = vr.source;
    row.used = vr.used;
    row.rms = vr.rms_px;
    row.rejected_points = vr.points_rejected;
    row.reason = vr.dropped_reason;
    return row;
  };
  if (views.empty()) {
    for (const ViewResult& vr : result.views) rows.push_back(fromResult(vr));
    return rows;
  }
  std::vector<int> solved_index(views.size(), -1);
  if (selected.empty()) {
    for (size_t i = 0; i < views.size() && i < result.views.size(); ++i) solved_index[i] = static_cast<int>(i);
  } else {
    for (size_t k = 0; k < selected.size() && k < result.views.size(); ++k)
      if (selected[k] >= 0 && selected[k] < static_cast<int>(views.size())) solved_index[selected[k]] = static_cast<int>(k);
  }
  for (size_t i = 0; i < views.size(); ++i) {
    if (solved_index[i] >= 0) {
      rows.push_back(fromResult(result.views[solved_index[i]]));
      continue;
    }
    ViewRow row;
    row.name = views[i].source;
    if (!views[i].found()) row.reason = views[i].failure.empty() ? "no board found" : views[i].failure;
    else if (views[i].rejected) row.reason = views[i].rejected_reason;
    else row.reason = "not selected";
    rows.push_back(row);
  }
  return rows;
}

}  // namespace

cv::Mat drawResiduals(const IntrinsicsResult& result, int max_side) {
  const double s = canvasScale(result.image_size, max_side);
  const int w = static_cast<int>(std::lround(result.image_size.width * s));
  const int h = static_cast<int>(std::lround(result.image_size.height * s));
  const int footer = 40;
  cv::Mat canvas(h + footer, w, CV_8UC3, kBackground);
  cv::rectangle(canvas, cv::Rect(0, 0, w, h), kAxis, 1);
  // Magnify so that the 95th percentile inlier residual draws about 2 % of the width.
  std::vector<double> norms;
  for (const PointResidual& p : result.residuals)
    if (!p.rejected) norms.push_back(p.residual.norm());
  double p95 = 0;
  if (!norms.empty()) {
    std::nth_element(norms.begin(), norms.begin() + norms.size() * 95 / 100, norms.end());
    p95 = norms[norms.size() * 95 / 100];
  }
  const double magnify = p95 > 0 ? std::max(1.0, 0.02 * result.image_size.width / p95) : 1.0;
  for (const PointResidual& p : result.residuals) {
    const cv::Point2d a(p.px.x() * s, p.px.y() * s);
    // The residual is detected - projected; the arrow points from the model to the detection.
    const cv::Point2d b = a - cv::Point2d(p.residual.x(), p.residual.y()) * (magnify * s);
    const cv::Scalar colour = p.rejected ? kBad : kGood;
    if (p.rejected) {
      cv::circle(canvas, a, 3, colour, 1, cv::LINE_AA);
    } else {
      cv::line(canvas, b, a, colour, 1, cv::LINE_AA);
      cv::circle(canvas, a, 1, colour, -1, cv::LINE_AA);
    }
  }
  text(canvas,
       "residuals x" + fmt("%.0f", magnify) + " (model -> detection); RMS " + fmt("%.3f", result.rms_px) +
           " px; " + std::to_string(result.points_rejected) + " outliers (red circles)",
       cv::Point(8, h + 26));
  return canvas;
}

cv::Mat drawCoverage(const IntrinsicsResult& result, int max_side) {
  const int cols = 32;
  const int rows = std::max(2, static_cast<int>(std::lround(32.0 * result.image_size.height / result.image_size.width)));
  cv::Mat counts(rows, cols, CV_32F, cv::Scalar(0));
  for (const PointResidual& p : result.residuals) {
    if (p.rejected) continue;
    const int c = std::clamp(static_cast<int>((p.px.x() + 0.5) * cols / result.image_size.width), 0, cols - 1);
    const int r = std::clamp(static_cast<int>((p.px.y() + 0.5) * rows / result.image_size.height), 0, rows - 1);
    counts.at<float>(r, c) += 1.0f;
  }
  double max_count = 0;
  cv::minMaxLoc(counts, nullptr, &max_count);
  const int covered = cv::countNonZero(counts);
  const double s = canvasScale(result.image_size, max_side);
  const int w = static_cast<int>(std::lround(result.image_size.width * s));
  const int h = static_cast<int>(std::lround(result.image_size.height * s));
  cv::Mat scaled8;
  counts.convertTo(scaled8, CV_8U, max_count > 0 ? 255.0 / max_count : 0.0);
  cv::Mat coloured;
  cv::applyColorMap(scaled8, coloured, cv::COLORMAP_INFERNO);
  cv::resize(coloured, coloured, cv::Size(w, h), 0, 0, cv::INTER_NEAREST);
  const int footer = 40, bar = 90;
  cv::Mat canvas(h + footer, w + bar, CV_8UC3, kBackground);
  coloured.copyTo(canvas(cv::Rect(0, 0, w, h)));
  colourBar(canvas, cv::Rect(w + 10, 10, 16, h - 20), max_count, "pts", cv::COLORMAP_INFERNO);
  text(canvas,
       "board points per cell (" + std::to_string(cols) + " x " + std::to_string(rows) + "); " +
           fmt("%.0f", 100.0 * covered / (rows * cols)) + " % of cells covered",
       cv::Point(8, h + 26));
  return canvas;
}

cv::Mat drawUncertainty(const UncertaintyMap& map, int max_side) {
  const double s = canvasScale(map.grid.image_size, max_side);
  const int w = static_cast<int>(std::lround(map.grid.image_size.width * s));
  const int h = static_cast<int>(std::lround(map.grid.image_size.height * s));
  cv::Mat sigma;
  map.sigma_px.convertTo(sigma, CV_32F);
  cv::patchNaNs(sigma, 0.0);
  double max_value = 0;
  cv::minMaxLoc(sigma, nullptr, &max_value);
  cv::Mat up;
  cv::resize(sigma, up, cv::Size(w, h), 0, 0, cv::INTER_LINEAR);
  cv::Mat scaled8;
  up.convertTo(scaled8, CV_8U, max_value > 0 ? 255.0 / max_value : 0.0);
  cv::Mat coloured;
  cv::applyColorMap(scaled8, coloured, cv::COLORMAP_VIRIDIS);
  const int footer = 40, bar = 110;
  cv::Mat canvas(h + footer, w + bar, CV_8UC3, kBackground);
  coloured.copyTo(canvas(cv::Rect(0, 0, w, h)));
  // A few labelled grid values so the map reads without the bar.
  for (int r = 1; r < map.grid.rows; r += std::max(1, map.grid.rows / 4)) {
    for (int c = 1; c < map.grid.cols; c += std::max(1, map.grid.cols / 5)) {
      const double v = map.sigma_px.at<double>(r, c);
      if (!std::isfinite(v)) continue;
      const Eigen::Vector2d px = map.grid.pixel(r, c) * s;
      text(canvas, fmt("%.3f", v), cv::Point(static_cast<int>(px.x()) - 18, static_cast<int>(px.y())), 0.4,
           cv::Scalar(255, 255, 255));
    }
  }
  colourBar(canvas, cv::Rect(w + 10, 10, 16, h - 20), max_value, "px", cv::COLORMAP_VIRIDIS);
  text(canvas,
       std::string("projection uncertainty (worst-direction sigma, ") + toString(map.mode) +
           "): mean " + fmt("%.3f", map.mean_px) + " px, max " + fmt("%.3f", map.max_px) + " px",
       cv::Point(8, h + 26));
  return canvas;
}

cv::Mat drawViewChart(const IntrinsicsResult& result, const std::vector<ViewObservations>& views,
                      const std::vector<int>& selected) {
  const std::vector<ViewRow> rows = viewRows(result, views, selected);
  const int n = static_cast<int>(rows.size());
  const int bar_w = std::clamp(900 / std::max(1, n), 4, 40);
  const int plot_h = 300, left = 70, top = 30;
  std::vector<const ViewRow*> not_used;
  for (const ViewRow& r : rows)
    if (!r.used) not_used.push_back(&r);
  const int listed = std::min<int>(static_cast<int>(not_used.size()), 30);
  const int width = std::max(left + n * bar_w + 40, 820);
  const int height = top + plot_h + 60 + 18 * (listed + 1);
  cv::Mat canvas(height, width, CV_8UC3, kBackground);
  double max_rms = 0;
  for (const ViewRow& r : rows) max_rms = std::max(max_rms, r.rms);
  if (!(max_rms > 0)) max_rms = 1;
  const int base = top + plot_h;
  cv::line(canvas, cv::Point(left, top), cv::Point(left, base), kAxis, 1);
  cv::line(canvas, cv::Point(left, base), cv::Point(left + n * bar_w, base), kAxis, 1);
  for (int k = 0; k <= 4; ++k) {
    const int y = base - k * plot_h / 4;
    text(canvas, fmt("%.3f", max_rms * k / 4), cv::Point(4, y + 4), 0.4);
    cv::line(canvas, cv::Point(left - 3, y), cv::Point(left, y), kAxis, 1);
  }
  const int rms_y = base - static_cast<int>(plot_h * result.rms_px / max_rms);
  for (int i = 0; i < n; ++i) {
    const ViewRow& r = rows[i];
    const int x = left + i * bar_w;
    if (r.used) {
      const int h = static_cast<int>(plot_h * r.rms / max_rms);
      cv::rectangle(canvas, cv::Rect(x + 1, base - h, bar_w - 2, std::max(h, 1)),
                    r.rejected_points > 0 ? cv::Scalar(80, 180, 230) : kGood, -1);
    } else {
      cv::rectangle(canvas, cv::Rect(x + 1, top, bar_w - 2, plot_h), kBad, 1);
      cv::line(canvas, cv::Point(x + 1, top), cv::Point(x + bar_w - 2, base), kBad, 1);
    }
    if (n <= 40 || i % 5 == 0) text(canvas, std::to_string(i), cv::Point(x + 2, base + 16), 0.35);
  }
  cv::line(canvas, cv::Point(left, rms_y), cv::Point(left + n * bar_w, rms_y), kText, 1, cv::LINE_AA);
  text(canvas, "per-view RMS (px); line: overall " + fmt("%.3f", result.rms_px) +
                   " px; orange: view with outliers; red cross: not used",
       cv::Point(left, 18), 0.45);
  int y = base + 40;
  text(canvas, std::to_string(not_used.size()) + " view(s) not used:", cv::Point(8, y), 0.45);
  for (int k = 0; k < listed; ++k) {
    y += 18;
    const int index = static_cast<int>(not_used[k] - rows.data());
    text(canvas, std::to_string(index) + "  " + not_used[k]->name + ": " + not_used[k]->reason,
         cv::Point(16, y), 0.4, cv::Scalar(150, 150, 255));
  }
  return canvas;
}

nlohmann::json reportToJson(const CalibReport& report) {
  const IntrinsicsResult& r = report.result;
  nlohmann::json j;
  j["format"] = "previz calibration report 1";
  j["pixel_origin"] = "(0,0) is the centre of the top-left pixel";
  j["camera"] = cameraToJson(r.camera);
  j["initial_camera"] = cameraToJson(r.initial_camera);
  j["board"] = boardToJson(report.board);
  nlohmann::json sigma, held;
  const auto mask = r.locks.heldMask(r.camera.dist.model);
  for (int k = 0; k < kIntrinsicCount; ++k) {
    sigma[kIntrinsicNames[k]] = r.sigma[k];
    held[kIntrinsicNames[k]] = mask[k];
  }
  j["sigma"] = sigma;
  j["held"] = held;
  j["locks"] = r.locks.toString();
  j["covariance_order"] = std::vector<std::string>(kIntrinsicNames.begin(), kIntrinsicNames.end());
  nlohmann::json cov = nlohmann::json::array();
  for (int a = 0; a < r.covariance.rows(); ++a) {
    std::vector<double> row;
    for (int b = 0; b < r.covariance.cols(); ++b) row.push_back(r.covariance(a, b));
    cov.push_back(row);
  }
  j["covariance"] = cov;
  j["covariance_ok"] = r.covariance_ok;
  if (!r.covariance_ok) j["covariance_message"] = r.covariance_message;
  j["rms_px"] = r.rms_px;
  j["rms_all_px"] = r.rms_all_px;
  j["initial_rms_px"] = r.initial_rms_px;
  j["residual_sigma_px"] = r.residual_sigma_px;
  j["views_used"] = r.views_used;
  j["points_used"] = r.points_used;
  j["points_rejected"] = r.points_rejected;
  j["rejection_rounds"] = r.rejection_rounds;
  j["iterations"] = r.iterations;
  j["termination"] = r.termination;
  j["solve_ms"] = r.solve_ms;
  nlohmann::json solved = nlohmann::json::array();
  for (const ViewResult& v : r.views) {
    nlohmann::json e = {{"source", v.source}, {"used", v.used}, {"points", v.points},
                        {"points_used", v.points_used}, {"points_rejected", v.points_rejected},
                        {"rms_px", v.rms_px}, {"max_px", v.max_px}};
    if (!v.used) e["reason"] = v.dropped_reason;
    else e["T_cam_board"] = poseToJson(v.T_cam_board);
    solved.push_back(e);
  }
  j["solved_views"] = solved;
  nlohmann::json images = nlohmann::json::array();
  for (size_t i = 0; i < report.views.size(); ++i) {
    const ViewObservations& v = report.views[i];
    nlohmann::json e = {{"source", v.source}, {"found", v.found()}, {"points", v.points.size()},
                        {"sharpness", v.focus.sharpness}};
    if (!v.found()) e["failure"] = v.failure;
    if (v.rejected) e["rejected"] = v.rejected_reason;
    images.push_back(e);
  }
  j["images"] = images;
  if (!report.selected.empty()) {
    j["selection"] = {{"chosen", report.selected}, {"summary", report.selection_summary}};
  }
  if (!report.frontal.empty()) {
    nlohmann::json rounds = nlohmann::json::array();
    for (const FrontalIteration& it : report.frontal) {
      rounds.push_back({{"round", it.iteration}, {"rms_px", it.rms_px}, {"points", it.points},
                        {"views_redetected", it.views_redetected}, {"views_kept", it.views_kept},
                        {"mean_shift_px", it.mean_shift_px}, {"max_change_sigma", it.max_change_sigma},
                        {"camera", cameraToJson(it.camera)}, {"ms", it.ms}});
    }
    j["frontal_refinement"] = rounds;
  }
  if (report.uncertainty) {
    const UncertaintyMap& m = *report.uncertainty;
    j["uncertainty"] = {{"mode", toString(m.mode)}, {"mean_px", m.mean_px}, {"max_px", m.max_px},
                        {"centre_px", m.centre_px}, {"corners_px", m.corners_px},
                        {"grid", {m.grid.cols, m.grid.rows}}};
    if (m.grid.data_radius_px > 0) j["uncertainty"]["data_radius_px"] = m.grid.data_radius_px;
  }
  if (report.cross_validation) {
    const CrossValidationResult& c = *report.cross_validation;
    j["cross_validation"] = {{"diff_rms_px", c.diff_rms_px}, {"diff_max_px", c.diff_max_px},
                             {"predicted_rms_px", c.predicted_rms_px},
                             {"normalised_rms", c.normalised_rms},
                             {"fraction_beyond_3sigma", c.fraction_beyond_3sigma},
                             {"consistent", c.consistent},
                             {"half_a", cameraToJson(c.a.camera)},
                             {"half_b", cameraToJson(c.b.camera)}};
    if (c.grid.data_radius_px > 0) j["cross_validation"]["data_radius_px"] = c.grid.data_radius_px;
  }
  return j;
}

ReportFiles writeCalibReport(const CalibReport& report, const std::filesystem::path& stem) {
  ReportFiles files;
  const std::string base = stem.string();
  files.json = base + ".report.json";
  files.residuals = base + ".residuals.png";
  files.coverage = base + ".coverage.png";
  files.views = base + ".views.png";
  writeJsonAtomic(files.json, reportToJson(report));
  writeImageAtomic(files.residuals, drawResiduals(report.result));
  writeImageAtomic(files.coverage, drawCoverage(report.result));
  writeImageAtomic(files.views, drawViewChart(report.result, report.views, report.selected));
  if (report.uncertainty) {
    files.uncertainty = base + ".uncertainty.png";
    writeImageAtomic(files.uncertainty, drawUncertainty(*report.uncertainty));
  }
  return files;
}

}  // namespace previz::calib
