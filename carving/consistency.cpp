// Cameras judged against the hull of the others (see consistency.h).
#include "carving/consistency.h"

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <set>

#include <opencv2/imgproc.hpp>

#include "carving/hull.h"
#include "core/error.h"
#include "core/stats.h"
#include "core/threads.h"

namespace previz::carving {

namespace {

double iou(const cv::Mat& a, const cv::Mat& b) {
  cv::Mat both, any;
  cv::bitwise_and(a, b, both);
  cv::bitwise_or(a, b, any);
  const int u = cv::countNonZero(any);
  return u > 0 ? static_cast<double>(cv::countNonZero(both)) / u : 1.0;
}

std::string signedFrames(int d) { return (d > 0 ? "+" : "") + std::to_string(d); }

// Silhouettes and hulls of the take at the working scale.
class Judge {
 public:
  Judge(const Take& take, const ConsistencyOptions& o) : take_(take), o_(o) {
    o_.validate();
    if (o_.cameras.empty()) {
      for (const RigCamera& rc : take.rig().cameras) names_.push_back(rc.camera.name);
    } else {
      names_ = o_.cameras;
      for (const std::string& n : names_) take.rig().at(n);  // throws naming an unknown camera
    }
    if (names_.size() < 3)
      throw Error("judging a camera by the others needs at least 3 cameras (got " + std::to_string(names_.size()) +
                  ")",
                  fieldContext("cameras"));
    std::vector<RigCamera> cams;
    for (const std::string& n : names_) cams.push_back(take.rig().at(n));
    volume_automatic_ = o_.volume.isEmpty();
    volume_ = volume_automatic_ ? autoVolume(cams) : o_.volume;
    sil_.resize(names_.size());
    why_.resize(names_.size());
  }

  const std::vector<std::string>& names() const { return names_; }
  const Eigen::AlignedBox3d& volume() const { return volume_; }
  bool volumeAutomatic() const { return volume_automatic_; }

  // The take frames judged: evenly spread over the take, 'margin' frames away from its ends.
  std::vector<int> sampleFrames(int margin) const {
    const std::vector<int>& all = take_.frames();
    std::vector<int> inner;
    if (all.empty()) return inner;
    for (int f : all)
      if (f - all.front() >= margin && all.back() - f >= margin) inner.push_back(f);
    if (inner.empty()) inner = {all[all.size() / 2]};
    std::vector<int> picks;
    const int n = std::min<int>(o_.sample_frames, static_cast<int>(inner.size()));
    for (int i = 0; i < n; ++i)
      picks.push_back(inner[n == 1 ? inner.size() / 2 : static_cast<size_t>(i) * (inner.size() - 1) / (n - 1)]);
    picks.erase(std::unique(picks.begin(), picks.end()), picks.end());
    return picks;
  }

  // Keys (or reads the mattes of) every camera at every frame asked, each camera's frames in
  // take order with its own Keyer, cameras in parallel.
  void load(const std::set<int>& frames) {
    const int n = static_cast<int>(names_.size());
#pragma omp parallel for schedule(dynamic) num_threads(threads())
    for (int c = 0; c < n; ++c) {
      Keyer keyer(o_.keyer);
      // A clean plate the keyer cannot use leaves the camera out, as carve does.
      std::string unusable;
      if (!take_.hasMasks()) {
        try {
          const cv::Mat clean = take_.cleanPlate(names_[c]);
          if (!clean.empty()) keyer.setCleanPlate(clean, "clean plate of " + names_[c]);
        } catch (const std::exception& e) {
          unusable = std::string("clean plate unusable: ") + e.what();
        }
      }
      for (int f : frames) {
        if (sil_[c].count(f) || why_[c].count(f)) continue;
        if (!unusable.empty()) {
          why_[c][f] = unusable;
          continue;
        }
        try {
          const CameraFrame in = take_.read(names_[c], f);
          if (!in.ok()) {
            why_[c][f] = in.dropped;
            continue;
          }
          cv::Mat mask = in.mask;
          if (mask.empty()) mask = keyer.key(in.image, take_.source(names_[c], f)).silhouette;
          const RigCamera rc = scaled(take_.rig().at(names_[c]));
          cv::Mat small;
          cv::resize(mask, small, cv::Size(rc.camera.width, rc.camera.height), 0, 0, cv::INTER_AREA);
          sil_[c][f] = small > 127;
        } catch (const std::exception& e) {
          why_[c][f] = e.what();
        }
      }
    }
  }

