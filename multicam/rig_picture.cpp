// The stage picture: top and side views with frusta, floor board and coverage, as PNG (OpenCV
// drawing) and SVG from one list of drawing calls.
#include "multicam/rig_picture.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/error.h"
#include "core/io.h"
#include "core/names.h"

namespace previz::multicam {
namespace {

namespace fs = std::filesystem;

// Draws each primitive on a BGR image and appends it to an SVG document at the same pixel
// coordinates, so the two files always show the same picture.
class Canvas {
 public:
  Canvas(int width, int height) : image_(height, width, CV_8UC3, cv::Scalar(255, 255, 255)) {
    svg_ << "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << width << "\" height=\"" << height
         << "\" viewBox=\"0 0 " << width << " " << height << "\">\n"
         << "<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n";
  }
  void rect(cv::Point2d a, cv::Point2d b, cv::Scalar fill) {
    cv::rectangle(image_, pt(a), pt(b) - cv::Point(1, 1), fill, cv::FILLED);
    svg_ << "<rect x=\"" << std::min(a.x, b.x) << "\" y=\"" << std::min(a.y, b.y) << "\" width=\""
         << std::abs(b.x - a.x) << "\" height=\"" << std::abs(b.y - a.y) << "\" fill=\"" << hex(fill)
         << "\"/>\n";
  }
  void line(cv::Point2d a, cv::Point2d b, cv::Scalar colour, int thickness = 1, bool dashed = false) {
    if (dashed) {
      const double len = cv::norm(b - a);
      const int dashes = std::max(1, static_cast<int>(len / 8));
      for (int i = 0; i < dashes; i += 2) {
        cv::line(image_, pt(a + (b - a) * (static_cast<double>(i) / dashes)),
                 pt(a + (b - a) * (static_cast<double>(i + 1) / dashes)), colour, thickness, cv::LINE_AA);
      }
    } else {
      cv::line(image_, pt(a), pt(b), colour, thickness, cv::LINE_AA);
    }
    svg_ << "<line x1=\"" << a.x << "\" y1=\"" << a.y << "\" x2=\"" << b.x << "\" y2=\"" << b.y
         << "\" stroke=\"" << hex(colour) << "\" stroke-width=\"" << thickness << "\""
         << (dashed ? " stroke-dasharray=\"8,8\"" : "") << "/>\n";
  }
  void polygon(const std::vector<cv::Point2d>& points, cv::Scalar colour, int thickness = 1) {
    for (size_t i = 0; i < points.size(); ++i) {
      cv::line(image_, pt(points[i]), pt(points[(i + 1) % points.size()]), colour, thickness, cv::LINE_AA);
    }
    svg_ << "<polygon points=\"";
    for (const cv::Point2d& p : points) svg_ << p.x << "," << p.y << " ";
    svg_ << "\" fill=\"none\" stroke=\"" << hex(colour) << "\" stroke-width=\"" << thickness << "\"/>\n";
  }
  void dot(cv::Point2d c, double radius, cv::Scalar colour) {
    cv::circle(image_, pt(c), static_cast<int>(std::lround(radius)), colour, cv::FILLED, cv::LINE_AA);
    svg_ << "<circle cx=\"" << c.x << "\" cy=\"" << c.y << "\" r=\"" << radius << "\" fill=\"" << hex(colour)
         << "\"/>\n";
  }
  // Text with its baseline's left end at p; size ~ cap height in px.
  void text(cv::Point2d p, const std::string& s, double size, cv::Scalar colour = cv::Scalar(0, 0, 0)) {
    const double scale = size / 22.0;  // Hershey simplex: cap height ~22 px at scale 1
    cv::putText(image_, s, pt(p), cv::FONT_HERSHEY_SIMPLEX, scale, colour, std::max(1, static_cast<int>(size / 10)),
                cv::LINE_AA);
    svg_ << "<text x=\"" << p.x << "\" y=\"" << p.y << "\" font-family=\"sans-serif\" font-size=\""
         << size * 1.35 << "\" fill=\"" << hex(colour) << "\">" << escape(s) << "</text>\n";
  }
  // Width in px of text() drawn at this size.
  static double textWidth(const std::string& s, double size) {
    int baseline = 0;
    return cv::getTextSize(s, cv::FONT_HERSHEY_SIMPLEX, size / 22.0, std::max(1, static_cast<int>(size / 10)),
                           &baseline).width;
  }
  const cv::Mat& image() const { return image_; }
  std::string svg() const { return svg_.str() + "</svg>\n"; }

