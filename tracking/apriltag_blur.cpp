// libapriltag's quad-search blur, the same integers (tracking/detail/apriltag_blur.h).
#include "tracking/detail/apriltag_blur.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

namespace previz::tracking::detail {
namespace {

// The 8-bit kernel of image_u8_gaussian_blur(im, sigma, ksz): exp(-x^2 / (2 sigma^2)) at
// x = -ksz/2 .. ksz/2 in double, normalised to sum 1, each weight * 255 truncated. The weights sum
// to at most 255, so a sum of weight * 8-bit value is at most 255 * 255 and fits 16 bits.
std::vector<std::uint16_t> kernel(double sigma, int ksz) {
  std::vector<double> dk(ksz);
  for (int i = 0; i < ksz; ++i) {
    const int x = -ksz / 2 + i;
    const double t = x / sigma;
    dk[i] = std::exp(-.5 * (t * t));
  }
  double acc = 0;
  for (int i = 0; i < ksz; ++i) acc += dk[i];
  std::vector<std::uint16_t> k(ksz);
  for (int i = 0; i < ksz; ++i) k[i] = static_cast<std::uint8_t>(dk[i] / acc * 255);
  return k;
}

// out[x] = (sum_j k[j] src[j][x]) >> 8 for x < n: one 1-D pass, its sources j along the row
// (in + j) or down the column (row y - ksz/2 + j). Sums in 16 bits, 8-16 pixels a step.
void weightedSum(const std::vector<std::uint16_t>& k, const std::vector<const std::uint8_t*>& src,
                 int n, std::vector<std::uint16_t>& acc, std::uint8_t* out) {
  for (int x = 0; x < n; ++x) acc[x] = static_cast<std::uint16_t>(k[0] * src[0][x]);
  for (size_t j = 1; j < k.size(); ++j) {
    const std::uint16_t kj = k[j];
    const std::uint8_t* s = src[j];
    for (int x = 0; x < n; ++x) acc[x] = static_cast<std::uint16_t>(acc[x] + kj * s[x]);
  }
  for (int x = 0; x < n; ++x) out[x] = static_cast<std::uint8_t>(acc[x] >> 8);
}

}  // namespace

int apriltagBlurSize(float quad_sigma) {
  const float sigma = std::fabs(quad_sigma);
  int ksz = static_cast<int>(4 * sigma);  // libapriltag: 2 standard deviations each way
  if ((ksz & 1) == 0) ++ksz;
  return ksz;
}

bool apriltagBlur(cv::Mat& grey, float quad_sigma, ApriltagBlurScratch& scratch) {
  CV_Assert(grey.type() == CV_8UC1);
  if (!(quad_sigma > 0)) return false;
  const int ksz = apriltagBlurSize(quad_sigma);
  const int W = grey.cols, H = grey.rows, h = ksz / 2;
  if (ksz <= 1 || W <= ksz || H <= ksz) return false;
  const std::vector<std::uint16_t> k = kernel(static_cast<double>(std::fabs(quad_sigma)), ksz);
  // libapriltag's 1-D pass over n values: out[i] = in[i] for i < ksz/2 and i >= n - ksz + ksz/2,
  // else (sum_j k[j] in[i - ksz/2 + j]) >> 8. Rows first, then columns (here: rows of the
  // row-blurred image, each column's sum the same).
  scratch.rows.resize(static_cast<size_t>(W) * H);
  scratch.acc.resize(W);
  scratch.src.resize(ksz);
  cv::Mat rows(H, W, CV_8UC1, scratch.rows.data());
  std::vector<std::uint16_t>& acc = scratch.acc;
  std::vector<const std::uint8_t*>& src = scratch.src;
  const int n = W - ksz;  // positions blurred in a row
  for (int y = 0; y < H; ++y) {
    const std::uint8_t* in = grey.ptr<std::uint8_t>(y);
    std::uint8_t* out = rows.ptr<std::uint8_t>(y);
    for (int j = 0; j < ksz; ++j) src[j] = in + j;
    for (int x = 0; x < h; ++x) out[x] = in[x];
    weightedSum(k, src, n, acc, out + h);
    for (int x = n + h; x < W; ++x) out[x] = in[x];
  }
  for (int y = 0; y < H; ++y) {
    std::uint8_t* out = grey.ptr<std::uint8_t>(y);
    if (y < h || y >= H - ksz + h) {
      const std::uint8_t* in = rows.ptr<std::uint8_t>(y);
      std::copy(in, in + W, out);
      continue;
    }
    for (int j = 0; j < ksz; ++j) src[j] = rows.ptr<std::uint8_t>(y - h + j);
    weightedSum(k, src, W, acc, out);
  }
  return true;
}

}  // namespace previz::tracking::detail
