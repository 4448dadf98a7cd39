#pragma once
// A camera read live: a capture device ("0", "/dev/video2"), a network stream (rtsp://, udp://,
// srt://, http://...), a video file played as if live, or a GStreamer pipeline (text with '!'),
// opened through OpenCV's VideoCapture (in the previz_video plugin). Frames come as the take
// model gives every image (8-bit sRGB-coded BGR, take/take.h). A take names live cameras in
// take.json "sources" as "live:<source>"; `previz run` reads them (or --live NAME=SOURCE) through
// live/inputs.h's LiveReader, which paces them: before each frame every camera is advanced
// (grab, no decode) to the frame the clock says the cameras are at.
#include <memory>
#include <string>

#include <opencv2/core.hpp>

namespace previz::take {

// "live:0" -> "0"; "" when the text is not a live source.
std::string liveSource(const std::string& source_text);

class LiveStream {
 public:
  // Throws Error naming the camera and the source when it cannot be opened.
  LiveStream(const std::string& camera, const std::string& source);
  ~LiveStream();
  LiveStream(const LiveStream&) = delete;
  LiveStream& operator=(const LiveStream&) = delete;

  const std::string& camera() const { return camera_; }
  const std::string& source() const { return source_; }
  // The stream's own rate (0 when it does not say).
  double fps() const;
  // Moves to the next frame without decoding it; false at the end of the stream.
  bool grab();
  // The next frame decoded, as 8-bit BGR; false at the end of the stream.
  bool read(cv::Mat& bgr);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  std::string camera_, source_;
};

}  // namespace previz::take
