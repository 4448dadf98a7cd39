// Distortion benchmarks: forward model, Newton and fixed-point inverses on every pixel of a
// 1280x720 image, and a whole 1920x1080 distort map, for a mild and two strong lenses.
// Google Benchmark's table first, then one JSON line per case on stdout (median of a few runs).
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cstdio>
#include <string>
#include <vector>

#include "core/camera.h"
#include "core/distortion_maps.h"
#include "core/stopwatch.h"

namespace previz {
namespace {

struct Lens {
  const char* label;
  Distortion dist;
};

const Lens kLenses[] = {
    {"k1=-0.1", {-0.1, 0, 0, 0, 0}},
    {"k1=-0.5", {-0.5, 0, 0, 0, 0}},
    {"k1=1.0", {1.0, 0, 0, 0, 0}},
};

// 1280x720 at f = 900 px (about 71 x 44 degrees) or 1920x1080 at 1350 px: the same lens.
Camera camera(const Distortion& d, int width, int height) {
  Camera c;
  c.name = "bench";
  c.width = width;
  c.height = height;
  c.fx = c.fy = 900.0 * width / 1280.0;
  c.cx = (width - 1) / 2.0;
  c.cy = (height - 1) / 2.0;
  c.dist = d;
  return c;
}

// The inputs of each stage, prepared outside the timed loops.
struct Points {
  std::vector<Eigen::Vector2d> ideal;      // undistorted normalized, for distort()
  std::vector<Eigen::Vector2d> distorted;  // normalized of every pixel, for the inverses
};

Points makePoints(const Camera& cam) {
  Points p;
  p.distorted.reserve(static_cast<size_t>(cam.width) * cam.height);
  for (int v = 0; v < cam.height; ++v)
    for (int u = 0; u < cam.width; ++u) p.distorted.push_back(cam.pixelToNormalized({u, v}));
  // Forward model input: the ideal points of a distortion-free camera with the same K.
  p.ideal = p.distorted;
  return p;
}

struct Tally {
  long converged = 0, not_invertible = 0, failed = 0;
  long iterations = 0;
  double sink = 0;
};

void runDistort(const Camera& cam, const Points& pts, Tally& t) {
  double s = 0;
  for (const auto& x : pts.ideal) s += cam.distort(x).x();
  t.sink += s;
}

void runInverse(const InverseDistortion& inv, const Points& pts, const InverseOptions& o, Tally& t) {
  Tally local;
  for (const auto& xd : pts.distorted) {
    const InverseResult r = inv.solve(xd, o);
    local.iterations += r.iterations;
    if (r.ok()) {
      ++local.converged;
      local.sink += r.point.x();
    } else if (r.status == InverseStatus::kNotInvertible) {
      ++local.not_invertible;
    } else {
      ++local.failed;
    }
  }
  t = local;
}

// ---- Google Benchmark cases -------------------------------------------------------------------

void BM_Distort(benchmark::State& state) {
  const Camera cam = camera(kLenses[state.range(0)].dist, 1280, 720);
  const Points pts = makePoints(cam);
  Tally t;
  for (auto _ : state) {
    runDistort(cam, pts, t);
    benchmark::DoNotOptimize(t.sink);
  }
  state.SetItemsProcessed(state.iterations() * static_cast<int64_t>(pts.ideal.size()));
  state.SetLabel(kLenses[state.range(0)].label);
}

template <InverseMethod kMethod>
void BM_Undistort(benchmark::State& state) {
  const Camera cam = camera(kLenses[state.range(0)].dist, 1280, 720);
  const Points pts = makePoints(cam);
  const InverseDistortion inv(cam.dist);
  InverseOptions o;
  o.method = kMethod;
  Tally t;
  for (auto _ : state) {
    runInverse(inv, pts, o, t);
    benchmark::DoNotOptimize(t.sink);
  }
  state.SetItemsProcessed(state.iterations() * static_cast<int64_t>(pts.distorted.size()));
  state.SetLabel(kLenses[state.range(0)].label);
}

void BM_MakeDistortMap(benchmark::State& state) {
  const Camera cam = camera(kLenses[state.range(0)].dist, 1920, 1080);
  const Camera pinhole = idealPinhole(cam, 0.2);
  for (auto _ : state) {
    DistortMapResult r = makeDistortMap(cam, pinhole);
    benchmark::DoNotOptimize(r.map.data);
  }
  state.SetItemsProcessed(state.iterations() * 1920 * 1080);
  state.SetLabel(kLenses[state.range(0)].label);
}

BENCHMARK(BM_Distort)->DenseRange(0, 2)->Unit(benchmark::kMillisecond);
BENCHMARK_TEMPLATE(BM_Undistort, InverseMethod::kNewton)->DenseRange(0, 2)->Unit(benchmark::kMillisecond);
BENCHMARK_TEMPLATE(BM_Undistort, InverseMethod::kFixedPoint)->DenseRange(0, 2)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_MakeDistortMap)->DenseRange(0, 2)->Unit(benchmark::kMillisecond);

// ---- JSON lines ---------------------------------------------------------------------------------

template <typename F>
double medianMs(F&& f, int runs = 7) {
  std::vector<double> ms;
  for (int i = 0; i < runs; ++i) {
    const Stopwatch t0;
    f();
    ms.push_back(t0.ms());
  }
  std::sort(ms.begin(), ms.end());
  return ms[ms.size() / 2];
}

void printJsonLines() {
  for (const Lens& lens : kLenses) {
    const Camera cam = camera(lens.dist, 1280, 720);
    const Points pts = makePoints(cam);
    const double n = static_cast<double>(pts.distorted.size());
    const InverseDistortion inv(cam.dist);
    Tally t;
    double ms = medianMs([&] { runDistort(cam, pts, t); });
    std::printf("{\"stage\":\"distort\",\"lens\":\"%s\",\"size\":\"1280x720\",\"ms\":%.3f,\"points_per_s\":%.4g}\n",
                lens.label, ms, n / (ms * 1e-3));

    // Newton first: its verdict (converged / not invertible) defines the invertible pixels.
    // mean_iterations: over the pixels that have a preimage (the others are refused up front,
    // in 0 iterations, by both methods); points_per_s: over all pixels.
    InverseOptions newton;
    Tally tn;
    ms = medianMs([&] { runInverse(inv, pts, newton, tn); });
    const double invertible = static_cast<double>(tn.converged + tn.failed);
    std::printf(
        "{\"stage\":\"undistort_newton\",\"lens\":\"%s\",\"size\":\"1280x720\",\"ms\":%.3f,\"points_per_s\":%.4g,"
        "\"mean_iterations\":%.3f,\"failed_fraction\":%.6f,\"not_invertible_fraction\":%.6f}\n",
        lens.label, ms, n / (ms * 1e-3), tn.iterations / std::max(1.0, n - tn.not_invertible),
        tn.failed / std::max(1.0, invertible),
        tn.not_invertible / n);

    InverseOptions fp;
    fp.method = InverseMethod::kFixedPoint;
    Tally tf;
    ms = medianMs([&] { runInverse(inv, pts, fp, tf); });
    // failed_fraction: share of the invertible pixels (Newton converged) on which the fixed
    // point did not converge within 100 iterations.
    std::printf(
        "{\"stage\":\"undistort_fixed_point\",\"lens\":\"%s\",\"size\":\"1280x720\",\"ms\":%.3f,\"points_per_s\":%.4g,"
        "\"mean_iterations\":%.3f,\"failed_fraction\":%.6f,\"not_invertible_fraction\":%.6f}\n",
        lens.label, ms, n / (ms * 1e-3), tf.iterations / std::max(1.0, n - tf.not_invertible),
        (tn.converged - tf.converged) / std::max(1.0, static_cast<double>(tn.converged)),
        tf.not_invertible / n);

    const Camera big = camera(lens.dist, 1920, 1080);
    const Camera pinhole = idealPinhole(big, 0.2);
    DistortMapResult map;
    ms = medianMs([&] { map = makeDistortMap(big, pinhole); }, 5);
    std::printf(
        "{\"stage\":\"make_distort_map\",\"lens\":\"%s\",\"size\":\"1920x1080\",\"ms\":%.3f,\"points_per_s\":%.4g,"
        "\"max_iterations\":%d,\"not_invertible_fraction\":%.6f}\n",
        lens.label, ms, 1920.0 * 1080.0 / (ms * 1e-3), map.max_iterations,
        map.not_invertible / (1920.0 * 1080.0));
    std::fflush(stdout);
  }
}

}  // namespace
}  // namespace previz

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  previz::printJsonLines();
  return 0;
}
