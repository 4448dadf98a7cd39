#pragma once
// Carving's view of one witness camera: a flattened projection (world -> pixel with the true
// Brown distortion) cheap enough for the inner loops, the conservative padding that makes a
// cell's bounding rectangle contain its true (curved) footprint, and one frame's silhouette as
// a binarized region of interest with its integral image. Internal to carving/hull.cpp.
//
// Why distorted projection rather than undistorted silhouettes: undistorting 8 silhouettes per
// frame is a remap of every pixel (~1 ms per 1280x720 camera), a fifth of the whole carve
// budget, and it resamples the matte (its edge moves by up to half a pixel). Projecting cell
// corners through the true lens costs a few flops per corner and tests the silhouette exactly
// as the keyer produced it. The price is that a cell's footprint is no longer the convex hull of
// its projected corners; the bound below (padForDiameter) restores conservativeness.
#include <cmath>
#include <algorithm>
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "core/lens_model.h"
#include "core/rig.h"

namespace previz::carving::detail {

// Points nearer than this to a camera's image plane (camera z, metres) are not seen by it.
constexpr double kZNear = 1e-3;
// Added to every footprint (px): covers rounding between the lattice projection used for cells
// and the direct projection of the point test, so that both always agree on a pixel.
constexpr double kPadEpsPx = 0.01;

// What one camera says about a point or a cell.
enum CamState : std::uint8_t {
  kUnseen = 0,  // projects outside the image (or behind the camera): never carves
  kOut = 1,     // wholly outside the silhouette
  kIn = 2,      // wholly inside the silhouette
  kMixed = 3,   // cells only: some of each, or partly seen
};

struct CameraModel {
  std::string name;
  int width = 0, height = 0;
  double R[9] = {};  // world -> camera rotation, row-major
  double t[3] = {};  // world -> camera translation
  double fx = 0, fy = 0, cx = 0, cy = 0, skew = 0;
  double k1 = 0, k2 = 0, p1 = 0, p2 = 0, k3 = 0, k4 = 0, k5 = 0, k6 = 0;  // core/camera.h's Distortion
  bool distorted = false;
  bool kannala_brandt = false;  // the lens model (core/lens_model.h): else Brown–Conrady
  bool rational = false;        // Brown–Conrady with k4 k5 k6 (else the plain model, no division)
  // Ideal normalized radius^2 past which a point counts as unseen: just beyond what the image
  // border undistorts to, and inside the lens' invertible domain (past its fold the model maps
  // points back into the image, which would carve with points the camera cannot see).
  double r2_valid = 0;
  // A convex region of ideal normalized diameter d maps through the distortion into the convex
  // hull of its mapped corners grown by 0.5 * M2 * d^2 (M2: bound on the second derivative of
  // the distortion over the valid disc); in pixels that is pad_per_diam2 * d^2.
  double pad_per_diam2 = 0;
  // Second-order bound of the whole world -> pixel map (perspective and distortion) over a
  // region whose ideal footprint stays in the valid disc: |pixel(c + h) - pixel(c) - J h| <=
  // pad_per_h2 * |h|^2 / z_min^2 (z_min: nearest camera z of the region). See affineFootprint.
  double pad_per_h2 = 0;
  double r_valid = 0;
  Eigen::Vector3d centre_world = Eigen::Vector3d::Zero();

