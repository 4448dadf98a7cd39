#include "multicam/pipeline.h"

#include <algorithm>
#include <cmath>

#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/io.h"
#include "core/names.h"
#include "core/stopwatch.h"

namespace previz::multicam {
namespace fs = std::filesystem;

namespace {

// What identifies a detection run: a cached observations file is reused only when all of it
// matches (take, cameras, boards, frames on disk and their times, detector settings).
nlohmann::json cacheKey(const RigTake& t, const calib::DetectOptions& detect) {
  nlohmann::json files = nlohmann::json::object();
  for (const std::string& name : t.cameras) {
    const fs::path dir = t.take / "cams" / name;
    long long count = 0, newest = 0;
    if (fs::is_directory(dir)) {
      for (const auto& entry : fs::directory_iterator(dir)) {
        ++count;
        newest = std::max<long long>(newest, entry.last_write_time().time_since_epoch().count());
      }
    }
    files[name] = {count, newest};
  }
  nlohmann::json floor_json;
  if (t.floor) floor_json = {{"board", boardToJson(t.floor->board)}, {"frames", t.floor->frames}};
  return {{"take", fs::weakly_canonical(t.take).string()},
          {"cameras", t.cameras},
          {"board", boardToJson(t.board)},
          {"floor", floor_json},
          {"files", files},
          {"linear_light", detect.linear_light}};
}

}  // namespace

void RigPipelineOptions::validate() const {
  calib.validate();
  sync.validate();
}

Rig initialRig(const RigTake& take, const RigObservations& obs, std::vector<std::string>* log) {
  if (take.known.size() != take.cameras.size())
    throw Error("rig pipeline: " + std::to_string(take.known.size()) + " known intrinsics for " +
                std::to_string(take.cameras.size()) + " cameras");
  Rig rig;
  for (size_t i = 0; i < take.cameras.size(); ++i) {
    const std::string& name = take.cameras[i];
    const CameraDetections* d = obs.find(name);
    const cv::Size size = d ? d->image_size : cv::Size();
    ErrorContext context;
    context.camera = name;
    RigCamera rc;
    if (take.known[i]) {
      rc = *take.known[i];
      if (!size.empty() && (size.width != rc.camera.width || size.height != rc.camera.height)) {
        // A lens table's entry for another image size (same aspect) is scaled; anything else
        // is intrinsics for another camera or mode.
        const double sx = static_cast<double>(size.width) / rc.camera.width;
        const double sy = static_cast<double>(size.height) / rc.camera.height;
        if (rc.role != kMainRole || std::abs(sx - sy) >= 1e-9) {
          throw Error("rig: the intrinsics are for " + std::to_string(rc.camera.width) + "x" +
                          std::to_string(rc.camera.height) + " but the take's images are " +
                          std::to_string(size.width) + "x" + std::to_string(size.height),
                      context);
        }
        if (log)
          log->push_back(name + ": lens table at " + std::to_string(rc.camera.width) + "x" +
                         std::to_string(rc.camera.height) + ", take at " + std::to_string(size.width) + "x" +
                         std::to_string(size.height) + ": intrinsics scaled");
        const std::string keep = rc.camera.name;
        rc.camera = rc.camera.scaled(sx, sy);
        rc.camera.name = keep;
      }
    } else {
      if (size.empty()) throw Error("rig: no readable image to size a first guess of the intrinsics from", context);
      rc.camera.name = name;
      rc.camera.width = size.width;
      rc.camera.height = size.height;
      rc.camera.fx = rc.camera.fy = size.width;
      rc.camera.cx = (size.width - 1) / 2.0;
      rc.camera.cy = (size.height - 1) / 2.0;
      rc.role = name == take.main_camera ? kMainRole : "witness";
      if (log)
        log->push_back(name + ": no intrinsics given; starting the estimate from fx = fy = " +
                       std::to_string(size.width) + " px");
    }
    rc.T_world_cam = Pose::Identity();
    rig.cameras.push_back(rc);
  }
  return rig;
}

RigPipelineResult solveRigTake(const RigObservations& obs, const Rig& initial, const RigPipelineOptions& options) {
  options.validate();
  RigPipelineResult out;
  out.initial = initial;
  out.calib = calibrateRig(obs, initial, options.calib);
  // The sync check needs every camera's intrinsics and pose: the solved rig's.
  out.sync = checkSync(obs, out.calib.rig, options.sync);
  return out;
}

TakeDetections detectRigTake(const RigTake& take, const DetectTakeOptions& detect, const fs::path& cache,
                             const std::function<void(const DetectProgress&)>& progress) {
  TakeDetections out;
  const nlohmann::json key = cacheKey(take, detect.detect);
  if (!cache.empty() && fs::exists(cache)) {
    try {
      const nlohmann::json j = readJsonFile(cache);
      if (j.is_object() && j.contains("cache_key") && j.at("cache_key") == key) {
        out.observations = observationsFromJson(j, cache.string());
        out.cached = true;
        out.log.push_back("board detections from " + cache.string() + " (take unchanged)");
        return out;
      }
      out.log.push_back(cache.string() + " is for another take or settings; detecting again");
    } catch (const Error& e) {
      // A cache is never worth failing for: it is rewritten below.
      out.log.push_back("cannot use " + cache.string() + " (" + e.what() + "); detecting again");
    }
  }
  const Stopwatch start;
  out.observations =
      detectTake(take.take, take.cameras, take.board, take.floor ? &*take.floor : nullptr, detect, progress);
  out.detect_s = start.seconds();
  if (!cache.empty()) {
    nlohmann::json j = observationsToJson(out.observations);
    j["cache_key"] = key;
    writeJsonAtomic(cache, j, -1);
  }
  return out;
}

RigPipelineResult calibrateRigTake(const RigTake& take, const RigPipelineOptions& options,
                                   const std::function<void(const DetectProgress&)>& progress) {
  options.validate();
  std::vector<std::string> log;
  if (!take.floor) log.push_back("no floor frames: world frame = " + take.cameras.front());
  // 1. Board detections (or the cache), 2. the initial rig, 3. solve and sync check.
  TakeDetections detections = detectRigTake(take, options.detect, options.observations_cache, progress);
  log.insert(log.end(), detections.log.begin(), detections.log.end());
  const Rig initial = initialRig(take, detections.observations, &log);
  RigPipelineResult out = solveRigTake(detections.observations, initial, options);
  out.observations = std::move(detections.observations);
  out.cached = detections.cached;
  out.detect_s = detections.detect_s;
  out.log = std::move(log);
  return out;
}

}  // namespace previz::multicam
