// RigCapture (datasets/rig_capture.h) and the board presets' fast renderer it shares with the
// take writer (datasets/detail/board_view.h).
#include "datasets/rig_capture.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <sstream>
#include <string>

#include "core/error.h"
#include "core/threads.h"
#include "datasets/detail/board_view.h"
#include "datasets/detail/render_kernel.h"
#include "datasets/random.h"
#include "datasets/render.h"
#include "datasets/studio.h"

namespace previz::synth {
namespace detail {
namespace {

constexpr std::uint64_t kStreamNoise = 0x4E015E;

// Standard normal quantiles at the centres of 65536 equal-probability bins: a 16-bit uniform
// index gives a Gaussian draw (variance 1 - 2e-4, tails cut at 4.3 sigma).
class GaussianTable {
 public:
  static constexpr int kBits = 16, kSize = 1 << kBits;
  GaussianTable() {
    for (int i = 0; i < kSize / 2; ++i) {
      const double z = inverseNormal((i + 0.5) / kSize);
      table_[i] = static_cast<float>(z);
      table_[kSize - 1 - i] = static_cast<float>(-z);
    }
  }
  float operator[](std::uint64_t index) const { return table_[index & (kSize - 1)]; }

 private:
  // Acklam's rational approximation (rel. error 1.2e-9) polished by two Halley steps on erfc.
  static double inverseNormal(double p) {
    static const double a[] = {-3.969683028665376e+01, 2.209460984245205e+02,
                               -2.759285104469687e+02, 1.383577518672690e+02,
                               -3.066479806614716e+01, 2.506628277459239e+00};
    static const double b[] = {-5.447609879822406e+01, 1.615858368580409e+02,
                               -1.556989798598866e+02, 6.680131188771972e+01,
                               -1.328068155288572e+01};
    static const double c[] = {-7.784894002430293e-03, -3.223964580411365e-01,
                               -2.400758277161838e+00, -2.549732539343734e+00,
                               4.374664141464968e+00, 2.938163982698783e+00};
    static const double d[] = {7.784695709041462e-03, 3.224671290700398e-01,
                               2.445134137142996e+00, 3.754408661907416e+00};
    double x;
    if (p < 0.02425) {
      const double q = std::sqrt(-2.0 * std::log(p));
      x = (((((c[0] * q + c[1]) * q + c[2]) * q + c[3]) * q + c[4]) * q + c[5]) /
          ((((d[0] * q + d[1]) * q + d[2]) * q + d[3]) * q + 1.0);
    } else {
      const double q = p - 0.5, r = q * q;
      x = (((((a[0] * r + a[1]) * r + a[2]) * r + a[3]) * r + a[4]) * r + a[5]) * q /
          (((((b[0] * r + b[1]) * r + b[2]) * r + b[3]) * r + b[4]) * r + 1.0);
    }
    for (int it = 0; it < 2; ++it) {
      const double e = 0.5 * std::erfc(-x / std::sqrt(2.0)) - p;
      const double u = e * std::sqrt(2.0 * 3.14159265358979323846) * std::exp(0.5 * x * x);
      x -= u / (1.0 + 0.5 * x * u);
    }
    return x;
  }
  std::array<float, kSize> table_;
};
const GaussianTable& gaussianTable() {
  static const GaussianTable table;
  return table;
}

// Linear RGB (CV_32FC3) -> encoded grey levels in BGR order (CV_32FC3).
cv::Mat encodeBgr(const cv::Mat& rgb) {
  const SrgbTable& table = srgbTable();
  cv::Mat out(rgb.size(), CV_32FC3);
  for (int v = 0; v < rgb.rows; ++v) {
    const float* in = rgb.ptr<float>(v);
    float* o = out.ptr<float>(v);
    for (int u = 0; u < rgb.cols; ++u) {
      for (int c = 0; c < 3; ++c) o[3 * u + (2 - c)] = table.encode255(in[3 * u + c]);
    }
  }
  return out;
}

// Per image row, the columns whose pixel centres lie within kRegionMarginPx of the projected
// board (printed margin included). lo > hi: the row cannot see the board.
struct Region {
  bool whole_image = false;
  std::vector<int> lo, hi;  // per row
  bool empty() const {
    if (whole_image) return false;
    for (size_t v = 0; v < lo.size(); ++v) {
      if (lo[v] <= hi[v]) return false;
    }
    return true;
  }
};

Region boardRegion(const Camera& camera, const Pose& T_cam_board, const BoardSpec& spec) {
  Region region;
  region.lo.assign(camera.height, std::numeric_limits<int>::max());
  region.hi.assign(camera.height, std::numeric_limits<int>::min());
  const Eigen::Vector2d size = spec.size_m();
  const double m = spec.margin_m;
  const Eigen::Vector3d corners[4] = {{-m, -m, 0}, {size.x() + m, -m, 0},
                                      {size.x() + m, size.y() + m, 0}, {-m, size.y() + m, 0}};
  constexpr int kPerEdge = 64;
  std::vector<Eigen::Vector2d> outline;
  int behind = 0, failed = 0;
  for (int e = 0; e < 4; ++e) {
    for (int k = 0; k < kPerEdge; ++k) {
      const Eigen::Vector3d p =
          T_cam_board * (corners[e] + (corners[(e + 1) % 4] - corners[e]) * (double(k) / kPerEdge));
      if (!(p.z() > 0)) ++behind;
      const std::optional<Eigen::Vector2d> px = camera.project(p);
      if (!px) {
        ++failed;
        continue;
      }
      outline.push_back(*px);
    }
  }
  // A flat board wholly behind the camera plane cannot be seen. Partly behind, or reaching past
  // the lens' fold: the outline does not bound what the pixels see, so trace everything.
  if (behind == 4 * kPerEdge) return region;
  if (failed > 0) {
    region.whole_image = true;
    return region;
  }
  const double M = kRegionMarginPx;
  const int H = camera.height, W = camera.width;
  for (size_t i = 0; i < outline.size(); ++i) {
    const Eigen::Vector2d a = outline[i], b = outline[(i + 1) % outline.size()];
    const double y_min = std::min(a.y(), b.y()), y_max = std::max(a.y(), b.y());
    const int v0 = std::max(0, static_cast<int>(std::ceil(y_min - M)));
    const int v1 = std::min(H - 1, static_cast<int>(std::floor(y_max + M)));
    for (int v = v0; v <= v1; ++v) {
      // The part of the segment within the strip |y - v| <= M: x at its ends.
      double x_lo, x_hi;
      if (b.y() == a.y()) {
        x_lo = std::min(a.x(), b.x());
        x_hi = std::max(a.x(), b.x());
      } else {
        const double t0 = std::clamp((v - M - a.y()) / (b.y() - a.y()), 0.0, 1.0);
        const double t1 = std::clamp((v + M - a.y()) / (b.y() - a.y()), 0.0, 1.0);
        const double xa = a.x() + t0 * (b.x() - a.x()), xb = a.x() + t1 * (b.x() - a.x());
        x_lo = std::min(xa, xb);
        x_hi = std::max(xa, xb);
      }
      const double lo = std::ceil(x_lo - M), hi = std::floor(x_hi + M);
      if (hi < 0 || lo > W - 1) continue;
      region.lo[v] = std::min(region.lo[v], static_cast<int>(std::max(lo, 0.0)));
      region.hi[v] = std::max(region.hi[v], static_cast<int>(std::min(hi, W - 1.0)));
    }
  }
  return region;
}

// Encoded grey levels (BGR) that replace the cached stage: row v of the frame takes columns
// lo[v - v0] .. hi[v - v0] from enc (whose column 0 is frame column u0).
struct Patch {
  int v0 = 0, u0 = 0;
  cv::Mat enc;  // CV_32FC3
  std::vector<int> lo, hi;
};

}  // namespace

struct BoardView::Cache {
  cv::Mat linear;  // CV_32FC3 linear RGB with gain, before defocus (kept when blurring)
  cv::Mat enc;     // CV_32FC3 encoded BGR of the empty stage (defocused; kept with noise)
  cv::Mat bgr;     // CV_8UC3 the same, rounded
  cv::Mat stage_t; // CV_32FC1 least hit distance over each pixel's samples (rounded down)
};

BoardView::BoardView(const Camera& camera, const Pose& T_world_cam, const Scene& stage,
                     const BoardViewOptions& options)
    : camera_(camera), T_world_cam_(T_world_cam), stage_(stage), options_(options) {
  camera_.validate();
  RenderOptions check;
  check.samples_per_pixel = options.samples_per_pixel;
  check.gain = options.gain;
  check.blur_sigma_px = options.blur_sigma_px;
  check.noise_sigma = options.noise_sigma;
  check.threads = options.threads;
  check.validate();
}

BoardView::~BoardView() = default;

const BoardView::Cache& BoardView::cache() const {
  std::call_once(once_, [this] {
    auto cache = std::make_unique<Cache>();
    const SpanTracer tracer(camera_, T_world_cam_, options_.samples_per_pixel, options_.gain);
    cv::Mat linear(camera_.height, camera_.width, CV_32FC3);
    cache->stage_t.create(camera_.height, camera_.width, CV_32FC1);
#pragma omp parallel for schedule(dynamic, 2) num_threads(resolveThreads(options_.threads))
    for (int v = 0; v < camera_.height; ++v) {
      tracer.traceRow(stage_, v, 0, camera_.width - 1, linear.ptr<float>(v), nullptr, nullptr,
                      cache->stage_t.ptr<float>(v));
    }
    cv::Mat seen = linear;
    if (options_.blur_sigma_px > 0) {
      seen = GaussianBlur(options_.blur_sigma_px).apply(linear, resolveThreads(options_.threads));
      cache->linear = linear;
    }
    cache->enc = encodeBgr(seen);
    cache->bgr.create(camera_.height, camera_.width, CV_8UC3);
    const float* e = cache->enc.ptr<float>();
    std::uint8_t* b = cache->bgr.ptr<std::uint8_t>();
    for (size_t i = 0; i < cache->bgr.total() * 3; ++i) b[i] = quantize255(e[i]);
    if (options_.noise_sigma == 0) cache->enc.release();  // noise-free frames copy bgr
    cache_ = std::move(cache);
  });
  return *cache_;
}

cv::Mat BoardView::background() const { return cache().bgr.clone(); }

Scene BoardView::sceneWith(const BoardSpec& spec, const Pose& T_world_board, bool on_floor) const {
  Scene scene = stage_;
  std::shared_ptr<const Primitive> board = makeBoard(spec, T_world_board);
  scene.add(on_floor ? onTopOf(board) : board);
  return scene;
}

cv::Mat BoardView::render(const BoardSpec& spec, const Pose& T_world_board, bool on_floor,
                          std::uint64_t noise_seed, int camera_index, int frame,
                          BoardViewStats* stats) const {
  const Cache& c = cache();
  const int W = camera_.width, H = camera_.height;
  const int threads = resolveThreads(options_.threads);
  const Region region = boardRegion(camera_, T_world_cam_.inverse() * T_world_board, spec);
  BoardViewStats local;
  local.whole_image = region.whole_image;
  local.board_in_view = !region.empty();

  // 1. Trace the pixels that can see the board, row span by row span.
  int v0 = H, v1 = -1, u0 = W, u1 = -1;
  std::vector<int> lo(H, 0), hi(H, -1);
  if (local.board_in_view) {
    for (int v = 0; v < H; ++v) {
      lo[v] = region.whole_image ? 0 : region.lo[v];
      hi[v] = region.whole_image ? W - 1 : region.hi[v];
      if (lo[v] > hi[v]) continue;
      v0 = std::min(v0, v), v1 = std::max(v1, v);
      u0 = std::min(u0, lo[v]), u1 = std::max(u1, hi[v]);
      local.traced_pixels += hi[v] - lo[v] + 1;
    }
  }
  std::vector<Patch> patches;
  if (local.board_in_view) {
    const Scene scene = sceneWith(spec, T_world_board, on_floor);
    const SpanTracer tracer(camera_, T_world_cam_, options_.samples_per_pixel, options_.gain);
    const cv::Rect traced(u0, v0, u1 - u0 + 1, v1 - v0 + 1);
    const Primitive* board = scene.primitives().back().get();
    cv::Mat linear(traced.size(), CV_32FC3, cv::Scalar::all(0));
#pragma omp parallel for schedule(dynamic, 4) num_threads(threads)
    for (int v = v0; v <= v1; ++v) {
      if (lo[v] > hi[v]) continue;
      tracer.traceRow(scene, v, lo[v], hi[v], linear.ptr<float>(v - v0) + 3 * (lo[v] - u0), board,
                      c.stage_t.ptr<float>(v));
    }

    // 2. Encoded patches over the cached stage: the traced spans, or with defocus a window
    //    composited in linear light and blurred (it reaches the kernel radius beyond the traced
    //    pixels, and its input twice that, so it equals a whole-frame blur there).
    Patch p;
    if (options_.blur_sigma_px > 0) {
      const GaussianBlur blur(options_.blur_sigma_px);
      const int r = blur.radius();
      const cv::Rect image(0, 0, W, H);
      const cv::Rect window =
          cv::Rect(u0 - 2 * r, v0 - 2 * r, traced.width + 4 * r, traced.height + 4 * r) & image;
      const cv::Rect out =
          cv::Rect(u0 - r, v0 - r, traced.width + 2 * r, traced.height + 2 * r) & image;
      cv::Mat composite = c.linear(window).clone();
      for (int v = v0; v <= v1; ++v) {
        if (lo[v] > hi[v]) continue;
        std::memcpy(composite.ptr<float>(v - window.y) + 3 * (lo[v] - window.x),
                    linear.ptr<float>(v - v0) + 3 * (lo[v] - u0),
                    sizeof(float) * 3 * (hi[v] - lo[v] + 1));
      }
      const cv::Mat blurred = blur.apply(composite, threads);
      p.v0 = out.y;
      p.u0 = out.x;
      p.enc = encodeBgr(blurred(cv::Rect(out.x - window.x, out.y - window.y, out.width, out.height)));
      p.lo.assign(out.height, out.x);
      p.hi.assign(out.height, out.x + out.width - 1);
    } else {
      p.v0 = v0;
      p.u0 = u0;
      p.enc = encodeBgr(linear);  // its untraced corners are never read
      p.lo.assign(lo.begin() + v0, lo.begin() + v1 + 1);
      p.hi.assign(hi.begin() + v0, hi.begin() + v1 + 1);
    }
    patches.push_back(std::move(p));
  }
  std::vector<const Patch*> row_patch(H, nullptr);
  for (const Patch& p : patches) {
    for (int v = p.v0; v < p.v0 + p.enc.rows; ++v) {
      if (p.lo[v - p.v0] <= p.hi[v - p.v0]) row_patch[v] = &p;
    }
  }

  // 3. Noise over the whole frame, then 8 bits.
  cv::Mat frame_bgr(H, W, CV_8UC3);
  const double sigma = options_.noise_sigma;
  const float sigma_f = static_cast<float>(sigma);
  const GaussianTable& gauss = gaussianTable();
  const std::uint64_t stream =
      hashKey(noise_seed, static_cast<std::uint64_t>(camera_index),
              static_cast<std::uint64_t>(frame), kStreamNoise);
#pragma omp parallel for schedule(static) num_threads(threads)
  for (int v = 0; v < H; ++v) {
    std::uint8_t* out = frame_bgr.ptr<std::uint8_t>(v);
    const Patch* p = row_patch[v];
    if (sigma == 0) {
      std::memcpy(out, c.bgr.ptr<std::uint8_t>(v), 3 * static_cast<size_t>(W));
      if (p != nullptr) {
        const int a = p->lo[v - p->v0], b = p->hi[v - p->v0];
        const float* e = p->enc.ptr<float>(v - p->v0) + 3 * (a - p->u0);
        for (int x = 0; x < 3 * (b - a + 1); ++x) out[3 * a + x] = quantize255(e[x]);
      }
      continue;
    }
    const float* bg = c.enc.ptr<float>(v);
    // Pixel u's channels draw from one 64-bit hash of (stream, pixel index), 16 bits each.
    const std::uint64_t row_key = stream + static_cast<std::uint64_t>(v) * W;
    auto emit = [&](const float* src, int u_begin, int u_end) {
      for (int u = u_begin; u < u_end; ++u) {
        const std::uint64_t h = mix64(row_key + static_cast<std::uint64_t>(u));
        for (int ch = 0; ch < 3; ++ch) {
          const float value = src[3 * u + ch] + sigma_f * gauss[h >> (16 * ch)];
          out[3 * u + ch] = static_cast<std::uint8_t>(std::clamp(value, 0.0f, 255.0f) + 0.5f);
        }
      }
    };
    if (p == nullptr) {
      emit(bg, 0, W);
    } else {
      const int a = p->lo[v - p->v0], b = p->hi[v - p->v0] + 1;
      emit(bg, 0, a);
      emit(p->enc.ptr<float>(v - p->v0) - 3 * p->u0, a, b);
      emit(bg, b, W);
    }
  }
  if (stats != nullptr) *stats = local;
  return frame_bgr;
}

}  // namespace detail

// ---------------------------------------------------------------------------------------------
// RigCapture

namespace {

template <typename T>
std::string str(T value) {
  std::ostringstream s;
  s << value;
  return s.str();
}

[[noreturn]] void badOption(const std::string& field, const std::string& message,
                            const std::string& camera = {}) {
  ErrorContext context;
  context.field = field;
  context.camera = camera;
  throw Error("rig capture: " + field + " " + message, context);
}

bool finitePose(const Pose& T) {
  return T.matrix().allFinite() &&
         (T.linear().transpose() * T.linear() - Eigen::Matrix3d::Identity()).norm() < 1e-6 &&
         T.linear().determinant() > 0;
}

}  // namespace

struct RigCapture::Impl {
  RigCaptureOptions options;
  Rig rig;
  BoardSpec board;
  std::vector<int> delay;  // per camera
  std::uint64_t noise_seed = 0;
  std::vector<std::unique_ptr<detail::BoardView>> views;

