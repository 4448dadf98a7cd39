#include "calib/selection.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <unordered_map>

#include <Eigen/Cholesky>
#include <Eigen/LU>

#include "calib/detail/projection.h"
#include "core/error.h"

namespace previz::calib {

namespace {

[[noreturn]] void failField(const std::string& field, const std::string& what) {
  ErrorContext context;
  context.field = field;
  throw Error("select: " + field + " " + what, context);
}

// SplitMix64 (Steele et al. 2014): calib does not depend on datasets' generators.
std::uint64_t splitMix(std::uint64_t& state) {
  std::uint64_t z = (state += 0x9E3779B97F4A7C15ull);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

int usablePoints(const ViewObservations& view) {
  return view.found() && !view.rejected ? static_cast<int>(view.points.size()) : 0;
}

}  // namespace

const char* toString(SelectionMethod method) {
  switch (method) {
    case SelectionMethod::kInformation: return "information";
    case SelectionMethod::kUncertainty: return "uncertainty";
    case SelectionMethod::kPlaneAngles: return "plane-angles";
    case SelectionMethod::kRandom: return "random";
    case SelectionMethod::kSequential: return "sequential";
  }
  return "?";
}

SelectionMethod selectionMethodFromString(const std::string& name) {
  for (auto m : {SelectionMethod::kInformation, SelectionMethod::kUncertainty,
                 SelectionMethod::kPlaneAngles, SelectionMethod::kRandom,
                 SelectionMethod::kSequential}) {
    if (name == toString(m)) return m;
  }
  ErrorContext context;
  context.field = "method";
  throw Error("select: unknown method '" + name +
                  "' (information, uncertainty, plane-angles, random, sequential)",
              context);
}

void SelectionOptions::validate() const {
  if (views < 1) failField("views", "must be >= 1 (got " + std::to_string(views) + ")");
  if (buffer_size < 0) failField("buffer_size", "must be >= 0 (got " + std::to_string(buffer_size) + ")");
  if (!(noise_px > 0) || !std::isfinite(noise_px))
    failField("noise_px", "must be > 0 (got " + std::to_string(noise_px) + ")");
  if (!(min_improvement >= 0)) failField("min_improvement", "must be >= 0");
  if (min_points < 4) failField("min_points", "must be >= 4 (got " + std::to_string(min_points) + ")");
  if (relinearise_every < 0)
    failField("relinearise_every", "must be >= 0 (got " + std::to_string(relinearise_every) + ")");
  if (guess) guess->validate();
}

Eigen::MatrixXd marginalViewInformation(const Camera& camera, const Pose& T_cam_board,
                                        const ViewObservations& view, const BoardSpec& board,
                                        const std::vector<int>& free, double aspect_tie) {
  std::unordered_map<int, Eigen::Vector3d> points;
  for (const BoardPoint& p : boardPoints(board)) points[p.id] = p.p_board;
  double intr[kIntrinsicCount];
  detail::cameraToVector(camera, intr);
  Eigen::Vector3d r, t;
  poseToRvecTvec(T_cam_board, r, t);
  const double pose[6] = {r.x(), r.y(), r.z(), t.x(), t.y(), t.z()};
  constexpr int kN = kIntrinsicCount + 6;
  Eigen::Matrix<double, kN, kN> JtJ = Eigen::Matrix<double, kN, kN>::Zero();
  Eigen::Matrix<double, 2, kN> J;
  for (const Observation& o : view.points) {
    auto it = points.find(o.id);
    if (it == points.end()) continue;
    detail::projectBoardPointJacobian(intr, pose, it->second, aspect_tie, camera.dist.model, J);
    JtJ.noalias() += J.transpose() * J;
  }
  const int n = static_cast<int>(free.size());
  Eigen::MatrixXd A(n, n), B(n, 6);
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) A(i, j) = JtJ(free[i], free[j]);
    for (int j = 0; j < 6; ++j) B(i, j) = JtJ(free[i], kIntrinsicCount + j);
  }
  const Eigen::Matrix<double, 6, 6> D = JtJ.bottomRightCorner<6, 6>();
  const Eigen::FullPivLU<Eigen::Matrix<double, 6, 6>> lu(D);
  if (!lu.isInvertible()) return Eigen::MatrixXd::Zero(n, n);
  Eigen::MatrixXd M = A - B * lu.solve(B.transpose());
  return 0.5 * (M + M.transpose());
}

