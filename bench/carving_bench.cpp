// Carving benchmark (issue 5, item 4): one studio frame, 8 witnesses 1280x720 + main 1920x1080
// rendered by the synthetic studio (t = 4 s, 4 spp), then in this process: keying per camera,
// carving at 1 cm and 5 mm, main-view depth (hull, refined, photo hull), mesh extraction, and a
// dense-grid carve at the same 1 cm cell size (cell centres projected through each camera's true
// lens into its silhouette, early exit on the first camera that carves: the plain visual-hull
// loop, as cheap per cell as it gets). Carving and depth use the renderer's true masks (pixel-centre ray hits the actor),
// so that their figures do not move with the keyer's; the keyer is timed on the rendered plates
// and its silhouettes' IoU against the true foreground (actor and props: the keyer keys both) is
// printed, also on the witness plates with sensor noise added (sigma 2 grey levels).
// Rigs of 8 to 128 witnesses (3_carve_cameras_N, 4_depth_cameras_N): analytic silhouettes of a
// figure of capsules, so that the cost's growth with the camera count is measured apart from
// the renderer's.
// Besides Google Benchmark's table, one JSON line per stage:
//   {"stage":..., "size":..., "ms":..., "budget_ms":..., "ratio_vs_dense":...}
// "ms" is the median wall time of the runs, "ms_min" the fastest; "cpu_ms" the median CPU time of
// the process (all threads): on a shared machine wall time also measures the other jobs.
#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <string>
#include <thread>
#include <vector>

#include "carving/hull.h"
#include "carving/keyer.h"
#include "carving/refine.h"
#include "core/cpu_time.h"
#include "core/lens_model.h"
#include "core/names.h"
#include "core/pose.h"
#include "core/threads.h"
#include "datasets/render.h"
#include "datasets/rigs.h"
#include "datasets/studio.h"

namespace {

using namespace previz;
using namespace previz::carving;
using namespace previz::synth;

constexpr double kTime = 4.0;  // mid-take: the actor walks on stage

double nowMs() {
  return std::chrono::duration<double, std::milli>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}
// CPU time of the whole process (every thread): on a shared machine wall time measures the
// other jobs as much as this code; CPU time / threads is what an idle 2-core machine would take
// if the stage scaled perfectly.
struct Stopwatch {
  double wall = nowMs(), cpu = previz::processCpuMs();
  double wallMs() const { return nowMs() - wall; }
  double cpuMsSince() const { return previz::processCpuMs() - cpu; }
};

struct Frame {
  std::vector<RigCamera> witnesses;
  RigCamera main;
  std::vector<cv::Mat> plates, truth_masks;  // witnesses; masks: the actor (what carving uses)
  std::vector<cv::Mat> truth_foreground;      // the keyer's reference: actor and props
  cv::Mat main_plate, main_truth;
};

const Frame& frame() {
  static const Frame f = [] {
    Frame fr;
    const StudioConfig config;
    const Studio studio(config);
    const Rig rig = studioRig(StudioRigOptions{}, config.take_duration_s, true);
    const Scene scene = studio.sceneAt(kTime, kLayersPlate);
    RenderOptions ro;
    ro.samples_per_pixel = 4;
    for (const RigCamera& rc : rig.cameras) {
      RigCamera c = rc;
      if (c.role == kMainRole) c.T_world_cam = mainCameraPose(kTime, config.take_duration_s, true);
      const RenderedView view = renderView(c.camera, c.T_world_cam, scene, ro);
      if (c.role == kMainRole) {
        fr.main = c;
        fr.main_plate = view.bgr;
        fr.main_truth = view.mask;
      } else {
        fr.witnesses.push_back(c);
        fr.plates.push_back(view.bgr);
        fr.truth_masks.push_back(view.mask);
        fr.truth_foreground.push_back((view.labels == static_cast<int>(ObjectClass::kActor)) |
                                      (view.labels == static_cast<int>(ObjectClass::kProp)));
      }
    }
    return fr;
  }();
  return f;
}

struct Result {
  std::string stage, size, extra;
  std::vector<double> ms, cpu_ms;
  double budget_ms = -1;  // < 0: none
  int threads = 1;
};
std::map<std::string, Result>& results() {
  static std::map<std::string, Result> r;
  return r;
}
void record(const std::string& key, const std::string& stage, const std::string& size,
            const Stopwatch& sw, double budget_ms, int threads, const std::string& extra = {}) {
  const double ms = sw.wallMs(), cpu_ms = sw.cpuMsSince();
  Result& r = results()[key];
  r.threads = threads;
  r.stage = stage;
  r.size = size;
  r.budget_ms = budget_ms;
  r.extra = extra;
  r.ms.push_back(ms);
  r.cpu_ms.push_back(cpu_ms);
}
double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0 : v[v.size() / 2];
}

