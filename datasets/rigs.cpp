#include "datasets/rigs.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

#include <Eigen/Geometry>

#include "core/error.h"
#include "core/names.h"
#include "core/units.h"
#include "datasets/random.h"
#include "datasets/studio.h"

namespace previz::synth {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDeg = radians(1.0);

// Streams of the layout generator, so adding draws to one never shifts another.
enum Stream : std::uint64_t {
  kStreamWitnessLens = 101,
  kStreamWitnessPose = 102,
  kStreamIntrinsicsBoard = 201,
  kStreamRigBoard = 301,
};

// True when the whole image lies comfortably inside the invertible domain: every border pixel
// (sampled densely) undistorts, and its ideal radius stays below 90 % of the turning radius.
bool lensCoversImage(const Camera& c) {
  const double r_max = c.maxInvertibleRadius();
  const int steps = 64;
  for (int i = 0; i <= steps; ++i) {
    const double s = static_cast<double>(i) / steps;
    const Eigen::Vector2d border[4] = {
        {-0.5 + s * c.width, -0.5},
        {-0.5 + s * c.width, c.height - 0.5},
        {-0.5, -0.5 + s * c.height},
        {c.width - 0.5, -0.5 + s * c.height}};
    for (const Eigen::Vector2d& px : border) {
      const InverseResult r = c.undistort(c.pixelToNormalized(px));
      if (!r.ok()) return false;
      if (std::isfinite(r_max) && r.point.norm() > 0.9 * r_max) return false;
      if (!c.inInvertibleDomain(r.point)) return false;
    }
  }
  return true;
}

// Board outline (printed margin included) in the board frame.
std::vector<Eigen::Vector3d> boardOutline(const BoardSpec& spec) {
  const Eigen::Vector2d size = spec.size_m();
  const double m = spec.margin_m;
  return {{-m, -m, 0}, {size.x() + m, -m, 0}, {size.x() + m, size.y() + m, 0},
          {-m, size.y() + m, 0}};
}

class OnTop : public Primitive {
 public:
  OnTop(std::shared_ptr<const Primitive> inner, double tolerance_m)
      : inner_(std::move(inner)), tolerance_m_(tolerance_m) {
    bound_centre = inner_->bound_centre;
    bound_radius = inner_->bound_radius;
  }
  bool intersect(const Ray& ray, double t_min, Hit& hit) const override {
    Hit probe = hit;
    probe.t = hit.t + tolerance_m_;
    if (!inner_->intersect(ray, t_min, probe)) return false;
    hit = probe;
    return true;
  }
  void shade(const Ray& ray, Hit& hit) const override { inner_->shade(ray, hit); }

 private:
  std::shared_ptr<const Primitive> inner_;
  double tolerance_m_;
};

}  // namespace

std::shared_ptr<const Primitive> onTopOf(std::shared_ptr<const Primitive> inner,
                                         double tolerance_m) {
  if (!inner) throw Error("onTopOf: null primitive");
  return std::make_shared<OnTop>(std::move(inner), tolerance_m);
}

std::string witnessName(int index) {
  char name[32];
  std::snprintf(name, sizeof(name), "witness%02d", index + 1);
  return name;
}

