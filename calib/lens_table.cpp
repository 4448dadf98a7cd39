#include "calib/lens_table.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <set>
#include <utility>

#include "core/distortion_maps.h"
#include "core/error.h"
#include "core/io.h"
#include "core/rig.h"

namespace previz::calib {
namespace {

using nlohmann::json;

std::string entryField(size_t i, const std::string& field) {
  return "entries[" + std::to_string(i) + "]" + (field.empty() ? "" : "." + field);
}

// ---- interpolation ------------------------------------------------------------------------

// Parameters interpolated between samples, in one flat list so every path treats them alike.
constexpr int kNumParams = 11;
using Params = std::array<double, kNumParams>;

Params toParams(const LensTableEntry& e) {
  const Camera& c = e.camera;
  return {c.fx, c.fy, c.cx, c.cy, c.skew, c.dist.k1, c.dist.k2, c.dist.k3, c.dist.p1, c.dist.p2,
          e.entrance_pupil_m};
}

LensTableEntry fromParams(const LensTable& table, const Params& p, double focus, double zoom) {
  LensTableEntry e;
  e.focus = focus;
  e.zoom = zoom;
  Camera& c = e.camera;
  c.name = table.lens_name;
  c.width = table.width;
  c.height = table.height;
  c.fx = p[0];
  c.fy = p[1];
  c.cx = p[2];
  c.cy = p[3];
  c.skew = p[4];
  c.dist.k1 = p[5];
  c.dist.k2 = p[6];
  c.dist.k3 = p[7];
  c.dist.p1 = p[8];
  c.dist.p2 = p[9];
  e.entrance_pupil_m = p[10];
  return e;
}

// (1 - t) a + t b rather than a + t (b - a): exact at both ends.
Params lerp(const Params& a, const Params& b, double t) {
  Params r;
  for (int i = 0; i < kNumParams; ++i) r[i] = (1.0 - t) * a[i] + t * b[i];
  return r;
}

// Index i of the interval [v[i], v[i+1]] holding x (v sorted, size >= 2, x clamped into range).
size_t bracket(const std::vector<double>& v, double x) {
  const auto it = std::upper_bound(v.begin(), v.end(), x);
  size_t i = it == v.begin() ? 0 : static_cast<size_t>(it - v.begin()) - 1;
  return std::min(i, v.size() - 2);
}

double clampTo(const std::vector<double>& v, double x, bool* clamped) {
  if (x < v.front()) {
    *clamped = true;
    return v.front();
  }
  if (x > v.back()) {
    *clamped = true;
    return v.back();
  }
  return x;
}

// ---- JSON helpers ---------------------------------------------------------------------------

const char* typeName(const json& j) { return j.type_name(); }

const json& member(const json& j, const std::string& key, const std::string& file,
                   const std::string& path) {
  const std::string field = path.empty() ? key : path + "." + key;
  if (!j.is_object())
    throw Error(std::string("expected an object, got ") + typeName(j),
                ErrorContext{file, "", std::nullopt, path.empty() ? "(root)" : path});
  const auto it = j.find(key);
  if (it == j.end()) throw Error("missing field", ErrorContext{file, "", std::nullopt, field});
  return *it;
}

double getNumber(const json& j, const std::string& key, const std::string& file,
                 const std::string& path) {
  const json& v = member(j, key, file, path);
  const std::string field = path.empty() ? key : path + "." + key;
  if (!v.is_number())
    throw Error(std::string("expected a number, got ") + typeName(v),
                ErrorContext{file, "", std::nullopt, field});
  const double x = v.get<double>();
  if (!std::isfinite(x)) throw Error("not finite", ErrorContext{file, "", std::nullopt, field});
  return x;
}

int getInt(const json& j, const std::string& key, const std::string& file,
           const std::string& path) {
  const json& v = member(j, key, file, path);
  const std::string field = path.empty() ? key : path + "." + key;
  if (!v.is_number_integer())
    throw Error(std::string("expected an integer, got ") + typeName(v),
                ErrorContext{file, "", std::nullopt, field});
  return v.get<int>();
}

std::string getString(const json& j, const std::string& key, const std::string& file,
                      const std::string& path) {
  const json& v = member(j, key, file, path);
  const std::string field = path.empty() ? key : path + "." + key;
  if (!v.is_string())
    throw Error(std::string("expected a string, got ") + typeName(v),
                ErrorContext{file, "", std::nullopt, field});
  return v.get<std::string>();
}

const json& getArray(const json& j, const std::string& key, const std::string& file,
                     const std::string& path) {
  const json& v = member(j, key, file, path);
  if (!v.is_array())
    throw Error(std::string("expected an array, got ") + typeName(v),
                ErrorContext{file, "", std::nullopt, path.empty() ? key : path + "." + key});
  return v;
}

std::string idx(const std::string& path, size_t i) { return path + "[" + std::to_string(i) + "]"; }

// Validation errors from a reader carry the file too.
void validateIn(const LensTable& t, const std::string& file) {
  try {
    t.validate();
  } catch (const Error& e) {
    ErrorContext c = e.context();
    c.file = file;
    throw Error(e.message(), c);
  }
}

bool isNormalised(const std::string& units) {
  return units == "normalised" || units == "normalized";
}

}  // namespace

// ---- LensTable ------------------------------------------------------------------------------

void LensTable::validate() const {
  const auto fail = [&](const std::string& msg, const std::string& field) {
    throw Error(msg, ErrorContext{"", lens_name, std::nullopt, field});
  };
  if (lens_name.empty()) fail("lens name is empty", "lens_name");
  if (width <= 0) fail("image width must be > 0", "width");
  if (height <= 0) fail("image height must be > 0", "height");
  if (!(sensor_width_mm >= 0) || !std::isfinite(sensor_width_mm))
    fail("sensor width must be finite and >= 0 (0 = unknown)", "sensor_width_mm");
  if (!(sensor_height_mm >= 0) || !std::isfinite(sensor_height_mm))
    fail("sensor height must be finite and >= 0 (0 = unknown)", "sensor_height_mm");
  if (entries.empty()) fail("the table has no entries", "entries");
  std::map<std::pair<double, double>, size_t> seen;
  for (size_t i = 0; i < entries.size(); ++i) {
    const LensTableEntry& e = entries[i];
    if (!std::isfinite(e.focus)) fail("focus is not finite", entryField(i, "focus"));
    if (!std::isfinite(e.zoom)) fail("zoom is not finite", entryField(i, "zoom"));
    if (!std::isfinite(e.entrance_pupil_m))
      fail("entrance pupil is not finite", entryField(i, "entrance_pupil_m"));
    if (e.camera.width != width)
      fail("image width " + std::to_string(e.camera.width) + " differs from the table's " +
               std::to_string(width),
           entryField(i, "camera.width"));
    if (e.camera.height != height)
      fail("image height " + std::to_string(e.camera.height) + " differs from the table's " +
               std::to_string(height),
           entryField(i, "camera.height"));
    try {
      e.camera.validate();
      // Interpolation, the Unreal and OpenTrackIO lens files carry k1 k2 k3 p1 p2.
      requireBrownConrady(lens_name, e.camera.dist, "a lens table");
      // Nor the rational terms: none of those files has a place for them, and a blend of two
      // rational factors is not the factor of the blended coefficients; refused, never dropped.
      const std::pair<const char*, double> rational[] = {
          {"k4", e.camera.dist.k4}, {"k5", e.camera.dist.k5}, {"k6", e.camera.dist.k6}};
      for (const auto& [term, v] : rational)
        if (v != 0.0) {
          ErrorContext context;
          context.field = std::string("distortion.") + term;
          throw Error("a lens table carries k1 k2 k3 p1 p2 only; this entry has the rational term " +
                          std::string(term) + " = " + std::to_string(v),
                      context);
        }
    } catch (const Error& err) {
      fail(err.message(), entryField(i, "camera." + err.context().field));
    }
    const auto [it, inserted] = seen.emplace(std::make_pair(e.focus, e.zoom), i);
    if (!inserted)
      fail("duplicate (focus, zoom) = (" + std::to_string(e.focus) + ", " +
               std::to_string(e.zoom) + "), also entries[" + std::to_string(it->second) + "]",
           entryField(i, "focus"));
  }
}

LensTableEntry LensTable::at(double focus, double zoom) const {
  validate();
  if (!std::isfinite(focus) || !std::isfinite(zoom))
    throw Error("lens table query must be finite",
                ErrorContext{"", lens_name, std::nullopt, std::isfinite(focus) ? "zoom" : "focus"});
  std::set<double> fs, zs;
  std::map<std::pair<double, double>, const LensTableEntry*> grid;
  for (const auto& e : entries) {
    fs.insert(e.focus);
    zs.insert(e.zoom);
    grid[{e.focus, e.zoom}] = &e;
  }
  const std::vector<double> F(fs.begin(), fs.end()), Z(zs.begin(), zs.end());
  bool clamped = false;
  const double f = clampTo(F, focus, &clamped);
  const double z = clampTo(Z, zoom, &clamped);
  const auto find = [&](double fv, double zv) -> const LensTableEntry* {
    const auto it = grid.find({fv, zv});
    return it == grid.end() ? nullptr : it->second;
  };

  // Nearest sample, distances measured in units of each axis' sampled span.
  const auto nearest = [&]() {
    const double sf = F.size() > 1 ? F.back() - F.front() : 1.0;
    const double sz = Z.size() > 1 ? Z.back() - Z.front() : 1.0;
    const LensTableEntry* best = nullptr;
    double best_d = std::numeric_limits<double>::infinity();
    for (const auto& e : entries) {
      const double d = std::hypot((e.focus - f) / sf, (e.zoom - z) / sz);
      if (d < best_d) best_d = d, best = &e;
    }
    return toParams(*best);
  };

  Params p;
  if (F.size() == 1 && Z.size() == 1) {
    p = toParams(entries.front());
  } else if (F.size() == 1 || Z.size() == 1) {
    // 1-D table: linear along the sampled axis (every sample lies on the line).
    const bool along_zoom = F.size() == 1;
    const std::vector<double>& v = along_zoom ? Z : F;
    const double x = along_zoom ? z : f;
    const size_t i = bracket(v, x);
    const double t = (x - v[i]) / (v[i + 1] - v[i]);
    const LensTableEntry* a = along_zoom ? find(F[0], v[i]) : find(v[i], Z[0]);
    const LensTableEntry* b = along_zoom ? find(F[0], v[i + 1]) : find(v[i + 1], Z[0]);
    p = lerp(toParams(*a), toParams(*b), t);
  } else {
    const size_t i = bracket(F, f), j = bracket(Z, z);
    const double s = (f - F[i]) / (F[i + 1] - F[i]);
    const double t = (z - Z[j]) / (Z[j + 1] - Z[j]);
    const LensTableEntry* c00 = find(F[i], Z[j]);
    const LensTableEntry* c10 = find(F[i + 1], Z[j]);
    const LensTableEntry* c01 = find(F[i], Z[j + 1]);
    const LensTableEntry* c11 = find(F[i + 1], Z[j + 1]);
    if (c00 && c10 && c01 && c11) {
      const Params a = toParams(*c00), b = toParams(*c10), c = toParams(*c01), d = toParams(*c11);
      for (int k = 0; k < kNumParams; ++k)
        p[k] = (1 - s) * (1 - t) * a[k] + s * (1 - t) * b[k] + (1 - s) * t * c[k] + s * t * d[k];
    } else {
      // Incomplete cell: interpolate along the nearer complete edge, else the nearest sample.
      const bool near_f0 = s <= 0.5, near_z0 = t <= 0.5;
      const LensTableEntry* zf0 = near_f0 ? c00 : c10;  // edge at the nearer focus, along zoom
      const LensTableEntry* zf1 = near_f0 ? c01 : c11;
      const LensTableEntry* fz0 = near_z0 ? c00 : c01;  // edge at the nearer zoom, along focus
      const LensTableEntry* fz1 = near_z0 ? c10 : c11;
      const double s_edge = near_f0 ? s : 1 - s, t_edge = near_z0 ? t : 1 - t;
      if (zf0 && zf1 && s_edge <= t_edge)
        p = lerp(toParams(*zf0), toParams(*zf1), t);
      else if (fz0 && fz1)
        p = lerp(toParams(*fz0), toParams(*fz1), s);
      else if (zf0 && zf1)
        p = lerp(toParams(*zf0), toParams(*zf1), t);
      else
        p = nearest();
    }
  }
  LensTableEntry e = fromParams(*this, p, f, z);
  e.clamped = clamped;
  return e;
}

// ---- own JSON -------------------------------------------------------------------------------

json lensTableToJson(const LensTable& table) {
  table.validate();
  json j;
  j["format"] = "previz-lens-table";
  j["version"] = 1;
  j["lens_name"] = table.lens_name;
  j["focus_units"] = table.focus_units;
  j["zoom_units"] = table.zoom_units;
  j["width"] = table.width;
  j["height"] = table.height;
  j["sensor_width_mm"] = table.sensor_width_mm;
  j["sensor_height_mm"] = table.sensor_height_mm;
  j["entries"] = json::array();
  for (const auto& e : table.entries) {
    json je;
    je["focus"] = e.focus;
    je["zoom"] = e.zoom;
    je["entrance_pupil_m"] = e.entrance_pupil_m;
    je["camera"] = cameraToJson(e.camera);
    j["entries"].push_back(std::move(je));
  }
  return j;
}

LensTable lensTableFromJson(const json& j, const std::string& file) {
  if (!j.is_object())
    throw Error(std::string("expected a lens table object, got ") + typeName(j),
                ErrorContext{file, "", std::nullopt, "(root)"});
  const std::string format = getString(j, "format", file, "");
  if (format != "previz-lens-table")
    throw Error("expected \"previz-lens-table\", got \"" + format + "\"",
                ErrorContext{file, "", std::nullopt, "format"});
  const int version = getInt(j, "version", file, "");
  if (version != 1)
    throw Error("unsupported version " + std::to_string(version),
                ErrorContext{file, "", std::nullopt, "version"});
  LensTable t;
  t.lens_name = getString(j, "lens_name", file, "");
  t.focus_units = getString(j, "focus_units", file, "");
  t.zoom_units = getString(j, "zoom_units", file, "");
  t.width = getInt(j, "width", file, "");
  t.height = getInt(j, "height", file, "");
  t.sensor_width_mm = getNumber(j, "sensor_width_mm", file, "");
  t.sensor_height_mm = getNumber(j, "sensor_height_mm", file, "");
  const json& arr = getArray(j, "entries", file, "");
  for (size_t i = 0; i < arr.size(); ++i) {
    const std::string path = idx("entries", i);
    LensTableEntry e;
    e.focus = getNumber(arr[i], "focus", file, path);
    e.zoom = getNumber(arr[i], "zoom", file, path);
    e.entrance_pupil_m = getNumber(arr[i], "entrance_pupil_m", file, path);
    try {
      e.camera = cameraFromJson(member(arr[i], "camera", file, path), file);
    } catch (const Error& err) {
      ErrorContext c = err.context();
      c.file = file;
      c.field = path + ".camera" + (c.field.empty() ? "" : "." + c.field);
      throw Error(err.message(), c);
    }
    t.entries.push_back(std::move(e));
  }
  validateIn(t, file);
  return t;
}

void writeLensTable(const std::filesystem::path& path, const LensTable& table) {
  writeJsonAtomic(path, lensTableToJson(table));
}

LensTable readLensTable(const std::filesystem::path& path) {
  return lensTableFromJson(readJsonFile(path), path.string());
}

// ---- Unreal Engine .ulens -------------------------------------------------------------------
// Follows the LensFile data model of Unreal's CameraCalibrationCore plugin as documented in
//   https://dev.epicgames.com/documentation/en-us/unreal-engine/python-api/class/LensFile?application_version=5.5
//   https://dev.epicgames.com/documentation/en-us/unreal-engine/API/Plugins/CameraCalibrationCore/FFocalLengthInfo
//   https://dev.epicgames.com/documentation/en-us/unreal-engine/python-api/class/LensDistortionState?application_version=5.1
// FxFy "normalized (unitless) ... if focal length is in pixel, normalize using pixel
// dimensions": Fx = fx / width, Fy = fy / height. Image centre "normalized, in the range
// [0, 1]" from the image's top-left corner: Cx = (cx + 0.5) / width (our (0,0) is the centre
// of the top-left pixel, so its left edge is at -0.5). Distortion: the spherical (Brown-
// Conrady) model parameters K1 K2 K3 P1 P2. Nodal offset: Unreal units (cm), Unreal axes
// (X forward), so the entrance pupil along the optical axis is LocationX = 100 * pupil_m.
// The tables (FocalLengthTable, ImageCenterTable, DistortionTable, NodalOffsetTable) hold
// one point per (focus, zoom); the exact key spelling of Epic's exchange file could not be
// checked against a published schema, so the field names below mirror the documented
// structs and a file written here is read back exactly.

json lensTableToUnreal(const LensTable& table) {
  table.validate();
  const double W = table.width, H = table.height;
  json j;
  j["metadata"] = {{"type", "LensFile"},
                   {"version", 1},
                   {"name", table.lens_name},
                   {"lensModel", "SphericalLensModel"},
                   {"focusUnits", table.focus_units},
                   {"zoomUnits", table.zoom_units},
                   {"nodalOffsetUnits", "cm"},
                   {"sensorDimensions",
                    {{"width", table.sensor_width_mm}, {"height", table.sensor_height_mm},
                     {"units", "mm"}}},
                   {"imageDimensions", {{"width", table.width}, {"height", table.height}}}};
  json fl = json::array(), ic = json::array(), dist = json::array(), nodal = json::array();
  for (const auto& e : table.entries) {
    const Camera& c = e.camera;
    fl.push_back({{"focus", e.focus}, {"zoom", e.zoom}, {"Fx", c.fx / W}, {"Fy", c.fy / H},
                  {"skew", c.skew / W}});
    ic.push_back(
        {{"focus", e.focus}, {"zoom", e.zoom}, {"Cx", (c.cx + 0.5) / W}, {"Cy", (c.cy + 0.5) / H}});
    dist.push_back({{"focus", e.focus},
                    {"zoom", e.zoom},
                    {"K1", c.dist.k1},
                    {"K2", c.dist.k2},
                    {"K3", c.dist.k3},
                    {"P1", c.dist.p1},
                    {"P2", c.dist.p2}});
    nodal.push_back({{"focus", e.focus},
                     {"zoom", e.zoom},
                     {"LocationOffset", {100.0 * e.entrance_pupil_m, 0.0, 0.0}},
                     {"RotationOffset", {1.0, 0.0, 0.0, 0.0}}});
  }
  j["data"] = {{"focalLength", fl}, {"imageCenter", ic}, {"distortion", dist},
               {"nodalOffset", nodal}};
  return j;
}

LensTable lensTableFromUnreal(const json& j, const std::string& file) {
  const json& meta = member(j, "metadata", file, "");
  LensTable t;
  t.lens_name = getString(meta, "name", file, "metadata");
  t.focus_units = getString(meta, "focusUnits", file, "metadata");
  t.zoom_units = getString(meta, "zoomUnits", file, "metadata");
  const std::string nodal_units = getString(meta, "nodalOffsetUnits", file, "metadata");
  if (nodal_units != "cm")
    throw Error("only cm is supported, got \"" + nodal_units + "\"",
                ErrorContext{file, "", std::nullopt, "metadata.nodalOffsetUnits"});
  const json& sensor = member(meta, "sensorDimensions", file, "metadata");
  t.sensor_width_mm = getNumber(sensor, "width", file, "metadata.sensorDimensions");
  t.sensor_height_mm = getNumber(sensor, "height", file, "metadata.sensorDimensions");
  const json& image = member(meta, "imageDimensions", file, "metadata");
  t.width = getInt(image, "width", file, "metadata.imageDimensions");
  t.height = getInt(image, "height", file, "metadata.imageDimensions");
  if (t.width <= 0 || t.height <= 0)
    throw Error("image dimensions must be > 0",
                ErrorContext{file, "", std::nullopt, "metadata.imageDimensions"});
  const double W = t.width, H = t.height;

  const json& data = member(j, "data", file, "");
  // Every table must cover the same (focus, zoom) points; entries follow focalLength's order.
  std::map<std::pair<double, double>, size_t> index;
  const json& fl = getArray(data, "focalLength", file, "data");
  for (size_t i = 0; i < fl.size(); ++i) {
    const std::string path = idx("data.focalLength", i);
    LensTableEntry e;
    e.focus = getNumber(fl[i], "focus", file, path);
    e.zoom = getNumber(fl[i], "zoom", file, path);
    e.camera.name = t.lens_name;
    e.camera.width = t.width;
    e.camera.height = t.height;
    e.camera.fx = getNumber(fl[i], "Fx", file, path) * W;
    e.camera.fy = getNumber(fl[i], "Fy", file, path) * H;
    if (fl[i].contains("skew")) e.camera.skew = getNumber(fl[i], "skew", file, path) * W;
    if (!index.emplace(std::make_pair(e.focus, e.zoom), t.entries.size()).second)
      throw Error("duplicate (focus, zoom) point", ErrorContext{file, "", std::nullopt, path});
    t.entries.push_back(std::move(e));
  }
  std::vector<std::array<bool, 3>> have(t.entries.size(), {false, false, false});
  const auto lookup = [&](const json& p, const std::string& path, int table) -> LensTableEntry& {
    const double f = getNumber(p, "focus", file, path), z = getNumber(p, "zoom", file, path);
    const auto it = index.find({f, z});
    if (it == index.end())
      throw Error("point (focus, zoom) = (" + std::to_string(f) + ", " + std::to_string(z) +
                      ") has no focal length",
                  ErrorContext{file, "", std::nullopt, path});
    if (have[it->second][table])
      throw Error("duplicate (focus, zoom) point", ErrorContext{file, "", std::nullopt, path});
    have[it->second][table] = true;
    return t.entries[it->second];
  };
  const json& ic = getArray(data, "imageCenter", file, "data");
  for (size_t i = 0; i < ic.size(); ++i) {
    const std::string path = idx("data.imageCenter", i);
    LensTableEntry& e = lookup(ic[i], path, 0);
    e.camera.cx = getNumber(ic[i], "Cx", file, path) * W - 0.5;
    e.camera.cy = getNumber(ic[i], "Cy", file, path) * H - 0.5;
  }
  const json& dist = getArray(data, "distortion", file, "data");
  for (size_t i = 0; i < dist.size(); ++i) {
    const std::string path = idx("data.distortion", i);
    LensTableEntry& e = lookup(dist[i], path, 1);
    e.camera.dist.k1 = getNumber(dist[i], "K1", file, path);
    e.camera.dist.k2 = getNumber(dist[i], "K2", file, path);
    e.camera.dist.k3 = getNumber(dist[i], "K3", file, path);
    e.camera.dist.p1 = getNumber(dist[i], "P1", file, path);
    e.camera.dist.p2 = getNumber(dist[i], "P2", file, path);
  }
  const json& nodal = getArray(data, "nodalOffset", file, "data");
  for (size_t i = 0; i < nodal.size(); ++i) {
    const std::string path = idx("data.nodalOffset", i);
    LensTableEntry& e = lookup(nodal[i], path, 2);
    const json& loc = getArray(nodal[i], "LocationOffset", file, path);
    if (loc.size() != 3 || !loc[0].is_number())
      throw Error("expected [x, y, z] in cm",
                  ErrorContext{file, "", std::nullopt, path + ".LocationOffset"});
    e.entrance_pupil_m = loc[0].get<double>() / 100.0;
  }
  static const char* kTables[3] = {"data.imageCenter", "data.distortion", "data.nodalOffset"};
  for (size_t i = 0; i < t.entries.size(); ++i)
    for (int k = 0; k < 3; ++k)
      if (!have[i][k])
        throw Error("no point for data.focalLength[" + std::to_string(i) + "]",
                    ErrorContext{file, "", std::nullopt, kTables[k]});
  validateIn(t, file);
  return t;
}

void writeUnrealLensFile(const std::filesystem::path& path, const LensTable& table) {
  writeJsonAtomic(path, lensTableToUnreal(table));
}

LensTable readUnrealLensFile(const std::filesystem::path& path) {
  return lensTableFromUnreal(readJsonFile(path), path.string());
}

// ---- OpenTrackIO ----------------------------------------------------------------------------
// The lens object of an OpenTrackIO sample (SMPTE RIS OSVP), as documented for Unreal's
// LiveLinkOpenTrackIO plugin:
//   https://dev.epicgames.com/documentation/en-us/unreal-engine/python-api/class/LiveLinkOpenTrackIOLens?application_version=5.7
//   https://dev.epicgames.com/documentation/unreal-engine/BlueprintAPI/Utilities/Struct/MakeLiveLinkOpenTrackIOLens
//   https://dev.epicgames.com/documentation/en-us/unreal-engine/python-api/class/LiveLinkOpenTrackIOLens_Encoders?application_version=5.7
// encoders: normalised 0-1 focus/iris/zoom. distortion: list of {model, radial [k1..],
// tangential [p1..]}; our model maps undistorted to distorted, i.e. "Brown-Conrady U-D".
// pinholeFocalLength and projectionOffset / distortionOffset are in millimetres (converted
// through the sensor's physical size / resolution); entrancePupilOffset in metres, positive
// towards the object. OpenTrackIO has one focal length (square pixels); fy goes in the
// lens' "custom" coefficients (documented as producer/consumer-negotiated) as fy in mm so
// non-square calibrations survive. projectionOffset is the principal point minus the
// sensor centre, x right, y up (sign of y assumed: not stated in the pages above).

json lensTableToOpenTrackIo(const LensTable& table) {
  table.validate();
  if (!(table.sensor_width_mm > 0) || !(table.sensor_height_mm > 0))
    throw Error("OpenTrackIO needs the physical sensor size (focal length in mm)",
                ErrorContext{"", table.lens_name, std::nullopt, "sensor_width_mm"});
  if (!isNormalised(table.focus_units) || !isNormalised(table.zoom_units))
    throw Error("OpenTrackIO encoders are normalised 0-1; table units are \"" +
                    table.focus_units + "\" / \"" + table.zoom_units + "\"",
                ErrorContext{"", table.lens_name, std::nullopt,
                             isNormalised(table.focus_units) ? "zoom_units" : "focus_units"});
  const double W = table.width, H = table.height;
  const double mm_x = table.sensor_width_mm / W, mm_y = table.sensor_height_mm / H;
  json samples = json::array();
  for (const auto& e : table.entries) {
    const Camera& c = e.camera;
    json s;
    s["static"] = {
        {"camera",
         {{"activeSensorPhysicalDimensions",
           {{"width", table.sensor_width_mm}, {"height", table.sensor_height_mm}}},
          {"activeSensorResolution", {{"width", table.width}, {"height", table.height}}}}},
        {"lens", {{"model", table.lens_name}}}};
    s["lens"] = {
        {"encoders", {{"focus", e.focus}, {"zoom", e.zoom}}},
        {"pinholeFocalLength", c.fx * mm_x},
        {"custom", {c.fy * mm_y, c.skew * mm_x}},
        {"distortion",
         {{{"model", "Brown-Conrady U-D"},
           {"radial", {c.dist.k1, c.dist.k2, c.dist.k3}},
           {"tangential", {c.dist.p1, c.dist.p2}}}}},
        {"projectionOffset",
         {{"x", (c.cx - 0.5 * (W - 1)) * mm_x}, {"y", (0.5 * (H - 1) - c.cy) * mm_y}}},
        {"distortionOffset", {{"x", 0.0}, {"y", 0.0}}},
        {"entrancePupilOffset", e.entrance_pupil_m}};
    samples.push_back(std::move(s));
  }
  return samples;
}

LensTable lensTableFromOpenTrackIo(const json& j, const std::string& file) {
  if (!j.is_array() || j.empty())
    throw Error("expected a non-empty array of OpenTrackIO samples",
                ErrorContext{file, "", std::nullopt, "(root)"});
  LensTable t;
  for (size_t i = 0; i < j.size(); ++i) {
    const std::string path = idx("", i);
    const std::string sp = path + ".static";
    const json& st = member(j[i], "static", file, path);
    const json& cam = member(st, "camera", file, sp);
    const json& dims = member(cam, "activeSensorPhysicalDimensions", file, sp + ".camera");
    const json& res = member(cam, "activeSensorResolution", file, sp + ".camera");
    const std::string dp = sp + ".camera.activeSensorPhysicalDimensions";
    const std::string rp = sp + ".camera.activeSensorResolution";
    const double sw = getNumber(dims, "width", file, dp), sh = getNumber(dims, "height", file, dp);
    const int w = getInt(res, "width", file, rp), h = getInt(res, "height", file, rp);
    const std::string name = getString(member(st, "lens", file, sp), "model", file, sp + ".lens");
    if (i == 0) {
      t.lens_name = name;
      t.sensor_width_mm = sw;
      t.sensor_height_mm = sh;
      t.width = w;
      t.height = h;
    } else if (name != t.lens_name || sw != t.sensor_width_mm || sh != t.sensor_height_mm ||
               w != t.width || h != t.height) {
      throw Error("static lens/camera data differs from sample [0]",
                  ErrorContext{file, "", std::nullopt, sp});
    }
    if (!(sw > 0) || !(sh > 0) || w <= 0 || h <= 0)
      throw Error("sensor size and resolution must be > 0",
                  ErrorContext{file, "", std::nullopt, sp + ".camera"});
    const double mm_x = sw / w, mm_y = sh / h;
    const std::string lp = path + ".lens";
    const json& lens = member(j[i], "lens", file, path);
    LensTableEntry e;
    const json& enc = member(lens, "encoders", file, lp);
    e.focus = getNumber(enc, "focus", file, lp + ".encoders");
    e.zoom = getNumber(enc, "zoom", file, lp + ".encoders");
    Camera& c = e.camera;
    c.name = name;
    c.width = w;
    c.height = h;
    c.fx = getNumber(lens, "pinholeFocalLength", file, lp) / mm_x;
    c.fy = c.fx;
    if (lens.contains("custom")) {
      const json& custom = getArray(lens, "custom", file, lp);
      if (custom.size() >= 1) c.fy = getNumber(json{{"v", custom[0]}}, "v", file, lp + ".custom[0]") / mm_y;
      if (custom.size() >= 2) c.skew = getNumber(json{{"v", custom[1]}}, "v", file, lp + ".custom[1]") / mm_x;
    }
    const json& po = member(lens, "projectionOffset", file, lp);
    c.cx = getNumber(po, "x", file, lp + ".projectionOffset") / mm_x + 0.5 * (w - 1);
    c.cy = 0.5 * (h - 1) - getNumber(po, "y", file, lp + ".projectionOffset") / mm_y;
    if (lens.contains("distortionOffset")) {
      const json& dof = lens["distortionOffset"];
      const double dx = getNumber(dof, "x", file, lp + ".distortionOffset");
      const double dy = getNumber(dof, "y", file, lp + ".distortionOffset");
      if (dx != 0 || dy != 0)
        throw Error("a distortion centre apart from the projection centre is not supported",
                    ErrorContext{file, "", std::nullopt, lp + ".distortionOffset"});
    }
    const json& dl = getArray(lens, "distortion", file, lp);
    if (dl.size() > 1)
      throw Error("only one distortion model per sample is supported",
                  ErrorContext{file, "", std::nullopt, lp + ".distortion"});
    if (dl.size() == 1) {
      const std::string dp2 = lp + ".distortion[0]";
      if (dl[0].contains("model")) {
        const std::string model = getString(dl[0], "model", file, dp2);
        if (model != "Brown-Conrady U-D")
          throw Error("model \"" + model + "\" is not supported (need \"Brown-Conrady U-D\")",
                      ErrorContext{file, "", std::nullopt, dp2 + ".model"});
      } else {
        // The documented default is D-U, which our forward model is not.
        throw Error("missing model; the default \"Brown-Conrady D-U\" is not supported",
                    ErrorContext{file, "", std::nullopt, dp2 + ".model"});
      }
      const json& radial = getArray(dl[0], "radial", file, dp2);
      if (radial.size() > 3)
        throw Error("more than 3 radial coefficients", ErrorContext{file, "", std::nullopt, dp2 + ".radial"});
      double* rk[3] = {&c.dist.k1, &c.dist.k2, &c.dist.k3};
      for (size_t k = 0; k < radial.size(); ++k)
        *rk[k] = getNumber(json{{"v", radial[k]}}, "v", file, dp2 + ".radial[" + std::to_string(k) + "]");
      if (dl[0].contains("tangential")) {
        const json& tan = getArray(dl[0], "tangential", file, dp2);
        if (tan.size() > 2)
          throw Error("more than 2 tangential coefficients",
                      ErrorContext{file, "", std::nullopt, dp2 + ".tangential"});
        double* tk[2] = {&c.dist.p1, &c.dist.p2};
        for (size_t k = 0; k < tan.size(); ++k)
          *tk[k] = getNumber(json{{"v", tan[k]}}, "v", file, dp2 + ".tangential[" + std::to_string(k) + "]");
      }
    }
    e.entrance_pupil_m = getNumber(lens, "entrancePupilOffset", file, lp);
    t.entries.push_back(std::move(e));
  }
  t.focus_units = "normalised";
  t.zoom_units = "normalised";
  validateIn(t, file);
  return t;
}

void writeOpenTrackIoLens(const std::filesystem::path& path, const LensTable& table) {
  writeJsonAtomic(path, lensTableToOpenTrackIo(table));
}

LensTable readOpenTrackIoLens(const std::filesystem::path& path) {
  return lensTableFromOpenTrackIo(readJsonFile(path), path.string());
}

// ---- ST maps --------------------------------------------------------------------------------

std::string lensStMapStem(const LensTable& table, const LensTableEntry& entry) {
  // %.6g keeps encoder values readable; validate() rejects duplicates, but two settings
  // closer than 6 significant digits would collide, so writeLensStMaps checks for that.
  char buf[64];
  std::snprintf(buf, sizeof buf, "_f%.6g_z%.6g", entry.focus, entry.zoom);
  return table.lens_name + buf;
}

std::vector<std::filesystem::path> writeLensStMaps(const LensTable& table,
                                                   const std::filesystem::path& dir,
                                                   double overscan) {
  table.validate();
  std::set<std::string> stems;
  for (size_t i = 0; i < table.entries.size(); ++i)
    if (!stems.insert(lensStMapStem(table, table.entries[i])).second)
      throw Error("ST map name " + lensStMapStem(table, table.entries[i]) +
                      " collides with another entry's (focus/zoom equal to 6 digits)",
                  ErrorContext{dir.string(), table.lens_name, std::nullopt, entryField(i, "focus")});
  std::vector<std::filesystem::path> written;
  for (const auto& e : table.entries) {
    const Camera& lens = e.camera;
    const Camera pinhole = idealPinhole(lens, overscan);
    const std::string stem = lensStMapStem(table, e);
    const cv::Size lens_size(lens.width, lens.height), pinhole_size(pinhole.width, pinhole.height);
    const auto undistort_path = dir / (stem + "_undistort.exr");
    writeStMap(undistort_path, makeUndistortMap(lens, pinhole), lens_size,
               "undistort " + stem + ": output = ideal pinhole, source = lens image");
    const auto distort_path = dir / (stem + "_distort.exr");
    writeStMap(distort_path, makeDistortMap(lens, pinhole).map, pinhole_size,
               "distort " + stem + ": output = lens image, source = ideal pinhole render");
    written.push_back(undistort_path);
    written.push_back(distort_path);
  }
  return written;
}

}  // namespace previz::calib
