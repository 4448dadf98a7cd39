// take.json (take/take.h Take): fps, frames, sources (patterns, videos, stills, live:), offsets,
// roles, cameras; then what `previz take info` prints and a read of each camera's first frame.
// The take folder also holds cams/A/ with two 4x4 PNG frames (a.0001.png, a.0002.png), written
// once per process, so that sources, offsets and frames meet a real sequence.
// Inputs that name a path outside the take folder (an absolute source, "..", a camera name with
// '/') are skipped: the harness must not scan or open the machine's files (/dev, /proc).
#include <string>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "core/io.h"
#include "fuzz/fuzz_common.h"
#include "take/take.h"

namespace {

bool insideTake(const std::string& s) { return s.find("..") == std::string::npos && !s.empty() && s[0] != '/'; }
bool plainName(const std::string& s) { return s.find('/') == std::string::npos && s.find("..") == std::string::npos; }

// Whether every path and camera name the JSON gives stays inside the take folder.
bool staysInside(const std::string& text) {
  const nlohmann::json j = nlohmann::json::parse(text, nullptr, false);
  if (j.is_discarded() || !j.is_object()) return true;  // the reader refuses it by itself
  if (auto it = j.find("sources"); it != j.end() && it->is_object())
    for (const auto& [name, v] : it->items())
      if (!plainName(name) || (v.is_string() && !insideTake(v.get<std::string>()))) return false;
  if (auto it = j.find("cameras"); it != j.end() && it->is_array())
    for (const auto& n : *it)
      if (n.is_string() && !plainName(n.get<std::string>())) return false;
  return true;
}

const std::filesystem::path& takeDir() {
  static const std::filesystem::path dir = [] {
    const std::filesystem::path d = previz::fuzz::scratchDir() / "take";
    const cv::Mat frame(4, 4, CV_8UC3, cv::Scalar(0, 200, 0));
    previz::writeImageAtomic(d / "cams/A/a.0001.png", frame);
    previz::writeImageAtomic(d / "cams/A/a.0002.png", frame);
    return d;
  }();
  return dir;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size) {
  const std::string text = previz::fuzz::asString(data, size);
  if (!staysInside(text)) return 0;
  return previz::fuzz::guarded([&] {
    const previz::fuzz::TempPath file("take/take.json");
    (void)takeDir();
    previz::fuzz::writeBytes(file.path(), data, size);
    const previz::take::Take take(takeDir());
    take.info();
    for (const std::string& camera : take.cameras())
      if (!take.frames().empty()) take.read(camera, take.frames().front());
  });
}
