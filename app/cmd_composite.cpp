// previz composite: the compositor alone on one take — the main plate keyed (soft alpha +
// despill), the actor depth from a folder of depth EXRs (e.g. `previz carve`'s out/depth), the
// CG frames of the take — into composites, debug layers and optionally a video.
#include <iostream>

#include <nlohmann/json.hpp>

#include "app/commands.h"
#include "app/progress.h"
#include "calib/lens_table.h"
#include "carving/keyer.h"
#include "carving/run.h"
#include "carving/take.h"
#include "composite/compositor.h"
#include "composite/output.h"
#include "core/error.h"
#include "core/io.h"
#include "core/names.h"
#include "core/rig.h"

namespace previz::app {
namespace {

namespace fs = std::filesystem;

struct CompositeArgs {
  std::string take, rig, depth, out, frames, video, cg_dir, lens;
  double focus = 0, zoom = 0, band_m = 0.04, cg_gain = 1.0;
  int edge_fill_px = 3, threads = 0;
  bool layers = false, exr = false, json = false, quiet = false;
};

int runComposite(const CompositeArgs& a) {
  carving::TakeSource src;
  src.take_dir = a.take;
  src.rig_path = a.rig.empty() ? fs::path(a.take) / "truth" / "rig.json" : fs::path(a.rig);
  const carving::Take take(src);
  std::string main_name;
  for (const RigCamera& rc : take.rig().cameras)
    if (rc.role == kMainRole) main_name = rc.camera.name;
  if (main_name.empty()) throw Error("the rig has no camera with role 'main'", fieldContext("--rig"));
  Camera lens = take.rig().at(main_name).camera;
  if (!a.lens.empty()) {
    const calib::LensTableEntry e = calib::readLensTable(a.lens).at(a.focus, a.zoom);
    Camera c = e.camera;
    if (c.width != lens.width || c.height != lens.height)
      c = c.scaled(double(lens.width) / c.width, double(lens.height) / c.height);
    c.width = lens.width;
    c.height = lens.height;
    c.name = main_name;
    lens = c;
  }
  const fs::path cg_dir = a.cg_dir.empty() ? fs::path(a.take) / "cg" : fs::path(a.cg_dir);
  composite::CompositeOptions co;
  co.depth_band_m = a.band_m;
  co.cg_gain = a.cg_gain;
  co.edge_fill_px = a.edge_fill_px;
  co.threads = a.threads;
  const composite::Compositor compositor(lens, composite::readCgCamera(cg_dir / "camera.json"), co);

  composite::OutputOptions oo;
  oo.out = a.out;
  oo.layers = a.layers;
  oo.exr = a.exr;
  oo.video = a.video;
  if (!a.video.empty() && fs::path(a.video).extension() == ".avi") oo.fourcc = "MJPG";
  composite::CompositeWriter writer(oo);

  carving::KeyerOptions ko;
  ko.remember_garbage_zone = false;  // the main camera moves
  ko.threads = a.threads;
  carving::Keyer keyer(ko);
  const carving::FrameRange range = a.frames.empty() ? carving::FrameRange{} : carving::parseFrameRange(a.frames);
  std::vector<int> frames;
  for (int f : take.frames())
    if (range.contains(f)) frames.push_back(f);
  if (frames.empty()) throw Error("no frame of the take is in the range", fieldContext("--frames"));

  ProgressLine progress("composite", static_cast<int>(frames.size()), a.quiet);
  composite::CompositeStats total;
  double ms = 0;
  int done = 0;
  for (int f : frames) {
    const carving::CameraFrame plate = take.read(main_name, f);
    if (!plate.ok()) {
      ErrorContext c;
      c.camera = main_name;
      c.frame = f;
      c.file = take.source(main_name, f);
      throw Error("main plate unusable: " + plate.dropped, c);
    }
    const carving::KeyResult key = keyer.key(plate.image, take.source(main_name, f));
    composite::CompositeInputs in;
    in.foreground = carving::despill(plate.image, key, keyer.screen(), ko);
    in.alpha = key.alpha;
    if (a.depth.empty()) {
      in.actor_depth = cv::Mat(lens.height, lens.width, CV_32FC1, cv::Scalar(std::numeric_limits<float>::infinity()));
    } else {
      in.actor_depth = readDepthExr(fs::path(a.depth) / (frameStem(f) + ".exr"));
    }
    const composite::CgFrame cg = composite::readCgFrame(cg_dir, f, cv::Size(compositor.cg().width, compositor.cg().height));
    in.cg_color = cg.color;
    in.cg_depth = cg.depth;
    const composite::CompositeResult r = compositor.composite(in, a.layers || a.exr, "frame " + std::to_string(f));
    writer.write(f, r);
    total.actor_px += r.stats.actor_px;
    total.actor_front_px += r.stats.actor_front_px;
    total.cg_front_px += r.stats.cg_front_px;
    total.edge_filled_px += r.stats.edge_filled_px;
    total.fallback_px += r.stats.fallback_px;
    ms += r.stats.ms;
    progress.update(++done);
  }
  writer.close();
  std::cerr << "composite: " << frames.size() << " frames, " << ms / frames.size() << " ms a frame (composite pass), "
            << total.fallback_px << " actor px without depth (drawn in front, flagged)"
            << (compositor.outsideCg() ? ", " + std::to_string(compositor.outsideCg()) + " lens px outside the CG render" : "")
            << " -> " << a.out << "\n";
  if (a.json) {
    std::cout << nlohmann::json{{"command", "composite"},
                                {"out", a.out},
                                {"frames", frames},
                                {"ms_per_frame", ms / frames.size()},
                                {"actor_px", total.actor_px},
                                {"actor_front_px", total.actor_front_px},
                                {"cg_front_px", total.cg_front_px},
                                {"edge_filled_px", total.edge_filled_px},
                                {"fallback_px", total.fallback_px},
                                {"lens_outside_cg_px", compositor.outsideCg()},
                                {"lens_not_invertible_px", compositor.map().not_invertible}}
                     .dump()
              << "\n";
  }
  return 0;
}

}  // namespace

Runner addCompositeCommand(CLI::App& app) {
  auto a = std::make_shared<CompositeArgs>();
  CLI::App* cmd = app.add_subcommand(
      "composite", "Composite a take's keyed main plate over its CG frames, depth-aware (docs/formats.md, "
                   "\"Composite output\")");
  cmd->add_option("--take", a->take, "Take folder (the main camera's stream in cams/, cg/; docs/formats.md \"Take folder\")")->required();
  cmd->add_option("--out", a->out, "Output folder")->required();
  cmd->add_option("--depth", a->depth,
                  "Actor depth DIR/%06d.exr in the main view (e.g. previz carve's OUT/depth); none: "
                  "the actor is in front everywhere (fallback, flagged)");
  cmd->add_option("--rig", a->rig, "rig.json with the main camera (default: TAKE/truth/rig.json)");
  cmd->add_option("--cg", a->cg_dir, "CG folder with color/, depth/, camera.json (default: TAKE/cg)");
  cmd->add_option("--lens", a->lens, "Lens table for the main camera's intrinsics");
  cmd->add_option("--focus", a->focus, "Focus encoder value for --lens")->capture_default_str();
  cmd->add_option("--zoom", a->zoom, "Zoom encoder value for --lens")->capture_default_str();
  cmd->add_option("--frames", a->frames, "Frames A:B (A inclusive, B exclusive), A:, :B or A");
  cmd->add_option("--depth-band", a->band_m, "Soft front/behind transition, metres")->capture_default_str();
  cmd->add_option("--edge-fill", a->edge_fill_px, "Key pixels without depth take a neighbour's within this (px)")
      ->capture_default_str();
  cmd->add_option("--cg-gain", a->cg_gain, "Linear gain on the CG colour")->capture_default_str();
  cmd->add_flag("--layers", a->layers, "Also write the debug layers (alpha, actor depth, CG depth, front)");
  cmd->add_flag("--exr", a->exr, "Also write linear EXR composites");
  cmd->add_option("--video", a->video, "Also write a video OUT/NAME (.mp4, or .avi = MJPG)");
  cmd->add_option("--threads", a->threads, "OpenMP threads (0 = all cores)")->capture_default_str();
  cmd->add_flag("--json", a->json, "Print a JSON summary on stdout");
  cmd->add_flag("--quiet", a->quiet, "No progress line");
  return [a]() { return runComposite(*a); };
}

}  // namespace previz::app
