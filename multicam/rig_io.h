#pragma once
// Rig calibration outputs beside rig.json: per-camera OpenCV YAML (intrinsics, distortion and
// the extrinsics R, t as cam <- world, the way cv::stereoCalibrate and most tools read them)
// and the calibration report JSON.
#include <filesystem>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "multicam/rig_calib.h"
#include "multicam/sync.h"

namespace previz::multicam {

// One <dir>/<camera>.yaml per camera (atomic). Returns the files written.
std::vector<std::filesystem::path> writeRigYaml(const Rig& rig, const std::filesystem::path& dir);

nlohmann::json reportToJson(const RigCalibResult& result);
nlohmann::json syncToJson(const SyncReport& sync);
nlohmann::json checkToJson(const RigCheckResult& check);

}  // namespace previz::multicam
