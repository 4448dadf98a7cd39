// Depth beyond the visual hull by photo-consistency along the depth camera's rays (refine.h).
#include "carving/refine.h"

#include <omp.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/imgproc.hpp>

#include "core/error.h"
#include "core/srgb.h"
#include "core/stopwatch.h"
#include "core/threads.h"

namespace previz::carving {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr float kInfF = std::numeric_limits<float>::infinity();

std::string num(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}

// A reference view: a witness, or (photoHullDepth) the depth camera seen from a witness.
struct Witness {
  const RigCamera* rc = nullptr;
  Pose T_cam_world;
  cv::Mat bgr;         // the plate (8-bit, sRGB)
  double gain = 1;     // given (> 0) or estimated (estimateGains)
  bool estimated = false;
  int gain_samples = 0;
  float inv_gain = 1;
  cv::Mat front;       // nearest hull depth per kVisibilityBlock^2 pixels (visibilityMap)
  // photoHullDepth: the view's own refined depth (full size), min and max over each pixel's
  // 3x3 neighbourhood (the projection of a point is not the pixel centre); empty = none yet.
  cv::Mat near_depth, far_depth;
};

// The witnesses' hull depth only serves the loose visibility test (a candidate more than
// visibility_m behind it is hidden), so it is made at a quarter of the witness' resolution:
// 16x fewer rays (and ray tables) per witness.
constexpr int kVisibilityBlock = 4;

// Per block of kVisibilityBlock^2 witness pixels, a depth no farther than the hull's first
// surface at any of its pixels: the hull depth of the scaled-down camera (silhouette max-pooled,
// so every block that holds an inside pixel is cast), then the minimum over each block's 3x3
// neighbourhood (the scaled rays are not the full-size ones).
cv::Mat visibilityMap(const Carver& carver, const VisualHull& hull, const RigCamera& rc,
                      const cv::Mat& mask) {
  const int b = kVisibilityBlock;
  const int w = (rc.camera.width + b - 1) / b, h = (rc.camera.height + b - 1) / b;
  RigCamera small = rc;
  small.camera = rc.camera.scaled(static_cast<double>(w) / rc.camera.width,
                                  static_cast<double>(h) / rc.camera.height);
  small.camera.width = w;
  small.camera.height = h;
  cv::Mat pooled(h, w, CV_8UC1, cv::Scalar(0));
  for (int v = 0; v < mask.rows; ++v) {
    const std::uint8_t* m = mask.ptr<std::uint8_t>(v);
    std::uint8_t* out = pooled.ptr<std::uint8_t>(v / b);
    for (int u = 0; u < mask.cols; ++u)
      if (m[u] > 127) out[u / b] = 255;
  }
  cv::Mat front = carver.depth(hull, small, pooled);
  cv::erode(front, front, cv::Mat::ones(3, 3, CV_8UC1), cv::Point(-1, -1), 1, cv::BORDER_REPLICATE);
  return front;
}

// Linear colour of a plate at a pixel position, divided by the camera's gain: bilinear between
// the four pixel centres around it (false outside the image). Plates are not smoothed: a box
// filter mixes a part's colour with its neighbour's at every image edge between parts, where the
// hull's concavities are (measured: 3x3 boxes cost 0.1-0.15 points at 10 cm).
bool sample(const cv::Mat& bgr, float inv_gain, double u, double v, float* c) {
  if (!(u >= 0 && v >= 0 && u <= bgr.cols - 1 && v <= bgr.rows - 1)) return false;
  const std::array<float, 256>& lin = srgb8ToLinear();
  const int u0 = std::min(static_cast<int>(u), bgr.cols - 2);
  const int v0 = std::min(static_cast<int>(v), bgr.rows - 2);
  const float fu = static_cast<float>(u - u0), fv = static_cast<float>(v - v0);
  const std::uint8_t* a = bgr.ptr<std::uint8_t>(v0) + 3 * u0;
  const std::uint8_t* b = bgr.ptr<std::uint8_t>(v0 + 1) + 3 * u0;
  for (int ch = 0; ch < 3; ++ch)
    c[ch] = inv_gain * ((1 - fv) * ((1 - fu) * lin[a[ch]] + fu * lin[a[3 + ch]]) +
                        fv * ((1 - fu) * lin[b[ch]] + fu * lin[b[3 + ch]]));
  return true;
}

// Linear colour of the plate's pixel (u, v), divided by the camera's gain.
void pixelColour(const cv::Mat& bgr, float inv_gain, int u, int v, float* c) {
  const std::array<float, 256>& lin = srgb8ToLinear();
  const std::uint8_t* p = bgr.ptr<std::uint8_t>(v) + 3 * u;
  for (int ch = 0; ch < 3; ++ch) c[ch] = inv_gain * lin[p[ch]];
}

// World direction of pixel (u, v)'s ray, scaled to unit depth along the camera axis (a point at
// depth t is centre + t * direction); nullopt where the lens has no ray.
std::optional<Eigen::Vector3d> rayDirection(const RigCamera& camera, int u, int v) {
  const auto ray = camera.camera.unproject(Eigen::Vector2d(u, v));
  if (!ray) return std::nullopt;
  return Eigen::Vector3d(camera.T_world_cam.linear() * (*ray / ray->z()));
}

// Relative colour distance: L1 difference over the pair's mean brightness (floored, so that the
// noise of near-black pixels does not read as disagreement).
float colourDistance(const float* a, const float* b) {
  const float diff = std::abs(a[0] - b[0]) + std::abs(a[1] - b[1]) + std::abs(a[2] - b[2]);
  const float level = 0.5f * (a[0] + a[1] + a[2] + b[0] + b[1] + b[2]);
  return diff / std::max(level, 0.03f);
}

// Gains the caller does not know (<= 0), relative to the depth camera's: where the hull depth
// is the surface (almost everywhere: the hull is within millimetres of it outside concavities)
// a witness sees the same Lambertian point at that point's depth on its own hull surface, so the
// ratio of the two plates' linear brightness there is the ratio of the gains; the median over
// every 2nd pixel in each direction rejects the concavities, occlusions and edges. Fewer than
// kMinGainSamples points (a witness facing the actor's other side, which then hardly ever sees
// a candidate either): gain 1.
constexpr int kMinGainSamples = 50;
void estimateGains(const RigCamera& camera, const cv::Mat& bgr, double main_gain,
                   const cv::Mat& hull_depth, std::vector<Witness>& witnesses) {
  const std::array<float, 256>& lin = srgb8ToLinear();
  const Camera& cam = camera.camera;
  const Eigen::Vector3d centre = camera.T_world_cam.translation();
  for (Witness& w : witnesses) {
    if (w.gain > 0) {
      w.inv_gain = static_cast<float>(1.0 / w.gain);
      continue;
    }
    std::vector<float> ratios;
    for (int v = 0; v < cam.height; v += 2)
      for (int u = 0; u < cam.width; u += 2) {
        const double t = hull_depth.at<float>(v, u);
        if (!std::isfinite(t)) continue;
        const std::uint8_t* m = bgr.ptr<std::uint8_t>(v) + 3 * u;
        const float main_level = lin[m[0]] + lin[m[1]] + lin[m[2]];
        if (main_level < 0.03f) continue;  // too dark to measure a ratio
        const auto ray = rayDirection(camera, u, v);
        if (!ray) continue;
        const Eigen::Vector3d X = centre + t * *ray;
        const Eigen::Vector3d q = w.T_cam_world * X;
        const auto px = w.rc->camera.project(q);
        if (!px) continue;
        const int iu = static_cast<int>(std::floor((px->x() + 0.5) / kVisibilityBlock));
        const int iv = static_cast<int>(std::floor((px->y() + 0.5) / kVisibilityBlock));
        if (iu < 0 || iv < 0 || iu >= w.front.cols || iv >= w.front.rows) continue;
        if (!(std::abs(q.z() - w.front.at<float>(iv, iu)) < 0.02)) continue;
        float cw[3];
        if (!sample(w.bgr, 1.0f, px->x(), px->y(), cw)) continue;
        ratios.push_back((cw[0] + cw[1] + cw[2]) / main_level);
      }
    w.estimated = true;
    w.gain_samples = static_cast<int>(ratios.size());
    if (static_cast<int>(ratios.size()) < kMinGainSamples) {
      w.gain = 1.0;
    } else {
      std::nth_element(ratios.begin(), ratios.begin() + ratios.size() / 2, ratios.end());
      w.gain = main_gain * ratios[ratios.size() / 2];
    }
    w.inv_gain = static_cast<float>(1.0 / w.gain);
  }
}

struct ViewCounts {
  long long pixels = 0, inconsistent = 0, moved = 0, free_space = 0;
};

// Refines 'depth' in place: the hull depth of 'camera' (full size, plate 'bgr' divided by its
// gain) against the reference views. With 'fs' (photoHullDepth's options: its free-space, veto
// and air-search terms; options.refine is not read from it) the references' own refined
// depths also decide free space (a point well in front of the refined surface of
// fs->free_views references is air: they see through it; where the hull entry is air and nothing
// deeper agrees, the first point no reference sees through) and, with hidden_m > 0, visibility
// (a point far behind a reference's refined surface is hidden from it).
ViewCounts refineView(const Carver& carver, const VisualHull& hull, const RigCamera& camera,
                      const cv::Mat& bgr_plate, float inv_gain, cv::Mat& depth,
                      const std::vector<const Witness*>& refs, const RefineOptions& options,
                      const PhotoHullOptions* fs, int threads) {
  const Camera& cam = camera.camera;
  const Eigen::Vector3d centre = camera.T_world_cam.translation();
  const int n_steps = static_cast<int>(std::floor(options.search_m / options.step_m));
  const int air_steps =
      fs ? static_cast<int>(std::floor(fs->air_search_m / options.step_m)) : n_steps;
  const int nw = static_cast<int>(refs.size());
  constexpr float kAir = -1.0f;  // cost() result: free space
  long long pixels = 0, inconsistent = 0, moved = 0, free_space = 0;

  // Cost of the point X for the plate colour c: mean of the best_of smallest colour distances
  // over the witnesses that can see X; +inf when fewer see it. A witness that has X on its own
  // hull surface (within veto_m) sees X itself if X is matter (the hull holds all of it, so
  // nothing can hide X from it): its disagreement beyond 'veto' rules X out.
  auto cost = [&](const Eigen::Vector3d& X, const float* c) {
    float d[32];
    double vetoed = 0;
    int n = 0, free = 0;
    for (int i = 0; i < nw && n < 32; ++i) {
      const Witness& w = *refs[i];
      const Eigen::Vector3d q = w.T_cam_world * X;
      const auto px = w.rc->camera.project(q);
      if (!px) continue;
      const int iu = static_cast<int>(std::floor((px->x() + 0.5) / kVisibilityBlock));
      const int iv = static_cast<int>(std::floor((px->y() + 0.5) / kVisibilityBlock));
      if (iu < 0 || iv < 0 || iu >= w.front.cols || iv >= w.front.rows) continue;
      const float front = w.front.at<float>(iv, iu);
      if (!std::isfinite(front) || q.z() > front + options.visibility_m) continue;
      float seen_near = kInfF;  // the reference's refined depth, with seen_veto
      if (fs && !w.near_depth.empty()) {
        const int du = static_cast<int>(std::floor(px->x() + 0.5));
        const int dv = static_cast<int>(std::floor(px->y() + 0.5));
        if (du < 0 || dv < 0 || du >= w.near_depth.cols || dv >= w.near_depth.rows) continue;
        const float near = w.near_depth.at<float>(dv, du);
        const float far = w.far_depth.at<float>(dv, du);
        if (std::isfinite(near) && near > q.z() + fs->free_m && ++free >= fs->free_views)
          return static_cast<double>(kAir);
        if (fs->hidden_m > 0 && std::isfinite(far) && q.z() > far + fs->hidden_m) continue;
        if (fs->seen_veto > 0) seen_near = near;
      }
      float cw[3];
      if (!sample(w.bgr, w.inv_gain, px->x(), px->y(), cw)) continue;
      d[n] = colourDistance(c, cw);
      if (q.z() <= front + options.veto_m && d[n] > options.veto)
        vetoed = std::max(vetoed, static_cast<double>(d[n]));
      if (seen_near < kInfF && d[n] > fs->seen_veto && q.z() <= seen_near + fs->seen_m)
        vetoed = std::max(vetoed, static_cast<double>(d[n]));
      ++n;
    }
    if (n < options.best_of) return kInf;
    std::partial_sort(d, d + options.best_of, d + n);
    double s = 0;
    for (int i = 0; i < options.best_of; ++i) s += d[i];
    return std::max(s / options.best_of, vetoed);
  };

#pragma omp parallel for schedule(dynamic, 4) num_threads(threads) reduction(+ : pixels, inconsistent, moved, free_space)
  for (int v = 0; v < cam.height; ++v) {
    float* row = depth.ptr<float>(v);
    for (int u = 0; u < cam.width; ++u) {
      const double t0 = row[u];
      if (!std::isfinite(t0)) continue;
      ++pixels;
      const auto ray = rayDirection(camera, u, v);
      if (!ray) continue;
      const Eigen::Vector3d& d = *ray;
      float c[3];
      pixelColour(bgr_plate, inv_gain, u, v, c);
      double cost0 = cost(centre + t0 * d, c);
      if (cost0 <= options.agree && cost0 != kAir) continue;
      ++inconsistent;
      const bool entry_air = cost0 == kAir;
      if (entry_air) {
        ++free_space;
        cost0 = kInf;
      }
      double first_solid = kInf;
      bool found = false;
      // Where the entry and the whole search range are air (a deep crease that witnesses see
      // through), the first point no witness sees through lies farther on: an air entry marches
      // on past search_m (to air_steps) looking for that point only.
      for (int s = 1; s <= (entry_air ? air_steps : n_steps); ++s) {
        if (s > n_steps && first_solid < kInf) break;
        const double t = t0 + s * options.step_m;
        const Eigen::Vector3d X = centre + t * d;
        if (!carver.inside(hull, X)) continue;
        const double k = cost(X, c);
        if (k != kAir && first_solid == kInf) first_solid = t;
        if (s <= n_steps && k != kAir && k <= options.agree && k <= options.margin * cost0) {
          row[u] = static_cast<float>(t);
          ++moved;
          found = true;
          break;
        }
      }
      // Space carving: what a witness looks through is air even where nothing deeper is
      // photo-consistent; the depth goes to the first point no witness sees through.
      if (entry_air && !found && first_solid < kInf) {
        row[u] = static_cast<float>(first_solid);
        ++moved;
      }
    }
  }
  return ViewCounts{pixels, inconsistent, moved, free_space};
}

void checkImage(const cv::Mat& m, int type, const Camera& c, const char* what) {
  if (m.type() != type || m.cols != c.width || m.rows != c.height)
    throw Error(std::string("refine: ") + what + " must be " +
                    (type == CV_8UC3 ? "8-bit BGR" : type == CV_8UC1 ? "8-bit single-channel"
                                                                     : "32-bit float") +
                    " at the camera's " + std::to_string(c.width) + "x" +
                    std::to_string(c.height),
                ErrorContext{"", c.name, std::nullopt, what});
}

// The witnesses with a plate and a mask (checked), their visibility maps and their gains
// (estimated against the depth camera's where unknown).
std::vector<Witness> makeWitnesses(const Carver& carver, const VisualHull& hull,
                                   const RigCamera& camera, const Plate& plate,
                                   const cv::Mat& hull_depth,
                                   const std::vector<Plate>& witness_plates,
                                   const std::vector<cv::Mat>& witness_masks, RefineStats& local,
                                   std::vector<int>* indices = nullptr) {
  const Camera& cam = camera.camera;
  checkImage(plate.bgr, CV_8UC3, cam, "plate");
  checkImage(hull_depth, CV_32FC1, cam, "hull depth");
  const std::vector<RigCamera>& cams = carver.cameras();
  if (witness_plates.size() != cams.size() || witness_masks.size() != cams.size())
    throw Error("refine: " + std::to_string(witness_plates.size()) + " plates and " +
                    std::to_string(witness_masks.size()) + " masks for " +
                    std::to_string(cams.size()) + " carving cameras",
                ErrorContext{"", cam.name, std::nullopt, "witness_plates"});
  std::vector<Witness> witnesses;
  for (size_t c = 0; c < cams.size(); ++c) {
    if (witness_plates[c].bgr.empty() || witness_masks[c].empty()) continue;
    checkImage(witness_plates[c].bgr, CV_8UC3, cams[c].camera, "plate");
    checkImage(witness_masks[c], CV_8UC1, cams[c].camera, "mask");
    Witness w;
    w.rc = &cams[c];
    w.T_cam_world = cams[c].T_world_cam.inverse();
    w.bgr = witness_plates[c].bgr;
    w.gain = witness_plates[c].gain;
    w.front = visibilityMap(carver, hull, cams[c], witness_masks[c]);
    witnesses.push_back(std::move(w));
    local.witnesses_used.push_back(cams[c].camera.name);
    if (indices) indices->push_back(static_cast<int>(c));
  }
  const double main_gain = plate.gain > 0 ? plate.gain : 1.0;
  estimateGains(camera, plate.bgr, main_gain, hull_depth, witnesses);
  for (const Witness& w : witnesses) {
    local.witness_gains.push_back(w.gain);
    if (w.estimated) {
      local.gains_estimated.push_back(w.rc->camera.name);
      local.gain_samples.push_back(w.gain_samples);
    }
  }
  return witnesses;
}

}  // namespace

