// `previz track` and `previz track camera` over a take folder (see run.h).
#include "tracking/run.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>

#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/io.h"
#include "core/names.h"
#include "core/stats.h"
#include "core/stopwatch.h"
#include "core/units.h"
#include "take/take.h"

namespace fs = std::filesystem;

namespace previz::tracking {

namespace {

double maxOf(const std::vector<double>& v) { return v.empty() ? 0 : *std::max_element(v.begin(), v.end()); }

// The take's rate: the option when given, else the take model's (take.json, a video's, 24).
double takeFps(const take::Take& take, double given) { return given > 0 ? given : take.fps(); }

std::vector<int> selectFrames(const std::vector<int>& all, const TrackRunOptions& o) {
  std::vector<int> out;
  for (int f : all)
    if (f >= o.first_frame && (o.end_frame < 0 || f < o.end_frame)) out.push_back(f);
  return out;
}

}  // namespace

void TrackRunOptions::validate() const {
  tracker.validate();
  ErrorContext c;
  if (out.empty()) {
    c.field = "--out";
    throw Error("track: an output folder is required", c);
  }
  if (first_frame < 0 || (end_frame >= 0 && end_frame <= first_frame)) {
    c.field = "--frames";
    throw Error("track: frames must be A:B with 0 <= A < B", c);
  }
  if (shard_count < 1 || shard_index < 0 || shard_index >= shard_count) {
    c.field = "--shard";
    throw Error("track: shard must be i/n with 0 <= i < n", c);
  }
  if (frame_files && !udp.empty()) {
    c.field = "--udp";
    throw Error("track: frame files are not streamed (frames may be kept from an earlier run)", c);
  }
  if (fps < 0) {
    c.field = "--fps";
    throw Error("track: fps must be > 0", c);
  }
  if (!udp.empty()) parseHostPort(udp);
}

std::map<int, std::map<int, Pose>> readPropTruth(const fs::path& path) {
  std::map<int, std::map<int, Pose>> out;
  const std::string expected = "{\"frame\", \"props\": [{\"id\", \"T_world_prop\"}]}";
  forEachFrameLine(path, "props", expected, [&](const nlohmann::json& j, const ErrorContext& c) {
    if (!j["props"].is_array()) throw Error("expected " + expected, c);
    for (const auto& p : j["props"]) {
      if (!p.is_object() || !p.contains("id") || !p["id"].is_number_integer() || !jsonInt(p["id"]) ||
          !p.contains("T_world_prop"))
        throw Error("expected props entries {\"id\", \"T_world_prop\"}", c);
      out[j["frame"].get<int>()][p["id"].get<int>()] = poseFromJson(p["T_world_prop"], "T_world_prop");
    }
  });
  return out;
}

TrackRunSummary runTrack(const TrackInput& in, const TrackRunOptions& o,
                         const std::function<void(int, int)>& progress) {
  o.validate();
  const Stopwatch t0;
  const Rig rig = readRig(in.rig);
  const PropSet props = readProps(in.props);
  std::vector<RigCamera> cams;
  if (in.cameras.empty()) {
    cams = rig.cameras;
  } else {
    for (const std::string& name : in.cameras) cams.push_back(rig.at(name));
  }
  std::map<int, Pose> moving;
  std::map<int, std::string> moving_lost;
  int moving_index = -1;
  if (!in.main_poses.empty()) {
    moving = readPoseLines(in.main_poses, "T_world_cam", &moving_lost);
    for (size_t c = 0; c < cams.size(); ++c)
      if (cams[c].camera.name == in.moving_camera) moving_index = static_cast<int>(c);
  }
  std::map<int, std::map<int, Pose>> truth;
  if (!in.truth.empty()) truth = readPropTruth(in.truth);

  TrackRunSummary s;
  for (const RigCamera& rc : cams) s.cameras.push_back(rc.camera.name);
  take::TakeOptions streams;
  streams.cameras = s.cameras;
  const take::Take take(in.take, streams);
  const std::vector<int> in_range = selectFrames(take.frames(), o);
  if (in_range.empty()) {
    ErrorContext c;
    c.file = (in.take / "cams").string();
    throw Error("track: no frames for the selected cameras and frames (take/take.h: cams/<camera>/ sequences, "
                "cams/<camera>.mkv|.mov|..., take.json \"sources\")", c);
  }
  std::vector<int> frames;
  for (size_t i = 0; i < in_range.size(); ++i)
    if (static_cast<int>(i % static_cast<size_t>(o.shard_count)) == o.shard_index) frames.push_back(in_range[i]);
  s.selected = frames;
  const double fps = takeFps(take, o.fps);
  PropTracker tracker(cams, props, o.tracker);
  std::unique_ptr<PoseStreamer> streamer;
  if (!o.udp.empty()) {
    const auto [host, port] = parseHostPort(o.udp);
    streamer = std::make_unique<PoseStreamer>(host, port, o.protocol, fps, "previz:" + in.take.filename().string());
  }

  struct Acc {
    std::vector<double> sigma, pos, rot, mpos, mrot;
  };
  std::map<int, Acc> acc;
  std::string lines;
  const int n_cams = static_cast<int>(cams.size());
  for (size_t i = 0; i < frames.size(); ++i) {
    const int f = frames[i];
    fs::path frame_file;
    if (o.frame_files) {
      frame_file = o.out / "frames" / (frameStem(f) + ".json");
      std::error_code ec;
      if (fs::is_regular_file(frame_file, ec)) {
        const nlohmann::json kept = nlohmann::json::parse(readTextFile(frame_file), nullptr, false);
        if (!kept.is_discarded() && kept.is_object() && kept.value("frame", -1) == f && kept.contains("props")) {
          ++s.kept;  // not in s.frames: the summary covers the frames tracked by this run
          if (progress) progress(static_cast<int>(i + 1), static_cast<int>(frames.size()));
          continue;
        }
      }
      tracker.reset();
    }
    std::vector<cv::Mat> images(cams.size());
    std::vector<std::string> failures(cams.size());
#pragma omp parallel for schedule(dynamic)
    for (int c = 0; c < n_cams; ++c) {
      const RigCamera& rc = cams[static_cast<size_t>(c)];
      const take::CameraImage img = take.read(rc.camera.name, f);
      if (!img.ok()) {
        failures[static_cast<size_t>(c)] = img.dropped;
      } else if (img.image.cols != rc.camera.width || img.image.rows != rc.camera.height) {
        failures[static_cast<size_t>(c)] = "image is " + std::to_string(img.image.cols) + "x" +
                                           std::to_string(img.image.rows) + ", the rig's camera is " +
                                           std::to_string(rc.camera.width) + "x" +
                                           std::to_string(rc.camera.height) + ": " + img.source;
      } else {
        images[static_cast<size_t>(c)] = img.image;
      }
    }
    // The moving camera where its poses file has it; where the file marks it lost (or its frame
    // bad) it has no pose and sits the frame out; frames the file does not list, the rig's pose.
    if (moving_index >= 0) {
      const size_t m = static_cast<size_t>(moving_index);
      const auto it = moving.find(f);
      const auto lost = moving_lost.find(f);
      tracker.setCameraPose(moving_index, it != moving.end() ? it->second : cams[m].T_world_cam);
      if (lost != moving_lost.end() && failures[m].empty()) {
        images[m].release();
        failures[m] = "no pose at this frame in " + in.main_poses.string() + " (" + lost->second + ")";
      }
    }
    for (int c = 0; c < n_cams; ++c)
      if (!failures[static_cast<size_t>(c)].empty())
        s.camera_failures.push_back("camera '" + cams[static_cast<size_t>(c)].camera.name + "': frame " +
                                    std::to_string(f) + ": " + failures[static_cast<size_t>(c)]);
    // No camera has an image: the frame failed (no line, no frame file: a resume tries it
    // again); the tracks do not bridge it.
    if (std::all_of(images.begin(), images.end(), [](const cv::Mat& m) { return m.empty(); })) {
      s.failed_frames.push_back(f);
      tracker.reset();
      if (progress) progress(static_cast<int>(i + 1), static_cast<int>(frames.size()));
      continue;
    }
    const Stopwatch t_track;
    const TrackFrame r = tracker.track(f, f / fps, images);
    s.track_ms += t_track.ms();
    if (streamer) streamer->send(r);
    if (o.frame_files) writeFileAtomic(frame_file, trackFrameToJson(r).dump() + "\n");
    else lines += trackFrameToJson(r).dump() + "\n";
    ++s.frames;
    s.unknown_tags += r.unknown_tags;
    s.full_frames += r.full_frame ? 1 : 0;
    s.rescanned_frames += r.rescanned_cameras > 0 ? 1 : 0;
    for (const CameraSearch& cs : r.search)
      if (!cs.failure.empty() && cs.failure != "no image")
        s.camera_failures.push_back("camera '" + cs.camera + "': frame " + std::to_string(f) + ": " + cs.failure);
    for (const PropResult& p : r.props) {
      Acc& a = acc[p.id];
      if (!p.tracked) continue;
      a.sigma.push_back(1e3 * p.measured.sigma_position_m);
      const auto tf = truth.find(f);
      if (tf == truth.end()) continue;
      const auto tp = tf->second.find(p.id);
      if (tp == tf->second.end()) continue;
      a.pos.push_back(1e3 * translationDistance(p.T_world_prop, tp->second));
      a.rot.push_back(degrees(rotationDistance(p.T_world_prop, tp->second)));
      a.mpos.push_back(1e3 * translationDistance(p.measured.T, tp->second));
      a.mrot.push_back(degrees(rotationDistance(p.measured.T, tp->second)));
    }
    if (progress) progress(static_cast<int>(i + 1), static_cast<int>(frames.size()));
  }
  for (const PropDef& def : props.props) {
    if (def.T_world_prop) continue;
    PropRunSummary ps;
    ps.id = def.id;
    ps.name = def.name;
    const Acc& a = acc[def.id];
    ps.tracked = static_cast<int>(a.sigma.size());
    ps.lost = s.frames - ps.tracked;
    ps.median_sigma_position_mm = median(a.sigma);
    ps.truth_frames = static_cast<int>(a.pos.size());
    ps.median_position_error_mm = median(a.pos);
    ps.max_position_error_mm = maxOf(a.pos);
    ps.median_rotation_error_deg = median(a.rot);
    ps.max_rotation_error_deg = maxOf(a.rot);
    ps.median_measured_position_error_mm = median(a.mpos);
    ps.median_measured_rotation_error_deg = median(a.mrot);
    s.props.push_back(ps);
  }
  if (streamer) {
    s.packets_sent = streamer->sent();
    s.packets_failed = streamer->failed();
  }
  if (o.frame_files) {
    s.poses = o.out / "frames";
  } else {
    s.poses = o.out / "poses.jsonl";
    writeFileAtomic(s.poses, lines);
  }
  s.ms = t0.ms();
  return s;
}

CameraTrackSummary runTrackCamera(const CameraTrackInput& in, const TrackRunOptions& o,
                                  const std::function<void(int, int)>& progress) {
  o.validate();
  const Stopwatch t0;
  const Rig rig = readRig(in.rig);
  const RigCamera& rc = rig.at(in.camera);
  const PropSet set = readProps(in.tags);
  // Every studio tag in one world-fixed set.
  PropDef studio;
  studio.name = "studio tags";
  studio.T_world_prop = Pose::Identity();
  for (const PropDef& p : set.props) {
    if (!p.T_world_prop) continue;
    for (TagDef t : p.tags) {
      t.T_prop_tag = *p.T_world_prop * t.T_prop_tag;
      studio.tags.push_back(t);
    }
  }
  if (studio.tags.empty()) {
    ErrorContext c;
    c.file = in.tags.string();
    throw Error("track camera: no prop with T_world_prop (studio tags fixed in the world) in this file", c);
  }
  PropSet lookup;
  lookup.props.push_back(studio);
  std::map<int, Pose> truth;
  if (!in.truth.empty()) truth = readPoseLines(in.truth);
  take::TakeOptions streams;
  streams.cameras = {in.camera};
  const take::Take take(in.take, streams);
  const std::vector<int> frames = selectFrames(take.frames(), o);
  if (frames.empty()) {
    ErrorContext c;
    c.file = (in.take / "cams" / in.camera).string();
    c.camera = in.camera;
    const take::CameraStream& st = take.stream(in.camera);
    throw Error("track camera: no frames" + (st.usable() ? std::string() : ": " + st.unusable), c);
  }
  const double fps = takeFps(take, o.fps);
  DetectorOptions d = o.tracker.detector;
  const auto it = o.tracker.per_camera.find(in.camera);
  if (it != o.tracker.per_camera.end()) d = it->second;
  d.families = set.families();
  TagDetector detector(d);
  PoseFilter filter(o.tracker.filter);
  CameraTrackSummary s;
  std::vector<double> sigma, pos, rot;
  std::string lines;
  bool live = false;
  for (size_t i = 0; i < frames.size(); ++i) {
    const int f = frames[i];
    // A frame that cannot be read, or is not the rig camera's size, is reported and skipped: the
    // take goes on, and the pose after it starts afresh (no filter across the gap).
    const take::CameraImage frame = take.read(in.camera, f);
    const std::string file = (in.take / frame.source).string();
    const cv::Mat& img = frame.image;
    std::string bad = frame.dropped;
    if (bad.empty() && (img.cols != rc.camera.width || img.rows != rc.camera.height))
      bad = "image is " + std::to_string(img.cols) + "x" + std::to_string(img.rows) + ", the rig's camera is " +
            std::to_string(rc.camera.width) + "x" + std::to_string(rc.camera.height);
    if (!bad.empty()) {
      live = false;
      ++s.frames;
      s.bad_frames.push_back(f);
      lines += nlohmann::json{{"frame", f}, {"time_s", f / fps}, {"camera", in.camera}, {"state", "bad frame"},
                              {"file", file}, {"reason", bad}}.dump() + "\n";
      if (progress) progress(static_cast<int>(i + 1), static_cast<int>(frames.size()));
      continue;
    }
    std::vector<TagObservation> obs;
    int unknown = 0;
    for (const TagDetection& det : detector.detect(img)) {
      const auto owner = lookup.findTag(det.family, det.id);
      if (!owner) {
        ++unknown;
        continue;
      }
      obs.push_back(makeTagObservation(rc.camera, 0, owner->second, det.corners_px));
    }
    const double t = f / fps;
    Pose prior;
    const bool has_prior = live && filter.initialised();
    if (has_prior) prior = filter.predict(t);
    const PoseEstimate e = obs.empty() ? PoseEstimate{} : solveCameraPose(rc.camera, studio, obs, o.tracker.solve,
                                                                          has_prior ? &prior : nullptr);
    nlohmann::json j = {{"frame", f}, {"time_s", t}, {"camera", in.camera}, {"unknown_tags", unknown}};
    ++s.frames;
    if (e.ok && e.sigma_position_m <= o.tracker.max_sigma_position_m) {
      if (!live) filter.reset();
      const Pose T = o.tracker.filter_enabled ? filter.update(t, e.T, e.covariance) : e.T;
      live = true;
      ++s.solved;
      j["state"] = "tracked";
      j["T_world_cam"] = poseToJson(T);
      j["T_world_cam_measured"] = poseToJson(e.T);
      j["sigma_position_mm"] = 1e3 * e.sigma_position_m;
      j["sigma_rotation_deg"] = degrees(e.sigma_rotation_rad);
      j["rms_px"] = e.rms_px;
      j["tags"] = e.tags;
      j["corners"] = e.inliers;
      sigma.push_back(1e3 * e.sigma_position_m);
      const auto tt = truth.find(f);
      if (tt != truth.end()) {
        pos.push_back(1e3 * translationDistance(e.T, tt->second));
        rot.push_back(degrees(rotationDistance(e.T, tt->second)));
      }
    } else {
      live = false;
      j["state"] = "lost";
      j["reason"] = obs.empty() ? std::string("no studio tag seen") : e.failure.empty() ? "pose too uncertain" : e.failure;
    }
    lines += j.dump() + "\n";
    if (progress) progress(static_cast<int>(i + 1), static_cast<int>(frames.size()));
  }
  s.median_sigma_position_mm = median(sigma);
  s.truth_frames = static_cast<int>(pos.size());
  s.median_position_error_mm = median(pos);
  s.max_position_error_mm = maxOf(pos);
  s.median_rotation_error_deg = median(rot);
  s.max_rotation_error_deg = maxOf(rot);
  s.poses = o.out / "camera_poses.jsonl";
  writeFileAtomic(s.poses, lines);
  s.ms = t0.ms();
  return s;
}

}  // namespace previz::tracking
