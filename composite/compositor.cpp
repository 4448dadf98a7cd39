// Depth-aware compositor (see compositor.h).
#include "composite/compositor.h"

#include <omp.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <vector>

#include <opencv2/imgproc.hpp>

#include "core/error.h"
#include "core/simd.h"
#include "core/srgb.h"
#include "core/stopwatch.h"
#include "core/threads.h"

namespace previz::composite {
namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();

// Linear [0, 1] in 65536 steps -> 8-bit sRGB code, rounded as the renderer rounds. The step
// (1.5e-5 linear) is below a tenth of a code everywhere, darks included.
constexpr int kEncodeSize = 65536;
const std::vector<std::uint8_t>& encodeTable() {
  static const std::vector<std::uint8_t> table = [] {
    std::vector<std::uint8_t> t(kEncodeSize);
    for (int i = 0; i < kEncodeSize; ++i)
      t[i] = static_cast<std::uint8_t>(std::lround(255.0 * srgbEncode(i / double(kEncodeSize - 1))));
    return t;
  }();
  return table;
}

// Four floats as one vector (GCC/Clang vector extension: SSE on x86-64, NEON on ARM). A CG
// pixel's R, G, B and the next pixel's R are loaded at once; lane 3 is never used.
typedef float Float4 __attribute__((vector_size(16)));
typedef std::int32_t Int4 __attribute__((vector_size(16)));
inline Float4 load4(const float* p) {
  Float4 v;
  std::memcpy(&v, p, sizeof v);
  return v;
}

// Two pixels' Float4s side by side (the AVX2 version's 256-bit registers; two SSE registers in
// the baseline one: each lane computes what it would alone). Inlined by force: called from the
// PREVIZ_WIDE composite, whose AVX2 version would otherwise call the baseline code and pass
// every 32-byte vector through memory.
// GCC warns that a 32-byte vector returned without AVX is passed in memory (-Wpsabi): these
// helpers are always inlined, so no call passes one.
#pragma GCC diagnostic ignored "-Wpsabi"
typedef float Float8 __attribute__((vector_size(32)));
typedef std::int32_t Int8 __attribute__((vector_size(32)));
// (Joined by a shuffle: two 16-byte stores read back as one 32-byte load stall the CPU.)
[[gnu::always_inline]] inline Float8 load4x2(const float* a, const float* b) {
  return __builtin_shufflevector(load4(a), load4(b), 0, 1, 2, 3, 4, 5, 6, 7);
}
[[gnu::always_inline]] inline Float8 splat2(float a, float b) {
  return __builtin_shufflevector(Float4{a, a, a, a}, Float4{b, b, b, b}, 0, 1, 2, 3, 4, 5, 6, 7);
}

// Linear values -> the encode table's indices, lane by lane (Float4 -> Int4, Float8 -> Int8).
// Clamped without branches (min/max; the CG's values are random to the branch predictor), NaN to
// 0 (an EXR may hold NaN: it used to index the table at INT_MIN).
template <typename Int, typename Float>
[[gnu::always_inline]] inline Int encodeIndex(Float linear) {
  Float s = linear * float(kEncodeSize - 1) + 0.5f;
  s = s > 0.f ? s : 0.f;
  s = s < float(kEncodeSize - 1) ? s : float(kEncodeSize - 1);
  return __builtin_convertvector(s, Int);
}

// Linear R, G, B (lanes 0-2) -> the 8-bit codes, written B, G, R.
inline void encode3(const std::uint8_t* table, Float4 rgb, std::uint8_t* bgr) {
  const Int4 i = encodeIndex<Int4>(rgb);
  bgr[0] = table[i[2]];
  bgr[1] = table[i[1]];
  bgr[2] = table[i[0]];
}

// encode3 of two pixels (lanes 0-2 and 4-6), written at bgr and bgr + 3.
[[gnu::always_inline]] inline void encode3x2(const std::uint8_t* table, Float8 rgb, std::uint8_t* bgr) {
  const Int8 i = encodeIndex<Int8>(rgb);
  bgr[0] = table[i[2]];
  bgr[1] = table[i[1]];
  bgr[2] = table[i[0]];
  bgr[3] = table[i[6]];
  bgr[4] = table[i[5]];
  bgr[5] = table[i[4]];
}

inline float smoothstep01(float t) {
  t = std::clamp(t, 0.f, 1.f);
  return t * t * (3.f - 2.f * t);
}

void checkInput(const cv::Mat& m, int type, cv::Size size, const char* name, const std::string& source) {
  if (m.empty() || m.type() != type || m.size() != size) {
    ErrorContext c = fieldContext(name);
    throw Error(std::string("composite") + (source.empty() ? "" : " (" + source + ")") + ": " + name +
                    " must be " + cv::typeToString(type) + " of " + std::to_string(size.width) + "x" +
                    std::to_string(size.height) + " (got " +
                    (m.empty() ? std::string("an empty image")
                               : cv::typeToString(m.type()) + " of " + std::to_string(m.cols) + "x" +
                                     std::to_string(m.rows)) +
                    ")",
                c);
  }
}

bool sameLens(const Camera& a, const Camera& b) {
  return a.width == b.width && a.height == b.height && a.fx == b.fx && a.fy == b.fy && a.cx == b.cx &&
         a.cy == b.cy && a.skew == b.skew && a.dist == b.dist;
}

}  // namespace

