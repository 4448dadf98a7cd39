// Chessboard: OpenCV finds the grid of inner corners (the sector-based detector first, the
// classic quad detector as a fall-back); the ids come from the grid's geometry and the square
// colours, not from OpenCV's ordering, which may start at any corner of the grid.
#include <array>
#include <cmath>
#include <string>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "calib/detail/detect_common.h"

namespace previz::calib::detail {

namespace {

// Mean grey of a small patch (3 x 3) around px; -1 if outside the image.
double patchMean(const cv::Mat& grey, const Eigen::Vector2d& px) {
  const int u = static_cast<int>(std::lround(px.x())), v = static_cast<int>(std::lround(px.y()));
  if (u < 1 || v < 1 || u >= grey.cols - 1 || v >= grey.rows - 1) return -1;
  double sum = 0;
  for (int dv = -1; dv <= 1; ++dv)
    for (int du = -1; du <= 1; ++du) sum += grey.at<std::uint8_t>(v + dv, u + du);
  return sum / 9.0;
}

// The model fit (detect_common.h fitPatterns) of every refined corner: the local homography
// from the 3 x 3 corners around it (refined where they were), the pattern the two black squares
// at it. A corner whose fit fails keeps cornerSubPix's position.
template <typename At>
void fitChessboardCorners(const DetectInput& input, const BoardSpec& board,
                          const GridMapping& mapping, const At& at,
                          const std::vector<Eigen::Vector2i>& lattice, const std::vector<bool>& ok,
                          std::vector<cv::Point2f>& pts) {
  const int ni = board.cols - 1, nj = board.rows - 1;
  std::vector<int> index(static_cast<size_t>(ni * nj), -1);
  for (size_t k = 0; k < pts.size(); ++k)
    if (ok[k])
      index[static_cast<size_t>(lattice[k].y() * ni + lattice[k].x())] = static_cast<int>(k);
  const std::vector<cv::Point2f> refined = pts;
  auto position = [&](int i, int j) {
    const int k = index[static_cast<size_t>(j * ni + i)];
    return k >= 0 ? Eigen::Vector2d(refined[k].x, refined[k].y) : at(i, j);
  };
  std::vector<Eigen::Matrix3d> H(pts.size(), Eigen::Matrix3d::Identity());
  std::vector<LocalPattern> patterns(pts.size());
  std::vector<LineBending> bending(pts.size());
  std::vector<bool> to_fit = ok;
  for (size_t k = 0; k < pts.size(); ++k) {
    if (!ok[k]) continue;
    const int i = lattice[k].x(), j = lattice[k].y();
    const Eigen::Vector2i cr = mapping.map(i, j);
    std::vector<Eigen::Vector2d> from, to;
    // The neighbours one square away along board x and y (either side), for the line bends.
    const Eigen::Vector2d* along[2][2] = {{nullptr, nullptr}, {nullptr, nullptr}};
    std::array<Eigen::Vector2d, 9> neighbour;
    for (int dj = -1; dj <= 1; ++dj)
      for (int di = -1; di <= 1; ++di) {
        if (i + di < 0 || j + dj < 0 || i + di >= ni || j + dj >= nj) continue;
        const Eigen::Vector2i offset = mapping.map(i + di, j + dj) - cr;
        from.push_back(offset.cast<double>() * board.square_m);
        to.push_back(position(i + di, j + dj));
        Eigen::Vector2d& n = neighbour[static_cast<size_t>((dj + 1) * 3 + di + 1)];
        n = to.back();
        if (std::abs(offset.x()) + std::abs(offset.y()) == 1)
          along[offset.x() != 0 ? 0 : 1][offset.x() + offset.y() > 0 ? 1 : 0] = &n;
      }
    const double s = board.square_m;
    const Eigen::Vector2d here = position(i, j);
    bending[k].along_x = bendLine(along[0][0], -s, here, along[0][1], s);
    bending[k].along_y = bendLine(along[1][0], -s, here, along[1][1], s);
    if (!fitGridHomography(from, to, H[k])) {
      to_fit[k] = false;
      continue;
    }
    // Black squares: (row + column) even (core/board.h, studio_board.cpp).
    patterns[k] = chessboardCornerPattern(board.square_m, cr.y(), cr.x(),
                                          [](int sr, int sc) { return (sr + sc) % 2 == 0; });
  }
  fitPatterns(input, pts, H, patterns, bending, to_fit);
}

}  // namespace

void detectChessboard(const DetectInput& input, const BoardSpec& board, ViewObservations& out) {
  const DetectOptions& options = input.options();
  const int ni = board.cols - 1, nj = board.rows - 1;  // inner corners along x, along y
  const cv::Size pattern(ni, nj);
  // OpenCV's detectors in turn, cheapest first; each detection is refined below as any other.
  // On small, slanted or strongly lit boards the sector-based detector gives up where its
  // exhaustive search or a 2x upsampled image finds them (OpenCV's stereo sample shrunk to a
  // quarter and slanted: found in 3, 6 and 12 of 13 views that way; detect_test).
  const cv::Mat& grey = input.grey();
  std::vector<cv::Point2f> corners;
  auto complete = [&](bool found) { return found && static_cast<int>(corners.size()) == ni * nj; };
  bool found = complete(cv::findChessboardCornersSB(grey, pattern, corners, cv::CALIB_CB_NORMALIZE_IMAGE));
  if (!found)
    found = complete(cv::findChessboardCorners(grey, pattern, corners,
                                               cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE));
  if (!found)
    found = complete(cv::findChessboardCornersSB(
        grey, pattern, corners, cv::CALIB_CB_NORMALIZE_IMAGE | cv::CALIB_CB_EXHAUSTIVE | cv::CALIB_CB_ACCURACY));
  if (!found && grey.cols * grey.rows <= 4096 * 4096 / 4) {
    cv::Mat up;
    cv::resize(grey, up, cv::Size(), 2.0, 2.0, cv::INTER_CUBIC);
    found = complete(cv::findChessboardCornersSB(up, pattern, corners, cv::CALIB_CB_NORMALIZE_IMAGE));
    // Pixel centres: x_up = 2 x + 0.5.
    for (cv::Point2f& c : corners) c = (c - cv::Point2f(0.5f, 0.5f)) * 0.5f;
  }
  if (!found) {
    out.failure = "no chessboard of " + std::to_string(ni) + " x " + std::to_string(nj) +
                  " inner corners found (sector-based, classic, exhaustive and 2x upsampled searches)";
    return;
  }

  // OpenCV's output: nj rows of ni corners. Lattice node (i, j) = corners[j * ni + i].
  auto at = [&](int i, int j) {
    const cv::Point2f& p = corners[static_cast<size_t>(j * ni + i)];
    return Eigen::Vector2d(p.x, p.y);
  };
  std::vector<LatticeNode> nodes;
  for (int j = 0; j < nj; ++j)
    for (int i = 0; i < ni; ++i) nodes.push_back({i, j, at(i, j)});

  // Grey at the centre of every square between four corners (the board's inner squares).
  std::vector<double> square_grey(static_cast<size_t>((ni - 1) * (nj - 1)));
  for (int j = 0; j + 1 < nj; ++j)
    for (int i = 0; i + 1 < ni; ++i)
      square_grey[static_cast<size_t>(j * (ni - 1) + i)] = patchMean(
          input.grey(), 0.25 * (at(i, j) + at(i + 1, j) + at(i, j + 1) + at(i + 1, j + 1)));
  // Lower is better: mean grey of the squares the mapping says are black minus the white ones.
  auto colourScore = [&](const GridMapping& m) {
    double black = 0, white = 0;
    int n_black = 0, n_white = 0;
    for (int j = 0; j + 1 < nj; ++j)
      for (int i = 0; i + 1 < ni; ++i) {
        const double g = square_grey[static_cast<size_t>(j * (ni - 1) + i)];
        if (g < 0) continue;
        const Eigen::Vector2i a = m.map(i, j), b = m.map(i + 1, j + 1);
        // Inner corner (c, r) sits at board ((c + 1) s, (r + 1) s): the square between corners
        // c and c + 1 is square column c + 1.
        const int sc = std::min(a.x(), b.x()) + 1, sr = std::min(a.y(), b.y()) + 1;
        if ((sc + sr) % 2 == 0) {  // black in the print (core/board.h, studio_board.cpp)
          black += g;
          ++n_black;
        } else {
          white += g;
          ++n_white;
        }
      }
    if (n_black == 0 || n_white == 0) return 0.0;
    return black / n_black - white / n_white;
  };
  const GridMapping mapping = chooseGridMapping(nodes, ni, nj, ni, nj, colourScore);
  if (mapping.transform < 0) {
    out.failure = "chessboard corners found but their grid is degenerate (mirrored or collinear)";
    return;
  }

  // Per corner: the local square size and the distance to the nearest parallel grid line.
  std::vector<cv::Point2f> pts;
  std::vector<RefineWindow> windows;
  std::vector<int> ids;
  std::vector<Observation> unrefined;  // corners too small for any window: the detector's own
  std::vector<Eigen::Vector2i> lattice;  // (i, j) of each point
  for (int j = 0; j < nj; ++j)
    for (int i = 0; i < ni; ++i) {
      auto step = [&](int di, int dj) {
        Eigen::Vector2d best = Eigen::Vector2d::Constant(std::numeric_limits<double>::infinity());
        for (int sgn : {-1, 1}) {
          const int a = i + sgn * di, b = j + sgn * dj;
          if (a < 0 || b < 0 || a >= ni || b >= nj) continue;
          const Eigen::Vector2d e = at(a, b) - at(i, j);
          if (e.norm() < best.norm()) best = e;
        }
        return best;
      };
      const Eigen::Vector2d ei = step(1, 0), ej = step(0, 1);
      const double square_px = std::min(ei.norm(), ej.norm());
      if (!(square_px >= options.min_square_px)) continue;
      // Grid lines not through this corner lie |ei x ej| / max(|ei|, |ej|) away; a window
      // turned by 45 degrees against the grid reaches sqrt(2) w along a grid axis.
      const double line_px =
          std::abs(ei.x() * ej.y() - ei.y() * ej.x()) / std::max(ei.norm(), ej.norm());
      RefineWindow window;
      if (options.subpixel)
        window = refineWindow(line_px / std::sqrt(2.0), options);
      else
        window.half = options.subpixel_window_px;
      const int w = window.half;
      if (nearBorder(at(i, j), input.size(), options.border_margin_px + w)) continue;
      const Eigen::Vector2i cr = mapping.map(i, j);
      if (w == 0) {
        unrefined.push_back({cr.y() * (board.cols - 1) + cr.x(), at(i, j)});
        continue;
      }
      ids.push_back(cr.y() * (board.cols - 1) + cr.x());
      pts.emplace_back(static_cast<float>(at(i, j).x()), static_cast<float>(at(i, j).y()));
      windows.push_back(window);
      lattice.emplace_back(i, j);
    }
  std::vector<bool> ok(pts.size(), true);
  if (options.subpixel) {
    ok = refineCorners(input, pts, windows);
    if (options.model_fit) fitChessboardCorners(input, board, mapping, at, lattice, ok, pts);
  }
  for (size_t k = 0; k < pts.size(); ++k)
    if (ok[k]) out.points.push_back({ids[k], Eigen::Vector2d(pts[k].x, pts[k].y)});
  out.points.insert(out.points.end(), unrefined.begin(), unrefined.end());
  if (out.points.empty())
    out.failure = "chessboard found but every corner was too close to the border or too small";
}

}  // namespace previz::calib::detail
