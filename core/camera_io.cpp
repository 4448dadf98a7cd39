#include "core/camera_io.h"

#include <cmath>
#include <fstream>
#include <iomanip>
#include <sstream>

#include <Eigen/LU>
#include <Eigen/QR>
#include <opencv2/core.hpp>

#include "core/error.h"
#include "core/io.h"

namespace fs = std::filesystem;

namespace previz {

namespace {

ErrorContext context(const fs::path& file, const std::string& camera, const std::string& field) {
  ErrorContext c;
  c.file = file.string();
  c.camera = camera;
  c.field = field;
  return c;
}

std::string lowerExtension(const fs::path& p) {
  std::string e = p.extension().string();
  for (auto& ch : e) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
  return e;
}

bool isRotation(const Eigen::Matrix3d& R, double tol) {
  return R.allFinite() && (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() <= tol &&
         R.determinant() > 0.0;
}

RigCamera rigCameraFromKRt(const Eigen::Matrix3d& K, const Eigen::Matrix3d& R, const Eigen::Vector3d& t,
                           int width, int height, const std::string& name) {
  RigCamera rc;
  rc.camera.name = name;
  rc.camera.width = width;
  rc.camera.height = height;
  rc.camera.fx = K(0, 0);
  rc.camera.fy = K(1, 1);
  rc.camera.cx = K(0, 2);
  rc.camera.cy = K(1, 2);
  rc.camera.skew = K(0, 1);
  Pose T_cam_world = Pose::Identity();
  T_cam_world.linear() = R;
  T_cam_world.translation() = t;
  rc.T_world_cam = T_cam_world.inverse();
  return rc;
}

// Text rows: yields (line number, tokens) for every non-empty, non-comment line.
std::vector<std::pair<int, std::vector<std::string>>> readRows(const fs::path& path) {
  std::istringstream in(readTextFile(path));
  std::vector<std::pair<int, std::vector<std::string>>> rows;
  std::string line;
  int number = 0;
  while (std::getline(in, line)) {
    ++number;
    const auto hash = line.find('#');
    if (hash != std::string::npos) line.erase(hash);
    std::istringstream ls(line);
    std::vector<std::string> tokens;
    std::string tok;
    while (ls >> tok) tokens.push_back(tok);
    if (!tokens.empty()) rows.emplace_back(number, std::move(tokens));
  }
  return rows;
}

double parseNumber(const std::string& s, const fs::path& path, int line, const std::string& camera,
                   const std::string& field) {
  size_t used = 0;
  double v = 0;
  try {
    v = std::stod(s, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used != s.size() || !std::isfinite(v))
    throw Error("line " + std::to_string(line) + ": expected a finite number, got '" + s + "'",
                context(path, camera, field));
  return v;
}

// Middlebury-style rows may start with a line holding only the number of cameras.
void skipCountLine(std::vector<std::pair<int, std::vector<std::string>>>& rows, const fs::path& path) {
  if (rows.empty() || rows.front().second.size() != 1) return;
  const std::string& s = rows.front().second[0];
  if (s.find_first_not_of("0123456789") != std::string::npos)
    throw Error("line " + std::to_string(rows.front().first) +
                    ": a one-token line must be the camera count, got '" + s + "'",
                context(path, "", "count"));
  const long count = std::stol(s);
  const int line = rows.front().first;
  rows.erase(rows.begin());
  if (count != static_cast<long>(rows.size()))
    throw Error("line " + std::to_string(line) + ": the file announces " + std::to_string(count) +
                    " cameras but holds " + std::to_string(rows.size()),
                context(path, "", "count"));
}

void checkSize(int width, int height, const fs::path& path) {
  if (width <= 0 || height <= 0)
    throw Error("image size must be given and > 0 (got " + std::to_string(width) + "x" +
                    std::to_string(height) + ")",
                context(path, "", "width/height"));
}

}  // namespace

Camera readOpenCvCamera(const fs::path& path, const std::string& name) {
  std::error_code ec;
  if (!fs::exists(path, ec)) throw Error("camera file does not exist", context(path, name, ""));
  Camera c;
  c.name = name.empty() ? path.stem().string() : name;
  cv::FileStorage fs;
  try {
    if (!fs.open(path.string(), cv::FileStorage::READ))
      throw Error("cannot open as OpenCV FileStorage (YAML/XML/JSON)", context(path, c.name, ""));
  } catch (const cv::Exception& e) {
    throw Error(std::string("not a valid OpenCV FileStorage file: ") + e.what(), context(path, c.name, ""));
  }
  auto node = [&](const char* key, const char* expected) {
    cv::FileNode n = fs[key];
    if (n.empty()) throw Error(std::string("missing field, expected ") + expected, context(path, c.name, key));
    return n;
  };
  try {
    cv::FileNode w = node("image_width", "an integer");
    cv::FileNode h = node("image_height", "an integer");
    if (!w.isInt() || !h.isInt())
      throw Error("expected integers", context(path, c.name, w.isInt() ? "image_height" : "image_width"));
    c.width = static_cast<int>(w);
    c.height = static_cast<int>(h);

    cv::Mat K;
    node("camera_matrix", "a 3x3 matrix (!!opencv-matrix)") >> K;
    if (K.rows != 3 || K.cols != 3 || K.channels() != 1)
      throw Error("expected a 3x3 matrix, got " + std::to_string(K.rows) + "x" + std::to_string(K.cols),
                  context(path, c.name, "camera_matrix"));
    K.convertTo(K, CV_64F);
    const auto k = [&](int r, int col) { return K.at<double>(r, col); };
    if (k(1, 0) != 0.0 || k(2, 0) != 0.0 || k(2, 1) != 0.0 || std::abs(k(2, 2) - 1.0) > 1e-12)
      throw Error("expected an upper-triangular camera matrix [fx s cx; 0 fy cy; 0 0 1]",
                  context(path, c.name, "camera_matrix"));
    c.fx = k(0, 0);
    c.skew = k(0, 1);
    c.cx = k(0, 2);
    c.fy = k(1, 1);
    c.cy = k(1, 2);

    cv::Mat D;
    node("distortion_coefficients", "a 1xN or Nx1 matrix (k1 k2 p1 p2 [k3 ...])") >> D;
    if (D.empty() || (D.rows != 1 && D.cols != 1) || D.channels() != 1)
      throw Error("expected a 1xN or Nx1 matrix", context(path, c.name, "distortion_coefficients"));
    D.convertTo(D, CV_64F);
    D = D.reshape(1, 1);
    const int n = D.cols;
    if (n < 4)
      throw Error("expected at least 4 coefficients (k1 k2 p1 p2), got " + std::to_string(n),
                  context(path, c.name, "distortion_coefficients"));
    for (int i = 5; i < n; ++i)
      if (D.at<double>(0, i) != 0.0)
        throw Error("coefficient " + std::to_string(i) +
                        " is non-zero: rational / thin-prism / tilt terms are not supported "
                        "(model brown-conrady-opencv: k1 k2 p1 p2 k3)",
                    context(path, c.name, "distortion_coefficients"));
    c.dist.k1 = D.at<double>(0, 0);
    c.dist.k2 = D.at<double>(0, 1);
    c.dist.p1 = D.at<double>(0, 2);
    c.dist.p2 = D.at<double>(0, 3);
    c.dist.k3 = n > 4 ? D.at<double>(0, 4) : 0.0;
  } catch (const cv::Exception& e) {
    throw Error(std::string("malformed OpenCV FileStorage content: ") + e.what(), context(path, c.name, ""));
  }
  try {
    c.validate();
  } catch (const Error& e) {
    throw Error(e.message(), context(path, c.name, e.context().field));
  }
  return c;
}

void writeOpenCvCamera(const Camera& camera, const fs::path& path) {
  try {
    camera.validate();
  } catch (const Error& e) {
    throw Error(e.message(), context(path, camera.name, e.context().field));
  }
  const std::string ext = lowerExtension(path);
  int format = cv::FileStorage::FORMAT_YAML;
  if (ext == ".xml") format = cv::FileStorage::FORMAT_XML;
  else if (ext == ".json") format = cv::FileStorage::FORMAT_JSON;
  else if (ext != ".yml" && ext != ".yaml")
    throw Error("unknown extension '" + ext + "': use .yml, .yaml, .xml or .json", context(path, camera.name, ""));
  std::string text;
  try {
    cv::FileStorage fs(".yml", cv::FileStorage::WRITE | cv::FileStorage::MEMORY | format);
    if (format != cv::FileStorage::FORMAT_JSON)
      fs.writeComment("previz camera '" + camera.name +
                      "': OpenCV Brown-Conrady (k1 k2 p1 p2 k3); pixel (0,0) is the centre of the "
                      "top-left pixel");
    fs << "image_width" << camera.width;
    fs << "image_height" << camera.height;
    cv::Mat K = (cv::Mat_<double>(3, 3) << camera.fx, camera.skew, camera.cx, 0, camera.fy, camera.cy, 0, 0, 1);
    // 5x1, as cv::calibrateCamera returns it.
    cv::Mat D = (cv::Mat_<double>(5, 1) << camera.dist.k1, camera.dist.k2, camera.dist.p1, camera.dist.p2,
                 camera.dist.k3);
    fs << "camera_matrix" << K;
    fs << "distortion_coefficients" << D;
    text = fs.releaseAndGetString();
  } catch (const cv::Exception& e) {
    throw Error(std::string("cannot encode camera: ") + e.what(), context(path, camera.name, ""));
  }
  writeFileAtomic(path, text);
}

RigCamera rigCameraFromProjection(const Eigen::Matrix<double, 3, 4>& P_in, int width, int height,
                                  const std::string& name) {
  ErrorContext ctx;
  ctx.camera = name;
  ctx.field = "P";
  if (!P_in.allFinite()) throw Error("projection matrix has non-finite entries", ctx);
  Eigen::Matrix<double, 3, 4> P = P_in;
  Eigen::Matrix3d M = P.leftCols<3>();
  const double det = M.determinant();
  if (!(std::abs(det) > 0.0)) throw Error("projection matrix has a singular left 3x3 block", ctx);
  // P and -P are the same projective map; choose the sign that puts points in front at z > 0
  // (det M > 0, so K with positive diagonal goes with a proper rotation).
  if (det < 0.0) {
    P = -P;
    M = -M;
  }
  // RQ from QR: with J the row reversal, QR of (J M)^T = Q U gives M = (J U^T J) (J Q^T).
  Eigen::Matrix3d J = Eigen::Matrix3d::Zero();
  J(0, 2) = J(1, 1) = J(2, 0) = 1.0;
  Eigen::HouseholderQR<Eigen::Matrix3d> qr((J * M).transpose());
  const Eigen::Matrix3d Q = qr.householderQ();
  const Eigen::Matrix3d U = qr.matrixQR().triangularView<Eigen::Upper>();
  Eigen::Matrix3d K = J * U.transpose() * J;
  Eigen::Matrix3d R = J * Q.transpose();
  // Make K's diagonal positive: K R = (K D)(D R) with D = diag(+-1).
  for (int i = 0; i < 3; ++i) {
    if (K(i, i) < 0.0) {
      K.col(i) *= -1.0;
      R.row(i) *= -1.0;
    }
  }
  const Eigen::Vector3d t = K.inverse() * P.col(3);  // before normalising K: P = K [R | t]
  K /= K(2, 2);
  K(1, 0) = K(2, 0) = K(2, 1) = 0.0;
  K(2, 2) = 1.0;
  return rigCameraFromKRt(K, R, t, width, height, name);
}

Eigen::Matrix<double, 3, 4> projectionMatrix(const RigCamera& camera) {
  const Pose T_cam_world = camera.T_world_cam.inverse();
  Eigen::Matrix<double, 3, 4> Rt;
  Rt.leftCols<3>() = T_cam_world.linear();
  Rt.col(3) = T_cam_world.translation();
  return camera.camera.K() * Rt;
}

Rig readKRtRows(const fs::path& path, int width, int height) {
  checkSize(width, height, path);
  auto rows = readRows(path);
  skipCountLine(rows, path);
  Rig rig;
  for (const auto& [line, tok] : rows) {
    const std::string& name = tok[0];
    if (tok.size() != 22)
      throw Error("line " + std::to_string(line) + ": expected 22 fields (name k11..k33 r11..r33 t1 t2 t3), got " +
                      std::to_string(tok.size()),
                  context(path, name, "row"));
    double v[21];
    for (int i = 0; i < 21; ++i) {
      const char* group = i < 9 ? "K" : i < 18 ? "R" : "t";
      v[i] = parseNumber(tok[i + 1], path, line, name, group);
    }
    Eigen::Matrix3d K, R;
    K << v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[8];
    R << v[9], v[10], v[11], v[12], v[13], v[14], v[15], v[16], v[17];
    const Eigen::Vector3d t(v[18], v[19], v[20]);
    if (K(1, 0) != 0.0 || K(2, 0) != 0.0 || K(2, 1) != 0.0 || K(2, 2) != 1.0)
      throw Error("line " + std::to_string(line) + ": expected K = [fx s cx; 0 fy cy; 0 0 1]", context(path, name, "K"));
    if (!isRotation(R, 1e-6))
      throw Error("line " + std::to_string(line) + ": R is not a proper rotation (R^T R = I within 1e-6, det +1)",
                  context(path, name, "R"));
    rig.cameras.push_back(rigCameraFromKRt(K, R, t, width, height, name));
    try {
      rig.cameras.back().camera.validate();
    } catch (const Error& e) {
      throw Error("line " + std::to_string(line) + ": " + e.message(), context(path, name, e.context().field));
    }
  }
  try {
    rig.validate();
  } catch (const Error& e) {
    throw Error(e.message(), context(path, e.context().camera, e.context().field));
  }
  return rig;
}

Rig readProjectionRows(const fs::path& path, int width, int height) {
  checkSize(width, height, path);
  auto rows = readRows(path);
  skipCountLine(rows, path);
  Rig rig;
  for (const auto& [line, tok] : rows) {
    const std::string& name = tok[0];
    if (tok.size() != 13)
      throw Error("line " + std::to_string(line) + ": expected 13 fields (name p11..p34), got " +
                      std::to_string(tok.size()),
                  context(path, name, "row"));
    Eigen::Matrix<double, 3, 4> P;
    for (int i = 0; i < 12; ++i) P(i / 4, i % 4) = parseNumber(tok[i + 1], path, line, name, "P");
    try {
      rig.cameras.push_back(rigCameraFromProjection(P, width, height, name));
      rig.cameras.back().camera.validate();
    } catch (const Error& e) {
      throw Error("line " + std::to_string(line) + ": " + e.message(), context(path, name, e.context().field));
    }
  }
  try {
    rig.validate();
  } catch (const Error& e) {
    throw Error(e.message(), context(path, e.context().camera, e.context().field));
  }
  return rig;
}

void writeKRtRows(const Rig& rig, const fs::path& path) {
  std::ostringstream out;
  out << "# previz KRt rows: name k11..k33 r11..r33 t1 t2 t3; P = K [R | t] maps world to pixels,\n"
         "# pixel (0,0) is the centre of the top-left pixel; metres; no distortion\n";
  out << rig.cameras.size() << "\n";
  out << std::setprecision(17);
  for (const auto& rc : rig.cameras) {
    const Camera& c = rc.camera;
    if (!c.dist.isZero())
      throw Error("KRt rows cannot hold lens distortion", context(path, c.name, "distortion"));
    if (c.name.empty() || c.name.find_first_of(" \t#\n") != std::string::npos)
      throw Error("camera names in KRt rows must be non-empty without spaces or '#'", context(path, c.name, "name"));
    const Eigen::Matrix3d K = c.K();
    const Pose T = rc.T_world_cam.inverse();
    out << c.name;
    for (int r = 0; r < 3; ++r)
      for (int col = 0; col < 3; ++col) out << ' ' << K(r, col);
    for (int r = 0; r < 3; ++r)
      for (int col = 0; col < 3; ++col) out << ' ' << T.linear()(r, col);
    for (int i = 0; i < 3; ++i) out << ' ' << T.translation()(i);
    out << '\n';
  }
  writeFileAtomic(path, out.str());
}

}  // namespace previz
