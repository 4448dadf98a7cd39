// The live loop under scheduled faults (live/soak.h).
#include "live/soak.h"

#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <set>
#include <sstream>

#include "carving/take.h"
#include "composite/output.h"
#include "core/cpu_time.h"
#include "core/error.h"
#include "core/io.h"
#include "core/names.h"
#include "core/stats.h"
#include "core/stopwatch.h"
#include "core/write_fault.h"
#include "live/inputs.h"
#include "take/take.h"

namespace previz::live {

namespace fs = std::filesystem;

namespace {

constexpr int kLateFrames = 2;  // camera_late: the witness shows the frame this many before

// q-quantile by rank (q = 0.5: the upper median, as bench run reports it; 0.99: p99).
// Resident set size of this process, MiB (/proc/self/statm: pages).
double rssMiB() {
  std::ifstream in("/proc/self/statm");
  long long size = 0, resident = 0;
  in >> size >> resident;
  return static_cast<double>(resident) * static_cast<double>(::sysconf(_SC_PAGESIZE)) / (1024.0 * 1024.0);
}

std::uint64_t fnv1a(const std::string& bytes) {
  std::uint64_t h = 0xcbf29ce484222325ull;
  for (unsigned char c : bytes) h = (h ^ c) * 0x100000001b3ull;
  return h;
}

ErrorContext frameContext(const std::string& file, const std::string& camera, int frame) {
  ErrorContext c;
  c.file = file;
  c.camera = camera;
  c.frame = frame;
  return c;
}

// The fault schedule: one block per period, each fault at its place in the period; witness
// faults turn through the witnesses from one period to the next.
std::vector<SoakFault> schedule(const SoakOptions& o, const std::vector<std::string>& witnesses,
                                const std::string& main) {
  std::vector<SoakFault> faults;
  const int p = o.period;
  const int span = std::max(3, p / 25);  // frames an unplug, a late camera, a full disk last
  for (int k = 0; (k + 1) * p <= o.frames; ++k) {
    const int b = k * p;
    const std::string w = witnesses[k % witnesses.size()];
    const std::string w2 = witnesses[(k + 1) % witnesses.size()];
    auto add = [&](const std::string& kind, const std::string& cam, double at, int frames, int datagrams = 0) {
      SoakFault f;
      f.kind = kind;
      f.camera = cam;
      f.first_frame = b + static_cast<int>(at * p);
      f.end_frame = f.first_frame + frames;
      f.datagrams = datagrams;
      faults.push_back(f);
    };
    add("witness_unplugged", w, 0.06, span);
    add("witness_corrupt", w2, 0.16, 1);
    add("witness_truncated", w, 0.20, 1);
    add("main_corrupt", main, 0.26, 1);
    add("main_truncated", main, 0.30, 1);
    add("camera_late", w2, 0.36, span);
    add("tracker_loss", "", 0.50, 1, 2);      // 2 datagrams at 60 Hz: 50 ms between samples, bridged
    add("tracker_reorder", "", 0.56, 1, 1);   // one pair swapped
    add("tracker_outage", "", 0.64, 1, 30);   // half a second: frames without a pose
    add("disk_full", "", 0.80, span);
  }
  return faults;
}

const SoakFault* faultAt(const std::vector<SoakFault>& faults, const std::string& kind, int frame) {
  for (const SoakFault& f : faults)
    if (f.kind == kind && frame >= f.first_frame && frame < f.end_frame) return &f;
  return nullptr;
}

// A file of the working take changed for one frame and put back after it.
class FileFault {
 public:
  FileFault(const fs::path& path, const std::string& kind, const fs::path& late_source) : path_(path) {
    original_ = readTextFile(path);
    if (kind == "witness_unplugged") {
      hidden_ = path.string() + ".unplugged";
      fs::rename(path, hidden_);
    } else if (kind == "witness_corrupt" || kind == "main_corrupt") {
      // Bytes in the middle of the image data flipped: the PNG's chunk CRC no longer holds.
      std::string bytes = original_;
      const size_t at = bytes.size() / 2, n = std::min<size_t>(64, bytes.size() - at);
      for (size_t i = 0; i < n; ++i) bytes[at + i] = static_cast<char>(bytes[at + i] ^ 0x5a);
      writeFileAtomic(path, bytes);
    } else if (kind == "witness_truncated" || kind == "main_truncated") {
      writeFileAtomic(path, original_.substr(0, original_.size() / 2));
    } else if (kind == "camera_late") {
      writeFileAtomic(path, readTextFile(late_source));
    }
  }
  ~FileFault() {
    std::error_code ec;
    if (!hidden_.empty()) fs::rename(hidden_, path_, ec);
    else writeFileAtomic(path_, original_);
  }
  FileFault(const FileFault&) = delete;
  FileFault& operator=(const FileFault&) = delete;