void CompositeOptions::validate() const {
  if (!(depth_band_m >= 0) || !std::isfinite(depth_band_m))
    throw Error("composite: depth_band_m must be >= 0 (got " + std::to_string(depth_band_m) + ")",
                fieldContext("depth_band_m"));
  if (edge_fill_px < 0 || edge_fill_px > 32)
    throw Error("composite: edge_fill_px must be in [0, 32] (got " + std::to_string(edge_fill_px) + ")",
                fieldContext("edge_fill_px"));
  if (!(cg_gain > 0) || !std::isfinite(cg_gain))
    throw Error("composite: cg_gain must be > 0 (got " + std::to_string(cg_gain) + ")", fieldContext("cg_gain"));
  if (threads < 0)
    throw Error("composite: threads must be >= 0 (got " + std::to_string(threads) + ")", fieldContext("threads"));
}

Compositor::Compositor(const Camera& lens, const Camera& cg, const CompositeOptions& options)
    : lens_(lens), cg_(cg), options_(options) {
  options_.validate();
  lens_.validate();
  cg_.validate();
  if (!cg_.dist.isZero()) {
    ErrorContext c;
    c.camera = cg_.name;
    c.field = "distortion";
    throw Error("composite: the CG camera must be an ideal pinhole (zero distortion)", c);
  }
  build();
}

bool Compositor::setLens(const Camera& lens) {
  if (sameLens(lens, lens_)) return false;
  lens.validate();
  lens_ = lens;
  build();
  return true;
}

void Compositor::build() {
  map_ = makeDistortMap(lens_, cg_);
  int outside = 0;
  const int CW = cg_.width, CH = cg_.height;
  taps_.assign(static_cast<size_t>(lens_.width) * lens_.height, Tap{});
  for (int v = 0; v < map_.map.rows; ++v) {
    const cv::Vec2f* m = map_.map.ptr<cv::Vec2f>(v);
    for (int u = 0; u < map_.map.cols; ++u) {
      const float sx = m[u][0], sy = m[u][1];
      if (sx == -1.f && sy == -1.f) continue;  // not invertible, counted by the map
      if (sx < -0.5f || sy < -0.5f || sx > CW - 0.5f || sy > CH - 0.5f) {
        ++outside;
        continue;
      }
      // Within half a pixel of the border: the border pixel (clamped), then the 2 x 2 block that
      // holds the point, its origin kept inside the image.
      const float x = std::clamp(sx, 0.f, CW - 1.f), y = std::clamp(sy, 0.f, CH - 1.f);
      const int x0 = std::min(static_cast<int>(x), std::max(CW - 2, 0));
      const int y0 = std::min(static_cast<int>(y), std::max(CH - 2, 0));
      Tap& t = taps_[static_cast<size_t>(v) * lens_.width + u];
      t.index = y0 * CW + x0;
      // Weights in 1/256, at most 255: a point on the far pixel's centre (the last column or
      // row) is read 1/256 px short of it.
      t.ax = std::min(255, static_cast<int>((x - x0) * 256.f + 0.5f)) * (1.f / 256);
      t.ay = std::min(255, static_cast<int>((y - y0) * 256.f + 0.5f)) * (1.f / 256);
    }
  }
  outside_cg_ = outside;
}

