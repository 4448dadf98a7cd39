#include "core/rig_import.h"

#include <cmath>
#include <cstdio>
#include <map>
#include <optional>
#include <sstream>
#include <tuple>

#include <Eigen/Dense>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "core/camera_io.h"
#include "core/error.h"
#include "core/io.h"
#include "core/detail/yaml_subset.h"

namespace fs = std::filesystem;

namespace previz {

namespace {

using detail::YamlNode;
using detail::YamlSubsetParser;

std::string sci(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.2g", v);
  return buf;
}

// 17 significant digits: reads back as the same double.
std::string exact(double v) {
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.17g", v);
  return buf;
}

std::string lineTag(int line) { return "line " + std::to_string(line) + ": "; }

// Strict number: all of 's', finite.
std::optional<double> toNumber(const std::string& s) {
  if (s.empty()) return std::nullopt;
  char* end = nullptr;
  const double v = std::strtod(s.c_str(), &end);
  if (end != s.c_str() + s.size() || !std::isfinite(v)) return std::nullopt;
  return v;
}

std::optional<int> toInt(const std::string& s) {
  const auto v = toNumber(s);
  if (!v || *v != std::floor(*v) || std::abs(*v) > 1e9) return std::nullopt;
  return static_cast<int>(*v);
}

double requireNumber(const std::string& s, const fs::path& file, int line, const std::string& camera,
                     const std::string& field) {
  if (const auto v = toNumber(s)) return *v;
  throw Error(lineTag(line) + "expected a finite number, got '" + s + "'", cameraFileContext(file, camera, field));
}

Pose poseFromRt(const Eigen::Matrix3d& R, const Eigen::Vector3d& t) {
  Pose T = Pose::Identity();
  T.linear() = R;
  T.translation() = t;
  return T;
}

// Camera names given by the caller, handed out in reading order; the format's own otherwise.
class Namer {
 public:
  explicit Namer(const std::vector<std::string>& given) : given_(given) {}
  std::string next(const std::string& fallback) {
    const size_t i = count_++;
    return i < given_.size() ? given_[i] : fallback;
  }

 private:
  const std::vector<std::string>& given_;
  size_t count_ = 0;
};

// Text rows: (line number, tokens) for every line that is neither empty nor a '#' comment.
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
    for (std::string tok; ls >> tok;) tokens.push_back(tok);
    if (!tokens.empty()) rows.emplace_back(number, std::move(tokens));
  }
  return rows;
}

