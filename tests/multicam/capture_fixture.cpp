// CTest fixture multicam.capture: renders the rig captures the image-level multicam tests solve
// on (synth::RigCapture: 8 witnesses 1280x720 + main 1920x1080, AprilGrid rig board, noise
// sigma 2 grey levels), detects the board in every image with calib::detectBoard (in parallel
// over cameras and frames), and writes the observations and the true rigs to the folder given
// as argv[1] (README.txt there says what each file is). Work already done (same recipe, same
// program bytes, every file present) is skipped, so a second CTest run costs nothing.
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "calib/detect.h"
#include "core/error.h"
#include "core/io.h"
#include "datasets/rig_capture.h"
#include "multicam/observations.h"
#include "tests/multicam/rig_calib_fixtures.h"

namespace fs = std::filesystem;
using namespace previz;

namespace {

// Bump when anything below changes what the files hold.
constexpr int kRecipeVersion = 2;
constexpr int kMainFrames = 300, kDelayedFrames = 100, kResurveyFrames = 40;
constexpr int kDelay = 2;
const char* const kDelayedCamera = "witness03";
const char* const kBumpedCamera = "witness05";

using Clock = std::chrono::steady_clock;
double secondsSince(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

struct DetectStats {
  int images = 0, found = 0, failed = 0;
  int skipped = 0;               // no board in view: not rendered nor detected
  double seconds = 0;
  std::vector<double> error_px;  // detected minus true pixel, matched by id
};

// Renders and detects frames [0, frames) of the cameras listed (indices into the capture's
// rig) into obs. Exceptions never leave the parallel loop: a failed image is recorded in its
// camera's failures.
// An image in which fewer board points are visible than the detector needs (truth: the board is
// out of view, faces away or is hidden) holds no board to find: it is neither rendered nor
// detected. That is ~45 % of the rig's images, and the detector (libapriltag at full resolution
// within the board's window, calib/detect_aprilgrid.cpp) and the rendering are the cost.
void renderAndDetect(const synth::RigCapture& capture, const std::vector<int>& cameras, int frames,
                     multicam::RigObservations& obs, DetectStats& stats) {
  const Clock::time_point start = Clock::now();
  const int n = static_cast<int>(cameras.size()) * frames;
  std::vector<calib::ViewObservations> views(n);
  std::vector<std::string> errors(n);
  std::vector<std::vector<double>> errors_px(n);
  std::vector<char> skipped(n, 0);
  calib::DetectOptions detect;
  detect.measure_focus = false;
  int done = 0, next_report = n / 10;
#pragma omp parallel for schedule(dynamic, 1)
  for (int k = 0; k < n; ++k) {
    const int camera = cameras[k / frames];
    const int frame = k % frames;
    try {
      std::map<int, Eigen::Vector2d> truth;
      for (const synth::BoardObservation& t : capture.truth(camera, frame)) truth[t.id] = t.px;
      if (static_cast<int>(truth.size()) < detect.min_points) {
        skipped[k] = 1;
      } else {
        const cv::Mat image = capture.render(camera, frame);
        views[k] = calib::detectBoard(image, capture.board(), detect, "frame " + std::to_string(frame));
      }
      for (const calib::Observation& o : views[k].points) {
        const auto it = truth.find(o.id);
        errors_px[k].push_back(it == truth.end() ? 1e9 : (o.px - it->second).norm());
      }
    } catch (const std::exception& e) {
      errors[k] = e.what();
    }
#pragma omp critical
    {
      if (++done >= next_report) {
        std::printf("  %d / %d images, %.0f s\n", done, n, secondsSince(start));
        std::fflush(stdout);
        next_report += n / 10;
      }
    }
  }
  for (int k = 0; k < n; ++k) {
    const int camera = cameras[k / frames];
    const int frame = k % frames;
    multicam::CameraDetections& det = obs.cameras[camera];
    ++stats.images;
    stats.skipped += skipped[k];
    if (!errors[k].empty()) {
      det.failures[frame] = errors[k];
      ++stats.failed;
      continue;
    }
    if (!views[k].found()) continue;
    det.frames[frame] = views[k].points;
    ++stats.found;
    stats.error_px.insert(stats.error_px.end(), errors_px[k].begin(), errors_px[k].end());
  }
  stats.seconds += secondsSince(start);
}

multicam::RigObservations emptyObservations(const synth::RigCapture& capture, int frames, bool floor) {
  multicam::RigObservations obs;
  obs.board = capture.board();
  obs.frame_count = frames;
  obs.has_floor = floor;
  obs.floor.board = capture.board();
  obs.floor.T_world_board = capture.floorBoardPose();
  for (int f = 0; f < frames && floor; ++f)
    if (capture.isFloorFrame(f)) obs.floor.frames.push_back(f);
  for (const RigCamera& rc : capture.rig().cameras) {
    multicam::CameraDetections d;
    d.camera = rc.camera.name;
    d.image_size = cv::Size(rc.camera.width, rc.camera.height);
    obs.cameras.push_back(d);
  }
  return obs;
}

void report(const char* what, const DetectStats& s) {
  std::vector<double> e = s.error_px;
  std::sort(e.begin(), e.end());
  const double median = e.empty() ? 0 : e[e.size() / 2];
  const double p99 = e.empty() ? 0 : e[std::min(e.size() - 1, e.size() * 99 / 100)];
  const long wrong = std::count_if(e.begin(), e.end(), [](double v) { return v > 2.0; });
  std::printf("%s: %d images (%d without the board in view, skipped), board found in %d, %d failed, %zu points "
              "(error vs truth: median %.4f px, 99%% %.4f px, %ld beyond 2 px), %.1f s\n",
              what, s.images, s.skipped, s.found, s.failed, e.size(), median, p99, wrong, s.seconds);
  std::fflush(stdout);
}

std::vector<int> allCameras(const synth::RigCapture& capture) {
  std::vector<int> v(capture.rig().cameras.size());
  for (size_t i = 0; i < v.size(); ++i) v[i] = static_cast<int>(i);
  return v;
}

// FNV-1a of this program's bytes, hex.
std::string programHash() {
  const std::string bytes = readTextFile(fs::read_symlink("/proc/self/exe"));
  std::uint64_t h = 14695981039346656037ull;
  for (unsigned char c : bytes) h = (h ^ c) * 1099511628211ull;
  char hex[17];
  std::snprintf(hex, sizeof(hex), "%016llx", static_cast<unsigned long long>(h));
  return hex;
}

int cameraIndex(const Rig& rig, const std::string& name) {
  for (size_t i = 0; i < rig.cameras.size(); ++i)
    if (rig.cameras[i].camera.name == name) return static_cast<int>(i);
  throw Error("no camera '" + name + "' in the studio rig");
}

const char* const kReadme = R"(Rig captures for the image-level tests of multicam (tests/multicam/rig_calib_test.cpp,
sync_test.cpp), written by tests/multicam/capture_fixture.cpp (CTest fixture multicam.capture).
Rendered with synth::RigCapture (8 witnesses 1280x720 + main 1920x1080, studio rig seed 1,
AprilGrid rig board, 4 samples per pixel, noise sigma 2 grey levels), board detected in every
image with calib::detectBoard (default options; images in which fewer than 6 board points are
visible — board out of view, facing away, hidden — are skipped: they hold no board to find).
Observation files: docs/formats.md
"Rig observations"; pixels: (0,0) = centre of the top-left pixel; metres.

main.json                 300 frames, board seed 1: frames 0-296 wave the board through the
                          volume, 297-299 show it lying on the floor (floor frames; the floor
                          board's pose T_world_board defines the world: z up, metres).
truth_rig.json            the true rig of main.json and delayed_witness03.json.
delayed_witness03.json    frames 0-99 of the same capture with witness03 late by 2 frames (its
                          frame f shows the board of frame f - 2, clamped at 0). No floor frames.
                          The other cameras' images are those of main.json (same recipe), so
                          their detections are main.json's frames 0-99.
resurvey_witness05.json   40 frames, board seed 2, no floor frames (every frame waves the board),
                          witness05 knocked: its pose is T_world_cam * bump, the bump moving its
                          centre 3 cm and turning it 1 degree (tests/multicam/rig_calib_fixtures.h
                          witnessBump()).
truth_rig_bumped.json     the true rig of resurvey_witness05.json (witness05 bumped).
stamp.json                recipe version, a hash of the fixture program and timings; while they
                          match, the fixture does nothing.
)";

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s OUTPUT_DIR\n", argv[0]);
    return 2;
  }
  const fs::path dir = argv[1];
  const fs::path stamp = dir / "stamp.json";
  const std::vector<std::string> files = {"main.json", "truth_rig.json", "delayed_witness03.json",
                                          "resurvey_witness05.json", "truth_rig_bumped.json", "README.txt"};
  try {
    // The files depend on this recipe and on the renderer and detector linked into this program:
    // a program whose bytes changed makes them again (a relink that pulls in nothing new, e.g.
    // after a change to the rig solve, which this program does not link, keeps them).
    const std::string program = programHash();
    if (fs::exists(stamp)) {
      const nlohmann::json j = readJsonFile(stamp);
      const bool complete = std::all_of(files.begin(), files.end(), [&](const std::string& f) { return fs::exists(dir / f); });
      if (complete && j.value("version", 0) == kRecipeVersion && j.value("program", std::string()) == program) {
        std::printf("multicam capture up to date in %s\n", dir.string().c_str());
        return 0;
      }
    }
    fs::create_directories(dir);
    fs::remove(stamp);
    const Clock::time_point start = Clock::now();
    nlohmann::json timings;

    // (i) the main capture: 300 frames, floor frames at the end.
    synth::RigCaptureOptions main_options;
    main_options.frames = kMainFrames;
    const synth::RigCapture main_capture(main_options);
    multicam::RigObservations main_obs = emptyObservations(main_capture, kMainFrames, true);
    DetectStats main_stats;
    renderAndDetect(main_capture, allCameras(main_capture), kMainFrames, main_obs, main_stats);
    report("main", main_stats);
    timings["main_s"] = main_stats.seconds;
    multicam::writeObservations(main_obs, dir / "main.json");
    writeRig(main_capture.rig(), dir / "truth_rig.json");

    // (ii) witness03 two frames late: only its images differ from the main capture's.
    synth::RigCaptureOptions delayed_options = main_options;
    delayed_options.delay_frames[kDelayedCamera] = kDelay;
    const synth::RigCapture delayed_capture(delayed_options);
    const int delayed_index = cameraIndex(delayed_capture.rig(), kDelayedCamera);
    {
      // The reuse rests on the images being the same: checked on one frame of another camera.
      const int other = delayed_index == 0 ? 1 : 0;
      const cv::Mat a = main_capture.render(other, 10), b = delayed_capture.render(other, 10);
      if (cv::norm(a, b, cv::NORM_INF) != 0)
        throw Error("the delayed capture's images differ from the main capture's for a camera on time");
    }
    multicam::RigObservations delayed_obs = emptyObservations(delayed_capture, kDelayedFrames, false);
    for (size_t c = 0; c < delayed_obs.cameras.size(); ++c) {
      if (static_cast<int>(c) == delayed_index) continue;
      for (const auto& [frame, points] : main_obs.cameras[c].frames)
        if (frame < kDelayedFrames) delayed_obs.cameras[c].frames[frame] = points;
      for (const auto& [frame, why] : main_obs.cameras[c].failures)
        if (frame < kDelayedFrames) delayed_obs.cameras[c].failures[frame] = why;
    }
    DetectStats delayed_stats;
    renderAndDetect(delayed_capture, {delayed_index}, kDelayedFrames, delayed_obs, delayed_stats);
    report("delayed witness03", delayed_stats);
    timings["delayed_s"] = delayed_stats.seconds;
    multicam::writeObservations(delayed_obs, dir / "delayed_witness03.json");

    // (iv) re-survey: a new 40-frame capture without floor, witness05 knocked.
    synth::RigCaptureOptions resurvey_options;
    resurvey_options.frames = kResurveyFrames;
    resurvey_options.board_seed = 2;
    resurvey_options.floor_frames = false;
    resurvey_options.bump[kBumpedCamera] = multicam::testing::witnessBump();
    const synth::RigCapture resurvey_capture(resurvey_options);
    multicam::RigObservations resurvey_obs = emptyObservations(resurvey_capture, kResurveyFrames, false);
    DetectStats resurvey_stats;
    renderAndDetect(resurvey_capture, allCameras(resurvey_capture), kResurveyFrames, resurvey_obs, resurvey_stats);
    report("resurvey witness05", resurvey_stats);
    timings["resurvey_s"] = resurvey_stats.seconds;
    multicam::writeObservations(resurvey_obs, dir / "resurvey_witness05.json");
    writeRig(resurvey_capture.rig(), dir / "truth_rig_bumped.json");

    writeFileAtomic(dir / "README.txt", kReadme);
    timings["total_s"] = secondsSince(start);
    timings["threads"] = omp_get_max_threads();
    writeJsonAtomic(stamp, {{"version", kRecipeVersion}, {"program", program}, {"timings", timings}});
    std::printf("multicam capture written to %s in %.1f s on %d threads\n", dir.string().c_str(),
                secondsSince(start), omp_get_max_threads());
    return 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "multicam capture: %s\n", e.what());
    return 1;
  }
}
