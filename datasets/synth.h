#pragma once
// The synthetic studio's public entry point: renders a take folder plus truth/.
// Layout of what it writes: docs/formats.md ("Synthetic take").
#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <optional>
#include <string>

#include "core/names.h"
#include "core/pose.h"

namespace previz::synth {

enum class Preset {
  kStudio,      // actor + tagged prop on the green stage, N witness cameras + main camera, CG set
  kIntrinsics,  // one camera, a calibration board moved and rotated in front of it
  kRig,         // every camera, a board waved through the volume, then frames of a floor board
};
const char* toString(Preset preset);
Preset presetFromString(const std::string& name);  // throws Error naming the value

struct SynthOptions {
  Preset preset = Preset::kStudio;
  int frames = 24;
  int witness_cameras = 8;
  int fisheye_witnesses = 0;     // the first N witnesses have a fisheye lens (rigs.h witnessCamera)
  std::uint64_t seed = 1;
  int witness_width = 1280, witness_height = 720;  // --size WxH sets these
  int main_width = 1920, main_height = 1080;
  double fps = 24.0;
  int samples_per_pixel = 4;     // anti-aliasing samples (>= 4), stratified, fixed per seed
  double noise_sigma = 0.0;      // additive Gaussian noise, grey levels (0..255)
  double blur_sigma_px = 0.0;    // defocus blur (Gaussian sigma, pixels)
  double shutter = 0.0;          // motion blur: fraction of the frame interval the shutter is open
  double brightness_jitter = 0.0;  // per camera gain drawn in [1 - j, 1 + j]
  bool main_dolly = true;        // main camera moves along its dolly path (else fixed)
  double cg_overscan = 0.1;      // CG render of the main camera: extra fraction each way
  std::string board = "charuco"; // intrinsics/rig presets: chessboard|charuco|aprilgrid|circles|quadtree
  std::string camera = kMainCamera;  // intrinsics preset: "main", "witness" (= witness01) or a witness name
  bool write_meshes = true;      // truth/mesh/actor.%06d.{ply,obj}
  // Studio preset: what the stage is dressed in (datasets/studio.h Backdrop): green | blue | set
  // (no screen). clean_plates: clean/<camera>.png of every static camera (the empty stage, same
  // noise and gain); a set always has them (it is keyed by difference against them).
  std::string backdrop = "green";
  bool clean_plates = false;
  int threads = 0;               // OpenMP threads (0 = default)
  // Studio preset: the form of the cameras' streams, as a camera or a conform delivers them
  // (take/stream_writer.h; read back by the take model, take/take.h):
  std::string camera_format = "png";       // png|jpg|png16|tif16|exr (sequences), ffv1|h264|prores (videos)
  std::string sequence_pattern;            // "" = %06d; e.g. "{camera}_A001C003.####"
  int sequence_start = 0;                  // number of a sequence's first file (VFX: 1001)
  std::string start_timecode;              // timecode of take frame 0 ("" = none): EXR timeCode, container
  // camera -> it started recording N frames after take frame 0 (its stream begins there; its
  // timecode, or take.json "offsets" when there is none, says so).
  std::map<std::string, int> late_frames;
  // Rig preset (datasets/rig_capture.h RigCaptureOptions has the same meanings), and the studio
  // preset for delay_frames (an unsynchronised camera: its stream's take frame f shows f - delay):
  std::optional<std::uint64_t> board_seed;  // board trajectory; default: seed
  bool floor_frames = true;                 // false: every frame waves the board (no floor.json)
  bool floor_only = false;                  // true: every frame shows the floor board, none waved
  std::map<std::string, int> delay_frames;  // camera -> frames late (its frame f shows f - delay)
  std::map<std::string, Pose> bump;         // camera -> true pose T_world_cam * bump

  void validate() const;  // throws Error naming the bad field (and the camera for delay/bump)
};

struct SynthProgress {
  int frames_done = 0;
  int frames_total = 0;
  double elapsed_s = 0;
};

struct SynthSummary {
  int frames = 0;
  int cameras = 0;
  double render_ms = 0;         // total time spent rendering (summed over threads)
  double ms_per_camera_frame = 0;  // plates; board presets include each camera's one-off stage
  std::filesystem::path out;
};

// Renders the take into out (created; existing files are replaced atomically one by one).
SynthSummary synthesizeTake(const SynthOptions& options, const std::filesystem::path& out,
                            const std::function<void(const SynthProgress&)>& progress = {});

}  // namespace previz::synth