// The same witness plates with sensor noise (Gaussian, sigma 2 grey levels, fixed seed, added to
// the 8-bit codes as the studio renderer adds it): a camera's footage, where the first pass
// leaves more pixels unknown (dark costume parts, the dark surroundings) than on clean renders.
const std::vector<cv::Mat>& noisyPlates() {
  static const std::vector<cv::Mat> noisy = [] {
    std::vector<cv::Mat> out;
    cv::RNG rng(20261204);
    for (const cv::Mat& p : frame().plates) {
      cv::Mat n(p.size(), CV_32FC3), q;
      rng.fill(n, cv::RNG::NORMAL, 0.0, 2.0);
      p.convertTo(q, CV_32FC3);
      q += n;
      q.convertTo(q, CV_8UC3);  // rounds and saturates
      out.push_back(q);
    }
    return out;
  }();
  return noisy;
}

// Keyers per witness over one set of plates (the screen model is estimated on the first key and
// reused, as live), and that first key's silhouettes.
struct WitnessKeying {
  const std::vector<cv::Mat>* plates;
  std::vector<Keyer> keyers;
  std::vector<cv::Mat> silhouettes;
  WitnessKeying(const std::vector<cv::Mat>& p, int threads) : plates(&p) {
    KeyerOptions o;
    o.soft_alpha = false;  // carving needs the silhouette only
    o.threads = threads;
    const Frame& f = frame();
    for (size_t c = 0; c < p.size(); ++c) {
      keyers.emplace_back(o);
      silhouettes.push_back(keyers.back().key(p[c], f.witnesses[c].camera.name).silhouette);
    }
  }
};
// The rendered plates (noisy = false) or the same with sensor noise.
WitnessKeying& witnessKeying(bool noisy, int threads) {
  static std::map<std::pair<bool, int>, std::unique_ptr<WitnessKeying>> k;
  std::unique_ptr<WitnessKeying>& w = k[{noisy, threads}];
  if (!w) w = std::make_unique<WitnessKeying>(noisy ? noisyPlates() : frame().plates, threads);
  return *w;
}
Keyer& mainKeyer(int threads) {
  static std::map<int, std::unique_ptr<Keyer>> k;
  std::unique_ptr<Keyer>& m = k[threads];
  if (!m) {
    KeyerOptions o;
    o.remember_garbage_zone = false;  // the main camera moves on its dolly
    o.threads = threads;
    m = std::make_unique<Keyer>(o);
    m->key(frame().main_plate, kMainCamera);
  }
  return *m;
}

// Every stage runs with 1 thread and with the machine's threads (2 on the target). On a shared
// machine the 1-thread CPU time is the figure that does not move with the other jobs.
int benchThreads(const benchmark::State& state) {
  return state.range(1) > 0 ? static_cast<int>(state.range(1))
                            : coreCount();
}
std::string threadKey(int threads) { return "_t" + std::to_string(threads); }

double iou(const cv::Mat& a, const cv::Mat& b) {
  const double inter = cv::countNonZero(a & b), uni = cv::countNonZero(a | b);
  return uni > 0 ? inter / uni : 1.0;
}

// Keys every witness once per iteration, one record per camera.
void timeWitnessKeys(benchmark::State& state, bool noisy, const std::string& key, const std::string& stage,
                     const std::string& extra) {
  const Frame& f = frame();
  const int threads = benchThreads(state);
  WitnessKeying& k = witnessKeying(noisy, threads);
  for (auto _ : state) {
    for (size_t c = 0; c < k.keyers.size(); ++c) {
      const Stopwatch sw;
      KeyResult r = k.keyers[c].key((*k.plates)[c], f.witnesses[c].camera.name);
      record(key + threadKey(threads), stage, "1280x720", sw, 5.0 / 9, threads, extra);
      benchmark::DoNotOptimize(r.silhouette.data);
    }
  }
}
void BM_KeyWitness(benchmark::State& state) { timeWitnessKeys(state, false, "1_key_witness", "key_witness", ""); }
void BM_KeyWitnessNoisy(benchmark::State& state) {
  timeWitnessKeys(state, true, "1b_key_witness_noise2", "key_witness_noise2", "\"noise_sigma\":2");
}
void BM_KeyMain(benchmark::State& state) {
  const Frame& f = frame();
  const int threads = benchThreads(state);
  Keyer& main = mainKeyer(threads);
  for (auto _ : state) {
    const Stopwatch sw;
    KeyResult r = main.key(f.main_plate, kMainCamera);
    record("2_key_main" + threadKey(threads), "key_main", "1920x1080", sw, 5.0 / 9, threads);
    benchmark::DoNotOptimize(r.silhouette.data);
  }
}

