// Composite benchmark (issue 7): one pass of the depth-aware compositor at the main camera's
// 1920x1080 with the studio's main lens and a 10 % overscan CG render (1 and 2 threads), and
// the one-off distortion map build per lens state. Inputs are synthetic but shaped like a frame:
// CG colour/depth everywhere, an actor region (a fifth of the image) with soft alpha edges and
// depth in front of and behind the CG, and a band of edge pixels without depth (edge fill).
// Besides Google Benchmark's table, one JSON line per case:
//   {"stage":"composite", "size":..., "ms":..., "budget_ms": 2, "threads":...}
// "ms" is the median wall time; "cpu_ms" the median CPU time of the process (all threads): on a
// shared machine wall time also measures the other jobs.
#include <benchmark/benchmark.h>

#include <time.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <vector>

#include "composite/compositor.h"
#include "core/cpu_time.h"
#include "core/distortion_maps.h"
#include "datasets/rigs.h"

namespace {

using namespace previz;
using namespace previz::composite;

double nowMs() {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

struct Inputs {
  Camera lens, cg;
  CompositeInputs in;
};

const Inputs& inputs() {
  static const Inputs f = [] {
    Inputs i;
    i.lens = synth::mainCamera(1920, 1080);
    i.cg = idealPinhole(i.lens, 0.1);
    const int W = i.lens.width, H = i.lens.height;
    i.in.foreground = cv::Mat(H, W, CV_8UC3);
    cv::randu(i.in.foreground, 0, 255);
    i.in.alpha = cv::Mat(H, W, CV_32FC1, cv::Scalar(0));
    i.in.actor_depth = cv::Mat(H, W, CV_32FC1, cv::Scalar(std::numeric_limits<float>::infinity()));
    // The actor: an ellipse covering ~20 % of the frame, soft 2-px rim, depth 5.5-6.5 m (the
    // pillar's CG depth is 6 m: half in front, half behind); the rim's outer pixel has no depth.
    const cv::Point2d c(W * 0.5, H * 0.55);
    const double ax = W * 0.16, ay = H * 0.40;
    for (int v = 0; v < H; ++v)
      for (int u = 0; u < W; ++u) {
        const double r = std::hypot((u - c.x) / ax, (v - c.y) / ay);
        const double edge = (1.0 - r) * std::min(ax, ay);  // px inside the rim
        if (edge < -1) continue;
        i.in.alpha.at<float>(v, u) = static_cast<float>(std::clamp((edge + 1) / 3, 0.0, 1.0));
        if (edge >= 0) i.in.actor_depth.at<float>(v, u) = static_cast<float>(5.5 + (u - (c.x - ax)) / (2 * ax));
      }
    i.in.cg_color = cv::Mat(i.cg.height, i.cg.width, CV_32FC3);
    cv::randu(i.in.cg_color, 0.0, 1.0);
    i.in.cg_depth = cv::Mat(i.cg.height, i.cg.width, CV_32FC1, cv::Scalar(12.0));
    i.in.cg_depth.colRange(i.cg.width / 2 - 150, i.cg.width / 2 + 150).setTo(6.0);  // the pillar
    return i;
  }();
  return f;
}

void composite(benchmark::State& state) {
  const int threads = static_cast<int>(state.range(0));
  const Inputs& i = inputs();
  CompositeOptions o;
  o.threads = threads;
  const Compositor compositor(i.lens, i.cg, o);
  CompositeResult r;
  compositor.composite(i.in, r);  // warm the tables and the output image
  std::vector<double> wall, cpu;
  for (auto _ : state) {
    const double w0 = nowMs(), c0 = previz::processCpuMs();
    compositor.composite(i.in, r);
    benchmark::DoNotOptimize(r.bgr.data);
    wall.push_back(nowMs() - w0);
    cpu.push_back(previz::processCpuMs() - c0);
  }
  std::sort(wall.begin(), wall.end());
  std::sort(cpu.begin(), cpu.end());
  std::printf("{\"stage\":\"composite\",\"size\":\"1920x1080\",\"ms\":%.3f,\"ms_min\":%.3f,\"cpu_ms\":%.3f,"
              "\"budget_ms\":2,\"threads\":%d}\n",
              wall[wall.size() / 2], wall.front(), cpu[cpu.size() / 2], threads);
  std::fflush(stdout);
}
BENCHMARK(composite)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(1.0);

void lensMap(benchmark::State& state) {
  const Inputs& i = inputs();
  std::vector<double> wall;
  for (auto _ : state) {
    const double w0 = nowMs();
    const Compositor compositor(i.lens, i.cg);
    benchmark::DoNotOptimize(compositor.map().map.data);
    wall.push_back(nowMs() - w0);
  }
  std::sort(wall.begin(), wall.end());
  std::printf("{\"stage\":\"composite_lens_map\",\"size\":\"1920x1080\",\"ms\":%.3f,\"note\":\"once per lens state\"}\n",
              wall[wall.size() / 2]);
  std::fflush(stdout);
}
BENCHMARK(lensMap)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(3);

}  // namespace

BENCHMARK_MAIN();
