#pragma once
// What every fuzz harness (fuzz/<harness>.cpp) shares: the rule for what counts as a finding,
// and temporary files for parsers that only take a path.
//
// A parser refusing bad input with previz::Error (or another std::exception: nlohmann's, OpenCV's
// cv::Exception, std::out_of_range) is its documented behaviour, not a finding; anything else is
// (a crash, an ASan / UBSan report, std::terminate, a hang). With PREVIZ_FUZZ_STRICT=1 in the
// environment an exception that is not a previz::Error aborts too, naming its type and message:
// a way to list the parsers whose errors do not yet name the file and field (README "Fuzzing").
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <system_error>
#include <typeinfo>

#include "core/error.h"

namespace previz::fuzz {

inline bool strict() {
  static const bool on = [] {
    const char* v = std::getenv("PREVIZ_FUZZ_STRICT");
    return v && *v && std::string(v) != "0";
  }();
  return on;
}

// Runs 'parse' on one input; previz's own refusals are caught, everything else is left to the
// sanitizers and libFuzzer. Always returns 0 (libFuzzer's "keep going").
template <class F>
int guarded(F&& parse) {
  try {
    parse();
  } catch (const previz::Error&) {
  } catch (const std::exception& e) {
    if (strict()) {
      std::fprintf(stderr, "previz fuzz (strict): %s escaped the parser: %s\n", typeid(e).name(), e.what());
      std::abort();
    }
  }
  return 0;
}

// A folder unique to this process (<tmp>/previz-fuzz-<pid>), removed when the process exits
// normally. A crashing run leaves it behind for the post-mortem.
inline const std::filesystem::path& scratchDir() {
  struct Dir {
    std::filesystem::path path;
    Dir() {
      std::error_code ec;
      path = std::filesystem::temp_directory_path(ec) / ("previz-fuzz-" + std::to_string(::getpid()));
      std::filesystem::remove_all(path, ec);
      std::filesystem::create_directories(path);
    }
    ~Dir() {
      std::error_code ec;
      std::filesystem::remove_all(path, ec);
    }
  };
  static const Dir dir;
  return dir.path;
}

// A file (or a folder of files) in the scratch folder for one input, removed when it goes out
// of scope: the next input starts from nothing.
class TempPath {
 public:
  explicit TempPath(const std::string& name) : path_(scratchDir() / name) {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  ~TempPath() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  TempPath(const TempPath&) = delete;
  TempPath& operator=(const TempPath&) = delete;
  const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
};

// Writes bytes to 'path' (parent folders created).
inline void writeBytes(const std::filesystem::path& path, const std::uint8_t* data, size_t size) {
  std::filesystem::create_directories(path.parent_path());
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
}
inline void writeBytes(const std::filesystem::path& path, const std::string& bytes) {
  writeBytes(path, reinterpret_cast<const std::uint8_t*>(bytes.data()), bytes.size());
}

inline std::string asString(const std::uint8_t* data, size_t size) {
  return std::string(reinterpret_cast<const char*>(data), size);
}

// Splits an input into the files of a multi-file format at lines "=== <name>" (the corpus stays
// readable text): what comes before the first marker is 'first'.
inline void writeSplit(const std::filesystem::path& dir, const std::string& first, const std::string& text) {
  std::string name = first, body;
  size_t pos = 0;
  auto flush = [&] {
    // Only plain names: a marker cannot reach outside the folder.
    if (!name.empty() && name.find('/') == std::string::npos && name != "." && name != "..")
      writeBytes(dir / name, body);
    body.clear();
  };
  while (pos <= text.size()) {
    size_t end = text.find('\n', pos);
    if (end == std::string::npos) end = text.size();
    const std::string line = text.substr(pos, end - pos);
    if (line.rfind("=== ", 0) == 0) {
      flush();
      name = line.substr(4);
    } else {
      body += line;
      if (end < text.size()) body += '\n';
    }
    pos = end + 1;
  }
  flush();
}

}  // namespace previz::fuzz
