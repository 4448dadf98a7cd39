// A live frame's inputs: a take folder or live sources (live/inputs.h).
#include "live/inputs.h"

#include <omp.h>
#include <time.h>

#include <algorithm>
#include <cstdint>
#include <cmath>
#include <sstream>

#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/io.h"
#include "core/pose.h"

namespace previz::live {

TakeReader::TakeReader(const carving::Take& take, const FrameLoop& loop, const TakeInputOptions& options)
    : take_(take), carve_names_(loop.carveCameras()), main_name_(loop.mainCamera()),
      cg_(loop.compositor().cg()), options_(options) {
  if (options_.main_lens) {
    const Camera& plate = take.rig().at(main_name_).camera;
    if (options_.main_lens->width != plate.width || options_.main_lens->height != plate.height) {
      ErrorContext c;
      c.camera = main_name_;
      c.field = "lens";
      throw Error("the lens state is for " + std::to_string(options_.main_lens->width) + "x" +
                      std::to_string(options_.main_lens->height) + " images, the main plate is " +
                      std::to_string(plate.width) + "x" + std::to_string(plate.height),
                  c);
    }
  }
  if (options_.tracker) clock_ = frameClock(take.streams(), main_name_);
  if (!options_.tracked_main_poses.empty()) {
    const std::string text = readTextFile(options_.tracked_main_poses);
    std::istringstream in(text);
    int line_no = 0;
    for (std::string line; std::getline(in, line);) {
      ++line_no;
      if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
      ErrorContext c;
      c.file = options_.tracked_main_poses.string();
      try {
        const nlohmann::json j = nlohmann::json::parse(line);
        tracked_[jsonInt(j.at("frame"), c)] = poseFromJson(j.at("T_main0_main"), "T_main0_main");
      } catch (const std::exception& e) {
        c.field = "line " + std::to_string(line_no);
        throw Error(std::string("bad tracked main pose: ") + e.what(), c);
      }
    }
  }
}

RigCamera TakeReader::mainAt(int frame) const {
  RigCamera rc = take_.cameraAt(main_name_, frame);
  if (options_.tracker) {
    if (options_.main_lens) {
      const std::string name = rc.camera.name;
      rc.camera = *options_.main_lens;
      rc.camera.name = name;
    }
    return options_.tracker->mainAt(frame, clock_.timeOf(frame), clock_.timecodeOf(frame), rc);
  }
  if (!options_.tracked_main_poses.empty()) {
    const auto it = tracked_.find(frame);
    if (it == tracked_.end()) {
      ErrorContext c;
      c.file = options_.tracked_main_poses.string();
      c.camera = main_name_;
      c.frame = frame;
      throw Error("no tracked pose of the main camera for this frame", c);
    }
    rc.T_world_cam = take_.rig().at(main_name_).T_world_cam * it->second;
  }
  if (options_.main_lens) {
    const std::string name = rc.camera.name;
    rc.camera = *options_.main_lens;
    rc.camera.name = name;
  }
  return rc;
}

void TakeReader::read(int frame, FrameState& s) const {
  s.frame = frame;
  const int n = static_cast<int>(carve_names_.size());
  s.witness_plates.assign(n, cv::Mat());
  s.dropped.assign(n, "");
  std::vector<carving::CameraFrame> frames(n + 1);
  std::vector<std::string> errors(n + 1);
#pragma omp parallel for schedule(dynamic)
  for (int i = 0; i <= n; ++i) {
    try {
      frames[i] = take_.read(i < n ? carve_names_[i] : main_name_, frame);
    } catch (const std::exception& e) {
      errors[i] = e.what();
    }
  }
  for (int i = 0; i < n; ++i) {
    if (!errors[i].empty()) s.dropped[i] = errors[i];
    else if (!frames[i].ok()) s.dropped[i] = frames[i].dropped;
    else s.witness_plates[i] = frames[i].image;
  }
  if (!errors[n].empty() || !frames[n].ok() || frames[n].image.empty()) {
    ErrorContext c;
    c.camera = main_name_;
    c.frame = frame;
    c.file = take_.source(main_name_, frame);
    throw Error("main plate unusable: " + (errors[n].empty() ? frames[n].dropped : errors[n]), c);
  }
  s.main_plate = frames[n].image;
  readCg(frame, s);
}

void TakeReader::readCg(int frame, FrameState& s) const {
  s.frame = frame;
  s.main = mainAt(frame);
  s.cg = composite::readCgFrame(options_.cg_dir.empty() ? take_.source().take_dir / "cg" : options_.cg_dir, frame,
                                cv::Size(cg_.width, cg_.height));
}

struct LiveReader::Source {
  std::unique_ptr<take::LiveStream> stream;
};

LiveReader::LiveReader(const FrameLoop& loop, const TakeReader& take, const LiveOptions& options)
    : take_(take), options_(options) {
  std::vector<std::string> names = loop.carveCameras();
  names.push_back(loop.mainCamera());
  for (const std::string& name : names) {
    // --live NAME=SOURCE first, else the take's own "live:" source (take.json "sources").
    std::string uri;
    if (const auto it = options.sources.find(name); it != options.sources.end()) {
      uri = it->second;
    } else if (const take::Take& streams = take.take().streams();
               streams.has(name) && streams.stream(name).kind == take::SourceKind::kLive) {
      uri = streams.stream(name).path.string();
    } else {
      ErrorContext c;
      c.camera = name;
      c.field = "--live";
      throw Error("live: no source for this camera (--live NAME=SOURCE, or take.json \"sources\": \"live:...\")", c);
    }
    auto src = std::make_unique<Source>();
    src->stream = std::make_unique<take::LiveStream>(name, uri);
    sources_.push_back(std::move(src));
  }
  fps_ = options.fps > 0 ? options.fps : sources_.back()->stream->fps();
  if (!(fps_ > 0) || !std::isfinite(fps_)) fps_ = 24;
}

LiveReader::~LiveReader() = default;

bool LiveReader::next(FrameState& s) {
  if (!started_) {
    since_start_.restart();
    started_ = true;
  }
  if (options_.pace) {
    // The frame the cameras are at now; the ones in between are dropped (grabbed, not decoded).
    const double elapsed_s = since_start_.seconds();
    const int now_frame = static_cast<int>(elapsed_s * fps_);
    while (next_frame_ < now_frame) {
      for (auto& src : sources_)
        if (!src->stream->grab()) return false;
      ++next_frame_;
      ++dropped_;
    }
  }
  const int n = static_cast<int>(sources_.size()) - 1;
  std::vector<cv::Mat> images(n + 1);
  for (int i = 0; i <= n; ++i)
    if (!sources_[i]->stream->read(images[i]) || images[i].empty()) return false;
  s.witness_plates.assign(images.begin(), images.begin() + n);
  s.dropped.assign(n, "");
  s.main_plate = images[n];
  take_.readCg(next_frame_, s);
  ++next_frame_;
  ++delivered_;
  return true;
}

}  // namespace previz::live
