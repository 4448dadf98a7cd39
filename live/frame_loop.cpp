// The live frame's stages (live/frame_loop.h).
#include "live/frame_loop.h"

#include <omp.h>
#include <time.h>

#include <algorithm>
#include <cstdint>
#include <cmath>
#include <sstream>

#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/io.h"
#include "core/names.h"
#include "core/pose.h"
#include "core/stopwatch.h"
#include "core/threads.h"

namespace previz::live {
namespace {

Error frameError(const std::string& stage, int frame, const std::exception& e) {
  ErrorContext c;
  if (const auto* pe = dynamic_cast<const Error*>(&e)) c = pe->context();
  c.frame = frame;
  const std::string what = dynamic_cast<const Error*>(&e) ? static_cast<const Error&>(e).message() : e.what();
  return Error(stage + " failed: " + what, c);
}

}  // namespace

void FrameLoopOptions::validate() const {
  hull.validate();
  keyer.validate();
  composite.validate();
  if (threads < 0) throw Error("run: threads must be >= 0", fieldContext("threads"));
  if (key_region_margin_px < 0)
    throw Error("run: key_region_margin_px must be >= 0 (got " + std::to_string(key_region_margin_px) + ")",
                fieldContext("key_region_margin_px"));
  if (witness_bin < 1 || witness_bin > 8)
    throw Error("run: witness_bin must be in [1, 8] (got " + std::to_string(witness_bin) + ")",
                fieldContext("witness_bin"));
}

namespace {

// bin x bin pixels of an 8-bit sRGB image averaged as light into dst (size: the scaled camera's,
// Camera::scaled; a block past the image's edge repeats its last row / column). A sensor bins
// light, not codes: the mean of the codes is darker than the mean of the light on every mixed
// pixel of bright screen and dark costume, and the key would read them as more foreground than
// they are (a wider silhouette, a hull nearer the camera). Light is taken as code^2 (gamma 2,
// against sRGB's ~2.2: a half-and-half block of codes 150 and 40 gives 110, sRGB's exact mean
// 112, the code mean 95), which keeps it to integer arithmetic that vectorises; a uniform block
// gives its own code back exactly.
void binLight(const cv::Mat& src, int bin, cv::Size size, cv::Mat& dst) {
  // round(sqrt(m)) for every mean of squared codes m (<= 255^2).
  static const std::vector<std::uint8_t> root = [] {
    std::vector<std::uint8_t> t(65536);
    for (int m = 0; m < 65536; ++m) t[m] = static_cast<std::uint8_t>(std::min(255L, std::lround(std::sqrt(m))));
    return t;
  }();
  dst.create(size, CV_8UC3);
  const int area = bin * bin;
  const int n = 3 * src.cols;
  // Plate columns past the last whole block repeat the last one; a binned size rounded down
  // leaves plate columns no block reads, so the buffer holds whichever is longer.
  std::vector<std::uint32_t> acc(std::max<size_t>(n, static_cast<size_t>(3) * size.width * bin));
  for (int y = 0; y < size.height; ++y) {
    // Squared codes summed down the block's rows (contiguous: the compiler vectorises it).
    std::uint32_t* a = acc.data();
    std::fill(a, a + n, 0u);
    for (int k = 0; k < bin; ++k) {
      const std::uint8_t* p = src.ptr<std::uint8_t>(std::min(y * bin + k, src.rows - 1));
      for (int i = 0; i < n; ++i) a[i] += static_cast<std::uint32_t>(p[i]) * p[i];
    }
    for (int i = n; i < static_cast<int>(acc.size()); ++i) a[i] = a[i - 3];  // repeat the last column
    std::uint8_t* o = dst.ptr<std::uint8_t>(y);
    for (int x = 0; x < size.width; ++x) {
      const std::uint32_t* q = a + 3 * bin * x;
      std::uint32_t b = 0, g = 0, r = 0;
      for (int j = 0; j < bin; ++j, q += 3) {
        b += q[0];
        g += q[1];
        r += q[2];
      }
      o[3 * x] = root[(b + area / 2) / area];
      o[3 * x + 1] = root[(g + area / 2) / area];
      o[3 * x + 2] = root[(r + area / 2) / area];
    }
  }
}

}  // namespace

struct FrameLoop::Impl {
  FrameLoopOptions options;
  std::vector<std::string> carve_names;
  std::string main_name;
  std::vector<carving::Keyer> keyers;  // carving cameras, then main
  // witness_bin > 1: each carving camera's plate size (the rig's) and its binned size (the
  // scaled camera's), and the binned plate, reused frame after frame.
  std::vector<cv::Size> plate_sizes, binned_sizes;
  std::vector<cv::Mat> binned;
  std::unique_ptr<carving::Carver> carver;
  std::unique_ptr<composite::Compositor> compositor;
  std::vector<std::pair<std::string, StageFn>> stages;
  composite::CompositeResult result;  // images reused frame after frame
  carving::KeyResult main_key;        // likewise (the main camera's 2 Mpx: no allocation per frame)
  std::vector<carving::KeyResult> witness_keys;
  cv::Mat foreground;
  cv::Mat main_depth;                 // likewise
  std::optional<int> last_frame;      // the last frame keyed (region keying needs consecutive ones)

