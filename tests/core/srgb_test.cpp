// sRGB on 8-bit codes (core/srgb.h): the table-free encode must round exactly as
// lround(255 * encode(x)) does, everywhere in [0, 1] (the despill and the keyer used pow() per
// pixel; their outputs must not move by a code).
#include "core/srgb.h"

#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include <gtest/gtest.h>

namespace previz {
namespace {

// The reference: IEC 61966-2-1 encode in double, rounded to the nearest code.
int referenceCode(float linear) {
  if (!(linear > 0.0f)) return 0;
  if (linear >= 1.0f) return 255;
  const double l = linear;
  const double c = l <= 0.0031308 ? 12.92 * l : 1.055 * std::pow(l, 1.0 / 2.4) - 0.055;
  return static_cast<int>(std::lround(c * 255.0));
}

TEST(Srgb, DecodeTableIsTheStandardCurve) {
  const auto& t = srgb8ToLinear();
  EXPECT_EQ(t[0], 0.0f);
  EXPECT_EQ(t[255], 1.0f);
  EXPECT_NEAR(t[10], 10.0 / 255.0 / 12.92, 1e-9);                          // linear toe
  EXPECT_NEAR(t[128], std::pow((128 / 255.0 + 0.055) / 1.055, 2.4), 1e-7);  // 0.2158605
  for (int i = 1; i < 256; ++i) EXPECT_GT(t[i], t[i - 1]) << i;
}

TEST(Srgb, EncodeRoundTripsEveryCode) {
  const auto& t = srgb8ToLinear();
  for (int i = 0; i < 256; ++i) EXPECT_EQ(linearToSrgb8(t[i]), i) << i;
}

TEST(Srgb, EncodeMatchesTheRoundedCurve) {
  // Two float steps either side of every decision level (where a one-code error would show),
  // then 2 million uniform and 2 million log-uniform values (the darks).
  int checked = 0;
  for (int i = 0; i < 255; ++i) {
    const double level = std::pow(((i + 0.5) / 255.0 + 0.055) / 1.055, 2.4);
    const double toe = (i + 0.5) / 255.0 / 12.92;
    float x = static_cast<float>((i + 0.5) / 255.0 <= 0.04045 ? toe : level);
    x = std::nextafter(std::nextafter(x, 0.0f), 0.0f);
    for (int k = 0; k < 5; ++k, x = std::nextafter(x, 1.0f)) {
      EXPECT_EQ(linearToSrgb8(x), referenceCode(x)) << "level " << i << " x " << x;
      ++checked;
    }
  }
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> uniform(0.0f, 1.0f), exponent(-12.0f, 0.0f);
  int mismatches = 0;
  for (int n = 0; n < 2000000; ++n) {
    const float a = uniform(rng), b = std::pow(10.0f, exponent(rng));
    mismatches += linearToSrgb8(a) != referenceCode(a);
    mismatches += linearToSrgb8(b) != referenceCode(b);
    checked += 2;
  }
  EXPECT_EQ(mismatches, 0) << "of " << checked;
}

// The table-driven batch encode gives the search's code for every value: around every decision
// level, over uniform and log-uniform values, and out of range.
TEST(Srgb, BatchEncodeEqualsTheSearch) {
  std::vector<float> x;
  for (int i = 0; i < 255; ++i) {
    const double level = std::pow(((i + 0.5) / 255.0 + 0.055) / 1.055, 2.4);
    const double toe = (i + 0.5) / 255.0 / 12.92;
    float v = static_cast<float>((i + 0.5) / 255.0 <= 0.04045 ? toe : level);
    for (int k = 0; k < 3; ++k) v = std::nextafter(v, 0.0f);
    for (int k = 0; k < 7; ++k, v = std::nextafter(v, 1.0f)) x.push_back(v);
  }
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> uniform(-0.1f, 1.1f), exponent(-12.0f, 0.0f);
  for (int n = 0; n < 1000000; ++n) {
    x.push_back(uniform(rng));
    x.push_back(std::pow(10.0f, exponent(rng)));
  }
  x.push_back(std::numeric_limits<float>::quiet_NaN());
  x.push_back(std::numeric_limits<float>::infinity());
  std::vector<std::uint8_t> codes(x.size());
  linearToSrgb8(x.data(), codes.data(), x.size());
  size_t mismatches = 0;
  for (size_t i = 0; i < x.size(); ++i) mismatches += codes[i] != linearToSrgb8(x[i]);
  EXPECT_EQ(mismatches, 0u) << "of " << x.size();
}

TEST(Srgb, EncodeClampsOutOfRangeAndNan) {
  EXPECT_EQ(linearToSrgb8(-0.5f), 0);
  EXPECT_EQ(linearToSrgb8(0.0f), 0);
  EXPECT_EQ(linearToSrgb8(std::numeric_limits<float>::quiet_NaN()), 0);
  EXPECT_EQ(linearToSrgb8(1.0f), 255);
  EXPECT_EQ(linearToSrgb8(7.0f), 255);
  EXPECT_EQ(linearToSrgb8(std::numeric_limits<float>::infinity()), 255);
  EXPECT_EQ(linearToSrgb8(0.2158605f), 128);
}

}  // namespace
}  // namespace previz