// Each keying mode on one frame set of its own stage (green, blue, the set without a screen:
// datasets/studio.h Backdrop), sensor noise 2 on plates and frames, every camera keyed against
// its clean plate (the main camera's too: it stands still at this instant). One record per
// frame set: 8 witnesses (silhouette only) + the main camera (soft alpha), as the live loop keys.
struct BackdropFrame {
  std::vector<cv::Mat> frames;
  std::vector<Keyer> keyers;
};
BackdropFrame& backdropFrame(synth::Backdrop backdrop, int threads) {
  static std::map<std::pair<int, int>, std::unique_ptr<BackdropFrame>> cache;
  std::unique_ptr<BackdropFrame>& b = cache[{static_cast<int>(backdrop), threads}];
  if (b) return *b;
  b = std::make_unique<BackdropFrame>();
  StudioConfig config;
  config.backdrop = backdrop;
  const Studio studio(config);
  const Rig rig = studioRig(StudioRigOptions{}, config.take_duration_s, true);
  const Scene scene = studio.sceneAt(kTime, kLayersPlate), empty = studio.sceneAt(kTime, kLayerStage);
  RenderOptions ro;
  ro.samples_per_pixel = 4;
  ro.noise_sigma = 2.0;
  ro.truth = false;
  for (size_t i = 0; i < rig.cameras.size(); ++i) {
    RigCamera c = rig.cameras[i];
    if (c.role == kMainRole) c.T_world_cam = mainCameraPose(kTime, config.take_duration_s, true);
    ro.camera_index = static_cast<int>(i);
    ro.frame = 1;
    b->frames.push_back(renderView(c.camera, c.T_world_cam, scene, ro).bgr);
    KeyerOptions o;
    o.soft_alpha = c.role == kMainRole;
    o.remember_garbage_zone = c.role != kMainRole;
    o.threads = threads;
    b->keyers.emplace_back(o);
    ro.frame = 0;
    b->keyers.back().setCleanPlate(renderView(c.camera, c.T_world_cam, empty, ro).bgr, c.camera.name + " plate");
  }
  return *b;
}
void BM_KeyBackdrop(benchmark::State& state) {
  const auto backdrop = static_cast<synth::Backdrop>(state.range(0));
  const int threads = benchThreads(state);
  BackdropFrame& b = backdropFrame(backdrop, threads);
  const std::string mode = carving::toString(b.keyers.front().screen().backdrop);  // as the keyer chose it
  for (auto _ : state) {
    const Stopwatch sw;
    for (size_t c = 0; c < b.frames.size(); ++c) {
      KeyResult r = b.keyers[c].key(b.frames[c], "frame");
      benchmark::DoNotOptimize(r.silhouette.data);
    }
    record("1c_key_frameset_" + mode + threadKey(threads), "key_frameset_" + mode, "8x1280x720+1920x1080", sw,
           5.0, threads, "\"noise_sigma\":2,\"clean_plate\":true,\"backdrop\":\"" + mode + "\"");
  }
}

struct CarveCase {
  std::unique_ptr<Carver> carver;
  VisualHull hull;
};
CarveCase& carveCase(double voxel, int threads) {
  static std::map<std::pair<double, int>, CarveCase> cases;
  CarveCase& c = cases[{voxel, threads}];
  if (!c.carver) {
    HullOptions o;
    o.voxel_m = voxel;
    o.threads = threads;
    c.carver = std::make_unique<Carver>(frame().witnesses, o);
    Silhouettes s;
    s.masks = frame().truth_masks;
    c.hull = c.carver->carve(s);
    // First depth call builds the main lens' ray table (once per lens, not per frame).
    c.carver->depth(c.hull, frame().main, frame().main_truth);
  }
  return c;
}
std::string voxelLabel(double voxel) { return std::to_string(static_cast<int>(voxel * 1000 + 0.5)) + "mm"; }