 private:
  fs::path path_, hidden_;
  std::string original_;
};

// The file a sequence camera's take frame is read from.
fs::path frameFile(const carving::Take& take, const std::string& camera, int frame) {
  const take::CameraStream& s = take.streams().stream(camera);
  if (s.kind != take::SourceKind::kSequence)
    throw Error("soak: faults are injected into image sequences; this camera's stream is " + toString(s.kind),
                frameContext(s.path.string(), camera, frame));
  return s.path / s.pattern.fileName(frame + s.offset);
}

bool contains(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

void copyTake(const fs::path& from, const fs::path& to) {
  std::error_code ec;
  fs::remove_all(to, ec);
  fs::create_directories(to);
  for (const auto& e : fs::directory_iterator(from)) {
    const std::string name = e.path().filename().string();
    if (name == "truth" || name == "out") continue;  // not read by the loop; out/ is the take's own
    fs::copy(e.path(), to / name, fs::copy_options::recursive, ec);
    if (ec) throw Error("soak: cannot copy the take into the working folder: " + ec.message(), fileContext(e.path().string()));
  }
}

}  // namespace

void SoakOptions::validate() const {
  auto bad = [](const std::string& field, const std::string& what) {
    throw Error("soak: " + field + " " + what, fieldContext(field));
  };
  if (take.empty()) bad("take", "is required");
  if (out.empty()) bad("out", "is required");
  if (period < 100) bad("period", "must be >= 100 frames (got " + std::to_string(period) + ")");
  if (frames < period) bad("frames", "must be >= period (" + std::to_string(period) + "), got " + std::to_string(frames));
  if (rss_window < 1) bad("rss_window", "must be >= 1");
  if (warmup_frames < 0 || warmup_frames + 2 * rss_window > frames)
    bad("warmup_frames", "plus two RSS windows (" + std::to_string(rss_window) + ") must fit in the frames (" +
                             std::to_string(frames) + ")");
  if (!(max_rss_growth >= 0)) bad("max_rss_growth", "must be >= 0");
  if (output_slots < 1) bad("output_slots", "must be >= 1");
  if (!(fps > 0)) bad("fps", "must be > 0");
  if (!(tracker_rate_hz >= 2 * fps)) bad("tracker_rate_hz", "must be at least twice the fps");
  loop.validate();
}

nlohmann::json SoakFault::toJson() const {
  nlohmann::json j = {{"kind", kind}, {"first_frame", first_frame}, {"end_frame", end_frame},
                      {"expected", expected}, {"observed", observed}, {"matched", matched}};
  if (!camera.empty()) j["camera"] = camera;
  if (datagrams) j["datagrams"] = datagrams;
  return j;
}

bool SoakReport::faultsMatched() const {
  return std::all_of(faults.begin(), faults.end(), [](const SoakFault& f) { return f.matched; });
}

nlohmann::json SoakReport::toJson() const { return toJson(false); }

nlohmann::json SoakReport::toJson(bool with_frames) const {
  auto events = [](const std::vector<SoakEvent>& v) {
    nlohmann::json a = nlohmann::json::array();
    for (const SoakEvent& e : v) {
      nlohmann::json j = {{"frame", e.frame}, {"reason", e.reason}};
      if (!e.camera.empty()) j["camera"] = e.camera;
      if (!e.file.empty()) j["file"] = e.file;
      a.push_back(j);
    }
    return a;
  };
  nlohmann::json faults_json = nlohmann::json::array();
  std::map<std::string, std::pair<int, int>> by_kind;  // injected, matched
  for (const SoakFault& f : faults) {
    faults_json.push_back(f.toJson());
    ++by_kind[f.kind].first;
    by_kind[f.kind].second += f.matched ? 1 : 0;
  }
  nlohmann::json kinds = nlohmann::json::object();
  for (const auto& [k, v] : by_kind) kinds[k] = {{"injected", v.first}, {"matched", v.second}};
  nlohmann::json j = {
      {"command", "soak"},
      {"ok", ok()},
      {"take", take},
      {"resolution", resolution},
      {"frames", {{"in", frames_in}, {"processed", frames_processed}, {"failed", frames_failed},
                  {"accounted", accounted()}}},
      {"faults_by_kind", kinds},
      {"faults", faults_json},
      {"failed", events(failed)},
      {"dropped", events(dropped)},
      {"skipped_writes", events(skipped_writes)},
      {"unexplained", events(unexplained)},
      {"tracker", tracker.toJson()},
      {"rss_mib", {{"start", rss_start_mib}, {"end", rss_end_mib}, {"max", rss_max_mib},
                   {"growth", rss_growth}, {"max_growth", max_rss_growth}, {"ok", rssOk()}}},
      {"frame_ms", {{"median", ms_median}, {"p99", ms_p99}, {"max", ms_max}}},
      {"frame_cpu_ms", {{"median", cpu_ms_median}, {"p99", cpu_ms_p99}, {"max", cpu_ms_max}}},
      {"outputs", {{"files", output_files}, {"complete", outputs_complete}, {"problems", output_problems}}},
      {"wall_s", wall_s}};
  if (with_frames) {
    nlohmann::json ms = nlohmann::json::array(), cpu = nlohmann::json::array(), rss = nlohmann::json::array(),
                   bad = nlohmann::json::array();
    for (const SoakFrame& f : frame_log) {
      ms.push_back(std::round(f.ms * 1000) / 1000);
      cpu.push_back(std::round(f.cpu_ms * 1000) / 1000);
      rss.push_back(std::round(f.rss_mib * 1000) / 1000);
      if (f.failed) bad.push_back(f.frame);
    }
    j["series"] = {{"frame_ms", ms}, {"frame_cpu_ms", cpu}, {"rss_mib", rss}, {"failed_frames", bad}};
  }
  return j;
}

std::string SoakReport::fullReport() const {
  std::ostringstream s;
  char line[512];
  s << "soak: " << take << " (" << resolution << ") looped for " << frames_in << " frames\n";
  std::snprintf(line, sizeof(line), "  frames: %d in = %d processed + %d failed (%s)\n", frames_in, frames_processed,
                frames_failed, accounted() ? "every frame accounted for" : "NOT ACCOUNTED");
  s << line;
  std::map<std::string, std::vector<const SoakFault*>> by_kind;
  for (const SoakFault& f : faults) by_kind[f.kind].push_back(&f);
  s << "  faults injected and how the loop handled them:\n";
  for (const auto& [kind, v] : by_kind) {
    const int matched = static_cast<int>(std::count_if(v.begin(), v.end(), [](const SoakFault* f) { return f->matched; }));
    std::snprintf(line, sizeof(line), "    %-18s %3zu injected, %3d matched: %s\n", kind.c_str(), v.size(), matched,
                  v.front()->expected.c_str());
    s << line;
    for (const SoakFault* f : v)
      if (!f->matched)
        s << "      NOT MATCHED frames " << f->first_frame << ".." << f->end_frame - 1
          << (f->camera.empty() ? "" : " camera '" + f->camera + "'") << ": " << f->observed << "\n";
  }
  if (!faults.empty()) s << "    e.g. " << faults.front().kind << ": " << faults.front().observed << "\n";
  for (const SoakEvent& e : unexplained)
    s << "  UNEXPLAINED frame " << e.frame << (e.camera.empty() ? "" : " camera '" + e.camera + "'") << ": " << e.reason << "\n";
  std::snprintf(line, sizeof(line), "  reported: %zu failed frames, %zu camera drops, %zu skipped writes\n", failed.size(),
                dropped.size(), skipped_writes.size());
  s << line;
  s << "  tracker: " << tracker.toJson().dump() << "\n";
  std::snprintf(line, sizeof(line),
                "  RSS: %.1f MiB after warm-up -> %.1f MiB at the end (%+.2f %%, limit %+.1f %%), max %.1f MiB: %s\n",
                rss_start_mib, rss_end_mib, 100 * rss_growth, 100 * max_rss_growth, rss_max_mib, rssOk() ? "ok" : "GROWING");
  s << line;
  std::snprintf(line, sizeof(line), "  frame time (read + stages + write): median %.2f ms, p99 %.2f ms, max %.2f ms\n",
                ms_median, ms_p99, ms_max);
  s << line;
  std::snprintf(line, sizeof(line), "  frame CPU time (every thread; wall time above also measures other jobs on a shared machine): "
                "median %.2f ms, p99 %.2f ms, max %.2f ms\n", cpu_ms_median, cpu_ms_p99, cpu_ms_max);
  s << line;
  std::snprintf(line, sizeof(line), "  outputs: %d of %d files complete and the last frame written to their slot\n",
                outputs_complete, output_files);
  s << line;
  for (const std::string& p : output_problems) s << "    " << p << "\n";
  s << "  " << (ok() ? "PASS" : "FAIL") << "\n";
  return s.str();
}

SoakReport runSoak(const SoakOptions& o, const std::function<void(const SoakProgress&)>& progress) {
  o.validate();
  const Stopwatch t_start;
  SoakReport r;
  r.take = o.take.string();
  r.max_rss_growth = o.max_rss_growth;
  const fs::path work = o.out / "take";
  const fs::path frames_dir = o.out / "frames";
  std::error_code ec;
  fs::remove_all(frames_dir, ec);
  copyTake(o.take, work);

  carving::TakeSource src;
  src.take_dir = work;
  src.rig_path = o.rig.empty() ? o.take / "truth" / "rig.json" : o.rig;
  if (fs::exists(o.take / "truth" / "main_poses.jsonl")) src.main_poses = o.take / "truth" / "main_poses.jsonl";
  const carving::Take take(src);
  const Camera cg = composite::readCgCamera(work / "cg" / "camera.json");
  FrameLoop loop(take.rig(), cg, o.loop);
  const TakeReader reader(take, loop, {});
  const std::vector<int>& take_frames = take.frames();
  if (take_frames.size() < kLateFrames + 1)
    throw Error("soak: the take needs at least " + std::to_string(kLateFrames + 1) + " frames", fileContext(o.take.string()));
  const int T = static_cast<int>(take_frames.size());
  auto takeFrame = [&](int n) { return take_frames[((n % T) + T) % T]; };
  const std::vector<std::string>& witnesses = loop.carveCameras();
  const std::string main = loop.mainCamera();
  {
    const Camera& w = take.rig().at(witnesses.front()).camera;
    const Camera& m = take.rig().at(main).camera;
    r.resolution = std::to_string(witnesses.size()) + " x " + std::to_string(w.width) + "x" + std::to_string(w.height) +
                   " + main " + std::to_string(m.width) + "x" + std::to_string(m.height);
  }

  r.faults = schedule(o, witnesses, main);

  // The camera tracker: the main camera's poses along the looped take, as OpenTrackIO at
  // tracker_rate_hz (numbered samples: losses and reordering are visible), no loss or jitter of
  // its own; the tracker faults are cut into the recording.
  TrackerSimulation sim;
  sim.protocol = tracking::StreamProtocol::kOpenTrackIo;
  sim.rate_hz = o.tracker_rate_hz;
  sim.start_s = 0;
  sim.end_s = (o.frames + 2) / o.fps;
  sim.delay_s = 0;
  sim.jitter_s = 0;
  sim.loss = 0;
  const RigCamera rig_main = take.rig().at(main);
  TrackerRecording rec = simulateTracker(
      [&](double t) { return take.cameraAt(main, takeFrame(static_cast<int>(std::floor(t * o.fps + 1e-9)))).T_world_cam; },
      sim);
  std::vector<bool> lost(rec.datagrams.size(), false);
  for (SoakFault& f : r.faults) {
    if (f.kind.rfind("tracker_", 0) != 0) continue;
    const size_t i0 = static_cast<size_t>(std::ceil(f.first_frame / o.fps * o.tracker_rate_hz));
    const size_t n = static_cast<size_t>(f.datagrams) * (f.kind == "tracker_reorder" ? 2 : 1);
    if (i0 + n >= rec.datagrams.size()) continue;
    if (f.kind == "tracker_reorder") {
      for (int k = 0; k < f.datagrams; ++k) std::swap(rec.datagrams[i0 + 2 * k].bytes, rec.datagrams[i0 + 2 * k + 1].bytes);
    } else {
      for (size_t i = i0; i < i0 + n; ++i) lost[i] = true;
    }
    // The frames whose tracker input the fault touches: up to the first sample after it.
    f.end_frame = static_cast<int>(std::ceil(rec.datagrams[i0 + n].arrival_s * o.fps)) + 1;
  }
  {
    std::vector<RecordedDatagram> kept;
    for (size_t i = 0; i < rec.datagrams.size(); ++i)
      if (!lost[i]) kept.push_back(rec.datagrams[i]);
    rec.datagrams = std::move(kept);
  }
  TrackerOptions to;
  const fs::path rec_path = o.out / "tracker.jsonl";
  writeRecording(rec_path, rec, to);
  TrackerUrl url;
  url.kind = TrackerUrl::Kind::kRecording;
  url.file = rec_path;
  url.text = rec_path.string();
  TrackerInput tracker(url, to, rig_main.camera);
  // Frames the outages leave without a pose: their instant is no sample's, and the samples
  // around it are further apart than max_gap_s (TrackerMatcher::interpolate).
  std::set<int> no_pose_expected;
  {
    std::vector<double> keys;
    for (const RecordedDatagram& d : rec.datagrams) keys.push_back(d.arrival_s - to.delay_s);
    for (int n = 0; n < o.frames; ++n) {
      const double t = n / o.fps;
      const auto after = std::lower_bound(keys.begin(), keys.end(), t);
      if (after == keys.end() || *after == t || after == keys.begin()) continue;
      if (*after - *(after - 1) > to.max_gap_s) no_pose_expected.insert(n);
    }
  }

  // Writes to the output ring fail while the disk is "full".
  std::atomic<bool> disk_full{false};
  const std::string frames_prefix = frames_dir.string();
  setWriteFaultHook([&disk_full, frames_prefix](const fs::path& p) {
    return disk_full.load() && p.string().compare(0, frames_prefix.size(), frames_prefix) == 0;
  });
  struct HookReset {
    ~HookReset() { setWriteFaultHook({}); }
  } hook_reset;

  composite::OutputOptions oo;
  oo.out = frames_dir;
  oo.fps = o.fps;
  composite::CompositeWriter writer(oo);
  struct Written {
    int frame = -1;
    std::uint64_t hash = 0;
  };
  std::map<fs::path, Written> written;  // the last frame written to each ring file
  std::vector<TrackerCounts> counts_after(o.frames);
  std::vector<std::map<std::string, std::string>> drops(o.frames);  // frame -> camera -> reason
  std::vector<std::string> fail_reason(o.frames);
  std::vector<std::vector<SoakEvent>> skips(o.frames);

  for (int n = 0; n < o.frames; ++n) {
    const int t = takeFrame(n);
    std::vector<int> stamp(witnesses.size(), n);  // the frame each witness's plate shows
    FrameState s;
    double ms = 0, cpu_ms = 0;
    bool failed = false;
    {
      // This frame's file faults, undone when the frame is read.
      std::vector<std::unique_ptr<FileFault>> file_faults;
      for (const char* kind : {"witness_unplugged", "witness_corrupt", "witness_truncated", "main_corrupt",
                               "main_truncated", "camera_late"}) {
        const SoakFault* f = faultAt(r.faults, kind, n);
        if (!f) continue;
        const fs::path late = frameFile(take, f->camera, takeFrame(n - kLateFrames));
        file_faults.push_back(std::make_unique<FileFault>(frameFile(take, f->camera, t), kind, late));
        if (f->kind == "camera_late")
          stamp[std::find(witnesses.begin(), witnesses.end(), f->camera) - witnesses.begin()] = n - kLateFrames;
      }
      disk_full = faultAt(r.faults, "disk_full", n) != nullptr;
      const Stopwatch t0;
      const double c0 = processCpuMs();
      try {
        reader.read(t, s);
      } catch (const Error& e) {
        failed = true;
        fail_reason[n] = e.what();
      }
      ms += t0.ms();
      cpu_ms += processCpuMs() - c0;
    }
    const Stopwatch t1;
    const double c1 = processCpuMs();
    if (!failed) {
      // A plate stamped with another frame than the frame set's (a camera out of sync) is not
      // carved with the others.
      for (size_t i = 0; i < witnesses.size(); ++i) {
        if (stamp[i] == n || s.witness_plates[i].empty()) continue;
        s.witness_plates[i] = cv::Mat();
        s.dropped[i] = formatError("late: its frame shows take frame " + std::to_string(takeFrame(stamp[i])) + " (" +
                                       std::to_string(n - stamp[i]) + " frames behind the frame set's)",
                                   frameContext(frameFile(take, witnesses[i], t).string(), witnesses[i], n));
      }
      try {
        s.main = tracker.mainAt(n, n / o.fps, std::nullopt, s.main);
        loop.run(s);
      } catch (const Error& e) {
        failed = true;
        fail_reason[n] = e.what();
      }
    }
    counts_after[n] = tracker.counts();
    if (failed) {
      ++r.frames_failed;
      r.failed.push_back({n, "", "", fail_reason[n]});
    } else {
      ++r.frames_processed;
      for (size_t i = 0; i < witnesses.size(); ++i)
        if (!s.dropped[i].empty()) {
          drops[n][witnesses[i]] = s.dropped[i];
          r.dropped.push_back({n, witnesses[i], "", s.dropped[i]});
        }
      // Outputs as `previz run` writes them, into the ring; a failed write is reported and the
      // loop goes on.
      const int slot = n % o.output_slots;
      const fs::path png = frames_dir / "composite" / (frameStem(slot) + ".png");
      const fs::path exr = frames_dir / "depth" / (frameStem(slot) + ".exr");
      try {
        writer.write(slot, s.composite);
        written[png] = {n, fnv1a(readTextFile(png))};
      } catch (const Error& e) {
        skips[n].push_back({n, "", png.string(), e.what()});
      }
      try {
        writeDepthExr(exr, s.main_depth,
                      {{"previz:camera", main}, {"previz:frame", std::to_string(t)}, {"previz:soak_frame", std::to_string(n)}});
        written[exr] = {n, 0};
      } catch (const Error& e) {
        skips[n].push_back({n, "", exr.string(), e.what()});
      }
      for (const SoakEvent& e : skips[n]) r.skipped_writes.push_back(e);
    }
    ms += t1.ms();
    cpu_ms += processCpuMs() - c1;
    SoakFrame log;
    log.frame = n;
    log.take_frame = t;
    log.failed = failed;
    log.ms = ms;
    log.cpu_ms = cpu_ms;
    log.rss_mib = rssMiB();
    r.frame_log.push_back(log);
    if (progress)
      progress({n + 1, o.frames, ms, log.rss_mib, r.frames_failed, static_cast<int>(r.dropped.size()),
                static_cast<int>(r.skipped_writes.size())});
  }
  disk_full = false;
  r.frames_in = o.frames;
  r.tracker = tracker.counts();

  // Each fault against what the loop reported.
  std::set<std::pair<int, std::string>> explained_drops;  // (frame, camera)
  std::set<int> explained_failures, explained_skips;
  auto delta = [&](const SoakFault& f, long long TrackerCounts::*field) {
    const int a = std::max(0, f.first_frame - 1), b = std::min(o.frames, f.end_frame + 2);
    return counts_after[b - 1].*field - (a > 0 ? counts_after[a - 1].*field : 0);
  };
  for (SoakFault& f : r.faults) {
    std::ostringstream obs;
    bool ok = true;
    std::string first_reason;
    if (f.kind == "witness_unplugged" || f.kind == "witness_corrupt" || f.kind == "witness_truncated" ||
        f.kind == "camera_late") {
      f.expected = f.kind == "camera_late"
                       ? "the camera dropped on every frame it is late (\"late: ... frames behind\"), used again after"
                       : "the camera dropped on every frame, the reason naming its file, the frame composited";
      int seen = 0;
      for (int n = f.first_frame; n < f.end_frame; ++n) {
        // The reason names the frame's file (late: says so).
        const std::string want =
            f.kind == "camera_late" ? std::string("late: ") : frameFile(take, f.camera, takeFrame(n)).string();
        const auto it = drops[n].find(f.camera);
        if (it != drops[n].end() && contains(it->second, want) && fail_reason[n].empty()) {
          ++seen;
          explained_drops.insert({n, f.camera});
          if (first_reason.empty()) first_reason = it->second;
        }
      }
      const bool back = f.end_frame >= o.frames || (fail_reason[f.end_frame].empty() && !drops[f.end_frame].count(f.camera));
      ok = seen == f.end_frame - f.first_frame && (f.kind != "camera_late" || back);
      obs << "camera '" << f.camera << "' dropped on " << seen << " of " << f.end_frame - f.first_frame << " frames"
          << (f.kind == "camera_late" ? (back ? ", in sync again at frame " : ", STILL DROPPED at frame ") +
                                            std::to_string(f.end_frame)
                                      : std::string())
          << (first_reason.empty() ? "" : ": " + first_reason);
    } else if (f.kind == "main_corrupt" || f.kind == "main_truncated") {
      f.expected = "the frame failed, reason naming the main plate's file";
      const std::string& why = fail_reason[f.first_frame];
      ok = contains(why, "main plate unusable") && contains(why, frameFile(take, main, takeFrame(f.first_frame)).string());
      if (ok) explained_failures.insert(f.first_frame);
      obs << "frame " << f.first_frame << (why.empty() ? " not failed" : " failed: " + why);
    } else if (f.kind == "tracker_loss" || f.kind == "tracker_outage") {
      const long long missing = delta(f, &TrackerCounts::missing);
      std::vector<int> failed_frames, expected_frames;
      for (int n = f.first_frame; n < f.end_frame; ++n) {
        if (no_pose_expected.count(n)) expected_frames.push_back(n);
        if (contains(fail_reason[n], "no tracker pose")) failed_frames.push_back(n);
      }
      if (f.kind == "tracker_loss") {
        f.expected = "the lost datagrams counted missing, every frame still posed (interpolated across the gap)";
        ok = missing == f.datagrams && failed_frames.empty();
      } else {
        f.expected = "the lost datagrams counted missing, the frames beyond max_gap_s failed \"no tracker pose\"";
        ok = missing == f.datagrams && !failed_frames.empty() && failed_frames == expected_frames;
      }
      for (int n : failed_frames) explained_failures.insert(n);
      obs << missing << " datagrams counted missing (" << f.datagrams << " lost), " << failed_frames.size()
          << " frames failed without a pose (" << expected_frames.size() << " expected)";
      if (!failed_frames.empty()) obs << ": " << fail_reason[failed_frames.front()];
    } else if (f.kind == "tracker_reorder") {
      f.expected = "counted out_of_order (the older datagram not used) and its gap counted missing";
      const long long ooo = delta(f, &TrackerCounts::out_of_order), missing = delta(f, &TrackerCounts::missing);
      ok = ooo == f.datagrams && missing == f.datagrams;
      obs << ooo << " out_of_order, " << missing << " missing (" << f.datagrams << " pairs swapped)";
    } else if (f.kind == "disk_full") {
      f.expected = "both writes of every frame skipped (ENOSPC, file named), the loop going on, no half file";
      int frames_skipped = 0, processed = 0;
      for (int n = f.first_frame; n < f.end_frame; ++n) {
        if (!fail_reason[n].empty()) continue;
        ++processed;
        const bool both = skips[n].size() == 2 && std::all_of(skips[n].begin(), skips[n].end(), [](const SoakEvent& e) {
                            return contains(e.reason, "No space left on device");
                          });
        if (both) {
          ++frames_skipped;
          explained_skips.insert(n);
          if (first_reason.empty()) first_reason = skips[n].front().reason;
        }
      }
      ok = processed > 0 && frames_skipped == processed;
      obs << "writes skipped on " << frames_skipped << " of " << processed << " frames processed"
          << (first_reason.empty() ? "" : ": " + first_reason);
    }
    f.matched = ok;
    f.observed = obs.str();
  }
  // ... and every report against the faults: nothing the schedule does not explain.
  for (const SoakEvent& e : r.dropped)
    if (!explained_drops.count({e.frame, e.camera})) r.unexplained.push_back(e);
  for (const SoakEvent& e : r.failed)
    if (!explained_failures.count(e.frame)) r.unexplained.push_back(e);
  for (const SoakEvent& e : r.skipped_writes)
    if (!explained_skips.count(e.frame)) r.unexplained.push_back(e);
  const long long injected_missing = [&] {
    long long m = 0;
    for (const SoakFault& f : r.faults)
      if (f.kind.rfind("tracker_", 0) == 0) m += f.datagrams;
    return m;
  }();
  if (r.tracker.missing != injected_missing)
    r.unexplained.push_back({o.frames, "", rec_path.string(),
                             "the tracker counted " + std::to_string(r.tracker.missing) + " datagrams missing, " +
                                 std::to_string(injected_missing) + " were lost or swapped"});
  if (r.tracker.frames_without_pose != static_cast<long long>(no_pose_expected.size()))
    r.unexplained.push_back({o.frames, "", rec_path.string(),
                             std::to_string(r.tracker.frames_without_pose) + " frames without a tracker pose, " +
                                 std::to_string(no_pose_expected.size()) + " expected from the outages"});

  // RSS after warm-up against the last window; frame times.
  {
    std::vector<double> first, last, ms, cpu;
    for (const SoakFrame& f : r.frame_log) {
      if (f.frame >= o.warmup_frames && f.frame < o.warmup_frames + o.rss_window) first.push_back(f.rss_mib);
      if (f.frame >= o.frames - o.rss_window) last.push_back(f.rss_mib);
      if (f.frame >= o.warmup_frames) r.rss_max_mib = std::max(r.rss_max_mib, f.rss_mib);
      ms.push_back(f.ms);
      cpu.push_back(f.cpu_ms);
    }
    r.rss_start_mib = quantile(first, 0.5);
    r.rss_end_mib = quantile(last, 0.5);
    r.rss_growth = r.rss_start_mib > 0 ? r.rss_end_mib / r.rss_start_mib - 1 : 0;
    r.ms_median = quantile(ms, 0.5);
    r.ms_p99 = quantile(ms, 0.99);
    r.ms_max = quantile(ms, 1.0);
    r.cpu_ms_median = quantile(cpu, 0.5);
    r.cpu_ms_p99 = quantile(cpu, 0.99);
    r.cpu_ms_max = quantile(cpu, 1.0);
  }

  // Every output file read back whole, the last frame written to its slot; nothing else there.
  for (const auto& [path, w] : written) {
    ++r.output_files;
    try {
      if (path.extension() == ".png") {
        const cv::Mat img = readImage(path, 1);
        if (img.cols != rig_main.camera.width || img.rows != rig_main.camera.height)
          throw Error("composite is " + std::to_string(img.cols) + "x" + std::to_string(img.rows), fileContext(path));
        if (fnv1a(readTextFile(path)) != w.hash)
          throw Error("not the bytes of frame " + std::to_string(w.frame) + ", the last written here", fileContext(path));
      } else {
        const ExrImage exr = readExr(path);
        const auto it = exr.attributes.find("previz:soak_frame");
        if (it == exr.attributes.end() || it->second != std::to_string(w.frame))
          throw Error("holds soak frame " + (it == exr.attributes.end() ? std::string("?") : it->second) +
                          ", the last written here was " + std::to_string(w.frame),
                      fileContext(path));
      }
      ++r.outputs_complete;
    } catch (const Error& e) {
      r.output_problems.push_back(e.what());
    }
  }
  for (const auto& e : fs::recursive_directory_iterator(frames_dir, ec))
    if (e.is_regular_file() && !written.count(e.path()))
      r.output_problems.push_back("left in the output folder: " + e.path().string());

  r.wall_s = t_start.seconds();
  writeJsonAtomic(o.out / "soak.json", r.toJson(true));
  writeSoakPlot(r, o.out / "soak.svg");
  return r;
}

void writeSoakPlot(const SoakReport& r, const fs::path& svg) {
  const double W = 960, H = 560, left = 70, right = 20, top = 40, gap = 50;
  const double ph = (H - top - gap - 40) / 2;  // each panel's height
  const int n = static_cast<int>(r.frame_log.size());
  std::ostringstream s;
  s << "<svg xmlns='http://www.w3.org/2000/svg' width='" << W << "' height='" << H << "' font-family='sans-serif' "
       "font-size='12'>\n<rect width='100%' height='100%' fill='white'/>\n";
  char t[256];
  std::snprintf(t, sizeof(t), "previz soak: %d frames (%s), %zu faults; RSS %+.2f %%, frame time median %.1f ms",
                r.frames_in, r.resolution.c_str(), r.faults.size(), 100 * r.rss_growth, r.ms_median);
  s << "<text x='" << left << "' y='20' font-size='14'>" << t << "</text>\n";
  auto x = [&](double frame) { return left + (W - left - right) * frame / std::max(1, n); };
  auto panel = [&](double y0, const std::string& label, auto value, double lo, double hi) {
    if (!(hi > lo)) hi = lo + 1;
    // Fault windows (faint) and failed frames (red ticks).
    for (const SoakFault& f : r.faults)
      s << "<rect x='" << x(f.first_frame) << "' y='" << y0 << "' width='" << std::max(1.0, x(f.end_frame) - x(f.first_frame))
        << "' height='" << ph << "' fill='" << (f.kind.rfind("tracker", 0) == 0 ? "#cce" : f.kind == "disk_full" ? "#ecc" : "#cec")
        << "' opacity='0.6'/>\n";
    for (const SoakFrame& f : r.frame_log)
      if (f.failed) s << "<line x1='" << x(f.frame) << "' x2='" << x(f.frame) << "' y1='" << y0 + ph - 6 << "' y2='" << y0 + ph
                      << "' stroke='red'/>\n";
    s << "<rect x='" << left << "' y='" << y0 << "' width='" << W - left - right << "' height='" << ph
      << "' fill='none' stroke='black'/>\n";
    // At most one point per pixel column: the column's largest value (spikes stay visible).
    const int cols = static_cast<int>(W - left - right);
    std::vector<double> col(cols, -1e300);
    for (const SoakFrame& f : r.frame_log) {
      const int c = std::min(cols - 1, static_cast<int>((x(f.frame) - left)));
      col[c] = std::max(col[c], value(f));
    }
    s << "<polyline fill='none' stroke='#036' stroke-width='1' points='";
    for (int c = 0; c < cols; ++c)
      if (col[c] > -1e300) s << left + c << "," << y0 + ph - ph * (std::min(hi, col[c]) - lo) / (hi - lo) << " ";
    s << "'/>\n";
    std::snprintf(t, sizeof(t), "%.1f", hi);
    s << "<text x='" << left - 6 << "' y='" << y0 + 10 << "' text-anchor='end'>" << t << "</text>\n";
    std::snprintf(t, sizeof(t), "%.1f", lo);
    s << "<text x='" << left - 6 << "' y='" << y0 + ph << "' text-anchor='end'>" << t << "</text>\n";
    s << "<text x='" << left + 6 << "' y='" << y0 + 14 << "'>" << label << "</text>\n";
  };
  double rss_lo = 1e300, rss_hi = 0;
  std::vector<double> ms;
  for (const SoakFrame& f : r.frame_log) {
    rss_lo = std::min(rss_lo, f.rss_mib);
    rss_hi = std::max(rss_hi, f.rss_mib);
    ms.push_back(f.ms);
  }
  if (n == 0) rss_lo = 0;
  panel(top, "RSS (MiB)", [](const SoakFrame& f) { return f.rss_mib; }, std::floor(rss_lo * 0.98), std::ceil(rss_hi * 1.02));
  const double ms_hi = std::max(1.0, 1.2 * quantile(ms, 1.0));
  panel(top + ph + gap, "frame time (ms): read + stages + write", [](const SoakFrame& f) { return f.ms; }, 0.0, ms_hi);
  s << "<text x='" << left << "' y='" << H - 12 << "'>frame 0</text><text x='" << W - right << "' y='" << H - 12
    << "' text-anchor='end'>frame " << n << "</text>\n";
  s << "<text x='" << W / 2 << "' y='" << H - 12
    << "' text-anchor='middle'>shaded: fault windows (green camera, blue tracker, red disk); red ticks: failed frames</text>\n";
  s << "</svg>\n";
  writeFileAtomic(svg, s.str());
}

}  // namespace previz::live
