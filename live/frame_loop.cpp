// The live frame's stages (live/frame_loop.h).
#include "live/frame_loop.h"

#include <omp.h>
#include <time.h>

#include <algorithm>
#include <cstdint>
#include <cmath>
#include <numeric>
#include <sstream>

#include <nlohmann/json.hpp>

#include "core/cpu_time.h"
#include "core/error.h"
#include "core/io.h"
#include "core/names.h"
#include "core/pose.h"
#include "core/stopwatch.h"
#include "core/threads.h"
#include "live/bin_light.h"

namespace previz::live {
namespace {

Error frameError(const std::string& stage, int frame, const std::exception& e) {
  ErrorContext c;
  if (const auto* pe = dynamic_cast<const Error*>(&e)) c = pe->context();
  c.frame = frame;
  const std::string what = dynamic_cast<const Error*>(&e) ? static_cast<const Error&>(e).message() : e.what();
  return Error(stage + " failed: " + what, c);
}

}  // namespace

void FrameLoopOptions::validate() const {
  hull.validate();
  keyer.validate();
  composite.validate();
  if (threads < 0) throw Error("run: threads must be >= 0", fieldContext("threads"));
  if (key_region_margin_px < 0)
    throw Error("run: key_region_margin_px must be >= 0 (got " + std::to_string(key_region_margin_px) + ")",
                fieldContext("key_region_margin_px"));
  if (witness_bin < 1 || witness_bin > 8)
    throw Error("run: witness_bin must be in [1, 8] (got " + std::to_string(witness_bin) + ")",
                fieldContext("witness_bin"));
}

struct FrameLoop::Impl {
  FrameLoopOptions options;
  std::vector<std::string> carve_names;
  std::string main_name;
  std::vector<carving::Keyer> keyers;  // carving cameras, then main
  // witness_bin > 1: each carving camera's plate size (the rig's) and its binned size (the
  // scaled camera's), and the binned plate, reused frame after frame.
  std::vector<cv::Size> plate_sizes, binned_sizes;
  std::vector<cv::Mat> binned;
  std::unique_ptr<carving::Carver> carver;
  std::unique_ptr<composite::Compositor> compositor;
  std::vector<std::pair<std::string, StageFn>> stages;
  composite::CompositeResult result;  // images reused frame after frame
  carving::KeyResult main_key;        // likewise (the main camera's 2 Mpx: no allocation per frame)
  std::vector<carving::KeyResult> witness_keys;
  cv::Mat foreground;
  cv::Mat main_depth;                 // likewise
  std::optional<int> last_frame;      // the last frame keyed (region keying needs consecutive ones)
  // Work pooled with the key stage (FrameLoop::poolWithKey), each with its items' time a pixel
  // as measured (thread CPU ms, averaged over the last frames; the first guess is libapriltag's
  // on a witness's regions, bench_tracking).
  struct Pooled {
    PooledWork work;
    double ms_per_px = 30e-6;
  };
  std::vector<Pooled> pooled;
  std::vector<double> key_ms;         // each camera's last key (thread CPU ms; < 0: none yet)
  // This frame's share of the key stage's time owed to each pooled work's stage (the fraction
  // of the pool's CPU time its items took), added to that stage's time by run().
  std::vector<double> pooled_share;

  int threads() const { return resolveThreads(options.threads); }