void BM_Carve(benchmark::State& state) {
  const double voxel = state.range(0) / 1000.0;
  const int threads = benchThreads(state);
  CarveCase& c = carveCase(voxel, threads);
  Silhouettes s;
  s.masks = frame().truth_masks;
  for (auto _ : state) {
    const Stopwatch sw;
    c.hull = c.carver->carve(s);
    char extra[160];
    std::snprintf(extra, sizeof extra, "\"voxel_m\":%.3f,\"surface_cells\":%lld,\"inside_cells\":%lld",
                  voxel, c.hull.stats.surface_cells, c.hull.stats.inside_cells);
    record("3_carve_" + voxelLabel(voxel) + threadKey(threads), "carve",
           "8x1280x720@" + voxelLabel(voxel), sw, 5.0, threads, extra);
  }
}
void BM_Depth(benchmark::State& state) {
  const double voxel = state.range(0) / 1000.0;
  const int threads = benchThreads(state);
  CarveCase& c = carveCase(voxel, threads);
  for (auto _ : state) {
    const Stopwatch sw;
    cv::Mat d = c.carver->depth(c.hull, frame().main, frame().main_truth);
    char extra[96];
    std::snprintf(extra, sizeof extra, "\"voxel_m\":%.3f,\"pixels\":%d", voxel,
                  cv::countNonZero(frame().main_truth));
    record("4_depth_" + voxelLabel(voxel) + threadKey(threads), "main_depth",
           "1920x1080@" + voxelLabel(voxel), sw, 5.0, threads, extra);
    benchmark::DoNotOptimize(d.data);
  }
}
// Depth beyond the hull (refine.h) on the same frame: the plates (every gain 1 in this render),
// the hull depth of BM_Depth; includes the witnesses' quarter-size visibility maps. The first
// call (ray tables of those quarter-size lenses, once per lens) is left out.
// What both refinements start from: the frame's carve, its hull depth and its plates.
struct RefineInput {
  CarveCase& c;
  const Frame& f;
  cv::Mat hull_depth;
  std::vector<Plate> plates;
  Plate main;
};
RefineInput refineInput(double voxel, int threads) {
  CarveCase& c = carveCase(voxel, threads);
  const Frame& f = frame();
  RefineInput in{c, f, c.carver->depth(c.hull, f.main, f.main_truth), {}, Plate{f.main_plate, 1.0}};
  for (const cv::Mat& p : f.plates) in.plates.push_back(Plate{p, 1.0});
  return in;
}
void BM_RefineDepth(benchmark::State& state) {
  const double voxel = state.range(0) / 1000.0;
  const int threads = benchThreads(state);
  const RefineInput in = refineInput(voxel, threads);
  RefineOptions o;
  o.threads = threads;
  refineDepth(*in.c.carver, in.c.hull, in.f.main, in.main, in.hull_depth, in.plates,
              in.f.truth_masks, o);
  for (auto _ : state) {
    const Stopwatch sw;
    RefineStats stats;
    cv::Mat d = refineDepth(*in.c.carver, in.c.hull, in.f.main, in.main, in.hull_depth, in.plates,
                            in.f.truth_masks, o, &stats);
    char extra[128];
    std::snprintf(extra, sizeof extra, "\"voxel_m\":%.3f,\"pixels\":%lld,\"inconsistent\":%lld,\"moved\":%lld",
                  voxel, stats.pixels, stats.inconsistent, stats.moved);
    record("4r_refine_" + voxelLabel(voxel) + threadKey(threads), "main_depth_refined",
           "1920x1080@" + voxelLabel(voxel), sw, -1, threads, extra);
    benchmark::DoNotOptimize(d.data);
  }
}
// What `previz carve --refine` runs: the photo hull (every witness refined too, then free space).
void BM_PhotoHull(benchmark::State& state) {
  const double voxel = state.range(0) / 1000.0;
  const int threads = benchThreads(state);
  const RefineInput in = refineInput(voxel, threads);
  PhotoHullOptions o;
  o.refine.threads = threads;
  photoHullDepth(*in.c.carver, in.c.hull, in.f.main, in.main, in.hull_depth, in.plates,
                 in.f.truth_masks, o);  // warm: the witnesses' ray tables
  for (auto _ : state) {
    const Stopwatch sw;
    PhotoHullStats stats;
    cv::Mat d = photoHullDepth(*in.c.carver, in.c.hull, in.f.main, in.main, in.hull_depth,
                               in.plates, in.f.truth_masks, o, &stats);
    char extra[160];
    std::snprintf(extra, sizeof extra,
                  "\"voxel_m\":%.3f,\"pixels\":%lld,\"moved\":%lld,\"free_space\":%lld,"
                  "\"edge_moved\":%lld,\"witness_ms\":%.1f",
                  voxel, stats.depth.pixels, stats.depth.moved, stats.free_space, stats.edge_moved,
                  stats.witness_ms);
    record("4s_photo_hull_" + voxelLabel(voxel) + threadKey(threads), "main_depth_photo_hull",
           "1920x1080+8x1280x720@" + voxelLabel(voxel), sw, -1, threads, extra);
    benchmark::DoNotOptimize(d.data);
  }
}
void BM_Mesh(benchmark::State& state) {
  const double voxel = state.range(0) / 1000.0;
  const int threads = benchThreads(state);
  CarveCase& c = carveCase(voxel, threads);
  for (auto _ : state) {
    const Stopwatch sw;
    TriangleMesh m = c.carver->mesh(c.hull);
    char extra[96];
    std::snprintf(extra, sizeof extra, "\"voxel_m\":%.3f,\"vertices\":%zu,\"faces\":%zu", voxel,
                  m.vertices.size(), m.faces.size());
    record("5_mesh_" + voxelLabel(voxel) + threadKey(threads), "mesh", "hull@" + voxelLabel(voxel),
           sw, -1, threads, extra);
  }
}

