#include "calib/detail/pattern_fit.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include <Eigen/Cholesky>
#include <Eigen/SVD>

#include "calib/detail/detect_common.h"
#include "core/srgb.h"

namespace previz::calib::detail {

namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kInvSqrt2 = 0.70710678118654752440;
constexpr double kInvSqrt2Pi = 0.39894228040143267794;

double normCdf(double x) { return 0.5 * std::erfc(-x * kInvSqrt2); }
// Single precision for the fit's inner loop (twice as fast; the model needs ~1e-6 of the
// contrast, the noise is 1e-2 of it).
float normCdfF(float x) { return 0.5f * std::erfc(-x * static_cast<float>(kInvSqrt2)); }
float normPdfF(float x) { return static_cast<float>(kInvSqrt2Pi) * std::exp(-0.5f * x * x); }

// Gauss-Legendre nodes (the negative half) and weights, 6, 12 and 20 points (Genz's tables).
constexpr std::array<double, 3> kX6 = {-0.9324695142031522, -0.6612093864662647,
                                       -0.2386191860831970};
constexpr std::array<double, 3> kW6 = {0.1713244923791705, 0.3607615730481384,
                                       0.4679139345726904};
constexpr std::array<double, 6> kX12 = {-0.9815606342467191, -0.9041172563704750,
                                        -0.7699026741943050, -0.5873179542866171,
                                        -0.3678314989981802, -0.1252334085114692};
constexpr std::array<double, 6> kW12 = {0.04717533638651177, 0.1069393259953183,
                                        0.1600783285433464,  0.2031674267230659,
                                        0.2334925365383547,  0.2491470458134029};
constexpr std::array<double, 10> kX20 = {
    -0.9931285991850949, -0.9639719272779138, -0.9122344282513259, -0.8391169718222188,
    -0.7463319064601508, -0.6360536807265150, -0.5108670019508271, -0.3737060887154196,
    -0.2277858511416451, -0.07652652113349733};
constexpr std::array<double, 10> kW20 = {
    0.01761400713915212, 0.04060142980038694, 0.06267204833410906, 0.08327674157670475,
    0.1019301198172404,  0.1181945319615184,  0.1316886384491766,  0.1420961093183821,
    0.1491729864726037,  0.1527533871307259};

constexpr double kMaxCorrelation = 0.925;
// Farther than this many sigmas inside one edge line a wedge is that of its other edge alone,
// and outside either edge it is empty (errors below 2e-8 of the contrast).
constexpr double kFar = 5.5;
constexpr int kMaxWedges = 8;

// A blurred wedge at one pixel: P(X < h, Y < k), its partial derivatives, and the marginals
// (which the wedge opposite it, see ImageWedge::partner, reuses).
struct WedgeValue {
  double v = 0, dh = 0, dk = 0;
  double cdf_h = 0, cdf_k = 0, pdf_h = 0, pdf_k = 0;
};

// Genz's sum for one correlation, precomputed: the nodes' sines do not depend on (h, k), so a
// wedge (fixed r) costs 6-20 exponentials a pixel.
class BivariateNormal {
 public:
  explicit BivariateNormal(double r) : r_(r) {
    if (!(std::abs(r) <= kMaxCorrelation)) {
      n_ = -1;
      return;
    }
    const double* x;
    const double* w;
    int half;
    if (std::abs(r) < 0.3) {
      x = kX6.data(), w = kW6.data(), half = 3;
    } else if (std::abs(r) < 0.75) {
      x = kX12.data(), w = kW12.data(), half = 6;
    } else {
      x = kX20.data(), w = kW20.data(), half = 10;
    }
    const double asr = std::asin(r);
    n_ = 0;
    for (int i = 0; i < half; ++i)
      for (double sign : {1.0, -1.0}) {
        const double sn = std::sin(asr * (sign * x[i] + 1) / 2);
        sn_[n_] = sn;
        inv_[n_] = 1.0 / (1 - sn * sn);
        w_[n_] = w[i];
        snf_[n_] = static_cast<float>(sn_[n_]);
        invf_[n_] = static_cast<float>(inv_[n_]);
        wf_[n_] = static_cast<float>(w_[n_]);
        ++n_;
      }
    scale_ = asr / (4 * kPi);
    inv_sqrt_1mr2_ = 1.0 / std::sqrt(1 - r * r);
  }
  bool valid() const { return n_ > 0; }