void RefineOptions::validate() const {
  auto bad = [](const std::string& field, const std::string& message) {
    throw Error("refine: " + field + " " + message, fieldContext(field));
  };
  if (!(search_m > 0) || !std::isfinite(search_m))
    bad("search_m", "must be a finite value > 0 (got " + num(search_m) + ")");
  if (!(step_m > 0) || !(step_m <= search_m))
    bad("step_m", "must be > 0 and <= search_m (got " + num(step_m) + ")");
  if (!(agree > 0) || !std::isfinite(agree))
    bad("agree", "must be a finite value > 0 (got " + num(agree) + ")");
  if (best_of < 1) bad("best_of", "must be >= 1 (got " + std::to_string(best_of) + ")");
  if (!(visibility_m >= 0) || !std::isfinite(visibility_m))
    bad("visibility_m", "must be a finite value >= 0 (got " + num(visibility_m) + ")");
  if (!(margin > 0) || !(margin <= 1))
    bad("margin", "must be in (0, 1] (got " + num(margin) + ")");
  if (!(veto > 0) || !std::isfinite(veto))
    bad("veto", "must be a finite value > 0 (got " + num(veto) + ")");
  if (!(veto_m >= 0) || !(veto_m <= visibility_m))
    bad("veto_m", "must be in [0, visibility_m] (got " + num(veto_m) + ")");
  if (threads < 0) bad("threads", "must be >= 0 (got " + std::to_string(threads) + ")");
}

