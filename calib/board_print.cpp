#include "calib/board_print.h"

#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <sstream>
#include <string>
#include <vector>

#include <apriltag/apriltag.h>
#include <apriltag/common/image_u8.h>
#include <apriltag/tag36h11.h>
#include <opencv2/aruco.hpp>

#include "core/error.h"
#include "core/io.h"

namespace previz::calib {

namespace {

// The sheet as shapes painted in order on white paper, metres from the sheet's top-left corner.
struct Shape {
  bool circle = false;
  bool black = true;
  double x0 = 0, y0 = 0, x1 = 0, y1 = 0;  // rectangle [x0, x1) x [y0, y1)
  double cx = 0, cy = 0, r = 0;           // circle
};

// Black runs of a bitmap row as rectangles: cells of 'cell' metres from (x0, y0).
void bitmapShapes(const std::vector<std::vector<bool>>& black, double x0, double y0, double cell,
                  std::vector<Shape>& shapes) {
  for (size_t y = 0; y < black.size(); ++y)
    for (size_t x = 0; x < black[y].size();) {
      if (!black[y][x]) {
        ++x;
        continue;
      }
      size_t end = x;
      while (end < black[y].size() && black[y][end]) ++end;
      Shape s;
      s.x0 = x0 + x * cell;
      s.x1 = x0 + end * cell;
      s.y0 = y0 + y * cell;
      s.y1 = y0 + (y + 1) * cell;
      shapes.push_back(s);
      x = end;
    }
}

std::vector<Shape> boardShapes(const BoardSpec& spec) {
  spec.validate();
  std::vector<Shape> shapes;
  const double s = spec.square_m, o = spec.margin_m;
  auto rect = [&](double x0, double y0, double x1, double y1) {
    Shape sh;
    sh.x0 = o + x0;
    sh.y0 = o + y0;
    sh.x1 = o + x1;
    sh.y1 = o + y1;
    shapes.push_back(sh);
  };
  switch (spec.type) {
    case BoardType::kChessboard:
      for (int r = 0; r < spec.rows; ++r)
        for (int c = 0; c < spec.cols; ++c)
          if ((r + c) % 2 == 0) rect(c * s, r * s, (c + 1) * s, (r + 1) * s);
      break;
    case BoardType::kCharuco: {
      const auto dictionary =
          cv::aruco::getPredefinedDictionary(openCvDictionaryId(spec.dictionary));
      const int cells = dictionary->markerSize + 2;  // one-cell black border, as OpenCV draws
      const double m = spec.marker_m, cell = m / cells;
      const bool flip = spec.legacy_pattern && spec.rows % 2 == 0;
      int k = 0;
      for (int r = 0; r < spec.rows; ++r)
        for (int c = 0; c < spec.cols; ++c) {
          if (((r + c) % 2 == 0) != flip) {
            rect(c * s, r * s, (c + 1) * s, (r + 1) * s);
            continue;
          }
          cv::Mat marker;
          cv::aruco::drawMarker(dictionary, spec.first_id + k++, cells, marker, 1);
          std::vector<std::vector<bool>> bits(static_cast<size_t>(cells),
                                              std::vector<bool>(static_cast<size_t>(cells)));
          for (int y = 0; y < cells; ++y)
            for (int x = 0; x < cells; ++x) bits[y][x] = marker.at<std::uint8_t>(y, x) < 128;
          bitmapShapes(bits, o + c * s + 0.5 * (s - m), o + r * s + 0.5 * (s - m), cell, shapes);
        }
      break;
    }
    case BoardType::kAprilGrid: {
      const double g = spec.marker_m, pitch = s + g;
      for (int r = 0; r <= spec.rows; ++r)
        for (int c = 0; c <= spec.cols; ++c)
          rect(c * pitch, r * pitch, c * pitch + g, r * pitch + g);
      apriltag_family_t* family = tag36h11_create();
      // libapriltag's bitmap has a one-cell black border; Kalibr's print has spec.tag_border_cells.
      const int extra = spec.tag_border_cells - 1;
      const int bitmap_black = family->width_at_border, black_width = bitmap_black + 2 * extra;
      const int border = (family->total_width - bitmap_black) / 2;
      const double cell = s / black_width;
      for (int r = 0; r < spec.rows; ++r)
        for (int c = 0; c < spec.cols; ++c) {
          image_u8_t* im = apriltag_to_image(family, spec.first_id + aprilGridTagIndex(spec, r, c));
          std::vector<std::vector<bool>> bits(static_cast<size_t>(black_width),
                                              std::vector<bool>(static_cast<size_t>(black_width), true));
          for (int y = 0; y < bitmap_black; ++y)
            for (int x = 0; x < bitmap_black; ++x)
              bits[y + extra][x + extra] = im->buf[(y + border) * im->stride + (x + border)] < 128;
          image_u8_destroy(im);
          bitmapShapes(bits, o + g + c * pitch, o + g + r * pitch, cell, shapes);
        }
      tag36h11_destroy(family);
      break;
    }
    case BoardType::kCircles: {
      const double R = spec.circle_radius_m;
      for (int r = 0; r < spec.rows; ++r)
        for (int c = 0; c < spec.cols; ++c)
          for (int ring = 0; ring < 3; ++ring) {
            Shape sh;
            sh.circle = true;
            sh.black = ring != 1;
            sh.cx = o + (c + 0.5) * s;
            sh.cy = o + (r + 0.5) * s;
            sh.r = R * (3 - ring) / 3.0;
            shapes.push_back(sh);
          }
      break;
    }
    case BoardType::kQuadtree: {
      const auto dictionary =
          cv::aruco::getPredefinedDictionary(openCvDictionaryId(spec.dictionary));
      const int cells = dictionary->markerSize + 2;  // one-cell black border, as OpenCV draws
      const std::vector<QuadtreeMarker> markers = quadtreeMarkers(spec);
      for (size_t i = 0; i < markers.size(); ++i) {
        cv::Mat marker;
        cv::aruco::drawMarker(dictionary, spec.first_id + static_cast<int>(i), cells, marker, 1);
        std::vector<std::vector<bool>> bits(static_cast<size_t>(cells),
                                            std::vector<bool>(static_cast<size_t>(cells)));
        for (int y = 0; y < cells; ++y)
          for (int x = 0; x < cells; ++x) bits[y][x] = marker.at<std::uint8_t>(y, x) < 128;
        bitmapShapes(bits, o + markers[i].top_left.x(), o + markers[i].top_left.y(),
                     markers[i].edge_m / cells, shapes);
      }
      break;
    }
  }
  return shapes;
}

Eigen::Vector2d sheetSize(const BoardSpec& spec) {
  return spec.size_m() + Eigen::Vector2d::Constant(2 * spec.margin_m);
}

// PNG chunk CRC (ISO 3309 / ITU-T V.42, as the PNG specification defines it).
std::uint32_t crc32(const std::uint8_t* data, size_t n) {
  static const auto table = [] {
    std::array<std::uint32_t, 256> t{};
    for (std::uint32_t i = 0; i < 256; ++i) {
      std::uint32_t c = i;
      for (int k = 0; k < 8; ++k) c = c & 1 ? 0xEDB88320u ^ (c >> 1) : c >> 1;
      t[i] = c;
    }
    return t;
  }();
  std::uint32_t c = 0xFFFFFFFFu;
  for (size_t i = 0; i < n; ++i) c = table[(c ^ data[i]) & 0xFF] ^ (c >> 8);
  return c ^ 0xFFFFFFFFu;
}

void putBigEndian(std::string& out, std::uint32_t v) {
  for (int shift = 24; shift >= 0; shift -= 8)
    out.push_back(static_cast<char>((v >> shift) & 0xFF));
}

// Inserts a pHYs chunk (pixels per metre, unit = metre) right after IHDR.
std::string withPhys(const std::string& png, double px_per_m) {
  constexpr size_t kAfterIhdr = 8 + 4 + 4 + 13 + 4;  // signature + IHDR (length, type, data, CRC)
  if (png.size() < kAfterIhdr) throw Error("board: PNG encoder returned too few bytes");
  const auto ppm = static_cast<std::uint32_t>(std::lround(px_per_m));
  std::string chunk_body = "pHYs";
  putBigEndian(chunk_body, ppm);
  putBigEndian(chunk_body, ppm);
  chunk_body.push_back(1);  // unit: metre
  std::string chunk;
  putBigEndian(chunk, 9);
  chunk += chunk_body;
  putBigEndian(chunk,
               crc32(reinterpret_cast<const std::uint8_t*>(chunk_body.data()), chunk_body.size()));
  return png.substr(0, kAfterIhdr) + chunk + png.substr(kAfterIhdr);
}

std::string mm(double metres) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.4f", metres * 1000.0);
  std::string s(buf);
  while (s.size() > 1 && s.back() == '0') s.pop_back();
  if (s.back() == '.') s.pop_back();
  return s;
}

}  // namespace

