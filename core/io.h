#pragma once
// File output that never leaves a half-written file (write to a temporary beside the target,
// then rename), and image / EXR / JSON readers that throw previz::Error naming the file.
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "core/error.h"

namespace previz {

// Writes bytes to path atomically (temp file in the same folder + rename). Creates parent
// folders. Throws Error naming the file on failure.
void writeFileAtomic(const std::filesystem::path& path, const std::string& bytes);
void writeJsonAtomic(const std::filesystem::path& path, const nlohmann::json& j, int indent = 2);
// Images as cv::imwrite / cv::imread give them, byte for byte. PNG and JPEG go through libpng
// and libjpeg directly (detail/image_codecs.h); any other format OpenCV knows (.tif, .bmp, ...)
// through OpenCV's imgcodecs in the previz_imgcodecs plugin, loaded then (core/plugin.h).
// The bytes cv::imencode gives for path's extension (.png, .jpg, ...); errors name the file.
std::string encodeImage(const std::filesystem::path& path, const cv::Mat& image);
// encodeImage written atomically.
void writeImageAtomic(const std::filesystem::path& path, const cv::Mat& image);

std::string readTextFile(const std::filesystem::path& path);
nlohmann::json readJsonFile(const std::filesystem::path& path);

// A JSON value as an int, checked. nlohmann's get<int>() (also value(key, 0) and
// get<std::vector<int>>()) converts a float or a wider integer unchecked: 1e10 is undefined
// behaviour, 4294967297 becomes 1 (found by fuzz/). An integer, or a float with an integral
// value, that fits an int; else nullopt / an Error with 'context' saying what was there.
std::optional<int> jsonInt(const nlohmann::json& v);
int jsonInt(const nlohmann::json& v, const ErrorContext& context);
// Every element of an array so (an Error for anything else).
std::vector<int> jsonInts(const nlohmann::json& v, const ErrorContext& context);
// cv::imread(path, flags) with a clear error (missing file / not an image / empty) naming the file.
cv::Mat readImage(const std::filesystem::path& path, int flags = -1 /* IMREAD_UNCHANGED */);

// Float EXR images (OpenEXR, uncompressed-or-ZIP, FLOAT channels), written atomically.
// 'image' is CV_32FC1 (one channel, named channels[0]) or CV_32FC2/3/4 with as many names.
// 'attributes' become string header attributes (e.g. "previz:pixel_origin").
struct ExrImage {
  cv::Mat image;                                   // CV_32FC(n)
  std::vector<std::string> channels;               // one name per channel
  std::map<std::string, std::string> attributes;   // string attributes in the header
  // Store the channels as 16-bit HALF (colour, as render engines deliver it: half the size;
  // relative precision 2^-11). Depth and ST maps stay FLOAT. Reading always gives CV_32F.
  bool half = false;
  // The standard "timeCode" attribute (SMPTE 12M, as cameras and conform tools write it), as
  // "HH:MM:SS:FF" ("HH:MM:SS;FF" drop frame); "" = none.
  std::string timecode = {};
};
void writeExr(const std::filesystem::path& path, const ExrImage& exr);
ExrImage readExr(const std::filesystem::path& path);

// Depth maps: metric z along the camera axis, +inf where empty, channel "Z".
void writeDepthExr(const std::filesystem::path& path, const cv::Mat& depth_m,
                   std::map<std::string, std::string> attributes = {});
cv::Mat readDepthExr(const std::filesystem::path& path);

}  // namespace previz