// The point nearest to all lines c_i + s d_i (least squares: sum (I - d d^T) p = sum (I - d d^T) c),
// the common point a rig's optical axes look at; none when the lines are within about a degree
// of parallel (a stereo pair with parallel axes has no such point).
std::optional<Eigen::Vector3d> nearestPointToLines(const std::vector<Eigen::Vector3d>& centres,
                                                   const std::vector<Eigen::Vector3d>& directions) {
  if (centres.size() < 2) return std::nullopt;
  Eigen::Matrix3d A = Eigen::Matrix3d::Zero();
  Eigen::Vector3d b = Eigen::Vector3d::Zero();
  for (size_t i = 0; i < centres.size(); ++i) {
    const Eigen::Vector3d d = directions[i].normalized();
    const Eigen::Matrix3d P = Eigen::Matrix3d::Identity() - d * d.transpose();
    A += P;
    b += P * centres[i];
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(A);
  const double one_degree = 1.0 - std::cos(std::acos(-1.0) / 180.0);
  if (!(eig.eigenvalues()(0) / static_cast<double>(centres.size()) >= one_degree)) return std::nullopt;
  return A.ldlt().solve(b);
}

// What every import does last: names checked, translations to metres, axes to z up, the rig
// validated, the whole rig's poses looked at.
void finishImport(RigImport& out, const ImportOptions& opt, const std::string& world) {
  Rig& rig = out.rig;
  const fs::path file = out.report.files.empty() ? fs::path() : fs::path(out.report.files.front());
  if (!opt.names.empty() && opt.names.size() != rig.cameras.size())
    throw Error(std::to_string(opt.names.size()) + " names given for " + std::to_string(rig.cameras.size()) +
                    " cameras (one name per camera, in the file's order)",
                cameraFileContext(file, "", "names"));
  if (!opt.names.empty()) out.report.assumptions.push_back("names: as given, in the order the cameras were read");

  const double s = opt.metresPerUnit();
  for (RigCamera& rc : rig.cameras) rc.T_world_cam.translation() *= s;
  out.report.assumptions.push_back(
      opt.units == "m" ? "units: translations taken as metres (say the file's unit if not: mm, cm)"
                       : "units: translations in " + opt.units + ", scaled by " + exact(s) + " to metres");

  Eigen::Matrix3d F = Eigen::Matrix3d::Identity();
  std::string turn;
  if (opt.flip == "y-up") {
    F << 1, 0, 0, 0, 0, -1, 0, 1, 0;
    turn = "(x, y, z) -> (x, -z, y), +90 deg about x";
  } else if (opt.flip == "z-down") {
    F << 1, 0, 0, 0, -1, 0, 0, 0, -1;
    turn = "(x, y, z) -> (x, -y, -z), 180 deg about x";
  } else if (opt.flip == "y-down") {
    F << 1, 0, 0, 0, 0, 1, 0, -1, 0;
    turn = "(x, y, z) -> (x, z, -y), -90 deg about x";
  }
  Pose T_new_old = Pose::Identity();
  T_new_old.linear() = F;
  for (RigCamera& rc : rig.cameras) rc.T_world_cam = T_new_old * rc.T_world_cam;
  out.report.assumptions.push_back(
      turn.empty() ? "axes: the file's world taken as z up, as previz's (no flip)"
                   : "axes: the file's world is " + opt.flip + "; turned z up by " + turn);
  rig.world_frame = world + (turn.empty() ? "" : ", turned z up from " + opt.flip);

  try {
    rig.validate();
  } catch (const Error& e) {
    throw Error(e.message(), cameraFileContext(file, e.context().camera, e.context().field));
  }
  for (std::string& w : rigPoseWarnings(rig)) out.report.warnings.push_back(std::move(w));
}

// ---------------------------------------------------------------------------------------------
// OpenCV FileStorage

bool has(const cv::FileStorage& store, const char* key) { return !store[key].empty(); }

// 3 values as 3x1 or 1x3.
Eigen::Vector3d readVector3(const cv::FileNode& n, const fs::path& file, const std::string& camera,
                            const std::string& field, const std::string& what) {
  const Eigen::MatrixXd M = readOpenCvMatrix(n, file, camera, field);
  if (M.size() != 3 || (M.rows() != 1 && M.cols() != 1))
    throw Error("expected " + what + " (3x1), got " + std::to_string(M.rows()) + "x" + std::to_string(M.cols()),
                cameraFileContext(file, camera, field));
  return Eigen::Map<const Eigen::Vector3d>(M.data());
}

// T_cam_world from a rotation (3x3, or a 3-vector: Rodrigues) and a translation.
Pose readPose(const cv::FileStorage& store, const char* r_key, const char* t_key, const fs::path& file,
              const std::string& camera, ImportReport& report) {
  if (store[r_key].empty() || store[t_key].empty())
    throw Error(std::string("a pose needs both ") + r_key + " and " + t_key,
                cameraFileContext(file, camera, store[r_key].empty() ? r_key : t_key));
  const Eigen::MatrixXd M = readOpenCvMatrix(store[r_key], file, camera, r_key);
  Eigen::Matrix3d R;
  if (M.rows() == 3 && M.cols() == 3) {
    R = checkedRotation(M, file, camera, r_key, report);
  } else if (M.size() == 3 && (M.rows() == 1 || M.cols() == 1)) {
    R = poseFromRvecTvec(Eigen::Map<const Eigen::Vector3d>(M.data()), Eigen::Vector3d::Zero()).linear();
  } else {
    throw Error("expected a rotation vector (3x1) or matrix (3x3), got " + std::to_string(M.rows()) + "x" +
                    std::to_string(M.cols()),
                cameraFileContext(file, camera, r_key));
  }
  return poseFromRt(R, readVector3(store[t_key], file, camera, t_key, "a translation"));
}

// The name a file gives its camera: the stem, or the parent folder's name where several files
// share a stem (cam1/config.xml, cam2/config.xml).
std::vector<std::string> fileCameraNames(const std::vector<fs::path>& files) {
  std::map<std::string, int> stems;
  for (const fs::path& f : files) ++stems[f.stem().string()];
  std::vector<std::string> names;
  for (const fs::path& f : files) {
    const std::string stem = f.stem().string();
    const std::string parent = fs::absolute(f).parent_path().filename().string();
    names.push_back(stems[stem] > 1 && !parent.empty() ? parent : stem);
  }
  return names;
}

// The size a file without one gives its camera: --size, else the camera's images (size_of);
// (0, 0) when neither knows it.
std::pair<int, int> givenSize(const ImportOptions& opt, const std::string& camera) {
  if (opt.width > 0) return {opt.width, opt.height};
  if (opt.size_of)
    if (const std::optional<std::pair<int, int>> s = opt.size_of(camera)) return *s;
  return {0, 0};
}

// The intrinsics under k_key / d_key, the image size's origin said in the report.
Camera readCamera(const cv::FileStorage& store, const fs::path& file, const std::string& name, const char* k_key,
                  const char* d_key, const ImportOptions& opt, ImportReport& report) {
  const bool sized = has(store, "image_width") || has(store, "image_height");
  const auto [w, h] = givenSize(opt, name);
  Camera c = readOpenCvIntrinsics(store, file, name, k_key, d_key, w, h);
  const std::string size = std::to_string(c.width) + "x" + std::to_string(c.height);
  if (!sized)
    report.assumptions.push_back("camera '" + name + "': image size " + size +
                                 (opt.width > 0 ? " as given" : " from its images") + " (the file has none)");
  else if (opt.width > 0 && (opt.width != c.width || opt.height != c.height))
    report.warnings.push_back("camera '" + name + "': the file says " + size + ", the given size is " +
                              std::to_string(opt.width) + "x" + std::to_string(opt.height) + "; the file's size is used");
  return c;
}

// OpenCV's calibration sample writes every view's board pose (rvec | tvec rows); taken for a
// camera pose it would put the camera where the board was. Refuse with the reason.
[[noreturn]] void refuseViewPoses(const fs::path& file, const std::string& camera) {
  throw Error(
      "extrinsic_parameters holds per-view board poses (one rvec|tvec row per calibration image, as "
      "OpenCV's calibration sample writes them), not this camera's pose: give the camera's pose as "
      "rvec/tvec, or import it without extrinsic_parameters",
      cameraFileContext(file, camera, "extrinsic_parameters"));
}

// ---------------------------------------------------------------------------------------------
// Typed access to a camera's entries, errors naming file, camera, field and line.
struct KalibrCamera {
  const YamlNode& node;
  const fs::path& file;
  std::string key;  // cam0, cam1, ...

  Error error(const std::string& field, const std::string& what, int line = 0) const {
    return Error((line ? lineTag(line) : "") + what, cameraFileContext(file, key, key + "." + field));
  }
  const YamlNode& get(const std::string& field) const {
    const YamlNode* n = node.find(field);
    if (!n) throw error(field, "missing field", node.line);
    return *n;
  }
  std::string text(const std::string& field) const {
    const YamlNode& n = get(field);
    if (n.kind != YamlNode::Kind::kScalar) throw error(field, "expected a word", n.line);
    return n.scalar;
  }
  std::vector<double> numbers(const YamlNode& n, const std::string& field, size_t count) const {
    if (n.kind != YamlNode::Kind::kList || n.items.size() != count)
      throw error(field, "expected a list of " + std::to_string(count) + " numbers", n.line);
    std::vector<double> v;
    for (const YamlNode& item : n.items) {
      const auto x = item.kind == YamlNode::Kind::kScalar ? toNumber(item.scalar) : std::nullopt;
      if (!x) throw error(field, "expected a number, got '" + item.scalar + "'", n.line);
      v.push_back(*x);
    }
    return v;
  }
  std::vector<double> numbers(const std::string& field, size_t count) const { return numbers(get(field), field, count); }
  // A 4x4 homogeneous transform as a list of 4 rows; the 3x3 block under the rotation rule.
  Pose transform(const std::string& field, ImportReport& report) const {
    const YamlNode& n = get(field);
    if (n.kind != YamlNode::Kind::kList || n.items.size() != 4)
      throw error(field, "expected a 4x4 matrix (a list of 4 rows of 4 numbers)", n.line);
    Eigen::Matrix4d M;
    for (int r = 0; r < 4; ++r) {
      const std::vector<double> row = numbers(n.items[r], field, 4);
      for (int c = 0; c < 4; ++c) M(r, c) = row[c];
    }
    if (M.row(3) != Eigen::RowVector4d(0, 0, 0, 1)) throw error(field, "the last row must be [0, 0, 0, 1]", n.line);
    return poseFromRt(checkedRotation(M.topLeftCorner<3, 3>(), file, key, key + "." + field, report),
                      M.topRightCorner<3, 1>());
  }
};

// YAML 1.1 readers (PyYAML, so Kalibr) take a number for a float only with a '.' and a signed
// exponent: "1e-05" would come back as a string.
std::string yamlFloat(double v) {
  std::string s = exact(v);
  if (s.find_first_of(".ni") != std::string::npos) return s;  // has a '.', or is inf / nan
  const size_t e = s.find('e');
  return e == std::string::npos ? s + ".0" : s.insert(e, ".0");
}

std::string yamlRow(std::initializer_list<double> values) {
  std::string s = "[";
  for (double v : values) s += (s.size() > 1 ? ", " : "") + yamlFloat(v);
  return s + "]";
}

void writeYamlTransform(std::ostringstream& out, const char* key, const Pose& T) {
  const Eigen::Matrix4d M = T.matrix();
  out << "  " << key << ":\n";
  for (int r = 0; r < 4; ++r) out << "  - " << yamlRow({M(r, 0), M(r, 1), M(r, 2), M(r, 3)}) << "\n";
}

// ---------------------------------------------------------------------------------------------
// COLMAP

// The name COLMAP's NAME gives a camera: its stem, or where stems repeat (cam1/0001.jpg,
// cam2/0001.jpg) the whole NAME without its extension, '/' -> '_'.
std::vector<std::string> colmapCameraNames(const std::vector<std::string>& image_names) {
  std::map<std::string, int> stems;
  for (const std::string& n : image_names) ++stems[fs::path(n).stem().string()];
  std::vector<std::string> out;
  for (const std::string& n : image_names) {
    const fs::path p(n);
    if (stems[p.stem().string()] == 1) {
      out.push_back(p.stem().string());
    } else {
      std::string s = (p.parent_path() / p.stem()).generic_string();
      for (char& ch : s)
        if (ch == '/') ch = '_';
      out.push_back(s);
    }
  }
  return out;
}

// One COLMAP camera model's parameters -> previz intrinsics (OpenCV pixel centres: cx, cy - 0.5).
Camera colmapCamera(const std::vector<std::string>& tok, const fs::path& file, int line) {
  const std::string id = tok[0];
  const std::string model = tok[1];
  const std::string cam = "camera id " + id;
  const std::map<std::string, size_t> counts = {{"SIMPLE_PINHOLE", 3}, {"PINHOLE", 4},     {"SIMPLE_RADIAL", 4},
                                                {"RADIAL", 5},         {"OPENCV", 8},      {"FULL_OPENCV", 12},
                                                {"OPENCV_FISHEYE", 8}};
  const auto it = counts.find(model);
  if (it == counts.end()) {
    throw Error(lineTag(line) + "unsupported camera model '" + model +
                    "' (SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV, FULL_OPENCV, OPENCV_FISHEYE)",
                cameraFileContext(file, cam, "MODEL"));
  }
  if (tok.size() != 4 + it->second)
    throw Error(lineTag(line) + model + " has " + std::to_string(it->second) + " parameters, got " +
                    std::to_string(static_cast<long>(tok.size()) - 4),
                cameraFileContext(file, cam, "PARAMS"));
  Camera c;
  const auto w = toInt(tok[2]), h = toInt(tok[3]);
  if (!w || !h) throw Error(lineTag(line) + "expected integer WIDTH HEIGHT", cameraFileContext(file, cam, "WIDTH"));
  c.width = *w;
  c.height = *h;
  std::vector<double> p;
  for (size_t i = 4; i < tok.size(); ++i) p.push_back(requireNumber(tok[i], file, line, cam, "PARAMS"));
  const bool one_f = model == "SIMPLE_PINHOLE" || model == "SIMPLE_RADIAL" || model == "RADIAL";
  const size_t k = one_f ? 3 : 4;  // first distortion parameter
  c.fx = p[0];
  c.fy = one_f ? p[0] : p[1];
  c.cx = p[k - 2] - 0.5;
  c.cy = p[k - 1] - 0.5;
  if (model == "SIMPLE_RADIAL") c.dist.k1 = p[3];
  if (model == "RADIAL") c.dist = {p[3], p[4], 0, 0, 0};
  if (model == "OPENCV" || model == "FULL_OPENCV") c.dist = {p[4], p[5], p[6], p[7], 0};
  if (model == "OPENCV_FISHEYE") c.dist = Distortion::kannalaBrandt(p[4], p[5], p[6], p[7]);
  if (model == "FULL_OPENCV") {
    // fx fy cx cy k1 k2 p1 p2 k3 k4 k5 k6: OpenCV's rational model, the same order.
    c.dist.k3 = p[8];
    c.dist.k4 = p[9];
    c.dist.k5 = p[10];
    c.dist.k6 = p[11];
  }
  return c;
}

// ---------------------------------------------------------------------------------------------
// Checks an export makes: what the format cannot carry is an Error, never dropped.

void requireNoSkew(const Camera& c, const fs::path& file, const char* format) {
  if (c.skew != 0.0) throw Error(std::string(format) + " cannot hold a skew (got " + exact(c.skew) + ")", cameraFileContext(file, c.name, "skew"));
}

void requireSafeName(const Camera& c, const fs::path& file, const char* format) {
  if (c.name.empty() || c.name.find_first_of(" \t\r\n#/\\") != std::string::npos)
    throw Error(std::string(format) + " needs camera names without spaces, '#', '/' or '\\'", cameraFileContext(file, c.name, "name"));
}

}  // namespace

