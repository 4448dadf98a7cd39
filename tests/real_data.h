#pragma once
// What the tests know of the real public data in ../shared/data (its README.md).
#include "core/board.h"

namespace previz::test {

// opencv-chessboard/: OpenCV's stereo sample, 9 x 6 inner corners; the square size is not
// published, so 1 unit (intrinsics and RMS do not depend on it; baselines come out in squares).
inline BoardSpec opencvSampleBoard() {
  BoardSpec board;
  board.type = BoardType::kChessboard;
  board.rows = 7;  // squares: 6 x 9 inner corners
  board.cols = 10;
  board.square_m = 1.0;
  board.margin_m = 0.5;
  return board;
}

}  // namespace previz::test
