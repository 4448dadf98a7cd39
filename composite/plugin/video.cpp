// The previz_composite_video plugin: cv::VideoWriter behind composite/output.cpp
// (detail/video_plugin.h).
#include <opencv2/videoio.hpp>

#include "composite/detail/video_plugin.h"
#include "core/plugin.h"

namespace previz::composite {
namespace {

class Writer final : public detail::VideoOut {
 public:
  cv::VideoWriter video;
  void write(const cv::Mat& bgr) override { video.write(bgr); }
  void release() override { video.release(); }
};

std::unique_ptr<detail::VideoOut> open(const std::string& file, const std::string& fourcc, double fps, cv::Size size) {
  if (fourcc.size() != 4) return nullptr;
  auto w = std::make_unique<Writer>();
  w->video.open(file, cv::VideoWriter::fourcc(fourcc[0], fourcc[1], fourcc[2], fourcc[3]), fps, size);
  if (!w->video.isOpened()) return nullptr;
  return w;
}

const detail::VideoPlugin kPlugin{detail::VideoPlugin::kVersion, open};

}  // namespace
}  // namespace previz::composite

PREVIZ_PLUGIN_ENTRY const void* previz_composite_video_plugin(int version) {
  return version == previz::composite::kPlugin.version ? &previz::composite::kPlugin : nullptr;
}
