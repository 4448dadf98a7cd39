#include "carving/keyer.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <sstream>
#include <vector>

#include <omp.h>
#include <opencv2/core/hal/intrin.hpp>
#include <opencv2/imgproc.hpp>

#include "core/error.h"
#include "core/simd.h"
#include "core/srgb.h"
#include "core/threads.h"

namespace previz::carving {
namespace {

// Pixel classes of the first pass. Background <= kGarbage < kUnknown < foreground.
constexpr std::uint8_t kScreen = 0;   // the lit or shadowed screen
constexpr std::uint8_t kGarbage = 1;  // beyond the screen (dark studio), border-connected
constexpr std::uint8_t kUnknown = 2;  // between: decided by the two-colour alpha
constexpr std::uint8_t kFg = 3;       // clearly foreground
// Looks like the garbage colour but not connected to the border: foreground (tag ink, a dark
// neutral costume part surrounded by screen). Turned into kGarbage by the flood when reached.
constexpr std::uint8_t kGarbageLike = 4;
// Difference keying, first pass only: the plate darkened within one pixel's noise, a shadow if
// its neighbourhood agrees (shadowNeighbourhood turns it into kScreen or kUnknown).
constexpr std::uint8_t kShadowCandidate = 5;

// True where every byte of the 8 at p is background (<= kGarbage).
bool allBackground8(const std::uint8_t* p) {
  std::uint64_t v;
  std::memcpy(&v, p, 8);
  return (v & 0xFEFEFEFEFEFEFEFEull) == 0;
}

// True where some byte of the 8 at p is kUnknown.
bool anyUnknown8(const std::uint8_t* p) {
  std::uint64_t v;
  std::memcpy(&v, p, 8);
  v ^= 0x0101010101010101ull * kUnknown;  // bytes equal to kUnknown become 0
  return ((v - 0x0101010101010101ull) & ~v & 0x8080808080808080ull) != 0;
}

// Screen chroma thresholds, as fractions of the screen's own q = (G - max(R, B)) / G.
// A pixel within 15 % of the screen's q is screen (8-bit quantisation of a deep shadow moves q by
// ~2 %; sensor noise of a few levels by ~5 %). At or below 40 % it is foreground: the studio's
// greenish-grey costume sits at ~25 % of the screen's q, a 50/50 mix of screen and costume at
// ~70 %, so the costume is foreground and its edges are unknown (two-colour alpha).
constexpr float kScreenQFraction = 0.85f;
constexpr float kFgQFraction = 0.40f;
// Brightness accepted for screen, relative to the reference green (the key colour, or the
// plate's own pixel): shadows and the cyclorama's falloff darken the screen, nothing brightens
// it much. Below the floor chroma is too noisy to trust.
constexpr float kMinScreenBrightness = 0.06f;  // no plate: of the key's median green
constexpr float kMinPlateShadow = 0.15f;       // plate: darkest accepted shadow factor
constexpr float kMaxPlateBrightening = 1.3f;
// Alphas within this of the silhouette threshold are decided on the 3 x 3 mean (see key()),
// when the window holds clear background and clear foreground (alpha within kClearAlpha of 0, 1).
constexpr float kAmbiguousAlpha = 0.2f;
constexpr float kClearAlpha = 0.15f;
// Rows per parallel band of the first two passes.
constexpr int kBandRows = 16;
// Region keying: every 8th row outside the region is probed; 3 clear foreground pixels in a row
// there are something new (sensor noise at 4 sigma past the screen's chroma band does not line
// up three in a row).
constexpr int kRegionProbeRows = 8;
constexpr int kRegionProbeRun = 3;

[[noreturn]] void fail(const std::string& message, const std::string& source) {
  ErrorContext context;
  context.file = source;
  throw Error("keyer: " + (source.empty() ? "" : "'" + source + "': ") + message, context);
}

template <typename T>
std::string str(T value) {
  std::ostringstream s;
  s << value;
  return s.str();
}

// Smallest 8-bit code whose linear value is >= v (256 when none is).
int srgbCodeAtLeast(float v) {
  const auto& lut = srgb8ToLinear();
  return static_cast<int>(std::lower_bound(lut.begin(), lut.end(), v) - lut.begin());
}

void checkImage(const cv::Mat& bgr8, const std::string& source) {
  if (bgr8.empty()) fail("empty image", source);
  if (bgr8.type() != CV_8UC3) {
    fail("expected an 8-bit 3-channel BGR image, got type " + cv::typeToString(bgr8.type()),
         source);
  }
}

float chromaQ(float r, float g, float b) { return (g - std::max(r, b)) / std::max(g, 1e-6f); }

void swapBlueGreen(const cv::Mat& in, cv::Mat& out) {
  out.create(in.size(), CV_8UC3);
  const int from_to[] = {0, 1, 1, 0, 2, 2};
  cv::mixChannels(&in, 1, &out, 1, from_to, 3);
}

// Which screen a frame shows: on a 4-px grid, the pixels that are clearly green (G above R and
// B by a quarter of G in linear light, not dark) against those clearly blue. A screen fills a
// good part of a witness frame; the dark studio's slight blue cast is below the quarter.
Backdrop dominantScreen(const cv::Mat& bgr8, int& support) {
  const auto& lut = srgb8ToLinear();
  constexpr int kStep = 4;
  constexpr float kQ = 0.25f;
  int green = 0, blue = 0, samples = 0;
  for (int y = kStep / 2; y < bgr8.rows; y += kStep) {
    const std::uint8_t* p = bgr8.ptr<std::uint8_t>(y);
    for (int x = kStep / 2; x < bgr8.cols; x += kStep, ++samples) {
      const float b = lut[p[3 * x]], g = lut[p[3 * x + 1]], r = lut[p[3 * x + 2]];
      if (r + g + b < 0.03f) continue;
      green += chromaQ(r, g, b) >= kQ;
      blue += chromaQ(r, b, g) >= kQ;
    }
  }
  support = std::max(green, blue);
  // Fewer than 2 % of the samples: no screen in the frame (or one too small to estimate).
  if (support < std::max(50, samples / 50)) return Backdrop::kAuto;
  return green >= blue ? Backdrop::kGreen : Backdrop::kBlue;
}

// Key colour from the frame: the mode of a chromaticity histogram over green-dominant pixels
// (the screen is the largest uniform area of a witness frame), then the per-channel median of
// the samples in and around that bin. Sampled on a 4-px grid.
bool estimateKeyColour(const cv::Mat& bgr8, cv::Vec3f& key) {
  const auto& lut = srgb8ToLinear();
  constexpr int kBins = 32, kStep = 4;
  struct Sample {
    float b, g, r;
    int bin;
  };
  std::vector<Sample> samples;
  samples.reserve(static_cast<size_t>(bgr8.rows / kStep + 1) * (bgr8.cols / kStep + 1));
  std::vector<int> histogram(kBins * kBins, 0);
  for (int y = kStep / 2; y < bgr8.rows; y += kStep) {
    const std::uint8_t* p = bgr8.ptr<std::uint8_t>(y);
    for (int x = kStep / 2; x < bgr8.cols; x += kStep) {
      const float b = lut[p[3 * x]], g = lut[p[3 * x + 1]], r = lut[p[3 * x + 2]];
      const float s = r + g + b;
      if (s < 0.03f || g <= std::max(r, b)) continue;  // dark or not green-dominant
      const int br = std::min(kBins - 1, static_cast<int>(r / s * kBins));
      const int bb = std::min(kBins - 1, static_cast<int>(b / s * kBins));
      const int bin = br * kBins + bb;
      ++histogram[bin];
      samples.push_back({b, g, r, bin});
    }
  }
  const int mode = static_cast<int>(std::max_element(histogram.begin(), histogram.end()) -
                                    histogram.begin());
  if (histogram[mode] < 50) return false;
  std::vector<float> cb, cg, cr;
  for (const Sample& s : samples) {
    if (std::abs(s.bin / kBins - mode / kBins) <= 1 && std::abs(s.bin % kBins - mode % kBins) <= 1) {
      cb.push_back(s.b);
      cg.push_back(s.g);
      cr.push_back(s.r);
    }
  }
  auto median = [](std::vector<float>& v) {
    std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
    return v[v.size() / 2];
  };
  key = cv::Vec3f(median(cb), median(cg), median(cr));
  return key[1] > 0;
}

// Per-frame constants of the first pass. In linear light a pixel has the screen's chroma when
// G - max(R, B) >= q G, i.e. lin(m8) <= k lin(g8) with m8 = max(r8, b8), k = 1 - q. Above the
// sRGB curve's linear toe (code 10) lin(c) = ((c / 255 + 0.055) / 1.055)^2.4 exactly, so the
// test is m8 + 14.025 <= k^(1 / 2.4) (g8 + 14.025): integer arithmetic on the 8-bit codes, no
// decode, no division (16 pixels per SIMD step). Pixels darker than the toe fail the brightness
// floor anyway.
struct ClassifyTables {
  int screen_k = 0, screen_c = 0;                // 128 m8 + c <= k g8: screen chroma
  std::array<std::int16_t, 256> fg_min_m{};      // max(r8, b8) >= this: foreground chroma
  int min_green8 = 0;                            // no plate: darkest screen green
  bool screenChroma(int m8, int g8) const { return 128 * m8 + screen_c <= screen_k * g8; }
};

ClassifyTables makeTables(const ScreenModel& sm) {
  const auto& lut = srgb8ToLinear();
  ClassifyTables t;
  const double kappa = std::pow(1.0 - kScreenQFraction * sm.key_q, 1.0 / 2.4);
  t.screen_k = static_cast<int>(std::lround(128.0 * kappa));
  t.screen_c = static_cast<int>(std::lround(128.0 * 14.025 * (1.0 - kappa)));
  const float keep_fg = 1.0f - kFgQFraction * sm.key_q;
  for (int g = 0; g < 256; ++g) {
    // Smallest m with lin(m) >= keep_fg lin(g).
    t.fg_min_m[g] = static_cast<std::int16_t>(srgbCodeAtLeast(keep_fg * lut[g]));
  }
  t.min_green8 = srgbCodeAtLeast(kMinScreenBrightness * sm.key_color[1]);
  return t;
}

// Colour of the non-screen surroundings from the image border band (no clean plate): the pixels
// of the two outermost rows / columns that are not screen. Returns an invalid model when the
// border is (almost) all screen.
GarbageModel estimateGarbage(const cv::Mat& bgr8, const ClassifyTables& tables) {
  const auto& lut = srgb8ToLinear();
  std::vector<float> rs, bs, sums;
  auto take = [&](int y, int x) {
    const cv::Vec3b& p = bgr8.at<cv::Vec3b>(y, x);
    if (tables.screenChroma(std::max(p[0], p[2]), p[1]) && p[1] >= tables.min_green8) return;
    const float b = lut[p[0]], g = lut[p[1]], r = lut[p[2]];
    const float s = r + g + b;
    if (s <= 1e-4f) return;
    rs.push_back(r / s);
    bs.push_back(b / s);
    sums.push_back(s);
  };
  constexpr int kBand = 2, kStep = 2;
  for (int k = 0; k < kBand; ++k) {
    for (int x = 0; x < bgr8.cols; x += kStep) {
      take(k, x);
      take(bgr8.rows - 1 - k, x);
    }
    for (int y = 0; y < bgr8.rows; y += kStep) {
      take(y, k);
      take(y, bgr8.cols - 1 - k);
    }
  }
  GarbageModel model;
  const size_t border_samples =
      static_cast<size_t>(kBand) * 2 * (bgr8.cols + bgr8.rows) / kStep;
  // Fewer than 2 % of the border off the screen: nothing to model (an actor's feet, say).
  if (rs.size() < std::max<size_t>(16, border_samples / 50)) return model;
  auto quantile = [](std::vector<float> v, double f) {
    const size_t k = std::min(v.size() - 1, static_cast<size_t>(f * v.size()));
    std::nth_element(v.begin(), v.begin() + k, v.end());
    return v[k];
  };
  // Near-black samples (black drapes, a dark band at the frame's edge) have no chroma to speak
  // of: one mode of any chroma up to their brightness, when they hold a tenth of the border.
  constexpr float kBlack = 0.03f;  // linear R + G + B: codes below ~30 each
  std::vector<float> left_r, left_b, left_s;
  size_t black = 0;
  for (size_t i = 0; i < rs.size(); ++i) {
    if (sums[i] < kBlack) {
      ++black;
      continue;
    }
    left_r.push_back(rs[i]);
    left_b.push_back(bs[i]);
    left_s.push_back(sums[i]);
  }
  if (black >= std::max<size_t>(16, border_samples / 10)) {
    model.modes[model.count++] = GarbageMode{1.0f / 3, 1.0f / 3, 1.0f, kBlack};
  } else {
    left_r = rs, left_b = bs, left_s = sums;  // too few to be a surface of their own
  }
  // The first colour from the other off-screen samples; a further one from the samples the colours
  // before it leave, only when it holds a twentieth of the border: a second surface around the
  // screen (the dino's wall: 7 %), not the actor crossing the border (whose colours are many
  // and each small).
  for (int m = model.count; m < 3 && left_r.size() >= 16; ++m) {
    GarbageMode mode;
    mode.r = quantile(left_r, 0.5);
    mode.b = quantile(left_b, 0.5);
    // Spread of the surroundings' chroma (robust: 80th percentile of the distance to the
    // median), 0.05 to 0.08: 8-bit quantisation of a dark neutral moves r, b by ~0.01, noise by
    // more; the costume's dark blue trousers in shadow sit ~0.11 from the studio's grey.
    std::vector<float> dist(left_r.size());
    for (size_t i = 0; i < left_r.size(); ++i)
      dist[i] = std::max(std::abs(left_r[i] - mode.r), std::abs(left_b[i] - mode.b));
    mode.tolerance = std::clamp(1.5f * quantile(dist, 0.8), 0.05f, 0.08f);
    // Brightest accepted: 1.5x the 95th percentile of the samples that match the chroma (the
    // studio's floor is brighter than its drapes and may barely reach the border; the
    // greenish-grey costume in shadow is ~3x the drapes' brightness).
    std::vector<float> matching, next_r, next_b, next_s;
    for (size_t i = 0; i < left_r.size(); ++i) {
      if (dist[i] <= mode.tolerance) {
        matching.push_back(left_s[i]);
      } else {
        next_r.push_back(left_r[i]);
        next_b.push_back(left_b[i]);
        next_s.push_back(left_s[i]);
      }
    }
    if (matching.size() < 16 || (m > 0 && matching.size() < border_samples / 20)) break;
    mode.max_sum = 1.5f * quantile(matching, 0.95);
    model.modes[model.count++] = mode;
    left_r.swap(next_r);
    left_b.swap(next_b);
    left_s.swap(next_s);
  }
  model.valid = model.count > 0;
  return model;
}

struct ClassifyParams {
  const ClassifyTables* tables = nullptr;
  const ScreenModel* screen = nullptr;
  bool use_plate = false;
  bool use_garbage_model = false;
  int plate_tolerance = 10;
  const cv::Mat* memory = nullptr;  // garbage zone of earlier frames (no plate), or null
};

// 2: the surroundings' colour; 1: near it (twice the chroma tolerance, 1.5x the brightness: a
// defocused edge of the actor over the surroundings, a noisy pixel), which must not be taken for
// clear foreground; 0: neither.
int garbageLikeness(const GarbageModel& gm, float r, float g, float b) {
  const float s = r + g + b;
  int likeness = 0;
  for (int m = 0; m < gm.count; ++m) {
    const GarbageMode& mode = gm.modes[m];
    const float dr = std::abs(r - mode.r * s), db = std::abs(b - mode.b * s);
    if (s <= mode.max_sum && dr <= mode.tolerance * s && db <= mode.tolerance * s) return 2;
    if (s <= 1.5f * mode.max_sum && dr <= 2.0f * mode.tolerance * s && db <= 2.0f * mode.tolerance * s) likeness = 1;
  }
  return likeness;
}

// Calls gap(y, x0, x1) for every run [x0, x1) of row y (within W) that no rect of 'rects'
// (disjoint) covers ('spans' is scratch).
template <class Gap>
void rowGaps(int y, int W, const std::vector<cv::Rect>& rects, std::vector<std::pair<int, int>>& spans, Gap&& gap) {
  spans.clear();
  for (const cv::Rect& r : rects)
    if (y >= r.y && y < r.br().y) spans.emplace_back(r.x, r.br().x);
  std::sort(spans.begin(), spans.end());
  int x = 0;
  for (const auto& [x0, x1] : spans) {
    if (x0 > x) gap(y, x, x0);
    x = std::max(x, x1);
  }
  if (x < W) gap(y, x, W);
}
// The same for every row of the W x H image.
template <class Gap>
void forEachGap(int W, int H, const std::vector<cv::Rect>& rects, Gap&& gap) {
  std::vector<std::pair<int, int>> spans;
  for (int y = 0; y < H; ++y) rowGaps(y, W, rects, spans, gap);
}

// Sets every pixel of m outside the rects (disjoint, within m) to 0.
void zeroOutside(cv::Mat& m, const std::vector<cv::Rect>& rects) {
  const size_t px = m.elemSize();
  forEachGap(m.cols, m.rows, rects, [&](int y, int x0, int x1) {
    std::memset(m.ptr<std::uint8_t>(y) + px * x0, 0, px * static_cast<size_t>(x1 - x0));
  });
}

// Boxes grown by 'margin', clipped to 'whole', and merged until no two overlap (a merged box
// is the bounding box of the two, which may overlap a third).
std::vector<cv::Rect> growAndMerge(const std::vector<cv::Rect>& boxes, int margin, const cv::Rect& whole) {
  std::vector<cv::Rect> out;
  for (const cv::Rect& b : boxes) {
    const cv::Rect g = cv::Rect(b.x - margin, b.y - margin, b.width + 2 * margin, b.height + 2 * margin) & whole;
    if (!g.empty()) out.push_back(g);
  }
  for (bool merged = true; merged;) {
    merged = false;
    for (size_t i = 0; i < out.size() && !merged; ++i)
      for (size_t j = i + 1; j < out.size(); ++j)
        if (!(out[i] & out[j]).empty()) {
          out[i] |= out[j];
          out.erase(out.begin() + static_cast<std::ptrdiff_t>(j));
          merged = true;
          break;
        }
  }
  // Top to bottom, left to right: the keying order, whatever order the parts were found in.
  std::sort(out.begin(), out.end(), [](const cv::Rect& a, const cv::Rect& b) {
    return a.y != b.y ? a.y < b.y : a.x < b.x;
  });
  return out;
}

// Screen test of one row, 16 pixels per step: kScreen where the chroma and the green's range say
// screen, kUnknown elsewhere (decided by the scalar pass). range: per-pixel (min, max) green
// (plate) or null (min = tables.min_green8, no max).
PREVIZ_WIDE
void screenRow(const std::uint8_t* px, const std::uint8_t* range, const ClassifyTables& t, int W,
               std::uint8_t* c) {
  int x = 0;
#if CV_SIMD128
  const cv::v_uint16x8 vk = cv::v_setall_u16(static_cast<std::uint16_t>(t.screen_k));
  const cv::v_uint16x8 vc = cv::v_setall_u16(static_cast<std::uint16_t>(t.screen_c));
  const cv::v_uint8x16 vmin = cv::v_setall_u8(static_cast<std::uint8_t>(std::min(255, t.min_green8)));
  const cv::v_uint8x16 screen = cv::v_setall_u8(kScreen), unknown = cv::v_setall_u8(kUnknown);
  for (; x + 16 <= W; x += 16) {
    cv::v_uint8x16 b, g, r;
    cv::v_load_deinterleave(px + 3 * x, b, g, r);
    const cv::v_uint8x16 m = cv::v_max(r, b);
    cv::v_uint16x8 m0, m1, g0, g1;
    cv::v_expand(m, m0, m1);
    cv::v_expand(g, g0, g1);
    const cv::v_uint16x8 ok0 = cv::v_add_wrap(cv::v_shl<7>(m0), vc) <= cv::v_mul_wrap(g0, vk);
    const cv::v_uint16x8 ok1 = cv::v_add_wrap(cv::v_shl<7>(m1), vc) <= cv::v_mul_wrap(g1, vk);
    cv::v_uint8x16 ok = cv::v_pack(ok0, ok1);
    if (range != nullptr) {
      cv::v_uint8x16 lo, hi;
      cv::v_load_deinterleave(range + 2 * x, lo, hi);
      ok = ok & (g >= lo) & (g <= hi);
    } else {
      ok = ok & (g >= vmin);
    }
    cv::v_store(c + x, cv::v_select(ok, screen, unknown));
  }
#endif
  for (; x < W; ++x) {
    const int b8 = px[3 * x], g8 = px[3 * x + 1], r8 = px[3 * x + 2];
    const int lo = range != nullptr ? range[2 * x] : t.min_green8;
    const int hi = range != nullptr ? range[2 * x + 1] : 255;
    c[x] = t.screenChroma(std::max(r8, b8), g8) && g8 >= lo && g8 <= hi ? kScreen : kUnknown;
  }
}

// First pass over rows [y0, y1): pixel classes. Garbage-like pixels remembered from earlier
// frames are garbage at once; those touching the remembered zone seed the flood.
PREVIZ_WIDE
void classifyRows(const cv::Mat& bgr8, const ClassifyParams& p, int y0, int y1, cv::Mat& cls,
                  std::vector<cv::Point>& seeds) {
  const auto& lut = srgb8ToLinear();
  const ClassifyTables& t = *p.tables;
  const ScreenModel& sm = *p.screen;
  const int W = bgr8.cols, H = bgr8.rows;
  for (int y = y0; y < y1; ++y) {
    const std::uint8_t* px = bgr8.ptr<std::uint8_t>(y);
    std::uint8_t* c = cls.ptr<std::uint8_t>(y);
    const std::uint8_t* range = p.use_plate ? sm.plate_green_range.ptr<std::uint8_t>(y) : nullptr;
    const std::uint8_t* plate = p.use_plate ? sm.plate.ptr<std::uint8_t>(y) : nullptr;
    const std::uint8_t* mem = p.memory != nullptr ? p.memory->ptr<std::uint8_t>(y) : nullptr;
    const std::uint8_t* mem_up = p.memory != nullptr ? p.memory->ptr<std::uint8_t>(std::max(0, y - 1)) : nullptr;
    const std::uint8_t* mem_down =
        p.memory != nullptr ? p.memory->ptr<std::uint8_t>(std::min(H - 1, y + 1)) : nullptr;
    screenRow(px, range, t, W, c);
    for (int x = 0; x < W; ++x) {
      if (x + 8 <= W && allBackground8(c + x)) {
        x += 7;
        continue;
      }
      if (c[x] == kScreen) continue;
      const int b8 = px[3 * x], g8 = px[3 * x + 1], r8 = px[3 * x + 2];
      if (range != nullptr && range[2 * x] > range[2 * x + 1]) {
        // Garbage zone: difference against the plate.
        const int d = std::max({std::abs(b8 - plate[3 * x]), std::abs(g8 - plate[3 * x + 1]),
                                std::abs(r8 - plate[3 * x + 2])});
        c[x] = d <= p.plate_tolerance ? kGarbage : d >= 2 * p.plate_tolerance ? kFg : kUnknown;
        continue;
      }
      int likeness = p.use_garbage_model ? garbageLikeness(sm.garbage, lut[r8], lut[g8], lut[b8]) : 0;
      if (likeness == 1) {
        // Near the surroundings' colour: sensor noise on dark drapes throws a fifth of their
        // pixels out of the colour's tolerance (a dark pixel's chroma is noisy). Their 3 x 3
        // mean (a third of the noise) says whether they are the surroundings; an actor's edge
        // over them mixes its own colour in and stays unknown, for the two-colour alpha.
        float mr = 0, mg = 0, mb = 0;
        int n = 0;
        for (int yy = std::max(0, y - 1); yy <= std::min(H - 1, y + 1); ++yy) {
          const std::uint8_t* q = bgr8.ptr<std::uint8_t>(yy);
          for (int xx = std::max(0, x - 1); xx <= std::min(W - 1, x + 1); ++xx) {
            mb += lut[q[3 * xx]];
            mg += lut[q[3 * xx + 1]];
            mr += lut[q[3 * xx + 2]];
            ++n;
          }
        }
        if (garbageLikeness(sm.garbage, mr / n, mg / n, mb / n) != 2) {
          c[x] = kUnknown;
          continue;
        }
        likeness = 2;
      }
      if (likeness == 2) {
        if (mem != nullptr && mem[x]) {
          c[x] = kGarbage;
        } else {
          c[x] = kGarbageLike;
          if (mem != nullptr && ((x > 0 && mem[x - 1]) || (x + 1 < W && mem[x + 1]) || mem_up[x] || mem_down[x])) {
            seeds.emplace_back(x, y);
          }
        }
        continue;
      }
      c[x] = std::max(r8, b8) >= t.fg_min_m[g8] ? kFg : kUnknown;
    }
  }
}

// The garbage zone (no plate): garbage-like pixels connected (8-neighbours, through garbage-like
// pixels) to the image border or to the zone remembered from earlier frames are garbage; the
// others stay foreground (dark neutral parts of the actor or prop, e.g. tag ink, separated from
// the surroundings by the crate's white margin). The memory covers what a single frame cannot
// tell: the surroundings showing through a gap enclosed by the actor (between the raised arm and
// the head) are reached in frames where the actor stands elsewhere.
// Scan-line flood fill: work proportional to the pixels it turns, one stack of row spans.
PREVIZ_WIDE
void floodGarbage(cv::Mat& cls, std::vector<cv::Point>& stack) {
  const int W = cls.cols, H = cls.rows;
  auto seed = [&](int x, int y) {
    if (cls.at<std::uint8_t>(y, x) == kGarbageLike) stack.emplace_back(x, y);
  };
  for (int x = 0; x < W; ++x) {
    seed(x, 0);
    seed(x, H - 1);
  }
  for (int y = 0; y < H; ++y) {
    seed(0, y);
    seed(W - 1, y);
  }
  while (!stack.empty()) {
    const cv::Point s = stack.back();
    stack.pop_back();
    std::uint8_t* row = cls.ptr<std::uint8_t>(s.y);
    if (row[s.x] != kGarbageLike) continue;
    int left = s.x, right = s.x;
    while (left > 0 && row[left - 1] == kGarbageLike) --left;
    while (right + 1 < W && row[right + 1] == kGarbageLike) ++right;
    std::memset(row + left, kGarbage, static_cast<size_t>(right - left + 1));
    // Runs of the rows above and below touching [left - 1, right + 1] (8-connectivity): one
    // seed per run.
    const int x0 = std::max(0, left - 1), x1 = std::min(W - 1, right + 1);
    for (int dy = -1; dy <= 1; dy += 2) {
      const int y = s.y + dy;
      if (y < 0 || y >= H) continue;
      const std::uint8_t* next = cls.ptr<std::uint8_t>(y);
      for (int x = x0; x <= x1; ++x) {
        if (next[x] == kGarbageLike && (x == x0 || next[x - 1] != kGarbageLike)) stack.emplace_back(x, y);
      }
    }
  }
}

// Lone unknown pixels of rows [y0, y1) (2 px or more inside the image): an unknown pixel whose 8
// neighbours are background, or whose 3 x 3 neighbourhood holds only background and unknown
// pixels and whose ring at distance 2 only background (a cluster of at most 9 unknown pixels
// with background all round), is sensor noise on the screen or the surroundings (foreground that
// small would be a speck, which the silhouette's cleaning removes). Such pixels become background
// (garbage when the window holds garbage, else screen), so that neither they nor their
// neighbours are refined. Read-only on the classes (bands run in parallel); the caller applies
// 'out' afterwards.
PREVIZ_WIDE
void findLoneUnknown(const cv::Mat& cls, int y0, int y1, std::vector<detail::LonePixel>& out) {
  const int W = cls.cols, H = cls.rows;
  out.clear();
  for (int y = std::max(2, y0); y < std::min(H - 2, y1); ++y) {
    const std::uint8_t* row[5];
    for (int k = 0; k < 5; ++k) row[k] = cls.ptr<std::uint8_t>(y - 2 + k);
    const std::uint8_t* c = row[2];
    for (int x = 2; x + 2 < W; ++x) {
      if (x + 8 <= W && !anyUnknown8(c + x)) {
        x += 7;
        continue;
      }
      if (c[x] != kUnknown) continue;
      // Alone: the 8 neighbours are background. In a small cluster: the 3 x 3 holds no
      // foreground and the ring at distance 2 only background.
      bool alone = true, cluster = true, garbage = false, garbage_near = false;
      for (int dy = -2; dy <= 2 && (alone || cluster); ++dy) {
        const std::uint8_t* r = row[dy + 2];
        for (int dx = -2; dx <= 2; ++dx) {
          if (dx == 0 && dy == 0) continue;
          const bool inner = std::abs(dx) <= 1 && std::abs(dy) <= 1;
          const std::uint8_t k = r[x + dx];
          if (inner) {
            alone &= k <= kGarbage;
            cluster &= k <= kUnknown;
            garbage_near |= k == kGarbage;
          } else {
            cluster &= k <= kGarbage;
          }
          garbage |= k == kGarbage;
        }
      }
      if (alone) {
        out.push_back({x, y, garbage_near ? kGarbage : kScreen});
      } else if (cluster) {
        out.push_back({x, y, garbage ? kGarbage : kScreen});
      }
    }
  }
}

// ---- Difference keying (no screen) ----

// Sensor noise of an image (grey levels): the median absolute second difference along rows of
// each channel on a sparse grid, scaled to the sigma of Gaussian noise (a second difference of
// white noise has sigma * sqrt(6); median |x| = 0.6745 sigma). Texture adds to it a little, which
// only widens the tolerance.
float estimateNoise(const cv::Mat& bgr8) {
  std::vector<int> d;
  d.reserve(static_cast<size_t>(bgr8.rows / 4 + 1) * (bgr8.cols / 4 + 1) * 3);
  for (int y = 2; y < bgr8.rows; y += 4) {
    const std::uint8_t* p = bgr8.ptr<std::uint8_t>(y);
    for (int x = 1; x + 1 < bgr8.cols; x += 4)
      for (int c = 0; c < 3; ++c) {
        const int v = p[3 * x + c];
        if (v < 4 || v > 251) continue;  // clipped: no noise to see
        d.push_back(std::abs(p[3 * (x - 1) + c] - 2 * v + p[3 * (x + 1) + c]));
      }
  }
  if (d.empty()) return 0.0f;
  std::nth_element(d.begin(), d.begin() + d.size() / 2, d.end());
  return static_cast<float>(d[d.size() / 2] / (0.6745 * std::sqrt(6.0)));
}

cv::Vec3f plateMeanColour(const cv::Mat& bgr8) {
  const auto& lut = srgb8ToLinear();
  double sum[3] = {0, 0, 0};
  for (int y = 0; y < bgr8.rows; ++y) {
    const std::uint8_t* p = bgr8.ptr<std::uint8_t>(y);
    for (int x = 0; x < bgr8.cols; ++x)
      for (int c = 0; c < 3; ++c) sum[c] += lut[p[3 * x + c]];
  }
  const double n = std::max(1.0, static_cast<double>(bgr8.total()));
  return cv::Vec3f(static_cast<float>(sum[0] / n), static_cast<float>(sum[1] / n), static_cast<float>(sum[2] / n));
}

// One frame's constants of the difference pass.
struct DifferenceFrame {
  float gain = 1;                             // the frame's exposure relative to the plate
  std::array<std::uint8_t, 256> expected{};   // plate code -> its code at the frame's exposure
  std::array<float, 256> expected_linear{};   // the same, linear
  int tolerance = 0;                          // levels: equal to the plate within noise
  float sigma_frame = 0, sigma_plate = 0;     // estimated sensor noise, grey levels
  float min_shadow = 0.4f;
  float hue_levels = 3;                       // KeyerOptions::shadow_hue_levels
};

DifferenceFrame differenceFrame(const cv::Mat& bgr8, const ScreenModel& sm, const KeyerOptions& o) {
  const auto& lut = srgb8ToLinear();
  // Exposure: median of frame / plate brightness on a sparse grid, over pixels bright enough for
  // the ratio to mean something. The actor, its shadows and the noise are a minority.
  std::vector<float> ratios;
  ratios.reserve(static_cast<size_t>(bgr8.rows / 6 + 1) * (bgr8.cols / 6 + 1));
  for (int y = 3; y < bgr8.rows; y += 6) {
    const std::uint8_t* f = bgr8.ptr<std::uint8_t>(y);
    const std::uint8_t* p = sm.plate.ptr<std::uint8_t>(y);
    for (int x = 3; x < bgr8.cols; x += 6) {
      const float sp = lut[p[3 * x]] + lut[p[3 * x + 1]] + lut[p[3 * x + 2]];
      if (sp < 0.05f || std::max({p[3 * x], p[3 * x + 1], p[3 * x + 2]}) > 250) continue;
      ratios.push_back((lut[f[3 * x]] + lut[f[3 * x + 1]] + lut[f[3 * x + 2]]) / sp);
    }
  }
  DifferenceFrame d;
  if (!ratios.empty()) {
    std::nth_element(ratios.begin(), ratios.begin() + ratios.size() / 2, ratios.end());
    d.gain = ratios[ratios.size() / 2];
  }
  for (int v = 0; v < 256; ++v) {
    d.expected_linear[static_cast<size_t>(v)] = std::min(1.0f, d.gain * lut[static_cast<size_t>(v)]);
    d.expected[static_cast<size_t>(v)] = linearToSrgb8(d.expected_linear[static_cast<size_t>(v)]);
  }
  // The difference of two noisy images: 4 sigma of it, plus a level of quantisation, at least
  // plate_tolerance / 3 (a noise-free render still has anti-aliasing and encoder rounding).
  const float sigma_frame = estimateNoise(bgr8);
  const float sigma = std::sqrt(sigma_frame * sigma_frame + sm.plate_noise * sm.plate_noise);
  d.tolerance = std::max(o.plate_tolerance / 3, static_cast<int>(std::ceil(3.0f * sigma + 1.0f)));
  d.sigma_frame = sigma_frame;
  d.sigma_plate = sm.plate_noise;
  d.min_shadow = static_cast<float>(o.min_shadow);
  d.hue_levels = static_cast<float>(o.shadow_hue_levels);
  return d;
}

// Pass 1 of difference keying over rows [y0, y1): kScreen (the plate), kShadowCandidate (the
// plate darkened, to one pixel's noise), kFg, kUnknown. A candidate's residual to the darkened
// plate (frame - s plate, sRGB levels per channel, within one pixel's noise so a few levels) and
// a 1 go to 'residual' (CV_8SC4; 0 elsewhere).
void differenceRows(const cv::Mat& bgr8, const cv::Mat& plate, const DifferenceFrame& d, int y0, int y1,
                    cv::Mat& cls, cv::Mat& residual) {
  const auto& lut = srgb8ToLinear();
  const int W = bgr8.cols, tol = d.tolerance;
  for (int y = y0; y < y1; ++y) {
    const std::uint8_t* f = bgr8.ptr<std::uint8_t>(y);
    const std::uint8_t* p = plate.ptr<std::uint8_t>(y);
    std::uint8_t* c = cls.ptr<std::uint8_t>(y);
    std::int8_t* res = residual.ptr<std::int8_t>(y);
    std::memset(res, 0, 4 * static_cast<size_t>(W));
    for (int x = 0; x < W; ++x) {
      const std::uint8_t* fx = f + 3 * x;
      const std::uint8_t* px = p + 3 * x;
      int diff = 0;
      for (int k = 0; k < 3; ++k) diff = std::max(diff, std::abs(fx[k] - d.expected[px[k]]));
      if (diff <= tol) {
        c[x] = kScreen;
        continue;
      }
      // A shadow: the plate's colour darkened by one factor s (the least-squares one, in linear
      // light), within 3 sigma of the noise on every channel (the plate's noise darkened too):
      // tighter than the plain difference, as a dark costume of the floor's hue is also a
      // darkened plate, only darker than the lights' deepest shadow or off by its hue.
      const float e0 = d.expected_linear[px[0]], e1 = d.expected_linear[px[1]], e2 = d.expected_linear[px[2]];
      const float ee = e0 * e0 + e1 * e1 + e2 * e2;
      const float s = ee > 1e-8f ? (lut[fx[0]] * e0 + lut[fx[1]] * e1 + lut[fx[2]] * e2) / ee : 0.0f;
      if (s >= d.min_shadow && s <= 1.0f) {
        const int r0 = fx[0] - linearToSrgb8(s * e0), r1 = fx[1] - linearToSrgb8(s * e1),
                  r2 = fx[2] - linearToSrgb8(s * e2);
        const int ds = std::max({std::abs(r0), std::abs(r1), std::abs(r2)});
        const float sigma = std::sqrt(d.sigma_frame * d.sigma_frame + s * s * d.sigma_plate * d.sigma_plate);
        if (ds <= 3.0f * sigma + 1.0f) {
          c[x] = kShadowCandidate;
          res[4 * x] = static_cast<std::int8_t>(std::clamp(r0, -127, 127));
          res[4 * x + 1] = static_cast<std::int8_t>(std::clamp(r1, -127, 127));
          res[4 * x + 2] = static_cast<std::int8_t>(std::clamp(r2, -127, 127));
          res[4 * x + 3] = 1;
          continue;
        }
        diff = std::min(diff, ds);
      }
      c[x] = diff >= 2 * tol ? kFg : kUnknown;
    }
  }
}

// The shadow candidates of rows [y0, y1) decided by their neighbourhood: a shadow darkens the
// plate and keeps its hue, so the residuals of the candidates around a pixel (5 x 5) average to
// the noise's mean, 0, within 3 sigma / sqrt(n) and the hue a real shadow may take
// (shadow_hue_levels); a costume that only looks like the plate darkened (dark brown hair over a
// dark grey wall: 9 levels off in blue, within one pixel's noise) is off the same way at every
// pixel. residual: differenceRows' (read only, so bands may run in parallel). Candidates that
// fail become kUnknown (the two-colour alpha decides them). Returns the shadows kept.
PREVIZ_WIDE
int shadowNeighbourhood(const cv::Mat& residual, const DifferenceFrame& d, int y0, int y1, cv::Mat& cls) {
  int shadows = 0;
  const float sigma = std::sqrt(d.sigma_frame * d.sigma_frame + d.sigma_plate * d.sigma_plate);
  const int H = cls.rows, W = cls.cols;
  for (int y = y0; y < y1; ++y) {
    std::uint8_t* c = cls.ptr<std::uint8_t>(y);
    const int ya = std::max(0, y - 2), yb = std::min(H - 1, y + 2);
    // Column x's residuals over the window's rows, added with the sign given.
    auto addColumn = [&](int xx, int sign, int* sum) {
      if (xx < 0 || xx >= W) return;
      for (int yy = ya; yy <= yb; ++yy) {
        const std::int8_t* r = residual.ptr<std::int8_t>(yy) + 4 * xx;
        for (int k = 0; k < 4; ++k) sum[k] += sign * r[k];
      }
    };
    int sum[4] = {0, 0, 0, 0};  // the window's residuals, then its candidates' count
    int window_x = -10;         // the x the sums are for
    for (int x = 0; x < W; ++x) {
      if (c[x] != kShadowCandidate) continue;
      if (window_x == x - 1) {  // slide along a run of candidates
        addColumn(x - 3, -1, sum);
        addColumn(x + 2, 1, sum);
      } else {
        std::fill(sum, sum + 4, 0);
        for (int xx = x - 2; xx <= x + 2; ++xx) addColumn(xx, 1, sum);
      }
      window_x = x;
      const float count = static_cast<float>(sum[3]);
      const float limit = (3.0f * sigma / std::sqrt(count) + d.hue_levels) * count;
      const bool shadow = std::abs(sum[0]) <= limit && std::abs(sum[1]) <= limit && std::abs(sum[2]) <= limit;
      c[x] = shadow ? kScreen : kUnknown;
      shadows += shadow;
    }
  }
  return shadows;
}

// F's candidates: aligned foreground neighbours at least this fraction of the purest one's
// distance from B. Measured on 24 studio keys against the exact 4-sample coverage, sensor noise
// 2, no plate, against the purest alone: alpha on mixed pixels RMS error 0.093 -> 0.089, bias
// -0.024 -> -0.009; silhouette pixels wrong 3041 -> 2775. 0.7 removes the bias, but its F takes
// in mixed neighbours, and the despilled main plate keeps screen green on 2 % of its edge.
constexpr float kPureReach = 0.8f;

struct Rgb {
  float b, g, r;
};

// The two-colour alpha's window, one row of up to 8 pixels per vector lane (2 * 3 + 1 = 7 at
// the largest radius). GCC's vector extensions: the AVX2 clone and the baseline one compute the
// same lanes with the same operations, so their bytes agree (the live.wide test compares them).
#pragma GCC diagnostic ignored "-Wpsabi"  // the helpers below are inlined: no vector crosses a call
typedef float WinF __attribute__((vector_size(32)));
typedef std::int32_t WinI __attribute__((vector_size(32)));
typedef std::uint8_t WinI8 __attribute__((vector_size(8)));
constexpr int kWinLanes = 8;
constexpr int kMaxWinRows = 7;  // 2 * 3 + 1: KeyerOptions::edge_radius_px is at most 3

// Lanes summed in a fixed order (the same in every clone).
[[gnu::always_inline]] inline float laneSum(WinF v) {
  typedef float F4 __attribute__((vector_size(16)));
  const F4 h = __builtin_shufflevector(v, v, 0, 1, 2, 3) + __builtin_shufflevector(v, v, 4, 5, 6, 7);
  return (h[0] + h[1]) + (h[2] + h[3]);
}
[[gnu::always_inline]] inline int laneSum(WinI v) {
  int n = 0;
  for (int i = 0; i < kWinLanes; ++i) n += v[i];
  return n;
}
[[gnu::always_inline]] inline WinI8 loadBytes8(const std::uint8_t* p) {
  WinI8 v;
  std::memcpy(&v, p, sizeof v);
  return v;
}
[[gnu::always_inline]] inline WinF pick(WinI mask, WinF a, WinF b) { return mask ? a : b; }

// A window row's colours in linear light (p: its B, G, R bytes), lane i = pixel i; lanes past
// the window (in_window false) are 0. 'whole': eight pixels can be read, and the vectors are
// built in registers (lanes stored one by one and read back as a vector stall the load: the key
// was 1.3-1.4x slower that way); else only the window's pixels are read, lane by lane.
[[gnu::always_inline]] inline void linearRow(const std::uint8_t* p, const std::array<float, 256>& lut, bool whole,
                                             WinI in_window, WinF& b, WinF& g, WinF& r) {
  if (whole) {
    b = WinF{lut[p[0]], lut[p[3]], lut[p[6]], lut[p[9]], lut[p[12]], lut[p[15]], lut[p[18]], lut[p[21]]};
    g = WinF{lut[p[1]], lut[p[4]], lut[p[7]], lut[p[10]], lut[p[13]], lut[p[16]], lut[p[19]], lut[p[22]]};
    r = WinF{lut[p[2]], lut[p[5]], lut[p[8]], lut[p[11]], lut[p[14]], lut[p[17]], lut[p[20]], lut[p[23]]};
    b = pick(in_window, b, WinF{}), g = pick(in_window, g, WinF{}), r = pick(in_window, r, WinF{});
    return;
  }
  b = g = r = WinF{};
  for (int j = 0; j < kWinLanes && in_window[j]; ++j) b[j] = lut[p[3 * j]], g[j] = lut[p[3 * j + 1]], r[j] = lut[p[3 * j + 2]];
}

// Two-colour alpha of pixel (x, y) from its window: B = local background, F = the mean of the
// foreground neighbours whose lines to B pass closest to the pixel's colour and that are nearly
// the purest of those (at least kPureReach of the farthest one's distance from B). Returns -1
// when the window has no background (interior: alpha 1) and -2 when it has no foreground to mix
// with (alpha 0).
// The window is read into vectors, a window row per vector, and every sum and choice below is
// made on whole rows (masks for the classes) instead of pixel by pixel: a quarter fewer samples
// than the pixel loop it replaced (the keyer's largest cost) and the same decisions. Sums are
// added lane by lane, so they may round differently in the last bit (no output moved).
PREVIZ_WIDE
float edgeAlpha(const cv::Mat& bgr8, const cv::Mat& cls, const ScreenModel& sm, bool use_plate,
                int x, int y, int radius) {
  const auto& lut = srgb8ToLinear();
  const int x0 = std::max(0, x - radius), x1 = std::min(bgr8.cols - 1, x + radius);
  const int y0 = std::max(0, y - radius), y1 = std::min(bgr8.rows - 1, y + radius);
  // Interior first, on the classes alone: no background in the window but the pixel itself
  // (a background pixel being refined is not its own B). Most refined pixels of a noisy plate
  // are unknown pixels inside a dark costume part; reading their window's colours is the cost.
  bool any_bg = false;
  if (__BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__ && 2 * radius + 1 <= 8 && x - radius >= 0 &&
      x - radius + 8 <= cls.cols) {
    // A window row's classes as one word (byte i = pixel x - radius + i), the bytes past the
    // window and the pixel itself made non-background; background is a byte <= 1, a zero byte
    // once the low bit is masked, found by the zero-byte test (exact, no false hits).
    const int width = 2 * radius + 1;
    const std::uint64_t outside = width == 8 ? 0 : ~0ull << (8 * width);
    for (int yy = y0; yy <= y1 && !any_bg; ++yy) {
      std::uint64_t v;
      std::memcpy(&v, cls.ptr<std::uint8_t>(yy) + (x - radius), 8);
      if (yy == y) v |= 0xFFull << (8 * radius);
      v = (v & 0xFEFEFEFEFEFEFEFEull) | outside;
      any_bg = ((v - 0x0101010101010101ull) & ~v & 0x8080808080808080ull) != 0;
    }
  } else {
    for (int yy = y0; yy <= y1 && !any_bg; ++yy) {
      const std::uint8_t* c = cls.ptr<std::uint8_t>(yy);
      for (int xx = x0; xx <= x1; ++xx) any_bg |= c[xx] <= kGarbage && (xx != x || yy != y);
    }
  }
  if (!any_bg) return -1.0f;
  // The window's colours in linear light and its classes, lane i = pixel x0 + i; lanes past the
  // window hold class -1 (none) and colour 0. The pixel itself is not background (a background
  // pixel being refined is not its own B) but is a candidate for F like its neighbours.
  const int rows = y1 - y0 + 1, width = x1 - x0 + 1;
  WinF wb[kMaxWinRows], wg[kMaxWinRows], wr[kMaxWinRows];
  WinI fg[kMaxWinRows], unknown[kMaxWinRows];
  WinF sum_sb{}, sum_sg{}, sum_sr{}, sum_gb{}, sum_gg{}, sum_gr{}, sum_pb{}, sum_pg{}, sum_pr{};
  WinI n_screen_v{}, n_garbage_v{}, any_fg_v{};
  const WinI lane{0, 1, 2, 3, 4, 5, 6, 7};
  const WinI in_window = lane < width;
  const bool whole_rows = x0 + kWinLanes <= cls.cols;  // eight pixels can be read from x0
  for (int i = 0; i < rows; ++i) {
    const int yy = y0 + i;
    const std::uint8_t* c = cls.ptr<std::uint8_t>(yy) + x0;
    const std::uint8_t* p = bgr8.ptr<std::uint8_t>(yy) + 3 * x0;
    WinI k;
    if (whole_rows) {
      k = __builtin_convertvector(loadBytes8(c), WinI);
      k = in_window ? k : -1;
    } else {
      for (int j = 0; j < kWinLanes; ++j) k[j] = j < width ? c[j] : -1;
    }
    WinF b, g, r;
    linearRow(p, lut, whole_rows, in_window, b, g, r);
    const WinI itself = yy == y ? lane == x - x0 : WinI{};
    const WinI is_screen = (k == kScreen) & ~itself, is_garbage = (k == kGarbage) & ~itself;
    const WinI is_fg = k > kUnknown, is_unknown = k == kUnknown;
    wb[i] = b, wg[i] = g, wr[i] = r;
    fg[i] = is_fg, unknown[i] = is_unknown;
    sum_sb += pick(is_screen, b, WinF{}), sum_sg += pick(is_screen, g, WinF{}), sum_sr += pick(is_screen, r, WinF{});
    sum_gb += pick(is_garbage, b, WinF{}), sum_gg += pick(is_garbage, g, WinF{}), sum_gr += pick(is_garbage, r, WinF{});
    n_screen_v -= is_screen;
    n_garbage_v -= is_garbage;
    any_fg_v |= is_fg;
    if (use_plate) {
      // Only background lanes are summed.
      WinF pb, pg, pr;
      linearRow(sm.plate.ptr<std::uint8_t>(yy) + 3 * x0, lut, whole_rows, in_window, pb, pg, pr);
      const WinI bg = is_screen | is_garbage;
      sum_pb += pick(bg, pb, WinF{}), sum_pg += pick(bg, pg, WinF{}), sum_pr += pick(bg, pr, WinF{});
    }
  }
  const int n_screen = laneSum(n_screen_v), n_garbage = laneSum(n_garbage_v);
  const int n_bg = n_screen + n_garbage;
  if (n_bg == 0) return -1.0f;
  const Rgb sum_screen{laneSum(sum_sb), laneSum(sum_sg), laneSum(sum_sr)};
  const Rgb sum_garbage{laneSum(sum_gb), laneSum(sum_gg), laneSum(sum_gr)};
  auto colour = [&](const cv::Mat& img, int xx, int yy) {
    const std::uint8_t* p = img.ptr<std::uint8_t>(yy) + 3 * xx;
    return Rgb{lut[p[0]], lut[p[1]], lut[p[2]]};
  };
  const Rgb c = colour(bgr8, x, y);
  Rgb bg{};
  if (use_plate) {
    // The plate's own colour here, darkened by the neighbours' shadow factor.
    const Rgb sum_plate{laneSum(sum_pb), laneSum(sum_pg), laneSum(sum_pr)};
    const float shadow = (sum_screen.b + sum_screen.g + sum_screen.r + sum_garbage.b +
                          sum_garbage.g + sum_garbage.r) /
                         std::max(sum_plate.b + sum_plate.g + sum_plate.r, 1e-6f);
    const Rgb here = colour(sm.plate, x, y);
    bg = {here.b * shadow, here.g * shadow, here.r * shadow};
  } else if (n_screen > 0 && n_garbage > 0) {
    // On the screen's rim: the background is a mix of screen and surroundings. Take the point of
    // the segment between their means nearest to the pixel; a pixel on that segment is rim.
    const Rgb s{sum_screen.b / n_screen, sum_screen.g / n_screen, sum_screen.r / n_screen};
    const Rgb g{sum_garbage.b / n_garbage, sum_garbage.g / n_garbage, sum_garbage.r / n_garbage};
    const float db = g.b - s.b, dg = g.g - s.g, dr = g.r - s.r;
    const float dd = std::max(db * db + dg * dg + dr * dr, 1e-12f);
    const float t = std::clamp(((c.b - s.b) * db + (c.g - s.g) * dg + (c.r - s.r) * dr) / dd, 0.0f, 1.0f);
    bg = {s.b + t * db, s.g + t * dg, s.r + t * dr};
    const float eb = c.b - bg.b, eg = c.g - bg.g, er = c.r - bg.r;
    if (eb * eb + eg * eg + er * er <= 0.01f * dd) return -2.0f;
  } else {
    const Rgb& sum = n_screen > 0 ? sum_screen : sum_garbage;
    bg = {sum.b / n_bg, sum.g / n_bg, sum.r / n_bg};
  }
  // Candidates for F: the clear foreground, else the unknown (dark foreground in front of dark
  // surroundings differs from the plate or the surroundings' colour by little; a thin structure
  // has no pure pixel).
  bool any_fg = false;
  for (int j = 0; j < kWinLanes; ++j) any_fg |= any_fg_v[j] != 0;
  const WinI* cand = any_fg ? fg : unknown;
  float min_reach2 = 0.0f;
  if (!any_fg) {
    // An unknown neighbour counts only if it differs from B by more than noise does: 0.02 in
    // linear light (about 10 sigma of 2-level sensor noise on the dark surroundings) or 30 % of
    // B's own magnitude.
    const float floor = std::max(0.02f, 0.3f * std::sqrt(bg.b * bg.b + bg.g * bg.g + bg.r * bg.r));
    min_reach2 = floor * floor;
  }
  const float cb = c.b - bg.b, cg = c.g - bg.g, cr = c.r - bg.r;
  const float cc = cb * cb + cg * cg + cr * cr;
  const bool colour_off_b = cc > 1e-12f;  // else C is B: every candidate is on the line
  // Score every candidate: squared sine of the angle between C - B and F - B (0 = on the mixing
  // line; 4 = not a candidate: too near B, or not in the set).
  WinF sine2[kMaxWinRows], reach[kMaxWinRows];
  WinF best = WinF{} + 4.0f;
  for (int i = 0; i < rows; ++i) {
    const WinF db = wb[i] - bg.b, dg = wg[i] - bg.g, dr = wr[i] - bg.r;
    const WinF dd = db * db + dg * dg + dr * dr;
    const WinF dot = cb * db + cg * dg + cr * dr;
    const WinI ok = cand[i] & (dd >= 1e-10f) & (dd >= min_reach2);
    WinF s = WinF{};
    if (colour_off_b) {
      s = 1.0f - dot * dot / (dd * cc);
      s = pick(s > 0.0f, s, WinF{});
    }
    sine2[i] = pick(ok, s, WinF{} + 4.0f);
    reach[i] = dd;
    best = pick(sine2[i] < best, sine2[i], best);
  }
  float best_sine2 = best[0];
  for (int j = 1; j < kWinLanes; ++j) best_sine2 = std::min(best_sine2, best[j]);
  if (best_sine2 > 2.0f) return -2.0f;  // no candidate (a candidate's sine2 is at most 1)
  // Among the candidates nearly as well aligned as the best (sine within 0.1), the farthest
  // from B: a mixed neighbour lies on the same line but nearer, and would overstate alpha.
  const float tolerance = std::sqrt(best_sine2) + 0.1f;
  const float tolerance2 = tolerance * tolerance;
  WinF far = WinF{} - 1.0f;
  for (int i = 0; i < rows; ++i) far = pick((sine2[i] <= tolerance2) & (reach[i] > far), reach[i], far);
  float farthest = far[0];
  for (int j = 1; j < kWinLanes; ++j) farthest = std::max(farthest, far[j]);
  // F is the mean of the aligned candidates nearly as far as the farthest: the farthest alone
  // is the noisiest of them (the largest of several noisy distances), which understated alpha
  // under sensor noise, and a single pixel's noise went into alpha unaveraged.
  const float min_reach = kPureReach * kPureReach * farthest;
  WinF pure_b{}, pure_g{}, pure_r{};
  WinI n_pure_v{};
  for (int i = 0; i < rows; ++i) {
    const WinI pure = (sine2[i] <= tolerance2) & (reach[i] >= min_reach);
    pure_b += pick(pure, wb[i], WinF{}), pure_g += pick(pure, wg[i], WinF{}), pure_r += pick(pure, wr[i], WinF{});
    n_pure_v -= pure;
  }
  int n_pure = 0;
  for (int j = 0; j < kWinLanes; ++j) n_pure += n_pure_v[j];
  const float db = laneSum(pure_b) / n_pure - bg.b, dg = laneSum(pure_g) / n_pure - bg.g,
              dr = laneSum(pure_r) / n_pure - bg.r;
  const float dd = db * db + dg * dg + dr * dr;
  if (dd < 1e-10f) {
    // The farthest candidate's own projection (the first in scan order; a candidate is never
    // one too near B).
    for (int i = 0; i < rows; ++i) {
      for (int j = 0; j < kWinLanes; ++j) {
        if (sine2[i][j] > tolerance2 || reach[i][j] != farthest) continue;
        const float pb = wb[i][j] - bg.b, pg = wg[i][j] - bg.g, pr = wr[i][j] - bg.r;
        return std::clamp((cb * pb + cg * pg + cr * pr) / reach[i][j], 0.0f, 1.0f);
      }
    }
  }
  return std::clamp((cb * db + cg * dg + cr * dr) / dd, 0.0f, 1.0f);
}

// One row of pass 2's bulk: alpha / silhouette 0 on background and 255 elsewhere, need = 1 at a
// transition (unknown, or a 4-neighbour of another kind: background / unknown / foreground),
// memory |= garbage.
// Returns the row's garbage pixel count.
PREVIZ_WIDE
int markTransitions(const std::uint8_t* c, const std::uint8_t* up, const std::uint8_t* down, int W,
                    std::uint8_t* a, std::uint8_t* s, std::uint8_t* need, std::uint8_t* mem) {
  auto kind = [&](const std::uint8_t* row, int x) {
    return row[x] <= kGarbage ? 0 : row[x] == kUnknown ? 1 : 2;
  };
  auto scalar = [&](int x) {
    const int k = kind(c, x);
    a[x] = s[x] = k == 0 ? 0 : 255;
    need[x] = k == 1 || kind(up, x) != k || kind(down, x) != k || (x > 0 && kind(c, x - 1) != k) ||
              (x + 1 < W && kind(c, x + 1) != k);
    if (mem != nullptr) mem[x] |= static_cast<std::uint8_t>(c[x] == kGarbage);
    return c[x] == kGarbage ? 1 : 0;
  };
  int garbage = scalar(0);
  int x = 1;
#if CV_SIMD128
  const cv::v_uint8x16 one = cv::v_setall_u8(kGarbage), unknown = cv::v_setall_u8(kUnknown);
  const cv::v_uint8x16 ones = cv::v_setall_u8(1);
  for (; x + 17 <= W; x += 16) {
    const cv::v_uint8x16 vc = cv::v_load(c + x);
    const cv::v_uint8x16 bg = vc <= one, fg = vc > unknown;
    cv::v_uint8x16 t = vc == unknown;
    for (const std::uint8_t* n : {up + x, down + x, c + x - 1, c + x + 1}) {
      const cv::v_uint8x16 vn = cv::v_load(n);
      t = t | (bg ^ (vn <= one)) | (fg ^ (vn > unknown));
    }
    cv::v_store(a + x, ~bg);
    cv::v_store(s + x, ~bg);
    cv::v_store(need + x, t & ones);
    const cv::v_uint8x16 is_garbage = vc == one;
    garbage += __builtin_popcount(static_cast<unsigned>(cv::v_signmask(is_garbage)));
    if (mem != nullptr) cv::v_store(mem + x, cv::v_load(mem + x) | (is_garbage & ones));
  }
#endif
  for (; x < W; ++x) garbage += scalar(x);
  return garbage;
}

// Specks and holes by connected components of runs: each row of the silhouette is cut into
// runs of foreground and of background, runs are joined to the touching runs of the row above
// (foreground 8-connected, background 4-connected) with union-find, and the components' areas
// decide. An actor's silhouette has a few runs per row, so this costs about one scan of the
// image (most 8-byte words are all background and skipped) plus a few thousand unions, where
// pixel labelling costs a label per pixel of the box around actor and prop.
struct Run {
  int y, x0, x1;  // [x0, x1) on row y
  bool fg;
};

int findRoot(std::vector<int>& parent, int i) {
  while (parent[i] != i) {
    parent[i] = parent[parent[i]];
    i = parent[i];
  }
  return i;
}

PREVIZ_WIDE
void cleanSilhouette(cv::Mat& sil, cv::Mat& alpha8, const KeyerOptions& o, KeyStats& stats,
                     std::vector<cv::Rect>* parts) {
  if (o.min_blob_px <= 1 && o.min_hole_px <= 1 && parts == nullptr) return;
  const int W = sil.cols, H = sil.rows;
  std::vector<Run> runs;
  std::vector<int> row_start(H + 1, 0);
  for (int y = 0; y < H; ++y) {
    row_start[y] = static_cast<int>(runs.size());
    const std::uint8_t* s = sil.ptr<std::uint8_t>(y);
    int x = 0;
    while (x < W) {
      const bool fg = s[x] != 0;
      int end = x + 1;
      // Skip whole 8-byte words of the same value.
      const std::uint64_t same = fg ? ~0ull : 0ull;
      while (end + 8 <= W) {
        std::uint64_t word;
        std::memcpy(&word, s + end, 8);
        if (word != same) break;
        end += 8;
      }
      while (end < W && (s[end] != 0) == fg) ++end;
      runs.push_back({y, x, end, fg});
      x = end;
    }
  }
  row_start[H] = static_cast<int>(runs.size());
  const int n = static_cast<int>(runs.size());
  std::vector<int> parent(n);
  for (int i = 0; i < n; ++i) parent[i] = i;
  for (int y = 1; y < H; ++y) {
    int first = row_start[y];  // first run of row y that may still touch a run above
    for (int i = row_start[y - 1]; i < row_start[y]; ++i) {
      const Run& a = runs[i];
      while (first < row_start[y + 1] && runs[first].x1 + 1 <= a.x0) ++first;
      for (int j = first; j < row_start[y + 1] && runs[j].x0 < a.x1 + 1; ++j) {
        const Run& b = runs[j];
        // Foreground touches diagonally too (8-connectivity), background only edge to edge.
        const int slack = a.fg ? 1 : 0;
        if (a.fg != b.fg || !(a.x0 < b.x1 + slack && b.x0 < a.x1 + slack)) continue;
        const int ra = findRoot(parent, i), rb = findRoot(parent, j);
        if (ra != rb) parent[std::max(ra, rb)] = std::min(ra, rb);
      }
    }
  }
  // Areas and contact with the image border per component.
  std::vector<long long> area(n, 0);
  std::vector<std::uint8_t> outside(n, 0);
  for (int i = 0; i < n; ++i) {
    const Run& r = runs[i];
    const int root = findRoot(parent, i);
    area[root] += r.x1 - r.x0;
    if (r.y == 0 || r.y == H - 1 || r.x0 == 0 || r.x1 == W) outside[root] = 1;
  }
  std::vector<std::uint8_t> counted(n, 0);
  for (int i = 0; i < n; ++i) {
    const Run& r = runs[i];
    const int root = findRoot(parent, i);
    std::uint8_t value;
    if (r.fg && area[root] < o.min_blob_px) {
      value = 0;
      if (!counted[root]) ++stats.specks_removed;
    } else if (!r.fg && !outside[root] && area[root] < o.min_hole_px) {
      value = 255;
      if (!counted[root]) ++stats.holes_filled;
    } else {
      continue;
    }
    counted[root] = 1;
    std::memset(sil.ptr<std::uint8_t>(r.y) + r.x0, value, static_cast<size_t>(r.x1 - r.x0));
    std::memset(alpha8.ptr<std::uint8_t>(r.y) + r.x0, value, static_cast<size_t>(r.x1 - r.x0));
  }
  if (parts == nullptr) return;
  // The boxes of the foreground parts kept (a filled hole lies inside the part around it).
  std::vector<int> box_of(n, -1);
  parts->clear();
  for (int i = 0; i < n; ++i) {
    const Run& r = runs[i];
    const int root = findRoot(parent, i);
    if (!r.fg || area[root] < o.min_blob_px) continue;
    const cv::Rect run(r.x0, r.y, r.x1 - r.x0, 1);
    if (box_of[root] < 0) {
      box_of[root] = static_cast<int>(parts->size());
      parts->push_back(run);
    } else {
      (*parts)[static_cast<size_t>(box_of[root])] |= run;
    }
  }
}

}  // namespace

// One frame's constants, shared by the regions keyed in it (Keyer::key).
struct Keyer::Frame {
  const cv::Mat* bgr8 = nullptr;  // the whole frame, working order
  ClassifyTables tables;
  ClassifyParams params;          // whole-frame images (memory)
  bool difference = false;        // no screen: difference keying with 'diff'
  DifferenceFrame diff;
};

void KeyerOptions::validate() const {
  auto bad = [](const std::string& field, const std::string& what) {
    ErrorContext context;
    context.field = field;
    throw Error("keyer: " + field + " " + what, context);
  };
  if (!(silhouette_threshold > 0 && silhouette_threshold < 1)) {
    bad("silhouette_threshold", "must be in (0, 1) (got " + str(silhouette_threshold) + ")");
  }
  if (min_blob_px < 0) bad("min_blob_px", "must be >= 0 (got " + str(min_blob_px) + ")");
  if (min_hole_px < 0) bad("min_hole_px", "must be >= 0 (got " + str(min_hole_px) + ")");
  if (edge_radius_px < 1 || edge_radius_px > 3) {
    bad("edge_radius_px", "must be in [1, 3] (got " + str(edge_radius_px) + ")");
  }
  if (plate_tolerance < 1 || plate_tolerance > 80) {
    bad("plate_tolerance", "must be in [1, 80] (got " + str(plate_tolerance) + ")");
  }
  if (!(min_shadow > 0 && min_shadow < 1)) bad("min_shadow", "must be in (0, 1) (got " + str(min_shadow) + ")");
  if (!(shadow_hue_levels >= 0 && shadow_hue_levels <= 64))
    bad("shadow_hue_levels", "must be in [0, 64] (got " + str(shadow_hue_levels) + ")");
  if (threads < 0) bad("threads", "must be >= 0 (got " + str(threads) + ")");
  if (region_margin_px < 0) bad("region_margin_px", "must be >= 0 (got " + str(region_margin_px) + ")");
  if (region_full_every < 0) bad("region_full_every", "must be >= 0 (got " + str(region_full_every) + ")");
  if (region_full_phase < 0) bad("region_full_phase", "must be >= 0 (got " + str(region_full_phase) + ")");
}

const char* toString(Backdrop backdrop) {
  switch (backdrop) {
    case Backdrop::kAuto: return "auto";
    case Backdrop::kGreen: return "green";
    case Backdrop::kBlue: return "blue";
    case Backdrop::kNone: return "none";
  }
  return "?";
}

Backdrop backdropFromString(const std::string& name) {
  for (Backdrop b : {Backdrop::kAuto, Backdrop::kGreen, Backdrop::kBlue, Backdrop::kNone})
    if (name == toString(b)) return b;
  ErrorContext context;
  context.field = "screen";
  throw Error("keyer: unknown backdrop '" + name + "' (auto, green, blue or none)", context);
}

Keyer::Keyer(const KeyerOptions& options) : options_(options), backdrop_(options.backdrop) {
  options_.validate();
}

const cv::Mat& Keyer::working(const cv::Mat& bgr8) {
  if (backdrop_ != Backdrop::kBlue) return bgr8;
  swapBlueGreen(bgr8, swapped_);
  return swapped_;
}

void Keyer::chooseBackdrop(const cv::Mat& bgr8, const std::string& source, bool is_plate) {
  if (backdrop_ != Backdrop::kAuto) return;
  int support = 0;
  backdrop_ = dominantScreen(bgr8, support);
  if (backdrop_ != Backdrop::kAuto) return;
  if (is_plate) {
    backdrop_ = Backdrop::kNone;  // a set without a screen: keyed by difference
    return;
  }
  fail("no green or blue screen found (" + str(support) +
           " screen-coloured samples) and no clean plate to key by difference",
       source);
}

void Keyer::setCleanPlate(const cv::Mat& plate, const std::string& source) {
  checkImage(plate, source);
  chooseBackdrop(plate, source, true);
  const cv::Mat& bgr8 = working(plate);
  const auto& lut = srgb8ToLinear();
  ScreenModel sm;
  sm.backdrop = backdrop_;
  sm.from_clean_plate = true;
  sm.plate = bgr8.clone();
  if (backdrop_ == Backdrop::kNone) {
    sm.plate_noise = estimateNoise(sm.plate);
    sm.key_color = plateMeanColour(sm.plate);  // despill's fallback background, nothing more
    screen_ = std::move(sm);
    has_screen_ = true;
    return;
  }
  if (!estimateKeyColour(bgr8, sm.key_color))
    fail(std::string("no ") + toString(backdrop_) + " screen found in the clean plate", source);
  sm.key_q = chromaQ(sm.key_color[2], sm.key_color[1], sm.key_color[0]);
  if (!(sm.key_q > 0.1f)) fail("screen colour is too unsaturated to key (q = " + str(sm.key_q) + ")", source);
  const ClassifyTables tables = makeTables(sm);
  // Screen pixels of the plate: its chroma within the screen band of the key. The rest, where
  // connected to the border, is the garbage zone (keyed by difference against the plate).
  sm.illumination.create(bgr8.size(), CV_32FC1);
  cv::Mat not_screen(bgr8.size(), CV_8UC1);
  for (int y = 0; y < bgr8.rows; ++y) {
    const std::uint8_t* p = bgr8.ptr<std::uint8_t>(y);
    float* g = sm.illumination.ptr<float>(y);
    std::uint8_t* n = not_screen.ptr<std::uint8_t>(y);
    for (int x = 0; x < bgr8.cols; ++x) {
      const int b8 = p[3 * x], g8 = p[3 * x + 1], r8 = p[3 * x + 2];
      g[x] = lut[g8];
      n[x] = tables.screenChroma(std::max(r8, b8), g8) && g8 >= tables.min_green8 ? 0 : 255;
    }
  }
  sm.garbage_zone = cv::Mat::zeros(bgr8.size(), CV_8UC1);
  if (options_.garbage_matte) {
    cv::Mat labels;
    const int n = cv::connectedComponents(not_screen, labels, 8, CV_32S);
    std::vector<std::uint8_t> border(n, 0);
    for (int x = 0; x < labels.cols; ++x) {
      border[labels.at<int>(0, x)] = 1;
      border[labels.at<int>(labels.rows - 1, x)] = 1;
    }
    for (int y = 0; y < labels.rows; ++y) {
      border[labels.at<int>(y, 0)] = 1;
      border[labels.at<int>(y, labels.cols - 1)] = 1;
    }
    for (int y = 0; y < labels.rows; ++y) {
      const int* l = labels.ptr<int>(y);
      const std::uint8_t* s = not_screen.ptr<std::uint8_t>(y);
      std::uint8_t* z = sm.garbage_zone.ptr<std::uint8_t>(y);
      for (int x = 0; x < labels.cols; ++x) z[x] = s[x] && border[l[x]] ? 255 : 0;
    }
    const int r = options_.edge_radius_px;
    cv::dilate(sm.garbage_zone, sm.garbage_zone,
               cv::getStructuringElement(cv::MORPH_RECT, cv::Size(2 * r + 1, 2 * r + 1)));
  }
  // Per-pixel green range of the screen: from the deepest shadow to a slight brightening of
  // the plate (uneven light and the cyclorama's falloff are in the plate).
  sm.plate_green_range.create(bgr8.size(), CV_8UC2);
  for (int y = 0; y < bgr8.rows; ++y) {
    const float* g = sm.illumination.ptr<float>(y);
    const std::uint8_t* z = sm.garbage_zone.ptr<std::uint8_t>(y);
    std::uint8_t* range = sm.plate_green_range.ptr<std::uint8_t>(y);
    for (int x = 0; x < bgr8.cols; ++x) {
      if (z[x]) {
        range[2 * x] = 255;
        range[2 * x + 1] = 0;
      } else {
        range[2 * x] = static_cast<std::uint8_t>(std::min(255, srgbCodeAtLeast(kMinPlateShadow * g[x])));
        range[2 * x + 1] =
            static_cast<std::uint8_t>(std::min(255, srgbCodeAtLeast(kMaxPlateBrightening * g[x])));
      }
    }
  }
  screen_ = std::move(sm);
  has_screen_ = true;
}

KeyResult Keyer::key(const cv::Mat& frame, const std::string& source) {
  KeyResult result;
  key(frame, source, result);
  return result;
}

void Keyer::key(const cv::Mat& frame, const std::string& source, KeyResult& result) {
  checkImage(frame, source);
  if (has_screen_ && screen_.from_clean_plate && frame.size() != screen_.plate.size()) {
    fail("frame is " + str(frame.cols) + "x" + str(frame.rows) + " but the clean plate is " +
             str(screen_.plate.cols) + "x" + str(screen_.plate.rows),
         source);
  }
  if (!has_screen_) chooseBackdrop(frame, source, false);
  if (backdrop_ == Backdrop::kNone && !has_screen_)
    fail("no screen (backdrop none): keying by difference needs the camera's clean plate", source);
  const cv::Mat& bgr8 = working(frame);
  if (!has_screen_) {
    ScreenModel sm;
    sm.backdrop = backdrop_;
    if (!estimateKeyColour(bgr8, sm.key_color))
      fail(std::string("no ") + toString(backdrop_) + " screen found in the frame", source);
    sm.key_q = chromaQ(sm.key_color[2], sm.key_color[1], sm.key_color[0]);
    if (!(sm.key_q > 0.1f)) fail("screen colour is too unsaturated to key (q = " + str(sm.key_q) + ")", source);
    screen_ = std::move(sm);
    has_screen_ = true;
  }
  const int W = bgr8.cols, H = bgr8.rows;
  // The frame's constants, from the whole frame whatever region is keyed: the surroundings'
  // colour (the image border), the exposure and noise (a sparse grid).
  Frame f;
  f.bgr8 = &bgr8;
  f.tables = makeTables(screen_);
  f.params.tables = &f.tables;
  f.params.screen = &screen_;
  f.params.use_plate = screen_.from_clean_plate;
  f.params.plate_tolerance = options_.plate_tolerance;
  if (!f.params.use_plate && options_.garbage_matte) {
    screen_.garbage = estimateGarbage(bgr8, f.tables);
    f.params.use_garbage_model = screen_.garbage.valid;
    if (f.params.use_garbage_model && options_.remember_garbage_zone) {
      if (garbage_memory_.size() != bgr8.size()) garbage_memory_ = cv::Mat::zeros(bgr8.size(), CV_8UC1);
      f.params.memory = &garbage_memory_;
    }
  }
  f.difference = screen_.backdrop == Backdrop::kNone;
  if (f.difference) {
    f.diff = differenceFrame(bgr8, screen_, options_);
    screen_.exposure_gain = f.diff.gain;
  }
  classes_.create(H, W, CV_8UC1);
  alpha8_.create(H, W, CV_8UC1);
  if (f.difference) shadow_residual_.create(H, W, CV_8SC4);
  result.silhouette.create(H, W, CV_8UC1);

  // Region keying (KeyerOptions::region_margin_px): the boxes around the last silhouette's parts,
  // unless a whole frame is due or something new shows outside them.
  const cv::Rect whole(0, 0, W, H);
  const char* full_reason = nullptr;
  if (options_.region_margin_px <= 0) full_reason = "regions off";
  else if (regions_.empty()) full_reason = "no earlier silhouette";
  else if (std::any_of(regions_.begin(), regions_.end(), [&](const cv::Rect& r) { return (r & whole) != r; }))
    full_reason = "frame size changed";
  else if (options_.region_full_every > 0 &&
           (frames_keyed_ + options_.region_full_phase) % options_.region_full_every == 0)
    full_reason = "periodic whole frame";
  else if (foregroundOutside(f, regions_)) full_reason = "foreground outside the region";
  // The silhouette's parts (their boxes), for the next frame's regions.
  std::vector<cv::Rect>* parts = options_.region_margin_px > 0 ? &parts_ : nullptr;
  if (parts != nullptr) parts->clear();
  result.stats = {};
  if (full_reason == nullptr) {
    // keyRegion writes every pixel of a region: only the rest is cleared (the alpha only when
    // it is returned; a witness's is never read outside the regions).
    zeroOutside(result.silhouette, regions_);
    if (options_.soft_alpha) zeroOutside(alpha8_, regions_);
    for (const cv::Rect& r : regions_) {
      keyRegion(f, r, result, &region_parts_);
      for (const cv::Rect& part : region_parts_) parts->push_back(part + r.tl());
      result.stats.keyed_px += r.area();
      if (reachesEdge(result.silhouette, r)) {
        full_reason = "silhouette reached the region's edge";
        break;
      }
    }
  }
  if (full_reason != nullptr) {
    result.stats = {};
    if (parts != nullptr) parts->clear();
    keyRegion(f, whole, result, parts);
    result.stats.keyed_px = W * H;
  }
  ++frames_keyed_;
  result.stats.whole_frame = full_reason != nullptr;
  result.stats.whole_frame_reason = full_reason != nullptr ? full_reason : "";
  if (options_.soft_alpha) {
    if (full_reason != nullptr) {
      alpha8_.convertTo(result.alpha, CV_32FC1, 1.0 / 255.0);
    } else {
      result.alpha.create(H, W, CV_32FC1);
      zeroOutside(result.alpha, regions_);
      for (const cv::Rect& r : regions_) {
        cv::Mat dst = result.alpha(r);
        alpha8_(r).convertTo(dst, CV_32FC1, 1.0 / 255.0);
      }
    }
  } else {
    result.alpha.release();
  }
  // The next frame's regions: each part's box grown by the margin, overlapping boxes merged
  // (none when the silhouette is empty: the next frame is keyed whole, which also finds an
  // actor walking in).
  if (parts != nullptr) regions_ = growAndMerge(*parts, options_.region_margin_px, whole);
}

void Keyer::resetRegion() { regions_.clear(); }

PREVIZ_WIDE
bool Keyer::foregroundOutside(const Frame& f, const std::vector<cv::Rect>& regions) {
  // Every kRegionProbeRows-th row classified whole (the first pass alone, no flood, so
  // garbage-like pixels do not count): a run of clear foreground outside the regions is
  // something new (an actor walking in, a prop put down). Smaller than the row step, or the
  // surroundings' own colour, it is found by the periodic whole frame.
  const cv::Mat& bgr8 = *f.bgr8;
  const int W = bgr8.cols, H = bgr8.rows;
  std::vector<cv::Point> seeds;
  std::vector<std::pair<int, int>> spans;
  for (int y = kRegionProbeRows / 2; y < H; y += kRegionProbeRows) {
    if (f.difference)
      differenceRows(bgr8, screen_.plate, f.diff, y, y + 1, classes_, shadow_residual_);
    else
      classifyRows(bgr8, f.params, y, y + 1, classes_, seeds);
    const std::uint8_t* c = classes_.ptr<std::uint8_t>(y);
    bool found = false;
    rowGaps(y, W, regions, spans, [&](int, int x0, int x1) {
      int run = 0;  // a run stops at a region's edge
      for (int x = x0; x < x1 && !found; ++x) {
        run = c[x] == kFg ? run + 1 : 0;
        found = run >= kRegionProbeRun;
      }
    });
    if (found) return true;
  }
  return false;
}

bool Keyer::reachesEdge(const cv::Mat& silhouette, const cv::Rect& region) {
  // Foreground on the region's edge (where that is not the image's): the silhouette may go on
  // outside it.
  const int W = silhouette.cols, H = silhouette.rows;
  auto row_any = [&](int y) {
    const std::uint8_t* s = silhouette.ptr<std::uint8_t>(y);
    for (int x = region.x; x < region.br().x; ++x)
      if (s[x]) return true;
    return false;
  };
  if (region.y > 0 && row_any(region.y)) return true;
  if (region.br().y < H && row_any(region.br().y - 1)) return true;
  for (int y = region.y; y < region.br().y; ++y) {
    const std::uint8_t* s = silhouette.ptr<std::uint8_t>(y);
    if (region.x > 0 && s[region.x]) return true;
    if (region.br().x < W && s[region.br().x - 1]) return true;
  }
  return false;
}

PREVIZ_WIDE
void Keyer::keyRegion(const Frame& f, const cv::Rect& r, KeyResult& result, std::vector<cv::Rect>* parts) {
  // The region as images of its own (views: no copy): the frame, the screen model's per-pixel
  // images, the garbage memory and the scratch. Every pass below reads rows of these views, so
  // the region's edge is their image edge (the garbage flood starts there too: the region's edge
  // lies on background, or reachesEdge sends the frame to a whole key).
  const cv::Mat bgr8 = (*f.bgr8)(r);
  ScreenModel sm = screen_;
  for (cv::Mat* m : {&sm.plate, &sm.illumination, &sm.garbage_zone, &sm.plate_green_range})
    if (!m->empty()) *m = (*m)(r);
  cv::Mat memory_view;
  ClassifyParams params = f.params;
  params.screen = &sm;
  if (params.memory != nullptr) {
    memory_view = garbage_memory_(r);
    params.memory = &memory_view;
  }
  cv::Mat cls = classes_(r);
  cv::Mat alpha8 = alpha8_(r);
  cv::Mat silhouette = result.silhouette(r);
  cv::Mat residual = f.difference ? shadow_residual_(r) : cv::Mat();
  const int threads = resolveThreads(options_.threads);
  const int W = bgr8.cols, H = bgr8.rows;
  const bool use_plate = sm.from_clean_plate;
  const int bands = (H + kBandRows - 1) / kBandRows;
  band_refined_.resize(bands);
  band_seeds_.resize(bands);

  // Pass 1: classes.
  int shadows = 0;
  if (f.difference) {
#pragma omp parallel for schedule(dynamic, 1) num_threads(threads)
    for (int band = 0; band < bands; ++band)
      differenceRows(bgr8, sm.plate, f.diff, band * kBandRows, std::min(H, (band + 1) * kBandRows), cls, residual);
#pragma omp parallel for schedule(dynamic, 1) num_threads(threads) reduction(+ : shadows)
    for (int band = 0; band < bands; ++band)
      shadows += shadowNeighbourhood(residual, f.diff, band * kBandRows, std::min(H, (band + 1) * kBandRows), cls);
  } else {
#pragma omp parallel for schedule(dynamic, 1) num_threads(threads)
    for (int band = 0; band < bands; ++band) {
      band_seeds_[band].clear();
      classifyRows(bgr8, params, band * kBandRows, std::min(H, (band + 1) * kBandRows), cls, band_seeds_[band]);
    }
    if (params.use_garbage_model) {
      std::vector<cv::Point>& stack = band_seeds_[0];
      for (int band = 1; band < bands; ++band) {
        stack.insert(stack.end(), band_seeds_[band].begin(), band_seeds_[band].end());
      }
      floodGarbage(cls, stack);
    }
  }
  band_lone_.resize(bands);
#pragma omp parallel for schedule(dynamic, 1) num_threads(threads)
  for (int band = 0; band < bands; ++band) {
    findLoneUnknown(cls, band * kBandRows, std::min(H, (band + 1) * kBandRows), band_lone_[band]);
  }
  int lone = 0;
  for (const std::vector<detail::LonePixel>& band : band_lone_) {
    for (const detail::LonePixel& p : band) cls.at<std::uint8_t>(p.y, p.x) = p.cls;
    lone += static_cast<int>(band.size());
  }
  // Pass 2: alpha (8-bit). Background 0, foreground 255; the two-colour alpha for unknown
  // pixels and for pixels with a 4-neighbour on the other side (a background pixel beside the
  // foreground may hold a little of it: a dark costume's edge keeps the screen's chroma).
  need_rows_.create(bands, W, CV_8UC1);
  const int radius = options_.edge_radius_px;
  const int threshold8 = static_cast<int>(std::lround(options_.silhouette_threshold * 255.0));
  cv::Mat* memory = params.memory != nullptr ? &memory_view : nullptr;
  int unknown = 0, garbage = 0;
#pragma omp parallel for schedule(dynamic, 1) num_threads(threads) reduction(+ : unknown, garbage)
  for (int band = 0; band < bands; ++band) {
    std::vector<cv::Point>& refined = band_refined_[band];
    refined.clear();
    std::uint8_t* need_row = need_rows_.ptr<std::uint8_t>(band);
    const int y1 = std::min(H, (band + 1) * kBandRows);
    for (int y = band * kBandRows; y < y1; ++y) {
      const std::uint8_t* c = cls.ptr<std::uint8_t>(y);
      const std::uint8_t* up = cls.ptr<std::uint8_t>(std::max(0, y - 1));
      const std::uint8_t* down = cls.ptr<std::uint8_t>(std::min(H - 1, y + 1));
      std::uint8_t* a = alpha8.ptr<std::uint8_t>(y);
      std::uint8_t* s = silhouette.ptr<std::uint8_t>(y);
      // Alpha and silhouette from the class, and the pixels at a transition (unknown, or a
      // 4-neighbour on the other side): 16 pixels per SIMD step.
      std::uint8_t* need = need_row;
      std::uint8_t* mem = memory != nullptr ? memory->ptr<std::uint8_t>(y) : nullptr;
      garbage += markTransitions(c, up, down, W, a, s, need, mem);
      for (int x = 0; x < W; ++x) {
        if (x + 8 <= W) {
          std::uint64_t word;
          std::memcpy(&word, need + x, 8);
          if (word == 0) {
            x += 7;
            continue;
          }
        }
        if (!need[x]) continue;
        ++unknown;
        const float e = edgeAlpha(bgr8, cls, sm, use_plate, x, y, radius);
        if (e >= 0.0f) {
          a[x] = static_cast<std::uint8_t>(std::lround(e * 255.0f));
        } else if (e == -2.0f && c[x] == kUnknown) {
          a[x] = 0;  // unknown with no foreground to mix with
        }
        s[x] = a[x] >= threshold8 ? 255 : 0;
        refined.emplace_back(x, y);
      }
    }
  }
  // A refined pixel whose alpha is near one half is decided by the mean alpha of its 3 x 3
  // neighbourhood: for a straight edge that mean is the fraction of the 3 x 3 square on the
  // inside, which exceeds one half exactly when the pixel's centre is inside (the square is
  // centrally symmetric). The pixel's own alpha cannot tell (a half-covered pixel looks the same
  // whichever side its centre is on). Only across one edge (clear background and clear
  // foreground in the window): a slit of screen between arm and torso has foreground on both
  // sides and would be closed.
  const int ambiguous8 = static_cast<int>(kAmbiguousAlpha * 255.0f);
  const int clear8 = static_cast<int>(kClearAlpha * 255.0f);
#pragma omp parallel for schedule(dynamic, 1) num_threads(threads)
  for (int band = 0; band < bands; ++band) {
    for (const cv::Point& p : band_refined_[band]) {
      const int v = alpha8.at<std::uint8_t>(p);
      if (std::abs(v - threshold8) >= ambiguous8 || p.x == 0 || p.y == 0 || p.x + 1 == W ||
          p.y + 1 == H) {
        continue;
      }
      int sum = 0, lo = 255, hi = 0;
      for (int dy = -1; dy <= 1; ++dy) {
        const std::uint8_t* r = alpha8.ptr<std::uint8_t>(p.y + dy);
        for (int dx = -1; dx <= 1; ++dx) {
          sum += r[p.x + dx];
          lo = std::min<int>(lo, r[p.x + dx]);
          hi = std::max<int>(hi, r[p.x + dx]);
        }
      }
      if (lo <= clear8 && hi >= 255 - clear8) {
        silhouette.at<std::uint8_t>(p) = sum >= 9 * threshold8 ? 255 : 0;
      }
    }
  }
  result.stats.unknown_px += unknown;
  result.stats.lone_unknown_px += lone;
  result.stats.garbage_px += garbage;
  result.stats.shadow_px += shadows;
  cleanSilhouette(silhouette, alpha8, options_, result.stats, parts);
}

cv::Mat despill(const cv::Mat& frame, const KeyResult& key, const ScreenModel& screen,
                const KeyerOptions& options) {
  cv::Mat out;
  despill(frame, key, screen, options, out);
  return out;
}

PREVIZ_WIDE
void despill(const cv::Mat& frame, const KeyResult& key, const ScreenModel& screen, const KeyerOptions& options,
             cv::Mat& out) {
  checkImage(frame, "despill");
  // Blue screen: despilled in the working order (blue and green swapped) and swapped back.
  cv::Mat swapped;
  if (screen.backdrop == Backdrop::kBlue) swapBlueGreen(frame, swapped);
  const cv::Mat& bgr8 = screen.backdrop == Backdrop::kBlue ? swapped : frame;
  if (key.alpha.size() != bgr8.size() || key.alpha.type() != CV_32FC1) {
    fail("needs the key's soft alpha (CV_32FC1, the image's size; KeyerOptions::soft_alpha)",
         "despill");
  }
  const bool use_plate = screen.from_clean_plate && screen.plate.size() == bgr8.size();
  const auto& lut = srgb8ToLinear();
  const int W = bgr8.cols, H = bgr8.rows, radius = options.edge_radius_px;
  // Blue: written in the working order, then swapped into 'out'.
  cv::Mat work_blue;
  cv::Mat& work = screen.backdrop == Backdrop::kBlue ? work_blue : out;
  work.create(H, W, CV_8UC3);
  const bool spill = screen.backdrop != Backdrop::kNone;
  const int threads = resolveThreads(options.threads);
#pragma omp parallel for schedule(dynamic, 8) num_threads(threads)
  for (int y = 0; y < H; ++y) {
    const std::uint8_t* in = bgr8.ptr<std::uint8_t>(y);
    const float* a = key.alpha.ptr<float>(y);
    std::uint8_t* o = work.ptr<std::uint8_t>(y);
    auto pixel = [&](int x) {
      const std::uint8_t* p = in + 3 * x;
      std::uint8_t* q = o + 3 * x;
      const float alpha = a[x];
      if (alpha >= 1.0f) {
        q[0] = p[0];
        q[1] = p[1];
        q[2] = p[2];
        return;
      }
      if (alpha <= 0.0f && screen.backdrop == Backdrop::kNone) {
        q[0] = p[0];  // no screen: nothing spilt
        q[1] = p[1];
        q[2] = p[2];
        return;
      }
      if (alpha <= 0.0f) {
        // Green limited to max(R, B) in linear light; the decode is monotonic, so that is the
        // same limit on the codes.
        q[0] = p[0];
        q[1] = std::min(p[1], std::max(p[0], p[2]));
        q[2] = p[2];
        return;
      }
      const float cb = lut[p[0]], cg = lut[p[1]], cr = lut[p[2]];
      // Local screen colour: the alpha-0 neighbours (as the keyer's edge alpha).
      float sb = 0, sg = 0, sr = 0, pb = 0, pg = 0, pr = 0;
      int n = 0;
      for (int yy = std::max(0, y - radius); yy <= std::min(H - 1, y + radius); ++yy) {
        const float* aa = key.alpha.ptr<float>(yy);
        const std::uint8_t* ii = bgr8.ptr<std::uint8_t>(yy);
        const std::uint8_t* pp = use_plate ? screen.plate.ptr<std::uint8_t>(yy) : nullptr;
        for (int xx = std::max(0, x - radius); xx <= std::min(W - 1, x + radius); ++xx) {
          if (aa[xx] > 0.0f) continue;
          sb += lut[ii[3 * xx]];
          sg += lut[ii[3 * xx + 1]];
          sr += lut[ii[3 * xx + 2]];
          if (pp != nullptr) {
            pb += lut[pp[3 * xx]];
            pg += lut[pp[3 * xx + 1]];
            pr += lut[pp[3 * xx + 2]];
          }
          ++n;
        }
      }
      float bb, bgreen, br;
      if (n == 0 && use_plate && screen.backdrop == Backdrop::kNone) {
        // No background in reach: the plate here at the frame's exposure.
        const std::uint8_t* pl = screen.plate.ptr<std::uint8_t>(y) + 3 * x;
        bb = lut[pl[0]] * screen.exposure_gain;
        bgreen = lut[pl[1]] * screen.exposure_gain;
        br = lut[pl[2]] * screen.exposure_gain;
      } else if (n == 0) {
        // No screen in reach (a hole or a soft interior): the key colour at this brightness.
        const float k = cg / std::max(screen.key_color[1], 1e-6f);
        bb = screen.key_color[0] * k;
        bgreen = screen.key_color[1] * k;
        br = screen.key_color[2] * k;
      } else if (use_plate) {
        const std::uint8_t* pl = screen.plate.ptr<std::uint8_t>(y) + 3 * x;
        const float shadow = (sb + sg + sr) / std::max(pb + pg + pr, 1e-6f);
        bb = lut[pl[0]] * shadow;
        bgreen = lut[pl[1]] * shadow;
        br = lut[pl[2]] * shadow;
      } else {
        bb = sb / n;
        bgreen = sg / n;
        br = sr / n;
      }
      const float inv = 1.0f / alpha, rest = 1.0f - alpha;
      q[0] = linearToSrgb8(std::max(0.0f, (cb - rest * bb) * inv));
      q[1] = linearToSrgb8(std::max(0.0f, (cg - rest * bgreen) * inv));
      q[2] = linearToSrgb8(std::max(0.0f, (cr - rest * br) * inv));
    };
    int x = 0;
#if CV_SIMD128
    // 16 pixels at a time where all are opaque (copied) or all clear (green limited): most of
    // a frame; the transition goes pixel by pixel.
    const cv::v_float32x4 one = cv::v_setall_f32(1.0f), zero = cv::v_setzero_f32();
    for (; x + 16 <= W; x += 16) {
      const cv::v_float32x4 a0 = cv::v_load(a + x), a1 = cv::v_load(a + x + 4), a2 = cv::v_load(a + x + 8),
                            a3 = cv::v_load(a + x + 12);
      if (cv::v_check_all((a0 >= one) & (a1 >= one) & (a2 >= one) & (a3 >= one)) ||
          (!spill && cv::v_check_all((a0 <= zero) & (a1 <= zero) & (a2 <= zero) & (a3 <= zero)))) {
        std::memcpy(o + 3 * x, in + 3 * x, 48);
      } else if (cv::v_check_all((a0 <= zero) & (a1 <= zero) & (a2 <= zero) & (a3 <= zero))) {
        cv::v_uint8x16 b, g, r;
        cv::v_load_deinterleave(in + 3 * x, b, g, r);
        cv::v_store_interleave(o + 3 * x, b, cv::v_min(g, cv::v_max(b, r)), r);
      } else {
        for (int i = 0; i < 16; ++i) pixel(x + i);
      }
    }
#endif
    for (; x < W; ++x) pixel(x);
  }
  if (screen.backdrop == Backdrop::kBlue) swapBlueGreen(work_blue, out);
}

}  // namespace previz::carving
