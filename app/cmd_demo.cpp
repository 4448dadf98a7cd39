// previz demo (README command 1): renders the built-in synthetic studio, writes a contact sheet,
// runs the live frame (key -> carve -> main-view depth -> composite, app/frame_loop.h) over the
// take with its rig, and writes a report page (report.html) with the composites beside the true
// ones, depth previews, the front/behind layer and the stage timings. Calibrating the cameras
// from board takes is not part of the demo yet: it runs on the take's rig (truth/rig.json).
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <sstream>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "app/commands.h"
#include "app/frame_loop.h"
#include "carving/take.h"
#include "composite/output.h"
#include "app/options.h"
#include "app/progress.h"
#include "core/io.h"
#include "core/rig.h"
#include "datasets/synth.h"

namespace previz::app {
namespace {

namespace fs = std::filesystem;

struct DemoArgs {
  std::string out = "out/demo";
  std::string size;
  int frames = 12;
  int cams = 8;
  std::uint64_t seed = 1;
  bool json = false;
  bool quiet = false;
};

// Depth in metres -> false-colour preview (near = warm), black where empty (+inf).
cv::Mat depthPreview(const cv::Mat& depth_m) {
  double lo = 1e9, hi = 0;
  for (int y = 0; y < depth_m.rows; ++y) {
    for (int x = 0; x < depth_m.cols; ++x) {
      const float z = depth_m.at<float>(y, x);
      if (std::isfinite(z)) {
        lo = std::min(lo, double(z));
        hi = std::max(hi, double(z));
      }
    }
  }
  cv::Mat grey(depth_m.size(), CV_8U, cv::Scalar(0));
  cv::Mat valid(depth_m.size(), CV_8U, cv::Scalar(0));
  for (int y = 0; y < depth_m.rows; ++y) {
    for (int x = 0; x < depth_m.cols; ++x) {
      const float z = depth_m.at<float>(y, x);
      if (!std::isfinite(z) || hi <= lo) continue;
      grey.at<uchar>(y, x) = cv::saturate_cast<uchar>(255.0 * (hi - z) / (hi - lo));
      valid.at<uchar>(y, x) = 255;
    }
  }
  cv::Mat colour;
  cv::applyColorMap(grey, colour, cv::COLORMAP_TURBO);
  cv::Mat out(depth_m.size(), CV_8UC3, cv::Scalar(0, 0, 0));
  colour.copyTo(out, valid);
  return out;
}

cv::Mat labelled(const cv::Mat& bgr, const std::string& text, cv::Size tile) {
  cv::Mat t;
  cv::resize(bgr, t, tile, 0, 0, cv::INTER_AREA);
  cv::rectangle(t, cv::Rect(0, 0, tile.width, 22), cv::Scalar(0, 0, 0), cv::FILLED);
  cv::putText(t, text, cv::Point(6, 16), cv::FONT_HERSHEY_SIMPLEX, 0.5, cv::Scalar(255, 255, 255), 1,
              cv::LINE_AA);
  return t;
}

// One row per view: every camera's plate, then the main camera's truth layers.
cv::Mat contactSheet(const fs::path& take, const Rig& rig, int frame) {
  char name[32];
  std::snprintf(name, sizeof(name), "%06d", frame);
  const cv::Size tile(384, 216);
  std::vector<cv::Mat> tiles;
  for (const RigCamera& rc : rig.cameras) {
    const std::string& cam = rc.camera.name;
    tiles.push_back(labelled(readImage(take / "cams" / cam / (std::string(name) + ".png"), cv::IMREAD_COLOR),
                             cam + " plate", tile));
  }
  const fs::path truth = take / "truth";
  tiles.push_back(labelled(depthPreview(readDepthExr(truth / "depth" / "main" / (std::string(name) + ".exr"))),
                           "main depth (truth)", tile));
  cv::Mat mask = readImage(truth / "masks" / "main" / (std::string(name) + ".png"), cv::IMREAD_GRAYSCALE);
  cv::Mat mask_bgr;
  cv::cvtColor(mask, mask_bgr, cv::COLOR_GRAY2BGR);
  tiles.push_back(labelled(mask_bgr, "main actor mask (truth)", tile));
  tiles.push_back(labelled(readImage(truth / "composite" / (std::string(name) + ".png"), cv::IMREAD_COLOR),
                           "true composite (target)", tile));
  const int cols = 4;
  const int rows = (static_cast<int>(tiles.size()) + cols - 1) / cols;
  cv::Mat sheet(rows * tile.height, cols * tile.width, CV_8UC3, cv::Scalar(40, 40, 40));
  for (size_t i = 0; i < tiles.size(); ++i) {
    const int r = static_cast<int>(i) / cols, c = static_cast<int>(i) % cols;
    tiles[i].copyTo(sheet(cv::Rect(c * tile.width, r * tile.height, tile.width, tile.height)));
  }
  return sheet;
}

std::string stem(int frame) {
  char s[32];
  std::snprintf(s, sizeof(s), "%06d", frame);
  return s;
}

// Runs the live frame over the take (true rig, true main poses) into out/run and returns the
// per-frame stage timings.
std::vector<std::vector<StageTime>> runTake(const fs::path& take_dir, const fs::path& out, bool quiet) {
  carving::TakeSource src;
  src.take_dir = take_dir;
  src.rig_path = take_dir / "truth" / "rig.json";
  src.main_poses = take_dir / "truth" / "main_poses.jsonl";
  const carving::Take take(src);
  FrameLoopOptions lo;
  lo.debug_layers = true;
  FrameLoop loop(take.rig(), composite::readCgCamera(take_dir / "cg" / "camera.json"), lo);
  const TakeReader reader(take, loop, TakeInputOptions{});
  composite::OutputOptions oo;
  oo.out = out;
  oo.layers = true;
  oo.video = "composite.avi";
  oo.fourcc = "MJPG";
  composite::CompositeWriter writer(oo);
  std::vector<std::vector<StageTime>> times;
  ProgressLine progress("demo run", static_cast<int>(take.frames().size()), quiet);
  for (int f : take.frames()) {
    FrameState s;
    reader.read(f, s);
    times.push_back(loop.run(s));
    writer.write(f, s.composite);
    progress.update(static_cast<int>(times.size()));
  }
  writer.close();
  return times;
}

// report.html beside the take: every path in it is relative, so the folder can be moved.
void writeReport(const fs::path& out, const std::vector<int>& frames, const std::vector<std::vector<StageTime>>& times,
                 const synth::SynthOptions& o) {
  std::map<std::string, double> mean;
  std::vector<std::string> order;
  for (const auto& frame : times)
    for (const StageTime& t : frame) {
      if (!mean.count(t.stage)) order.push_back(t.stage);
      mean[t.stage] += t.ms / times.size();
    }
  std::ostringstream h;
  h << "<!DOCTYPE html><html><head><meta charset=\"utf-8\"><title>previz demo</title><style>"
       "body{font-family:sans-serif;background:#222;color:#ddd;margin:2em}img{width:100%}"
       "table{border-collapse:collapse}td,th{border:1px solid #555;padding:4px 10px;text-align:right}"
       ".row{display:grid;grid-template-columns:repeat(4,1fr);gap:6px;margin-bottom:14px}"
       ".row div{font-size:12px}</style></head><body>\n";
  h << "<h1>previz demo: the synthetic studio, end to end</h1>\n";
  h << "<p>" << o.witness_cameras << " witness cameras " << o.witness_width << "x" << o.witness_height << " + main "
    << o.main_width << "x" << o.main_height << ", " << frames.size()
    << " frames over the 10 s choreography (the actor walks behind the CG pillar, then in front of it). "
       "Rig: the take's own (truth/rig.json). Per frame: key &rarr; carve &rarr; main-view depth &rarr; composite.</p>\n";
  h << "<p><img src=\"contact_sheet.png\" style=\"width:60%\"></p>\n";
  h << "<h2>Stage timings (mean wall ms a frame, this machine)</h2><table><tr><th>stage</th><th>ms</th></tr>\n";
  double total = 0;
  for (const std::string& s : order) {
    h << "<tr><td style=\"text-align:left\">" << s << "</td><td>" << mean[s] << "</td></tr>\n";
    total += mean[s];
  }
  h << "<tr><th style=\"text-align:left\">total</th><th>" << total << "</th></tr></table>\n";
  h << "<p>Target of the live loop: 20 ms a frame on 2 cores (see <code>previz bench run</code>).</p>\n";
  h << "<h2>Frames</h2><p>composite (previz) &middot; true composite &middot; actor depth used (turbo, 2&ndash;12 m) "
       "&middot; in front: green actor, red CG, magenta fallback (no depth)</p>\n";
  for (int f : frames) {
    const std::string s = stem(f);
    h << "<div class=\"row\">"
      << "<div><img src=\"run/composite/" << s << ".png\">frame " << f << "</div>"
      << "<div><img src=\"take/truth/composite/" << s << ".png\">truth</div>"
      << "<div><img src=\"run/layers/actor_depth/" << s << ".png\">actor depth</div>"
      << "<div><img src=\"run/layers/front/" << s << ".png\">front</div></div>\n";
  }
  h << "<p>Video: <a href=\"run/composite.avi\">run/composite.avi</a>. Files: docs/formats.md.</p></body></html>\n";
  writeFileAtomic(out / "report.html", h.str());
}

}  // namespace

Runner addDemoCommand(CLI::App& app) {
  auto a = std::make_shared<DemoArgs>();
  CLI::App* cmd = app.add_subcommand(
      "demo", "Render the built-in synthetic studio, run the live frame over it, write a report page (README command 1)");
  cmd->add_option("--out", a->out, "Output folder (the take goes to OUT/take)")->capture_default_str();
  cmd->add_option("--frames", a->frames, "Frames to render")->capture_default_str();
  cmd->add_option("--cams", a->cams, "Witness cameras")->capture_default_str();
  cmd->add_option("--size", a->size, "Witness size WxH (default 1280x720; main scales with it)");
  cmd->add_option("--seed", a->seed, "Random seed")->capture_default_str();
  cmd->add_flag("--json", a->json, "JSON summary on stdout");
  cmd->add_flag("--quiet", a->quiet, "No progress line");

  return [a]() {
    synth::SynthOptions o;
    o.preset = synth::Preset::kStudio;
    o.frames = a->frames;
    o.witness_cameras = a->cams;
    o.seed = a->seed;
    o.noise_sigma = 1.5;
    // The studio's choreography (walk behind the pillar, arms up, turn, walk in front) lasts
    // 10 s; the demo samples all of it with however many frames it renders.
    o.fps = std::max(1, a->frames) / 10.0;
    if (!a->size.empty()) {
      const auto [w, h] = parseSize(a->size, "--size");
      o.main_width = static_cast<int>(o.main_width * static_cast<double>(w) / o.witness_width + 0.5);
      o.main_height = static_cast<int>(o.main_height * static_cast<double>(h) / o.witness_height + 0.5);
      o.witness_width = w;
      o.witness_height = h;
    }
    o.validate();
    const fs::path out(a->out);
    const fs::path take = out / "take";
    std::cerr << "demo: rendering the synthetic studio (" << o.witness_cameras << " witness "
              << o.witness_width << "x" << o.witness_height << " + main " << o.main_width << "x"
              << o.main_height << ", " << o.frames << " frames) into " << take << "\n";
    ProgressLine progress("demo synth", o.frames, a->quiet);
    const synth::SynthSummary s = synth::synthesizeTake(
        o, take, [&](const synth::SynthProgress& p) { progress.update(p.frames_done); });

    const Rig rig = readRig(take / "truth" / "rig.json");
    const int frame = o.frames / 2;
    const fs::path sheet_path = out / "contact_sheet.png";
    writeImageAtomic(sheet_path, contactSheet(take, rig, frame));
    std::cerr << "demo: running the live frame over the take (key, carve, depth, composite) into " << out / "run" << "\n";
    const std::vector<std::vector<StageTime>> times = runTake(take, out / "run", a->quiet);
    std::vector<int> frames;
    for (int f = 0; f < o.frames; ++f) frames.push_back(f);
    writeReport(out, frames, times, o);
    const nlohmann::json summary = {{"command", "demo"},
                                    {"take", take.string()},
                                    {"frames", s.frames},
                                    {"cameras", s.cameras},
                                    {"render_ms", s.render_ms},
                                    {"ms_per_camera_frame", s.ms_per_camera_frame},
                                    {"contact_sheet", sheet_path.string()},
                                    {"report", (out / "report.html").string()}};
    writeJsonAtomic(out / "summary.json", summary);
    std::cerr << "demo: take in " << take << ", contact sheet " << sheet_path << " (frame " << frame
              << "), " << s.ms_per_camera_frame << " ms per camera-frame; report " << out / "report.html" << "\n";
    if (a->json) std::cout << summary.dump() << "\n";
    return 0;
  };
}

}  // namespace previz::app