ViewSelector::ViewSelector(const BoardSpec& board, cv::Size image_size,
                           const SelectionOptions& options)
    : board_(board), image_size_(image_size), options_(options) {
  options_.validate();
  board_.validate();
  if (image_size.width <= 0 || image_size.height <= 0) failField("image_size", "must be positive");
  if (options_.guess) {
    guess_ = *options_.guess;
    if (guess_.width != image_size.width || guess_.height != image_size.height)
      failField("guess", "size differs from the image size");
  } else {
    guess_.name = "guess";
    guess_.dist.model = options_.model;
    guess_.width = image_size.width;
    guess_.height = image_size.height;
    guess_.fx = guess_.fy = 0.8 * std::max(image_size.width, image_size.height);
    guess_.cx = 0.5 * (image_size.width - 1);
    guess_.cy = 0.5 * (image_size.height - 1);
  }
  const auto held = options_.locks.heldMask(guess_.dist.model);
  for (int i = 0; i < kIntrinsicCount; ++i)
    if (!held[i]) free_.push_back(i);
  updateLinearisation();
  rng_state_ = options_.seed * 0x2545F4914F6CDD1Dull + 1;
}

void ViewSelector::updateLinearisation() {
  const cv::Size image_size = image_size_;
  // Weak prior (1-sigma ranges a person would not dispute) so that a set that leaves some
  // parameter unobservable still scores finitely and the first swaps have a gradient.
  const int n = static_cast<int>(free_.size());
  prior_ = Eigen::MatrixXd::Zero(n, n);
  const double extent = std::max(image_size.width, image_size.height);
  for (int k = 0; k < n; ++k) {
    double s = 1.0;
    switch (free_[k]) {
      case detail::kFx:
      case detail::kFy: s = 0.5 * guess_.fx; break;
      case detail::kCx:
      case detail::kCy: s = 0.25 * extent; break;
      case detail::kSkew: s = 0.1 * guess_.fx; break;
      case detail::kP1:
      case detail::kP2: s = 0.05; break;
      default: s = 1.0; break;
    }
    prior_(k, k) = 1.0 / (s * s);
  }
  if (options_.method == SelectionMethod::kUncertainty) {
    double intr[kIntrinsicCount];
    detail::cameraToVector(guess_, intr);
    const double aspect = options_.locks.fix_aspect ? guess_.fy / guess_.fx : 0.0;
    grid_ = Eigen::MatrixXd::Zero(n, n);
    int count = 0;
    Eigen::Matrix<double, 2, kIntrinsicCount> J;
    for (int gy = 0; gy < 12; ++gy) {
      for (int gx = 0; gx < 16; ++gx) {
        const Eigen::Vector2d q((gx + 0.5) / 16.0 * (image_size.width - 1),
                                (gy + 0.5) / 12.0 * (image_size.height - 1));
        const auto ray = guess_.unproject(q);
        if (!ray) continue;
        detail::projectCameraPointJacobian(intr, *ray, aspect, guess_.dist.model, J);
        Eigen::MatrixXd Jf(2, n);
        for (int k = 0; k < n; ++k) Jf.col(k) = J.col(free_[k]);
        grid_ += Jf.transpose() * Jf;
        ++count;
      }
    }
    if (count > 0) grid_ /= count;
  }
}

void ViewSelector::relinearise() {
  std::vector<ViewObservations> held_views;
  for (const Candidate& c : chosen_) held_views.push_back(c.view);
  for (const Candidate& c : buffer_) held_views.push_back(c.view);
  IntrinsicsOptions io;
  io.locks = options_.locks;
  io.initial_camera = guess_;
  io.compute_covariance = false;
  io.reject_outliers = false;
  io.camera_name = guess_.name;
  try {
    const IntrinsicsResult r = calibrateIntrinsics(held_views, board_, io);
    // A handful of views can fit a wild lens; only take an estimate that is itself invertible
    // over the image.
    if (!(r.rms_px < 5.0) || !(r.camera.fx > 0) || !(r.camera.fy > 0)) return;
    const double corner = std::hypot(0.5 * image_size_.width / r.camera.fx,
                                      0.5 * image_size_.height / r.camera.fy);
    if (!(r.camera.maxInvertibleRadius() > 1.2 * corner)) return;
    guess_ = r.camera;
  } catch (const Error&) {
    return;
  }
  ++relinearisations_;
  updateLinearisation();
  auto refresh = [&](std::vector<Candidate>& list) {
    for (auto it = list.begin(); it != list.end();) {
      Candidate fresh;
      fresh.index = it->index;
      if (prepare(it->view, fresh)) {
        *it = std::move(fresh);
        ++it;
      } else {
        it = list.erase(it);
      }
    }
  };
  refresh(chosen_);
  refresh(buffer_);
}