cv::Mat drawBoard(const BoardSpec& spec, double px_per_m) {
  if (!(std::isfinite(px_per_m) && px_per_m > 0)) {
    ErrorContext context;
    context.field = "px_per_m";
    throw Error("board: px_per_m must be > 0", context);
  }
  const std::vector<Shape> shapes = boardShapes(spec);
  const Eigen::Vector2d size = sheetSize(spec) * px_per_m;
  const double w = std::round(size.x()), h = std::round(size.y());
  if (w < 1 || h < 1 || w * h > double(1 << 28))
    throw Error("board: a " + std::to_string(w) + " x " + std::to_string(h) +
                " px image is out of range (lower the DPI)");
  cv::Mat img(static_cast<int>(h), static_cast<int>(w), CV_8U, cv::Scalar(255));
  // Pixel u is painted when its centre (u + 0.5) / px_per_m lies in the shape.
  auto first = [&](double x) { return static_cast<int>(std::ceil(x * px_per_m - 0.5)); };
  for (const Shape& s : shapes) {
    const std::uint8_t value = s.black ? 0 : 255;
    if (!s.circle) {
      const int u0 = std::max(0, first(s.x0)), u1 = std::min(img.cols, first(s.x1));
      const int v0 = std::max(0, first(s.y0)), v1 = std::min(img.rows, first(s.y1));
      for (int v = v0; v < v1; ++v) {
        std::uint8_t* row = img.ptr<std::uint8_t>(v);
        for (int u = u0; u < u1; ++u) row[u] = value;
      }
      continue;
    }
    const int u0 = std::max(0, first(s.cx - s.r)), u1 = std::min(img.cols, first(s.cx + s.r) + 1);
    const int v0 = std::max(0, first(s.cy - s.r)), v1 = std::min(img.rows, first(s.cy + s.r) + 1);
    for (int v = v0; v < v1; ++v) {
      std::uint8_t* row = img.ptr<std::uint8_t>(v);
      const double y = (v + 0.5) / px_per_m - s.cy;
      for (int u = u0; u < u1; ++u) {
        const double x = (u + 0.5) / px_per_m - s.cx;
        if (x * x + y * y < s.r * s.r) row[u] = value;
      }
    }
  }
  return img;
}

