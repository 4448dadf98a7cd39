// Rig calibration outputs: per-camera OpenCV YAML with extrinsics, and the report JSON.
#include "multicam/rig_io.h"

#include <cmath>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "core/camera_io.h"
#include "core/error.h"
#include "core/io.h"

namespace previz::multicam {
namespace {

namespace fs = std::filesystem;

cv::Mat toMat(const Eigen::MatrixXd& m) {
  cv::Mat out(static_cast<int>(m.rows()), static_cast<int>(m.cols()), CV_64F);
  for (int r = 0; r < m.rows(); ++r) {
    for (int c = 0; c < m.cols(); ++c) out.at<double>(r, c) = m(r, c);
  }
  return out;
}

nlohmann::json vec3(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }

// JSON has no NaN/inf: a figure that could not be computed is null.
nlohmann::json number(double x) { return std::isfinite(x) ? nlohmann::json(x) : nlohmann::json(); }

}  // namespace

std::vector<fs::path> writeRigYaml(const Rig& rig, const fs::path& dir) {
  std::vector<fs::path> written;
  for (const RigCamera& rc : rig.cameras) {
    const Camera& cam = rc.camera;
    const fs::path path = dir / (cam.name + ".yaml");
    try {
      cam.validate();
    } catch (const Error& e) {
      ErrorContext context = e.context();
      context.file = path.string();
      throw Error(e.message(), context);
    }
    const Pose T_cam_world = rc.T_world_cam.inverse();
    Eigen::Vector3d rvec, tvec;
    poseToRvecTvec(T_cam_world, rvec, tvec);
    std::string text;
    try {
      cv::FileStorage fs(".yaml", cv::FileStorage::WRITE | cv::FileStorage::MEMORY | cv::FileStorage::FORMAT_YAML);
      fs.writeComment("previz rig camera '" + cam.name + "' (" + rc.role +
                      "): OpenCV Brown-Conrady (k1 k2 p1 p2 k3 [k4 k5 k6]) or fisheye (distortion_model "
                      "equidistant, k1 k2 k3 k4); pixel (0,0) is the centre of the "
                      "top-left pixel; R, t, rvec map world to camera (x_cam = R x_world + t), "
                      "world z up, metres");
      fs << "camera_name" << cam.name;
      fs << "role" << rc.role;
      fs << "image_width" << cam.width;
      fs << "image_height" << cam.height;
      fs << "camera_matrix" << toMat(cam.K());
      // A fisheye as cv::fisheye and ROS write it (it was written as a Brown D, dropping k4).
      if (!cam.dist.isBrown()) fs << "distortion_model" << "equidistant";
      fs << "distortion_coefficients" << openCvDistortion(cam.dist);
      fs << "R" << toMat(T_cam_world.linear());
      fs << "t" << toMat(tvec);
      fs << "rvec" << toMat(rvec);
      fs << "camera_centre_world" << toMat(rc.T_world_cam.translation());
      text = fs.releaseAndGetString();
    } catch (const cv::Exception& e) {
      ErrorContext context;
      context.file = path.string();
      context.camera = cam.name;
      throw Error(std::string("cannot encode camera: ") + e.what(), context);
    }
    writeFileAtomic(path, text);
    written.push_back(path);
  }
  return written;
}

nlohmann::json reportToJson(const RigCalibResult& result) {
  nlohmann::json cameras = nlohmann::json::array();
  for (size_t i = 0; i < result.cameras.size(); ++i) {
    const CameraCalibReport& c = result.cameras[i];
    nlohmann::json jc = {{"camera", c.camera},
                         {"views", c.views},
                         {"points", c.points},
                         {"rejected", c.rejected},
                         {"rms_px", number(c.rms_px)},
                         {"sigma_position_m", number(c.sigma_position_m)},
                         {"sigma_rotation_deg", number(c.sigma_rotation_deg)}};
    nlohmann::json cov = nlohmann::json::array();
    for (int r = 0; r < 6; ++r) {
      nlohmann::json row = nlohmann::json::array();
      for (int k = 0; k < 6; ++k) row.push_back(number(c.covariance(r, k)));
      cov.push_back(row);
    }
    jc["covariance"] = cov;
    jc["covariance_order"] = "rotation x y z (rad, world axes), position x y z (m)";
    if (const RigCamera* rc = result.rig.find(c.camera)) {
      jc["role"] = rc->role;
      jc["position_m"] = vec3(rc->T_world_cam.translation());
      // Where the camera looks, as a person reads it: the optical axis in the world.
      jc["optical_axis_world"] = vec3(rc->T_world_cam.linear().col(2));
    }
    cameras.push_back(jc);
  }
  nlohmann::json tree = nlohmann::json::array();
  for (const GraphEdge& e : result.spanning_tree) {
    tree.push_back({{"a", e.a},
                    {"b", e.b},
                    {"shared_frames", e.shared_frames},
                    {"consistent_frames", e.consistent_frames},
                    {"spread_m", number(e.spread_m)},
                    {"spread_deg", number(e.spread_deg)}});
  }
  return {{"cameras", cameras},
          {"spanning_tree", tree},
          {"world_from_floor", result.world_from_floor},
          {"board_frames", result.T_world_board.size()},
          {"residuals", result.residuals},
          {"rejected", result.rejected},
          {"rms_px", number(result.rms_px)},
          {"sigma_px", number(result.sigma_px)},
          {"covariance_ok", result.covariance_ok},
          {"solve_ms", number(result.solve_ms)},
          {"ceres_iterations", result.ceres_iterations}};
}

nlohmann::json syncToJson(const SyncReport& sync) {
  nlohmann::json cameras = nlohmann::json::array();
  for (const CameraSync& c : sync.cameras) {
    cameras.push_back({{"camera", c.camera},
                       {"offset_frames", c.offset_frames},
                       {"in_sync", c.in_sync},
                       {"pairs", c.pairs},
                       {"spread_at_offset_m", c.spread_at_offset < 0 ? nlohmann::json() : number(c.spread_at_offset)},
                       {"spread_at_zero_m", c.spread_at_zero < 0 ? nlohmann::json() : number(c.spread_at_zero)}});
  }
  nlohmann::json pairs = nlohmann::json::array();
  for (const PairSync& p : sync.pairs) {
    pairs.push_back({{"a", p.a},
                     {"b", p.b},
                     {"best_offset", p.best_offset},
                     {"shared_frames", p.shared_frames},
                     {"spread_at_best_m", number(p.spread_at_best)},
                     {"spread_at_zero_m", p.spread_at_zero < 0 ? nlohmann::json() : number(p.spread_at_zero)},
                     {"decisive", p.decisive}});
  }
  return {{"ok", sync.ok},
          {"max_offset", sync.max_offset},
          {"offset_meaning", "camera's frame f shows what the majority shows at frame f - offset"},
          {"cameras", cameras},
          {"unchecked", sync.unchecked},
          {"pairs", pairs}};
}

nlohmann::json checkToJson(const RigCheckResult& check) {
  nlohmann::json cameras = nlohmann::json::array();
  for (const RigCheckCamera& c : check.cameras) {
    cameras.push_back({{"camera", c.camera},
                       {"views", c.views},
                       {"points", c.points},
                       {"outliers", c.outliers},
                       {"rms_px", number(c.rms_px)},
                       {"median_px", number(c.median_px)},
                       {"flagged", c.flagged},
                       {"reason", c.reason}});
  }
  return {{"ok", check.ok}, {"cameras", cameras}};
}

}  // namespace previz::multicam