  int threads() const { return resolveThreads(options.threads); }

  void key(FrameState& s) {
    const int n = static_cast<int>(carve_names.size());
    s.silhouettes.assign(n, cv::Mat());
    if (s.dropped.size() != static_cast<size_t>(n)) s.dropped.assign(n, "");
    if (s.witness_plates.size() != static_cast<size_t>(n))
      throw Error("key: expected " + std::to_string(n) + " witness plates (got " +
                  std::to_string(s.witness_plates.size()) + ")");
    std::vector<std::string> errors(n + 1);
    // A gap or a seek: the last frame's silhouettes say nothing about this one's.
    if (!last_frame || s.frame != *last_frame + 1)
      for (carving::Keyer& k : keyers) k.resetRegion();
    last_frame = s.frame;
    // One item per camera, dynamic scheduling, the largest first: the main camera (index n; 2x
    // a witness's pixels, soft alpha and despill), so that the witnesses fill in around it. No
    // exception leaves the region (STYLE.md rule 11).
#pragma omp parallel for schedule(dynamic) num_threads(threads())
    for (int item = 0; item <= n; ++item) {
      const int i = n - item;
      try {
        if (i < n) {
          if (!s.dropped[i].empty() || s.witness_plates[i].empty()) {
            if (s.dropped[i].empty()) s.dropped[i] = "no frame";
            keyers[i].resetRegion();
            continue;
          }
          keyers[i].key(witnessPlate(s, i), carve_names[i], witness_keys[i]);
          s.silhouettes[i] = witness_keys[i].silhouette;
        } else {
          keyers[n].key(s.main_plate, main_name, main_key);
          carving::despill(s.main_plate, main_key, keyers[n].screen(), keyers[n].options(), foreground);
          s.main_key = main_key;
          s.foreground = foreground;
        }
      } catch (const std::exception& e) {
        errors[i] = e.what();
      }
    }
    for (int i = 0; i < n; ++i)
      if (!errors[i].empty()) s.dropped[i] = "keying failed: " + errors[i];
    if (!errors[n].empty()) {
      ErrorContext c;
      c.camera = main_name;
      throw Error("keying the main plate failed: " + errors[n], c);
    }
  }

  // The plate keyed for carving camera i: the frame itself, or binned to the scaled camera. A
  // plate of another size than the rig's is an error (resizing would hide it).
  const cv::Mat& witnessPlate(const FrameState& s, int i) {
    const cv::Mat& plate = s.witness_plates[i];
    if (options.witness_bin == 1) return plate;
    if (plate.size() != plate_sizes[i])
      throw Error("plate is " + std::to_string(plate.cols) + "x" + std::to_string(plate.rows) + " but the camera is " +
                  std::to_string(plate_sizes[i].width) + "x" + std::to_string(plate_sizes[i].height));
    binLight(plate, options.witness_bin, binned_sizes[i], binned[i]);
    return binned[i];
  }

