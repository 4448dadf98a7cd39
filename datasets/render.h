#pragma once
// CPU renderer of the synthetic studio: one camera view of a Scene through a previz::Camera
// with its TRUE distortion (every sample's ray comes from the inverse of the Brown model, so
// an image point lands exactly where Camera::project puts the 3-D point), plus exact truth
// layers (depth, object class, actor mask) from the pixel-centre ray.
// Pixel (u, v) covers [u - 0.5, u + 0.5] x [v - 0.5, v + 0.5] (docs/conventions.md).
//
// Image formation, in order: stratified sub-pixel samples (fixed pattern, identical for every
// pixel, seed-independent) -> mean linear radiance -> gain -> optional defocus (Gaussian, in
// linear light) -> sRGB encode to [0, 255] -> optional additive Gaussian noise (grey levels,
// counter-based hash of seed/camera/frame/pixel/channel) -> round to 8 bits.
// Output is bit-identical for any thread count.
#include <cstdint>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "core/camera.h"
#include "core/pose.h"
#include "core/srgb.h"
#include "datasets/scene.h"

namespace previz::synth {

struct RenderOptions {
  int samples_per_pixel = 4;   // >= 4; a perfect square gives an n-rooks n x n pattern
  double gain = 1.0;           // linear radiance multiplier (per-camera brightness), > 0
  double blur_sigma_px = 0.0;  // defocus: Gaussian sigma in pixels, applied in linear light
  double noise_sigma = 0.0;    // additive Gaussian noise after encoding, grey levels (0..255)
  std::uint64_t seed = 1;      // noise stream (the sample pattern never depends on it)
  int camera_index = 0;        // noise stream
  int frame = 0;               // noise stream
  bool truth = true;           // also fill depth / labels / mask from the pixel-centre ray
  bool keep_encoded = false;   // also fill RenderedView::encoded (16-bit and float plates)
  int threads = 0;             // OpenMP threads for this call (0 = OpenMP's default)

  void validate() const;  // throws Error naming the field
};

// One instant within the shutter interval: the scene and the camera pose at that time.
struct ShutterSample {
  const Scene* scene = nullptr;
  Pose T_world_cam = Pose::Identity();
};

struct RenderedView {
  cv::Mat bgr;     // CV_8UC3, sRGB-encoded
  cv::Mat depth;   // CV_32FC1, metric z along the camera axis, +inf where nothing is hit
  cv::Mat labels;  // CV_8UC1, ObjectClass of the pixel-centre hit
  cv::Mat mask;    // CV_8UC1, 255 where the pixel-centre ray hits the actor, else 0
  // With keep_encoded: the picture before 8-bit rounding (CV_32FC3 BGR, sRGB-coded, noise
  // included, clamped to [0, 1]); bgr is exactly its codes rounded. Deeper plates store this.
  cv::Mat encoded;
  int not_invertible = 0;  // pixels whose centre lies past the lens' fold (rendered black)
};

struct LinearView {
  cv::Mat rgb;    // CV_32FC3, linear radiance, channel order R, G, B (EXR-ready)
  cv::Mat depth;  // CV_32FC1, as RenderedView::depth
};

// Sub-pixel offsets in (-0.5, 0.5)^2 used for every pixel. n x n (spp = n^2): the canonical
// multi-jittered arrangement without jitter, i.e. one sample per cell of the n x n grid AND one
// per row and column of the n^2 x n^2 grid, so near-axis-aligned edges get n^2 + 1 coverage
// levels instead of n + 1. Other counts: a Hammersley set (also one sample per column).
std::vector<Eigen::Vector2d> samplePattern(int samples_per_pixel);

// Static scene, one camera pose.
RenderedView renderView(const Camera& camera, const Pose& T_world_cam, const Scene& scene,
                        const RenderOptions& options);
// Motion blur: sample k of pixel (u, v) sees instant (k + u + 2 v) mod shutter.size(), so with
// spp a multiple of shutter.size() every pixel averages every instant equally. Truth layers come
// from 'centre' (the frame's nominal time).
RenderedView renderView(const Camera& camera, const std::vector<ShutterSample>& shutter,
                        const ShutterSample& centre, const RenderOptions& options);

// Linear colour + depth (the CG renders): anti-aliased and motion-blurred like renderView, no
// gain, blur, noise or encoding. Usually called with an ideal pinhole (idealPinhole()).
LinearView renderLinear(const Camera& camera, const std::vector<ShutterSample>& shutter,
                        const ShutterSample& centre, int samples_per_pixel, int threads = 0);

// sRGB transfer function (IEC 61966-2-1), [0, 1] -> [0, 1], clamped: core/srgb.h's.
using previz::srgbDecode;
using previz::srgbEncode;

// Pixel-centre ray in the camera frame (unit, z > 0); false past the lens' fold. Exposed so
// truth and tests trace exactly the rays the renderer traces.
bool pixelRay(const Camera& camera, const Eigen::Vector2d& px, Eigen::Vector3d& dir_cam);

}  // namespace previz::synth
