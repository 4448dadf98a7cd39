#include "live/bin_light.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include <opencv2/core/hal/intrin.hpp>

#include "core/error.h"
#include "core/simd.h"

namespace previz::live {

namespace {

// round(sqrt(m)) for every mean of squared codes m (<= 255^2).
const std::uint8_t* rootTable() {
  static const std::vector<std::uint8_t> root = [] {
    std::vector<std::uint8_t> t(65536);
    for (int m = 0; m < 65536; ++m) t[m] = static_cast<std::uint8_t>(std::min(255L, std::lround(std::sqrt(m))));
    return t;
  }();
  return root.data();
}

// Output pixel x of a bin-2 row from plate rows p0 and p1 (columns past the edge repeat the last).
inline void bin2Pixel(const std::uint8_t* p0, const std::uint8_t* p1, int cols, int x, const std::uint8_t* root,
                      std::uint8_t* o) {
  const int c0 = std::min(2 * x, cols - 1), c1 = std::min(2 * x + 1, cols - 1);
  for (int ch = 0; ch < 3; ++ch) {
    const std::uint32_t a = p0[3 * c0 + ch], b = p0[3 * c1 + ch], c = p1[3 * c0 + ch], d = p1[3 * c1 + ch];
    o[3 * x + ch] = root[(a * a + b * b + c * c + d * d + 2) / 4];
  }
}

#if CV_SIMD128
// 8 output pixels' means from 16 plate pixels of one channel in rows 0 and 1: v_dotprod of a
// row with itself sums the squares of each pixel pair, exactly, in s32 (pmaddwd).
[[gnu::always_inline]] inline cv::v_int32x4 bin2Means(const cv::v_int16x8& r0, const cv::v_int16x8& r1) {
  return (cv::v_dotprod(r0, r0) + cv::v_dotprod(r1, r1) + cv::v_setall_s32(2)) >> 2;
}

// round(sqrt(m)): m <= 255^2, whose square root float computes to within 2e-5 of the true one,
// while the square root of an integer is never nearer than 5e-4 to a half: the table's bytes.
[[gnu::always_inline]] inline cv::v_int32x4 bin2Root(const cv::v_int32x4& m) {
  return cv::v_round(cv::v_sqrt(cv::v_cvt_f32(m)));
}

// 16 output pixels of one channel from 32 plate pixels of rows 0 and 1 (a: plate pixels 0-15,
// b: 16-31).
[[gnu::always_inline]] inline cv::v_uint8x16 bin2Channel(const cv::v_uint8x16& a0, const cv::v_uint8x16& b0,
                                                         const cv::v_uint8x16& a1, const cv::v_uint8x16& b1) {
  cv::v_uint16x8 a0l, a0h, b0l, b0h, a1l, a1h, b1l, b1h;
  cv::v_expand(a0, a0l, a0h);
  cv::v_expand(b0, b0l, b0h);
  cv::v_expand(a1, a1l, a1h);
  cv::v_expand(b1, b1l, b1h);
  using cv::v_reinterpret_as_s16;
  const cv::v_int32x4 m0 = bin2Root(bin2Means(v_reinterpret_as_s16(a0l), v_reinterpret_as_s16(a1l)));
  const cv::v_int32x4 m1 = bin2Root(bin2Means(v_reinterpret_as_s16(a0h), v_reinterpret_as_s16(a1h)));
  const cv::v_int32x4 m2 = bin2Root(bin2Means(v_reinterpret_as_s16(b0l), v_reinterpret_as_s16(b1l)));
  const cv::v_int32x4 m3 = bin2Root(bin2Means(v_reinterpret_as_s16(b0h), v_reinterpret_as_s16(b1h)));
  return cv::v_pack_u(cv::v_pack(m0, m1), cv::v_pack(m2, m3));
}
#endif

PREVIZ_WIDE
void bin2(const cv::Mat& src, cv::Size size, cv::Mat& dst) {
  const std::uint8_t* root = rootTable();
  const int cols = src.cols;
  // Output pixels whose 2 x 2 blocks lie inside the plate's columns, 16 at a time.
  const int whole = std::min(size.width, cols / 2);
  for (int y = 0; y < size.height; ++y) {
    const std::uint8_t* p0 = src.ptr<std::uint8_t>(std::min(2 * y, src.rows - 1));
    const std::uint8_t* p1 = src.ptr<std::uint8_t>(std::min(2 * y + 1, src.rows - 1));
    std::uint8_t* o = dst.ptr<std::uint8_t>(y);
    int x = 0;
#if CV_SIMD128
    for (; x + 16 <= whole; x += 16) {
      cv::v_uint8x16 b0a, g0a, r0a, b0b, g0b, r0b, b1a, g1a, r1a, b1b, g1b, r1b;
      cv::v_load_deinterleave(p0 + 6 * x, b0a, g0a, r0a);
      cv::v_load_deinterleave(p0 + 6 * x + 48, b0b, g0b, r0b);
      cv::v_load_deinterleave(p1 + 6 * x, b1a, g1a, r1a);
      cv::v_load_deinterleave(p1 + 6 * x + 48, b1b, g1b, r1b);
      cv::v_store_interleave(o + 3 * x, bin2Channel(b0a, b0b, b1a, b1b), bin2Channel(g0a, g0b, g1a, g1b),
                             bin2Channel(r0a, r0b, r1a, r1b));
    }
#endif
    for (; x < size.width; ++x) bin2Pixel(p0, p1, cols, x, root, o);
  }
}

}  // namespace

void binLight(const cv::Mat& src, int bin, cv::Size size, cv::Mat& dst) {
  if (src.empty() || src.type() != CV_8UC3)
    throw Error("binning: the plate must be 8-bit BGR (got " +
                (src.empty() ? std::string("an empty image") : cv::typeToString(src.type())) + ")");
  if (bin < 1 || size.width < 1 || size.height < 1 || size.width > (src.cols + bin - 1) / bin ||
      size.height > (src.rows + bin - 1) / bin)
    throw Error("binning: " + std::to_string(src.cols) + "x" + std::to_string(src.rows) + " cannot bin " +
                std::to_string(bin) + " x " + std::to_string(bin) + " into " + std::to_string(size.width) + "x" +
                std::to_string(size.height));
  dst.create(size, CV_8UC3);
  if (bin == 2) {
    bin2(src, size, dst);
    return;
  }
  const std::uint8_t* root = rootTable();
  const int area = bin * bin;
  const int n = 3 * src.cols;
  // Plate columns past the last whole block repeat the last one; a binned size rounded down
  // leaves plate columns no block reads, so the buffer holds whichever is longer.
  std::vector<std::uint32_t> acc(std::max<size_t>(n, static_cast<size_t>(3) * size.width * bin));
  for (int y = 0; y < size.height; ++y) {
    // Squared codes summed down the block's rows (contiguous: the compiler vectorises it).
    std::uint32_t* a = acc.data();
    std::fill(a, a + n, 0u);
    for (int k = 0; k < bin; ++k) {
      const std::uint8_t* p = src.ptr<std::uint8_t>(std::min(y * bin + k, src.rows - 1));
      for (int i = 0; i < n; ++i) a[i] += static_cast<std::uint32_t>(p[i]) * p[i];
    }
    for (int i = n; i < static_cast<int>(acc.size()); ++i) a[i] = a[i - 3];  // repeat the last column
    std::uint8_t* o = dst.ptr<std::uint8_t>(y);
    for (int x = 0; x < size.width; ++x) {
      const std::uint32_t* q = a + 3 * bin * x;
      std::uint32_t b = 0, g = 0, r = 0;
      for (int j = 0; j < bin; ++j, q += 3) {
        b += q[0];
        g += q[1];
        r += q[2];
      }
      o[3 * x] = root[(b + area / 2) / area];
      o[3 * x + 1] = root[(g + area / 2) / area];
      o[3 * x + 2] = root[(r + area / 2) / area];
    }
  }
}

}  // namespace previz::live