  // marginals: also fill cdf_h, cdf_k, pdf_h, pdf_k when the value alone would not need them.
  // Beyond kFar the marginals are 0 or 1 and the densities 0: most pixels of a large window are
  // that far from at least one edge line.
  void eval(double h, double k, bool marginals, WedgeValue& out) const {
    const bool outside = h < -kFar || k < -kFar;
    if (outside && !marginals) {
      out.v = out.dh = out.dk = 0;
      return;
    }
    marginal(h, out.cdf_h, out.pdf_h);
    marginal(k, out.cdf_k, out.pdf_k);
    if (outside) {
      out.v = out.dh = out.dk = 0;
    } else if (h > kFar || k > kFar) {  // the other edge alone (both: inside, 1)
      out.v = out.cdf_h * out.cdf_k, out.dh = out.pdf_h * out.cdf_k, out.dk = out.pdf_k * out.cdf_h;
    } else {
      out.v = genzSumF(static_cast<float>(h), static_cast<float>(k)) + out.cdf_h * out.cdf_k;
      out.dh = out.pdf_h * normCdfF(static_cast<float>((k - r_ * h) * inv_sqrt_1mr2_));
      out.dk = out.pdf_k * normCdfF(static_cast<float>((h - r_ * k) * inv_sqrt_1mr2_));
    }
  }
  static void marginal(double x, double& cdf, double& pdf) {
    if (x > kFar) {
      cdf = 1, pdf = 0;
    } else if (x < -kFar) {
      cdf = 0, pdf = 0;
    } else {
      cdf = normCdfF(static_cast<float>(x)), pdf = normPdfF(static_cast<float>(x));
    }
  }
  double cdf(double h, double k) const {
    if (h < -9 || k < -9) return 0;  // below 1e-19
    return genzSum(h, k) + normCdf(h) * normCdf(k);
  }

 private:
  double genzSum(double h, double k) const {
    const double hk = h * k, hs = 0.5 * (h * h + k * k);
    double sum = 0;
    for (int i = 0; i < n_; ++i) sum += w_[i] * std::exp((sn_[i] * hk - hs) * inv_[i]);
    return sum * scale_;
  }
  float genzSumF(float h, float k) const {
    const float hk = h * k, hs = 0.5f * (h * h + k * k);
    float sum = 0;
    for (int i = 0; i < n_; ++i) sum += wf_[i] * std::exp((snf_[i] * hk - hs) * invf_[i]);
    return sum * static_cast<float>(scale_);
  }

