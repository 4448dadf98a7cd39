#pragma once
// PNG and JPEG read and written with libpng and libjpeg-turbo directly, giving byte for byte
// what OpenCV 4.6's cv::imread / cv::imencode give: the same libraries driven with the same
// calls and settings (modules/imgcodecs/src/grfmt_png.cpp, grfmt_jpeg.cpp, exif.cpp and
// loadsave.cpp of OpenCV 4.6.0; tests/core/image_codecs_test.cpp compares both). OpenCV's
// imgcodecs is not linked: it loads 140 shared libraries (GDAL, poppler, HDF5, ...). Every other
// format, and the few cases OpenCV treats with code of its own (CMYK JPEG, an image rotated by
// an EXIF orientation OpenCV would parse differently, PNG with an eXIf chunk), are left to OpenCV
// through the previz_imgcodecs plugin (core/io.cpp).
#include <cstdint>
#include <optional>
#include <string>

#include <opencv2/core.hpp>

namespace previz::detail {

// The image in 'bytes' as cv::imread(file holding 'bytes', flags) gives it; nullopt when these
// codecs leave the bytes or the flags to OpenCV. Throws Error (no file context) when the bytes
// are a PNG or JPEG that does not decode (corrupt, truncated), saying why.
std::optional<cv::Mat> decodeImage(const std::string& bytes, int flags);

// validateInputImageSize (loadsave.cpp): width, height within OpenCV's limits, 2^20 a side and
// 2^30 pixels unless the environment's OPENCV_IO_MAX_IMAGE_WIDTH, _HEIGHT, _PIXELS say otherwise
// (read once, as OpenCV reads them). Throws Error (no file context) outside them. The EXR reader
// (core/io.cpp) applies them too: a 600-byte file declaring a huge data window made it allocate
// and zero gigabytes (fuzz/exr.cpp).
struct ImageLimits {
  std::uint64_t width, height, pixels;
};
const ImageLimits& imageLimits();
cv::Size checkedImageSize(std::uint64_t width, std::uint64_t height);

// cv::imencode(ext, image) without parameters for ".png" and ".jpg" / ".jpeg" / ".jpe" (any
// case); nullopt for any other extension. Throws Error (no file context) for an image these
// formats cannot hold (2 or more than 4 channels).
std::optional<std::string> encodeImage(const std::string& ext, const cv::Mat& image);

// How many images this process has read or written through the previz_imgcodecs plugin
// (core/io.cpp), so that a test can say which calls went to OpenCV whatever ran before it in the
// same process (pluginLoaded only says whether anything ever did).
std::uint64_t imgcodecsPluginCalls();

}  // namespace previz::detail
