#pragma once
// The take model: how every previz command reads a take's camera streams (docs/formats.md,
// "Take folder"). One camera's stream is, in the order looked for:
//   1. what take.json "sources" names for it: a pattern ("cams/A/A001C003.%04d.exr", "####"
//      allowed), a video file, or one still image (a one-frame camera); relative to the take
//      folder, "{camera}" standing for the camera's name, "*" for every camera;
//   2. a folder cams/<camera>/ holding a numbered image sequence of any name and start number
//      (the largest numbered set in it; take.json names the pattern when there are several);
//   3. a video file cams/<camera>.mkv|.mov|.mp4|.avi|.mxf|.webm (decoded by OpenCV's FFmpeg
//      backend, ahead of the frame asked for, on a worker thread);
//   4. one still image cams/<camera>.png|.jpg|.tif|.exr (a one-frame camera).
// A live camera is named in take.json "sources" as "live:<device, URL or pipeline>" (take/live.h):
// it has no frames on disk; `previz run` reads it live.
// Take frames: source frame = take frame + offset, the offset of each camera from (in order)
// take.json "offsets" (camera A's source frame 2 is take frame 0: "offsets": {"A": 2}), the
// cameras' start timecodes when every camera has one (container timecode; EXR timeCode
// attribute; the earliest camera's first frame is take frame 0), the estimate `previz take sync
// --write` left in out/sync.json (carving/consistency.h), else 0 (sequences keep their own
// numbers: frame 1001 of "%04d" is take frame 1001). The take's frames are those some camera
// really has (containers lie: a video is read as far as it decodes, a sparse sequence lists only
// its frames) and take.json "frames" frames from the first of them (or from 0).
// Images come out as 8-bit BGR whatever the file holds: 16-bit scaled (v / 257, rounded), float
// (EXR, float TIFF) taken as linear light and sRGB-encoded once (core/srgb.h), grey expanded,
// alpha dropped. A camera is never fatal for a frame: a missing, unreadable or out-of-range
// frame comes back as CameraImage::dropped naming the file (and the video frame); its size is
// for the reader to check against the camera it expects.
#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "take/sequence.h"

namespace previz::take {

class VideoReader;  // take/video.h

enum class SourceKind { kNone, kSequence, kVideo, kStill, kLive };
std::string toString(SourceKind kind);

// One camera's stream as found.
struct CameraStream {
  std::string camera;
  SourceKind kind = SourceKind::kNone;
  std::filesystem::path path;     // sequence: its folder; video, still: the file; live: the source
  SequencePattern pattern;        // sequence only
  std::string found_by;           // "take.json sources", "cams/<camera>/", "cams/<camera>.mkv", ...
  std::vector<long long> source_frames;  // what is really there, ascending (video: 0 .. decoded - 1)
  // From the first readable frame (or the container): size, channels, bit depth (8, 16 or 32 =
  // float), the file format ("png", "exr", or the video codec: "ffv1", "h264", ...).
  int width = 0, height = 0, channels = 0, bit_depth = 0;
  std::string format;
  double fps = 0;                 // video: the container's rate; 0 = the stream does not say
  long long header_frames = -1;   // video: the container's frame count (-1 = not given)
  std::string start_timecode;     // of source_frames.front() ("" = none)
  std::string timecode_from;      // "container", "exr attribute"
  long long offset = 0;           // source frame = take frame + offset
  std::string offset_from;        // "given", "take.json", "timecode", "estimate (out/sync.json)", "none"
  // Why the whole stream is unusable ("" = usable): another fps than the take's, unreadable.
  std::string unusable;
  // Mismatches named for a person (a hole in a sequence, a container whose header promises more
  // frames than decode, ...); the stream is still used.
  std::vector<std::string> notes;