  double r_ = 0, scale_ = 0, inv_sqrt_1mr2_ = 1;
  int n_ = 0;
  std::array<double, 20> sn_{}, inv_{}, w_{};
  std::array<float, 20> snf_{}, invf_{}, wf_{};
};

Eigen::Vector2d applyH(const Eigen::Matrix3d& H, const Eigen::Vector2d& b) {
  return (H * b.homogeneous()).hnormalized();
}

// d(pixel) / d(board point) at b.
Eigen::Matrix2d jacobianH(const Eigen::Matrix3d& H, const Eigen::Vector2d& b) {
  const Eigen::Vector3d y = H * b.homogeneous();
  const Eigen::Vector2d q = y.head<2>() / y.z();
  Eigen::Matrix2d J;
  for (int c = 0; c < 2; ++c) J.col(c) = (H.block<2, 1>(0, c) - q * H(2, c)) / y.z();
  return J;
}

// A wedge in the image: apex (before the fitted shift), inward edge normals, its correlation.
// partner: an earlier wedge with the same apex and opposite normals (the other black square of
// an X-junction), whose value gives this one for free:
// P(X > h, Y > k) = 1 - Phi(h) - Phi(k) + P(X < h, Y < k).
struct ImageWedge {
  Eigen::Vector2d apex, n1, n2;
  BivariateNormal bvn;
  int family1 = 0, family2 = 1;  // board axis of each edge (0: x, 1: y), for its bend
  int partner = -1;
  bool has_partner = false;  // another wedge reuses this one's marginals
  ImageWedge(const Eigen::Vector2d& a, const Eigen::Vector2d& m1, const Eigen::Vector2d& m2)
      : apex(a), n1(m1), n2(m2), bvn(m1.dot(m2)) {}
};

struct Pixel {
  Eigen::Vector2d q;
  double grey;
  // Displacement of the board-x and board-y line families at q by the lens' bend (LineBending),
  // evaluated at the start (the fit moves by a fraction of a pixel; the bend is a few
  // thousandths of one).
  std::array<Eigen::Vector2d, 2> bend;
};

// Black coverage C (sum of the blurred wedges) at every pixel for one shift and blur, with
// its derivatives by the shift and by sigma. The levels enter only afterwards (assemble), so
// they are solved for without recomputing it.
struct Coverage {
  std::vector<double> c, d_sigma;
  std::vector<Eigen::Vector2d> d_shift;
  void compute(const std::vector<Pixel>& pixels, const std::vector<ImageWedge>& wedges,
               const Eigen::Vector2d& shift, double sigma) {
    const size_t n = pixels.size();
    c.assign(n, 0.0);
    d_sigma.assign(n, 0.0);
    d_shift.assign(n, Eigen::Vector2d::Zero());
    const double inv_s = 1.0 / sigma;
    std::array<WedgeValue, kMaxWedges> value;
    for (size_t i = 0; i < n; ++i) {
      double cov = 0, dcov_dsigma = 0;
      Eigen::Vector2d dcov_dshift = Eigen::Vector2d::Zero();
      for (size_t j = 0; j < wedges.size(); ++j) {
        const ImageWedge& w = wedges[j];
        const Pixel& px = pixels[i];
        const Eigen::Vector2d d = px.q - w.apex - shift;
        const double h = w.n1.dot(d - px.bend[w.family1]) * inv_s;
        const double k = w.n2.dot(d - px.bend[w.family2]) * inv_s;
        WedgeValue& v = value[j];
        if (w.partner >= 0) {
          const WedgeValue& b = value[static_cast<size_t>(w.partner)];
          v.v = 1 - b.cdf_h - b.cdf_k + b.v;
          v.dh = b.pdf_h - b.dh;  // d/dh of this wedge's own (h, k) = (-h_b, -k_b)
          v.dk = b.pdf_k - b.dk;
        } else {
          w.bvn.eval(h, k, w.has_partner, v);
        }
        if (v.v == 0 && v.dh == 0 && v.dk == 0) continue;
        cov += v.v;
        dcov_dshift -= inv_s * (v.dh * w.n1 + v.dk * w.n2);  // h, k fall as the shift grows
        dcov_dsigma -= inv_s * (v.dh * h + v.dk * k);
      }
      c[i] = cov;
      d_shift[i] = dcov_dshift;
      d_sigma[i] = dcov_dsigma;
    }
  }
};

// The model's state: shift, levels, blur.
struct Params {
  Eigen::Vector2d shift = Eigen::Vector2d::Zero();
  double black = 0, white = 1, sigma = 1.2;
};

// grey = 255 sRGB(linear) and its slope, with one pow.
double encode(double linear, bool srgb, double& slope) {
  if (!srgb) {
    slope = 1.0;
    return linear;
  }
  if (!(linear > 0.0031308)) {
    slope = 255.0 * 12.92;
    return 255.0 * 12.92 * std::max(linear, 0.0);
  }
  const double root = std::pow(linear, 1.0 / 2.4);
  slope = 255.0 * 1.055 / 2.4 * root / linear;
  return 255.0 * (1.055 * root - 0.055);
}

// Sum of squared residuals and the normal equations of (shift, black, white, sigma).
double assemble(const std::vector<Pixel>& pixels, const Coverage& cov, const Params& p, bool srgb,
                Eigen::Matrix<double, 5, 5>& JtJ, Eigen::Matrix<double, 5, 1>& Jtr) {
  double ssr = 0;
  JtJ.setZero();
  Jtr.setZero();
  const double contrast = p.white - p.black;
  for (size_t i = 0; i < pixels.size(); ++i) {
    const double c = cov.c[i];
    const double linear = p.white - contrast * c;
    double e;
    const double r = pixels[i].grey - encode(linear, srgb, e);
    ssr += r * r;
    Eigen::Matrix<double, 5, 1> j;
    j << -e * contrast * cov.d_shift[i].x(), -e * contrast * cov.d_shift[i].y(), e * c,
        e * (1 - c), -e * contrast * cov.d_sigma[i];
    JtJ.selfadjointView<Eigen::Lower>().rankUpdate(j);
    Jtr += j * r;
  }
  JtJ = JtJ.selfadjointView<Eigen::Lower>();
  return ssr;
}

}  // namespace

