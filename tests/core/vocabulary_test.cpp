// The shared vocabulary of core (issue 34): units.h, threads.h, stopwatch.h, names.h, stats.h.
#include <cmath>
#include <cstdlib>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "core/names.h"
#include "core/stats.h"
#include "core/stopwatch.h"
#include "core/threads.h"
#include "core/units.h"

namespace previz {
namespace {

TEST(Units, KnownAnglesConvertExactly) {
  EXPECT_EQ(degrees(M_PI), 180.0);
  EXPECT_EQ(degrees(M_PI / 2), 90.0);
  EXPECT_EQ(radians(180.0), M_PI);
  EXPECT_EQ(radians(90.0), M_PI / 2);
  EXPECT_EQ(degrees(0.0), 0.0);
  EXPECT_EQ(radians(-45.0), -M_PI / 4);
}

TEST(Units, RoundTripWithinOneUlp) {
  for (double deg = -720.0; deg <= 720.0; deg += 0.37) {
    EXPECT_NEAR(degrees(radians(deg)), deg, std::abs(deg) * 4e-16) << deg;
  }
}

// The spelling the code had before issue 34 (x * 180 / pi, x * pi / 180), bit for bit: the
// figures previz writes must not move.
TEST(Units, RoundsAsTheFormerSpelling) {
  for (double x = -10.0; x <= 10.0; x += 0.0123) {
    EXPECT_EQ(degrees(x), x * 180 / M_PI) << x;
    EXPECT_EQ(radians(x), x * M_PI / 180.0) << x;
  }
  EXPECT_EQ(degrees(1.0), 180.0 / M_PI);
  EXPECT_EQ(radians(1.0), M_PI / 180.0);
  static_assert(degrees(0.0) == 0.0, "usable in constant expressions");
}

TEST(Threads, ZeroOrLessMeansAllAndNeverBelowOne) {
  EXPECT_GE(defaultThreadCount(), 1);
  EXPECT_GE(coreCount(), 1);
  EXPECT_EQ(resolveThreads(0), defaultThreadCount());
  EXPECT_EQ(resolveThreads(-3), defaultThreadCount());
  EXPECT_EQ(resolveThreads(1), 1);
  EXPECT_EQ(resolveThreads(7), 7);
}

// Never the wall-clock figure itself (a loaded machine makes any bound flaky): only that time
// does not run backwards and that restart() starts again from zero.
TEST(Stopwatch, NonNegativeMonotonicAndRestarts) {
  const Stopwatch outer;
  Stopwatch sw;
  const double a = sw.ms();
  const double b = sw.ms();
  EXPECT_GE(a, 0.0);
  EXPECT_GE(b, a);
  EXPECT_GE(sw.seconds(), 0.0);
  sw.restart();
  const double restarted = sw.ms();  // read before outer: restarted after outer began
  EXPECT_GE(restarted, 0.0);
  EXPECT_LE(restarted, outer.ms());
}

TEST(Names, FrameStemIsSixDigitsZeroPadded) {
  EXPECT_EQ(frameStem(0), "000000");
  EXPECT_EQ(frameStem(42), "000042");
  EXPECT_EQ(frameStem(123456), "123456");
  EXPECT_EQ(frameStem(1234567), "1234567");  // wider numbers are not cut
}

TEST(Names, MainCameraAndRole) {
  EXPECT_STREQ(kMainCamera, "main");
  EXPECT_STREQ(kMainRole, "main");
}

TEST(Stats, MedianIsTheUpperMiddleOfAnEvenCount) {
  EXPECT_EQ(median(std::vector<double>{4, 1, 3, 2}), 3.0);
  EXPECT_EQ(median(std::vector<int>{5, 1, 3}), 3.0);
  EXPECT_EQ(median(std::vector<double>{}), 0.0);
  EXPECT_EQ(quantile(std::vector<double>{1, 2, 3, 4, 5, 6, 7, 8, 9, 10}, 0.9), 10.0);
  EXPECT_EQ(quantile(std::vector<double>{1, 2, 3, 4, 5, 6, 7, 8, 9, 10}, 0.0), 1.0);
}

}  // namespace
}  // namespace previz
