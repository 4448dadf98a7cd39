// A take re-written in another form (see convert.h).
#include "take/convert.h"

#include <algorithm>
#include <memory>

#include "core/error.h"
#include "core/io.h"
#include "take/take.h"

namespace previz::take {
namespace fs = std::filesystem;

namespace {

// The take folder's other contents (take.json aside, rewritten last) copied as they are.
void copyOthers(const fs::path& from, const fs::path& to) {
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(from)) {
    const std::string name = entry.path().filename().string();
    if (name == "cams" || name == "out" || name == "take.json") continue;
    fs::copy(entry.path(), to / name, fs::copy_options::recursive | fs::copy_options::overwrite_existing, ec);
    if (ec) throw Error("cannot copy: " + ec.message(), fileContext(entry.path().string()));
  }
}

}  // namespace

ConvertSummary convertTake(const fs::path& in_dir, const fs::path& out, const ConvertOptions& options,
                           const std::function<void(long long, long long)>& progress) {
  if (out.empty()) throw Error("an output folder is required", fieldContext("out"));
  std::error_code ec;
  if (fs::exists(out / "take.json", ec)) throw Error("the output is a take already (take.json)", fileContext(out.string()));
  TakeOptions to;
  to.cameras = options.cameras;
  const Take in(in_dir, to);
  if (in.frames().empty()) throw Error("the take has no frames", fileContext(in_dir.string()));
  for (const auto& [name, frames] : options.late_frames)
    if (!in.has(name)) throw Error("no camera '" + name + "' in the take", fieldContext("late_frames"));
  StreamWriterOptions base = options.writer;
  base.fps = in.fps();
  base.validate();
  // Nothing to convert is an error before anything is written, not an empty take.
  bool any_usable = false;
  for (const std::string& name : in.cameras()) any_usable = any_usable || in.stream(name).usable();
  if (!any_usable) throw Error("no camera of the take has a usable stream", fileContext(in_dir.string()));

  // A conversion that fails part-way leaves no half-written take: a folder it made is removed.
  const bool made_out = !fs::exists(out, ec);
  struct RemoveOnFailure {
    const fs::path& dir;
    bool armed;
    ~RemoveOnFailure() {
      std::error_code ignored;
      if (armed) fs::remove_all(dir, ignored);
    }
  } cleanup{out, made_out};
  fs::create_directories(out);
  copyOthers(in_dir, out);
  ConvertSummary summary;
  long long total = 0;
  for (const std::string& name : in.cameras()) total += static_cast<long long>(in.stream(name).takeFrames().size());
  for (const std::string& name : in.cameras()) {
    const CameraStream& s = in.stream(name);
    if (!s.usable()) {
      summary.left_out.push_back(name + ": " + s.unusable);
      continue;
    }
    std::vector<int> frames = s.takeFrames();
    const auto late = options.late_frames.find(name);
    if (late != options.late_frames.end())
      frames.erase(frames.begin(), std::lower_bound(frames.begin(), frames.end(), late->second));
    if (frames.empty()) {
      summary.left_out.push_back(name + ": no frame at or after take frame " + std::to_string(late->second) +
                                 " (late_frames)");
      continue;
    }
    const StreamPlacement place = placeStream(base, frames.front());
    if (place.offset) summary.offsets[name] = *place.offset;
    std::unique_ptr<StreamWriter> w;
    int next = frames.front();
    for (int f : frames) {
      const CameraImage img = in.read(name, f);
      if (!img.ok()) {
        ErrorContext c = fileContext((in_dir / img.source).string());
        c.camera = name;
        c.frame = f;
        throw Error("cannot convert: " + img.dropped, c);
      }
      if (!w) w = std::make_unique<StreamWriter>(out, name, img.image.size(), place.writer);
      for (; next < f; ++next) w->skip();  // a hole stays a hole (a video refuses it)
      w->write(img.image);
      ++next;
      if (progress) progress(++summary.frames_written, total);
    }
    w->close();
    summary.streams[name] = w->source();
  }
  if (summary.streams.empty()) throw Error("no camera was converted", fileContext(in_dir.string()));
  // take.json last: its presence marks a complete take. Sources and offsets are the new ones.
  nlohmann::json j = in.takeJson();
  j.erase("sources");
  j.erase("offsets");
  if (!summary.offsets.empty()) j["offsets"] = summary.offsets;
  if (!base.start_timecode.empty()) j["start_timecode"] = base.start_timecode;
  j["converted_from"] = {{"take", fs::absolute(in_dir).lexically_normal().string()}, {"format", base.format}};
  if (!j.contains("fps")) j["fps"] = in.fps();
  writeJsonAtomic(out / "take.json", j);
  cleanup.armed = false;
  return summary;
}

}  // namespace previz::take
