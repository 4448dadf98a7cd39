// Board detection against the synthetic studio's exact truth (datasets/rigs.h
// visibleBoardPoints: Camera::project of boardPoints() through the true distorted lens), and
// against OpenCV's own chessboard pipeline on real images.
#include "calib/detect.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/error.h"
#include "scratch.h"
#include "core/io.h"
#include "core/pose.h"
#include "datasets/render.h"
#include "datasets/rigs.h"
#include "datasets/studio.h"

namespace fs = std::filesystem;

namespace previz::calib {
namespace {

using synth::BoardObservation;

constexpr double kDeg = M_PI / 180.0;

// 640 x 480 with strong barrel distortion and some decentring: a detector that ignored lens
// curvature between points, or was off by half a pixel, would show.
Camera distortedCamera() {
  Camera c;
  c.name = "test";
  c.width = 640;
  c.height = 480;
  c.fx = c.fy = 480.0;
  c.cx = 322.7;
  c.cy = 236.4;
  c.dist.k1 = -0.22;
  c.dist.k2 = 0.05;
  c.dist.p1 = 0.0007;
  c.dist.p2 = -0.0005;
  return c;
}

// The board's centre on the ray through target_px, at the distance where the board (margin
// included) spans 'coverage' of the image width when frontal; then tilted about its x and y
// axes and rolled about the optical axis.
Pose boardPose(const Camera& camera, const BoardSpec& spec, double coverage, double tilt_x_deg,
               double tilt_y_deg, double roll_deg, const Eigen::Vector2d& target_frac) {
  const Eigen::Vector2d size = spec.size_m();
  const double width_m = size.x() + 2 * spec.margin_m;
  const double distance = camera.fx * width_m / (coverage * camera.width);
  const Eigen::Matrix3d R = (Eigen::AngleAxisd(roll_deg * kDeg, Eigen::Vector3d::UnitZ()) *
                             Eigen::AngleAxisd(tilt_x_deg * kDeg, Eigen::Vector3d::UnitX()) *
                             Eigen::AngleAxisd(tilt_y_deg * kDeg, Eigen::Vector3d::UnitY()))
                                .toRotationMatrix();
  const Eigen::Vector2d px(target_frac.x() * (camera.width - 1),
                           target_frac.y() * (camera.height - 1));
  const Eigen::Vector3d ray = *camera.unproject(px);
  Pose T = Pose::Identity();
  T.linear() = R;
  T.translation() =
      ray / ray.z() * distance - R * Eigen::Vector3d(0.5 * size.x(), 0.5 * size.y(), 0);
  return T;
}

struct View {
  cv::Mat bgr;
  std::map<int, Eigen::Vector2d> truth;  // id -> true pixel of every visible board point
};

// 16 samples per pixel (4 x 4 n-rooks: 17 coverage levels on near-axis edges); with the default
// 4 the edges of a frontal board are quantised to 1/4 px along their whole length.
synth::RenderOptions sharpRender() {
  synth::RenderOptions options;
  options.samples_per_pixel = 16;
  return options;
}

View renderUncached(const Camera& camera, const BoardSpec& spec, const Pose& T_cam_board,
                    const synth::RenderOptions& options) {
  static const synth::Studio studio([] {
    synth::StudioConfig config;
    config.with_actor = false;
    config.with_prop = false;
    return config;
  }());
  const Pose T_world_cam = synth::mainCameraPose(0.0, 1.0, false);
  const Pose T_world_board = T_world_cam * T_cam_board;
  synth::Scene scene = studio.sceneAt(0.0, synth::kLayerStage);
  scene.add(synth::makeBoard(spec, T_world_board));
  View view;
  view.bgr = synth::renderView(camera, T_world_cam, scene, options).bgr;
  for (const BoardObservation& o :
       synth::visibleBoardPoints(camera, T_world_cam, spec, T_world_board, scene))
    view.truth[o.id] = o.px;
  return view;
}

// Several tests read the same views (refined / unrefined, legacy print with either layout):
// render each once.
View render(const Camera& camera, const BoardSpec& spec, const Pose& T_cam_board,
            const synth::RenderOptions& options = sharpRender()) {
  static std::map<std::string, View> cache;
  std::string key = boardToJson(spec).dump() + poseToJson(T_cam_board).dump() +
                    std::to_string(camera.fx) + "/" + std::to_string(options.samples_per_pixel) +
                    "/" + std::to_string(options.blur_sigma_px) + "/" +
                    std::to_string(options.noise_sigma);
  auto it = cache.find(key);
  if (it == cache.end())
    it = cache.emplace(key, renderUncached(camera, spec, T_cam_board, options)).first;
  return it->second;
}

double median(std::vector<double> v) {
  if (v.empty()) return NAN;
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}
double maxOf(const std::vector<double>& v) {
  return v.empty() ? NAN : *std::max_element(v.begin(), v.end());
}

struct PoseCase {
  double coverage, tilt_x, tilt_y, roll;
  Eigen::Vector2d target;
};
// Frontal, tilted both ways up to 35 degrees, a quarter turn, upside down, off centre (where the
// distortion is strongest).
const std::vector<PoseCase> kPoses = {
    {0.70, 0, 0, 0, {0.5, 0.5}},        {0.62, 25, -15, 10, {0.45, 0.47}},
    {0.58, -30, 20, -15, {0.55, 0.52}}, {0.62, 15, 30, 98, {0.5, 0.5}},
    {0.55, -20, -25, 185, {0.47, 0.5}}, {0.50, 35, 10, 25, {0.38, 0.4}},
};

// The 180-degree image of a point id on a board with a grid of nc x nr points (row-major).
int halfTurn(int id, int nc, int nr) { return (nr - 1 - id / nc) * nc + (nc - 1 - id % nc); }

struct Figures {
  std::vector<double> errors;
  int views_found = 0, points = 0, truth_points = 0;
};

// Detects in every pose, checks that every detected id is a visible board point with the right
// id (symmetric: up to the board's half turn, resolved by the documented convention) and
// collects the pixel errors.
Figures runPoses(const BoardSpec& spec, const DetectOptions& options_in, bool symmetric,
                 const synth::RenderOptions& render_options = sharpRender()) {
  const Camera camera = distortedCamera();
  Figures fig;
  const DetectOptions& options = options_in;
  for (size_t k = 0; k < kPoses.size(); ++k) {
    const PoseCase& p = kPoses[k];
    const Pose T = boardPose(camera, spec, p.coverage, p.tilt_x, p.tilt_y, p.roll, p.target);
    const View view = render(camera, spec, T, render_options);
    const ViewObservations obs = detectBoard(view.bgr, spec, options, "pose " + std::to_string(k));
    fig.truth_points += static_cast<int>(view.truth.size());
    EXPECT_TRUE(obs.found()) << "pose " << k << ": " << obs.failure;
    if (!obs.found()) continue;
    ++fig.views_found;
    const int nc = spec.type == BoardType::kCircles ? spec.cols : spec.cols - 1;
    const int nr = spec.type == BoardType::kCircles ? spec.rows : spec.rows - 1;
    // Which of the two symmetric labellings the detector chose (decided on the first point).
    bool flipped = false;
    if (symmetric) {
      const Observation& o = obs.points.front();
      const auto direct = view.truth.find(o.id);
      const auto turned = view.truth.find(halfTurn(o.id, nc, nr));
      const double d_direct = direct == view.truth.end() ? 1e9 : (direct->second - o.px).norm();
      const double d_turned = turned == view.truth.end() ? 1e9 : (turned->second - o.px).norm();
      flipped = d_turned < d_direct;
    }
    std::set<int> ids;
    std::vector<double> errors;
    for (const Observation& o : obs.points) {
      EXPECT_TRUE(ids.insert(o.id).second) << "pose " << k << ": id " << o.id << " twice";
      const int truth_id = flipped ? halfTurn(o.id, nc, nr) : o.id;
      const auto it = view.truth.find(truth_id);
      if (it == view.truth.end()) {
        ADD_FAILURE() << "pose " << k << ": id " << o.id << " is not visible";
        continue;
      }
      errors.push_back((it->second - o.px).norm());
    }
    EXPECT_LT(maxOf(errors), 1.0) << "pose " << k << ": a point with a wrong id or off its corner";
    if (symmetric) {
      // Convention: board +x points to the right in the image (u grows from column 0 to the
      // last column along the middle row of the grid as detected).
      std::map<int, Eigen::Vector2d> by_id;
      for (const Observation& o : obs.points) by_id[o.id] = o.px;
      const int r = nr / 2;
      const auto first = by_id.find(r * nc), last = by_id.find(r * nc + nc - 1);
      if (first != by_id.end() && last != by_id.end()) {
        EXPECT_GT(last->second.x(), first->second.x()) << "pose " << k << ": +x points left";
      }
    }
    std::printf("  pose %zu: %zu of %zu visible points, median %.4f px, max %.4f px%s\n", k,
                obs.points.size(), view.truth.size(), median(errors), maxOf(errors),
                flipped ? " (half turn)" : "");
    fig.points += static_cast<int>(obs.points.size());
    fig.errors.insert(fig.errors.end(), errors.begin(), errors.end());
  }
  std::printf("%s: %d/%zu views, %d of %d visible points, median %.4f px, max %.4f px\n",
              toString(spec.type), fig.views_found, kPoses.size(), fig.points, fig.truth_points,
              median(fig.errors), maxOf(fig.errors));
  return fig;
}

TEST(DetectChessboard, IdsMatchTruthAndMedianErrorBelowFiveHundredthsPixel) {
  const BoardSpec spec = synth::defaultBoard(BoardType::kChessboard);  // 7 x 10: asymmetric
  const Figures fig = runPoses(spec, {}, false);
  EXPECT_EQ(fig.views_found, static_cast<int>(kPoses.size()));
  EXPECT_GE(fig.points, 0.9 * fig.truth_points);
  EXPECT_LE(median(fig.errors), 0.05);
}

TEST(DetectChessboard, SymmetricBoardFollowsTheRightwardConvention) {
  BoardSpec spec = synth::defaultBoard(BoardType::kChessboard);
  spec.rows = 7;
  spec.cols = 9;  // 7 + 9 even: the same under a half turn
  const Figures fig = runPoses(spec, {}, true);
  EXPECT_EQ(fig.views_found, static_cast<int>(kPoses.size()));
  EXPECT_LE(median(fig.errors), 0.05);
}

TEST(DetectCharuco, IdsMatchTruthAndMedianErrorBelowFiveHundredthsPixel) {
  const BoardSpec spec = synth::defaultBoard(BoardType::kCharuco);  // 7 rows
  const Figures fig = runPoses(spec, {}, false);
  EXPECT_EQ(fig.views_found, static_cast<int>(kPoses.size()));
  EXPECT_GE(fig.points, 0.85 * fig.truth_points);
  EXPECT_LE(median(fig.errors), 0.05);
}

// OpenCV 4.6 changed the ChArUco layout for even row counts; both prints must be read with the
// layout the board JSON names. A legacy print read with the current layout is the assumed board
// moved by one square (9 columns): every local fit agrees, so only the layout checks stand
// between it and corners with wrong ids; none may come out.
TEST(DetectCharuco, EvenRowLayoutsBothMatchTruthAndAMismatchGivesNoWrongIds) {
  for (bool legacy : {false, true}) {
    BoardSpec spec = synth::defaultBoard(BoardType::kCharuco);
    spec.rows = 6;
    spec.cols = 9;
    spec.legacy_pattern = legacy;
    std::printf("legacy_pattern = %d\n", legacy);
    const Figures fig = runPoses(spec, {}, false);
    EXPECT_EQ(fig.views_found, static_cast<int>(kPoses.size()));
    EXPECT_GE(fig.points, 0.85 * fig.truth_points);
    EXPECT_LE(median(fig.errors), 0.05);
  }
  BoardSpec printed = synth::defaultBoard(BoardType::kCharuco);
  printed.rows = 6;
  printed.cols = 9;
  printed.legacy_pattern = true;
  BoardSpec assumed = printed;
  assumed.legacy_pattern = false;
  const Camera camera = distortedCamera();
  int wrong = 0, returned = 0;
  for (const PoseCase& p : kPoses) {
    const View view =
        render(camera, printed,
               boardPose(camera, printed, p.coverage, p.tilt_x, p.tilt_y, p.roll, p.target));
    const ViewObservations obs = detectBoard(view.bgr, assumed);
    std::printf("  legacy print read as current: %zu points; '%s'\n", obs.points.size(),
                obs.failure.c_str());
    for (const Observation& o : obs.points) {
      ++returned;
      const auto it = view.truth.find(o.id);
      if (it == view.truth.end() || (it->second - o.px).norm() > 1.0) ++wrong;
    }
  }
  std::printf("legacy print, current layout assumed: %d points returned, %d wrong\n", returned,
              wrong);
  EXPECT_EQ(wrong, 0);
}

// Refined corners within 0.1 px (median). Without refinement the detector returns
// libapriltag's corners shifted to OpenCV's pixel convention: they must already sit on the
// corners to well under a pixel (with the wrong half-pixel convention they would be ~0.7 px off
// and cornerSubPix would start off its corner).
TEST(DetectAprilGrid, CornersWithinTenthPixelAndUnrefinedWithinHalfPixel) {
  const BoardSpec spec = synth::defaultBoard(BoardType::kAprilGrid);
  const Figures fig = runPoses(spec, {}, false);
  EXPECT_EQ(fig.views_found, static_cast<int>(kPoses.size()));
  EXPECT_GE(fig.points, 0.85 * fig.truth_points);
  EXPECT_LE(median(fig.errors), 0.1);
  DetectOptions unrefined;
  unrefined.subpixel = false;
  const Figures raw = runPoses(spec, unrefined, false);
  EXPECT_EQ(raw.views_found, static_cast<int>(kPoses.size()));
  EXPECT_LE(median(raw.errors), 0.5);
}

// Kalibr's layout rendered by the synthetic studio (tag 0 at the bottom left, 2-cell tag
// borders): the same accuracy as previz's own layout, every point id Kalibr's (runPoses compares
// each with boardPoints' position for that id).
TEST(DetectAprilGrid, KalibrLayoutCornersWithinTenthPixel) {
  BoardSpec spec = synth::defaultBoard(BoardType::kAprilGrid);
  spec.layout = AprilGridLayout::kKalibr;
  spec.tag_border_cells = 2;
  const Figures fig = runPoses(spec, {}, false);
  std::printf("kalibr layout: %d of %d views, %d of %d points, median %.4f px\n", fig.views_found,
              static_cast<int>(kPoses.size()), fig.points, fig.truth_points, median(fig.errors));
  EXPECT_EQ(fig.views_found, static_cast<int>(kPoses.size()));
  EXPECT_GE(fig.points, 0.85 * fig.truth_points);
  EXPECT_LE(median(fig.errors), 0.1);
}

// Real Kalibr AprilGrids (../shared/data/aprilgrid-kalibr): a drone camera's view of a 6 x 6 grid
// (EuRoC, turned upside down) and a phone's view of a 6 x 11 print; Kalibr's aprilgrid.yaml as the
// board. Every tag is found (36 and 66, the counts aprilgrid-rs's tests expect) with no bit
// errors, and the points are numbered as Kalibr numbers them: each tag's four corners, mapped
// through the homography they define, put the next tag's corners (right and above, by Kalibr's
// ids) where they were found, to a few percent of a tag (a wrong or mirrored numbering misses by
// whole tags).
TEST(DetectAprilGridReal, KalibrBoardsEveryTagFoundNumberedAsKalibr) {
  const fs::path dir = fs::path(PREVIZ_SHARED_DATA) / "aprilgrid-kalibr";
  struct Case {
    const char* image;
    int rows, cols;
    double tag_m;
  };
  const Case cases[] = {{"EuRoC.png", 6, 6, 0.088}, {"iphone.png", 6, 11, 0.03}};
  for (const Case& c : cases) {
    const fs::path yaml = test::scratchDir("detect", "kalibr") / (std::string(c.image) + ".yaml");
    {
      std::ofstream out(yaml);
      out << "target_type: 'aprilgrid' #gridtype\ntagCols: " << c.cols << "\ntagRows: " << c.rows
          << "\ntagSize: " << c.tag_m << "\ntagSpacing: 0.3\n";
    }
    const BoardSpec spec = readBoard(yaml);
    const cv::Mat image = cv::imread((dir / c.image).string(), cv::IMREAD_GRAYSCALE);
    ASSERT_FALSE(image.empty()) << "real data missing: " << (dir / c.image) << " (../shared/data, see its README)";
    const ViewObservations obs = detectBoard(image, spec, {}, c.image);
    int exact = 0;
    for (const DecodedTag& tag : obs.tags) exact += tag.bit_errors == 0;
    EXPECT_EQ(static_cast<int>(obs.tags.size()), c.rows * c.cols) << c.image << ": " << obs.failure;
    EXPECT_EQ(exact, c.rows * c.cols) << c.image;
    std::map<int, Eigen::Vector3d> board;
    for (const BoardPoint& bp : boardPoints(spec)) board[bp.id] = bp.p_board;
    std::map<int, cv::Point2f> px;
    for (const Observation& o : obs.points) px[o.id] = cv::Point2f(static_cast<float>(o.px.x()), static_cast<float>(o.px.y()));
    const int width = 2 * c.cols;  // Kalibr: points a row of the corner grid
    int checked = 0;
    double worst = 0;
    for (int tag = 0; tag < c.rows * c.cols; ++tag) {
      const int bl = 2 * (tag / c.cols) * width + 2 * (tag % c.cols);
      const int own[4] = {bl, bl + 1, bl + width + 1, bl + width};
      std::vector<cv::Point2f> from, to;
      for (int id : own)
        if (px.count(id)) {
          from.emplace_back(static_cast<float>(board[id].x()), static_cast<float>(board[id].y()));
          to.push_back(px[id]);
        }
      if (from.size() < 4) continue;
      const cv::Mat H = cv::getPerspectiveTransform(from, to);
      const double edge = cv::norm(to[1] - to[0]);
      for (int next : {bl + 2, bl + 2 * width}) {  // the tag to the right, the tag above
        if (!px.count(next) || (next == bl + 2 && tag % c.cols == c.cols - 1)) continue;
        std::vector<cv::Point2f> predicted;
        cv::perspectiveTransform(std::vector<cv::Point2f>{cv::Point2f(static_cast<float>(board[next].x()),
                                                                      static_cast<float>(board[next].y()))},
                                 predicted, H);
        worst = std::max(worst, cv::norm(predicted[0] - px[next]) / edge);
        ++checked;
      }
    }
    std::printf("%s: %zu tags (%d exact), %zu points; next tag's corner predicted within %.3f tag edges (%d checks)\n",
                c.image, obs.tags.size(), exact, obs.points.size(), worst, checked);
    EXPECT_GE(checked, c.rows * c.cols);
    EXPECT_LE(worst, 0.08) << c.image;
  }
}

// Quadtree (core/board.h): marker corners are L-shaped black corners on white paper, refined by
// cornerSubPix and then from the marker's two edges (detect_quadtree.cpp), within the marker's
// border bit and the gap to its neighbours. Rendered with 1 px blur (a sharp render leaves the
// edge step a pixel wide). Measured: 1052 of 1536 visible points (the centre cell's 24 mm
// markers, 12-17 px here, are below min_marker_px or undecoded in the oblique views), median
// 0.065 px with the edge refinement against 0.317 px for cornerSubPix alone (an L corner's
// blurred tip pulls cornerSubPix into the black).
TEST(DetectQuadtree, IdsMatchTruthAndMedianErrorBelowTenthPixel) {
  const BoardSpec spec = synth::defaultBoard(BoardType::kQuadtree);
  synth::RenderOptions soft = sharpRender();
  soft.blur_sigma_px = 1.0;
  const Figures fig = runPoses(spec, {}, false, soft);
  EXPECT_EQ(fig.views_found, static_cast<int>(kPoses.size()));
  EXPECT_GE(fig.points, 0.62 * fig.truth_points);
  EXPECT_LE(median(fig.errors), 0.1);
  DetectOptions subpix;
  subpix.model_fit = false;
  const Figures plain = runPoses(spec, subpix, false, soft);
  std::printf("quadtree corners: model fit median %.4f px, cornerSubPix alone %.4f px\n",
              median(fig.errors), median(plain.errors));
  EXPECT_LE(median(fig.errors), 0.5 * median(plain.errors));

  // min_marker_px between the outer ring's markers (96 mm, ~67 px frontal here) and the next
  // ring's (48 mm, ~34 px): only outer-ring corners come out, and all of them.
  const Camera camera = distortedCamera();
  const PoseCase& p = kPoses[0];
  const View view = render(camera, spec, boardPose(camera, spec, p.coverage, p.tilt_x, p.tilt_y, p.roll, p.target));
  DetectOptions strict;
  strict.min_marker_px = 50;
  const ViewObservations big = detectBoard(view.bgr, spec, strict, "frontal");
  const auto markers = quadtreeMarkers(spec);
  int outer = 0;
  for (const QuadtreeMarker& m : markers) outer += m.level == 0;
  EXPECT_EQ(static_cast<int>(big.points.size()), 4 * outer);
  for (const Observation& o : big.points) {
    EXPECT_EQ(markers[static_cast<size_t>(o.id / 4)].level, 0) << "id " << o.id;
    ASSERT_TRUE(view.truth.count(o.id));
    EXPECT_LT((view.truth.at(o.id) - o.px).norm(), 0.2) << "id " << o.id;
  }
  std::printf("quadtree with min_marker_px 50: %zu points (outer ring: %d markers)\n",
              big.points.size(), outer);
}

// A print whose ids start elsewhere than the board JSON says (first_id 0 printed, 16 assumed):
// every marker decodes but sits where the layout puts another; the layout check must not let
// any corner out with a wrong id.
TEST(DetectQuadtree, FirstIdMismatchGivesNoWrongIds) {
  const BoardSpec printed = synth::defaultBoard(BoardType::kQuadtree);
  BoardSpec assumed = printed;
  assumed.first_id = 16;
  const Camera camera = distortedCamera();
  int wrong = 0, returned = 0;
  for (const PoseCase& p : kPoses) {
    // The views of the test above (same render options: read from the cache).
    synth::RenderOptions soft = sharpRender();
    soft.blur_sigma_px = 1.0;
    const View view = render(camera, printed,
                             boardPose(camera, printed, p.coverage, p.tilt_x, p.tilt_y, p.roll, p.target),
                             soft);
    DetectOptions any;
    any.min_points = 1;  // a lone marker that passed the check would count
    const ViewObservations obs = detectBoard(view.bgr, assumed, any);
    for (const Observation& o : obs.points) {
      ++returned;
      // Assumed id k is printed marker k + 16: the truth of the assumed layout is elsewhere.
      const auto it = view.truth.find(o.id);
      if (it == view.truth.end() || (it->second - o.px).norm() > 1.0) ++wrong;
    }
    std::printf("  first_id mismatch: %zu points; '%s'\n", obs.points.size(), obs.failure.c_str());
  }
  std::printf("quadtree first_id mismatch: %d points returned, %d wrong\n", returned, wrong);
  EXPECT_EQ(wrong, 0);
}

// Circle centres: compared with the projection of the true centre, not with the centre of the
// image ellipse, which lies off it under perspective and distortion. Measured in these poses
// (16 spp): the outer ellipse's centre alone is off by 0.23 px median (0.32 max), the middle
// ring's by 0.10, the inner disc's by 0.028 (the r^2 law); extrapolated to r = 0: 0.016 median,
// 0.066 max. Bounds 0.05 / 0.15 px: about three times the measured figures; the outer or middle
// ellipse's centre would fail them.
TEST(DetectCircles, CentresMatchProjectedTruthWithinFiveHundredthsPixel) {
  const BoardSpec spec = synth::defaultBoard(BoardType::kCircles);  // 6 x 8, symmetric
  const Figures fig = runPoses(spec, {}, true);
  EXPECT_EQ(fig.views_found, static_cast<int>(kPoses.size()));
  EXPECT_GE(fig.points, 0.85 * fig.truth_points);
  EXPECT_LE(median(fig.errors), 0.05);
  EXPECT_LE(maxOf(fig.errors), 0.15);
}

// Half the board out of the image: ChArUco and AprilGrid still give correct ids for what is
// visible; a chessboard or a circle board (no cue to place a part) gives nothing rather than
// wrong ids.
TEST(DetectPartial, HalfBoardOutOfImageGivesCorrectIdsOrAReason) {
  const Camera camera = distortedCamera();
  for (BoardType type : {BoardType::kCharuco, BoardType::kAprilGrid, BoardType::kQuadtree,
                         BoardType::kChessboard, BoardType::kCircles}) {
    const BoardSpec spec = synth::defaultBoard(type);
    // Centre on the right image border: about half the board outside.
    const Pose T = boardPose(camera, spec, 0.6, 10, -15, 5, {1.0, 0.5});
    const View view = render(camera, spec, T);
    const int total = static_cast<int>(boardPoints(spec).size());
    const ViewObservations obs = detectBoard(view.bgr, spec, {}, "partial");
    std::printf("%s partial: %zu detected, %zu visible of %d; failure '%s'\n", toString(type),
                obs.points.size(), view.truth.size(), total, obs.failure.c_str());
    EXPECT_LT(static_cast<int>(view.truth.size()), 0.7 * total);
    for (const Observation& o : obs.points) {
      const auto it = view.truth.find(o.id);
      ASSERT_NE(it, view.truth.end()) << toString(type) << ": id " << o.id << " not visible";
      EXPECT_LT((it->second - o.px).norm(), 0.5) << toString(type) << ": id " << o.id;
    }
    if (type == BoardType::kQuadtree) {
      // Visible includes the corners of markers the border cuts, and the centre cell's 24 mm
      // markers (14 px here, 2.4 px a bit) rarely decode on this sharp 4-spp render: measured
      // 46 of 131, every one with its right id and within 0.5 px.
      EXPECT_GE(obs.points.size(), 0.3 * view.truth.size()) << toString(type);
    } else if (type == BoardType::kCharuco || type == BoardType::kAprilGrid) {
      EXPECT_GE(obs.points.size(), 0.6 * view.truth.size()) << toString(type);
    } else {
      EXPECT_FALSE(obs.found()) << toString(type);
      EXPECT_FALSE(obs.failure.empty());
    }
    if (type == BoardType::kCircles) {
      EXPECT_NE(obs.failure.find("seen whole"), std::string::npos) << obs.failure;
    }
  }
}

// Markers / tags below min_marker_px, squares below min_square_px are skipped with a reason:
// the same image is read with the defaults (12 px; no floor on squares) and with limits above
// its marker size.
TEST(DetectSmall, MarkersBelowMinMarkerPxAreSkipped) {
  const Camera camera = distortedCamera();
  for (BoardType type : {BoardType::kCharuco, BoardType::kAprilGrid, BoardType::kChessboard}) {
    const BoardSpec spec = synth::defaultBoard(type);
    // Markers (ChArUco 45 mm, AprilGrid 80 mm) and squares (60 mm) about 26 px wide (an
    // AprilGrid corner needs a data cell, 1/8 of the tag, of 2.5 px for its refinement window).
    const double marker_m = type == BoardType::kCharuco     ? spec.marker_m
                            : type == BoardType::kAprilGrid ? spec.square_m
                                                            : spec.square_m;
    const double coverage =
        (spec.size_m().x() + 2 * spec.margin_m) / marker_m * 26.0 / camera.width;
    const View view = render(camera, spec, boardPose(camera, spec, coverage, 0, 0, 3, {0.5, 0.5}));
    const ViewObservations normal = detectBoard(view.bgr, spec, {}, "26 px markers");
    DetectOptions strict;
    strict.min_marker_px = 32;
    strict.min_square_px = 32;
    const ViewObservations skipped = detectBoard(view.bgr, spec, strict, "26 px markers");
    std::printf("%s with ~26 px markers: %zu points by default, %zu at a 32 px floor ('%s')\n",
                toString(type), normal.points.size(), skipped.points.size(),
                skipped.failure.c_str());
    EXPECT_TRUE(normal.found()) << toString(type) << ": " << normal.failure;
    {
      std::vector<double> e;
      for (const Observation& o : normal.points)
        if (view.truth.count(o.id)) e.push_back((view.truth.at(o.id) - o.px).norm());
      std::printf("   errors median %.4f max %.4f\n", median(e), maxOf(e));
    }
    EXPECT_FALSE(skipped.found()) << toString(type);
    if (type != BoardType::kChessboard) {
      EXPECT_NE(skipped.failure.find("too small"), std::string::npos) << skipped.failure;
    }
  }
}

TEST(DetectBadInput, EmptyOrWrongTypeImageThrowsNamingTheSource) {
  const BoardSpec spec = synth::defaultBoard(BoardType::kChessboard);
  for (const cv::Mat& bad :
       {cv::Mat(), cv::Mat(48, 64, CV_16UC1, cv::Scalar(0)),
        cv::Mat(48, 64, CV_32FC1, cv::Scalar(0)), cv::Mat(48, 64, CV_8UC2, cv::Scalar(0))}) {
    try {
      detectBoard(bad, spec, {}, "cams/w1/000003.png");
      ADD_FAILURE() << "no error for type " << bad.type();
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("cams/w1/000003.png"), std::string::npos) << e.what();
      std::printf("%s\n", e.what());
    }
  }
  DetectOptions options;
  options.subpixel_window_px = 0;
  try {
    detectBoard(cv::Mat(48, 64, CV_8UC1, cv::Scalar(128)), spec, options, "x");
    ADD_FAILURE() << "no error for subpixel_window_px 0";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("subpixel_window_px"), std::string::npos) << e.what();
  }
  // A blank image is not an error: no board, with a reason.
  for (BoardType type : {BoardType::kChessboard, BoardType::kCharuco, BoardType::kAprilGrid,
                         BoardType::kCircles, BoardType::kQuadtree}) {
    const ViewObservations obs = detectBoard(cv::Mat(120, 160, CV_8UC3, cv::Scalar(200, 200, 200)),
                                             synth::defaultBoard(type), {}, "blank");
    EXPECT_FALSE(obs.found());
    EXPECT_FALSE(obs.failure.empty()) << toString(type);
    EXPECT_EQ(obs.source, "blank");
    EXPECT_EQ(obs.image_size, cv::Size(160, 120));
  }
}