  // Ideal normalized (x, y) -> pixel (u, v).
  inline void toPixel(double x, double y, double& u, double& v) const {
    double xd = x, yd = y;
    if (kannala_brandt) lens::kannalaBrandtDistort(k1, k2, k3, k4, x, y, xd, yd);
    else if (rational) lens::brownDistort(k1, k2, p1, p2, k3, k4, k5, k6, x, y, xd, yd);
    else if (distorted) lens::brownDistort<false>(k1, k2, p1, p2, k3, k4, k5, k6, x, y, xd, yd);
    u = fx * xd + skew * yd + cx;
    v = fy * yd + cy;
  }
  inline void toCamera(const double* p, double* q) const {
    q[0] = R[0] * p[0] + R[1] * p[1] + R[2] * p[2] + t[0];
    q[1] = R[3] * p[0] + R[4] * p[1] + R[5] * p[2] + t[1];
    q[2] = R[6] * p[0] + R[7] * p[1] + R[8] * p[2] + t[2];
  }
  // d pixel / d (ideal normalized) at (x, y), row-major 2x2.
  inline void pixelJacobian(double x, double y, double* J) const {
    double a = 1, b = 0, c = 0, d = 1;  // d distort / d x
    if (distorted) {
      double xd, yd;
      if (kannala_brandt) lens::kannalaBrandtDistortWithJacobian(k1, k2, k3, k4, x, y, xd, yd, a, b, d);
      else if (rational) lens::brownDistortWithJacobian(k1, k2, p1, p2, k3, k4, k5, k6, x, y, xd, yd, a, b, d);
      else lens::brownDistortWithJacobian<false>(k1, k2, p1, p2, k3, k4, k5, k6, x, y, xd, yd, a, b, d);
      c = b;
    }
    J[0] = fx * a + skew * c;
    J[1] = fx * b + skew * d;
    J[2] = fy * c;
    J[3] = fy * d;
  }
  // Camera-frame point -> pixel; false when unseen for geometric reasons (behind, past the
  // valid disc). Does not clip to the image.
  inline bool project(const double* q, double& u, double& v) const {
    if (!(q[2] > kZNear)) return false;
    const double iz = 1.0 / q[2];
    const double x = q[0] * iz, y = q[1] * iz;
    if (x * x + y * y > r2_valid) return false;
    toPixel(x, y, u, v);
    return true;
  }
};

// Builds the model of a rig camera (validates it; throws Error naming the camera).
CameraModel makeCameraModel(const RigCamera& camera);

// One camera's silhouette for one frame. Only the bounding box of the inside pixels is kept:
// everything outside it is outside. Inside it, the silhouette is kept twice: bit-packed rows
// (1 bit per pixel, a few kB per camera, so the small footprints of fine cells and the point
// test read cache-resident memory) and an integral image for footprints too wide for one
// 64-bit read per row (coarse cells only).
struct FrameCam {
  static constexpr int kMaxBitSpan = 57;  // widest row span read with one unaligned 64-bit load

  bool used = false;
  int width = 0, height = 0;
  int x0 = 0, y0 = 0, x1 = -1, y1 = -1;  // inclusive bbox of inside pixels (empty: x1 < x0)
  std::vector<std::uint8_t> bits;        // row r (image row y0 + r) at bits.data() + r * stride
  int stride = 0;                        // bytes per packed row (8 bytes of slack at the end)
  cv::Mat integral;                      // CV_32SC1 (h+1) x (w+1) over the bbox

