// The calibration chain as one library call (calib/pipeline.h, issue 34), on the thesis Table
// 5.1 renders (the cached set the other tests use): every step's decision in the report, the
// result against the truth, and an unreadable image named.
#include "calib/pipeline.h"

#include <cmath>
#include <string>

#include <gtest/gtest.h>

#include "core/error.h"
#include "tests/calib/solve_fixtures.h"

namespace previz::calib {
namespace {

ImageSet imagesOf(const testing::RenderedSet& set, int blank = -1) {
  ImageSet images;
  images.source = "table 5.1 renders";
  images.count = static_cast<int>(set.images.size()) + (blank >= 0 ? 1 : 0);
  images.name = [](int i) { return "frame " + std::to_string(i); };
  images.read = [&set, blank](int i) -> cv::Mat {
    if (blank >= 0 && i == blank) return cv::Mat(set.images.front().size(), CV_8UC3, cv::Scalar(128, 128, 128));
    const int k = blank >= 0 && i > blank ? i - 1 : i;
    return testing::noiseCopy(set.images[static_cast<size_t>(k)], testing::kTable51Noise, synth::hashKey(5, k));
  };
  return images;
}

TEST(CalibPipeline, SelectsSolvesRefinesAndCrossValidatesWithEveryDecisionReported) {
  const testing::RenderedSet& set = testing::table51Set(BoardType::kChessboard);
  const Camera truth = testing::thesisCamera();
  PipelineOptions options;
  options.select = 12;
  options.refine = 1;
  options.threads = 2;
  options.board_source = "thesis chessboard";
  const int blank = 3;  // a grey frame among the 20 views: no board there, listed
  int last_progress = 0;
  const PipelineResult run =
      calibratePipeline(imagesOf(set, blank), set.board, options, [&](int done) { last_progress = done; });
  const CalibReport& r = run.report;
  EXPECT_EQ(last_progress, 21);
  EXPECT_EQ(run.found, 20);
  ASSERT_EQ(r.views.size(), 21u);
  EXPECT_FALSE(r.views[blank].found());
  bool listed = false;
  for (const std::string& line : run.log) listed = listed || line.find("no board in frame 3") != std::string::npos;
  EXPECT_TRUE(listed);
  // Selected, refined, cross-validated, uncertainty mapped: all in the report.
  EXPECT_EQ(r.selected.size(), 12u);
  for (int i : r.selected) EXPECT_NE(i, blank);
  EXPECT_NE(r.selection_summary.find("12 of 20"), std::string::npos) << r.selection_summary;
  EXPECT_EQ(r.frontal.size(), 2u);  // the starting solve and the one round asked for
  EXPECT_TRUE(r.uncertainty.has_value());
  EXPECT_TRUE(r.cross_validation.has_value());
  EXPECT_EQ(r.result.views_used, 12);
  // Against the truth, within 3 of its sigmas.
  EXPECT_NEAR(r.result.camera.fx, truth.fx, 3 * r.result.sigma[0]);
  EXPECT_NEAR(r.result.camera.cx, truth.cx, 3 * r.result.sigma[2]);
  EXPECT_NEAR(r.result.camera.dist.k1, truth.dist.k1, 3 * r.result.sigma[5]);
  std::printf("pipeline: %d of %zu views with the board, 12 selected, fx %+.4f (sigma %.4f), RMS %.4f px\n", run.found,
              r.views.size(), r.result.camera.fx - truth.fx, r.result.sigma[0], r.result.rms_px);
}

TEST(CalibPipeline, UnreadableImageAndBoardNowhereAreNamed) {
  const testing::RenderedSet& set = testing::table51Set(BoardType::kChessboard);
  ImageSet images = imagesOf(set);
  images.read = [](int) { return cv::Mat(); };
  try {
    calibratePipeline(images, set.board, {});
    FAIL() << "an unreadable image was accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.context().file, "frame 0");
  }
  ImageSet grey = imagesOf(set);
  grey.count = 3;
  grey.read = [&](int) { return cv::Mat(set.images.front().size(), CV_8UC3, cv::Scalar(90, 90, 90)); };
  PipelineOptions options;
  options.board_source = "board.json";
  try {
    calibratePipeline(grey, set.board, options);
    FAIL() << "no board anywhere was accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("board.json"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("none of the 3 images"), std::string::npos) << e.what();
    EXPECT_EQ(e.context().file, "table 5.1 renders");
  }
  PipelineOptions bad;
  bad.select = -1;
  try {
    calibratePipeline(grey, set.board, bad);
    FAIL() << "select -1 accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.context().field, "select");
  }
}

}  // namespace
}  // namespace previz::calib
