// The tagged prop: a 30 cm grey crate with one tag36h11 tag on each face but the bottom,
// carried along a slow path by an invisible grip. Tag pixels come from libapriltag's own family
// bitmaps, so what is drawn is exactly what the detector decodes.
#include <algorithm>
#include <array>
#include <cmath>
#include <vector>

#include <apriltag/apriltag.h>
#include <apriltag/common/image_u8.h>
#include <apriltag/tag36h11.h>

#include "core/box_tag.h"
#include "datasets/detail/studio_detail.h"

namespace previz::synth::detail {

namespace {

constexpr double kPropTagSize = 0.12;    // black border edge
constexpr double kPropLabelHalf = 0.10;  // white label around each tag (quiet zone)
using TagBitmap = std::array<std::uint8_t, kTagBitmapWidth * kTagBitmapWidth>;

std::vector<TagBitmap> buildTag36h11() {
  apriltag_family_t* family = tag36h11_create();
  std::vector<TagBitmap> bitmaps(family->ncodes);
  for (unsigned id = 0; id < family->ncodes; ++id) {
    image_u8_t* image = apriltag_to_image(family, static_cast<int>(id));
    for (int y = 0; y < kTagBitmapWidth; ++y)
      for (int x = 0; x < kTagBitmapWidth; ++x)
        bitmaps[id][y * kTagBitmapWidth + x] = image->buf[y * image->stride + x] ? 255 : 0;
    image_u8_destroy(image);
  }
  tag36h11_destroy(family);
  return bitmaps;
}

struct FaceTag {
  bool present = false;
  Eigen::Matrix3d R_tag_prop;  // prop -> tag rotation
  Eigen::Vector3d t_prop_tag;  // tag centre in the prop frame
  double cell = 0;             // metres per bitmap cell
  const std::uint8_t* bitmap = nullptr;
};

// Face index: 0 +x, 1 -x, 2 +y, 3 -y, 4 +z, 5 -z (outward normal of the box in the prop frame).
int faceOfNormal(const Eigen::Vector3d& n_prop) {
  int axis = 0;
  n_prop.cwiseAbs().maxCoeff(&axis);
  return 2 * axis + (n_prop[axis] > 0 ? 0 : 1);
}

class PropPrimitive final : public Primitive {
 public:
  PropPrimitive(const PropSpec& spec, const Pose& T_world_prop)
      : R_(T_world_prop.linear()), t_(T_world_prop.translation()), half_(0.5 * spec.box_size_m) {
    for (const PropTag& tag : spec.tags) {
      const Eigen::Vector3d z_prop = tag.T_prop_tag.linear().col(2);  // into the face
      const int face = faceOfNormal(-z_prop);
      FaceTag& f = faces_[face];
      f.present = true;
      f.R_tag_prop = tag.T_prop_tag.linear().transpose();
      f.t_prop_tag = tag.T_prop_tag.translation();
      f.cell = tag.size_m / kTagBlackWidth;
      f.bitmap = tag36h11Bitmap(tag.id);
    }
    bound_centre = t_;
    bound_radius = half_.norm() * (1 + 1e-9);
  }

  bool intersect(const Ray& ray, double t_min, Hit& hit) const override {
    const Eigen::Vector3d o = R_.transpose() * (ray.origin - t_);
    const Eigen::Vector3d d = R_.transpose() * ray.dir;
    double t0 = t_min, t1 = hit.t;
    int axis = -1;
    for (int a = 0; a < 3; ++a) {
      const double inv = 1.0 / d[a];
      double ta = (-half_[a] - o[a]) * inv, tb = (half_[a] - o[a]) * inv;
      if (ta > tb) std::swap(ta, tb);
      if (ta > t0) {
        t0 = ta;
        axis = a;
      }
      t1 = std::min(t1, tb);
      if (t0 > t1) return false;
    }
    if (axis < 0) return false;
    Eigen::Vector3d n_prop = Eigen::Vector3d::Zero();
    n_prop[axis] = d[axis] > 0 ? -1 : 1;
    hit.t = t0;
    hit.cls = ObjectClass::kProp;
    hit.object = faceOfNormal(n_prop);
    hit.normal = R_ * n_prop;
    return true;
  }

  void shade(const Ray& ray, Hit& hit) const override {
    const Eigen::Vector3d p = ray.origin + hit.t * ray.dir;
    hit.rgb = shadeDiffuse(albedoAt(hit.object, R_.transpose() * (p - t_)), p, hit.normal);
  }

