#pragma once
// Where the synthetic studio's cameras stand, what their lenses are, and how the calibration
// boards move in the intrinsics and rig presets. All deterministic from the seed.
// World frame: z up, floor at z = 0, metres; poses T_a_b map b -> a (docs/conventions.md).
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/board.h"
#include "core/camera.h"
#include "core/pose.h"
#include "core/rig.h"
#include "datasets/scene.h"

namespace previz::synth {

// Sizes at which the studio's lenses are designed; other sizes use Camera::scaled, which keeps
// the field of view.
constexpr int kWitnessDesignWidth = 1280, kWitnessDesignHeight = 720;
constexpr int kMainDesignWidth = 1920, kMainDesignHeight = 1080;

// Where every witness camera aims (the stage centre at about chest height).
// 0.65 m rather than chest height: when the actor comes within ~2.5 m of a witness its feet are
// the first thing to leave the view, while there is headroom to spare above it.
inline Eigen::Vector3d witnessAimPoint() { return Eigen::Vector3d(0.0, 0.0, 0.65); }

// "witness01" for index 0.
std::string witnessName(int index);

// Witness camera 'index' of 'count': true intrinsics drawn from the seed at the design size
// (fx in [800, 950], principal point a few px off centre, k1 in [-0.25, 0.05], small k2,
// |p1|, |p2| <= 0.001, k3 = 0; k2 redrawn until the whole image lies well inside the lens'
// invertible domain), then scaled to width x height; pose on a circle of radius 4.2–4.8 m at
// 2.0–2.7 m height aimed at witnessAimPoint() (+-5 cm). The layout leaves a gap around the main camera's
// line of sight (azimuth -90 degrees).
// fisheye: a Kannala–Brandt lens (f 470–520 px at the design size: the image corners ~80
// degrees off the axis, a 160-degree diagonal) instead of the Brown–Conrady witness lens.
RigCamera witnessCamera(int index, int count, std::uint64_t seed, int width, int height, bool fisheye = false);

// Main (film) camera "main": fx = 1500 at 1920x1080, k1 = -0.06, k2 = 0.02, scaled to
// width x height.
Camera mainCamera(int width, int height);
// Main camera pose at time t: eye at (x, -6, 1.6) with the orientation of a look at
// (0, 0, 1.0) from (0, -6, 1.6); with 'dolly' x = -cos(pi t / duration) (from -1 m to +1 m over
// 'duration', easing in and out), else x = 0. synthesizeTake passes the studio's choreography
// length (StudioConfig::take_duration_s), so the camera moves at a realistic 0.2–0.3 m/s.
Pose mainCameraPose(double time_s, double duration_s, bool dolly);

struct StudioRigOptions {
  int witness_cameras = 8;
  std::uint64_t seed = 1;
  int witness_width = kWitnessDesignWidth, witness_height = kWitnessDesignHeight;
  int main_width = kMainDesignWidth, main_height = kMainDesignHeight;
  bool with_main = true;
  // The first fisheye_witnesses witnesses (index order) have a fisheye lens (witnessCamera).
  int fisheye_witnesses = 0;
};
// Witness cameras in index order, then "main" at its pose at t = 0 (no dolly offset applied
// beyond mainCameraPose(0, ...)).
Rig studioRig(const StudioRigOptions& options, double duration_s, bool dolly);

// Intrinsics preset, frame 'frame': T_cam_board of the board in front of the camera. The board
// covers 20–70 % of the image width, tilts up to +-45 degrees about its x and y axes, rolls a
// little (every fifth frame by a quarter turn more), and its centre visits a 3 x 3 grid of image
// cells in turn (corners included) with jitter; it is pulled towards the image centre until the
// whole printed board (margin included) lies in the image.
Pose intrinsicsBoardPose(const Camera& camera, const BoardSpec& spec, int frame,
                         std::uint64_t seed);

// The rig preset's board: defaultBoard(type) with every length scaled by 2.5 (ChArUco: 0.15 m
// squares, 1.5 x 1.05 m). The witnesses see the volume from 3–6 m, where the default board's
// 45 mm markers span ~9 px (about one pixel per code cell) — too small to decode.
BoardSpec rigBoard(BoardType type);

// Rig preset. The last floorBoardFrameCount(frames) frames show the board on the floor; the
// others wave it through the volume (centre at 0.8–2.0 m height within 1 m of the stage
// centre, lifted where needed so that no part comes within 5 cm of the floor), its face turning around the vertical so that it faces every witness in turn and
// neighbouring cameras see it together.
int floorBoardFrameCount(int frames);
bool isFloorBoardFrame(int frame, int frames);
Pose rigBoardPose(const BoardSpec& spec, int frame, int frames, std::uint64_t seed);
// The waving part of rigBoardPose on its own: frame 'frame' of a path spread over
// 'waved_frames' frames (rigBoardPose(spec, f, frames, seed) equals
// rigWavedBoardPose(spec, f, max(1, frames - floorBoardFrameCount(frames)), seed) in its waved
// frames). A capture without floor frames (a re-survey) waves the board in every frame.
Pose rigWavedBoardPose(const BoardSpec& spec, int frame, int waved_frames, std::uint64_t seed);
// The floor board: lying face up with its board-frame origin (top-left outer corner of the
// pattern) at the world origin, board x = world x, board y = -world y, board z = -world z
// (a half turn about x), so world = board frame rotated a half turn about its x axis.
Pose floorBoardPose();

// Wraps a primitive so that it wins ties (hits within tolerance_m along the ray) against the
// primitives added to the scene before it. The floor board is printed flat on the floor at
// exactly z = 0, so it and the stage floor meet every ray at the same distance; without this the
// stage (added first) would win and the board would not show.
std::shared_ptr<const Primitive> onTopOf(std::shared_ptr<const Primitive> inner,
                                         double tolerance_m = 1e-6);

// Board points a camera really sees: projected with Camera::project, centre inside the image,
// in front of the camera, printed face towards the camera, and not occluded (a ray traced from
// the camera centre through 'scene' reaches the point).
struct BoardObservation {
  int id = 0;
  Eigen::Vector2d px = Eigen::Vector2d::Zero();
};
std::vector<BoardObservation> visibleBoardPoints(const Camera& camera, const Pose& T_world_cam,
                                                 const BoardSpec& spec,
                                                 const Pose& T_world_board, const Scene& scene);

}  // namespace previz::synth