cv::Mat refineDepth(const Carver& carver, const VisualHull& hull, const RigCamera& camera,
                    const Plate& plate, const cv::Mat& hull_depth,
                    const std::vector<Plate>& witness_plates,
                    const std::vector<cv::Mat>& witness_masks, const RefineOptions& options,
                    RefineStats* stats) {
  const Stopwatch start;
  options.validate();
  RefineStats local;
  const std::vector<Witness> witnesses = makeWitnesses(carver, hull, camera, plate, hull_depth,
                                                       witness_plates, witness_masks, local);
  std::vector<const Witness*> refs;
  for (const Witness& w : witnesses) refs.push_back(&w);
  cv::Mat out = hull_depth.clone();
  const float main_inv_gain = static_cast<float>(1.0 / (plate.gain > 0 ? plate.gain : 1.0));
  const int threads = resolveThreads(options.threads);
  const ViewCounts n =
      refineView(carver, hull, camera, plate.bgr, main_inv_gain, out, refs, options, nullptr, threads);
  local.pixels = n.pixels;
  local.inconsistent = n.inconsistent;
  local.moved = n.moved;
  local.ms = start.ms();
  if (stats) *stats = std::move(local);
  return out;
}

void PhotoHullOptions::validate() const {
  refine.validate();
  auto bad = [](const std::string& field, const std::string& message) {
    throw Error("photo hull: " + field + " " + message, fieldContext(field));
  };
  if (rounds < 0) bad("rounds", "must be >= 0 (got " + std::to_string(rounds) + ")");
  if (!(free_m > 0) || !std::isfinite(free_m))
    bad("free_m", "must be a finite value > 0 (got " + num(free_m) + ")");
  if (free_views < 1) bad("free_views", "must be >= 1 (got " + std::to_string(free_views) + ")");
  if (witness_stride < 1 || witness_stride > 8)
    bad("witness_stride", "must be 1 to 8 (got " + std::to_string(witness_stride) + ")");
  if (!(hidden_m >= 0) || !std::isfinite(hidden_m))
    bad("hidden_m", "must be a finite value >= 0 (got " + num(hidden_m) + ")");
  if (!(seen_veto >= 0) || !std::isfinite(seen_veto))
    bad("seen_veto", "must be a finite value >= 0 (got " + num(seen_veto) + ")");
  if (!(seen_m >= 0) || !std::isfinite(seen_m))
    bad("seen_m", "must be a finite value >= 0 (got " + num(seen_m) + ")");
  if (!(edge_jump_m >= 0) || !std::isfinite(edge_jump_m))
    bad("edge_jump_m", "must be a finite value >= 0 (got " + num(edge_jump_m) + ")");
  if (!(edge_alpha > 0) || !(edge_alpha <= 1))
    bad("edge_alpha", "must be in (0, 1] (got " + num(edge_alpha) + ")");
  if (!(edge_contrast > 0) || !std::isfinite(edge_contrast))
    bad("edge_contrast", "must be a finite value > 0 (got " + num(edge_contrast) + ")");
  if (!(air_search_m >= refine.search_m) || !std::isfinite(air_search_m))
    bad("air_search_m", "must be finite and >= refine.search_m (got " + num(air_search_m) + ")");
}

