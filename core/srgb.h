#pragma once
// The sRGB transfer function (IEC 61966-2-1): the curve itself, and on 8-bit codes, for the
// per-pixel loops that render, key, despill, refine and composite camera plates in linear light,
// a decode table and an encode that gives exactly lround(255 * encode(linear)) without a pow()
// per pixel.
#include <array>
#include <cstddef>
#include <cstdint>

namespace previz {

// The transfer function, [0, 1] -> [0, 1], clamped (NaN -> 0).
double srgbEncode(double linear);
double srgbDecode(double encoded);

// Code value 0..255 -> linear light in [0, 1].
const std::array<float, 256>& srgb8ToLinear();

// Linear light -> the nearest 8-bit sRGB code (0 for <= 0 and NaN, 255 for >= 1): the count of
// the 255 decision levels (the linear values of codes i + 0.5, i = 0..254) at or below
// 'linear', found by binary search. Equal to rounding the exact encode; the decision levels are
// computed in double once.
std::uint8_t linearToSrgb8(float linear);
// The same over n values, for float images: a 2^16-bin table over [0, 1] answers every bin that
// holds no decision level, the search above the few that do (the same codes, ~10x faster).
void linearToSrgb8(const float* linear, std::uint8_t* codes, size_t n);

}  // namespace previz