// Small, slanted boards (a floor board far from a witness): OpenCV's sample views slanted (the
// top edge squeezed to 3/8 of the width) and shrunk to a quarter (160 x 120, squares of ~4 px
// at the far edge). The truth: OpenCV's corners on the full image, carried through the same
// warp. At a quarter size OpenCV's sector-based detector alone finds 3 of 13, with its
// exhaustive search 6, on a 2x upsampled image 12. Here at 0.35 (squares 4-20 px) previz with
// its fall-backs finds 12 of 13, every corner of each (before: 2, with 7 and 10 corners: squares
// under 12 px were dropped), median 0.075 px from the truth; the worst are the far row's
// squares of 3-4 px, refined in 2-px windows (up to 1.8 px off).
TEST(DetectRealChessboard, SmallSlantedBoardsAreFoundByTheFallbacks) {
  const std::filesystem::path folder = std::filesystem::path(PREVIZ_SHARED_DATA) / "opencv-chessboard";
  ASSERT_TRUE(std::filesystem::is_directory(folder)) << "missing real data folder " << folder;
  BoardSpec spec;
  spec.type = BoardType::kChessboard;
  spec.rows = 7;
  spec.cols = 10;
  spec.square_m = 1.0;
  spec.margin_m = 0.0;
  const cv::Point2f src[4] = {{0, 0}, {640, 0}, {640, 480}, {0, 480}};
  const cv::Point2f dst[4] = {{200, 60}, {440, 60}, {640, 480}, {0, 480}};
  const cv::Mat H = cv::getPerspectiveTransform(src, dst);
  constexpr double kScale = 0.35;  // the far squares 3-4 px high
  int views = 0, found = 0;
  std::vector<double> errors;
  for (int k = 1; k <= 14; ++k) {
    if (k == 10) continue;
    char name[32];
    std::snprintf(name, sizeof name, "left%02d.jpg", k);
    const cv::Mat grey = readImage(folder / name, cv::IMREAD_GRAYSCALE);
    std::vector<cv::Point2f> truth;
    ASSERT_TRUE(cv::findChessboardCorners(grey, cv::Size(9, 6), truth,
                                          cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE));
    cv::cornerSubPix(grey, truth, cv::Size(5, 5), cv::Size(-1, -1),
                     cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 30, 0.01));
    cv::perspectiveTransform(truth, truth, H);
    for (cv::Point2f& p : truth) p = (p + cv::Point2f(0.5f, 0.5f)) * static_cast<float>(kScale) - cv::Point2f(0.5f, 0.5f);
    cv::Mat slanted, small;
    cv::warpPerspective(grey, slanted, H, grey.size(), cv::INTER_AREA, cv::BORDER_CONSTANT, 128);
    cv::resize(slanted, small, cv::Size(), kScale, kScale, cv::INTER_AREA);
    ++views;
    const ViewObservations obs = detectBoard(small, spec, {}, name);
    if (!obs.found()) {
      std::printf("%s: not found (%s)\n", name, obs.failure.c_str());
      continue;
    }
    ++found;
    EXPECT_EQ(obs.points.size(), truth.size()) << name;
    double worst = 0;
    for (const Observation& o : obs.points) {
      double best = 1e9;
      for (const cv::Point2f& t : truth) best = std::min(best, (Eigen::Vector2d(t.x, t.y) - o.px).norm());
      worst = std::max(worst, best);
      errors.push_back(best);
    }
    std::printf("%s: %zu corners, max %.3f px from the truth\n", name, obs.points.size(), worst);
  }
  std::vector<double> sorted = errors;
  std::sort(sorted.begin(), sorted.end());
  const double p95 = sorted.empty() ? 1e9 : sorted[sorted.size() * 95 / 100];
  std::printf("small slanted boards: %d of %d found, corner error median %.3f p95 %.3f max %.3f px\n", found,
              views, median(errors), p95, maxOf(errors));
  EXPECT_GE(found, 11);
  EXPECT_LE(median(errors), 0.1);
  EXPECT_LE(p95, 0.6);
}

