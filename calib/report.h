#pragma once
// What `previz calib intrinsics` leaves beside the camera file for a person to read: a JSON
// report (every figure of the solve, each view and why it was or was not used, selection,
// refinement rounds, uncertainty and cross-validation) and PNGs drawn with OpenCV:
//   <stem>.residuals.png    residual vectors at the detected points (magnified), outliers red
//   <stem>.coverage.png     where the board's points fell over the image (heat map)
//   <stem>.uncertainty.png  projection uncertainty map (validation.h) with a colour scale
//   <stem>.views.png        per-view RMS bars; views not used in red with the reason
// Pixels: docs/conventions.md. Every file is written atomically.
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "calib/frontal.h"
#include "calib/intrinsics.h"
#include "calib/observations.h"
#include "calib/validation.h"
#include "core/board.h"

namespace previz::calib {

struct CalibReport {
  IntrinsicsResult result;
  BoardSpec board;
  // The views as detected (image order), with focus and rejection marks; may be empty.
  std::vector<ViewObservations> views;
  std::vector<int> selected;            // indices into views chosen by the selector (if any)
  std::string selection_summary;
  std::vector<FrontalIteration> frontal;  // refinement rounds (if any)
  std::optional<UncertaintyMap> uncertainty;
  std::optional<CrossValidationResult> cross_validation;
};

nlohmann::json reportToJson(const CalibReport& report);

// Drawings (8-bit BGR). Long side about max_side px.
cv::Mat drawResiduals(const IntrinsicsResult& result, int max_side = 1200);
cv::Mat drawCoverage(const IntrinsicsResult& result, int max_side = 1200);
cv::Mat drawUncertainty(const UncertaintyMap& map, int max_side = 1200);
// One bar per image of `views` (or per solved view when `views` is empty). With `selected`
// non-empty, result.views[k] is views[selected[k]]; otherwise result.views[i] is views[i].
cv::Mat drawViewChart(const IntrinsicsResult& result, const std::vector<ViewObservations>& views,
                      const std::vector<int>& selected = {});

struct ReportFiles {
  std::filesystem::path json, residuals, coverage, uncertainty, views;
};
// Writes <stem>.report.json and the PNGs above (uncertainty only when the report has a map).
ReportFiles writeCalibReport(const CalibReport& report, const std::filesystem::path& stem);

}  // namespace previz::calib
