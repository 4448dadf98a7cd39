// The collected summary page in headless Chromium (issue 9, item 5): a screenshot that is not
// blank, every <img src> and <a href> resolving to a file, no console errors. A page with a
// broken image and a console error is checked the same way first, so the checks can fail.
#include <gtest/gtest.h>

#include <regex>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "batch_fixture.h"
#include "core/io.h"
#include "scratch.h"

namespace previz::batch {
namespace {
namespace fs = std::filesystem;

struct PageCheck {
  std::vector<std::string> unresolved;  // src/href that is not a file beside the page
  std::vector<std::string> console;     // console messages Chromium logged
  int links = 0, images = 0;
  double screenshot_stddev = 0;
  double dark_fraction = 0;             // pixels darker than 64 (the contact sheets)
  std::string log;
};

PageCheck checkPage(const fs::path& page, const fs::path& work) {
  PageCheck c;
  const std::string html = readTextFile(page);
  const std::regex attr(R"re(<(img|a)\s[^>]*(src|href)="([^"]*)")re");
  for (auto it = std::sregex_iterator(html.begin(), html.end(), attr); it != std::sregex_iterator(); ++it) {
    const std::string tag = (*it)[1], target = (*it)[3];
    (tag == "img" ? c.images : c.links)++;
    if (target.find("://") != std::string::npos || !fs::is_regular_file(page.parent_path() / target))
      c.unresolved.push_back(target);
  }
  const fs::path shot = work / "shot.png";
  fs::remove(shot);
  fs::create_directories(work / "profile");
  const std::string cmd = "chromium --headless --no-sandbox --disable-gpu --disable-quic --no-first-run "
                          "--disable-background-networking --disable-component-update --disable-sync "
                          "--user-data-dir=" + test::quoted(work / "profile") + " --enable-logging=stderr --v=0 "
                          "--window-size=1200,1400 --screenshot=" + test::quoted(shot) + " " +
                          test::quoted("file://" + fs::absolute(page).string());
  test::shell("timeout 120 " + cmd, &c.log);
  std::istringstream in(c.log);
  for (std::string line; std::getline(in, line);)
    if (line.find(":CONSOLE") != std::string::npos || line.find("Uncaught") != std::string::npos)
      c.console.push_back(line);
  const cv::Mat image = fs::is_regular_file(shot) ? cv::imread(shot.string(), cv::IMREAD_GRAYSCALE) : cv::Mat();
  if (!image.empty()) {
    cv::Scalar mean, stddev;
    cv::meanStdDev(image, mean, stddev);
    c.screenshot_stddev = stddev[0];
    c.dark_fraction = cv::countNonZero(image < 64) / static_cast<double>(image.total());
  }
  return c;
}

TEST(BatchSummaryPage, OpensInHeadlessChromiumWithEveryImageAndLinkResolvingAndNoConsoleErrors) {
  const test::BatchFixture& f = test::batchFixture();
  const fs::path work = test::scratchDir("batch", "chromium");

  // Control: the checks catch a broken image and a console error.
  { std::ofstream(work / "bad.html") << "<!DOCTYPE html><html><body><h1>x</h1><img src=\"missing.png\">"
                                        "<script>console.error('previz control error')</script></body></html>\n"; }
  const PageCheck bad = checkPage(work / "bad.html", work / "bad");
  EXPECT_EQ(bad.unresolved, std::vector<std::string>{"missing.png"});
  ASSERT_FALSE(bad.console.empty()) << "Chromium's console log was not captured:\n" << bad.log;

  const PageCheck c = checkPage(f.collected / "index.html", work / "good");
  EXPECT_TRUE(c.unresolved.empty()) << c.unresolved.size() << " unresolved, e.g. " << c.unresolved[0];
  EXPECT_GE(c.images, 1);           // the take's contact sheet
  EXPECT_GE(c.links, 4 * 4 + 3);    // 4 frames x (obj, ply, pcd, exr), camera .chan + JSON, collect.json
  EXPECT_TRUE(c.console.empty()) << c.console.size() << " console messages, e.g. " << c.console[0];
  ASSERT_GT(c.screenshot_stddev, 0) << "no screenshot:\n" << c.log;
  EXPECT_GT(c.screenshot_stddev, 20.0) << "blank screenshot";
  // The contact sheet (dark background, depth thumbnails) is on screen, not just text.
  EXPECT_GT(c.dark_fraction, 0.02);
}

}  // namespace
}  // namespace previz::batch
