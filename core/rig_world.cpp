#include "core/rig_world.h"

#include <cmath>
#include <cstdio>
#include <set>

#include <Eigen/Geometry>
#include <Eigen/SVD>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/io.h"

namespace fs = std::filesystem;

namespace previz {

namespace {

// Above these the report warns: a point 1 cm off is a mismeasured point or a wrong one; a
// scale 1 % off is a unit wrong (mm vs cm is 10x) or a rig whose scale is not metric.
constexpr double kWarnResidualM = 0.01;
constexpr double kWarnScale = 0.01;

std::string fmt(const char* format, double v) {
  char s[64];
  std::snprintf(s, sizeof(s), format, v);
  return s;
}

Eigen::Vector3d readPoint(const nlohmann::json& p, const char* key, const std::string& file, const std::string& where) {
  const std::string field = where + "." + key;
  if (!p.contains(key) || !p[key].is_array() || p[key].size() != 3)
    throw Error("needs \"" + std::string(key) + "\": [x, y, z]", fileContext(file, field));
  Eigen::Vector3d v;
  for (int k = 0; k < 3; ++k) {
    if (!p[key][k].is_number() || !std::isfinite(p[key][k].get<double>()))
      throw Error("coordinate " + std::to_string(k) + " is not a finite number", fileContext(file, field));
    v(k) = p[key][k].get<double>();
  }
  return v;
}

}  // namespace

WorldPoints readWorldPoints(const fs::path& path) {
  const std::string file = path.string();
  const nlohmann::json j = readJsonFile(path);
  if (!j.is_object() || !j.contains("points") || !j["points"].is_array())
    throw Error("needs \"points\": [{\"name\", \"world\", \"rig\"}, ...]", fileContext(file, "points"));
  WorldPoints out;
  out.file = file;
  if (j.contains("fit_scale")) {
    if (!j["fit_scale"].is_boolean()) throw Error("must be true or false", fileContext(file, "fit_scale"));
    out.fit_scale = j["fit_scale"].get<bool>();
  }
  std::set<std::string> names;
  for (size_t i = 0; i < j["points"].size(); ++i) {
    const nlohmann::json& p = j["points"][i];
    WorldPoint w;
    w.name = p.is_object() && p.contains("name") && p["name"].is_string() ? p["name"].get<std::string>()
                                                                          : "#" + std::to_string(i);
    const std::string where = "points[" + std::to_string(i) + "] '" + w.name + "'";
    if (!p.is_object()) throw Error("is not an object", fileContext(file, where));
    if (!names.insert(w.name).second) throw Error("name repeated", fileContext(file, where));
    w.world_m = readPoint(p, "world", file, where);
    w.rig = readPoint(p, "rig", file, where);
    out.points.push_back(w);
  }
  if (out.points.size() < 3)
    throw Error("needs 3 or more points (got " + std::to_string(out.points.size()) + ")", fileContext(file, "points"));
  return out;
}

WorldPlacement fitWorldPlacement(const WorldPoints& points, double metres_per_unit) {
  const int n = static_cast<int>(points.points.size());
  if (n < 3) throw Error("needs 3 or more points (got " + std::to_string(n) + ")", fileContext(points.file, "points"));
  Eigen::Matrix3Xd rig(3, n), world(3, n);
  for (int i = 0; i < n; ++i) {
    rig.col(i) = points.points[i].rig * metres_per_unit;
    world.col(i) = points.points[i].world_m;
  }
  // Collinear points leave a rotation about their line free: the second singular value of the
  // centred rig points against the first, 1e-6 being far below any surveyed layout.
  const Eigen::Matrix3Xd centred = rig.colwise() - rig.rowwise().mean();
  const Eigen::Vector3d sv = Eigen::JacobiSVD<Eigen::Matrix3Xd>(centred).singularValues();
  if (!(sv(1) > 1e-6 * sv(0)))
    throw Error("the points are (nearly) collinear: the rotation about their line is not fixed; give a point off "
                "that line",
                fileContext(points.file, "points"));

  WorldPlacement out;
  const Eigen::Matrix4d similarity = Eigen::umeyama(rig, world, true);
  out.implied_scale = similarity.topLeftCorner<3, 3>().determinant() > 0
                          ? std::cbrt(similarity.topLeftCorner<3, 3>().determinant())
                          : 0.0;
  const Eigen::Matrix4d T = points.fit_scale ? similarity : Eigen::umeyama(rig, world, false);
  out.scale = points.fit_scale ? out.implied_scale : 1.0;
  out.T_world_rig.linear() = T.topLeftCorner<3, 3>() / out.scale;
  out.T_world_rig.translation() = T.topRightCorner<3, 1>();
  double ssr = 0;
  for (int i = 0; i < n; ++i) {
    const double r = (out.T_world_rig * (out.scale * rig.col(i)) - world.col(i)).norm();
    ssr += r * r;
    if (r >= out.max_m) {
      out.max_m = r;
      out.worst = points.points[i].name;
    }
  }
  out.rms_m = std::sqrt(ssr / n);
  return out;
}

void placeRig(Rig& rig, const Pose& T_world_rig, double scale, const std::string& world_frame) {
  for (RigCamera& rc : rig.cameras) {
    rc.T_world_cam.translation() *= scale;
    rc.T_world_cam = T_world_rig * rc.T_world_cam;
  }
  rig.world_frame = world_frame;
}

void placeImport(RigImport& imported, const Pose& T_world_rig, double scale, const std::string& world_frame,
                 const std::string& by) {
  placeRig(imported.rig, T_world_rig, scale, world_frame);
  for (std::string& a : imported.report.assumptions)
    if (a.rfind("axes:", 0) == 0) a = "axes: previz's z up set by " + by + " (the file's own axes not used)";
}

std::string impliedScaleWarning(double implied_scale, double sigma, const std::string& who_implies,
                                const ImportOptions& options) {
  if (!(std::abs(implied_scale - 1.0) > kWarnScale)) return "";
  return "world: " + who_implies + " a scale of " + fmt("%.4f", implied_scale) +
         (sigma > 0 ? " +- " + fmt("%.2g", sigma) : std::string()) + " between the file and the world: is --units " +
         options.units + " right? (--fit-scale fits it)";
}

WorldPlacement placeImportByPoints(RigImport& imported, const WorldPoints& points, const ImportOptions& options) {
  if (options.flip != "none")
    throw Error("--world points fixes the world's axes itself; leave out --flip (got '" + options.flip + "')",
                fieldContext("flip"));
  const double s = options.metresPerUnit();
  const WorldPlacement w = fitWorldPlacement(points, s);
  placeImport(imported, w.T_world_rig, w.scale,
              "z up, floor at z = 0 (placed by " + std::to_string(points.points.size()) + " points of " + points.file + ")",
              "the points of " + points.file);
  ImportReport& r = imported.report;
  r.files.push_back(points.file);
  r.assumptions.push_back("world: placed by " + std::to_string(points.points.size()) + " points of " + points.file +
                          ": \"world\" in metres in previz's world (z up, floor at z = 0), \"rig\" in the file's "
                          "frame, in " + options.units);
  r.assumptions.push_back(points.fit_scale ? "world: a similarity fitted (fit_scale): positions scaled by " +
                                                 fmt("%.9g", w.scale) + " after the units"
                                           : "world: a rigid motion fitted (no scale; the implied scale is " +
                                                 fmt("%.6f", w.implied_scale) + ")");
  r.assumptions.push_back("world: point residuals RMS " + fmt("%.3g", w.rms_m * 1e3) + " mm, worst '" + w.worst +
                          "' " + fmt("%.3g", w.max_m * 1e3) + " mm");
  if (w.max_m > kWarnResidualM)
    r.warnings.push_back("world: point '" + w.worst + "' is " + fmt("%.1f", w.max_m * 1e3) +
                         " mm from where the others put it: mismeasured, or a different point in the two frames?");
  if (!points.fit_scale) {
    const std::string warning = impliedScaleWarning(w.implied_scale, 0, "the points imply", options);
    if (!warning.empty()) r.warnings.push_back(warning);
  }
  return w;
}

}  // namespace previz