namespace {

// The mask's pixels at every stride-th row and column (stride 1: the mask itself).
cv::Mat strideMask(const cv::Mat& mask, int stride) {
  if (stride <= 1) return mask;
  cv::Mat out = cv::Mat::zeros(mask.size(), CV_8UC1);
  for (int v = 0; v < mask.rows; v += stride)
    for (int u = 0; u < mask.cols; u += stride) out.at<std::uint8_t>(v, u) = mask.at<std::uint8_t>(v, u);
  return out;
}

// Each stride x stride block takes the depth of its top-left pixel where the mask is set.
void spreadBlocks(cv::Mat& depth, const cv::Mat& mask, int stride) {
  if (stride <= 1) return;
  for (int v = 0; v < depth.rows; ++v) {
    float* row = depth.ptr<float>(v);
    const float* anchor = depth.ptr<float>(v - v % stride);
    const std::uint8_t* m = mask.ptr<std::uint8_t>(v);
    for (int u = 0; u < depth.cols; ++u)
      if ((v % stride || u % stride) && m[u] > 127) row[u] = anchor[u - u % stride];
  }
}

// PhotoHullOptions::edge_jump_m: a pixel between a deeper neighbour and, opposite, one at its
// own depth, whose colour holds less than edge_alpha of the near neighbour's, takes the deeper
// neighbour's depth (refine.h). One pass over a copy, so that an edge moves by at most a pixel.
long long settleOcclusionEdges(const Carver& carver, const VisualHull& hull,
                               const RigCamera& camera, const cv::Mat& bgr, float inv_gain,
                               cv::Mat& depth, const PhotoHullOptions& options, int threads) {
  const Camera& cam = camera.camera;
  const Eigen::Vector3d centre = camera.T_world_cam.translation();
  const double jump = options.edge_jump_m;
  const cv::Mat src = depth.clone();
  constexpr int kDu[4] = {1, 0, 1, 1}, kDv[4] = {0, 1, 1, -1};
  constexpr double kSnapM = 0.03;  // how far from the deeper neighbour's depth the hull is sought
  long long moved = 0;
#pragma omp parallel for schedule(dynamic, 8) num_threads(threads) reduction(+ : moved)
  for (int v = 1; v < cam.height - 1; ++v) {
    for (int u = 1; u < cam.width - 1; ++u) {
      const float z = src.at<float>(v, u);
      if (!std::isfinite(z)) continue;
      double least_alpha = options.edge_alpha;
      float deeper = 0;
      float cp[3];
      pixelColour(bgr, inv_gain, u, v, cp);
      for (int dir = 0; dir < 4; ++dir)
        for (int sense = -1; sense <= 1; sense += 2) {
          const int uf = u + sense * kDu[dir], vf = v + sense * kDv[dir];
          const int un = u - sense * kDu[dir], vn = v - sense * kDv[dir];
          const float zf = src.at<float>(vf, uf), zn = src.at<float>(vn, un);
          if (!(std::isfinite(zf) && zf > z + jump)) continue;
          if (!(std::isfinite(zn) && std::abs(zn - z) <= 0.5 * jump)) continue;
          float cf[3], cn[3];
          pixelColour(bgr, inv_gain, uf, vf, cf);
          pixelColour(bgr, inv_gain, un, vn, cn);
          if (colourDistance(cn, cf) < options.edge_contrast) continue;
          double dd = 0, dp = 0;
          for (int k = 0; k < 3; ++k) {
            dd += (cn[k] - cf[k]) * (cn[k] - cf[k]);
            dp += (cp[k] - cf[k]) * (cn[k] - cf[k]);
          }
          const double alpha = dp / dd;  // the near colour's share of the pixel's
          if (alpha < least_alpha) {
            least_alpha = alpha;
            deeper = zf;
          }
        }
      if (deeper == 0) continue;
      const auto ray = rayDirection(camera, u, v);
      if (!ray) continue;
      const Eigen::Vector3d& d = *ray;
      bool found = false;
      for (double dt = 0; dt <= kSnapM + 1e-9 && !found; dt += options.refine.step_m)
        for (const double t : {deeper - dt, deeper + dt})
          if (t > z && carver.inside(hull, centre + t * d)) {
            depth.at<float>(v, u) = static_cast<float>(t);
            found = true;
            break;
          }
      moved += found;
    }
  }
  return moved;
}

}  // namespace

