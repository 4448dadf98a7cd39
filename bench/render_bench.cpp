// Synthetic studio renderer: ms per camera-frame for a witness (1280x720) and the main camera
// (1920x1080) on the studio scene at 4 samples per pixel, and a whole studio frame (8 witness +
// main). Besides Google Benchmark's table, prints one JSON line per case:
//   {"stage":"render","camera":"witness","size":"1280x720","spp":4,"threads":2,"ms":...}
// Rig captures (datasets/rig_capture.h): one witness through a whole 300-frame capture on one
// thread, its empty stage rendered once and then only the board traced, against a full render
// of one of its camera-frames in the same process:
//   {"stage":"rig_capture_frame","size":"1280x720",...,"ms":...,"full_render_ms":...,"ratio":...}
#include <benchmark/benchmark.h>

#include <cstdio>
#include <ctime>
#include <map>
#include <string>
#include <vector>

#include "core/cpu_time.h"
#include "core/stopwatch.h"
#include "core/threads.h"
#include "datasets/render.h"
#include "datasets/rig_capture.h"
#include "datasets/rigs.h"
#include "datasets/studio.h"

namespace {

using namespace previz;
using namespace previz::synth;

constexpr int kSpp = 4;
constexpr double kTime = 4.0;  // mid-take: the actor is on stage, walking

struct Case {
  std::string camera, size;
  int cameras = 1;
  double ms = 0;
  int runs = 0;
};
std::map<std::string, Case>& results() {
  static std::map<std::string, Case> r;
  return r;
}

const Studio& studio() {
  static const Studio s{StudioConfig{}};
  return s;
}
const Rig& rig() {
  static const Rig r = studioRig(StudioRigOptions{}, StudioConfig{}.take_duration_s, true);
  return r;
}

void renderCameras(benchmark::State& state, const std::string& key, const std::string& label,
                   const std::vector<const RigCamera*>& cameras) {
  const Scene scene = studio().sceneAt(kTime, kLayersPlate);
  RenderOptions options;
  options.samples_per_pixel = kSpp;
  double total_ms = 0;
  int runs = 0;
  for (auto _ : state) {
    const Stopwatch start;
    for (const RigCamera* rc : cameras) {
      RenderedView view = renderView(rc->camera, rc->T_world_cam, scene, options);
      benchmark::DoNotOptimize(view.bgr.data);
    }
    total_ms += start.ms();
    ++runs;
  }
  const RigCamera& first = *cameras.front();
  Case c;
  c.camera = label;
  c.size = std::to_string(first.camera.width) + "x" + std::to_string(first.camera.height);
  c.cameras = static_cast<int>(cameras.size());
  c.ms = total_ms / runs;
  c.runs = runs;
  results()[key] = c;
  state.counters["ms"] = c.ms;
}

void BM_RenderWitness720p(benchmark::State& state) {
  renderCameras(state, "1_witness", "witness", {&rig().cameras.front()});
}
void BM_RenderMain1080p(benchmark::State& state) {
  renderCameras(state, "2_main", "main", {&rig().cameras.back()});
}
void BM_RenderStudioFrame(benchmark::State& state) {
  std::vector<const RigCamera*> all;
  for (const RigCamera& rc : rig().cameras) all.push_back(&rc);
  renderCameras(state, "3_frame", "8 witness + main", all);
}

BENCHMARK(BM_RenderWitness720p)->Unit(benchmark::kMillisecond)->Iterations(3);
BENCHMARK(BM_RenderMain1080p)->Unit(benchmark::kMillisecond)->Iterations(2);
BENCHMARK(BM_RenderStudioFrame)->Unit(benchmark::kMillisecond)->Iterations(1);

// CPU time of the calling thread (core/cpu_time.h): with threads = 1 every render runs on it, so
// the figure holds on a machine shared with other work (wall time is printed too).
using previz::threadCpuMs;

struct RigCaptureCase {
  std::string board;
  int frames = 0, spp = 0;
  double noise = 0;
  double ms = 0, cpu_ms = 0, first_ms = 0;  // per camera-frame; first: empty stage + frame 0
  double full_ms = 0, full_cpu_ms = 0;      // renderView of one camera-frame
  double traced_fraction = 0;
  bool done = false;
};
RigCaptureCase& rigCaptureCase() {
  static RigCaptureCase c;
  return c;
}

// witness01 (1280x720) through a whole capture: what multicam's tests and benchmarks pay.
void BM_RigCaptureWitness720p(benchmark::State& state) {
  RigCaptureOptions o;  // 8 witnesses + main, AprilGrid, 300 frames, 4 spp, noise 2
  o.threads = 1;
  const int camera = 0;
  RigCaptureCase& c = rigCaptureCase();
  for (auto _ : state) {
    const RigCapture capture(o);
    const Stopwatch start;
    const double cpu_start = threadCpuMs();
    for (int f = 0; f < o.frames; ++f) {
      cv::Mat image = capture.render(camera, f);
      benchmark::DoNotOptimize(image.data);
      if (f == 0) c.first_ms = threadCpuMs() - cpu_start;
    }
    c.cpu_ms = (threadCpuMs() - cpu_start) / o.frames;
    c.ms = start.ms() / o.frames;

    // The same camera-frame rendered whole, as synth rendered board takes before.
    const int frame = o.frames / 2;
    const RigCamera& rc = capture.rig().cameras[camera];
    StudioConfig config;
    config.seed = o.rig.seed;
    config.with_actor = false;
    config.with_prop = false;
    Scene scene = Studio(config).sceneAt(0.0, kLayerStage);
    scene.add(makeBoard(capture.board(), capture.T_world_board(camera, frame)));
    RenderOptions ro;
    ro.samples_per_pixel = o.samples_per_pixel;
    ro.noise_sigma = o.noise_sigma;
    ro.threads = 1;
    const Stopwatch full_start;
    const double full_cpu_start = threadCpuMs();
    RenderedView full = renderView(rc.camera, rc.T_world_cam, scene, ro);
    benchmark::DoNotOptimize(full.bgr.data);
    c.full_cpu_ms = threadCpuMs() - full_cpu_start;
    c.full_ms = full_start.ms();
  }
  c.board = toString(o.board);
  c.frames = o.frames;
  c.spp = o.samples_per_pixel;
  c.noise = o.noise_sigma;
  c.done = true;
  state.counters["ms"] = c.ms;
  state.counters["cpu_ms"] = c.cpu_ms;
  state.counters["full_cpu_ms"] = c.full_cpu_ms;
}
BENCHMARK(BM_RigCaptureWitness720p)->Unit(benchmark::kMillisecond)->Iterations(1);

}  // namespace

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  const int threads = defaultThreadCount();
  for (const auto& [key, c] : results()) {
    if (c.cameras == 1) {
      std::printf("{\"stage\":\"render\",\"camera\":\"%s\",\"size\":\"%s\",\"spp\":%d,"
                  "\"threads\":%d,\"runs\":%d,\"ms\":%.1f}\n",
                  c.camera.c_str(), c.size.c_str(), kSpp, threads, c.runs, c.ms);
    } else {
      std::printf("{\"stage\":\"render\",\"camera\":\"%s\",\"size\":\"8x1280x720+1920x1080\","
                  "\"spp\":%d,\"threads\":%d,\"runs\":%d,\"ms\":%.1f,"
                  "\"ms_per_camera_frame\":%.1f}\n",
                  c.camera.c_str(), kSpp, threads, c.runs, c.ms, c.ms / c.cameras);
    }
  }
  const RigCaptureCase& r = rigCaptureCase();
  if (r.done) {
    // Per camera-frame over the whole capture, the camera's one-off empty-stage render included
    // (first_frame_ms: that render + frame 0). ms = CPU time of the one rendering thread (what
    // the budget means: one core's work, whatever else runs on the machine); wall_ms beside it.
    // full_render_*: one renderView of a camera-frame of the capture; ratio = full / capture.
    std::printf("{\"stage\":\"rig_capture_frame\",\"size\":\"1280x720\",\"camera\":\"witness01\","
                "\"board\":\"%s\",\"spp\":%d,\"noise_sigma\":%.1f,\"threads\":1,\"frames\":%d,"
                "\"ms\":%.1f,\"wall_ms\":%.1f,\"first_frame_ms\":%.0f,\"full_render_ms\":%.1f,"
                "\"full_render_wall_ms\":%.1f,\"ratio\":%.1f,\"budget_ms\":40}\n",
                r.board.c_str(), r.spp, r.noise, r.frames, r.cpu_ms, r.ms, r.first_ms, r.full_cpu_ms,
                r.full_ms, r.full_cpu_ms / r.cpu_ms);
  }
  return 0;
}