  void carve(FrameState& s) {
    // Fewer usable witnesses than the hull needs: the frame fails (an empty hull would put the
    // whole actor in front of the CG without a word).
    int usable = 0;
    std::string why;
    for (size_t i = 0; i < s.dropped.size(); ++i) {
      if (s.dropped[i].empty()) ++usable;
      else why += (why.empty() ? "" : "; ") + carve_names[i] + ": " + s.dropped[i];
    }
    if (usable < options.hull.min_views)
      throw Error("only " + std::to_string(usable) + " of " + std::to_string(s.dropped.size()) +
                  " witnesses usable, the hull needs " + std::to_string(options.hull.min_views) +
                  (why.empty() ? std::string() : " (" + why + ")"));
    carving::Silhouettes sil;
    sil.masks = s.silhouettes;
    sil.dropped = s.dropped;
    s.hull = carver->carve(sil);
  }

  void depth(FrameState& s) {
    carver->depth(s.hull, s.main, s.main_key.silhouette, main_depth);
    s.main_depth = main_depth;
  }

  void compose(FrameState& s) {
    compositor->setLens(s.main.camera);
    composite::CompositeInputs in;
    in.foreground = s.foreground;
    in.alpha = s.main_key.alpha;
    in.actor_depth = s.main_depth;
    in.cg_color = s.cg.color;
    in.cg_depth = s.cg.depth;
    compositor->composite(in, result, options.debug_layers, "frame " + std::to_string(s.frame));
    s.composite = result;
  }
};

FrameLoop::FrameLoop(const Rig& rig, const Camera& cg, const FrameLoopOptions& options)
    : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.options = options;
  m.options.validate();
  if (!options.main_camera.empty()) {
    rig.at(options.main_camera);
    m.main_name = options.main_camera;
  } else {
    for (const RigCamera& rc : rig.cameras)
      if (rc.role == kMainRole) m.main_name = rc.camera.name;
    if (m.main_name.empty()) throw Error("run: the rig has no camera with role 'main'", fieldContext("main_camera"));
  }
  std::vector<RigCamera> carve_cams;
  if (options.carve_cameras.empty()) {
    for (const RigCamera& rc : rig.cameras)
      if (rc.role == "witness" && rc.camera.name != m.main_name) m.carve_names.push_back(rc.camera.name);
  } else {
    m.carve_names = options.carve_cameras;
  }
  for (const std::string& name : m.carve_names) carve_cams.push_back(rig.at(name));
  if (carve_cams.size() < 2)
    throw Error("run: at least 2 carving cameras are needed (got " + std::to_string(carve_cams.size()) + ")",
                fieldContext("carve_cameras"));
  carving::KeyerOptions witness_key = options.keyer;
  witness_key.soft_alpha = false;  // carving needs the silhouette only
  witness_key.threads = 1;         // cameras are keyed in parallel
  witness_key.region_margin_px = (options.key_region_margin_px + options.witness_bin - 1) / options.witness_bin;
  if (const int bin = options.witness_bin; bin > 1) {
    const int area = bin * bin;
    witness_key.min_blob_px = std::max(1, witness_key.min_blob_px / area);
    witness_key.min_hole_px = std::max(1, witness_key.min_hole_px / area);
    for (RigCamera& rc : carve_cams) {
      m.plate_sizes.emplace_back(rc.camera.width, rc.camera.height);
      rc.camera = rc.camera.scaled(1.0 / bin, 1.0 / bin);
      m.binned_sizes.emplace_back(rc.camera.width, rc.camera.height);
    }
    m.binned.resize(carve_cams.size());
  }
  // Whole frames in turn: witness i's on frames i, i + every, ... (one witness a frame while
  // there are no more witnesses than 'every', 24 by default); the main camera's halfway between
  // the last witness's and the first's next.
  const int every = std::max(1, witness_key.region_full_every);
  const int n_carve = static_cast<int>(m.carve_names.size());
  for (int i = 0; i < n_carve; ++i) {
    witness_key.region_full_phase = (every - i % every) % every;
    m.keyers.emplace_back(witness_key);
  }
  m.witness_keys.resize(m.carve_names.size());
  carving::KeyerOptions main_key = options.keyer;
  main_key.soft_alpha = true;
  main_key.remember_garbage_zone = false;  // the main camera moves
  main_key.threads = 1;
  main_key.region_margin_px = options.key_main_region ? options.key_region_margin_px : 0;
  const int main_whole = n_carve < every ? (n_carve + every) / 2 : every / 2;
  main_key.region_full_phase = (every - main_whole % every) % every;
  m.keyers.emplace_back(main_key);
  carving::HullOptions hull = options.hull;
  hull.threads = options.threads;
  m.carver = std::make_unique<carving::Carver>(carve_cams, hull);
  composite::CompositeOptions co = options.composite;
  co.threads = options.threads;
  m.compositor = std::make_unique<composite::Compositor>(rig.at(m.main_name).camera, cg, co);
  m.stages = {{"key", [&m](FrameState& s) { m.key(s); }},
              {"carve", [&m](FrameState& s) { m.carve(s); }},
              {"depth", [&m](FrameState& s) { m.depth(s); }},
              {"composite", [&m](FrameState& s) { m.compose(s); }}};
}

