// previz run: the live previz frame over a take — per frame key -> carve -> main-view depth ->
// track props -> composite (live/frame_loop.h), writing composites, depth, the main camera's and
// the props' poses and, on request, meshes, debug layers and a video; a progress line with
// per-stage ms and fps.
// previz bench run: the same loop on frames held in memory, ms per stage, as JSON, with the
// binary's start-up (shared libraries loaded, `previz --version` ms).
#include <link.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <map>
#include <numeric>
#include <optional>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "app/commands.h"
#include "core/names.h"
#include "core/stopwatch.h"
#include "core/threads.h"
#include "live/frame_loop.h"
#include "live/inputs.h"
#include "live/tracker.h"
#include "app/options.h"
#include "app/progress.h"
#include "batch/process.h"
#include "calib/lens_table.h"
#include "batch/manifest.h"
#include "carving/run.h"
#include "composite/measure.h"
#include "core/error.h"
#include "core/io.h"
#include "core/leftovers.h"
#include "core/mesh.h"
#include "core/pose.h"
#include "core/simd.h"
#include "core/stats.h"
#include "datasets/scene.h"
#include "datasets/synth.h"
#include "take/convert.h"
#include "take/take.h"
#include "tracking/props.h"
#include "tracking/tracker.h"

namespace previz::app {
// The live frame (live/frame_loop.h, live/inputs.h).
using live::FrameLoop;
using live::FrameLoopOptions;
using live::FrameState;
using live::TakeReader;
using live::LiveReader;
using live::LiveOptions;
using live::TakeInputOptions;
using live::PropStage;
using live::PropStageOptions;
using live::StageTime;
using live::kLiveVoxelM;
namespace {

namespace fs = std::filesystem;

// Loop options shared by run and bench run.
struct LoopArgs {
  std::string rig, main_poses, lens, cg_dir;
  double focus = 0, zoom = 0;
  std::string tracked_main_poses;
  double voxel_m = std::nan("");  // NaN: kLiveVoxelM (frame_loop.h says why 2 cm), kLiveMeshVoxelM with run --meshes
  double depth_step_m = live::kLiveDepthStepM;
  int k = 0;
  double band_m = 0.04;
  double cg_gain = 1.0;
  int threads = 0;
  int witness_bin = 1;
  int key_region_margin_px = live::FrameLoopOptions{}.key_region_margin_px;
  bool key_main_whole = false;
  bool props_own_pool = false;
  std::string props;
  bool no_props = false;
  // The stage's camera tracker (run only; live/tracker.h).
  std::string tracker, tracker_config, tracker_match;
  double tracker_delay_s = std::nan("");  // NaN: tracker.json's
};

void addTrackerOptions(CLI::App* cmd, LoopArgs& a) {
  cmd->add_option("--tracker", a.tracker,
                  "The main camera's pose (and lens, with --lens) from the stage's camera tracker: freed://HOST:PORT, "
                  "otio://HOST:PORT (multicast 239.135.1.x:55555 joined), or a recording FILE.jsonl "
                  "(previz tracker record); replaces --main-poses");
  cmd->add_option("--tracker-config", a.tracker_config,
                  "tracker.json: T_world_stage, T_tracker_cam, delay_s, ... (docs/formats.md \"Camera tracker\"; "
                  "previz tracker align writes it); default: identities, no delay");
  cmd->add_option("--tracker-delay", a.tracker_delay_s,
                  "Seconds from a tracker sample's instant to its arrival (overrides tracker.json's delay_s)");
  cmd->add_option("--tracker-match", a.tracker_match, "auto (timecode when the take and the samples have one), arrival, timecode");
}

void addLoopOptions(CLI::App* cmd, LoopArgs& a, bool rig_required) {
  auto* rig = cmd->add_option("--rig", a.rig, "rig.json (witnesses + main); default: the take's truth/rig.json");
  if (rig_required) rig->required();
  cmd->add_option("--main-poses", a.main_poses,
                  "JSON lines {frame, T_world_cam} of the moving main camera (default: the take's "
                  "truth/main_poses.jsonl when it exists)");
  cmd->add_option("--tracked-main-poses", a.tracked_main_poses,
                  "Camera tracker's JSON lines {frame, T_main0_main}: the main camera's motion from its pose "
                  "in the rig (where it stood at rig calibration); replaces --main-poses");
  cmd->add_option("--lens", a.lens, "Lens table (lens/<lens>.json) for the main camera's intrinsics");
  cmd->add_option("--focus", a.focus, "Focus encoder value for --lens")->capture_default_str();
  cmd->add_option("--zoom", a.zoom, "Zoom encoder value for --lens")->capture_default_str();
  cmd->add_option("--cg", a.cg_dir, "CG folder with color/, depth/, camera.json (default: TAKE/cg)");
  cmd->add_option("--voxel", a.voxel_m,
                  "Finest carving cell, metres (default 0.02; run --meshes: 0.01); the depth is the exact hull of the "
                  "silhouettes whatever the cell (--depth-step)")
      ->check(CLI::Validator(
          [](std::string& text) {
            // NaN stands for "not given": "--voxel nan" must not become the default.
            double v = 0;
            return CLI::detail::lexical_cast(text, v) && std::isfinite(v) && v > 0
                       ? std::string()
                       : "must be a finite number of metres > 0 (got " + text + ")";
          },
          "METRES > 0"));
  cmd->add_option("--depth-step", a.depth_step_m,
                  "Main-view depth: the step each ray samples the silhouettes at inside the hull's surface cells, "
                  "metres (a hull sliver thinner than this can be missed; 0 = half the cell)")
      ->capture_default_str();
  cmd->add_option("--k", a.k, "A cell survives outside the silhouette of at most k cameras")->capture_default_str();
  cmd->add_option("--depth-band", a.band_m, "Soft front/behind transition, metres")->capture_default_str();
  cmd->add_option("--cg-gain", a.cg_gain, "Linear gain on the CG colour (match the plate's exposure)")
      ->capture_default_str();
  cmd->add_option("--threads", a.threads, "OpenMP threads (0 = all cores)")->capture_default_str();
  cmd->add_option("--witness-bin", a.witness_bin,
                  "Key and carve the witnesses at 1/N resolution (plates averaged over N x N pixels): faster, a "
                  "little less silhouette detail; the main camera stays at full resolution")
      ->capture_default_str();
  cmd->add_option("--key-region-margin", a.key_region_margin_px,
                  "Key each camera only around its last frame's silhouette parts, grown by this many pixels (whole "
                  "frames when something shows outside them, and in turn every 24 frames); 0 = key every frame whole")
      ->capture_default_str();
  cmd->add_flag("--key-main-whole", a.key_main_whole,
                "Key the main camera's whole frame every frame (the witnesses keep --key-region-margin): what "
                "shows outside its regions under 8 rows tall is then composited at once, not from the next "
                "whole frame");
  cmd->add_flag("--props-own-pool", a.props_own_pool,
                "Search the plates for tags in a pool of threads of the props stage's own, not among the key "
                "stage's cameras (the same poses; to compare)");
  cmd->add_option("--props", a.props,
                  "props.json of the tagged props to track (stage \"props\"; default: the take's props.json when it "
                  "has a prop that is not fixed to the studio)");
  cmd->add_flag("--no-props", a.no_props, "Do not track props");
}

struct Loaded {
  std::unique_ptr<carving::Take> take;
  std::unique_ptr<FrameLoop> loop;
  std::unique_ptr<TakeReader> reader;
  std::unique_ptr<PropStage> props;  // null: no prop tracking
  std::unique_ptr<live::TrackerInput> tracker;  // null: no camera tracker
  std::string lens_note, props_note, tracker_note;
};

// The props to track: --props, else the take's props.json when it has a carried prop.
std::optional<tracking::PropSet> runProps(const fs::path& take_dir, const LoopArgs& a, std::string& note) {
  if (a.no_props) {
    if (!a.props.empty()) throw Error("--props and --no-props exclude each other", fieldContext("--no-props"));
    return std::nullopt;
  }
  const fs::path path = a.props.empty() ? take_dir / "props.json" : fs::path(a.props);
  if (a.props.empty() && !fs::exists(path)) return std::nullopt;
  tracking::PropSet set = tracking::readProps(path);
  int carried = 0;
  for (const tracking::PropDef& p : set.props) carried += p.T_world_prop ? 0 : 1;
  if (carried == 0) {
    if (!a.props.empty()) {
      ErrorContext c;
      c.file = path.string();
      throw Error("no prop to track (every prop is fixed to the studio)", c);
    }
    return std::nullopt;
  }
  note = std::to_string(carried) + " props of " + path.string();
  return set;
}

Loaded load(const fs::path& take_dir, const LoopArgs& a, bool debug_layers) {
  Loaded l;
  carving::TakeSource src;
  src.take_dir = take_dir;
  src.rig_path = a.rig.empty() ? take_dir / "truth" / "rig.json" : fs::path(a.rig);
  if (!a.tracker.empty() && (!a.main_poses.empty() || !a.tracked_main_poses.empty()))
    throw Error("--tracker replaces --main-poses and --tracked-main-poses: give one", fieldContext("--tracker"));
  // A bad tracker URL is said before the take is read.
  std::optional<live::TrackerUrl> tracker_url;
  if (!a.tracker.empty()) tracker_url = live::parseTrackerUrl(a.tracker, "--tracker");
  if (!a.main_poses.empty()) src.main_poses = a.main_poses;
  else if (a.tracked_main_poses.empty() && a.tracker.empty() && fs::exists(take_dir / "truth" / "main_poses.jsonl"))
    src.main_poses = take_dir / "truth" / "main_poses.jsonl";
  l.take = std::make_unique<carving::Take>(src);
  const fs::path cg_dir = a.cg_dir.empty() ? take_dir / "cg" : fs::path(a.cg_dir);
  const Camera cg = composite::readCgCamera(cg_dir / "camera.json");

  FrameLoopOptions o;
  o.hull.voxel_m = std::isnan(a.voxel_m) ? live::kLiveVoxelM : a.voxel_m;
  o.hull.depth_step_m = a.depth_step_m;
  o.hull.k = a.k;
  o.composite.depth_band_m = a.band_m;
  o.composite.cg_gain = a.cg_gain;
  o.threads = a.threads;
  o.witness_bin = a.witness_bin;
  o.key_region_margin_px = a.key_region_margin_px;
  o.key_main_region = !a.key_main_whole;
  o.pool_with_key = !a.props_own_pool;
  o.debug_layers = debug_layers;
  Rig rig = l.take->rig();
  TakeInputOptions io;
  io.cg_dir = cg_dir;
  io.tracked_main_poses = a.tracked_main_poses;
  std::optional<calib::LensTable> lens_table;
  if (!a.lens.empty()) {
    const calib::LensTable table = calib::readLensTable(a.lens);
    lens_table = table;
    const calib::LensTableEntry e = table.at(a.focus, a.zoom);
    std::string main_name;
    for (const RigCamera& rc : rig.cameras)
      if (rc.role == kMainRole) main_name = rc.camera.name;
    if (main_name.empty()) throw Error("the rig has no main camera for --lens", fieldContext("--lens"));
    RigCamera& main = rig.at(main_name);
    Camera lens = e.camera;
    if (lens.width != main.camera.width || lens.height != main.camera.height)
      lens = lens.scaled(double(main.camera.width) / lens.width, double(main.camera.height) / lens.height);
    lens.width = main.camera.width;
    lens.height = main.camera.height;
    lens.name = main_name;
    main.camera = lens;
    io.main_lens = lens;
    l.lens_note = "lens " + table.lens_name + " at focus " + std::to_string(a.focus) + ", zoom " +
                  std::to_string(a.zoom) + (e.clamped ? " (clamped to the table)" : "");
  }
  l.loop = std::make_unique<FrameLoop>(rig, cg, o);
  if (std::optional<tracking::PropSet> props = runProps(take_dir, a, l.props_note)) {
    PropStageOptions po;
    po.fps = l.take->streams().fps();
    po.tracker.threads = a.threads;
    l.props = std::make_unique<PropStage>(*l.loop, rig, std::move(*props), po);
    l.props->addTo(*l.loop);
  }
  if (!a.tracker.empty()) {
    const live::TrackerUrl& url = *tracker_url;
    live::TrackerOptions to = a.tracker_config.empty() ? live::TrackerOptions{} : live::readTrackerConfig(a.tracker_config);
    if (!std::isnan(a.tracker_delay_s)) to.delay_s = a.tracker_delay_s;
    if (!a.tracker_match.empty()) to.match = a.tracker_match;
    try {
      to.validate();
    } catch (const Error& e) {
      throw Error(e.what(), fieldContext(e.context().field == "delay_s" ? "--tracker-delay"
                                         : e.context().field == "match" ? "--tracker-match" : e.context().field));
    }
    const RigCamera& main = rig.at(l.loop->mainCamera());
    l.tracker = std::make_unique<live::TrackerInput>(url, to, main.camera, lens_table);
    io.tracker = l.tracker.get();
    l.tracker_note = "camera tracker " + a.tracker + (lens_table ? " (lens from its encoders)" : "");
  }
  l.reader = std::make_unique<TakeReader>(*l.take, *l.loop, io);
  return l;
}

struct RunArgs {
  std::string take, out, frames, video;
  std::vector<std::string> live;  // NAME=SOURCE
  bool no_pace = false;
  double live_fps = 0;
  LoopArgs loop;
  bool meshes = false, layers = false, exr = false, json = false, quiet = false;
};

nlohmann::json stageJson(const std::vector<StageTime>& times) {
  nlohmann::json j = nlohmann::json::object();
  for (const StageTime& t : times) j[t.stage] = t.ms;
  return j;
}

int runRun(const RunArgs& args) {
  RunArgs a = args;
  // Meshes for post: 1 cm cells unless --voxel says otherwise (the live loop's 2 cm only guides
  // its depth rays, frame_loop.h).
  if (a.meshes && std::isnan(a.loop.voxel_m)) a.loop.voxel_m = live::kLiveMeshVoxelM;
  if (a.out.empty()) throw Error("an output folder is required", fieldContext("--out"));
  Loaded l = load(a.take, a.loop, a.layers || a.exr);
  const carving::FrameRange range = a.frames.empty() ? carving::FrameRange{} : carving::parseFrameRange(a.frames);
  std::vector<int> frames;
  for (int f : l.take->frames())
    if (range.contains(f)) frames.push_back(f);
  // Live: --live NAME=SOURCE, or cameras the take names "live:..." (take/live.h).
  bool take_live = false;
  for (const std::string& name : l.take->streams().cameras())
    take_live = take_live || l.take->streams().stream(name).kind == take::SourceKind::kLive;
  const bool is_live = !a.live.empty() || take_live;
  if (frames.empty() && !is_live) throw Error("no frame of the take is in the range", fieldContext("--frames"));
  std::unique_ptr<LiveReader> live;
  if (is_live) {
    LiveOptions lo;
    for (const std::string& item : a.live) {
      const size_t eq = item.find('=');
      if (eq == std::string::npos || eq == 0 || eq + 1 == item.size())
        throw Error("expected NAME=SOURCE (device index, file or GStreamer pipeline), got '" + item + "'", fieldContext("--live"));
      lo.sources[item.substr(0, eq)] = item.substr(eq + 1);
    }
    lo.pace = !a.no_pace;
    lo.fps = a.live_fps;
    live = std::make_unique<LiveReader>(*l.loop, *l.reader, lo);
  }

  const fs::path out(a.out);
  // Every frame is written again: the temporaries of a run killed before (kill -9) go.
  removeLeftoverTemporaries(out, true);
  composite::OutputOptions oo;
  oo.out = out;
  oo.exr = a.exr;
  oo.layers = a.layers;
  oo.video = a.video;
  if (!a.video.empty() && fs::path(a.video).extension() == ".avi") oo.fourcc = "MJPG";
  composite::CompositeWriter writer(oo);
  const std::string main = l.loop->mainCamera();
  if (!a.quiet) {
    std::cerr << "run: " << (live ? std::string("live") : std::to_string(frames.size()) + " frames") << ", "
              << l.loop->carveCameras().size()
              << " witnesses carve, main '" << main << "'" << (l.lens_note.empty() ? "" : ", " + l.lens_note)
              << (l.props_note.empty() ? ", no props" : ", " + l.props_note)
              << (l.tracker_note.empty() ? "" : ", " + l.tracker_note)
              << "; stages:";
    for (const std::string& s : l.loop->stages()) std::cerr << " " << s;
    std::cerr << " -> " << out << "\n";
  }

  std::string poses, report, prop_lines;
  std::map<std::string, double> stage_sum;
  std::vector<std::string> stage_order;
  double total_ms = 0;
  nlohmann::json dropped = nlohmann::json::array();
  nlohmann::json failed = nlohmann::json::array();  // frames not composited: {"frame", "reason"}
  const Stopwatch start;
  int done = 0;
  std::vector<int> ran;
  const size_t live_limit = range.end >= 0 ? static_cast<size_t>(range.end - range.first) : 0;
  for (size_t next = 0;; ++next) {
    const Stopwatch t0;
    FrameState s;
    if (live) {
      if (live_limit > 0 && ran.size() >= live_limit) break;
      if (!live->next(s)) break;
    } else {
      if (next >= frames.size()) break;
      try {
        l.reader->read(frames[next], s);
      } catch (const Error& e) {
        ran.push_back(frames[next]);
        failed.push_back({{"frame", frames[next]}, {"reason", e.what()}});
        std::cerr << "run: frame " << frames[next] << " failed: " << e.what() << "\n";
        continue;
      }
    }
    const int f = s.frame;
    ran.push_back(f);
    const double read_ms = t0.ms();
    std::vector<StageTime> times;
    try {
      times = l.loop->run(s);
    } catch (const Error& e) {
      // A frame that cannot be composited (too few witnesses, ...) is reported and skipped.
      failed.push_back({{"frame", f}, {"reason", e.what()}});
      std::cerr << "run: frame " << f << " failed: " << e.what() << "\n";
      continue;
    }
    const Stopwatch w0;
    writer.write(f, s.composite);
    writeDepthExr(out / "depth" / (frameStem(f) + ".exr"), s.main_depth,
                  {{"previz:camera", main}, {"previz:frame", std::to_string(f)},
                   {"previz:source", "visual hull (previz run)"}});
    if (a.meshes) writePly(l.loop->carver().mesh(s.hull), out / "mesh" / (frameStem(f) + ".ply"));
    const double write_ms = w0.ms();
    times.insert(times.begin(), StageTime{"read", read_ms});
    times.push_back(StageTime{"write", write_ms});
    double frame_ms = 0;
    for (const StageTime& t : times) {
      if (!stage_sum.count(t.stage)) stage_order.push_back(t.stage);
      stage_sum[t.stage] += t.ms;
      frame_ms += t.ms;
    }
    total_ms += frame_ms;
    nlohmann::json drops = nlohmann::json::array();
    for (size_t i = 0; i < s.dropped.size(); ++i) {
      if (s.dropped[i].empty()) continue;
      const std::string cam = l.loop->carveCameras()[i];
      drops.push_back({{"camera", cam}, {"reason", s.dropped[i]}});
      dropped.push_back({{"camera", cam}, {"frame", f}, {"reason", s.dropped[i]}});
      std::cerr << "run: frame " << f << ": camera '" << cam << "' dropped: " << s.dropped[i] << "\n";
    }
    if (s.props) prop_lines += tracking::trackFrameToJson(*s.props).dump() + "\n";
    poses += nlohmann::json{{"frame", f}, {"camera", main}, {"T_world_cam", poseToJson(s.main.T_world_cam)}}.dump() + "\n";
    const composite::CompositeStats& cs = s.composite.stats;
    report += nlohmann::json{{"frame", f},
                             {"ms", stageJson(times)},
                             {"total_ms", frame_ms},
                             {"cameras_dropped", drops},
                             {"hull", {{"surface_cells", s.hull.stats.surface_cells}, {"inside_cells", s.hull.stats.inside_cells}}},
                             {"composite", {{"actor_px", cs.actor_px}, {"actor_front_px", cs.actor_front_px},
                                            {"cg_front_px", cs.cg_front_px}, {"edge_filled_px", cs.edge_filled_px},
                                            {"fallback_px", cs.fallback_px}}}}
                  .dump() + "\n";
    ++done;
    if (!a.quiet) {
      const double fps = 1000.0 * done / std::max(1e-9, start.ms());
      std::fprintf(stderr, "[run] frame %d (%d/%s) |", f, done, live ? "live" : std::to_string(frames.size()).c_str());
      for (const StageTime& t : times) std::fprintf(stderr, " %s %.1f", t.stage.c_str(), t.ms);
      std::fprintf(stderr, " ms | %.2f fps%s\n", fps,
                   live ? (" | dropped " + std::to_string(live->dropped())).c_str() : "");
    }
  }
  if (ran.empty()) throw Error("no frame was run (the live sources gave none)", fieldContext("--live"));
  frames.clear();
  for (int f : ran)
    if (std::none_of(failed.begin(), failed.end(), [&](const nlohmann::json& j) { return j["frame"] == f; }))
      frames.push_back(f);
  writer.close();
  writeFileAtomic(out / "poses.jsonl", poses);
  writeFileAtomic(out / "run.jsonl", report);
  if (l.props) writeFileAtomic(out / "props.jsonl", prop_lines);
  nlohmann::json mean = nlohmann::json::object();
  for (const std::string& s : stage_order) mean[s] = frames.empty() ? 0.0 : stage_sum[s] / frames.size();
  const double fps = total_ms > 0 ? 1000.0 * frames.size() / total_ms : 0.0;
  std::cerr << "run: " << frames.size() << " frames, " << failed.size() << " failed, " << fps
            << " fps (read and write included)";
  if (live)
    std::cerr << ", live at " << live->fps() << " fps: " << live->delivered() << " frames processed, "
              << live->dropped() << " dropped (late)";
  std::cerr << " -> " << out << "\n";
  if (l.tracker) std::cerr << "run: tracker " << l.tracker->summary().dump() << "\n";
  if (a.json) {
    std::cout << nlohmann::json{{"command", "run"},
                                {"out", out.string()},
                                {"frames", frames},
                                {"stages", stage_order},
                                {"mean_ms", mean},
                                {"fps", fps},
                                {"dropped", dropped},
                                {"failed", failed},
                                {"props", l.props ? nlohmann::json((out / "props.jsonl").string()) : nlohmann::json()},
                                {"tracker", l.tracker ? l.tracker->summary() : nlohmann::json()},
                                {"live", live ? nlohmann::json{{"fps", live->fps()},
                                                               {"delivered", live->delivered()},
                                                               {"dropped_frames", live->dropped()}}
                                              : nlohmann::json()}}
                     .dump()
              << "\n";
  }
  // A frame not composited is a failure, said in the exit status as `previz carve` does.
  return failed.empty() ? 0 : 1;
}

// ---- previz bench run --------------------------------------------------------------------

struct BenchArgs {
  std::string take, out = "out/bench_run";
  int frames = 3;
  int repeats = 5;
  double fps = 0.5;  // default studio: frames 2 s apart over the choreography
  double noise = 2.0;  // default studio: sensor noise, grey levels (a camera's plate is never clean)
  std::string scaling;  // "1,2,4": the loop timed again at each thread count
  LoopArgs loop;
  bool json = false;
};

// Start-up (issue 31): the shared objects this process mapped before any command ran, counted as
// `ldd previz | wc -l` counts them (every one but the executable: the vDSO and the dynamic
// loader included). Called first thing: plugins load later, when a command needs them.
int startupLibraries() {
  int objects = 0;
  dl_iterate_phdr([](dl_phdr_info*, size_t, void* count) { return ++*static_cast<int*>(count), 0; }, &objects);
  return objects - 1;
}

// The median wall time of `previz --version` (this binary) run 5 times as a child: the price of
// starting previz at all (loading its libraries), which every command and every batch task pays.
double versionMs() {
  std::error_code ec;
  const fs::path self = fs::read_symlink("/proc/self/exe", ec);
  batch::ProcessSpec spec;
  spec.argv = {ec ? std::string("/proc/self/exe") : self.string(), "--version"};
  spec.stdout_path = "/dev/null";
  std::vector<double> ms;
  for (int i = 0; i < 5; ++i) {
    const Stopwatch t0;
    if (const int status = batch::runProcess(spec))
      throw Error("bench run: `previz --version` exited with " + std::to_string(status), fileContext(spec.argv[0]));
    ms.push_back(t0.ms());
  }
  return median(ms);
}

// The floor the frame is measured against (issue 31), timed on each frame's own plates between
// the frames, so that it sees the same machine as the frame beside it: a plain binary green key of
// every camera's plate (G - max(R, B) > 40 in 8-bit codes, into a mask; no screen model, no soft
// edge, no cleaning), one OpenMP loop over all the plates' rows at the loop's thread count. What a
// frame costs over this is the rest of the work; the ratio moves less with the machine's speed
// than either time does. Masks reused from frame to frame.
PREVIZ_WIDE
void binaryKeyRows(const cv::Mat& bgr, int y0, int y1, cv::Mat& mask) {
  const int n = bgr.cols;
  for (int y = y0; y < y1; ++y) {
    const std::uint8_t* p = bgr.ptr<std::uint8_t>(y);
    std::uint8_t* m = mask.ptr<std::uint8_t>(y);
    for (int x = 0; x < n; ++x) {
      const int g = p[3 * x + 1], rb = std::max(p[3 * x], p[3 * x + 2]);
      m[x] = g - rb > 40 ? 255 : 0;
    }
  }
}

double binaryKeyFloorMs(const FrameState& s, int threads, std::vector<cv::Mat>& masks) {
  std::vector<const cv::Mat*> plates;
  for (const cv::Mat& p : s.witness_plates)
    if (!p.empty()) plates.push_back(&p);
  plates.push_back(&s.main_plate);
  masks.resize(plates.size());
  constexpr int kRows = 16;  // rows per work item
  std::vector<std::pair<int, int>> items;  // (plate, first row)
  for (size_t i = 0; i < plates.size(); ++i) {
    masks[i].create(plates[i]->size(), CV_8UC1);
    for (int y = 0; y < plates[i]->rows; y += kRows) items.emplace_back(static_cast<int>(i), y);
  }
  const Stopwatch t0;
#pragma omp parallel for schedule(static) num_threads(threads)
  for (size_t k = 0; k < items.size(); ++k) {
    const cv::Mat& p = *plates[items[k].first];
    binaryKeyRows(p, items[k].second, std::min(p.rows, items[k].second + kRows), masks[items[k].first]);
  }
  return t0.ms();
}

// The sensor noise a synthetic take was rendered with (take.json "options"), if it says.
std::optional<double> takeNoiseSigma(const nlohmann::json& take) {
  const nlohmann::json options = take.value("options", nlohmann::json::object());
  if (!options.is_object() || !options.contains("noise_sigma") || !options["noise_sigma"].is_number())
    return std::nullopt;
  return options["noise_sigma"].get<double>();
}

// The default studio of the benchmarks: 8 witnesses 1280x720 + main 1920x1080, rendered once
// and kept under 'out' (one folder per fps and noise: take, take_24fps, take_noise0, ...).
fs::path defaultBenchTake(const std::string& out, int frame_count, double fps, double noise, const char* who) {
  if (!(fps > 0) || !std::isfinite(fps))
    throw Error(std::string(who) + ": --fps must be a finite value > 0 (got " + std::to_string(fps) + ")",
                fieldContext("--fps"));
  if (!(noise >= 0) || !std::isfinite(noise))
    throw Error(std::string(who) + ": --noise must be a finite value >= 0 (got " + std::to_string(noise) + ")",
                fieldContext("--noise"));
  std::string folder = "take";
  char part[64];
  if (fps != 0.5) {
    std::snprintf(part, sizeof part, "_%gfps", fps);
    folder += part;
  }
  if (noise != 2.0) {
    std::snprintf(part, sizeof part, "_noise%g", noise);
    folder += part;
  }
  const fs::path take_dir = fs::path(out) / folder;
  synth::SynthOptions so;
  so.frames = frame_count;
  so.fps = fps;  // 0.5: frames 2 s apart over the choreography (behind the pillar at 2 s)
  so.noise_sigma = noise;
  so.write_meshes = false;
  bool have = false;
  if (fs::exists(take_dir / "take.json")) {
    const nlohmann::json t = readJsonFile(take_dir / "take.json");
    have = t.value("frames", 0) == so.frames && t.value("fps", 0.0) == so.fps && takeNoiseSigma(t) == so.noise_sigma;
  }
  if (!have) {
    std::cerr << who << ": rendering the default studio (" << so.frames << " frames, 8 x 1280x720 + 1920x1080, noise "
              << so.noise_sigma << " grey levels) into " << take_dir << " (once)\n";
    synth::synthesizeTake(so, take_dir);
  }
  return take_dir;
}

// How good the frames bench run times are, against the synthetic take's truth (truth/labels:
// the keyer's foreground is the actor and the props; truth/masks/main, truth/composite) and
// the exact hull of the same silhouettes (a 5 mm carve: the live loop carves at 1 cm,
// docs/formats.md): witness silhouettes' IoU, main-view depth against that hull (mm, where
// both have depth), composite PSNR over the actor's bounding box. Nothing when the take has no
// truth (a real take).
class BenchQuality {
 public:
  BenchQuality(const fs::path& take_dir, const FrameLoop& loop) : take_dir_(take_dir), loop_(loop) {
    if (!fs::is_directory(take_dir / "truth" / "labels")) return;
    carving::HullOptions fine = loop.carver().options();
    fine.voxel_m = 0.005;
    exact_ = std::make_unique<carving::Carver>(loop.carver().cameras(), fine);
  }

