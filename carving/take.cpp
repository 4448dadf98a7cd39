// Reading a take for carving (see take.h).
#include "carving/take.h"

#include <algorithm>
#include <fstream>
#include <set>
#include <sstream>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/camera_io.h"
#include "core/error.h"
#include "core/io.h"
#include "core/names.h"
#include "core/pose_lines.h"

namespace previz::carving {
namespace fs = std::filesystem;

namespace {

ErrorContext context(const fs::path& file, const std::string& field = {}) {
  ErrorContext c;
  c.file = file.string();
  c.field = field;
  return c;
}

// Frame numbers of the %06d.png mattes in a folder.
void collectMaskFrames(const fs::path& dir, std::set<int>& frames) {
  static const take::SequencePattern kMasks = *take::parsePattern(std::string(kFramePattern) + ".png");
  for (long long f : take::framesOf(dir, kMasks)) frames.insert(static_cast<int>(f));
}

// Number of fields on the first camera row of a text rig (comments, blank lines and an
// optional leading count line skipped).
size_t rowFieldCount(const fs::path& path) {
  std::istringstream in(readTextFile(path));
  std::string line;
  bool first = true;
  while (std::getline(in, line)) {
    const size_t hash = line.find('#');
    if (hash != std::string::npos) line.resize(hash);
    std::istringstream fields(line);
    std::vector<std::string> tok;
    for (std::string t; fields >> t;) tok.push_back(t);
    if (tok.empty()) continue;
    if (first && tok.size() == 1) {  // the camera count line of Middlebury's files
      first = false;
      continue;
    }
    return tok.size();
  }
  return 0;
}

}  // namespace

Take::Take(const TakeSource& source) : source_(source) {
  std::error_code ec;
  if (source_.take_dir.empty() || !fs::is_directory(source_.take_dir, ec))
    throw Error("take folder not found", context(source_.take_dir, "--take"));
  if (source_.rig_path.empty()) throw Error("no rig file given", context({}, "--rig"));
  if (!fs::is_regular_file(source_.rig_path, ec))
    throw Error("rig file not found", context(source_.rig_path, "--rig"));
  if (!source_.masks_dir.empty() && !fs::is_directory(source_.masks_dir, ec))
    throw Error("masks folder not found", context(source_.masks_dir, "--masks"));

  if (source_.rig_path.extension() == ".json") {
    rig_ = readRig(source_.rig_path);
    rig_format_ = "rig.json";
  } else {
    // The rows carry no size; it does not enter the decomposition, so read with a placeholder
    // and give each camera the size of its own images below.
    const size_t fields = rowFieldCount(source_.rig_path);
    if (fields == 13) {
      rig_ = readProjectionRows(source_.rig_path, 1, 1);
      rig_format_ = "projection rows";
    } else if (fields == 22) {
      rig_ = readKRtRows(source_.rig_path, 1, 1);
      rig_format_ = "K R t rows";
    } else {
      throw Error("not a rig: expected rig.json, or rows of 13 fields (name p11..p34) or 22 "
                  "fields (name K R t); the first row has " + std::to_string(fields),
                  context(source_.rig_path, "row"));
    }
  }
  if (rig_.cameras.empty()) throw Error("the rig has no cameras", context(source_.rig_path));

  take::TakeOptions streams;
  for (const RigCamera& rc : rig_.cameras) streams.cameras.push_back(rc.camera.name);
  streams_ = std::make_shared<const take::Take>(source_.take_dir, streams);
  std::set<int> frames(streams_->frames().begin(), streams_->frames().end());
  if (hasMasks())
    for (const RigCamera& rc : rig_.cameras) collectMaskFrames(source_.masks_dir / rc.camera.name, frames);
  const nlohmann::json& j = streams_->takeJson();
  const fs::path take_json = source_.take_dir / "take.json";
  if (j.contains("camera_gains") && j["camera_gains"].is_object())
    for (const auto& [name, g] : j["camera_gains"].items()) {
      if (!g.is_number() || !(g.get<double>() > 0))
        throw Error("camera_gains: the gain of '" + name + "' must be a number > 0",
                    context(take_json, "camera_gains"));
      gains_[name] = g.get<double>();
    }
  frames_.assign(frames.begin(), frames.end());
  bool live = false;  // live cameras have no frames on disk (take/live.h)
  for (const RigCamera& rc : rig_.cameras) live = live || streams_->stream(rc.camera.name).kind == take::SourceKind::kLive;
  if (frames_.empty() && !live) {
    std::string why;
    for (const RigCamera& rc : rig_.cameras) {
      const take::CameraStream& s = streams_->stream(rc.camera.name);
      if (!s.usable()) why += (why.empty() ? "" : "; ") + rc.camera.name + ": " + s.unusable;
    }
    throw Error("no frames: no rig camera has a readable stream (" + std::to_string(rig_.cameras.size()) +
                    " cameras; take/take.h: cams/<camera>/ sequences, cams/<camera>.mkv|.mov|..., take.json "
                    "\"sources\")" + (hasMasks() ? " and no <masks>/<camera>/%06d.png" : "") +
                    (why.empty() ? "" : ": " + why),
                context(source_.take_dir, "--take"));
  }

  if (rig_format_ != "rig.json") {
    for (RigCamera& rc : rig_.cameras) {
      const std::string& name = rc.camera.name;
      const take::CameraStream& s = streams_->stream(name);
      cv::Size size(s.usable() ? s.width : 0, s.usable() ? s.height : 0);
      if (size.width <= 0 && hasMasks()) {
        for (int f : frames_) {
          const fs::path p = maskPath(name, f);
          if (!fs::is_regular_file(p, ec)) continue;
          try {
            size = readImage(p).size();
            break;
          } catch (const Error&) {
            // Not readable: the next frame's mask may be.
          }
        }
      }
      if (size.width <= 0) {
        ErrorContext c = context(source_.rig_path, "width/height");
        c.camera = name;
        throw Error("no readable frame of this camera in the take gives its image size", c);
      }
      rc.camera.width = size.width;
      rc.camera.height = size.height;
    }
  }

  for (const RigCamera& rc : rig_.cameras)
    if (rc.role == kMainRole) main_name_ = rc.camera.name;
  if (!source_.main_poses.empty()) {
    if (main_name_.empty())
      throw Error("main camera poses given but the rig has no camera with role 'main'",
                  context(source_.main_poses, "--main-poses"));
    if (!fs::is_regular_file(source_.main_poses, ec))
      throw Error("main camera poses file not found", context(source_.main_poses, "--main-poses"));
    main_poses_ = readPoseLines(source_.main_poses, "T_world_cam", &main_lost_);
  }
}

std::string Take::source(const std::string& camera, int frame) const {
  return streams_->has(camera) ? streams_->describe(camera, frame) : "cams/" + camera;
}

fs::path Take::maskPath(const std::string& camera, int frame) const {
  return source_.masks_dir / camera / (frameStem(frame) + ".png");
}

cv::Mat Take::cleanPlate(const std::string& camera) const {
  const cv::Mat plate = streams_->cleanPlate(camera);
  const RigCamera& rc = rig_.at(camera);
  if (!plate.empty() && (plate.cols != rc.camera.width || plate.rows != rc.camera.height)) {
    ErrorContext c = context(source_.take_dir / "clean");
    c.camera = camera;
    throw Error("clean plate is " + std::to_string(plate.cols) + "x" + std::to_string(plate.rows) +
                    ", the camera " + std::to_string(rc.camera.width) + "x" + std::to_string(rc.camera.height),
                c);
  }
  return plate;
}

namespace {

// One camera's matte for one frame.
CameraFrame readMaskFile(const RigCamera& rc, int frame, const fs::path& path) {
  CameraFrame out;
  out.camera = rc.camera.name;
  out.frame = frame;
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) {
    out.dropped = "missing mask " + path.string();
    return out;
  }
  cv::Mat image;
  try {
    image = readImage(path, cv::IMREAD_GRAYSCALE);
  } catch (const Error& e) {
    out.dropped = std::string("unreadable mask (corrupt or truncated?): ") + e.what();
    return out;
  }
  if (image.cols != rc.camera.width || image.rows != rc.camera.height) {
    out.dropped = "mask is " + std::to_string(image.cols) + "x" + std::to_string(image.rows) + ", the rig says " +
                  std::to_string(rc.camera.width) + "x" + std::to_string(rc.camera.height) + ": " + path.string();
    return out;
  }
  cv::threshold(image, out.mask, 127, 255, cv::THRESH_BINARY);
  return out;
}

}  // namespace

