// The calibration chain as one library call (calib/pipeline.h, issue 34), on the thesis Table
// 5.1 renders (the cached set the other tests use): every step's decision in the report, the
// result against the truth, unreadable images skipped and reported.
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

// Unreadable images (a corrupt file, an undecodable video frame) are skipped and reported, as a
// long job does with bad frames: the calibration from the rest is as good as without them.
TEST(CalibPipeline, UnreadableImagesAreSkippedAndReported) {
  const testing::RenderedSet& set = testing::table51Set(BoardType::kChessboard);
  const Camera truth = testing::thesisCamera();
  ImageSet images = imagesOf(set);
  const auto readable = images.read;
  images.read = [&](int i) -> cv::Mat {
    if (i == 2) return cv::Mat();  // a reader that gives nothing
    if (i == 7) {
      ErrorContext context;
      context.file = "take.mov";
      context.frame = 7;
      throw Error("frame 7 does not decode", context);
    }
    return readable(i);
  };
  PipelineOptions options;
  options.cross_validate = false;
  const PipelineResult run = calibratePipeline(images, set.board, options);
  EXPECT_EQ(run.unreadable, (std::vector<std::string>{"frame 2", "frame 7"}));
  EXPECT_EQ(run.found, 18);
  ASSERT_EQ(run.report.views.size(), 20u);
  EXPECT_NE(run.report.views[2].failure.find("unreadable"), std::string::npos) << run.report.views[2].failure;
  EXPECT_NE(run.report.views[7].failure.find("does not decode"), std::string::npos) << run.report.views[7].failure;
  int logged = 0;
  for (const std::string& line : run.log) logged += line.find("unreadable") != std::string::npos;
  EXPECT_EQ(logged, 3);  // each image, and the count in the summary line
  const IntrinsicsResult& r = run.report.result;
  EXPECT_EQ(r.views_used, 18);
  EXPECT_NEAR(r.camera.fx, truth.fx, 3 * r.sigma[0]);
  EXPECT_NEAR(r.camera.cy, truth.cy, 3 * r.sigma[3]);

  // Not one image readable: an error naming the source and the first image's reason.
  images.read = [](int) -> cv::Mat { return cv::Mat(); };
  try {
    calibratePipeline(images, set.board, {});
    FAIL() << "a set of unreadable images was accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.context().file, "table 5.1 renders");
    EXPECT_NE(std::string(e.what()).find("none of the 20 images could be read"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("frame 0"), std::string::npos) << e.what();
  }
}

TEST(CalibPipeline, BoardNowhereAndBadOptionsAreNamed) {
  const testing::RenderedSet& set = testing::table51Set(BoardType::kChessboard);
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