// Real webcam images (OpenCV's sample stereo pair, 9 x 6 inner corners): the same corners as
// OpenCV's own findChessboardCorners + cornerSubPix with an 11 x 11 window (half size 5, our
// default) and the criteria of its stereo_calib sample, when run like it (8-bit values, no
// pre-filter, no model fit); and how far our defaults (linear light, pre-filter, model fit) move
// them: 0.12 px median, 0.48 px at most. Which corners are better is judged by the calibration
// residual (intrinsics_test RealChessboardModelFitLowersResidual).
TEST(DetectRealChessboard, MatchesOpenCvWithinTenthPixelOnEveryImage) {
  const std::filesystem::path folder =
      std::filesystem::path(PREVIZ_SHARED_DATA) / "opencv-chessboard";
  ASSERT_TRUE(std::filesystem::is_directory(folder)) << "missing real data folder " << folder;
  BoardSpec spec;
  spec.type = BoardType::kChessboard;
  spec.rows = 7;
  spec.cols = 10;
  spec.square_m = 1.0;  // unpublished: one unit
  spec.margin_m = 0.0;
  DetectOptions like_opencv;
  like_opencv.linear_light = false;
  like_opencv.prefilter_sigma_px = 0;
  like_opencv.model_fit = false;
  int images = 0;
  double worst = 0, worst_default = 0;
  std::vector<double> all_default;
  for (const char* side : {"left", "right"})
    for (int k = 1; k <= 14; ++k) {
      if (k == 10) continue;  // not in the set
      char name[32];
      std::snprintf(name, sizeof name, "%s%02d.jpg", side, k);
      const std::filesystem::path path = folder / name;
      ASSERT_TRUE(std::filesystem::exists(path)) << "missing " << path;
      const cv::Mat grey = readImage(path, cv::IMREAD_GRAYSCALE);
      std::vector<cv::Point2f> reference;
      ASSERT_TRUE(
          cv::findChessboardCorners(grey, cv::Size(9, 6), reference,
                                    cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE))
          << "OpenCV finds no board in " << path;
      cv::cornerSubPix(grey, reference, cv::Size(5, 5), cv::Size(-1, -1),
                       cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 30, 0.01));
      auto compare = [&](const ViewObservations& obs, std::vector<double>& d) {
        EXPECT_EQ(obs.points.size(), reference.size()) << name << ": " << obs.failure;
        for (const Observation& o : obs.points) {
          double best = 1e9;
          for (const cv::Point2f& r : reference)
            best = std::min(best, (Eigen::Vector2d(r.x, r.y) - o.px).norm());
          d.push_back(best);
        }
      };
      std::vector<double> d, d_default;
      compare(detectBoard(grey, spec, like_opencv, path.string()), d);
      compare(detectBoard(grey, spec, {}, path.string()), d_default);
      std::printf(
          "%s: %zu corners, OpenCV-like settings: median %.4f max %.4f px; defaults: "
          "median %.4f max %.4f px\n",
          name, reference.size(), median(d), maxOf(d), median(d_default), maxOf(d_default));
      worst = std::max(worst, maxOf(d));
      worst_default = std::max(worst_default, maxOf(d_default));
      all_default.insert(all_default.end(), d_default.begin(), d_default.end());
      ++images;
    }
  std::printf(
      "%d images: max difference to OpenCV %.4f px (OpenCV-like settings), defaults "
      "median %.4f max %.4f px\n",
      images, worst, median(all_default), worst_default);
  EXPECT_EQ(images, 26);
  EXPECT_LE(worst, 0.1);
}

}  // namespace
}  // namespace previz::calib