double bivariateNormalCdf(double h, double k, double r) {
  const BivariateNormal b(r);
  return b.valid() ? b.cdf(h, k) : std::numeric_limits<double>::quiet_NaN();
}

double LocalPattern::clearanceM(const Eigen::Vector2d& b) const {
  double c = std::min(exact_half_m - std::abs(b.x()), exact_half_m - std::abs(b.y()));
  for (const Eigen::AlignedBox2d& box : unknown)
    c = std::min(c, std::sqrt(box.squaredExteriorDistance(b)));
  return std::max(c, 0.0);
}

PatternFit fitLocalPattern(const cv::Mat& grey, const Eigen::Matrix3d& H_px_board,
                           const LocalPattern& pattern, const PatternFitOptions& options,
                           const LineBending& bending) {
  PatternFit out;
  const Eigen::Vector2d start = applyH(H_px_board, Eigen::Vector2d::Zero());
  const Eigen::Matrix3d H_board_px = H_px_board.inverse();
  if (!start.allFinite() || !H_board_px.allFinite()) {
    out.why = "degenerate homography";
    return out;
  }
  // The pattern's wedges in the image: apex and the images of the edge directions (a homography
  // maps the board's edge lines to lines, so this is exact).
  if (pattern.black.empty() || pattern.black.size() > static_cast<size_t>(kMaxWedges)) {
    out.why = "no pattern or too many wedges";
    return out;
  }
  std::vector<ImageWedge> wedges;
  for (const PatternWedge& w : pattern.black) {
    const Eigen::Matrix2d J = jacobianH(H_px_board, w.apex);
    const Eigen::Vector2d u1 = (J * w.e1).normalized(), u2 = (J * w.e2).normalized();
    Eigen::Vector2d n1(-u1.y(), u1.x()), n2(-u2.y(), u2.x());
    if (n1.dot(u2) < 0) n1 = -n1;
    if (n2.dot(u1) < 0) n2 = -n2;
    wedges.emplace_back(applyH(H_px_board, w.apex), n1, n2);
    wedges.back().family1 = std::abs(w.e1.x()) >= std::abs(w.e1.y()) ? 0 : 1;
    wedges.back().family2 = std::abs(w.e2.x()) >= std::abs(w.e2.y()) ? 0 : 1;
    if (!wedges.back().bvn.valid()) {
      out.why = "pattern edges too close to parallel in the image";
      return out;
    }
    for (size_t j = 0; j + 1 < wedges.size(); ++j) {
      const ImageWedge& o = wedges[j];
      if (o.partner < 0 && (o.apex - wedges.back().apex).norm() < 1e-9 &&
          (o.n1 + n1).norm() < 1e-9 && (o.n2 + n2).norm() < 1e-9) {
        wedges.back().partner = static_cast<int>(j);
        wedges[j].has_partner = true;
        break;
      }
    }
  }
  // Smallest magnification (px per metre) near the point: clearances in metres become at least
  // this many pixels.
  const Eigen::JacobiSVD<Eigen::Matrix2d> svd(jacobianH(H_px_board, Eigen::Vector2d::Zero()));
  const double px_per_m = svd.singularValues()(1);
  const float* lut = srgb8ToLinear().data();
  // Line bends: for each family, the image direction u of its lines at the point, the normal m,
  // and the curvature kappa (px^-1): with t the board offset along the line,
  // m.(q(t) - q(0)) = lambda t + K t^2 through the two neighbours, kappa = K / (px per m)^2.
  std::array<Eigen::Vector2d, 2> family_u, family_m;
  std::array<double, 2> kappa{0.0, 0.0};
  {
    const Eigen::Matrix2d J0 = jacobianH(H_px_board, Eigen::Vector2d::Zero());
    const LineBending::Line* lines[2] = {&bending.along_x, &bending.along_y};
    for (int f = 0; f < 2; ++f) {
      const Eigen::Vector2d along = J0.col(f);
      family_u[f] = along.normalized();
      family_m[f] = Eigen::Vector2d(-family_u[f].y(), family_u[f].x());
      const LineBending::Line& line = *lines[f];
      const double a = -line.before_m, b = line.after_m;
      if (!line.valid || !(a > 0 && b > 0)) continue;
      const double d1 = family_m[f].dot(line.before_px - line.at_px);
      const double d2 = family_m[f].dot(line.after_px - line.at_px);
      const double K = (d1 * b + d2 * a) / (a * b * (a + b));
      if (std::isfinite(K)) kappa[f] = K / along.squaredNorm();
    }
  }

  Params p;
  p.sigma = options.start_sigma_px;
  double last_cost = 0;  // at p, over `pixels`
  Eigen::Matrix<double, 5, 5> last_JtJ;
  std::vector<Pixel> pixels;
  Coverage cov, next_cov;
  for (int pass = 0; pass < 2; ++pass) {
    // Pixels: within the radius, and clear of everything the pattern does not model.
    const double sigma_used = p.sigma;
    pixels.clear();
    pixels.reserve(static_cast<size_t>(4 * options.max_radius_px * options.max_radius_px + 8));
    const Eigen::Vector2d centre = start + p.shift;
    const double R = options.max_radius_px;
    const double need = options.clearance_sigmas * p.sigma + 0.5;
    const int u0 = std::max(0, static_cast<int>(std::ceil(centre.x() - R)));
    const int u1 = std::min(grey.cols - 1, static_cast<int>(std::floor(centre.x() + R)));
    const int v0 = std::max(0, static_cast<int>(std::ceil(centre.y() - R)));
    const int v1 = std::min(grey.rows - 1, static_cast<int>(std::floor(centre.y() + R)));
    for (int v = v0; v <= v1; ++v) {
      const std::uint8_t* row = grey.ptr<std::uint8_t>(v);
      for (int u = u0; u <= u1; ++u) {
        const Eigen::Vector2d q(u, v);
        if ((q - centre).squaredNorm() > R * R) continue;
        const Eigen::Vector2d b = applyH(H_board_px, q - p.shift);
        if (pattern.clearanceM(b) * px_per_m < need) continue;
        Pixel px{q, static_cast<double>(row[u]), {}};
        for (int f = 0; f < 2; ++f) {
          const double t = family_u[f].dot(q - start);
          px.bend[f] = kappa[f] * t * t * family_m[f];
        }
        pixels.push_back(px);
      }
    }
    out.pixels = static_cast<int>(pixels.size());
    if (out.pixels < options.min_pixels) {
      out.why = "too few clear pixels (" + std::to_string(out.pixels) + ")";
      return out;
    }
    cov.compute(pixels, wedges, p.shift, p.sigma);
    if (pass == 0) {
      // Levels: linear least squares on the decoded pixels at the start geometry.
      Eigen::Matrix2d A = Eigen::Matrix2d::Zero();
      Eigen::Vector2d y = Eigen::Vector2d::Zero();
      for (size_t i = 0; i < pixels.size(); ++i) {
        const double obs = options.srgb ? lut[static_cast<int>(pixels[i].grey)] : pixels[i].grey;
        const Eigen::Vector2d a(cov.c[i], 1 - cov.c[i]);  // black, white
        A += a * a.transpose();
        y += a * obs;
      }
      const Eigen::Vector2d levels = A.ldlt().solve(y);
      p.black = levels(0);
      p.white = levels(1);
      if (!(p.white > p.black)) {
        out.why = "no contrast";
        return out;
      }
    }
    // Levenberg-Marquardt on (shift, black, white, sigma).
    Eigen::Matrix<double, 5, 5> JtJ, JtJ_next;
    Eigen::Matrix<double, 5, 1> Jtr, Jtr_next;
    double cost = assemble(pixels, cov, p, options.srgb, JtJ, Jtr);
    double lambda = 1e-3;
    bool converged = false;
    for (int it = 0; it < options.max_iterations && !converged; ++it) {
      ++out.iterations;
      Eigen::Matrix<double, 5, 5> A = JtJ;
      A.diagonal() *= 1 + lambda;
      const Eigen::Matrix<double, 5, 1> step = A.ldlt().solve(Jtr);
      Params next = p;
      next.shift += step.head<2>();
      next.black += step(2);
      next.white += step(3);
      next.sigma += step(4);
      if (!step.allFinite() || !(next.sigma > 0.2)) {
        lambda *= 10;
        continue;
      }
      next_cov.compute(pixels, wedges, next.shift, next.sigma);
      const double next_cost = assemble(pixels, next_cov, next, options.srgb, JtJ_next, Jtr_next);
      if (next_cost <= cost) {
        p = next;
        cost = next_cost;
        std::swap(cov, next_cov);
        JtJ = JtJ_next;
        Jtr = Jtr_next;
        lambda = std::max(1e-6, lambda / 4);
        // Gauss-Newton converges quadratically from cornerSubPix's start: after a step this
        // small what is left is below 1e-5 px.
        converged = step.head<2>().norm() < 2e-3 && std::abs(step(4)) < 1e-2;
      } else {
        lambda *= 8;
        converged = lambda > 1e6;
      }
    }
    last_cost = cost;
    last_JtJ = JtJ;
    // The blur came out much wider than the pixel set allowed for: choose again.
    if (p.sigma <= 1.2 * sigma_used) break;
  }
  out.px = start + p.shift;
  out.blur_sigma_px = p.sigma;
  out.black = p.black;
  out.white = p.white;
  const int dof = std::max(1, out.pixels - 5);
  out.rms_grey = std::sqrt(last_cost / out.pixels);
  const Eigen::Matrix<double, 5, 5> covariance = last_JtJ.inverse() * (last_cost / dof);
  out.covariance = covariance.topLeftCorner<2, 2>();
  if (!out.px.allFinite() || !covariance.allFinite() || !(out.covariance.determinant() > 0)) {
    out.why = "fit did not converge";
    return out;
  }
  if (p.shift.norm() > options.max_move_px) {
    out.why = "moved " + std::to_string(p.shift.norm()) + " px";
    return out;
  }
  if (!(p.sigma > 0.3 && p.sigma < 8) || !(p.white > p.black)) {
    out.why = "implausible blur or levels";
    return out;
  }
  out.ok = true;
  return out;
}

}  // namespace previz::calib::detail
