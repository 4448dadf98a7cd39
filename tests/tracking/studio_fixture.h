// Fixtures for the tracking tests and benchmark: the synthetic studio's tagged crate seen by the
// studio rig's witness cameras, rendered by the studio's own renderer (datasets/render.h) with
// the true lenses, 4 samples per pixel and noise. To keep 8 x 1280x720 frames affordable, each
// frame traces only a window around the projected crate (the crate's box corners + 48 px): the
// window is rendered through the same camera with its principal point shifted, so its pixels are
// the full render's (the sample pattern is the same for every pixel; the noise is the same
// Gaussian, drawn for the window's pixel coordinates). The rest of the frame is the camera's
// empty stage (rendered once, stage layer only, no actor) with the same noise added: outside the
// window no tag can be, and the full-frame detector still searches every pixel of it.
#pragma once

#include <algorithm>
#include <filesystem>
#include <cmath>
#include <map>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>

#include <Eigen/Geometry>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "core/error.h"
#include "core/io.h"
#include "core/rig.h"
#include "datasets/render.h"
#include "datasets/rigs.h"
#include "datasets/studio.h"
#include "tracking/props.h"

namespace previz::tracking::test {

template <class F>
void parallelFor(int n, F body) {
  const int threads = std::max(1u, std::thread::hardware_concurrency());
  std::vector<std::thread> pool;
  for (int t = 0; t < threads; ++t)
    pool.emplace_back([&, t] {
      for (int i = t; i < n; i += threads) body(i);
    });
  for (auto& th : pool) th.join();
}

// The studio's crate as tracking's PropDef (the same numbers props.json carries).
inline PropSet studioProps(const synth::Studio& studio) {
  const synth::PropSpec& s = studio.prop();
  PropDef p;
  p.id = s.id;
  p.name = s.name;
  p.box_size_m = s.box_size_m;
  for (const synth::PropTag& t : s.tags) p.tags.push_back({t.family, t.id, t.size_m, t.T_prop_tag});
  PropSet set;
  set.props.push_back(p);
  return set;
}

struct StudioFixture {
  synth::StudioConfig config;
  synth::Studio studio{config};
  Rig rig;  // the 8 witnesses at 1280x720 (no main camera)
  // The empty stages are cached as PNG files in cache_dir when given (shared by the test
  // processes: CTest runs each test in its own process; files are written atomically).
  std::filesystem::path cache_dir;
  double noise_sigma = 2.0;
  mutable std::vector<cv::Mat> stage;  // per camera: empty stage, no noise
  mutable std::once_flag stage_once;

  // fisheye_witnesses: the first N witnesses with a fisheye lens (datasets/rigs.h witnessCamera).
  explicit StudioFixture(std::filesystem::path stage_cache = {}, int width = 1280, int height = 720,
                         int fisheye_witnesses = 0)
      : cache_dir(std::move(stage_cache)) {
    synth::StudioRigOptions o;
    o.witness_width = width;
    o.witness_height = height;
    o.with_main = false;
    o.fisheye_witnesses = fisheye_witnesses;
    rig = synth::studioRig(o, config.take_duration_s, true);
  }

  int cameras() const { return static_cast<int>(rig.cameras.size()); }

  void renderStage() const {
    std::call_once(stage_once, [&] {
      stage.resize(rig.cameras.size());
      const synth::Scene scene = studio.sceneAt(0.0, synth::kLayerStage);
      parallelFor(cameras(), [&](int c) {
        const RigCamera& rc = rig.cameras[static_cast<size_t>(c)];
        const std::filesystem::path file =
            cache_dir / (rc.camera.name + "_" + std::to_string(rc.camera.width) + "x" +
                         std::to_string(rc.camera.height) + "_seed" + std::to_string(config.seed) +
                         (rc.camera.dist.isBrown() ? "" : "_kb") + ".png");
        if (!cache_dir.empty() && std::filesystem::exists(file)) {
          try {
            stage[static_cast<size_t>(c)] = readImage(file, cv::IMREAD_COLOR);
            return;
          } catch (const Error&) {
            // A damaged cache file: rendered again below.
          }
        }
        synth::RenderOptions ro;
        ro.truth = false;
        ro.threads = 1;
        stage[static_cast<size_t>(c)] = synth::renderView(rc.camera, rc.T_world_cam, scene, ro).bgr;
        if (!cache_dir.empty()) writeImageAtomic(file, stage[static_cast<size_t>(c)]);
      });
    });
  }

