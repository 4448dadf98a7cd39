// The actor: an articulated figure of capsules that walks a path across the stage, stops,
// raises both arms, turns on the spot and walks on. Kinematics are a pure function of
// (StudioConfig, time); the renderer traces the capsules analytically and actorMesh() gives a
// tessellation of the same capsules for truth files.
#include <algorithm>
#include <cmath>
#include <vector>

#include "datasets/detail/studio_detail.h"

namespace previz::synth::detail {

namespace {

constexpr double kPi = 3.14159265358979323846;

// ---- body dimensions (metres), about 1.75 m tall standing ---------------------------------
constexpr double kHipHalfWidth = 0.09;
constexpr double kThigh = 0.43, kShank = 0.42;
constexpr double kThighRadius = 0.075, kShankRadius = 0.052;
constexpr double kFootRadius = 0.035, kFootLength = 0.16;
constexpr double kHeelBack = 0.035, kHeelDown = 0.045;  // heel centre relative to the ankle
constexpr double kPelvisRadius = 0.12, kTorsoRadius = 0.15, kNeckRadius = 0.05, kHeadRadius = 0.105;
constexpr double kBackpackRadius = 0.10;
constexpr double kShoulderHalfWidth = 0.20, kShoulderUp = 0.47;
constexpr double kUpperArm = 0.29, kLowerArm = 0.25;
constexpr double kUpperArmRadius = 0.045, kLowerArmRadius = 0.038, kHandRadius = 0.048, kHandReach = 0.055;

// ---- gait ---------------------------------------------------------------------------------
constexpr double kStrideLength = 1.3;  // one full gait cycle (two steps), metres
constexpr double kNominalSpeed = 0.8;  // speed at which the gait reaches full amplitude, m/s

// ---- the path: two walking legs joined by a stop (fractions of the take) -------------------
struct LegSpec {
  double u0, u1;           // fraction of the take
  double ramp_in_s, ramp_out_s;
  std::vector<Eigen::Vector2d> waypoints;
};

// Chosen against the CG set (pillar at (0.3, -0.6), table at (-1.3, -0.3)) and the main camera
// at about (0, -6, 1.6) looking +y: leg 1 runs along the back (behind the pillar and the table
// as the main camera sees them) and down the right side; leg 2 runs along the front, in front of
// both. Both keep >= 0.1 m from the CG objects (tests check).
constexpr double kLeg1U0 = 0.0, kLeg1U1 = 0.48;
constexpr double kRaiseUpU0 = 0.49, kRaiseUpU1 = 0.53, kRaiseDownU0 = 0.57, kRaiseDownU1 = 0.62;
constexpr double kTurnU0 = 0.575, kTurnU1 = 0.655;
constexpr double kLeg2U0 = 0.66, kLeg2U1 = 1.0;

const std::vector<LegSpec>& legs() {
  static const std::vector<LegSpec> kLegs = {
      {kLeg1U0, kLeg1U1, 0.5, 0.7,
       {{-1.7, 0.9}, {-0.6, 1.15}, {0.4, 1.2}, {1.1, 0.95}, {1.4, 0.3}, {1.35, -0.5},
        {1.35, -1.15}}},
      {kLeg2U0, kLeg2U1, 0.6, 0.7,
       {{1.35, -1.15}, {0.95, -1.22}, {0.4, -1.5}, {-0.4, -1.5}, {-1.1, -1.32},
        {-1.6, -1.2}}},
  };
  return kLegs;
}

double smoothstep(double e0, double e1, double x) {
  const double t = std::clamp((x - e0) / (e1 - e0), 0.0, 1.0);
  return t * t * (3 - 2 * t);
}

// Uniform Catmull–Rom spline through the waypoints (phantom end points by reflection).
struct Spline {
  const std::vector<Eigen::Vector2d>& p;
  int segments() const { return static_cast<int>(p.size()) - 1; }
  Eigen::Vector2d point(int i) const {
    const int n = static_cast<int>(p.size());
    if (i < 0) return 2 * p[0] - p[1];
    if (i >= n) return 2 * p[n - 1] - p[n - 2];
    return p[i];
  }
  // Position and derivative at global parameter x in [0, segments].
  void eval(double x, Eigen::Vector2d& pos, Eigen::Vector2d& deriv) const {
    int i = std::clamp(static_cast<int>(std::floor(x)), 0, segments() - 1);
    const double t = x - i;
    const Eigen::Vector2d p0 = point(i), p1 = point(i + 1);
    const Eigen::Vector2d m0 = 0.5 * (point(i + 1) - point(i - 1));
    const Eigen::Vector2d m1 = 0.5 * (point(i + 2) - point(i));
    const double t2 = t * t, t3 = t2 * t;
    pos = (2 * t3 - 3 * t2 + 1) * p0 + (t3 - 2 * t2 + t) * m0 + (-2 * t3 + 3 * t2) * p1 +
          (t3 - t2) * m1;
    deriv = (6 * t2 - 6 * t) * p0 + (3 * t2 - 4 * t + 1) * m0 + (-6 * t2 + 6 * t) * p1 +
            (3 * t2 - 2 * t) * m1;
  }
};

// Arc-length table of a spline: parameter x at uniform steps and the distance up to it.
struct ArcTable {
  static constexpr int kPerSegment = 64;
  std::vector<double> x, s;
  explicit ArcTable(const Spline& spline) {
    const int n = spline.segments() * kPerSegment;
    x.resize(n + 1);
    s.resize(n + 1);
    Eigen::Vector2d prev, d;
    spline.eval(0, prev, d);
    s[0] = 0;
    x[0] = 0;
    for (int k = 1; k <= n; ++k) {
      x[k] = static_cast<double>(k) / kPerSegment;
      Eigen::Vector2d q;
      spline.eval(x[k], q, d);
      s[k] = s[k - 1] + (q - prev).norm();
      prev = q;
    }
  }
  double length() const { return s.back(); }
  double paramAt(double dist) const {
    dist = std::clamp(dist, 0.0, length());
    const auto it = std::upper_bound(s.begin(), s.end(), dist);
    const size_t k = std::min<size_t>(std::max<size_t>(it - s.begin(), 1), s.size() - 1);
    const double f = (dist - s[k - 1]) / std::max(s[k] - s[k - 1], 1e-12);
    return x[k - 1] + f * (x[k] - x[k - 1]);
  }
};

// Trapezoidal speed profile: distance and speed after tau seconds of a leg of 'length' metres
// lasting 'duration' seconds with the given acceleration / deceleration ramps.
void speedProfile(double length, double duration, double ramp_in, double ramp_out, double tau,
                  double& dist, double& speed) {
  tau = std::clamp(tau, 0.0, duration);
  const double v = length / (duration - 0.5 * ramp_in - 0.5 * ramp_out);
  if (tau < ramp_in) {
    dist = 0.5 * v * tau * tau / ramp_in;
    speed = v * tau / ramp_in;
  } else if (tau <= duration - ramp_out) {
    dist = 0.5 * v * ramp_in + v * (tau - ramp_in);
    speed = v;
  } else {
    const double left = duration - tau;
    dist = length - 0.5 * v * left * left / ramp_out;
    speed = v * left / ramp_out;
  }
}

struct PathState {
  Eigen::Vector2d position;
  double heading;  // radians
  double speed;    // m/s
  double distance; // walked since the take start (drives the gait phase)
};

// Where the actor's path puts it at fraction u of the take with duration T.
PathState pathAt(double u, double T) {
  const auto& L = legs();
  std::vector<double> lengths;
  for (const auto& leg : L) lengths.push_back(ArcTable(Spline{leg.waypoints}).length());
  auto legState = [&](int k, double uu) {
    const LegSpec& leg = L[k];
    const Spline spline{leg.waypoints};
    const ArcTable table(spline);
    double dist, speed;
    speedProfile(lengths[k], (leg.u1 - leg.u0) * T, leg.ramp_in_s, leg.ramp_out_s,
                 (uu - leg.u0) * T, dist, speed);
    Eigen::Vector2d pos, deriv;
    spline.eval(table.paramAt(dist), pos, deriv);
    PathState st;
    st.position = pos;
    st.heading = std::atan2(deriv.y(), deriv.x());
    st.speed = speed;
    st.distance = dist;
    for (int j = 0; j < k; ++j) st.distance += lengths[j];
    return st;
  };
  u = std::clamp(u, 0.0, 1.0);
  if (u <= L[0].u1) return legState(0, u);
  if (u >= L[1].u0) return legState(1, u);
  // Standing between the legs: turn on the spot from the end heading of leg 1 to the start
  // heading of leg 2 the short way round.
  const PathState end1 = legState(0, L[0].u1);
  const PathState start2 = legState(1, L[1].u0);
  double delta = start2.heading - end1.heading;
  delta = std::remainder(delta, 2 * kPi);
  PathState st = end1;
  st.heading = end1.heading + delta * smoothstep(kTurnU0, kTurnU1, u);
  st.speed = 0;
  return st;
}

struct LegChain {
  Eigen::Vector3d hip, knee, ankle, heel, toe;
};

// One leg with hip flexion theta (forward positive), knee flexion kappa and foot pitch rho (toe
// up positive), all in the sagittal plane spanned by forward F and up U.
LegChain legChain(const Eigen::Vector3d& hip, const Eigen::Vector3d& F, const Eigen::Vector3d& U,
                  double theta, double kappa, double rho) {
  LegChain c;
  c.hip = hip;
  const Eigen::Vector3d thigh = -U * std::cos(theta) + F * std::sin(theta);
  c.knee = hip + kThigh * thigh;
  const double shank_angle = theta - kappa;
  const Eigen::Vector3d shank = -U * std::cos(shank_angle) + F * std::sin(shank_angle);
  c.ankle = c.knee + kShank * shank;
  const Eigen::Vector3d fwd = F * std::cos(rho) + U * std::sin(rho);
  const Eigen::Vector3d up = U * std::cos(rho) - F * std::sin(rho);
  c.heel = c.ankle - kHeelBack * fwd - kHeelDown * up;
  c.toe = c.heel + kFootLength * fwd;
  return c;
}

double footLowest(const LegChain& c) { return std::min(c.heel.z(), c.toe.z()) - kFootRadius; }

}  // namespace

const char* actorPartName(int part) {
  static const char* kNames[kActorPartCount] = {
      "head",        "neck",        "torso",      "pelvis",      "backpack",    "upper_arm_l",
      "lower_arm_l", "hand_l",      "upper_arm_r", "lower_arm_r", "hand_r",      "upper_leg_l",
      "lower_leg_l", "foot_l",      "upper_leg_r", "lower_leg_r", "foot_r"};
  return part >= 0 && part < kActorPartCount ? kNames[part] : "unknown";
}

Eigen::Vector3f actorAlbedo(int part) {
  const Eigen::Vector3f skin(0.60f, 0.38f, 0.27f);
  const Eigen::Vector3f shirt(0.55f, 0.12f, 0.09f);
  const Eigen::Vector3f trousers(0.05f, 0.055f, 0.09f);
  const Eigen::Vector3f shoes(0.10f, 0.07f, 0.05f);
  // Greenish grey: close enough to the screen green in hue to test a keyer's honesty.
  const Eigen::Vector3f backpack(0.20f, 0.26f, 0.21f);
  switch (part) {
    case kHead: case kNeck: case kLowerArmL: case kLowerArmR: case kHandL: case kHandR:
      return skin;
    case kTorso: case kUpperArmL: case kUpperArmR: return shirt;
    case kPelvis: case kUpperLegL: case kLowerLegL: case kUpperLegR: case kLowerLegR:
      return trousers;
    case kFootL: case kFootR: return shoes;
    case kBackpack: return backpack;
    default: return Eigen::Vector3f(0.5f, 0.5f, 0.5f);
  }
}

ActorPose actorPoseAt(const StudioConfig& config, double time_s) {
  const double T = config.take_duration_s;
  const double u = std::clamp(time_s / T, 0.0, 1.0);
  const PathState path = pathAt(u, T);

  ActorPose pose;
  pose.heading = path.heading;
  pose.speed = path.speed;
  const double amp = smoothstep(0.0, kNominalSpeed, path.speed);  // gait amplitude 0..1
  const double w = smoothstep(kRaiseUpU0, kRaiseUpU1, u) * (1 - smoothstep(kRaiseDownU0, kRaiseDownU1, u));
  pose.arms_raised = w;
  const double phase = 2 * kPi * path.distance / kStrideLength;

  const Eigen::Vector3d F(std::cos(path.heading), std::sin(path.heading), 0);
  const Eigen::Vector3d Lf(-F.y(), F.x(), 0);
  const Eigen::Vector3d U = Eigen::Vector3d::UnitZ();
  const Eigen::Vector3d ground(path.position.x(), path.position.y(), 0);

  // Legs first, with the hips at height 0: the pelvis is then lifted so that the lower foot
  // just touches the floor (no penetration, and the vertical bob of walking for free).
  LegChain leg[2];
  for (int side = 0; side < 2; ++side) {
    const double sigma = side == 0 ? 1.0 : -1.0;  // left, right
    const double ph = phase + (side == 0 ? 0.0 : kPi);
    const double theta = amp * (0.05 + 0.38 * std::sin(ph));
    const double c = std::max(0.0, std::cos(ph + 0.4));
    const double kappa = amp * (0.06 + 0.9 * c * c);
    const double rho = amp * (-0.5 * std::max(0.0, -std::sin(ph)) * std::max(0.0, std::cos(ph)) +
                              0.15 * std::max(0.0, std::sin(ph)) * std::max(0.0, std::cos(ph)));
    leg[side] = legChain(ground + sigma * kHipHalfWidth * Lf, F, U, theta, kappa, rho);
  }
  const double lift = -std::min(footLowest(leg[0]), footLowest(leg[1]));
  for (auto& c : leg)
    for (Eigen::Vector3d* p : {&c.hip, &c.knee, &c.ankle, &c.heel, &c.toe}) p->z() += lift;

  const Eigen::Vector3d P = ground + lift * U;  // pelvis centre (between the hips)
  pose.pelvis = P;
  const double lean = 0.06 * amp;
  const Eigen::Vector3d up = U * std::cos(lean) + F * std::sin(lean);

  auto& parts = pose.parts;
  parts[kPelvis] = {P - kHipHalfWidth * Lf + 0.03 * U, P + kHipHalfWidth * Lf + 0.03 * U, kPelvisRadius};
  parts[kTorso] = {P + 0.14 * up, P + 0.36 * up, kTorsoRadius};
  parts[kNeck] = {P + 0.50 * up, P + 0.62 * up, kNeckRadius};
  const Eigen::Vector3d head = P + 0.72 * up + 0.02 * F;
  parts[kHead] = {head, head, kHeadRadius};
  parts[kBackpack] = {P + 0.18 * up - 0.19 * F, P + 0.38 * up - 0.19 * F, kBackpackRadius};

  for (int side = 0; side < 2; ++side) {
    const double sigma = side == 0 ? 1.0 : -1.0;
    const double ph = phase + (side == 0 ? 0.0 : kPi);
    const Eigen::Vector3d shoulder = P + kShoulderUp * up + sigma * kShoulderHalfWidth * Lf;
    // Arms swing against the leg of the same side; raised, they go up in a V to the front.
    const double alpha = -0.32 * amp * std::sin(ph);
    const Eigen::Vector3d hang =
        (-U * std::cos(alpha) + F * std::sin(alpha) + 0.10 * sigma * Lf).normalized();
    const double beta = 2.85 * w;
    const double gamma = 0.45;
    const Eigen::Vector3d e = F * std::cos(gamma) + sigma * Lf * std::sin(gamma);
    const Eigen::Vector3d raised = -U * std::cos(beta) + e * std::sin(beta);
    const Eigen::Vector3d upper = ((1 - w) * hang + w * raised).normalized();
    const double elbow = (1 - w) * (0.22 + 0.2 * amp) + w * 0.25;
    const Eigen::Vector3d bend = (F - F.dot(upper) * upper).normalized();
    const Eigen::Vector3d lower = upper * std::cos(elbow) + bend * std::sin(elbow);
    const Eigen::Vector3d elbow_p = shoulder + kUpperArm * upper;
    const Eigen::Vector3d wrist = elbow_p + kLowerArm * lower;
    const Eigen::Vector3d hand = wrist + kHandReach * lower;
    const int base = side == 0 ? kUpperArmL : kUpperArmR;
    parts[base + 0] = {shoulder, elbow_p, kUpperArmRadius};
    parts[base + 1] = {elbow_p, wrist, kLowerArmRadius};
    parts[base + 2] = {hand, hand, kHandRadius};

    const int lbase = side == 0 ? kUpperLegL : kUpperLegR;
    parts[lbase + 0] = {leg[side].hip, leg[side].knee, kThighRadius};
    parts[lbase + 1] = {leg[side].knee, leg[side].ankle, kShankRadius};
    parts[lbase + 2] = {leg[side].heel, leg[side].toe, kFootRadius};
  }

  // Bounding sphere: around the AABB centre, radius to the farthest capsule extent.
  Eigen::AlignedBox3d box;
  for (const auto& c : parts) {
    box.extend(c.a - Eigen::Vector3d::Constant(c.r));
    box.extend(c.a + Eigen::Vector3d::Constant(c.r));
    box.extend(c.b - Eigen::Vector3d::Constant(c.r));
    box.extend(c.b + Eigen::Vector3d::Constant(c.r));
  }
  pose.bound_centre = box.center();
  double r = 0;
  for (const auto& c : parts)
    r = std::max({r, (c.a - pose.bound_centre).norm() + c.r, (c.b - pose.bound_centre).norm() + c.r});
  pose.bound_radius = r * (1 + 1e-9) + 1e-9;
  return pose;
}

double segmentSegmentDistance(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1,
                              const Eigen::Vector3d& q0, const Eigen::Vector3d& q1, double& s,
                              double& t) {
  // Ericson, Real-Time Collision Detection, 5.1.9 (ClosestPtSegmentSegment).
  const Eigen::Vector3d d1 = p1 - p0, d2 = q1 - q0, r = p0 - q0;
  const double a = d1.squaredNorm(), e = d2.squaredNorm(), f = d2.dot(r);
  constexpr double kEps = 1e-18;
  if (a <= kEps && e <= kEps) {
    s = t = 0;
    return r.norm();
  }
  if (a <= kEps) {
    s = 0;
    t = std::clamp(f / e, 0.0, 1.0);
  } else {
    const double c = d1.dot(r);
    if (e <= kEps) {
      t = 0;
      s = std::clamp(-c / a, 0.0, 1.0);
    } else {
      const double b = d1.dot(d2);
      const double denom = a * e - b * b;
      s = denom > 0 ? std::clamp((b * f - c * e) / denom, 0.0, 1.0) : 0.0;
      t = (b * s + f) / e;
      if (t < 0) {
        t = 0;
        s = std::clamp(-c / a, 0.0, 1.0);
      } else if (t > 1) {
        t = 1;
        s = std::clamp((b - c) / a, 0.0, 1.0);
      }
    }
  }
  return ((p0 + s * d1) - (q0 + t * d2)).norm();
}

namespace {

// The whole actor as one primitive: the scene's bound test rejects most rays against the
// actor's bounding sphere; survivors test each part's sphere, then the capsule.
class ActorPrimitive final : public Primitive {
 public:
  explicit ActorPrimitive(const ActorPose& pose) {
    const Eigen::Vector3d F(std::cos(pose.heading), std::sin(pose.heading), 0);
    back_ = -F;
    for (int k = 0; k < kActorPartCount; ++k) {
      const Capsule& c = pose.parts[k];
      Part& p = parts_[k];
      p.a = c.a;
      p.b = c.b;
      p.ba = c.b - c.a;
      p.baba = p.ba.squaredNorm();
      p.r = c.r;
      p.r2 = c.r * c.r;
      p.centre = 0.5 * (c.a + c.b);
      const double br = 0.5 * std::sqrt(p.baba) + c.r;
      p.bound_r = br;
      p.bound_r2 = br * br;
      p.albedo = actorAlbedo(k);
    }
    head_up_ = (pose.parts[kHead].a - pose.parts[kNeck].a).normalized();
    bound_centre = pose.bound_centre;
    bound_radius = pose.bound_radius;
  }