FrameLoop::~FrameLoop() = default;

const std::vector<std::string>& FrameLoop::carveCameras() const { return impl_->carve_names; }
const std::string& FrameLoop::mainCamera() const { return impl_->main_name; }
const carving::Carver& FrameLoop::carver() const { return *impl_->carver; }
const composite::Compositor& FrameLoop::compositor() const { return *impl_->compositor; }

std::vector<std::string> FrameLoop::stages() const {
  std::vector<std::string> names;
  for (const auto& s : impl_->stages) names.push_back(s.first);
  return names;
}

void FrameLoop::insertStage(const std::string& after, const std::string& name, StageFn fn) {
  auto& st = impl_->stages;
  const auto it = std::find_if(st.begin(), st.end(), [&](const auto& s) { return s.first == after; });
  if (it == st.end()) throw Error("run: no stage '" + after + "' to insert '" + name + "' after", fieldContext("after"));
  st.insert(it + 1, {name, std::move(fn)});
}

namespace {
double processCpuMs() {
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return t.tv_sec * 1e3 + t.tv_nsec * 1e-6;
}
}  // namespace

std::vector<StageTime> FrameLoop::run(FrameState& state) {
  std::vector<StageTime> times;
  for (auto& [name, fn] : impl_->stages) {
    const Stopwatch start;
    const double cpu0 = processCpuMs();
    try {
      fn(state);
    } catch (const std::exception& e) {
      throw frameError(name, state.frame, e);
    }
    times.push_back({name, start.ms(),
                     processCpuMs() - cpu0});
  }
  return times;
}

void PropStageOptions::validate() const {
  tracker.validate();
  if (!(fps > 0) || !std::isfinite(fps)) throw Error("run: props fps must be > 0", fieldContext("fps"));
}

PropStage::PropStage(const FrameLoop& loop, const Rig& rig, tracking::PropSet props, const PropStageOptions& options)
    : options_(options) {
  options_.validate();
  std::vector<RigCamera> cams;
  for (const std::string& name : loop.carveCameras()) cams.push_back(rig.at(name));
  cams.push_back(rig.at(loop.mainCamera()));
  main_index_ = static_cast<int>(cams.size()) - 1;
  tracker_ = std::make_unique<tracking::PropTracker>(std::move(cams), std::move(props), options_.tracker);
}

PropStage::~PropStage() = default;

void PropStage::operator()(FrameState& s) {
  const double t = s.frame / options_.fps;
  if (any_ && (t <= last_time_s_ || t - last_time_s_ > options_.tracker.filter.max_gap_s)) tracker_->reset();
  any_ = true;
  last_time_s_ = t;
  tracker_->setCameraPose(main_index_, s.main.T_world_cam);
  std::vector<cv::Mat> images = s.witness_plates;
  images.push_back(s.main_plate);
  s.props = tracker_->track(s.frame, t, images);
}

void PropStage::addTo(FrameLoop& loop) {
  loop.insertStage("depth", "props", [this](FrameState& s) { (*this)(s); });
}

}  // namespace previz::live