bool ViewSelector::prepare(const ViewObservations& view, Candidate& c) const {
  if (usablePoints(view) < options_.min_points) return false;
  const auto pose = estimateBoardPose(guess_, view, board_, false);
  if (!pose) return false;
  c.view = view;
  c.normal = pose->linear().col(2);
  const double aspect = options_.locks.fix_aspect ? guess_.fy / guess_.fx : 0.0;
  c.information = marginalViewInformation(guess_, *pose, view, board_, free_, aspect);
  return true;
}

Eigen::MatrixXd ViewSelector::sumInformation(const std::vector<const Candidate*>& set) const {
  Eigen::MatrixXd info = prior_;
  const double w = 1.0 / (options_.noise_px * options_.noise_px);
  for (const Candidate* c : set) info += w * c->information;
  return info;
}

double ViewSelector::score(const std::vector<const Candidate*>& set) const {
  switch (options_.method) {
    case SelectionMethod::kInformation: {
      const Eigen::LLT<Eigen::MatrixXd> llt(sumInformation(set));
      if (llt.info() != Eigen::Success) return -1e300;
      return 2.0 * llt.matrixL().toDenseMatrix().diagonal().array().log().sum();
    }
    case SelectionMethod::kUncertainty: {
      const Eigen::LLT<Eigen::MatrixXd> llt(sumInformation(set));
      if (llt.info() != Eigen::Success) return -1e300;
      return -(llt.solve(grid_)).trace();
    }
    case SelectionMethod::kPlaneAngles: {
      double sum = 0;
      for (size_t i = 0; i < set.size(); ++i)
        for (size_t j = i + 1; j < set.size(); ++j)
          sum += std::acos(std::clamp(set[i]->normal.dot(set[j]->normal), -1.0, 1.0));
      return sum;
    }
    default:
      return 0.0;
  }
}

double ViewSelector::scoreWith(int skip, const Candidate* extra) const {
  std::vector<const Candidate*> set;
  for (size_t i = 0; i < chosen_.size(); ++i)
    if (static_cast<int>(i) != skip) set.push_back(&chosen_[i]);
  if (extra) set.push_back(extra);
  return score(set);
}

bool ViewSelector::trySwap(Candidate& incoming) {
  const double current = scoreWith(-1, nullptr);
  double best = current + options_.min_improvement;
  int best_i = -1;
  for (size_t i = 0; i < chosen_.size(); ++i) {
    const double s = scoreWith(static_cast<int>(i), &incoming);
    if (s > best) {
      best = s;
      best_i = static_cast<int>(i);
    }
  }
  if (best_i < 0) return false;
  std::swap(chosen_[best_i], incoming);
  ++swaps_;
  return true;
}

void ViewSelector::trimBuffer() {
  while (static_cast<int>(buffer_.size()) > options_.buffer_size) {
    // Drop the runner-up that would add least to the chosen set.
    size_t worst = 0;
    double worst_gain = 0;
    for (size_t b = 0; b < buffer_.size(); ++b) {
      const double gain = scoreWith(-1, &buffer_[b]);
      if (b == 0 || gain < worst_gain) {
        worst_gain = gain;
        worst = b;
      }
    }
    buffer_.erase(buffer_.begin() + static_cast<long>(worst));
  }
}