// One camera's plate for one frame through the take model, checked against the rig's size.
CameraFrame Take::plate(const RigCamera& rc, int frame) const {
  CameraFrame out;
  out.camera = rc.camera.name;
  out.frame = frame;
  const take::CameraImage img = streams_->read(rc.camera.name, frame);
  if (!img.ok()) {
    out.dropped = img.dropped;
    return out;
  }
  if (img.image.cols != rc.camera.width || img.image.rows != rc.camera.height) {
    out.dropped = "frame is " + std::to_string(img.image.cols) + "x" + std::to_string(img.image.rows) +
                  ", the rig says " + std::to_string(rc.camera.width) + "x" + std::to_string(rc.camera.height) +
                  ": " + img.source;
    return out;
  }
  out.image = img.image;
  return out;
}

CameraFrame Take::read(const std::string& camera, int frame) const {
  const RigCamera& rc = rig_.at(camera);
  if (CameraFrame lost = unposed(camera, frame); !lost.ok()) return lost;
  return hasMasks() ? readMaskFile(rc, frame, maskPath(camera, frame)) : plate(rc, frame);
}

CameraFrame Take::unposed(const std::string& camera, int frame) const {
  CameraFrame out;
  out.camera = camera;
  out.frame = frame;
  const auto it = camera == main_name_ ? main_lost_.find(frame) : main_lost_.end();
  if (it != main_lost_.end())
    out.dropped = "no pose at this frame in " + source_.main_poses.string() + " (" + it->second + ")";
  return out;
}

CameraFrame Take::readPlate(const std::string& camera, int frame) const {
  if (CameraFrame lost = unposed(camera, frame); !lost.ok()) return lost;
  return plate(rig_.at(camera), frame);
}

double Take::gain(const std::string& camera) const {
  const auto it = gains_.find(camera);
  return it == gains_.end() ? 0.0 : it->second;
}

RigCamera Take::cameraAt(const std::string& camera, int frame) const {
  RigCamera rc = rig_.at(camera);
  if (camera == main_name_) {
    const auto it = main_poses_.find(frame);
    if (it != main_poses_.end()) rc.T_world_cam = it->second;
  }
  return rc;
}

}  // namespace previz::carving
