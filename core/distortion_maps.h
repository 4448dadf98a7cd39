#pragma once
// Whole-image distortion and undistortion maps (cv::remap-ready) and ST maps.
// Pixel (0,0) is the centre of the top-left pixel (docs/conventions.md).
#include <filesystem>

#include <opencv2/core.hpp>

#include "core/camera.h"

namespace previz {

// An ideal pinhole (no distortion) with the same focal lengths, optionally enlarged by an
// overscan fraction (0.1 = 10 % more pixels each way, principal point shifted to stay centred).
Camera idealPinhole(const Camera& lens_camera, double overscan = 0.0);

// Undistort: output pixels are in 'pinhole' (no distortion); each holds the source position in
// the distorted image of 'lens'. cv::remap(distorted, out, map, noArray(), INTER_LINEAR).
// Forward model only: exact.
cv::Mat makeUndistortMap(const Camera& lens, const Camera& pinhole);  // CV_32FC2

// Distort: output pixels are in 'lens' (distorted); each holds the source position in the
// 'pinhole' image (e.g. a CG render with overscan). Needs the inverse model: pixels that are
// not invertible get (-1,-1) (remap then reads the border value) and are counted.
struct DistortMapResult {
  cv::Mat map;                // CV_32FC2
  int not_invertible = 0;     // pixels with no valid inverse
  int max_iterations = 0;     // worst Newton iteration count seen
};
DistortMapResult makeDistortMap(const Camera& lens, const Camera& pinhole,
                                const InverseOptions& options = {});

// ST maps (Nuke's convention) written as EXR with channels R = s, G = t:
//   s = (x_src + 0.5) / W_src, t = 1 - (y_src + 0.5) / H_src, origin at the bottom-left corner
//   of the source image. The header records the convention (previz:st_convention,
//   previz:pixel_origin, previz:source_size) so nothing is left to guess.
void writeStMap(const std::filesystem::path& path, const cv::Mat& remap_map, cv::Size source_size,
                const std::string& description);
// Reads an ST map back into a remap-ready CV_32FC2 map (inverse of the formula above).
cv::Mat readStMap(const std::filesystem::path& path, cv::Size* source_size = nullptr);

}  // namespace previz