  // Window of camera c around the prop at T_world_prop (empty when not in view).
  cv::Rect propWindow(int c, const Pose& T_world_prop, int margin = 48) const {
    const RigCamera& rc = rig.cameras[static_cast<size_t>(c)];
    const Pose T_cam_prop = rc.T_world_cam.inverse() * T_world_prop;
    const Eigen::Vector3d h = 0.5 * studio.prop().box_size_m;
    double u0 = 1e18, v0 = 1e18, u1 = -1e18, v1 = -1e18;
    for (int k = 0; k < 8; ++k) {
      const Eigen::Vector3d X((k & 1 ? 1 : -1) * h.x(), (k & 2 ? 1 : -1) * h.y(), (k & 4 ? 1 : -1) * h.z());
      const auto px = rc.camera.project(T_cam_prop * X);
      if (!px) return {};
      u0 = std::min(u0, px->x());
      v0 = std::min(v0, px->y());
      u1 = std::max(u1, px->x());
      v1 = std::max(v1, px->y());
    }
    const cv::Rect r(cv::Point(static_cast<int>(u0) - margin, static_cast<int>(v0) - margin),
                     cv::Point(static_cast<int>(u1) + margin, static_cast<int>(v1) + margin));
    return r & cv::Rect(0, 0, rc.camera.width, rc.camera.height);
  }

  // The crate at T_world_prop (with the actor of time_s when 'actor'), camera c, frame 'frame'
  // (noise stream). 'scene' must contain the prop at T_world_prop.
  // Adds N(0, noise_sigma) grey levels to the pixels of 'region' (rounded, saturated).
  void addNoise(cv::Mat& img, const cv::Rect& region, std::uint64_t seed) const {
    if (region.area() <= 0) return;
    cv::Mat view = img(region);
    cv::Mat noise(view.size(), CV_32FC3);
    cv::RNG rng(seed);
    rng.fill(noise, cv::RNG::NORMAL, 0.0, noise_sigma);
    cv::Mat f;
    view.convertTo(f, CV_32FC3);
    f += noise;
    f.convertTo(view, CV_8UC3);
  }

  // 'clean': no noise in the window (callers add their own per frame with addNoise).
  cv::Mat renderWith(int c, const synth::Scene& scene, const Pose& T_world_prop, int frame, bool clean = false,
                     int margin = 48) const {
    renderStage();
    const RigCamera& rc = rig.cameras[static_cast<size_t>(c)];
    cv::Mat img = stage[static_cast<size_t>(c)].clone();
    // Noise over the whole frame (the window gets the renderer's own noise instead).
    addNoise(img, cv::Rect(0, 0, img.cols, img.rows),
             0x9e3779b97f4a7c15ULL ^ (static_cast<std::uint64_t>(c) << 32) ^ static_cast<std::uint64_t>(frame));
    const cv::Rect w = propWindow(c, T_world_prop, margin);
    if (w.area() <= 0) return img;
    Camera crop = rc.camera;
    crop.width = w.width;
    crop.height = w.height;
    crop.cx -= w.x;
    crop.cy -= w.y;
    synth::RenderOptions ro;
    ro.truth = false;
    ro.threads = 1;
    ro.noise_sigma = clean ? 0.0 : noise_sigma;
    ro.camera_index = c;
    ro.frame = frame;
    synth::renderView(crop, rc.T_world_cam, scene, ro).bgr.copyTo(img(w));
    return img;
  }

  // The take's frame at time_s: actor, crate and stage as the studio has them.
  std::vector<cv::Mat> renderTake(double time_s, int frame, int margin = 48) const {
    const synth::Scene scene = studio.sceneAt(time_s, synth::kLayersPlate);
    const Pose T = studio.T_world_prop(time_s);
    std::vector<cv::Mat> images(rig.cameras.size());
    parallelFor(cameras(), [&](int c) {
      images[static_cast<size_t>(c)] = renderWith(c, scene, T, frame, false, margin);
    });
    return images;
  }
};

}  // namespace previz::tracking::test
