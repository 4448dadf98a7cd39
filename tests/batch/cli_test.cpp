// `previz batch` as a user meets it: bad input is refused with a message naming the culprit.
#include <gtest/gtest.h>

#include "batch_fixture.h"
#include "scratch.h"

namespace previz::batch {
namespace {
namespace fs = std::filesystem;

// Runs previz with the arguments; expects a non-zero exit and 'needle' in its output.
void expectRefused(const std::string& args, const std::string& needle) {
  std::string out;
  const int rc = test::shell(test::quoted(PREVIZ_BIN) + " " + args, &out);
  EXPECT_NE(rc, 0) << args;
  EXPECT_NE(out.find(needle), std::string::npos) << args << "\n" << out;
}

TEST(BatchCli, BadInputIsRefusedNamingTheFileFlagOrShard) {
  const test::BatchFixture& f = test::batchFixture();
  const fs::path dir = test::scratchDir("batch", "cli");
  const std::string rig = test::quoted(f.take / "truth" / "rig.json");
  expectRefused("batch plan --takes " + test::quoted(dir / "nosuchtake") + " --rig " + rig + " --out " +
                    test::quoted(dir / "j1"), "nosuchtake");
  expectRefused("batch plan --takes " + test::quoted(f.take) + " --rig " + test::quoted(dir / "nosuch.json") +
                    " --out " + test::quoted(dir / "j2"), "nosuch.json");
  expectRefused("batch plan --takes " + test::quoted(f.take) + " --rig " + rig + " --quality best --out " +
                    test::quoted(dir / "j3"), "--quality");
  expectRefused("batch plan --takes " + test::quoted(f.take) + " " + test::quoted(f.take) + " --rig " + rig +
                    " --out " + test::quoted(dir / "j4"), "share the folder name");
  expectRefused("batch status " + test::quoted(dir / "nojob"), "manifest.json");
  expectRefused("batch task " + test::quoted(f.job) + " --shard 9", "--shard");
  expectRefused("batch submit " + test::quoted(f.job) + " --local --jobs 0", "--jobs");
  expectRefused("batch submit " + test::quoted(f.job) + " --local --slurm", "one backend");
  // A finished batch has nothing to submit and says so.
  std::string out;
  EXPECT_EQ(test::shell(test::quoted(PREVIZ_BIN) + " batch resume " + test::quoted(f.job) + " --local", &out), 0) << out;
  EXPECT_NE(out.find("nothing to do"), std::string::npos) << out;
}

}  // namespace
}  // namespace previz::batch
