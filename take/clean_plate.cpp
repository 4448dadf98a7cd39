// Clean plates of a take (Take::cleanPlate, see take.h): one still, or the per-pixel median of a
// plate video or sequence, computed once and cached under <take>/out/clean/.
#include <algorithm>
#include <cstdint>
#include <vector>

#include <opencv2/imgcodecs.hpp>

#include "core/error.h"
#include "core/io.h"
#include "take/detail/files.h"
#include "take/take.h"
#include "take/video.h"

namespace previz::take {
namespace fs = std::filesystem;

namespace {

constexpr int kMaxPlateFrames = 25;

ErrorContext plateContext(const fs::path& file, const std::string& camera) {
  ErrorContext c = fileContext(file.string());
  c.camera = camera;
  return c;
}

// Per-pixel median of 8-bit BGR frames, and the median over pixels of each pixel's spread (the
// median absolute deviation of its frames, grey levels): how still the plate was.
cv::Mat medianPlate(const std::vector<cv::Mat>& frames, double* spread) {
  const int n = static_cast<int>(frames.size());
  const cv::Size size = frames.front().size();
  cv::Mat out(size, CV_8UC3);
  std::vector<float> mad_rows(size.height);
#pragma omp parallel for schedule(static)
  for (int y = 0; y < size.height; ++y) {
    std::vector<std::uint8_t> v(n);
    std::vector<int> dev(n);
    std::vector<int> row_mad;
    row_mad.reserve(3 * size.width);
    std::uint8_t* o = out.ptr<std::uint8_t>(y);
    for (int i = 0; i < 3 * size.width; ++i) {
      for (int k = 0; k < n; ++k) v[k] = frames[k].ptr<std::uint8_t>(y)[i];
      std::nth_element(v.begin(), v.begin() + n / 2, v.end());
      const int m = v[n / 2];
      o[i] = static_cast<std::uint8_t>(m);
      for (int k = 0; k < n; ++k) dev[k] = std::abs(static_cast<int>(v[k]) - m);
      std::nth_element(dev.begin(), dev.begin() + n / 2, dev.end());
      row_mad.push_back(dev[n / 2]);
    }
    std::nth_element(row_mad.begin(), row_mad.begin() + row_mad.size() / 2, row_mad.end());
    mad_rows[y] = static_cast<float>(row_mad[row_mad.size() / 2]);
  }
  std::nth_element(mad_rows.begin(), mad_rows.begin() + mad_rows.size() / 2, mad_rows.end());
  if (spread) *spread = mad_rows[mad_rows.size() / 2];
  return out;
}

// Up to kMaxPlateFrames frames spread evenly over [0, count).
std::vector<long long> pickFrames(long long count) {
  std::vector<long long> picks;
  const long long n = std::min<long long>(count, kMaxPlateFrames);
  for (long long i = 0; i < n; ++i) picks.push_back(n == 1 ? 0 : i * (count - 1) / (n - 1));
  return picks;
}

}  // namespace

cv::Mat Take::cleanPlate(const std::string& camera) const {
  const CameraStream& s = stream(camera);
  std::error_code ec;
  const fs::path clean = dir_ / "clean";
  if (!fs::is_directory(clean, ec)) return {};

  // The source: a still, a video, or a sequence folder.
  fs::path source = detail::findByStem(clean, camera, detail::kStillExtensions);
  SourceKind kind = source.empty() ? SourceKind::kNone : SourceKind::kStill;
  if (source.empty()) {
    source = detail::findByStem(clean, camera, detail::kVideoExtensions);
    if (!source.empty()) kind = SourceKind::kVideo;
  }
  if (source.empty() && fs::is_directory(clean / camera, ec)) {
    source = clean / camera;
    kind = SourceKind::kSequence;
  }
  if (kind == SourceKind::kNone) return {};

  const auto checkSize = [&](const cv::Mat& plate) {
    if (s.width > 0 && (plate.cols != s.width || plate.rows != s.height))
      throw Error("clean plate is " + std::to_string(plate.cols) + "x" + std::to_string(plate.rows) +
                      ", the camera's frames " + std::to_string(s.width) + "x" + std::to_string(s.height),
                  plateContext(source, camera));
    return plate;
  };
  if (kind == SourceKind::kStill) {
    try {
      return checkSize(readImage8(source));
    } catch (const Error& e) {
      if (!e.context().file.empty()) throw;
      throw Error(e.message(), plateContext(source, camera));
    }
  }

  // A plate clip: the cache first (valid while the source's size and time are the same).
  const fs::path cache = dir_ / "out" / "clean" / (camera + ".png");
  const fs::path cache_info = dir_ / "out" / "clean" / (camera + ".json");
  const auto stamp = [&]() {
    nlohmann::json j = {{"source", source.lexically_relative(dir_).string()}};
    if (kind == SourceKind::kVideo) {
      j["size"] = fs::file_size(source, ec);
      j["mtime"] = static_cast<long long>(fs::last_write_time(source, ec).time_since_epoch().count());
    } else {
      long long files = 0, bytes = 0, newest = 0;
      for (const auto& e : fs::directory_iterator(source, ec)) {
        if (!e.is_regular_file(ec)) continue;
        ++files;
        bytes += static_cast<long long>(e.file_size(ec));
        newest = std::max<long long>(newest, e.last_write_time(ec).time_since_epoch().count());
      }
      j["files"] = files;
      j["size"] = bytes;
      j["mtime"] = newest;
    }
    return j;
  }();
  if (fs::is_regular_file(cache, ec) && fs::is_regular_file(cache_info, ec)) {
    try {
      const nlohmann::json info = readJsonFile(cache_info);
      if (info.value("stamp", nlohmann::json()) == stamp) return checkSize(readImage8(cache));
    } catch (const Error&) {
      // A damaged cache is recomputed.
    }
  }

  std::vector<cv::Mat> frames;
  if (kind == SourceKind::kVideo) {
    VideoReader reader(source, 0);
    const long long count = reader.decodableFrames();
    for (long long f : pickFrames(count)) {
      VideoReader::Frame fr = reader.read(f);
      if (fr.error.empty()) frames.push_back(toBgr8(fr.bgr));
    }
  } else {
    const std::vector<FoundSequence> found = findSequences(source);
    if (!found.empty())
      for (long long i : pickFrames(static_cast<long long>(found[0].frames.size()))) {
        try {
          frames.push_back(readImage8(source / found[0].pattern.fileName(found[0].frames[i])));
        } catch (const Error&) {
          // An unreadable plate frame is left out; the median needs only most of them.
        }
      }
  }
  if (frames.empty()) throw Error("no frame of the clean plate reads", plateContext(source, camera));
  for (const cv::Mat& f : frames)
    if (f.size() != frames.front().size())
      throw Error("the clean plate's frames differ in size", plateContext(source, camera));
  double spread = 0;
  const cv::Mat plate = checkSize(medianPlate(frames, &spread));
  try {
    writeImageAtomic(cache, plate);
    writeJsonAtomic(cache_info, {{"stamp", stamp},
                                 {"frames_used", frames.size()},
                                 {"median_spread", spread},
                                 {"what", "per-pixel median of the clean plate's frames (8-bit sRGB BGR); "
                                          "median_spread: median over pixels of each pixel's median absolute "
                                          "deviation, grey levels"}});
  } catch (const Error&) {
    // A read-only take: the plate is recomputed next time.
  }
  return plate;
}

}  // namespace previz::take
