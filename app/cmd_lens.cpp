// previz lens: build a main-camera lens table from calibrations at several focus/zoom encoder
// settings, query it, and hand it to render engines (Unreal .ulens, OpenTrackIO) and
// compositors (ST maps per entry).
#include <filesystem>
#include <iostream>
#include <sstream>

#include <nlohmann/json.hpp>

#include "app/commands.h"
#include "app/options.h"
#include "calib/lens_table.h"
#include "core/camera_io.h"
#include "core/error.h"
#include "core/io.h"
#include "core/rig.h"

namespace previz::app {
namespace {

namespace fs = std::filesystem;

struct LensArgs {
  std::vector<std::string> entries;  // FOCUS,ZOOM,cam.json[,pupil_m]
  std::string table, name, out, ulens, opentrackio, stmaps, at, sensor_mm;
  std::string focus_units = "normalised", zoom_units = "normalised";
  double overscan = 0.0;
  bool json = false;
};

// "a,,b" -> {a, "", b}: every item, empty ones too (--entry mixes numbers and a path, so an
// empty item must reach parseNumber and be refused there, not vanish as splitList drops it).
std::vector<std::string> splitComma(const std::string& text) {
  std::vector<std::string> parts;
  std::stringstream s(text);
  std::string part;
  while (std::getline(s, part, ',')) parts.push_back(part);
  return parts;
}

calib::LensTable buildTable(const LensArgs& a) {
  calib::LensTable table;
  if (!a.table.empty()) {
    table = calib::readLensTable(a.table);
  } else {
    if (a.entries.empty()) throw Error("give --table or at least one --entry", fieldContext("--entry"));
    table.lens_name = a.name.empty() ? "lens" : a.name;
    table.focus_units = a.focus_units;
    table.zoom_units = a.zoom_units;
    for (const std::string& e : a.entries) {
      const auto parts = splitComma(e);
      if (parts.size() != 3 && parts.size() != 4) {
        throw Error("expected FOCUS,ZOOM,camera.json[,entrance_pupil_m] (got '" + e + "')",
                    fieldContext("--entry"));
      }
      calib::LensTableEntry entry;
      entry.focus = parseNumber(parts[0], "--entry");
      entry.zoom = parseNumber(parts[1], "--entry");
      const std::string ext = fs::path(parts[2]).extension().string();
      entry.camera = (ext == ".yaml" || ext == ".yml" || ext == ".xml")
                         ? readOpenCvCamera(parts[2], table.lens_name)
                         : cameraFromJson(readJsonFile(parts[2]), parts[2]);
      if (parts.size() == 4) entry.entrance_pupil_m = parseNumber(parts[3], "--entry");
      table.width = entry.camera.width;
      table.height = entry.camera.height;
      table.entries.push_back(entry);
    }
  }
  if (!a.sensor_mm.empty()) {
    const std::vector<double> mm = parseNumbers(a.sensor_mm, 2, "--sensor-mm", "WIDTH_MM,HEIGHT_MM");
    table.sensor_width_mm = mm[0];
    table.sensor_height_mm = mm[1];
  }
  table.validate();
  return table;
}

int runLens(const LensArgs& a) {
  const calib::LensTable table = buildTable(a);
  nlohmann::json summary = {{"command", "calib lens"},
                            {"lens", table.lens_name},
                            {"entries", table.entries.size()}};
  std::vector<std::string> written;
  if (!a.out.empty()) {
    calib::writeLensTable(a.out, table);
    written.push_back(a.out);
  }
  if (!a.ulens.empty()) {
    calib::writeUnrealLensFile(a.ulens, table);
    written.push_back(a.ulens);
  }
  if (!a.opentrackio.empty()) {
    calib::writeOpenTrackIoLens(a.opentrackio, table);
    written.push_back(a.opentrackio);
  }
  if (!a.stmaps.empty()) {
    for (const fs::path& p : calib::writeLensStMaps(table, a.stmaps, a.overscan)) written.push_back(p.string());
  }
  for (const auto& w : written) std::cerr << "calib lens: wrote " << w << "\n";
  summary["files"] = written;
  if (!a.at.empty()) {
    const std::vector<double> at = parseNumbers(a.at, 2, "--at", "FOCUS,ZOOM");
    const calib::LensTableEntry e = table.at(at[0], at[1]);
    std::cerr << "calib lens: at focus " << e.focus << " zoom " << e.zoom << ": fx " << e.camera.fx
              << " fy " << e.camera.fy << " c (" << e.camera.cx << ", " << e.camera.cy << ") k1 "
              << e.camera.dist.k1 << " entrance pupil " << e.entrance_pupil_m << " m"
              << (e.clamped ? " (clamped to the sampled range)" : "") << "\n";
    summary["at"] = {{"focus", e.focus},
                     {"zoom", e.zoom},
                     {"clamped", e.clamped},
                     {"entrance_pupil_m", e.entrance_pupil_m},
                     {"camera", cameraToJson(e.camera)}};
  }
  if (written.empty() && a.at.empty()) {
    throw Error("nothing to do: give --out, --ulens, --opentrackio, --stmaps or --at");
  }
  if (a.json) std::cout << summary.dump() << "\n";
  return 0;
}

}  // namespace

Runner addLensCommand(CLI::App& calib) {
  auto a = std::make_shared<LensArgs>();
  CLI::App* cmd = calib.add_subcommand(
      "lens", "Lens table over focus/zoom: build, query, export (.ulens, OpenTrackIO), ST maps");
  cmd->add_option("--entry", a->entries,
                  "FOCUS,ZOOM,CAMERA[,entrance_pupil_m]: one calibration (camera JSON or OpenCV YAML; repeat per setting)");
  cmd->add_option("--table", a->table, "Read an existing lens table (previz JSON) instead of --entry");
  cmd->add_option("--name", a->name, "Lens name (with --entry)");
  cmd->add_option("--focus-units", a->focus_units, "Focus encoder units")->capture_default_str();
  cmd->add_option("--zoom-units", a->zoom_units, "Zoom encoder units")->capture_default_str();
  cmd->add_option("--sensor-mm", a->sensor_mm, "Active sensor size WIDTH_MM,HEIGHT_MM (OpenTrackIO needs it)");
  cmd->add_option("--out", a->out, "Lens table JSON to write (lens/<lens>.json in a take)");
  cmd->add_option("--ulens", a->ulens, "Unreal lens file (.ulens JSON) to write");
  cmd->add_option("--opentrackio", a->opentrackio, "OpenTrackIO lens samples (JSON) to write");
  cmd->add_option("--stmaps", a->stmaps, "Folder for undistort/distort ST maps of every entry");
  cmd->add_option("--overscan", a->overscan, "ST map pinhole overscan fraction")->capture_default_str();
  cmd->add_option("--at", a->at, "FOCUS,ZOOM: print the interpolated camera");
  cmd->add_flag("--json", a->json, "JSON summary on stdout");
  return [a]() { return runLens(*a); };
}

}  // namespace previz::app