  bool usable() const { return kind != SourceKind::kNone && unusable.empty(); }
  // The take frames this camera has (source frames - offset).
  std::vector<int> takeFrames() const;
};

// One camera's image for one take frame.
struct CameraImage {
  std::string camera;
  int frame = 0;                  // take frame
  long long source_frame = 0;
  std::string source;             // the file ("cams/A/A.1001.exr") or "cams/A.mkv frame 12"
  cv::Mat image;                  // CV_8UC3 sRGB-coded BGR
  std::string dropped;            // "" = usable; else why the camera has no image this frame
  bool ok() const { return dropped.empty(); }
};

// Every camera's image for one take frame (or the reason a camera has none), in the order asked.
struct FrameSet {
  int frame = 0;
  std::vector<CameraImage> cameras;
  int usable() const;
};

struct TakeOptions {
  // The cameras to read (a rig's); empty = every stream found (take.json sources, then cams/).
  std::vector<std::string> cameras;
  // Offsets given by the caller (an estimate it made); they win over everything else.
  std::map<std::string, long long> offsets;
  // The take's fps when take.json and the streams do not give it.
  double default_fps = 24;
  int video_prefetch = 4;         // frames decoded ahead per video stream (0 = none)
};

class Take {
 public:
  // Finds every camera's stream and the take's frames. Throws Error naming take.json (and its
  // field) when it is malformed, or the folder when it does not exist; a camera without a stream
  // is not an error here (CameraStream::kind kNone; every read of it is dropped, saying so).
  explicit Take(const std::filesystem::path& dir, const TakeOptions& options = {});
  ~Take();
  Take(Take&&) noexcept;
  Take& operator=(Take&&) noexcept;

  const std::filesystem::path& dir() const { return dir_; }
  double fps() const { return fps_; }
  const std::string& fpsFrom() const { return fps_from_; }  // "take.json", "video", "default"
  const nlohmann::json& takeJson() const { return take_json_; }  // {} when there is none
  const std::vector<std::string>& cameras() const { return names_; }
  bool has(const std::string& camera) const;
  // Throws Error naming the camera when the take was not opened for it.
  const CameraStream& stream(const std::string& camera) const;
  // The main camera as take.json "roles" names it ({"main": "A"}), else a camera named "main";
  // "" when neither.
  std::string mainCamera() const { return main_; }

  // Take frames, ascending (see above). Empty when no camera has a frame.
  const std::vector<int>& frames() const { return frames_; }

  // One camera's image; never throws for a bad or missing frame. Thread-safe (cameras may be
  // read in parallel; one video is read by one thread at a time).
  CameraImage read(const std::string& camera, int frame) const;
  // Every camera asked for, in parallel.
  FrameSet readFrameSet(int frame, const std::vector<std::string>& cameras) const;
  // Where a camera's frame comes from, for messages ("cams/A/000012.png", "cams/A.mkv frame 14").
  std::string describe(const std::string& camera, int frame) const;

  // The camera's clean plate (the empty stage), 8-bit BGR, or an empty Mat when the take has
  // none: clean/<camera>.png|.jpg|.tif|.exr (one image), or a plate video clean/<camera>.mkv|.mov
  // |.mp4|... or sequence clean/<camera>/ whose per-pixel median over up to 25 frames (spread in
  // CleanPlateInfo) is computed once and cached in <take>/out/clean/<camera>.png (recomputed when
  // the source changes; not cached when the take folder is read-only). Throws Error naming the
  // file and camera when one exists but cannot be read or has another size than the camera's.
  cv::Mat cleanPlate(const std::string& camera) const;

  // Everything `previz take info` prints: fps, frames, and per camera its stream (kind, files,
  // size, bit depth, fps, frame range, timecode, offset and where each came from) and every note.
  nlohmann::json info() const;

 private:
  void findStream(CameraStream& s);
  void probeStill(CameraStream& s) const;
  void probeSequence(CameraStream& s) const;
  void probeVideo(CameraStream& s);
  std::filesystem::path sourceFile(const CameraStream& s, long long source_frame) const;

  std::filesystem::path dir_;
  TakeOptions options_;
  nlohmann::json take_json_ = nlohmann::json::object();
  double fps_ = 24;
  std::string fps_from_ = "default";
  std::vector<std::string> names_;
  std::map<std::string, CameraStream> streams_;
  std::map<std::string, std::unique_ptr<VideoReader>> videos_;  // video cameras' decoders
  std::string main_;
  std::vector<int> frames_;
};

// An image file of any depth as 8-bit sRGB-coded BGR (see above); 'format' and 'bit_depth' say
// what the file held. Throws Error naming the file.
cv::Mat readImage8(const std::filesystem::path& path, std::string* format = nullptr, int* bit_depth = nullptr,
                   std::string* timecode = nullptr);
// The same conversion for an image already in memory (8/16-bit or float linear; 1, 3 or 4 channels).
cv::Mat toBgr8(const cv::Mat& image, bool float_is_linear = true);

}  // namespace previz::take
