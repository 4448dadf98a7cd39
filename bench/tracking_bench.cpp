// Tracking benchmark (issue 6, item 3 and the 3 ms tag-tracking budget): 48 consecutive frames
// (2 s at 24 fps from t = 2 s, where the crate moves fastest) of the studio's tagged crate seen by
// the 8 witnesses at 1280x720, noise sigma = 2, rendered by the synthetic studio
// (tests/tracking/studio_fixture.h: the crate's window traced, the rest the empty stage). Then, in
// this process and on the same frames: PropTracker with full-frame search on every frame, with ROI
// search (full frame only on the first frame), and with ROI plus a full frame every 30 frames; the
// joint solve and the filter alone. It also checks that the ROI search found the same tags as the
// full-frame search of the same frame in every camera.
// The filter's lag and jitter (issue 33 item 4), on generated poses (tests/tracking/filter_motion.h,
// no rendering): a prop turning 10 deg/frame about an axis 10 cm from its origin (sudden start and
// stop, 50 runs) and a still prop (20 runs), at the crate's per-frame sigma 0.3 mm / 0.05 deg; the
// filter as it is ("options":"default") and as it was before issue 33 ("legacy"), same seeds. Their
// "ms" is the median time per frame of drawing the measurement and updating the filter; "lag_*"
// the worst frame of the error averaged over the runs, "median_*" / "max_*" of the 3-D error
// (units: mm, deg, and the per-frame sigma per axis), "jitter_*" the RMS spread of the still prop's
// filtered pose over 100 frames after 10.
// Besides Google Benchmark's table, one JSON line per case:
//   {"stage":..., "size":..., "ms":..., "cpu_ms":..., "budget_ms":..., "threads":...}
// "ms" is the median wall time per frame, "ms_max" the worst frame, "ms_mean" the mean, "cpu_ms"
// the median CPU time of the process per frame.
#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <map>
#include <set>
#include <string>
#include <vector>

#include "core/cpu_time.h"
#include "core/threads.h"
#include "core/units.h"
#include "tests/tracking/filter_motion.h"
#include "tests/tracking/studio_fixture.h"
#include "tracking/filter.h"
#include "tracking/solve.h"
#include "tracking/tracker.h"