  bool intersect(const Ray& ray, double t_min, Hit& hit) const override {
    bool found = false;
    for (int k = 0; k < kActorPartCount; ++k) {
      const Part& p = parts_[k];
      const Eigen::Vector3d oc = p.centre - ray.origin;
      const double along = oc.dot(ray.dir);
      if (along + p.bound_r < t_min || along - p.bound_r > hit.t) continue;
      if (oc.squaredNorm() - along * along > p.bound_r2) continue;
      double t;
      if (!capsuleHit(p, ray, t) || t <= t_min || t >= hit.t) continue;
      hit.t = t;
      hit.object = k;
      found = true;
    }
    if (found) {
      hit.cls = ObjectClass::kActor;
      const Part& p = parts_[hit.object];
      const Eigen::Vector3d q = ray.origin + hit.t * ray.dir;
      const double h = p.baba > 0 ? std::clamp((q - p.a).dot(p.ba) / p.baba, 0.0, 1.0) : 0.0;
      hit.normal = (q - p.a - h * p.ba) / p.r;
    }
    return found;
  }

  void shade(const Ray& ray, Hit& hit) const override {
    const Eigen::Vector3d q = ray.origin + hit.t * ray.dir;
    Eigen::Vector3f albedo = parts_[hit.object].albedo;
    if (hit.object == kHead) {
      // Hair on the crown and the back of the head.
      const double up = hit.normal.dot(head_up_), back = hit.normal.dot(back_);
      if (up > 0.35 || (back > 0.45 && up > -0.35)) albedo = Eigen::Vector3f(0.07f, 0.045f, 0.03f);
    }
    hit.rgb = shadeDiffuse(albedo, q, hit.normal);
  }