  const cv::Mat* silhouette(int c, int frame) const {
    const auto it = sil_[c].find(frame);
    return it == sil_[c].end() ? nullptr : &it->second;
  }
  std::string whyNot(int c, int frame) const {
    const auto it = why_[c].find(frame);
    return it == why_[c].end() ? "frame " + std::to_string(frame) + " not in the take" : it->second;
  }

  // The hull of every judging camera but c at take frame t (camera o's silhouette from
  // t + corr[o]), projected into c at t: 255 where a ray of c meets it. Empty when fewer than two
  // others have a silhouette there.
  cv::Mat othersHull(int c, int t, const std::vector<int>& corr, const std::vector<bool>& judges, int k) const {
    std::vector<RigCamera> cams;
    Silhouettes sil;
    int usable = 0;
    for (size_t o = 0; o < names_.size(); ++o) {
      if (static_cast<int>(o) == c || !judges[o]) continue;
      cams.push_back(scaled(take_.cameraAt(names_[o], t)));
      const cv::Mat* s = silhouette(static_cast<int>(o), t + corr[o]);
      sil.masks.push_back(s ? *s : cv::Mat());
      usable += s ? 1 : 0;
    }
    if (usable < 2) return {};
    HullOptions h;
    h.volume = volume_;
    h.voxel_m = o_.voxel_m;
    h.k = std::min(k, std::max(0, usable - 2));
    h.min_views = 2;
    h.threads = 1;
    Carver carver(std::move(cams), h);
    const VisualHull hull = carver.carve(sil);
    const cv::Mat depth = carver.depth(hull, scaled(take_.cameraAt(names_[c], t)), cv::Mat());
    return depth < std::numeric_limits<float>::infinity();
  }

  int threads() const { return resolveThreads(o_.threads); }

 private:
  RigCamera scaled(RigCamera rc) const {
    rc.camera = rc.camera.scaled(o_.scale, o_.scale);
    return rc;
  }

