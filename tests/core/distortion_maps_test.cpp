// Whole-image maps: undistort (forward), distort (inverse), their composition, cv::remap of a
// checker against the analytic answer, ST map EXR round trip.
#include "core/distortion_maps.h"

#include <cmath>
#include <filesystem>

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "core/error.h"
#include "core/io.h"
#include "scratch.h"

namespace fs = std::filesystem;

namespace previz {
namespace {

// 640x360 at f = 450 px: the field of view of 1280x720 at 900 px, at a quarter of the pixels.
Camera lens(const Distortion& d) {
  Camera c;
  c.name = "lens";
  c.width = 640;
  c.height = 360;
  c.fx = 450;
  c.fy = 452;
  c.cx = 321.3;
  c.cy = 178.6;
  c.dist = d;
  return c;
}

const Distortion kBarrel{-0.25, 0.05, 0.001, -0.0015, 0.0};

TEST(DistortionMaps, IdealPinholeKeepsFocalLengthsAndCentresTheOverscan) {
  const Camera l = lens(kBarrel);
  const Camera p = idealPinhole(l, 0.1);
  EXPECT_TRUE(p.dist.isZero());
  EXPECT_EQ(p.width, 704);
  EXPECT_EQ(p.height, 396);
  EXPECT_EQ(p.fx, l.fx);
  EXPECT_EQ(p.fy, l.fy);
  EXPECT_DOUBLE_EQ(p.cx, l.cx + 32);
  EXPECT_DOUBLE_EQ(p.cy, l.cy + 18);
  EXPECT_THROW(idealPinhole(l, -0.1), Error);
}

// Bilinear sample of a CV_32FC2 map in double precision. (cv::remap itself quantizes source
// positions to 1/32 px — INTER_TAB_SIZE — which alone is a 0.03 px error.)
cv::Vec2d sampleBilinear(const cv::Mat& map, double x, double y) {
  const int x0 = static_cast<int>(std::floor(x)), y0 = static_cast<int>(std::floor(y));
  const double a = x - x0, b = y - y0;
  cv::Vec2d out(0, 0);
  for (int j = 0; j < 2; ++j)
    for (int i = 0; i < 2; ++i) {
      const cv::Vec2f m = map.at<cv::Vec2f>(y0 + j, x0 + i);
      const double w = (i ? a : 1 - a) * (j ? b : 1 - b);
      out += w * cv::Vec2d(m[0], m[1]);
    }
  return out;
}

// undistort map: pinhole pixel -> lens pixel; distort map: lens pixel -> pinhole pixel.
// Composing them (undistort map sampled where the distort map points) must bring every lens
// pixel back to itself.
// Every lens model (core/lens_model.h) through the same maps: Brown–Conrady barrel and
// pincushion, its rational form (OpenCV's k4 k5 k6), and a Kannala–Brandt fisheye (about 92 degrees
// across this frame's diagonal, all of it inside the overscanned pinhole).
TEST(DistortionMaps, UndistortMapAfterDistortMapIsTheIdentityBelowAMilliPixel) {
  for (const Distortion& d : {kBarrel, Distortion{0.3, -0.05, -0.002, 0.001, 0.01},
                              Distortion{-0.1, 0.04, 0.001, -0.0015, 0.0, 0.15, 0.02, 0.001},
                              Distortion::kannalaBrandt(0.021, -0.0065, 0.0012, -0.00011)}) {
    const Camera l = lens(d);
    const Camera p = idealPinhole(l, 0.4);  // barrel: the lens corners reach far out in the pinhole
    const cv::Mat U = makeUndistortMap(l, p);
    const DistortMapResult D = makeDistortMap(l, p);
    ASSERT_EQ(D.not_invertible, 0);
    EXPECT_GT(D.max_iterations, 0);
    EXPECT_LE(D.max_iterations, 10);
    double worst = 0;
    for (int v = 0; v < l.height; ++v)
      for (int u = 0; u < l.width; ++u) {
        const cv::Vec2f src = D.map.at<cv::Vec2f>(v, u);
        ASSERT_TRUE(src[0] >= 0 && src[1] >= 0 && src[0] < p.width - 1 && src[1] < p.height - 1);
        const cv::Vec2d q = sampleBilinear(U, src[0], src[1]);
        worst = std::max(worst, std::hypot(q[0] - u, q[1] - v));
      }
    std::cout << toString(d.model) << (d.isRational() ? " (rational)" : "") << " k1=" << d.k1
              << ": map composition max error " << worst << " px (bilinear + float)\n";
    EXPECT_LT(worst, 1e-3);
    // The distort map itself against the analytic inverse (double precision).
    double worst_map = 0;
    for (int v = 0; v < l.height; v += 7)
      for (int u = 0; u < l.width; u += 7) {
        const InverseResult r = l.undistort(l.pixelToNormalized({u, v}));
        ASSERT_TRUE(r.ok());
        const Eigen::Vector2d src = p.normalizedToPixel(r.point);
        const cv::Vec2f m = D.map.at<cv::Vec2f>(v, u);
        worst_map = std::max(worst_map, std::hypot(double(m[0]) - src.x(), double(m[1]) - src.y()));
      }
    EXPECT_LT(worst_map, 1e-4);  // float storage of coordinates below 1000 px
  }
}

// A lens that folds inside the frame: exactly the pixels past the image of the turning circle
// are marked (-1,-1) and counted.
TEST(DistortionMaps, DistortMapCountsExactlyThePixelsPastTheFold) {
  const Camera l = lens({-0.5, 0, 0, 0, 0});
  const Camera p = idealPinhole(l, 0.5);
  const DistortMapResult D = makeDistortMap(l, p);
  const double rmax = l.maxInvertibleRadius();
  const double rd_edge = rmax * (1 - 0.5 * rmax * rmax);
  int expected = 0, marked = 0;
  for (int v = 0; v < l.height; ++v)
    for (int u = 0; u < l.width; ++u) {
      const bool past = l.pixelToNormalized({u, v}).norm() >= rd_edge;
      expected += past;
      const cv::Vec2f m = D.map.at<cv::Vec2f>(v, u);
      const bool is_marked = m[0] == -1.f && m[1] == -1.f;
      marked += is_marked;
      EXPECT_EQ(past, is_marked) << u << "," << v;
    }
  std::cout << "k1=-0.5: " << D.not_invertible << " of " << l.width * l.height << " pixels not invertible\n";
  EXPECT_GT(expected, 0);
  EXPECT_EQ(D.not_invertible, expected);
  EXPECT_EQ(marked, expected);
  // The undistort map refuses ideal points past the turning radius instead of folding back.
  const cv::Mat U = makeUndistortMap(l, p);
  const Eigen::Vector2d corner = p.pixelToNormalized({0, 0});
  ASSERT_GT(corner.norm(), rmax);
  EXPECT_EQ(U.at<cv::Vec2f>(0, 0), cv::Vec2f(-1.f, -1.f));
}

// A checker rendered by an ideal pinhole (16 px squares, by pixel index), warped into the lens
// by cv::remap through the distort map. Wherever the analytic source position (Camera::undistort)
// has all four bilinear neighbours in one square, the result must be exactly that square's value.
TEST(DistortionMaps, RemappedCheckerMatchesTheAnalyticLensImage) {
  const Camera l = lens(kBarrel);
  const Camera p = idealPinhole(l, 0.2);
  cv::Mat checker(p.height, p.width, CV_8UC1);
  for (int y = 0; y < p.height; ++y)
    for (int x = 0; x < p.width; ++x) checker.at<uint8_t>(y, x) = ((x / 16 + y / 16) % 2) ? 200 : 40;
  const DistortMapResult D = makeDistortMap(l, p);
  cv::Mat warped;
  cv::remap(checker, warped, D.map, cv::noArray(), cv::INTER_LINEAR, cv::BORDER_CONSTANT, cv::Scalar(0));
  int checked = 0, mismatched = 0;
  for (int v = 0; v < l.height; ++v)
    for (int u = 0; u < l.width; ++u) {
      const InverseResult r = l.undistort(l.pixelToNormalized({u, v}));
      ASSERT_TRUE(r.ok());
      const Eigen::Vector2d src = p.normalizedToPixel(r.point);
      const double fx = src.x() - std::floor(src.x()), fy = src.y() - std::floor(src.y());
      if (fx < 1e-3 || fx > 1 - 1e-3 || fy < 1e-3 || fy > 1 - 1e-3) continue;  // float rounding may flip floor
      const int x0 = static_cast<int>(std::floor(src.x())), y0 = static_cast<int>(std::floor(src.y()));
      if (x0 < 0 || y0 < 0 || x0 + 1 >= p.width || y0 + 1 >= p.height) continue;
      if (x0 % 16 == 15 || y0 % 16 == 15) continue;  // neighbours straddle a square edge
      ++checked;
      mismatched += warped.at<uint8_t>(v, u) != checker.at<uint8_t>(y0, x0);
    }
  std::cout << "checker: " << checked << " interior pixels compared, " << mismatched << " mismatched\n";
  EXPECT_GT(checked, l.width * l.height * 3 / 4);
  EXPECT_EQ(mismatched, 0);
  // The lens bends the pinhole's straight rows: the middle of the top edge of the lens image
  // reads a higher pinhole row than its corner does (barrel pulls the corners outward).
  EXPECT_GT(D.map.at<cv::Vec2f>(0, 320)[1], D.map.at<cv::Vec2f>(0, 0)[1] + 5);
}

TEST(DistortionMaps, StMapExrRoundTripIsExactToFloatAndStatesItsConvention) {
  const fs::path dir = test::scratchDir("distortion_maps_test", "stmap");
  const Camera l = lens(kBarrel);
  const Camera p = idealPinhole(l, 0.1);
  const DistortMapResult D = makeDistortMap(l, p);
  const cv::Size source(p.width, p.height);
  writeStMap(dir / "st.exr", D.map, source, "lens <- pinhole, 10 % overscan");

  const ExrImage raw = readExr(dir / "st.exr");
  EXPECT_EQ(raw.channels, (std::vector<std::string>{"R", "G"}));
  EXPECT_EQ(raw.attributes.at("previz:pixel_origin"), "pixel (0,0) is the centre of the top-left pixel");
  EXPECT_EQ(raw.attributes.at("previz:source_size"), "704x396");
  EXPECT_EQ(raw.attributes.at("previz:description"), "lens <- pinhole, 10 % overscan");
  EXPECT_NE(raw.attributes.at("previz:st_convention").find("s = (x + 0.5) / W"), std::string::npos);
  EXPECT_NE(raw.attributes.at("previz:st_convention").find("bottom-left"), std::string::npos);
  // The stored values are the formula, bit for bit.
  for (const cv::Point q : {cv::Point(0, 0), cv::Point(639, 0), cv::Point(13, 359), cv::Point(320, 180)}) {
    const cv::Vec2f m = D.map.at<cv::Vec2f>(q);
    const cv::Vec2f st = raw.image.at<cv::Vec2f>(q);
    EXPECT_EQ(st[0], static_cast<float>((m[0] + 0.5) / source.width));
    EXPECT_EQ(st[1], static_cast<float>(1.0 - (m[1] + 0.5) / source.height));
  }

  cv::Size read_size;
  const cv::Mat back = readStMap(dir / "st.exr", &read_size);
  EXPECT_EQ(read_size, source);
  ASSERT_EQ(back.type(), CV_32FC2);
  double worst = 0, worst_allowed_ratio = 0;
  for (int v = 0; v < back.rows; ++v)
    for (int u = 0; u < back.cols; ++u)
      for (int c = 0; c < 2; ++c) {
        const double a = D.map.at<cv::Vec2f>(v, u)[c], b = back.at<cv::Vec2f>(v, u)[c];
        const double size = c == 0 ? source.width : source.height;
        // One float rounding of s (relative 2^-24, times W) and one of the coordinate.
        const double allowed = (size + std::abs(a) + 1) * std::ldexp(1.0, -24);
        worst = std::max(worst, std::abs(a - b));
        worst_allowed_ratio = std::max(worst_allowed_ratio, std::abs(a - b) / allowed);
      }
  std::cout << "ST map round trip: max " << worst << " px\n";
  EXPECT_LE(worst_allowed_ratio, 1.0);

  // The convention itself on an identity map: pixel (0,0) is s = 0.5/W at the top (t near 1).
  cv::Mat identity(2, 4, CV_32FC2);
  for (int v = 0; v < 2; ++v)
    for (int u = 0; u < 4; ++u) identity.at<cv::Vec2f>(v, u) = cv::Vec2f(u, v);
  writeStMap(dir / "identity.exr", identity, {4, 2}, "identity");
  const ExrImage id = readExr(dir / "identity.exr");
  EXPECT_EQ(id.image.at<cv::Vec2f>(0, 0), cv::Vec2f(0.125f, 0.75f));
  EXPECT_EQ(id.image.at<cv::Vec2f>(1, 3), cv::Vec2f(0.875f, 0.25f));
  ExrImage no_size = id;
  no_size.attributes.erase("previz:source_size");
  writeExr(dir / "nosize.exr", no_size);
  EXPECT_THROW(readStMap(dir / "nosize.exr"), Error);
}

}  // namespace
}  // namespace previz
