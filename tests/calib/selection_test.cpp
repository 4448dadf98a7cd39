#include "calib/selection.h"

#include <algorithm>
#include <cstdio>
#include <functional>

#include <gtest/gtest.h>

#include "calib/intrinsics.h"
#include "core/error.h"
#include "datasets/studio.h"
#include "tests/calib/solve_fixtures.h"

namespace previz::calib {
namespace {

using testing::projectedView;
using testing::table52Capture;
using testing::thesisCamera;

// Detection noise of the projected views: about what cornerSubPix achieves on the thesis scene
// (blur 1 px, noise 2 grey levels; see intrinsics_test's Table 5.1).
constexpr double kNoisePx = 0.05;

struct Errors {
  double fx = 0, fy = 0, cx = 0, cy = 0, k1 = 0;
  double f() const { return 0.5 * (fx + fy); }
  double c() const { return 0.5 * (cx + cy); }
  Errors& operator+=(const Errors& o) {
    fx += o.fx, fy += o.fy, cx += o.cx, cy += o.cy, k1 += o.k1;
    return *this;
  }
  Errors operator/(double d) const { return {fx / d, fy / d, cx / d, cy / d, k1 / d}; }
};

Errors errorsOf(const Camera& est, const Camera& truth) {
  return {std::abs(est.fx - truth.fx), std::abs(est.fy - truth.fy), std::abs(est.cx - truth.cx),
          std::abs(est.cy - truth.cy), std::abs(est.dist.k1 - truth.dist.k1)};
}

std::vector<ViewObservations> captureViews(const Camera& truth, const BoardSpec& board,
                                           std::uint64_t capture_seed) {
  std::vector<ViewObservations> views;
  const auto capture = table52Capture(truth, board, capture_seed);
  const std::uint64_t noise_seed = capture_seed;
  for (size_t i = 0; i < capture.size(); ++i) {
    views.push_back(projectedView(truth, board, capture[i].T_cam_board, kNoisePx,
                                  synth::hashKey(noise_seed, 5200, i),
                                  capture[i].kind + " " + std::to_string(i)));
  }
  return views;
}

std::vector<ViewObservations> runSelector(const std::vector<ViewObservations>& views,
                                          const BoardSpec& board, SelectionOptions options,
                                          std::vector<int>* indices = nullptr) {
  ViewSelector selector(board, views.front().image_size, options);
  for (const auto& v : views) selector.add(v);
  if (indices) *indices = selector.selectedIndices();
  return selector.selected();
}

// Thesis Table 5.2: select 4 views of a capture of near-duplicate and pure-translation views
// with a few tilted ones, calibrate from them, compare the intrinsics with the truth.
TEST(Selection, Table52OursNoWorseThanThesisGreedyAndFarBetterThanRandom) {
  const Camera truth = thesisCamera();
  const BoardSpec board = synth::defaultBoard(BoardType::kChessboard);
  constexpr int kSelect = 4;
  constexpr int kCaptures = 6;
  constexpr int kRandomSeeds = 20;
  IntrinsicsOptions solve;
  solve.joint_covariance = false;

  struct Row {
    const char* name = "";
    Errors mean;
    int solved = 0, failed = 0;
    std::vector<int> example;
    double sigma_f = 0, sigma_c = 0;  // predicted at the true camera and poses, summed
    int sigma_count = 0;
  };
  std::vector<testing::CaptureView> capture;
  const std::vector<int> free = {0, 1, 2, 3, 5, 6, 7, 8, 9};  // all but skew
  // Predicted sigma of fx and cx for a chosen set, from the truth (noise kNoisePx).
  auto predicted = [&](const std::vector<ViewObservations>& chosen, const std::vector<int>& idx) {
    Eigen::MatrixXd info = Eigen::MatrixXd::Zero(9, 9);
    for (size_t k = 0; k < idx.size(); ++k) {
      info += marginalViewInformation(truth, capture[idx[k]].T_cam_board, chosen[k], board, free);
    }
    const Eigen::MatrixXd cov = kNoisePx * kNoisePx * info.inverse();
    return std::make_pair(std::sqrt(cov(0, 0)), std::sqrt(cov(2, 2)));
  };
  std::vector<Row> rows;
  for (const char* name : {"ours (uncertainty)", "ours (information)", "thesis (plane angles)",
                           "random (mean of 20)", "sequential"}) {
    rows.emplace_back();
    rows.back().name = name;
  }
  const SelectionMethod methods[] = {SelectionMethod::kUncertainty, SelectionMethod::kInformation,
                                     SelectionMethod::kPlaneAngles, SelectionMethod::kRandom,
                                     SelectionMethod::kSequential};
  for (int seed = 1; seed <= kCaptures; ++seed) {
    capture = table52Capture(truth, board, seed);
    const auto views = captureViews(truth, board, seed);
    for (size_t m = 0; m < rows.size(); ++m) {
      const int repeats = methods[m] == SelectionMethod::kRandom ? kRandomSeeds : 1;
      for (int r = 0; r < repeats; ++r) {
        SelectionOptions so;
        so.views = kSelect;
        so.method = methods[m];
        so.seed = 1000 * seed + r;
        std::vector<int> indices;
        const auto chosen = runSelector(views, board, so, &indices);
        if (seed == 1 && r == 0) rows[m].example = indices;
        const auto [sf, sc] = predicted(chosen, indices);
        if (std::isfinite(sf) && std::isfinite(sc)) {
          rows[m].sigma_f += sf;
          rows[m].sigma_c += sc;
          ++rows[m].sigma_count;
        }
        try {
          const IntrinsicsResult res = calibrateIntrinsics(chosen, board, solve);
          rows[m].mean += errorsOf(res.camera, truth);
          ++rows[m].solved;
        } catch (const Error& e) {
          ++rows[m].failed;  // a degenerate set (e.g. all fronto-parallel) may not even solve
        }
      }
    }
  }
  std::printf("\nTable 5.2 (select %d of 36 views: frontal translations, near-duplicates, 6 tilted;"
              " %.2f px noise; mean over %d captures; sigma predicted at the truth)\n",
              kSelect, kNoisePx, kCaptures);
  std::printf("  %-24s %10s %10s %10s %10s %10s %10s %10s  %s\n", "method", "|dfx| px", "|dfy| px",
              "|dcx| px", "|dcy| px", "|dk1|", "sfx pred", "scx pred", "views (seed 1)");
  for (Row& row : rows) {
    row.mean = row.solved > 0 ? row.mean / row.solved : Errors{1e9, 1e9, 1e9, 1e9, 1e9};
    std::string ex;
    for (int i : row.example) ex += std::to_string(i) + " ";
    std::printf("  %-24s %10.4f %10.4f %10.4f %10.4f %10.6f %10.4f %10.4f  %s%s\n", row.name,
                row.mean.fx, row.mean.fy, row.mean.cx, row.mean.cy, row.mean.k1,
                row.sigma_f / std::max(1, row.sigma_count), row.sigma_c / std::max(1, row.sigma_count),
                ex.c_str(),
                row.failed ? ("(" + std::to_string(row.failed) + " sets failed to solve)").c_str() : "");
  }
  const Row& ours = rows[0];
  const Row& thesis = rows[2];
  const Row& random = rows[3];
  EXPECT_EQ(ours.failed, 0);
  EXPECT_LE(ours.mean.f(), thesis.mean.f());
  EXPECT_LE(ours.mean.c(), thesis.mean.c());
  EXPECT_LE(ours.sigma_f, thesis.sigma_f);
  EXPECT_LE(ours.sigma_c, thesis.sigma_c);
  // Tilted views carry the focal length: the chosen sets must be far better than chance.
  EXPECT_LT(ours.mean.f(), 0.2 * random.mean.f());
}

// The selector streams: whatever the stream length, it never holds more than the chosen set
// plus its buffer between calls.
TEST(Selection, StreamingHoldsAtMostChosenPlusBuffer) {
  const Camera truth = thesisCamera();
  const BoardSpec board = synth::defaultBoard(BoardType::kChessboard);
  for (SelectionMethod method : {SelectionMethod::kInformation, SelectionMethod::kUncertainty,
                                 SelectionMethod::kPlaneAngles, SelectionMethod::kRandom,
                                 SelectionMethod::kSequential}) {
    SelectionOptions so;
    so.views = 6;
    so.buffer_size = 3;
    so.method = method;
    ViewSelector selector(board, cv::Size(truth.width, truth.height), so);
    for (int f = 0; f < 150; ++f) {
      const Pose T = synth::intrinsicsBoardPose(truth, board, f, 9);
      selector.add(projectedView(truth, board, T, kNoisePx, synth::hashKey(9, f), "frame"));
      ASSERT_LE(selector.held(), so.views + so.buffer_size) << toString(method) << " frame " << f;
    }
    EXPECT_EQ(selector.seen(), 150);
    EXPECT_EQ(static_cast<int>(selector.selected().size()), so.views);
    EXPECT_LE(selector.maxHeld(), so.views + so.buffer_size) << toString(method);
    std::printf("  %s\n", selector.summary().c_str());
  }
}

// Greedy streaming swaps against the exhaustive optimum on a stream small enough to enumerate:
// log det within a small margin of the best 3-subset of 12 views.
TEST(Selection, StreamingLogDetCloseToExhaustiveOptimum) {
  const Camera truth = thesisCamera();
  const BoardSpec board = synth::defaultBoard(BoardType::kChessboard);
  std::vector<ViewObservations> views;
  for (int f = 0; f < 12; ++f) {
    views.push_back(projectedView(truth, board, synth::intrinsicsBoardPose(truth, board, f, 3),
                                  kNoisePx, synth::hashKey(3, f), "frame " + std::to_string(f)));
  }
  SelectionOptions so;
  so.views = 3;
  so.method = SelectionMethod::kInformation;
  so.relinearise_every = 0;  // the exhaustive search below scores at the same linearisation
  ViewSelector streamed(board, cv::Size(truth.width, truth.height), so);
  for (const auto& v : views) streamed.add(v);

  double best = -1e300;
  std::vector<int> best_set;
  for (int a = 0; a < 12; ++a)
    for (int b = a + 1; b < 12; ++b)
      for (int c = b + 1; c < 12; ++c) {
        ViewSelector s(board, cv::Size(truth.width, truth.height), so);
        for (int i : {a, b, c}) s.add(views[i]);
        if (s.objective() > best) {
          best = s.objective();
          best_set = {a, b, c};
        }
      }
  const auto chosen = streamed.selectedIndices();
  std::printf("  streamed log det %.4f (views %d %d %d), exhaustive best %.4f (views %d %d %d)\n",
              streamed.objective(), chosen[0], chosen[1], chosen[2], best, best_set[0],
              best_set[1], best_set[2]);
  // log det differences are log volume ratios: 0.5 means the confidence ellipsoid is at most
  // exp(0.25) = 1.28 times the best one's in volume.
  EXPECT_GE(streamed.objective(), best - 0.5);
}

TEST(Selection, BadOptionsNameTheField) {
  SelectionOptions so;
  so.views = 0;
  try {
    so.validate();
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_EQ(e.context().field, "views");
  }
  EXPECT_THROW(selectionMethodFromString("best"), Error);
  EXPECT_EQ(selectionMethodFromString("plane-angles"), SelectionMethod::kPlaneAngles);
}

}  // namespace
}  // namespace previz::calib
