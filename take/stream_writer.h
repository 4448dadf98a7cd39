#pragma once
// Writing one camera's stream into a take folder, as a camera or a conform delivers it: an image
// sequence of any pattern and start number (8-bit PNG/JPEG, 16-bit PNG/TIFF, float EXR in
// linear light with the SMPTE timeCode attribute), or a video file (lossless FFV1, H.264, ProRes;
// the container's start timecode). The synthetic studio writes its plates through it and
// `previz take convert` re-writes a take in another form; the take model (take.h) reads
// every form back. Each file is written atomically.
#include <filesystem>
#include <memory>
#include <optional>
#include <string>

#include <opencv2/core.hpp>

namespace previz::take {

struct StreamWriterOptions {
  // Sequences: "png" (8-bit), "jpg", "png16", "tif16" (16-bit), "exr" (float, linear light);
  // videos: "ffv1" (.mkv), "h264" (.mp4), "prores" (.mov).
  std::string format = "png";
  // Sequences: the file name pattern in cams/<camera>/ ("%06d" or "####" style, "{camera}"
  // standing for the camera's name); "" = "%06d". The extension comes from the format.
  std::string pattern;
  long long first_number = 0;   // sequences: the number of the first frame written
  double fps = 24;
  std::string start_timecode;   // of the first frame written ("" = none): EXR attribute, container
  void validate() const;        // throws Error naming the field
  bool isVideo() const;
};

// Where to write a camera whose first frame is take frame 'first_frame' so that the take model
// reads it back at the same take frames. 'base' gives the form, the number of a sequence's first
// file (first_number) and the timecode of take frame 0 (start_timecode). Forms that carry a
// timecode (EXR, videos) get first_frame's, and sequences keep their own numbering from
// first_number; others are numbered by take frame (sequences: first_number + first_frame) or
// start at it (videos), and need the take.json offset given back (nullopt: none needed).
struct StreamPlacement {
  StreamWriterOptions writer;
  std::optional<long long> offset;
};
StreamPlacement placeStream(const StreamWriterOptions& base, long long first_frame);

class StreamWriter {
 public:
  // Writes to <take_dir>/cams/<camera>/<pattern> or <take_dir>/cams/<camera>.<ext>.
  StreamWriter(const std::filesystem::path& take_dir, const std::string& camera, cv::Size size,
               const StreamWriterOptions& options);
  ~StreamWriter();
  StreamWriter(StreamWriter&&) noexcept;
  StreamWriter& operator=(StreamWriter&&) noexcept;

  // The next frame: 8-bit BGR, and optionally the same picture before 8-bit quantisation
  // (CV_32FC3 BGR, sRGB-coded in [0, 1]) that 16-bit and float formats store instead of
  // widening the 8-bit codes. Throws Error naming the file.
  void write(const cv::Mat& bgr8, const cv::Mat& encoded = cv::Mat());
  // Leaves the next frame out (a hole in a sequence: its number is skipped). Videos have no
  // holes: throws Error naming the camera.
  void skip();
  // Finishes a video (renamed into place); nothing to do for sequences.
  void close();

  // What take.json "sources" would say for this stream, relative to the take folder:
  // "cams/A/A001C003.%04d.exr", "cams/A.mkv".
  std::string source() const;
  long long framesWritten() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace previz::take
