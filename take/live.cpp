// Live cameras (see live.h).
#include "take/live.h"

#include "core/error.h"
#include "take/detail/video_plugin.h"
#include "take/take.h"

namespace previz::take {

std::string liveSource(const std::string& source_text) {
  const std::string prefix = "live:";
  return source_text.compare(0, prefix.size(), prefix) == 0 ? source_text.substr(prefix.size()) : std::string();
}

// OpenCV's VideoCapture, in the previz_video plugin (detail/video_plugin.h).
struct LiveStream::Impl {
  std::unique_ptr<detail::LiveCapture> capture;
};

LiveStream::LiveStream(const std::string& camera, const std::string& source)
    : impl_(std::make_unique<Impl>()), camera_(camera), source_(source) {
  ErrorContext c;
  c.camera = camera;
  c.file = source;
  if (source.empty()) throw Error("live: an empty source", c);
  impl_->capture = detail::videoPlugin().open_live(source);
  if (!impl_->capture) throw Error("live: cannot open the source", c);
}

LiveStream::~LiveStream() = default;

double LiveStream::fps() const {
  const double fps = impl_->capture->fps();
  return fps > 0 && fps < 1000 ? fps : 0.0;
}

bool LiveStream::grab() { return impl_->capture->grab(); }

bool LiveStream::read(cv::Mat& bgr) {
  cv::Mat frame;
  if (!impl_->capture->read(frame)) return false;
  bgr = toBgr8(frame, false);  // a capture device's frames are display-referred codes already
  return true;
}

}  // namespace previz::take