RigCamera witnessCamera(int index, int count, std::uint64_t seed, int width, int height, bool fisheye) {
  if (index < 0 || index >= count) {
    ErrorContext context;
    context.field = "witness_cameras";
    throw Error("witness index " + std::to_string(index) + " out of range [0, " +
                    std::to_string(count) + ")",
                context);
  }
  Rng lens_rng(hashKey(seed, kStreamWitnessLens, static_cast<std::uint64_t>(index)));
  Camera c;
  c.name = witnessName(index);
  c.width = kWitnessDesignWidth;
  c.height = kWitnessDesignHeight;
  c.fx = lens_rng.uniform(800.0, 950.0);
  c.fy = c.fx;
  c.cx = 0.5 * (c.width - 1) + lens_rng.uniform(-6.0, 6.0);
  c.cy = 0.5 * (c.height - 1) + lens_rng.uniform(-4.0, 4.0);
  c.dist.k1 = lens_rng.uniform(-0.25, 0.05);
  c.dist.p1 = lens_rng.uniform(-0.001, 0.001);
  c.dist.p2 = lens_rng.uniform(-0.001, 0.001);
  c.dist.k3 = 0.0;
  if (fisheye) {
    // The same draws for the position of the principal point; a short equidistant-like lens.
    c.fx = c.fy = lens_rng.uniform(470.0, 520.0);
    c.dist = Distortion::kannalaBrandt(lens_rng.uniform(-0.02, 0.03), lens_rng.uniform(-0.01, 0.005), 0.001, 0.0);
  }
  // Strong barrel lenses need a positive k2 to keep the corners invertible (the radial map is
  // monotone everywhere when 9 k1^2 < 20 k2); redraw k2 until the whole image is covered.
  bool covered = fisheye && lensCoversImage(c);
  for (int attempt = 0; attempt < 64 && !covered && !fisheye; ++attempt) {
    c.dist.k2 = lens_rng.uniform(-0.02, 0.05);
    covered = lensCoversImage(c);
  }
  if (!covered && !fisheye) {
    c.dist.k2 = 0.5 * c.dist.k1 * c.dist.k1 + 0.01;
    covered = lensCoversImage(c);
  }
  if (!covered) throw Error("internal: no invertible witness lens for " + c.name);

  Rng pose_rng(hashKey(seed, kStreamWitnessPose, static_cast<std::uint64_t>(index)));
  // Evenly spread azimuths, offset by half a step from the main camera's line of sight (-90°)
  // so that no witness stands in front of the film camera.
  const double step = 2.0 * kPi / count;
  const double azimuth =
      -0.5 * kPi + 0.5 * step + index * step + pose_rng.uniform(-0.12, 0.12) * std::min(1.0, step);
  // Radius, height and aim keep the whole actor in every witness for most of the take: the
  // actor walks to within ~1.7 m of the centre, so a witness can be 2.5 m from it; nearer or
  // higher cameras (or a longer lens) cut off the feet or the raised hands there.
  const double radius = pose_rng.uniform(4.2, 4.8);
  const double height_m = pose_rng.uniform(2.0, 2.7);
  const Eigen::Vector3d eye(radius * std::cos(azimuth), radius * std::sin(azimuth), height_m);
  const Eigen::Vector3d target =
      witnessAimPoint() + Eigen::Vector3d(pose_rng.uniform(-0.05, 0.05),
                                          pose_rng.uniform(-0.05, 0.05),
                                          pose_rng.uniform(-0.05, 0.05));
  RigCamera rc;
  rc.camera = c.scaled(static_cast<double>(width) / kWitnessDesignWidth,
                       static_cast<double>(height) / kWitnessDesignHeight);
  rc.camera.name = c.name;
  rc.T_world_cam = lookAt(eye, target);
  rc.role = "witness";
  return rc;
}

Camera mainCamera(int width, int height) {
  Camera c;
  c.name = kMainCamera;
  c.width = kMainDesignWidth;
  c.height = kMainDesignHeight;
  c.fx = 1500.0;
  c.fy = 1500.0;
  c.cx = 0.5 * (c.width - 1) + 3.2;
  c.cy = 0.5 * (c.height - 1) - 2.1;
  c.dist.k1 = -0.06;
  c.dist.k2 = 0.02;
  Camera out = c.scaled(static_cast<double>(width) / kMainDesignWidth,
                        static_cast<double>(height) / kMainDesignHeight);
  out.name = kMainCamera;
  return out;
}

Pose mainCameraPose(double time_s, double duration_s, bool dolly) {
  const Eigen::Vector3d home(0.0, -6.0, 1.6);
  Pose T = lookAt(home, Eigen::Vector3d(0.0, 0.0, 1.0));
  if (dolly && duration_s > 0) {
    const double s = std::clamp(time_s / duration_s, 0.0, 1.0);
    T.translation() = home + Eigen::Vector3d(-std::cos(kPi * s), 0.0, 0.0);
  }
  return T;
}

Rig studioRig(const StudioRigOptions& options, double duration_s, bool dolly) {
  Rig rig;
  for (int i = 0; i < options.witness_cameras; ++i) {
    rig.cameras.push_back(witnessCamera(i, options.witness_cameras, options.seed, options.witness_width,
                                        options.witness_height, i < options.fisheye_witnesses));
  }
  if (options.with_main) {
    RigCamera main;
    main.camera = mainCamera(options.main_width, options.main_height);
    main.T_world_cam = mainCameraPose(0.0, duration_s, dolly);
    main.role = kMainRole;
    rig.cameras.push_back(main);
  }
  return rig;
}

