// The take model (see take.h).
#include "take/take.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <limits>
#include <set>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/error.h"
#include "core/io.h"
#include "core/names.h"
#include "core/srgb.h"
#include "take/detail/files.h"
#include "take/live.h"
#include "take/timecode.h"
#include "take/video.h"

namespace previz::take {
namespace fs = std::filesystem;

namespace {

// take.json "frames" at most (11.5 hours at 24 fps: a take is one shot), and how far an offset
// may move a camera: source frame numbers have at most 15 digits (take/sequence.cpp), so
// source - offset is exact.
constexpr long long kMaxTakeFrames = 1'000'000;
constexpr long long kMaxOffset = 1'000'000'000'000'000;
constexpr const char* kOffsetRule = "offsets: an integer frame count per camera, at most 10^15 either way";
bool isOffset(const nlohmann::json& v) {
  if (v.is_number_unsigned()) return v.get<unsigned long long>() <= static_cast<unsigned long long>(kMaxOffset);
  return v.is_number_integer() && v.get<long long>() >= -kMaxOffset && v.get<long long>() <= kMaxOffset;
}

using detail::findByStem;
using detail::kStillExtensions;
using detail::kVideoExtensions;
using detail::lower;
using detail::replaceAll;

bool isVideo(const fs::path& p) { return detail::hasExtension(p, kVideoExtensions); }

ErrorContext takeJsonContext(const fs::path& file, const std::string& field, const std::string& camera = {}) {
  ErrorContext c = fileContext(file.string(), field);
  c.camera = camera;
  return c;
}

// "cams/A/A001C003.1001.exr", relative to the take folder when inside it.
std::string shown(const fs::path& dir, const fs::path& p) {
  const fs::path rel = p.lexically_relative(dir);
  return rel.empty() || *rel.begin() == ".." ? p.string() : rel.string();
}

}  // namespace

std::string toString(SourceKind kind) {
  switch (kind) {
    case SourceKind::kSequence: return "sequence";
    case SourceKind::kVideo: return "video";
    case SourceKind::kStill: return "still";
    case SourceKind::kLive: return "live";
    case SourceKind::kNone: break;
  }
  return "none";
}

std::vector<int> CameraStream::takeFrames() const {
  std::vector<int> out;
  if (!usable()) return out;
  for (long long s : source_frames) {
    const long long t = s - offset;
    if (t >= 0 && t <= std::numeric_limits<int>::max()) out.push_back(static_cast<int>(t));
  }
  return out;
}

int FrameSet::usable() const {
  return static_cast<int>(std::count_if(cameras.begin(), cameras.end(), [](const CameraImage& c) { return c.ok(); }));
}

// ---------------------------------------------------------------------------------------------
// Pixels

cv::Mat toBgr8(const cv::Mat& image, bool float_is_linear) {
  cv::Mat bgr;
  const int cn = image.channels();
  if (cn == 1) {
    cv::cvtColor(image, bgr, cv::COLOR_GRAY2BGR);
  } else if (cn == 4) {
    cv::cvtColor(image, bgr, cv::COLOR_BGRA2BGR);
  } else if (cn == 3) {
    bgr = image;
  } else {
    throw Error("an image of " + std::to_string(cn) + " channels (expected 1, 3 or 4)");
  }
  switch (bgr.depth()) {
    case CV_8U:
      return bgr;
    case CV_16U: {
      cv::Mat out;
      bgr.convertTo(out, CV_8U, 1.0 / 257.0);  // 65535 -> 255, rounded
      return out;
    }
    case CV_32F:
    case CV_64F: {
      cv::Mat f;
      if (bgr.depth() == CV_32F && bgr.isContinuous()) f = bgr;
      else bgr.convertTo(f, CV_32F);
      cv::Mat out(f.size(), CV_8UC3);
      if (!float_is_linear) {
        f.convertTo(out, CV_8U, 255.0);  // display-referred [0, 1]: rounded, saturated
        return out;
      }
      for (int y = 0; y < f.rows; ++y) linearToSrgb8(f.ptr<float>(y), out.ptr<std::uint8_t>(y), 3 * static_cast<size_t>(f.cols));
      return out;
    }
    default:
      throw Error("an image of a pixel depth previz does not read (8/16-bit integer or float)");
  }
}

cv::Mat readImage8(const fs::path& path, std::string* format, int* bit_depth, std::string* timecode) {
  const std::string ext = lower(path.extension().string());
  if (format) *format = ext.empty() ? "" : ext.substr(1);
  if (ext == ".exr") {
    // Linear light by definition of the format; OpenCV's EXR reader is off by default in 4.6.
    ExrImage exr = readExr(path);
    const auto index = [&](const char* name) {
      const auto it = std::find(exr.channels.begin(), exr.channels.end(), name);
      return it == exr.channels.end() ? -1 : static_cast<int>(it - exr.channels.begin());
    };
    const int r = index("R"), g = index("G"), b = index("B"), y = index("Y");
    cv::Mat bgr;
    if (r >= 0 && g >= 0 && b >= 0) {
      bgr.create(exr.image.size(), CV_32FC3);
      const int from_to[] = {b, 0, g, 1, r, 2};
      cv::mixChannels(&exr.image, 1, &bgr, 1, from_to, 3);
    } else if (y >= 0 || exr.channels.size() == 1) {
      cv::extractChannel(exr.image, bgr, std::max(y, 0));
    } else {
      throw Error("EXR has no R, G, B or Y channels", fileContext(path.string()));
    }
    if (bit_depth) *bit_depth = 32;
    if (timecode) *timecode = exr.timecode;
    return toBgr8(bgr, true);
  }
  const cv::Mat image = previz::readImage(path, cv::IMREAD_ANYDEPTH | cv::IMREAD_ANYCOLOR);
  if (bit_depth) *bit_depth = image.depth() == CV_8U ? 8 : image.depth() == CV_16U ? 16 : 32;
  if (timecode) timecode->clear();
  try {
    return toBgr8(image, true);
  } catch (const Error& e) {
    throw Error(e.message(), fileContext(path.string()));
  }
}

Take::~Take() = default;
Take::Take(Take&&) noexcept = default;
Take& Take::operator=(Take&&) noexcept = default;

// ---------------------------------------------------------------------------------------------
// Finding the streams

Take::Take(const fs::path& dir, const TakeOptions& options) : dir_(dir), options_(options) {
  std::error_code ec;
  if (dir_.empty() || !fs::is_directory(dir_, ec)) throw Error("take folder not found", fileContext(dir_.string(), "--take"));
  const fs::path tj = dir_ / "take.json";
  if (fs::is_regular_file(tj, ec)) {
    take_json_ = readJsonFile(tj);
    if (!take_json_.is_object()) throw Error("take.json must hold a JSON object", fileContext(tj.string()));
  }
  const nlohmann::json& j = take_json_;
  if (j.contains("fps")) {
    if (!j["fps"].is_number() || !(j["fps"].get<double>() > 0))
      throw Error("fps must be a number > 0", takeJsonContext(tj, "fps"));
    fps_ = j["fps"].get<double>();
    fps_from_ = "take.json";
  } else {
    fps_ = options_.default_fps;
  }
  // Bounds keep the take's frame list finite and its arithmetic exact: "frames": 2000000000 listed
  // two billion frames (minutes, gigabytes), a huge offset overflowed source - offset
  // (fuzz/take_json.cpp).
  if (j.contains("frames") && (!j["frames"].is_number_integer() || j["frames"].get<long long>() < 0 ||
                               j["frames"].get<long long>() > kMaxTakeFrames))
    throw Error("frames must be an integer from 0 to " + std::to_string(kMaxTakeFrames), takeJsonContext(tj, "frames"));
  for (const char* key : {"sources", "offsets", "roles"})
    if (j.contains(key) && !j[key].is_object())
      throw Error(std::string(key) + " must be an object {camera: ...}", takeJsonContext(tj, key));

  // The cameras: the caller's, else every camera take.json names or cams/ holds.
  names_ = options_.cameras;
  if (names_.empty()) {
    std::set<std::string> found;
    if (j.contains("sources"))
      for (const auto& [name, v] : j["sources"].items())
        if (name != "*") found.insert(name);
    if (found.empty() && j.contains("cameras") && j["cameras"].is_array())
      for (const auto& n : j["cameras"])
        if (n.is_string()) found.insert(n.get<std::string>());
    for (const auto& entry : fs::directory_iterator(dir_ / "cams", ec)) {
      const fs::path& p = entry.path();
      if (entry.is_directory(ec)) found.insert(p.filename().string());
      else if (isVideo(p) || isImageExtension(p)) found.insert(p.stem().string());
    }
    names_.assign(found.begin(), found.end());
  }

  for (const std::string& name : names_) {
    CameraStream& s = streams_[name];
    s.camera = name;
    findStream(s);
  }

  // The main camera.
  if (j.contains("roles")) {
    for (const auto& [role, cam] : j["roles"].items()) {
      if (!cam.is_string()) throw Error("roles: each role names a camera", takeJsonContext(tj, "roles"));
      if (role == kMainRole) main_ = cam.get<std::string>();
    }
  }
  if (main_.empty() && streams_.count(kMainCamera)) main_ = kMainCamera;

  // The take's rate: take.json's, else the main camera's video, else the first video's.
  if (fps_from_ != "take.json") {
    const CameraStream* video = nullptr;
    for (const std::string& name : names_) {
      const CameraStream& s = streams_.at(name);
      if (s.kind == SourceKind::kVideo && s.fps > 0 && (!video || name == main_)) video = &s;
    }
    if (video) {
      fps_ = video->fps;
      fps_from_ = "video " + video->camera;
    }
  }
  for (auto& [name, s] : streams_) {
    if (s.kind == SourceKind::kVideo && s.fps > 0 && std::abs(s.fps - fps_) > 1e-3 * fps_) {
      char text[160];
      std::snprintf(text, sizeof(text), "the video runs at %.3f fps, the take at %.3f fps (%s)", s.fps, fps_,
                    fps_from_.c_str());
      s.unusable = text;
    }
  }

  // Offsets: given, take.json, timecode, none.
  const nlohmann::json offsets = j.value("offsets", nlohmann::json::object());
  for (const auto& [name, v] : offsets.items())
    if (!isOffset(v)) throw Error(kOffsetRule, takeJsonContext(tj, "offsets", name));
  std::optional<long long> t0;
  bool all_timecoded = true;
  std::map<std::string, long long> start_tc;
  for (auto& [name, s] : streams_) {
    if (!s.usable() || s.source_frames.empty()) continue;
    if (s.start_timecode.empty()) {
      all_timecoded = false;
      continue;
    }
    const std::optional<Timecode> tc = parseTimecode(s.start_timecode);
    long long frames = 0;
    try {
      if (!tc) throw Error("not HH:MM:SS:FF");
      frames = timecodeToFrames(*tc, fps_);
    } catch (const Error& e) {
      s.notes.push_back("unreadable timecode '" + s.start_timecode + "' (" + e.message() + "): not used");
      all_timecoded = false;
      continue;
    }
    start_tc[name] = frames;
    t0 = t0 ? std::min(*t0, start_tc[name]) : start_tc[name];
  }
  // The estimate `previz take sync --write` left (out/sync.json): used where neither take.json nor
  // timecode says.
  nlohmann::json estimated = nlohmann::json::object();
  const fs::path sync_json = dir_ / "out" / "sync.json";
  if (fs::is_regular_file(sync_json, ec)) {
    const nlohmann::json sj = readJsonFile(sync_json);
    if (!sj.is_object() || !sj.contains("offsets") || !sj["offsets"].is_object())
      throw Error("expected {\"offsets\": {camera: frames}}", takeJsonContext(sync_json, "offsets"));
    estimated = sj["offsets"];
    for (const auto& [name, v] : estimated.items())
      if (!isOffset(v)) throw Error(kOffsetRule, takeJsonContext(sync_json, "offsets", name));
  }
  for (auto& [name, s] : streams_) {
    if (const auto it = options_.offsets.find(name); it != options_.offsets.end()) {
      s.offset = it->second;
      s.offset_from = "given";
    } else if (offsets.contains(name)) {
      s.offset = offsets[name].get<long long>();
      s.offset_from = "take.json";
    } else if (all_timecoded && start_tc.count(name)) {
      // The earliest camera's first frame is take frame 0.
      s.offset = s.source_frames.front() + (*t0 - start_tc[name]);
      s.offset_from = "timecode";
    } else if (estimated.contains(name)) {
      s.offset = estimated[name].get<long long>();
      s.offset_from = "estimate (out/sync.json)";
    } else {
      s.offset = 0;
      s.offset_from = "none";
      if (!all_timecoded && start_tc.count(name))
        s.notes.push_back("its timecode " + s.start_timecode +
                          " is not used: not every camera has one (offsets: take.json \"offsets\" or `previz take sync`)");
    }
  }

  std::set<int> frames;
  for (const auto& [name, s] : streams_) {
    const std::vector<int> f = s.takeFrames();
    frames.insert(f.begin(), f.end());
  }
  // take.json "frames": the take's length from its first frame (frames no camera has are then
  // listed too, and fail with every camera named).
  if (j.contains("frames")) {
    const long long first = frames.empty() ? 0 : *frames.begin();
    const long long last = std::min<long long>(first + j["frames"].get<long long>(), std::numeric_limits<int>::max());
    for (long long f = first; f < last; ++f) frames.insert(static_cast<int>(f));
  }
  frames_.assign(frames.begin(), frames.end());
}

void Take::findStream(CameraStream& s) {
  std::error_code ec;
  const fs::path tj = dir_ / "take.json";
  // 1. take.json "sources".
  std::string given;
  if (take_json_.contains("sources")) {
    const nlohmann::json& src = take_json_["sources"];
    const nlohmann::json* entry = src.contains(s.camera) ? &src[s.camera] : src.contains("*") ? &src["*"] : nullptr;
    if (entry) {
      if (!entry->is_string())
        throw Error("sources: a path or pattern per camera", takeJsonContext(tj, "sources", s.camera));
      given = replaceAll(entry->get<std::string>(), "{camera}", s.camera);
    }
  }
  if (!given.empty()) {
    s.found_by = "take.json sources";
    if (const std::string live = liveSource(given); !live.empty()) {
      s.kind = SourceKind::kLive;
      s.path = live;
      return;
    }
    const fs::path p = fs::path(given).is_absolute() ? fs::path(given) : dir_ / given;
    if (const std::optional<SequencePattern> pattern = parsePattern(p.filename().string())) {
      s.kind = SourceKind::kSequence;
      s.path = p.parent_path();
      s.pattern = *pattern;
      probeSequence(s);
    } else if (isVideo(p)) {
      s.kind = SourceKind::kVideo;
      s.path = p;
      probeVideo(s);
    } else {
      s.kind = SourceKind::kStill;
      s.path = p;
      probeStill(s);
    }
    return;
  }
  // 2. cams/<camera>/ with a numbered sequence.
  const fs::path folder = dir_ / "cams" / s.camera;
  if (fs::is_directory(folder, ec)) {
    const std::vector<FoundSequence> found = findSequences(folder);
    if (found.empty()) {
      s.kind = SourceKind::kSequence;
      s.path = folder;
      s.found_by = "cams/" + s.camera + "/";
      s.unusable = "no numbered image files in " + shown(dir_, folder);
      return;
    }
    if (found.size() > 1 && found[1].frames.size() == found[0].frames.size())
      throw Error("two numbered sequences of " + std::to_string(found[0].frames.size()) + " files, " +
                      found[0].pattern.str() + " and " + found[1].pattern.str() +
                      ": name the camera's in take.json \"sources\"",
                  takeJsonContext(folder, "sources", s.camera));
    s.kind = SourceKind::kSequence;
    s.path = folder;
    s.pattern = found[0].pattern;
    s.found_by = "cams/" + s.camera + "/";
    for (size_t i = 1; i < found.size(); ++i)
      s.notes.push_back("ignored " + std::to_string(found[i].frames.size()) + " other files " + found[i].pattern.str());
    probeSequence(s);
    return;
  }
  // 3. cams/<camera>.<video>, 4. cams/<camera>.<image>.
  if (const fs::path p = findByStem(dir_ / "cams", s.camera, kVideoExtensions); !p.empty()) {
    s.kind = SourceKind::kVideo;
    s.path = p;
    s.found_by = "cams/" + p.filename().string();
    probeVideo(s);
    return;
  }
  if (const fs::path p = findByStem(dir_ / "cams", s.camera, kStillExtensions); !p.empty()) {
    s.kind = SourceKind::kStill;
    s.path = p;
    s.found_by = "cams/" + p.filename().string();
    probeStill(s);
    return;
  }
  s.kind = SourceKind::kNone;
  s.unusable = "no stream: looked for cams/" + s.camera + "/ (an image sequence), cams/" + s.camera +
               ".mkv|.mov|.mp4|... and take.json \"sources\"";
}

void Take::probeStill(CameraStream& s) const {
  std::error_code ec;
  if (!fs::is_regular_file(s.path, ec)) {
    s.unusable = "file not found: " + s.path.string();
    return;
  }
  s.source_frames = {0};
  try {
    const cv::Mat img = readImage8(s.path, &s.format, &s.bit_depth, &s.start_timecode);
    s.width = img.cols;
    s.height = img.rows;
    s.channels = 3;
    if (!s.start_timecode.empty()) s.timecode_from = "exr attribute";
  } catch (const Error& e) {
    s.unusable = std::string("unreadable: ") + e.what();
  }
}

void Take::probeSequence(CameraStream& s) const {
  std::error_code ec;
  if (!fs::is_directory(s.path, ec)) {
    s.unusable = "folder not found: " + s.path.string();
    return;
  }
  s.source_frames = framesOf(s.path, s.pattern);
  if (s.source_frames.empty()) {
    s.unusable = "no files " + s.pattern.str() + " in " + shown(dir_, s.path);
    return;
  }
  const SequenceGaps gaps = sequenceGaps(s.source_frames);
  if (gaps.missing_count > 0) {
    std::string list;
    for (long long f : gaps.missing) list += (list.empty() ? "" : ", ") + std::to_string(f);
    if (gaps.missing_count > static_cast<long long>(gaps.missing.size())) list += ", ...";
    s.notes.push_back(std::to_string(gaps.missing_count) + " frame(s) missing from the sequence " +
                      std::to_string(s.source_frames.front()) + ".." + std::to_string(s.source_frames.back()) +
                      (gaps.step > 1 ? " (every " + std::to_string(gaps.step) + ")" : "") + ": " + list);
  } else if (gaps.step > 1) {
    s.notes.push_back("sparse sequence: every " + std::to_string(gaps.step) + " frames");
  }
  // Size, depth and timecode from the first file that reads (of the first few).
  int tried = 0;
  for (long long f : s.source_frames) {
    if (++tried > 5) break;
    try {
      const cv::Mat img = readImage8(s.path / s.pattern.fileName(f), &s.format, &s.bit_depth, &s.start_timecode);
      s.width = img.cols;
      s.height = img.rows;
      s.channels = 3;
      if (!s.start_timecode.empty()) {
        // The attribute belongs to that file: the first frame's timecode is earlier by the
        // frames before it.
        if (f != s.source_frames.front()) {
          if (const std::optional<Timecode> tc = parseTimecode(s.start_timecode)) {
            try {
              const long long first = timecodeToFrames(*tc, fps_) - (f - s.source_frames.front());
              if (first >= 0) s.start_timecode = formatTimecode(framesToTimecode(first, fps_, tc->drop_frame));
            } catch (const Error&) {
              // Left as it is: the offsets below name it as unreadable.
            }
          }
        }
        s.timecode_from = "exr attribute";
      }
      return;
    } catch (const Error& e) {
      s.notes.push_back("unreadable " + shown(dir_, s.path / s.pattern.fileName(f)) + ": " + e.what());
    }
  }
  // Every file unreadable: each read says so, frame by frame (the stream's size stays unknown).
}

void Take::probeVideo(CameraStream& s) {
  std::error_code ec;
  if (!fs::is_regular_file(s.path, ec)) {
    s.unusable = "file not found: " + s.path.string();
    return;
  }
  try {
    const VideoProbe probe = take::probeVideo(s.path);
    s.format = probe.codec;
    s.width = probe.width;
    s.height = probe.height;
    s.bit_depth = probe.bit_depth;
    s.channels = 3;
    s.fps = probe.fps;
    s.header_frames = probe.header_frames;
    s.start_timecode = probe.timecode;
    if (!s.start_timecode.empty()) s.timecode_from = "container";
    // One decoder per camera, shared by the threads that read it (VideoReader is thread-safe).
    auto video = std::make_unique<VideoReader>(s.path, options_.video_prefetch);
    const long long decodable = video->decodableFrames();
    for (long long f = 0; f < decodable; ++f) s.source_frames.push_back(f);
    if (s.header_frames >= 0 && s.header_frames != decodable)
      s.notes.push_back("the container says " + std::to_string(s.header_frames) + " frames, " +
                        std::to_string(decodable) + " decode");
    else if (probe.packets != decodable)
      s.notes.push_back(std::to_string(probe.packets) + " packets, " + std::to_string(decodable) + " frames decode");
    if (decodable == 0) s.unusable = "no frame decodes";
    videos_[s.camera] = std::move(video);
  } catch (const Error& e) {
    s.unusable = std::string("unreadable video: ") + e.what();
  }
}

// ---------------------------------------------------------------------------------------------
// Reading

bool Take::has(const std::string& camera) const { return streams_.count(camera) != 0; }

const CameraStream& Take::stream(const std::string& camera) const {
  const auto it = streams_.find(camera);
  if (it == streams_.end()) {
    ErrorContext c = fileContext(dir_.string());
    c.camera = camera;
    throw Error("the take was not opened for this camera", c);
  }
  return it->second;
}

fs::path Take::sourceFile(const CameraStream& s, long long source_frame) const {
  return s.kind == SourceKind::kSequence ? s.path / s.pattern.fileName(source_frame) : s.path;
}

std::string Take::describe(const std::string& camera, int frame) const {
  const CameraStream& s = stream(camera);
  const long long src = frame + s.offset;
  switch (s.kind) {
    case SourceKind::kSequence: return shown(dir_, sourceFile(s, src));
    case SourceKind::kVideo: return shown(dir_, s.path) + " frame " + std::to_string(src);
    case SourceKind::kStill: return shown(dir_, s.path);
    case SourceKind::kLive: return "live:" + s.path.string();
    case SourceKind::kNone: break;
  }
  return "cams/" + camera + " (no stream)";
}

CameraImage Take::read(const std::string& camera, int frame) const {
  const CameraStream& s = stream(camera);
  CameraImage out;
  out.camera = camera;
  out.frame = frame;
  out.source_frame = frame + s.offset;
  out.source = describe(camera, frame);
  if (!s.usable()) {
    out.dropped = s.unusable;
    return out;
  }
  if (s.kind == SourceKind::kLive) {
    out.dropped = "a live camera (" + out.source + "): `previz run` reads it as it comes";
    return out;
  }
  const bool there = std::binary_search(s.source_frames.begin(), s.source_frames.end(), out.source_frame);
  if (!there) {
    if (s.kind == SourceKind::kVideo)
      out.dropped = "no frame " + std::to_string(out.source_frame) + " in " + shown(dir_, s.path) + " (it has " +
                    std::to_string(s.source_frames.size()) + " frames; offset " + std::to_string(s.offset) + ")";
    else if (s.kind == SourceKind::kStill)
      out.dropped = "a one-frame camera (" + shown(dir_, s.path) + ") has no frame " + std::to_string(frame);
    else
      out.dropped = "missing frame " + out.source;
    return out;
  }
  try {
    if (s.kind == SourceKind::kVideo) {
      VideoReader::Frame f = videos_.at(camera)->read(out.source_frame);
      if (!f.error.empty()) {
        out.dropped = "unreadable " + out.source + ": " + f.error;
        return out;
      }
      out.image = toBgr8(f.bgr, true);
    } else {
      out.image = readImage8(sourceFile(s, out.source_frame));
    }
  } catch (const std::exception& e) {
    out.dropped = "unreadable frame (corrupt or truncated?): " + std::string(e.what());
    return out;
  }
  // The size is the reader's to check: against the rig's camera (carving/take.h, tracking), or
  // the camera's other frames (multicam).
  return out;
}

FrameSet Take::readFrameSet(int frame, const std::vector<std::string>& cameras) const {
  FrameSet set;
  set.frame = frame;
  set.cameras.resize(cameras.size());
  const int n = static_cast<int>(cameras.size());
#pragma omp parallel for schedule(dynamic)
  for (int i = 0; i < n; ++i) {
    try {
      set.cameras[i] = read(cameras[i], frame);
    } catch (const std::exception& e) {  // a camera the take was not opened for
      set.cameras[i].camera = cameras[i];
      set.cameras[i].frame = frame;
      set.cameras[i].dropped = e.what();
    }
  }
  return set;
}

// ---------------------------------------------------------------------------------------------
// Info

nlohmann::json Take::info() const {
  nlohmann::json cams = nlohmann::json::array();
  for (const std::string& name : names_) {
    const CameraStream& s = streams_.at(name);
    nlohmann::json c = {{"camera", name},
                        {"kind", toString(s.kind)},
                        {"found_by", s.found_by},
                        {"path", s.kind == SourceKind::kNone  ? ""
                                 : s.kind == SourceKind::kLive ? "live:" + s.path.string()
                                                               : shown(dir_, s.path)},
                        {"usable", s.usable()},
                        {"width", s.width},
                        {"height", s.height},
                        {"bit_depth", s.bit_depth},
                        {"format", s.format},
                        {"frames", s.source_frames.size()},
                        {"offset", s.offset},
                        {"offset_from", s.offset_from},
                        {"start_timecode", s.start_timecode},
                        {"timecode_from", s.timecode_from},
                        {"notes", s.notes}};
    if (s.kind == SourceKind::kSequence) c["pattern"] = s.pattern.str();
    if (s.kind == SourceKind::kVideo) {
      c["fps"] = s.fps;
      c["header_frames"] = s.header_frames;
    }
    if (!s.source_frames.empty()) {
      c["source_range"] = {s.source_frames.front(), s.source_frames.back()};
      const std::vector<int> t = s.takeFrames();
      if (!t.empty()) c["take_range"] = {t.front(), t.back()};
    }
    if (!s.unusable.empty()) c["unusable"] = s.unusable;
    cams.push_back(c);
  }
  nlohmann::json j = {{"take", dir_.string()},   {"fps", fps_},         {"fps_from", fps_from_},
                      {"main", main_},           {"frames", frames_.size()}, {"cameras", cams}};
  if (!frames_.empty()) j["frame_range"] = {frames_.front(), frames_.back()};
  // Mismatches between cameras, named.
  nlohmann::json mismatches = nlohmann::json::array();
  for (const std::string& name : names_) {
    const CameraStream& s = streams_.at(name);
    if (!s.unusable.empty()) mismatches.push_back(name + ": " + s.unusable);
    for (const std::string& n : s.notes) mismatches.push_back(name + ": " + n);
  }
  j["mismatches"] = mismatches;
  return j;
}

}  // namespace previz::take
