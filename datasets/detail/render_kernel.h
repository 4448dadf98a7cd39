#pragma once
// renderView's image-formation pieces (datasets/render.h), defined once in datasets/render.cpp
// and shared with the board presets' fast path (datasets/detail/board_view.h, defined in
// datasets/rig_capture.cpp), so that both make the same rays, sums, defocus and sRGB encoding to
// the bit. Not public API.
#include <algorithm>
#include <array>
#include <cstdint>
#include <memory>
#include <vector>

#include <opencv2/core.hpp>

#include "core/camera.h"
#include "core/pose.h"
#include "datasets/scene.h"

namespace previz::synth::detail {

// Linear RGB of pixel spans of one camera at one pose (static scene): renderView's samples (the
// same lens inversion warm-started along the row, sample pattern, double sums and float scale,
// gain folded in), without the truth ray. A span's first pixel starts the inversion cold, so a
// span that does not begin at column 0 may differ from renderView in the last bits of a ray.
class SpanTracer {
 public:
  SpanTracer(const Camera& camera, const Pose& T_world_cam, int samples_per_pixel, double gain);
  ~SpanTracer();
  SpanTracer(const SpanTracer&) = delete;
  SpanTracer& operator=(const SpanTracer&) = delete;

  // Pixels u0..u1 of row v into rgb[3 (u - u0) + c], c = R, G, B.
  //
  // The board shortcut: with 'board' (the scene's last primitive) and 'stage_t' (row v of the
  // scene-without-board's least hit distance over each pixel's samples, rounded down, indexed by
  // u), a sample whose ray meets the board nearer than that is the board's, as Scene::trace
  // would find after testing everything else first, so the full trace is skipped there.
  // 'least_t' (indexed by u) receives each pixel's least hit distance over its samples, rounded
  // down to a float (what 'stage_t' wants).
  void traceRow(const Scene& scene, int v, int u0, int u1, float* rgb,
                const Primitive* board = nullptr, const float* stage_t = nullptr,
                float* least_t = nullptr) const;

 private:
  struct Impl;
  std::unique_ptr<const Impl> impl_;
};

// renderView's sRGB encoding table: 8192 intervals over [0, 1], linear interpolation. Worst
// error about 0.004 grey levels (near the knee at 0.0031), far below the 8-bit step.
class SrgbTable {
 public:
  static constexpr int kSize = 8192;
  SrgbTable();
  // Linear [0, 1] (clamped) -> encoded grey level [0, 255].
  float encode255(float linear) const {
    if (!(linear > 0.0f)) return 0.0f;
    if (linear >= 1.0f) return table_[kSize];
    const float x = linear * kSize;
    const int i = static_cast<int>(x);
    const float f = x - static_cast<float>(i);
    return table_[i] + f * (table_[i + 1] - table_[i]);
  }

 private:
  std::array<float, kSize + 1> table_;
};
const SrgbTable& srgbTable();  // built once, thread-safe

// renderView's rounding to 8 bits: clamp to [0, 255], round half up (the truncation of a
// non-negative value is its floor).
inline std::uint8_t quantize255(double value) {
  return static_cast<std::uint8_t>(std::clamp(value, 0.0, 255.0) + 0.5);
}

// renderView's defocus: separable Gaussian on a float image (any channel count), clamp-to-edge
// borders, radius ceil(4 sigma). Each output value is a fixed-order sum, so the result does not
// depend on the thread count, and a window blurred here equals the same pixels of a whole-frame
// blur wherever the window reaches radius() beyond them or ends at the image border.
class GaussianBlur {
 public:
  explicit GaussianBlur(double sigma);
  int radius() const { return radius_; }
  cv::Mat apply(const cv::Mat& src, int threads) const;

 private:
  int radius_;
  std::vector<float> kernel_;
};

}  // namespace previz::synth::detail
