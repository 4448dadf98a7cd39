// The take writer: every documented file is there and reads back, the truth agrees with the
// studio's own geometry, and the image options (noise, blur) do what they say.
#include "datasets/synth.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <gtest/gtest.h>
#include <unistd.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>

#include "core/board.h"
#include "core/distortion_maps.h"
#include "core/error.h"
#include "core/io.h"
#include "core/rig.h"
#include "datasets/render.h"
#include "datasets/rigs.h"
#include "datasets/studio.h"

namespace previz::synth {
namespace {

namespace fs = std::filesystem;

fs::path tmpDir(const std::string& name) {
  // Per process: CTest runs each test in its own process, in parallel, and suite fixtures
  // render into their folder in each of them.
  const fs::path dir =
      fs::path(PREVIZ_TEST_TMP) / ("synth." + std::to_string(::getpid())) / name;
  fs::remove_all(dir);
  return dir;
}

std::vector<nlohmann::json> readJsonLines(const fs::path& path) {
  std::ifstream in(path);
  EXPECT_TRUE(in.good()) << path;
  std::vector<nlohmann::json> lines;
  std::string line;
  while (std::getline(in, line)) {
    if (!line.empty()) lines.push_back(nlohmann::json::parse(line));
  }
  return lines;
}

std::string frameName(int f, const char* ext) {
  char s[32];
  std::snprintf(s, sizeof(s), "%06d.%s", f, ext);
  return s;
}

SynthOptions smallOptions(Preset preset, int frames) {
  SynthOptions o;
  o.preset = preset;
  o.frames = frames;
  o.witness_cameras = 3;
  o.witness_width = 320;
  o.witness_height = 180;
  o.main_width = 480;
  o.main_height = 270;
  o.seed = 5;
  return o;
}

// One small studio take shared by the tests below (rendering it is the expensive part).
class StudioTake : public ::testing::Test {
 protected:
  static constexpr int kFrames = 3;
  static void SetUpTestSuite() {
    dir_ = new fs::path(tmpDir("studio"));
    options_ = new SynthOptions(smallOptions(Preset::kStudio, kFrames));
    int calls = 0;
    summary_ = new SynthSummary(synthesizeTake(*options_, *dir_, [&](const SynthProgress& p) {
      ++calls;
      EXPECT_EQ(p.frames_done, calls);
      EXPECT_EQ(p.frames_total, kFrames);
    }));
    EXPECT_EQ(calls, kFrames);
  }
  static void TearDownTestSuite() {
    delete dir_;
    delete options_;
    delete summary_;
  }
  static StudioConfig config() {
    StudioConfig c;
    c.seed = options_->seed;
    // A short take is a clip of the studio's choreography; take.json says how long that is.
    c.take_duration_s = readJsonFile(*dir_ / "take.json").at("choreography_duration_s");
    return c;
  }
  static fs::path* dir_;
  static SynthOptions* options_;
  static SynthSummary* summary_;
};
fs::path* StudioTake::dir_ = nullptr;
SynthOptions* StudioTake::options_ = nullptr;
SynthSummary* StudioTake::summary_ = nullptr;

TEST_F(StudioTake, HasEveryDocumentedFile) {
  const fs::path& d = *dir_;
  const std::vector<std::string> cams = {"witness01", "witness02", "witness03", "main"};
  std::vector<fs::path> expected = {"take.json",           "props.json",
                                    "truth/rig.json",      "truth/main_poses.jsonl",
                                    "truth/props.jsonl",   "cg/camera.json"};
  for (int f = 0; f < kFrames; ++f) {
    const std::string png = frameName(f, "png"), exr = frameName(f, "exr");
    for (const std::string& c : cams) {
      expected.push_back(fs::path("cams") / c / png);
      expected.push_back(fs::path("truth/depth") / c / exr);
      expected.push_back(fs::path("truth/masks") / c / png);
      expected.push_back(fs::path("truth/labels") / c / png);
    }
    expected.push_back(fs::path("cg/color") / exr);
    expected.push_back(fs::path("cg/depth") / exr);
    expected.push_back(fs::path("truth/composite") / png);
    char mesh[32];
    std::snprintf(mesh, sizeof(mesh), "actor.%06d", f);
    expected.push_back(fs::path("truth/mesh") / (std::string(mesh) + ".ply"));
    expected.push_back(fs::path("truth/mesh") / (std::string(mesh) + ".obj"));
  }
  for (const fs::path& p : expected) EXPECT_TRUE(fs::is_regular_file(d / p)) << p;
  // Board files belong to the board presets only; no temporaries are left behind.
  EXPECT_FALSE(fs::exists(d / "board.json"));
  for (const auto& entry : fs::recursive_directory_iterator(d)) {
    const std::string name = entry.path().filename().string();
    EXPECT_EQ(name.find(".tmp"), std::string::npos) << entry.path();
  }
  const nlohmann::json take = readJsonFile(d / "take.json");
  EXPECT_EQ(take.at("preset"), "studio");
  EXPECT_EQ(take.at("frames"), kFrames);
  EXPECT_EQ(take.at("seed"), options_->seed);
  EXPECT_EQ(take.at("cameras"), nlohmann::json(cams));
  EXPECT_EQ(summary_->frames, kFrames);
  EXPECT_EQ(summary_->cameras, 4);

  // Image sizes and types as documented.
  const cv::Mat plate = readImage(d / "cams/main" / frameName(0, "png"));
  EXPECT_EQ(plate.type(), CV_8UC3);
  EXPECT_EQ(plate.cols, 480);
  const ExrImage cg = readExr(d / "cg/color" / frameName(0, "exr"));
  EXPECT_EQ(cg.channels, (std::vector<std::string>{"R", "G", "B"}));
  // CG through the ideal pinhole of the main camera with overscan, as cg/camera.json says.
  const Camera cg_camera = cameraFromJson(readJsonFile(d / "cg/camera.json").at("camera"));
  const Camera expected_cg = idealPinhole(mainCamera(480, 270), options_->cg_overscan);
  EXPECT_EQ(cg.image.cols, cg_camera.width);
  EXPECT_EQ(cg.image.rows, cg_camera.height);
  EXPECT_EQ(cg_camera.width, expected_cg.width);
  EXPECT_GT(cg_camera.width, 480);
  EXPECT_NEAR(cg_camera.fx, expected_cg.fx, 1e-9);
  EXPECT_TRUE(cg_camera.dist.isZero());
  EXPECT_EQ(readDepthExr(d / "cg/depth" / frameName(0, "exr")).size(), cg.image.size());
  const cv::Mat labels = readImage(d / "truth/labels/witness01" / frameName(0, "png"));
  EXPECT_EQ(labels.type(), CV_8UC1);
}

TEST_F(StudioTake, TruthRigReadsBackAsTheStudioLayout) {
  const Rig rig = readRig(*dir_ / "truth/rig.json");
  ASSERT_EQ(rig.cameras.size(), 4u);
  for (int i = 0; i < 3; ++i) {
    const RigCamera expected = witnessCamera(i, 3, options_->seed, 320, 180);
    const RigCamera& got = rig.at(witnessName(i));
    EXPECT_EQ(got.camera.width, 320);
    EXPECT_NEAR(got.camera.fx, expected.camera.fx, 1e-9);
    EXPECT_NEAR(got.camera.dist.k1, expected.camera.dist.k1, 1e-12);
    EXPECT_LT(translationDistance(got.T_world_cam, expected.T_world_cam), 1e-9);
    EXPECT_LT(rotationDistance(got.T_world_cam, expected.T_world_cam), 1e-9);
  }
  const RigCamera& main = rig.at("main");
  EXPECT_EQ(main.role, "main");
  EXPECT_EQ(main.camera.width, 480);
  // Main camera fx scales with the size: 1500 at 1920 px.
  EXPECT_NEAR(main.camera.fx, 1500.0 * 480 / 1920, 1e-9);

  const std::vector<nlohmann::json> poses = readJsonLines(*dir_ / "truth/main_poses.jsonl");
  ASSERT_EQ(poses.size(), static_cast<size_t>(kFrames));
  const double duration = config().take_duration_s;
  for (int f = 0; f < kFrames; ++f) {
    EXPECT_EQ(poses[f].at("frame"), f);
    const Pose T = poseFromJson(poses[f].at("T_world_cam"));
    EXPECT_LT(translationDistance(T, mainCameraPose(f / options_->fps, duration, true)), 1e-9);
  }
  // The dolly moves the camera along +x only, with a fixed orientation.
  const Pose first = poseFromJson(poses.front().at("T_world_cam"));
  const Pose last = poseFromJson(poses.back().at("T_world_cam"));
  EXPECT_GT(last.translation().x(), first.translation().x());
  EXPECT_NEAR(last.translation().y(), first.translation().y(), 1e-12);
  EXPECT_NEAR(last.translation().z(), first.translation().z(), 1e-12);
  EXPECT_LT(rotationDistance(first, last), 1e-12);
  // Over the whole choreography it travels from x = -1 m to +1 m.
  EXPECT_NEAR(mainCameraPose(0.0, duration, true).translation().x(), -1.0, 1e-12);
  EXPECT_NEAR(mainCameraPose(duration, duration, true).translation().x(), 1.0, 1e-12);
}

TEST_F(StudioTake, PropsParseAndPosesMatchTheStudio) {
  const Studio studio(config());
  const nlohmann::json props = readJsonFile(*dir_ / "props.json");
  ASSERT_EQ(props.at("props").size(), 1u);
  const nlohmann::json& p = props.at("props")[0];
  EXPECT_EQ(p.at("id"), studio.prop().id);
  ASSERT_EQ(p.at("tags").size(), studio.prop().tags.size());
  for (size_t i = 0; i < studio.prop().tags.size(); ++i) {
    const PropTag& tag = studio.prop().tags[i];
    const nlohmann::json& t = p.at("tags")[i];
    EXPECT_EQ(t.at("family"), tag.family);
    EXPECT_EQ(t.at("id"), tag.id);
    EXPECT_DOUBLE_EQ(t.at("size_m").get<double>(), tag.size_m);
    EXPECT_LT(translationDistance(poseFromJson(t.at("T_prop_tag")), tag.T_prop_tag), 1e-12);
  }
  const std::vector<nlohmann::json> lines = readJsonLines(*dir_ / "truth/props.jsonl");
  ASSERT_EQ(lines.size(), static_cast<size_t>(kFrames));
  for (int f = 0; f < kFrames; ++f) {
    const Pose T = poseFromJson(lines[f].at("props")[0].at("T_world_prop"));
    const Pose expected = studio.T_world_prop(f / options_->fps);
    EXPECT_LT(translationDistance(T, expected), 1e-12);
    EXPECT_LT(rotationDistance(T, expected), 1e-9);
  }
}

// The depth EXR, the actor mask and the truth mesh describe the same surface: for every masked
// pixel the mesh is hit along the pixel-centre ray at the stored depth (<= 1 mm), and the mask
// covers exactly the pixels whose centre ray hits the mesh first. The mesh is inscribed in the
// traced capsules (within 0.3 mm along the normal), so a ray that grazes a silhouette — the
// outline, or one body part's edge over another — may pass between the two surfaces: such
// disagreements are allowed only within 1 px of a silhouette or depth edge, and are counted.
TEST_F(StudioTake, DepthMaskAndMeshAgree) {
  const Rig rig = readRig(*dir_ / "truth/rig.json");
  const int f = 1;
  const TriangleMesh mesh = readPly(*dir_ / "truth/mesh" / "actor.000001.ply");
  ASSERT_FALSE(mesh.faces.empty());
  Eigen::AlignedBox3d box;
  for (const Eigen::Vector3f& v : mesh.vertices) box.extend(v.cast<double>());
  for (const char* name : {"witness01", "witness02", "witness03"}) {
    const RigCamera& rc = rig.at(name);
    const cv::Mat depth = readDepthExr(*dir_ / "truth/depth" / name / frameName(f, "exr"));
    const cv::Mat mask = readImage(*dir_ / "truth/masks" / name / frameName(f, "png"));
    ASSERT_EQ(depth.size(), mask.size());
    auto masked_at = [&](int u, int v) {
      return u >= 0 && v >= 0 && u < mask.cols && v < mask.rows && mask.at<std::uint8_t>(v, u);
    };
    // Edges: the silhouette (a masked and an unmasked 4-neighbour) and depth steps between
    // masked neighbours of more than 3 pixel footprints (z / fx): one part over another, or a
    // surface tilted more than 72 degrees from the view, where 0.3 mm along the normal may
    // exceed 1 mm along the ray. The band is every pixel within 1 px of an edge.
    cv::Mat edges = cv::Mat::zeros(mask.size(), CV_8U);
    for (int v = 0; v < mask.rows; ++v) {
      for (int u = 0; u < mask.cols; ++u) {
        for (const auto& [du, dv] : {std::pair{1, 0}, std::pair{0, 1}}) {
          if (u + du >= mask.cols || v + dv >= mask.rows) continue;
          const bool a = masked_at(u, v), b = masked_at(u + du, v + dv);
          const float za = depth.at<float>(v, u), zb = depth.at<float>(v + dv, u + du);
          const bool step =
              a && b && std::abs(za - zb) > 3.0 * std::min(za, zb) / rc.camera.fx;
          if (a != b || step) {
            edges.at<std::uint8_t>(v, u) = 255;
            edges.at<std::uint8_t>(v + dv, u + du) = 255;
          }
        }
      }
    }
    cv::Mat band;
    cv::dilate(edges, band, cv::Mat::ones(3, 3, CV_8U));
    int masked = 0, interior = 0, band_disagree = 0, occluded = 0;
    const int band_pixels = cv::countNonZero(band);
    double worst_interior_mm = 0;
    for (int v = 0; v < mask.rows; ++v) {
      for (int u = 0; u < mask.cols; ++u) {
        Eigen::Vector3d d_cam;
        ASSERT_TRUE(pixelRay(rc.camera, Eigen::Vector2d(u, v), d_cam));
        const Ray ray{rc.T_world_cam.translation(), rc.T_world_cam.linear() * d_cam};
        // Skip the brute-force mesh test for rays that miss the mesh's box.
        const Eigen::Vector3d inv = ray.dir.cwiseInverse();
        const Eigen::Vector3d t0 = (box.min() - ray.origin).cwiseProduct(inv);
        const Eigen::Vector3d t1 = (box.max() - ray.origin).cwiseProduct(inv);
        const double t_near = t0.cwiseMin(t1).maxCoeff(), t_far = t0.cwiseMax(t1).minCoeff();
        const double t_mesh = t_near <= t_far && t_far > 0
                                  ? intersectMesh(mesh, ray)
                                  : std::numeric_limits<double>::infinity();
        const double z_mesh = t_mesh * d_cam.z();
        const float z = depth.at<float>(v, u);
        const bool in_band = band.at<std::uint8_t>(v, u) != 0;
        if (masked_at(u, v)) {
          ++masked;
          const double err_mm = 1000.0 * std::abs(z - z_mesh);  // inf when the mesh is missed
          if (in_band) {
            band_disagree += !(err_mm <= 1.0);
            continue;
          }
          ++interior;
          worst_interior_mm = std::max(worst_interior_mm, err_mm);
          EXPECT_LE(err_mm, 1.0) << name << " pixel (" << u << "," << v << "): depth " << z
                                 << " mesh " << z_mesh;
        } else if (std::isfinite(z_mesh)) {
          // The mesh is hit but the pixel is not the actor: either something nearer hides the
          // actor there (the prop), or we are on the silhouette band.
          if (z < z_mesh - 1e-3) {
            ++occluded;
          } else {
            EXPECT_TRUE(in_band) << name << " pixel (" << u << "," << v << ") hits the mesh at z "
                                 << z_mesh << " but is not masked (depth " << z << ")";
            ++band_disagree;
          }
        }
      }
    }
    std::printf("%s: %d masked px, %d off the edge band with worst |z - z_mesh| %.3f mm; %d "
                "disagreements among %d band px; %d mesh px hidden by the prop\n",
                name, masked, interior, worst_interior_mm, band_disagree, band_pixels, occluded);
    EXPECT_GT(interior, 100) << name << ": actor too small to judge";
    // A ray must pass within ~0.3 mm of an edge to disagree: at ~4 m and ~230 px focal length
    // (17 mm per pixel) that is a small fraction of the band.
    EXPECT_LE(band_disagree, std::max(3, band_pixels / 20)) << name;
  }
}

TEST_F(StudioTake, ActorIsSeenByEveryCameraInEveryFrame) {
  for (const std::string name : {"witness01", "witness02", "witness03", "main"}) {
    for (int f = 0; f < kFrames; ++f) {
      const cv::Mat mask = readImage(*dir_ / "truth/masks" / name / frameName(f, "png"));
      EXPECT_GT(cv::countNonZero(mask), 0.004 * mask.total()) << name << " frame " << f;
    }
  }
}

// The true composite and the main plate render the actor through the same lens with the same
// samples: where the actor covers a pixel entirely and is nearer than the CG set, they agree;
// where the CG set (the pillar) is nearer it hides the actor; the green stage is replaced.
TEST_F(StudioTake, CompositeShowsTheActorInDepthOrderOverTheCgSet) {
  const Studio studio(config());
  const Rig rig = readRig(*dir_ / "truth/rig.json");
  const Camera& camera = rig.at("main").camera;
  const std::vector<nlohmann::json> poses = readJsonLines(*dir_ / "truth/main_poses.jsonl");
  int compared = 0, equal = 0, hidden = 0, hidden_changed = 0, stage = 0, stage_changed = 0;
  for (int f = 0; f < kFrames; ++f) {
    const Pose T_world_cam = poseFromJson(poses[f].at("T_world_cam"));
    const Scene cg = studio.sceneAt(f / options_->fps, kLayerCg);
    const cv::Mat plate = readImage(*dir_ / "cams/main" / frameName(f, "png"));
    const cv::Mat comp = readImage(*dir_ / "truth/composite" / frameName(f, "png"));
    const cv::Mat mask = readImage(*dir_ / "truth/masks/main" / frameName(f, "png"));
    const cv::Mat labels = readImage(*dir_ / "truth/labels/main" / frameName(f, "png"));
    const cv::Mat depth = readDepthExr(*dir_ / "truth/depth/main" / frameName(f, "exr"));
    cv::Mat interior;
    cv::erode(mask, interior, cv::Mat::ones(3, 3, CV_8U));
    for (int v = 0; v < plate.rows; ++v) {
      for (int u = 0; u < plate.cols; ++u) {
        const cv::Vec3b a = plate.at<cv::Vec3b>(v, u), b = comp.at<cv::Vec3b>(v, u);
        if (interior.at<std::uint8_t>(v, u)) {
          Eigen::Vector3d d_cam;
          ASSERT_TRUE(pixelRay(camera, Eigen::Vector2d(u, v), d_cam));
          Hit hit;
          cg.trace({T_world_cam.translation(), T_world_cam.linear() * d_cam}, hit);
          const double z_cg = hit.t * d_cam.z();
          const double z_actor = depth.at<float>(v, u);
          if (z_cg < z_actor - 0.01) {
            ++hidden;
            hidden_changed += a != b;
          } else if (z_cg > z_actor + 0.01) {
            ++compared;
            equal += cv::norm(cv::Vec3i(a) - cv::Vec3i(b), cv::NORM_INF) <= 1;
          }
        }
        if (labels.at<std::uint8_t>(v, u) == static_cast<int>(ObjectClass::kStage)) {
          ++stage;
          stage_changed += a != b;
        }
      }
    }
  }
  std::printf("composite: %d/%d actor px in front of the CG equal to the plate, %d/%d actor px "
              "behind the CG replaced, %d/%d stage px replaced\n",
              equal, compared, hidden_changed, hidden, stage_changed, stage);
  ASSERT_GT(compared, 200);
  EXPECT_GE(equal, 0.99 * compared);
  EXPECT_GE(hidden_changed, 0.95 * hidden);
  ASSERT_GT(stage, 1000);
  EXPECT_GE(stage_changed, 0.95 * stage);
}

TEST(SynthLayout, ActorInViewOfEveryCameraForMostOfTheTake) {
  // Geometry only: the true actor surface (every 50th mesh vertex), sampled over a default
  // take, lies entirely inside each camera's image for at least 80 % of the take.
  StudioConfig config;
  const Studio studio(config);
  const int samples = 40;
  std::vector<std::vector<Eigen::Vector3d>> surface(samples);
  for (int i = 0; i < samples; ++i) {
    const TriangleMesh mesh = studio.actorMesh(config.take_duration_s * (i + 0.5) / samples);
    for (size_t k = 0; k < mesh.vertices.size(); k += 50) {
      surface[i].push_back(mesh.vertices[k].cast<double>());
    }
  }
  int total_in_view = 0, total = 0;
  for (std::uint64_t seed : {1u, 2u, 3u, 4u}) {
    StudioRigOptions rig_options;
    rig_options.seed = seed;
    const Rig rig = studioRig(rig_options, config.take_duration_s, true);
    for (const RigCamera& rc : rig.cameras) {
      int in_view = 0;
      for (int i = 0; i < samples; ++i) {
        const double t = config.take_duration_s * (i + 0.5) / samples;
        const Pose T_cam_world = (rc.role == "main"
                                      ? mainCameraPose(t, config.take_duration_s, true)
                                      : rc.T_world_cam)
                                     .inverse();
        bool all_in = true;
        for (const Eigen::Vector3d& p : surface[i]) {
          const std::optional<Eigen::Vector2d> px = rc.camera.project(T_cam_world * p);
          if (!px || !rc.camera.inImage(*px)) {
            all_in = false;
            break;
          }
        }
        in_view += all_in;
      }
      std::printf("seed %d %s: actor fully in view %d/%d\n", static_cast<int>(seed),
                  rc.camera.name.c_str(), in_view, samples);
      EXPECT_GE(in_view, 0.75 * samples) << "seed " << seed << " " << rc.camera.name;
      total_in_view += in_view;
      total += samples;
    }
  }
  // Only a witness the actor walks up close to loses the feet for a while.
  EXPECT_GE(total_in_view, 0.95 * total);
}

TEST(SynthLayout, WitnessLensesStayInsideTheRequestedRanges) {
  for (int i = 0; i < 8; ++i) {
    const RigCamera rc = witnessCamera(i, 8, 9, 1280, 720);
    const Camera& c = rc.camera;
    EXPECT_GE(c.fx, 800);
    EXPECT_LE(c.fx, 1000);  // fx around 800-1000
    EXPECT_LT(std::abs(c.cx - 639.5), 10);
    EXPECT_LT(std::abs(c.cy - 359.5), 10);
    EXPECT_GT(std::abs(c.cx - 639.5) + std::abs(c.cy - 359.5), 0.0);
    EXPECT_GE(c.dist.k1, -0.25);
    EXPECT_LE(c.dist.k1, 0.05);
    EXPECT_LE(std::abs(c.dist.p1), 0.001);
    EXPECT_LE(std::abs(c.dist.p2), 0.001);
    EXPECT_EQ(c.dist.k3, 0.0);
    // Every corner pixel has a ray: no black corners from the lens folding back.
    for (const Eigen::Vector2d& px : {Eigen::Vector2d(-0.5, -0.5), Eigen::Vector2d(1279.5, 719.5),
                                     Eigen::Vector2d(-0.5, 719.5), Eigen::Vector2d(1279.5, -0.5)}) {
      EXPECT_TRUE(c.unproject(px).has_value()) << c.name;
    }
    const Eigen::Vector3d eye = rc.T_world_cam.translation();
    EXPECT_GE(eye.z(), 2.0);
    EXPECT_LE(eye.z(), 3.0);
    EXPECT_GE(eye.head<2>().norm(), 3.5);
    EXPECT_LE(eye.head<2>().norm(), 5.0);
    // Aimed at the stage centre: the aim point projects near the image centre.
    const std::optional<Eigen::Vector2d> aim =
        c.project(rc.T_world_cam.inverse() * witnessAimPoint());
    ASSERT_TRUE(aim.has_value());
    EXPECT_LT((*aim - Eigen::Vector2d(639.5, 359.5)).norm(), 80);
  }
}

TEST(SynthLayout, IntrinsicsBoardCoversTheImageAndStaysInside) {
  const Camera camera = mainCamera(1920, 1080);
  const BoardSpec spec = defaultBoard(BoardType::kCharuco);
  const Eigen::Vector2d size = spec.size_m();
  const double m = spec.margin_m;
  const std::vector<Eigen::Vector3d> outline = {
      {-m, -m, 0}, {size.x() + m, -m, 0}, {size.x() + m, size.y() + m, 0}, {-m, size.y() + m, 0}};
  bool corner_reached[4] = {false, false, false, false};
  double min_cover = 1, max_cover = 0, max_tilt = 0;
  for (int f = 0; f < 36; ++f) {
    const Pose T = intrinsicsBoardPose(camera, spec, f, 3);
    double u0 = 1e9, u1 = -1e9;
    for (const Eigen::Vector3d& p : outline) {
      const std::optional<Eigen::Vector2d> px = camera.project(T * p);
      ASSERT_TRUE(px.has_value());
      ASSERT_TRUE(camera.inImage(*px)) << "frame " << f;
      u0 = std::min(u0, px->x());
      u1 = std::max(u1, px->x());
      // A corner of the image is "reached" when a board corner comes within 20 % of it.
      const int qx = px->x() < 0.2 * camera.width ? 0 : px->x() > 0.8 * camera.width ? 1 : -1;
      const int qy = px->y() < 0.2 * camera.height ? 0 : px->y() > 0.8 * camera.height ? 1 : -1;
      if (qx >= 0 && qy >= 0) corner_reached[qx + 2 * qy] = true;
    }
    const double cover = (u1 - u0) / camera.width;
    min_cover = std::min(min_cover, cover);
    max_cover = std::max(max_cover, cover);
    const double tilt = std::acos(std::clamp(T.linear().col(2).z(), -1.0, 1.0));
    max_tilt = std::max(max_tilt, tilt);
  }
  std::printf("board width coverage %.2f..%.2f, max tilt %.1f deg\n", min_cover, max_cover,
              max_tilt * 180 / M_PI);
  EXPECT_GT(min_cover, 0.1);
  EXPECT_LT(max_cover, 0.85);
  EXPECT_GT(max_cover - min_cover, 0.3);
  EXPECT_GT(max_tilt, 25 * M_PI / 180);
  EXPECT_LT(max_tilt, 65 * M_PI / 180);
  for (int q = 0; q < 4; ++q) EXPECT_TRUE(corner_reached[q]) << "image corner " << q;
}

// A board take's scene: the empty stage and the board.
Scene boardScene(const BoardSpec& spec, const Pose& T_world_board, bool floor, std::uint64_t seed) {
  StudioConfig config;
  config.seed = seed;
  config.with_actor = false;
  config.with_prop = false;
  Scene scene = Studio(config).sceneAt(0.0, kLayerStage);
  const auto board = makeBoard(spec, T_world_board);
  scene.add(floor ? onTopOf(board) : board);
  return scene;
}

// The object class the pixel-centre ray of (u, v) hits, as the truth labels said before board
// takes stopped writing them.
ObjectClass classAt(const Camera& camera, const Pose& T_world_cam, const Scene& scene, int u, int v) {
  Eigen::Vector3d dir_cam;
  if (!pixelRay(camera, Eigen::Vector2d(u, v), dir_cam)) return ObjectClass::kNone;
  Hit hit;
  scene.trace({T_world_cam.translation(), T_world_cam.linear() * dir_cam}, hit);
  return hit.cls;
}

TEST(SynthRig, BoardTruthIsVisibleOnTheBoardAndFloorFramesSetTheWorld) {
  const fs::path dir = tmpDir("rig");
  SynthOptions o = smallOptions(Preset::kRig, 10);
  o.board = "charuco";
  synthesizeTake(o, dir);
  const BoardSpec spec = readBoard(dir / "board.json");
  EXPECT_EQ(spec.type, BoardType::kCharuco);
  EXPECT_DOUBLE_EQ(spec.square_m, rigBoard(BoardType::kCharuco).square_m);
  const nlohmann::json frames = readJsonFile(dir / "truth/board_frames.json");
  EXPECT_EQ(frames.at("floor_frames"), nlohmann::json({7, 8, 9}));
  const Pose floor = poseFromJson(frames.at("T_world_board"));
  EXPECT_LT(floor.translation().norm(), 1e-12);
  // Board z points down (into the floor), so the printed face looks up.
  EXPECT_NEAR(floor.linear().col(2).z(), -1.0, 1e-12);
  // The operator's floor.json (multicam reads it): the same frames and pose, the take's board.
  const nlohmann::json floor_json = readJsonFile(dir / "floor.json");
  EXPECT_EQ(floor_json.at("board"), "board.json");
  EXPECT_EQ(floor_json.at("frames"), nlohmann::json({7, 8, 9}));
  EXPECT_TRUE(poseFromJson(floor_json.at("T_world_board")).isApprox(floor, 0));
  // Calibration takes carry plates and board truth, no per-pixel truth layers.
  for (const char* layer : {"truth/depth", "truth/masks", "truth/labels"}) {
    EXPECT_FALSE(fs::exists(dir / layer)) << layer;
  }

  const Rig rig = readRig(dir / "truth/rig.json");
  ASSERT_EQ(rig.cameras.size(), 4u);
  const size_t n_points = boardPoints(spec).size();
  std::map<int, Eigen::Vector3d> board_point;
  for (const BoardPoint& bp : boardPoints(spec)) board_point[bp.id] = bp.p_board;
  for (const RigCamera& rc : rig.cameras) {
    const std::string& name = rc.camera.name;
    const std::vector<nlohmann::json> lines = readJsonLines(dir / "truth/boards" / (name + ".jsonl"));
    ASSERT_EQ(lines.size(), 10u) << name;
    int frames_seen = 0, on_board = 0, total = 0;
    for (int f = 0; f < 10; ++f) {
      const nlohmann::json& line = lines[f];
      EXPECT_EQ(line.at("frame"), f);
      EXPECT_EQ(line.at("floor").get<bool>(), f >= 7);
      const auto& points = line.at("points");
      frames_seen += points.size() >= n_points / 2;
      const Pose T_world_board = poseFromJson(line.at("T_world_board"));
      const Scene scene = boardScene(spec, T_world_board, f >= 7, o.seed);
      for (const auto& p : points) {
        const int id = p.at("id");
        const Eigen::Vector2d px(p.at("x").get<double>(), p.at("y").get<double>());
        // The truth pixel is Camera::project of the board point.
        ASSERT_TRUE(board_point.count(id)) << "unknown board point id " << id;
        const std::optional<Eigen::Vector2d> expected =
            rc.camera.project(rc.T_world_cam.inverse() * T_world_board * board_point.at(id));
        ASSERT_TRUE(expected.has_value());
        EXPECT_LT((*expected - px).norm(), 1e-6);
        // ... and the pixel shows the board.
        const int u = std::clamp(static_cast<int>(std::lround(px.x())), 0, rc.camera.width - 1);
        const int v = std::clamp(static_cast<int>(std::lround(px.y())), 0, rc.camera.height - 1);
        on_board += classAt(rc.camera, rc.T_world_cam, scene, u, v) == ObjectClass::kBoard;
        ++total;
      }
      if (f >= 7 && rc.role == "witness") {
        EXPECT_GE(points.size(), n_points * 9 / 10) << name << " floor frame " << f;
      }
    }
    std::printf("%s: board half-visible in %d/10 frames, %d/%d truth points on board pixels\n",
                name.c_str(), frames_seen, on_board, total);
    EXPECT_GE(frames_seen, 3) << name;
    EXPECT_GE(on_board, 0.98 * total) << name;
  }
}

// A late camera, a knocked one and a capture without floor frames, as `previz synth --delay
// --bump --no-floor` ask for them: the truth rig holds the knocked pose, the late camera's
// board truth is that of earlier frames, and the rig board waves to the end.
TEST(SynthRig, DelayBumpAndNoFloorReachTheTruth) {
  const fs::path dir = tmpDir("rig_delay");
  SynthOptions o = smallOptions(Preset::kRig, 6);
  o.witness_width = 160;
  o.witness_height = 90;
  o.main_width = 240;
  o.main_height = 135;
  o.board = "aprilgrid";
  o.delay_frames["witness02"] = 2;
  Pose bump = Pose::Identity();
  bump.linear() = Eigen::AngleAxisd(0.01, Eigen::Vector3d::UnitY()).toRotationMatrix();
  bump.translation() = Eigen::Vector3d(0.03, 0.0, 0.0);
  o.bump["main"] = bump;
  o.board_seed = 77;
  o.floor_frames = false;
  synthesizeTake(o, dir);

  StudioRigOptions ro;
  ro.witness_cameras = o.witness_cameras;
  ro.seed = o.seed;
  ro.witness_width = o.witness_width;
  ro.witness_height = o.witness_height;
  ro.main_width = o.main_width;
  ro.main_height = o.main_height;
  const Rig layout = studioRig(ro, 10.0, false);
  const Rig truth = readRig(dir / "truth/rig.json");
  EXPECT_TRUE(truth.at("main").T_world_cam.isApprox(layout.at("main").T_world_cam * bump, 1e-9));
  EXPECT_TRUE(truth.at("witness01").T_world_cam.isApprox(layout.at("witness01").T_world_cam, 1e-9));
  const std::vector<nlohmann::json> main_poses = readJsonLines(dir / "truth/main_poses.jsonl");
  ASSERT_EQ(main_poses.size(), 6u);
  EXPECT_TRUE(poseFromJson(main_poses[3].at("T_world_cam")).isApprox(truth.at("main").T_world_cam, 1e-9));

  const BoardSpec spec = rigBoard(BoardType::kAprilGrid);
  const std::vector<nlohmann::json> late = readJsonLines(dir / "truth/boards/witness02.jsonl");
  const std::vector<nlohmann::json> on_time = readJsonLines(dir / "truth/boards/witness01.jsonl");
  ASSERT_EQ(late.size(), 6u);
  ASSERT_EQ(on_time.size(), 6u);
  for (int f = 0; f < 6; ++f) {
    // Every frame waves the board along the path of seed 77 (no floor frames).
    const Pose expected_late = rigWavedBoardPose(spec, std::max(0, f - 2), 6, 77);
    const Pose expected = rigWavedBoardPose(spec, f, 6, 77);
    EXPECT_TRUE(poseFromJson(late[f].at("T_world_board")).isApprox(expected_late, 1e-9)) << f;
    EXPECT_TRUE(poseFromJson(on_time[f].at("T_world_board")).isApprox(expected, 1e-9)) << f;
    EXPECT_FALSE(late[f].at("floor").get<bool>());
  }
  EXPECT_FALSE(fs::exists(dir / "floor.json"));
  EXPECT_EQ(readJsonFile(dir / "truth/board_frames.json").at("floor_frames"), nlohmann::json::array());
  const nlohmann::json take = readJsonFile(dir / "take.json");
  EXPECT_EQ(take.at("options").at("delay_frames").at("witness02"), 2);
  EXPECT_EQ(take.at("options").at("board_seed"), 77);
  EXPECT_TRUE(poseFromJson(take.at("options").at("bump").at("main")).isApprox(bump, 1e-12));
}

TEST(SynthOptionsTest, BadOptionsNameTheField) {
  auto fieldOf = [](const SynthOptions& o) -> std::string {
    try {
      o.validate();
    } catch (const Error& e) {
      return e.context().field;
    }
    return "(accepted)";
  };
  SynthOptions o;
  EXPECT_EQ(fieldOf(o), "(accepted)");
  o.frames = 0;
  EXPECT_EQ(fieldOf(o), "frames");
  o = SynthOptions{};
  o.frames = -3;
  EXPECT_EQ(fieldOf(o), "frames");
  o = SynthOptions{};
  o.witness_width = 0;
  EXPECT_EQ(fieldOf(o), "witness_width");
  o = SynthOptions{};
  o.main_height = 0;
  EXPECT_EQ(fieldOf(o), "main_height");
  o = SynthOptions{};
  o.samples_per_pixel = 2;
  EXPECT_EQ(fieldOf(o), "samples_per_pixel");
  o = SynthOptions{};
  o.board = "dartboard";
  EXPECT_EQ(fieldOf(o), "board");
  o = SynthOptions{};
  o.camera = "drone";
  EXPECT_EQ(fieldOf(o), "camera");
  o = SynthOptions{};
  o.shutter = 1.5;
  EXPECT_EQ(fieldOf(o), "shutter");
  // Rig- and studio-only options, and camera names the take does not have.
  o = SynthOptions{};
  o.delay_frames["witness01"] = 1;
  EXPECT_EQ(fieldOf(o), "(accepted)");  // studio preset: an unsynchronised camera
  o.preset = Preset::kIntrinsics;
  EXPECT_EQ(fieldOf(o), "delay_frames");
  o.preset = Preset::kRig;
  EXPECT_EQ(fieldOf(o), "(accepted)");
  o.delay_frames["witness09"] = 1;  // 8 witnesses
  EXPECT_EQ(fieldOf(o), "delay_frames");
  try {
    o.validate();
  } catch (const Error& e) {
    EXPECT_EQ(e.context().camera, "witness09");
  }
  // Studio-only stream forms, checked by the writer's own rules.
  o = SynthOptions{};
  o.camera_format = "webp";
  EXPECT_EQ(fieldOf(o), "camera_format");
  o = SynthOptions{};
  o.start_timecode = "1:00";
  EXPECT_EQ(fieldOf(o), "start_timecode");
  o = SynthOptions{};
  o.late_frames["witness01"] = 24;  // the take has 24 frames
  EXPECT_EQ(fieldOf(o), "late_frames");
  o = SynthOptions{};
  o.preset = Preset::kRig;
  o.camera_format = "ffv1";
  EXPECT_EQ(fieldOf(o), "camera_format");
  o = SynthOptions{};
  o.preset = Preset::kRig;
  o.bump["witness1"] = Pose::Identity();
  EXPECT_EQ(fieldOf(o), "bump");
  o = SynthOptions{};
  o.preset = Preset::kIntrinsics;
  o.floor_frames = false;
  EXPECT_EQ(fieldOf(o), "floor_frames");
  try {
    presetFromString("documentary");
    ADD_FAILURE() << "unknown preset accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.context().field, "preset");
    EXPECT_NE(std::string(e.what()).find("documentary"), std::string::npos);
  }
  EXPECT_EQ(presetFromString("rig"), Preset::kRig);
  // synthesizeTake validates before writing anything.
  const fs::path dir = tmpDir("bad");
  o = SynthOptions{};
  o.frames = 0;
  EXPECT_THROW(synthesizeTake(o, dir), Error);
  EXPECT_FALSE(fs::exists(dir));
}

// Small intrinsics takes: one camera, one frame — cheap enough to render several variants.
cv::Mat renderIntrinsicsFrame(const std::string& name, double noise, double blur,
                              std::uint64_t seed = 5) {
  const fs::path dir = tmpDir(name);
  SynthOptions o = smallOptions(Preset::kIntrinsics, 1);
  o.camera = "witness";
  o.board = "chessboard";
  o.noise_sigma = noise;
  o.blur_sigma_px = blur;
  o.seed = seed;
  synthesizeTake(o, dir);
  return readImage(dir / "cams/witness01" / frameName(0, "png"));
}

TEST(SynthImage, NoiseHasTheRequestedSigma) {
  const cv::Mat clean = renderIntrinsicsFrame("noise0", 0.0, 0.0);
  for (double sigma : {2.0, 6.0}) {
    const cv::Mat noisy = renderIntrinsicsFrame("noise", sigma, 0.0);
    double sum = 0, sum2 = 0;
    int n = 0;
    for (size_t i = 0; i < clean.total() * 3; ++i) {
      const int a = clean.data[i], b = noisy.data[i];
      if (a < 25 || a > 230) continue;  // away from clipping
      sum += b - a;
      sum2 += double(b - a) * (b - a);
      ++n;
    }
    const double mean = sum / n, sd = std::sqrt(sum2 / n - mean * mean);
    std::printf("noise sigma %.1f: measured std %.3f (mean %.3f) over %d channels\n", sigma, sd,
                mean, n);
    ASSERT_GT(n, 10000);
    EXPECT_NEAR(sd, sigma, 0.1 * sigma);
    // Zero-mean noise; what remains is the clean image's own rounding offset (flat areas share
    // one sub-level residual), at most half a grey level.
    EXPECT_LT(std::abs(mean), 0.5);
  }
}

TEST(SynthImage, BlurIsAGaussianInLinearLight) {
  const double sigma = 1.5;
  const cv::Mat sharp = renderIntrinsicsFrame("blur0", 0.0, 0.0);
  const cv::Mat blurred = renderIntrinsicsFrame("blur", 0.0, sigma);
  // Expected: decode the sharp image to linear light, blur, encode.
  cv::Mat linear(sharp.size(), CV_32FC3);
  for (size_t i = 0; i < sharp.total() * 3; ++i) {
    reinterpret_cast<float*>(linear.data)[i] = static_cast<float>(srgbDecode(sharp.data[i] / 255.0));
  }
  cv::GaussianBlur(linear, linear, cv::Size(0, 0), sigma, sigma, cv::BORDER_REPLICATE);
  double diff = 0;
  for (size_t i = 0; i < sharp.total() * 3; ++i) {
    diff += std::abs(255.0 * srgbEncode(reinterpret_cast<float*>(linear.data)[i]) - blurred.data[i]);
  }
  diff /= sharp.total() * 3;
  auto gradientEnergy = [](const cv::Mat& bgr) {
    cv::Mat gray, gx, gy;
    cv::cvtColor(bgr, gray, cv::COLOR_BGR2GRAY);
    cv::Sobel(gray, gx, CV_32F, 1, 0);
    cv::Sobel(gray, gy, CV_32F, 0, 1);
    return cv::mean(gx.mul(gx) + gy.mul(gy))[0];
  };
  const double ratio = gradientEnergy(blurred) / gradientEnergy(sharp);
  std::printf("blur sigma %.1f: mean |render - blur(decode(sharp))| = %.3f grey levels, gradient "
              "energy ratio %.3f\n", sigma, diff, ratio);
  EXPECT_LT(diff, 0.5);
  EXPECT_LT(ratio, 0.5);
}

TEST(SynthImage, SameSeedWritesIdenticalFilesAnotherSeedDoesNot) {
  const cv::Mat a = renderIntrinsicsFrame("seed_a", 2.0, 0.0, 21);
  const cv::Mat b = renderIntrinsicsFrame("seed_b", 2.0, 0.0, 21);
  const cv::Mat c = renderIntrinsicsFrame("seed_c", 2.0, 0.0, 22);
  EXPECT_TRUE(std::equal(a.datastart, a.dataend, b.datastart));
  EXPECT_FALSE(std::equal(a.datastart, a.dataend, c.datastart));
}

}  // namespace
}  // namespace previz::synth
