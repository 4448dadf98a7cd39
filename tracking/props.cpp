// props.json: reading with errors that name the file, the prop and the field; generators for
// boxes and plates; printable tag sheets drawn from libapriltag's own family bitmaps.
#include "tracking/props.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <set>
#include <sstream>

#include <apriltag/apriltag.h>
#include <apriltag/common/image_u8.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>

#include "core/box_tag.h"
#include "core/error.h"
#include "core/io.h"
#include "tracking/detail/families.h"

namespace previz::tracking {

namespace {

ErrorContext ctx(const std::string& file, const std::string& field) {
  ErrorContext c;
  c.file = file;
  c.field = field;
  return c;
}

std::string propLabel(const PropDef& p) { return "prop " + std::to_string(p.id) + " ('" + p.name + "')"; }

const nlohmann::json& need(const nlohmann::json& j, const std::string& key, const std::string& field,
                           const std::string& file, const std::string& expected) {
  if (!j.is_object() || !j.contains(key))
    throw Error("missing field, expected " + expected, ctx(file, field));
  return j.at(key);
}

int needInt(const nlohmann::json& j, const std::string& key, const std::string& field,
            const std::string& file) {
  const auto& v = need(j, key, field, file, "an integer");
  if (!v.is_number_integer())
    throw Error(std::string("expected an integer, got ") + v.type_name(), ctx(file, field));
  return v.get<int>();
}

double needNumber(const nlohmann::json& j, const std::string& key, const std::string& field,
                  const std::string& file) {
  const auto& v = need(j, key, field, file, "a number");
  if (!v.is_number())
    throw Error(std::string("expected a number, got ") + v.type_name(), ctx(file, field));
  return v.get<double>();
}

std::string needString(const nlohmann::json& j, const std::string& key, const std::string& field,
                       const std::string& file) {
  const auto& v = need(j, key, field, file, "a string");
  if (!v.is_string())
    throw Error(std::string("expected a string, got ") + v.type_name(), ctx(file, field));
  return v.get<std::string>();
}

Pose poseField(const nlohmann::json& j, const std::string& field, const std::string& file) {
  try {
    return poseFromJson(j, field);
  } catch (const Error& e) {
    throw Error(e.message(), ctx(file, e.context().field.empty() ? field : e.context().field));
  }
}

std::optional<Eigen::Vector3d> faceNormal(const std::string& face) {
  static const std::map<std::string, Eigen::Vector3d> kFaces = {
      {"+x", Eigen::Vector3d::UnitX()},  {"-x", -Eigen::Vector3d::UnitX()},
      {"+y", Eigen::Vector3d::UnitY()},  {"-y", -Eigen::Vector3d::UnitY()},
      {"+z", Eigen::Vector3d::UnitZ()},  {"-z", -Eigen::Vector3d::UnitZ()}};
  const auto it = kFaces.find(face);
  if (it == kFaces.end()) return std::nullopt;
  return it->second;
}

}  // namespace

std::array<Eigen::Vector3d, 4> TagDef::cornersInProp() const {
  const double h = 0.5 * size_m;
  return {T_prop_tag * Eigen::Vector3d(-h, h, 0), T_prop_tag * Eigen::Vector3d(h, h, 0),
          T_prop_tag * Eigen::Vector3d(h, -h, 0), T_prop_tag * Eigen::Vector3d(-h, -h, 0)};
}

void PropSet::validate(const std::string& file) const {
  std::map<int, std::string> prop_ids;
  std::map<std::pair<std::string, int>, std::string> owners;
  for (size_t i = 0; i < props.size(); ++i) {
    const PropDef& p = props[i];
    const std::string at = "props[" + std::to_string(i) + "]";
    if (!prop_ids.emplace(p.id, p.name).second)
      throw Error("duplicate prop id " + std::to_string(p.id) + " ('" + prop_ids[p.id] + "' and '" +
                      p.name + "')",
                  ctx(file, at + ".id"));
    if (p.tags.empty()) throw Error(propLabel(p) + " has no tags", ctx(file, at + ".tags"));
    if (p.box_size_m && (!p.box_size_m->allFinite() || (p.box_size_m->array() < 0).any()))
      throw Error(propLabel(p) + ": box_size_m must be finite and >= 0", ctx(file, at + ".box_size_m"));
    for (size_t k = 0; k < p.tags.size(); ++k) {
      const TagDef& t = p.tags[k];
      const std::string tat = at + ".tags[" + std::to_string(k) + "]";
      if (!isKnownFamily(t.family)) {
        std::string known;
        for (const auto& f : knownFamilies()) known += (known.empty() ? "" : ", ") + f;
        throw Error(propLabel(p) + ": unknown AprilTag family '" + t.family + "' (libapriltag has " +
                        known + ")",
                    ctx(file, tat + ".family"));
      }
      if (!(std::isfinite(t.size_m) && t.size_m > 0)) {
        std::ostringstream s;
        s << propLabel(p) << ": tag " << t.id << ": size_m must be > 0 (got " << t.size_m << ")";
        throw Error(s.str(), ctx(file, tat + ".size_m"));
      }
      if (t.id < 0) throw Error(propLabel(p) + ": tag id must be >= 0", ctx(file, tat + ".id"));
      const auto key = std::make_pair(t.family, t.id);
      const auto [it, fresh] = owners.emplace(key, propLabel(p));
      if (!fresh)
        throw Error("duplicate tag " + t.family + " id " + std::to_string(t.id) + " in " + it->second +
                        " and " + propLabel(p) + ": a detection must name one tag",
                    ctx(file, tat + ".id"));
    }
  }
}

std::optional<std::pair<int, int>> PropSet::findTag(const std::string& family, int id) const {
  for (size_t p = 0; p < props.size(); ++p)
    for (size_t k = 0; k < props[p].tags.size(); ++k)
      if (props[p].tags[k].id == id && props[p].tags[k].family == family)
        return std::make_pair(static_cast<int>(p), static_cast<int>(k));
  return std::nullopt;
}

std::vector<std::string> PropSet::families() const {
  std::vector<std::string> out;
  for (const PropDef& p : props)
    for (const TagDef& t : p.tags)
      if (std::find(out.begin(), out.end(), t.family) == out.end()) out.push_back(t.family);
  return out;
}

nlohmann::json propsToJson(const PropSet& set) {
  nlohmann::json list = nlohmann::json::array();
  for (const PropDef& p : set.props) {
    nlohmann::json tags = nlohmann::json::array();
    for (const TagDef& t : p.tags)
      tags.push_back({{"family", t.family}, {"id", t.id}, {"size_m", t.size_m},
                      {"T_prop_tag", poseToJson(t.T_prop_tag)}});
    nlohmann::json jp = {{"id", p.id}, {"name", p.name}};
    if (!p.shape.empty()) jp["shape"] = p.shape;
    if (p.box_size_m) jp["box_size_m"] = {p.box_size_m->x(), p.box_size_m->y(), p.box_size_m->z()};
    jp["tags"] = tags;
    if (p.T_world_prop) jp["T_world_prop"] = poseToJson(*p.T_world_prop);
    list.push_back(jp);
  }
  return {{"units", "m"},
          {"prop_frame", "origin at the box centre, axes along the box edges"},
          {"tag_frame",
           "origin at the tag centre, x right and y down as the tag is read, z into the tag; "
           "size_m is the edge of the outer black border (libapriltag tagsize)"},
          {"props", list}};
}

PropSet propsFromJson(const nlohmann::json& j, const std::string& file) {
  if (!j.is_object()) throw Error("expected a props object {\"props\": [...]}", ctx(file, "props"));
  if (j.contains("units") && (!j["units"].is_string() || j["units"] != "m"))
    throw Error("units must be \"m\"", ctx(file, "units"));
  const auto& list = need(j, "props", "props", file, "an array of props");
  if (!list.is_array()) throw Error("expected an array of props", ctx(file, "props"));
  PropSet set;
  for (size_t i = 0; i < list.size(); ++i) {
    const std::string at = "props[" + std::to_string(i) + "]";
    const auto& jp = list[i];
    if (!jp.is_object()) throw Error("expected a prop object", ctx(file, at));
    PropDef p;
    p.id = needInt(jp, "id", at + ".id", file);
    p.name = needString(jp, "name", at + ".name", file);
    if (jp.contains("shape")) p.shape = needString(jp, "shape", at + ".shape", file);
    if (jp.contains("box_size_m")) {
      const auto& b = jp["box_size_m"];
      if (!b.is_array() || b.size() != 3 || !b[0].is_number() || !b[1].is_number() || !b[2].is_number())
        throw Error("expected [x, y, z] in metres", ctx(file, at + ".box_size_m"));
      p.box_size_m = Eigen::Vector3d(b[0].get<double>(), b[1].get<double>(), b[2].get<double>());
    }
    if (jp.contains("T_world_prop")) p.T_world_prop = poseField(jp["T_world_prop"], at + ".T_world_prop", file);
    const auto& tags = need(jp, "tags", at + ".tags", file, "an array of tags");
    if (!tags.is_array()) throw Error("expected an array of tags", ctx(file, at + ".tags"));
    for (size_t k = 0; k < tags.size(); ++k) {
      const std::string tat = at + ".tags[" + std::to_string(k) + "]";
      TagDef t;
      t.family = needString(tags[k], "family", tat + ".family", file);
      t.id = needInt(tags[k], "id", tat + ".id", file);
      t.size_m = needNumber(tags[k], "size_m", tat + ".size_m", file);
      t.T_prop_tag = poseField(need(tags[k], "T_prop_tag", tat + ".T_prop_tag", file, "a pose {R, t}"),
                               tat + ".T_prop_tag", file);
      p.tags.push_back(t);
    }
    set.props.push_back(std::move(p));
  }
  set.validate(file);
  return set;
}

PropSet readProps(const std::filesystem::path& path) {
  return propsFromJson(readJsonFile(path), path.string());
}

void writeProps(const PropSet& props, const std::filesystem::path& path) {
  props.validate(path.string());
  writeJsonAtomic(path, propsToJson(props));
}

void BoxPropOptions::validate() const {
  auto bad = [](const std::string& field, const std::string& what) {
    ErrorContext c;
    c.field = field;
    throw Error("track prop: " + what, c);
  };
  if (!size_m.allFinite() || (size_m.array() <= 0).any()) bad("size_m", "box sizes must be > 0");
  if (!(tag_size_m > 0)) bad("tag_size_m", "tag size must be > 0 (got " + std::to_string(tag_size_m) + ")");
  if (!isKnownFamily(family)) bad("family", "unknown AprilTag family '" + family + "'");
  if (first_tag_id < 0) bad("first_tag_id", "must be >= 0");
  if (faces.empty()) bad("faces", "at least one face");
  std::set<std::string> seen;
  for (const std::string& f : faces) {
    const auto n = faceNormal(f);
    if (!n) bad("faces", "unknown face '" + f + "' (one of +x -x +y -y +z -z)");
    if (!seen.insert(f).second) bad("faces", "face '" + f + "' twice");
    // The tag must fit on its face.
    Eigen::Vector2d extent;
    int axis = 0;
    n->cwiseAbs().maxCoeff(&axis);
    extent = axis == 0 ? Eigen::Vector2d(size_m.y(), size_m.z())
                       : axis == 1 ? Eigen::Vector2d(size_m.x(), size_m.z()) : Eigen::Vector2d(size_m.x(), size_m.y());
    if (tag_size_m > extent.minCoeff() + 1e-12)
      bad("tag_size_m", "a " + std::to_string(tag_size_m) + " m tag does not fit on face " + f);
  }
}

PropDef makeBoxProp(const BoxPropOptions& o) {
  o.validate();
  PropDef p;
  p.id = o.prop_id;
  p.name = o.name;
  p.shape = "box";
  p.box_size_m = o.size_m;
  const Eigen::Vector3d half = 0.5 * o.size_m;
  int id = o.first_tag_id;
  for (const std::string& f : o.faces) {
    TagDef t;
    t.family = o.family;
    t.id = id++;
    t.size_m = o.tag_size_m;
    t.T_prop_tag = boxFaceTagPose(*faceNormal(f), half);
    p.tags.push_back(t);
  }
  return p;
}

void PlatePropOptions::validate() const {
  auto bad = [](const std::string& field, const std::string& what) {
    ErrorContext c;
    c.field = field;
    throw Error("track prop: " + what, c);
  };
  if (!(width_m > 0) || !(height_m > 0)) bad("width_m", "plate sizes must be > 0");
  if (!(tag_size_m > 0)) bad("tag_size_m", "tag size must be > 0 (got " + std::to_string(tag_size_m) + ")");
  if (!isKnownFamily(family)) bad("family", "unknown AprilTag family '" + family + "'");
  if (rows < 1 || cols < 1) bad("rows", "rows and cols must be >= 1");
  if (first_tag_id < 0) bad("first_tag_id", "must be >= 0");
  if (cols * tag_size_m > width_m + 1e-12 || rows * tag_size_m > height_m + 1e-12)
    bad("tag_size_m", "the tags do not fit on the plate");
}

PropDef makePlateProp(const PlatePropOptions& o) {
  o.validate();
  PropDef p;
  p.id = o.prop_id;
  p.name = o.name;
  p.shape = "plate";
  p.box_size_m = Eigen::Vector3d(o.width_m, o.height_m, 0.0);
  // Tags centred in equal cells of the plate.
  const double cw = o.width_m / o.cols, ch = o.height_m / o.rows;
  int id = o.first_tag_id;
  for (int r = 0; r < o.rows; ++r)
    for (int c = 0; c < o.cols; ++c) {
      TagDef t;
      t.family = o.family;
      t.id = id++;
      t.size_m = o.tag_size_m;
      t.T_prop_tag.translation() = Eigen::Vector3d(-0.5 * o.width_m + (c + 0.5) * cw,
                                                   -0.5 * o.height_m + (r + 0.5) * ch, 0.0);
      p.tags.push_back(t);
    }
  return p;
}

std::vector<TagSheet> writeTagSheets(const PropSet& props, const std::filesystem::path& dir, double dpi) {
  if (!(dpi > 0)) {
    ErrorContext c;
    c.field = "dpi";
    throw Error("track prop: dpi must be > 0", c);
  }
  std::vector<TagSheet> out;
  for (const PropDef& p : props.props)
    for (const TagDef& t : p.tags) {
      detail::FamilyPtr family = detail::createFamily(t.family);
      if (t.id >= static_cast<int>(family->ncodes))
        throw Error(propLabel(p) + ": tag id " + std::to_string(t.id) + " exceeds family " + t.family +
                    " (" + std::to_string(family->ncodes) + " codes)");
      image_u8_t* bitmap = apriltag_to_image(family.get(), t.id);
      const int total = family->total_width, border = family->width_at_border;
      // The bitmap's outer ring (total - border cells on each side) is the white quiet zone.
      const double cell_m = t.size_m / border;
      const double sheet_m = cell_m * (total + 2) + 0.02;  // one extra white cell + label strip
      const double px_per_m = dpi / 0.0254;
      const int side = static_cast<int>(std::lround(sheet_m * px_per_m));
      cv::Mat img(side + static_cast<int>(std::lround(0.02 * px_per_m)), side, CV_8UC1, cv::Scalar(255));
      const double origin_m = cell_m;  // left/top offset of the bitmap on the sheet
      std::ostringstream svg;
      const double sheet_mm = sheet_m * 1000, height_mm = sheet_mm + 20;
      svg << "<?xml version=\"1.0\"?>\n<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << sheet_mm
          << "mm\" height=\"" << height_mm << "mm\" viewBox=\"0 0 " << sheet_mm << " " << height_mm
          << "\">\n<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n";
      for (int y = 0; y < total; ++y)
        for (int x = 0; x < total; ++x) {
          if (bitmap->buf[y * bitmap->stride + x]) continue;  // white cell
          const double x0 = origin_m + x * cell_m, y0 = origin_m + y * cell_m;
          const int u0 = static_cast<int>(std::lround(x0 * px_per_m)), v0 = static_cast<int>(std::lround(y0 * px_per_m));
          const int u1 = static_cast<int>(std::lround((x0 + cell_m) * px_per_m)),
                    v1 = static_cast<int>(std::lround((y0 + cell_m) * px_per_m));
          cv::rectangle(img, cv::Point(u0, v0), cv::Point(u1 - 1, v1 - 1), cv::Scalar(0), cv::FILLED);
          svg << "<rect x=\"" << x0 * 1000 << "\" y=\"" << y0 * 1000 << "\" width=\"" << cell_m * 1000
              << "\" height=\"" << cell_m * 1000 << "\" fill=\"black\"/>\n";
        }
      image_u8_destroy(bitmap);
      char label[256];
      std::snprintf(label, sizeof(label), "%s  %s id %d  black border %.1f mm  (prop %d)", p.name.c_str(),
                    t.family.c_str(), t.id, t.size_m * 1000, p.id);
      const double label_y_m = origin_m + total * cell_m + 0.012;
      cv::putText(img, label, cv::Point(static_cast<int>(origin_m * px_per_m), static_cast<int>(label_y_m * px_per_m)),
                  cv::FONT_HERSHEY_SIMPLEX, std::max(0.3, 0.004 * px_per_m / 30.0), cv::Scalar(0),
                  std::max(1, static_cast<int>(px_per_m / 4000)));
      svg << "<text x=\"" << origin_m * 1000 << "\" y=\"" << label_y_m * 1000
          << "\" font-family=\"sans-serif\" font-size=\"4\">" << label << "</text>\n</svg>\n";
      char stem[256];
      std::snprintf(stem, sizeof(stem), "%s_%s_%d", p.name.c_str(), t.family.c_str(), t.id);
      TagSheet sheet{std::string(stem) + ".png", std::string(stem) + ".svg"};
      writeImageAtomic(dir / sheet.png_name, img);
      writeFileAtomic(dir / sheet.svg_name, svg.str());
      out.push_back(sheet);
    }
  return out;
}

}  // namespace previz::tracking
