// Frame-sync check from the board's motion (algorithm in sync.h).
#include "multicam/sync.h"

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <optional>

#include "calib/intrinsics.h"
#include "core/error.h"
#include "core/stats.h"
#include "core/threads.h"

namespace previz::multicam {
namespace {

Eigen::Vector3d logRotation(const Eigen::Matrix3d& R) {
  const Eigen::AngleAxisd aa(R);
  return aa.angle() * aa.axis();
}

Eigen::Matrix3d expRotation(const Eigen::Vector3d& w) {
  const double angle = w.norm();
  if (angle < 1e-15) return Eigen::Matrix3d::Identity();
  return Eigen::AngleAxisd(angle, w / angle).toRotationMatrix();
}

struct Score {
  double spread = -1;    // m; -1 = too few shared frames
  double baseline = 0;   // m, |median translation| (distance between the cameras)
  int shared = 0;
};

// Spread of the relative poses T_a_b(t) (sync.h) and the baseline. Robust to a minority of bad
// PnP poses.
Score spreadOf(const std::vector<Pose>& rel) {
  std::vector<double> x, y, z;
  for (const Pose& T : rel) {
    x.push_back(T.translation().x());
    y.push_back(T.translation().y());
    z.push_back(T.translation().z());
  }
  const Eigen::Vector3d c_med(median(x), median(y), median(z));
  std::vector<double> dist;
  size_t closest = 0;
  for (size_t i = 0; i < rel.size(); ++i) {
    dist.push_back((rel[i].translation() - c_med).norm());
    if (dist[i] < dist[closest]) closest = i;
  }
  // Rotation: start at the sample with the most typical translation, step to the
  // component-wise median of the rotation vectors about it.
  const Eigen::Matrix3d R0 = rel[closest].linear();
  std::vector<double> wx, wy, wz;
  for (const Pose& T : rel) {
    const Eigen::Vector3d w = logRotation(R0.transpose() * T.linear());
    wx.push_back(w.x());
    wy.push_back(w.y());
    wz.push_back(w.z());
  }
  const Eigen::Matrix3d R_ref = R0 * expRotation(Eigen::Vector3d(median(wx), median(wy), median(wz)));
  std::vector<double> angles;
  for (const Pose& T : rel) angles.push_back(Eigen::AngleAxisd(R_ref.transpose() * T.linear()).angle());
  Score score;
  score.spread = median(dist) + c_med.norm() * median(angles);
  score.baseline = c_med.norm();
  score.shared = static_cast<int>(rel.size());
  return score;
}

// Most common value; ties go to the one nearest 0 (then the smaller).
int mode(const std::vector<int>& values) {
  std::map<int, int> counts;
  for (int v : values) ++counts[v];
  int best = 0, best_count = -1;
  for (const auto& [v, n] : counts) {
    if (n > best_count || (n == best_count && std::abs(v) < std::abs(best))) {
      best = v;
      best_count = n;
    }
  }
  return best;
}

struct Vote {
  int a, b, d;  // offset(b) - offset(a) = d
};

// Offsets of n cameras from pairwise votes (see step 4 of checkSync). Cameras without votes
// get 0. Deterministic: ties go to the first root in index order.
std::vector<int> combineVotes(int n, const std::vector<Vote>& votes) {
  std::vector<std::vector<std::pair<int, int>>> adjacent(n);  // (other camera, offset(other) - offset(this))
  for (const Vote& v : votes) {
    adjacent[v.a].push_back({v.b, v.d});
    adjacent[v.b].push_back({v.a, -v.d});
  }
  std::vector<int> offset(n, 0), component(n, -1);
  for (int seed = 0; seed < n; ++seed) {
    if (component[seed] >= 0 || adjacent[seed].empty()) continue;
    // The component's cameras.
    std::vector<int> members = {seed};
    component[seed] = seed;
    for (size_t i = 0; i < members.size(); ++i) {
      for (const auto& [other, d] : adjacent[members[i]]) {
        if (component[other] < 0) {
          component[other] = seed;
          members.push_back(other);
        }
      }
    }
    std::vector<int> best;
    int best_agree = -1;
    for (int root : members) {
      std::vector<int> o(n, 0);
      std::vector<bool> set(n, false);
      std::vector<int> queue = {root};
      set[root] = true;
      for (size_t i = 0; i < queue.size(); ++i) {
        for (const auto& [other, d] : adjacent[queue[i]]) {
          if (set[other]) continue;
          o[other] = o[queue[i]] + d;
          set[other] = true;
          queue.push_back(other);
        }
      }
      int agree = 0;
      for (const Vote& v : votes) agree += component[v.a] == seed && o[v.b] - o[v.a] == v.d;
      if (agree > best_agree) {
        best_agree = agree;
        best = o;
      }
    }
    std::vector<int> values;
    for (int m : members) values.push_back(best[m]);
    const int common = mode(values);
    for (int m : members) offset[m] = best[m] - common;
  }
  return offset;
}

}  // namespace

void SyncOptions::validate() const {
  auto bad = [](const std::string& field, const std::string& what) {
    ErrorContext context;
    context.field = field;
    throw Error("sync: " + field + " " + what, context);
  };
  if (max_offset < 0 || max_offset > 1000) bad("max_offset", "must be in [0, 1000] (got " + std::to_string(max_offset) + ")");
  if (min_shared_frames < 3) bad("min_shared_frames", "must be >= 3 (got " + std::to_string(min_shared_frames) + ")");
  if (min_points < 4) bad("min_points", "must be >= 4 (got " + std::to_string(min_points) + ")");
  if (!(decisive_ratio > 0 && decisive_ratio <= 1)) bad("decisive_ratio", "must be in (0, 1] (got " + std::to_string(decisive_ratio) + ")");
  if (!(max_relative_spread > 0)) bad("max_relative_spread", "must be > 0 (got " + std::to_string(max_relative_spread) + ")");
}

SyncReport checkSync(const RigObservations& obs, const Rig& intrinsics, const SyncOptions& options) {
  options.validate();
  SyncReport report;
  report.max_offset = options.max_offset;

  // Cameras checked: those of the rig that have detections.
  struct Track {
    std::string name;
    const Camera* camera = nullptr;
    const CameraDetections* detections = nullptr;
    std::map<int, Pose> T_cam_board;  // moving frames with a pose
  };
  std::vector<Track> tracks;
  for (const RigCamera& rc : intrinsics.cameras) {
    const CameraDetections* d = obs.find(rc.camera.name);
    if (d == nullptr) {
      report.unchecked.push_back(rc.camera.name);
      continue;
    }
    if (!d->image_size.empty() && (d->image_size.width != rc.camera.width || d->image_size.height != rc.camera.height)) {
      ErrorContext context;
      context.camera = rc.camera.name;
      throw Error("sync: the camera's images are " + std::to_string(d->image_size.width) + "x" +
                      std::to_string(d->image_size.height) + " but its intrinsics are for " +
                      std::to_string(rc.camera.width) + "x" + std::to_string(rc.camera.height),
                  context);
    }
    tracks.push_back({rc.camera.name, &rc.camera, d, {}});
  }

  // 1. Board poses by PnP, in parallel over (camera, frame); results merged in index order.
  struct Item {
    int track, frame;
  };
  std::vector<Item> items;
  for (int k = 0; k < static_cast<int>(tracks.size()); ++k) {
    for (const auto& [frame, points] : tracks[k].detections->frames) {
      if (!obs.isFloorFrame(frame) && static_cast<int>(points.size()) >= options.min_points) items.push_back({k, frame});
    }
  }
  std::vector<std::optional<Pose>> poses(items.size());
  const int threads = resolveThreads(options.threads);
#pragma omp parallel for schedule(dynamic, 8) num_threads(threads)
  for (int i = 0; i < static_cast<int>(items.size()); ++i) {
    const Track& t = tracks[items[i].track];
    calib::ViewObservations view;
    view.source = "frame " + std::to_string(items[i].frame);
    view.image_size = cv::Size(t.camera->width, t.camera->height);
    view.points = t.detections->frames.at(items[i].frame);
    try {
      poses[i] = calib::estimateBoardPose(*t.camera, view, obs.board, false);
    } catch (const std::exception&) {
      poses[i].reset();  // a view PnP cannot use is simply not a sample
    }
  }
  for (size_t i = 0; i < items.size(); ++i) {
    if (poses[i]) tracks[items[i].track].T_cam_board[items[i].frame] = *poses[i];
  }

  // 2. Scores of every pair at every offset, in parallel over pairs.
  const int n = static_cast<int>(tracks.size());
  const int span = 2 * options.max_offset + 1;
  std::vector<std::pair<int, int>> pair_index;
  for (int a = 0; a < n; ++a) {
    for (int b = a + 1; b < n; ++b) pair_index.push_back({a, b});
  }
  std::vector<std::vector<Score>> scores(pair_index.size(), std::vector<Score>(span));
#pragma omp parallel for schedule(dynamic, 1) num_threads(threads)
  for (int p = 0; p < static_cast<int>(pair_index.size()); ++p) {
    const Track& A = tracks[pair_index[p].first];
    const Track& B = tracks[pair_index[p].second];
    for (int k = 0; k < span; ++k) {
      const int d = k - options.max_offset;
      std::vector<Pose> rel;
      for (const auto& [t, T_a] : A.T_cam_board) {
        const auto it = B.T_cam_board.find(t + d);
        if (it == B.T_cam_board.end()) continue;
        rel.push_back(T_a * it->second.inverse());
      }
      Score& s = scores[p][k];
      s.shared = static_cast<int>(rel.size());
      if (s.shared >= options.min_shared_frames) s = spreadOf(rel);
    }
  }

  // 3. Best offset per pair; decisive pairs vote.
  std::vector<Vote> votes;
  std::vector<int> pairs_of(n, 0);
  for (size_t p = 0; p < pair_index.size(); ++p) {
    const auto [a, b] = pair_index[p];
    int best = -1;
    std::vector<double> valid;
    for (int k = 0; k < span; ++k) {
      if (scores[p][k].spread < 0) continue;
      valid.push_back(scores[p][k].spread);
      if (best < 0 || scores[p][k].spread < scores[p][best].spread) best = k;
    }
    if (best < 0) continue;
    PairSync ps;
    ps.a = tracks[a].name;
    ps.b = tracks[b].name;
    ps.best_offset = best - options.max_offset;
    ps.shared_frames = scores[p][best].shared;
    ps.spread_at_best = scores[p][best].spread;
    ps.spread_at_zero = scores[p][options.max_offset].spread;
    // With one offset only (max_offset 0) nothing can be told apart; and a best offset whose
    // relative pose still wanders by a good part of the distance between the cameras is no fit
    // (only a few, wrongly matched frames were shared).
    ps.decisive = valid.size() >= 2 && ps.spread_at_best < options.decisive_ratio * median(valid) &&
                  ps.spread_at_best < options.max_relative_spread * scores[p][best].baseline;
    if (ps.decisive) {
      votes.push_back({a, b, ps.best_offset});
      ++pairs_of[a];
      ++pairs_of[b];
    }
    report.pairs.push_back(ps);
  }

  // 4. Per-camera offsets from the votes (offset(b) - offset(a) = d), one connected component of
  // the vote graph at a time: spread offsets from every camera in turn along the votes (breadth
  // first), keep the assignment most votes agree with, then subtract the component's most common
  // offset (the majority is in sync).
  const std::vector<int> offset = combineVotes(n, votes);
  // 5. Per-camera report: spreads over the camera's pairs at the offsets found and at 0.
  auto scoreAt = [&](int p, int d) {
    const int k = d + options.max_offset;
    return (k < 0 || k >= span) ? -1.0 : scores[p][k].spread;
  };
  for (int c = 0; c < n; ++c) {
    CameraSync cs;
    cs.camera = tracks[c].name;
    cs.pairs = pairs_of[c];
    if (cs.pairs == 0) {
      cs.spread_at_offset = cs.spread_at_zero = -1;
      report.unchecked.push_back(cs.camera);
      report.cameras.push_back(cs);
      continue;
    }
    cs.offset_frames = offset[c];
    std::vector<double> at_offset, at_zero;
    for (size_t p = 0; p < pair_index.size(); ++p) {
      const auto [a, b] = pair_index[p];
      if (a != c && b != c) continue;
      const int partner = a == c ? b : a;
      const int sign = a == c ? -1 : 1;  // d = offset(b) - offset(a)
      const double s1 = scoreAt(static_cast<int>(p), sign * (offset[c] - offset[partner]));
      const double s0 = scoreAt(static_cast<int>(p), sign * (0 - offset[partner]));
      if (s1 >= 0) at_offset.push_back(s1);
      if (s0 >= 0) at_zero.push_back(s0);
    }
    cs.spread_at_offset = at_offset.empty() ? -1 : median(at_offset);
    cs.spread_at_zero = at_zero.empty() ? -1 : median(at_zero);
    cs.in_sync = cs.offset_frames == 0;
    report.ok = report.ok && cs.in_sync;
    report.cameras.push_back(cs);
  }
  // Rig cameras without detections were listed first; keep rig order in 'cameras' for them too.
  std::vector<CameraSync> ordered;
  for (const RigCamera& rc : intrinsics.cameras) {
    auto it = std::find_if(report.cameras.begin(), report.cameras.end(),
                           [&](const CameraSync& cs) { return cs.camera == rc.camera.name; });
    if (it != report.cameras.end()) {
      ordered.push_back(*it);
    } else {
      CameraSync cs;
      cs.camera = rc.camera.name;
      cs.spread_at_offset = cs.spread_at_zero = -1;
      ordered.push_back(cs);
    }
  }
  report.cameras = ordered;
  return report;
}

}  // namespace previz::multicam
