#pragma once
// Depth-aware compositing of the keyed main plate over the engine's CG frame, per pixel, in one
// pass (the live frame's last stage, budget 2 ms at 1920x1080):
//  - The CG arrives as linear colour + metric depth rendered through an ideal pinhole (usually
//    with overscan, core/distortion_maps.h idealPinhole). It is distorted to the real lens by a
//    map built once per lens state with the iterative inverse of Brown's model
//    (makeDistortMap): lens pixel -> ideal ray -> CG pixel. The plate is never resampled: every
//    output pixel is a plate pixel.
//  - Per pixel the actor is in front where its depth is nearer than the CG's, with a smooth
//    step over depth_band_m centred on equal depth, times the key's alpha (soft silhouette
//    edges): a = alpha * w, out = a F + (1 - a) gain CG, in linear light, F the despilled
//    (unpremultiplied) foreground colour.
//  - Where the key has foreground but the actor depth is unknown (+inf: no hull along the ray,
//    typically the soft edge just outside the carved silhouette), the nearest known depth
//    within edge_fill_px is used; where there is none, the documented fallback: the actor is in
//    front, and the pixel is flagged (layer "front" = kFrontFallback, stats.fallback_px).
// Colour: plates and outputs are 8-bit sRGB (B, G, R), CG colour linear R, G, B (EXR order).
// Depth: metric z along the camera axis, +inf = nothing; pixel (0,0) is the centre of the
// top-left pixel (docs/conventions.md).
#include <cstdint>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/camera.h"
#include "core/distortion_maps.h"

namespace previz::composite {

struct CompositeOptions {
  // Width of the soft front/behind transition, metres: the actor's weight is a smoothstep of
  // (z_cg - z_actor) over [-band/2, +band/2] (0 = hard switch at equal depth).
  double depth_band_m = 0.04;
  // Pixels with key alpha > 0 and unknown actor depth take the nearest known actor depth within
  // this radius (px); 0 = none (every such pixel uses the fallback).
  int edge_fill_px = 3;
  // Linear multiplier on the CG colour (the engine's exposure against the plate's gain).
  double cg_gain = 1.0;
  // CG pixels outside the CG render (overscan too small) or where the lens is not invertible
  // take this linear colour (B, G, R order like the plate) and depth +inf.
  cv::Vec3f outside_rgb = cv::Vec3f(0, 0, 0);
  int threads = 0;          // OpenMP threads (0 = OpenMP's default)
  void validate() const;    // throws Error naming the field
};

// What the debug layer "front" holds per pixel (CV_8UC1).
enum FrontCode : unsigned char {
  kFrontNone = 0,      // no actor (key alpha = 0)
  kFrontCg = 1,        // CG in front of the actor (weight < 0.5)
  kFrontActor = 2,     // actor in front (weight >= 0.5)
  kFrontFallback = 3,  // key foreground without actor depth: drawn in front (fallback)
};

// One frame's inputs, all at the lens camera's size except the CG (the CG camera's size).
struct CompositeInputs {
  cv::Mat foreground;   // CV_8UC3 sRGB B G R: the plate, spill suppressed (carving::despill)
  cv::Mat alpha;        // CV_32FC1 in [0, 1]: the key's soft alpha
  cv::Mat actor_depth;  // CV_32FC1 metres, +inf = unknown (carving: main-view hull depth)
  cv::Mat cg_color;     // CV_32FC3 linear R G B through the CG pinhole
  cv::Mat cg_depth;     // CV_32FC1 metres through the CG pinhole, +inf = nothing
};

struct CompositeStats {
  long long actor_px = 0;      // alpha > 0
  long long actor_front_px = 0, cg_front_px = 0;
  long long edge_filled_px = 0;  // depth taken from a neighbour within edge_fill_px
  long long fallback_px = 0;     // no depth at all: drawn in front
  double ms = 0;
};

struct CompositeResult {
  cv::Mat bgr;  // CV_8UC3 sRGB, the lens camera's size
  // Debug layers (filled when asked): effective alpha a = alpha * w (CV_32FC1), actor depth
  // used (after edge fill, CV_32FC1), CG depth through the lens (CV_32FC1), front (CV_8UC1,
  // FrontCode), and the composite in linear light (CV_32FC3 B G R).
  cv::Mat layer_alpha, layer_actor_depth, layer_cg_depth, layer_front, linear;
  CompositeStats stats;
};

class Compositor {
 public:
  // lens: the main camera as the plate was shot (intrinsics + distortion of the current lens
  // state); cg: the engine's ideal pinhole (zero distortion, any size, e.g. cg/camera.json).
  // Builds the distortion map (~0.1-0.3 s at 1920x1080); throws Error naming the camera.
  Compositor(const Camera& lens, const Camera& cg, const CompositeOptions& options = {});

  // A new lens state (focus/zoom changed): the map is rebuilt only when the intrinsics or
  // distortion differ from the current ones. Returns true when it was rebuilt.
  bool setLens(const Camera& lens);

  const Camera& lens() const { return lens_; }
  const Camera& cg() const { return cg_; }
  const CompositeOptions& options() const { return options_; }
  // Lens pixel -> CG pixel (CV_32FC2, (-1,-1) where the lens is not invertible).
  const DistortMapResult& map() const { return map_; }
  // Lens pixels whose CG source lies outside the CG image (overscan too small).
  int outsideCg() const { return outside_cg_; }

  // A CG image (any float/8-bit type, channels 1-4) distorted to the lens: bilinear by default;
  // nearest for depth or labels. Outside pixels get 'border'.
  cv::Mat distortCg(const cv::Mat& cg_image, bool nearest = false,
                    const cv::Scalar& border = cv::Scalar::all(0)) const;

  // Composites one frame (one pass over the lens image). Throws Error naming the input (and
  // 'source', e.g. "frame 12") when a size or type is wrong.
  CompositeResult composite(const CompositeInputs& in, bool debug_layers = false,
                            const std::string& source = {}) const;
  // The same into 'out', reusing its images when they have the right size (the live loop keeps
  // one result: no 6 MB allocation and page faults per 1920x1080 frame). The previous
  // images are overwritten in place: clone what must outlive the next call.
  void composite(const CompositeInputs& in, CompositeResult& out, bool debug_layers = false,
                 const std::string& source = {}) const;

 private:
  void build();
  Camera lens_, cg_;
  CompositeOptions options_;
  DistortMapResult map_;
  int outside_cg_ = 0;
  // The map as the pass reads it, one entry per lens pixel: index of the top-left of the 2 x 2
  // CG pixels it blends (-1 = outside the CG) and the blend weights, in steps of 1/256 (0.004 px).
  struct Tap {
    std::int32_t index = -1;
    float ax = 0, ay = 0;
  };
  std::vector<Tap> taps_;
};

// 8-bit previews for people (the EXR layers hold the numbers): depth as turbo colour over
// [near, far] (near = warm, black = +inf); front layer as colours (black none, red CG in
// front, green actor in front, magenta fallback).
cv::Mat depthPreview(const cv::Mat& depth_m, double near_m, double far_m);
cv::Mat frontPreview(const cv::Mat& front);

}  // namespace previz::composite
