#include "core/srgb.h"

#include <cmath>
#include <vector>

namespace previz {
namespace {

// Decision levels: level[i] = linear value of code i + 0.5, i = 0..254; level[255] = +inf pads
// the search to 256 entries.
const std::array<double, 256>& decisionLevels() {
  static const std::array<double, 256> levels = [] {
    std::array<double, 256> t{};
    for (int i = 0; i < 255; ++i) t[i] = srgbDecode((i + 0.5) / 255.0);
    t[255] = HUGE_VAL;
    return t;
  }();
  return levels;
}

}  // namespace

double srgbEncode(double linear) {
  if (!(linear > 0)) return 0;
  if (linear >= 1) return 1;
  return linear <= 0.0031308 ? 12.92 * linear : 1.055 * std::pow(linear, 1.0 / 2.4) - 0.055;
}

double srgbDecode(double encoded) {
  if (!(encoded > 0)) return 0;
  if (encoded >= 1) return 1;
  return encoded <= 0.04045 ? encoded / 12.92 : std::pow((encoded + 0.055) / 1.055, 2.4);
}

const std::array<float, 256>& srgb8ToLinear() {
  static const std::array<float, 256> table = [] {
    std::array<float, 256> t{};
    for (int i = 0; i < 256; ++i) t[i] = static_cast<float>(srgbDecode(i / 255.0));
    return t;
  }();
  return table;
}

std::uint8_t linearToSrgb8(float linear) {
  if (!(linear > 0.0f)) return 0;
  if (linear >= 1.0f) return 255;
  const std::array<double, 256>& level = decisionLevels();
  const double x = linear;
  // Branch-free binary search for the number of levels <= x (levels ascend; level[255] = inf).
  int i = 0;
  for (int step = 128; step > 0; step >>= 1)
    if (level[i + step - 1] <= x) i += step;
  return static_cast<std::uint8_t>(i);
}

void linearToSrgb8(const float* linear, std::uint8_t* codes, size_t n) {
  constexpr int kBins = 1 << 16;
  // Per bin [b, b + 1) / kBins: its code, or 0xFFFF when a decision level falls inside it.
  static const std::vector<std::uint16_t> table = [] {
    std::vector<std::uint16_t> t(kBins);
    for (int b = 0; b < kBins; ++b) {
      const std::uint8_t lo = linearToSrgb8(static_cast<float>(b) / kBins);
      const std::uint8_t hi = linearToSrgb8(std::nextafter(static_cast<float>(b + 1) / kBins, 0.0f));
      t[b] = lo == hi ? lo : 0xFFFF;
    }
    return t;
  }();
  for (size_t i = 0; i < n; ++i) {
    const float x = linear[i];
    if (!(x > 0.0f)) {
      codes[i] = 0;
    } else if (x >= 1.0f) {
      codes[i] = 255;
    } else {
      const std::uint16_t c = table[static_cast<int>(x * kBins)];
      codes[i] = c != 0xFFFF ? static_cast<std::uint8_t>(c) : linearToSrgb8(x);
    }
  }
}

}  // namespace previz
