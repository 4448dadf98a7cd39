#include "datasets/render.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include <omp.h>

#include "core/error.h"
#include "core/threads.h"
#include "core/lens_model.h"
#include "datasets/detail/render_kernel.h"
#include "datasets/random.h"

namespace previz::synth {
namespace {


constexpr float kInf = std::numeric_limits<float>::infinity();

[[noreturn]] void fail(const std::string& field, const std::string& message) {
  ErrorContext context;
  context.field = field;
  throw Error("render: " + field + " " + message, context);
}

// The camera's lens model of core/lens_model.h (Brown–Conrady or Kannala–Brandt), evaluated
// together with its Jacobian in one pass (inline: the inner loop inverts it for every sample;
// Camera::distort/distortJacobian return through two out-of-line calls each, which cost more than
// the arithmetic). The test Render.PixelRayEqualsUnprojectAndProjectsBackBelowNanoPixel holds
// this Newton to Camera::unproject.
struct Brown {
  double k1, k2, k3, k4, k5, k6, p1, p2;
  bool kannala_brandt;
  bool rational;  // Brown–Conrady with k4 k5 k6 (else the plain model, no division)
  double r2_max;  // squared ideal radius where the radial map folds (inf when it never does)

  explicit Brown(const Camera& c)
      : k1(c.dist.k1), k2(c.dist.k2), k3(c.dist.k3), k4(c.dist.k4), k5(c.dist.k5), k6(c.dist.k6),
        p1(c.dist.p1), p2(c.dist.p2),
        kannala_brandt(c.dist.model == LensModel::kKannalaBrandt), rational(c.dist.isRational()) {
    const double r = c.maxInvertibleRadius();
    r2_max = std::isfinite(r) ? r * r : std::numeric_limits<double>::infinity();
  }

  // f = distort(x) - target, J = d distort / dx.
  void evaluate(double x, double y, double tx, double ty, double& fx, double& fy, double& j00,
                double& j01, double& j10, double& j11) const {
    if (kannala_brandt) lens::kannalaBrandtDistortWithJacobian(k1, k2, k3, k4, x, y, fx, fy, j00, j01, j11);
    else if (rational) lens::brownDistortWithJacobian(k1, k2, p1, p2, k3, k4, k5, k6, x, y, fx, fy, j00, j01, j11);
    else lens::brownDistortWithJacobian<false>(k1, k2, p1, p2, k3, k4, k5, k6, x, y, fx, fy, j00, j01, j11);
    fx -= tx;
    fy -= ty;
    j10 = j01;
  }

  // Newton from a nearby start; the same stopping rule as Camera::undistort's default
  // (|distort(x) - xd| <= 1e-13). False when it does not converge fast or lands past the fold.
  bool invert(double tx, double ty, double& x, double& y) const {
    for (int it = 0; it < 12; ++it) {
      double fx, fy, a, b, c, d;
      evaluate(x, y, tx, ty, fx, fy, a, b, c, d);
      // The domain test of core's InverseDistortion: inside the turning radius, det J > 0.
      if (fx * fx + fy * fy <= 1e-26) return x * x + y * y < r2_max && a * d - b * c > 0;
      const double det = a * d - b * c;
      if (!(std::abs(det) > 1e-12)) return false;
      const double inv_det = 1.0 / det;
      x -= (d * fx - b * fy) * inv_det;
      y -= (a * fy - c * fx) * inv_det;
    }
    return false;
  }

