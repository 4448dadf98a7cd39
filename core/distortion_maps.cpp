#include "core/distortion_maps.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "core/error.h"
#include "core/io.h"

namespace fs = std::filesystem;

namespace previz {

namespace {

constexpr const char* kPixelOrigin = "pixel (0,0) is the centre of the top-left pixel";
constexpr const char* kStConvention =
    "R = s = (x + 0.5) / W, G = t = 1 - (y + 0.5) / H, (x, y) the source pixel read by each "
    "output pixel, W x H the source size; (s, t) = (0, 0) is the bottom-left corner of the "
    "source image (Nuke STMap)";

void checkCamera(const Camera& c, const char* role) {
  try {
    c.validate();
  } catch (const Error& e) {
    ErrorContext ctx = e.context();
    ctx.field = std::string(role) + "." + ctx.field;
    throw Error(e.message(), ctx);
  }
}

}  // namespace

Camera idealPinhole(const Camera& lens_camera, double overscan) {
  if (!(overscan >= 0.0) || !std::isfinite(overscan))
    throw Error("overscan must be a finite value >= 0 (got " + std::to_string(overscan) + ")",
                ErrorContext{"", lens_camera.name, std::nullopt, "overscan"});
  Camera c = lens_camera;
  c.dist = Distortion{};
  c.width = static_cast<int>(std::lround(lens_camera.width * (1.0 + overscan)));
  c.height = static_cast<int>(std::lround(lens_camera.height * (1.0 + overscan)));
  // The extra pixels are split evenly between both sides.
  c.cx = lens_camera.cx + 0.5 * (c.width - lens_camera.width);
  c.cy = lens_camera.cy + 0.5 * (c.height - lens_camera.height);
  return c;
}

cv::Mat makeUndistortMap(const Camera& lens, const Camera& pinhole) {
  checkCamera(lens, "lens");
  checkCamera(pinhole, "pinhole");
  if (!pinhole.dist.isZero())
    throw Error("the pinhole camera of an undistort map must have no distortion",
                ErrorContext{"", pinhole.name, std::nullopt, "pinhole.distortion"});
  cv::Mat map(pinhole.height, pinhole.width, CV_32FC2);
#pragma omp parallel for schedule(static)
  for (int v = 0; v < map.rows; ++v) {
    cv::Vec2f* row = map.ptr<cv::Vec2f>(v);
    for (int u = 0; u < map.cols; ++u) {
      const Eigen::Vector2d x = pinhole.pixelToNormalized(Eigen::Vector2d(u, v));
      // Past the fold the forward model would fetch a second, mirrored copy of the image.
      if (lens.inInvertibleDomain(x)) {
        const Eigen::Vector2d src = lens.normalizedToPixel(lens.distort(x));
        row[u] = cv::Vec2f(static_cast<float>(src.x()), static_cast<float>(src.y()));
      } else {
        row[u] = cv::Vec2f(-1.f, -1.f);
      }
    }
  }
  return map;
}

DistortMapResult makeDistortMap(const Camera& lens, const Camera& pinhole,
                                const InverseOptions& options) {
  checkCamera(lens, "lens");
  checkCamera(pinhole, "pinhole");
  options.validate();
  if (!pinhole.dist.isZero())
    throw Error("the pinhole camera of a distort map must have no distortion",
                ErrorContext{"", pinhole.name, std::nullopt, "pinhole.distortion"});
  const InverseDistortion inverse(lens.dist);
  DistortMapResult result;
  result.map.create(lens.height, lens.width, CV_32FC2);
  int not_invertible = 0;
  int max_iterations = 0;
  // Integer reductions: the same totals whatever the thread count.
#pragma omp parallel for schedule(dynamic, 8) reduction(+ : not_invertible) reduction(max : max_iterations)
  for (int v = 0; v < lens.height; ++v) {
    cv::Vec2f* row = result.map.ptr<cv::Vec2f>(v);
    for (int u = 0; u < lens.width; ++u) {
      const InverseResult r = inverse.solve(lens.pixelToNormalized(Eigen::Vector2d(u, v)), options);
      max_iterations = std::max(max_iterations, r.iterations);
      if (r.ok()) {
        const Eigen::Vector2d src = pinhole.normalizedToPixel(r.point);
        row[u] = cv::Vec2f(static_cast<float>(src.x()), static_cast<float>(src.y()));
      } else {
        row[u] = cv::Vec2f(-1.f, -1.f);
        ++not_invertible;
      }
    }
  }
  result.not_invertible = not_invertible;
  result.max_iterations = max_iterations;
  return result;
}

void writeStMap(const fs::path& path, const cv::Mat& remap_map, cv::Size source_size,
                const std::string& description) {
  if (remap_map.empty() || remap_map.type() != CV_32FC2)
    throw Error("ST map input must be a non-empty CV_32FC2 remap map", fileContext(path));
  if (source_size.width <= 0 || source_size.height <= 0)
    throw Error("source size must be > 0", fileContext(path, "source_size"));
  const double W = source_size.width, H = source_size.height;
  ExrImage exr;
  exr.image.create(remap_map.size(), CV_32FC2);
  for (int v = 0; v < remap_map.rows; ++v) {
    const cv::Vec2f* in = remap_map.ptr<cv::Vec2f>(v);
    cv::Vec2f* out = exr.image.ptr<cv::Vec2f>(v);
    for (int u = 0; u < remap_map.cols; ++u)
      out[u] = cv::Vec2f(static_cast<float>((in[u][0] + 0.5) / W),
                         static_cast<float>(1.0 - (in[u][1] + 0.5) / H));
  }
  exr.channels = {"R", "G"};
  exr.attributes["previz:st_convention"] = kStConvention;
  exr.attributes["previz:pixel_origin"] = kPixelOrigin;
  exr.attributes["previz:source_size"] =
      std::to_string(source_size.width) + "x" + std::to_string(source_size.height);
  exr.attributes["previz:description"] = description;
  writeExr(path, exr);
}

cv::Mat readStMap(const fs::path& path, cv::Size* source_size) {
  const ExrImage exr = readExr(path);
  const auto s_it = std::find(exr.channels.begin(), exr.channels.end(), "R");
  const auto t_it = std::find(exr.channels.begin(), exr.channels.end(), "G");
  if (s_it == exr.channels.end() || t_it == exr.channels.end())
    throw Error("ST map needs channels R (s) and G (t)", fileContext(path, "channels"));
  const auto size_it = exr.attributes.find("previz:source_size");
  if (size_it == exr.attributes.end())
    throw Error("ST map has no previz:source_size attribute: the source size is needed to turn "
                "(s, t) into pixels",
                fileContext(path, "previz:source_size"));
  int W = 0, H = 0;
  char x = 0;
  if (std::sscanf(size_it->second.c_str(), "%d%c%d", &W, &x, &H) != 3 || x != 'x' || W <= 0 || H <= 0)
    throw Error("expected 'WxH', got '" + size_it->second + "'", fileContext(path, "previz:source_size"));
  const int cs = static_cast<int>(s_it - exr.channels.begin());
  const int ct = static_cast<int>(t_it - exr.channels.begin());
  const int n = exr.image.channels();
  cv::Mat map(exr.image.size(), CV_32FC2);
  for (int v = 0; v < map.rows; ++v) {
    const float* in = exr.image.ptr<float>(v);
    cv::Vec2f* out = map.ptr<cv::Vec2f>(v);
    for (int u = 0; u < map.cols; ++u)
      out[u] = cv::Vec2f(static_cast<float>(in[u * n + cs] * static_cast<double>(W) - 0.5),
                         static_cast<float>((1.0 - in[u * n + ct]) * static_cast<double>(H) - 0.5));
  }
  if (source_size) *source_size = cv::Size(W, H);
  return map;
}

}  // namespace previz