// ---------------------------------------------------------------------------------------------
// Rigs of any size: volumetric stages run 50-100+ witnesses. Rendering 128 studio views would
// take minutes, so these rigs see a figure of capsules (a standing actor's size and limbs) with
// analytic silhouettes: a pixel is inside when its centre's ray passes within a capsule's
// radius of its axis.
// ---------------------------------------------------------------------------------------------
struct Capsule {
  Eigen::Vector3d a, b;
  double radius;
};
const std::vector<Capsule>& figure() {
  static const std::vector<Capsule> f = {
      {{0.0, 0.0, 0.95}, {0.0, 0.0, 1.40}, 0.17},    // torso
      {{0.0, 0.0, 1.60}, {0.0, 0.02, 1.66}, 0.11},   // head
      {{-0.10, 0.0, 0.05}, {-0.10, 0.05, 0.90}, 0.07},  // legs
      {{0.10, 0.0, 0.05}, {0.12, -0.08, 0.90}, 0.07},
      {{-0.22, 0.0, 1.40}, {-0.45, 0.12, 0.95}, 0.05},  // arms
      {{0.22, 0.0, 1.40}, {0.40, -0.20, 1.10}, 0.05},
  };
  return f;
}
const Eigen::AlignedBox3d kFigureBounds(Eigen::Vector3d(-0.55, -0.35, -0.05),
                                        Eigen::Vector3d(0.55, 0.35, 1.80));

// Squared distance from the ray o + t d (t >= 0, |d| = 1) to the segment [a, b]: the closest
// point of the segment to the ray's line, then the ray's point nearest to it (exact when the
// ray starts outside the capsule, as a camera does).
double raySegmentDistance2(const Eigen::Vector3d& o, const Eigen::Vector3d& d,
                           const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  const Eigen::Vector3d e = b - a, w = a - o;
  const double de = d.dot(e), ee = e.dot(e), dw = d.dot(w), ew = e.dot(w);
  const double den = ee - de * de;
  double s = den > 1e-12 ? std::clamp((de * dw - ew) / den, 0.0, 1.0) : 0.0;
  const double t = std::max(0.0, dw + s * de);
  s = std::clamp((t * de - ew) / ee, 0.0, 1.0);
  return (o + t * d - (a + s * e)).squaredNorm();
}

