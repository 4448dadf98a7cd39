// previz demo (README command 1): renders the built-in synthetic studio, calibrates every
// camera's intrinsics from its own board take (intrinsics preset) through the chain `previz calib
// intrinsics` runs (calib/pipeline.h: detect, reject soft views, select, solve, uncertainty,
// cross-validation; calib report pictures), calibrates the rig from a rig take (rig preset: board waved, then on the floor;
// intrinsics held at the calibrated ones), runs the live frame (key -> carve -> main-view depth
// -> track props -> composite, live/frame_loop.h) over the studio take with the calibrated rig (the main
// camera's dolly motion from the take's tracker file, relative to where it stood during the rig
// take) and, for comparison, with the take's true rig, and writes a report page (report.html):
// calibration figures against truth, the rig picture, composites beside the true ones, PSNR,
// depth previews, the front/behind layer and the stage timings. Layout: docs/formats.md.

#include <array>
#include <filesystem>
#include <iostream>
#include <map>
#include <optional>
#include <sstream>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "app/commands.h"
#include "core/names.h"
#include "core/threads.h"
#include "core/units.h"
#include "live/frame_loop.h"
#include "live/inputs.h"
#include "app/options.h"
#include "app/progress.h"
#include "calib/detect.h"
#include "calib/intrinsics.h"
#include "calib/pipeline.h"
#include "calib/report.h"
#include "calib/validation.h"
#include "multicam/pipeline.h"
#include "carving/take.h"
#include "composite/measure.h"
#include "composite/output.h"
#include "core/board.h"
#include "core/io.h"
#include "core/pose.h"
#include "core/rig.h"
#include "core/stats.h"
#include "core/text.h"
#include "datasets/synth.h"
#include "multicam/observations.h"
#include "multicam/rig_calib.h"
#include "multicam/rig_io.h"
#include "multicam/rig_picture.h"
#include "tracking/props.h"
#include "tracking/run.h"
#include "tracking/tracker.h"

