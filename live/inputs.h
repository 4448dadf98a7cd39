#pragma once
// Where a live frame's inputs come from (live/frame_loop.h runs the frame): a take folder
// (TakeReader: plates, main camera pose and lens, CG frame) or live sources read in lock step
// (LiveReader: VideoCapture devices, files, streams; take/live.h).
#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "carving/take.h"
#include "core/camera.h"
#include "core/pose.h"
#include "core/rig.h"
#include "core/stopwatch.h"
#include "live/frame_loop.h"
#include "live/tracker.h"
#include "take/live.h"

namespace previz::live {

// Inputs of one frame from a take folder (carving/take.h: plates, rig, main poses) and its CG
// (composite/output.h readCgFrame).
struct TakeInputOptions {
  std::filesystem::path cg_dir;     // <take>/cg by default
  // The main camera's intrinsics for the current lens state (a lens-table entry, already at the
  // plate's size); nullopt = the rig's.
  std::optional<Camera> main_lens;
  // The camera tracker's poses of the main camera, JSON lines {"frame", "T_main0_main"}: its
  // motion from where it stood when the rig was calibrated (the tracker is zeroed there). When
  // given, T_world_main(f) = T_world_main(rig) T_main0_main(f), and every frame read must be
  // listed. That is how a rig previz calibrated itself, in its own world frame, meets a tracked
  // camera. Empty: the take's main poses (world poses, carving/take.h) or the rig's.
  std::filesystem::path tracked_main_poses;
  // The stage's camera tracker (live/tracker.h; `run --tracker`): when set, every frame's main
  // camera comes from it (pose, and lens when it holds a lens table) and a frame it has no pose
  // for is an Error naming the frame ("no tracker pose: ..."). Not owned; outlives the reader.
  // Frame f's instant is (f - the take's first frame) / the take's fps, and its timecode the
  // main camera's start timecode + that many frames (when the main stream has one).
  TrackerInput* tracker = nullptr;
};

class TakeReader {
 public:
  TakeReader(const carving::Take& take, const FrameLoop& loop, const TakeInputOptions& options);
  // The main camera at a frame: pose (see tracked_main_poses) and lens.
  RigCamera mainAt(int frame) const;
  // Reads every plate (in parallel over cameras) and the CG frame into s (stage outputs are
  // left as they are). A missing or bad witness frame drops that camera (s.dropped); a missing
  // main plate or CG frame throws Error naming the file and the frame.
  void read(int frame, FrameState& s) const;
  // The CG frame and the main camera of a frame whose plates came from elsewhere (live).
  void readCg(int frame, FrameState& s) const;
  const carving::Take& take() const { return take_; }

 private:
  const carving::Take& take_;
  std::vector<std::string> carve_names_;
  std::string main_name_;
  Camera cg_;
  TakeInputOptions options_;
  std::map<int, Pose> tracked_;
  FrameClock clock_;  // the frames' instants for the tracker
};

// Live input (take/live.h): one source per camera (a device index "0", a file, a network
// stream, or a GStreamer pipeline string; --live NAME=SOURCE, else the take's "live:" source in
// take.json "sources"), read in lock step; frame k of every source is frame k of the
// take (CG frame, main pose). With pacing the loop never falls behind: before each frame, every
// source is advanced to the frame the clock says the cameras are at now (fps), and the frames
// skipped are counted as dropped. Without pacing (files, tests) every frame is processed.
struct LiveOptions {
  std::map<std::string, std::string> sources;  // camera -> source; every carving camera and main
  bool pace = true;
  double fps = 0;  // camera rate for pacing; 0 = the main source's CAP_PROP_FPS (else 24)
};

class LiveReader {
 public:
  // Opens every source; throws Error naming the camera and the source when one cannot be
  // opened or a camera of the loop has no source.
  LiveReader(const FrameLoop& loop, const TakeReader& take, const LiveOptions& options);
  ~LiveReader();
  // The next frame to process into s (plates, CG, main camera); false at the end of a stream.
  bool next(FrameState& s);
  int delivered() const { return delivered_; }
  int dropped() const { return dropped_; }
  double fps() const { return fps_; }

 private:
  struct Source;
  std::vector<std::unique_ptr<Source>> sources_;  // carving cameras, then main
  const TakeReader& take_;
  LiveOptions options_;
  double fps_ = 24;
  int next_frame_ = 0, delivered_ = 0, dropped_ = 0;
  Stopwatch since_start_;  // restarted at the first frame
  bool started_ = false;
};

}  // namespace previz::live
