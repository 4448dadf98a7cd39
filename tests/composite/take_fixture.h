// The studio take the end-to-end composite tests run on, and the measures of issue 7 item 1
// against its truth: PSNR over the actor's bounding box against truth/composite, and wrong-side
// pixels (the actor drawn in front of the CG where the truth has it behind, or the reverse),
// with a breakdown of where they are.
#pragma once

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <string>
#include <vector>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "live/frame_loop.h"
#include "live/inputs.h"
#include "carving/take.h"
#include "composite/measure.h"
#include "composite/output.h"
#include "core/io.h"
#include "datasets/render.h"
#include "datasets/studio.h"
#include "datasets/synth.h"
#include "tests/scratch.h"

namespace previz::composite::test {

namespace fs = std::filesystem;

// 5 frames 2 s apart (fps 0.5): t = 0, 2, 4, 6, 8 s of the 10 s choreography; at about 2 s the
// actor passes behind the CG pillar, at about 8 s in front of it. 8 witnesses 640x360, main
// 960x540 on its dolly; 4 samples per pixel, no noise.
inline synth::SynthOptions takeOptions() {
  synth::SynthOptions o;
  o.frames = 5;
  o.fps = 0.5;
  o.witness_width = 640;
  o.witness_height = 360;
  o.main_width = 960;
  o.main_height = 540;
  o.write_meshes = false;
  return o;
}

// The CTest fixture composite.take renders it once per CTest run (`previz synth` with the same
// options) into PREVIZ_COMPOSITE_TAKE; a test process run on its own, without it, renders its
// own copy once.
inline const fs::path& studioTake() {
  static const fs::path dir = [] {
    const fs::path shared(PREVIZ_COMPOSITE_TAKE);
    const synth::SynthOptions o = takeOptions();
    if (fs::exists(shared / "take.json")) {
      const nlohmann::json t = readJsonFile(shared / "take.json");
      const nlohmann::json& opt = t.at("options");
      if (t.value("frames", 0) == o.frames && t.value("fps", 0.0) == o.fps && opt.value("witness_width", 0) == o.witness_width &&
          opt.value("main_width", 0) == o.main_width && opt.value("seed", 0) == static_cast<int>(o.seed))
        return shared;
    }
    const fs::path d = previz::test::scratchDir("composite", "studio");
    synth::synthesizeTake(o, d);
    return d;
  }();
  return dir;
}

inline std::string stem(int frame) {
  char s[32];
  std::snprintf(s, sizeof(s), "%06d", frame);
  return s;
}

struct FrameMeasure {
  int frame = 0;
  double psnr_db = 0;
  cv::Rect bbox;
  long long actor_px = 0;      // truth mask
  long long truth_behind_px = 0;  // of those, behind the CG in truth
  long long wrong_px = 0;      // drawn on the wrong side (where the key has the actor)
  long long key_missed_px = 0; // truth actor pixels the key gave alpha 0
  // Where the wrong-side pixels are.
  long long wrong_fallback = 0;     // no actor depth: drawn in front by the fallback
  long long wrong_near_edge = 0;    // within 2 px of the true silhouette's edge
  long long wrong_hull_front = 0;   // actor depth > 2 cm in front of the true surface (hull)
  long long wrong_hull_behind = 0;  // actor depth > 2 cm behind the true surface
  long long wrong_other = 0;
  double comp_ms = 0;
};

struct TakeMeasure {
  std::vector<FrameMeasure> frames;
  double min_psnr_db = std::numeric_limits<double>::infinity();
  long long actor_px = 0, wrong_px = 0;
  // |actor depth - true depth| (m) at the true actor pixels at least 2 px inside its silhouette
  // where the loop has an actor depth, every frame.
  std::vector<float> depth_err;
  double depthErrQuantile(double q) const {
    if (depth_err.empty()) return std::numeric_limits<double>::infinity();
    std::vector<float> e = depth_err;
    const size_t k = std::min(e.size() - 1, static_cast<size_t>(q * (e.size() - 1) + 0.5));
    std::nth_element(e.begin(), e.begin() + k, e.end());
    return e[k];
  }
  double wrongFraction() const { return actor_px > 0 ? double(wrong_px) / actor_px : 0; }
};

// The CG set's depth through the main camera's real lens at the frame time, from the
// renderer's pixel-centre rays (exact truth; not the compositor's map).
inline cv::Mat trueCgDepth(const RigCamera& main_true, double time_s) {
  synth::StudioConfig config;
  config.seed = takeOptions().seed;
  const synth::Studio studio(config);
  const synth::Scene scene = studio.sceneAt(time_s, synth::kLayerCg);
  synth::RenderOptions ro;
  ro.samples_per_pixel = 4;
  return synth::renderView(main_true.camera, main_true.T_world_cam, scene, ro).depth;
}

// Runs the frame loop on every frame of the take with 'rig' (+ main poses as given) and measures
// each frame against truth. 'label' heads the printed table.
// tracked_poses: "" = the take's true world poses of main (truth/main_poses.jsonl); else the
// camera tracker's T_main0_main lines (live/frame_loop.h TakeInputOptions).
inline TakeMeasure measureTake(const fs::path& take_dir, const fs::path& rig_path, const fs::path& tracked_poses,
                               const char* label, int witness_bin = 1) {
  carving::TakeSource src;
  src.take_dir = take_dir;
  src.rig_path = rig_path;
  if (tracked_poses.empty()) src.main_poses = take_dir / "truth" / "main_poses.jsonl";
  const carving::Take take(src);
  const Camera cg = readCgCamera(take_dir / "cg" / "camera.json");
  live::FrameLoopOptions lo;
  lo.debug_layers = true;
  lo.witness_bin = witness_bin;
  live::FrameLoop loop(take.rig(), cg, lo);
  live::TakeInputOptions io;
  io.tracked_main_poses = tracked_poses;
  const live::TakeReader reader(take, loop, io);

  // Truth side of the main camera: the true rig and the true poses.
  carving::TakeSource truth_src = src;
  truth_src.main_poses = take_dir / "truth" / "main_poses.jsonl";
  truth_src.rig_path = take_dir / "truth" / "rig.json";
  const carving::Take truth_take(truth_src);

  TakeMeasure out;
  std::printf("  %s:\n", label);
  for (int f : take.frames()) {
    live::FrameState s;
    reader.read(f, s);
    const std::vector<live::StageTime> times = loop.run(s);
    FrameMeasure m;
    m.frame = f;
    for (const live::StageTime& t : times) m.comp_ms += t.ms;
    const cv::Mat truth = readImage(take_dir / "truth" / "composite" / (stem(f) + ".png"), cv::IMREAD_COLOR);
    const cv::Mat mask = readImage(take_dir / "truth" / "masks" / "main" / (stem(f) + ".png"), cv::IMREAD_GRAYSCALE);
    const cv::Mat true_depth = readDepthExr(take_dir / "truth" / "depth" / "main" / (stem(f) + ".exr"));
    const RigCamera main_true = truth_take.cameraAt(loop.mainCamera(), f);
    const cv::Mat cg_depth = trueCgDepth(main_true, f / takeOptions().fps);
    const ActorPsnr actor_psnr = actorPsnr(s.composite.bgr, truth, mask);
    m.bbox = actor_psnr.bbox;
    m.psnr_db = actor_psnr.psnr_db;
    cv::Mat inner;  // pixels at least 2 px inside the true silhouette
    cv::erode(mask, inner, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(5, 5)));
    cv::Mat outer;
    cv::dilate(mask, outer, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(5, 5)));
    for (int v = 0; v < mask.rows; ++v) {
      for (int u = 0; u < mask.cols; ++u) {
        if (mask.at<uchar>(v, u) == 0) continue;
        ++m.actor_px;
        const float zt = true_depth.at<float>(v, u), zc = cg_depth.at<float>(v, u);
        if (inner.at<uchar>(v, u) != 0 && s.composite.layer_front.at<uchar>(v, u) != kFrontNone &&
            std::isfinite(s.composite.layer_actor_depth.at<float>(v, u)) && std::isfinite(zt))
          out.depth_err.push_back(std::abs(s.composite.layer_actor_depth.at<float>(v, u) - zt));
        const bool truth_front = zt < zc;
        m.truth_behind_px += truth_front ? 0 : 1;
        const uchar code = s.composite.layer_front.at<uchar>(v, u);
        if (code == kFrontNone) {
          ++m.key_missed_px;
          continue;
        }
        const bool drawn_front = code != kFrontCg;
        if (drawn_front == truth_front) continue;
        ++m.wrong_px;
        const float za = s.composite.layer_actor_depth.at<float>(v, u);
        if (code == kFrontFallback) ++m.wrong_fallback;
        else if (inner.at<uchar>(v, u) == 0) ++m.wrong_near_edge;
        else if (za < zt - 0.02f) ++m.wrong_hull_front;
        else if (za > zt + 0.02f) ++m.wrong_hull_behind;
        else ++m.wrong_other;
      }
    }
    std::printf("    frame %d (t %.0f s): PSNR %.2f dB over actor bbox %dx%d; actor %lld px (%lld behind CG in truth), "
                "wrong side %lld (%.3f %%: fallback %lld, <2 px from edge %lld, hull >2 cm in front %lld, "
                "hull >2 cm behind %lld, other %lld), key missed %lld; loop %.0f ms\n",
                f, f / takeOptions().fps, m.psnr_db, m.bbox.width, m.bbox.height, m.actor_px, m.truth_behind_px,
                m.wrong_px, m.actor_px ? 100.0 * m.wrong_px / m.actor_px : 0.0, m.wrong_fallback, m.wrong_near_edge,
                m.wrong_hull_front, m.wrong_hull_behind, m.wrong_other, m.key_missed_px, m.comp_ms);
    out.min_psnr_db = std::min(out.min_psnr_db, m.psnr_db);
    out.actor_px += m.actor_px;
    out.wrong_px += m.wrong_px;
    out.frames.push_back(m);
  }
  std::printf("    %s: min PSNR %.2f dB, wrong side %lld of %lld actor px = %.3f %%; actor depth - true depth "
              "median %.1f mm, 90th percentile %.1f mm\n",
              label, out.min_psnr_db, out.wrong_px, out.actor_px, 100.0 * out.wrongFraction(),
              1e3 * out.depthErrQuantile(0.5), 1e3 * out.depthErrQuantile(0.9));
  std::fflush(stdout);
  return out;
}

}  // namespace previz::composite::test
