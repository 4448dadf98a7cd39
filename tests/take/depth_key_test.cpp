// 16-bit and float plates of the same studio take key as the 8-bit ones do (issue 29 item 1):
// the synthetic studio renders one picture and stores it three ways (8-bit PNG, 16-bit PNG of the
// values before 8-bit rounding, float EXR in linear light); the take model reads each back to
// 8-bit sRGB and the keyer's silhouettes agree.
#include <gtest/gtest.h>

#include <cstdio>

#include <opencv2/core.hpp>

#include "carving/keyer.h"
#include "datasets/synth.h"
#include "take/take.h"
#include "tests/scratch.h"

namespace previz::take {
namespace {

namespace fs = std::filesystem;

fs::path render(const std::string& format) {
  synth::SynthOptions o;
  o.frames = 2;
  o.fps = 0.5;  // t = 0 and 2 s
  o.witness_cameras = 8;
  o.witness_width = 320;
  o.witness_height = 180;
  o.main_width = 480;
  o.main_height = 270;
  o.noise_sigma = 2;
  o.write_meshes = false;
  o.camera_format = format;
  const fs::path dir = test::scratchDir("take_depth", format);
  synth::synthesizeTake(o, dir);
  return dir;
}

double iou(const cv::Mat& a, const cv::Mat& b) {
  const double both = cv::countNonZero(a & b), any = cv::countNonZero(a | b);
  return any > 0 ? both / any : 1.0;
}

TEST(TakeDepths, SixteenBitAndFloatPlatesKeyLikeTheEightBitOnes) {
  const fs::path png = render("png"), png16 = render("png16"), exr = render("exr");
  const Take t8(png), t16(png16), tf(exr);
  ASSERT_EQ(t16.stream("witness01").bit_depth, 16);
  ASSERT_EQ(tf.stream("witness01").bit_depth, 32);
  double worst = 1;
  long long differ = 0, pixels = 0;
  for (const std::string& cam : t8.cameras()) {
    if (cam == "main") continue;
    carving::KeyerOptions ko;
    ko.soft_alpha = false;
    carving::Keyer k8(ko), k16(ko), kf(ko);
    for (int f : t8.frames()) {
      const CameraImage a = t8.read(cam, f), b = t16.read(cam, f), c = tf.read(cam, f);
      ASSERT_TRUE(a.ok() && b.ok() && c.ok()) << a.dropped << b.dropped << c.dropped;
      // The wider forms hold the picture before 8-bit rounding: read back, it is within one
      // code of the 8-bit plate (a value near .5 rounds either way), most of it equal.
      EXPECT_LE(cv::norm(a.image, b.image, cv::NORM_INF), 1) << cam << " frame " << f;
      EXPECT_LE(cv::norm(a.image, c.image, cv::NORM_INF), 1) << cam << " frame " << f;
      const cv::Mat s8 = k8.key(a.image).silhouette, s16 = k16.key(b.image).silhouette, sf = kf.key(c.image).silhouette;
      for (const cv::Mat* s : {&s16, &sf}) {
        const double v = iou(s8, *s);
        worst = std::min(worst, v);
        EXPECT_GE(v, 0.999) << cam << " frame " << f;
        differ += cv::countNonZero(s8 != *s);
        pixels += s8.total();
      }
    }
  }
  std::printf("{\"stage\": \"key_depths\", \"worst_iou\": %.5f, \"silhouette_px_differing\": %lld, \"of\": %lld}\n", worst,
              differ, pixels);
}

}  // namespace
}  // namespace previz::take
