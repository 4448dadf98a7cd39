#pragma once
// One small batch shared by every batch test process (CTest runs each test in its own process):
// a 4-frame studio take (4 witnesses at 320x180), planned as 2 shards at 0.02 m cells with refined depth, run by
// the local backend with 2 jobs and collected with --y-up. Built once per previz binary under
// PREVIZ_TEST_TMP/batch_fixture (an flock serialises the first build); tests that change files
// work on copies in their own scratch folder.
#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>

namespace previz::test {

// Runs a shell command line; returns its exit status; stdout+stderr into 'output' when given.
inline int shell(const std::string& command, std::string* output = nullptr) {
  std::string line = command + " 2>&1";
  FILE* p = popen(line.c_str(), "r");
  if (!p) return -1;
  std::string out;
  char buffer[4096];
  size_t n;
  while ((n = fread(buffer, 1, sizeof(buffer), p)) > 0) out.append(buffer, n);
  const int status = pclose(p);
  if (output) *output = out;
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128;
}

inline std::string quoted(const std::filesystem::path& p) { return "'" + p.string() + "'"; }

struct BatchFixture {
  std::filesystem::path root, take, job, collected;
};

inline const BatchFixture& batchFixture() {
  static BatchFixture f = [] {
    namespace fs = std::filesystem;
    BatchFixture b;
    b.root = fs::path(PREVIZ_TEST_TMP) / "batch_fixture";
    b.take = b.root / "take";
    b.job = b.root / "job";
    b.collected = b.root / "collected";
    fs::create_directories(fs::path(PREVIZ_TEST_TMP));
    const int lock = ::open((fs::path(PREVIZ_TEST_TMP) / "batch_fixture.lock").c_str(), O_CREAT | O_RDWR, 0644);
    if (lock < 0 || flock(lock, LOCK_EX) != 0) throw std::runtime_error("batch fixture: cannot lock");
    struct stat st {};
    ::stat(PREVIZ_BIN, &st);
    const std::string stamp = std::to_string(st.st_size) + " " + std::to_string(st.st_mtime);
    const fs::path marker = b.root / "complete";
    std::string have;
    if (fs::exists(marker)) std::getline(std::ifstream(marker), have);
    if (have != stamp) {
      fs::remove_all(b.root);
      fs::create_directories(b.root);
      const std::string bin = quoted(PREVIZ_BIN);
      std::string log;
      const std::string steps[] = {
          bin + " synth --preset studio --out " + quoted(b.take) +
              " --frames 4 --cams 4 --size 320x180 --no-meshes --quiet",
          bin + " batch plan --takes " + quoted(b.take) + " --rig " + quoted(b.take / "truth" / "rig.json") +
              " --quality preview --refine --shards-per-take 2 --out " + quoted(b.job),
          bin + " batch submit " + quoted(b.job) + " --local --jobs 2 --quiet",
          bin + " batch collect " + quoted(b.job) + " --y-up --out " + quoted(b.collected)};
      for (const std::string& s : steps) {
        if (shell(s, &log) != 0) {
          flock(lock, LOCK_UN);
          throw std::runtime_error("batch fixture: '" + s + "' failed:\n" + log);
        }
      }
      std::ofstream(marker) << stamp << "\n";
    }
    flock(lock, LOCK_UN);
    ::close(lock);
    return b;
  }();
  return f;
}

}  // namespace previz::test