cv::Mat Compositor::distortCg(const cv::Mat& cg_image, bool nearest, const cv::Scalar& border) const {
  if (cg_image.empty() || cg_image.cols != cg_.width || cg_image.rows != cg_.height) {
    ErrorContext c;
    c.camera = cg_.name;
    throw Error("composite: a CG image must be " + std::to_string(cg_.width) + "x" +
                    std::to_string(cg_.height) + " (the CG camera's size)",
                c);
  }
  cv::Mat out;
  cv::remap(cg_image, out, map_.map, cv::noArray(), nearest ? cv::INTER_NEAREST : cv::INTER_LINEAR,
            cv::BORDER_CONSTANT, border);
  return out;
}

CompositeResult Compositor::composite(const CompositeInputs& in, bool debug_layers,
                                      const std::string& source) const {
  CompositeResult r;
  composite(in, r, debug_layers, source);
  return r;
}

PREVIZ_WIDE
void Compositor::composite(const CompositeInputs& in, CompositeResult& r, bool debug_layers,
                           const std::string& source) const {
  const Stopwatch start;
  const cv::Size lens_size(lens_.width, lens_.height), cg_size(cg_.width, cg_.height);
  checkInput(in.foreground, CV_8UC3, lens_size, "foreground", source);
  checkInput(in.alpha, CV_32FC1, lens_size, "alpha", source);
  checkInput(in.actor_depth, CV_32FC1, lens_size, "actor_depth", source);
  checkInput(in.cg_color, CV_32FC3, cg_size, "cg_color", source);
  checkInput(in.cg_depth, CV_32FC1, cg_size, "cg_depth", source);

  r.stats = CompositeStats{};
  const int W = lens_.width, H = lens_.height, CW = cg_.width, CH = cg_.height;
  r.bgr.create(H, W, CV_8UC3);
  if (debug_layers) {
    r.layer_alpha.create(H, W, CV_32FC1);
    r.layer_actor_depth.create(H, W, CV_32FC1);
    r.layer_cg_depth.create(H, W, CV_32FC1);
    r.layer_front.create(H, W, CV_8UC1);
    r.linear.create(H, W, CV_32FC3);
  } else {
    r.layer_alpha.release();
    r.layer_actor_depth.release();
    r.layer_cg_depth.release();
    r.layer_front.release();
    r.linear.release();
  }
  const std::array<float, 256>& dec = srgb8ToLinear();
  const std::uint8_t* enc = encodeTable().data();
  const float gain = static_cast<float>(options_.cg_gain);
  const float band = static_cast<float>(options_.depth_band_m);
  const int fill = options_.edge_fill_px;
  const cv::Vec3f outside = options_.outside_rgb;
  // The CG images as flat arrays (continuous: EXR reads and cv::Mat creates are).
  const cv::Mat cg_color = in.cg_color.isContinuous() ? in.cg_color : in.cg_color.clone();
  const cv::Mat cg_depth = in.cg_depth.isContinuous() ? in.cg_depth : in.cg_depth.clone();
  const float* cg_rgb = cg_color.ptr<float>();
  const float* cg_z = cg_depth.ptr<float>();
  const int dx1 = CW > 1 ? 1 : 0, dy1 = CH > 1 ? CW : 0;  // neighbour offsets (pixels)

  // The 2 x 2 block of a tap read as four 4-float vectors, unless that would read past the CG's
  // last float (a block whose bottom-right pixel is the CG's last pixel).
  const long long vector_taps_below = static_cast<long long>(CW) * CH - 1 - dx1 - dy1;
  long long actor_px = 0, actor_front = 0, cg_front = 0, filled = 0, fallback = 0;
#pragma omp parallel for schedule(static, 16) num_threads(resolveThreads(options_.threads)) \
    reduction(+ : actor_px, actor_front, cg_front, filled, fallback)
  for (int v = 0; v < H; ++v) {
    const Tap* tap_row = taps_.data() + static_cast<size_t>(v) * W;
    const std::uint8_t* f = in.foreground.ptr<std::uint8_t>(v);
    const float* al = in.alpha.ptr<float>(v);
    const float* za_row = in.actor_depth.ptr<float>(v);
    std::uint8_t* o = r.bgr.ptr<std::uint8_t>(v);
    // What the pixels read, copied into the row's own variables: a byte store may alias any
    // memory, so a value read through the parallel region's shared data (or a lambda's
    // reference) was reloaded from memory after every pixel's stores.
    const bool debug = debug_layers;
    const std::uint8_t* const enc_row = enc;
    const float* const cg_z_row = cg_z;
    const float band_row = band;
    const int dx1_row = dx1, dy1_row = dy1;
    const Float4 outside_rgb{outside[2], outside[1], outside[0], 0.f};
    // CG through the lens at a tap: bilinear colour in lanes R, G, B, the CG's gain applied.
    auto cgColour = [=](const Tap& t) -> Float4 {
      if (t.index < 0) return outside_rgb;
      const float ax = t.ax, ay = t.ay;
      const float* p00 = cg_rgb + 3 * static_cast<size_t>(t.index);
      const float* p01 = p00 + 3 * dx1_row;
      const float* p10 = p00 + 3 * static_cast<size_t>(dy1_row);
      const float* p11 = p10 + 3 * dx1_row;
      const float w00 = (1 - ax) * (1 - ay), w01 = ax * (1 - ay), w10 = (1 - ax) * ay, w11 = ax * ay;
      if (t.index < vector_taps_below) {
        // The same products and sums, in the same order, as the scalar lines below.
        return gain * (w00 * load4(p00) + w01 * load4(p01) + w10 * load4(p10) + w11 * load4(p11));
      }
      return Float4{gain * (w00 * p00[0] + w01 * p01[0] + w10 * p10[0] + w11 * p11[0]),
                    gain * (w00 * p00[1] + w01 * p01[1] + w10 * p10[1] + w11 * p11[1]),
                    gain * (w00 * p00[2] + w01 * p01[2] + w10 * p10[2] + w11 * p11[2]), 0.f};
    };

    // Two CG-only pixels at a time (most of the frame), where both read a whole 2 x 2 block:
    // the same operations lane by lane as cgColour's vector line and encode3.
    const Float8 gain8 = splat2(gain, gain);
    auto cgOnlyPair = [&](int u) __attribute__((always_inline)) {
      const Tap& ta = tap_row[u];
      const Tap& tb = tap_row[u + 1];
      if (debug || al[u] > 0 || al[u + 1] > 0 || ta.index < 0 || tb.index < 0 || ta.index >= vector_taps_below ||
          tb.index >= vector_taps_below)
        return false;
      const float* a00 = cg_rgb + 3 * static_cast<size_t>(ta.index);
      const float* b00 = cg_rgb + 3 * static_cast<size_t>(tb.index);
      const float* a10 = a00 + 3 * static_cast<size_t>(dy1_row);
      const float* b10 = b00 + 3 * static_cast<size_t>(dy1_row);
      const Float8 ax = splat2(ta.ax, tb.ax), ay = splat2(ta.ay, tb.ay);
      const Float8 w00 = (1 - ax) * (1 - ay), w01 = ax * (1 - ay), w10 = (1 - ax) * ay, w11 = ax * ay;
      const Float8 c = gain8 * (w00 * load4x2(a00, b00) + w01 * load4x2(a00 + 3 * dx1_row, b00 + 3 * dx1_row) +
                                w10 * load4x2(a10, b10) + w11 * load4x2(a10 + 3 * dx1_row, b10 + 3 * dx1_row));
      encode3x2(enc_row, c, o + 3 * u);
      return true;
    };
    for (int u = 0; u < W; ++u) {
      if (u + 1 < W && cgOnlyPair(u)) {
        ++u;
        continue;
      }
      const Tap t = tap_row[u];
      if (!(al[u] > 0) && !debug) {
        encode3(enc_row, cgColour(t), o + 3 * u);  // no actor (most of the frame): the CG alone
        continue;
      }
      // CG depth through the lens: nearest (a blend of depths across the pillar's edge would be
      // a depth that exists nowhere).
      const float zc = t.index < 0 ? kInf : cg_z_row[t.index + (t.ax >= 0.5f ? dx1_row : 0) + (t.ay >= 0.5f ? dy1_row : 0)];
      const float alpha = std::clamp(al[u], 0.f, 1.f);
      float za = za_row[u];
      unsigned char code = kFrontNone;
      float a = 0;
      if (alpha > 0) {
        ++actor_px;
        if (!std::isfinite(za) && fill > 0) {
          // Nearest known depth in the window (ties: the nearer surface).
          int best_d2 = std::numeric_limits<int>::max();
          float best = kInf;
          for (int dy = -fill; dy <= fill; ++dy) {
            const int yy = v + dy;
            if (yy < 0 || yy >= H) continue;
            const float* row = in.actor_depth.ptr<float>(yy);
            for (int dx = -fill; dx <= fill; ++dx) {
              const int xx = u + dx;
              if (xx < 0 || xx >= W) continue;
              const float z = row[xx];
              if (!std::isfinite(z)) continue;
              const int d2 = dx * dx + dy * dy;
              if (d2 < best_d2 || (d2 == best_d2 && z < best)) {
                best_d2 = d2;
                best = z;
              }
            }
          }
          if (std::isfinite(best)) {
            za = best;
            ++filled;
          }
        }
        float w;
        if (!std::isfinite(za)) {
          w = 1.f;
          code = kFrontFallback;
          ++fallback;
        } else if (!std::isfinite(zc)) {
          w = 1.f;
        } else if (band_row > 0) {
          w = smoothstep01((zc - za) / band_row + 0.5f);
        } else {
          w = za < zc ? 1.f : 0.f;
        }
        if (code != kFrontFallback) {
          code = w >= 0.5f ? kFrontActor : kFrontCg;
          if (code == kFrontActor) ++actor_front; else ++cg_front;
        }
        a = alpha * w;
      }
      const std::uint8_t* fp = f + 3 * u;
      if (a >= 1.f && !debug) {
        // The plate as shot, byte for byte (decode + encode is the identity on 8-bit codes).
        o[3 * u + 0] = fp[0];
        o[3 * u + 1] = fp[1];
        o[3 * u + 2] = fp[2];
        continue;
      }
      const Float4 c = cgColour(t);
      const float cb = c[2], cgc = c[1], cr = c[0];
      const float ob = a * dec[fp[0]] + (1 - a) * cb;
      const float og = a * dec[fp[1]] + (1 - a) * cgc;
      const float orr = a * dec[fp[2]] + (1 - a) * cr;
      encode3(enc_row, Float4{orr, og, ob, 0.f}, o + 3 * u);
      if (debug) {
        r.layer_alpha.ptr<float>(v)[u] = a;
        r.layer_actor_depth.ptr<float>(v)[u] = alpha > 0 ? za : kInf;
        r.layer_cg_depth.ptr<float>(v)[u] = zc;
        r.layer_front.ptr<std::uint8_t>(v)[u] = code;
        float* lin = r.linear.ptr<float>(v) + 3 * u;
        lin[0] = ob;
        lin[1] = og;
        lin[2] = orr;
      }
    }
  }
  r.stats.actor_px = actor_px;
  r.stats.actor_front_px = actor_front;
  r.stats.cg_front_px = cg_front;
  r.stats.edge_filled_px = filled;
  r.stats.fallback_px = fallback;
  r.stats.ms = start.ms();
}

