#pragma once
// Lens table for the main camera: calibrations at several (focus, zoom) encoder settings,
// interpolated in between, stored as our own JSON (lens/<lens>.json) and exchanged with
// Unreal Engine (LensFile-style .ulens JSON) and OpenTrackIO (one lens sample per state).
#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/camera.h"

namespace previz::calib {

struct LensTableEntry {
  double focus = 0;  // encoder value in LensTable::focus_units
  double zoom = 0;   // encoder value in LensTable::zoom_units
  Camera camera;     // intrinsics at this lens state (pixels, table image size)
  // No-parallax point (entrance pupil) offset along the optical axis from the sensor-side
  // reference, metres, positive towards the scene.
  double entrance_pupil_m = 0;
  // Set only by LensTable::at(): the query lay outside the sampled focus/zoom range and was
  // clamped to its edge.
  bool clamped = false;
};

struct LensTable {
  std::string lens_name;
  std::string focus_units = "normalised";  // "normalised" (0-1 encoder) or a physical unit
  std::string zoom_units = "normalised";
  int width = 0;
  int height = 0;
  // Physical active sensor size (mm); 0 = unknown. Needed only by the OpenTrackIO export,
  // whose focal length and offsets are in millimetres.
  double sensor_width_mm = 0;
  double sensor_height_mm = 0;
  std::vector<LensTableEntry> entries;

  // Throws Error naming the field and entry: image size > 0 and equal for every entry, valid
  // cameras, finite focus/zoom/pupil, no duplicate (focus, zoom), at least one entry.
  void validate() const;

  // The lens state at (focus, zoom). The entries lie on a (possibly incomplete) focus x zoom
  // grid: bilinear in the enclosing cell when its four corners exist, linear along the line
  // when the table is 1-D in focus or zoom; a cell with missing corners falls back to the
  // edge of the cell nearest the query that has both ends, else to the nearest sample.
  // Outside the sampled range the query is clamped to it and the result has clamped = true.
  // Interpolates fx, fy, cx, cy, skew, k1..k3, p1, p2 and the entrance pupil. Exact at samples.
  LensTableEntry at(double focus, double zoom) const;
};

// Own format (docs: lens/<lens>.json). Readers throw Error naming the file and field.
nlohmann::json lensTableToJson(const LensTable& table);
LensTable lensTableFromJson(const nlohmann::json& j, const std::string& file = {});
void writeLensTable(const std::filesystem::path& path, const LensTable& table);  // atomic
LensTable readLensTable(const std::filesystem::path& path);

// Unreal Engine lens file exchange JSON (.ulens): metadata (lens name, sensor and image
// dimensions) and "data" tables of focus/zoom points for focal length (Fx, Fy normalised by
// image width/height), image centre (Cx, Cy in [0,1] of the image, pixel-edge origin),
// spherical distortion (K1 K2 K3 P1 P2) and nodal offset (cm, Unreal axes: X forward).
nlohmann::json lensTableToUnreal(const LensTable& table);
LensTable lensTableFromUnreal(const nlohmann::json& j, const std::string& file = {});
void writeUnrealLensFile(const std::filesystem::path& path, const LensTable& table);
LensTable readUnrealLensFile(const std::filesystem::path& path);

// OpenTrackIO: a JSON array of samples, one per lens state, each with "static" (camera
// sensor size and resolution, lens model) and "lens" (encoders, pinholeFocalLength mm,
// distortion [{model, radial, tangential}], projectionOffset mm, entrancePupilOffset m).
// Needs sensor_width_mm/height_mm and normalised focus/zoom units (encoders are 0-1).
nlohmann::json lensTableToOpenTrackIo(const LensTable& table);
LensTable lensTableFromOpenTrackIo(const nlohmann::json& j, const std::string& file = {});
void writeOpenTrackIoLens(const std::filesystem::path& path, const LensTable& table);
LensTable readOpenTrackIoLens(const std::filesystem::path& path);

// ST maps per entry: <dir>/<lens>_f<focus>_z<zoom>_{undistort,distort}.exr, the pinhole being
// idealPinhole(entry camera, overscan). Returns the files written (undistort, distort, ...).
std::vector<std::filesystem::path> writeLensStMaps(const LensTable& table,
                                                   const std::filesystem::path& dir,
                                                   double overscan);
// File stem used above for one entry, e.g. "cooke_f0.25_z0.5".
std::string lensStMapStem(const LensTable& table, const LensTableEntry& entry);

}  // namespace previz::calib