// ---------------------------------------------------------------------------------------------

void ImportOptions::validate() const {
  if (width < 0 || height < 0 || (width > 0) != (height > 0))
    throw Error("image size must be both > 0 or both 0 (got " + std::to_string(width) + "x" + std::to_string(height) + ")",
                fieldContext("width/height"));
  if (units != "m" && units != "cm" && units != "mm")
    throw Error("units must be mm, cm or m (got '" + units + "')", fieldContext("units"));
  if (flip != "none" && flip != "y-up" && flip != "z-down" && flip != "y-down")
    throw Error("flip must be none, y-up, z-down or y-down (got '" + flip + "')", fieldContext("flip"));
  for (size_t i = 0; i < names.size(); ++i)
    if (names[i].empty()) throw Error("names must not be empty", fieldContext("names[" + std::to_string(i) + "]"));
}

double ImportOptions::metresPerUnit() const { return units == "mm" ? 1e-3 : units == "cm" ? 1e-2 : 1.0; }

std::string ImportReport::fullReport() const {
  std::ostringstream s;
  s << "import (" << format << ") from";
  for (const std::string& f : files) s << " " << f;
  s << "\n";
  for (const std::string& a : assumptions) s << "  assumed: " << a << "\n";
  for (const std::string& w : warnings) s << "  WARNING: " << w << "\n";
  return s.str();
}

nlohmann::json ImportReport::toJson() const {
  return {{"format", format}, {"files", files}, {"assumptions", assumptions}, {"warnings", warnings}};
}