namespace {

using namespace previz;
using namespace previz::tracking;

constexpr int kFrames = 48;
constexpr double kFps = 24.0;
constexpr double kBudgetMs = 3.0;  // ARCHITECTURE.md: tag tracking <= 3 ms a frame

double nowMs() {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

struct Take {
  test::StudioFixture fx;
  PropSet props;
  std::vector<std::vector<cv::Mat>> frames;
  Take() : props(test::studioProps(fx.studio)) {
    for (int f = 0; f < kFrames; ++f) frames.push_back(fx.renderTake(2.0 + f / kFps, f, 24));
  }
};
const Take& take() {
  static const Take t;
  return t;
}

struct Result {
  std::string stage, size, extra;
  std::vector<double> ms, cpu_ms;
  double budget_ms = -1;
  int threads = 1;
};
std::map<std::string, Result>& results() {
  static std::map<std::string, Result> r;
  return r;
}
double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0 : v[v.size() / 2];
}
int benchThreads(const benchmark::State& state) {
  return state.range(0) > 0 ? static_cast<int>(state.range(0))
                            : coreCount();
}

// Tags found per frame per camera by the last full-frame and ROI runs (for the comparison).
std::vector<std::vector<std::set<int>>> g_full_tags, g_roi_tags;

void runTracker(benchmark::State& state, const std::string& key, const std::string& stage, bool roi, int full_every,
                std::vector<std::vector<std::set<int>>>* tags) {
  const Take& t = take();
  const int threads = benchThreads(state);
  for (auto _ : state) {
    TrackerOptions o;
    o.roi = roi;
    o.full_frame_every = full_every;
    o.threads = threads;
    PropTracker tracker(t.fx.rig.cameras, t.props, o);
    if (tags) tags->assign(kFrames, std::vector<std::set<int>>(t.frames[0].size()));
    for (int f = 0; f < kFrames; ++f) {
      const double w = nowMs(), c = previz::processCpuMs();
      const TrackFrame r = tracker.track(f, 2.0 + f / kFps, t.frames[static_cast<size_t>(f)]);
      const double ms = nowMs() - w, cpu = previz::processCpuMs() - c;
      benchmark::DoNotOptimize(r.props.data());
      // ROI cases: the first frame is the full-frame acquisition, not the ROI path.
      if (!(roi && f == 0)) {
        Result& res = results()[key + "_t" + std::to_string(threads)];
        res.stage = stage;
        res.size = "8x1280x720";
        res.budget_ms = kBudgetMs;
        res.threads = threads;
        res.ms.push_back(ms);
        res.cpu_ms.push_back(cpu);
      }
      if (tags) {
        // Re-search the same regions to learn which ids each camera found (not timed).
        for (size_t cam = 0; cam < r.search.size(); ++cam) {
          TagDetector d{DetectorOptions{}};
          for (const TagDetection& x : d.detect(t.frames[static_cast<size_t>(f)][cam], r.search[cam].rois))
            (*tags)[static_cast<size_t>(f)][cam].insert(x.id);
        }
      }
    }
  }
}

void BM_TrackFullFrame(benchmark::State& state) {
  runTracker(state, "1_full", "track_full_frame", false, 0, state.range(0) == 0 ? &g_full_tags : nullptr);
}
void BM_TrackRoi(benchmark::State& state) {
  runTracker(state, "2_roi", "track_roi", true, 0, state.range(0) == 0 ? &g_roi_tags : nullptr);
}
void BM_TrackRoiPeriodicFull(benchmark::State& state) {
  runTracker(state, "3_roi_full30", "track_roi_full_every_30", true, 30, nullptr);
}

void BM_Solve(benchmark::State& state) {
  const Take& t = take();
  std::vector<TagDetector> det;
  for (size_t c = 0; c < t.frames[0].size(); ++c) det.emplace_back(DetectorOptions{});
  std::vector<TagObservation> obs;
  for (size_t c = 0; c < t.frames[0].size(); ++c)
    for (const TagDetection& d : det[c].detect(t.frames[0][c])) {
      const auto owner = t.props.findTag(d.family, d.id);
      if (owner) obs.push_back(makeTagObservation(t.fx.rig.cameras[c].camera, static_cast<int>(c), owner->second, d.corners_px));
    }
  for (auto _ : state) {
    const double w = nowMs(), c = previz::processCpuMs();
    const PoseEstimate e = solvePropPose(t.fx.rig.cameras, t.props.props[0], obs, SolveOptions{});
    benchmark::DoNotOptimize(e.T);
    Result& res = results()["4_solve"];
    res.stage = "joint_solve";
    res.size = std::to_string(obs.size()) + " tags";
    res.ms.push_back(nowMs() - w);
    res.cpu_ms.push_back(previz::processCpuMs() - c);
  }
}

void BM_Filter(benchmark::State& state) {
  PoseFilter filter;
  Eigen::Matrix<double, 6, 6> cov = 1e-8 * Eigen::Matrix<double, 6, 6>::Identity();
  Pose T = Pose::Identity();
  int f = 0;
  for (auto _ : state) {
    const double w = nowMs(), c = previz::processCpuMs();
    T.translation().x() = 0.001 * f;
    benchmark::DoNotOptimize(filter.update(f / kFps, T, cov));
    ++f;
    Result& res = results()["5_filter"];
    res.stage = "filter_update";
    res.size = "1 prop";
    res.ms.push_back(nowMs() - w);
    res.cpu_ms.push_back(previz::processCpuMs() - c);
  }
}

// Arg 0: 0 turn, 1 still; arg 1: 0 default options, 1 legacy.
void BM_FilterFollow(benchmark::State& state) {
  const bool turn = state.range(0) == 0, legacy = state.range(1) == 1;
  const FilterOptions options = legacy ? test::legacyFilterOptions() : FilterOptions{};
  constexpr double kSigmaDeg = 0.05, kSigmaMm = 0.3;
  const double sr = radians(kSigmaDeg), sp = 1e-3 * kSigmaMm;
  constexpr unsigned kSeed = 33;
  const int runs = turn ? 50 : 20;
  const test::PropMotion motion = turn ? test::turnMotion(10, 0.1, 0) : test::PropMotion{};
  for (auto _ : state) {
    Result& res = results()[std::string("6_filter_") + (turn ? "turn" : "still") + (legacy ? "_legacy" : "")];
    res.stage = turn ? "filter_turn" : "filter_still";
    char extra[512];
    if (turn) {
      res.size = std::to_string(runs) + " runs x " + std::to_string(motion.truth.size()) + " frames";
      double w = nowMs(), c = previz::processCpuMs();
      test::runFilter(motion, options, sr, sp, runs, kSeed, [&](int, int, const Pose&, const Pose&, const Pose&) {
        const double w1 = nowMs(), c1 = previz::processCpuMs();
        res.ms.push_back(w1 - w);
        res.cpu_ms.push_back(c1 - c);
        w = w1;
        c = c1;
      });
      const test::FollowFigures f = test::followMotion(motion, options, sr, sp, runs, kSeed);
      std::snprintf(extra, sizeof(extra),
                    "\"options\":\"%s\",\"motion\":\"%s\",\"sigma_mm\":%.2f,\"sigma_deg\":%.3f,\"lag_mm\":%.4f,"
                    "\"lag_deg\":%.5f,\"lag_sigma_position\":%.3f,\"lag_sigma_rotation\":%.3f,\"median_mm\":%.4f,"
                    "\"median_deg\":%.5f,\"max_mm\":%.4f,\"max_deg\":%.5f",
                    legacy ? "legacy" : "default", motion.name.c_str(), kSigmaMm, kSigmaDeg, kSigmaMm * f.lag_position,
                    kSigmaDeg * f.lag_rotation, f.lag_position, f.lag_rotation, kSigmaMm * f.median_position,
                    kSigmaDeg * f.median_rotation, kSigmaMm * f.max_position, kSigmaDeg * f.max_rotation);
    } else {
      res.size = std::to_string(runs) + " runs x 110 frames";
      const double w = nowMs(), c = previz::processCpuMs();
      const test::Spread j = test::stillJitter(options, sr, sp, runs, kSeed);
      res.ms.push_back((nowMs() - w) / (runs * 110));  // mean per frame: one number per run of the case
      res.cpu_ms.push_back((previz::processCpuMs() - c) / (runs * 110));
      std::snprintf(extra, sizeof(extra),
                    "\"options\":\"%s\",\"sigma_mm\":%.2f,\"sigma_deg\":%.3f,\"jitter_mm\":%.4f,\"jitter_deg\":%.5f",
                    legacy ? "legacy" : "default", kSigmaMm, kSigmaDeg, 1e3 * j.position_m, degrees(j.rotation_rad));
    }
    res.extra = extra;
  }
}

}  // namespace

