#pragma once
// The board presets' fast path, shared by RigCapture (datasets/rig_capture.h) and the take
// writer (datasets/synth.cpp); defined in datasets/rig_capture.cpp. Not public API.
//
// One static camera looking at a static stage in which only a flat board moves. The empty
// stage is rendered once (lazily, thread-safe) and kept as linear light (when blurring) and as
// encoded grey levels; a frame ray-traces only the pixels whose centre lies within
// kRegionMarginPx of the projected board (printed margin included), row span by row span, with
// renderView's own sample kernel (detail::SpanTracer, datasets/detail/render_kernel.h: same
// rays, same sums), so those pixels are renderView's; a sample that meets the board nearer than
// the empty stage's nearest hit over its pixel (cached too) skips the stage's intersection test.
// The rest of the frame is the cached stage. Image formation then follows renderView
// (datasets/render.h), with its pieces from render_kernel.h: gain -> optional defocus in linear
// light (detail::GaussianBlur, applied to a window around the board over the cached linear
// stage, so it equals a whole-frame blur) -> sRGB -> additive Gaussian noise over the whole
// frame -> 8 bits.
//
// Noise differs from renderView's stream: a per-pixel hash of (seed, camera, frame, pixel)
// picks each channel's value from a table of 65536 Gaussian quantiles (|z| <= 4.3). The
// Box–Muller draw renderView makes per channel costs ~120 ms a 1280x720 frame, three times
// what a whole board frame is allowed here.
#include <cstdint>
#include <memory>
#include <mutex>

#include <opencv2/core.hpp>

#include "core/board.h"
#include "core/camera.h"
#include "core/pose.h"
#include "datasets/scene.h"

namespace previz::synth::detail {

// Pixels whose centre lies within this distance of the projected board outline are traced.
// Sample rays lie within 0.5 px of the pixel centre and the outline is projected at 64 points
// an edge (chord error far below 0.1 px at these lenses), so 2 px leaves a safe margin.
constexpr double kRegionMarginPx = 2.0;

struct BoardViewOptions {
  int samples_per_pixel = 4;
  double gain = 1.0;           // linear radiance multiplier
  double blur_sigma_px = 0.0;  // defocus, Gaussian sigma in pixels (linear light)
  double noise_sigma = 0.0;    // grey levels, after encoding
  int threads = 0;             // OpenMP threads for a render (0 = default; 1 inside a parallel loop)
};

// What a frame cost (for benchmarks and tests).
struct BoardViewStats {
  bool board_in_view = false;  // some traced pixel could see the board
  bool whole_image = false;    // the outline did not project everywhere: the frame was traced whole
  long long traced_pixels = 0;
};

class BoardView {
 public:
  // 'stage' is the scene without the board (its primitives are shared, not copied).
  BoardView(const Camera& camera, const Pose& T_world_cam, const Scene& stage,
            const BoardViewOptions& options);
  ~BoardView();
  BoardView(const BoardView&) = delete;
  BoardView& operator=(const BoardView&) = delete;

  // The stage plus the board at T_world_board; on the floor it wins the tie with the floor.
  Scene sceneWith(const BoardSpec& spec, const Pose& T_world_board, bool on_floor) const;
  // 8-bit BGR frame; noise from (noise_seed, camera_index, frame). Thread-safe.
  cv::Mat render(const BoardSpec& spec, const Pose& T_world_board, bool on_floor,
                 std::uint64_t noise_seed, int camera_index, int frame,
                 BoardViewStats* stats = nullptr) const;
  // The empty stage without noise, 8 bits (renders the cache if needed).
  cv::Mat background() const;

  const Camera& camera() const { return camera_; }
  const Pose& T_world_cam() const { return T_world_cam_; }

 private:
  struct Cache;
  const Cache& cache() const;

  Camera camera_;
  Pose T_world_cam_;
  Scene stage_;
  BoardViewOptions options_;
  mutable std::once_flag once_;
  mutable std::unique_ptr<Cache> cache_;
};

}  // namespace previz::synth::detail
