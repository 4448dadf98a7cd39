// The prop tracking loop (see tracker.h).
#include "tracking/tracker.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <optional>

#include <nlohmann/json.hpp>
#include <omp.h>

#include "core/error.h"
#include "core/stopwatch.h"
#include "core/threads.h"
#include "core/units.h"

namespace previz::tracking {

namespace {

}  // namespace

void TrackerOptions::validate() const {
  detector.validate();
  for (const auto& [name, d] : per_camera) {
    try {
      d.validate();
    } catch (const Error& e) {
      ErrorContext c = e.context();
      c.camera = name;
      throw Error(e.message(), c);
    }
  }
  solve.validate();
  filter.validate();
  auto bad = [](const std::string& f, const std::string& what) {
    ErrorContext c;
    c.field = f;
    throw Error("track: " + what, c);
  };
  if (full_frame_every < 0) bad("full_frame_every", "full_frame_every must be >= 0");
  if (!(roi_margin_px >= 0)) bad("roi_margin_px", "roi_margin_px must be >= 0");
  if (!(roi_margin_fraction >= 0)) bad("roi_margin_fraction", "roi_margin_fraction must be >= 0");
  if (!(max_sigma_position_m > 0)) bad("max_sigma_position_m", "max_sigma_position_m must be > 0");
  if (threads < 0) bad("threads", "threads must be >= 0");
}

namespace {
// A frame between begin() and finish(). At namespace scope, not nested in Impl: clang (the fuzz
// build) decides whether a nested class with member initializers is default-constructible
// before the enclosing class is complete, and then rejects std::optional's emplace().
struct PendingFrame {
  TrackFrame out;
  std::vector<std::vector<TagDetection>> found;
  const std::vector<cv::Mat>* images = nullptr;
  std::vector<double> search_ms;  // each camera's search, wall
  int frames_since_full = 0;      // the whole-frame schedule once this frame is finished
};
}  // namespace

struct PropTracker::Impl {
  std::vector<RigCamera> cameras;
  PropSet props;
  std::vector<int> tracked_props;  // indices into props.props (carried props)
  TrackerOptions options;
  std::vector<TagDetector> detectors;
  struct Track {
    PoseFilter filter;
    bool live = false;
    Pose last = Pose::Identity();
    double last_time_s = 0;
  };
  std::vector<Track> tracks;  // per tracked prop
  int frames_since_full = 0;
  bool any_frame = false;
  // The frame between begin() and finish(): its result so far, each camera's tags, its images.
  using Pending = PendingFrame;
  std::optional<Pending> pending;

  // Camera c's search of the regions planned in pending->out.search[c] (its whole frame, or
  // the predicted regions) into its found[c]: a failure is recorded, never thrown (it runs on
  // OpenMP threads, STYLE.md rule 11).
  void search(int c) {
    CameraSearch& s = pending->out.search[static_cast<size_t>(c)];
    std::vector<TagDetection>& found = pending->found[static_cast<size_t>(c)];
    found.clear();
    if (!s.failure.empty()) return;
    const Stopwatch t;
    try {
      TagDetector& d = detectors[static_cast<size_t>(c)];
      found = d.detect((*pending->images)[static_cast<size_t>(c)], s.rois);
      s.noise = d.lastNoise();
      s.blur = d.lastSigma();
      s.detections = static_cast<int>(found.size());
    } catch (const std::exception& e) {
      s.failure = e.what();
    }
    pending->search_ms[static_cast<size_t>(c)] = t.ms();
  }

  TrackFrame finish(double detect_ms);