  // Jacobian only (for the warm start of the next solve).
  void jacobian(double x, double y, double& a, double& b, double& c, double& d) const {
    double fx, fy;
    evaluate(x, y, 0, 0, fx, fy, a, b, c, d);
  }
};

// Pixel -> ideal normalized coordinates: pixel-to-normalized through K^-1 (skew included).
struct Intrinsics {
  double inv_fx, inv_fy, cx, cy, skew;
  explicit Intrinsics(const Camera& c)
      : inv_fx(1.0 / c.fx), inv_fy(1.0 / c.fy), cx(c.cx), cy(c.cy), skew(c.skew) {}
  void toNormalized(double u, double v, double& xd, double& yd) const {
    yd = (v - cy) * inv_fy;
    xd = (u - cx - skew * yd) * inv_fx;
  }
};

// A solved point and the inverse Jacobian there: the first-order start for nearby points.
struct Start {
  bool ok = false;
  double x = 0, y = 0, xd = 0, yd = 0;
  double i00 = 0, i01 = 0, i10 = 0, i11 = 0;
};

inline Start makeStart(const Brown& brown, double x, double y, double xd, double yd) {
  Start s;
  double a, b, c, d;
  brown.jacobian(x, y, a, b, c, d);
  const double det = a * d - b * c;
  if (!(std::abs(det) > 1e-12)) return s;
  const double inv_det = 1.0 / det;
  s = {true, x, y, xd, yd, d * inv_det, -b * inv_det, -c * inv_det, a * inv_det};
  return s;
}

// Solves the inverse for the distorted point (xd, yd): first-order step from a nearby solved
// point, then Newton to convergence (usually one step). Falls back to a cold start and then to
// Camera::undistort (the reference) when the warm start fails.
inline bool invertFrom(const Camera& camera, const Brown& brown, double xd, double yd,
                       const Start& start, double& x, double& y) {
  if (start.ok) {
    const double ex = xd - start.xd, ey = yd - start.yd;
    x = start.x + start.i00 * ex + start.i01 * ey;
    y = start.y + start.i10 * ex + start.i11 * ey;
    if (brown.invert(xd, yd, x, y)) return true;
  }
  x = xd;
  y = yd;
  if (brown.invert(xd, yd, x, y)) return true;
  const InverseResult r = camera.undistort(Eigen::Vector2d(xd, yd));
  if (!r.ok() || !camera.inInvertibleDomain(r.point)) return false;
  x = r.point.x();
  y = r.point.y();
  return true;
}

// A pixel's rays through the true lens (K^-1, then the inverse Brown model), warm-started along
// the row: the kernel that renderView, renderLinear and detail::SpanTracer share.
struct Lens {
  const Camera& camera;
  Brown brown;
  Intrinsics k;

  explicit Lens(const Camera& c) : camera(c), brown(c), k(c) {}

  // Solves the centre of pixel (u, v) from 'start' (the previous pixel's centre) into (x, y);
  // 'start' becomes this centre, the warm start of its samples and of the next pixel.
  bool centre(int u, int v, Start& start, double& x, double& y) const {
    double xd, yd;
    k.toNormalized(u, v, xd, yd);
    const bool ok = invertFrom(camera, brown, xd, yd, start, x, y);
    start = ok ? makeStart(brown, x, y, xd, yd) : Start{};
    return ok;
  }