  void add(const FrameState& s) {
    if (!exact_) return;
    const fs::path truth = take_dir_ / "truth";
    const std::string stem = frameStem(s.frame) + ".png";
    const std::vector<std::string>& names = loop_.carveCameras();
    for (size_t i = 0; i < names.size() && i < s.silhouettes.size(); ++i) {
      const fs::path path = truth / "labels" / names[i] / stem;
      if (s.silhouettes[i].empty() || !fs::exists(path)) continue;
      const cv::Mat labels = readImage(path, 0 /* grey */);
      cv::Mat mask = (labels == static_cast<int>(synth::ObjectClass::kActor)) |
                     (labels == static_cast<int>(synth::ObjectClass::kProp));
      if (mask.size() != s.silhouettes[i].size()) {  // witnesses keyed binned (--witness-bin)
        cv::resize(mask, mask, s.silhouettes[i].size(), 0, 0, cv::INTER_AREA);
      }
      const cv::Mat truth_in = mask > 127, key_in = s.silhouettes[i] > 127;
      const double both = cv::countNonZero(truth_in & key_in), any = cv::countNonZero(truth_in | key_in);
      if (any > 0) iou_.push_back(both / any);
    }
    carving::Silhouettes sil{s.silhouettes, s.dropped};
    const carving::VisualHull hull = exact_->carve(sil);
    const cv::Mat exact = exact_->depth(hull, s.main, s.main_key.silhouette);
    for (int v = 0; v < exact.rows; ++v) {
      const float* e = exact.ptr<float>(v);
      const float* d = s.main_depth.ptr<float>(v);
      for (int u = 0; u < exact.cols; ++u) {
        if (std::isfinite(e[u]) != std::isfinite(d[u])) ++depth_mismatch_px_;
        else if (std::isfinite(e[u])) depth_err_mm_.push_back(1000.0 * std::abs(d[u] - e[u]));
      }
    }
    const fs::path comp = truth / "composite" / stem, main_mask = truth / "masks" / loop_.mainCamera() / stem;
    if (fs::exists(comp) && fs::exists(main_mask))
      psnr_.push_back(composite::actorPsnr(s.composite.bgr, readImage(comp, 1 /* colour */),
                                           readImage(main_mask, 0)).psnr_db);
  }

