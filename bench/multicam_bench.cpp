// Rig solve benchmarks: the full joint calibration (views, camera graph, bundle adjustment,
// covariances) of the studio rig (8 witnesses 1280x720 + main 1920x1080) on a 300-frame capture
// at the observation level (exact projections + 0.2 px noise, tests/multicam/rig_calib_fixtures.h),
// and on the image-level capture multicam.capture wrote, when it is there
// ($PREVIZ_MULTICAM_CAPTURE, else <build>/test_tmp/multicam_capture beside this program's
// folder); then re-survey and check on a 40-frame capture.
// Google Benchmark's table first, then one JSON line per case on stdout (median of a few runs).
#include <benchmark/benchmark.h>

#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "core/stopwatch.h"
#include "multicam/rig_calib.h"
#include "tests/multicam/rig_calib_fixtures.h"

namespace previz::multicam {
namespace {

namespace fs = std::filesystem;

const testing::ProjectedCapture& observationCapture() {
  static const testing::ProjectedCapture capture = testing::projectedCapture({});
  return capture;
}

template <typename F>
double medianMs(F&& f, int runs) {
  std::vector<double> ms;
  for (int i = 0; i < runs; ++i) {
    const Stopwatch t0;
    f();
    ms.push_back(t0.ms());
  }
  std::sort(ms.begin(), ms.end());
  return ms[ms.size() / 2];
}

fs::path captureDir() {
  if (const char* env = std::getenv("PREVIZ_MULTICAM_CAPTURE")) return env;
  char exe[4096];
  const ssize_t n = ::readlink("/proc/self/exe", exe, sizeof(exe) - 1);
  if (n <= 0) return {};
  exe[n] = 0;
  return fs::path(exe).parent_path().parent_path() / "test_tmp" / "multicam_capture";
}

void BM_RigSolve(benchmark::State& state) {
  const auto& capture = observationCapture();
  const Rig initial = testing::intrinsicsOnly(capture.truth);
  for (auto _ : state) benchmark::DoNotOptimize(calibrateRig(capture.obs, initial));
}
BENCHMARK(BM_RigSolve)->Unit(benchmark::kMillisecond)->Iterations(3);

void printSolve(const char* source, const RigObservations& obs, const Rig& truth, int runs) {
  const Rig initial = testing::intrinsicsOnly(truth);
  RigCalibResult r;
  const double ms = medianMs([&] { r = calibrateRig(obs, initial); }, runs);
  double max_mm = 0, max_deg = 0;
  for (size_t c = 0; c < r.rig.cameras.size(); ++c) {
    const testing::CameraError e =
        testing::cameraError(r.rig.cameras[c], r.cameras[c], truth.at(r.rig.cameras[c].camera.name).T_world_cam);
    max_mm = std::max(max_mm, e.position_m * 1e3);
    max_deg = std::max(max_deg, e.rotation_deg);
  }
  std::printf("{\"stage\":\"rig_solve\",\"source\":\"%s\",\"size\":\"%zu cameras x %d frames\",\"cameras\":%zu,"
              "\"frames\":%d,\"views\":%d,\"residuals\":%d,\"rejected\":%d,\"iterations\":%d,\"rms_px\":%.4f,"
              "\"max_position_mm\":%.3f,\"max_rotation_deg\":%.5f,\"ms\":%.1f}\n",
              source, r.rig.cameras.size(), obs.frame_count, r.rig.cameras.size(), obs.frame_count,
              [&] { int v = 0; for (const auto& c : r.cameras) v += c.views; return v; }(), r.residuals,
              r.rejected, r.ceres_iterations, r.rms_px, max_mm, max_deg, ms);
  std::fflush(stdout);
}

void printJsonLines() {
  const auto& capture = observationCapture();
  printSolve("observations", capture.obs, capture.truth, 3);

  testing::ProjectedCaptureOptions o;
  o.frames = 40;
  o.floor = false;
  o.board_seed = 2;
  o.bump["witness05"] = testing::witnessBump();
  const auto bumped = testing::projectedCapture(o);
  ResurveyResult rs;
  const double resurvey_ms = medianMs([&] { rs = resurveyCamera(capture.truth, "witness05", bumped.obs); }, 3);
  std::printf("{\"stage\":\"rig_resurvey\",\"source\":\"observations\",\"size\":\"1 of 9 cameras x 40 frames\","
              "\"views\":%d,\"points\":%d,\"ms\":%.1f}\n",
              rs.report.views, rs.report.points, resurvey_ms);
  RigCheckResult check;
  const double check_ms = medianMs([&] { check = checkRig(capture.truth, bumped.obs); }, 3);
  int flagged = 0;
  for (const RigCheckCamera& c : check.cameras) flagged += c.flagged ? 1 : 0;
  std::printf("{\"stage\":\"rig_check\",\"source\":\"observations\",\"size\":\"9 cameras x 40 frames\","
              "\"flagged\":%d,\"ms\":%.1f}\n",
              flagged, check_ms);

  const fs::path dir = captureDir();
  if (!dir.empty() && fs::exists(dir / "main.json") && fs::exists(dir / "truth_rig.json")) {
    printSolve("images", readObservations(dir / "main.json"), readRig(dir / "truth_rig.json"), 3);
  } else {
    std::fprintf(stderr, "rig_solve on images: no capture in '%s' (run ctest -R multicam.capture first)\n",
                 dir.string().c_str());
  }
  std::fflush(stdout);
}

}  // namespace
}  // namespace previz::multicam

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  previz::multicam::printJsonLines();
  return 0;
}
