#include "calib/intrinsics.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>

#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>

#include "calib/detect.h"
#include "core/error.h"
#include "core/io.h"
#include "datasets/studio.h"
#include "tests/calib/solve_fixtures.h"
#include "tests/real_data.h"

namespace previz::calib {
namespace {

using testing::projectedView;
using testing::projectedViews;
using testing::thesisCamera;

double intrinsic(const Camera& c, int k) {
  const double v[kIntrinsicCount] = {c.fx, c.fy, c.cx, c.cy, c.skew,
                                     c.dist.k1, c.dist.k2, c.dist.p1, c.dist.p2, c.dist.k3, c.dist.k4,
                                     c.dist.k5, c.dist.k6};
  return v[k];
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

// ---------------------------------------------------------------------------------------------
// The solver on exact projections plus Gaussian noise (no detector in the loop).

// The sigmas the covariance reports must be the spread the estimates really have: 40 noise
// draws of the same 20 views, the sample standard deviation against the reported sigma.
TEST(Intrinsics, ReportedSigmaMatchesMonteCarloSpread) {
  const Camera truth = thesisCamera();
  const BoardSpec board = synth::defaultBoard(BoardType::kChessboard);
  constexpr int kDraws = 40;
  IntrinsicsOptions options;
  options.joint_covariance = false;
  std::vector<std::vector<double>> estimates(kIntrinsicCount);
  std::array<double, kIntrinsicCount> sigma_sum{};
  for (int draw = 0; draw < kDraws; ++draw) {
    std::vector<ViewObservations> views;
    for (int f = 0; f < 20; ++f) {
      views.push_back(projectedView(truth, board, synth::intrinsicsBoardPose(truth, board, f, 1),
                                    0.1, synth::hashKey(draw, f, 31), "frame"));
    }
    const IntrinsicsResult r = calibrateIntrinsics(views, board, options);
    for (int k = 0; k < kIntrinsicCount; ++k) {
      estimates[k].push_back(intrinsic(r.camera, k));
      sigma_sum[k] += r.sigma[k];
    }
  }
  std::printf("  parameter  spread (%d draws)  mean reported sigma  ratio\n", kDraws);
  for (int k : {0, 1, 2, 3, 5, 6, 9}) {
    double mean = 0, var = 0;
    for (double e : estimates[k]) mean += e / kDraws;
    for (double e : estimates[k]) var += (e - mean) * (e - mean) / (kDraws - 1);
    const double spread = std::sqrt(var), reported = sigma_sum[k] / kDraws;
    std::printf("  %-9s %18.6f %20.6f %6.2f\n", kIntrinsicNames[k], spread, reported, spread / reported);
    // With 40 draws the sample sigma is within +-25 % of the true one at ~2.2 sigma.
    EXPECT_GT(spread / reported, 0.7) << kIntrinsicNames[k];
    EXPECT_LT(spread / reported, 1.35) << kIntrinsicNames[k];
  }
}

TEST(Intrinsics, LocksHoldTheirValuesExactly) {
  Camera truth = thesisCamera();
  truth.fy = 801.0;  // an aspect the lock must keep from the initial camera
  const BoardSpec board = synth::defaultBoard(BoardType::kChessboard);
  const auto views = projectedViews(truth, board, 15, 2, 0.05);
  IntrinsicsOptions options;
  options.locks = IntrinsicLocks::parse("fix_k3, fix_tangential,fix_aspect,fix_principal_point");
  Camera initial = truth;
  initial.fx = 780;
  initial.fy = 780 * 801.0 / 800.0;
  initial.cx = 603.25;
  initial.cy = 447.5;
  initial.dist = {};
  options.initial_camera = initial;
  const IntrinsicsResult r = calibrateIntrinsics(views, board, options);
  EXPECT_EQ(r.camera.cx, 603.25);
  EXPECT_EQ(r.camera.cy, 447.5);
  EXPECT_EQ(r.camera.dist.k3, 0.0);
  EXPECT_EQ(r.camera.dist.p1, 0.0);
  EXPECT_EQ(r.camera.dist.p2, 0.0);
  EXPECT_NEAR(r.camera.fy / r.camera.fx, 801.0 / 800.0, 1e-15);
  EXPECT_EQ(r.sigma[2], 0.0);
  EXPECT_EQ(r.sigma[9], 0.0);
  EXPECT_NEAR(r.sigma[1], r.sigma[0] * 801.0 / 800.0, 1e-12);
  EXPECT_GT(r.sigma[0], 0.0);
  EXPECT_NE(r.fullReport().find("(held)"), std::string::npos);
  // The principal point is held 3.25 px off: the focal length absorbs little of it.
  EXPECT_NEAR(r.camera.fx, truth.fx, 2.0);

  EXPECT_EQ(IntrinsicLocks::parse("fix_distortion").toString(),
            "fix_k1,fix_k2,fix_k3,fix_k4,fix_k5,fix_k6,fix_tangential");
  // The rational model: Brown's k4 k5 k6 free with it (fix_k5 still holds one), held without it;
  // a fisheye never has k5 k6.
  {
    const IntrinsicLocks rational = IntrinsicLocks::parse("rational,fix_k5");
    EXPECT_EQ(rational.toString(), "fix_k5,rational");
    const auto brown = rational.heldMask(LensModel::kBrownConrady);
    EXPECT_FALSE(brown[10]);
    EXPECT_TRUE(brown[11]);
    EXPECT_FALSE(brown[12]);
    const auto plain = IntrinsicLocks{}.heldMask(LensModel::kBrownConrady);
    EXPECT_TRUE(plain[10] && plain[11] && plain[12]);
    const auto kb = rational.heldMask(LensModel::kKannalaBrandt);
    EXPECT_FALSE(kb[10]);
    EXPECT_TRUE(kb[11] && kb[12] && kb[7] && kb[8]);
  }
  try {
    IntrinsicLocks::parse("fix_k3,fix_k9");
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("fix_k9"), std::string::npos);
  }
  IntrinsicsOptions bad;
  bad.locks.fix_focal = true;  // needs an initial camera
  try {
    bad.validate();
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_EQ(e.context().field, "initial_camera");
  }
}

// Gross outliers (mis-detected corners) are dropped, counted, and do not move the estimate.
TEST(Intrinsics, OutliersAreRejectedReportedAndHarmless) {
  const Camera truth = thesisCamera();
  const BoardSpec board = synth::defaultBoard(BoardType::kChessboard);
  auto views = projectedViews(truth, board, 20, 4, 0.05);
  const IntrinsicsResult clean = calibrateIntrinsics(views, board);
  int injected = 0;
  for (size_t v = 0; v < views.size(); v += 2) {
    views[v].points[7].px += Eigen::Vector2d(3.0, -2.0);
    views[v].points[20].px += Eigen::Vector2d(-4.0, 1.0);
    injected += 2;
  }
  const IntrinsicsResult r = calibrateIntrinsics(views, board);
  std::printf("  injected %d outliers: rejected %d in %d re-solves; RMS %.4f px (all %.4f px)\n",
              injected, r.points_rejected, r.rejection_rounds, r.rms_px, r.rms_all_px);
  EXPECT_GE(r.points_rejected, injected);
  EXPECT_LE(r.points_rejected, injected + 3);  // and hardly any good point
  int flagged = 0;
  for (const PointResidual& p : r.residuals) flagged += p.rejected;
  EXPECT_EQ(flagged, r.points_rejected);
  EXPECT_NEAR(r.camera.fx, clean.camera.fx, 0.5 * clean.sigma[0]);
  EXPECT_NEAR(r.camera.cx, clean.camera.cx, 0.5 * clean.sigma[2]);
  EXPECT_LT(r.rms_px, 0.1);
  EXPECT_GT(r.rms_all_px, 0.3);
}

TEST(Intrinsics, TooFewViewsAndMixedSizesAreClearErrors) {
  const Camera truth = thesisCamera();
  const BoardSpec board = synth::defaultBoard(BoardType::kChessboard);
  auto views = projectedViews(truth, board, 4, 5, 0.05);
  views[0].points.clear();
  views[0].failure = "no chessboard found";
  views[1].points.resize(3);
  try {
    calibrateIntrinsics(views, board);
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("only 2 of 4 views"), std::string::npos) << e.what();
  }
  auto mixed = projectedViews(truth, board, 5, 5, 0.05);
  mixed[3].image_size = cv::Size(640, 480);
  mixed[3].source = "odd.png";
  try {
    calibrateIntrinsics(mixed, board);
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_EQ(e.context().file, "odd.png");
  }
  // Views without a board are listed with the detector's reason, not fatal.
  auto some = projectedViews(truth, board, 8, 5, 0.05);
  some[2].points.clear();
  some[2].failure = "no chessboard found";
  const IntrinsicsResult r = calibrateIntrinsics(some, board);
  EXPECT_FALSE(r.views[2].used);
  EXPECT_EQ(r.views[2].dropped_reason, "no chessboard found");
  EXPECT_EQ(r.views_used, 7);
  EXPECT_NE(r.fullReport().find("not used: no chessboard found"), std::string::npos);
}

// ---------------------------------------------------------------------------------------------
// Thesis Table 5.1: the thesis camera (1200 x 900, f 800, c (600, 450), k1 0.2), 20 rendered
// views of a board, blur 1 px, noise 2 grey levels, detected by detectBoard. Seeds vary the
// noise on one rendered set (rendering dominates the cost); median errors over the seeds, and
// every free parameter's truth within 3 sigma. Two models are solved on the same detections:
// "full" (k1 k2 p1 p2 k3, OpenCV's default) and "radial" (k1 k2 k3, tangential held at 0; the
// thesis' simulated lens is radial). The thesis targets are asserted on the radial model:
// with the tangential terms free, p1/p2 trade against the principal point and sigma(c) alone is
// ~0.1 px at this detection noise (the full rows show it).

struct Table51 {
  std::vector<double> dfx, dfy, dcx, dcy, dk1, rms, points;
  int within = 0, checked = 0;
  std::string worst;  // the parameter farthest from the truth in sigmas
  double worst_ratio = 0;
  double median_sigma_f = 0, median_sigma_c = 0;
};

std::pair<Table51, Table51> runTable51(const testing::RenderedSet& set, const std::string& label, int seeds) {
  const Camera truth = thesisCamera();
  const BoardType type = set.board.type;
  Table51 rows[2];
  std::vector<double> sigma_f[2], sigma_c[2];
  for (int seed = 1; seed <= seeds; ++seed) {
    const auto views = testing::detectedViews(set, testing::kTable51Noise, seed);
    for (int m = 0; m < 2; ++m) {
      IntrinsicsOptions options;
      options.joint_covariance = false;
      if (m == 1) options.locks.fix_tangential = true;
      const IntrinsicsResult r = calibrateIntrinsics(views, set.board, options);
      Table51& t = rows[m];
      t.dfx.push_back(std::abs(r.camera.fx - truth.fx));
      t.dfy.push_back(std::abs(r.camera.fy - truth.fy));
      t.dcx.push_back(std::abs(r.camera.cx - truth.cx));
      t.dcy.push_back(std::abs(r.camera.cy - truth.cy));
      t.dk1.push_back(std::abs(r.camera.dist.k1 - truth.dist.k1));
      t.rms.push_back(r.rms_px);
      t.points.push_back(static_cast<double>(r.points_used) / std::max(1, r.views_used));
      sigma_f[m].push_back(r.sigma[0]);
      sigma_c[m].push_back(r.sigma[2]);
      for (int k = 0; k < kIntrinsicCount; ++k) {
        if (!(r.sigma[k] > 0)) continue;
        const double ratio = std::abs(intrinsic(r.camera, k) - intrinsic(truth, k)) / r.sigma[k];
        ++t.checked;
        t.within += ratio <= 3.0;
        if (ratio > t.worst_ratio) {
          t.worst_ratio = ratio;
          t.worst = std::string(kIntrinsicNames[k]) + " (seed " + std::to_string(seed) + ")";
        }
      }
    }
  }
  std::printf("\nTable 5.1 (thesis camera 1200x900, f 800, c (600, 450), k1 0.2; %d views, blur 1 px,"
              " noise 2 grey levels, %d spp; median over %d noise seeds)\n",
              testing::kTable51Views, testing::table51Spp(type), seeds);
  std::printf("  %-10s %-7s %9s %9s %9s %9s %10s %8s %8s %8s %7s  %s\n", "board", "model", "|dfx| px",
              "|dfy| px", "|dcx| px", "|dcy| px", "|dk1|", "sigma fx", "sigma cx", "RMS px",
              "pts/view", "truth within 3 sigma");
  for (int m = 0; m < 2; ++m) {
    Table51& t = rows[m];
    t.median_sigma_f = median(sigma_f[m]);
    t.median_sigma_c = median(sigma_c[m]);
    std::printf("  %-10s %-7s %9.4f %9.4f %9.4f %9.4f %10.6f %8.4f %8.4f %8.4f %7.1f  %d/%d (worst %s at %.2f sigma)\n",
                label.c_str(), m == 0 ? "full" : "radial", median(t.dfx), median(t.dfy),
                median(t.dcx), median(t.dcy), median(t.dk1), t.median_sigma_f, t.median_sigma_c,
                median(t.rms), median(t.points), t.within, t.checked, t.worst.c_str(), t.worst_ratio);
  }
  std::printf("  thesis best: |df| ~0.02 px, |dc| ~0.5 px, |dk1| ~0.001\n");
  return {rows[0], rows[1]};
}

std::pair<Table51, Table51> runTable51(BoardType type, int seeds) {
  return runTable51(testing::table51Set(type), toString(type), seeds);
}

// The thesis targets, asserted as such: median |df| <= 0.05 px, |dc| <= 0.1 px, |dk1| <= 0.001,
// and every truth within 3 sigma. What made f reachable is the corner refiner: cornerSubPix
// alone left 0.020 px of noise a coordinate on the chessboard (twice the Cramer-Rao bound of its
// window) and, on ChArUco, a -0.07 px bias in f from marker edges caught unevenly by its small
// windows under perspective (sigma f 0.042 and 0.096 px, medians 0.065 and 0.073 px). The model
// fit (DetectOptions::model_fit, calib/detail/pattern_fit.h) measures 0.005 px a coordinate
// (sigma f 0.015 and 0.021 px). Checked beyond these seeds: noise seeds 6-25 give 5-seed
// medians 0.007-0.011 px (chessboard) and 0.014-0.036 px (ChArUco); a second rendered pose
// set 0.019-0.022 and 0.008 px. What is left on ChArUco (a +0.015-0.03 px bias) comes from
// the renderer's defocus, a discrete Gaussian on pixel values that shifts edges within a few
// degrees of the pixel axes by up to 0.02 px; rendered with a continuous blur it is +0.009 px.
void expectThesisTargets(const Table51& t) {
  std::printf("  thesis f target (0.05 px): %s (median sigma f %.4f px)\n",
              median(t.dfx) <= 0.05 && median(t.dfy) <= 0.05 ? "met" : "not met", t.median_sigma_f);
  EXPECT_LE(median(t.dfx), 0.05);
  EXPECT_LE(median(t.dfy), 0.05);
  EXPECT_LE(median(t.dcx), 0.1);
  EXPECT_LE(median(t.dcy), 0.1);
  EXPECT_LE(median(t.dk1), 0.001);
  EXPECT_EQ(t.within, t.checked) << "worst: " << t.worst << " at " << t.worst_ratio << " sigma";
}

TEST(Intrinsics, Table51ChessboardMeetsThesisTargets) {
  const auto [full, radial] = runTable51(BoardType::kChessboard, 5);
  expectThesisTargets(radial);
  EXPECT_EQ(full.within, full.checked) << "worst: " << full.worst << " at " << full.worst_ratio;
}

TEST(Intrinsics, Table51CharucoMeetsThesisTargets) {
  const auto [full, radial] = runTable51(BoardType::kCharuco, 5);
  expectThesisTargets(radial);
  EXPECT_EQ(full.within, full.checked) << "worst: " << full.worst << " at " << full.worst_ratio;
}

// AprilGrid corners are refined by cornerSubPix alone (detect.h model_fit) and circle centres
// carry the perspective bias of ellipse centres (calib/frontal.h removes it). Their sigma f at
// this noise is 0.068 and 0.044 px, so the thesis' 0.05 px is not a bound two seeds can be held
// to; they are held to 4 sigma and to the truth within 3 sigma (measured medians: AprilGrid
// |dfx| 0.042 px, circles 0.011 px).
void expectWithinSigma(const Table51& t) {
  EXPECT_LE(median(t.dfx), 4 * t.median_sigma_f);
  EXPECT_LE(median(t.dfy), 4 * t.median_sigma_f);
  EXPECT_LE(median(t.dcx), 4 * t.median_sigma_c);
  EXPECT_LE(median(t.dk1), 0.002);
  EXPECT_EQ(t.within, t.checked) << "worst: " << t.worst << " at " << t.worst_ratio << " sigma";
}

TEST(Intrinsics, Table51AprilGridMeasured) {
  const auto [full, radial] = runTable51(BoardType::kAprilGrid, 2);
  expectWithinSigma(radial);
}

// The same scene with the AprilGrid as Kalibr prints it (tag 0 at the bottom left, Kalibr's point
// ids, 2-cell tag borders, which also give cornerSubPix a wider window): the same bounds.
TEST(Intrinsics, Table51KalibrAprilGridMeasured) {
  BoardSpec board = testing::thesisBoard(BoardType::kAprilGrid);
  board.layout = AprilGridLayout::kKalibr;
  board.tag_border_cells = 2;
  const auto& set = testing::renderedSet(thesisCamera(), board, testing::kTable51Views, 1, testing::kTable51Blur,
                                         testing::table51Spp(BoardType::kAprilGrid));
  const auto [full, radial] = runTable51(set, "kalibr grid", 2);
  expectWithinSigma(radial);
}

TEST(Intrinsics, Table51CirclesMeasured) {
  const auto [full, radial] = runTable51(BoardType::kCircles, 2);
  expectWithinSigma(radial);
}

// Quadtree ArUco board (the thesis' own design, 5 x 5 cells of 12 cm, 3 levels): marker corners
// are L-shaped, refined by cornerSubPix and then from the markers' edges (detect_quadtree.cpp);
// the centre cell's 24 mm markers come out only in the nearer views (187 of 256 points a view).
// Measured (2 seeds, radial): |dfx| 0.022 px, |dfy| 0.018, |dcx| 0.021, |dcy| 0.049, |dk1|
// 0.00013, sigma f 0.080 px: the thesis targets are met here, but with sigma f 0.08 px two
// seeds cannot hold the 0.05 px bound, so it is held like AprilGrid and circles: to 4 sigma
// and every truth within 3 sigma (full model too).
TEST(Intrinsics, Table51QuadtreeMeasured) {
  const auto [full, radial] = runTable51(BoardType::kQuadtree, 2);
  expectWithinSigma(radial);
  EXPECT_EQ(full.within, full.checked) << "worst: " << full.worst << " at " << full.worst_ratio;
}

// ---------------------------------------------------------------------------------------------
// Real data: OpenCV's left camera sample images (9 x 6 inner corners, square 1 unit).

TEST(Intrinsics, RealChessboardAgreesWithOpenCv) {
  const std::filesystem::path dir = std::filesystem::path(PREVIZ_SHARED_DATA) / "opencv-chessboard";
  std::vector<std::filesystem::path> files;
  if (std::filesystem::is_directory(dir)) {
    for (const auto& entry : std::filesystem::directory_iterator(dir)) {
      const std::string name = entry.path().filename().string();
      if (name.rfind("left", 0) == 0 && entry.path().extension() == ".jpg") files.push_back(entry.path());
    }
  }
  std::sort(files.begin(), files.end());
  ASSERT_EQ(files.size(), 13u) << "expected 13 images " << (dir / "left*.jpg").string();

  const BoardSpec board = previz::test::opencvSampleBoard();
  std::vector<ViewObservations> views;
  for (const auto& f : files) {
    const cv::Mat image = readImage(f, cv::IMREAD_GRAYSCALE);
    ViewObservations v = detectBoard(image, board, {}, f.filename().string());
    v.image_size = image.size();
    views.push_back(v);
  }
  const IntrinsicsResult ours = calibrateIntrinsics(views, board);

  // OpenCV on the very same detections, default model and flags.
  std::vector<std::vector<cv::Point3f>> object;
  std::vector<std::vector<cv::Point2f>> image;
  std::map<int, Eigen::Vector3d> points;
  for (const BoardPoint& p : boardPoints(board)) points[p.id] = p.p_board;
  for (const auto& v : views) {
    if (!v.found()) continue;
    object.emplace_back();
    image.emplace_back();
    for (const Observation& o : v.points) {
      const Eigen::Vector3d& p = points.at(o.id);
      object.back().emplace_back(p.x(), p.y(), p.z());
      image.back().emplace_back(o.px.x(), o.px.y());
    }
  }
  cv::Mat K, dist;
  std::vector<cv::Mat> rvecs, tvecs;
  const double cv_rms = cv::calibrateCamera(object, image, views.front().image_size, K, dist, rvecs, tvecs);
  std::printf("\nReal data (%zu images, %zu with the board): ours vs cv::calibrateCamera on the same detections\n",
              views.size(), object.size());
  std::printf("  %-8s %9s %9s %9s %9s %10s %10s %10s %9s\n", "", "fx", "fy", "cx", "cy", "k1", "k2",
              "k3", "RMS px");
  std::printf("  %-8s %9.3f %9.3f %9.3f %9.3f %10.5f %10.5f %10.5f %9.4f (all points %.4f, %d rejected)\n",
              "ours", ours.camera.fx, ours.camera.fy, ours.camera.cx, ours.camera.cy,
              ours.camera.dist.k1, ours.camera.dist.k2, ours.camera.dist.k3, ours.rms_px,
              ours.rms_all_px, ours.points_rejected);
  std::printf("  %-8s %9.3f %9.3f %9.3f %9.3f %10.5f %10.5f %10.5f %9.4f\n", "sigma", ours.sigma[0],
              ours.sigma[1], ours.sigma[2], ours.sigma[3], ours.sigma[5], ours.sigma[6], ours.sigma[9], 0.0);
  std::printf("  %-8s %9.3f %9.3f %9.3f %9.3f %10.5f %10.5f %10.5f %9.4f\n", "opencv", K.at<double>(0, 0),
              K.at<double>(1, 1), K.at<double>(0, 2), K.at<double>(1, 2), dist.at<double>(0),
              dist.at<double>(1), dist.at<double>(4), cv_rms);
  EXPECT_LE(ours.rms_all_px, cv_rms + 0.01);
  EXPECT_NEAR(ours.camera.fx, K.at<double>(0, 0), 3 * ours.sigma[0]);
  EXPECT_NEAR(ours.camera.cx, K.at<double>(0, 2), 3 * ours.sigma[2]);
}

// The model fit on real corners (no truth here): the same 13 images calibrated with the
// corners cornerSubPix gives and with the fitted ones. Fitted corners agree with one camera
// model better: RMS 0.2116 -> 0.1600 px measured (0.1836 -> 0.1603 px when the images are read
// as not sRGB-encoded; the right camera 0.2335 -> 0.1579 px).
TEST(Intrinsics, RealChessboardModelFitLowersResidual) {
  const std::filesystem::path dir = std::filesystem::path(PREVIZ_SHARED_DATA) / "opencv-chessboard";
  std::vector<std::filesystem::path> files;
  if (std::filesystem::is_directory(dir)) {
    for (const auto& entry : std::filesystem::directory_iterator(dir)) {
      const std::string name = entry.path().filename().string();
      if (name.rfind("left", 0) == 0 && entry.path().extension() == ".jpg") files.push_back(entry.path());
    }
  }
  ASSERT_EQ(files.size(), 13u) << "expected 13 images " << (dir / "left*.jpg").string();
  BoardSpec board;
  board.type = BoardType::kChessboard;
  board.rows = 7;
  board.cols = 10;
  board.square_m = 1.0;
  board.margin_m = 0.5;
  double rms[2];
  for (int fit = 0; fit < 2; ++fit) {
    DetectOptions options;
    options.model_fit = fit == 1;
    std::vector<ViewObservations> views;
    for (const auto& f : files) {
      const cv::Mat image = readImage(f, cv::IMREAD_GRAYSCALE);
      views.push_back(detectBoard(image, board, options, f.filename().string()));
      views.back().image_size = image.size();
    }
    const IntrinsicsResult r = calibrateIntrinsics(views, board);
    rms[fit] = r.rms_all_px;
    std::printf("  %s: RMS %.4f px, fx %.3f +- %.3f\n", fit ? "model fit  " : "cornerSubPix",
                r.rms_all_px, r.camera.fx, r.sigma[0]);
  }
  EXPECT_LT(rms[1], 0.85 * rms[0]);
}

}  // namespace
}  // namespace previz::calib