namespace previz::app {
// The live frame (live/frame_loop.h, live/inputs.h).
using live::FrameLoop;
using live::FrameLoopOptions;
using live::FrameState;
using live::TakeReader;
using live::TakeInputOptions;
using live::PropStage;
using live::PropStageOptions;
using live::StageTime;
namespace {

namespace fs = std::filesystem;

struct DemoArgs {
  std::string out = "out/demo";
  std::string size;
  int frames = 12;
  int cams = 8;
  int fisheye_witnesses = 0;  // the first N witnesses with a fisheye lens
  std::uint64_t seed = 1;
  int views = 12;        // intrinsics board views per camera
  int select = 0;        // calibrate from the N most informative of them (0 = every usable view)
  int rig_frames = 48;   // rig take frames (the last few show the floor board)
  bool no_calibrate = false;
  bool json = false;
  bool quiet = false;
};

// Depth in metres -> false-colour preview (near = warm), black where empty (+inf).
cv::Mat depthPreview(const cv::Mat& depth_m) {
  double lo = 1e9, hi = 0;
  for (int y = 0; y < depth_m.rows; ++y) {
    for (int x = 0; x < depth_m.cols; ++x) {
      const float z = depth_m.at<float>(y, x);
      if (std::isfinite(z)) {
        lo = std::min(lo, double(z));
        hi = std::max(hi, double(z));
      }
    }
  }
  cv::Mat grey(depth_m.size(), CV_8U, cv::Scalar(0));
  cv::Mat valid(depth_m.size(), CV_8U, cv::Scalar(0));
  for (int y = 0; y < depth_m.rows; ++y) {
    for (int x = 0; x < depth_m.cols; ++x) {
      const float z = depth_m.at<float>(y, x);
      if (!std::isfinite(z) || hi <= lo) continue;
      grey.at<uchar>(y, x) = cv::saturate_cast<uchar>(255.0 * (hi - z) / (hi - lo));
      valid.at<uchar>(y, x) = 255;
    }
  }
  cv::Mat colour;
  cv::applyColorMap(grey, colour, cv::COLORMAP_TURBO);
  cv::Mat out(depth_m.size(), CV_8UC3, cv::Scalar(0, 0, 0));
  colour.copyTo(out, valid);
  return out;
}

cv::Mat labelled(const cv::Mat& bgr, const std::string& text, cv::Size tile) {
  cv::Mat t;
  cv::resize(bgr, t, tile, 0, 0, cv::INTER_AREA);
  cv::rectangle(t, cv::Rect(0, 0, tile.width, 22), cv::Scalar(0, 0, 0), cv::FILLED);
  cv::putText(t, text, cv::Point(6, 16), cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(255, 255, 255), 1,
              cv::LINE_AA);
  return t;
}

// One row per view: every camera's plate, then the main camera's truth layers.
cv::Mat contactSheet(const fs::path& take, const Rig& rig, int frame) {
  const std::string name = frameStem(frame);
  const cv::Size tile(384, 216);
  std::vector<cv::Mat> tiles;
  for (const RigCamera& rc : rig.cameras) {
    const std::string& cam = rc.camera.name;
    tiles.push_back(labelled(readImage(take / "cams" / cam / (name + ".png"), cv::IMREAD_COLOR),
                             cam + " plate", tile));
  }
  const fs::path truth = take / "truth";
  tiles.push_back(labelled(depthPreview(readDepthExr(truth / "depth" / kMainCamera / (name + ".exr"))),
                           "main depth (truth)", tile));
  cv::Mat mask = readImage(truth / "masks" / kMainCamera / (name + ".png"), cv::IMREAD_GRAYSCALE);
  cv::Mat mask_bgr;
  cv::cvtColor(mask, mask_bgr, cv::COLOR_GRAY2BGR);
  tiles.push_back(labelled(mask_bgr, "main actor mask (truth)", tile));
  tiles.push_back(labelled(readImage(truth / "composite" / (name + ".png"), cv::IMREAD_COLOR),
                           "true composite (target)", tile));
  const int cols = 4;
  const int rows = (static_cast<int>(tiles.size()) + cols - 1) / cols;
  cv::Mat sheet(rows * tile.height, cols * tile.width, CV_8UC3, cv::Scalar(40, 40, 40));
  for (size_t i = 0; i < tiles.size(); ++i) {
    const int r = static_cast<int>(i) / cols, c = static_cast<int>(i) % cols;
    tiles[i].copyTo(sheet(cv::Rect(c * tile.width, r * tile.height, tile.width, tile.height)));
  }
  return sheet;
}

// One camera's intrinsics as the demo calibrated them, against the take's truth.
struct CameraCalib {
  std::string camera;
  Camera truth;
  calib::IntrinsicsResult result;
  int views = 0, found = 0, soft = 0;
  std::vector<std::string> not_used;  // views the pipeline left out, with why
  std::string selection;              // the selector's summary ("" = every usable view)
};

// The rig as the demo calibrated it, against the rig take's truth.
struct RigCalib {
  multicam::RigCalibResult result;
  Rig truth;
  int frames = 0;
  std::vector<int> floor_frames;
  double detect_s = 0;
  multicam::SyncReport sync;
};

// Per camera of the studio rig: an intrinsics-preset take of its own (the board moved and tilted
// in front of it), detected and solved; the report files go to out/calib/<camera>.*.
std::vector<CameraCalib> calibrateCameras(const synth::SynthOptions& studio, const Rig& truth, int views,
                                          int select, const fs::path& out, bool quiet) {
  std::vector<CameraCalib> all;
  for (const RigCamera& rc : truth.cameras) {
    const std::string& name = rc.camera.name;
    synth::SynthOptions o = studio;
    o.preset = synth::Preset::kIntrinsics;
    o.camera = name;
    // A chessboard: always seen whole here, found at the smallest sizes, and its corners get the
    // pattern fit (calib/detect.h model_fit).
    o.board = "chessboard";
    o.frames = views;
    o.fps = 24;
    o.validate();
    const fs::path take = out / "calib_takes" / name;
    {
      ProgressLine progress("demo intrinsics take " + name, o.frames, quiet);
      synth::synthesizeTake(o, take, [&](const synth::SynthProgress& p) { progress.update(p.frames_done); });
    }
    const BoardSpec board = readBoard(take / "board.json");
    // The shipped chain (calib/pipeline.h, as `previz calib intrinsics` runs it): detect ->
    // reject soft views -> select (--select) -> solve -> uncertainty -> cross-validate.
    calib::PipelineOptions pipeline;
    pipeline.board_source = (take / "board.json").string();
    pipeline.select = select;
    pipeline.solve.camera_name = name;
    // The lens type is the studio's to say (a fisheye witness is bought as one): the model the
    // camera was built with; its terms are solved from the board.
    pipeline.solve.model = rc.camera.dist.model;
    pipeline.solve.threads = 2;
    pipeline.threads = defaultThreadCount();
    calib::ImageSet images;
    images.source = (take / "cams" / name).string();
    images.count = o.frames;
    images.name = [&](int f) { return (take / "cams" / name / (frameStem(f) + ".png")).string(); };
    images.read = [&](int f) { return readImage(images.name(f), cv::IMREAD_COLOR); };
    const calib::PipelineResult run = calib::calibratePipeline(images, board, pipeline);  // throws naming views
    CameraCalib c;
    c.camera = name;
    c.truth = rc.camera;
    c.views = o.frames;
    c.found = run.found;
    c.soft = run.soft;
    c.result = run.report.result;
    c.selection = run.report.selection_summary;
    for (const calib::ViewObservations& v : run.report.views) {
      if (!v.found()) c.not_used.push_back(fs::path(v.source).filename().string() + ": no board (" + v.failure + ")");
      else if (v.rejected) c.not_used.push_back(fs::path(v.source).filename().string() + ": " + v.rejected_reason);
    }
    calib::writeCalibReport(run.report, out / "calib" / name);
    std::cerr << "demo: " << name << ": board in " << c.found << " of " << c.views << " views; "
              << c.result.briefReport() << "\n";
    all.push_back(std::move(c));
  }
  return all;
}

// A rig-preset take (board waved through the volume, then on the floor), detected and solved
// with every camera's intrinsics held at the calibrated ones; writes out/rig.json and the rig
// picture out/rig.png (+ .svg).
RigCalib calibrateRigTake(const synth::SynthOptions& studio, const std::vector<CameraCalib>& cameras, int frames,
                          const fs::path& out, bool quiet) {
  synth::SynthOptions o = studio;
  o.preset = synth::Preset::kRig;
  // AprilGrid: partial views decode (every tag carries its id), as the witnesses see the board.
  o.board = "aprilgrid";
  o.frames = frames;
  o.fps = 24;
  o.validate();
  const fs::path take = out / "rig_take";
  {
    ProgressLine progress("demo rig take", o.frames, quiet);
    synth::synthesizeTake(o, take, [&](const synth::SynthProgress& p) { progress.update(p.frames_done); });
  }
  RigCalib r;
  r.frames = frames;
  r.truth = readRig(take / "truth" / "rig.json");
  const multicam::FloorSpec floor = multicam::readFloor(take / "floor.json");
  r.floor_frames = floor.frames;
  // Detect -> initial rig -> solve -> sync check, as `previz rig calibrate` runs them
  // (multicam/pipeline.h), every camera's intrinsics those calibrated above.
  multicam::RigTake rig_take;
  rig_take.take = take;
  rig_take.cameras = multicam::takeCameras(take);
  rig_take.board = readBoard(take / "board.json");
  rig_take.floor = floor;
  for (const std::string& name : rig_take.cameras) {
    const RigCamera* truth = r.truth.find(name);
    const CameraCalib* calibrated = nullptr;
    for (const CameraCalib& c : cameras)
      if (c.camera == name) calibrated = &c;
    if (!truth || !calibrated) {
      ErrorContext context;
      context.camera = name;
      throw Error("demo: no calibrated intrinsics for " + name, context);
    }
    RigCamera known;
    known.camera = calibrated->result.camera;
    known.role = truth->role;  // the truth's names and roles; its poses are not used
    rig_take.known.push_back(known);
  }
  std::unique_ptr<ProgressLine> progress;
  const multicam::RigPipelineResult solved =
      multicam::calibrateRigTake(rig_take, {}, [&](const multicam::DetectProgress& p) {
        if (!progress) progress = std::make_unique<ProgressLine>("demo rig detect", p.images_total, quiet);
        progress->update(p.images_done);
      });
  r.detect_s = solved.detect_s;
  r.result = solved.calib;
  r.sync = solved.sync;
  writeRig(r.result.rig, out / "rig.json");
  multicam::writeRigPicture(r.result.rig, &floor, out / "rig");
  std::cerr << "demo: rig calibrated from " << frames << " frames (" << floor.frames.size()
            << " floor): RMS " << r.result.rms_px << " px, world from floor " << r.result.world_from_floor
            << "; frame sync " << (r.sync.ok ? "every checked camera in sync" : "A CAMERA IS OUT OF SYNC") << "\n";
  for (const multicam::CameraSync& c : r.sync.cameras)
    if (!c.in_sync) std::cerr << "demo: " << c.camera << " out of sync by " << c.offset_frames << " frames\n";
  return r;
}

// The camera tracker's file for the studio take: main's motion T_main0_main(f) from where it
// stood during the rig take (the tracker is zeroed there), here taken from the take's
// truth/main_poses.jsonl as a tracker would give it (live/frame_loop.h TakeInputOptions).
void writeTrackedMain(const fs::path& take, const Pose& T_world_main0, const fs::path& path) {
  std::istringstream in(readTextFile(take / "truth" / "main_poses.jsonl"));
  std::string lines;
  for (std::string line; std::getline(in, line);) {
    if (line.empty()) continue;
    const nlohmann::json j = nlohmann::json::parse(line);
    const Pose T_main0_main = T_world_main0.inverse() * poseFromJson(j.at("T_world_cam"));
    lines += nlohmann::json{{"frame", j.at("frame")}, {"T_main0_main", poseToJson(T_main0_main)}}.dump() + "\n";
  }
  writeFileAtomic(path, lines);
}

struct RunResult {
  std::vector<std::vector<StageTime>> times;
  std::vector<double> psnr_db;  // per frame, over the actor's bounding box vs truth/composite
  double min_psnr_db = 99, mean_psnr_db = 0;
  // The props stage (the take's props.json, as `previz run` tracks it): per tracked prop and
  // frame, the position and rotation error against truth/props.jsonl.
  int prop_frames = 0, prop_tracked = 0;
  std::vector<double> prop_err_mm, prop_err_deg;
};

// Runs the live frame over the take with the rig at rig_path (tracked: the tracker's main poses,
// empty = the take's true main poses) into 'out' and measures each composite against the truth.
RunResult runTake(const fs::path& take_dir, const fs::path& rig_path, const fs::path& tracked,
                  const fs::path& out, bool layers, const std::string& label, bool quiet) {
  carving::TakeSource src;
  src.take_dir = take_dir;
  src.rig_path = rig_path;
  if (tracked.empty()) src.main_poses = take_dir / "truth" / "main_poses.jsonl";
  const carving::Take take(src);
  FrameLoopOptions lo;
  lo.debug_layers = true;
  FrameLoop loop(take.rig(), composite::readCgCamera(take_dir / "cg" / "camera.json"), lo);
  TakeInputOptions io;
  io.tracked_main_poses = tracked;
  const TakeReader reader(take, loop, io);
  std::unique_ptr<PropStage> props;
  if (fs::exists(take_dir / "props.json")) {
    tracking::PropSet set = tracking::readProps(take_dir / "props.json");
    if (!set.props.empty()) {
      PropStageOptions po;
      po.fps = take.streams().fps();
      props = std::make_unique<PropStage>(loop, take.rig(), std::move(set), po);
      props->addTo(loop);
    }
  }
  const fs::path props_truth = take_dir / "truth" / "props.jsonl";
  const auto true_props = fs::exists(props_truth) ? tracking::readPropTruth(props_truth)
                                                  : std::map<int, std::map<int, Pose>>{};
  std::string prop_lines;
  composite::OutputOptions oo;
  oo.out = out;
  oo.layers = layers;
  if (layers) {
    oo.video = "composite.avi";
    oo.fourcc = "MJPG";
  }
  composite::CompositeWriter writer(oo);
  RunResult r;
  ProgressLine progress(label, static_cast<int>(take.frames().size()), quiet);
  for (int f : take.frames()) {
    FrameState s;
    reader.read(f, s);
    r.times.push_back(loop.run(s));
    writer.write(f, s.composite);
    if (s.props) {
      prop_lines += tracking::trackFrameToJson(*s.props).dump() + "\n";
      for (const tracking::PropResult& p : s.props->props) {
        ++r.prop_frames;
        if (!p.tracked) continue;
        ++r.prop_tracked;
        const auto tf = true_props.find(f);
        if (tf == true_props.end() || !tf->second.count(p.id)) continue;
        const Pose& T = tf->second.at(p.id);
        r.prop_err_mm.push_back(1000 * translationDistance(p.T_world_prop, T));
        r.prop_err_deg.push_back(rotationDistance(p.T_world_prop, T) * 180 / 3.14159265358979323846);
      }
    }
    const cv::Mat truth = readImage(take_dir / "truth" / "composite" / (frameStem(f) + ".png"), cv::IMREAD_COLOR);
    const cv::Mat mask = readImage(take_dir / "truth" / "masks" / kMainCamera / (frameStem(f) + ".png"), cv::IMREAD_GRAYSCALE);
    r.psnr_db.push_back(composite::actorPsnr(s.composite.bgr, truth, mask).psnr_db);
    r.min_psnr_db = std::min(r.min_psnr_db, r.psnr_db.back());
    r.mean_psnr_db += r.psnr_db.back();
    progress.update(static_cast<int>(r.times.size()));
  }
  writer.close();
  if (props) {
    fs::create_directories(out);
    writeFileAtomic(out / "props.jsonl", prop_lines);
  }
  if (!r.psnr_db.empty()) r.mean_psnr_db /= r.psnr_db.size();
  return r;
}

std::string num(double v, int decimals) {
  char s[64];
  std::snprintf(s, sizeof(s), "%.*f", decimals, v);
  return s;
}

// report.html beside the take: every path in it is relative, so the folder can be moved.
// calibrated: the run with the rig previz calibrated (absent with --no-calibrate); truth: the
// run with the take's true rig.
void writeReport(const fs::path& out, const std::vector<int>& frames, const synth::SynthOptions& o,
                 const std::vector<CameraCalib>& cameras, const std::optional<RigCalib>& rig,
                 const std::optional<RunResult>& calibrated, const RunResult& truth) {
  const RunResult& shown = calibrated ? *calibrated : truth;
  const std::string shown_dir = calibrated ? "run" : "run_true";
  std::map<std::string, double> mean;
  std::vector<std::string> order;
  for (const auto& frame : shown.times)
    for (const StageTime& t : frame) {
      if (!mean.count(t.stage)) order.push_back(t.stage);
      mean[t.stage] += t.ms / shown.times.size();
    }
  std::ostringstream h;
  h << "<!DOCTYPE html><html><head><meta charset=\"utf-8\"><title>previz demo</title><style>"
       "body{font-family:sans-serif;background:#222;color:#ddd;margin:2em}img{width:100%}a{color:#9cf}"
       "table{border-collapse:collapse;margin-bottom:1em}td,th{border:1px solid #555;padding:4px 10px;text-align:right}"
       ".row{display:grid;grid-template-columns:repeat(5,1fr);gap:6px;margin-bottom:14px}"
       ".cal{display:grid;grid-template-columns:repeat(4,1fr);gap:6px;margin-bottom:14px}"
       ".row div,.cal div{font-size:12px}</style></head><body>\n";
  h << "<h1>previz demo: the synthetic studio, end to end</h1>\n";
  h << "<p>" << o.witness_cameras << " witness cameras " << o.witness_width << "x" << o.witness_height << " + main "
    << o.main_width << "x" << o.main_height << ", " << frames.size()
    << " frames over the 10 s choreography (the actor walks behind the CG pillar, then in front of it). ";
  if (calibrated) {
    h << "Rig: calibrated by previz from the board takes below (<a href=\"rig.json\">rig.json</a>); the main "
         "camera's dolly motion comes from the take's camera-tracker file (<a href=\"tracked_main.jsonl\">"
         "tracked_main.jsonl</a>: T_main0_main per frame, relative to where main stood during the rig take, "
         "taken from the take's truth/main_poses.jsonl as a tracker would give it). ";
  } else {
    h << "Rig: the take's own (truth/rig.json; calibration skipped with --no-calibrate). ";
  }
  h << "Per frame: key &rarr; carve &rarr; main-view depth &rarr; track props &rarr; composite.</p>\n";
  h << "<p><img src=\"contact_sheet.png\" style=\"width:60%\"></p>\n";

  h << "<h2>Composite against the true composite</h2><table><tr><th style=\"text-align:left\">rig</th>"
       "<th>min PSNR dB</th><th>mean PSNR dB</th></tr>\n";
  if (calibrated) {
    h << "<tr><td style=\"text-align:left\">calibrated by previz, tracked main</td><td>" << num(calibrated->min_psnr_db, 2)
      << "</td><td>" << num(calibrated->mean_psnr_db, 2) << "</td></tr>\n";
  }
  h << "<tr><td style=\"text-align:left\">true rig and main poses</td><td>" << num(truth.min_psnr_db, 2) << "</td><td>"
    << num(truth.mean_psnr_db, 2) << "</td></tr></table>\n";
  h << "<p>PSNR over the bounding box of the actor's true mask in the main view, 8-bit composite against "
       "take/truth/composite (issue 7's measure; the target is &ge; 30 dB).</p>\n";
  if (shown.prop_frames > 0) {
    h << "<h2>Tracked props</h2><p>The props stage (AprilTag-tagged crate, every camera, joint solve): tracked in "
      << shown.prop_tracked << " of " << shown.prop_frames << " prop-frames; median error against the take's "
      << "truth/props.jsonl " << num(median(shown.prop_err_mm), 2) << " mm, " << num(median(shown.prop_err_deg), 3)
      << "&deg; (poses: <a href=\"" << shown_dir << "/props.jsonl\">" << shown_dir << "/props.jsonl</a>).</p>\n";
  }

  if (!cameras.empty()) {
    h << "<h2>Camera calibration (intrinsics)</h2><p>Each camera filmed its own board take "
         "(calib_takes/&lt;camera&gt;, intrinsics preset: a chessboard moved and tilted in front of it), "
         "calibrated by the chain <code>previz calib intrinsics</code> runs (calib/pipeline.h: detect, reject soft "
         "views, select, solve fx fy cx cy and the lens's terms with skew held: k1 k2 p1 p2 k3 for a Brown-Conrady "
         "lens, k1 k2 k3 k4 for a fisheye (Kannala-Brandt), uncertainty, cross-validation). "
         "Value &plusmn; 1&sigma; (error against the take's truth/rig.json); views: used / rendered, and the "
         "views left out with why.</p>\n<table><tr><th style=\"text-align:left\">camera</th>"
         "<th>lens</th><th>views</th><th>RMS px</th>";
    const int shown_params[] = {0, 1, 2, 3, 5, 6, 7, 8, 9, 10};
    for (int k : shown_params) h << "<th>" << calib::kIntrinsicNames[k] << "</th>";
    h << "</tr>\n";
    for (const CameraCalib& c : cameras) {
      const Camera& e = c.result.camera;
      const Camera& t = c.truth;
      const double est[] = {e.fx,      e.fy,      e.cx,      e.cy,      e.skew,   e.dist.k1,
                            e.dist.k2, e.dist.p1, e.dist.p2, e.dist.k3, e.dist.k4};
      const double tru[] = {t.fx,      t.fy,      t.cx,      t.cy,      t.skew,   t.dist.k1,
                            t.dist.k2, t.dist.p1, t.dist.p2, t.dist.k3, t.dist.k4};
      // The terms this lens model does not have (p1 p2 of a fisheye, k4 of a plain Brown lens):
      // the ones the solve holds at 0 whatever the locks.
      calib::IntrinsicLocks no_locks;  // (skew aside, not shown)
      no_locks.rational = e.dist.isRational();
      const std::array<bool, calib::kIntrinsicCount> absent = no_locks.heldMask(e.dist.model);
      h << "<tr><td style=\"text-align:left\"><a href=\"calib/" << c.camera << ".report.json\">" << c.camera
        << "</a></td><td>" << toString(e.dist.model) << "</td><td>" << c.result.views_used << "/" << c.views;
      for (const std::string& why : c.not_used) h << "<br><small>" << htmlEscape(why) << "</small>";
      if (!c.selection.empty()) h << "<br><small>" << htmlEscape(c.selection) << "</small>";
      h << "</td><td>" << num(c.result.rms_px, 3) << "</td>";
      for (int k : shown_params) {
        if (absent[k]) {
          h << "<td>&ndash;</td>";
          continue;
        }
        const int d = k < 4 ? 2 : 5;
        h << "<td>" << num(est[k], d) << " &plusmn; " << num(c.result.sigma[k], d) << "<br><small>("
          << (est[k] - tru[k] >= 0 ? "+" : "") << num(est[k] - tru[k], d) << ")</small></td>";
      }
      h << "</tr>\n";
    }
    h << "</table>\n<p>Per camera: residuals (magnified, outliers red) &middot; where the board's points fell "
         "&middot; projection uncertainty &middot; per-view RMS.</p>\n";
    for (const CameraCalib& c : cameras) {
      h << "<h3>" << c.camera << "</h3><div class=\"cal\">";
      for (const char* kind : {"residuals", "coverage", "uncertainty", "views"}) {
        const std::string file = "calib/" + c.camera + "." + kind + ".png";
        if (fs::exists(out / file)) h << "<div><a href=\"" << file << "\"><img src=\"" << file << "\"></a>" << kind << "</div>";
      }
      h << "</div>\n";
    }
  }

  if (rig) {
    const multicam::RigCalibResult& r = rig->result;
    h << "<h2>Rig calibration</h2><p>Rig take (rig_take, rig preset): " << rig->frames << " frames, an AprilGrid waved "
         "through the volume, then " << rig->floor_frames.size() << " frames of it on the floor (the world frame). "
         "Detected in " << num(rig->detect_s, 1) << " s; solved with every camera's intrinsics held at the ones "
         "above: RMS " << num(r.rms_px, 3) << " px over " << r.residuals << " residuals (" << r.rejected
      << " rejected), world from floor: " << (r.world_from_floor ? "yes" : "no") << "; frame sync (the check "
         "<code>previz rig calibrate</code> runs): "
      << (rig->sync.ok ? "every checked camera in sync" : "<b>a camera is out of sync</b>");
    for (const multicam::CameraSync& c : rig->sync.cameras)
      if (!c.in_sync) h << " (" << htmlEscape(c.camera) << ": " << c.offset_frames << " frames)";
    h << ". Error against the rig take's truth/rig.json.</p>\n<table><tr><th style=\"text-align:left\">camera</th><th>views</th>"
         "<th>RMS px</th><th>position error mm</th><th>rotation error deg</th><th>&sigma; position mm</th>"
         "<th>&sigma; rotation deg</th></tr>\n";
    for (size_t i = 0; i < r.rig.cameras.size(); ++i) {
      const RigCamera& rc = r.rig.cameras[i];
      const multicam::CameraCalibReport& cr = r.cameras[i];
      const Pose& T_true = rig->truth.at(rc.camera.name).T_world_cam;
      h << "<tr><td style=\"text-align:left\">" << rc.camera.name << "</td><td>" << cr.views << "</td><td>"
        << num(cr.rms_px, 3) << "</td><td>" << num(1e3 * translationDistance(rc.T_world_cam, T_true), 1)
        << "</td><td>" << num(degrees(rotationDistance(rc.T_world_cam, T_true)), 3) << "</td><td>"
        << num(1e3 * cr.sigma_position_m, 1) << "</td><td>" << num(cr.sigma_rotation_deg, 3) << "</td></tr>\n";
    }
    h << "</table>\n<p><a href=\"rig.png\"><img src=\"rig.png\" style=\"width:80%\"></a></p>\n";
  }

  h << "<h2>Stage timings (mean wall ms a frame, this machine" << (calibrated ? ", calibrated rig" : "")
    << ")</h2><table><tr><th>stage</th><th>ms</th></tr>\n";
  double total = 0;
  for (const std::string& st : order) {
    h << "<tr><td style=\"text-align:left\">" << st << "</td><td>" << num(mean[st], 1) << "</td></tr>\n";
    total += mean[st];
  }
  h << "<tr><th style=\"text-align:left\">total</th><th>" << num(total, 1) << "</th></tr></table>\n";
  h << "<p>Target of the live loop: 20 ms a frame on 2 cores (see <code>previz bench run</code>).</p>\n";
  h << "<h2>Frames</h2><p>composite (previz" << (calibrated ? ", calibrated rig" : "") << ") &middot; "
    << (calibrated ? "composite with the true rig &middot; " : "") << "true composite &middot; actor depth used "
       "(turbo, 2&ndash;12 m) &middot; in front: green actor, red CG, magenta fallback (no depth)</p>\n";
  for (size_t i = 0; i < frames.size(); ++i) {
    const std::string st = frameStem(frames[i]);
    h << "<div class=\"row\">"
      << "<div><img src=\"" << shown_dir << "/composite/" << st << ".png\">frame " << frames[i] << ", "
      << num(shown.psnr_db[i], 2) << " dB</div>";
    if (calibrated) {
      h << "<div><img src=\"run_true/composite/" << st << ".png\">true rig, " << num(truth.psnr_db[i], 2) << " dB</div>";
    }
    h << "<div><img src=\"take/truth/composite/" << st << ".png\">truth</div>"
      << "<div><img src=\"" << shown_dir << "/layers/actor_depth/" << st << ".png\">actor depth</div>"
      << "<div><img src=\"" << shown_dir << "/layers/front/" << st << ".png\">front</div></div>\n";
  }
  h << "<p>Video: <a href=\"" << shown_dir << "/composite.avi\">" << shown_dir
    << "/composite.avi</a>. Files: docs/formats.md.</p></body></html>\n";
  writeFileAtomic(out / "report.html", h.str());
}

}  // namespace

Runner addDemoCommand(CLI::App& app) {
  auto a = std::make_shared<DemoArgs>();
  CLI::App* cmd = app.add_subcommand(
      "demo", "Render the built-in synthetic studio, calibrate its cameras and rig, run the live frame over it, write a report page (README command 1)");
  cmd->add_option("--out", a->out, "Output folder (the take goes to OUT/take)")->capture_default_str();
  cmd->add_option("--frames", a->frames, "Frames to render")->capture_default_str();
  cmd->add_option("--cams", a->cams, "Witness cameras")->capture_default_str();
  cmd->add_option("--size", a->size, "Witness size WxH (default 1280x720; main scales with it)");
  cmd->add_option("--fisheye-witnesses", a->fisheye_witnesses,
                  "The first N witnesses get a fisheye lens (Kannala-Brandt, ~160 degrees diagonal), calibrated as one")
      ->capture_default_str();
  cmd->add_option("--seed", a->seed, "Random seed")->capture_default_str();
  cmd->add_option("--views", a->views, "Intrinsics board views rendered per camera")->capture_default_str();
  cmd->add_option("--select", a->select,
                  "Calibrate each camera from the N most informative of its views (0 = every usable view)")
      ->capture_default_str();
  cmd->add_option("--rig-frames", a->rig_frames, "Frames of the rig take (the last few show the floor board)")
      ->capture_default_str();
  cmd->add_flag("--no-calibrate", a->no_calibrate, "Skip the calibration: run on the take's true rig only (quick look)");
  cmd->add_flag("--json", a->json, "JSON summary on stdout");
  cmd->add_flag("--quiet", a->quiet, "No progress line");

  return [a]() {
    synth::SynthOptions o;
    o.preset = synth::Preset::kStudio;
    o.frames = a->frames;
    o.witness_cameras = a->cams;
    o.fisheye_witnesses = a->fisheye_witnesses;
    o.seed = a->seed;
    o.noise_sigma = 1.5;
    // The studio's choreography (walk behind the pillar, arms up, turn, walk in front) lasts
    // 10 s; the demo samples all of it with however many frames it renders.
    o.fps = std::max(1, a->frames) / 10.0;
    if (!a->size.empty()) {
      const auto [w, h] = parseSize(a->size, "--size");
      o.main_width = static_cast<int>(o.main_width * static_cast<double>(w) / o.witness_width + 0.5);
      o.main_height = static_cast<int>(o.main_height * static_cast<double>(h) / o.witness_height + 0.5);
      o.witness_width = w;
      o.witness_height = h;
    }
    o.validate();
    if (!a->no_calibrate && a->views < 3) {
      throw Error("demo: --views must be >= 3 (got " + std::to_string(a->views) + ")",
                  fieldContext("--views"));
    }
    if (!a->no_calibrate && a->rig_frames < 10) {
      throw Error("demo: --rig-frames must be >= 10 (got " + std::to_string(a->rig_frames) + ")",
                  fieldContext("--rig-frames"));
    }
    const fs::path out(a->out);
    const fs::path take = out / "take";
    std::cerr << "demo: rendering the synthetic studio (" << o.witness_cameras << " witness "
              << o.witness_width << "x" << o.witness_height << " + main " << o.main_width << "x"
              << o.main_height << ", " << o.frames << " frames) into " << take << "\n";
    ProgressLine progress("demo synth", o.frames, a->quiet);
    const synth::SynthSummary s = synth::synthesizeTake(
        o, take, [&](const synth::SynthProgress& p) { progress.update(p.frames_done); });

    const Rig rig = readRig(take / "truth" / "rig.json");
    const int frame = o.frames / 2;
    const fs::path sheet_path = out / "contact_sheet.png";
    writeImageAtomic(sheet_path, contactSheet(take, rig, frame));

    std::vector<CameraCalib> cameras;
    std::optional<RigCalib> rig_calib;
    std::optional<RunResult> calibrated;
    if (!a->no_calibrate) {
      std::cerr << "demo: [1/4] calibrating " << rig.cameras.size() << " cameras' intrinsics, " << a->views
                << " board views each, into " << out / "calib" << "\n";
      cameras = calibrateCameras(o, rig, a->views, a->select, out, a->quiet);
      std::cerr << "demo: [2/4] calibrating the rig from a " << a->rig_frames << "-frame rig take\n";
      rig_calib = calibrateRigTake(o, cameras, a->rig_frames, out, a->quiet);
      writeTrackedMain(take, rig_calib->truth.at(rig.cameras.back().camera.name).T_world_cam,
                       out / "tracked_main.jsonl");
      std::cerr << "demo: [3/4] running the live frame over the take with the calibrated rig into " << out / "run" << "\n";
      calibrated = runTake(take, out / "rig.json", out / "tracked_main.jsonl", out / "run", true, "demo run", a->quiet);
    }
    std::cerr << "demo: [4/4] running the live frame over the take with the true rig into " << out / "run_true" << "\n";
    const RunResult truth = runTake(take, take / "truth" / "rig.json", "", out / "run_true", a->no_calibrate,
                                    "demo run (true rig)", a->quiet);
    std::vector<int> frames;
    for (int f = 0; f < o.frames; ++f) frames.push_back(f);
    writeReport(out, frames, o, cameras, rig_calib, calibrated, truth);
    nlohmann::json summary = {{"command", "demo"},
                              {"take", take.string()},
                              {"frames", s.frames},
                              {"cameras", s.cameras},
                              {"render_ms", s.render_ms},
                              {"ms_per_camera_frame", s.ms_per_camera_frame},
                              {"contact_sheet", sheet_path.string()},
                              {"report", (out / "report.html").string()},
                              {"psnr_true_rig", {{"min_db", truth.min_psnr_db}, {"mean_db", truth.mean_psnr_db}}}};
    {
      const RunResult& shown = calibrated ? *calibrated : truth;
      summary["props"] = {{"prop_frames", shown.prop_frames},
                          {"tracked", shown.prop_tracked},
                          {"median_position_error_mm", median(shown.prop_err_mm)},
                          {"median_rotation_error_deg", median(shown.prop_err_deg)}};
    }
    if (calibrated) {
      summary["psnr_calibrated_rig"] = {{"min_db", calibrated->min_psnr_db}, {"mean_db", calibrated->mean_psnr_db}};
      nlohmann::json intrinsics = nlohmann::json::array();
      for (const CameraCalib& c : cameras) {
        intrinsics.push_back({{"camera", c.camera},
                              {"model", toString(c.result.camera.dist.model)},
                              {"views_used", c.result.views_used},
                              {"views_rendered", c.views},
                              {"views_with_board", c.found},
                              {"views_soft", c.soft},
                              {"views_not_used", c.not_used},
                              {"selection", c.selection},
                              {"rms_px", c.result.rms_px},
                              {"fx_error_px", c.result.camera.fx - c.truth.fx},
                              {"cx_error_px", c.result.camera.cx - c.truth.cx},
                              {"cy_error_px", c.result.camera.cy - c.truth.cy},
                              {"k1_error", c.result.camera.dist.k1 - c.truth.dist.k1}});
      }
      summary["intrinsics"] = intrinsics;
      nlohmann::json rig_cams = nlohmann::json::array();
      for (const RigCamera& rc : rig_calib->result.rig.cameras) {
        const Pose& T_true = rig_calib->truth.at(rc.camera.name).T_world_cam;
        rig_cams.push_back({{"camera", rc.camera.name},
                            {"position_error_m", translationDistance(rc.T_world_cam, T_true)},
                            {"rotation_error_deg", degrees(rotationDistance(rc.T_world_cam, T_true))}});
      }
      summary["rig"] = {{"rms_px", rig_calib->result.rms_px},
                        {"rig", (out / "rig.json").string()},
                        {"cameras", rig_cams},
                        {"sync", multicam::syncToJson(rig_calib->sync)}};
    }
    writeJsonAtomic(out / "summary.json", summary);
    std::cerr << "demo: take in " << take << ", contact sheet " << sheet_path << " (frame " << frame << "); composite PSNR over the actor: "
              << (calibrated ? "calibrated rig min " + num(calibrated->min_psnr_db, 2) + " dB, " : std::string())
              << "true rig min " << num(truth.min_psnr_db, 2) << " dB; report " << out / "report.html" << "\n";
    if (a->json) std::cout << summary.dump() << "\n";
    return 0;
  };
}

}  // namespace previz::app