Pose intrinsicsBoardPose(const Camera& camera, const BoardSpec& spec, int frame,
                         std::uint64_t seed) {
  Rng rng(hashKey(seed, kStreamIntrinsicsBoard, static_cast<std::uint64_t>(frame)));
  const Eigen::Vector2d size = spec.size_m();
  const Eigen::Vector3d centre_board(0.5 * size.x(), 0.5 * size.y(), 0.0);
  const double width_m = size.x() + 2.0 * spec.margin_m;

  const double coverage = rng.uniform(0.2, 0.7);
  const double tilt_x = rng.uniform(-45.0, 45.0) * kDeg;
  const double tilt_y = rng.uniform(-45.0, 45.0) * kDeg;
  double roll = rng.uniform(-20.0, 20.0) * kDeg;
  if (frame % 5 == 4) roll += 0.5 * kPi;
  // 3 x 3 cells visited in a fixed shuffled order so consecutive frames land far apart.
  static const int kCellOrder[9] = {4, 0, 8, 2, 6, 1, 7, 3, 5};
  const int cell = kCellOrder[frame % 9];
  const Eigen::Vector2d cell_centre((cell % 3 + 0.5) / 3.0, (cell / 3 + 0.5) / 3.0);
  Eigen::Vector2d target_frac =
      cell_centre + Eigen::Vector2d(rng.uniform(-0.12, 0.12), rng.uniform(-0.12, 0.12));
  // A board seen in a corner cell should reach into that corner: push the target outwards.
  target_frac = (Eigen::Vector2d(0.5, 0.5) + 1.4 * (target_frac - Eigen::Vector2d(0.5, 0.5)))
                    .cwiseMax(0.0)
                    .cwiseMin(1.0);

  const Eigen::Matrix3d R =
      (Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitZ()) *
       Eigen::AngleAxisd(tilt_x, Eigen::Vector3d::UnitX()) *
       Eigen::AngleAxisd(tilt_y, Eigen::Vector3d::UnitY()))
          .toRotationMatrix();
  const Eigen::Vector2d image_centre(0.5 * (camera.width - 1), 0.5 * (camera.height - 1));
  const double margin_px = 0.01 * camera.width;
  double distance = camera.fx * width_m / (coverage * camera.width);
  Pose T_cam_board = Pose::Identity();
  T_cam_board.linear() = R;
  // Pull the board towards the image centre (and then away from the camera) until the whole
  // printed board lies inside the image.
  for (int attempt = 0; attempt < 200; ++attempt) {
    const double pull = std::pow(0.75, attempt % 10);
    if (attempt > 0 && attempt % 10 == 0) distance *= 1.15;
    const Eigen::Vector2d px =
        image_centre + pull * (Eigen::Vector2d(target_frac.x() * (camera.width - 1),
                                               target_frac.y() * (camera.height - 1)) -
                               image_centre);
    const std::optional<Eigen::Vector3d> ray = camera.unproject(px);
    if (!ray) continue;
    const Eigen::Vector3d centre_cam = *ray / ray->z() * distance;
    T_cam_board.translation() = centre_cam - R * centre_board;
    bool inside = true;
    for (const Eigen::Vector3d& corner : boardOutline(spec)) {
      const Eigen::Vector3d p_cam = T_cam_board * corner;
      const std::optional<Eigen::Vector2d> uv = camera.project(p_cam);
      if (p_cam.z() < 0.1 || !uv || !camera.inImage(*uv, margin_px)) {
        inside = false;
        break;
      }
    }
    if (inside) return T_cam_board;
  }
  throw Error("internal: could not fit the board in camera '" + camera.name + "'");
}

BoardSpec rigBoard(BoardType type) {
  constexpr double kScale = 2.5;
  BoardSpec spec = defaultBoard(type);
  spec.square_m *= kScale;
  spec.marker_m *= kScale;
  spec.circle_radius_m *= kScale;
  spec.margin_m *= kScale;
  spec.validate();
  return spec;
}

int floorBoardFrameCount(int frames) {
  if (frames >= 8) return 3;
  if (frames >= 2) return 1;
  return 0;
}

bool isFloorBoardFrame(int frame, int frames) {
  return frame >= frames - floorBoardFrameCount(frames);
}

Pose floorBoardPose() {
  Pose T = Pose::Identity();
  T.linear() = Eigen::Vector3d(1.0, -1.0, -1.0).asDiagonal();
  return T;
}

Pose rigBoardPose(const BoardSpec& spec, int frame, int frames, std::uint64_t seed) {
  if (isFloorBoardFrame(frame, frames)) return floorBoardPose();
  return rigWavedBoardPose(spec, frame, std::max(1, frames - floorBoardFrameCount(frames)), seed);
}

