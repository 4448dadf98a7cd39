// previz soak: the live loop over a looping take for thousands of frames with faults injected
// on a schedule (live/soak.h): what every fault did, frames accounted for, RSS over time and
// frame times; OUT/soak.json and OUT/soak.svg. Exit 1 when a fault was not handled as it must
// be, a frame is unaccounted for, RSS grew beyond the limit or an output is incomplete.
#include <cmath>
#include <cstdio>
#include <iostream>

#include <nlohmann/json.hpp>

#include "app/commands.h"
#include "app/options.h"
#include "app/progress.h"
#include "core/error.h"
#include "core/io.h"
#include "datasets/synth.h"
#include "live/soak.h"

namespace previz::app {
namespace {

namespace fs = std::filesystem;

struct SoakArgs {
  std::string take, rig, out = "out/soak";
  int frames = 5000, period = 500, warmup = 500, rss_window = 250, slots = 64, threads = 0;
  double max_rss_growth = 0.05;
  // The built-in synthetic studio take (when --take is not given): small, so the soak is about
  // the loop's robustness, not its speed.
  int take_frames = 48, cams = 8;
  std::string size = "320x180", main_size = "480x270";
  bool json = false, quiet = false;
};

// The synthetic studio rendered once into OUT/studio_<size>_<cams>_<frames> (kept for re-runs).
fs::path studioTake(const SoakArgs& a) {
  synth::SynthOptions so;
  so.frames = a.take_frames;
  so.witness_cameras = a.cams;
  std::tie(so.witness_width, so.witness_height) = parseSize(a.size, "--size");
  std::tie(so.main_width, so.main_height) = parseSize(a.main_size, "--main-size");
  so.noise_sigma = 2.0;
  so.write_meshes = false;
  const fs::path dir = fs::path(a.out) / ("studio_" + a.size + "_" + a.main_size + "_" + std::to_string(a.cams) + "x" +
                                         std::to_string(a.take_frames));
  if (!fs::exists(dir / "take.json")) {
    if (!a.quiet)
      std::cerr << "soak: rendering the synthetic studio (" << a.take_frames << " frames, " << a.cams << " x " << a.size
                << " + main " << a.main_size << ") into " << dir << " (once)\n";
    synth::synthesizeTake(so, dir);
  }
  return dir;
}

int runSoakCommand(const SoakArgs& a) {
  live::SoakOptions o;
  o.take = a.take.empty() ? studioTake(a) : fs::path(a.take);
  o.rig = a.rig;
  o.out = a.out;
  o.frames = a.frames;
  o.period = a.period;
  o.warmup_frames = a.warmup;
  o.rss_window = a.rss_window;
  o.max_rss_growth = a.max_rss_growth;
  o.output_slots = a.slots;
  o.loop.threads = a.threads;
  try {
    o.validate();
  } catch (const Error& e) {
    // The option's flag, not the struct's field.
    const std::string f = e.context().field;
    const std::string flag = f == "warmup_frames" ? "--warmup" : f == "output_slots" ? "--slots"
                           : f == "max_rss_growth" ? "--max-rss-growth" : f == "rss_window" ? "--rss-window"
                           : "--" + f;
    throw Error(e.message(), fieldContext(flag));
  }
  ProgressLine line("soak", a.frames, a.quiet);
  const live::SoakReport r = live::runSoak(o, [&](const live::SoakProgress& p) { line.update(p.frame); });
  std::cerr << r.fullReport();
  std::cerr << "soak: report " << (fs::path(a.out) / "soak.json").string() << ", plot "
            << (fs::path(a.out) / "soak.svg").string() << "\n";
  if (a.json) std::cout << r.toJson(false).dump() << "\n";
  return r.ok() ? 0 : 1;
}

}  // namespace

Runner addSoakCommand(CLI::App& app) {
  auto a = std::make_shared<SoakArgs>();
  CLI::App* cmd = app.add_subcommand(
      "soak", "The live loop over a looping take for thousands of frames with faults injected on a schedule "
              "(witness unplugged, corrupt/truncated frames, a late camera, tracker packets lost/reordered, disk "
              "full): every fault matched to what the loop reported, frames accounted, RSS and frame times; "
              "OUT/soak.json + OUT/soak.svg; exit 1 when a check fails");
  cmd->add_option("--take", a->take,
                  "Take folder with cg/ and image sequences (default: the synthetic studio rendered into OUT once)");
  cmd->add_option("--rig", a->rig, "rig.json (default: TAKE/truth/rig.json)");
  cmd->add_option("--out", a->out, "Output folder (working copy of the take, outputs, report)")->capture_default_str();
  cmd->add_option("--frames", a->frames, "Frames to run (the take looped)")->capture_default_str();
  cmd->add_option("--period", a->period, "The fault schedule repeats every this many frames (>= 100)")
      ->capture_default_str();
  cmd->add_option("--warmup", a->warmup, "Frames before the RSS reference window")->capture_default_str();
  cmd->add_option("--rss-window", a->rss_window, "Frames in the RSS reference and end windows (medians)")
      ->capture_default_str();
  cmd->add_option("--max-rss-growth", a->max_rss_growth, "Largest RSS growth allowed after warm-up (0.05 = 5 %)")
      ->capture_default_str();
  cmd->add_option("--slots", a->slots, "Output ring: frame n written to slot n % slots")->capture_default_str();
  cmd->add_option("--threads", a->threads, "OpenMP threads (0 = all cores)")->capture_default_str();
  cmd->add_option("--take-frames", a->take_frames, "Synthetic take: frames")->capture_default_str();
  cmd->add_option("--cams", a->cams, "Synthetic take: witness cameras")->capture_default_str();
  cmd->add_option("--size", a->size, "Synthetic take: witness size WxH")->capture_default_str();
  cmd->add_option("--main-size", a->main_size, "Synthetic take: main camera size WxH")->capture_default_str();
  cmd->add_flag("--json", a->json, "Print the report as JSON on stdout");
  cmd->add_flag("--quiet", a->quiet, "No progress line");
  return [a]() { return runSoakCommand(*a); };
}

}  // namespace previz::app
