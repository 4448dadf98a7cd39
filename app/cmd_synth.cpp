// previz synth: render a synthetic take (studio, intrinsics or rig preset) with ground truth.
#include <iostream>

#include <nlohmann/json.hpp>

#include "app/commands.h"
#include "app/options.h"
#include "app/progress.h"
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
  synth::SynthOptions options;
};

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
  cmd->add_option("--board", o.board, "Board for intrinsics/rig presets: chessboard|charuco|aprilgrid|circles")
      ->capture_default_str();
  cmd->add_option("--camera", o.camera, "Intrinsics preset: camera to film (main|witness)")
      ->capture_default_str();
  cmd->add_option("--overscan", o.cg_overscan, "CG render overscan fraction")->capture_default_str();
  cmd->add_option("--threads", o.threads, "OpenMP threads (0 = all cores)")->capture_default_str();
  cmd->add_flag("--static-main", args->static_main, "Keep the main camera fixed (no dolly move)");
  cmd->add_flag("--no-meshes", args->no_meshes, "Do not write truth/mesh/actor.*");
  cmd->add_flag("--json", args->json, "Print a JSON summary on stdout");
  cmd->add_flag("--quiet", args->quiet, "No progress line");

  return [args]() {
    synth::SynthOptions o = args->options;
    o.preset = synth::presetFromString(args->preset);
    o.main_dolly = !args->static_main;
    o.write_meshes = !args->no_meshes;
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