  void key(FrameState& s) {
    const int n = static_cast<int>(carve_names.size());
    s.silhouettes.assign(n, cv::Mat());
    if (s.dropped.size() != static_cast<size_t>(n)) s.dropped.assign(n, "");
    if (s.witness_plates.size() != static_cast<size_t>(n))
      throw Error("key: expected " + std::to_string(n) + " witness plates (got " +
                  std::to_string(s.witness_plates.size()) + ")");
    std::vector<std::string> errors(n + 1);
    // A gap or a seek: the last frame's silhouettes say nothing about this one's.
    if (!last_frame || s.frame != *last_frame + 1)
      for (carving::Keyer& k : keyers) k.resetRegion();
    last_frame = s.frame;
    // The pool's items: every camera's key (index n: the main camera) and the pooled work's,
    // each with its expected time, run longest first with dynamic scheduling so that the threads
    // finish together (a witness's key is 1-4 ms on the bench take, the main camera's 8, a tag
    // search of a witness's regions under 1, of a whole frame 18-40). No exception leaves the
    // region (STYLE.md rule 11).
    struct Item {
      int work;   // -1: a camera's key, else the index into 'pooled'
      int index;  // the camera, or the work's item
      long long px;
      double expected_ms;
    };
    std::vector<Item> items;
    for (int i = 0; i <= n; ++i) {
      const cv::Mat& plate = i < n ? s.witness_plates[i] : s.main_plate;
      // Not keyed yet: about 4 ns a plate pixel, the main camera's twice (soft alpha, despill).
      const double guess = 4e-6 * static_cast<double>(plate.total()) * (i < n ? 1 : 2);
      items.push_back({-1, i, 0, key_ms[i] >= 0 ? key_ms[i] : guess});
    }
    for (size_t w = 0; w < pooled.size(); ++w) {
      std::vector<long long> px;
      try {
        px = pooled[w].work.plan(s);
      } catch (const std::exception& e) {
        throw Error(pooled[w].work.stage + ": " + e.what());
      }
      for (size_t i = 0; i < px.size(); ++i)
        if (px[i] > 0)
          items.push_back({static_cast<int>(w), static_cast<int>(i), px[i], pooled[w].ms_per_px * px[i]});
    }
    std::stable_sort(items.begin(), items.end(),
                     [](const Item& a, const Item& b) { return a.expected_ms > b.expected_ms; });
    std::vector<double> cpu_ms(items.size(), 0.0);
    std::vector<std::string> work_errors(pooled.size());
#pragma omp parallel for schedule(dynamic) num_threads(threads())
    for (int t = 0; t < static_cast<int>(items.size()); ++t) {
      const Item& item = items[t];
      const double cpu0 = threadCpuMs();
      if (item.work >= 0) {
        try {
          pooled[item.work].work.item(item.index);
        } catch (const std::exception& e) {
#pragma omp critical(previz_pooled_errors)
          work_errors[item.work] = e.what();
        }
        cpu_ms[t] = threadCpuMs() - cpu0;
        continue;
      }
      const int i = item.index;
      try {
        if (i < n) {
          if (!s.dropped[i].empty() || s.witness_plates[i].empty()) {
            if (s.dropped[i].empty()) s.dropped[i] = "no frame";
            keyers[i].resetRegion();
            continue;
          }
          keyers[i].key(witnessPlate(s, i), carve_names[i], witness_keys[i]);
          s.silhouettes[i] = witness_keys[i].silhouette;
        } else {
          keyers[n].key(s.main_plate, main_name, main_key);
          carving::despill(s.main_plate, main_key, keyers[n].screen(), keyers[n].options(), foreground);
          s.main_key = main_key;
          s.foreground = foreground;
        }
      } catch (const std::exception& e) {
        errors[i] = e.what();
      }
      cpu_ms[t] = threadCpuMs() - cpu0;
    }
    // What each item took teaches the next frame's order; the CPU time shares the stage's time.
    double key_cpu = 0;
    std::vector<double> work_cpu(pooled.size(), 0.0);
    std::vector<long long> work_px(pooled.size(), 0);
    for (size_t t = 0; t < items.size(); ++t) {
      if (items[t].work < 0) {
        key_ms[items[t].index] = cpu_ms[t];
        key_cpu += cpu_ms[t];
      } else {
        work_cpu[items[t].work] += cpu_ms[t];
        work_px[items[t].work] += items[t].px;
      }
    }
    const double pool_cpu = key_cpu + std::accumulate(work_cpu.begin(), work_cpu.end(), 0.0);
    pooled_share.assign(pooled.size(), 0.0);
    for (size_t w = 0; w < pooled.size(); ++w) {
      if (work_px[w] > 0) pooled[w].ms_per_px = 0.5 * pooled[w].ms_per_px + 0.5 * work_cpu[w] / work_px[w];
      if (pool_cpu > 0) pooled_share[w] = work_cpu[w] / pool_cpu;
      if (!work_errors[w].empty()) throw Error(pooled[w].work.stage + ": " + work_errors[w]);
    }
    for (int i = 0; i < n; ++i)
      if (!errors[i].empty()) s.dropped[i] = "keying failed: " + errors[i];
    if (!errors[n].empty()) {
      ErrorContext c;
      c.camera = main_name;
      throw Error("keying the main plate failed: " + errors[n], c);
    }
  }

