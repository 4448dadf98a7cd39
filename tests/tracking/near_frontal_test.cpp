// Issue 33 item 2: near-frontal tags as a real camera films them. One tag36h11 tag (65 mm) a
// few degrees off face-on at 0.2-0.6 m, rendered here with exact geometry and then formed as a
// real camera would: the lens's blur in linear light, a tone response that is not sRGB (a pure
// 2.2 power, Rec.709, a filmic S-curve), sensor noise, 8 bits and JPEG. The pose from the
// detector's corners is compared with the truth, with and without the corner refinement.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <apriltag/apriltag.h>
#include <apriltag/tag36h11.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "tracking/detect.h"

namespace previz::tracking {
namespace {

enum class Response { kSrgb, kGamma22, kRec709, kFilmic, kLinear };

const char* name(Response r) {
  switch (r) {
    case Response::kSrgb: return "sRGB";
    case Response::kGamma22: return "gamma2.2";
    case Response::kRec709: return "Rec709";
    case Response::kFilmic: return "filmic";
    case Response::kLinear: return "linear";
  }
  return "?";
}

double encode(Response r, double x) {
  x = std::clamp(x, 0.0, 1.0);
  switch (r) {
    case Response::kSrgb: return x <= 0.0031308 ? 12.92 * x : 1.055 * std::pow(x, 1 / 2.4) - 0.055;
    case Response::kGamma22: return std::pow(x, 1 / 2.2);
    case Response::kRec709: return x < 0.018 ? 4.5 * x : 1.099 * std::pow(x, 0.45) - 0.099;
    case Response::kFilmic: {
      const double v = std::pow(x, 1 / 2.2), k = 3.0;
      return 0.5 + 0.5 * std::tanh(k * (v - 0.5)) / std::tanh(0.5 * k);
    }
    case Response::kLinear: return x;
  }
  return x;
}

struct Shot {
  double f_px = 800, dist_m = 0.3, tilt_deg = 5, spin_deg = 0, blur_px = 0.8, noise = 1.5;
  int width = 1280, height = 960, jpeg_quality = 90, seed = 1;
  Response response = Response::kGamma22;
};

struct Truth {
  Eigen::Matrix3d R;  // tag -> camera
  Eigen::Vector3d t;
  std::array<Eigen::Vector2d, 4> corners;  // the black border's outer corners, image
  cv::Mat K;
};

constexpr double kTagM = 0.065;

// Tag frame: x right, y down, z away from the camera, origin at the tag's centre; the black
// border's outer square spans [-L/2, L/2]^2.
cv::Mat render(const Shot& s, int id, Truth& truth) {
  std::mt19937 rng(static_cast<unsigned>(s.seed));
  std::uniform_real_distribution<double> uni(0, 1);
  const double az = 2 * M_PI * uni(rng);
  const Eigen::Vector3d axis(std::cos(az), std::sin(az), 0);
  truth.R = Eigen::AngleAxisd(s.tilt_deg * M_PI / 180, axis).toRotationMatrix() *
            Eigen::AngleAxisd(s.spin_deg * M_PI / 180, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  const double cx = 0.5 * (s.width - 1) + 20 * (uni(rng) - 0.5), cy = 0.5 * (s.height - 1) + 20 * (uni(rng) - 0.5);
  truth.t = Eigen::Vector3d(0.01 * (uni(rng) - 0.5), 0.01 * (uni(rng) - 0.5), s.dist_m);
  Eigen::Matrix3d K;
  K << s.f_px, 0, cx, 0, s.f_px, cy, 0, 0, 1;
  truth.K = (cv::Mat_<double>(3, 3) << s.f_px, 0, cx, 0, s.f_px, cy, 0, 0, 1);
  // Homography tag plane (x, y, 1) -> pixels, and its inverse.
  Eigen::Matrix3d H;
  H.col(0) = K * truth.R.col(0);
  H.col(1) = K * truth.R.col(1);
  H.col(2) = K * truth.t;
  const Eigen::Matrix3d Hinv = H.inverse();
  const double L = kTagM;
  const Eigen::Vector2d sq[4] = {{-L / 2, L / 2}, {L / 2, L / 2}, {L / 2, -L / 2}, {-L / 2, -L / 2}};
  for (int q = 0; q < 4; ++q) truth.corners[q] = (H * sq[q].homogeneous()).hnormalized();

  apriltag_family_t* fam = tag36h11_create();
  image_u8_t* bitmap = apriltag_to_image(fam, id);  // total_width^2, white quiet zone included
  const int W = fam->total_width, B = fam->width_at_border, off = (W - B) / 2;
  constexpr double kBlack = 0.04, kWhite = 0.75;
  cv::Mat radiance(s.height, s.width, CV_32F, cv::Scalar(kWhite));
  // Only the pixels the tag and its quiet zone can touch differ from the paper.
  Eigen::Vector2d lo(1e9, 1e9), hi(-1e9, -1e9);
  for (double sx : {-1.0, 1.0})
    for (double sy : {-1.0, 1.0}) {
      const double h = 0.5 * L * W / B + L / B;
      const Eigen::Vector2d c = (H * Eigen::Vector3d(sx * h, sy * h, 1)).hnormalized();
      lo = lo.cwiseMin(c);
      hi = hi.cwiseMax(c);
    }
  constexpr int kN = 6;
  for (int v = std::max(0, static_cast<int>(lo.y())); v < std::min(s.height, static_cast<int>(hi.y()) + 2); ++v)
    for (int u = std::max(0, static_cast<int>(lo.x())); u < std::min(s.width, static_cast<int>(hi.x()) + 2); ++u) {
      double sum = 0;
      for (int j = 0; j < kN; ++j)
        for (int i = 0; i < kN; ++i) {
          const Eigen::Vector3d p(u - 0.5 + (i + 0.5) / kN, v - 0.5 + (j + 0.5) / kN, 1);
          const Eigen::Vector2d x = (Hinv * p).hnormalized();
          const double bx = (x.x() + L / 2) / L * B, by = (x.y() + L / 2) / L * B;
          double value = kWhite;
          if (bx >= -off && by >= -off && bx < B + off && by < B + off) {
            const int ix = static_cast<int>(std::floor(bx)) + off, iy = static_cast<int>(std::floor(by)) + off;
            value = bitmap->buf[iy * bitmap->stride + ix] < 128 ? kBlack : kWhite;
          }
          sum += value;
        }
      radiance.at<float>(v, u) = static_cast<float>(sum / (kN * kN));
    }
  image_u8_destroy(bitmap);
  tag36h11_destroy(fam);
  if (s.blur_px > 0) cv::GaussianBlur(radiance, radiance, cv::Size(), s.blur_px);
  std::normal_distribution<double> noise(0, s.noise);
  cv::Mat grey(s.height, s.width, CV_8U);
  for (int v = 0; v < s.height; ++v)
    for (int u = 0; u < s.width; ++u)
      grey.at<uint8_t>(v, u) = cv::saturate_cast<uint8_t>(
          std::lround(255 * encode(s.response, radiance.at<float>(v, u)) + noise(rng)));
  if (s.jpeg_quality > 0) {
    std::vector<uint8_t> buf;
    cv::imencode(".jpg", grey, buf, {cv::IMWRITE_JPEG_QUALITY, s.jpeg_quality});
    grey = cv::imdecode(buf, cv::IMREAD_GRAYSCALE);
  }
  return grey;
}

struct PoseError {
  bool found = false;
  double corner_rms_px = 0, pos_mm = 0, dist_mm = 0, normal_deg = 0;
};

PoseError poseError(const Truth& truth, const std::vector<TagDetection>& dets) {
  PoseError e;
  if (dets.size() != 1) return e;
  const double L = kTagM;
  const cv::Point3d sq[4] = {{-L / 2, L / 2, 0}, {L / 2, L / 2, 0}, {L / 2, -L / 2, 0}, {-L / 2, -L / 2, 0}};
  std::vector<cv::Point3d> obj;
  std::vector<cv::Point2d> img;
  double sum2 = 0;
  for (int q = 0; q < 4; ++q) {
    int best = 0;
    for (int k = 1; k < 4; ++k)
      if ((dets[0].corners_px[k] - truth.corners[q]).norm() < (dets[0].corners_px[best] - truth.corners[q]).norm())
        best = k;
    const Eigen::Vector2d c = dets[0].corners_px[best];
    sum2 += (c - truth.corners[q]).squaredNorm();
    obj.push_back(sq[q]);
    img.emplace_back(c.x(), c.y());
  }
  cv::Mat rvec, tvec;
  cv::solvePnP(obj, img, truth.K, cv::Mat(), rvec, tvec, false, cv::SOLVEPNP_IPPE_SQUARE);
  cv::Mat Rcv;
  cv::Rodrigues(rvec, Rcv);
  Eigen::Matrix3d R;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) R(r, c) = Rcv.at<double>(r, c);
  const Eigen::Vector3d t(tvec.at<double>(0), tvec.at<double>(1), tvec.at<double>(2));
  e.found = true;
  e.corner_rms_px = std::sqrt(sum2 / 4);
  e.pos_mm = 1000 * (t - truth.t).norm();
  e.dist_mm = 1000 * (t.norm() - truth.t.norm());
  e.normal_deg = std::acos(std::clamp(R.col(2).dot(truth.R.col(2)), -1.0, 1.0)) * 180 / M_PI;
  return e;
}

// Over seeds (tilt 3-8 degrees, random spin, the principal point and the tag's position
// jittered), three distances (the tag 290, 117 and 65 px wide) and five tone responses: the
// refined corners are response-free within 0.08 px RMS of the truth, where libapriltag's sit
// 0.5-0.7 px inside the border for every response but linear, and the pose from the refined
// corners is never worse than from libapriltag's: over the seeds, paired, the mean difference of
// the position error and of the normal's error is not above 2 of its standard errors (a face-on
// tag's normal is ill-conditioned: a few hundredths of a pixel move it by tenths of a degree). Before the border's inner edge was measured (previz 2026-12-04), the
// refinement decoded every camera as sRGB and a linear camera's corners came out 0.69 px outside
// (4.2 mm at 0.5 m), and tags over ~190 px were never refined at all.
TEST(NearFrontalTags, RefinedCornersNeverWorseThanTheDetectorsWhateverTheCamerasResponse) {
  constexpr int kSeeds = 10;
  std::printf("response  dist  corners      rms px (max)     position mm (max)   normal deg (max)   shift px\n");
  for (Response resp : {Response::kSrgb, Response::kGamma22, Response::kRec709, Response::kFilmic, Response::kLinear})
    for (double dist : {0.2, 0.5, 0.9}) {
      std::array<std::array<double, 3>, 2> mean{}, worst{};
      double shift = 0;
      int refined = 0;
      std::array<std::vector<double>, 2> diff;  // refined - libapriltag, per seed: position, normal
      for (int seed = 1; seed <= kSeeds; ++seed) {
        Shot s;
        s.response = resp;
        s.dist_m = dist;
        s.f_px = 900;
        s.seed = seed;
        s.tilt_deg = 2 + seed;
        s.spin_deg = 17 * seed;
        Truth truth;
        const cv::Mat image = render(s, 7 + seed, truth);
        for (int refine = 0; refine < 2; ++refine) {
          DetectorOptions o;
          o.refine_corners = refine == 1;
          TagDetector detector(o);
          const std::vector<TagDetection> dets = detector.detect(image);
          ASSERT_EQ(dets.size(), 1u) << name(resp) << " at " << dist << " m, seed " << seed;
          if (refine) {
            refined += dets[0].refined ? 1 : 0;
            EXPECT_TRUE(dets[0].refined) << dets[0].refine_why_not << " (" << name(resp) << ", " << dist << " m)";
            shift += dets[0].response_shift_px / kSeeds;
          }
          const PoseError e = poseError(truth, dets);
          const double v[3] = {e.corner_rms_px, e.pos_mm, e.normal_deg};
          if (refine) {
            diff[0].back() += v[1];
            diff[1].back() += v[2];
          } else {
            diff[0].push_back(-v[1]);
            diff[1].push_back(-v[2]);
          }
          for (int k = 0; k < 3; ++k) {
            mean[refine][k] += v[k] / kSeeds;
            worst[refine][k] = std::max(worst[refine][k], v[k]);
          }
        }
      }
      for (int refine = 0; refine < 2; ++refine)
        std::printf("%-9s %.1f m %-10s %.3f (%.3f)    %.3f (%.3f)     %.3f (%.3f)      %s\n", name(resp), dist,
                    refine ? "refined" : "libapriltag", mean[refine][0], worst[refine][0], mean[refine][1],
                    worst[refine][1], mean[refine][2], worst[refine][2],
                    refine ? cv::format("%+.3f", shift).c_str() : "");
      EXPECT_EQ(refined, kSeeds);
      EXPECT_LE(mean[1][0], 0.08) << name(resp) << " at " << dist << " m";
      for (int k = 0; k < 2; ++k) {
        double m = 0, m2 = 0;
        for (double x : diff[k]) {
          m += x / kSeeds;
          m2 += x * x / kSeeds;
        }
        const double se = std::sqrt(std::max(m2 - m * m, 0.0) / (kSeeds - 1));
        EXPECT_LE(m, 2 * se) << (k ? "normal" : "position") << ", " << name(resp) << " at " << dist << " m";
      }
      if (resp != Response::kLinear) {
        EXPECT_GT(mean[0][0], 0.3) << "the detector's own corners were expected biased";
      }
    }
}

}  // namespace
}  // namespace previz::tracking