cv::Mat depthPreview(const cv::Mat& depth_m, double near_m, double far_m) {
  cv::Mat t(depth_m.size(), CV_8UC1, cv::Scalar(0)), valid(depth_m.size(), CV_8UC1, cv::Scalar(0));
  const double span = far_m > near_m ? far_m - near_m : 1.0;
  for (int y = 0; y < depth_m.rows; ++y) {
    const float* d = depth_m.ptr<float>(y);
    for (int x = 0; x < depth_m.cols; ++x) {
      if (!std::isfinite(d[x])) continue;
      t.at<uchar>(y, x) = cv::saturate_cast<uchar>(40 + 215 * (far_m - d[x]) / span);
      valid.at<uchar>(y, x) = 255;
    }
  }
  cv::Mat colour;
  cv::applyColorMap(t, colour, cv::COLORMAP_TURBO);
  cv::Mat out(depth_m.size(), CV_8UC3, cv::Scalar::all(0));
  colour.copyTo(out, valid);
  return out;
}

cv::Mat frontPreview(const cv::Mat& front) {
  static const cv::Vec3b colours[4] = {{0, 0, 0}, {40, 40, 220}, {40, 200, 40}, {220, 40, 220}};
  cv::Mat out(front.size(), CV_8UC3);
  for (int y = 0; y < front.rows; ++y) {
    const std::uint8_t* f = front.ptr<std::uint8_t>(y);
    cv::Vec3b* o = out.ptr<cv::Vec3b>(y);
    for (int x = 0; x < front.cols; ++x) o[x] = colours[std::min<int>(f[x], 3)];
  }
  return out;
}

}  // namespace previz::composite