PrintedBoard printBoard(const BoardSpec& spec, double dpi, const std::filesystem::path& out_stem) {
  if (!(std::isfinite(dpi) && dpi >= 25 && dpi <= 2400)) {
    ErrorContext context;
    context.field = "dpi";
    throw Error("board: dpi must be in [25, 2400] (got " + std::to_string(dpi) + ")", context);
  }
  spec.validate();
  PrintedBoard out;
  out.png = out_stem;
  out.png += ".png";
  out.svg = out_stem;
  out.svg += ".svg";
  out.json = out_stem;
  out.json += ".json";
  const double px_per_m = dpi / 0.0254;
  const Eigen::Vector2d sheet = sheetSize(spec);
  out.width_mm = sheet.x() * 1000;
  out.height_mm = sheet.y() * 1000;

  const cv::Mat img = drawBoard(spec, px_per_m);
  out.png_size = img.size();
  writeFileAtomic(out.png, withPhys(encodeImage(out.png, img), px_per_m));

  std::ostringstream svg;
  svg << "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
      << "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << mm(sheet.x()) << "mm\" height=\""
      << mm(sheet.y()) << "mm\" viewBox=\"0 0 " << mm(sheet.x()) << " " << mm(sheet.y())
      << "\" shape-rendering=\"crispEdges\">\n"
      << "<!-- previz calibration board: " << toString(spec.type) << " " << spec.rows << " rows x "
      << spec.cols << " cols, square " << mm(spec.square_m) << " mm;"
      << (spec.type == BoardType::kAprilGrid
              ? std::string(" ") + toString(spec.layout) + " layout (" +
                    (spec.layout == AprilGridLayout::kKalibr ? "tag 0 at the bottom left, ids rising up"
                                                             : "tag 0 at the top left, ids going down") +
                    "), tag border " + std::to_string(spec.tag_border_cells) + " cells;"
              : std::string())
      << " user units are millimetres;"
      << " print at 100 % (no fit-to-page). Board JSON: " << out.json.filename().string()
      << " -->\n"
      << "<rect x=\"0\" y=\"0\" width=\"" << mm(sheet.x()) << "\" height=\"" << mm(sheet.y())
      << "\" fill=\"#ffffff\"/>\n";
  for (const Shape& s : boardShapes(spec)) {
    const char* fill = s.black ? "#000000" : "#ffffff";
    if (s.circle)
      svg << "<circle cx=\"" << mm(s.cx) << "\" cy=\"" << mm(s.cy) << "\" r=\"" << mm(s.r)
          << "\" fill=\"" << fill << "\"/>\n";
    else
      svg << "<rect x=\"" << mm(s.x0) << "\" y=\"" << mm(s.y0) << "\" width=\"" << mm(s.x1 - s.x0)
          << "\" height=\"" << mm(s.y1 - s.y0) << "\" fill=\"" << fill << "\"/>\n";
  }
  svg << "</svg>\n";
  writeFileAtomic(out.svg, svg.str());
  writeBoard(spec, out.json);
  if (spec.type == BoardType::kAprilGrid && spec.layout == AprilGridLayout::kKalibr) {
    // Kalibr's own target description of the same board (its aprilgrid.yaml).
    out.kalibr_yaml = out_stem;
    out.kalibr_yaml += ".yaml";
    std::ostringstream yaml;
    yaml.precision(10);
    yaml << "target_type: 'aprilgrid' #gridtype\n"
         << "tagCols: " << spec.cols << "               #number of apriltags\n"
         << "tagRows: " << spec.rows << "               #number of apriltags\n"
         << "tagSize: " << spec.square_m << "           #size of apriltag, edge to edge [m]\n"
         << "tagSpacing: " << spec.marker_m / spec.square_m << "          #ratio of space between tags to tagSize\n";
    writeFileAtomic(out.kalibr_yaml, yaml.str());
  }
  return out;
}

}  // namespace previz::calib
