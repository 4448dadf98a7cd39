// Calibration benchmarks on the thesis camera (1200x900, f 800, k1 0.2): the intrinsic solve on
// 20 views (OpenCV initialisation + Ceres + covariance), view selection per streamed view, board
// detection per image (cornerSubPix alone and with the model fit) and frontal re-detection per
// view.
// Google Benchmark's table first, then one JSON line per case on stdout (median of a few runs).
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cstdio>
#include <map>
#include <string>
#include <vector>

#include "calib/detect.h"
#include "calib/frontal.h"
#include "calib/intrinsics.h"
#include "calib/selection.h"
#include "core/stopwatch.h"
#include "datasets/random.h"
#include "datasets/render.h"
#include "datasets/rigs.h"
#include "datasets/studio.h"

namespace previz::calib {
namespace {

Camera thesisCamera() {
  Camera c;
  c.name = "thesis";
  c.width = 1200;
  c.height = 900;
  c.fx = c.fy = 800;
  c.cx = 600;
  c.cy = 450;
  c.dist.k1 = 0.2;
  return c;
}

BoardSpec denseChessboard() {
  BoardSpec b = synth::defaultBoard(BoardType::kChessboard);
  b.rows = 12, b.cols = 16, b.square_m = 0.04, b.margin_m = 0.04;
  return b;
}

// Exact projections plus 0.1 px Gaussian noise, the studio's intrinsics-preset poses.
std::vector<ViewObservations> projectedViews(const Camera& camera, const BoardSpec& board, int n,
                                             std::uint64_t seed) {
  std::vector<ViewObservations> views;
  for (int f = 0; f < n; ++f) {
    const Pose T = synth::intrinsicsBoardPose(camera, board, f, seed);
    ViewObservations view;
    view.source = "frame " + std::to_string(f);
    view.image_size = cv::Size(camera.width, camera.height);
    int k = 0;
    for (const BoardPoint& p : boardPoints(board)) {
      const auto px = camera.project(T * p.p_board);
      ++k;
      if (!px || !camera.inImage(*px, 2.0)) continue;
      const Eigen::Vector2d noise(synth::normalFromKey(synth::hashKey(seed, f, k, 0)),
                                  synth::normalFromKey(synth::hashKey(seed, f, k, 1)));
      view.points.push_back({p.id, *px + 0.1 * noise});
    }
    views.push_back(view);
  }
  return views;
}

struct RenderedBoard {
  BoardSpec board;
  Pose T_cam_board;
  cv::Mat image;
};

// One rendered view per board type (blur 1 px, noise 2 grey levels, 4 spp), made once.
const std::vector<RenderedBoard>& renderedBoards() {
  static const std::vector<RenderedBoard> boards = [] {
    std::vector<RenderedBoard> out;
    const Camera camera = thesisCamera();
    synth::StudioConfig config;
    config.with_actor = false;
    config.with_prop = false;
    const synth::Studio studio(config);
    const Pose T_world_cam = lookAt(Eigen::Vector3d(0, -3, 1.5), Eigen::Vector3d(0, 0, 1.5));
    for (BoardType type : {BoardType::kChessboard, BoardType::kCharuco, BoardType::kAprilGrid,
                           BoardType::kCircles, BoardType::kQuadtree}) {
      RenderedBoard r;
      r.board = synth::defaultBoard(type);
      r.T_cam_board = synth::intrinsicsBoardPose(camera, r.board, 0, 1);
      synth::Scene scene = studio.sceneAt(0.0, synth::kLayerStage);
      scene.add(synth::makeBoard(r.board, T_world_cam * r.T_cam_board));
      synth::RenderOptions ro;
      ro.blur_sigma_px = 1.0;
      ro.noise_sigma = 2.0;
      ro.truth = false;
      r.image = synth::renderView(camera, T_world_cam, scene, ro).bgr;
      out.push_back(r);
    }
    return out;
  }();
  return boards;
}

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

// ---- Google Benchmark cases ---------------------------------------------------------------------

void BM_Solve20Views(benchmark::State& state) {
  const BoardSpec board = synth::defaultBoard(BoardType::kChessboard);
  const auto views = projectedViews(thesisCamera(), board, 20, 1);
  for (auto _ : state) benchmark::DoNotOptimize(calibrateIntrinsics(views, board));
}
BENCHMARK(BM_Solve20Views)->Unit(benchmark::kMillisecond);

void BM_SelectPerView(benchmark::State& state) {
  const BoardSpec board = synth::defaultBoard(BoardType::kChessboard);
  const auto views = projectedViews(thesisCamera(), board, 100, 2);
  SelectionOptions so;
  so.views = 10;
  so.method = static_cast<SelectionMethod>(state.range(0));
  for (auto _ : state) {
    ViewSelector selector(board, cv::Size(1200, 900), so);
    for (const auto& v : views) selector.add(v);
    benchmark::DoNotOptimize(selector.objective());
  }
  state.SetItemsProcessed(state.iterations() * static_cast<int64_t>(views.size()));
}
BENCHMARK(BM_SelectPerView)->DenseRange(0, 2)->Unit(benchmark::kMillisecond);

void BM_Detect(benchmark::State& state) {
  const RenderedBoard& r = renderedBoards()[state.range(0)];
  for (auto _ : state) benchmark::DoNotOptimize(detectBoard(r.image, r.board));
}
BENCHMARK(BM_Detect)->DenseRange(0, 4)->Unit(benchmark::kMillisecond);

// ---- JSON lines ---------------------------------------------------------------------------------

void printJsonLines() {
  const Camera camera = thesisCamera();
  for (const auto& [label, board] :
       std::vector<std::pair<std::string, BoardSpec>>{{"chessboard 7x10 (54 points)", synth::defaultBoard(BoardType::kChessboard)},
                                                      {"chessboard 12x16 (165 points)", denseChessboard()}}) {
    const auto views = projectedViews(camera, board, 20, 1);
    IntrinsicsResult r;
    for (int variant = 0; variant < 3; ++variant) {
      IntrinsicsOptions o;
      o.compute_covariance = variant > 0;
      o.joint_covariance = variant > 1;
      const double ms = medianMs([&] { r = calibrateIntrinsics(views, board, o); });
      const char* what = variant == 0 ? "no covariance" : variant == 1 ? "intrinsics covariance" : "joint covariance";
      std::printf("{\"stage\":\"calib_solve\",\"views\":20,\"board\":\"%s\",\"covariance\":\"%s\",\"size\":\"1200x900\","
                  "\"ms\":%.3f,\"iterations\":%d,\"points\":%d}\n",
                  label.c_str(), what, ms, r.iterations, r.points_used);
    }
    IntrinsicsOptions warm;
    warm.opencv_init = false;
    warm.initial_camera = r.camera;
    const double ms = medianMs([&] { r = calibrateIntrinsics(views, board, warm); });
    std::printf("{\"stage\":\"calib_solve\",\"views\":20,\"board\":\"%s\",\"covariance\":\"joint covariance\","
                "\"init\":\"warm (no OpenCV)\",\"size\":\"1200x900\",\"ms\":%.3f,\"iterations\":%d,\"points\":%d}\n",
                label.c_str(), ms, r.iterations, r.points_used);
  }
  {
    const BoardSpec board = synth::defaultBoard(BoardType::kChessboard);
    const auto views = projectedViews(camera, board, 200, 2);
    for (SelectionMethod m : {SelectionMethod::kUncertainty, SelectionMethod::kInformation,
                              SelectionMethod::kPlaneAngles, SelectionMethod::kRandom}) {
      SelectionOptions so;
      so.views = 10;
      so.method = m;
      int held = 0, relin = 0;
      const double ms = medianMs(
          [&] {
            ViewSelector selector(board, cv::Size(1200, 900), so);
            for (const auto& v : views) selector.add(v);
            held = selector.maxHeld();
            relin = selector.relinearisations();
          },
          3);
      std::printf("{\"stage\":\"calib_select\",\"method\":\"%s\",\"views_streamed\":200,\"chosen\":10,"
                  "\"ms_per_view\":%.4f,\"ms\":%.3f,\"max_held\":%d,\"relinearisations\":%d}\n",
                  toString(m), ms / views.size(), ms, held, relin);
    }
  }
  for (const RenderedBoard& r : renderedBoards()) {
    // cornerSubPix alone, then with the model fit (the default; chessboard, ChArUco, quadtree).
    ViewObservations found;
    for (bool fit : {false, true}) {
      DetectOptions options;
      options.model_fit = fit;
      const double ms = medianMs([&] { found = detectBoard(r.image, r.board, options); }, 5);
      std::printf("{\"stage\":\"calib_detect\",\"board\":\"%s\",\"refine\":\"%s\",\"size\":\"1200x900\","
                  "\"ms\":%.3f,\"points\":%zu}\n",
                  toString(r.board.type), fit ? "model fit" : "cornerSubPix", ms, found.points.size());
    }
    if (!found.found()) continue;
    ViewObservations frontal;
    const double fms = medianMs(
        [&] { frontal = redetectFrontal(r.image, found, camera, r.T_cam_board, r.board); }, 5);
    std::printf("{\"stage\":\"calib_frontal_redetect\",\"board\":\"%s\",\"size\":\"1200x900\",\"ms\":%.3f,"
                "\"points\":%zu}\n",
                toString(r.board.type), fms, frontal.points.size());
  }
  std::fflush(stdout);
}

}  // namespace
}  // namespace previz::calib

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  previz::calib::printJsonLines();
  return 0;
}
