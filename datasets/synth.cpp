#include "datasets/synth.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <exception>
#include <map>
#include <memory>
#include <sstream>
#include <vector>

#include <nlohmann/json.hpp>
#include <omp.h>

#include "core/board.h"
#include "core/distortion_maps.h"
#include "core/error.h"
#include "core/io.h"
#include "core/names.h"
#include "core/rig.h"
#include "core/stopwatch.h"
#include "core/threads.h"
#include "datasets/detail/board_view.h"
#include "datasets/random.h"
#include "datasets/render.h"
#include "datasets/rig_capture.h"
#include "datasets/rigs.h"
#include "datasets/studio.h"
#include "take/stream_writer.h"

namespace previz::synth {
namespace {

namespace fs = std::filesystem;

constexpr int kTakeFormatVersion = 1;
constexpr std::uint64_t kStreamGain = 401;

[[noreturn]] void badOption(const std::string& field, const std::string& message,
                            const std::string& camera = {}) {
  ErrorContext context;
  context.field = field;
  context.camera = camera;
  throw Error("synth: " + field + " " + message, context);
}

template <typename T>
std::string str(T value) {
  std::ostringstream s;
  s << value;
  return s.str();
}

BoardType boardTypeFromString(const std::string& name) {
  if (name == "chessboard") return BoardType::kChessboard;
  if (name == "charuco") return BoardType::kCharuco;
  if (name == "aprilgrid") return BoardType::kAprilGrid;
  if (name == "circles") return BoardType::kCircles;
  if (name == "quadtree") return BoardType::kQuadtree;
  badOption("board", "must be chessboard|charuco|aprilgrid|circles|quadtree (got '" + name + "')");
}

// The instants a frame's shutter averages: 'count' times centred on the frame time, spread over
// shutter / fps seconds (one instant, the frame time itself, when the shutter is 0).
std::vector<double> shutterTimes(double frame_time_s, const SynthOptions& o) {
  if (o.shutter <= 0) return {frame_time_s};
  const int count = 4;
  std::vector<double> times;
  for (int i = 0; i < count; ++i) {
    times.push_back(frame_time_s + o.shutter / o.fps * ((i + 0.5) / count - 0.5));
  }
  return times;
}

// Appends lines of a .jsonl file in memory; written once at the end of the take.
struct JsonLines {
  std::string text;
  void add(const nlohmann::json& j) { text += j.dump() + "\n"; }
};

nlohmann::json optionsToJson(const SynthOptions& o) {
  nlohmann::json bumps = nlohmann::json::object();
  for (const auto& [name, T] : o.bump) bumps[name] = poseToJson(T);
  return {{"preset", toString(o.preset)},
          {"frames", o.frames},
          {"witness_cameras", o.witness_cameras},
          {"fisheye_witnesses", o.fisheye_witnesses},
          {"seed", o.seed},
          {"witness_width", o.witness_width},
          {"witness_height", o.witness_height},
          {"main_width", o.main_width},
          {"main_height", o.main_height},
          {"fps", o.fps},
          {"samples_per_pixel", o.samples_per_pixel},
          {"noise_sigma", o.noise_sigma},
          {"blur_sigma_px", o.blur_sigma_px},
          {"shutter", o.shutter},
          {"brightness_jitter", o.brightness_jitter},
          {"main_dolly", o.main_dolly},
          {"cg_overscan", o.cg_overscan},
          {"board", o.board},
          {"camera", o.camera},
          {"write_meshes", o.write_meshes},
          {"board_seed", o.board_seed.value_or(o.seed)},
          {"floor_frames", o.floor_frames},
          {"floor_only", o.floor_only},
          {"delay_frames", o.delay_frames},
          {"camera_format", o.camera_format},
          {"sequence_pattern", o.sequence_pattern},
          {"sequence_start", o.sequence_start},
          {"start_timecode", o.start_timecode},
          {"late_frames", o.late_frames},
          {"bump", bumps}};
}

nlohmann::json propsToJson(const std::vector<PropSpec>& props) {
  nlohmann::json list = nlohmann::json::array();
  for (const PropSpec& p : props) {
    nlohmann::json tags = nlohmann::json::array();
    for (const PropTag& t : p.tags) {
      tags.push_back({{"family", t.family},
                      {"id", t.id},
                      {"size_m", t.size_m},
                      {"T_prop_tag", poseToJson(t.T_prop_tag)}});
    }
    list.push_back({{"id", p.id},
                    {"name", p.name},
                    {"box_size_m", {p.box_size_m.x(), p.box_size_m.y(), p.box_size_m.z()}},
                    {"tags", tags}});
  }
  return {{"units", "m"},
          {"prop_frame", "origin at the box centre, axes along the box edges"},
          {"tag_frame",
           "origin at the tag centre, x right and y down as the tag is read, z into the tag; "
           "size_m is the edge of the outer black border (libapriltag tagsize)"},
          {"props", list}};
}

// A camera of the take with what the renderer needs to know about it.
struct TakeCamera {
  RigCamera rig;
  int index = 0;      // position in the take's camera list (noise stream)
  double gain = 1.0;  // brightness of this camera
  bool moving = false;  // main camera on the dolly
};

// A board preset's frames, camera by camera (RigCapture for the rig preset, one BoardView for
// the intrinsics preset).
struct BoardFrames {
  std::function<cv::Mat(int camera, int frame)> render;
  std::function<std::vector<BoardObservation>(int camera, int frame)> truth;
  std::function<Pose(int camera, int frame)> T_world_board;
  std::function<bool(int camera, int frame)> floor;
};

// Renders one frame of every camera of a board preset (in parallel over cameras; a single
// camera renders in parallel itself), writes the plates and returns each camera's truth line
// and render time. The first exception is rethrown after the parallel region.
void renderBoardFrame(const BoardFrames& source, const std::vector<TakeCamera>& cameras, int f,
                      double t, const fs::path& out, int threads,
                      std::vector<nlohmann::json>& lines, std::vector<double>& ms) {
  const int n = static_cast<int>(cameras.size());
  lines.assign(n, nullptr);
  ms.assign(n, 0.0);
  std::vector<std::exception_ptr> errors(n);
#pragma omp parallel for schedule(dynamic, 1) num_threads(threads) if (n > 1)
  for (int i = 0; i < n; ++i) {
    try {
      const std::string& name = cameras[i].rig.camera.name;
      const Stopwatch start;
      const cv::Mat plate = source.render(i, f);
      ms[i] = start.ms();
      writeImageAtomic(out / "cams" / name / (frameStem(f) + ".png"), plate);
      nlohmann::json points = nlohmann::json::array();
      for (const BoardObservation& b : source.truth(i, f)) {
        points.push_back({{"id", b.id}, {"x", b.px.x()}, {"y", b.px.y()}});
      }
      lines[i] = {{"frame", f},
                  {"time_s", t},
                  {"floor", source.floor(i, f)},
                  {"T_world_board", poseToJson(source.T_world_board(i, f))},
                  {"points", points}};
    } catch (...) {  // never across the parallel region
      errors[i] = std::current_exception();
    }
  }
  for (const std::exception_ptr& e : errors) {
    if (e) std::rethrow_exception(e);
  }
}

}  // namespace

const char* toString(Preset preset) {
  switch (preset) {
    case Preset::kStudio: return "studio";
    case Preset::kIntrinsics: return "intrinsics";
    case Preset::kRig: return "rig";
  }
  return "unknown";
}

Preset presetFromString(const std::string& name) {
  if (name == "studio") return Preset::kStudio;
  if (name == "intrinsics") return Preset::kIntrinsics;
  if (name == "rig") return Preset::kRig;
  badOption("preset", "must be studio|intrinsics|rig (got '" + name + "')");
}

void SynthOptions::validate() const {
  if (preset != Preset::kStudio && preset != Preset::kIntrinsics && preset != Preset::kRig) {
    badOption("preset", "is not a known preset (" + str(static_cast<int>(preset)) + ")");
  }
  if (frames <= 0) badOption("frames", "must be > 0 (got " + str(frames) + ")");
  backdropFromString(backdrop);  // throws naming the field
  if (witness_cameras < 1 || witness_cameras > 99) {
    badOption("witness_cameras", "must be in [1, 99] (got " + str(witness_cameras) + ")");
  }
  if (fisheye_witnesses < 0 || fisheye_witnesses > witness_cameras) {
    badOption("fisheye_witnesses",
              "must be in [0, witness_cameras = " + str(witness_cameras) + "] (got " + str(fisheye_witnesses) + ")");
  }
  if (witness_width <= 0) badOption("witness_width", "must be > 0 (got " + str(witness_width) + ")");
  if (witness_height <= 0) {
    badOption("witness_height", "must be > 0 (got " + str(witness_height) + ")");
  }
  if (main_width <= 0) badOption("main_width", "must be > 0 (got " + str(main_width) + ")");
  if (main_height <= 0) badOption("main_height", "must be > 0 (got " + str(main_height) + ")");
  if (!(fps > 0) || !std::isfinite(fps)) badOption("fps", "must be > 0 (got " + str(fps) + ")");
  if (samples_per_pixel < 4 || samples_per_pixel > 4096) {
    badOption("samples_per_pixel", "must be in [4, 4096] (got " + str(samples_per_pixel) + ")");
  }
  if (!(noise_sigma >= 0) || !std::isfinite(noise_sigma)) {
    badOption("noise_sigma", "must be >= 0 (got " + str(noise_sigma) + ")");
  }
  if (!(blur_sigma_px >= 0) || !(blur_sigma_px <= 50)) {
    badOption("blur_sigma_px", "must be in [0, 50] (got " + str(blur_sigma_px) + ")");
  }
  if (!(shutter >= 0) || !(shutter <= 1)) {
    badOption("shutter", "must be in [0, 1] (got " + str(shutter) + ")");
  }
  if (!(brightness_jitter >= 0) || !(brightness_jitter < 1)) {
    badOption("brightness_jitter", "must be in [0, 1) (got " + str(brightness_jitter) + ")");
  }
  if (!(cg_overscan >= 0) || !(cg_overscan <= 1)) {
    badOption("cg_overscan", "must be in [0, 1] (got " + str(cg_overscan) + ")");
  }
  boardTypeFromString(board);
  bool known_camera = camera == kMainCamera || camera == "witness";
  for (int i = 0; i < witness_cameras && !known_camera; ++i) known_camera = camera == witnessName(i);
  if (!known_camera) {
    badOption("camera", "must be main|witness|witness01.." + witnessName(witness_cameras - 1) + " (got '" + camera + "')");
  }
  if (threads < 0) badOption("threads", "must be >= 0 (got " + str(threads) + ")");
  // Rig preset only: a knocked or late camera, another board path, no floor board.
  if (preset != Preset::kRig && preset != Preset::kStudio && !delay_frames.empty())
    badOption("delay_frames", "applies to the rig and studio presets only");
  if (preset != Preset::kStudio) {
    if (camera_format != "png") badOption("camera_format", "applies to the studio preset only");
    if (!sequence_pattern.empty()) badOption("sequence_pattern", "applies to the studio preset only");
    if (sequence_start != 0) badOption("sequence_start", "applies to the studio preset only");
    if (!start_timecode.empty()) badOption("start_timecode", "applies to the studio preset only");
    if (!late_frames.empty()) badOption("late_frames", "applies to the studio preset only");
  }
  {
    take::StreamWriterOptions w;
    w.format = camera_format;
    w.pattern = sequence_pattern;
    w.first_number = sequence_start;
    w.fps = fps;
    w.start_timecode = start_timecode;
    try {
      w.validate();
    } catch (const Error& e) {
      const std::string field = e.context().field == "format"         ? "camera_format"
                                : e.context().field == "pattern"      ? "sequence_pattern"
                                : e.context().field == "first_number" ? "sequence_start"
                                                                      : e.context().field;
      badOption(field, e.message());
    }
  }
  if (preset != Preset::kRig) {
    if (!bump.empty()) badOption("bump", "applies to the rig preset only");
    if (board_seed) badOption("board_seed", "applies to the rig preset only");
    if (!floor_frames) badOption("floor_frames", "applies to the rig preset only");
    if (floor_only) badOption("floor_only", "applies to the rig preset only");
  }
  if (floor_only && !floor_frames) badOption("floor_only", "contradicts floor_frames = false (--no-floor)");
  auto known = [&](const std::string& name) {
    if (name == kMainCamera) return true;
    for (int i = 0; i < witness_cameras; ++i) {
      if (witnessName(i) == name) return true;
    }
    return false;
  };
  for (const auto& [name, late] : late_frames) {
    if (!known(name)) badOption("late_frames", "names no camera of the take: '" + name + "'", name);
    if (late < 0 || late >= this->frames)
      badOption("late_frames", "of '" + name + "' must be in [0, frames) (got " + str(late) + ")", name);
  }
  for (const auto& [name, frames_late] : delay_frames) {
    if (!known(name)) badOption("delay_frames", "names no camera of the take: '" + name + "'", name);
    if (std::abs(frames_late) >= std::max(1, this->frames)) {
      badOption("delay_frames", "of '" + name + "' must be shorter than the take (got " +
                                    str(frames_late) + " frames)", name);
    }
  }
  for (const auto& [name, T] : bump) {
    if (!known(name)) badOption("bump", "names no camera of the take: '" + name + "'", name);
    if (!T.matrix().allFinite()) badOption("bump", "of '" + name + "' is not finite", name);
  }
}

SynthSummary synthesizeTake(const SynthOptions& options, const fs::path& out,
                            const std::function<void(const SynthProgress&)>& progress) {
  options.validate();
  const Stopwatch take_start;
  const SynthOptions& o = options;
  const bool studio_preset = o.preset == Preset::kStudio;
  const bool board_preset = !studio_preset;
  const double duration_s = o.frames / o.fps;

  // The studio's choreography runs at walking pace over at least its default length; a short
  // take is a clip of it (the actor moves at a realistic speed), a long one stretches it.
  StudioConfig config;
  config.seed = o.seed;
  config.take_duration_s = std::max(StudioConfig{}.take_duration_s, duration_s);
  config.with_actor = studio_preset;
  config.with_prop = studio_preset;
  config.backdrop = backdropFromString(o.backdrop);
  const Studio studio(config);

  const BoardType board_type = boardTypeFromString(o.board);
  const BoardSpec board_spec =
      o.preset == Preset::kRig ? rigBoard(board_type) : defaultBoard(board_type);

  // The take's cameras. The main camera only moves in the studio preset: calibration takes
  // assume a static rig.
  StudioRigOptions rig_options;
  rig_options.witness_cameras = o.witness_cameras;
  rig_options.fisheye_witnesses = o.fisheye_witnesses;
  rig_options.seed = o.seed;
  rig_options.witness_width = o.witness_width;
  rig_options.witness_height = o.witness_height;
  rig_options.main_width = o.main_width;
  rig_options.main_height = o.main_height;
  const bool dolly = studio_preset && o.main_dolly;
  // The dolly runs on the choreography's clock too, so camera and actor move at the same
  // (realistic) speeds whatever the take's length.
  Rig full_rig = studioRig(rig_options, config.take_duration_s, dolly);
  Rig rig;
  if (o.preset == Preset::kIntrinsics) {
    // "witness" is witness01; a witness name picks that witness (its own lens and pose).
    const std::string name = o.camera == "witness" ? witnessName(0) : o.camera;
    rig.cameras.push_back(full_rig.at(name));
  } else {
    rig = full_rig;
  }
  std::vector<TakeCamera> cameras;
  for (size_t i = 0; i < rig.cameras.size(); ++i) {
    TakeCamera c;
    c.rig = rig.cameras[i];
    c.index = static_cast<int>(i);
    Rng gain_rng(hashKey(o.seed, kStreamGain, static_cast<std::uint64_t>(i)));
    c.gain = 1.0 + o.brightness_jitter * gain_rng.uniform(-1.0, 1.0);
    c.moving = dolly && c.rig.role == kMainRole;
    cameras.push_back(c);
  }
  const TakeCamera* main_camera = nullptr;
  for (const TakeCamera& c : cameras) {
    if (c.rig.role == kMainRole) main_camera = &c;
  }

  // Board presets: the stage is static, so each camera renders its empty stage once and then
  // only the board's part of the image (datasets/detail/board_view.h).
  const int threads = resolveThreads(o.threads);
  std::unique_ptr<RigCapture> capture;
  std::unique_ptr<detail::BoardView> intrinsics_view;
  BoardFrames board_frames;
  if (o.preset == Preset::kRig) {
    RigCaptureOptions ro;
    ro.rig = rig_options;
    ro.board = board_type;
    ro.frames = o.frames;
    ro.board_seed = o.board_seed.value_or(o.seed);
    ro.samples_per_pixel = o.samples_per_pixel;
    ro.noise_sigma = o.noise_sigma;
    ro.blur_sigma_px = o.blur_sigma_px;
    ro.delay_frames = o.delay_frames;
    ro.bump = o.bump;
    ro.floor_frames = o.floor_frames;
    ro.floor_only = o.floor_only;
    ro.threads = o.threads;
    for (const TakeCamera& c : cameras) ro.gain[c.rig.camera.name] = c.gain;
    capture = std::make_unique<RigCapture>(ro);
    // The true rig is the capture's: bumped cameras stand where the bump put them.
    rig = capture->rig();
    for (TakeCamera& c : cameras) c.rig = rig.cameras[c.index];
    const RigCapture* cap = capture.get();
    board_frames.render = [cap](int i, int f) { return cap->render(i, f); };
    board_frames.truth = [cap](int i, int f) { return cap->truth(i, f); };
    board_frames.T_world_board = [cap](int i, int f) { return cap->T_world_board(i, f); };
    board_frames.floor = [cap](int i, int f) { return cap->showsFloorBoard(i, f); };
  } else if (o.preset == Preset::kIntrinsics) {
    const TakeCamera& c = cameras.front();
    detail::BoardViewOptions vo;
    vo.samples_per_pixel = o.samples_per_pixel;
    vo.gain = c.gain;
    vo.blur_sigma_px = o.blur_sigma_px;
    vo.noise_sigma = o.noise_sigma;
    vo.threads = o.threads;
    intrinsics_view = std::make_unique<detail::BoardView>(c.rig.camera, c.rig.T_world_cam,
                                                          studio.sceneAt(0.0, kLayerStage), vo);
    const detail::BoardView* view = intrinsics_view.get();
    const std::uint64_t seed = o.seed;
    auto boardPose = [view, board_spec, seed](int f) {
      return view->T_world_cam() * intrinsicsBoardPose(view->camera(), board_spec, f, seed);
    };
    board_frames.render = [view, board_spec, boardPose, seed](int, int f) {
      return view->render(board_spec, boardPose(f), false, seed, 0, f);
    };
    board_frames.truth = [view, board_spec, boardPose](int, int f) {
      const Pose T_world_board = boardPose(f);
      return visibleBoardPoints(view->camera(), view->T_world_cam(), board_spec, T_world_board,
                                view->sceneWith(board_spec, T_world_board, false));
    };
    board_frames.T_world_board = [boardPose](int, int f) { return boardPose(f); };
    board_frames.floor = [](int, int) { return false; };
  }

  // Files known before rendering.
  fs::create_directories(out);
  writeRig(rig, out / "truth" / "rig.json");
  std::vector<PropSpec> props;
  if (studio_preset && config.with_prop) props.push_back(studio.prop());
  writeJsonAtomic(out / "props.json", propsToJson(props));
  if (board_preset) writeBoard(board_spec, out / "board.json");

  Camera cg_camera;
  if (main_camera != nullptr) {
    cg_camera = idealPinhole(main_camera->rig.camera, o.cg_overscan);
    cg_camera.name = "cg";
  }

  JsonLines main_poses, prop_poses;
  std::map<std::string, JsonLines> board_lines;
  nlohmann::json cg_frames = nlohmann::json::array();
  std::vector<int> floor_frames;

  // The studio cameras' streams, one writer each, in the form asked (take/stream_writer.h). A
  // camera that started late carries its start in its timecode (EXR attribute, container) or,
  // when the form has none, in take.json "offsets"; sequences without timecode are numbered by
  // take frame (offsets then map sequence_start back to take frame 0).
  const auto perCamera = [](const std::map<std::string, int>& m, const std::string& name) {
    const auto it = m.find(name);
    return it == m.end() ? 0 : it->second;
  };
  std::map<std::string, take::StreamWriter> writers;
  nlohmann::json offsets = nlohmann::json::object();
  bool keep_encoded = false;
  if (studio_preset) {
    for (const TakeCamera& c : cameras) {
      const std::string& name = c.rig.camera.name;
      take::StreamWriterOptions base;
      base.format = o.camera_format;
      base.pattern = o.sequence_pattern;
      base.fps = o.fps;
      base.first_number = o.sequence_start;
      base.start_timecode = o.start_timecode;
      keep_encoded = base.format == "png16" || base.format == "tif16" || base.format == "exr";
      const take::StreamPlacement place = take::placeStream(base, perCamera(o.late_frames, name));
      const take::StreamWriterOptions& w = place.writer;
      if (place.offset) offsets[name] = *place.offset;
      writers.emplace(name, take::StreamWriter(out, name, {c.rig.camera.width, c.rig.camera.height}, w));
    }
  }

  double render_ms = 0, plate_ms = 0;
  // How camera c films frame f: the take's sampling, its gain, lens blur and sensor noise.
  auto plateOptions = [&](const TakeCamera& c, int f) {
    RenderOptions ro;
    ro.samples_per_pixel = o.samples_per_pixel;
    ro.gain = c.gain;
    ro.blur_sigma_px = o.blur_sigma_px;
    ro.noise_sigma = o.noise_sigma;
    ro.seed = o.seed;
    ro.camera_index = c.index;
    ro.frame = f;
    ro.threads = o.threads;
    return ro;
  };
  // Clean plates: the empty stage from every static camera (a moving main camera has none), with
  // the camera's own gain and noise (a noise stream of their own: frame -1).
  if (studio_preset && (o.clean_plates || config.backdrop == Backdrop::kSet)) {
    const Scene empty = studio.sceneAt(0.0, kLayerStage);
    for (const TakeCamera& c : cameras) {
      if (c.moving) continue;
      RenderOptions ro = plateOptions(c, -1);
      ro.truth = false;
      const Stopwatch start;
      const RenderedView view = renderView(c.rig.camera, c.rig.T_world_cam, empty, ro);
      render_ms += start.ms();
      writeImageAtomic(out / "clean" / (c.rig.camera.name + ".png"), view.bgr);
    }
  }
  for (int f = 0; f < o.frames; ++f) {
    const double t = f / o.fps;
    if (board_preset) {
      // Plates and board truth only: depth, masks and labels of a board on an empty stage say
      // nothing a calibration needs (and made a 30-frame rig take 1 GB).
      if (capture && capture->isFloorFrame(f)) floor_frames.push_back(f);
      std::vector<nlohmann::json> lines;
      std::vector<double> ms;
      renderBoardFrame(board_frames, cameras, f, t, out, threads, lines, ms);
      for (size_t i = 0; i < cameras.size(); ++i) {
        board_lines[cameras[i].rig.camera.name].add(lines[i]);
        plate_ms += ms[i];
        render_ms += ms[i];
      }
      if (main_camera != nullptr) {
        main_poses.add({{"frame", f}, {"time_s", t}, {"T_world_cam", poseToJson(main_camera->rig.T_world_cam)}});
      }
      if (progress) {
        SynthProgress p;
        p.frames_done = f + 1;
        p.frames_total = o.frames;
        p.elapsed_s = take_start.seconds();
        progress(p);
      }
      continue;
    }
    const std::vector<double> times = shutterTimes(t, o);
    const std::string png = frameStem(f) + ".png";
    const std::string exr = frameStem(f) + ".exr";

    // Scenes of this frame: plate (what the cameras film) at every shutter instant plus the
    // frame time itself (truth layers).
    const unsigned plate_layers = kLayersPlate;
    auto sceneAt = [&](double time_s, unsigned layers) { return studio.sceneAt(time_s, layers); };
    const bool single_instant = times.size() == 1 && times[0] == t;
    const Scene centre_scene = sceneAt(t, plate_layers);
    std::vector<Scene> instant_scenes;
    if (!single_instant) {
      for (double ti : times) instant_scenes.push_back(sceneAt(ti, plate_layers));
    }

    auto poseAt = [&](const TakeCamera& c, double time_s) {
      return c.moving ? mainCameraPose(time_s, config.take_duration_s, true) : c.rig.T_world_cam;
    };
    auto shutterFor = [&](const TakeCamera& c, const std::vector<Scene>& scenes,
                          const Scene& centre) {
      std::vector<ShutterSample> shutter;
      if (single_instant) {
        shutter.push_back({&centre, poseAt(c, t)});
      } else {
        for (size_t i = 0; i < times.size(); ++i) {
          shutter.push_back({&scenes[i], poseAt(c, times[i])});
        }
      }
      return shutter;
    };

    for (const TakeCamera& c : cameras) {
      const std::string& name = c.rig.camera.name;
      const int delay = perCamera(o.delay_frames, name);
      if (f < perCamera(o.late_frames, name)) continue;  // not recording yet
      RenderOptions ro = plateOptions(c, f);
      ro.keep_encoded = keep_encoded;
      const Stopwatch start;
      RenderedView view;
      if (delay == 0) {
        const ShutterSample centre{&centre_scene, poseAt(c, t)};
        view = renderView(c.rig.camera, shutterFor(c, instant_scenes, centre_scene), centre, ro);
      } else {
        // An unsynchronised camera films the scene of frame f - delay (its truth layers too).
        const double shift_s = -delay / o.fps;
        const Scene shifted = sceneAt(t + shift_s, plate_layers);
        std::vector<Scene> shifted_instants;
        std::vector<ShutterSample> shutter;
        if (single_instant) {
          shutter.push_back({&shifted, poseAt(c, t + shift_s)});
        } else {
          for (double ti : times) shifted_instants.push_back(sceneAt(ti + shift_s, plate_layers));
          for (size_t i = 0; i < times.size(); ++i)
            shutter.push_back({&shifted_instants[i], poseAt(c, times[i] + shift_s)});
        }
        view = renderView(c.rig.camera, shutter, {&shifted, poseAt(c, t + shift_s)}, ro);
      }
      const double ms = start.ms();
      plate_ms += ms;
      render_ms += ms;
      writers.at(name).write(view.bgr, view.encoded);
      writeDepthExr(out / "truth" / "depth" / name / exr, view.depth,
                    {{"previz:camera", name}, {"previz:frame", std::to_string(f)}});
      writeImageAtomic(out / "truth" / "masks" / name / png, view.mask);
      writeImageAtomic(out / "truth" / "labels" / name / png, view.labels);
    }

    if (main_camera != nullptr) {
      main_poses.add({{"frame", f},
                      {"time_s", t},
                      {"T_world_cam", poseToJson(poseAt(*main_camera, t))}});
    }

    if (studio_preset) {
      // CG set through the ideal pinhole of the main camera (the engine's render).
      const Scene cg_centre = studio.sceneAt(t, kLayerCg);
      std::vector<Scene> cg_scenes;
      if (!single_instant) {
        for (double ti : times) cg_scenes.push_back(studio.sceneAt(ti, kLayerCg));
      }
      Stopwatch start;
      const LinearView cg =
          renderLinear(cg_camera, shutterFor(*main_camera, cg_scenes, cg_centre),
                       {&cg_centre, poseAt(*main_camera, t)}, o.samples_per_pixel, o.threads);
      render_ms += start.ms();
      ExrImage color;
      color.image = cg.rgb;
      color.channels = {"R", "G", "B"};
      color.half = true;
      color.attributes = {{"previz:color", "linear RGB (scene-referred), no gain, no encoding"},
                          {"previz:pixel_origin", "pixel (0,0) is the centre of the top-left pixel"},
                          {"previz:camera", "cg (ideal pinhole of main, see cg/camera.json)"},
                          {"previz:frame", std::to_string(f)}};
      writeExr(out / "cg" / "color" / exr, color);
      writeDepthExr(out / "cg" / "depth" / exr, cg.depth,
                    {{"previz:camera", "cg"}, {"previz:frame", std::to_string(f)}});
      cg_frames.push_back({{"frame", f},
                           {"time_s", t},
                           {"T_world_cam", poseToJson(poseAt(*main_camera, t))}});

      // The true composite: the main camera's real lens seeing actor + prop + CG set, no stage.
      const unsigned comp_layers = kLayerActor | kLayerProp | kLayerCg;
      const Scene comp_centre = studio.sceneAt(t, comp_layers);
      std::vector<Scene> comp_scenes;
      if (!single_instant) {
        for (double ti : times) comp_scenes.push_back(studio.sceneAt(ti, comp_layers));
      }
      RenderOptions ro;
      ro.samples_per_pixel = o.samples_per_pixel;
      ro.gain = main_camera->gain;
      ro.truth = false;
      ro.threads = o.threads;
      start.restart();
      const RenderedView comp =
          renderView(main_camera->rig.camera, shutterFor(*main_camera, comp_scenes, comp_centre),
                     {&comp_centre, poseAt(*main_camera, t)}, ro);
      render_ms += start.ms();
      writeImageAtomic(out / "truth" / "composite" / png, comp.bgr);

      if (config.with_prop) {
        prop_poses.add({{"frame", f},
                        {"time_s", t},
                        {"props",
                         {{{"id", studio.prop().id},
                           {"T_world_prop", poseToJson(studio.T_world_prop(t))}}}}});
      }
      if (o.write_meshes && config.with_actor) {
        const TriangleMesh mesh = studio.actorMesh(t);
        const std::string stem = "actor." + frameStem(f);
        writePly(mesh, out / "truth" / "mesh" / (stem + ".ply"));
        writeObj(mesh, out / "truth" / "mesh" / (stem + ".obj"));
      }
    }

    if (progress) {
      SynthProgress p;
      p.frames_done = f + 1;
      p.frames_total = o.frames;
      p.elapsed_s = take_start.seconds();
      progress(p);
    }
  }

  // Per-frame truth collected over the take.
  if (main_camera != nullptr) {
    writeFileAtomic(out / "truth" / "main_poses.jsonl", main_poses.text);
  }
  if (studio_preset) {
    writeFileAtomic(out / "truth" / "props.jsonl", prop_poses.text);
    writeJsonAtomic(out / "cg" / "camera.json",
                    {{"camera", cameraToJson(cg_camera)},
                     {"lens_camera", main_camera->rig.camera.name},
                     {"overscan", o.cg_overscan},
                     {"pixel_origin", "pixel (0,0) is the centre of the top-left pixel"},
                     {"pose", "T_world_cam of each frame equals the main camera's "
                              "(truth/main_poses.jsonl)"},
                     {"frames", cg_frames}});
  }
  for (const auto& [name, lines] : board_lines) {
    writeFileAtomic(out / "truth" / "boards" / (name + ".jsonl"), lines.text);
  }
  if (o.preset == Preset::kRig) {
    writeJsonAtomic(out / "truth" / "board_frames.json",
                    {{"floor_frames", floor_frames},
                     {"T_world_board", poseToJson(floorBoardPose())},
                     {"note",
                      "in floor frames the board lies face up with its board-frame origin at the "
                      "world origin: board x = world x, board y = -world y, board z = -world z"}});
    // What the operator knows of the capture (multicam/observations.h readFloor): which frames
    // show the floor board. A capture without floor frames (--no-floor) has no floor.json.
    if (!floor_frames.empty()) {
      writeJsonAtomic(out / "floor.json", {{"board", "board.json"},
                                           {"frames", floor_frames},
                                           {"T_world_board", poseToJson(floorBoardPose())}});
    }
  }

  for (auto& [name, w] : writers) w.close();

  // take.json last: its presence marks a complete take.
  nlohmann::json names = nlohmann::json::array();
  nlohmann::json gains = nlohmann::json::object();
  for (const TakeCamera& c : cameras) {
    names.push_back(c.rig.camera.name);
    gains[c.rig.camera.name] = c.gain;
  }
  nlohmann::json take = {{"format", "previz synthetic take"},
                         {"format_version", kTakeFormatVersion},
                         {"previz_version", PREVIZ_VERSION},
                         {"preset", toString(o.preset)},
                         {"seed", o.seed},
                         {"fps", o.fps},
                         {"frames", o.frames},
                         {"frame_pattern", kFramePattern},
                         {"duration_s", duration_s},
                         {"choreography_duration_s", config.take_duration_s},
                         {"cameras", names},
                         {"camera_gains", gains},
                         {"shutter_instants", board_preset ? 1 : static_cast<int>(shutterTimes(0, o).size())},
                         {"options", optionsToJson(o)}};
  if (board_preset) take["board"] = o.board;
  if (!offsets.empty()) take["offsets"] = offsets;
  if (!o.start_timecode.empty()) take["start_timecode"] = o.start_timecode;
  writeJsonAtomic(out / "take.json", take);

  SynthSummary summary;
  summary.frames = o.frames;
  summary.cameras = static_cast<int>(cameras.size());
  summary.render_ms = render_ms;
  summary.ms_per_camera_frame = plate_ms / (static_cast<double>(o.frames) * cameras.size());
  summary.out = out;
  return summary;
}

}  // namespace previz::synth
