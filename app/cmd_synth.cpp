// previz synth: render a synthetic take (studio, intrinsics or rig preset) with ground truth.
#include <cmath>
#include <iostream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include "app/commands.h"
#include "app/options.h"
#include "app/progress.h"
#include "core/units.h"
#include "datasets/synth.h"

namespace previz::app {
namespace {

struct SynthArgs {
  std::string preset = "studio";
  std::string out;
  std::string size;
  std::string main_size;
  bool json = false;
  bool quiet = false;
  bool static_main = false;
  bool no_meshes = false;
  bool no_floor = false;
  std::vector<std::string> delays;
  std::vector<std::string> lates;
  std::vector<std::string> bumps;
  std::uint64_t board_seed = 0;
  CLI::Option* board_seed_option = nullptr;
  synth::SynthOptions options;
};

[[noreturn]] void badFlag(const std::string& flag, const std::string& message) {
  throw Error(flag + ": " + message, fieldContext(flag));
}

// "NAME=VALUE" -> (NAME, VALUE); throws Error naming the flag otherwise.
std::pair<std::string, std::string> splitNamed(const std::string& text, const std::string& flag,
                                               const std::string& form) {
  const auto eq = text.find('=');
  if (eq == std::string::npos || eq == 0 || eq + 1 == text.size()) {
    badFlag(flag, "expected " + form + " (got '" + text + "')");
  }
  return {text.substr(0, eq), text.substr(eq + 1)};
}


// --bump NAME=DX,DY,DZ,RX,RY,RZ: metres and a rotation vector in degrees, both in the camera's
// own frame (x right, y down, z forward): T_world_cam' = T_world_cam * bump.
void parseBump(const std::string& text, synth::SynthOptions& o) {
  const std::string form = "NAME=DX,DY,DZ,RX,RY,RZ (metres, degrees), e.g. witness02=0.01,0,0,0,0.5,0";
  const auto [name, value] = splitNamed(text, "--bump", form);
  std::vector<double> v;
  try {
    v = parseNumbers(value, 6, "--bump", form);
  } catch (const Error&) {
    badFlag("--bump", "expected " + form + " (got '" + text + "')");
  }
  const Eigen::Vector3d rotation_deg(v[3], v[4], v[5]);
  const double angle = radians(rotation_deg.norm());
  Pose bump = Pose::Identity();
  if (angle > 0) bump.linear() = Eigen::AngleAxisd(angle, rotation_deg.normalized()).toRotationMatrix();
  bump.translation() = Eigen::Vector3d(v[0], v[1], v[2]);
  o.bump[name] = bump;
}

}  // namespace

Runner addSynthCommand(CLI::App& app) {
  auto args = std::make_shared<SynthArgs>();
  CLI::App* cmd = app.add_subcommand(
      "synth", "Render a synthetic green-screen take with exact ground truth (docs/formats.md)");
  synth::SynthOptions& o = args->options;
  cmd->add_option("--preset", args->preset, "studio | intrinsics | rig")
      ->check(CLI::IsMember({"studio", "intrinsics", "rig"}))
      ->capture_default_str();
  cmd->add_option("--out", args->out, "Take folder to write")->required();
  cmd->add_option("--frames", o.frames, "Number of frames")->capture_default_str();
  cmd->add_option("--cams", o.witness_cameras, "Number of witness cameras")->capture_default_str();
  cmd->add_option("--fisheye-witnesses", o.fisheye_witnesses,
                  "The first N witnesses get a fisheye lens (Kannala-Brandt, ~160 degrees diagonal)")
      ->capture_default_str();
  cmd->add_option("--seed", o.seed, "Random seed (takes are reproducible bit for bit)")
      ->capture_default_str();
  cmd->add_option("--size", args->size,
                  "Witness camera size WxH (default 1280x720); the main camera scales with it");
  cmd->add_option("--main-size", args->main_size, "Main camera size WxH (overrides the scaling)");
  cmd->add_option("--noise", o.noise_sigma, "Additive Gaussian noise sigma, grey levels")
      ->capture_default_str();
  cmd->add_option("--blur", o.blur_sigma_px, "Defocus blur sigma, pixels")->capture_default_str();
  cmd->add_option("--shutter", o.shutter, "Motion blur: shutter open fraction of a frame (0..1)")
      ->capture_default_str();
  cmd->add_option("--brightness-jitter", o.brightness_jitter,
                  "Per-camera gain drawn in [1-j, 1+j]")->capture_default_str();
  cmd->add_option("--spp", o.samples_per_pixel, "Anti-aliasing samples per pixel (>= 4)")
      ->capture_default_str();
  cmd->add_option("--fps", o.fps, "Frame rate of the take")->capture_default_str();
  cmd->add_option("--board", o.board, "Board for intrinsics/rig presets: chessboard|charuco|aprilgrid|circles|quadtree")
      ->capture_default_str();
  cmd->add_option("--camera", o.camera, "Intrinsics preset: camera to film (main|witness|witness01..witnessNN)")
      ->capture_default_str();
  cmd->add_option("--overscan", o.cg_overscan, "CG render overscan fraction")->capture_default_str();
  cmd->add_option("--backdrop", o.backdrop,
                  "Studio preset: green | blue (cyclorama) | set (no screen: painted walls, concrete floor; "
                  "writes clean plates)")
      ->capture_default_str();
  cmd->add_flag("--clean-plates", o.clean_plates,
                "Studio preset: also write clean/<camera>.png, the empty stage from every static camera");
  cmd->add_option("--threads", o.threads, "OpenMP threads (0 = all cores)")->capture_default_str();
  cmd->add_flag("--static-main", args->static_main, "Keep the main camera fixed (no dolly move)");
  cmd->add_flag("--no-meshes", args->no_meshes, "Do not write truth/mesh/actor.*");
  cmd->add_option("--delay", args->delays,
                  "Rig and studio presets: NAME=FRAMES, camera NAME is out of sync: its frame f shows frame "
                  "f - FRAMES (repeatable)");
  cmd->add_option("--format", o.camera_format,
                  "Studio preset: the cameras' streams: png|jpg|png16|tif16|exr (sequences; exr float linear) or "
                  "ffv1|h264|prores (videos cams/<cam>.mkv|.mp4|.mov)")
      ->capture_default_str();
  cmd->add_option("--pattern", o.sequence_pattern,
                  "Studio preset: sequence file pattern ({camera}, %04d or ####; default %06d)");
  cmd->add_option("--start-number", o.sequence_start, "Studio preset: number of a sequence's first file (VFX: 1001)")
      ->capture_default_str();
  cmd->add_option("--timecode", o.start_timecode,
                  "Studio preset: timecode of take frame 0, HH:MM:SS:FF, written where the form carries one "
                  "(EXR timeCode, the video container)");
  cmd->add_option("--late", args->lates,
                  "Studio preset: NAME=FRAMES, camera NAME started recording FRAMES frames late (its stream "
                  "begins there; its timecode or take.json \"offsets\" says so; repeatable)");
  cmd->add_option("--bump", args->bumps,
                  "Rig preset: NAME=DX,DY,DZ,RX,RY,RZ, camera NAME truly stands at T_world_cam * bump "
                  "(metres; rotation vector in degrees; camera frame; repeatable)");
  args->board_seed_option = cmd->add_option("--board-seed", args->board_seed,
                  "Rig preset: seed of the board's path (default: --seed)");
  cmd->add_flag("--no-floor", args->no_floor,
                "Rig preset: every frame waves the board (no floor frames, no floor.json)");
  cmd->add_flag("--floor-only", args->options.floor_only,
                "Rig preset: every frame shows the board lying still on the floor, none waved "
                "(static witnesses placed from the floor board alone)");
  cmd->add_flag("--json", args->json, "Print a JSON summary on stdout");
  cmd->add_flag("--quiet", args->quiet, "No progress line");

  return [args]() {
    synth::SynthOptions o = args->options;
    o.preset = synth::presetFromString(args->preset);
    o.main_dolly = !args->static_main;
    o.write_meshes = !args->no_meshes;
    for (const std::string& d : args->delays) {
      const auto [name, frames] = parseNamedInt(d, "--delay");
      o.delay_frames[name] = frames;
    }
    for (const std::string& d : args->lates) {
      const auto [name, frames] = parseNamedInt(d, "--late");
      o.late_frames[name] = frames;
    }
    for (const std::string& b : args->bumps) parseBump(b, o);
    if (args->board_seed_option->count() > 0) o.board_seed = args->board_seed;
    o.floor_frames = !args->no_floor;
    if (!args->size.empty()) {
      const auto [w, h] = parseSize(args->size, "--size");
      const double scale = static_cast<double>(w) / o.witness_width;
      o.main_width = static_cast<int>(o.main_width * scale + 0.5);
      o.main_height = static_cast<int>(o.main_height * (static_cast<double>(h) / o.witness_height) + 0.5);
      o.witness_width = w;
      o.witness_height = h;
    }
    if (!args->main_size.empty()) {
      std::tie(o.main_width, o.main_height) = parseSize(args->main_size, "--main-size");
    }
    o.validate();
    ProgressLine progress("synth " + args->preset, o.frames, args->quiet);
    const synth::SynthSummary s = synth::synthesizeTake(
        o, args->out, [&](const synth::SynthProgress& p) { progress.update(p.frames_done); });
    std::cerr << "synth: wrote " << s.frames << " frames x " << s.cameras << " cameras to "
              << s.out.string() << " (" << s.ms_per_camera_frame << " ms per camera-frame)\n";
    if (args->json) {
      nlohmann::json j = {{"command", "synth"},          {"preset", args->preset},
                          {"out", s.out.string()},       {"frames", s.frames},
                          {"cameras", s.cameras},        {"render_ms", s.render_ms},
                          {"ms_per_camera_frame", s.ms_per_camera_frame}};
      std::cout << j.dump() << "\n";
    }
    return 0;
  };
}

}  // namespace previz::app