  // Plans camera c's search: its whole frame or the predicted regions at time_s.
  void plan(int c, bool whole_frame, double time_s) {
    CameraSearch& s = pending->out.search[static_cast<size_t>(c)];
    s = CameraSearch{};
    s.camera = cameras[static_cast<size_t>(c)].camera.name;
    const cv::Mat& img = (*pending->images)[static_cast<size_t>(c)];
    const Camera& cam = cameras[static_cast<size_t>(c)].camera;
    if (img.empty()) {
      s.failure = "no image";
      return;
    }
    if (img.cols != cam.width || img.rows != cam.height) {
      s.failure = "image is " + std::to_string(img.cols) + "x" + std::to_string(img.rows) + ", camera is " +
                  std::to_string(cam.width) + "x" + std::to_string(cam.height);
      return;
    }
    s.full_frame = whole_frame;
    s.rois = whole_frame ? std::vector<cv::Rect>{cv::Rect(0, 0, img.cols, img.rows)} : predictedRois(c, time_s);
    for (const cv::Rect& r : s.rois) s.pixels += r.area();
  }

  // Regions of camera c where the tracked props should appear at time_s.
  std::vector<cv::Rect> predictedRois(int c, double time_s) const {
    const RigCamera& rc = cameras[static_cast<size_t>(c)];
    const Pose T_cam_world = rc.T_world_cam.inverse();
    std::vector<cv::Rect> rois;
    for (size_t k = 0; k < tracked_props.size(); ++k) {
      const Track& tr = tracks[k];
      const Pose T = tr.filter.initialised() ? tr.filter.predict(time_s) : tr.last;
      double u0 = 1e18, v0 = 1e18, u1 = -1e18, v1 = -1e18;
      int n = 0;
      for (const TagDef& tag : props.props[static_cast<size_t>(tracked_props[k])].tags)
        for (const Eigen::Vector3d& X : tag.cornersInProp()) {
          const auto px = rc.camera.project(T_cam_world * (T * X));
          if (!px) continue;
          u0 = std::min(u0, px->x());
          v0 = std::min(v0, px->y());
          u1 = std::max(u1, px->x());
          v1 = std::max(v1, px->y());
          ++n;
        }
      if (n == 0) continue;
      const double m = options.roi_margin_px + options.roi_margin_fraction * std::max(u1 - u0, v1 - v0);
      // The origin on a multiple of 4 px: libapriltag thresholds in 4 x 4 tiles counted from the
      // searched image's origin, so the ROI then sees the full frame's tiles (same tags found).
      // The far edges too where the image allows (a partial last tile is thresholded differently).
      const auto down4 = [](double x) { return static_cast<int>(std::floor(x / 4.0)) * 4; };
      const auto up4 = [](double x) { return static_cast<int>(std::ceil(x / 4.0)) * 4; };
      const cv::Rect r(cv::Point(down4(u0 - m), down4(v0 - m)), cv::Point(up4(u1 + m + 1), up4(v1 + m + 1)));
      const cv::Rect clipped = r & cv::Rect(0, 0, rc.camera.width, rc.camera.height);
      if (clipped.area() > 0) rois.push_back(clipped);
    }
    return rois;
  }
};

PropTracker::PropTracker(std::vector<RigCamera> cameras, PropSet props, const TrackerOptions& options)
    : impl_(std::make_unique<Impl>()) {
  options.validate();
  props.validate();
  if (cameras.empty()) throw Error("track: no cameras to track from");
  for (const auto& [name, d] : options.per_camera) {
    bool found = false;
    for (const RigCamera& rc : cameras) found = found || rc.camera.name == name;
    if (!found) {
      ErrorContext c;
      c.camera = name;
      throw Error("track: detector settings for a camera that is not tracked from", c);
    }
  }
  impl_->cameras = std::move(cameras);
  impl_->props = std::move(props);
  impl_->options = options;
  const std::vector<std::string> families = impl_->props.families();
  for (const RigCamera& rc : impl_->cameras) {
    DetectorOptions d = options.detector;
    const auto it = options.per_camera.find(rc.camera.name);
    if (it != options.per_camera.end()) d = it->second;
    d.families = families;
    impl_->detectors.emplace_back(d);
  }
  for (size_t p = 0; p < impl_->props.props.size(); ++p)
    if (!impl_->props.props[p].T_world_prop) {
      impl_->tracked_props.push_back(static_cast<int>(p));
      impl_->tracks.push_back({PoseFilter(options.filter)});
    }
}

PropTracker::~PropTracker() = default;

const std::vector<RigCamera>& PropTracker::cameras() const { return impl_->cameras; }
const PropSet& PropTracker::props() const { return impl_->props; }
const TrackerOptions& PropTracker::options() const { return impl_->options; }

void PropTracker::setCameraPose(int camera, const Pose& T_world_cam) {
  if (camera < 0 || camera >= static_cast<int>(impl_->cameras.size()))
    throw Error("track: camera index " + std::to_string(camera) + " out of range");
  impl_->cameras[static_cast<size_t>(camera)].T_world_cam = T_world_cam;
}

void PropTracker::reset() {
  for (auto& t : impl_->tracks) {
    t.filter.reset();
    t.live = false;
  }
  impl_->any_frame = false;
}

TrackFrame PropTracker::track(int frame, double time_s, const std::vector<cv::Mat>& images) {
  begin(frame, time_s, images);
  const int n_cams = static_cast<int>(impl_->cameras.size());
  const Stopwatch t_detect;
#pragma omp parallel for schedule(dynamic) num_threads(resolveThreads(impl_->options.threads))
  for (int c = 0; c < n_cams; ++c) impl_->search(c);
  return impl_->finish(t_detect.ms());
}

std::vector<long long> PropTracker::begin(int frame, double time_s, const std::vector<cv::Mat>& images) {
  Impl& m = *impl_;
  m.pending.reset();
  const int n_cams = static_cast<int>(m.cameras.size());
  if (static_cast<int>(images.size()) != n_cams)
    throw Error("track: " + std::to_string(images.size()) + " images for " + std::to_string(n_cams) +
                    " cameras",
                ErrorContext{"", "", frame, ""});
  m.pending.emplace();
  Impl::Pending& pending = *m.pending;
  pending.images = &images;
  pending.found.resize(static_cast<size_t>(n_cams));
  pending.search_ms.assign(static_cast<size_t>(n_cams), 0.0);
  TrackFrame& out = pending.out;
  out.frame = frame;
  out.time_s = time_s;
  out.search.resize(static_cast<size_t>(n_cams));

  bool all_live = !m.tracks.empty();
  for (const auto& t : m.tracks) all_live = all_live && t.live;
  // Every camera searches its whole frame without ROIs, on the first frame, and while a prop is
  // not tracked. Otherwise the periodic whole-frame search (a new prop, a tag the prediction
  // misses) is staggered over the cameras: camera c searches whole when (frames since the last
  // all-camera search + c N / n) is a multiple of N = full_frame_every, so each camera still
  // does so every N frames, but a frame holds ceil(n / N) such searches, not n (one whole
  // 1280x720 frame costs about as much as 10 ROI frames: bench_tracking).
  const bool full = !m.options.roi || !m.any_frame || !all_live;
  const int every = m.options.full_frame_every;
  // The schedule moves on when the frame is finished (a begin() without finish() changes nothing).
  pending.frames_since_full = full ? 0 : m.frames_since_full + 1;
  std::vector<char> whole(static_cast<size_t>(n_cams), full ? 1 : 0);
  if (!full && every > 0)
    for (int c = 0; c < n_cams; ++c)
      whole[static_cast<size_t>(c)] = (pending.frames_since_full + c * every / n_cams) % every == 0;
  out.full_frame = std::all_of(whole.begin(), whole.end(), [](char w) { return w != 0; });
  std::vector<long long> pixels(static_cast<size_t>(n_cams));
  for (int c = 0; c < n_cams; ++c) {
    m.plan(c, whole[static_cast<size_t>(c)] != 0, time_s);
    pixels[static_cast<size_t>(c)] = out.search[static_cast<size_t>(c)].pixels;
  }
  return pixels;
}

void PropTracker::search(int camera) {
  if (!impl_->pending) throw Error("track: search() without begin()");
  if (camera < 0 || camera >= static_cast<int>(impl_->cameras.size()))
    throw Error("track: camera index " + std::to_string(camera) + " out of range");
  impl_->search(camera);
}

TrackFrame PropTracker::finish() {
  if (!impl_->pending) throw Error("track: finish() without begin()");
  const std::vector<double>& ms = impl_->pending->search_ms;
  return impl_->finish(std::accumulate(ms.begin(), ms.end(), 0.0));
}

// The frame's searches took detect_ms (wall, or the cameras' times summed when the caller ran them).
TrackFrame PropTracker::Impl::finish(double detect_ms) {
  Impl& m = *this;
  Impl::Pending& pending = *m.pending;
  TrackFrame& out = pending.out;
  std::vector<std::vector<TagDetection>>& found = pending.found;
  const double time_s = out.time_s;
  const int n_cams = static_cast<int>(m.cameras.size());
  const int threads = resolveThreads(m.options.threads);
  out.detect_ms = detect_ms;
  m.frames_since_full = pending.frames_since_full;
  m.any_frame = true;

  // Tags -> props.
  const Stopwatch t_solve;
  std::vector<std::vector<TagObservation>> obs;
  const auto observe = [&] {
    obs.assign(m.props.props.size(), {});
    out.unknown_tags = 0;
    for (int c = 0; c < n_cams; ++c)
      for (const TagDetection& d : found[static_cast<size_t>(c)]) {
        const auto owner = m.props.findTag(d.family, d.id);
        if (!owner) {
          ++out.unknown_tags;
          continue;
        }
        obs[static_cast<size_t>(owner->first)].push_back(
            makeTagObservation(m.cameras[static_cast<size_t>(c)].camera, c, owner->second, d.corners_px));
      }
  };
  // The joint solve of tracked prop k, from the filter's prediction when 'prior' and it has one.
  const auto measure = [&](size_t k, bool prior) {
    const int p = m.tracked_props[k];
    const std::vector<TagObservation>& o = obs[static_cast<size_t>(p)];
    PoseEstimate e;
    if (o.empty()) {
      e.failure = "no tag of this prop seen";
      return e;
    }
    const Impl::Track& tr = m.tracks[k];
    Pose predicted;
    const bool has_prior = prior && tr.live && tr.filter.initialised();
    if (has_prior) predicted = tr.filter.predict(time_s);
    e = solvePropPose(m.cameras, m.props.props[static_cast<size_t>(p)], o, m.options.solve,
                      has_prior ? &predicted : nullptr);
    if (e.ok && e.sigma_position_m > m.options.max_sigma_position_m) {
      e.ok = false;
      e.failure = "pose too uncertain (sigma " + std::to_string(e.sigma_position_m) + " m)";
    }
    return e;
  };
  observe();
  std::vector<PoseEstimate> measured(m.tracked_props.size());
  for (size_t k = 0; k < m.tracked_props.size(); ++k) measured[k] = measure(k, true);

  // A prop tracked until now that its predicted regions do not give (it moved faster than the
  // filter predicts, or its tags came out from behind the actor elsewhere): the cameras that
  // searched regions search their whole frames again in this frame, and the prop is solved
  // afresh (no prior; its filter restarts). A missed prediction costs one frame's whole-frame
  // search instead of a lost frame.
  std::vector<char> again(m.tracked_props.size(), 0);
  for (size_t k = 0; k < m.tracked_props.size(); ++k) again[k] = m.tracks[k].live && !measured[k].ok;
  std::vector<int> rescan;
  if (std::find(again.begin(), again.end(), 1) != again.end())
    for (int c = 0; c < n_cams; ++c)
      if (!out.search[static_cast<size_t>(c)].full_frame && out.search[static_cast<size_t>(c)].failure.empty())
        rescan.push_back(c);
  double rescan_ms = 0;  // inside the solve's time span, counted as detection
  if (rescan.empty()) {
    std::fill(again.begin(), again.end(), 0);  // nothing new to solve from: those props are lost
  } else {
    const Stopwatch t_again;
    for (const int c : rescan) m.plan(c, true, time_s);
#pragma omp parallel for schedule(dynamic) num_threads(threads)
    for (int i = 0; i < static_cast<int>(rescan.size()); ++i) m.search(rescan[static_cast<size_t>(i)]);
    rescan_ms = t_again.ms();
    out.detect_ms += rescan_ms;
    out.rescanned_cameras = static_cast<int>(rescan.size());
    out.full_frame = std::all_of(out.search.begin(), out.search.end(),
                                 [](const CameraSearch& s) { return s.full_frame || !s.failure.empty(); });
    observe();
    for (size_t k = 0; k < m.tracked_props.size(); ++k)
      if (again[k]) measured[k] = measure(k, false);
  }

  for (size_t k = 0; k < m.tracked_props.size(); ++k) {
    const int p = m.tracked_props[k];
    const PropDef& def = m.props.props[static_cast<size_t>(p)];
    Impl::Track& tr = m.tracks[k];
    PropResult r;
    r.id = def.id;
    r.name = def.name;
    r.measured = std::move(measured[k]);
    if (r.measured.ok) {
      r.tracked = true;
      r.reacquired = !tr.live || again[k];
      if (r.reacquired) tr.filter.reset();
      r.T_world_prop = m.options.filter_enabled ? tr.filter.update(time_s, r.measured.T, r.measured.covariance)
                                                : r.measured.T;
      for (int c : r.measured.cameras) r.cameras.push_back(m.cameras[static_cast<size_t>(c)].camera.name);
      tr.live = true;
      tr.last = r.T_world_prop;
      tr.last_time_s = time_s;
    } else {
      tr.live = false;  // lost: no pose reported, the filter restarts on reacquisition
    }
    out.props.push_back(std::move(r));
  }
  out.solve_ms = t_solve.ms() - rescan_ms;
  out.total_ms = out.detect_ms + out.solve_ms;
  TrackFrame done = std::move(out);
  m.pending.reset();
  return done;
}

nlohmann::json trackFrameToJson(const TrackFrame& f) {
  nlohmann::json props = nlohmann::json::array();
  for (const PropResult& r : f.props) {
    nlohmann::json j = {{"id", r.id}, {"name", r.name}, {"state", r.tracked ? "tracked" : "lost"}};
    if (r.tracked) {
      j["T_world_prop"] = poseToJson(r.T_world_prop);
      j["T_world_prop_measured"] = poseToJson(r.measured.T);
      j["sigma_position_mm"] = 1e3 * r.measured.sigma_position_m;
      j["sigma_rotation_deg"] = degrees(r.measured.sigma_rotation_rad);
      j["rms_px"] = r.measured.rms_px;
      j["cameras"] = r.cameras;
      j["tags"] = r.measured.tags;
      j["corners"] = r.measured.inliers;
      j["outliers"] = r.measured.corners - r.measured.inliers;
      j["ambiguity_ratio"] = std::isfinite(r.measured.ambiguity_ratio) ? nlohmann::json(r.measured.ambiguity_ratio)
                                                                       : nlohmann::json(nullptr);
      j["reacquired"] = r.reacquired;
    } else {
      j["reason"] = r.measured.failure;
    }
    props.push_back(j);
  }
  nlohmann::json failures = nlohmann::json::array(), blur = nlohmann::json::object();
  int rois = 0, whole = 0;
  long long pixels = 0;
  for (const CameraSearch& s : f.search) {
    if (s.failure.empty()) {
      blur[s.camera] = {{"blur_px", s.blur}};
      if (s.noise >= 0) blur[s.camera]["noise"] = s.noise;
    }
    rois += static_cast<int>(s.rois.size());
    whole += s.full_frame ? 1 : 0;
    pixels += s.pixels;
    if (!s.failure.empty()) failures.push_back({{"camera", s.camera}, {"reason", s.failure}});
  }
  return {{"frame", f.frame},
          {"time_s", f.time_s},
          {"props", props},
          {"unknown_tags", f.unknown_tags},
          {"full_frame", f.full_frame},
          {"whole_frame_cameras", whole},
          {"rescanned_cameras", f.rescanned_cameras},
          {"rois", rois},
          {"searched_pixels", pixels},
          {"camera_failures", failures},
          {"detector", blur},
          {"ms", {{"detect", f.detect_ms}, {"solve", f.solve_ms}, {"total", f.total_ms}}}};
}

}  // namespace previz::tracking