  // Pixel (OpenCV centre convention) -> inside? Caller guarantees 0 <= iu < width etc.
  inline bool insidePixel(int iu, int iv) const {
    if (iu < x0 || iu > x1 || iv < y0 || iv > y1) return false;
    const int c = iu - x0;
    return (bits[static_cast<size_t>(iv - y0) * stride + (c >> 3)] >> (c & 7)) & 1;
  }
  // Number of inside pixels in [u0, u1] x [v0, v1] (inclusive, within the bbox).
  inline long long count(int u0, int u1, int v0, int v1) const {
    const int c0 = u0 - x0, c1 = u1 - x0 + 1, r0 = v0 - y0, r1 = v1 - y0 + 1;
    const std::int32_t* top = integral.ptr<std::int32_t>(r0);
    const std::int32_t* bottom = integral.ptr<std::int32_t>(r1);
    return static_cast<long long>(bottom[c1]) - bottom[c0] - top[c1] + top[c0];
  }
  // State of the pixels [u0, u1] x [v0, v1] (within the image): kOut / kIn / kMixed.
  inline CamState rectPixels(int u0, int u1, int v0, int v1) const {
    const int a0 = std::max(u0, x0), a1 = std::min(u1, x1);
    const int b0 = std::max(v0, y0), b1 = std::min(v1, y1);
    if (a0 > a1 || b0 > b1) return kOut;  // no overlap with the bbox: all outside
    // Pixels of the rectangle outside the bbox are outside, so it cannot be wholly inside.
    const bool clipped = a0 != u0 || a1 != u1 || b0 != v0 || b1 != v1;
    const int w = a1 - a0 + 1;
    if (w > kMaxBitSpan) {
      const long long n = count(a0, a1, b0, b1);
      if (n == 0) return kOut;
      return !clipped && n == static_cast<long long>(w) * (b1 - b0 + 1) ? kIn : kMixed;
    }
    const std::uint64_t mask = (std::uint64_t{1} << w) - 1;
    const int c = a0 - x0;
    const std::uint8_t* p = bits.data() + static_cast<size_t>(b0 - y0) * stride + (c >> 3);
    const int shift = c & 7;
    bool any = false, all = !clipped;
    for (int r = b0; r <= b1; ++r, p += stride) {
      std::uint64_t word;
      std::memcpy(&word, p, sizeof word);  // little-endian: bit i of the row = pixel x0 + i
      const std::uint64_t m = (word >> shift) & mask;
      any |= m != 0;
      all &= m == mask;
      if (any && !all) return kMixed;
    }
    return any ? kIn : kOut;
  }
};

// Binarizes (> 127 = inside) and integrates one silhouette.
FrameCam makeFrameCam(const cv::Mat& mask);

// floor() for pixel coordinates in (-1e8, 1e8): the baseline x86-64 target has no rounding
// instruction, std::floor becomes a libm call and the compare-and-correct idiom a long
// dependency chain in the hottest loops; shifted positive, truncation is floor.
inline int floorToInt(double x) {
  return static_cast<int>(x + 1e8) - 100000000;
}

// State of a camera-frame point in one camera (kUnseen / kOut / kIn).
inline CamState cameraPointState(const CameraModel& cam, const FrameCam& frame, const double* q) {
  double u, v;
  if (!cam.project(q, u, v)) return kUnseen;
  const int iu = floorToInt(u + 0.5);
  const int iv = floorToInt(v + 0.5);
  if (iu < 0 || iv < 0 || iu >= cam.width || iv >= cam.height) return kUnseen;
  return frame.insidePixel(iu, iv) ? kIn : kOut;
}

// State of a world point in one camera (kUnseen / kOut / kIn).
inline CamState pointState(const CameraModel& cam, const FrameCam& frame, const double* p) {
  double q[3];
  cam.toCamera(p, q);
  return cameraPointState(cam, frame, q);
}

// State of a cell in one camera from the pixel-space rectangle that contains its footprint
// (already padded). A rectangle partly off the image is kMixed: its off-image part is unseen.
inline CamState rectState(const FrameCam& frame, double umin, double umax, double vmin,
                          double vmax) {
  // Far off-image rectangles (huge coarse footprints) are clamped before the int conversion.
  const double lim = 1e7;
  const int u0 = floorToInt(std::max(umin, -lim) + 0.5);
  const int u1 = floorToInt(std::min(umax, lim) + 0.5);
  const int v0 = floorToInt(std::max(vmin, -lim) + 0.5);
  const int v1 = floorToInt(std::min(vmax, lim) + 0.5);
  if (u1 < 0 || v1 < 0 || u0 >= frame.width || v0 >= frame.height) return kUnseen;
  if (u0 < 0 || v0 < 0 || u1 >= frame.width || v1 >= frame.height) return kMixed;
  return frame.rectPixels(u0, u1, v0, v1);
}

}  // namespace previz::carving::detail