bool ViewSelector::add(const ViewObservations& view) {
  const int index = seen_++;
  const int n = options_.views;
  bool taken = false;
  if (options_.method == SelectionMethod::kSequential ||
      options_.method == SelectionMethod::kRandom) {
    if (usablePoints(view) >= options_.min_points) {
      const int k = considered_++;
      Candidate c;
      c.index = index;
      if (static_cast<int>(chosen_.size()) < n) {
        c.view = view;
        chosen_.push_back(std::move(c));
        taken = true;
      } else if (options_.method == SelectionMethod::kRandom) {
        // Algorithm R (Vitter 1985): the k-th usable view replaces a member with probability n/(k+1).
        const std::uint64_t j = splitMix(rng_state_) % static_cast<std::uint64_t>(k + 1);
        if (j < static_cast<std::uint64_t>(n)) {
          c.view = view;
          chosen_[j] = std::move(c);
          taken = true;
        }
      }
    }
  } else {
    Candidate c;
    c.index = index;
    if (prepare(view, c)) {
      ++considered_;
      if (static_cast<int>(chosen_.size()) < n) {
        chosen_.push_back(std::move(c));
      } else {
        const bool swapped = trySwap(c);  // c now holds the evicted view (or itself)
        buffer_.push_back(std::move(c));
        // A change of the chosen set can make an earlier runner-up worth taking.
        for (int pass = 0; swapped && pass < 2 * options_.buffer_size + 2; ++pass) {
          bool any = false;
          for (Candidate& b : buffer_) any = trySwap(b) || any;
          if (!any) break;
        }
        trimBuffer();
      }
      // Geometric schedule (every, 2 every, 4 every, ... views past the first N): the first
      // re-calibrations move the linearisation most, and the cost stays logarithmic in the stream.
      const int past = considered_ - n;
      if (options_.relinearise_every > 0 && static_cast<int>(chosen_.size()) == n && past > 0 &&
          past % options_.relinearise_every == 0) {
        const int q = past / options_.relinearise_every;
        if ((q & (q - 1)) == 0) relinearise();
      }
      for (const Candidate& m : chosen_) taken = taken || m.index == index;
    }
  }
  max_held_ = std::max(max_held_, held());
  return taken;
}

int ViewSelector::held() const { return static_cast<int>(chosen_.size() + buffer_.size()); }

std::vector<int> ViewSelector::selectedIndices() const {
  std::vector<int> out;
  for (const Candidate& c : chosen_) out.push_back(c.index);
  std::sort(out.begin(), out.end());
  return out;
}

std::vector<ViewObservations> ViewSelector::selected() const {
  std::vector<const Candidate*> order;
  for (const Candidate& c : chosen_) order.push_back(&c);
  std::sort(order.begin(), order.end(),
            [](const Candidate* a, const Candidate* b) { return a->index < b->index; });
  std::vector<ViewObservations> out;
  for (const Candidate* c : order) out.push_back(c->view);
  return out;
}

double ViewSelector::objective() const { return scoreWith(-1, nullptr); }

std::array<double, kIntrinsicCount> ViewSelector::predictedSigma() const {
  std::array<double, kIntrinsicCount> sigma{};
  // Random and sequential members were never linearised: do it now (only for this report).
  std::vector<Candidate> prepared;
  std::vector<const Candidate*> set;
  for (const Candidate& c : chosen_) {
    if (c.information.size() > 0) {
      set.push_back(&c);
    } else {
      Candidate p;
      if (prepare(c.view, p)) prepared.push_back(std::move(p));
    }
  }
  for (const Candidate& p : prepared) set.push_back(&p);
  const Eigen::MatrixXd cov = sumInformation(set).inverse();
  for (size_t k = 0; k < free_.size(); ++k) sigma[free_[k]] = std::sqrt(std::max(0.0, cov(k, k)));
  if (options_.locks.fix_aspect && !options_.locks.fix_focal)
    sigma[detail::kFy] = sigma[detail::kFx] * guess_.fy / guess_.fx;
  return sigma;
}

std::string ViewSelector::summary() const {
  std::ostringstream s;
  s << "select (" << toString(options_.method) << "): " << chosen_.size() << " of " << considered_
    << " usable views (" << seen_ << " offered), " << swaps_ << " swaps, held at most "
    << max_held_ << " views, " << relinearisations_ << " re-linearisations; chosen:";
  for (int i : selectedIndices()) s << " " << i;
  return s.str();
}

}  // namespace previz::calib
