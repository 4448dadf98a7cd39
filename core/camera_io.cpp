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
#include "core/rig_import.h"

namespace fs = std::filesystem;

namespace previz {

namespace {

std::string lowerExtension(const fs::path& p) {
  std::string e = p.extension().string();
  for (auto& ch : e) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
  return e;
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

// OpenCV 4.6's YAML reader never returns from some files whose top level is not at column 1,
// all found by fuzz/opencv_camera.cpp (fuzz/corpus/opencv_camera/hang-*.yaml):
//   "%YAML:1.0\n M:-0\n0\n0"      the root map at column 2, then lines left of it;
//   " L: 1\n---\n -"               a second document after an indented one;
//   "--- a: 1\n.0\n-"              the first key on the document-start line.
// Camera files (OpenCV's, ROS's, Kalibr's, hand-written ones) start each document's top-level
// keys at column 1 on a line of their own, so any other shape is refused before OpenCV sees it,
// naming the line.
// The same reader also never returns when a document end marker "..." is followed by anything
// but "---" or the end (it loops on a '-': "a: 1\n...-]\n-", fuzz/corpus/opencv_camera/
// hang-after-document-end.yaml): text after "..." is refused too.
void checkYamlIndentation(const std::string& text, const fs::path& path) {
  const auto refuse = [&](int number, const std::string& what) {
    throw Error("line " + std::to_string(number) + " " + what, cameraFileContext(path, "", ""));
  };
  std::istringstream in(text);
  std::string line;
  bool document_start = true;  // the next line of content is a document's first
  int end_line = 0;            // the last "..." not yet followed by "---"
  for (int number = 1; std::getline(in, line); ++number) {
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    const size_t column = line.find_first_not_of(' ');
    const char c = line[column];
    if (c == '#' || c == '%') continue;
    // Anything but a comment after a 3-character marker ("---", "...") at `column`.
    const auto textAfterMarker = [&] {
      const size_t rest = line.find_first_not_of(" \t\r", column + 3);
      return rest != std::string::npos && line[rest] != '#';
    };
    if (line.compare(column, 3, "---") == 0) {
      if (textAfterMarker()) refuse(number, "has text after the document start '---': put it on a line of its own");
      document_start = true;
      end_line = 0;
      continue;
    }
    if (end_line)
      refuse(number, "follows the document end '...' (line " + std::to_string(end_line) + "): not YAML");
    if (line.compare(column, 3, "...") == 0) {
      if (textAfterMarker()) refuse(number, "has text after the document end '...': not YAML");
      document_start = true;
      end_line = number;
      continue;
    }
    if (document_start && column > 0)
      refuse(number, "starts the document at column " + std::to_string(column + 1) +
                         ": a camera file's top-level keys start the line");
    document_start = false;
  }
}

}  // namespace

cv::FileStorage openOpenCvStorage(const fs::path& path) {
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) throw Error("camera file does not exist", cameraFileContext(path, "", ""));
  std::string text = readTextFile(path);
  // OpenCV 4.6's parsers read the text as a C string beside its length: a NUL byte inside
  // ("<?xml version=\0...") made the XML reader dereference null (fuzz/opencv_camera.cpp,
  // fuzz/corpus/opencv_camera/segv-nul-byte.xml). No YAML, XML or JSON text holds one.
  if (const size_t nul = text.find('\0'); nul != std::string::npos)
    throw Error("a NUL byte at offset " + std::to_string(nul) + ": not a text file", cameraFileContext(path, "", ""));
  const std::string ext = lowerExtension(path);
  const int format = ext == ".json"  ? cv::FileStorage::FORMAT_JSON
                     : ext == ".xml" ? cv::FileStorage::FORMAT_XML
                                     : cv::FileStorage::FORMAT_AUTO;
  // FORMAT_AUTO reads XML from '<' and JSON from '{', everything else as YAML.
  const size_t first = text.find_first_not_of(" \t\r\n");
  if (format == cv::FileStorage::FORMAT_AUTO && first != std::string::npos && text[first] != '<' && text[first] != '{')
    checkYamlIndentation(text, path);
  // OpenCV refuses YAML without its "%YAML:1.0" first line; ROS camera_info files and hand-written
  // ones have none.
  if ((ext == ".yml" || ext == ".yaml") && text.rfind("%YAML", 0) != 0) text = "%YAML:1.0\n" + text;
  // OpenCV 4.6 reads a text that starts with "<?xml" (after an optional UTF-8 byte order mark) as
  // XML, whatever format it was asked for, and its XML reader dereferences null when the text ends
  // inside a tag just after an '=' ('<T type_id=' at the end: a file cut short;
  // fuzz/corpus/opencv_camera/segv-truncated-tag.xml). Every complete XML document ends with '>'.
  const size_t start = text.find_first_not_of(" \t\r\n", text.rfind("\xEF\xBB\xBF", 0) == 0 ? 3 : 0);
  if (start != std::string::npos && text[start] == '<' && text[text.find_last_not_of(" \t\r\n")] != '>')
    throw Error("XML text that does not end with '>': a file cut short?", cameraFileContext(path, "", ""));
  cv::FileStorage store;
  try {
    if (!store.open(text, cv::FileStorage::READ | cv::FileStorage::MEMORY | format))
      throw Error("cannot open as OpenCV FileStorage (YAML/XML/JSON)", cameraFileContext(path, "", ""));
  } catch (const cv::Exception& e) {
    throw Error(std::string("not a valid OpenCV FileStorage file: ") + e.what(), cameraFileContext(path, "", ""));
  }
  return store;
}

Eigen::MatrixXd readOpenCvMatrix(const cv::FileNode& n, const fs::path& file, const std::string& camera,
                                 const std::string& field) {
  auto bad = [&](const std::string& what) { return Error(what, cameraFileContext(file, camera, field)); };
  auto number = [&](const cv::FileNode& v) {
    if (!v.isReal() && !v.isInt()) throw bad("expected numbers in the matrix");
    const double x = static_cast<double>(v);
    if (!std::isfinite(x)) throw bad("expected finite numbers in the matrix");
    return x;
  };
  std::vector<double> values;
  int rows = 0, cols = 0;
  if (n.isMap()) {
    if (!n["rows"].isInt() || !n["cols"].isInt()) throw bad("expected a matrix with integer rows and cols");
    rows = static_cast<int>(n["rows"]);
    cols = static_cast<int>(n["cols"]);
    if (n["dt"].isString() && static_cast<std::string>(n["dt"]).size() != 1)
      throw bad("expected a one-channel matrix (dt '" + static_cast<std::string>(n["dt"]) + "')");
    if (!n["data"].isSeq()) throw bad("expected a matrix with a data list");
    for (const cv::FileNode& v : n["data"]) values.push_back(number(v));
  } else if (n.isSeq()) {
    for (const cv::FileNode& row : n) {
      if (row.isSeq()) {
        if (rows > 0 && static_cast<int>(row.size()) != cols) throw bad("rows of different lengths");
        cols = static_cast<int>(row.size());
        ++rows;
        for (const cv::FileNode& v : row) values.push_back(number(v));
      } else {
        if (rows > 0) throw bad("expected a flat list or a list of rows");
        values.push_back(number(row));
      }
    }
    if (rows == 0) {  // a flat list: one row
      rows = values.empty() ? 0 : 1;
      cols = static_cast<int>(values.size());
    }
  } else {
    throw bad("expected a matrix");
  }
  if (rows <= 0 || cols <= 0 || static_cast<size_t>(rows) * static_cast<size_t>(cols) != values.size())
    throw bad("matrix data holds " + std::to_string(values.size()) + " values for " + std::to_string(rows) + "x" +
              std::to_string(cols));
  Eigen::MatrixXd M(rows, cols);
  for (int r = 0; r < rows; ++r)
    for (int c = 0; c < cols; ++c) M(r, c) = values[static_cast<size_t>(r) * cols + c];
  return M;
}

Camera readOpenCvIntrinsics(const cv::FileStorage& store, const fs::path& file, const std::string& name,
                            const char* k_key, const char* d_key, int width, int height) {
  Camera c;
  c.name = name;
  try {
    if (!store["image_width"].empty() || !store["image_height"].empty()) {
      for (const char* key : {"image_width", "image_height"})
        if (!store[key].isInt()) throw Error("expected an integer", cameraFileContext(file, name, key));
      c.width = static_cast<int>(store["image_width"]);
      c.height = static_cast<int>(store["image_height"]);
    } else if (width > 0 && height > 0) {
      c.width = width;
      c.height = height;
    } else {
      throw Error("no image size: the file has no image_width / image_height and none was given (--size WxH)",
                  cameraFileContext(file, name, "image_width"));
    }

    if (store[k_key].empty())
      throw Error("missing field, expected a 3x3 matrix (!!opencv-matrix)", cameraFileContext(file, name, k_key));
    const Eigen::MatrixXd K = readOpenCvMatrix(store[k_key], file, name, k_key);
    if (K.rows() != 3 || K.cols() != 3)
      throw Error("expected a 3x3 matrix, got " + std::to_string(K.rows()) + "x" + std::to_string(K.cols()),
                  cameraFileContext(file, name, k_key));
    if (K(1, 0) != 0.0 || K(2, 0) != 0.0 || K(2, 1) != 0.0 || std::abs(K(2, 2) - 1.0) > 1e-12)
      throw Error("expected an upper-triangular camera matrix [fx s cx; 0 fy cy; 0 0 1]", cameraFileContext(file, name, k_key));
    c.fx = K(0, 0);
    c.skew = K(0, 1);
    c.cx = K(0, 2);
    c.fy = K(1, 1);
    c.cy = K(1, 2);

    // ROS camera_info names its lens model, and so does previz for a fisheye; OpenCV's own
    // calibrateCamera files do not (Brown-Conrady).
    bool fisheye = false;
    if (store["distortion_model"].isString()) {
      const std::string model = store["distortion_model"];
      fisheye = model == "equidistant" || model == "fisheye" || model == "kannala-brandt";
      if (!fisheye && model != "plumb_bob" && model != "rational_polynomial")
        throw Error("unsupported distortion model '" + model +
                        "' (plumb_bob: k1 k2 p1 p2 k3; equidistant / fisheye: k1 k2 k3 k4 of OpenCV's fisheye module)",
                    cameraFileContext(file, name, "distortion_model"));
    }
    if (fisheye) {
      if (store[d_key].empty())
        throw Error("missing field, expected a 1x4 or 4x1 matrix (k1 k2 k3 k4)", cameraFileContext(file, name, d_key));
      const Eigen::MatrixXd D = readOpenCvMatrix(store[d_key], file, name, d_key);
      if ((D.rows() != 1 && D.cols() != 1) || D.size() != 4)
        throw Error("expected 4 fisheye coefficients (k1 k2 k3 k4) in a 1x4 or 4x1 matrix, got " +
                        std::to_string(D.rows()) + "x" + std::to_string(D.cols()),
                    cameraFileContext(file, name, d_key));
      c.dist.model = LensModel::kKannalaBrandt;
      c.dist.k1 = D(0);
      c.dist.k2 = D(1);
      c.dist.k3 = D(2);
      c.dist.k4 = D(3);
    } else {
      if (store[d_key].empty())
        throw Error("missing field, expected a 1xN or Nx1 matrix (k1 k2 p1 p2 [k3 ...])", cameraFileContext(file, name, d_key));
      const Eigen::MatrixXd D = readOpenCvMatrix(store[d_key], file, name, d_key);
      if (D.rows() != 1 && D.cols() != 1) throw Error("expected a 1xN or Nx1 matrix", cameraFileContext(file, name, d_key));
      const Eigen::Index n = D.size();
      // OpenCV's lengths: 4, 5, 8 (rational k4 k5 k6), 12 (thin prism s1..s4), 14 (tilt tauX tauY).
      if (n != 4 && n != 5 && n != 8 && n != 12 && n != 14)
        throw Error("expected 4, 5, 8, 12 or 14 coefficients (OpenCV's k1 k2 p1 p2 [k3 [k4 k5 k6 [s1 s2 s3 s4 "
                    "[tauX tauY]]]]), got " + std::to_string(n),
                    cameraFileContext(file, name, d_key));
      static const char* const kExtra[] = {"s1", "s2", "s3", "s4", "tauX", "tauY"};
      for (Eigen::Index i = 8; i < n; ++i)
        if (D(i) != 0.0)
          throw Error("coefficient " + std::to_string(i) + " (" + kExtra[i - 8] + ") of " + std::to_string(n) +
                          " is non-zero: thin-prism and tilt terms are not supported "
                          "(model brown-conrady-opencv: k1 k2 p1 p2 k3 k4 k5 k6)",
                      cameraFileContext(file, name, d_key));
      c.dist.k1 = D(0);
      c.dist.k2 = D(1);
      c.dist.p1 = D(2);
      c.dist.p2 = D(3);
      c.dist.k3 = n > 4 ? D(4) : 0.0;
      c.dist.k4 = n > 5 ? D(5) : 0.0;
      c.dist.k5 = n > 5 ? D(6) : 0.0;
      c.dist.k6 = n > 5 ? D(7) : 0.0;
    }
  } catch (const cv::Exception& e) {
    throw Error(std::string("malformed OpenCV FileStorage content: ") + e.what(), cameraFileContext(file, name, ""));
  }
  try {
    c.validate();
  } catch (const Error& e) {
    throw Error(e.message(), cameraFileContext(file, name, e.context().field));
  }
  return c;
}

Camera readOpenCvCamera(const fs::path& path, const std::string& name) {
  const std::string n = name.empty() ? path.stem().string() : name;
  try {
    return readOpenCvIntrinsics(openOpenCvStorage(path), path, n, "camera_matrix", "distortion_coefficients");
  } catch (const Error& e) {
    throw Error(e.message(), cameraFileContext(path, n, e.context().field));
  }
}

namespace {

void writeOpenCv(const Camera& camera, const Pose* T_world_cam, const fs::path& path) {
  try {
    camera.validate();
  } catch (const Error& e) {
    throw Error(e.message(), cameraFileContext(path, camera.name, e.context().field));
  }
  const std::string ext = lowerExtension(path);
  int format = cv::FileStorage::FORMAT_YAML;
  if (ext == ".xml") format = cv::FileStorage::FORMAT_XML;
  else if (ext == ".json") format = cv::FileStorage::FORMAT_JSON;
  else if (ext != ".yml" && ext != ".yaml")
    throw Error("unknown extension '" + ext + "': use .yml, .yaml, .xml or .json", cameraFileContext(path, camera.name, ""));
  std::string text;
  try {
    cv::FileStorage store(".yml", cv::FileStorage::WRITE | cv::FileStorage::MEMORY | format);
    if (format != cv::FileStorage::FORMAT_JSON)
      store.writeComment("previz camera '" + camera.name +
                         (camera.dist.isBrown()
                              ? (camera.dist.isRational() ? "': OpenCV Brown-Conrady, rational (k1 k2 p1 p2 k3 k4 k5 k6)"
                                                          : "': OpenCV Brown-Conrady (k1 k2 p1 p2 k3)")
                              : "': OpenCV fisheye, Kannala-Brandt (k1 k2 k3 k4, cv::fisheye's D)") +
                         "; pixel (0,0) is the centre of the top-left pixel" +
                         (T_world_cam ? "; rvec/tvec map world to camera (x_cam = R x_world + t), metres, "
                                        "world z up"
                                      : ""));
    store << "image_width" << camera.width;
    store << "image_height" << camera.height;
    cv::Mat K = (cv::Mat_<double>(3, 3) << camera.fx, camera.skew, camera.cx, 0, camera.fy, camera.cy, 0, 0, 1);
    if (!camera.dist.isBrown()) store << "distortion_model" << "equidistant";
    store << "camera_matrix" << K;
    store << "distortion_coefficients" << openCvDistortion(camera.dist);
    if (T_world_cam) {
      Eigen::Vector3d rvec, tvec;
      poseToRvecTvec(T_world_cam->inverse(), rvec, tvec);
      store << "rvec" << (cv::Mat_<double>(3, 1) << rvec.x(), rvec.y(), rvec.z());
      store << "tvec" << (cv::Mat_<double>(3, 1) << tvec.x(), tvec.y(), tvec.z());
    }
    text = store.releaseAndGetString();
  } catch (const cv::Exception& e) {
    throw Error(std::string("cannot encode camera: ") + e.what(), cameraFileContext(path, camera.name, ""));
  }
  writeFileAtomic(path, text);
}

}  // namespace

cv::Mat openCvDistortion(const Distortion& d) {
  if (!d.isBrown()) return (cv::Mat_<double>(4, 1) << d.k1, d.k2, d.k3, d.k4);
  if (d.isRational()) return (cv::Mat_<double>(8, 1) << d.k1, d.k2, d.p1, d.p2, d.k3, d.k4, d.k5, d.k6);
  return (cv::Mat_<double>(5, 1) << d.k1, d.k2, d.p1, d.p2, d.k3);
}

void writeOpenCvCamera(const Camera& camera, const fs::path& path) { writeOpenCv(camera, nullptr, path); }

void writeOpenCvCamera(const RigCamera& camera, const fs::path& path) {
  writeOpenCv(camera.camera, &camera.T_world_cam, path);
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
  ImportOptions opt;
  opt.width = width;
  opt.height = height;
  return importKRtRows(path, opt).rig;
}

Rig readProjectionRows(const fs::path& path, int width, int height) {
  ImportOptions opt;
  opt.width = width;
  opt.height = height;
  return importProjectionRows(path, opt).rig;
}

namespace {

// One camera a line after a header comment and the count line (Middlebury's layout).
template <typename Row>
void writeRows(const Rig& rig, const fs::path& path, const std::string& header, Row row) {
  std::ostringstream out;
  out << header << rig.cameras.size() << "\n" << std::setprecision(17);
  for (const auto& rc : rig.cameras) {
    const Camera& c = rc.camera;
    if (!c.dist.isZero()) throw Error("rows cannot hold lens distortion", cameraFileContext(path, c.name, "distortion"));
    if (c.name.empty() || c.name.find_first_of(" \t#\r\n") != std::string::npos)
      throw Error("camera names in rows must be non-empty without spaces or '#'", cameraFileContext(path, c.name, "name"));
    out << c.name;
    row(out, rc);
    out << '\n';
  }
  writeFileAtomic(path, out.str());
}

}  // namespace

void writeKRtRows(const Rig& rig, const fs::path& path) {
  writeRows(rig, path,
            "# previz KRt rows: name k11..k33 r11..r33 t1 t2 t3; x_cam = R x_world + t, P = K [R | t] maps\n"
            "# world to pixels, pixel (0,0) is the centre of the top-left pixel; metres; no distortion\n",
            [](std::ostream& out, const RigCamera& rc) {
              const Eigen::Matrix3d K = rc.camera.K();
              const Pose T = rc.T_world_cam.inverse();
              for (int r = 0; r < 3; ++r)
                for (int col = 0; col < 3; ++col) out << ' ' << K(r, col);
              for (int r = 0; r < 3; ++r)
                for (int col = 0; col < 3; ++col) out << ' ' << T.linear()(r, col);
              for (int i = 0; i < 3; ++i) out << ' ' << T.translation()(i);
            });
}

void writeProjectionRows(const Rig& rig, const fs::path& path) {
  writeRows(rig, path,
            "# previz P rows: name p11..p34; P = K [R | t] maps world points (metres) to pixels,\n"
            "# pixel (0,0) is the centre of the top-left pixel; no distortion\n",
            [](std::ostream& out, const RigCamera& rc) {
              const Eigen::Matrix<double, 3, 4> P = projectionMatrix(rc);
              for (int r = 0; r < 3; ++r)
                for (int col = 0; col < 4; ++col) out << ' ' << P(r, col);
            });
}

}  // namespace previz