  const Take& take_;
  ConsistencyOptions o_;
  std::vector<std::string> names_;
  Eigen::AlignedBox3d volume_;
  bool volume_automatic_ = false;
  std::vector<std::map<int, cv::Mat>> sil_;
  std::vector<std::map<int, std::string>> why_;
};

// Mean IoU of camera c's silhouette at t + d with each hull, for d = -N .. N.
std::vector<double> offsetScores(const Judge& judge, int c, const std::vector<int>& frames,
                                 const std::vector<cv::Mat>& hulls, int N) {
  std::vector<double> scores(2 * N + 1, 0.0);
  for (int d = -N; d <= N; ++d) {
    double sum = 0;
    int n = 0;
    for (size_t i = 0; i < frames.size(); ++i) {
      if (hulls[i].empty()) continue;
      const cv::Mat* s = judge.silhouette(c, frames[i] + d);
      if (!s) continue;
      sum += iou(hulls[i], *s);
      ++n;
    }
    scores[d + N] = n > 0 ? sum / n : 0.0;
  }
  return scores;
}

OffsetEstimate decide(const std::string& camera, const std::vector<double>& scores, int N,
                      const ConsistencyOptions& o) {
  OffsetEstimate e;
  e.camera = camera;
  e.scores = scores;
  const int best = static_cast<int>(std::max_element(scores.begin(), scores.end()) - scores.begin());
  int second = -1;
  for (int i = 0; i < static_cast<int>(scores.size()); ++i)
    if (i != best && (second < 0 || scores[i] > scores[second])) second = i;
  e.correction = best - N;
  e.score = scores[best];
  e.runner_up = second >= 0 ? scores[second] : 0.0;
  e.runner_up_correction = second - N;
  e.spread = scores[best] - *std::min_element(scores.begin(), scores.end());
  const double margin = e.score - e.runner_up;
  char text[256];
  if (e.score <= 0) {
    e.evidence = "cannot tell: no frame to judge";
  } else if (e.spread < o.min_spread) {
    std::snprintf(text, sizeof(text),
                  "cannot tell: every offset in %+d..%+d scores within %.4f (IoU %.4f): too little motion", -N, N,
                  e.spread, e.score);
    e.evidence = text;
  } else if (margin < o.min_margin) {
    std::snprintf(text, sizeof(text), "cannot tell: %s scores IoU %.4f, %s %.4f: margin %.4f < %.4f",
                  signedFrames(e.correction).c_str(), e.score, signedFrames(e.runner_up_correction).c_str(),
                  e.runner_up, margin, o.min_margin);
    e.evidence = text;
  } else if (best == 0 || best == static_cast<int>(scores.size()) - 1) {
    std::snprintf(text, sizeof(text), "cannot tell: the best offset %s is the edge of the search (+-%d): search wider",
                  signedFrames(e.correction).c_str(), N);
    e.evidence = text;
  } else {
    e.confident = true;
    std::snprintf(text, sizeof(text), "%s: IoU %.4f, runner-up %s %.4f (margin %.4f), spread %.4f",
                  e.correction == 0 ? "in sync" : ("offset " + signedFrames(e.correction)).c_str(), e.score,
                  signedFrames(e.runner_up_correction).c_str(), e.runner_up, margin, e.spread);
    e.evidence = text;
  }
  if (!e.confident) e.correction = 0;
  return e;
}

// Every camera's hulls over the frames, in parallel over (camera, frame).
std::vector<std::vector<cv::Mat>> allHulls(const Judge& judge, const std::vector<int>& frames,
                                           const std::vector<int>& corr, const std::vector<bool>& judges, int k) {
  const int nc = static_cast<int>(judge.names().size());
  const int nf = static_cast<int>(frames.size());
  std::vector<std::vector<cv::Mat>> hulls(nc, std::vector<cv::Mat>(nf));
  std::vector<std::string> errors(static_cast<size_t>(nc) * nf);
#pragma omp parallel for schedule(dynamic) num_threads(judge.threads())
  for (int i = 0; i < nc * nf; ++i) {
    try {
      hulls[i / nf][i % nf] = judge.othersHull(i / nf, frames[i % nf], corr, judges, k);
    } catch (const std::exception& e) {
      errors[i] = e.what();
    }
  }
  for (int i = 0; i < nc * nf; ++i)
    if (!errors[i].empty()) {
      ErrorContext c;
      c.camera = judge.names()[i / nf];
      c.frame = frames[i % nf];
      throw Error("the others' hull: " + errors[i], c);
    }
  return hulls;
}

std::set<int> framesAround(const std::vector<int>& frames, int N) {
  std::set<int> all;
  for (int f : frames)
    for (int d = -N; d <= N; ++d) all.insert(f + d);
  return all;
}

}  // namespace

void ConsistencyOptions::validate() const {
  const auto bad = [](const char* field, const std::string& what) {
    throw Error(std::string("consistency: ") + field + " " + what, fieldContext(field));
  };
  if (!(scale > 0 && scale <= 1)) bad("scale", "must be in (0, 1]");
  if (!(voxel_m > 0)) bad("voxel_m", "must be > 0");
  if (tolerance_k < 0) bad("tolerance_k", "must be >= 0");
  if (search_frames < 1 || search_frames > 240) bad("search_frames", "must be in [1, 240]");
  if (sample_frames < 1) bad("sample_frames", "must be >= 1");
  if (!(min_margin >= 0) || !(min_spread >= 0)) bad("min_margin", "and min_spread must be >= 0");
  if (threads < 0) bad("threads", "must be >= 0");
  keyer.validate();
}

Eigen::AlignedBox3d autoVolume(const std::vector<RigCamera>& cameras, double height_m) {
  // A 0.2 m lattice over 40 x 40 m of floor (every stage we know is smaller) up to height_m.
  const double step = 0.2, half = 20.0;
  const int n = static_cast<int>(2 * half / step) + 1;
  const int nz = std::max(1, static_cast<int>(height_m / step) + 1);
  const int cams = static_cast<int>(cameras.size());
  std::vector<Pose> T_cam_world;
  for (const RigCamera& rc : cameras) T_cam_world.push_back(rc.T_world_cam.inverse());
  // Per lattice point, how many cameras see it.
  std::vector<unsigned char> seen(static_cast<size_t>(n) * n * nz, 0);
#pragma omp parallel for schedule(static)
  for (int iy = 0; iy < n; ++iy)
    for (int ix = 0; ix < n; ++ix)
      for (int iz = 0; iz < nz; ++iz) {
        const Eigen::Vector3d p(-half + ix * step, -half + iy * step, iz * step);
        unsigned char k = 0;
        for (int c = 0; c < cams; ++c) {
          const Eigen::Vector3d pc = T_cam_world[c] * p;
          if (pc.z() <= 0.1) continue;
          const std::optional<Eigen::Vector2d> px = cameras[c].camera.project(pc);
          if (px && cameras[c].camera.inImage(*px)) ++k;
        }
        seen[(static_cast<size_t>(iy) * n + ix) * nz + iz] = k;
      }
  for (int need = cams; need >= std::max(2, cams - 1); --need) {
    Eigen::AlignedBox3d box;
    for (int iy = 0; iy < n; ++iy)
      for (int ix = 0; ix < n; ++ix)
        for (int iz = 0; iz < nz; ++iz)
          if (seen[(static_cast<size_t>(iy) * n + ix) * nz + iz] >= need)
            box.extend(Eigen::Vector3d(-half + ix * step, -half + iy * step, iz * step));
    if (!box.isEmpty()) {
      // Half a lattice step of margin round the points found, the floor kept at z = 0.
      box.min() -= Eigen::Vector3d(step, step, 0);
      box.max() += Eigen::Vector3d(step, step, step);
      box.min().z() = 0;
      return box;
    }
  }
  throw Error("no part of the stage (40 x 40 m, up to " + std::to_string(height_m) +
                  " m) is seen by two cameras: check the rig's poses",
              fieldContext("volume"));
}

nlohmann::json SyncEstimate::toJson() const {
  nlohmann::json cams = nlohmann::json::array();
  for (const OffsetEstimate& e : cameras)
    cams.push_back({{"camera", e.camera},
                    {"correction", e.correction},
                    {"offset", e.offset},
                    {"confident", e.confident},
                    {"score", e.score},
                    {"runner_up", e.runner_up},
                    {"runner_up_correction", e.runner_up_correction},
                    {"spread", e.spread},
                    {"evidence", e.evidence},
                    {"scores", e.scores}});
  return {{"frames", frames}, {"cameras", cams}};
}

SyncEstimate estimateOffsets(const Take& take, const ConsistencyOptions& options,
                             const std::function<void(const std::string&)>& progress) {
  Judge judge(take, options);
  const int N = options.search_frames;
  SyncEstimate out;
  out.frames = judge.sampleFrames(N);
  if (progress) progress("keying " + std::to_string(framesAround(out.frames, N).size()) + " frames of " +
                         std::to_string(judge.names().size()) + " cameras");
  judge.load(framesAround(out.frames, 2 * N));
  const int nc = static_cast<int>(judge.names().size());
  std::vector<int> corr(nc, 0);
  // Pass 1 judges every camera by uncorrected others; pass 2 by others corrected where pass 1
  // was sure.
  for (int pass = 0; pass < 2; ++pass) {
    if (progress) progress("pass " + std::to_string(pass + 1) + ": the others' hull of " + std::to_string(nc) +
                           " cameras x " + std::to_string(out.frames.size()) + " frames");
    const std::vector<std::vector<cv::Mat>> hulls = allHulls(judge, out.frames, corr, std::vector<bool>(nc, true), options.tolerance_k);
    out.cameras.clear();
    for (int c = 0; c < nc; ++c)
      out.cameras.push_back(decide(judge.names()[c], offsetScores(judge, c, out.frames, hulls[c], N), N, options));
    for (int c = 0; c < nc; ++c) corr[c] = out.cameras[c].correction;
  }
  for (OffsetEstimate& e : out.cameras) e.offset = take.streams().stream(e.camera).offset + e.correction;
  return out;
}

nlohmann::json TakeCheck::toJson() const {
  nlohmann::json cams = nlohmann::json::array();
  for (const CameraCheck& c : cameras) {
    nlohmann::json frames_j = nlohmann::json::array();
    for (const FrameCheck& f : c.frames) {
      nlohmann::json j = {{"frame", f.frame}, {"iou", f.iou}, {"covered", f.covered}, {"outside", f.outside}};
      if (!f.dropped.empty()) j["dropped"] = f.dropped;
      frames_j.push_back(j);
    }
    cams.push_back({{"camera", c.camera},
                    {"iou", c.iou},
                    {"covered", c.covered},
                    {"outside", c.outside},
                    {"flagged", c.flagged},
                    {"cause", c.cause},
                    {"explanation", c.explanation},
                    {"sync_correction", c.sync_correction},
                    {"shift_px", {c.shift_px.x(), c.shift_px.y()}},
                    {"hole_fraction", c.hole_fraction},
                    {"frames", frames_j}});
  }
  return {{"frames", frames},
          {"volume", {{"min", {volume.min().x(), volume.min().y(), volume.min().z()}},
                      {"max", {volume.max().x(), volume.max().y(), volume.max().z()}},
                      {"automatic", volume_automatic}}},
          {"cameras", cams}};
}

TakeCheck checkTake(const Take& take, const ConsistencyOptions& options,
                    const std::function<void(const std::string&)>& progress) {
  Judge judge(take, options);
  const int N = options.search_frames;
  TakeCheck out;
  out.volume = judge.volume();
  out.volume_automatic = judge.volumeAutomatic();
  out.frames = judge.sampleFrames(N);
  if (progress) progress("keying the cameras");
  judge.load(framesAround(out.frames, N));
  const int nc = static_cast<int>(judge.names().size());
  const int nf = static_cast<int>(out.frames.size());
  // Every camera judged by the hull of the judging others (k of them forgiven): per frame and
  // as medians.
  const auto judgeAll = [&](const std::vector<bool>& judges, int k, std::vector<std::vector<cv::Mat>>& hulls) {
    hulls = allHulls(judge, out.frames, std::vector<int>(nc, 0), judges, k);
    std::vector<CameraCheck> cams;
    for (int c = 0; c < nc; ++c) {
      CameraCheck cc;
      cc.camera = judge.names()[c];
      std::vector<double> ious, covered, outside;
      for (int i = 0; i < nf; ++i) {
        FrameCheck f;
        f.frame = out.frames[i];
        const cv::Mat* s = judge.silhouette(c, f.frame);
        const cv::Mat& h = hulls[c][i];
        if (!s) f.dropped = judge.whyNot(c, f.frame);
        else if (h.empty()) f.dropped = "fewer than two other cameras have a silhouette";
        if (f.dropped.empty()) {
          const double ns = cv::countNonZero(*s), nh = cv::countNonZero(h);
          cv::Mat both;
          cv::bitwise_and(*s, h, both);
          const double nb = cv::countNonZero(both);
          f.iou = iou(*s, h);
          f.covered = ns > 0 ? nb / ns : 1.0;
          f.outside = nh > 0 ? (nh - nb) / nh : 0.0;
          ious.push_back(f.iou);
          covered.push_back(f.covered);
          outside.push_back(f.outside);
        }
        cc.frames.push_back(f);
      }
      cc.iou = median(ious);
      cc.covered = median(covered);
      cc.outside = median(outside);
      cams.push_back(cc);
    }
    return cams;
  };
  const auto coveredMedian = [](const std::vector<CameraCheck>& cams) {
    std::vector<double> v;
    for (const CameraCheck& c : cams)
      if (std::any_of(c.frames.begin(), c.frames.end(), [](const FrameCheck& f) { return f.dropped.empty(); }))
        v.push_back(c.covered);
    return median(v);
  };
  // Round 1 judges every camera by all the others, forgiving tolerance_k of them. Cameras that
  // stand out (covered well below the cameras' median) stop judging in round 2, whose hull
  // forgives that many fewer: several bad cameras must not erode the hull the good ones are
  // judged by (3 unsynchronised witnesses and a rotated one: good cameras covered 0.92-0.94 in
  // round 1, 0.987-0.998 in round 2; tests/take/take_sync_test.sh).
  if (progress) progress("round 1: the others' hull of " + std::to_string(nc) + " cameras x " + std::to_string(nf) + " frames");
  std::vector<std::vector<cv::Mat>> hulls;
  std::vector<bool> judges(nc, true);
  out.cameras = judgeAll(judges, options.tolerance_k, hulls);
  const double first = coveredMedian(out.cameras);
  int excluded = 0;
  for (int c = 0; c < nc; ++c)
    if (out.cameras[c].covered < first - options.max_covered_drop) {
      judges[c] = false;
      ++excluded;
    }
  if (excluded > 0 && nc - excluded >= 3) {
    if (progress) progress("round 2: without " + std::to_string(excluded) + " camera(s) that stand out");
    out.cameras = judgeAll(judges, std::max(0, options.tolerance_k - excluded), hulls);
  }
  const double typical = coveredMedian(out.cameras);

  for (int c = 0; c < nc; ++c) {
    CameraCheck& cc = out.cameras[c];
    if (std::all_of(cc.frames.begin(), cc.frames.end(), [](const FrameCheck& f) { return !f.dropped.empty(); })) {
      cc.flagged = true;
      cc.cause = "unknown";
      cc.explanation = "no frame to judge: " + (cc.frames.empty() ? std::string("none sampled") : cc.frames.front().dropped);
      continue;
    }
    if (cc.covered >= options.min_covered && cc.covered >= typical - options.max_covered_drop) continue;
    cc.flagged = true;
    char text[320];
    // 1. Time: does another frame of its own fit the others' hull much better?
    const OffsetEstimate e = decide(cc.camera, offsetScores(judge, c, out.frames, hulls[c], N), N, options);
    if (e.confident && e.correction != 0 && e.score - e.scores[N] > 0.02) {
      cc.cause = "out of sync";
      cc.sync_correction = e.correction;
      std::snprintf(text, sizeof(text),
                    "out of sync: its frame t %s matches the others at t (IoU %.3f against %.3f in step); "
                    "offset correction %s (`previz take sync`)",
                    signedFrames(e.correction).c_str(), e.score, e.scores[N], signedFrames(e.correction).c_str());
      cc.explanation = text;
      continue;
    }
    // 2. Space: one image shift, frame after frame (a bumped camera or a wrong calibration).
    std::vector<double> dx, dy;
    std::vector<cv::Mat> own, judge_h;
    for (int i = 0; i < nf; ++i) {
      const cv::Mat* s = judge.silhouette(c, out.frames[i]);
      if (!s || hulls[c][i].empty()) continue;
      cv::Mat a, b;
      s->convertTo(a, CV_32F, 1.0 / 255);
      hulls[c][i].convertTo(b, CV_32F, 1.0 / 255);
      cv::GaussianBlur(a, a, cv::Size(0, 0), 2.0);
      cv::GaussianBlur(b, b, cv::Size(0, 0), 2.0);
      const cv::Point2d d = cv::phaseCorrelate(a, b);  // b is a shifted by d
      dx.push_back(d.x);
      dy.push_back(d.y);
      own.push_back(*s);
      judge_h.push_back(hulls[c][i]);
    }
    if (!dx.empty()) {
      const cv::Point2d d(median(dx), median(dy));
      const auto coveredShare = [](const cv::Mat& s, const cv::Mat& h) {
        const int n = cv::countNonZero(s);
        cv::Mat both;
        cv::bitwise_and(s, h, both);
        return n > 0 ? static_cast<double>(cv::countNonZero(both)) / n : 1.0;
      };
      std::vector<double> after, before;
      for (size_t i = 0; i < own.size(); ++i) {
        cv::Mat moved;
        const cv::Mat M = (cv::Mat_<double>(2, 3) << 1, 0, d.x, 0, 1, d.y);
        cv::warpAffine(own[i], moved, M, own[i].size(), cv::INTER_NEAREST);
        after.push_back(coveredShare(moved, judge_h[i]));
        before.push_back(coveredShare(own[i], judge_h[i]));
      }
      cc.shift_px = Eigen::Vector2d(d.x, d.y) / options.scale;
      if (std::hypot(d.x, d.y) > 0.5 && median(after) - median(before) > 0.02) {
        cc.cause = "image shift";
        std::snprintf(text, sizeof(text),
                      "its silhouette sits (%.1f, %.1f) px from where the others put the actor, every frame (covered "
                      "%.3f -> %.3f once shifted): the camera moved or its calibration is off (`previz rig "
                      "resurvey`)",
                      cc.shift_px.x(), cc.shift_px.y(), median(before), median(after));
        cc.explanation = text;
        continue;
      }
    }
    // 3. The keyer: holes inside its own outline that the others' hull fills.
    double holes = 0, filled = 0;
    for (size_t i = 0; i < own.size(); ++i) {
      std::vector<std::vector<cv::Point>> contours;
      cv::findContours(own[i].clone(), contours, cv::RETR_EXTERNAL, cv::CHAIN_APPROX_SIMPLE);
      cv::Mat fill(own[i].size(), CV_8UC1, cv::Scalar(0));
      cv::drawContours(fill, contours, -1, 255, cv::FILLED);
      cv::Mat hole = fill & ~own[i] & judge_h[i];
      holes += cv::countNonZero(hole);
      filled += cv::countNonZero(fill);
    }
    cc.hole_fraction = filled > 0 ? holes / filled : 0;
    if (cc.hole_fraction > 0.03) {
      cc.cause = "keyer";
      std::snprintf(text, sizeof(text),
                    "its mask has holes the others fill (%.1f %% of its outline's area): a keyer problem (screen "
                    "colour, spill, a costume near the screen's colour)",
                    100 * cc.hole_fraction);
      cc.explanation = text;
      continue;
    }
    cc.cause = "unknown";
    std::snprintf(text, sizeof(text),
                  "disagrees with the others (the others' hull covers %.3f of its silhouette, the cameras' median "
                  "%.3f; IoU %.3f) with no single time offset, image shift or keyer holes to blame",
                  cc.covered, typical, cc.iou);
    cc.explanation = text;
  }
  return out;
}

}  // namespace previz::carving
