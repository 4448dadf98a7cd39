#include "multicam/rig_calib.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numeric>
#include <optional>
#include <queue>
#include <set>

#include <Eigen/Eigenvalues>

#include "core/error.h"
#include "core/stats.h"
#include "core/stopwatch.h"
#include "core/units.h"
#include "multicam/detail/bundle.h"
#include "multicam/detail/views.h"

namespace previz::multicam {

namespace {

using detail::BundleBoard;
using detail::BundleCamera;
using detail::BundlePoint;
using detail::BundleProblem;
using detail::View;
using ViewsByCamera = std::vector<std::map<int, View>>;

constexpr double kRadToDeg = degrees(1.0);
// Residual cap (px) when candidate board poses are scored: a wrong candidate must not win
// because one view's outliers are even worse under the right one.
constexpr double kScoreCapPx = 10.0;

[[noreturn]] void failField(const std::string& what, const std::string& field) {
  ErrorContext context;
  context.field = field;
  throw Error(what, context);
}

[[noreturn]] void failCamera(const std::string& what, const std::string& camera) {
  ErrorContext context;
  context.camera = camera;
  throw Error(what, context);
}

std::string joinNames(const std::vector<std::string>& names) {
  std::string s;
  for (size_t i = 0; i < names.size(); ++i) s += (i ? ", '" : "'") + names[i] + "'";
  return s;
}

// Free intrinsics per rig camera from options.estimate_intrinsics.
std::vector<std::vector<int>> freeIntrinsics(const Rig& rig, const RigCalibOptions& options) {
  std::vector<std::vector<int>> out(rig.cameras.size());
  for (const std::string& name : options.estimate_intrinsics) {
    if (name == "*") {
      for (size_t i = 0; i < rig.cameras.size(); ++i) out[i] = detail::defaultFreeIntrinsics(rig.cameras[i].camera.dist.model);
      continue;
    }
    bool found = false;
    for (size_t i = 0; i < rig.cameras.size(); ++i) {
      if (rig.cameras[i].camera.name == name) {
        out[i] = detail::defaultFreeIntrinsics(rig.cameras[i].camera.dist.model);
        found = true;
      }
    }
    if (!found) {
      ErrorContext context;
      context.camera = name;
      context.field = "estimate_intrinsics";
      throw Error("not a camera of the rig", context);
    }
  }
  return out;
}

int cameraIndex(const Rig& rig, const std::string& name) {
  for (size_t i = 0; i < rig.cameras.size(); ++i)
    if (rig.cameras[i].camera.name == name) return static_cast<int>(i);
  return -1;
}

// Views of one frame across cameras.
std::map<int, std::vector<const View*>> viewsByFrame(const ViewsByCamera& views) {
  std::map<int, std::vector<const View*>> frames;
  for (const auto& per_camera : views)
    for (const auto& [frame, v] : per_camera) frames[frame].push_back(&v);
  return frames;
}

// Sum of capped squared residuals of a frame's views for a world board pose.
double scoreBoardPose(const Pose& T_world_board, const std::vector<const View*>& views,
                      const std::vector<Camera>& cameras, const std::vector<Pose>& T_world_cam) {
  double score = 0;
  for (const View* v : views) {
    const Pose T_cam_board = T_world_cam[v->camera].inverse() * T_world_board;
    for (double r : detail::viewResiduals(cameras[v->camera], *v, T_cam_board))
      score += std::min(r, kScoreCapPx) * std::min(r, kScoreCapPx);
  }
  return score;
}

// The board pose of a frame from the placed cameras: one candidate per posed view (camera pose
// times its PnP), the one the frame's views agree with best.
std::optional<Pose> bestBoardPose(const std::vector<const View*>& views,
                                  const std::vector<Camera>& cameras,
                                  const std::vector<Pose>& T_world_cam,
                                  const std::vector<bool>& placed) {
  std::optional<Pose> best;
  double best_score = std::numeric_limits<double>::infinity();
  std::vector<const View*> usable;
  for (const View* v : views)
    if (placed[v->camera]) usable.push_back(v);
  for (const View* v : usable) {
    if (!v->posed) continue;
    const Pose candidate = T_world_cam[v->camera] * v->T_cam_board;
    const double score = scoreBoardPose(candidate, usable, cameras, T_world_cam);
    if (score < best_score) {
      best_score = score;
      best = candidate;
    }
  }
  return best;
}

// Adds every point of the given views to the problem, observing board 'board'.
void addViewPoints(const std::vector<const View*>& views, int board, BundleProblem& problem) {
  for (const View* v : views) {
    for (size_t i = 0; i < v->ids.size(); ++i) {
      BundlePoint p;
      p.camera = v->camera;
      p.board = board;
      p.p_board = v->p_board[i];
      p.px = v->px[i];
      problem.points.push_back(p);
    }
  }
}

// Per camera: views used, points kept and rejected, RMS, covariance and sigmas.
std::vector<CameraCalibReport> cameraReports(const BundleProblem& problem,
                                             const std::vector<Eigen::Matrix<double, 6, 6>>& cov) {
  const size_t n = problem.cameras.size();
  std::vector<CameraCalibReport> out(n);
  std::vector<std::set<int>> boards(n);
  std::vector<double> ssr(n, 0.0);
  for (const BundlePoint& p : problem.points) {
    CameraCalibReport& r = out[p.camera];
    if (!p.active) {
      ++r.rejected;
      continue;
    }
    ++r.points;
    boards[p.camera].insert(p.board);
    ssr[p.camera] += detail::bundleResidual(problem, p).squaredNorm();
  }
  for (size_t i = 0; i < n; ++i) {
    CameraCalibReport& r = out[i];
    r.camera = problem.cameras[i].camera.name;
    r.views = static_cast<int>(boards[i].size());
    r.rms_px = r.points > 0 ? std::sqrt(ssr[i] / r.points) : 0.0;
    r.covariance = cov[i];
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> rot(cov[i].topLeftCorner<3, 3>());
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> pos(cov[i].bottomRightCorner<3, 3>());
    r.sigma_rotation_deg = std::sqrt(std::max(0.0, rot.eigenvalues().maxCoeff())) * kRadToDeg;
    r.sigma_position_m = std::sqrt(std::max(0.0, pos.eigenvalues().maxCoeff()));
  }
  return out;
}

detail::BundleOptions bundleOptions(const RigCalibOptions& options) {
  detail::BundleOptions b;
  b.huber_px = options.huber_px;
  b.outlier_px = options.outlier_px;
  b.outlier_rounds = options.outlier_rounds;
  b.min_points = options.min_points;
  b.threads = options.threads;
  return b;
}

// Union-find over camera indices.
struct Components {
  std::vector<int> parent;
  explicit Components(int n) : parent(n) { std::iota(parent.begin(), parent.end(), 0); }
  int find(int i) { return parent[i] == i ? i : parent[i] = find(parent[i]); }
  bool unite(int a, int b) {
    a = find(a);
    b = find(b);
    if (a == b) return false;
    parent[b] = a;
    return true;
  }
};

struct Edge {
  int a = 0, b = 0;
  int shared = 0;
  detail::PoseMean T_a_b;   // relative pose: b's frame -> a's frame
};

std::vector<Edge> cameraEdges(const ViewsByCamera& views) {
  std::vector<Edge> edges;
  const int n = static_cast<int>(views.size());
  for (int a = 0; a < n; ++a) {
    for (int b = a + 1; b < n; ++b) {
      Edge e;
      e.a = a;
      e.b = b;
      std::vector<Pose> samples;
      for (const auto& [frame, va] : views[a]) {
        const auto it = views[b].find(frame);
        if (it == views[b].end()) continue;
        ++e.shared;
        if (va.posed && it->second.posed) samples.push_back(va.T_cam_board * it->second.T_cam_board.inverse());
      }
      if (samples.empty()) continue;
      e.T_a_b = detail::robustMeanPose(samples);
      edges.push_back(e);
    }
  }
  return edges;
}

// Every camera must have a view whose pose a PnP found; the error names all that have none.
// In a take whose every frame shows the floor board (static witnesses) that means the camera
// does not see the floor board, and the message says so.
void requireViews(const RigObservations& obs, const ViewsByCamera& views, const std::vector<Camera>& cameras,
                  int min_points) {
  std::vector<std::string> none;
  for (size_t c = 0; c < cameras.size(); ++c) {
    const bool posed = std::any_of(views[c].begin(), views[c].end(), [](const auto& kv) { return kv.second.posed; });
    if (!posed) none.push_back(cameras[c].name);
  }
  if (none.empty()) return;
  bool floor_only = obs.has_floor;
  for (const CameraDetections& d : obs.cameras)
    for (const auto& [frame, points] : d.frames) floor_only = floor_only && obs.isFloorFrame(frame);
  const bool one = none.size() == 1;
  const std::string what = floor_only ? std::string(one ? " does not" : " do not") +
                                            " see the floor board (every frame of the take is a floor frame; "
                                            "it needs >= " + std::to_string(min_points) +
                                            " board points that one pose explains): move the board or the camera"
                                      : std::string(one ? " has" : " have") + " no usable board view (a frame with >= " +
                                            std::to_string(min_points) + " board points that one pose explains)";
  failCamera(std::string("rig calibrate: camera") + (one ? " " : "s ") + joinNames(none) + what, none.front());
}

// Camera poses in the reference camera's frame (T_ref_cam) from the camera graph: the cameras
// outside the largest connected component are named in an Error; a maximum spanning tree on the
// edges whose relative pose the most frames agree on (ties: the smaller spread) is walked from
// the reference camera. The tree's edges go to 'tree'.
std::vector<Pose> placeCameras(const ViewsByCamera& views, const std::vector<Camera>& cameras, int ref,
                               std::vector<GraphEdge>& tree) {
  const int n = static_cast<int>(cameras.size());
  std::vector<Edge> edges = cameraEdges(views);
  Components components(n);
  for (const Edge& e : edges) components.unite(e.a, e.b);
  std::map<int, std::vector<int>> members;
  for (int c = 0; c < n; ++c) members[components.find(c)].push_back(c);
  int main_root = components.find(ref);
  for (const auto& [root, m] : members)
    if (m.size() > members[main_root].size()) main_root = root;
  std::vector<std::string> cut_off;
  for (int c = 0; c < n; ++c)
    if (components.find(c) != main_root) cut_off.push_back(cameras[c].name);
  if (!cut_off.empty()) {
    failCamera("rig calibrate: camera " + joinNames(cut_off) +
                   " shares no board view with the rest of the rig (directly or through other "
                   "cameras): wave the board where it and its neighbours see it together",
               cut_off.front());
  }

  std::sort(edges.begin(), edges.end(), [](const Edge& x, const Edge& y) {
    if (x.T_a_b.inliers != y.T_a_b.inliers) return x.T_a_b.inliers > y.T_a_b.inliers;
    return x.T_a_b.spread_m < y.T_a_b.spread_m;
  });
  Components tree_components(n);
  std::vector<std::vector<std::pair<int, Pose>>> adjacent(n);  // (neighbour, T_self_neighbour)
  for (const Edge& e : edges) {
    if (!tree_components.unite(e.a, e.b)) continue;
    adjacent[e.a].push_back({e.b, e.T_a_b.mean});
    adjacent[e.b].push_back({e.a, e.T_a_b.mean.inverse()});
    GraphEdge g;
    g.a = cameras[e.a].name;
    g.b = cameras[e.b].name;
    g.shared_frames = e.shared;
    g.consistent_frames = e.T_a_b.inliers;
    g.spread_m = e.T_a_b.spread_m;
    g.spread_deg = e.T_a_b.spread_rad * kRadToDeg;
    tree.push_back(g);
  }
  std::vector<Pose> T_ref_cam(n, Pose::Identity());
  std::vector<bool> placed(n, false);
  std::queue<int> queue;
  queue.push(ref);
  placed[ref] = true;
  while (!queue.empty()) {
    const int a = queue.front();
    queue.pop();
    for (const auto& [b, T_a_b] : adjacent[a]) {
      if (placed[b]) continue;
      T_ref_cam[b] = T_ref_cam[a] * T_a_b;
      placed[b] = true;
      queue.push(b);
    }
  }
  return T_ref_cam;
}

// T_world_ref from the floor frames: every posed floor view gives one (the floor board's known
// pose times the view's PnP and the camera's place in the rig); their robust mean.
Pose worldFromFloor(const RigObservations& obs, const std::map<int, std::vector<const View*>>& frames,
                    const std::vector<Pose>& T_ref_cam, int min_points) {
  std::vector<Pose> samples;
  for (const auto& [frame, fviews] : frames) {
    if (!obs.isFloorFrame(frame)) continue;
    for (const View* v : fviews)
      if (v->posed) samples.push_back(obs.floor.T_world_board * v->T_cam_board.inverse() * T_ref_cam[v->camera].inverse());
  }
  if (samples.empty()) {
    failField("rig calibrate: no camera sees the floor board (>= " + std::to_string(min_points) +
                  " points) in the floor frames, so the world frame cannot be set",
              "floor");
  }
  return detail::robustMeanPose(samples).mean;
}

// The boards of the solve, one per useful frame, with their initial poses and every point of
// their views. board_frame: the frame of each board.
void addBoards(const RigObservations& obs, const std::map<int, std::vector<const View*>>& frames,
               const std::vector<std::vector<int>>& free_intrinsics, const std::vector<Camera>& cameras,
               const std::vector<Pose>& T_world_cam, BundleProblem& problem, std::vector<int>& board_frame) {
  const std::vector<bool> placed(cameras.size(), true);
  for (const auto& [frame, fviews] : frames) {
    int posed = 0;
    for (const View* v : fviews) posed += v->posed ? 1 : 0;
    const bool floor = obs.isFloorFrame(frame);
    // A board seen by one camera only says nothing about the rig, unless it fixes the world
    // (floor) or the camera's intrinsics are being solved.
    const bool useful = floor ? posed >= 1
                              : posed >= 2 || (posed == 1 && fviews.size() == 1 &&
                                               !free_intrinsics[fviews.front()->camera].empty());
    if (!useful) continue;
    BundleBoard board;
    if (floor) {
      board.T_world_board = obs.floor.T_world_board;
      board.fixed = true;
      board.static_scene = 0;
    } else {
      const std::optional<Pose> T = bestBoardPose(fviews, cameras, T_world_cam, placed);
      if (!T) continue;
      board.T_world_board = *T;
    }
    addViewPoints(fviews, static_cast<int>(problem.boards.size()), problem);
    problem.boards.push_back(board);
    board_frame.push_back(frame);
  }
}

// Re-survey: one board per frame where the target camera has a posed view and the floor or
// another camera fixes the board, posed from the other (held) cameras, with their points.
// Returns the target's view of each board (same order).
std::vector<const View*> boardsFromOthers(const RigObservations& capture, const ViewsByCamera& views, int target,
                                          const std::vector<Camera>& cameras, const std::vector<Pose>& T_world_cam,
                                          BundleProblem& problem) {
  std::vector<bool> others(cameras.size(), true);
  others[target] = false;
  std::vector<const View*> target_views;
  for (const auto& [frame, fviews] : viewsByFrame(views)) {
    const auto own = views[target].find(frame);
    if (own == views[target].end() || !own->second.posed) continue;
    std::vector<const View*> fixed_views;
    for (const View* v : fviews)
      if (v->camera != target) fixed_views.push_back(v);
    BundleBoard board;
    if (capture.isFloorFrame(frame)) {
      board.T_world_board = capture.floor.T_world_board;
      board.fixed = true;
      board.static_scene = 0;
    } else {
      const std::optional<Pose> T = bestBoardPose(fixed_views, cameras, T_world_cam, others);
      if (!T) continue;
      board.T_world_board = *T;
    }
    addViewPoints(fixed_views, static_cast<int>(problem.boards.size()), problem);
    problem.boards.push_back(board);
    target_views.push_back(&own->second);
  }
  return target_views;
}

// checkRig: the board pose of one frame that most of its views agree with (median residual
// below agree_px; one candidate per view, its own PnP through its camera's pose; ties: the
// smaller capped squared error). nullopt when fewer than two views agree: the frame cannot tell
// a moved camera from the others. 'agreeing' gets the views that agree.
std::optional<Pose> consensusBoardPose(const std::vector<const View*>& views, const std::vector<Camera>& cameras,
                                       const std::vector<Pose>& T_world_cam, double agree_px,
                                       std::vector<const View*>& agreeing) {
  auto agrees = [&](const View& v, const Pose& T_world_board) {
    return median(detail::viewResiduals(cameras[v.camera], v, T_world_cam[v.camera].inverse() * T_world_board)) <
           agree_px;
  };
  if (views.size() < 2) return std::nullopt;
  int best_count = 0;
  double best_score = std::numeric_limits<double>::infinity();
  Pose best = Pose::Identity();
  for (const View* v : views) {
    if (!v->posed) continue;
    const Pose candidate = T_world_cam[v->camera] * v->T_cam_board;
    int count = 0;
    for (const View* w : views) count += agrees(*w, candidate) ? 1 : 0;
    const double score = scoreBoardPose(candidate, views, cameras, T_world_cam);
    if (count > best_count || (count == best_count && score < best_score)) {
      best_count = count;
      best_score = score;
      best = candidate;
    }
  }
  if (best_count < 2) return std::nullopt;
  agreeing.clear();
  for (const View* w : views)
    if (agrees(*w, best)) agreeing.push_back(w);
  return best;
}

// checkRig's verdict on one camera from the residual norms of its views. Gross outliers (a
// misread corner) say nothing about the camera's pose: counted, left out of the RMS.
RigCheckCamera checkCamera(const std::string& name, const std::vector<double>& norms, int views, double flag_px) {
  RigCheckCamera rc;
  rc.camera = name;
  rc.views = views;
  if (norms.empty()) {
    rc.reason = "not checked: no board view shared with another camera in this capture";
    return rc;
  }
  rc.median_px = median(norms);
  const double cut = std::max(3.0 * flag_px, 5.0 * rc.median_px / 1.1774);
  double ssr = 0;
  for (double r : norms) {
    if (r > cut) {
      ++rc.outliers;
      continue;
    }
    ssr += r * r;
    ++rc.points;
  }
  rc.rms_px = rc.points > 0 ? std::sqrt(ssr / rc.points) : 0.0;
  rc.flagged = rc.rms_px > flag_px;
  if (rc.flagged) {
    char line[160];
    std::snprintf(line, sizeof(line), "RMS %.2f px > %.2f px over %d views: bumped or wrong calibration", rc.rms_px,
                  flag_px, rc.views);
    rc.reason = line;
  }
  return rc;
}

}  // namespace

void RigCalibOptions::validate() const {
  auto bad = [](const std::string& field, const std::string& what) {
    failField("rig calibrate: " + field + " " + what, field);
  };
  if (!(huber_px > 0)) bad("huber_px", "must be > 0 (got " + std::to_string(huber_px) + ")");
  if (!(outlier_px >= 0)) bad("outlier_px", "must be >= 0 (got " + std::to_string(outlier_px) + ")");
  if (outlier_rounds < 0) bad("outlier_rounds", "must be >= 0 (got " + std::to_string(outlier_rounds) + ")");
  if (min_points < 4) bad("min_points", "must be >= 4 (got " + std::to_string(min_points) + ")");
  if (threads < 0) bad("threads", "must be >= 0 (got " + std::to_string(threads) + ")");
}

RigCalibResult calibrateRig(const RigObservations& obs, const Rig& initial,
                            const RigCalibOptions& options) {
  const Stopwatch start;
  options.validate();
  initial.validate();
  const int n = static_cast<int>(initial.cameras.size());
  if (n == 0) failField("rig calibrate: the rig has no cameras", "cameras");
  const std::vector<std::vector<int>> free_intrinsics = freeIntrinsics(initial, options);
  int ref = 0;
  if (!options.reference_camera.empty()) {
    ref = cameraIndex(initial, options.reference_camera);
    if (ref < 0) {
      ErrorContext context;
      context.camera = options.reference_camera;
      context.field = "reference_camera";
      throw Error("rig calibrate: the reference camera is not a camera of the rig", context);
    }
  }
  std::vector<Camera> cameras;
  for (const RigCamera& c : initial.cameras) cameras.push_back(c.camera);

  // ---- initialisation: views, camera graph, world frame, board poses
  const ViewsByCamera views = detail::collectViews(obs, initial, options.min_points, options.threads);
  requireViews(obs, views, cameras, options.min_points);
  RigCalibResult result;
  const std::vector<Pose> T_ref_cam = placeCameras(views, cameras, ref, result.spanning_tree);
  const std::map<int, std::vector<const View*>> frames = viewsByFrame(views);
  result.world_from_floor = obs.has_floor;
  const Pose T_world_ref = obs.has_floor ? worldFromFloor(obs, frames, T_ref_cam, options.min_points) : Pose::Identity();
  BundleProblem problem;
  std::vector<Pose> T_world_cam(n);
  for (int c = 0; c < n; ++c) {
    T_world_cam[c] = T_world_ref * T_ref_cam[c];
    BundleCamera bc;
    bc.camera = cameras[c];
    bc.T_world_cam = T_world_cam[c];
    bc.pose_fixed = !obs.has_floor && c == ref;  // the gauge without a floor
    bc.free_intrinsics = free_intrinsics[c];
    problem.cameras.push_back(bc);
  }
  std::vector<int> board_frame;
  addBoards(obs, frames, free_intrinsics, cameras, T_world_cam, problem, board_frame);

  // ---- bundle adjustment and covariances
  const detail::BundleStats stats = detail::solveBundle(problem, bundleOptions(options));
  result.ceres_iterations = stats.iterations;
  result.sigma_px = detail::bundleSigmaPx(problem);
  const auto cov = detail::bundleCameraCovariances(problem, result.sigma_px, &result.covariance_ok);
  result.cameras = cameraReports(problem, cov);
  for (const CameraCalibReport& r : result.cameras) {
    if (r.points < options.min_points) {
      failCamera("rig calibrate: camera '" + r.camera + "' kept " + std::to_string(r.points) +
                     " points after outlier rejection: its intrinsics or detections are wrong",
                 r.camera);
    }
  }

  // ---- results
  result.rig = initial;
  result.rig.world_frame =
      obs.has_floor ? Rig{}.world_frame : "camera '" + cameras[ref].name + "' (no floor board)";
  for (int c = 0; c < n; ++c) {
    result.rig.cameras[c].camera = problem.cameras[c].camera;
    result.rig.cameras[c].T_world_cam = problem.cameras[c].T_world_cam;
  }
  double ssr = 0;
  std::vector<bool> board_used(problem.boards.size(), false);
  for (const BundlePoint& p : problem.points) {
    if (!p.active) {
      ++result.rejected;
      continue;
    }
    ++result.residuals;
    board_used[p.board] = true;
    ssr += detail::bundleResidual(problem, p).squaredNorm();
  }
  result.rms_px = result.residuals > 0 ? std::sqrt(ssr / result.residuals) : 0.0;
  for (size_t j = 0; j < problem.boards.size(); ++j)
    if (board_used[j]) result.T_world_board[board_frame[j]] = problem.boards[j].T_world_board;
  result.solve_ms = start.ms();
  return result;
}

ResurveyResult resurveyCamera(const Rig& rig, const std::string& camera,
                              const RigObservations& capture, const RigCalibOptions& options) {
  options.validate();
  rig.validate();
  const int target = cameraIndex(rig, camera);
  if (target < 0) {
    ErrorContext context;
    context.camera = camera;
    context.field = "camera";
    throw Error("rig resurvey: not a camera of the rig", context);
  }
  const int n = static_cast<int>(rig.cameras.size());
  const std::vector<std::vector<int>> free_intrinsics = freeIntrinsics(rig, options);
  std::vector<Camera> cameras;
  std::vector<Pose> T_world_cam;
  for (const RigCamera& c : rig.cameras) {
    cameras.push_back(c.camera);
    T_world_cam.push_back(c.T_world_cam);
  }
  const ViewsByCamera views = detail::collectViews(capture, rig, options.min_points, options.threads);
  if (std::none_of(views[target].begin(), views[target].end(), [](const auto& kv) { return kv.second.posed; }))
    failCamera("rig resurvey: the camera has no usable board view in the capture", camera);

  // ---- board poses from the fixed cameras alone, in the frames the camera shares with them
  BundleProblem problem;
  for (int c = 0; c < n; ++c) {
    BundleCamera bc;
    bc.camera = cameras[c];
    bc.T_world_cam = T_world_cam[c];
    bc.pose_fixed = true;
    problem.cameras.push_back(bc);
  }
  const std::vector<const View*> target_views = boardsFromOthers(capture, views, target, cameras, T_world_cam, problem);
  if (problem.boards.empty())
    failCamera("rig resurvey: the camera shares no board view with the other cameras in the capture", camera);
  const detail::BundleOptions bundle_options = bundleOptions(options);
  detail::solveBundle(problem, bundle_options);

  // ---- the camera: robust mean of its per-frame poses, then camera and boards together with
  // every other camera held.
  std::vector<Pose> samples;
  for (size_t j = 0; j < target_views.size(); ++j)
    samples.push_back(problem.boards[j].T_world_board * target_views[j]->T_cam_board.inverse());
  problem.cameras[target].T_world_cam = detail::robustMeanPose(samples).mean;
  problem.cameras[target].pose_fixed = false;
  problem.cameras[target].free_intrinsics = free_intrinsics[target];
  for (size_t j = 0; j < target_views.size(); ++j) addViewPoints({target_views[j]}, static_cast<int>(j), problem);
  for (BundlePoint& p : problem.points) p.active = true;  // a fresh start for the rejection rounds
  detail::solveBundle(problem, bundle_options);

  const double sigma = detail::bundleSigmaPx(problem);
  bool ok = false;
  const auto cov = detail::bundleCameraCovariances(problem, sigma, &ok);
  const std::vector<CameraCalibReport> reports = cameraReports(problem, cov);

  ResurveyResult result;
  result.before = rig.cameras[target];
  result.after = rig.cameras[target];
  result.after.camera = problem.cameras[target].camera;
  result.after.T_world_cam = problem.cameras[target].T_world_cam;
  result.report = reports[target];
  if (result.report.points < options.min_points)
    failCamera("rig resurvey: the camera kept too few points after outlier rejection", camera);
  result.moved_m = translationDistance(result.before.T_world_cam, result.after.T_world_cam);
  result.rotated_deg = rotationDistance(result.before.T_world_cam, result.after.T_world_cam) * kRadToDeg;
  result.rig = rig;
  result.rig.cameras[target] = result.after;
  return result;
}

RigCheckResult checkRig(const Rig& rig, const RigObservations& capture, double flag_px) {
  if (!(flag_px > 0)) failField("rig check: flag_px must be > 0 (got " + std::to_string(flag_px) + ")", "flag_px");
  rig.validate();
  const int n = static_cast<int>(rig.cameras.size());
  std::vector<Camera> cameras;
  std::vector<Pose> T_world_cam;
  BundleProblem problem;
  for (const RigCamera& c : rig.cameras) {
    cameras.push_back(c.camera);
    T_world_cam.push_back(c.T_world_cam);
    BundleCamera bc;
    bc.camera = c.camera;
    bc.T_world_cam = c.T_world_cam;
    bc.pose_fixed = true;
    problem.cameras.push_back(bc);
  }
  constexpr int kMinPoints = 6;
  const ViewsByCamera views = detail::collectViews(capture, rig, kMinPoints, 0);

  // ---- per frame: the board pose the cameras agree on, refined on the agreeing views
  std::vector<std::vector<const View*>> checked;
  for (const auto& [frame, fviews] : viewsByFrame(views)) {
    std::vector<const View*> agreeing;
    const std::optional<Pose> T = consensusBoardPose(fviews, cameras, T_world_cam, 3.0 * flag_px, agreeing);
    if (!T) continue;
    BundleBoard board;
    board.T_world_board = *T;
    addViewPoints(agreeing, static_cast<int>(problem.boards.size()), problem);
    problem.boards.push_back(board);
    checked.push_back(fviews);
  }
  detail::BundleOptions bundle_options;
  bundle_options.outlier_rounds = 2;
  bundle_options.min_points = kMinPoints;
  detail::solveBundle(problem, bundle_options);

  // ---- every view of the checked frames against the refined board poses
  std::vector<std::vector<double>> norms(n);
  std::vector<int> view_count(n, 0);
  for (size_t j = 0; j < checked.size(); ++j) {
    for (const View* v : checked[j]) {
      const Pose T_cam_board = T_world_cam[v->camera].inverse() * problem.boards[j].T_world_board;
      const std::vector<double> r = detail::viewResiduals(cameras[v->camera], *v, T_cam_board);
      norms[v->camera].insert(norms[v->camera].end(), r.begin(), r.end());
      ++view_count[v->camera];
    }
  }
  RigCheckResult result;
  for (int c = 0; c < n; ++c) {
    result.cameras.push_back(checkCamera(cameras[c].name, norms[c], view_count[c], flag_px));
    if (result.cameras.back().flagged) result.ok = false;
  }
  return result;
}

}  // namespace previz::multicam
