// Live cameras (see live.h).
#include "take/live.h"

#include <opencv2/videoio.hpp>

#include "core/error.h"
#include "take/take.h"

namespace previz::take {

std::string liveSource(const std::string& source_text) {
  const std::string prefix = "live:";
  return source_text.compare(0, prefix.size(), prefix) == 0 ? source_text.substr(prefix.size()) : std::string();
}

struct LiveStream::Impl {
  cv::VideoCapture capture;
};

LiveStream::LiveStream(const std::string& camera, const std::string& source)
    : impl_(std::make_unique<Impl>()), camera_(camera), source_(source) {
  ErrorContext c;
  c.camera = camera;
  c.file = source;
  if (source.empty()) throw Error("live: an empty source", c);
  // A device index, a GStreamer pipeline, or anything FFmpeg opens (files, rtsp://, udp://, ...).
  const bool index = source.find_first_not_of("0123456789") == std::string::npos;
  const bool opened = index ? impl_->capture.open(std::stoi(source))
                            : impl_->capture.open(source, source.find('!') != std::string::npos ? cv::CAP_GSTREAMER
                                                                                                : cv::CAP_ANY);
  if (!opened) throw Error("live: cannot open the source", c);
}

LiveStream::~LiveStream() = default;

double LiveStream::fps() const {
  const double fps = impl_->capture.get(cv::CAP_PROP_FPS);
  return fps > 0 && fps < 1000 ? fps : 0.0;
}

bool LiveStream::grab() { return impl_->capture.grab(); }

bool LiveStream::read(cv::Mat& bgr) {
  cv::Mat frame;
  if (!impl_->capture.read(frame) || frame.empty()) return false;
  bgr = toBgr8(frame, false);  // a capture device's frames are display-referred codes already
  return true;
}

}  // namespace previz::take
