// Scratch folders for tests. CTest runs every test in its own process, in parallel, so a
// folder shared by name between two tests races (one removes what the other is writing).
// Each process gets its own folder under PREVIZ_TEST_TMP/<area>.<pid>/.
#pragma once

#include <unistd.h>

#include <filesystem>
#include <string>

namespace previz::test {

// A fresh, empty folder PREVIZ_TEST_TMP/<area>.<pid>/<name>.
inline std::filesystem::path scratchDir(const std::string& area, const std::string& name) {
  const std::filesystem::path dir =
      std::filesystem::path(PREVIZ_TEST_TMP) / (area + "." + std::to_string(::getpid())) / name;
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

}  // namespace previz::test
