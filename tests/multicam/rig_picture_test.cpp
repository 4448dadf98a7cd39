// Stage picture: coverage counts against an independent projection (cv::projectPoints), and
// the PNG / SVG files at the size the options ask for.
#include "multicam/rig_picture.h"

#include <gtest/gtest.h>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "core/error.h"
#include "core/io.h"
#include "datasets/rigs.h"
#include "scratch.h"

namespace previz::multicam {
namespace {

namespace fs = std::filesystem;

Rig studio() {
  synth::StudioRigOptions o;  // 8 witnesses 1280x720 + main 1920x1080
  return synth::studioRig(o, 10.0, false);
}

// Cameras that see world point p, by OpenCV's own projection (z > 0, inside the image).
int seenBy(const Rig& rig, const Eigen::Vector3d& p) {
  int count = 0;
  for (const RigCamera& rc : rig.cameras) {
    const Pose T_cam_world = rc.T_world_cam.inverse();
    if ((T_cam_world * p).z() <= 0) continue;
    Eigen::Vector3d rvec, tvec;
    poseToRvecTvec(T_cam_world, rvec, tvec);
    const Camera& c = rc.camera;
    const cv::Matx33d K(c.fx, c.skew, c.cx, 0, c.fy, c.cy, 0, 0, 1);
    const cv::Vec<double, 5> D(c.dist.k1, c.dist.k2, c.dist.p1, c.dist.p2, c.dist.k3);
    std::vector<cv::Point2d> px;
    cv::projectPoints(std::vector<cv::Point3d>{{p.x(), p.y(), p.z()}}, cv::Vec3d(rvec.x(), rvec.y(), rvec.z()),
                      cv::Vec3d(tvec.x(), tvec.y(), tvec.z()), K, D, px);
    if (px[0].x >= -0.5 && px[0].x <= c.width - 0.5 && px[0].y >= -0.5 && px[0].y <= c.height - 0.5) ++count;
  }
  return count;
}

TEST(RigPicture, CoverageCountsMatchOpenCvProjection) {
  const Rig rig = studio();
  const double extent = 6.0, cell = 0.25, height = 1.0;
  const cv::Mat grid = coverageGrid(rig, extent, cell, height);
  ASSERT_EQ(grid.type(), CV_32S);
  ASSERT_EQ(grid.rows, 48);
  ASSERT_EQ(grid.cols, 48);
  // Stage centre: every camera aims near it. Then cells off centre, near the edge of some
  // views, and behind the ring of cameras.
  int checked_partial = 0;
  for (const auto& [r, c] : std::vector<std::pair<int, int>>{{23, 23}, {10, 30}, {30, 8}, {40, 40}, {20, 2}, {2, 24}, {44, 12}}) {
    SCOPED_TRACE("cell " + std::to_string(r) + "," + std::to_string(c));
    const Eigen::Vector3d p(-extent + (c + 0.5) * cell, extent - (r + 0.5) * cell, height);
    const int expected = seenBy(rig, p);
    EXPECT_EQ(grid.at<int>(r, c), expected);
    checked_partial += expected > 0 && expected < static_cast<int>(rig.cameras.size());
  }
  EXPECT_EQ(grid.at<int>(23, 23), 9);  // (-0.125, 0.125, 1): all nine cameras
  EXPECT_GE(checked_partial, 2);       // the check covers cells only some cameras see
  // Row 0 is north (largest y): the camera seeing the top-left corner region differs from the
  // one seeing the bottom-left, so a flipped grid would not match the brute force above.
  EXPECT_THROW(coverageGrid(rig, extent, 0, height), Error);
}

TEST(RigPicture, WritesPngAndSvgOfTheAskedWidth) {
  const fs::path dir = test::scratchDir("multicam_picture", "files");
  const Rig rig = studio();
  FloorSpec floor;
  floor.board = synth::rigBoard(BoardType::kAprilGrid);
  floor.frames = {0};
  RigPictureOptions options;
  options.width_px = 1200;
  options.cell_m = 0.2;
  const RigPicture picture = writeRigPicture(rig, &floor, dir / "stage", options);
  EXPECT_EQ(picture.png, dir / "stage.png");
  EXPECT_EQ(picture.svg, dir / "stage.svg");
  const cv::Mat png = readImage(picture.png);
  EXPECT_EQ(png.cols, 1200);
  EXPECT_EQ(png.size(), picture.size);
  // Cameras stand 4.2-4.8 m from the centre: the fitted area holds them with a margin.
  EXPECT_GE(picture.half_extent_m, 4.8);
  EXPECT_LE(picture.half_extent_m, 6.5);
  EXPECT_EQ(picture.max_coverage, 9);
  // Height: title + the taller view at the same scale + legend; the top view is square.
  const double scale = (1200 - 2 * 30 - 40) / 2.0 / (2 * picture.half_extent_m);
  EXPECT_GE(png.rows, static_cast<int>(2 * picture.half_extent_m * scale));
  const std::string svg = readTextFile(picture.svg);
  EXPECT_NE(svg.find("width=\"1200\" height=\"" + std::to_string(png.rows) + "\""), std::string::npos);
  for (const RigCamera& rc : rig.cameras) {
    EXPECT_NE(svg.find(">" + rc.camera.name + "<"), std::string::npos) << rc.camera.name;
  }
  EXPECT_NE(svg.find("floor board"), std::string::npos);
  // Not blank: the heat map colours a good part of the top view.
  cv::Mat grey;
  cv::cvtColor(png, grey, cv::COLOR_BGR2GRAY);
  EXPECT_GT(cv::countNonZero(grey < 200), png.total() / 10);

  options.width_px = 10;
  EXPECT_THROW(writeRigPicture(rig, &floor, dir / "bad", options), Error);
  EXPECT_FALSE(fs::exists(dir / "bad.png"));
}

}  // namespace
}  // namespace previz::multicam