  std::optional<nlohmann::json> summary() const {
    if (!exact_ || iou_.empty()) return std::nullopt;
    auto at = [](std::vector<double> v, double q) {
      if (v.empty()) return std::nan("");
      std::sort(v.begin(), v.end());
      return v[std::min(v.size() - 1, static_cast<size_t>(q * static_cast<double>(v.size())))];
    };
    return nlohmann::json{
        {"witness_iou_min", at(iou_, 0)}, {"witness_iou_median", at(iou_, 0.5)},
        {"depth_vs_exact_hull_mm_median", at(depth_err_mm_, 0.5)},
        {"depth_vs_exact_hull_mm_p95", at(depth_err_mm_, 0.95)},
        {"depth_vs_exact_hull_px", depth_err_mm_.size()}, {"depth_vs_exact_hull_mismatch_px", depth_mismatch_px_},
        {"composite_actor_psnr_db_min", at(psnr_, 0)}, {"composite_actor_psnr_db_median", at(psnr_, 0.5)}};
  }

 private:
  fs::path take_dir_;
  const FrameLoop& loop_;
  std::unique_ptr<carving::Carver> exact_;
  std::vector<double> iou_, depth_err_mm_, psnr_;
  long long depth_mismatch_px_ = 0;
};

// Thread counts of --scaling ("1,2,4"); throws Error naming the flag.
std::vector<int> parseScaling(const std::string& text) {
  std::vector<int> counts;
  for (const std::string& item : splitList(text)) {
    try {
      size_t used = 0;
      const int n = std::stoi(item, &used);
      if (used != item.size() || n < 1 || n > 1024) throw std::invalid_argument(item);
      counts.push_back(n);
    } catch (const std::exception&) {
      throw Error("bench run: thread counts are integers in [1, 1024], comma-separated (got '" + text + "')",
                  fieldContext("--scaling"));
    }
  }
  return counts;
}

int runBench(const BenchArgs& a) {
  const std::vector<int> scaling = parseScaling(a.scaling);
  const int startup_libraries = startupLibraries();
  const double version_ms = versionMs();
  const fs::path take_dir = a.take.empty() ? defaultBenchTake(a.out, a.frames, a.fps, a.noise, "bench run") : fs::path(a.take);
  Loaded l = load(take_dir, a.loop, false);
  std::vector<int> frames = l.take->frames();
  if (static_cast<int>(frames.size()) > a.frames) frames.resize(a.frames);
  // Inputs decoded once (the live loop gets frames from capture, not PNG files).
  std::vector<FrameState> inputs(frames.size());
  std::vector<double> read_ms;
  for (size_t i = 0; i < frames.size(); ++i) {
    const Stopwatch t0;
    l.reader->read(frames[i], inputs[i]);
    read_ms.push_back(t0.ms());
  }
  // Warm-up: the keyers' screen models and the depth ray table are built on the first frame.
  { FrameState s = inputs[0]; l.loop->run(s); }
  std::map<std::string, std::vector<double>> ms, cpu;
  std::vector<double> total, total_cpu, floor_ms, over_floor;
  std::vector<cv::Mat> floor_masks;
  int prop_frames = 0, prop_full_frames = 0;
  BenchQuality quality(take_dir, *l.loop);
  std::vector<std::string> order = l.loop->stages();
  for (int r = 0; r < a.repeats; ++r) {
    for (const FrameState& in : inputs) {
      FrameState s = in;
      double sum = 0, sum_cpu = 0;
      for (const StageTime& t : l.loop->run(s)) {
        ms[t.stage].push_back(t.ms);
        cpu[t.stage].push_back(t.cpu_ms);
        sum += t.ms;
        sum_cpu += t.cpu_ms;
      }
      if (s.props) {
        ++prop_frames;
        prop_full_frames += s.props->full_frame ? 1 : 0;
      }
      if (r == 0) quality.add(s);  // after the timed stages
      total.push_back(sum);
      total_cpu.push_back(sum_cpu);
      floor_ms.push_back(binaryKeyFloorMs(in, resolveThreads(a.loop.threads), floor_masks));
      over_floor.push_back(sum / floor_ms.back());
    }
  }
  const double budget_ms = 20.0;
  const std::map<std::string, double> stage_budget = {{"key", 5}, {"carve", 5}, {"depth", 5}, {"props", 3}, {"composite", 2}};
  nlohmann::json stages = nlohmann::json::array();
  std::string largest;
  double largest_ms = -1;
  const Camera& main = l.take->rig().at(l.loop->mainCamera()).camera;
  const Camera& w0 = l.take->rig().at(l.loop->carveCameras().front()).camera;
  const std::string size = std::to_string(l.loop->carveCameras().size()) + "x" + std::to_string(w0.width) + "x" +
                           std::to_string(w0.height) + "+" + std::to_string(main.width) + "x" + std::to_string(main.height);
  for (const std::string& s : order) {
    const double m = median(ms[s]);
    if (m > largest_ms) {
      largest_ms = m;
      largest = s;
    }
    nlohmann::json j = {{"stage", s}, {"size", size}, {"ms", m}, {"cpu_ms", median(cpu[s])}};
    if (stage_budget.count(s)) j["budget_ms"] = stage_budget.at(s);
    stages.push_back(j);
    std::fprintf(stderr, "  %-10s %8.2f ms wall, %8.2f ms CPU (all threads)%s\n", s.c_str(), m, median(cpu[s]),
                 stage_budget.count(s) ? (" (budget " + std::to_string(int(stage_budget.at(s))) + " ms)").c_str() : "");
  }
  const double t = median(total);
  std::fprintf(stderr,
               "bench run: %s, %d threads: %.2f ms a frame (%.1f fps) against the %.0f ms target (%+.1f ms); largest "
               "stage: %s %.2f ms; reading the PNGs (not in the loop): %.1f ms a frame\n",
               size.c_str(), resolveThreads(a.loop.threads), t, 1000.0 / t, budget_ms,
               t - budget_ms, largest.c_str(), largest_ms, median(read_ms));
  if (prop_frames > 0 && prop_full_frames == prop_frames)
    std::fprintf(stderr, "bench run: props searched every camera's whole frame on every frame (these frames are further "
                 "apart than the tracker's filter bridges); at camera rate it searches predicted regions: "
                 "bench run --fps 24\n");
  const double mean_ms = std::accumulate(total.begin(), total.end(), 0.0) / static_cast<double>(total.size());
  const double p95_ms = quantile(total, 0.95), max_ms = *std::max_element(total.begin(), total.end());
  std::fprintf(stderr, "bench run: frame time mean %.2f ms, p95 %.2f ms, max %.2f ms\n", mean_ms, p95_ms, max_ms);
  std::fprintf(stderr, "bench run: a plain binary green key of the same plates (the floor, timed between the frames) "
               "%.2f ms: the frame is %.1f times that\n", median(floor_ms), median(over_floor));
  std::fprintf(stderr, "bench run: start-up: %d shared libraries loaded, `previz --version` %.1f ms (median of 5)\n",
               startup_libraries, version_ms);
  std::fprintf(stderr, "bench run: CPU time a frame (all threads) %.2f ms: an idle %d-core machine that scaled perfectly "
               "would take %.2f ms\n", median(total_cpu), resolveThreads(a.loop.threads),
               median(total_cpu) / resolveThreads(a.loop.threads));
  nlohmann::json j = {{"stage", "run"},      {"size", size},   {"ms", t}, {"cpu_ms", median(total_cpu)},
                      {"fps", 1000.0 / t},   {"target_ms", budget_ms}, {"largest_stage", largest},
                      {"largest_ms", largest_ms}, {"stages", stages}, {"frames", frames.size()},
                      {"repeats", a.repeats}, {"threads", resolveThreads(a.loop.threads)},
                      {"read_png_ms", median(read_ms)}, {"take", take_dir.string()},
                      {"witness_bin", a.loop.witness_bin},
                      {"voxel_m", l.loop->carver().options().voxel_m},
                      {"depth_step_m", l.loop->carver().options().depth_step_m},
                      {"key_region_margin_px", a.loop.key_region_margin_px},
                      {"key_main_region", a.loop.key_region_margin_px > 0 && !a.loop.key_main_whole},
                      {"props_pooled_with_key", l.props != nullptr && !a.loop.props_own_pool},
                      {"simd", wideVersion()},
                      {"binary_key_floor_ms", median(floor_ms)}, {"frame_over_floor", median(over_floor)},
                      // Frames are not overlapped: a frame's composite is out when its stages are done.
                      {"latency_ms", t},
                      // The spread the median hides: a frame that keys a witness whole or searches a
                      // camera's whole frame for tags (staggered over the cameras), and each repeat's
                      // first frame, which starts the region keys and the prop tracker over.
                      {"ms_mean", mean_ms}, {"ms_p95", p95_ms}, {"ms_max", max_ms},
                      {"startup", {{"libraries", startup_libraries}, {"version_ms", version_ms}}}};
  // The same frames at each thread count of --scaling, a loop built for each (warmed up first).
  if (!scaling.empty()) {
    nlohmann::json rows = nlohmann::json::array();
    double ms_at_1 = 0;
    for (const int n : scaling) {
      LoopArgs la = a.loop;
      la.threads = n;
      Loaded ln = load(take_dir, la, false);
      { FrameState s = inputs[0]; ln.loop->run(s); }
      std::vector<double> wall, cpu_ms;
      for (int r = 0; r < a.repeats; ++r)
        for (const FrameState& in : inputs) {
          FrameState s = in;
          double sum = 0, sum_cpu = 0;
          for (const StageTime& st : ln.loop->run(s)) {
            sum += st.ms;
            sum_cpu += st.cpu_ms;
          }
          wall.push_back(sum);
          cpu_ms.push_back(sum_cpu);
        }
      const double m = median(wall);
      if (n == 1) ms_at_1 = m;
      rows.push_back({{"threads", n}, {"ms", m}, {"cpu_ms", median(cpu_ms)}, {"fps", 1000.0 / m}});
      std::fprintf(stderr, "bench run: %d thread%s: %.2f ms a frame (%.1f fps), %.2f ms CPU\n", n, n == 1 ? "" : "s", m,
                   1000.0 / m, median(cpu_ms));
    }
    if (ms_at_1 > 0)
      for (nlohmann::json& row : rows) row["speedup"] = ms_at_1 / row["ms"].get<double>();
    j["scaling"] = rows;
  }
  if (const std::optional<nlohmann::json> q = quality.summary()) {
    j["quality"] = *q;
    std::fprintf(stderr, "bench run: quality against the truth: %s\n", q->dump().c_str());
  }
  // The plates' sensor noise, as the take records it (synthetic takes): the keyer's work grows with it.
  if (fs::exists(take_dir / "take.json")) {
    const std::optional<double> noise = takeNoiseSigma(readJsonFile(take_dir / "take.json"));
    if (noise) j["noise_sigma"] = *noise;
  }
  // The props stage searches whole frames when the frames are further apart than its filter
  // bridges (the default take: 2 s) and predicted regions at camera rate.
  if (l.props)
    j["props_full_frame_fraction"] = prop_frames ? double(prop_full_frames) / prop_frames : 0.0;
  std::cout << j.dump() << "\n";
  return 0;
}

// ---- previz bench take --------------------------------------------------------------------

struct BenchTakeArgs {
  std::string out = "out/bench_take", formats = "png,exr,ffv1,h264";
  int frames = 8;
  LoopArgs loop;
};

// Decoding a frame set (every camera's image of one take frame) from each form the take model
// reads, and the frame loop with its input read from that form: one JSON line each.
int runBenchTake(const BenchTakeArgs& a) {
  const fs::path png = defaultBenchTake(a.out, a.frames, 24.0, 2.0, "bench take");
  std::vector<std::pair<std::string, fs::path>> sources;
  for (const std::string& format : splitList(a.formats)) {
    if (format == "png") {
      sources.push_back({format, png});
      continue;
    }
    const fs::path dir = fs::path(a.out) / ("take_24fps_" + format);
    bool have = false;
    if (fs::exists(dir / "take.json")) {
      const nlohmann::json j = readJsonFile(dir / "take.json");
      have = j.value("converted_from", nlohmann::json::object()).value("format", "") == format &&
             j.value("frames", 0) == a.frames;
    }
    if (!have) {
      std::cerr << "bench take: converting the take to " << format << " (once)\n";
      fs::remove_all(dir);
      take::ConvertOptions co;
      co.writer.format = format;
      take::convertTake(png, dir, co);
    }
    sources.push_back({format, dir});
  }
  for (const auto& [format, dir] : sources) {
    // The frame sets alone, frames in order (videos decode ahead on their worker threads).
    const Stopwatch t_open;
    const take::Take t(dir);
    const double open_ms = t_open.ms();
    std::vector<double> read_ms;
    long long bytes = 0;
    std::error_code ec;
    for (const auto& e : fs::recursive_directory_iterator(dir / "cams", ec))
      if (e.is_regular_file(ec)) bytes += static_cast<long long>(e.file_size(ec));
    std::string size;
    for (int f : t.frames()) {
      const Stopwatch t0;
      const take::FrameSet set = t.readFrameSet(f, t.cameras());
      read_ms.push_back(t0.ms());
      if (set.usable() != static_cast<int>(t.cameras().size()))
        throw Error("bench take: a camera of frame " + std::to_string(f) + " did not read", fileContext(dir.string()));
    }
    const double first_ms = read_ms.front();
    // The loop with its input read from the form each frame: decode of frame N + 1 overlaps the
    // processing of frame N where the form decodes ahead (videos).
    // Frame 0 warms the loop up (screen models, ray tables); frames 1.. are timed.
    Loaded l = load(dir, a.loop, false);
    const std::vector<int> frames = l.take->frames();
    {
      FrameState warm;
      l.reader->read(frames.front(), warm);
      l.loop->run(warm);
    }
    std::vector<double> frame_ms, loop_read_ms;
    const Stopwatch t_loop;
    for (size_t i = 1; i < frames.size(); ++i) {
      const Stopwatch t0;
      FrameState s;
      l.reader->read(frames[i], s);
      loop_read_ms.push_back(t0.ms());
      l.loop->run(s);
      frame_ms.push_back(t0.ms());
    }
    const double loop_ms = t_loop.ms();
    const Camera& main = l.take->rig().at(l.loop->mainCamera()).camera;
    const Camera& w0 = l.take->rig().at(l.loop->carveCameras().front()).camera;
    size = std::to_string(l.loop->carveCameras().size()) + "x" + std::to_string(w0.width) + "x" +
           std::to_string(w0.height) + "+" + std::to_string(main.width) + "x" + std::to_string(main.height);
    std::cout << nlohmann::json{{"stage", "read_frameset"},
                                {"source", format},
                                {"size", size},
                                {"frames", read_ms.size()},
                                {"ms", median(read_ms)},
                                {"ms_first", first_ms},
                                {"open_ms", open_ms},
                                {"mb_per_frameset", bytes / 1e6 / std::max<size_t>(1, read_ms.size())},
                                {"threads", defaultThreadCount()}}
                     .dump()
              << "\n";
    std::cout << nlohmann::json{{"stage", "loop_with_read"},
                                {"source", format},
                                {"size", size},
                                {"frames", frame_ms.size()},
                                {"ms", median(frame_ms)},
                                {"read_ms", median(loop_read_ms)},
                                {"fps", 1000.0 * frame_ms.size() / loop_ms},
                                {"threads", defaultThreadCount()}}
                     .dump()
              << "\n";
  }
  return 0;
}

}  // namespace

Runner addRunCommand(CLI::App& app) {
  auto a = std::make_shared<RunArgs>();
  CLI::App* cmd = app.add_subcommand(
      "run", "The live previz frame over a take: key -> carve -> main-view depth -> track props -> composite "
             "(docs/formats.md, \"Run output\")");
  cmd->add_option("--take", a->take, "Take folder (cams/: a sequence or video per camera, cg/; docs/formats.md \"Take folder\")")->required();
  cmd->add_option("--out", a->out, "Output folder")->required();
  addLoopOptions(cmd, a->loop, false);
  addTrackerOptions(cmd, a->loop);
  cmd->add_option("--frames", a->frames, "Frames A:B (A inclusive, B exclusive), A:, :B or A");
  cmd->add_option("--live", a->live,
                  "Read cameras live through OpenCV VideoCapture: NAME=SOURCE per camera (device index, "
                  "/dev/videoN, video file or stream URL through FFmpeg, or a GStreamer pipeline); late frames are dropped and counted (repeatable)");
  cmd->add_flag("--no-pace", a->no_pace, "Live: process every frame (files), never drop");
  cmd->add_option("--live-fps", a->live_fps, "Live: camera rate for pacing (default: the main source's)");
  cmd->add_flag("--meshes", a->meshes, "Also write the hull mesh of every frame (mesh/%06d.ply)");
  cmd->add_flag("--layers", a->layers, "Also write the compositor's debug layers");
  cmd->add_flag("--exr", a->exr, "Also write linear EXR composites");
  cmd->add_option("--video", a->video, "Also write the composites as a video OUT/NAME (.mp4, or .avi = MJPG)");
  cmd->add_flag("--json", a->json, "Print a JSON summary on stdout");
  cmd->add_flag("--quiet", a->quiet, "No per-frame line");
  return [a]() { return runRun(*a); };
}

Runner addBenchCommand(CLI::App& app) {
  CLI::App* bench = app.add_subcommand("bench", "Benchmarks of the whole system (per-stage ones: bench/)");
  bench->require_subcommand(1);
  auto a = std::make_shared<BenchArgs>();
  CLI::App* cmd = bench->add_subcommand(
      "run", "The whole frame loop on frames in memory (default studio: 8 x 1280x720 + 1920x1080): ms per "
             "stage, total, fps, and previz's start-up (shared libraries loaded, --version ms), as JSON on stdout");
  cmd->add_option("--take", a->take, "Take to run on (default: render the default studio into OUT/take once)");
  cmd->add_option("--out", a->out, "Where the default take is kept")->capture_default_str();
  cmd->add_option("--frames", a->frames, "Frames measured")->capture_default_str();
  cmd->add_option("--repeats", a->repeats, "Runs over the frames (medians reported)")->capture_default_str();
  cmd->add_option("--fps", a->fps,
                  "Default studio: frame rate it is rendered at (0.5: frames 2 s apart over the choreography; "
                  "24: consecutive frames at camera rate, the props stage on predicted regions)")
      ->capture_default_str();
  cmd->add_option("--noise", a->noise,
                  "Default studio: sensor noise it is rendered with, grey levels (sigma; 0: noise-free plates, which "
                  "the keyer decides almost everywhere on its fast path)")
      ->capture_default_str();
  cmd->add_option("--scaling", a->scaling,
                  "Also time the loop at each of these thread counts (1,2,4,...: \"scaling\" in the JSON, with the "
                  "speedup over 1 thread when 1 is among them)");
  addLoopOptions(cmd, a->loop, false);
  cmd->add_flag("--json", a->json, "JSON on stdout (always written; kept for uniformity)");
  auto bt = std::make_shared<BenchTakeArgs>();
  CLI::App* take_cmd = bench->add_subcommand(
      "take", "Decoding the cameras' streams: ms per frame set (every camera's image of a frame) from PNG, EXR, "
              "FFV1 and H.264 forms of the default studio at 24 fps, and the frame loop's fps reading each");
  take_cmd->add_option("--out", bt->out, "Where the takes are kept")->capture_default_str();
  take_cmd->add_option("--frames", bt->frames, "Frames of the take")->capture_default_str();
  take_cmd->add_option("--formats", bt->formats, "Forms compared (take convert --format)")->capture_default_str();
  addLoopOptions(take_cmd, bt->loop, false);
  return [a, cmd, take_cmd, bt]() { return take_cmd->parsed() ? runBenchTake(*bt) : runBench(*a); };
}

}  // namespace previz::app
