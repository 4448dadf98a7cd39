// .chan files and the y-up conversions (see chan.h).
#include "batch/chan.h"

#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <sstream>

#include <Eigen/Geometry>

#include "core/error.h"
#include "core/io.h"
#include "core/units.h"

namespace previz::batch {

namespace {
constexpr double kDeg = degrees(1.0);
}

Eigen::Matrix3d yUpFromZUp() {
  Eigen::Matrix3d A;
  A << 1, 0, 0, 0, 0, 1, 0, -1, 0;
  return A;
}

Pose cameraPoseForPost(const Pose& T_world_cam) {
  const Eigen::Matrix3d A = yUpFromZUp();
  const Eigen::Matrix3d C = Eigen::Vector3d(1, -1, -1).asDiagonal();
  Pose T = Pose::Identity();
  T.linear() = A * T_world_cam.linear() * C;
  T.translation() = A * T_world_cam.translation();
  return T;
}

Pose cameraPoseFromPost(const Pose& T_yup_cgcam) {
  const Eigen::Matrix3d A = yUpFromZUp();
  const Eigen::Matrix3d C = Eigen::Vector3d(1, -1, -1).asDiagonal();
  Pose T = Pose::Identity();
  T.linear() = A.transpose() * T_yup_cgcam.linear() * C;
  T.translation() = A.transpose() * T_yup_cgcam.translation();
  return T;
}

Pose objectPoseForPost(const Pose& T_world_obj) {
  const Eigen::Matrix3d A = yUpFromZUp();
  Pose T = Pose::Identity();
  T.linear() = A * T_world_obj.linear();
  T.translation() = A * T_world_obj.translation();
  return T;
}

Eigen::Matrix3d rotationZXYDeg(const Eigen::Vector3d& r) {
  const Eigen::Matrix3d Rx = Eigen::AngleAxisd(r.x() / kDeg, Eigen::Vector3d::UnitX()).toRotationMatrix();
  const Eigen::Matrix3d Ry = Eigen::AngleAxisd(r.y() / kDeg, Eigen::Vector3d::UnitY()).toRotationMatrix();
  const Eigen::Matrix3d Rz = Eigen::AngleAxisd(r.z() / kDeg, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  return Ry * Rx * Rz;
}

Eigen::Vector3d eulerZXYDeg(const Eigen::Matrix3d& R, const Eigen::Vector3d* near) {
  // R = Ry(b) Rx(a) Rz(c): R(1,2) = -sin a, R(1,0) = cos a sin c, R(1,1) = cos a cos c,
  // R(0,2) = sin b cos a, R(2,2) = cos b cos a.
  const double sa = std::max(-1.0, std::min(1.0, -R(1, 2)));
  const double a = std::asin(sa);
  double b, c;
  if (std::abs(sa) < 1.0 - 1e-12) {
    b = std::atan2(R(0, 2), R(2, 2));
    c = std::atan2(R(1, 0), R(1, 1));
  } else {
    // Gimbal lock (rx = ±90°): only b ∓ c is defined; keep c = 0.
    c = 0;
    b = std::atan2(-R(2, 0), R(0, 0));
  }
  Eigen::Vector3d e(a * kDeg, b * kDeg, c * kDeg);
  if (near) {
    for (int k = 0; k < 3; ++k) e[k] += 360.0 * std::round(((*near)[k] - e[k]) / 360.0);
  }
  return e;
}

Pose ChanKey::pose() const {
  Pose T = Pose::Identity();
  T.linear() = rotationZXYDeg(rotate_deg);
  T.translation() = translate;
  return T;
}

std::vector<ChanKey> chanKeys(const std::vector<std::pair<int, Pose>>& poses) {
  std::vector<ChanKey> keys;
  for (const auto& [frame, T] : poses) {
    ChanKey k;
    k.frame = frame;
    k.translate = T.translation();
    k.rotate_deg = eulerZXYDeg(T.linear(), keys.empty() ? nullptr : &keys.back().rotate_deg);
    keys.push_back(k);
  }
  return keys;
}

void writeChan(const std::filesystem::path& path, const std::vector<ChanKey>& keys) {
  std::string text;
  char line[256];
  for (const ChanKey& k : keys) {
    std::snprintf(line, sizeof(line), "%d %.9g %.9g %.9g %.9g %.9g %.9g\n", k.frame, k.translate.x(),
                  k.translate.y(), k.translate.z(), k.rotate_deg.x(), k.rotate_deg.y(), k.rotate_deg.z());
    text += line;
  }
  writeFileAtomic(path, text);
}

std::vector<ChanKey> readChan(const std::filesystem::path& path) {
  std::ifstream in(path);
  ErrorContext c;
  c.file = path.string();
  if (!in) throw Error("cannot open .chan file", c);
  std::vector<ChanKey> keys;
  int number = 0;
  for (std::string line; std::getline(in, line);) {
    ++number;
    const size_t first = line.find_first_not_of(" \t\r");
    if (first == std::string::npos || line[first] == '#') continue;
    std::istringstream row(line);
    double v[7];
    int n = 0;
    while (n < 7 && row >> v[n]) ++n;
    std::string rest;
    if (n != 7 || (row >> rest) || std::round(v[0]) != v[0]) {
      c.field = "line " + std::to_string(number);
      throw Error("expected 'frame tx ty tz rx ry rz' (7 numbers, integer frame)", c);
    }
    // A frame beyond int made the conversion below undefined (fuzz/batch_chan.cpp).
    if (!(v[0] >= std::numeric_limits<int>::min() && v[0] <= std::numeric_limits<int>::max())) {
      c.field = "line " + std::to_string(number);
      throw Error("frame " + line.substr(first, line.find_first_of(" \t", first) - first) + " is out of range", c);
    }
    ChanKey k;
    k.frame = static_cast<int>(v[0]);
    k.translate = Eigen::Vector3d(v[1], v[2], v[3]);
    k.rotate_deg = Eigen::Vector3d(v[4], v[5], v[6]);
    keys.push_back(k);
  }
  return keys;
}

}  // namespace previz::batch
