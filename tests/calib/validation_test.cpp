#include "calib/validation.h"

#include <cmath>
#include <cstdio>
#include <filesystem>

#include <Eigen/Eigenvalues>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "calib/report.h"
#include "core/error.h"
#include "core/io.h"
#include "tests/calib/solve_fixtures.h"
#include "scratch.h"

namespace previz::calib {
namespace {

using testing::projectedView;
using testing::projectedViews;
using testing::thesisCamera;

void printCross(const char* what, const CrossValidationResult& r) {
  std::printf("\n%s\n%s", what, r.report().c_str());
}

// A right model on a good capture: the two halves differ by what their covariances predict.
TEST(Validation, CrossValidationOfGoodCaptureIsWithinPredictedUncertainty) {
  const Camera truth = thesisCamera();
  const BoardSpec board = synth::defaultBoard(BoardType::kChessboard);
  for (std::uint64_t seed : {1, 2, 3}) {
    const auto views = projectedViews(truth, board, 30, seed, 0.05);
    const CrossValidationResult r = crossValidate(views, board);
    printCross(("projected views, 0.05 px noise, seed " + std::to_string(seed)).c_str(), r);
    EXPECT_TRUE(r.consistent);
    EXPECT_LT(r.normalised_rms, 1.6);
    EXPECT_LT(r.fraction_beyond_3sigma, 0.05);
  }
  // The rendered thesis scene (detector in the loop), radial model.
  const auto& set = testing::table51Set(BoardType::kChessboard);
  CrossValidationOptions options;
  options.solve.locks.fix_tangential = true;
  const CrossValidationResult r =
      crossValidate(testing::detectedViews(set, testing::kTable51Noise, 1), set.board, options);
  printCross("rendered thesis scene (chessboard, 20 views)", r);
  EXPECT_TRUE(r.consistent);
  EXPECT_LT(r.fraction_beyond_3sigma, 0.05);
}

// A lens with k3 fitted with k3 held at 0: the residuals stay small (k1, k2 absorb most of it)
// but the halves disagree far beyond their predicted uncertainty.
TEST(Validation, CrossValidationFlagsWrongDistortionModel) {
  Camera truth = thesisCamera();
  const BoardSpec board = synth::defaultBoard(BoardType::kChessboard);
  CrossValidationOptions options;
  options.solve.locks.fix_k3 = true;
  for (double k3 : {0.4, -0.3}) {
    truth.dist.k3 = k3;
    for (std::uint64_t seed : {1, 2, 3}) {
      const auto views = projectedViews(truth, board, 30, seed, 0.05);
      const CrossValidationResult r = crossValidate(views, board, options);
      printCross(("true k3 = " + std::to_string(k3) + ", fitted with k3 held at 0, seed " +
                  std::to_string(seed)).c_str(), r);
      EXPECT_FALSE(r.consistent);
      EXPECT_GT(r.normalised_rms, 2.0);
      // ... while the RMS alone looks innocent (under twice the 0.07 px of a right model).
      EXPECT_LT(r.a.rms_px, 0.14);
    }
  }
}

// The uncertainty map is the spread real estimates have: 40 noise draws, projection of fixed
// rays through each estimate, sample spread against the predicted worst-direction sigma.
TEST(Validation, UncertaintyMapMatchesMonteCarloSpread) {
  const Camera truth = thesisCamera();
  const BoardSpec board = synth::defaultBoard(BoardType::kChessboard);
  std::vector<Pose> poses;
  for (int f = 0; f < 15; ++f) poses.push_back(synth::intrinsicsBoardPose(truth, board, f, 7));
  auto draw = [&](int d) {
    std::vector<ViewObservations> views;
    for (size_t f = 0; f < poses.size(); ++f)
      views.push_back(projectedView(truth, board, poses[f], 0.1, synth::hashKey(d, f, 99), "f"));
    return views;
  };
  IntrinsicsOptions io;
  io.joint_covariance = false;
  const IntrinsicsResult reference = calibrateIntrinsics(draw(0), board, io);
  UncertaintyOptions uo;
  uo.grid_cols = 8;
  const UncertaintyMap map = projectionUncertainty(reference, uo);
  constexpr int kDraws = 40;
  std::vector<std::vector<Eigen::Vector2d>> projections(map.grid.rows * map.grid.cols);
  for (int d = 1; d <= kDraws; ++d) {
    const IntrinsicsResult r = calibrateIntrinsics(draw(d), board, io);
    for (int row = 0; row < map.grid.rows; ++row)
      for (int col = 0; col < map.grid.cols; ++col) {
        const auto ray = truth.unproject(map.grid.pixel(row, col));
        projections[row * map.grid.cols + col].push_back(*r.camera.project(*ray));
      }
  }
  double ratio_sum = 0;
  int n = 0;
  std::printf("  grid point      predicted sigma   Monte Carlo sigma (worst direction)\n");
  for (int row = 0; row < map.grid.rows; ++row) {
    for (int col = 0; col < map.grid.cols; ++col) {
      const auto& p = projections[row * map.grid.cols + col];
      Eigen::Vector2d mean = Eigen::Vector2d::Zero();
      for (const auto& q : p) mean += q / p.size();
      Eigen::Matrix2d C = Eigen::Matrix2d::Zero();
      for (const auto& q : p) C += (q - mean) * (q - mean).transpose() / (p.size() - 1);
      const double mc = std::sqrt(Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d>(C).eigenvalues()(1));
      const double predicted = map.sigma_px.at<double>(row, col);
      if (row % 2 == 0 && col % 3 == 0)
        std::printf("  (%4.0f, %4.0f) %16.4f %19.4f\n", map.grid.pixel(row, col).x(),
                    map.grid.pixel(row, col).y(), predicted, mc);
      ratio_sum += mc / predicted;
      ++n;
    }
  }
  const double ratio = ratio_sum / n;
  std::printf("  mean Monte Carlo / predicted: %.3f over %d grid points\n", ratio, n);
  EXPECT_GT(ratio, 0.75);
  EXPECT_LT(ratio, 1.3);
}

TEST(Validation, MeanFramesUncertaintyGrowsTowardsTheCorners) {
  const Camera truth = thesisCamera();
  const BoardSpec board = synth::defaultBoard(BoardType::kChessboard);
  const IntrinsicsResult r = calibrateIntrinsics(projectedViews(truth, board, 20, 3, 0.05), board);
  UncertaintyOptions uo;
  uo.mode = UncertaintyMode::kMeanFrames;
  const UncertaintyMap frames = projectionUncertainty(r, uo);
  uo.mode = UncertaintyMode::kIntrinsicsOnly;
  const UncertaintyMap intrinsics = projectionUncertainty(r, uo);
  std::printf("  intrinsics-only: centre %.4f corners %.4f mean %.4f px; mean-frames (2 m): centre "
              "%.4f corners %.4f mean %.4f px\n",
              intrinsics.centre_px, intrinsics.corners_px, intrinsics.mean_px, frames.centre_px,
              frames.corners_px, frames.mean_px);
  // Where the boards were, the frames pin the projection; the corners extrapolate.
  EXPECT_LT(frames.centre_px, 0.5 * frames.corners_px);
  // Most of the intrinsics-only centre value is a principal-point shift a rotation absorbs.
  EXPECT_LT(frames.centre_px, intrinsics.centre_px);
  IntrinsicsResult no_cov = r;
  no_cov.covariance_ok = false;
  EXPECT_THROW(projectionUncertainty(no_cov), Error);
}

// The report a person reads: JSON with the figures, and the four pictures.
TEST(Validation, ReportWritesJsonAndPictures) {
  const Camera truth = thesisCamera();
  const BoardSpec board = synth::defaultBoard(BoardType::kChessboard);
  auto views = projectedViews(truth, board, 12, 4, 0.05);
  views[3].points.clear();
  views[3].failure = "no chessboard found";
  views[5].points[10].px += Eigen::Vector2d(4, 4);
  CalibReport report;
  report.result = calibrateIntrinsics(views, board);
  report.board = board;
  report.views = views;
  UncertaintyOptions uo;
  uo.mode = UncertaintyMode::kMeanFrames;
  report.uncertainty = projectionUncertainty(report.result, uo);
  const std::filesystem::path stem = test::scratchDir("calib_report", "report") / "cam";
  const ReportFiles files = writeCalibReport(report, stem);
  for (const auto& f : {files.json, files.residuals, files.coverage, files.uncertainty, files.views}) {
    ASSERT_TRUE(std::filesystem::exists(f)) << f;
  }
  const nlohmann::json j = readJsonFile(files.json);
  EXPECT_EQ(j["points_rejected"].get<int>(), 1);
  EXPECT_NEAR(j["camera"]["fx"].get<double>(), truth.fx, 3 * report.result.sigma[0]);
  EXPECT_EQ(j["images"][3]["failure"].get<std::string>(), "no chessboard found");
  EXPECT_FALSE(j["solved_views"][3]["used"].get<bool>());
  EXPECT_GT(j["uncertainty"]["max_px"].get<double>(), 0.0);
  const cv::Mat residuals = cv::imread(files.residuals.string());
  EXPECT_EQ(residuals.cols, 1200);
  EXPECT_FALSE(cv::imread(files.views.string()).empty());
}

}  // namespace
}  // namespace previz::calib
