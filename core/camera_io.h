#pragma once
// How other tools hand cameras over: OpenCV calibration YAML, 3x4 projection matrices and
// "name K R t" text rows (Middlebury's *_par.txt). Readers throw Error naming file and field.
#include <filesystem>
#include <string>
#include <vector>

#include "core/rig.h"

namespace previz {

// OpenCV FileStorage YAML/XML: image_width, image_height, camera_matrix (3x3),
// distortion_coefficients (1x4, 1x5, 1x8..; k1 k2 p1 p2 [k3]; higher terms must be zero).
Camera readOpenCvCamera(const std::filesystem::path& path, const std::string& name = {});
void writeOpenCvCamera(const Camera& camera, const std::filesystem::path& path);  // atomic

// Decomposes P = K [R | t] (RQ decomposition, K with positive diagonal). Distortion zero.
RigCamera rigCameraFromProjection(const Eigen::Matrix<double, 3, 4>& P, int width, int height,
                                  const std::string& name);
Eigen::Matrix<double, 3, 4> projectionMatrix(const RigCamera& camera);  // K [R|t], t = cam<-world

// Text rows, one camera a line, '#' comments allowed:
//   KRt:  name k11 k12 k13 k21 k22 k23 k31 k32 k33 r11 .. r33 t1 t2 t3   (Middlebury par.txt;
//         an optional first line holding only the count of cameras is skipped)
//   P:    name p11 .. p34
// width/height are not in these formats and are given by the caller.
Rig readKRtRows(const std::filesystem::path& path, int width, int height);
Rig readProjectionRows(const std::filesystem::path& path, int width, int height);
void writeKRtRows(const Rig& rig, const std::filesystem::path& path);

}  // namespace previz
