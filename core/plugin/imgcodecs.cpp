// The previz_imgcodecs plugin: OpenCV's imgcodecs behind core/io.cpp (detail/imgcodecs_plugin.h).
#include <opencv2/imgcodecs.hpp>

#include "core/detail/imgcodecs_plugin.h"
#include "core/plugin.h"

namespace {

cv::Mat read(const std::string& path, int flags) { return cv::imread(path, flags); }

bool encode(const std::string& ext, const cv::Mat& image, std::vector<unsigned char>& bytes) {
  return cv::imencode(ext, image, bytes);
}

const previz::detail::ImgcodecsPlugin kPlugin{previz::detail::ImgcodecsPlugin::kVersion, read, encode};

}  // namespace

PREVIZ_PLUGIN_ENTRY const void* previz_imgcodecs_plugin(int version) {
  return version == kPlugin.version ? &kPlugin : nullptr;
}
