// Collected output for post (see collect.h).
#include "batch/collect.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <set>
#include <sstream>

#include <opencv2/imgproc.hpp>

#include "batch/chan.h"
#include "batch/ledger.h"
#include "core/error.h"
#include "core/io.h"
#include "core/mesh.h"
#include "core/names.h"
#include "core/pose_lines.h"
#include "core/rig.h"
#include "core/text.h"
#include "core/units.h"

namespace previz::batch {
namespace fs = std::filesystem;

namespace {

void copyAtomic(const fs::path& from, const fs::path& to) { writeFileAtomic(to, readTextFile(from)); }

std::string fixed(double v, int digits) {
  char text[64];
  std::snprintf(text, sizeof(text), "%.*f", digits, v);
  return text;
}

nlohmann::json keysJson(const std::vector<ChanKey>& keys, const std::vector<std::pair<int, Pose>>& poses,
                        const char* pose_name) {
  nlohmann::json frames = nlohmann::json::array();
  for (size_t i = 0; i < keys.size(); ++i)
    frames.push_back({{"frame", keys[i].frame},
                      {"translate", {keys[i].translate.x(), keys[i].translate.y(), keys[i].translate.z()}},
                      {"rotate_deg", {keys[i].rotate_deg.x(), keys[i].rotate_deg.y(), keys[i].rotate_deg.z()}},
                      {pose_name, poseToJson(poses[i].second)}});
  return frames;
}

const char* kYUpNote =
    "y-up frame for Maya/Houdini/Nuke: (x, y, z) = (x, z, -y) of previz's z-up world (floor y = 0)";

// One row of thumbnails per contact_columns frames: the depth previews, frame number below.
cv::Mat contactSheet(const std::vector<std::pair<int, fs::path>>& previews, const CollectOptions& o) {
  const int w = o.thumb_width_px;
  int h = w * 9 / 16;
  std::vector<cv::Mat> thumbs;
  for (const auto& [frame, path] : previews) {
    cv::Mat image;
    std::error_code ec;
    if (!path.empty() && fs::is_regular_file(path, ec)) image = readImage(path, 1 /* colour */);
    if (!image.empty() && thumbs.empty()) h = std::max(1, static_cast<int>(std::lround(double(w) * image.rows / image.cols)));
    cv::Mat t(h, w, CV_8UC3, cv::Scalar(40, 40, 40));
    if (!image.empty()) cv::resize(image, t, cv::Size(w, h), 0, 0, cv::INTER_AREA);
    thumbs.push_back(t);
  }
  const int label = 22;
  const int n = static_cast<int>(thumbs.size());
  const int cols = std::max(1, std::min(o.contact_columns, n));
  const int rows = std::max(1, (n + cols - 1) / cols);
  cv::Mat sheet((h + label) * rows, w * cols, CV_8UC3, cv::Scalar(16, 16, 16));
  for (int i = 0; i < n; ++i) {
    const int x = (i % cols) * w, y = (i / cols) * (h + label);
    cv::resize(thumbs[i], thumbs[i], cv::Size(w, h));
    thumbs[i].copyTo(sheet(cv::Rect(x, y, w, h)));
    cv::putText(sheet, "frame " + std::to_string(previews[i].first + o.frame_offset),
                cv::Point(x + 6, y + h + 16), cv::FONT_HERSHEY_SIMPLEX, 0.45, cv::Scalar(230, 230, 230), 1,
                cv::LINE_AA);
  }
  return sheet;
}

}  // namespace

void CollectOptions::validate() const {
  ErrorContext c;
  if (out.empty()) {
    c.field = "--out";
    throw Error("batch collect: an output folder is needed", c);
  }
  if (contact_columns < 1 || thumb_width_px < 16) {
    c.field = "contact_columns";
    throw Error("batch collect: contact sheet needs >= 1 column and thumbnails >= 16 px wide", c);
  }
  if (frame_offset < 0) {
    c.field = "--frame-offset";
    throw Error("batch collect: frame offset must be >= 0", c);
  }
}

std::string sequenceName(const std::string& stem, int frame, const std::string& ext) {
  char text[64];
  std::snprintf(text, sizeof(text), "%04d", frame);
  return stem + "." + text + "." + ext;
}

std::vector<std::pair<int, Pose>> mainCameraPoses(const Manifest& m, const TakePlan& take) {
  std::vector<std::pair<int, Pose>> poses;
  if (take.main_camera.empty()) return poses;
  const Rig rig = readRig(m.rig);
  const Pose rig_pose = rig.at(take.main_camera).T_world_cam;
  // Frames the tracker lost (or could not read) have no pose and no key; frames the file does
  // not list keep the rig's.
  std::map<int, Pose> moving;
  std::map<int, std::string> lost;
  if (!take.main_poses.empty()) moving = readPoseLines(take.main_poses, "T_world_cam", &lost);
  for (int f : take.frames) {
    if (lost.count(f)) continue;
    const auto it = moving.find(f);
    poses.push_back({f, it != moving.end() ? it->second : rig_pose});
  }
  return poses;
}

std::vector<PropSample> readPropTrack(const fs::path& path) {
  std::ifstream in(path);
  if (!in) throw Error("cannot open prop track", fileContext(path));
  std::vector<PropSample> samples;
  int number = 0;
  for (std::string line; std::getline(in, line);) {
    ++number;
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    try {
      const nlohmann::json j = nlohmann::json::parse(line);
      // Checked: a "frame" or "id" of 1e10 was undefined behaviour in get<int>()
      // (fuzz/batch_prop_track.cpp).
      const int frame = jsonInt(j.at("frame"), fileContext(path, "line " + std::to_string(number) + ": frame"));
      for (const auto& p : j.at("props")) {
        if (!p.contains("T_world_prop") || p["T_world_prop"].is_null()) continue;  // not seen
        PropSample s;
        s.frame = frame;
        s.id = jsonInt(p.at("id"), fileContext(path, "line " + std::to_string(number) + ": props[].id"));
        s.name = p.value("name", "prop" + std::to_string(s.id));
        s.state = p.value("state", "");
        s.T_world_prop = poseFromJson(p.at("T_world_prop"), "T_world_prop");
        samples.push_back(s);
      }
    } catch (const std::exception& e) {
      ErrorContext c = fileContext(path);
      c.field = "line " + std::to_string(number);
      throw Error(std::string("bad prop track line: ") + e.what(), c);
    }
  }
  return samples;
}

nlohmann::json CollectSummary::toJson() const {
  return {{"frames", frames}, {"missing", missing}, {"takes", takes}};
}

CollectSummary collectBatch(const Manifest& m, const CollectOptions& o) {
  o.validate();
  CollectSummary summary;
  const Rig rig = readRig(m.rig);

  // What is finished, per take (the ledger's word, checksums verified).
  std::vector<std::set<int>> done(m.takes.size());
  for (const ShardPlan& s : m.shards) {
    const ShardCheck check = checkShard(m, s.id);
    for (int f : check.done) done[s.take].insert(f);
    const std::string take = m.takes[s.take].name;
    for (const auto& [f, why] : check.bad)
      summary.missing.push_back(take + " frame " + std::to_string(f) + " (shard " + std::to_string(s.id) + ": " + why + ")");
    for (int f : check.missing)
      summary.missing.push_back(take + " frame " + std::to_string(f) + " (shard " + std::to_string(s.id) + ": not finished)");
  }
  if (!summary.missing.empty() && !o.partial) {
    std::string first = summary.missing.front();
    throw Error("batch collect: " + std::to_string(summary.missing.size()) + " frames are not finished, e.g. " +
                    first + "; run `previz batch resume " + m.job_dir.string() + "` (or collect --partial)",
                fileContext(manifestPath(m.job_dir)));
  }

  fs::create_directories(o.out);
  std::string html_takes;
  for (size_t ti = 0; ti < m.takes.size(); ++ti) {
    const TakePlan& take = m.takes[ti];
    const fs::path td = o.out / take.name;
    const fs::path carve = m.job_dir / take.work / "carve";
    nlohmann::json files = nlohmann::json::array();
    std::string rows;
    std::vector<std::pair<int, fs::path>> previews;
    for (int f : take.frames) {
      if (!done[ti].count(f)) continue;
      const int out_frame = f + o.frame_offset;
      const std::string stem = frameStem(f);
      const std::string obj = "mesh/" + sequenceName("actor", out_frame, "obj");
      const std::string ply = "mesh/" + sequenceName("actor", out_frame, "ply");
      const std::string pcd = "points/" + sequenceName("actor", out_frame, "pcd");
      const std::string pts = "points/" + sequenceName("actor", out_frame, "ply");
      copyAtomic(carve / "mesh" / (stem + ".obj"), td / obj);
      copyAtomic(carve / "mesh" / (stem + ".ply"), td / ply);
      copyAtomic(carve / "points" / (stem + ".pcd"), td / pcd);
      copyAtomic(carve / "points" / (stem + ".ply"), td / pts);
      nlohmann::json entry = {{"frame", out_frame}, {"take_frame", f}, {"obj", obj}, {"ply", ply},
                              {"pcd", pcd}, {"points_ply", pts}};
      // Depth sequences per camera: depth/<cam>/<cam>.####.exr (the main camera's first).
      std::string depth_links;
      if (!take.main_camera.empty()) {
        entry["depth"] = nlohmann::json::object();
        std::vector<std::pair<std::string, fs::path>> sources = {
            {take.main_camera, carve / "depth" / (stem + ".exr")}};
        for (const std::string& cam : take.depth_cameras)
          sources.push_back({cam, carve / "depth_cameras" / cam / (stem + ".exr")});
        for (const auto& [cam, source] : sources) {
          const std::string exr = "depth/" + cam + "/" + sequenceName(cam, out_frame, "exr");
          copyAtomic(source, td / exr);
          entry["depth"][cam] = exr;
          depth_links += std::string(depth_links.empty() ? "" : " ") + "<a href=\"" +
                         htmlEscape(take.name + "/" + exr) + "\">" + htmlEscape(cam) + "</a>";
        }
        // The main camera's refined layer (plan --refine, default with post).
        if (m.settings.value("refine", false)) {
          const std::string& cam = take.main_camera;
          const std::string exr = "depth_refined/" + cam + "/" + sequenceName(cam, out_frame, "exr");
          copyAtomic(carve / "depth_refined" / (stem + ".exr"), td / exr);
          entry["depth_refined"] = {{cam, exr}};
          depth_links += " <a href=\"" + htmlEscape(take.name + "/" + exr) + "\">" + htmlEscape(cam) +
                         " refined</a>";
        }
        previews.push_back({f, carve / "depth" / (stem + ".png")});
      } else {
        previews.push_back({f, fs::path()});
      }
      if (o.y_up) {
        TriangleMesh mesh = readPly(carve / "mesh" / (stem + ".ply"));
        const Eigen::Matrix3f A = yUpFromZUp().cast<float>();
        for (auto& v : mesh.vertices) v = A * v;
        for (auto& n : mesh.normals) n = A * n;
        const std::string yobj = "mesh_yup/" + sequenceName("actor", out_frame, "obj");
        const std::string yply = "mesh_yup/" + sequenceName("actor", out_frame, "ply");
        writeObj(mesh, td / yobj, kYUpNote);
        writePly(mesh, td / yply, kYUpNote);
        entry["obj_yup"] = yobj;
        entry["ply_yup"] = yply;
      }
      // The frame's numbers from carve's report (timings left out: they differ run to run).
      const nlohmann::json report = readJsonFile(carve / "report" / (stem + ".json"));
      entry["mesh_vertices"] = report.value("mesh_vertices", 0);
      entry["mesh_faces"] = report.value("mesh_faces", 0);
      entry["points"] = report.value("points", 0);
      entry["volume_m3"] = report.value("volume_m3", 0.0);
      entry["cameras_dropped"] = report.value("cameras_dropped", nlohmann::json::array());
      files.push_back(entry);
      rows += "<tr><td>" + std::to_string(out_frame) + "</td><td><a href=\"" + htmlEscape(take.name + "/" + obj) +
              "\">obj</a> <a href=\"" + htmlEscape(take.name + "/" + ply) + "\">ply</a></td><td><a href=\"" +
              htmlEscape(take.name + "/" + pcd) + "\">pcd</a></td><td>" +
              (depth_links.empty() ? std::string("-") : depth_links) +
              "</td><td>" + std::to_string(entry["mesh_vertices"].get<long long>()) + "</td><td>" +
              std::to_string(entry["mesh_faces"].get<long long>()) + "</td><td>" +
              fixed(entry["volume_m3"].get<double>(), 4) + "</td><td>" +
              std::to_string(entry["cameras_dropped"].size()) + "</td></tr>\n";
      ++summary.frames;
    }

    // Main camera animation: every collected frame.
    nlohmann::json take_json = {{"take", take.name}, {"folder", take.name}, {"frames", files}};
    std::string anim_links;
    if (!take.main_camera.empty()) {
      std::vector<std::pair<int, Pose>> poses, post;
      for (const auto& [f, T] : mainCameraPoses(m, take)) {
        if (!done[ti].count(f)) continue;
        poses.push_back({f + o.frame_offset, T});
        post.push_back({f + o.frame_offset, cameraPoseForPost(T)});
      }
      const std::vector<ChanKey> keys = chanKeys(post);
      const std::string chan = "camera/" + take.main_camera + ".chan";
      const std::string json = "camera/" + take.main_camera + ".json";
      writeChan(td / chan, keys);
      const Camera& cam = rig.at(take.main_camera).camera;
      writeJsonAtomic(td / json,
                      {{"format", "previz animation"},
                       {"object", take.main_camera},
                       {"kind", "camera"},
                       {"units", "m"},
                       {"angles", "degrees"},
                       {"rotation_order", "ZXY"},
                       {"rotation", "R = Ry(ry) Rx(rx) Rz(rz): about Z first, then X, then Y"},
                       {"world", kYUpNote},
                       {"camera_axes", "x right, y up, looking down -z (Nuke/Maya)"},
                       {"source", take.main_poses.empty() ? "rig (static)" : take.main_poses.string()},
                       {"camera", cameraToJson(cam)},
                       {"horizontal_fov_deg", degrees(2 * std::atan(0.5 * cam.width / cam.fx))},
                       {"vertical_fov_deg", degrees(2 * std::atan(0.5 * cam.height / cam.fy))},
                       {"frames", keysJson(keys, poses, "T_world_cam_previz")}});
      take_json["camera"] = {{"chan", chan}, {"json", json}};
      anim_links += "<li>main camera <code>" + htmlEscape(take.main_camera) + "</code>: <a href=\"" +
                    htmlEscape(take.name + "/" + chan) + "\">.chan</a> <a href=\"" +
                    htmlEscape(take.name + "/" + json) + "\">JSON</a></li>\n";
    }

    // Prop animation, when a track stage left its output: one file for the take, or one line
    // per frame in track/frames/%06d.json (what a sharded stage writes without racing).
    const fs::path track = m.job_dir / take.work / "track" / "poses.jsonl";
    std::vector<fs::path> track_files;
    std::error_code ec;
    if (fs::is_regular_file(track, ec)) {
      track_files.push_back(track);
    } else {
      for (int f : take.frames) {
        const fs::path p = m.job_dir / take.work / "track" / "frames" / (frameStem(f) + ".json");
        if (done[ti].count(f) && fs::is_regular_file(p, ec)) track_files.push_back(p);
      }
    }
    if (!track_files.empty()) {
      std::map<std::string, std::vector<PropSample>> by_name;
      for (const fs::path& file : track_files)
        for (const PropSample& s : readPropTrack(file))
          if (done[ti].count(s.frame)) by_name[s.name].push_back(s);
      nlohmann::json props = nlohmann::json::array();
      for (const auto& [name, samples] : by_name) {
        std::vector<std::pair<int, Pose>> world, post;
        for (const PropSample& s : samples) {
          world.push_back({s.frame + o.frame_offset, s.T_world_prop});
          post.push_back({s.frame + o.frame_offset, objectPoseForPost(s.T_world_prop)});
        }
        const std::vector<ChanKey> keys = chanKeys(post);
        const std::string chan = "props/" + name + ".chan", json = "props/" + name + ".json";
        writeChan(td / chan, keys);
        nlohmann::json frames = keysJson(keys, world, "T_world_prop_previz");
        for (size_t i = 0; i < frames.size(); ++i) frames[i]["state"] = samples[i].state;
        writeJsonAtomic(td / json, {{"format", "previz animation"}, {"object", name}, {"id", samples[0].id},
                                    {"kind", "prop"}, {"units", "m"}, {"angles", "degrees"},
                                    {"rotation_order", "ZXY"}, {"world", kYUpNote},
                                    {"object_axes", "the prop frame of props.json"},
                                    {"source", track_files.size() == 1 ? track_files[0].string()
                                                                       : (track.parent_path() / "frames").string()},
                                    {"frames", frames}});
        props.push_back({{"name", name}, {"chan", chan}, {"json", json}});
        anim_links += "<li>prop <code>" + htmlEscape(name) + "</code>: <a href=\"" +
                      htmlEscape(take.name + "/" + chan) + "\">.chan</a> <a href=\"" +
                      htmlEscape(take.name + "/" + json) + "\">JSON</a></li>\n";
      }
      take_json["props"] = props;
    }

    const std::string sheet = "contact_sheet.png";
    writeImageAtomic(td / sheet, contactSheet(previews, o));
    take_json["contact_sheet"] = sheet;
    summary.takes.push_back(take_json);

    html_takes += "<section><h2>" + htmlEscape(take.name) + "</h2>\n<p>" + std::to_string(files.size()) +
                  " of " + std::to_string(take.frames.size()) + " frames; source <code>" +
                  htmlEscape(take.dir.string()) + "</code></p>\n<img src=\"" + htmlEscape(take.name + "/" + sheet) +
                  "\" alt=\"contact sheet of " + htmlEscape(take.name) + "\">\n<ul>\n" + anim_links +
                  "</ul>\n<table>\n<tr><th>frame</th><th>mesh</th><th>points</th><th>depth EXR</th>"
                  "<th>vertices</th><th>faces</th><th>volume m&sup3;</th><th>cameras dropped</th></tr>\n" +
                  rows + "</table></section>\n";
  }

  const std::string html =
      "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>previz batch</title>\n"
      "<style>body{font-family:sans-serif;background:#fafafa;color:#222;margin:2em}"
      "img{max-width:100%;border:1px solid #888}table{border-collapse:collapse;margin-top:1em}"
      "td,th{border:1px solid #bbb;padding:2px 8px;text-align:right}</style></head>\n<body>\n"
      "<h1>previz batch: " + std::to_string(m.takes.size()) + " takes, " + std::to_string(summary.frames) +
      " frames</h1>\n<p>Quality <b>" + htmlEscape(m.quality) + "</b>, voxel " +
      fixed(m.settings.value("voxel_m", 0.0), 4) + " m, manifest " + htmlEscape(m.hash) +
      ". Meshes and points: world frame, metres, z up" + (o.y_up ? " (y-up variant in mesh_yup/)" : "") +
      "; .chan: y up, rotation order ZXY, degrees (see <a href=\"collect.json\">collect.json</a>).</p>\n" +
      html_takes + "</body></html>\n";
  nlohmann::json j = summary.toJson();
  j["format"] = "previz batch collect";
  j["manifest_hash"] = m.hash;
  j["frame_offset"] = o.frame_offset;
  j["y_up"] = o.y_up;
  writeJsonAtomic(o.out / "collect.json", j);
  writeFileAtomic(o.out / "index.html", html);
  return summary;
}

}  // namespace previz::batch
