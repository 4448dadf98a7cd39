#include "calib/frontal.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>
#include <unordered_map>

#include <opencv2/imgproc.hpp>

#include "calib/detail/projection.h"
#include "core/error.h"
#include "core/stopwatch.h"

namespace previz::calib {

namespace {

[[noreturn]] void failField(const std::string& field, const std::string& what) {
  ErrorContext context;
  context.field = field;
  throw Error("frontal: " + field + " " + what, context);
}

}  // namespace

void FrontalOptions::validate() const {
  if (max_iterations < 1)
    failField("max_iterations", "must be >= 1 (got " + std::to_string(max_iterations) + ")");
  if (!(converge_sigma >= 0)) failField("converge_sigma", "must be >= 0");
  if (!(resolution > 0) || !std::isfinite(resolution))
    failField("resolution", "must be > 0 (got " + std::to_string(resolution) + ")");
  if (max_frontal_px < 64)
    failField("max_frontal_px", "must be >= 64 (got " + std::to_string(max_frontal_px) + ")");
  if (interpolation != cv::INTER_LINEAR && interpolation != cv::INTER_CUBIC)
    failField("interpolation", "must be 1 (linear) or 2 (cubic)");
  if (!(max_shift_px > 0)) failField("max_shift_px", "must be > 0");
  detect.validate();
  solve.validate();
}

FrontalView makeFrontalView(const cv::Mat& image, const Camera& camera, const Pose& T_cam_board,
                            const BoardSpec& board, const FrontalOptions& options) {
  // Magnifications the view gives the board (px per metre) over its points: the frontal image
  // takes the finest (no part of the board loses resolution) and the median tells how much the
  // typical corner is upsampled (redetectFrontal widens the sub-pixel window by as much).
  std::vector<double> scales;
  constexpr double kStep = 1e-3;
  for (const BoardPoint& p : boardPoints(board)) {
    const auto a = camera.project(T_cam_board * p.p_board);
    const auto bx = camera.project(T_cam_board * (p.p_board + Eigen::Vector3d(kStep, 0, 0)));
    const auto by = camera.project(T_cam_board * (p.p_board + Eigen::Vector3d(0, kStep, 0)));
    if (!a || !bx || !by) continue;
    scales.push_back((*bx - *a).norm() / kStep);
    scales.push_back((*by - *a).norm() / kStep);
  }
  double scale = 0, median_scale = 0;
  if (!scales.empty()) {
    std::nth_element(scales.begin(), scales.begin() + scales.size() / 2, scales.end());
    median_scale = scales[scales.size() / 2];
    scale = *std::max_element(scales.begin(), scales.end());
  }
  FrontalView view;
  if (!(scale > 0)) return view;
  const Eigen::Vector2d size = board.size_m();
  // The printed margin plus a little beyond it, so that detectors see the board's outline.
  const double pad = board.margin_m + 0.25 * board.square_m;
  view.x0_m = -pad;
  view.y0_m = -pad;
  const double extent = std::max(size.x(), size.y()) + 2 * pad;
  view.px_per_m = std::min(options.resolution * scale, options.max_frontal_px / extent);
  view.upsampling = median_scale > 0 ? view.px_per_m / median_scale : 1.0;
  const int w = static_cast<int>(std::ceil((size.x() + 2 * pad) * view.px_per_m));
  const int h = static_cast<int>(std::ceil((size.y() + 2 * pad) * view.px_per_m));
  cv::Mat map(h, w, CV_32FC2);
  const Eigen::Matrix3d R = T_cam_board.linear();
  const Eigen::Vector3d t = T_cam_board.translation();
#pragma omp parallel for schedule(static)
  for (int v = 0; v < h; ++v) {
    cv::Vec2f* row = map.ptr<cv::Vec2f>(v);
    for (int u = 0; u < w; ++u) {
      const Eigen::Vector3d p = R * view.boardPoint(Eigen::Vector2d(u, v)) + t;
      const auto px = camera.project(p);
      row[u] = px ? cv::Vec2f(static_cast<float>(px->x()), static_cast<float>(px->y()))
                  : cv::Vec2f(-1e4f, -1e4f);
    }
  }
  cv::remap(image, view.image, map, cv::noArray(), options.interpolation, cv::BORDER_CONSTANT,
            cv::Scalar::all(0));
  return view;
}

ViewObservations redetectFrontal(const cv::Mat& image, const ViewObservations& previous,
                                 const Camera& camera, const Pose& T_cam_board,
                                 const BoardSpec& board, const FrontalOptions& options) {
  ViewObservations out;
  out.source = previous.source;
  out.image_size = image.size();
  out.focus = previous.focus;
  const FrontalView frontal = makeFrontalView(image, camera, T_cam_board, board, options);
  if (frontal.image.empty()) {
    out.failure = "no frontal image (board not in front of the camera)";
    return out;
  }
  // The same physical window as in the original image for the typical corner, but never more
  // than a third of a square (neighbouring corners).
  DetectOptions detect = options.detect;
  const double square_px = board.square_m * frontal.px_per_m;
  detect.subpixel_window_px = std::max(
      options.detect.subpixel_window_px,
      std::min(static_cast<int>(std::lround(options.detect.subpixel_window_px * frontal.upsampling)),
               static_cast<int>(square_px / 3.0)));
  const ViewObservations found =
      detectBoard(frontal.image, board, detect, previous.source + " (frontal)");
  if (!found.found()) {
    out.failure = "frontal image: " + found.failure;
    return out;
  }
  std::unordered_map<int, Eigen::Vector2d> before;
  for (const Observation& o : previous.points) before[o.id] = o.px;
  int dropped = 0;
  for (const Observation& o : found.points) {
    const auto px = camera.project(T_cam_board * frontal.boardPoint(o.px));
    if (!px) continue;
    auto it = before.find(o.id);
    if (it != before.end() && (*px - it->second).norm() > options.max_shift_px) {
      ++dropped;
      continue;
    }
    out.points.push_back({o.id, *px});
  }
  // Most points far from where they were: the frontal detection is of a different labelling
  // (a symmetric board turned round), not a refinement.
  if (dropped > static_cast<int>(out.points.size())) {
    out.points.clear();
    out.failure = "frontal detection disagrees with the original labelling";
  }
  return out;
}

FrontalResult refineFrontal(const std::function<cv::Mat(size_t)>& image_of,
                            const std::vector<ViewObservations>& views, const BoardSpec& board,
                            const IntrinsicsResult& initial, const FrontalOptions& options) {
  options.validate();
  if (initial.views.size() != views.size()) {
    throw Error("frontal: the initial solve has " + std::to_string(initial.views.size()) +
                " views, the observations " + std::to_string(views.size()));
  }
  const bool replace_known =
      options.replace == FrontalReplace::kAll ||
      (options.replace == FrontalReplace::kAuto && board.type == BoardType::kCircles);
  FrontalResult out;
  out.result = initial;
  out.views = views;
  FrontalIteration start;
  start.camera = initial.camera;
  start.sigma = initial.sigma;
  start.rms_px = initial.rms_px;
  start.points = initial.points_used;
  out.iterations.push_back(start);

  for (int it = 1; it <= options.max_iterations; ++it) {
    const Stopwatch t0;
    const IntrinsicsResult& current = out.result;
    std::vector<ViewObservations> next = out.views;
    FrontalIteration round;
    round.iteration = it;
    double shift_sum = 0;
    int shift_count = 0;
    for (size_t v = 0; v < views.size(); ++v) {
      if (!current.views[v].used) continue;
      const cv::Mat image = image_of(v);
      if (image.empty()) {
        ErrorContext context;
        context.file = views[v].source;
        throw Error("frontal: image could not be read", context);
      }
      const ViewObservations redetected = redetectFrontal(
          image, out.views[v], current.camera, current.views[v].T_cam_board, board, options);
      if (static_cast<int>(redetected.points.size()) < options.solve.min_points_per_view) {
        ++round.views_kept;
        continue;
      }
      std::unordered_map<int, Eigen::Vector2d> before;
      for (const Observation& o : out.views[v].points) before[o.id] = o.px;
      std::vector<Observation> merged;
      for (const Observation& o : redetected.points) {
        auto b = before.find(o.id);
        if (b == before.end()) {
          merged.push_back(o);
          continue;
        }
        if (!replace_known) {
          merged.push_back({o.id, b->second});
          continue;
        }
        shift_sum += (o.px - b->second).norm();
        ++shift_count;
        merged.push_back(o);
      }
      // Keep the points the frontal detection missed.
      for (const Observation& o : out.views[v].points) {
        const bool present = std::any_of(merged.begin(), merged.end(),
                                         [&](const Observation& m) { return m.id == o.id; });
        if (!present) merged.push_back(o);
      }
      next[v].points = std::move(merged);
      ++round.views_redetected;
    }
    IntrinsicsOptions solve = options.solve;
    solve.initial_camera = current.camera;
    solve.opencv_init = false;
    solve.camera_name = current.camera.name;
    IntrinsicsResult refined = calibrateIntrinsics(next, board, solve);

    double intr_old[kIntrinsicCount], intr_new[kIntrinsicCount];
    detail::cameraToVector(current.camera, intr_old);
    detail::cameraToVector(refined.camera, intr_new);
    for (int k = 0; k < kIntrinsicCount; ++k) {
      if (refined.sigma[k] > 0) {
        round.max_change_sigma =
            std::max(round.max_change_sigma, std::abs(intr_new[k] - intr_old[k]) / refined.sigma[k]);
      }
    }
    round.camera = refined.camera;
    round.sigma = refined.sigma;
    round.rms_px = refined.rms_px;
    round.points = refined.points_used;
    round.mean_shift_px = shift_count > 0 ? shift_sum / shift_count : 0.0;
    round.ms = t0.ms();
    out.iterations.push_back(round);
    out.result = std::move(refined);
    out.views = std::move(next);
    if (round.max_change_sigma < options.converge_sigma) {
      out.converged = true;
      break;
    }
  }
  return out;
}

std::string FrontalResult::report() const {
  std::ostringstream s;
  char line[256];
  s << "frontal refinement (Datta et al. 2009): " << (iterations.size() - 1) << " round(s), "
    << (converged ? "converged" : "not converged") << "\n";
  s << "  round   RMS px   points  redetected  kept  mean shift px  max change/sigma"
       "        fx          cx          cy          k1\n";
  for (const FrontalIteration& it : iterations) {
    std::snprintf(line, sizeof(line),
                  "  %5d %8.4f %8d %11d %5d %14.4f %17.3f %11.4f %11.4f %11.4f %11.6f\n",
                  it.iteration, it.rms_px, it.points, it.views_redetected, it.views_kept,
                  it.mean_shift_px, it.max_change_sigma, it.camera.fx, it.camera.cx, it.camera.cy,
                  it.camera.dist.k1);
    s << line;
  }
  return s.str();
}

}  // namespace previz::calib
