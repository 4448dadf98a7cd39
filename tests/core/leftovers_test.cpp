// core/leftovers.h: the temporaries of a killed writer go, a live writer's and real files stay.
#include <gtest/gtest.h>

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "core/leftovers.h"
#include "tests/scratch.h"

namespace previz {
namespace {

namespace fs = std::filesystem;

void touch(const fs::path& p) {
  fs::create_directories(p.parent_path());
  std::ofstream(p) << "x";
}

TEST(Leftovers, TemporariesOfGoneProcessesAreRemovedLiveOnesAndOutputsKept) {
  const fs::path dir = test::scratchDir("core", "leftovers");
  const std::string me = std::to_string(::getpid());
  const std::string gone = "999999999";  // above any pid_max (2^22)
  touch(dir / ("." + std::string("000001.png.tmp.") + gone + ".123.0"));
  touch(dir / ("." + std::string("000002.ply.pcl.") + gone + ".0.ply"));
  touch(dir / "sub" / (".carve.jsonl.tmp." + gone + ".1.2"));
  touch(dir / (".000003.png.tmp." + me + ".1.2"));  // this process: writing now
  touch(dir / "000001.png");
  touch(dir / ".hidden");
  touch(dir / ".x.tmp.notapid.1");
  EXPECT_EQ(removeLeftoverTemporaries(dir, false), 2);
  EXPECT_TRUE(fs::exists(dir / "sub" / (".carve.jsonl.tmp." + gone + ".1.2")));
  EXPECT_EQ(removeLeftoverTemporaries(dir, true), 1);
  EXPECT_TRUE(fs::exists(dir / (".000003.png.tmp." + me + ".1.2")));
  EXPECT_TRUE(fs::exists(dir / "000001.png"));
  EXPECT_TRUE(fs::exists(dir / ".hidden"));
  EXPECT_TRUE(fs::exists(dir / ".x.tmp.notapid.1"));
  EXPECT_EQ(removeLeftoverTemporaries(dir / "missing", true), 0);
}

}  // namespace
}  // namespace previz
