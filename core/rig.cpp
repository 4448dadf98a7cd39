#include "core/rig.h"

#include <cmath>
#include <set>

#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/names.h"
#include "core/io.h"

namespace previz {

namespace {

constexpr const char* kModel = "brown-conrady-opencv";
constexpr const char* kPixelOrigin = "pixel (0,0) is the centre of the top-left pixel";

const char* typeName(const nlohmann::json& j) { return j.type_name(); }

// Field readers: the message says what was expected and what was found.
const nlohmann::json& require(const nlohmann::json& j, const std::string& key,
                              const std::string& prefix, const std::string& file,
                              const std::string& camera, const std::string& expected) {
  if (!j.contains(key))
    throw Error("missing field, expected " + expected, cameraFileContext(file, camera, prefix + key));
  return j.at(key);
}

double readNumber(const nlohmann::json& j, const std::string& key, const std::string& prefix,
                  const std::string& file, const std::string& camera) {
  const auto& v = require(j, key, prefix, file, camera, "a number");
  if (!v.is_number())
    throw Error(std::string("expected a number, got ") + typeName(v), cameraFileContext(file, camera, prefix + key));
  return v.get<double>();
}

int readInt(const nlohmann::json& j, const std::string& key, const std::string& prefix,
            const std::string& file, const std::string& camera) {
  const auto& v = require(j, key, prefix, file, camera, "an integer");
  if (!v.is_number_integer())
    throw Error(std::string("expected an integer, got ") + typeName(v), cameraFileContext(file, camera, prefix + key));
  const auto x = v.get<long long>();
  if (x < std::numeric_limits<int>::min() || x > std::numeric_limits<int>::max())
    throw Error("integer out of range", cameraFileContext(file, camera, prefix + key));
  return static_cast<int>(x);
}

std::string readString(const nlohmann::json& j, const std::string& key, const std::string& prefix,
                       const std::string& file, const std::string& camera) {
  const auto& v = require(j, key, prefix, file, camera, "a string");
  if (!v.is_string())
    throw Error(std::string("expected a string, got ") + typeName(v), cameraFileContext(file, camera, prefix + key));
  return v.get<std::string>();
}

Camera cameraFromJsonAt(const nlohmann::json& j, const std::string& file, const std::string& prefix) {
  if (!j.is_object())
    throw Error(std::string("expected a camera object, got ") + typeName(j), cameraFileContext(file, "", prefix.empty() ? "camera" : prefix.substr(0, prefix.size() - 1)));
  Camera c;
  c.name = readString(j, "name", prefix, file, "");
  const std::string& cam = c.name;
  c.width = readInt(j, "width", prefix, file, cam);
  c.height = readInt(j, "height", prefix, file, cam);
  c.fx = readNumber(j, "fx", prefix, file, cam);
  c.fy = readNumber(j, "fy", prefix, file, cam);
  c.cx = readNumber(j, "cx", prefix, file, cam);
  c.cy = readNumber(j, "cy", prefix, file, cam);
  c.skew = j.contains("skew") ? readNumber(j, "skew", prefix, file, cam) : 0.0;
  if (j.contains("model")) {
    const std::string model = readString(j, "model", prefix, file, cam);
    try {
      c.dist.model = lensModelFromString(model);
    } catch (const Error& e) {
      throw Error(e.message(), cameraFileContext(file, cam, prefix + "model"));
    }
  }
  const bool kb = c.dist.model == LensModel::kKannalaBrandt;
  if (j.contains("distortion")) {
    const auto& d = j.at("distortion");
    const std::string dp = prefix + "distortion.";
    const char* terms = kb ? "k1 k2 k3 k4" : "k1 k2 p1 p2 k3 k4 k5 k6";
    if (!d.is_object())
      throw Error(std::string("expected an object of the terms ") + terms + ", got " + typeName(d),
                  cameraFileContext(file, cam, prefix + "distortion"));
    for (auto it = d.begin(); it != d.end(); ++it) {
      static const std::set<std::string> brown = {"k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"},
                                         fisheye = {"k1", "k2", "k3", "k4"};
      if (!(kb ? fisheye : brown).count(it.key()))
        throw Error(std::string("unsupported distortion term (model ") + toString(c.dist.model) + " has " + terms + ")",
                    cameraFileContext(file, cam, dp + it.key()));
    }
    // Absent terms are zero (a lens calibrated with fewer terms).
    auto term = [&](const char* k) { return d.contains(k) ? readNumber(d, k, dp, file, cam) : 0.0; };
    c.dist.k1 = term("k1");
    c.dist.k2 = term("k2");
    c.dist.p1 = term("p1");
    c.dist.p2 = term("p2");
    c.dist.k3 = term("k3");
    c.dist.k4 = term("k4");
    c.dist.k5 = term("k5");
    c.dist.k6 = term("k6");
  }
  try {
    c.validate();
  } catch (const Error& e) {
    throw Error(e.message(), cameraFileContext(file, cam, prefix + e.context().field));
  }
  return c;
}

}  // namespace

const RigCamera* Rig::find(const std::string& name) const {
  for (const auto& c : cameras)
    if (c.camera.name == name) return &c;
  return nullptr;
}

const RigCamera& Rig::at(const std::string& name) const {
  if (const RigCamera* c = find(name)) return *c;
  std::string known;
  for (const auto& c : cameras) known += (known.empty() ? "" : ", ") + c.camera.name;
  throw Error("no such camera in the rig (cameras: " + known + ")", cameraFileContext("", name, ""));
}

RigCamera& Rig::at(const std::string& name) {
  return const_cast<RigCamera&>(static_cast<const Rig&>(*this).at(name));
}

std::vector<std::string> Rig::names() const {
  std::vector<std::string> out;
  for (const auto& c : cameras) out.push_back(c.camera.name);
  return out;
}

void Rig::validate() const {
  if (units != "m") throw Error("units must be \"m\" (got \"" + units + "\")", cameraFileContext("", "", "units"));
  std::set<std::string> seen;
  for (size_t i = 0; i < cameras.size(); ++i) {
    const RigCamera& rc = cameras[i];
    const std::string prefix = "cameras[" + std::to_string(i) + "].";
    if (rc.camera.name.empty()) throw Error("camera name must not be empty", cameraFileContext("", "", prefix + "name"));
    if (!seen.insert(rc.camera.name).second)
      throw Error("duplicate camera name", cameraFileContext("", rc.camera.name, prefix + "name"));
    rc.camera.validate();
    if (rc.role != "witness" && rc.role != kMainRole)
      throw Error("role must be \"witness\" or \"main\" (got \"" + rc.role + "\")",
                  cameraFileContext("", rc.camera.name, prefix + "role"));
    const Eigen::Matrix3d R = rc.T_world_cam.linear();
    if (!R.allFinite() || !rc.T_world_cam.translation().allFinite() ||
        (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() > 1e-6 ||
        R.determinant() <= 0.0)
      throw Error("T_world_cam must be a finite rigid transform with a proper rotation",
                  cameraFileContext("", rc.camera.name, prefix + "T_world_cam"));
  }
}

nlohmann::json cameraToJson(const Camera& c) {
  nlohmann::json j;
  j["name"] = c.name;
  j["width"] = c.width;
  j["height"] = c.height;
  j["fx"] = c.fx;
  j["fy"] = c.fy;
  j["cx"] = c.cx;
  j["cy"] = c.cy;
  j["skew"] = c.skew;
  if (c.dist.isBrown()) {
    j["distortion"] = {{"k1", c.dist.k1}, {"k2", c.dist.k2}, {"p1", c.dist.p1}, {"p2", c.dist.p2}, {"k3", c.dist.k3}};
    // The rational terms only on a lens that has them: other files stay as they were.
    if (c.dist.isRational()) {
      j["distortion"]["k4"] = c.dist.k4;
      j["distortion"]["k5"] = c.dist.k5;
      j["distortion"]["k6"] = c.dist.k6;
    }
    j["model"] = kModel;
  } else {
    j["distortion"] = {{"k1", c.dist.k1}, {"k2", c.dist.k2}, {"k3", c.dist.k3}, {"k4", c.dist.k4}};
    j["model"] = toString(c.dist.model);
  }
  return j;
}

Camera cameraFromJson(const nlohmann::json& j, const std::string& file) {
  return cameraFromJsonAt(j, file, "");
}

nlohmann::json rigToJson(const Rig& rig) {
  nlohmann::json j;
  j["units"] = rig.units;
  j["world_frame"] = rig.world_frame;
  j["pixel_origin"] = kPixelOrigin;
  j["cameras"] = nlohmann::json::array();
  for (const auto& rc : rig.cameras) {
    nlohmann::json c = cameraToJson(rc.camera);
    c["role"] = rc.role;
    c["T_world_cam"] = poseToJson(rc.T_world_cam);
    j["cameras"].push_back(std::move(c));
  }
  return j;
}

Rig rigFromJson(const nlohmann::json& j, const std::string& file) {
  if (!j.is_object())
    throw Error(std::string("expected a rig object {\"units\", \"world_frame\", \"cameras\": [...]}, got ") +
                    typeName(j),
                cameraFileContext(file, "", ""));
  Rig rig;
  if (j.contains("units")) rig.units = readString(j, "units", "", file, "");
  if (rig.units != "m")
    throw Error("units must be \"m\" (previz works in metres), got \"" + rig.units + "\"", cameraFileContext(file, "", "units"));
  if (j.contains("world_frame")) rig.world_frame = readString(j, "world_frame", "", file, "");
  if (j.contains("pixel_origin")) {
    // A file that claims another pixel convention would be misread by half a pixel: refuse.
    const std::string origin = readString(j, "pixel_origin", "", file, "");
    if (origin != kPixelOrigin)
      throw Error("unsupported pixel convention \"" + origin + "\", expected \"" + kPixelOrigin + "\"",
                  cameraFileContext(file, "", "pixel_origin"));
  }
  const auto& cams = require(j, "cameras", "", file, "", "an array of cameras");
  if (!cams.is_array())
    throw Error(std::string("expected an array of cameras, got ") + typeName(cams), cameraFileContext(file, "", "cameras"));
  std::set<std::string> seen;
  for (size_t i = 0; i < cams.size(); ++i) {
    const std::string prefix = "cameras[" + std::to_string(i) + "].";
    RigCamera rc;
    rc.camera = cameraFromJsonAt(cams[i], file, prefix);
    const std::string& name = rc.camera.name;
    if (name.empty()) throw Error("camera name must not be empty", cameraFileContext(file, "", prefix + "name"));
    if (!seen.insert(name).second)
      throw Error("duplicate camera name (names must be unique in a rig)", cameraFileContext(file, name, prefix + "name"));
    if (cams[i].contains("role")) rc.role = readString(cams[i], "role", prefix, file, name);
    if (rc.role != "witness" && rc.role != kMainRole)
      throw Error("role must be \"witness\" or \"main\" (got \"" + rc.role + "\")", cameraFileContext(file, name, prefix + "role"));
    const auto& pose = require(cams[i], "T_world_cam", prefix, file, name,
                               "a pose {\"R\": [[3],[3],[3]], \"t\": [3]}");
    try {
      rc.T_world_cam = poseFromJson(pose, prefix + "T_world_cam");
    } catch (const Error& e) {
      throw Error(e.message(), cameraFileContext(file, name, e.context().field));
    }
    rig.cameras.push_back(std::move(rc));
  }
  return rig;
}

Rig readRig(const std::filesystem::path& path) {
  return rigFromJson(readJsonFile(path), path.string());
}

void writeRig(const Rig& rig, const std::filesystem::path& path) {
  try {
    rig.validate();
  } catch (const Error& e) {
    ErrorContext c = e.context();
    c.file = path.string();
    throw Error(e.message(), c);
  }
  writeJsonAtomic(path, rigToJson(rig));
}

}  // namespace previz