  int cameraIndex(const std::string& name) const {
    for (size_t i = 0; i < rig.cameras.size(); ++i) {
      if (rig.cameras[i].camera.name == name) return static_cast<int>(i);
    }
    return -1;
  }
  void check(int camera, int frame) const {
    ErrorContext context;
    if (camera < 0 || camera >= static_cast<int>(rig.cameras.size())) {
      context.field = "camera";
      throw Error("rig capture: camera index " + str(camera) + " out of range [0, " +
                      str(rig.cameras.size()) + ")",
                  context);
    }
    if (frame < 0 || frame >= options.frames) {
      context.camera = rig.cameras[camera].camera.name;
      context.frame = frame;
      throw Error("rig capture: frame " + str(frame) + " out of range [0, " +
                      str(options.frames) + ")",
                  context);
    }
  }
  // The capture frame whose board camera 'camera' shows in its frame 'frame'.
  int shownFrame(int camera, int frame) const {
    return std::clamp(frame - delay[camera], 0, options.frames - 1);
  }
  bool isFloorFrame(int frame) const {
    return options.floor_only || (options.floor_frames && isFloorBoardFrame(frame, options.frames));
  }
  Pose boardPose(int frame) const {
    if (options.floor_only) return synth::floorBoardPose();
    return options.floor_frames ? rigBoardPose(board, frame, options.frames, options.board_seed)
                                : rigWavedBoardPose(board, frame, options.frames, options.board_seed);
  }
};

RigCapture::RigCapture(const RigCaptureOptions& options) : impl_(std::make_unique<Impl>()) {
  const RigCaptureOptions& o = options;
  if (o.frames <= 0) badOption("frames", "must be > 0 (got " + str(o.frames) + ")");
  if (o.samples_per_pixel < 4 || o.samples_per_pixel > 4096) {
    badOption("samples_per_pixel", "must be in [4, 4096] (got " + str(o.samples_per_pixel) + ")");
  }
  if (!(o.noise_sigma >= 0) || !std::isfinite(o.noise_sigma)) {
    badOption("noise_sigma", "must be >= 0 (got " + str(o.noise_sigma) + ")");
  }
  if (!(o.blur_sigma_px >= 0) || !(o.blur_sigma_px <= 50)) {
    badOption("blur_sigma_px", "must be in [0, 50] (got " + str(o.blur_sigma_px) + ")");
  }
  if (o.threads < 0) badOption("threads", "must be >= 0 (got " + str(o.threads) + ")");
  if (o.floor_only && !o.floor_frames) badOption("floor_only", "contradicts floor_frames = false");
  if (o.rig.witness_cameras < 1 || o.rig.witness_cameras > 99) {
    badOption("rig.witness_cameras", "must be in [1, 99] (got " + str(o.rig.witness_cameras) + ")");
  }

  Impl& m = *impl_;
  m.options = o;
  m.board = rigBoard(o.board);
  m.rig = studioRig(o.rig, StudioConfig{}.take_duration_s, false);
  for (const auto& [name, frames] : o.delay_frames) {
    if (m.cameraIndex(name) < 0) badOption("delay_frames", "names no camera of the rig: '" + name + "'", name);
  }
  for (const auto& [name, T] : o.bump) {
    if (m.cameraIndex(name) < 0) badOption("bump", "names no camera of the rig: '" + name + "'", name);
    if (!finitePose(T)) badOption("bump", "of '" + name + "' is not a finite rigid motion", name);
  }
  for (const auto& [name, g] : o.gain) {
    if (m.cameraIndex(name) < 0) badOption("gain", "names no camera of the rig: '" + name + "'", name);
    if (!(g > 0) || !std::isfinite(g)) badOption("gain", "of '" + name + "' must be > 0 (got " + str(g) + ")", name);
  }

  StudioConfig config;
  config.seed = o.rig.seed;
  config.with_actor = false;
  config.with_prop = false;
  const Scene stage = Studio(config).sceneAt(0.0, kLayerStage);
  m.noise_seed = hashKey(o.rig.seed, o.board_seed);
  for (RigCamera& rc : m.rig.cameras) {
    const std::string& name = rc.camera.name;
    if (auto it = o.bump.find(name); it != o.bump.end()) rc.T_world_cam = rc.T_world_cam * it->second;
    auto delay = o.delay_frames.find(name);
    m.delay.push_back(delay != o.delay_frames.end() ? delay->second : 0);
    detail::BoardViewOptions vo;
    vo.samples_per_pixel = o.samples_per_pixel;
    vo.noise_sigma = o.noise_sigma;
    vo.blur_sigma_px = o.blur_sigma_px;
    vo.threads = o.threads;
    if (auto g = o.gain.find(name); g != o.gain.end()) vo.gain = g->second;
    m.views.push_back(std::make_unique<detail::BoardView>(rc.camera, rc.T_world_cam, stage, vo));
  }
}

RigCapture::~RigCapture() = default;

const Rig& RigCapture::rig() const { return impl_->rig; }
const BoardSpec& RigCapture::board() const { return impl_->board; }
int RigCapture::frames() const { return impl_->options.frames; }
bool RigCapture::isFloorFrame(int frame) const { return impl_->isFloorFrame(frame); }
Pose RigCapture::floorBoardPose() const { return synth::floorBoardPose(); }

Pose RigCapture::T_world_board(int camera, int frame) const {
  impl_->check(camera, frame);
  return impl_->boardPose(impl_->shownFrame(camera, frame));
}

bool RigCapture::showsFloorBoard(int camera, int frame) const {
  impl_->check(camera, frame);
  return impl_->isFloorFrame(impl_->shownFrame(camera, frame));
}

cv::Mat RigCapture::render(int camera, int frame) const {
  const Impl& m = *impl_;
  m.check(camera, frame);
  const int shown = m.shownFrame(camera, frame);
  return m.views[camera]->render(m.board, m.boardPose(shown), m.isFloorFrame(shown), m.noise_seed,
                                 camera, frame);
}

std::vector<BoardObservation> RigCapture::truth(int camera, int frame) const {
  const Impl& m = *impl_;
  m.check(camera, frame);
  const int shown = m.shownFrame(camera, frame);
  const Pose T_world_board = m.boardPose(shown);
  const RigCamera& rc = m.rig.cameras[camera];
  return visibleBoardPoints(rc.camera, rc.T_world_cam, m.board, T_world_board,
                            m.views[camera]->sceneWith(m.board, T_world_board, m.isFloorFrame(shown)));
}

}  // namespace previz::synth