Eigen::Matrix3d nearestRotation(const Eigen::Matrix3d& M) {
  // Orthogonal Procrustes: U V^T, with the last axis flipped when that would be a reflection.
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(M, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d D = Eigen::Matrix3d::Identity();
  D(2, 2) = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0 ? -1.0 : 1.0;
  return svd.matrixU() * D * svd.matrixV().transpose();
}

Eigen::Matrix3d checkedRotation(const Eigen::Matrix3d& R, const fs::path& file, const std::string& camera,
                                const std::string& field, ImportReport& report) {
  if (!R.allFinite()) throw Error("rotation has non-finite entries", cameraFileContext(file, camera, field));
  const double deviation = (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  const double det = R.determinant();
  if (det <= 0.0 || deviation > kRotationRefuseAbove)
    throw Error("not a rotation: max |R^T R - I| = " + sci(deviation) + ", det = " + sci(det) +
                    " (a rotation orthonormal to " + sci(kRotationRefuseAbove) + " with det > 0 is expected)",
                cameraFileContext(file, camera, field));
  if (deviation > kRotationWarnAbove)
    report.warnings.push_back("camera '" + camera + "': " + field + " is orthonormal only to " + sci(deviation) +
                              " (max |R^T R - I|); replaced by the nearest rotation");
  return nearestRotation(R);
}

std::vector<std::string> rigPoseWarnings(const Rig& rig) {
  std::vector<std::string> warnings;
  const size_t n = rig.cameras.size();
  if (n < 2) return warnings;
  const Eigen::Vector3d c0 = rig.cameras[0].T_world_cam.translation();
  double spread = 0;
  for (const RigCamera& rc : rig.cameras) spread = std::max(spread, (rc.T_world_cam.translation() - c0).norm());
  if (spread <= 1e-9) {
    warnings.push_back(c0.norm() <= 1e-9
                           ? "every camera sits at the world origin: the poses are missing (a file without "
                             "extrinsics?)"
                           : "every camera sits at one point: the poses are missing or wrong");
    return warnings;
  }
  std::vector<Eigen::Vector3d> centres, axes;
  for (const RigCamera& rc : rig.cameras) {
    centres.push_back(rc.T_world_cam.translation());
    axes.push_back(rc.T_world_cam.linear().col(2));
  }
  const auto common = nearestPointToLines(centres, axes);
  if (!common) return warnings;
  const Eigen::Vector3d& p = *common;
  std::vector<std::string> behind;
  for (const RigCamera& rc : rig.cameras)
    if (rc.T_world_cam.linear().col(2).dot(p - rc.T_world_cam.translation()) <= 0.0) behind.push_back(rc.camera.name);
  if (2 * behind.size() > n) {
    std::ostringstream s;
    s << "the point nearest to all optical axes, (" << p.x() << ", " << p.y() << ", " << p.z() << ") m, lies behind "
      << behind.size() << " of " << n << " cameras (";
    for (size_t i = 0; i < behind.size() && i < 5; ++i) s << (i ? ", " : "") << behind[i];
    s << (behind.size() > 5 ? ", ..." : "") << "): the cameras look away from each other (inverted poses? a flipped axis?)";
    warnings.push_back(s.str());
  }
  return warnings;
}

// ---------------------------------------------------------------------------------------------

RigImport importOpenCv(const std::vector<fs::path>& files, const ImportOptions& opt) {
  opt.validate();
  if (files.empty()) throw Error("no OpenCV files given", fieldContext("files"));
  RigImport out;
  out.report.format = "opencv";
  for (const fs::path& f : files) out.report.files.push_back(f.string());
  const std::vector<std::string> file_names = fileCameraNames(files);
  if (opt.names.empty())
    for (size_t i = 0; i < files.size(); ++i)
      for (size_t j = i + 1; j < files.size(); ++j)
        if (file_names[i] == file_names[j])
          throw Error("files '" + files[i].string() + "' and '" + files[j].string() + "' both give the camera name '" +
                          file_names[i] + "': name the cameras (--name)",
                      cameraFileContext(files[j], file_names[j], "names"));
  Namer namer(opt.names);
  int world_poses = 0, stereo_frames = 0;

  for (size_t i = 0; i < files.size(); ++i) {
    const fs::path& file = files[i];
    const cv::FileStorage store = openOpenCvStorage(file);
    try {
      if (has(store, "camera_matrix") && has(store, "M1"))
        throw Error("holds both camera_matrix (one camera) and M1 (a stereo pair): which is it?",
                    cameraFileContext(file, "", "camera_matrix"));
      if (has(store, "camera_matrix")) {
        RigCamera rc;
        rc.camera = readCamera(store, file, namer.next(file_names[i]), "camera_matrix", "distortion_coefficients", opt,
                               out.report);
        const std::string& name = rc.camera.name;
        // previz's own per-camera rig YAML (multicam/rig_io.h) gives the world -> camera pose as
        // R, t (lower-case t), with rvec beside R: world -> camera like rvec/tvec, not
        // stereoCalibrate's R, T (upper-case T). Where both forms are there they must agree.
        const bool world_rt = has(store, "R") && has(store, "t") && !has(store, "T");
        const bool rvec = !world_rt && (has(store, "rvec") || has(store, "tvec"));
        const bool rt = !world_rt && (has(store, "R") || has(store, "T"));
        if (rvec && rt) throw Error("holds both rvec/tvec and R/T: which is the pose?", cameraFileContext(file, name, "rvec"));
        if (world_rt) {
          const Pose T_cam_world = readPose(store, "R", "t", file, name, out.report);
          if (has(store, "rvec")) {
            const Pose by_rvec = readPose(store, "rvec", has(store, "tvec") ? "tvec" : "t", file, name, out.report);
            if ((by_rvec.matrix() - T_cam_world.matrix()).cwiseAbs().maxCoeff() > 1e-6)
              throw Error("R, t and rvec, tvec give two different poses", cameraFileContext(file, name, "R"));
          }
          rc.T_world_cam = T_cam_world.inverse();
          ++world_poses;
          out.report.assumptions.push_back("camera '" + name + "': R, t map world to camera (x_cam = R x_world + t)");
        } else if (rvec) {
          rc.T_world_cam = readPose(store, "rvec", "tvec", file, name, out.report).inverse();
          ++world_poses;
          out.report.assumptions.push_back("camera '" + name + "': rvec/tvec map world to camera (x_cam = R x_world + t)");
        } else if (rt) {
          rc.T_world_cam = readPose(store, "R", "T", file, name, out.report).inverse();
          ++stereo_frames;
          out.report.assumptions.push_back("camera '" + name +
                                           "': R/T as cv::stereoCalibrate gives them (x_this = R x_first + T): the "
                                           "world is the first camera of its pair");
        } else if (has(store, "extrinsic_parameters")) {
          refuseViewPoses(file, name);
        } else {
          out.report.assumptions.push_back("camera '" + name + "': no pose in the file; placed at the world origin");
        }
        out.rig.cameras.push_back(std::move(rc));
      } else if (has(store, "M1")) {
        // OpenCV's samples/cpp/stereo_calib.cpp: intrinsics.yml (M1 D1 M2 D2), extrinsics.yml
        // (R T R1 R2 P1 P2 Q); R, T map camera-1 points into camera 2: x2 = R x1 + T.
        RigCamera first, second;
        first.camera = readCamera(store, file, namer.next(file_names[i] + "_1"), "M1", "D1", opt, out.report);
        second.camera = readCamera(store, file, namer.next(file_names[i] + "_2"), "M2", "D2", opt, out.report);
        cv::FileStorage rt_store = store;
        fs::path rt_file = file;
        if (!has(store, "R") && !has(store, "T") && i + 1 < files.size()) {
          const cv::FileStorage next = openOpenCvStorage(files[i + 1]);
          if (has(next, "R") && has(next, "T") && !has(next, "camera_matrix") && !has(next, "M1")) {
            rt_store = next;
            rt_file = files[++i];
          }
        }
        if (has(rt_store, "R") || has(rt_store, "T")) {
          second.T_world_cam = readPose(rt_store, "R", "T", rt_file, second.camera.name, out.report).inverse();
          ++stereo_frames;
          out.report.assumptions.push_back("stereo pair '" + first.camera.name + "', '" + second.camera.name +
                                           "': the world is the first camera's frame; R/T from " + rt_file.string() +
                                           " (x2 = R x1 + T)");
        } else {
          out.report.assumptions.push_back("stereo pair '" + first.camera.name + "', '" + second.camera.name +
                                           "': no R/T (neither in the file nor in the next one); both at the origin");
        }
        out.rig.cameras.push_back(std::move(first));
        out.rig.cameras.push_back(std::move(second));
      } else if (has(store, "R") && has(store, "T")) {
        throw Error(
            "holds R/T (stereoCalibrate's extrinsics) but no camera matrices: give it right after the stereo "
            "intrinsics file (M1 D1 M2 D2) it belongs to",
            cameraFileContext(file, "", "R"));
      } else {
        throw Error("missing field, expected camera_matrix (one camera) or M1/M2 (a stereo pair)",
                    cameraFileContext(file, file_names[i], "camera_matrix"));
      }
    } catch (const cv::Exception& e) {
      throw Error(std::string("malformed OpenCV FileStorage content: ") + e.what(), cameraFileContext(file, "", ""));
    }
  }
  const int frames = stereo_frames + (world_poses > 0 ? 1 : 0);
  if (frames > 1)
    out.report.warnings.push_back("the poses come from " + std::to_string(frames) +
                                  " different frames (each stereo R/T puts its first camera at the origin): they are "
                                  "not in one world");
  finishImport(out, opt, stereo_frames > 0 ? "first camera of the stereo pair" : "the OpenCV files' world");
  return out;
}

std::vector<fs::path> exportOpenCv(const Rig& rig, const fs::path& dir) {
  rig.validate();
  std::vector<fs::path> written;
  for (const RigCamera& rc : rig.cameras) {
    requireSafeName(rc.camera, dir, "OpenCV export (one file per camera name)");
    written.push_back(dir / (rc.camera.name + ".yaml"));
    writeOpenCvCamera(rc, written.back());
  }
  return written;
}

// ---------------------------------------------------------------------------------------------

RigImport importKalibr(const fs::path& camchain, const ImportOptions& opt) {
  opt.validate();
  RigImport out;
  out.report.format = "kalibr";
  out.report.files.push_back(camchain.string());
  const YamlNode root = YamlSubsetParser(readTextFile(camchain), camchain).parse();
  if (root.kind != YamlNode::Kind::kMap || root.entries.empty())
    throw Error("expected cam0:, cam1:, ... at the top", cameraFileContext(camchain, "", ""));
  // PyYAML sorts the keys as text (cam0, cam1, cam10, cam2, ...): the chain goes by number.
  std::vector<const YamlNode*> chain(root.entries.size(), nullptr);
  for (const auto& [key, node] : root.entries) {
    const auto n = key.rfind("cam", 0) == 0 ? toInt(key.substr(3)) : std::nullopt;
    if (!n || *n < 0 || static_cast<size_t>(*n) >= chain.size() || key != "cam" + std::to_string(*n))
      throw Error("expected cameras cam0 .. cam" + std::to_string(chain.size() - 1) + ", got '" + key + "'",
                  cameraFileContext(camchain, key, key));
    chain[static_cast<size_t>(*n)] = &node;
  }

  Namer namer(opt.names);
  Pose T_world_prev = Pose::Identity();  // T_world_c(n-1)
  for (size_t n = 0; n < chain.size(); ++n) {
    const KalibrCamera kc{*chain[n], camchain, "cam" + std::to_string(n)};
    if (kc.node.kind != YamlNode::Kind::kMap) throw kc.error("", "expected the camera's fields", kc.node.line);
    const std::string model = kc.text("camera_model");
    if (model != "pinhole")
      throw kc.error("camera_model", "camera model '" + model + "' is not supported (pinhole only)");
    const std::string dist = kc.text("distortion_model");
    if (dist != "radtan" && dist != "none" && dist != "equidistant")
      throw kc.error("distortion_model", "distortion model '" + dist + "' is not supported (radtan, equidistant or none)");

    RigCamera rc;
    Camera& c = rc.camera;
    c.name = namer.next(kc.key);
    const std::vector<double> k = kc.numbers("intrinsics", 4);  // fu fv pu pv
    c.fx = k[0];
    c.fy = k[1];
    c.cx = k[2];
    c.cy = k[3];
    if (dist == "radtan") {
      const std::vector<double> d = kc.numbers("distortion_coeffs", 4);  // k1 k2 r1 r2
      c.dist = {d[0], d[1], d[2], d[3], 0.0};
    } else if (dist == "equidistant") {
      const std::vector<double> d = kc.numbers("distortion_coeffs", 4);  // k1 k2 k3 k4
      c.dist = Distortion::kannalaBrandt(d[0], d[1], d[2], d[3]);
    }
    const std::vector<double> res = kc.numbers("resolution", 2);
    if (!toInt(exact(res[0])) || !toInt(exact(res[1]))) throw kc.error("resolution", "expected integers [width, height]");
    c.width = static_cast<int>(res[0]);
    c.height = static_cast<int>(res[1]);
    try {
      c.validate();
    } catch (const Error& e) {
      throw kc.error(e.context().field, e.message());
    }
    // T_cn_cnm1 maps camera n-1's points into camera n: T_world_cn = T_world_cnm1 * T_cn_cnm1^-1.
    if (n == 0) {
      if (kc.node.find("T_world_cam")) {
        T_world_prev = kc.transform("T_world_cam", out.report);
        out.report.assumptions.push_back("world: placed by cam0's T_world_cam (previz's key)");
      } else {
        out.report.assumptions.push_back("world: camera '" + c.name + "' (Kalibr's cam0; a chain has no world frame)");
      }
      if (kc.node.find("T_cn_cnm1"))
        out.report.warnings.push_back("camera '" + c.name + "': cam0 has a T_cn_cnm1 (no previous camera): ignored");
      rc.T_world_cam = T_world_prev;
    } else {
      rc.T_world_cam = T_world_prev * kc.transform("T_cn_cnm1", out.report).inverse();
    }
    T_world_prev = rc.T_world_cam;
    out.rig.cameras.push_back(std::move(rc));
  }
  out.report.assumptions.push_back("pixels: Kalibr's pu, pv taken in OpenCV's convention (pixel (0,0) at the centre of "
                                   "the top-left pixel); radtan [k1 k2 r1 r2] = OpenCV's k1 k2 p1 p2; equidistant "
                                   "[k1 k2 k3 k4] = OpenCV fisheye's D (Kannala-Brandt)");
  finishImport(out, opt,
               chain[0]->find("T_world_cam") ? "the Kalibr file's T_world_cam world"
                                                          : "camera '" + out.rig.cameras[0].camera.name + "' (Kalibr cam0)");
  return out;
}

void exportKalibr(const Rig& rig, const fs::path& camchain) {
  rig.validate();
  if (rig.cameras.empty()) throw Error("no cameras to write", cameraFileContext(camchain, "", "cameras"));
  std::ostringstream out;
  out << "# Kalibr camchain written by previz: pinhole-radtan or pinhole-equi, T_cn_cnm1 maps camera n-1 points into camera n,\n"
         "# metres. cam0.T_world_cam (previz) places the chain in previz's world (z up, floor z = 0).\n";
  for (size_t n = 0; n < rig.cameras.size(); ++n) {
    const RigCamera& rc = rig.cameras[n];
    const Camera& c = rc.camera;
    requireNoSkew(c, camchain, "Kalibr's pinhole model");
    const bool kb = c.dist.model == LensModel::kKannalaBrandt;
    if (!kb && c.dist.k3 != 0.0)
      throw Error("Kalibr's radtan model has no k3 (got " + exact(c.dist.k3) + ")", cameraFileContext(camchain, c.name, "distortion.k3"));
    if (!kb) {
      const std::pair<const char*, double> rational[] = {{"k4", c.dist.k4}, {"k5", c.dist.k5}, {"k6", c.dist.k6}};
      for (const auto& [term, v] : rational)
        if (v != 0.0)
          throw Error(std::string("Kalibr's radtan model has no rational term ") + term + " (got " + exact(v) + ")",
                      cameraFileContext(camchain, c.name, std::string("distortion.") + term));
    }
    out << "cam" << n << ":\n";
    if (n == 0) writeYamlTransform(out, "T_world_cam", rc.T_world_cam);
    else writeYamlTransform(out, "T_cn_cnm1", rc.T_world_cam.inverse() * rig.cameras[n - 1].T_world_cam);
    out << "  camera_model: pinhole\n"
        << "  distortion_coeffs: "
        << (kb ? yamlRow({c.dist.k1, c.dist.k2, c.dist.k3, c.dist.k4}) : yamlRow({c.dist.k1, c.dist.k2, c.dist.p1, c.dist.p2}))
        << "\n"
        << "  distortion_model: " << (kb ? "equidistant" : "radtan") << "\n"
        << "  intrinsics: " << yamlRow({c.fx, c.fy, c.cx, c.cy}) << "\n"
        << "  resolution: [" << c.width << ", " << c.height << "]\n";
    std::string topic = "/" + c.name + "/image_raw";
    if (topic.find_first_of(":#'\"[]{},") != std::string::npos) {
      std::string q = "\"";
      for (char ch : topic) q += (ch == '"' || ch == '\\') ? std::string("\\") + ch : std::string(1, ch);
      topic = q + "\"";
    }
    out << "  rostopic: " << topic << "\n";
  }
  writeFileAtomic(camchain, out.str());
}

// ---------------------------------------------------------------------------------------------

RigImport importColmap(const fs::path& dir, const ImportOptions& opt) {
  opt.validate();
  RigImport out;
  out.report.format = "colmap";
  const fs::path cameras_txt = dir / "cameras.txt", images_txt = dir / "images.txt";
  for (const fs::path& f : {cameras_txt, images_txt}) {
    std::error_code ec;
    if (!fs::is_regular_file(f, ec)) {
      fs::path bin = f;
      bin.replace_extension(".bin");
      throw Error(fs::exists(bin, ec) ? "missing; the model is binary: convert it with `colmap model_converter "
                                        "--output_type TXT`"
                                      : "missing (a COLMAP text model: cameras.txt + images.txt)",
                  cameraFileContext(f, "", ""));
    }
    out.report.files.push_back(f.string());
  }

  std::map<std::string, Camera> cameras;  // by CAMERA_ID
  for (const auto& [line, tok] : readRows(cameras_txt)) {
    if (tok.size() < 4) throw Error(lineTag(line) + "expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]", cameraFileContext(cameras_txt, "", "row"));
    if (!cameras.emplace(tok[0], colmapCamera(tok, cameras_txt, line)).second)
      throw Error(lineTag(line) + "duplicate CAMERA_ID " + tok[0], cameraFileContext(cameras_txt, "", "CAMERA_ID"));
  }

  // images.txt: an image line, then its 2-D points line (possibly empty), as COLMAP reads it.
  struct Image {
    int line;
    std::string name, camera_id;
    Eigen::Quaterniond q;
    Eigen::Vector3d t;
  };
  std::vector<Image> images;
  {
    std::istringstream in(readTextFile(images_txt));
    std::string text;
    int number = 0;
    while (std::getline(in, text)) {
      ++number;
      const size_t first = text.find_first_not_of(" \t\r");
      if (first == std::string::npos || text[first] == '#') continue;
      std::istringstream ls(text);
      std::vector<std::string> tok;
      for (std::string s; ls >> s;) tok.push_back(s);
      if (tok.size() < 10)
        throw Error(lineTag(number) + "expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME",
                    cameraFileContext(images_txt, "", "row"));
      Image im;
      im.line = number;
      im.name = tok[9];
      for (size_t i = 10; i < tok.size(); ++i) im.name += " " + tok[i];
      double v[7];
      const char* fields[7] = {"QW", "QX", "QY", "QZ", "TX", "TY", "TZ"};
      for (int i = 0; i < 7; ++i) v[i] = requireNumber(tok[i + 1], images_txt, number, im.name, fields[i]);
      im.q = Eigen::Quaterniond(v[0], v[1], v[2], v[3]);  // Hamilton, w first: R_cam_world
      im.t = Eigen::Vector3d(v[4], v[5], v[6]);
      im.camera_id = tok[8];
      images.push_back(std::move(im));
      std::getline(in, text);  // POINTS2D[] as (X, Y, POINT3D_ID)
      ++number;
    }
  }
  std::vector<std::string> image_names;
  for (const Image& im : images) image_names.push_back(im.name);
  const std::vector<std::string> names = colmapCameraNames(image_names);
  Namer namer(opt.names);
  for (size_t i = 0; i < images.size(); ++i) {
    const Image& im = images[i];
    const auto cam = cameras.find(im.camera_id);
    if (cam == cameras.end())
      throw Error(lineTag(im.line) + "CAMERA_ID " + im.camera_id + " is not in cameras.txt", cameraFileContext(images_txt, im.name, "CAMERA_ID"));
    RigCamera rc;
    rc.camera = cam->second;
    rc.camera.name = namer.next(names[i]);
    const std::string& name = rc.camera.name;
    // The rotation rule on the quaternion's norm (a unit quaternion is a rotation).
    const double deviation = std::abs(im.q.norm() - 1.0);
    if (deviation > kRotationRefuseAbove)
      throw Error(lineTag(im.line) + "quaternion norm " + exact(im.q.norm()) + " is not 1 (refused above " +
                      sci(kRotationRefuseAbove) + ")",
                  cameraFileContext(images_txt, name, "QW QX QY QZ"));
    if (deviation > kRotationWarnAbove)
      out.report.warnings.push_back("camera '" + name + "': quaternion norm differs from 1 by " + sci(deviation) +
                                    "; normalised");
    rc.T_world_cam = poseFromRt(im.q.normalized().toRotationMatrix(), im.t).inverse();
    out.rig.cameras.push_back(std::move(rc));
  }
  out.report.assumptions.push_back("pixels: COLMAP's cx, cy - 0.5 (COLMAP puts the centre of the top-left pixel at (0.5, 0.5))");
  out.report.assumptions.push_back("poses: QW QX QY QZ TX TY TZ map world to camera (Hamilton quaternion, w first)");
  out.report.assumptions.push_back("world: COLMAP's reconstruction frame, arbitrary orientation and scale unless the model "
                                   "was aligned (colmap model_aligner)");
  finishImport(out, opt, "COLMAP's reconstruction frame");
  return out;
}

std::vector<fs::path> exportColmap(const Rig& rig, const fs::path& dir) {
  rig.validate();
  std::ostringstream cams, imgs;
  cams << "# Camera list with one line of data per camera:\n"
          "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n"
          "# Number of cameras: "
       << rig.cameras.size() << "\n";
  imgs << "# Image list with two lines of data per image:\n"
          "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n"
          "#   POINTS2D[] as (X, Y, POINT3D_ID)\n"
          "# Number of images: "
       << rig.cameras.size() << ", mean observations per image: 0\n";
  for (size_t i = 0; i < rig.cameras.size(); ++i) {
    const RigCamera& rc = rig.cameras[i];
    const Camera& c = rc.camera;
    requireNoSkew(c, dir / "cameras.txt", "COLMAP");
    requireSafeName(c, dir / "images.txt", "COLMAP");
    // The simplest model that holds the lens exactly; principal point in COLMAP's pixels.
    const std::string id = std::to_string(i + 1);
    const std::string cx = exact(c.cx + 0.5), cy = exact(c.cy + 0.5);
    cams << id << " ";
    if (c.dist.model == LensModel::kKannalaBrandt) {
      cams << "OPENCV_FISHEYE " << c.width << " " << c.height << " " << exact(c.fx) << " " << exact(c.fy) << " " << cx
           << " " << cy << " " << exact(c.dist.k1) << " " << exact(c.dist.k2) << " " << exact(c.dist.k3) << " "
           << exact(c.dist.k4);
    } else if (c.dist.isZero()) {
      cams << "PINHOLE " << c.width << " " << c.height << " " << exact(c.fx) << " " << exact(c.fy) << " " << cx << " " << cy;
    } else {
      const bool full = c.dist.k3 != 0.0 || c.dist.isRational();
      cams << (full ? "FULL_OPENCV " : "OPENCV ") << c.width << " " << c.height << " " << exact(c.fx) << " "
           << exact(c.fy) << " " << cx << " " << cy << " " << exact(c.dist.k1) << " " << exact(c.dist.k2) << " "
           << exact(c.dist.p1) << " " << exact(c.dist.p2);
      if (full)
        cams << " " << exact(c.dist.k3) << " " << exact(c.dist.k4) << " " << exact(c.dist.k5) << " "
             << exact(c.dist.k6);
    }
    cams << "\n";
    const Pose T_cam_world = rc.T_world_cam.inverse();
    Eigen::Quaterniond q(T_cam_world.rotation());
    if (q.w() < 0) q.coeffs() *= -1.0;  // COLMAP's canonical sign
    const Eigen::Vector3d t = T_cam_world.translation();
    imgs << id << " " << exact(q.w()) << " " << exact(q.x()) << " " << exact(q.y()) << " " << exact(q.z()) << " "
         << exact(t.x()) << " " << exact(t.y()) << " " << exact(t.z()) << " " << id << " " << c.name << ".png\n\n";
  }
  const std::vector<fs::path> written = {dir / "cameras.txt", dir / "images.txt", dir / "points3D.txt"};
  writeFileAtomic(written[0], cams.str());
  writeFileAtomic(written[1], imgs.str());
  // COLMAP reads a model only with its points file; none are known here.
  writeFileAtomic(written[2],
                  "# 3D point list with one line of data per point:\n"
                  "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n"
                  "# Number of points: 0, mean track length: 0\n");
  return written;
}

// ---------------------------------------------------------------------------------------------

namespace {

// Middlebury-style rows may start with a line holding only the number of cameras.
void skipCountLine(std::vector<std::pair<int, std::vector<std::string>>>& rows, const fs::path& path) {
  if (rows.empty() || rows.front().second.size() != 1) return;
  const std::string& s = rows.front().second[0];
  // Digits only, and few enough for a long: "99999999999999999999" threw std::out_of_range from
  // std::stol, an error naming neither file nor line (fuzz/camera_rows.cpp, PREVIZ_FUZZ_STRICT).
  if (s.find_first_not_of("0123456789") != std::string::npos || s.size() > 9)
    throw Error(lineTag(rows.front().first) + "a one-token line must be the camera count, got '" + s + "'",
                cameraFileContext(path, "", "count"));
  const long count = std::stol(s);
  const int line = rows.front().first;
  rows.erase(rows.begin());
  if (count != static_cast<long>(rows.size()))
    throw Error(lineTag(line) + "the file announces " + std::to_string(count) + " cameras but holds " +
                    std::to_string(rows.size()),
                cameraFileContext(path, "", "count"));
}

struct CameraRow {
  int line;
  std::string name;
  std::vector<std::string> tok;
};

// The rows of a K R t or P file, names given (options.names) or the rows' own, field count checked.
std::vector<CameraRow> readCameraRows(const fs::path& path, const ImportOptions& opt, size_t fields,
                                      const char* layout, RigImport& out) {
  opt.validate();
  if (opt.width <= 0 && !opt.size_of)
    throw Error("rows carry no image size: give one (--size WxH, or --take)", cameraFileContext(path, "", "width/height"));
  out.report.files.push_back(path.string());
  auto rows = readRows(path);
  skipCountLine(rows, path);
  Namer namer(opt.names);
  std::vector<CameraRow> out_rows;
  for (auto& [line, tok] : rows) {
    const std::string name = namer.next(tok[0]);
    if (tok.size() != fields)
      throw Error(lineTag(line) + "expected " + std::to_string(fields) + " fields (" + layout + "), got " +
                      std::to_string(tok.size()),
                  cameraFileContext(path, name, "row"));
    out_rows.push_back({line, name, std::move(tok)});
  }
  out.report.assumptions.push_back(
      (opt.width > 0 ? "image size " + std::to_string(opt.width) + "x" + std::to_string(opt.height) + " as given"
                     : std::string("image sizes from each camera's images")) +
      " (rows carry none); no distortion (rows carry none)");
  out.report.assumptions.push_back("pixels: (0,0) at the centre of the top-left pixel, as OpenCV");
  return out_rows;
}

// A row's image size: --size, else its camera's images; an Error naming the camera when neither.
std::pair<int, int> rowSize(const ImportOptions& opt, const fs::path& path, const CameraRow& row) {
  const std::pair<int, int> s = givenSize(opt, row.name);
  if (s.first <= 0)
    throw Error(lineTag(row.line) + "no image size for this camera: the take has no image of it (give --size WxH)",
                cameraFileContext(path, row.name, "width/height"));
  return s;
}

// An Error from one row, with its line, file and camera.
Error rowError(const Error& e, const fs::path& path, const CameraRow& row) {
  const std::string msg = e.message().rfind("line ", 0) == 0 ? e.message() : lineTag(row.line) + e.message();
  return Error(msg, cameraFileContext(path, row.name, e.context().field));
}

// P rows written as K [R | t] by a tool whose world is left-handed (Oxford's dino.P.txt) have
// det M < 0 with the scene in front (w > 0): no proper rotation reads them as written, and
// rigCameraFromProjection's sign choice (det M > 0) would turn every camera away from the
// scene. Recognised when every row has det M < 0 and the common point of the optical axes
// (which does not depend on P's sign) is in front of most cameras as written.
bool leftHandedRows(const std::vector<Eigen::Matrix<double, 3, 4>>& Ps) {
  std::vector<Eigen::Vector3d> centres, axes;
  for (const auto& P : Ps) {
    const Eigen::Matrix3d M = P.leftCols<3>();
    if (!(M.determinant() < 0.0)) return false;
    centres.push_back(-M.inverse() * P.col(3));
    axes.push_back(M.row(2).transpose());
  }
  const auto common = nearestPointToLines(centres, axes);
  if (!common) return false;
  size_t in_front = 0;
  for (const auto& P : Ps) in_front += P.row(2).dot(common->homogeneous()) > 0.0;
  return 2 * in_front > Ps.size();
}

RigImport importRows(const fs::path& path, const ImportOptions& opt, bool krt) {
  RigImport out;
  out.report.format = krt ? "krt" : "projection";
  const std::vector<CameraRow> rows =
      readCameraRows(path, opt, krt ? 22 : 13, krt ? "name k11..k33 r11..r33 t1 t2 t3" : "name p11..p34", out);
  if (krt) {
    for (const CameraRow& row : rows) {
      RigCamera rc;
      try {
        double v[21];
        for (int i = 0; i < 21; ++i)
          v[i] = requireNumber(row.tok[i + 1], path, row.line, row.name, i < 9 ? "K" : i < 18 ? "R" : "t");
        Eigen::Matrix3d K, R;
        K << v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[8];
        R << v[9], v[10], v[11], v[12], v[13], v[14], v[15], v[16], v[17];
        if (K(1, 0) != 0.0 || K(2, 0) != 0.0 || K(2, 1) != 0.0 || K(2, 2) != 1.0)
          throw Error("expected K = [fx s cx; 0 fy cy; 0 0 1]", cameraFileContext(path, row.name, "K"));
        rc.camera.name = row.name;
        std::tie(rc.camera.width, rc.camera.height) = rowSize(opt, path, row);
        rc.camera.fx = K(0, 0);
        rc.camera.fy = K(1, 1);
        rc.camera.cx = K(0, 2);
        rc.camera.cy = K(1, 2);
        rc.camera.skew = K(0, 1);
        rc.T_world_cam =
            poseFromRt(checkedRotation(R, path, row.name, "R", out.report), {v[18], v[19], v[20]}).inverse();
        rc.camera.validate();
      } catch (const Error& e) {
        throw rowError(e, path, row);
      }
      out.rig.cameras.push_back(std::move(rc));
    }
    out.report.assumptions.push_back("poses: x_cam = R x_world + t");
    finishImport(out, opt, "the K R t rows' world");
    return out;
  }

  std::vector<Eigen::Matrix<double, 3, 4>> Ps;
  for (const CameraRow& row : rows) {
    Eigen::Matrix<double, 3, 4> P;
    for (int i = 0; i < 12; ++i) P(i / 4, i % 4) = requireNumber(row.tok[i + 1], path, row.line, row.name, "P");
    Ps.push_back(P);
  }
  const bool mirror = leftHandedRows(Ps);
  if (mirror) {
    // x -> -x: the same pixels (P S S X = P X), proper cameras, the scene its mirror image.
    for (auto& P : Ps) P.col(0) *= -1.0;
    out.report.warnings.push_back(
        "the P rows' cameras are left-handed in their world (det M < 0 with the scene in front): the world's x "
        "axis is mirrored (x -> -x) so that they are proper cameras; pixels are unchanged, the scene comes out as "
        "its mirror image");
  }
  for (size_t i = 0; i < rows.size(); ++i) {
    try {
      // The RQ decomposition returns a rotation to machine precision: the rotation rule holds.
      const auto [w, h] = rowSize(opt, path, rows[i]);
      RigCamera rc = rigCameraFromProjection(Ps[i], w, h, rows[i].name);
      rc.camera.validate();
      out.rig.cameras.push_back(std::move(rc));
    } catch (const Error& e) {
      throw rowError(e, path, rows[i]);
    }
  }
  out.report.assumptions.push_back("P = K [R | t] decomposed with K's diagonal positive and det R = +1");
  finishImport(out, opt, mirror ? "the P rows' world, x mirrored" : "the P rows' world");
  return out;
}

}  // namespace

RigImport importKRtRows(const fs::path& path, const ImportOptions& opt) { return importRows(path, opt, true); }

RigImport importProjectionRows(const fs::path& path, const ImportOptions& opt) { return importRows(path, opt, false); }

}  // namespace previz