  // The plate keyed for carving camera i: the frame itself, or binned to the scaled camera. A
  // plate of another size than the rig's is an error (resizing would hide it).
  const cv::Mat& witnessPlate(const FrameState& s, int i) {
    const cv::Mat& plate = s.witness_plates[i];
    if (options.witness_bin == 1) return plate;
    if (plate.size() != plate_sizes[i])
      throw Error("plate is " + std::to_string(plate.cols) + "x" + std::to_string(plate.rows) + " but the camera is " +
                  std::to_string(plate_sizes[i].width) + "x" + std::to_string(plate_sizes[i].height));
    binLight(plate, options.witness_bin, binned_sizes[i], binned[i]);
    return binned[i];
  }

  void carve(FrameState& s) {
    // Fewer usable witnesses than the hull needs: the frame fails (an empty hull would put the
    // whole actor in front of the CG without a word).
    int usable = 0;
    std::string why;
    for (size_t i = 0; i < s.dropped.size(); ++i) {
      if (s.dropped[i].empty()) ++usable;
      else why += (why.empty() ? "" : "; ") + carve_names[i] + ": " + s.dropped[i];
    }
    if (usable < options.hull.min_views)
      throw Error("only " + std::to_string(usable) + " of " + std::to_string(s.dropped.size()) +
                  " witnesses usable, the hull needs " + std::to_string(options.hull.min_views) +
                  (why.empty() ? std::string() : " (" + why + ")"));
    carving::Silhouettes sil;
    sil.masks = s.silhouettes;
    sil.dropped = s.dropped;
    s.hull = carver->carve(sil);
  }

  void depth(FrameState& s) {
    carver->depth(s.hull, s.main, s.main_key.silhouette, main_depth);
    s.main_depth = main_depth;
  }