Pose rigWavedBoardPose(const BoardSpec& spec, int frame, int waved_frames, std::uint64_t seed) {
  const int waved = std::max(1, waved_frames);
  Rng take_rng(hashKey(seed, kStreamRigBoard));
  const double phase_x = take_rng.uniform(0.0, 2.0 * kPi);
  const double phase_y = take_rng.uniform(0.0, 2.0 * kPi);
  const double phase_z = take_rng.uniform(0.0, 2.0 * kPi);
  const double heading0 = take_rng.uniform(0.0, 2.0 * kPi);
  Rng rng(hashKey(seed, kStreamRigBoard, static_cast<std::uint64_t>(frame) + 1));

  const double s = static_cast<double>(frame) / waved;  // [0, 1)
  // Lissajous path: covers the volume without returning to the same spot within a take.
  const Eigen::Vector3d centre(0.8 * std::sin(2.0 * kPi * 1.0 * s + phase_x),
                               0.8 * std::sin(2.0 * kPi * 1.5 * s + phase_y),
                               1.4 + 0.55 * std::sin(2.0 * kPi * 2.5 * s + phase_z));
  // The face turns twice around the vertical over the take: every witness is faced at least
  // twice, and with +-60 degrees of useful viewing angle two or three neighbours share a view.
  const double heading = heading0 + 2.0 * 2.0 * kPi * s + rng.uniform(-0.2, 0.2);
  // Tilt the face up towards the witnesses (2–3 m high, ~4 m away) with some variation.
  const double elevation = rng.uniform(5.0, 30.0) * kDeg;
  const Eigen::Vector3d face(std::cos(heading) * std::cos(elevation),
                             std::sin(heading) * std::cos(elevation), std::sin(elevation));
  // Board axes: z into the board (away from the viewers it faces), y down the print (as close to
  // world down as the face allows), x = y × z; then a roll about the face normal.
  const Eigen::Vector3d z_b = -face;
  Eigen::Vector3d y_b = -Eigen::Vector3d::UnitZ();
  y_b = (y_b - y_b.dot(z_b) * z_b).normalized();
  const Eigen::Vector3d x_b = y_b.cross(z_b);
  Eigen::Matrix3d R;
  R.col(0) = x_b;
  R.col(1) = y_b;
  R.col(2) = z_b;
  R = R * Eigen::AngleAxisd(rng.uniform(-30.0, 30.0) * kDeg, Eigen::Vector3d::UnitZ())
              .toRotationMatrix();
  const Eigen::Vector2d size = spec.size_m();
  Pose T = Pose::Identity();
  T.linear() = R;
  T.translation() = centre - R * Eigen::Vector3d(0.5 * size.x(), 0.5 * size.y(), 0.0);
  double lowest = std::numeric_limits<double>::infinity();
  for (const Eigen::Vector3d& corner : boardOutline(spec)) lowest = std::min(lowest, (T * corner).z());
  if (lowest < 0.05) T.translation().z() += 0.05 - lowest;
  return T;
}

std::vector<BoardObservation> visibleBoardPoints(const Camera& camera, const Pose& T_world_cam,
                                                 const BoardSpec& spec,
                                                 const Pose& T_world_board, const Scene& scene) {
  std::vector<BoardObservation> out;
  const Pose T_cam_board = T_world_cam.inverse() * T_world_board;
  const Eigen::Vector3d eye = T_world_cam.translation();
  const Eigen::Vector3d board_z = T_world_board.linear().col(2);
  for (const BoardPoint& point : boardPoints(spec)) {
    const Eigen::Vector3d p_world = T_world_board * point.p_board;
    const Eigen::Vector3d p_cam = T_cam_board * point.p_board;
    if (p_cam.z() <= 0) continue;
    // The printed face looks along -z_board; the camera sees it when it is on that side.
    if ((p_world - eye).dot(board_z) <= 0) continue;
    const std::optional<Eigen::Vector2d> px = camera.project(p_cam);
    if (!px || !camera.inImage(*px)) continue;
    const Eigen::Vector3d to_point = p_world - eye;
    const double distance = to_point.norm();
    Ray ray{eye, to_point / distance};
    Hit hit;
    scene.trace(ray, hit);
    // Anything nearer than the point by more than a hair occludes it (the board itself is hit at
    // 'distance' up to rounding).
    if (hit.t < distance - 1e-6 * std::max(1.0, distance)) continue;
    out.push_back({point.id, *px});
  }
  return out;
}

}  // namespace previz::synth
