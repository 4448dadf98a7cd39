#pragma once
// PropTracker: the per-frame loop of prop tracking, with the state that must survive between
// frames (filters, last poses, ROI schedule) in one explicit object (STYLE.md rule 2).
// A frame: detect tags in every camera (OpenMP over cameras, one TagDetector each) — in the
// predicted image regions of tracked props, or the full frame on loss and every N frames, and
// again the full frame in the same frame when a tracked prop is not in its predicted regions —;
// map tag ids to props (ids of no prop are counted and ignored); solve each prop jointly over
// every camera (solve.h); filter (filter.h). A prop not found this frame is "lost" and carries no
// pose: a stale pose is never reported as live.
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>
#include <opencv2/core.hpp>

#include "core/rig.h"
#include "tracking/detect.h"
#include "tracking/filter.h"
#include "tracking/props.h"
#include "tracking/solve.h"

namespace previz::tracking {

struct TrackerOptions {
  DetectorOptions detector;                           // every camera (families: props.json's)...
  std::map<std::string, DetectorOptions> per_camera;  // ...unless overridden by camera name
  SolveOptions solve;
  FilterOptions filter;
  bool filter_enabled = true;
  bool roi = true;                  // search only predicted regions once a prop is tracked
  int full_frame_every = 30;        // and each camera's whole frame every N frames, staggered over
                                    // the cameras (0 = only on loss)
  double roi_margin_px = 24;        // around the projected tags of the predicted pose...
  double roi_margin_fraction = 0.3; // ...plus this fraction of the projected size
  double max_sigma_position_m = 0.05;  // a solve less certain than this is not a track
  int threads = 0;                  // OpenMP threads over cameras (0 = OpenMP's default)
  void validate() const;            // throws Error naming the field (and the camera)
};

struct CameraSearch {
  std::string camera;
  bool full_frame = false;          // this camera searched its whole frame
  std::vector<cv::Rect> rois;
  long long pixels = 0;             // searched
  int detections = 0;               // tags decoded (any id)
  // The detector's blur before the quad search, and the frame noise it was chosen from (grey
  // levels; -1 when the blur is fixed: DetectorOptions::auto_sigma off).
  double noise = -1;
  float blur = 0;
  std::string failure;              // e.g. missing image
};

struct PropResult {
  int id = 0;
  std::string name;
  bool tracked = false;             // false: lost, no pose
  Pose T_world_prop = Pose::Identity();      // filtered (= measured when the filter is off)
  PoseEstimate measured;            // the joint solve of this frame (measured.failure when lost)
  std::vector<std::string> cameras; // names of the cameras whose corners were used
  bool reacquired = false;          // tracked now, lost (or never seen) before, or found only by the
                                    // same frame's whole-frame search again (the filter restarts)
};

struct TrackFrame {
  int frame = 0;
  double time_s = 0;
  std::vector<PropResult> props;    // in PropSet order (carried props only)
  std::vector<CameraSearch> search; // per tracker camera
  int unknown_tags = 0;             // decoded tags that belong to no prop
  bool full_frame = false;          // every camera searched whole
  // Cameras that searched their whole frame again in this frame because a tracked prop was not
  // found in its predicted regions (their search holds the whole-frame search).
  int rescanned_cameras = 0;
  double detect_ms = 0, solve_ms = 0, total_ms = 0;
};

class PropTracker {
 public:
  // 'cameras': the cameras to track from (witness and main), with their poses; props with a
  // T_world_prop (studio tags) are not tracked.
  PropTracker(std::vector<RigCamera> cameras, PropSet props, const TrackerOptions& options);
  ~PropTracker();
  PropTracker(const PropTracker&) = delete;
  PropTracker& operator=(const PropTracker&) = delete;

  // images[i] is camera i's frame (8-bit grey or BGR; empty = no image this frame, reported).
  TrackFrame track(int frame, double time_s, const std::vector<cv::Mat>& images);
  // track() in three steps, for a caller that runs the cameras' searches among work of its own
  // in one pool of threads (the live loop searches while it keys, live/frame_loop.h); track() is
  // the three steps with the searches over OpenMP, and gives the same frame.
  //   begin(): checks the images and plans each camera's search (its whole frame or the predicted
  //     regions); returns the pixels each camera will search (0: nothing, e.g. no image);
  //   search(c): camera c's search, from any thread, each camera once (the images must live until finish());
  //   finish(): the same-frame whole-frame search of a prop its regions missed, the solve and the
  //     filter. TrackFrame::detect_ms is then the cameras' search times summed (track(): the
  //     searches' wall time).
  // A begin() without its finish() (the caller's frame failed) changes nothing: the next begin()
  // forgets it.
  std::vector<long long> begin(int frame, double time_s, const std::vector<cv::Mat>& images);
  void search(int camera);
  TrackFrame finish();
  // A moving camera (the main camera on its dolly): its pose from this frame on.
  void setCameraPose(int camera, const Pose& T_world_cam);
  // Forget every track (next frame searches the full frames).
  void reset();

  const std::vector<RigCamera>& cameras() const;
  const PropSet& props() const;
  const TrackerOptions& options() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// One JSON line per frame (docs/formats.md, "Tracking").
nlohmann::json trackFrameToJson(const TrackFrame& frame);

}  // namespace previz::tracking
