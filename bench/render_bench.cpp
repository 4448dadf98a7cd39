// Synthetic studio renderer: ms per camera-frame for a witness (1280x720) and the main camera
// (1920x1080) on the studio scene at 4 samples per pixel, and a whole studio frame (8 witness +
// main). Besides Google Benchmark's table, prints one JSON line per case:
//   {"stage":"render","camera":"witness","size":"1280x720","spp":4,"threads":2,"ms":...}
#include <benchmark/benchmark.h>
#include <omp.h>

#include <chrono>
#include <cstdio>
#include <map>
#include <string>
#include <vector>

#include "datasets/render.h"
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
    const auto start = std::chrono::steady_clock::now();
    for (const RigCamera* rc : cameras) {
      RenderedView view = renderView(rc->camera, rc->T_world_cam, scene, options);
      benchmark::DoNotOptimize(view.bgr.data);
    }
    total_ms += std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
                    .count();
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

}  // namespace

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  const int threads = omp_get_max_threads();
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
  return 0;
}
