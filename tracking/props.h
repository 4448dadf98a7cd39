#pragma once
// Props: rigid sets of AprilTags. props.json is the synthetic studio's format (docs/formats.md,
// "Synthetic take" and "Tracking"), extended compatibly with an optional "shape" and, for tags
// fixed to the studio (`previz track camera`), an optional "T_world_prop".
// Tag frame (libapriltag): origin at the tag centre, x right and y down as the tag is read, z into
// the tag; size_m is the edge of the outer black border. Prop frame: the prop's own (box centre for
// generated boxes). T_prop_tag maps tag-frame points to the prop frame (docs/conventions.md).
#include <array>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <nlohmann/json_fwd.hpp>

#include "core/pose.h"

namespace previz::tracking {

struct TagDef {
  std::string family = "tag36h11";
  int id = 0;
  double size_m = 0.12;
  Pose T_prop_tag = Pose::Identity();

  // The four corners in the prop frame in libapriltag's order (p[0..3]: bottom-left,
  // bottom-right, top-right, top-left as the tag is read), i.e. tag-frame points
  // (-s/2, s/2), (s/2, s/2), (s/2, -s/2), (-s/2, -s/2) — also OpenCV's SOLVEPNP_IPPE_SQUARE order.
  std::array<Eigen::Vector3d, 4> cornersInProp() const;
};

struct PropDef {
  int id = 0;
  std::string name;
  std::string shape;                          // "box", "plate" or "" (free-form); informative
  std::optional<Eigen::Vector3d> box_size_m;  // extent of the physical object, if known
  std::vector<TagDef> tags;
  // Tags fixed to the studio (not carried): the prop's known pose in the world. Such a "prop"
  // is not tracked; `previz track camera` solves a camera's pose from it.
  std::optional<Pose> T_world_prop;
};

struct PropSet {
  std::vector<PropDef> props;

  // Throws Error naming the file and the field: duplicate prop ids, duplicate (family, tag id)
  // within or across props (a detection must name one tag), non-positive or non-finite sizes,
  // families libapriltag does not have, a prop without tags. 'file' is used in messages only.
  void validate(const std::string& file = {}) const;
  // Index of the prop that owns (family, id) and the tag index within it; nullopt when none.
  std::optional<std::pair<int, int>> findTag(const std::string& family, int id) const;
  // Families used, in first-use order.
  std::vector<std::string> families() const;
};

// Families libapriltag 3 builds in (tag36h11, tag25h9, tag16h5, tagCircle21h7, tagCircle49h12,
// tagCustom48h12, tagStandard41h12, tagStandard52h13).
const std::vector<std::string>& knownFamilies();
bool isKnownFamily(const std::string& family);

nlohmann::json propsToJson(const PropSet& props);
// Reads and validates; throws Error naming the file, the prop and the field.
PropSet propsFromJson(const nlohmann::json& j, const std::string& file = {});
PropSet readProps(const std::filesystem::path& path);
void writeProps(const PropSet& props, const std::filesystem::path& path);  // atomic

// Generators for common shapes (`previz track prop`).
struct BoxPropOptions {
  int prop_id = 0;
  std::string name = "crate";
  Eigen::Vector3d size_m = Eigen::Vector3d(0.3, 0.3, 0.3);
  std::string family = "tag36h11";
  double tag_size_m = 0.12;
  int first_tag_id = 0;
  // Faces to tag, in tag-id order: "-y", "+x", "+y", "-x", "+z", "-z" (the synthetic studio's
  // crate: -y +x +y -x +z).
  std::vector<std::string> faces = {"-y", "+x", "+y", "-x", "+z"};
  void validate() const;  // throws Error naming the field
};
// One tag centred on each face; on the sides the tag reads upright with the prop's +z up, on
// the top and bottom with +y away from a viewer standing at -y (the synthetic studio's crate).
PropDef makeBoxProp(const BoxPropOptions& options);

struct PlatePropOptions {
  int prop_id = 0;
  std::string name = "plate";
  double width_m = 0.3, height_m = 0.3;  // plate extent along prop x, y
  std::string family = "tag36h11";
  double tag_size_m = 0.12;
  int first_tag_id = 0;
  int rows = 1, cols = 1;                // grid of tags, ids row by row
  void validate() const;
};
// A flat plate in the prop's x-y plane, its printed face towards -z; tags read with x right,
// y down (prop frame = tag frame of a single centred tag).
PropDef makePlateProp(const PlatePropOptions& options);

// Printable sheet of one tag: exact size at 'dpi' (tag + one white cell quiet zone + label).
struct TagSheet {
  std::string png_name, svg_name;
};
// Writes <dir>/<prop name>_<family>_<id>.png (at dpi) and .svg (mm units, exact) for every tag
// of every prop; returns the names written.
std::vector<TagSheet> writeTagSheets(const PropSet& props, const std::filesystem::path& dir,
                                     double dpi = 300);

}  // namespace previz::tracking
