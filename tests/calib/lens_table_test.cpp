// Lens table: interpolation between (focus, zoom) samples, validation, and the three file
// formats (own JSON, Unreal .ulens, OpenTrackIO) read back exactly; ST maps per entry.
#include "calib/lens_table.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>

#include <gtest/gtest.h>

#include "core/distortion_maps.h"
#include "core/error.h"
#include "core/io.h"
#include "scratch.h"

namespace previz::calib {
namespace {

namespace fs = std::filesystem;

fs::path tmpDir(const std::string& name) {
  return test::scratchDir("lens_table_test", name);
}

// A made-up but plausible zoom lens state: focal length grows with zoom, distortion goes
// from barrel to pincushion, centre and pupil drift a little with focus. Values are not
// "round" so a format that drops digits or mixes up fields shows.
LensTableEntry sample(double focus, double zoom, int width = 160, int height = 90) {
  LensTableEntry e;
  e.focus = focus;
  e.zoom = zoom;
  Camera& c = e.camera;
  c.name = "zoomy";
  c.width = width;
  c.height = height;
  c.fx = 120.0 + 310.0 * zoom + 7.3 * focus;
  c.fy = c.fx * 1.0013 + 0.17 * focus;
  c.cx = 79.5 + 1.37 * focus - 0.61 * zoom;
  c.cy = 44.5 - 0.83 * focus + 0.29 * zoom * zoom;
  c.skew = 0.011 * focus;
  c.dist.k1 = -0.21 + 0.27 * zoom + 0.013 * focus;
  c.dist.k2 = 0.041 - 0.05 * zoom;
  c.dist.k3 = -0.0031 + 0.002 * focus * zoom;
  c.dist.p1 = 0.00043 * (1 + focus);
  c.dist.p2 = -0.00027 * (1 + zoom);
  e.entrance_pupil_m = 0.093 + 0.041 * zoom - 0.007 * focus;
  return e;
}

LensTable gridTable(const std::vector<double>& focus, const std::vector<double>& zoom) {
  LensTable t;
  t.lens_name = "zoomy";
  t.width = 160;
  t.height = 90;
  t.sensor_width_mm = 24.89;
  t.sensor_height_mm = 14.0;
  for (double f : focus)
    for (double z : zoom) t.entries.push_back(sample(f, z));
  return t;
}

std::array<double, 11> params(const LensTableEntry& e) {
  const Camera& c = e.camera;
  return {c.fx, c.fy, c.cx, c.cy, c.skew, c.dist.k1, c.dist.k2, c.dist.k3, c.dist.p1, c.dist.p2,
          e.entrance_pupil_m};
}

void expectSameTable(const LensTable& a, const LensTable& b, double tol) {
  EXPECT_EQ(a.lens_name, b.lens_name);
  EXPECT_EQ(a.focus_units, b.focus_units);
  EXPECT_EQ(a.zoom_units, b.zoom_units);
  EXPECT_EQ(a.width, b.width);
  EXPECT_EQ(a.height, b.height);
  EXPECT_NEAR(a.sensor_width_mm, b.sensor_width_mm, tol);
  EXPECT_NEAR(a.sensor_height_mm, b.sensor_height_mm, tol);
  ASSERT_EQ(a.entries.size(), b.entries.size());
  double worst = 0;
  for (size_t i = 0; i < a.entries.size(); ++i) {
    SCOPED_TRACE("entry " + std::to_string(i));
    EXPECT_NEAR(a.entries[i].focus, b.entries[i].focus, tol);
    EXPECT_NEAR(a.entries[i].zoom, b.entries[i].zoom, tol);
    EXPECT_EQ(a.entries[i].camera.width, b.entries[i].camera.width);
    EXPECT_EQ(a.entries[i].camera.height, b.entries[i].camera.height);
    const auto pa = params(a.entries[i]), pb = params(b.entries[i]);
    for (size_t k = 0; k < pa.size(); ++k) {
      EXPECT_NEAR(pa[k], pb[k], tol) << "param " << k;
      worst = std::max(worst, std::abs(pa[k] - pb[k]));
    }
  }
  std::printf("{\"check\":\"lens_table_round_trip\",\"max_abs_error\":%.3g}\n", worst);
}

template <typename F>
std::string errorField(F&& f) {
  try {
    f();
  } catch (const Error& e) {
    return e.context().field;
  }
  return "(no error)";
}

template <typename F>
ErrorContext errorContext(F&& f) {
  try {
    f();
  } catch (const Error& e) {
    return e.context();
  }
  ADD_FAILURE() << "no error thrown";
  return {};
}

TEST(LensTable, InterpolationExactAtSamplePoints) {
  const LensTable t = gridTable({0.0, 0.4, 1.0}, {0.0, 0.3, 0.7, 1.0});
  for (const auto& e : t.entries) {
    const LensTableEntry r = t.at(e.focus, e.zoom);
    EXPECT_FALSE(r.clamped);
    EXPECT_EQ(params(r), params(e)) << "focus " << e.focus << " zoom " << e.zoom;
  }
}

TEST(LensTable, BilinearInCellMiddleEqualsManualCombination) {
  const LensTable t = gridTable({0.0, 0.4, 1.0}, {0.0, 0.3, 0.7, 1.0});
  const double f = 0.55, z = 0.41;  // cell focus [0.4, 1], zoom [0.3, 0.7]
  const double s = (f - 0.4) / 0.6, u = (z - 0.3) / 0.4;
  const auto a = params(sample(0.4, 0.3)), b = params(sample(1.0, 0.3));
  const auto c = params(sample(0.4, 0.7)), d = params(sample(1.0, 0.7));
  const LensTableEntry r = t.at(f, z);
  EXPECT_FALSE(r.clamped);
  const auto p = params(r);
  for (size_t k = 0; k < p.size(); ++k) {
    const double want =
        (1 - s) * (1 - u) * a[k] + s * (1 - u) * b[k] + (1 - s) * u * c[k] + s * u * d[k];
    EXPECT_NEAR(p[k], want, 1e-12 * (1 + std::abs(want))) << "param " << k;
  }
  // fx is affine in focus and zoom in the fixture, so bilinear reproduces it exactly.
  EXPECT_NEAR(r.camera.fx, sample(f, z).camera.fx, 1e-9);
  EXPECT_EQ(r.camera.width, 160);
  EXPECT_EQ(r.camera.height, 90);
}

TEST(LensTable, OneDimensionalTableIsLinear) {
  // Zoom-only table (one focus), and focus-only table (one zoom).
  const LensTable tz = gridTable({0.5}, {0.0, 0.25, 1.0});
  const double z = 0.6, w = (z - 0.25) / 0.75;
  const auto a = params(sample(0.5, 0.25)), b = params(sample(0.5, 1.0));
  const LensTableEntry rz = tz.at(0.5, z);
  EXPECT_FALSE(rz.clamped);
  for (size_t k = 0; k < a.size(); ++k)
    EXPECT_NEAR(params(rz)[k], (1 - w) * a[k] + w * b[k], 1e-12 * (1 + std::abs(a[k])));

  const LensTable tf = gridTable({0.0, 1.0}, {0.3});
  const auto c = params(sample(0.0, 0.3)), d = params(sample(1.0, 0.3));
  const LensTableEntry rf = tf.at(0.2, 0.3);
  EXPECT_FALSE(rf.clamped);
  for (size_t k = 0; k < c.size(); ++k)
    EXPECT_NEAR(params(rf)[k], 0.8 * c[k] + 0.2 * d[k], 1e-12 * (1 + std::abs(c[k])));
}

TEST(LensTable, OutsideRangeClampsAndReportsIt) {
  const LensTable t = gridTable({0.2, 0.8}, {0.1, 0.9});
  const LensTableEntry r = t.at(1.5, -3.0);
  EXPECT_TRUE(r.clamped);
  EXPECT_EQ(r.focus, 0.8);
  EXPECT_EQ(r.zoom, 0.1);
  EXPECT_EQ(params(r), params(sample(0.8, 0.1)));
  // Only one axis outside: clamped on that axis, interpolated on the other.
  const LensTableEntry r2 = t.at(0.5, 2.0);
  EXPECT_TRUE(r2.clamped);
  EXPECT_NEAR(r2.camera.fx, 0.5 * (sample(0.2, 0.9).camera.fx + sample(0.8, 0.9).camera.fx),
              1e-9);
  // 1-D table clamps along its axis too.
  const LensTable tz = gridTable({0.5}, {0.0, 1.0});
  EXPECT_TRUE(tz.at(0.5, 1.2).clamped);
  EXPECT_TRUE(tz.at(0.7, 0.5).clamped);  // focus differs from the only sampled focus
  EXPECT_FALSE(tz.at(0.5, 0.5).clamped);
}

TEST(LensTable, IncompleteCellInterpolatesAlongCompleteEdge) {
  LensTable t = gridTable({0.0, 1.0}, {0.0, 1.0});
  t.entries.pop_back();  // drop (1, 1)
  // Near focus 0: the focus-0 edge (both zooms present) is used, linear in zoom.
  const LensTableEntry r = t.at(0.1, 0.5);
  const auto a = params(sample(0.0, 0.0)), b = params(sample(0.0, 1.0));
  for (size_t k = 0; k < a.size(); ++k)
    EXPECT_NEAR(params(r)[k], 0.5 * a[k] + 0.5 * b[k], 1e-12 * (1 + std::abs(a[k])));
  EXPECT_FALSE(r.clamped);
}

TEST(LensTable, ValidateErrorsNameFieldAndEntry) {
  LensTable t = gridTable({0.0, 1.0}, {0.0});
  EXPECT_NO_THROW(t.validate());

  LensTable size = t;
  size.entries[1].camera.width = 320;
  EXPECT_EQ(errorField([&] { size.validate(); }), "entries[1].camera.width");

  LensTable dup = t;
  dup.entries[1].focus = 0.0;
  EXPECT_EQ(errorField([&] { dup.validate(); }), "entries[1].focus");

  LensTable empty = t;
  empty.entries.clear();
  EXPECT_EQ(errorField([&] { empty.validate(); }), "entries");

  LensTable bad_fx = t;
  bad_fx.entries[0].camera.fx = -1;
  EXPECT_EQ(errorField([&] { bad_fx.validate(); }).rfind("entries[0].camera.", 0), 0u)
      << errorField([&] { bad_fx.validate(); });

  LensTable pupil = t;
  pupil.entries[1].entrance_pupil_m = std::nan("");
  EXPECT_EQ(errorField([&] { pupil.validate(); }), "entries[1].entrance_pupil_m");

  // A fisheye entry: the table's files and interpolation carry Brown-Conrady terms only.
  LensTable fisheye = t;
  fisheye.entries[1].camera.dist = Distortion::kannalaBrandt(0.01, 0, 0, 0);
  EXPECT_EQ(errorField([&] { fisheye.validate(); }), "entries[1].camera.distortion.model");
  // A rational entry (OpenCV's k4 k5 k6): no lens file has a place for them, and blending two
  // rational factors is not the factor of the blended terms: refused, naming the term.
  LensTable rational = t;
  rational.entries[1].camera.dist.k5 = 0.02;
  EXPECT_EQ(errorField([&] { rational.validate(); }), "entries[1].camera.distortion.k5");
}

TEST(LensTable, OwnJsonRoundTripIsExact) {
  LensTable t = gridTable({0.0, 0.35, 1.0}, {0.0, 0.5, 1.0});
  t.focus_units = "m";
  t.zoom_units = "mm";
  const fs::path p = tmpDir("own") / "zoomy.json";
  writeLensTable(p, t);
  const LensTable r = readLensTable(p);
  expectSameTable(t, r, 0.0);
}

TEST(LensTable, UnrealLensFileRoundTripWithin1e9) {
  const LensTable t = gridTable({0.0, 0.35, 1.0}, {0.0, 0.5, 1.0});
  const fs::path p = tmpDir("ulens") / "zoomy.ulens";
  writeUnrealLensFile(p, t);
  const nlohmann::json j = readJsonFile(p);
  // The documented normalisations: Fx by width, Cx of the pixel-edge frame in [0, 1].
  const Camera& c0 = t.entries[0].camera;
  EXPECT_NEAR(j["data"]["focalLength"][0]["Fx"].get<double>(), c0.fx / 160.0, 1e-15);
  EXPECT_NEAR(j["data"]["imageCenter"][0]["Cx"].get<double>(), (c0.cx + 0.5) / 160.0, 1e-15);
  EXPECT_NEAR(j["data"]["imageCenter"][0]["Cy"].get<double>(), (c0.cy + 0.5) / 90.0, 1e-15);
  const LensTable r = readUnrealLensFile(p);
  expectSameTable(t, r, 1e-9);
}

TEST(LensTable, OpenTrackIoRoundTripWithin1e9) {
  const LensTable t = gridTable({0.0, 0.35, 1.0}, {0.0, 0.5, 1.0});
  const fs::path p = tmpDir("otio") / "zoomy_opentrackio.json";
  writeOpenTrackIoLens(p, t);
  const nlohmann::json j = readJsonFile(p);
  ASSERT_EQ(j.size(), t.entries.size());
  const Camera& c0 = t.entries[0].camera;
  EXPECT_NEAR(j[0]["lens"]["pinholeFocalLength"].get<double>(), c0.fx * 24.89 / 160.0, 1e-12);
  EXPECT_EQ(j[0]["lens"]["distortion"][0]["radial"][0].get<double>(), c0.dist.k1);
  const LensTable r = readOpenTrackIoLens(p);
  expectSameTable(t, r, 1e-9);

  // Without a physical sensor size there is no focal length in mm: refused, field named.
  LensTable no_sensor = t;
  no_sensor.sensor_width_mm = 0;
  EXPECT_EQ(errorField([&] { writeOpenTrackIoLens(p, no_sensor); }), "sensor_width_mm");
}

TEST(LensTable, StMapsPerEntryHaveTheRightSizes) {
  const LensTable t = gridTable({0.0, 1.0}, {0.0, 1.0});
  const fs::path dir = tmpDir("stmaps");
  const double overscan = 0.1;
  const auto files = writeLensStMaps(t, dir, overscan);
  ASSERT_EQ(files.size(), 8u);
  for (const auto& e : t.entries) {
    const std::string stem = lensStMapStem(t, e);
    const Camera pinhole = idealPinhole(e.camera, overscan);
    ASSERT_EQ(pinhole.width, 176);
    ASSERT_EQ(pinhole.height, 99);
    cv::Size src;
    const cv::Mat und = readStMap(dir / (stem + "_undistort.exr"), &src);
    EXPECT_EQ(und.cols, pinhole.width);
    EXPECT_EQ(und.rows, pinhole.height);
    EXPECT_EQ(src, cv::Size(160, 90));
    // The map is the entry's own camera's (not another entry's): compare with core directly.
    const cv::Mat want = makeUndistortMap(e.camera, pinhole);
    const cv::Vec2f got_px = und.at<cv::Vec2f>(7, 11), want_px = want.at<cv::Vec2f>(7, 11);
    EXPECT_NEAR(got_px[0], want_px[0], 1e-3);
    EXPECT_NEAR(got_px[1], want_px[1], 1e-3);
    const cv::Mat dis = readStMap(dir / (stem + "_distort.exr"), &src);
    EXPECT_EQ(dis.cols, 160);
    EXPECT_EQ(dis.rows, 90);
    EXPECT_EQ(src, cv::Size(pinhole.width, pinhole.height));
  }
  EXPECT_TRUE(fs::exists(dir / "zoomy_f1_z0_undistort.exr"));
}

TEST(LensTable, MalformedFilesErrorsNameFileAndField) {
  const fs::path dir = tmpDir("malformed");
  const LensTable t = gridTable({0.0, 1.0}, {0.0});

  nlohmann::json own = lensTableToJson(t);
  own["entries"][1]["zoom"] = "wide";
  const fs::path p1 = dir / "own.json";
  writeJsonAtomic(p1, own);
  ErrorContext c = errorContext([&] { readLensTable(p1); });
  EXPECT_EQ(c.file, p1.string());
  EXPECT_EQ(c.field, "entries[1].zoom");

  nlohmann::json own2 = lensTableToJson(t);
  own2["entries"][0]["camera"].erase("fx");
  writeJsonAtomic(p1, own2);
  c = errorContext([&] { readLensTable(p1); });
  EXPECT_EQ(c.file, p1.string());
  EXPECT_NE(c.field.find("entries[0].camera"), std::string::npos) << c.field;

  nlohmann::json ul = lensTableToUnreal(t);
  ul["data"]["distortion"].erase(1);
  const fs::path p2 = dir / "bad.ulens";
  writeJsonAtomic(p2, ul);
  c = errorContext([&] { readUnrealLensFile(p2); });
  EXPECT_EQ(c.file, p2.string());
  EXPECT_EQ(c.field, "data.distortion");

  nlohmann::json ot = lensTableToOpenTrackIo(t);
  ot[1]["lens"].erase("pinholeFocalLength");
  const fs::path p3 = dir / "bad_otio.json";
  writeJsonAtomic(p3, ot);
  c = errorContext([&] { readOpenTrackIoLens(p3); });
  EXPECT_EQ(c.file, p3.string());
  EXPECT_EQ(c.field, "[1].lens.pinholeFocalLength");

  const fs::path p4 = dir / "not_json.json";
  writeFileAtomic(p4, "{ not json");
  c = errorContext([&] { readLensTable(p4); });
  EXPECT_EQ(c.file, p4.string());
}

}  // namespace
}  // namespace previz::calib