cv::Mat photoHullDepth(const Carver& carver, const VisualHull& hull, const RigCamera& camera,
                       const Plate& plate, const cv::Mat& hull_depth,
                       const std::vector<Plate>& witness_plates,
                       const std::vector<cv::Mat>& witness_masks,
                       const PhotoHullOptions& options, PhotoHullStats* stats) {
  const Stopwatch start;
  options.validate();
  PhotoHullStats local;
  std::vector<int> index;  // carver camera of each witness used
  std::vector<Witness> views = makeWitnesses(carver, hull, camera, plate, hull_depth,
                                             witness_plates, witness_masks, local.depth, &index);
  const int nw = static_cast<int>(views.size());
  const int threads = resolveThreads(options.refine.threads);
  {
    // The depth camera as the witnesses' reference: its silhouette is where its hull depth is.
    Witness m;
    m.rc = &camera;
    m.T_cam_world = camera.T_world_cam.inverse();
    m.bgr = plate.bgr;
    m.gain = plate.gain > 0 ? plate.gain : 1.0;
    m.inv_gain = static_cast<float>(1.0 / m.gain);
    cv::Mat mask = hull_depth < std::numeric_limits<float>::infinity();
    m.front = visibilityMap(carver, hull, camera, mask);
    views.push_back(std::move(m));
  }
  auto setDepth = [](Witness& w, const cv::Mat& depth) {
    const cv::Mat k = cv::Mat::ones(3, 3, CV_8UC1);
    cv::erode(depth, w.near_depth, k, cv::Point(-1, -1), 1, cv::BORDER_REPLICATE);
    cv::dilate(depth, w.far_depth, k, cv::Point(-1, -1), 1, cv::BORDER_REPLICATE);
  };
  std::vector<const Witness*> main_refs;
  for (int i = 0; i < nw; ++i) main_refs.push_back(&views[i]);
  const float main_inv_gain = views[nw].inv_gain;

  cv::Mat out = hull_depth.clone();
  ViewCounts n = refineView(carver, hull, camera, plate.bgr, main_inv_gain, out, main_refs,
                            options.refine, nullptr, threads);
  std::vector<cv::Mat> witness_hull(nw);
  const int stride = options.witness_stride;
  for (int round = 0; round < options.rounds; ++round) {
    const Stopwatch witness_start;
    setDepth(views[nw], out);
    std::vector<cv::Mat> refined(nw);
    local.witness_pixels.assign(nw, 0);
    local.witness_moved.assign(nw, 0);
    for (int i = 0; i < nw; ++i) {
      const RigCamera& rc = *views[i].rc;
      if (witness_hull[i].empty())
        witness_hull[i] = carver.depth(hull, rc, strideMask(witness_masks[index[i]], stride));
      std::vector<const Witness*> refs;
      for (int j = 0; j <= nw; ++j)
        if (j != i) refs.push_back(&views[j]);
      refined[i] = witness_hull[i].clone();
      const ViewCounts c = refineView(carver, hull, rc, views[i].bgr, views[i].inv_gain,
                                      refined[i], refs, options.refine, &options, threads);
      spreadBlocks(refined[i], witness_masks[index[i]], stride);
      local.witness_pixels[i] = c.pixels;
      local.witness_moved[i] = c.moved;
    }
    for (int i = 0; i < nw; ++i) setDepth(views[i], refined[i]);
    local.witness_ms += witness_start.ms();
    out = hull_depth.clone();
    n = refineView(carver, hull, camera, plate.bgr, main_inv_gain, out, main_refs, options.refine,
                   &options, threads);
  }
  if (options.edge_jump_m > 0)
    local.edge_moved = settleOcclusionEdges(carver, hull, camera, plate.bgr, main_inv_gain, out,
                                            options, threads);
  local.depth.pixels = n.pixels;
  local.depth.inconsistent = n.inconsistent;
  local.depth.moved = n.moved;
  local.free_space = n.free_space;
  local.ms = local.depth.ms = start.ms();
  if (stats) *stats = std::move(local);
  return out;
}

}  // namespace previz::carving