 private:
  static cv::Point pt(cv::Point2d p) { return cv::Point(static_cast<int>(std::lround(p.x)), static_cast<int>(std::lround(p.y))); }
  static std::string hex(cv::Scalar bgr) {
    char buf[16];
    std::snprintf(buf, sizeof(buf), "#%02x%02x%02x", static_cast<int>(bgr[2]) & 255,
                  static_cast<int>(bgr[1]) & 255, static_cast<int>(bgr[0]) & 255);
    return buf;
  }
  static std::string escape(const std::string& s) {
    std::string out;
    for (char c : s) {
      if (c == '<') out += "&lt;";
      else if (c == '>') out += "&gt;";
      else if (c == '&') out += "&amp;";
      else out += c;
    }
    return out;
  }
  cv::Mat image_;
  std::ostringstream svg_;
};

// Colour of a coverage count: 0 light grey, then viridis from 1 to max.
cv::Scalar coverageColour(int count, int max_count) {
  if (count <= 0) return cv::Scalar(235, 235, 235);
  static const cv::Mat lut = [] {
    cv::Mat ramp(1, 256, CV_8UC1);
    for (int i = 0; i < 256; ++i) ramp.at<uchar>(0, i) = static_cast<uchar>(i);
    cv::Mat colours;
    cv::applyColorMap(ramp, colours, cv::COLORMAP_VIRIDIS);
    return colours;
  }();
  const int i = max_count <= 1 ? 255 : static_cast<int>(std::lround(255.0 * (count - 1) / (max_count - 1)));
  const cv::Vec3b c = lut.at<cv::Vec3b>(0, std::clamp(i, 0, 255));
  return cv::Scalar(c[0], c[1], c[2]);
}

// The far rectangle of a camera's frustum at depth 'depth_m' (camera z), world frame: rays
// through the image corners (pinhole through K when a corner cannot be unprojected).
std::vector<Eigen::Vector3d> frustumCorners(const RigCamera& rc, double depth_m) {
  const Camera& cam = rc.camera;
  const std::vector<Eigen::Vector2d> px = {{-0.5, -0.5},
                                           {cam.width - 0.5, -0.5},
                                           {cam.width - 0.5, cam.height - 0.5},
                                           {-0.5, cam.height - 0.5}};
  std::vector<Eigen::Vector3d> out;
  for (const Eigen::Vector2d& p : px) {
    Eigen::Vector3d ray;
    if (const std::optional<Eigen::Vector3d> r = cam.unproject(p)) {
      ray = *r / r->z();
    } else {
      const Eigen::Vector2d n = cam.pixelToNormalized(p);
      ray = Eigen::Vector3d(n.x(), n.y(), 1.0);
    }
    out.push_back(rc.T_world_cam * (depth_m * ray));
  }
  return out;
}

std::string metres(double m) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), m == std::floor(m) ? "%.0f m" : "%.1f m", m);
  return buf;
}

}  // namespace

void RigPictureOptions::validate() const {
  auto bad = [](const std::string& field, const std::string& what) {
    ErrorContext context;
    context.field = field;
    throw Error("rig picture: " + field + " " + what, context);
  };
  if (!(cell_m > 0)) bad("cell_m", "must be > 0");
  if (!(half_extent_m >= 0)) bad("half_extent_m", "must be >= 0 (0 = fit the cameras)");
  if (half_extent_m > 0 && half_extent_m / cell_m > 4000) bad("cell_m", "is too small for the extent (> 8000 cells a side)");
  if (!(frustum_m > 0)) bad("frustum_m", "must be > 0");
  if (width_px < 400 || width_px > 20000) bad("width_px", "must be in [400, 20000]");
  if (!std::isfinite(coverage_height_m)) bad("coverage_height_m", "must be finite");
}

cv::Mat coverageGrid(const Rig& rig, double half_extent_m, double cell_m, double height_m) {
  if (!(cell_m > 0) || !(half_extent_m > 0)) {
    ErrorContext context;
    context.field = !(cell_m > 0) ? "cell_m" : "half_extent_m";
    throw Error("coverage: cell and extent must be > 0", context);
  }
  const int n = static_cast<int>(std::ceil(2.0 * half_extent_m / cell_m - 1e-9));
  cv::Mat grid(n, n, CV_32S, cv::Scalar(0));
  std::vector<Pose> T_cam_world;
  for (const RigCamera& rc : rig.cameras) T_cam_world.push_back(rc.T_world_cam.inverse());
#pragma omp parallel for schedule(static)
  for (int r = 0; r < n; ++r) {
    for (int c = 0; c < n; ++c) {
      const Eigen::Vector3d p(-half_extent_m + (c + 0.5) * cell_m, half_extent_m - (r + 0.5) * cell_m, height_m);
      int count = 0;
      for (size_t k = 0; k < rig.cameras.size(); ++k) {
        const std::optional<Eigen::Vector2d> px = rig.cameras[k].camera.project(T_cam_world[k] * p);
        if (px && rig.cameras[k].camera.inImage(*px)) ++count;
      }
      grid.at<int>(r, c) = count;
    }
  }
  return grid;
}