 private:
  Eigen::Vector3f albedoAt(int face, const Eigen::Vector3d& p_prop) const {
    const FaceTag& f = faces_[face];
    const Eigen::Vector3f crate(0.34f, 0.33f, 0.31f);
    if (!f.present || !f.bitmap) return crate;
    const Eigen::Vector3d q = f.R_tag_prop * (p_prop - f.t_prop_tag);  // tag frame, z ~ 0
    const double half_bitmap = 0.5 * kTagBitmapWidth;
    const double cx = std::floor(q.x() / f.cell + half_bitmap);
    const double cy = std::floor(q.y() / f.cell + half_bitmap);
    if (cx >= 0 && cy >= 0 && cx < kTagBitmapWidth && cy < kTagBitmapWidth) {
      const int idx = static_cast<int>(cy) * kTagBitmapWidth + static_cast<int>(cx);
      return f.bitmap[idx] ? kPaperWhite : kInkBlack;
    }
    if (std::abs(q.x()) <= kPropLabelHalf && std::abs(q.y()) <= kPropLabelHalf) return kPaperWhite;
    return crate;
  }

  Eigen::Matrix3d R_;
  Eigen::Vector3d t_, half_;
  std::array<FaceTag, 6> faces_;
};

double smoothstep(double e0, double e1, double x) {
  const double t = std::clamp((x - e0) / (e1 - e0), 0.0, 1.0);
  return t * t * (3 - 2 * t);
}

}  // namespace

const std::uint8_t* tag36h11Bitmap(int id) {
  static const std::vector<TagBitmap> kBitmaps = buildTag36h11();  // once, thread-safe
  if (id < 0 || id >= static_cast<int>(kBitmaps.size())) return nullptr;
  return kBitmaps[id].data();
}

PropSpec makePropSpec() {
  PropSpec spec;
  spec.id = 0;
  spec.name = "crate";
  spec.box_size_m = Eigen::Vector3d(0.3, 0.3, 0.3);
  const Eigen::Vector3d half = 0.5 * spec.box_size_m;
  // ids 0..4: front (-y), right (+x), back (+y), left (-x), top (+z).
  const Eigen::Vector3d normals[5] = {-Eigen::Vector3d::UnitY(), Eigen::Vector3d::UnitX(),
                                      Eigen::Vector3d::UnitY(), -Eigen::Vector3d::UnitX(),
                                      Eigen::Vector3d::UnitZ()};
  for (int id = 0; id < 5; ++id) {
    PropTag tag;
    tag.family = "tag36h11";
    tag.id = id;
    tag.size_m = kPropTagSize;
    tag.T_prop_tag = boxFaceTagPose(normals[id], half);
    spec.tags.push_back(tag);
  }
  return spec;
}

std::shared_ptr<const Primitive> makePropPrimitive(const PropSpec& spec, const Pose& T_world_prop) {
  return std::make_shared<PropPrimitive>(spec, T_world_prop);
}

Pose propPathAt(const StudioConfig& config, double time_s) {
  // Keyframes (fraction of the take -> grip position) chosen to stay clear of the actor: in
  // front while the actor walks along the back, behind once it comes to the front.
  struct Key {
    double u;
    Eigen::Vector3d p;
  };
  static const Key kKeys[] = {
      {0.00, {-0.9, -1.1, 1.15}}, {0.25, {-0.2, -0.9, 1.35}}, {0.45, {-0.3, 0.0, 1.45}},
      {0.60, {-0.6, 0.5, 1.30}},  {0.80, {0.2, 0.9, 1.20}},   {1.00, {1.0, 0.6, 1.10}},
  };
  constexpr int n = sizeof(kKeys) / sizeof(kKeys[0]);
  const double T = config.take_duration_s;
  const double u = std::clamp(time_s / T, 0.0, 1.0);
  int i = 0;
  while (i + 2 < n && u > kKeys[i + 1].u) ++i;
  // Catmull–Rom over non-uniform knots with tangents from neighbours (reflected at the ends).
  auto P = [&](int k) {
    if (k < 0) return Eigen::Vector3d(2 * kKeys[0].p - kKeys[1].p);
    if (k >= n) return Eigen::Vector3d(2 * kKeys[n - 1].p - kKeys[n - 2].p);
    return kKeys[k].p;
  };
  const double u0 = kKeys[i].u, u1 = kKeys[i + 1].u, h = u1 - u0;
  const double s = (u - u0) / h;
  const Eigen::Vector3d m0 = 0.5 * (P(i + 1) - P(i - 1));
  const Eigen::Vector3d m1 = 0.5 * (P(i + 2) - P(i));
  const double s2 = s * s, s3 = s2 * s;
  const Eigen::Vector3d position = (2 * s3 - 3 * s2 + 1) * P(i) + (s3 - 2 * s2 + s) * m0 +
                                   (-2 * s3 + 3 * s2) * P(i + 1) + (s3 - s2) * m1;
  // Slow yaw with a gentle wobble, eased in from rest.
  const double t = u * T;
  const double yaw = 0.4 + 0.5 * t * smoothstep(0.0, 1.0, t);
  const double roll = 0.12 * std::sin(0.7 * t);
  const double pitch = 0.08 * std::sin(0.5 * t + 1.0);
  Pose T_world_prop = Pose::Identity();
  T_world_prop.linear() = (Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) *
                           Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()) *
                           Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX()))
                              .toRotationMatrix();
  T_world_prop.translation() = position;
  return T_world_prop;
}

}  // namespace previz::synth::detail
