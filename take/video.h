#pragma once
// Video files of a take: a writer (FFmpeg's libavcodec / libavformat: lossless FFV1 for the
// synthetic studio, H.264 and ProRes for what cameras deliver), a probe that reads a
// container's header and counts its packets without decoding, and a reader that decodes through
// OpenCV's FFmpeg backend, ahead of the frame asked for, on a worker thread. FFmpeg and OpenCV's
// videoio are the previz_video plugin's (detail/video_plugin.h), loaded by the first writer,
// probe or reader; a command that reads no video does not load them.
// Frames are 0-based, 8-bit BGR (CV_8UC3). Every failure throws previz::Error naming the file.
#include <filesystem>
#include <memory>
#include <string>

#include <opencv2/core.hpp>

namespace previz::take {

struct VideoWriterOptions {
  // "ffv1": lossless FFV1 (level 3, every frame a keyframe), pixel format bgr0, so 8-bit BGR
  //         comes back bit-exactly through VideoReader;
  // "h264": libx264, yuv420p, the crf below (the encoder's default GOP and B-frames);
  // "prores": prores_ks, yuv422p10le.
  // H.264 and ProRes are converted with BT.601 limited range (what OpenCV's reader assumes)
  // and tagged so; their width and height must be even.
  std::string codec = "ffv1";
  double fps = 24;              // may be fractional: 23.976, 29.97, 59.94 are stored as n*1000/1001
  std::string start_timecode;   // "HH:MM:SS:FF" (";" drop frame); "" = none written
  int crf = 18;                 // h264 only, 0 (lossless) .. 51
  int threads = 0;              // encoder threads (0 = FFmpeg's choice)
  void validate() const;        // throws Error naming the field
};

// Writes a video atomically: frames go to a temporary file beside 'path', close() renames it
// into place; destroyed without close() (or after an error) the temporary is removed and
// nothing appears at 'path'. The container comes from the extension: .mkv, .mov, .mp4, .avi.
class VideoWriter {
 public:
  VideoWriter(const std::filesystem::path& path, cv::Size size, const VideoWriterOptions& options = {});
  ~VideoWriter();
  VideoWriter(VideoWriter&&) noexcept;
  VideoWriter& operator=(VideoWriter&&) noexcept;

  // 'bgr' is CV_8UC3 of exactly the size given.
  void write(const cv::Mat& bgr);
  // Flushes the encoder, writes the trailer, renames the file into place.
  void close();
  long long framesWritten() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// What a container says about its video stream, and how many packets it really holds.
struct VideoProbe {
  std::string codec;            // "ffv1", "h264", "prores", ...
  std::string pix_fmt;          // "bgr0", "yuv420p", ... ("" = unknown)
  int width = 0, height = 0;
  int bit_depth = 8;            // of the first component of pix_fmt
  double fps = 0;               // avg_frame_rate, else r_frame_rate (0 = unknown)
  long long header_frames = -1; // the container's frame count (-1 = not given)
  long long packets = 0;        // video packets demuxed (not decoded) to the end
  double duration_s = 0;        // the container's duration (0 = unknown)
  std::string timecode;         // start timecode ("" = none)
  std::string demux_error;      // why counting packets stopped before the end ("" = read to the end)
};

// Throws Error naming the file when it cannot be opened or holds no video stream. A file cut
// short is not an error: its packets are counted as far as they can be read.
VideoProbe probeVideo(const std::filesystem::path& path);

// Random access to a video's frames, decoded by OpenCV's FFmpeg backend. Frame i is the i-th
// frame decoding in order from the start gives. Reads in order (or a few frames ahead) continue
// decoding, and a worker thread has decoded up to 'prefetch' frames past the last one asked for
// meanwhile; any other frame is reached by seeking, checked, and decoded in order from the start
// where the seek missed (video.cpp, Decoder::seek). Thread-safe; one decoder, so calls are served
// one at a time.
class VideoReader {
 public:
  // Throws Error naming the file when OpenCV's FFmpeg backend cannot open it.
  explicit VideoReader(const std::filesystem::path& path, int prefetch = 4);
  ~VideoReader();
  VideoReader(const VideoReader&) = delete;
  VideoReader& operator=(const VideoReader&) = delete;

  struct Frame {
    cv::Mat bgr;                // CV_8UC3; empty when error is set
    std::string error;          // "" = ok; e.g. "the video ends at frame 32 (32 frames decode; frame 39 asked)"
    bool ok() const { return error.empty(); }
  };
  // Frame 'index' (0-based). Never throws for a bad or missing frame.
  Frame read(long long index);

  // How many frames really decode: the container's packet count, verified at the end (the
  // last frames are decoded, walking back until one decodes). Computed once. Throws Error naming
  // the file only when the file can no longer be opened to count its packets.
  long long decodableFrames();

  const std::filesystem::path& path() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace previz::take