BENCHMARK(BM_TrackFullFrame)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->Iterations(1);
BENCHMARK(BM_TrackRoi)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->Iterations(3);
BENCHMARK(BM_TrackRoiPeriodicFull)->Arg(0)->Unit(benchmark::kMillisecond)->Iterations(2);
BENCHMARK(BM_Solve)->Unit(benchmark::kMillisecond)->Iterations(200);
BENCHMARK(BM_Filter)->Unit(benchmark::kMicrosecond)->Iterations(10000);
BENCHMARK(BM_FilterFollow)->Args({0, 0})->Args({0, 1})->Args({1, 0})->Args({1, 1})->Unit(benchmark::kMillisecond)->Iterations(1);

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  take();  // render before timing
  benchmark::RunSpecifiedBenchmarks();
  std::map<int, double> full_ms;
  for (const auto& [key, r] : results()) {
    if (r.stage == "track_full_frame") full_ms[r.threads] = median(r.ms);
  }
  // Same tags: frames where every camera's ROI search found exactly the full-frame search's ids.
  int same = 0, compared = 0;
  if (!g_full_tags.empty() && g_full_tags.size() == g_roi_tags.size()) {
    for (size_t f = 0; f < g_full_tags.size(); ++f) {
      ++compared;
      same += g_full_tags[f] == g_roi_tags[f] ? 1 : 0;
    }
  }
  for (const auto& [key, r] : results()) {
    std::printf("{\"stage\":\"%s\",\"size\":\"%s\",\"ms\":%.4f,\"ms_min\":%.4f,\"cpu_ms\":%.4f,\"threads\":%d", r.stage.c_str(),
                r.size.c_str(), median(r.ms), *std::min_element(r.ms.begin(), r.ms.end()), median(r.cpu_ms), r.threads);
    if (r.budget_ms > 0) std::printf(",\"budget_ms\":%.1f", r.budget_ms);
    const bool tracker_case = r.stage.rfind("track_", 0) == 0;
    if (tracker_case) {
      // The worst frame and the mean: the periodic whole-frame searches are the spikes.
      double sum = 0;
      for (double m : r.ms) sum += m;
      std::printf(",\"ms_max\":%.4f,\"ms_mean\":%.4f", *std::max_element(r.ms.begin(), r.ms.end()),
                  sum / static_cast<double>(r.ms.size()));
    }
    if (tracker_case && r.stage != "track_full_frame" && full_ms.count(r.threads))
      std::printf(",\"speedup_vs_full_frame\":%.2f", full_ms[r.threads] / std::max(1e-9, median(r.ms)));
    if (r.stage == "track_roi" && compared > 0)
      std::printf(",\"same_tags_frames\":%d,\"frames\":%d,\"same_tags_fraction\":%.4f", same, compared,
                  double(same) / compared);
    if (!r.extra.empty()) std::printf(",%s", r.extra.c_str());
    std::printf("}\n");
  }
  return 0;
}