RigPicture writeRigPicture(const Rig& rig, const FloorSpec* floor, const fs::path& stem,
                           const RigPictureOptions& options) {
  options.validate();
  // Drawn area: every camera and its frustum, plus a margin, in whole half metres.
  double extent = options.half_extent_m;
  double z_max = std::max(2.0, options.coverage_height_m + 0.5);
  for (const RigCamera& rc : rig.cameras) {
    std::vector<Eigen::Vector3d> points = frustumCorners(rc, options.frustum_m);
    points.push_back(rc.T_world_cam.translation());
    for (const Eigen::Vector3d& p : points) {
      if (options.half_extent_m == 0) extent = std::max({extent, std::abs(p.x()), std::abs(p.y())});
      z_max = std::max(z_max, p.z());
    }
  }
  if (options.half_extent_m == 0) extent = std::ceil((extent + 0.5) * 2.0) / 2.0;
  extent = std::max(extent, 1.0);
  z_max = std::ceil((z_max + 0.3) * 2.0) / 2.0;
  const double z_min = -0.5;

  // Layout (px): margin | top view | gap | side view | margin; title above, legend below.
  const double margin = 30, gap = 40, title_h = 50, legend_h = 90;
  const double panel_w = (options.width_px - 2 * margin - gap) / 2.0;
  const double scale = panel_w / (2.0 * extent);  // px per metre, both views
  const double top_h = 2.0 * extent * scale;
  const double side_h = (z_max - z_min) * scale;
  const int height = static_cast<int>(std::ceil(title_h + std::max(top_h, side_h) + legend_h));
  const double x0_top = margin, x0_side = margin + panel_w + gap, y0 = title_h;
  auto top = [&](const Eigen::Vector3d& p) {
    return cv::Point2d(x0_top + (p.x() + extent) * scale, y0 + (extent - p.y()) * scale);
  };
  auto side = [&](const Eigen::Vector3d& p) {
    return cv::Point2d(x0_side + (p.x() + extent) * scale, y0 + (z_max - p.z()) * scale);
  };
  Canvas canvas(options.width_px, height);

  // Coverage heat map in the top view.
  const cv::Mat grid = coverageGrid(rig, extent, options.cell_m, options.coverage_height_m);
  double min_v = 0, max_v = 0;
  cv::minMaxLoc(grid, &min_v, &max_v);
  const int max_count = static_cast<int>(max_v);
  const int n = grid.rows;
  for (int r = 0; r < n; ++r) {
    // One rectangle per run of equal counts along the row keeps the SVG small.
    for (int c = 0; c < n;) {
      int end = c + 1;
      while (end < n && grid.at<int>(r, end) == grid.at<int>(r, c)) ++end;
      // Edges from the cell indices alone, so neighbouring cells share them exactly.
      const double x = -extent + c * options.cell_m, y = extent - r * options.cell_m;
      const double x1 = std::min(extent, -extent + end * options.cell_m);
      const double y1 = std::max(-extent, extent - (r + 1) * options.cell_m);
      canvas.rect(top(Eigen::Vector3d(x, y, 0)), top(Eigen::Vector3d(x1, y1, 0)),
                  coverageColour(grid.at<int>(r, c), max_count));
      c = end;
    }
  }
  const cv::Scalar frame_grey(150, 150, 150), black(0, 0, 0);
  canvas.polygon({top({-extent, extent, 0}), top({extent, extent, 0}), top({extent, -extent, 0}),
                  top({-extent, -extent, 0})}, frame_grey);
  canvas.polygon({side({-extent, 0, z_max}), side({extent, 0, z_max}), side({extent, 0, z_min}),
                  side({-extent, 0, z_min})}, frame_grey);
  // World axes at the origin, floor and coverage slice in the side view.
  canvas.line(top({0, 0, 0}), top({0.5, 0, 0}), cv::Scalar(0, 0, 200), 2);
  canvas.line(top({0, 0, 0}), top({0, 0.5, 0}), cv::Scalar(0, 160, 0), 2);
  canvas.line(side({-extent, 0, 0}), side({extent, 0, 0}), black, 2);
  canvas.line(side({-extent, 0, options.coverage_height_m}), side({extent, 0, options.coverage_height_m}),
              cv::Scalar(200, 120, 0), 1, true);
  canvas.line(side({0, 0, 0}), side({0, 0, 0.5}), cv::Scalar(200, 0, 0), 2);

  // Floor board: the printed pattern's outline.
  if (floor != nullptr) {
    const Eigen::Vector2d size = floor->board.size_m();
    std::vector<cv::Point2d> outline_top;
    double lo = std::numeric_limits<double>::infinity(), hi = -lo;
    Eigen::Vector3d lo_p = Eigen::Vector3d::Zero(), hi_p = Eigen::Vector3d::Zero();
    for (const Eigen::Vector3d& q : {Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(size.x(), 0, 0),
                                     Eigen::Vector3d(size.x(), size.y(), 0), Eigen::Vector3d(0, size.y(), 0)}) {
      const Eigen::Vector3d p = floor->T_world_board * q;
      outline_top.push_back(top(p));
      if (p.x() < lo) lo = p.x(), lo_p = p;
      if (p.x() > hi) hi = p.x(), hi_p = p;
    }
    const cv::Scalar board_colour(0, 90, 230);
    canvas.polygon(outline_top, board_colour, 2);
    canvas.line(side(lo_p), side(hi_p), board_colour, 4);
    canvas.text(outline_top[0] + cv::Point2d(4, -6), "floor board", 13, board_colour);
  }

  // Cameras: frustum edges and far rectangle in both views, centre dot, name.
  for (const RigCamera& rc : rig.cameras) {
    const cv::Scalar colour = rc.role == kMainRole ? cv::Scalar(20, 20, 200) : cv::Scalar(60, 30, 0);
    const Eigen::Vector3d c = rc.T_world_cam.translation();
    const std::vector<Eigen::Vector3d> far = frustumCorners(rc, options.frustum_m);
    std::vector<cv::Point2d> far_top, far_side;
    for (const Eigen::Vector3d& p : far) {
      canvas.line(top(c), top(p), colour);
      canvas.line(side(c), side(p), colour);
      far_top.push_back(top(p));
      far_side.push_back(side(p));
    }
    canvas.polygon(far_top, colour);
    canvas.polygon(far_side, colour);
    canvas.dot(top(c), 4, colour);
    canvas.dot(side(c), 4, colour);
    // Name on the side away from the stage centre, so it does not sit on the frustum.
    const Eigen::Vector3d out = c + 0.25 * Eigen::Vector3d(c.x(), c.y(), 0).normalized();
    cv::Point2d label = top(out);
    if (c.x() < 0) label.x -= 8.0 * rc.camera.name.size();
    canvas.text(label, rc.camera.name, 13, colour);
    canvas.text(side(c) + cv::Point2d(6, -6), rc.camera.name, 11, colour);
  }

  // Titles.
  canvas.text({x0_top, 32}, "top view (x right, y up)", 16);
  canvas.text({x0_side, 32}, "side view (x right, z up)", 16);

  // Legend: coverage colour bar and a scale bar.
  const double ly = y0 + std::max(top_h, side_h) + 25;
  char legend[120];
  std::snprintf(legend, sizeof(legend), "cameras seeing each cell at z = %.2f m:", options.coverage_height_m);
  canvas.text({x0_top, ly + 14}, legend, 13);
  const double box = std::min(28.0, (panel_w - Canvas::textWidth(legend, 13) - 20) / (std::max(max_count, 1) + 1) - 4);
  const double bx = x0_top + Canvas::textWidth(legend, 13) + 12;
  for (int k = 0; k <= std::max(max_count, 1); ++k) {
    const cv::Point2d a(bx + k * (box + 4), ly);
    canvas.rect(a, a + cv::Point2d(box, 18), coverageColour(k, max_count));
    canvas.text(a + cv::Point2d(box / 2 - 5, 38), std::to_string(k), 12);
  }
  // Scale bar: a round length about a fifth of the panel.
  const double nice[] = {0.25, 0.5, 1, 2, 5, 10};
  double bar_m = nice[0];
  for (double v : nice) {
    if (v * scale <= panel_w / 5) bar_m = v;
  }
  const cv::Point2d s0(x0_side, ly + 10), s1(x0_side + bar_m * scale, ly + 10);
  canvas.line(s0, s1, black, 3);
  canvas.line(s0 + cv::Point2d(0, -6), s0 + cv::Point2d(0, 6), black, 2);
  canvas.line(s1 + cv::Point2d(0, -6), s1 + cv::Point2d(0, 6), black, 2);
  canvas.text(s1 + cv::Point2d(10, 6), metres(bar_m) + " (both views)", 13);

  RigPicture out;
  out.png = fs::path(stem.string() + ".png");
  out.svg = fs::path(stem.string() + ".svg");
  out.size = canvas.image().size();
  out.half_extent_m = extent;
  out.max_coverage = max_count;
  writeImageAtomic(out.png, canvas.image());
  writeFileAtomic(out.svg, canvas.svg());
  return out;
}

}  // namespace previz::multicam