cv::Mat figureSilhouette(const RigCamera& rc) {
  const Camera& cam = rc.camera;
  const Pose T_cam_world = rc.T_world_cam.inverse();
  // Only the pixels of the figure's bounding box (every corner is in front of these cameras).
  double umin = cam.width, umax = 0, vmin = cam.height, vmax = 0;
  for (int c = 0; c < 8; ++c) {
    const Eigen::Vector3d p =
        T_cam_world * kFigureBounds.corner(static_cast<Eigen::AlignedBox3d::CornerType>(c));
    umin = std::min(umin, cam.fx * p.x() / p.z() + cam.cx);
    umax = std::max(umax, cam.fx * p.x() / p.z() + cam.cx);
    vmin = std::min(vmin, cam.fy * p.y() / p.z() + cam.cy);
    vmax = std::max(vmax, cam.fy * p.y() / p.z() + cam.cy);
  }
  cv::Mat mask = cv::Mat::zeros(cam.height, cam.width, CV_8UC1);
  const Eigen::Vector3d o = rc.T_world_cam.translation();
  const Eigen::Matrix3d R = rc.T_world_cam.linear();
  const int u0 = std::max(0, static_cast<int>(umin));
  const int u1 = std::min(cam.width - 1, static_cast<int>(umax) + 1);
  const int v0 = std::max(0, static_cast<int>(vmin));
  const int v1 = std::min(cam.height - 1, static_cast<int>(vmax) + 1);
  for (int v = v0; v <= v1; ++v)
    for (int u = u0; u <= u1; ++u) {
      const Eigen::Vector3d d =
          (R * Eigen::Vector3d((u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, 1.0)).normalized();
      for (const Capsule& k : figure())
        if (raySegmentDistance2(o, d, k.a, k.b) <= k.radius * k.radius) {
          mask.at<std::uint8_t>(v, u) = 255;
          break;
        }
    }
  return mask;
}

// n witnesses 1280x720 (ideal lenses, ~65 degrees across) 4 m from the stage centre, at
// heights 0.5-3 m, azimuths by the golden angle: rings as a volumetric stage has them.
std::vector<RigCamera> witnessRings(int n) {
  std::vector<RigCamera> rig(n);
  const double golden_angle = M_PI * (3.0 - std::sqrt(5.0));
  for (int i = 0; i < n; ++i) {
    Camera& cam = rig[i].camera;
    cam.name = "ring" + std::to_string(i);
    cam.width = 1280;
    cam.height = 720;
    cam.fx = cam.fy = 1000;
    cam.cx = 639.5;
    cam.cy = 359.5;
    const double z = 0.5 + 2.5 * (i + 0.5) / n;
    rig[i].T_world_cam = lookAt(Eigen::Vector3d(4.0 * std::cos(golden_angle * i),
                                                4.0 * std::sin(golden_angle * i), z),
                                Eigen::Vector3d(0, 0, 1.0));
  }
  return rig;
}

struct RingCase {
  std::vector<RigCamera> witnesses;
  Silhouettes silhouettes;
  RigCamera main;  // 1920x1080 in front of the figure
  cv::Mat main_mask;
  std::unique_ptr<Carver> carver;
  VisualHull hull;
};
RingCase& ringCase(int cameras, int threads) {
  static std::map<std::pair<int, int>, RingCase> cases;
  RingCase& c = cases[{cameras, threads}];
  if (!c.carver) {
    c.witnesses = witnessRings(cameras);
    c.silhouettes.masks.resize(cameras);
    std::vector<std::thread> pool;
    const int workers = coreCount();
    for (int th = 0; th < workers; ++th)
      pool.emplace_back([&, th] {
        for (int i = th; i < cameras; i += workers)
          c.silhouettes.masks[i] = figureSilhouette(c.witnesses[i]);
      });
    for (auto& t : pool) t.join();
    c.main.camera = c.witnesses[0].camera;
    c.main.camera.name = kMainCamera;
    c.main.camera.width = 1920;
    c.main.camera.height = 1080;
    c.main.camera.fx = c.main.camera.fy = 1500;
    c.main.camera.cx = 959.5;
    c.main.camera.cy = 539.5;
    c.main.T_world_cam = lookAt(Eigen::Vector3d(0.8, -5.0, 1.6), Eigen::Vector3d(0, 0, 1.0));
    c.main_mask = figureSilhouette(c.main);
    HullOptions o;  // 5 mm, the live setting
    o.threads = threads;
    c.carver = std::make_unique<Carver>(c.witnesses, o);
    c.hull = c.carver->carve(c.silhouettes);
    c.carver->depth(c.hull, c.main, c.main_mask);  // the main lens' ray table, once per lens
  }
  return c;
}

void BM_CarveCameras(benchmark::State& state) {
  const int cameras = static_cast<int>(state.range(0));
  const int threads = benchThreads(state);
  RingCase& c = ringCase(cameras, threads);
  for (auto _ : state) {
    const Stopwatch sw;
    c.hull = c.carver->carve(c.silhouettes);
    char extra[160];
    std::snprintf(extra, sizeof extra,
                  "\"cameras\":%d,\"voxel_m\":0.005,\"surface_cells\":%lld,\"inside_cells\":%lld",
                  cameras, c.hull.stats.surface_cells, c.hull.stats.inside_cells);
    record("3_carve_cameras_" + std::to_string(cameras) + threadKey(threads), "carve",
           std::to_string(cameras) + "x1280x720@5mm", sw, -1, threads, extra);
  }
}
void BM_DepthCameras(benchmark::State& state) {
  const int cameras = static_cast<int>(state.range(0));
  const int threads = benchThreads(state);
  RingCase& c = ringCase(cameras, threads);
  for (auto _ : state) {
    const Stopwatch sw;
    cv::Mat d = c.carver->depth(c.hull, c.main, c.main_mask);
    char extra[96];
    std::snprintf(extra, sizeof extra, "\"cameras\":%d,\"voxel_m\":0.005,\"pixels\":%d",
                  cameras, cv::countNonZero(c.main_mask));
    record("4_depth_cameras_" + std::to_string(cameras) + threadKey(threads), "main_depth",
           "1920x1080@5mm+" + std::to_string(cameras) + "x1280x720", sw, -1, threads, extra);
    benchmark::DoNotOptimize(d.data);
  }
}

// The dense reference: every cell centre of the grid, projected into every camera until one
// carves it (k = 0, at least 2 views), occupancy written to a byte grid.
struct DenseCamera {
  double R[9], t[3], fx, fy, cx, cy, skew, k1, k2, p1, p2, k3, k4, k5, k6;
  int w, h;
  const cv::Mat* mask;
};
long long denseCarve(const std::vector<DenseCamera>& cams, double voxel, int threads,
                     std::vector<std::uint8_t>& occupancy) {
  const HullOptions o;  // the same volume
  const Eigen::Vector3d lo = o.volume.min(), size = o.volume.sizes();
  const int nx = static_cast<int>(std::ceil(size.x() / voxel - 1e-9));
  const int ny = static_cast<int>(std::ceil(size.y() / voxel - 1e-9));
  const int nz = static_cast<int>(std::ceil(size.z() / voxel - 1e-9));
  occupancy.resize(static_cast<size_t>(nx) * ny * nz);
  std::vector<long long> kept(threads, 0);
  std::vector<std::thread> pool;
  for (int th = 0; th < threads; ++th)
    pool.emplace_back([&, th] {
      for (int z = th; z < nz; z += threads)
        for (int y = 0; y < ny; ++y)
          for (int x = 0; x < nx; ++x) {
            const double p[3] = {lo.x() + (x + 0.5) * voxel, lo.y() + (y + 0.5) * voxel,
                                 lo.z() + (z + 0.5) * voxel};
            int views = 0;
            bool in = true;
            for (const DenseCamera& c : cams) {
              const double qz = c.R[6] * p[0] + c.R[7] * p[1] + c.R[8] * p[2] + c.t[2];
              if (qz <= 1e-3) continue;
              const double xn = (c.R[0] * p[0] + c.R[1] * p[1] + c.R[2] * p[2] + c.t[0]) / qz;
              const double yn = (c.R[3] * p[0] + c.R[4] * p[1] + c.R[5] * p[2] + c.t[1]) / qz;
              const double r2 = xn * xn + yn * yn;
              if (r2 > 2.0) continue;  // far outside every studio lens' view
              double xd, yd;
              lens::brownDistort(c.k1, c.k2, c.p1, c.p2, c.k3, c.k4, c.k5, c.k6, xn, yn, xd, yd);
              const int u = static_cast<int>(c.fx * xd + c.skew * yd + c.cx + 0.5 + 1e6) - 1000000;
              const int v = static_cast<int>(c.fy * yd + c.cy + 0.5 + 1e6) - 1000000;
              if (u < 0 || v < 0 || u >= c.w || v >= c.h) continue;
              ++views;
              if (c.mask->ptr<std::uint8_t>(v)[u] <= 127) {
                in = false;
                break;
              }
            }
            const bool keep = in && views >= 2;
            occupancy[(static_cast<size_t>(z) * ny + y) * nx + x] = keep;
            kept[th] += keep;
          }
    });
  for (auto& t : pool) t.join();
  long long total = 0;
  for (long long k : kept) total += k;
  return total;
}

void BM_DenseCarve(benchmark::State& state) {
  const double voxel = state.range(0) / 1000.0;
  const int threads = benchThreads(state);
  const Frame& f = frame();
  std::vector<DenseCamera> cams;
  for (size_t i = 0; i < f.witnesses.size(); ++i) {
    const Camera& c = f.witnesses[i].camera;
    const Pose T = f.witnesses[i].T_world_cam.inverse();
    DenseCamera d;
    for (int r = 0; r < 3; ++r) {
      for (int col = 0; col < 3; ++col) d.R[r * 3 + col] = T.linear()(r, col);
      d.t[r] = T.translation()[r];
    }
    d.fx = c.fx, d.fy = c.fy, d.cx = c.cx, d.cy = c.cy, d.skew = c.skew;
    d.k1 = c.dist.k1, d.k2 = c.dist.k2, d.p1 = c.dist.p1, d.p2 = c.dist.p2, d.k3 = c.dist.k3;
    d.k4 = c.dist.k4, d.k5 = c.dist.k5, d.k6 = c.dist.k6;
    d.w = c.width, d.h = c.height;
    d.mask = &f.truth_masks[i];
    cams.push_back(d);
  }
  std::vector<std::uint8_t> occupancy;
  for (auto _ : state) {
    const Stopwatch sw;
    const long long kept = denseCarve(cams, voxel, threads, occupancy);
    char extra[96];
    std::snprintf(extra, sizeof extra, "\"voxel_m\":%.3f,\"cells\":%zu,\"kept\":%lld", voxel,
                  occupancy.size(), kept);
    record("6_dense_" + voxelLabel(voxel) + threadKey(threads), "dense_carve",
           "8x1280x720@" + voxelLabel(voxel), sw, -1, threads, extra);
  }
}

// Args: {voxel mm (unused by keying), threads (0 = the machine's)}.
BENCHMARK(BM_KeyWitness)->Args({0, 1})->Args({0, 0})->Unit(benchmark::kMillisecond)->Iterations(5);
BENCHMARK(BM_KeyWitnessNoisy)->Args({0, 1})->Args({0, 0})->Unit(benchmark::kMillisecond)->Iterations(5);
BENCHMARK(BM_KeyMain)->Args({0, 1})->Args({0, 0})->Unit(benchmark::kMillisecond)->Iterations(5);
// Backdrop (datasets/studio.h: 0 green, 1 blue, 2 set without a screen), threads.
BENCHMARK(BM_KeyBackdrop)->ArgsProduct({{0, 1, 2}, {1, 0}})->Unit(benchmark::kMillisecond)->Iterations(5);
BENCHMARK(BM_Carve)->ArgsProduct({{10, 5}, {1, 0}})->Unit(benchmark::kMillisecond)->Iterations(15);
BENCHMARK(BM_Depth)->ArgsProduct({{10, 5}, {1, 0}})->Unit(benchmark::kMillisecond)->Iterations(15);
// Args: {witnesses, threads}.
BENCHMARK(BM_CarveCameras)->ArgsProduct({{8, 32, 64, 128}, {1, 0}})->Unit(benchmark::kMillisecond)->Iterations(5);
BENCHMARK(BM_DepthCameras)->ArgsProduct({{8, 32, 64, 128}, {1, 0}})->Unit(benchmark::kMillisecond)->Iterations(5);
BENCHMARK(BM_RefineDepth)->ArgsProduct({{5}, {1, 0}})->Unit(benchmark::kMillisecond)->Iterations(5);
BENCHMARK(BM_PhotoHull)->ArgsProduct({{5}, {1, 0}})->Unit(benchmark::kMillisecond)->Iterations(3);
BENCHMARK(BM_Mesh)->ArgsProduct({{10, 5}, {1, 0}})->Unit(benchmark::kMillisecond)->Iterations(3);
BENCHMARK(BM_DenseCarve)->ArgsProduct({{10}, {1, 0}})->Unit(benchmark::kMillisecond)->Iterations(3);

}  // namespace

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  auto& r = results();
  const int machine_threads = coreCount();
  for (int threads : {1, machine_threads}) {
    // Keying as the live loop pays it: 8 witnesses + main, one after another.
    const std::string w = "1_key_witness" + threadKey(threads), m = "2_key_main" + threadKey(threads);
    if (r.count(w) && r.count(m)) {
      Result& k = r["1_key_frame" + threadKey(threads)];
      k.stage = "key_frame";
      k.size = "8x1280x720+1920x1080";
      k.budget_ms = 5.0;
      k.threads = threads;
      k.ms.push_back(8 * median(r[w].ms) + median(r[m].ms));
      k.cpu_ms.push_back(8 * median(r[w].cpu_ms) + median(r[m].cpu_ms));
    }
  }
  auto worstIou = [](const WitnessKeying& k) {
    double worst = 1;
    for (size_t c = 0; c < k.silhouettes.size(); ++c)
      worst = std::min(worst, iou(k.silhouettes[c], frame().truth_foreground[c]));
    return worst;
  };
  for (const auto& [key, res] : r) {
    const double ms = median(res.ms), cpu = median(res.cpu_ms);
    const double ms_min = *std::min_element(res.ms.begin(), res.ms.end());
    std::printf("{\"stage\":\"%s\",\"size\":\"%s\",\"threads\":%d,\"ms\":%.2f,\"ms_min\":%.2f,"
                "\"cpu_ms\":%.2f,\"runs\":%zu,",
                res.stage.c_str(), res.size.c_str(), res.threads, ms, ms_min, cpu, res.ms.size());
    if (res.budget_ms > 0)
      std::printf("\"budget_ms\":%.2f,", res.budget_ms);
    else
      std::printf("\"budget_ms\":null,");
    const std::string dense = "6_dense_10mm" + threadKey(res.threads);
    if (res.stage == "carve" && r.count(dense) && res.size.find("@10mm") != std::string::npos)
      std::printf("\"ratio_vs_dense\":%.1f,\"cpu_ratio_vs_dense\":%.1f", median(r[dense].ms) / ms,
                  median(r[dense].cpu_ms) / cpu);
    else
      std::printf("\"ratio_vs_dense\":null");
    if (!res.extra.empty()) std::printf(",%s", res.extra.c_str());
    std::printf("}\n");
  }
  std::printf("{\"stage\":\"key_check\",\"worst_witness_iou_vs_truth\":%.4f,"
              "\"worst_witness_iou_vs_truth_noise2\":%.4f}\n",
              worstIou(witnessKeying(false, machine_threads)), worstIou(witnessKeying(true, machine_threads)));
  return 0;
}