 private:
  struct Part {
    Eigen::Vector3d a, b, ba, centre;
    double baba, r, r2, bound_r, bound_r2;
    Eigen::Vector3f albedo;
  };

  // Front hit of a ray from outside (Quilez's capsule intersection, caps as spheres).
  static bool capsuleHit(const Part& p, const Ray& ray, double& t) {
    const Eigen::Vector3d oa = ray.origin - p.a;
    if (p.baba > 0) {
      const double bard = p.ba.dot(ray.dir), baoa = p.ba.dot(oa);
      const double rdoa = ray.dir.dot(oa), oaoa = oa.squaredNorm();
      const double a = p.baba - bard * bard;
      if (a > 1e-12 * p.baba) {
        const double b = p.baba * rdoa - baoa * bard;
        const double c = p.baba * oaoa - baoa * baoa - p.r2 * p.baba;
        const double h = b * b - a * c;
        if (h < 0) return false;  // misses the infinite cylinder, hence the capsule
        t = (-b - std::sqrt(h)) / a;
        const double y = baoa + t * bard;
        if (y > 0 && y < p.baba) return true;
      }
      // The nearer cap: a ray that missed the side can only enter through an end sphere.
      double ta, tb;
      const bool ha = sphereHit(p.a, p.r2, ray, ta), hb = sphereHit(p.b, p.r2, ray, tb);
      if (!ha && !hb) return false;
      t = ha && hb ? std::min(ta, tb) : (ha ? ta : tb);
      return true;
    }
    return sphereHit(p.a, p.r2, ray, t);
  }
  static bool sphereHit(const Eigen::Vector3d& centre, double r2, const Ray& ray, double& t) {
    const Eigen::Vector3d oc = ray.origin - centre;
    const double b = oc.dot(ray.dir);
    const double c = oc.squaredNorm() - r2;
    const double h = b * b - c;
    if (h < 0) return false;
    t = -b - std::sqrt(h);
    return true;
  }

