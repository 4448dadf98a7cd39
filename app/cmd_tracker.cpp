// previz tracker: the stage's camera tracker (live/tracker.h, live/tracker_align.h).
//   record    capture a FreeD / OpenTrackIO stream to JSON lines (every datagram, arrival time,
//             decoded pose, encoders, timecode)
//   replay    play a recording to HOST:PORT at its recorded rate, so a live take re-runs offline
//   simulate  a synthetic take's true main-camera move as a tracker stream (delay, jitter, loss)
//   align     T_tracker_cam and the delay from a board take filmed while the tracker streamed
#include <chrono>
#include <cmath>
#include <iostream>

#include <nlohmann/json.hpp>

#include "app/commands.h"
#include "app/options.h"
#include "core/board.h"
#include "core/camera_io.h"
#include "core/error.h"
#include "core/io.h"
#include "core/names.h"
#include "core/rig.h"
#include "core/stopwatch.h"
#include "datasets/rigs.h"
#include "live/tracker.h"
#include "live/tracker_align.h"
#include "multicam/observations.h"

namespace previz::app {
namespace {

namespace fs = std::filesystem;

struct RecordArgs {
  std::string listen, out;
  double seconds = 10;
  long long packets = 0;
  bool json = false, quiet = false;
};

int runRecord(const RecordArgs& a) {
  if (a.out.empty()) throw Error("an output file is required", fieldContext("--out"));
  if (!(a.seconds > 0)) throw Error("--seconds must be > 0", fieldContext("--seconds"));
  const live::TrackerUrl url = live::parseTrackerUrl(a.listen, "--listen");
  if (url.kind != live::TrackerUrl::Kind::kUdp) throw Error("--listen takes freed:// or otio://", fieldContext("--listen"));
  live::TrackerOptions options;
  live::TrackerReceiver receiver(url, options);
  receiver.keepDatagrams(true);
  live::TrackerRecording r;
  r.protocol = url.protocol;
  r.url = url.text;
  r.started_unix_ms = std::chrono::duration_cast<std::chrono::milliseconds>(
                          std::chrono::system_clock::now().time_since_epoch())
                          .count();
  if (!a.quiet)
    std::cerr << "tracker record: listening on " << url.host << ":" << receiver.port() << " ("
              << live::protocolScheme(url.protocol) << ") for " << a.seconds << " s\n";
  while (receiver.now_s() < a.seconds && (a.packets <= 0 || static_cast<long long>(r.datagrams.size()) < a.packets)) {
    receiver.poll(20);
    for (auto& [t, bytes] : receiver.takeDatagrams()) r.datagrams.push_back({t, std::move(bytes)});
    receiver.take();
  }
  live::writeRecording(a.out, r, options);
  const live::TrackerCounts& c = receiver.counts();
  if (!a.quiet)
    std::cerr << "tracker record: " << r.datagrams.size() << " datagrams, " << c.accepted << " samples decoded -> " << a.out
              << "\n";
  if (a.json)
    std::cout << nlohmann::json{{"command", "tracker record"}, {"out", a.out}, {"datagrams", r.datagrams.size()},
                                {"counts", c.toJson()}}
                     .dump()
              << "\n";
  return 0;
}

struct ReplayArgs {
  std::string file, to;
  double speed = 1;
  bool json = false, quiet = false;
};

int runReplay(const ReplayArgs& a) {
  const live::TrackerUrl url = live::parseTrackerUrl(a.to, "--to");
  if (url.kind != live::TrackerUrl::Kind::kUdp) throw Error("--to takes freed:// or otio://", fieldContext("--to"));
  if (url.host == "0.0.0.0") throw Error("--to needs the receiver's address, not 0.0.0.0", fieldContext("--to"));
  if (!(a.speed > 0)) throw Error("--speed must be > 0", fieldContext("--speed"));
  const live::TrackerRecording r = live::readRecording(a.file);
  if (r.protocol != url.protocol)
    throw Error("the recording is " + live::protocolScheme(r.protocol) + ", --to is " + live::protocolScheme(url.protocol) +
                    " (replay sends the recorded bytes; it does not translate)",
                fieldContext("--to"));
  if (!a.quiet)
    std::cerr << "tracker replay: " << r.datagrams.size() << " datagrams to " << url.host << ":" << url.port << " at x"
              << a.speed << "\n";
  const Stopwatch t0;
  const int sent = live::replayRecording(r, url.host, url.port, a.speed);
  const double s = t0.seconds();
  if (a.json)
    std::cout << nlohmann::json{{"command", "tracker replay"}, {"sent", sent}, {"datagrams", r.datagrams.size()}, {"seconds", s}}
                     .dump()
              << "\n";
  return sent == static_cast<int>(r.datagrams.size()) ? 0 : 1;
}

struct SimulateArgs {
  std::string take, out, protocol = "freed", config, timecode;
  double rate = 60, delay = 0.040, jitter = 0.002, loss = 0.01, zoom = -1, focus = -1, margin = 0.25;
  std::uint64_t seed = 1;
  bool cbor = false, json = false;
};

int runSimulate(const SimulateArgs& a) {
  if (a.out.empty()) throw Error("an output file is required", fieldContext("--out"));
  const nlohmann::json take_json = readJsonFile(fs::path(a.take) / "take.json");
  if (!take_json.contains("choreography_duration_s"))
    throw Error("not a synthetic studio take (take.json has no choreography_duration_s)", fileContext(a.take));
  const double duration = take_json.at("choreography_duration_s").get<double>();
  const double fps = take_json.value("fps", 24.0);
  const int frames = take_json.value("frames", 1);
  const bool dolly = take_json.value("options", nlohmann::json::object()).value("main_dolly", true);
  live::TrackerSimulation sim;
  if (a.protocol == "freed") sim.protocol = tracking::StreamProtocol::kFreeD;
  else if (a.protocol == "otio") sim.protocol = tracking::StreamProtocol::kOpenTrackIo;
  else throw Error("--protocol must be freed or otio (got '" + a.protocol + "')", fieldContext("--protocol"));
  sim.rate_hz = a.rate;
  sim.start_s = -a.margin;
  sim.end_s = (frames - 1) / fps + a.margin;
  sim.delay_s = a.delay;
  sim.jitter_s = a.jitter;
  sim.loss = a.loss;
  sim.seed = a.seed;
  sim.cbor = a.cbor;
  sim.start_timecode = a.timecode;
  sim.timecode_fps = fps;
  if (a.zoom >= 0) sim.zoom = a.zoom;
  if (a.focus >= 0) sim.focus = a.focus;
  if (!a.config.empty()) {
    const live::TrackerOptions o = live::readTrackerConfig(a.config);
    sim.T_world_stage = o.T_world_stage;
    sim.T_tracker_cam = o.T_tracker_cam;
  }
  const live::TrackerRecording r =
      live::simulateTracker([&](double t) { return synth::mainCameraPose(t, duration, dolly); }, sim);
  live::writeRecording(a.out, r, live::TrackerOptions{});
  std::cerr << "tracker simulate: " << r.datagrams.size() << " " << a.protocol << " datagrams at " << a.rate << " Hz over "
            << sim.end_s - sim.start_s << " s (delay " << 1e3 * a.delay << " ms, jitter +-" << 1e3 * a.jitter << " ms, loss "
            << 100 * a.loss << " %) -> " << a.out << "\n";
  if (a.json)
    std::cout << nlohmann::json{{"command", "tracker simulate"}, {"out", a.out}, {"datagrams", r.datagrams.size()}}.dump() << "\n";
  return 0;
}


struct AlignArgs {
  std::string take, observations, tracker_log, board, rig, camera = kMainCamera, config, out;
  double fps = 0, delay_search = 0.25, delay_step = 0.01;
  bool json = false;
};

int runAlign(const AlignArgs& a) {
  if (a.out.empty()) throw Error("an output tracker.json is required", fieldContext("--out"));
  if (a.take.empty() == a.observations.empty())
    throw Error("give the board take (--take) or its detections (--observations)", fieldContext("--take"));
  if (a.rig.empty()) throw Error("the main camera's calibrated intrinsics are needed", fieldContext("--rig"));
  const Rig rig = readRig(a.rig);
  const Camera cam = rig.at(a.camera).camera;
  live::TrackerOptions base = a.config.empty() ? live::TrackerOptions{} : live::readTrackerConfig(a.config);
  // The board's corners in the main camera per frame: detected now, or as `previz rig` wrote them.
  multicam::RigObservations obs;
  if (!a.observations.empty()) {
    obs = multicam::readObservations(a.observations);
  } else {
    if (a.board.empty()) throw Error("--take needs the board (--board board.json)", fieldContext("--board"));
    std::cerr << "tracker align: detecting the board in " << a.take << " (" << a.camera << ")\n";
    obs = multicam::detectTake(a.take, {a.camera}, readBoard(a.board), nullptr);
  }
  const multicam::CameraDetections* det = obs.find(a.camera);
  if (!det) throw Error("no detections of camera '" + a.camera + "'", fieldContext("--camera"));
  double fps = a.fps;
  if (!(fps > 0) && !a.take.empty() && fs::exists(fs::path(a.take) / "take.json"))
    fps = readJsonFile(fs::path(a.take) / "take.json").value("fps", 0.0);
  if (!(fps > 0)) throw Error("the take's frame rate is needed (--fps)", fieldContext("--fps"));
  std::map<int, Eigen::Vector3d> points;
  for (const BoardPoint& p : boardPoints(obs.board)) points[p.id] = p.p_board;
  std::vector<live::BoardView> views;
  for (const auto& [frame, list] : det->frames) {
    live::BoardView v;
    v.frame = frame;
    v.time_s = frame / fps;  // frame 0 of the take is the recording's instant 0 (live/tracker.h)
    for (const calib::Observation& o : list) {
      const auto it = points.find(o.id);
      if (it == points.end()) continue;
      v.board_points.push_back(it->second);
      v.pixels.push_back(o.px);
    }
    views.push_back(std::move(v));
  }
  // The tracker's samples through the receiver, as `previz run` would take them.
  const live::TrackerRecording rec = live::readRecording(a.tracker_log);
  live::TrackerReceiver receiver(rec.protocol, base);
  std::vector<live::AlignSample> samples;
  for (const live::RecordedDatagram& d : rec.datagrams) {
    receiver.feed(d.bytes.data(), d.bytes.size(), d.arrival_s);
    for (const live::TrackerSample& s : receiver.take()) samples.push_back({s.arrival_s, s.sample.T_stage_tracker});
  }
  live::TrackerAlignOptions ao;
  ao.delay_search_s = a.delay_search;
  ao.delay_step_s = a.delay_step;
  const live::TrackerAlignResult r = live::alignTracker(views, cam, samples, ao);
  std::cerr << r.fullReport();
  live::TrackerOptions o = base;
  o.T_tracker_cam = r.T_tracker_cam;
  o.delay_s = r.delay_s;
  nlohmann::json j = live::trackerOptionsToJson(o);
  j["report"] = r.toJson();
  j["report"]["counts"] = receiver.counts().toJson();
  writeJsonAtomic(a.out, j);
  if (a.json) std::cout << nlohmann::json{{"command", "tracker align"}, {"out", a.out}, {"report", j["report"]}}.dump() << "\n";
  return 0;
}

Runner addTrackerAlign(CLI::App& cmd) {
  auto a = std::make_shared<AlignArgs>();
  cmd.description(
      "The tracker's mount offset from the lens (T_tracker_cam, hand-eye) and its delay, from a board take the main "
      "camera filmed while the tracker streamed (recorded with previz tracker record); writes tracker.json with 1 sigma");
  cmd.add_option("--take", a->take, "Board take (cams/<camera>/...; frame f at f / fps on the recording's clock)");
  cmd.add_option("--observations", a->observations, "Or the board detections (previz-rig-observations JSON) instead of --take");
  cmd.add_option("--tracker-log", a->tracker_log, "The tracker's recording during the take (FILE.jsonl)")->required();
  cmd.add_option("--board", a->board, "board.json of the board (with --take)");
  cmd.add_option("--rig", a->rig, "rig.json holding the main camera's calibrated intrinsics");
  cmd.add_option("--camera", a->camera, "The main camera's name")->capture_default_str();
  cmd.add_option("--fps", a->fps, "The take's frame rate (default: take.json's)");
  cmd.add_option("--tracker-config", a->config, "tracker.json to start from (T_world_stage, FreeD encoder ranges); kept in --out");
  cmd.add_option("--delay-search", a->delay_search, "The delay is looked for in [-S, S] seconds")->capture_default_str();
  cmd.add_option("--delay-step", a->delay_step, "Grid step of that search, seconds")->capture_default_str();
  cmd.add_option("--out", a->out, "tracker.json to write (previz run --tracker-config)")->required();
  cmd.add_flag("--json", a->json, "JSON summary on stdout");
  return [a]() { return runAlign(*a); };
}

}  // namespace

Runner addTrackerCommand(CLI::App& app) {
  CLI::App* cmd = app.add_subcommand(
      "tracker", "The stage's camera tracker (FreeD D1, OpenTrackIO): record, replay, simulate, align to the lens "
                 "(docs/formats.md \"Camera tracker\"); previz run --tracker uses it");
  cmd->require_subcommand(1);

  auto rec = std::make_shared<RecordArgs>();
  CLI::App* r = cmd->add_subcommand("record", "Capture a tracker stream to JSON lines (every datagram with its arrival time)");
  r->add_option("--listen", rec->listen, "freed://HOST:PORT or otio://HOST:PORT (0.0.0.0: every interface; a multicast group is joined)")
      ->required();
  r->add_option("--out", rec->out, "Recording FILE.jsonl")->required();
  r->add_option("--seconds", rec->seconds, "How long to listen")->capture_default_str();
  r->add_option("--packets", rec->packets, "Stop after this many datagrams (0: no limit)")->capture_default_str();
  r->add_flag("--json", rec->json, "JSON summary on stdout");
  r->add_flag("--quiet", rec->quiet, "No progress on stderr");

  auto rep = std::make_shared<ReplayArgs>();
  CLI::App* p = cmd->add_subcommand("replay", "Play a recording to a receiver at its recorded rate");
  p->add_option("file", rep->file, "Recording FILE.jsonl (previz tracker record)")->required();
  p->add_option("--to", rep->to, "freed://HOST:PORT or otio://HOST:PORT (the recording's protocol)")->required();
  p->add_option("--speed", rep->speed, "Rate factor (2: twice as fast)")->capture_default_str();
  p->add_flag("--json", rep->json, "JSON summary on stdout");
  p->add_flag("--quiet", rep->quiet, "No progress on stderr");

  auto sim = std::make_shared<SimulateArgs>();
  CLI::App* s = cmd->add_subcommand(
      "simulate", "A synthetic studio take's true main-camera move as a camera tracker's stream (a recording)");
  s->add_option("--take", sim->take, "Synthetic take (previz synth --preset studio)")->required();
  s->add_option("--out", sim->out, "Recording FILE.jsonl")->required();
  s->add_option("--protocol", sim->protocol, "freed or otio")->capture_default_str();
  s->add_option("--rate", sim->rate, "Samples per second")->capture_default_str();
  s->add_option("--delay", sim->delay, "Seconds from a sample's instant to its arrival")->capture_default_str();
  s->add_option("--jitter", sim->jitter, "Arrival jitter, seconds (uniform +-)")->capture_default_str();
  s->add_option("--loss", sim->loss, "Fraction of datagrams lost")->capture_default_str();
  s->add_option("--seed", sim->seed, "Random seed (jitter, loss, sample ids)")->capture_default_str();
  s->add_option("--zoom", sim->zoom, "Zoom encoder 0..1 sent with every sample (default: none)");
  s->add_option("--focus", sim->focus, "Focus encoder 0..1 sent with every sample (default: none)");
  s->add_option("--timecode", sim->timecode, "OpenTrackIO: timecode of the take's frame 0 (HH:MM:SS:FF)");
  s->add_option("--tracker-config", sim->config, "tracker.json: T_world_stage and T_tracker_cam of the simulated tracker");
  s->add_flag("--cbor", sim->cbor, "OpenTrackIO payloads in CBOR");
  s->add_flag("--json", sim->json, "JSON summary on stdout");

  CLI::App* align = cmd->add_subcommand("align", "");  // defined in addTrackerAlign (below)
  Runner align_runner = addTrackerAlign(*align);
  return [=]() {
    if (r->parsed()) return runRecord(*rec);
    if (p->parsed()) return runReplay(*rep);
    if (s->parsed()) return runSimulate(*sim);
    return align_runner();
  };
}

}  // namespace previz::app
