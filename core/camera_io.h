#pragma once
// How other tools hand cameras over, one camera at a time: OpenCV calibration files, 3x4
// projection matrices and "name K R t" text rows (Middlebury's *_par.txt). Readers throw Error
// naming file and field. Whole rigs with their poses, and every format's import report:
// core/rig_import.h.
#include <filesystem>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "core/rig.h"

namespace previz {

// A lens's distortion_coefficients as OpenCV writes them: 5 x 1 (k1 k2 p1 p2 k3, cv::calibrateCamera),
// 8 x 1 with the rational terms (CALIB_RATIONAL_MODEL), or a fisheye's 4 x 1 (k1..k4, cv::fisheye;
// the file then says distortion_model: equidistant, ROS camera_info's key and value).
cv::Mat openCvDistortion(const Distortion& d);

// OpenCV FileStorage YAML/XML/JSON: image_width, image_height, camera_matrix (3x3),
// distortion_coefficients (1x4, 1x5, 1x8..; k1 k2 p1 p2 [k3]; higher terms must be zero).
// Intrinsics only: pose fields are not read (rig_import.h importOpenCv reads them).
Camera readOpenCvCamera(const std::filesystem::path& path, const std::string& name = {});
// Atomic. With a RigCamera also its pose as rvec / tvec (world -> camera, x_cam = R x_world +
// t, metres), as cv::solvePnP returns it.
void writeOpenCvCamera(const Camera& camera, const std::filesystem::path& path);
void writeOpenCvCamera(const RigCamera& camera, const std::filesystem::path& path);

// The pieces of an OpenCV reader, shared by readOpenCvCamera and importOpenCv.
// Opens YAML (also without OpenCV's "%YAML:1.0" header, as ROS and people write it), XML, JSON.
cv::FileStorage openOpenCvStorage(const std::filesystem::path& path);
// A one-channel matrix as OpenCV writes it (!!opencv-matrix: rows, cols, dt, data), as ROS
// writes it (rows, cols, data) or as a plain list (flat = one row, or a list of rows).
Eigen::MatrixXd readOpenCvMatrix(const cv::FileNode& node, const std::filesystem::path& file,
                                 const std::string& camera, const std::string& field);
// The intrinsics under k_key / d_key ("camera_matrix" / "distortion_coefficients", or the
// stereo sample's "M1" / "D1"); the size from image_width / image_height, else width x height
// (0: none, an Error naming image_width).
Camera readOpenCvIntrinsics(const cv::FileStorage& store, const std::filesystem::path& file,
                            const std::string& name, const char* k_key, const char* d_key, int width = 0,
                            int height = 0);

// Decomposes P = K [R | t] (RQ decomposition, K with positive diagonal). Distortion zero.
RigCamera rigCameraFromProjection(const Eigen::Matrix<double, 3, 4>& P, int width, int height,
                                  const std::string& name);
Eigen::Matrix<double, 3, 4> projectionMatrix(const RigCamera& camera);  // K [R|t], t = cam<-world

// Text rows, one camera a line, '#' comments allowed:
//   KRt:  name k11 k12 k13 k21 k22 k23 k31 k32 k33 r11 .. r33 t1 t2 t3   (Middlebury par.txt;
//         an optional first line holding only the count of cameras is skipped)
//   P:    name p11 .. p34
// width/height are not in these formats and are given by the caller. Rotations follow
// importKRtRows' rule (rig_import.h: orthonormal to 1e-4 is re-orthonormalised, worse refused);
// these return the rig alone: importKRtRows / importProjectionRows also return the report.
Rig readKRtRows(const std::filesystem::path& path, int width, int height);
Rig readProjectionRows(const std::filesystem::path& path, int width, int height);
// Atomic, metres, 17 significant digits; Error naming the camera when it has distortion.
void writeKRtRows(const Rig& rig, const std::filesystem::path& path);
void writeProjectionRows(const Rig& rig, const std::filesystem::path& path);

}  // namespace previz