  // Calls ray(s, d_cam) for each sample s of pixel (u, v) in pattern order with its unit ray in
  // the camera frame; samples past the fold are skipped (no light reaches that part of the
  // sensor).
  template <typename SampleRay>
  void forEachSample(const std::vector<Eigen::Vector2d>& pattern, const Start& start, int u,
                     int v, SampleRay&& ray) const {
    const int spp = static_cast<int>(pattern.size());
    for (int s = 0; s < spp; ++s) {
      double xd, yd, x, y;
      k.toNormalized(u + pattern[s].x(), v + pattern[s].y(), xd, yd);
      if (!invertFrom(camera, brown, xd, yd, start, x, y)) continue;
      const double inv = 1.0 / std::sqrt(x * x + y * y + 1.0);
      ray(s, Eigen::Vector3d(x * inv, y * inv, inv));
    }
  }
};

// A pixel's mean linear RGB: the double sum over its samples times 'scale', in float.
inline void storeMean(const Eigen::Vector3d& sum, float scale, float* rgb) {
  rgb[0] = static_cast<float>(sum.x()) * scale;
  rgb[1] = static_cast<float>(sum.y()) * scale;
  rgb[2] = static_cast<float>(sum.z()) * scale;
}

// What one pixel needs from the scene, shared by renderView and renderLinear.
struct PixelResult {
  Eigen::Vector3d rgb_sum = Eigen::Vector3d::Zero();
  float depth = kInf;
  ObjectClass cls = ObjectClass::kNone;
  bool centre_ok = false;
};

struct Instant {
  const Scene* scene;
  Eigen::Matrix3d R;  // world <- camera
  Eigen::Vector3d origin;
};

std::vector<Instant> makeInstants(const std::vector<ShutterSample>& shutter) {
  std::vector<Instant> out;
  out.reserve(shutter.size());
  for (const ShutterSample& s : shutter) {
    if (s.scene == nullptr) fail("shutter", "has an instant without a scene");
    out.push_back({s.scene, s.T_world_cam.rotation(), s.T_world_cam.translation()});
  }
  if (out.empty()) fail("shutter", "is empty");
  return out;
}

// What renderView and renderLinear set up alike (the camera and the shutter checked): the lens,
// the sample pattern and the instants.
struct Exposure {
  Lens lens;
  std::vector<Eigen::Vector2d> pattern;
  std::vector<Instant> instants;
  Instant centre;
};

Exposure makeExposure(const Camera& camera, const std::vector<ShutterSample>& shutter,
                      const ShutterSample& centre, int samples_per_pixel) {
  camera.validate();
  if (centre.scene == nullptr) fail("centre", "has no scene");
  return {Lens(camera), samplePattern(samples_per_pixel), makeInstants(shutter),
          {centre.scene, centre.T_world_cam.rotation(), centre.T_world_cam.translation()}};
}

// The per-row kernel: samples + (optionally) the truth ray of every pixel of row v.
template <typename PixelSink>
void renderRow(const Exposure& exposure, bool truth, int v, PixelSink&& sink) {
  const Lens& lens = exposure.lens;
  const std::vector<Instant>& instants = exposure.instants;
  const Instant& centre = exposure.centre;
  const int n_instants = static_cast<int>(instants.size());
  Start start;  // the previous pixel's centre: warm start along the row
  for (int u = 0; u < lens.camera.width; ++u) {
    PixelResult result;
    double x_c = 0, y_c = 0;
    result.centre_ok = lens.centre(u, v, start, x_c, y_c);
    if (truth && result.centre_ok) {
      const double inv = 1.0 / std::sqrt(x_c * x_c + y_c * y_c + 1.0);
      const Eigen::Vector3d d_cam(x_c * inv, y_c * inv, inv);
      Ray ray{centre.origin, centre.R * d_cam};
      Hit hit;
      if (centre.scene->trace(ray, hit)) {
        result.depth = static_cast<float>(hit.t * d_cam.z());
        result.cls = hit.cls;
      }
    }
    const int first = (u + 2 * v) % n_instants;
    lens.forEachSample(exposure.pattern, start, u, v, [&](int s, const Eigen::Vector3d& d_cam) {
      const Instant& in = instants[(first + s) % n_instants];
      Ray ray{in.origin, in.R * d_cam};
      Hit hit;
      in.scene->trace(ray, hit);
      result.rgb_sum += hit.rgb.cast<double>();
    });
    sink(u, result);
  }
}

// Scene::trace's lower bound on hit distances (datasets/scene.cpp kTMin).
constexpr double kTraceMin = 1e-9;

// The largest float not above t.
inline float floatBelow(double t) {
  float f = static_cast<float>(t);
  if (static_cast<double>(f) > t) f = std::nextafter(f, 0.0f);
  return f;
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// detail: the pieces shared with the board presets' fast path (datasets/detail/render_kernel.h)

namespace detail {


struct SpanTracer::Impl {
  Lens lens;
  std::vector<Eigen::Vector2d> pattern;
  Eigen::Matrix3d R;  // world <- camera
  Eigen::Vector3d origin;
  float scale;
};

SpanTracer::SpanTracer(const Camera& camera, const Pose& T_world_cam, int samples_per_pixel,
                       double gain) {
  std::vector<Eigen::Vector2d> pattern = samplePattern(samples_per_pixel);
  const float scale = static_cast<float>(gain / pattern.size());  // as renderView's
  impl_.reset(new Impl{Lens(camera), std::move(pattern), T_world_cam.rotation(),
                       T_world_cam.translation(), scale});
}

SpanTracer::~SpanTracer() = default;

void SpanTracer::traceRow(const Scene& scene, int v, int u0, int u1, float* rgb,
                          const Primitive* board, const float* stage_t, float* least_t) const {
  const Impl& m = *impl_;
  Start start;  // the previous pixel's centre: warm start along the row
  for (int u = u0; u <= u1; ++u) {
    double x_c = 0, y_c = 0;
    m.lens.centre(u, v, start, x_c, y_c);
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    double least = std::numeric_limits<double>::infinity();
    m.lens.forEachSample(m.pattern, start, u, v, [&](int, const Eigen::Vector3d& d_cam) {
      Ray ray{m.origin, m.R * d_cam};
      Hit hit;
      if (board != nullptr) {
        hit.t = stage_t[u];
        if (board->intersect(ray, kTraceMin, hit)) {
          board->shade(ray, hit);
          sum += hit.rgb.cast<double>();
          return;
        }
      }
      scene.trace(ray, hit);
      sum += hit.rgb.cast<double>();
      least = std::min(least, hit.t);
    });
    if (least_t != nullptr) least_t[u] = floatBelow(least);
    storeMean(sum, m.scale, rgb + 3 * (u - u0));
  }
}

SrgbTable::SrgbTable() {
  for (int i = 0; i <= kSize; ++i) {
    table_[i] = static_cast<float>(255.0 * srgbEncode(static_cast<double>(i) / kSize));
  }
}

const SrgbTable& srgbTable() {
  static const SrgbTable table;
  return table;
}

GaussianBlur::GaussianBlur(double sigma)
    : radius_(std::max(1, static_cast<int>(std::ceil(4.0 * sigma)))) {
  kernel_.resize(2 * radius_ + 1);
  double sum = 0;
  for (int i = -radius_; i <= radius_; ++i) {
    kernel_[i + radius_] = static_cast<float>(std::exp(-0.5 * i * i / (sigma * sigma)));
    sum += kernel_[i + radius_];
  }
  for (float& w : kernel_) w = static_cast<float>(w / sum);
}

cv::Mat GaussianBlur::apply(const cv::Mat& src, int threads) const {
  const int rows = src.rows, cols = src.cols, ch = src.channels(), r = radius_;
  cv::Mat tmp(src.size(), src.type()), dst(src.size(), src.type());
#pragma omp parallel for schedule(static) num_threads(threads)
  for (int v = 0; v < rows; ++v) {
    const float* in = src.ptr<float>(v);
    float* out = tmp.ptr<float>(v);
    for (int u = 0; u < cols; ++u) {
      for (int c = 0; c < ch; ++c) {
        float acc = 0;
        for (int i = -r; i <= r; ++i) {
          const int uu = std::clamp(u + i, 0, cols - 1);
          acc += kernel_[i + r] * in[uu * ch + c];
        }
        out[u * ch + c] = acc;
      }
    }
  }
#pragma omp parallel for schedule(static) num_threads(threads)
  for (int v = 0; v < rows; ++v) {
    float* out = dst.ptr<float>(v);
    for (int x = 0; x < cols * ch; ++x) out[x] = 0;
    for (int i = -r; i <= r; ++i) {
      const float* in = tmp.ptr<float>(std::clamp(v + i, 0, rows - 1));
      const float w = kernel_[i + r];
      for (int x = 0; x < cols * ch; ++x) out[x] += w * in[x];
    }
  }
  return dst;
}

}  // namespace detail

// ---------------------------------------------------------------------------------------------

void RenderOptions::validate() const {
  if (samples_per_pixel < 4) {
    fail("samples_per_pixel", "must be >= 4 (got " + std::to_string(samples_per_pixel) + ")");
  }
  if (samples_per_pixel > 4096) {
    fail("samples_per_pixel", "must be <= 4096 (got " + std::to_string(samples_per_pixel) + ")");
  }
  if (!(gain > 0) || !std::isfinite(gain)) fail("gain", "must be > 0 (got " + std::to_string(gain) + ")");
  if (!(blur_sigma_px >= 0) || !std::isfinite(blur_sigma_px)) {
    fail("blur_sigma_px", "must be >= 0 (got " + std::to_string(blur_sigma_px) + ")");
  }
  if (!(noise_sigma >= 0) || !std::isfinite(noise_sigma)) {
    fail("noise_sigma", "must be >= 0 (got " + std::to_string(noise_sigma) + ")");
  }
  if (threads < 0) fail("threads", "must be >= 0 (got " + std::to_string(threads) + ")");
}

std::vector<Eigen::Vector2d> samplePattern(int samples_per_pixel) {
  const int n_samples = samples_per_pixel;
  std::vector<Eigen::Vector2d> pattern;
  pattern.reserve(n_samples);
  const int n = static_cast<int>(std::lround(std::sqrt(static_cast<double>(n_samples))));
  if (n * n == n_samples) {
    // Chiu, Shirley & Wang 1994 (multi-jittered), canonical arrangement without the jitter.
    for (int j = 0; j < n; ++j) {
      for (int i = 0; i < n; ++i) {
        const double x = (i + (j + 0.5) / n) / n;
        const double y = (j + (i + 0.5) / n) / n;
        pattern.emplace_back(x - 0.5, y - 0.5);
      }
    }
  } else {
    for (int k = 0; k < n_samples; ++k) {
      double y = 0, f = 0.5;
      for (unsigned b = static_cast<unsigned>(k); b; b >>= 1, f *= 0.5) y += f * (b & 1u);
      pattern.emplace_back((k + 0.5) / n_samples - 0.5, y + 0.5 / n_samples - 0.5);
    }
  }
  return pattern;
}

bool pixelRay(const Camera& camera, const Eigen::Vector2d& px, Eigen::Vector3d& dir_cam) {
  const Lens lens(camera);
  double xd, yd, x, y;
  lens.k.toNormalized(px.x(), px.y(), xd, yd);
  if (!invertFrom(camera, lens.brown, xd, yd, Start{}, x, y)) return false;
  dir_cam = Eigen::Vector3d(x, y, 1.0).normalized();
  return true;
}

RenderedView renderView(const Camera& camera, const Pose& T_world_cam, const Scene& scene,
                        const RenderOptions& options) {
  const ShutterSample instant{&scene, T_world_cam};
  return renderView(camera, std::vector<ShutterSample>{instant}, instant, options);
}

RenderedView renderView(const Camera& camera, const std::vector<ShutterSample>& shutter,
                        const ShutterSample& centre, const RenderOptions& options) {
  options.validate();
  const Exposure exposure = makeExposure(camera, shutter, centre, options.samples_per_pixel);
  const int threads = resolveThreads(options.threads);
  const int W = camera.width, H = camera.height;
  const float scale = static_cast<float>(options.gain / exposure.pattern.size());

  RenderedView view;
  cv::Mat linear(H, W, CV_32FC3);  // R, G, B
  if (options.truth) {
    view.depth.create(H, W, CV_32FC1);
    view.labels.create(H, W, CV_8UC1);
    view.mask.create(H, W, CV_8UC1);
  }
  int not_invertible = 0;
#pragma omp parallel for schedule(dynamic, 2) num_threads(threads) reduction(+ : not_invertible)
  for (int v = 0; v < H; ++v) {
    float* rgb = linear.ptr<float>(v);
    float* depth = options.truth ? view.depth.ptr<float>(v) : nullptr;
    std::uint8_t* labels = options.truth ? view.labels.ptr<std::uint8_t>(v) : nullptr;
    std::uint8_t* mask = options.truth ? view.mask.ptr<std::uint8_t>(v) : nullptr;
    renderRow(exposure, options.truth, v,
              [&](int u, const PixelResult& p) {
                storeMean(p.rgb_sum, scale, rgb + 3 * u);
                if (!p.centre_ok) ++not_invertible;
                if (depth != nullptr) {
                  depth[u] = p.depth;
                  labels[u] = static_cast<std::uint8_t>(p.cls);
                  mask[u] = p.cls == ObjectClass::kActor ? 255 : 0;
                }
              });
  }
  view.not_invertible = not_invertible;

  if (options.blur_sigma_px > 0) {
    linear = detail::GaussianBlur(options.blur_sigma_px).apply(linear, threads);
  }

  const detail::SrgbTable& table = detail::srgbTable();
  view.bgr.create(H, W, CV_8UC3);
  const double noise = options.noise_sigma;
  const std::uint64_t stream =
      hashKey(options.seed, static_cast<std::uint64_t>(options.camera_index),
              static_cast<std::uint64_t>(options.frame));
  using detail::quantize255;
  if (options.keep_encoded) view.encoded.create(H, W, CV_32FC3);
#pragma omp parallel for schedule(static) num_threads(threads)
  for (int v = 0; v < H; ++v) {
    const float* rgb = linear.ptr<float>(v);
    std::uint8_t* bgr = view.bgr.ptr<std::uint8_t>(v);
    if (options.keep_encoded) {
      float* enc = view.encoded.ptr<float>(v);
      for (int u = 0; u < W; ++u) {
        const std::uint64_t pixel = static_cast<std::uint64_t>(v) * W + u;
        for (int c = 0; c < 3; ++c) {
          double value = table.encode255(rgb[3 * u + c]);
          if (noise > 0) value += noise * normalFromKey(hashKey(stream, pixel, c));
          bgr[3 * u + (2 - c)] = quantize255(value);
          enc[3 * u + (2 - c)] = static_cast<float>(std::clamp(value, 0.0, 255.0) / 255.0);
        }
      }
    } else if (noise > 0) {
      for (int u = 0; u < W; ++u) {
        const std::uint64_t pixel = static_cast<std::uint64_t>(v) * W + u;
        for (int c = 0; c < 3; ++c) {
          const double value = table.encode255(rgb[3 * u + c]) +
                               noise * normalFromKey(hashKey(stream, pixel, c));
          bgr[3 * u + (2 - c)] = quantize255(value);
        }
      }
    } else {
      for (int u = 0; u < W; ++u) {
        for (int c = 0; c < 3; ++c) {
          bgr[3 * u + (2 - c)] = quantize255(table.encode255(rgb[3 * u + c]));
        }
      }
    }
  }
  return view;
}

LinearView renderLinear(const Camera& camera, const std::vector<ShutterSample>& shutter,
                        const ShutterSample& centre, int samples_per_pixel, int threads) {
  RenderOptions check;
  check.samples_per_pixel = samples_per_pixel;
  check.threads = threads;
  check.validate();
  const Exposure exposure = makeExposure(camera, shutter, centre, samples_per_pixel);
  const int W = camera.width, H = camera.height;
  const float scale = 1.0f / static_cast<float>(exposure.pattern.size());

  LinearView view;
  view.rgb.create(H, W, CV_32FC3);
  view.depth.create(H, W, CV_32FC1);
#pragma omp parallel for schedule(dynamic, 2) num_threads(resolveThreads(threads))
  for (int v = 0; v < H; ++v) {
    float* rgb = view.rgb.ptr<float>(v);
    float* depth = view.depth.ptr<float>(v);
    renderRow(exposure, true, v,
              [&](int u, const PixelResult& p) {
                storeMean(p.rgb_sum, scale, rgb + 3 * u);
                depth[u] = p.depth;
              });
  }
  return view;
}

}  // namespace previz::synth
