#pragma once
// Fixtures shared by the calibration-solve tests (intrinsics, selection, frontal, validation):
// the thesis' simulated camera, board poses like the studio's intrinsics preset, and views
// either as exact projections plus Gaussian pixel noise (fast, for the solver's own logic) or
// rendered by the synthetic studio and detected (for the thesis tables).
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <map>
#include <mutex>
#include <string>
#include <vector>

#include <sys/stat.h>

#include <opencv2/imgcodecs.hpp>

#include "calib/detect.h"
#include "calib/observations.h"
#include "core/board.h"
#include "core/camera.h"
#include "core/io.h"
#include "datasets/random.h"
#include "datasets/render.h"
#include "datasets/rigs.h"
#include "datasets/studio.h"

namespace previz::calib::testing {

// Thesis Table 5.1 camera: 1200 x 900, fx = fy = 800, c = (600, 450), k1 = 0.2.
inline Camera thesisCamera() {
  Camera c;
  c.name = "thesis";
  c.width = 1200;
  c.height = 900;
  c.fx = c.fy = 800;
  c.cx = 600;
  c.cy = 450;
  c.dist.k1 = 0.2;
  return c;
}

// Boards for the thesis scene: denser than the studio's defaults where the detector allows (more
// points per view), each about 0.5 x 0.7 m.
inline BoardSpec thesisBoard(BoardType type) {
  BoardSpec b = synth::defaultBoard(type);
  switch (type) {
    case BoardType::kChessboard:
      b.rows = 12, b.cols = 16, b.square_m = 0.04, b.margin_m = 0.04;
      break;
    case BoardType::kCharuco:
      // 4x4 markers as large as the density allows: on denser prints the markers' bit cells
      // fall under ~2.5 px at 2 m and the detector decodes few of them (measured, 6 views:
      // 9 x 11 squares of 55 mm 73 % of 80 corners; 11 x 13 of 45 mm 37 % of 120).
      b.rows = 9, b.cols = 11, b.square_m = 0.055, b.marker_m = 0.041, b.margin_m = 0.02;
      b.dictionary = "DICT_4X4_250";
      break;
    case BoardType::kAprilGrid:
      b.rows = 6, b.cols = 8, b.square_m = 0.06, b.marker_m = 0.018, b.margin_m = 0.02;
      break;
    case BoardType::kCircles:
      b.rows = 9, b.cols = 12, b.square_m = 0.05, b.circle_radius_m = 0.018, b.margin_m = 0.02;
      break;
    case BoardType::kQuadtree:
      break;  // the studio's: 5 x 5 cells of 12 cm, 3 levels (0.6 m square, 64 markers)
  }
  b.validate();
  return b;
}

// Exact projections of the board points at T_cam_board plus isotropic Gaussian noise.
inline ViewObservations projectedView(const Camera& camera, const BoardSpec& board,
                                      const Pose& T_cam_board, double noise_px,
                                      std::uint64_t noise_key, const std::string& source) {
  ViewObservations view;
  view.source = source;
  view.image_size = cv::Size(camera.width, camera.height);
  int k = 0;
  for (const BoardPoint& p : boardPoints(board)) {
    const Eigen::Vector3d p_cam = T_cam_board * p.p_board;
    const auto px = camera.project(p_cam);
    ++k;
    if (!px || !camera.inImage(*px, 2.0)) continue;
    const Eigen::Vector2d noise(synth::normalFromKey(synth::hashKey(noise_key, k, 0)),
                                synth::normalFromKey(synth::hashKey(noise_key, k, 1)));
    view.points.push_back({p.id, *px + noise_px * noise});
  }
  if (view.points.empty()) view.failure = "board out of view";
  return view;
}

// n views with the studio's intrinsics-preset board poses.
inline std::vector<ViewObservations> projectedViews(const Camera& camera, const BoardSpec& board,
                                                    int n, std::uint64_t seed, double noise_px) {
  std::vector<ViewObservations> views;
  for (int f = 0; f < n; ++f) {
    const Pose T = synth::intrinsicsBoardPose(camera, board, f, seed);
    views.push_back(projectedView(camera, board, T, noise_px, synth::hashKey(seed, 77, f),
                                  "frame " + std::to_string(f)));
  }
  return views;
}

// Board pose with rotation R (camera frame) whose centre lands on pixel `target` at depth z,
// pulled towards the image centre until the whole pattern is inside the image.
inline Pose boardPoseAt(const Camera& camera, const BoardSpec& board, const Eigen::Matrix3d& R,
                        Eigen::Vector2d target, double z) {
  const Eigen::Vector2d size = board.size_m();
  const Eigen::Vector3d centre_board(0.5 * size.x(), 0.5 * size.y(), 0.0);
  const Eigen::Vector2d image_centre(0.5 * (camera.width - 1), 0.5 * (camera.height - 1));
  Pose T = Pose::Identity();
  T.linear() = R;
  for (int attempt = 0; attempt < 40; ++attempt) {
    const Eigen::Vector3d ray = *camera.unproject(target);
    T.translation() = ray / ray.z() * z - R * centre_board;
    bool inside = true;
    for (const BoardPoint& p : boardPoints(board)) {
      const auto px = camera.project(T * p.p_board);
      if (!px || !camera.inImage(*px, 10.0)) inside = false;
    }
    if (inside) return T;
    target = image_centre + 0.85 * (target - image_centre);
  }
  return T;
}

// Thesis Table 5.2 kind of capture: mostly fronto-parallel views translated over the image,
// runs of near-duplicates (a board held still), and a few tilted views in between, tilted 20–45
// degrees in random directions at 1.0–2.8 m (a real capture's tilted views vary in distance,
// hence in how much of the image the board covers).
struct CaptureView {
  Pose T_cam_board;
  std::string kind;  // "frontal", "duplicate", "tilted"
};
inline std::vector<CaptureView> table52Capture(const Camera& camera, const BoardSpec& board,
                                               std::uint64_t seed = 52) {
  using Eigen::AngleAxisd;
  using Eigen::Vector3d;
  constexpr double kPi = 3.14159265358979323846;
  constexpr double kDeg = kPi / 180.0;
  std::vector<CaptureView> out;
  synth::Rng rng(seed, 0);
  auto pixel = [&](double fx, double fy) {
    return Eigen::Vector2d(fx * (camera.width - 1), fy * (camera.height - 1));
  };
  for (int i = 0; i < 36; ++i) {
    if (i % 6 == 5) {
      const double tilt = rng.uniform(20.0, 45.0) * kDeg;
      const double direction = rng.uniform(0.0, 2.0 * kPi);
      const Eigen::Matrix3d R =
          AngleAxisd(tilt, Vector3d(std::cos(direction), std::sin(direction), 0.0)).toRotationMatrix();
      out.push_back({boardPoseAt(camera, board, R,
                                 pixel(rng.uniform(0.3, 0.7), rng.uniform(0.3, 0.7)),
                                 rng.uniform(1.0, 2.8)),
                     "tilted"});
    } else if (i % 6 >= 3 && !out.empty() && out.back().kind != "tilted") {
      // The board held (nearly) still: millimetres and tenths of a degree.
      Pose T = out.back().T_cam_board;
      T.linear() = T.linear() * AngleAxisd(rng.uniform(-0.3, 0.3) * kDeg,
                                           Vector3d(rng.normal(), rng.normal(), rng.normal()).normalized())
                                    .toRotationMatrix();
      T.translation() += 0.003 * Vector3d(rng.normal(), rng.normal(), rng.normal());
      out.push_back({T, "duplicate"});
    } else {
      out.push_back({boardPoseAt(camera, board, Eigen::Matrix3d::Identity(),
                                 pixel(rng.uniform(0.2, 0.8), rng.uniform(0.2, 0.8)),
                                 rng.uniform(1.1, 1.8)),
                     "frontal"});
    }
  }
  return out;
}

// ---------------------------------------------------------------------------------------------
// Rendered views. The thesis scene at 1200 x 900 costs 0.5-2 s a view, so each set is rendered
// once per build of the renderer: kept in memory for the process and as PNGs under
// PREVIZ_TEST_TMP keyed by the mtime and size of the libraries that render (previz_datasets,
// previz_core; PREVIZ_RENDER_LIBS) and by every scene parameter. A rebuilt renderer starts a
// fresh cache and the stale ones are removed. Images are rendered with
// the requested blur and no noise; noiseCopy() adds a seed's Gaussian noise before detection,
// so several noise seeds share one render (the renderer adds the same kind of noise before
// its 8-bit rounding; doing it after adds a 0.29 grey-level quantisation, 1 % of sigma = 2).

// Renders only the part of the image the printed board (margin included) covers, plus a
// 12 px border, through a cropped copy of the camera (same fx, fy, distortion; principal point
// shifted by the crop offset: the pixels are exactly those of the full render, whose sample
// pattern is the same for every pixel), and fills the rest of the frame with the crop's border
// colour. This is what makes anti-aliasing with many samples per pixel affordable in tests.
inline cv::Mat renderBoardRegion(const Camera& camera, const Pose& T_world_cam,
                                 const synth::Scene& scene, const BoardSpec& board,
                                 const Pose& T_cam_board, const synth::RenderOptions& options) {
  const Eigen::Vector2d size = board.size_m();
  const double m = board.margin_m;
  const Eigen::Vector3d corners[4] = {{-m, -m, 0}, {size.x() + m, -m, 0},
                                      {size.x() + m, size.y() + m, 0}, {-m, size.y() + m, 0}};
  double x0 = 1e9, y0 = 1e9, x1 = -1e9, y1 = -1e9;
  for (int e = 0; e < 4; ++e) {
    for (int k = 0; k <= 64; ++k) {
      const Eigen::Vector3d p = corners[e] + (corners[(e + 1) % 4] - corners[e]) * (k / 64.0);
      const auto px = camera.project(T_cam_board * p);
      if (!px) continue;
      x0 = std::min(x0, px->x()), y0 = std::min(y0, px->y());
      x1 = std::max(x1, px->x()), y1 = std::max(y1, px->y());
    }
  }
  const int border = 12;
  const int u0 = std::max(0, static_cast<int>(std::floor(x0)) - border);
  const int v0 = std::max(0, static_cast<int>(std::floor(y0)) - border);
  const int u1 = std::min(camera.width - 1, static_cast<int>(std::ceil(x1)) + border);
  const int v1 = std::min(camera.height - 1, static_cast<int>(std::ceil(y1)) + border);
  Camera crop = camera;
  crop.width = u1 - u0 + 1;
  crop.height = v1 - v0 + 1;
  crop.cx -= u0;
  crop.cy -= v0;
  const cv::Mat part = synth::renderView(crop, T_world_cam, scene, options).bgr;
  cv::Scalar fill = cv::mean(part.row(0));
  cv::Mat full(camera.height, camera.width, CV_8UC3, fill);
  part.copyTo(full(cv::Rect(u0, v0, crop.width, crop.height)));
  return full;
}

struct RenderedSet {
  Camera camera;
  BoardSpec board;
  std::vector<Pose> T_cam_board;
  std::vector<cv::Mat> images;  // 8-bit BGR, no noise
};

inline std::string rendererStamp() {
#ifdef PREVIZ_RENDER_LIBS
  const std::string libs = PREVIZ_RENDER_LIBS;
#else
  const std::string libs = "/proc/self/exe";
#endif
  std::string stamp;
  size_t start = 0;
  while (start <= libs.size()) {
    const size_t end = std::min(libs.find('|', start), libs.size());
    struct stat st {};
    if (stat(libs.substr(start, end - start).c_str(), &st) == 0) {
      stamp += std::to_string(static_cast<long long>(st.st_mtime)) + "_" +
               std::to_string(static_cast<long long>(st.st_size)) + "_";
    }
    start = end + 1;
  }
  return stamp.empty() ? "nostamp" : stamp;
}

// n views of `board` through `camera` with the intrinsics preset's poses (seed), blur sigma px.
inline const RenderedSet& renderedSet(const Camera& camera, const BoardSpec& board, int n,
                                      std::uint64_t pose_seed, double blur_sigma_px,
                                      int samples_per_pixel) {
  static std::mutex mutex;
  static std::map<std::string, RenderedSet> cache;
  char key[256];
  std::snprintf(key, sizeof(key),
                "%s%s_%dx%d_f%.3f_c%.3f_%.3f_k%.4f_%.4f_%.4f_r%dc%d_sq%.4f_n%d_s%llu_b%.2f_spp%d",
                toString(board.type),
                board.type == BoardType::kAprilGrid && (board.layout != AprilGridLayout::kPreviz || board.tag_border_cells != 1)
                    ? (std::string("_") + toString(board.layout) + std::to_string(board.tag_border_cells)).c_str()
                    : "",
                camera.width, camera.height, camera.fx, camera.cx, camera.cy,
                camera.dist.k1, camera.dist.k2, camera.dist.k3, board.rows, board.cols,
                board.square_m, n, static_cast<unsigned long long>(pose_seed), blur_sigma_px,
                samples_per_pixel);
  std::lock_guard<std::mutex> lock(mutex);
  auto it = cache.find(key);
  if (it != cache.end()) return it->second;

  RenderedSet set;
  set.camera = camera;
  set.board = board;
  const std::filesystem::path root = std::filesystem::path(PREVIZ_TEST_TMP) / "calib_render_cache";
  const std::string stamp = rendererStamp();
  const std::filesystem::path dir = root / stamp / key;
  std::error_code ec;
  if (!std::filesystem::exists(root / stamp, ec)) {
    try {
      for (const auto& old : std::filesystem::directory_iterator(root, ec)) {
        std::filesystem::remove_all(old.path(), ec);
      }
    } catch (const std::filesystem::filesystem_error&) {
      // another test process cleaning at the same time
    }
  }
  synth::StudioConfig config;
  config.with_actor = false;
  config.with_prop = false;
  const synth::Studio studio(config);
  const Pose T_world_cam = lookAt(Eigen::Vector3d(0, -3, 1.5), Eigen::Vector3d(0, 0, 1.5));
  for (int f = 0; f < n; ++f) {
    const Pose T_cam_board = synth::intrinsicsBoardPose(camera, board, f, pose_seed);
    set.T_cam_board.push_back(T_cam_board);
    const std::filesystem::path file = dir / ("frame_" + std::to_string(f) + ".png");
    cv::Mat image;
    if (std::filesystem::exists(file)) image = cv::imread(file.string(), cv::IMREAD_COLOR);
    if (image.empty()) {
      synth::Scene scene = studio.sceneAt(0.0, synth::kLayerStage);
      scene.add(synth::makeBoard(board, T_world_cam * T_cam_board));
      synth::RenderOptions ro;
      ro.samples_per_pixel = samples_per_pixel;
      ro.blur_sigma_px = blur_sigma_px;
      ro.truth = false;
      image = renderBoardRegion(camera, T_world_cam, scene, board, T_cam_board, ro);
      writeImageAtomic(file, image);
    }
    set.images.push_back(image);
  }
  return cache.emplace(key, std::move(set)).first->second;
}

// The image with Gaussian noise of sigma grey levels (seeded), rounded to 8 bits. cv::RNG: a
// per-pixel counter hash costs ~0.3 s an image at 1200 x 900 and the tables detect hundreds.
inline cv::Mat noiseCopy(const cv::Mat& image, double sigma, std::uint64_t seed) {
  cv::RNG rng(seed | 1);
  cv::Mat noise(image.size(), CV_32FC(image.channels()));
  rng.fill(noise, cv::RNG::NORMAL, 0.0, sigma);
  cv::Mat sum;
  image.convertTo(sum, CV_32F);
  sum += noise;
  cv::Mat out;
  sum.convertTo(out, image.type());  // saturating, rounds to nearest
  return out;
}

// Detected views of a rendered set with one noise seed.
inline std::vector<ViewObservations> detectedViews(const RenderedSet& set, double noise_sigma,
                                                   std::uint64_t noise_seed) {
  std::vector<ViewObservations> views(set.images.size());
#pragma omp parallel for schedule(dynamic)
  for (int f = 0; f < static_cast<int>(set.images.size()); ++f) {
    const cv::Mat image = noiseCopy(set.images[f], noise_sigma, synth::hashKey(noise_seed, f));
    try {
      views[f] = detectBoard(image, set.board, {}, "frame " + std::to_string(f));
    } catch (const std::exception& e) {  // never across the parallel region
      views[f].failure = e.what();
    }
    views[f].image_size = image.size();
  }
  return views;
}

// Thesis Table 5.1 scene: 20 views, blur 1 px, noise 2 grey levels. Anti-aliasing: 36 samples
// per pixel for the chessboard, 16 for the others. The renderer's default 4 leave ~0.08 px of
// corner error from coverage quantisation alone (cornerSubPix, noise-free: 0.082 px at 4 spp,
// 0.053 at 16, 0.028 at 36, 0.023 at 64). With the model fit (detect.h) the chessboard's f error
// is +0.02-0.04 px at 16 spp and -0.005-+0.01 px at 36 (5 noise seeds). What the renderer still
// leaves at any spp: its defocus is a discrete Gaussian on pixel values, which shifts edges
// within a few degrees of the pixel axes by up to ~0.02 px depending on their sub-pixel phase
// (calib/detail/pattern_fit.h's fit: 0.011-0.020 px rms there against 0.001 px with a
// continuous blur); it leaves ChArUco's f at +0.015-0.03 px (see intrinsics_test).
constexpr int kTable51Views = 20;
constexpr double kTable51Blur = 1.0;
constexpr double kTable51Noise = 2.0;
inline int table51Spp(BoardType type) {
  return type == BoardType::kChessboard ? 36 : 16;
}
inline const RenderedSet& table51Set(BoardType type) {
  return renderedSet(thesisCamera(), thesisBoard(type), kTable51Views, 1, kTable51Blur,
                     table51Spp(type));
}

}  // namespace previz::calib::testing
