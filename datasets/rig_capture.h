#pragma once
// A rig capture rendered on demand, in memory: the rig preset's board waved through the volume
// (then lying on the floor), seen by every camera of the studio rig. What multicam's tests and
// benchmarks detect and solve on, without writing thousands of PNGs.
//
// Speed: the rig preset's stage is static, so each camera's empty stage is rendered once (on
// first use, at samples_per_pixel) and cached; a frame ray-traces only the pixels that can see
// the board (printed board + margin + 2 px) with renderView's sample rays and pastes them over
// the cached stage, then adds the frame's noise over the whole image. Without noise the result
// equals a full renderView of the same scene to the bit (tests/datasets/rig_capture_test.cpp);
// the noise is Gaussian with the requested sigma but drawn from its own stream
// (datasets/detail/board_view.h). About 31 ms CPU a 1280x720 camera-frame on one core at 4 spp
// over a 300-frame AprilGrid capture, the one-off stage render included (a full render of the
// same camera-frame: ~650-780 ms; bench/render_bench.cpp rig_capture_frame).
//
// Memory: the cache holds 15 bytes a pixel per camera with noise (3 without; +12 with blur):
// ~140 MB for the full 8 x 1280x720 + 1920x1080 rig with noise, rendered as cameras are used.
#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/board.h"
#include "core/rig.h"
#include "datasets/rigs.h"

namespace previz::synth {

struct RigCaptureOptions {
  StudioRigOptions rig;                 // cameras (8 witnesses 1280x720 + main 1920x1080)
  BoardType board = BoardType::kAprilGrid;   // rigBoard(board)
  int frames = 300;                     // the last floorBoardFrameCount(frames) are floor frames
  std::uint64_t board_seed = 1;         // board trajectory: a new capture is a new seed
  int samples_per_pixel = 4;
  double noise_sigma = 2.0;             // grey levels
  double blur_sigma_px = 0.0;
  // Camera name -> frames late: its frame f shows the board of frame f - delay (clamped to
  // [0, frames - 1]; a negative delay is a camera running early).
  std::map<std::string, int> delay_frames;
  // Camera name -> motion applied to its true pose: T_world_cam' = T_world_cam * bump
  // (a knocked camera turns about its own centre and shifts).
  std::map<std::string, Pose> bump;
  // Camera name -> linear gain (brightness), default 1.
  std::map<std::string, double> gain;
  bool floor_frames = true;             // false: every frame waves the board (re-survey capture)
  // true: every frame shows the floor board and nothing is waved (static witnesses placed from
  // one still board each, for stages where a moving-board take is not possible).
  bool floor_only = false;
  int threads = 0;                      // OpenMP threads for rendering (0 = default)
};

class RigCapture {
 public:
  explicit RigCapture(const RigCaptureOptions& options);  // throws Error naming a bad option
  ~RigCapture();
  RigCapture(const RigCapture&) = delete;
  RigCapture& operator=(const RigCapture&) = delete;

  const Rig& rig() const;            // true rig of this capture (bumps applied)
  const BoardSpec& board() const;    // rigBoard(options.board)
  int frames() const;
  bool isFloorFrame(int frame) const;
  Pose floorBoardPose() const;       // T_world_board in floor frames
  // Board pose the camera sees in its frame 'frame' (its delay applied).
  Pose T_world_board(int camera, int frame) const;
  // Whether that board is the floor board (its delay applied).
  bool showsFloorBoard(int camera, int frame) const;

  // Camera 'camera' (index into rig().cameras), frame 'frame': 8-bit BGR, full size, noise
  // drawn from (rig.seed, board_seed, camera, frame). Thread-safe (call it from parallel loops;
  // its own OpenMP loops then run on the calling thread). The first call for a camera renders
  // its empty stage (~0.5 s at 1280x720 on one core). Throws Error naming camera and frame
  // when either is out of range.
  cv::Mat render(int camera, int frame) const;
  // The board points the camera really sees in that frame (visibleBoardPoints), exact pixels.
  std::vector<BoardObservation> truth(int camera, int frame) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace previz::synth
