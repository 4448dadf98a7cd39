// previz track: AprilTag-tagged props from every camera of a take -> one JSON line per frame and
// optional FreeD / OpenTrackIO streaming; `track prop` writes props.json and printable tag sheets;
// `track camera` solves a camera's pose per frame from studio tags. The work is tracking/.
#include <cmath>
#include <filesystem>
#include <iostream>
#include <sstream>

#include <nlohmann/json.hpp>

#include "app/commands.h"
#include "app/options.h"
#include "app/progress.h"
#include "core/error.h"
#include "core/io.h"
#include "core/names.h"
#include "core/rig.h"
#include "live/tracker.h"
#include "take/take.h"
#include "tracking/props.h"
#include "tracking/run.h"

namespace previz::app {
namespace {

namespace fs = std::filesystem;

struct TrackArgs {
  std::string take, rig, props, out, udp, main_poses, cameras, truth, frames, shard = "0/1";
  std::string tracker, tracker_config, tracker_match;  // the main camera from the stage's tracker
  double tracker_delay_s = std::nan("");
  bool freed = false, otio = false, frame_files = false;
  double fps = 0;
  float decimate = 1.0f;
  std::string sigma = "auto";
  int detector_threads = 1, threads = 0, full_every = 30;
  bool no_refine = false, no_refine_corners = false, no_filter = false, no_roi = false, not_srgb = false;
  std::vector<std::string> per_camera;
  bool json = false, quiet = false;
};

struct PropArgs {
  std::string shape = "box", name, size, faces = "-y,+x,+y,-x,+z", grid = "1x1", family = "tag36h11";
  std::string out, sheets;
  int id = 0, first_id = 0;
  double tag_size_m = 0.12, dpi = 300;
  bool append = false, json = false;
};

struct CameraArgs {
  std::string take, rig, tags, camera = kMainCamera, out, truth, frames;
  double fps = 0;
  float decimate = 1.0f;
  std::string sigma = "auto";
  bool no_filter = false, not_srgb = false, json = false, quiet = false;
};

void parseFrames(const std::string& text, tracking::TrackRunOptions& o) {
  if (text.empty()) return;
  const auto colon = text.find(':');
  try {
    if (colon == std::string::npos) {
      o.first_frame = std::stoi(text);
      o.end_frame = o.first_frame + 1;
    } else {
      if (colon > 0) o.first_frame = std::stoi(text.substr(0, colon));
      if (colon + 1 < text.size()) o.end_frame = std::stoi(text.substr(colon + 1));
    }
  } catch (const std::exception&) {
    throw Error("expected A:B, A:, :B or A (got '" + text + "')", fieldContext("--frames"));
  }
}

// "auto" (the blur chosen from each frame's noise) or a fixed blur in pixels.
void parseSigma(const std::string& text, const std::string& option, tracking::DetectorOptions& d) {
  if (text == "auto") {
    d.auto_sigma = true;
    return;
  }
  const auto number = finiteNumber(text);
  if (!number || *number < 0)
    throw Error("expected auto or a blur >= 0 in pixels (got '" + text + "')", fieldContext(option));
  d.auto_sigma = false;
  d.sigma = static_cast<float>(*number);
}

// "witness01:decimate=2,sigma=0.8,threads=1,refine-edges=0,refine-corners=1"; "auto" alone: every
// camera's blur chosen from its frames' noise (the default).
void parsePerCamera(const std::string& text, const tracking::DetectorOptions& base,
                    std::map<std::string, tracking::DetectorOptions>& out) {
  if (text == "auto") return;  // the default; --sigma N makes every camera fixed instead
  const auto colon = text.find(':');
  if (colon == std::string::npos || colon == 0)
    throw Error("expected CAMERA:key=value,... (keys decimate, sigma, threads, refine-edges, refine-corners), got '" +
                    text + "'",
                fieldContext("--detector"));
  tracking::DetectorOptions d = base;
  for (const std::string& kv : splitList(text.substr(colon + 1))) {
    const auto eq = kv.find('=');
    const std::string key = kv.substr(0, eq);
    if (key == "sigma" && eq != std::string::npos) {
      parseSigma(kv.substr(eq + 1), "--detector", d);
      continue;
    }
    const auto number = eq == std::string::npos ? std::nullopt : finiteNumber(kv.substr(eq + 1));
    if (!number) throw Error("expected key=number in '" + text + "'", fieldContext("--detector"));
    const double value = *number;
    if (key == "decimate") d.decimate = static_cast<float>(value);
    else if (key == "threads") d.threads = static_cast<int>(value);
    else if (key == "refine-edges") d.refine_edges = value != 0;
    else if (key == "refine-corners") d.refine_corners = value != 0;
    else throw Error("unknown key '" + key + "' (decimate, sigma, threads, refine-edges, refine-corners)",
                     fieldContext("--detector"));
  }
  out[text.substr(0, colon)] = d;
}

nlohmann::json propSummaryJson(const tracking::PropRunSummary& p) {
  nlohmann::json j = {{"id", p.id},         {"name", p.name},
                      {"tracked", p.tracked}, {"lost", p.lost},
                      {"median_sigma_position_mm", p.median_sigma_position_mm}};
  if (p.truth_frames > 0) {
    j["truth"] = {{"frames", p.truth_frames},
                  {"median_position_error_mm", p.median_position_error_mm},
                  {"max_position_error_mm", p.max_position_error_mm},
                  {"median_rotation_error_deg", p.median_rotation_error_deg},
                  {"max_rotation_error_deg", p.max_rotation_error_deg},
                  {"median_measured_position_error_mm", p.median_measured_position_error_mm},
                  {"median_measured_rotation_error_deg", p.median_measured_rotation_error_deg}};
  }
  return j;
}

// The main camera's poses from the stage's camera tracker (live/tracker.h), one line a frame of
// the take into OUT/tracker_main_poses.jsonl as camera_poses.jsonl has them: {"frame", "state":
// "tracked", "T_world_cam"}, or {"frame", "state": "lost", "reason"} where the tracker gave none
// (the main camera is then left out of that frame). Pose only: track uses the rig's lens.
fs::path trackerMainPoses(const TrackArgs& a) {
  const live::TrackerUrl url = live::parseTrackerUrl(a.tracker, "--tracker");
  live::TrackerOptions o = a.tracker_config.empty() ? live::TrackerOptions{} : live::readTrackerConfig(a.tracker_config);
  if (!std::isnan(a.tracker_delay_s)) o.delay_s = a.tracker_delay_s;
  if (!a.tracker_match.empty()) o.match = a.tracker_match;
  try {
    o.validate();
  } catch (const Error& e) {
    throw Error(e.what(), fieldContext(e.context().field == "delay_s" ? "--tracker-delay"
                                       : e.context().field == "match" ? "--tracker-match" : e.context().field));
  }
  const Rig rig = readRig(a.rig);
  std::string main_name = kMainCamera;  // the moving camera: the rig's "main" role, else the camera called main
  for (const RigCamera& rc : rig.cameras)
    if (rc.role == kMainRole) main_name = rc.camera.name;
  const RigCamera& main = rig.at(main_name);
  const take::Take streams(a.take);
  const live::FrameClock clock = live::frameClock(streams, main_name);
  live::TrackerInput input(url, o, main.camera);
  std::string lines;
  int posed = 0, lost = 0;
  for (int f : streams.frames()) {
    try {
      const RigCamera rc = input.mainAt(f, clock.timeOf(f), clock.timecodeOf(f), main);
      lines += nlohmann::json{{"frame", f}, {"state", "tracked"}, {"T_world_cam", poseToJson(rc.T_world_cam)}}.dump() + "\n";
      ++posed;
    } catch (const Error& e) {
      lines += nlohmann::json{{"frame", f}, {"state", "lost"}, {"reason", e.what()}}.dump() + "\n";
      ++lost;
    }
  }
  fs::create_directories(a.out);
  const fs::path path = fs::path(a.out) / "tracker_main_poses.jsonl";
  writeFileAtomic(path, lines);
  std::cerr << "track: main camera from the tracker " << a.tracker << ": " << posed << " frames posed, " << lost
            << " without a pose; " << input.summary()["counts"].dump() << " -> " << path.string() << "\n";
  return path;
}

int runTrack(const TrackArgs& a) {
  for (const char* f : {"--take", "--rig", "--props", "--out"}) {
    const std::string& v = std::string(f) == "--take" ? a.take : std::string(f) == "--rig" ? a.rig
                           : std::string(f) == "--props" ? a.props : a.out;
    if (v.empty()) throw Error(std::string("track: ") + f + " is required (or use `track prop` / `track camera`)", fieldContext(f));
  }
  if (a.freed && a.otio) throw Error("choose one of --freed and --otio", fieldContext("--otio"));
  if ((a.freed || a.otio) && a.udp.empty()) throw Error("--freed / --otio stream to --udp HOST:PORT", fieldContext("--udp"));
  tracking::TrackInput in;
  in.take = a.take;
  in.rig = a.rig;
  in.props = a.props;
  in.main_poses = a.main_poses;
  if (!a.tracker.empty()) {
    if (!a.main_poses.empty()) throw Error("--tracker replaces --main-poses: give one", fieldContext("--tracker"));
    in.main_poses = trackerMainPoses(a);
  }
  in.cameras = splitList(a.cameras);
  in.truth = a.truth;
  tracking::TrackRunOptions o;
  o.out = a.out;
  o.fps = a.fps;
  o.udp = a.udp;
  o.protocol = a.otio ? tracking::StreamProtocol::kOpenTrackIo : tracking::StreamProtocol::kFreeD;
  parseFrames(a.frames, o);
  {
    const auto slash = a.shard.find('/');
    try {
      if (slash == std::string::npos) throw std::invalid_argument(a.shard);
      size_t ui = 0, un = 0;
      o.shard_index = std::stoi(a.shard.substr(0, slash), &ui);
      o.shard_count = std::stoi(a.shard.substr(slash + 1), &un);
      if (ui != slash || un != a.shard.size() - slash - 1) throw std::invalid_argument(a.shard);
    } catch (const std::exception&) {
      throw Error("expected i/n with 0 <= i < n, e.g. 0/4 (got '" + a.shard + "')", fieldContext("--shard"));
    }
  }
  o.frame_files = a.frame_files;
  o.tracker.detector.decimate = a.decimate;
  parseSigma(a.sigma, "--sigma", o.tracker.detector);
  o.tracker.detector.threads = a.detector_threads;
  o.tracker.detector.refine_edges = !a.no_refine;
  o.tracker.detector.refine_corners = !a.no_refine_corners;
  o.tracker.detector.linear_light = !a.not_srgb;
  for (const std::string& pc : a.per_camera) parsePerCamera(pc, o.tracker.detector, o.tracker.per_camera);
  o.tracker.threads = a.threads;
  o.tracker.full_frame_every = a.full_every;
  o.tracker.filter_enabled = !a.no_filter;
  o.tracker.roi = !a.no_roi;
  o.validate();

  std::unique_ptr<ProgressLine> line;
  const tracking::TrackRunSummary s = tracking::runTrack(in, o, [&](int done, int n) {
    if (!line) line = std::make_unique<ProgressLine>("track", n, a.quiet);
    line->update(done);
  });
  for (const std::string& f : s.camera_failures) std::cerr << "track: " << f << "\n";
  for (int f : s.failed_frames) std::cerr << "track: frame " << f << " failed: no camera has an image\n";
  const double fps = s.ms > 0 ? 1000.0 * s.frames / s.ms : 0;
  std::cerr << "track: " << s.frames << " frames from " << s.cameras.size() << " cameras, " << s.full_frames
            << " full-frame searches (" << s.rescanned_frames << " after a missed prediction), " << s.unknown_tags << " tags of no prop ignored, "
            << (s.frames ? s.track_ms / s.frames : 0) << " ms/frame tracking, " << fps << " fps overall -> "
            << s.poses.string() << "\n";
  for (const tracking::PropRunSummary& p : s.props) {
    std::cerr << "track: prop " << p.id << " '" << p.name << "': tracked " << p.tracked << ", lost " << p.lost
              << ", median sigma " << p.median_sigma_position_mm << " mm";
    if (p.truth_frames)
      std::cerr << "; vs truth (" << p.truth_frames << " frames): median " << p.median_position_error_mm << " mm "
                << p.median_rotation_error_deg << " deg, max " << p.max_position_error_mm << " mm "
                << p.max_rotation_error_deg << " deg";
    std::cerr << "\n";
  }
  if (!a.udp.empty())
    std::cerr << "track: " << s.packets_sent << " " << (a.otio ? "OpenTrackIO" : "FreeD") << " datagrams to " << a.udp
              << (s.packets_failed ? ", " + std::to_string(s.packets_failed) + " refused" : "") << "\n";
  nlohmann::json props = nlohmann::json::array();
  for (const auto& p : s.props) props.push_back(propSummaryJson(p));
  nlohmann::json j = {{"command", "track"},
                      {"out", a.out},
                      {"poses", s.poses.string()},
                      {"frames", s.frames},
                      {"frames_selected", s.selected},
                      {"frames_kept", s.kept},
                      {"cameras", s.cameras},
                      {"props", props},
                      {"unknown_tags", s.unknown_tags},
                      {"full_frames", s.full_frames},
                      {"rescanned_frames", s.rescanned_frames},
                      {"camera_failures", s.camera_failures},
                      {"failed_frames", s.failed_frames},
                      {"ms", s.ms},
                      {"track_ms_per_frame", s.frames ? s.track_ms / s.frames : 0},
                      {"udp", a.udp.empty() ? nlohmann::json(nullptr) : nlohmann::json(a.udp)},
                      {"protocol", a.udp.empty() ? nlohmann::json(nullptr) : nlohmann::json(a.otio ? "otio" : "freed")},
                      {"packets_sent", s.packets_sent},
                      {"packets_failed", s.packets_failed}};
  // Frame files: shards share the folder, so the summary is only printed (--json).
  if (!a.frame_files) writeJsonAtomic(std::filesystem::path(a.out) / "track.json", j);
  if (a.json) std::cout << j.dump() << "\n";
  return s.failed_frames.empty() ? 0 : 1;
}

int runProp(const PropArgs& a) {
  tracking::PropDef prop;
  if (a.shape == "box") {
    tracking::BoxPropOptions o;
    o.prop_id = a.id;
    o.name = a.name.empty() ? "box" : a.name;
    if (!a.size.empty()) {
      const auto v = parseNumbers(a.size, 3, "--size");
      o.size_m = Eigen::Vector3d(v[0], v[1], v[2]);
    }
    o.family = a.family;
    o.tag_size_m = a.tag_size_m;
    o.first_tag_id = a.first_id;
    o.faces = splitList(a.faces);
    prop = tracking::makeBoxProp(o);
  } else if (a.shape == "plate") {
    tracking::PlatePropOptions o;
    o.prop_id = a.id;
    o.name = a.name.empty() ? "plate" : a.name;
    if (!a.size.empty()) {
      const auto v = parseNumbers(a.size, 2, "--size");
      o.width_m = v[0];
      o.height_m = v[1];
    }
    o.family = a.family;
    o.tag_size_m = a.tag_size_m;
    o.first_tag_id = a.first_id;
    const auto x = a.grid.find_first_of("xX");
    try {
      if (x == std::string::npos) throw std::invalid_argument(a.grid);
      o.rows = std::stoi(a.grid.substr(0, x));
      o.cols = std::stoi(a.grid.substr(x + 1));
    } catch (const std::exception&) {
      throw Error("expected ROWSxCOLS (got '" + a.grid + "')", fieldContext("--grid"));
    }
    prop = tracking::makePlateProp(o);
  } else {
    throw Error("unknown shape '" + a.shape + "' (box, plate)", fieldContext("--shape"));
  }
  tracking::PropSet set;
  if (a.append && std::filesystem::exists(a.out)) set = tracking::readProps(a.out);
  set.props.push_back(prop);
  tracking::writeProps(set, a.out);  // validates: a duplicate id is an error naming both props
  std::vector<tracking::TagSheet> sheets;
  if (!a.sheets.empty()) {
    tracking::PropSet only;
    only.props.push_back(prop);
    sheets = tracking::writeTagSheets(only, a.sheets, a.dpi);
  }
  std::cerr << "track prop: " << prop.shape << " '" << prop.name << "' (prop " << prop.id << ") with "
            << prop.tags.size() << " " << a.family << " tags of " << a.tag_size_m * 1000 << " mm -> " << a.out;
  if (!sheets.empty()) std::cerr << "; " << sheets.size() << " tag sheets at " << a.dpi << " dpi in " << a.sheets;
  std::cerr << "\n";
  if (a.json) {
    nlohmann::json names = nlohmann::json::array();
    for (const auto& s : sheets) names.push_back({{"png", s.png_name}, {"svg", s.svg_name}});
    std::cout << nlohmann::json{{"command", "track prop"}, {"out", a.out}, {"props", set.props.size()},
                                {"prop", tracking::propsToJson(tracking::PropSet{{prop}})["props"][0]},
                                {"sheets", names}}
                     .dump()
              << "\n";
  }
  return 0;
}

int runCamera(const CameraArgs& a) {
  tracking::CameraTrackInput in;
  in.take = a.take;
  in.rig = a.rig;
  in.tags = a.tags;
  in.camera = a.camera;
  in.truth = a.truth;
  tracking::TrackRunOptions o;
  o.out = a.out;
  o.fps = a.fps;
  parseFrames(a.frames, o);
  o.tracker.detector.decimate = a.decimate;
  parseSigma(a.sigma, "--sigma", o.tracker.detector);
  o.tracker.detector.linear_light = !a.not_srgb;
  o.tracker.filter_enabled = !a.no_filter;
  o.validate();
  std::unique_ptr<ProgressLine> line;
  const tracking::CameraTrackSummary s = tracking::runTrackCamera(in, o, [&](int done, int n) {
    if (!line) line = std::make_unique<ProgressLine>("track camera", n, a.quiet);
    line->update(done);
  });
  std::cerr << "track camera: '" << a.camera << "' solved in " << s.solved << "/" << s.frames
            << " frames, median sigma " << s.median_sigma_position_mm << " mm";
  if (s.truth_frames)
    std::cerr << "; vs truth: median " << s.median_position_error_mm << " mm " << s.median_rotation_error_deg
              << " deg, max " << s.max_position_error_mm << " mm " << s.max_rotation_error_deg << " deg";
  std::cerr << " -> " << s.poses.string() << "\n";
  if (!s.bad_frames.empty())
    std::cerr << "track camera: " << s.bad_frames.size() << " bad frame(s) skipped (first: frame "
              << s.bad_frames.front() << "; file and reason in " << s.poses.string() << ")\n";
  nlohmann::json j = {{"command", "track camera"}, {"camera", a.camera}, {"frames", s.frames},
                      {"solved", s.solved},        {"bad_frames", s.bad_frames}, {"poses", s.poses.string()},
                      {"median_sigma_position_mm", s.median_sigma_position_mm}, {"ms", s.ms}};
  if (s.truth_frames)
    j["truth"] = {{"frames", s.truth_frames},
                  {"median_position_error_mm", s.median_position_error_mm},
                  {"max_position_error_mm", s.max_position_error_mm},
                  {"median_rotation_error_deg", s.median_rotation_error_deg},
                  {"max_rotation_error_deg", s.max_rotation_error_deg}};
  if (a.json) std::cout << j.dump() << "\n";
  return s.solved > 0 ? 0 : 1;
}

}  // namespace

Runner addTrackCommand(CLI::App& app) {
  auto a = std::make_shared<TrackArgs>();
  auto p = std::make_shared<PropArgs>();
  auto c = std::make_shared<CameraArgs>();
  CLI::App* cmd = app.add_subcommand(
      "track", "Track AprilTag-tagged props from every camera; JSON lines per frame, FreeD / OpenTrackIO over UDP "
               "(docs/formats.md, \"Tracking\")");
  cmd->require_subcommand(0, 1);
  cmd->add_option("--take", a->take, "Take folder (cams/: a sequence or video per camera; docs/formats.md \"Take folder\")");
  cmd->add_option("--rig", a->rig, "rig.json (cameras and their poses)");
  cmd->add_option("--props", a->props, "props.json (docs/formats.md)");
  cmd->add_option("--out", a->out, "Output folder: poses.jsonl, track.json");
  cmd->add_option("--udp", a->udp, "Stream to HOST:PORT (numeric IPv4)");
  cmd->add_flag("--freed", a->freed, "Stream FreeD D1 packets (default with --udp)");
  cmd->add_flag("--otio", a->otio, "Stream OpenTrackIO-style JSON instead");
  cmd->add_option("--tracker", a->tracker,
                  "The main camera's pose from the stage's camera tracker: freed://HOST:PORT, otio://HOST:PORT or a "
                  "recording FILE.jsonl (previz tracker record); replaces --main-poses (docs/formats.md \"Camera tracker\")");
  cmd->add_option("--tracker-config", a->tracker_config, "tracker.json (T_world_stage, T_tracker_cam, delay_s, ...)");
  cmd->add_option("--tracker-delay", a->tracker_delay_s, "Seconds from a tracker sample's instant to its arrival");
  cmd->add_option("--tracker-match", a->tracker_match, "auto, arrival or timecode");
  cmd->add_option("--main-poses", a->main_poses,
                  "JSON lines {frame, T_world_cam} of the moving main camera (truth/main_poses.jsonl, or "
                  "`track camera` output)");
  cmd->add_option("--cameras", a->cameras, "Cameras to track from a,b,c (default: every rig camera)");
  cmd->add_option("--truth", a->truth, "truth/props.jsonl of a synthetic take: report errors");
  cmd->add_option("--frames", a->frames, "Frames A:B (A inclusive, B exclusive), A:, :B or A");
  cmd->add_option("--fps", a->fps, "Frame rate (default: take.json's, else 24)");
  cmd->add_option("--shard", a->shard, "Shard i/n: every n-th selected frame from the i-th")->capture_default_str();
  cmd->add_flag("--frame-files", a->frame_files,
                "Track every frame on its own into OUT/frames/%06d.json (kept when already there); no poses.jsonl");
  cmd->add_option("--decimate", a->decimate, "libapriltag quad_decimate")->capture_default_str();
  cmd->add_option("--sigma", a->sigma,
                  "Blur before the quad search (libapriltag quad_sigma), for sensor noise: auto = chosen per camera "
                  "from each frame's measured noise (0 on clean footage and JPEG photos, 0.8 at 2 grey levels a "
                  "channel), or a fixed blur in pixels for every camera")
      ->capture_default_str();
  cmd->add_option("--detector-threads", a->detector_threads, "libapriltag threads per camera")->capture_default_str();
  cmd->add_flag("--no-refine-edges", a->no_refine, "Do not refine tag edges on the image gradient (libapriltag)");
  cmd->add_flag("--no-refine-corners", a->no_refine_corners,
                "Keep libapriltag's corners (no fit of each tag's edges on linear light)");
  cmd->add_flag("--not-srgb", a->not_srgb, "8-bit images are linear, not sRGB-encoded (corners refined on them as they are)");
  cmd->add_option("--detector", a->per_camera,
                  "auto (the default: every camera's blur from its frames' noise) or a camera's own detector "
                  "CAM:decimate=2,sigma=auto|0.8,threads=1,refine-edges=1,refine-corners=1 (repeatable)");
  cmd->add_option("--threads", a->threads, "OpenMP threads over cameras (0 = all cores)")->capture_default_str();
  cmd->add_option("--full-every", a->full_every,
                  "Each camera searches its whole frame every N frames, staggered over the cameras (0 = only on loss)")
      ->capture_default_str();
  cmd->add_flag("--no-roi", a->no_roi, "Search the full frame every frame");
  cmd->add_flag("--no-filter", a->no_filter, "Report the per-frame solve unfiltered");
  cmd->add_flag("--json", a->json, "Print a JSON summary on stdout");
  cmd->add_flag("--quiet", a->quiet, "No progress line");

  CLI::App* prop = cmd->add_subcommand("prop", "Write props.json for a tagged box or plate, and printable tag sheets");
  prop->add_option("--shape", p->shape, "box | plate")->capture_default_str();
  prop->add_option("--id", p->id, "Prop id (FreeD camera id when streaming)")->capture_default_str();
  prop->add_option("--name", p->name, "Prop name");
  prop->add_option("--size", p->size, "Box X,Y,Z or plate W,H in metres (default 0.3 each)");
  prop->add_option("--tag-size", p->tag_size_m, "Tag black-border edge, metres")->capture_default_str();
  prop->add_option("--family", p->family, "AprilTag family")->capture_default_str();
  prop->add_option("--first-id", p->first_id, "First tag id")->capture_default_str();
  prop->add_option("--faces", p->faces, "Box faces to tag, in tag-id order")->capture_default_str();
  prop->add_option("--grid", p->grid, "Plate: ROWSxCOLS tags")->capture_default_str();
  prop->add_option("--out", p->out, "props.json to write")->required();
  prop->add_flag("--append", p->append, "Add the prop to an existing props.json");
  prop->add_option("--sheets", p->sheets, "Folder for printable tag sheets (PNG at --dpi, SVG in mm)");
  prop->add_option("--dpi", p->dpi, "Sheet resolution")->capture_default_str();
  prop->add_flag("--json", p->json, "Print a JSON summary on stdout");

  CLI::App* cam = cmd->add_subcommand("camera", "Track one camera's pose per frame from studio tags fixed in the world");
  cam->add_option("--take", c->take, "Take folder (cams/: a sequence or video per camera; docs/formats.md \"Take folder\")")->required();
  cam->add_option("--rig", c->rig, "rig.json (the camera's intrinsics)")->required();
  cam->add_option("--tags", c->tags, "props.json whose props carry T_world_prop (studio tags)")->required();
  cam->add_option("--camera", c->camera, "Camera to track")->capture_default_str();
  cam->add_option("--out", c->out, "Output folder: camera_poses.jsonl")->required();
  cam->add_option("--truth", c->truth, "JSON lines {frame, T_world_cam} (truth/main_poses.jsonl): report errors");
  cam->add_option("--frames", c->frames, "Frames A:B, A:, :B or A");
  cam->add_option("--fps", c->fps, "Frame rate (default: take.json's, else 24)");
  cam->add_option("--decimate", c->decimate, "libapriltag quad_decimate")->capture_default_str();
  cam->add_option("--sigma", c->sigma, "Blur before the quad search: auto (from the frames' noise) or pixels")
      ->capture_default_str();
  cam->add_flag("--no-filter", c->no_filter, "Report the per-frame solve unfiltered");
  cam->add_flag("--not-srgb", c->not_srgb, "8-bit images are linear, not sRGB-encoded");
  cam->add_flag("--json", c->json, "Print a JSON summary on stdout");
  cam->add_flag("--quiet", c->quiet, "No progress line");

  return [a, p, c, prop, cam]() {
    if (prop->parsed()) return runProp(*p);
    if (cam->parsed()) return runCamera(*c);
    return runTrack(*a);
  };
}

}  // namespace previz::app