  void compose(FrameState& s) {
    compositor->setLens(s.main.camera);
    composite::CompositeInputs in;
    in.foreground = s.foreground;
    in.alpha = s.main_key.alpha;
    in.actor_depth = s.main_depth;
    in.cg_color = s.cg.color;
    in.cg_depth = s.cg.depth;
    compositor->composite(in, result, options.debug_layers, "frame " + std::to_string(s.frame));
    s.composite = result;
  }
};

FrameLoop::FrameLoop(const Rig& rig, const Camera& cg, const FrameLoopOptions& options)
    : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.options = options;
  m.options.validate();
  if (!options.main_camera.empty()) {
    rig.at(options.main_camera);
    m.main_name = options.main_camera;
  } else {
    for (const RigCamera& rc : rig.cameras)
      if (rc.role == kMainRole) m.main_name = rc.camera.name;
    if (m.main_name.empty()) throw Error("run: the rig has no camera with role 'main'", fieldContext("main_camera"));
  }
  std::vector<RigCamera> carve_cams;
  if (options.carve_cameras.empty()) {
    for (const RigCamera& rc : rig.cameras)
      if (rc.role == "witness" && rc.camera.name != m.main_name) m.carve_names.push_back(rc.camera.name);
  } else {
    m.carve_names = options.carve_cameras;
  }
  for (const std::string& name : m.carve_names) carve_cams.push_back(rig.at(name));
  if (carve_cams.size() < 2)
    throw Error("run: at least 2 carving cameras are needed (got " + std::to_string(carve_cams.size()) + ")",
                fieldContext("carve_cameras"));
  carving::KeyerOptions witness_key = options.keyer;
  witness_key.soft_alpha = false;  // carving needs the silhouette only
  witness_key.threads = 1;         // cameras are keyed in parallel
  witness_key.region_margin_px = (options.key_region_margin_px + options.witness_bin - 1) / options.witness_bin;
  if (const int bin = options.witness_bin; bin > 1) {
    const int area = bin * bin;
    witness_key.min_blob_px = std::max(1, witness_key.min_blob_px / area);
    witness_key.min_hole_px = std::max(1, witness_key.min_hole_px / area);
    for (RigCamera& rc : carve_cams) {
      m.plate_sizes.emplace_back(rc.camera.width, rc.camera.height);
      rc.camera = rc.camera.scaled(1.0 / bin, 1.0 / bin);
      m.binned_sizes.emplace_back(rc.camera.width, rc.camera.height);
    }
    m.binned.resize(carve_cams.size());
  }
  // Whole frames in turn: witness i's on frames i, i + every, ... (one witness a frame while
  // there are no more witnesses than 'every', 24 by default); the main camera's halfway between
  // the last witness's and the first's next.
  const int every = std::max(1, witness_key.region_full_every);
  const int n_carve = static_cast<int>(m.carve_names.size());
  for (int i = 0; i < n_carve; ++i) {
    witness_key.region_full_phase = (every - i % every) % every;
    m.keyers.emplace_back(witness_key);
  }
  m.witness_keys.resize(m.carve_names.size());
  m.key_ms.assign(m.carve_names.size() + 1, -1.0);
  carving::KeyerOptions main_key = options.keyer;
  main_key.soft_alpha = true;
  main_key.remember_garbage_zone = false;  // the main camera moves
  main_key.threads = 1;
  main_key.region_margin_px = options.key_main_region ? options.key_region_margin_px : 0;
  const int main_whole = n_carve < every ? (n_carve + every) / 2 : every / 2;
  main_key.region_full_phase = (every - main_whole % every) % every;
  m.keyers.emplace_back(main_key);
  carving::HullOptions hull = options.hull;
  hull.threads = options.threads;
  m.carver = std::make_unique<carving::Carver>(carve_cams, hull);
  composite::CompositeOptions co = options.composite;
  co.threads = options.threads;
  m.compositor = std::make_unique<composite::Compositor>(rig.at(m.main_name).camera, cg, co);
  m.stages = {{"key", [&m](FrameState& s) { m.key(s); }},
              {"carve", [&m](FrameState& s) { m.carve(s); }},
              {"depth", [&m](FrameState& s) { m.depth(s); }},
              {"composite", [&m](FrameState& s) { m.compose(s); }}};
}

FrameLoop::~FrameLoop() = default;

const std::vector<std::string>& FrameLoop::carveCameras() const { return impl_->carve_names; }
const std::string& FrameLoop::mainCamera() const { return impl_->main_name; }
const carving::Carver& FrameLoop::carver() const { return *impl_->carver; }
const composite::Compositor& FrameLoop::compositor() const { return *impl_->compositor; }

std::vector<std::string> FrameLoop::stages() const {
  std::vector<std::string> names;
  for (const auto& s : impl_->stages) names.push_back(s.first);
  return names;
}

void FrameLoop::insertStage(const std::string& after, const std::string& name, StageFn fn) {
  auto& st = impl_->stages;
  const auto it = std::find_if(st.begin(), st.end(), [&](const auto& s) { return s.first == after; });
  if (it == st.end()) throw Error("run: no stage '" + after + "' to insert '" + name + "' after", fieldContext("after"));
  st.insert(it + 1, {name, std::move(fn)});
}

