// core/write_fault.h: an injected full disk fails writeFileAtomic like ENOSPC does, naming the
// file, and leaves the target as it was and no temporary beside it.
#include <gtest/gtest.h>

#include <filesystem>

#include "core/error.h"
#include "core/io.h"
#include "core/write_fault.h"
#include "tests/scratch.h"

namespace previz {
namespace {

namespace fs = std::filesystem;

TEST(WriteFault, FullDiskFailsTheWriteNamingTheFileAndLeavesTheOldFileAndNoTemporary) {
  const fs::path dir = test::scratchDir("core", "write_fault");
  const fs::path target = dir / "a.json", other = dir / "b.json";
  writeFileAtomic(target, "old contents\n");
  setWriteFaultHook([&](const fs::path& p) { return p == target; });
  try {
    writeFileAtomic(target, std::string(100000, 'x'));
    ADD_FAILURE() << "the injected full disk did not fail the write";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("No space left on device"), std::string::npos) << e.what();
    EXPECT_EQ(e.context().file, target.string());
  }
  writeFileAtomic(other, "not faulted\n");  // the hook picks its files
  setWriteFaultHook({});
  EXPECT_EQ(readTextFile(target), "old contents\n");
  EXPECT_EQ(readTextFile(other), "not faulted\n");
  int files = 0;
  for (const auto& e : fs::directory_iterator(dir)) {
    ++files;
    EXPECT_EQ(e.path().filename().string().find(".tmp."), std::string::npos) << e.path();
  }
  EXPECT_EQ(files, 2);
  writeFileAtomic(target, "new\n");  // hook cleared: writes go through again
  EXPECT_EQ(readTextFile(target), "new\n");
}

}  // namespace
}  // namespace previz
