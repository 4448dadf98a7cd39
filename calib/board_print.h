#pragma once
// Printable calibration boards (`previz calib board`): a PNG at a given DPI whose pixels have
// the board's exact physical size (margin included; the DPI is stored in the PNG's pHYs chunk),
// an SVG of the same board in millimetres, and the board JSON (core/board.h) beside them.
// The pattern is the one core/board.h describes and the synthetic studio draws.
#include <filesystem>

#include <opencv2/core.hpp>

#include "core/board.h"

namespace previz::calib {

// The printed sheet (pattern + margin) as an 8-bit grey image, 0 = ink, 255 = paper, at
// px_per_m pixels per metre. Pixel (u, v) covers [u, u + 1] x [v, v + 1] / px_per_m of the sheet
// from its top-left corner, and is black when its centre is; so board point (x, y) lies at
// pixel ((x + margin_m) px_per_m - 0.5, (y + margin_m) px_per_m - 0.5) (docs/conventions.md).
// Size: round((size_m + 2 margin_m) px_per_m). Throws Error for an invalid board or an image
// beyond 2^28 pixels.
cv::Mat drawBoard(const BoardSpec& spec, double px_per_m);

struct PrintedBoard {
  std::filesystem::path png, svg, json;
  std::filesystem::path kalibr_yaml;  // Kalibr-layout AprilGrid: <stem>.yaml, Kalibr's target file
  cv::Size png_size;
  double width_mm = 0, height_mm = 0;  // the sheet, margin included
};

// Writes <out_stem>.png (dpi dots per inch, pHYs set), <out_stem>.svg (width/height in mm,
// viewBox in mm) and <out_stem>.json (writeBoard), each atomically; a Kalibr-layout AprilGrid
// also <out_stem>.yaml (Kalibr's aprilgrid.yaml). Print at 100 % scale.
// dpi must lie in [25, 2400]; throws Error naming the field or file.
PrintedBoard printBoard(const BoardSpec& spec, double dpi, const std::filesystem::path& out_stem);

}  // namespace previz::calib