  std::array<Part, kActorPartCount> parts_;
  Eigen::Vector3d head_up_, back_;
};

}  // namespace

std::shared_ptr<const Primitive> makeActorPrimitive(const ActorPose& pose) {
  return std::make_shared<ActorPrimitive>(pose);
}

TriangleMesh capsuleMesh(const Capsule& c, double max_sagitta_m) {
  // Segment counts from the sagitta r (1 - cos(pi / n)) <= max_sagitta around the axis and
  // along the meridians; the two add at most, so callers pass half their surface tolerance.
  const double ratio = std::clamp(1.0 - max_sagitta_m / c.r, -1.0, 1.0);
  const int around = std::max(8, static_cast<int>(std::ceil(kPi / std::acos(ratio))));
  const int lat = std::max(2, (around + 3) / 4);  // rings per hemisphere, same angular step

  Eigen::Vector3d axis = c.b - c.a;
  const double len = axis.norm();
  axis = len > 0 ? Eigen::Vector3d(axis / len) : Eigen::Vector3d::UnitZ();
  const Eigen::Vector3d helper =
      std::abs(axis.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
  const Eigen::Vector3d e1 = axis.cross(helper).normalized();
  const Eigen::Vector3d e2 = axis.cross(e1);

  TriangleMesh mesh;
  auto addVertex = [&](const Eigen::Vector3d& centre, const Eigen::Vector3d& n) {
    mesh.vertices.push_back((centre + c.r * n).cast<float>());
    mesh.normals.push_back(n.cast<float>());
  };
  // Rings from the bottom pole (around a) to the top pole (around b). Latitude -pi/2..pi/2;
  // the equator appears twice (once per end) when the capsule has a cylinder.
  struct Ring {
    double lat;
    bool top;
  };
  std::vector<Ring> rings;
  for (int i = 1; i <= lat; ++i) rings.push_back({-kPi / 2 + kPi / 2 * i / lat, false});
  for (int i = len > 0 ? 0 : 1; i < lat; ++i) rings.push_back({kPi / 2 * i / lat, true});

  addVertex(c.a, -axis);  // bottom pole, index 0
  for (const Ring& ring : rings) {
    const Eigen::Vector3d centre = ring.top ? c.b : c.a;
    for (int j = 0; j < around; ++j) {
      const double phi = 2 * kPi * j / around;
      const Eigen::Vector3d n = std::cos(ring.lat) * (std::cos(phi) * e1 + std::sin(phi) * e2) +
                                std::sin(ring.lat) * axis;
      addVertex(centre, n);
    }
  }
  addVertex(c.b, axis);  // top pole
  const int top_pole = static_cast<int>(mesh.vertices.size()) - 1;
  const int nrings = static_cast<int>(rings.size());
  auto ringIndex = [&](int ring, int j) { return 1 + ring * around + (j % around); };
  // Counter-clockwise seen from outside: (e1, e2, axis) is right-handed, so going around by
  // increasing phi is counter-clockwise seen from +axis.
  for (int j = 0; j < around; ++j)
    mesh.faces.emplace_back(0, ringIndex(0, j + 1), ringIndex(0, j));
  for (int r = 0; r + 1 < nrings; ++r)
    for (int j = 0; j < around; ++j) {
      const int a = ringIndex(r, j), b = ringIndex(r, j + 1);
      const int c2 = ringIndex(r + 1, j), d = ringIndex(r + 1, j + 1);
      mesh.faces.emplace_back(a, b, d);
      mesh.faces.emplace_back(a, d, c2);
    }
  for (int j = 0; j < around; ++j)
    mesh.faces.emplace_back(top_pole, ringIndex(nrings - 1, j), ringIndex(nrings - 1, j + 1));
  return mesh;
}

}  // namespace previz::synth::detail