void FrameLoop::poolWithKey(PooledWork work) {
  Impl& m = *impl_;
  const auto it = std::find_if(m.stages.begin(), m.stages.end(), [&](const auto& s) { return s.first == work.stage; });
  if (it == m.stages.end() || work.stage == "key")
    throw Error("run: no stage '" + work.stage + "' to pool work of with the key stage", fieldContext("stage"));
  if (m.options.pool_with_key) {
    m.pooled.push_back({std::move(work)});
    return;
  }
  // A pool of its own at the start of its stage.
  it->second = [work = std::move(work), stage = std::move(it->second), &m](FrameState& s) {
    const std::vector<long long> px = work.plan(s);
    std::vector<std::string> errors(px.size());
#pragma omp parallel for schedule(dynamic) num_threads(m.threads())
    for (int i = 0; i < static_cast<int>(px.size()); ++i) {
      if (px[i] <= 0) continue;
      try {
        work.item(i);
      } catch (const std::exception& e) {
        errors[i] = e.what();
      }
    }
    for (const std::string& e : errors)
      if (!e.empty()) throw Error(e);
    stage(s);
  };
}

std::vector<StageTime> FrameLoop::run(FrameState& state) {
  Impl& m = *impl_;
  std::vector<StageTime> times;
  m.pooled_share.assign(m.pooled.size(), 0.0);
  StageTime key_pool;  // the key stage's whole time, shared with the pooled work's stages
  for (auto& [name, fn] : m.stages) {
    const Stopwatch start;
    const double cpu0 = processCpuMs();
    try {
      fn(state);
    } catch (const std::exception& e) {
      throw frameError(name, state.frame, e);
    }
    StageTime t{name, start.ms(), processCpuMs() - cpu0};
    if (name == "key") {
      key_pool = t;
      for (const double f : m.pooled_share) {
        t.ms -= f * key_pool.ms;
        t.cpu_ms -= f * key_pool.cpu_ms;
      }
    }
    for (size_t w = 0; w < m.pooled.size(); ++w)
      if (name == m.pooled[w].work.stage) {
        t.ms += m.pooled_share[w] * key_pool.ms;
        t.cpu_ms += m.pooled_share[w] * key_pool.cpu_ms;
      }
    times.push_back(t);
  }
  return times;
}

void PropStageOptions::validate() const {
  tracker.validate();
  if (!(fps > 0) || !std::isfinite(fps)) throw Error("run: props fps must be > 0", fieldContext("fps"));
}

PropStage::PropStage(const FrameLoop& loop, const Rig& rig, tracking::PropSet props, const PropStageOptions& options)
    : options_(options) {
  options_.validate();
  std::vector<RigCamera> cams;
  for (const std::string& name : loop.carveCameras()) cams.push_back(rig.at(name));
  cams.push_back(rig.at(loop.mainCamera()));
  main_index_ = static_cast<int>(cams.size()) - 1;
  tracker_ = std::make_unique<tracking::PropTracker>(std::move(cams), std::move(props), options_.tracker);
}

PropStage::~PropStage() = default;

double PropStage::prepare(const FrameState& s) {
  const double t = s.frame / options_.fps;
  if (any_ && (t <= last_time_s_ || t - last_time_s_ > options_.tracker.filter.max_gap_s)) tracker_->reset();
  any_ = true;
  last_time_s_ = t;
  tracker_->setCameraPose(main_index_, s.main.T_world_cam);
  images_ = s.witness_plates;
  images_.push_back(s.main_plate);
  return t;
}

void PropStage::operator()(FrameState& s) {
  const double t = prepare(s);
  s.props = tracker_->track(s.frame, t, images_);
}

void PropStage::addTo(FrameLoop& loop) {
  loop.insertStage("depth", "props", [this](FrameState& s) { s.props = tracker_->finish(); });
  loop.poolWithKey({"props",
                    [this](FrameState& s) { return tracker_->begin(s.frame, prepare(s), images_); },
                    [this](int camera) { tracker_->search(camera); }});
}

}  // namespace previz::live
