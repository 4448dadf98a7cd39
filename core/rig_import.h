#pragma once
// Other tools' calibrations in and out of previz, with their extrinsics: OpenCV FileStorage
// (camera_matrix / rvec / tvec, stereoCalibrate's R / T, the stereo_calib sample's M1 D1 M2 D2),
// Kalibr's camchain.yaml, COLMAP's text model, Middlebury K R t rows and 3x4 P rows.
//
// Every import returns the rig and a report of what it assumed (units, axes, sizes, names,
// pixel conventions) and of what looks wrong without stopping it (rotations re-orthonormalised,
// every camera at the origin, cameras looking away from their common point). The rig it returns
// is in previz's conventions (docs/conventions.md): metres, T_world_cam, pixel (0,0) at the
// centre of the top-left pixel. Readers throw Error naming file, camera and field.
// The formats and their conventions: docs/formats.md, "Camera exchange".
#include <filesystem>
#include <functional>
#include <optional>
#include <utility>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "core/rig.h"

namespace previz {

struct ImportOptions {
  // Image size for files that carry none (K R t / P rows, OpenCV files without image_width /
  // image_height, the stereo sample's M1 D1 M2 D2); 0 = not given. A file's own size wins.
  int width = 0;
  int height = 0;
  // Else the size of the named camera's images, when the caller knows them (`camera import
  // --take`: the take's first frame of that camera); nullopt = unknown.
  std::function<std::optional<std::pair<int, int>>(const std::string& camera)> size_of;
  // Unit of the file's translations: "m", "cm" or "mm"; the rig gets metres.
  std::string units = "m";
  // The file's world axes, turned into previz's z-up world by a rotation about x:
  //   "none"   taken as they are (the file's world is z up)
  //   "y-up"   (x, y, z) -> (x, -z, y)   Maya, Houdini, OpenGL-style worlds
  //   "z-down" (x, y, z) -> (x, -y, -z)  NED-style worlds, OpenCV boards lying face up
  //   "y-down" (x, y, z) -> (x, z, -y)   a camera frame used as the world (Kalibr's cam0, a
  //                                      stereo pair's camera 1), upright when that camera is level
  std::string flip = "none";
  // Camera names in the order the cameras are read (one per camera); empty = the format's own.
  std::vector<std::string> names;

  void validate() const;  // throws Error naming the field
  double metresPerUnit() const;
};

// What an import took for granted and what it found suspicious: never silent, never fatal.
struct ImportReport {
  std::string format;                    // "opencv", "kalibr", "colmap", "krt", "projection"
  std::vector<std::string> files;        // the files read
  std::vector<std::string> assumptions;  // conventions applied, values not in the files
  std::vector<std::string> warnings;     // suspicious input that was imported anyway

  std::string fullReport() const;  // one line each, for a person
  nlohmann::json toJson() const;
};

struct RigImport {
  Rig rig;
  ImportReport report;
};

// OpenCV FileStorage (YAML, XML or JSON; also ROS camera_info YAML), one or more files. Each
// file holds one camera (camera_matrix, distortion_coefficients, optional image_width/height,
// optional pose: rvec + tvec, or stereoCalibrate's R + T) or a stereo pair (M1 D1 M2 D2,
// optionally R T; or R T in the next file, as the stereo_calib sample writes intrinsics.yml
// and extrinsics.yml). Names: options.names, else the file's stem, else (stems shared) the
// parent folder's name. extrinsic_parameters (per-view board poses) is refused as a pose.
RigImport importOpenCv(const std::vector<std::filesystem::path>& files, const ImportOptions& options);
// Kalibr camchain.yaml: pinhole cameras with radtan (or no) distortion, chained by T_cn_cnm1;
// cam0 is the world unless cam0 holds previz's T_world_cam. Names cam0, cam1, ...
RigImport importKalibr(const std::filesystem::path& camchain, const ImportOptions& options);
// COLMAP text model: DIR/cameras.txt + DIR/images.txt; one camera per image, named by the
// image NAME's stem (the whole NAME, '/' -> '_', where stems repeat).
RigImport importColmap(const std::filesystem::path& dir, const ImportOptions& options);
// Text rows (see camera_io.h): Middlebury K R t rows and 3x4 P rows; options.width/height needed.
RigImport importKRtRows(const std::filesystem::path& path, const ImportOptions& options);
RigImport importProjectionRows(const std::filesystem::path& path, const ImportOptions& options);

// Exports, extrinsics included, every file atomic. A value a format cannot carry (skew in
// Kalibr or COLMAP, k3 in Kalibr, distortion in rows) is an Error naming camera and field.
// One OpenCV YAML per camera, DIR/<name>.yaml, with rvec/tvec; returns the files written.
std::vector<std::filesystem::path> exportOpenCv(const Rig& rig, const std::filesystem::path& dir);
// camchain.yaml: cam0 = the rig's first camera, T_cn_cnm1 down the rig's order; cam0 also
// holds T_world_cam (previz's key, ignored by Kalibr) so that the world survives the trip.
void exportKalibr(const Rig& rig, const std::filesystem::path& camchain);
// DIR/cameras.txt, DIR/images.txt (NAME = <camera name>.png) and an empty DIR/points3D.txt;
// returns the files written.
std::vector<std::filesystem::path> exportColmap(const Rig& rig, const std::filesystem::path& dir);
// K R t rows and P rows: writeKRtRows / writeProjectionRows (camera_io.h).

// The rotation rule of every import: a matrix orthonormal to kRotationRefuseAbove
// (max |R^T R - I|) with det > 0 is replaced by the nearest rotation (SVD), with a warning above
// kRotationWarnAbove (below it is the print precision of a double-precision file); worse, or a
// reflection, is refused naming file, camera and field.
constexpr double kRotationRefuseAbove = 1e-4;
constexpr double kRotationWarnAbove = 1e-9;
Eigen::Matrix3d nearestRotation(const Eigen::Matrix3d& M);
Eigen::Matrix3d checkedRotation(const Eigen::Matrix3d& R, const std::filesystem::path& file,
                                const std::string& camera, const std::string& field,
                                ImportReport& report);

// Warnings about a rig's poses as a whole: every camera at one point (the origin: a file that
// lost its poses), and cameras looking away from their common point (the point nearest to all
// optical axes lies behind most cameras: inverted poses, a flipped axis). Used by every import
// and by `camera info`.
std::vector<std::string> rigPoseWarnings(const Rig& rig);

}  // namespace previz
