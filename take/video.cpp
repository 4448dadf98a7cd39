// Video files of a take (video.h). The work is done by the previz_video plugin
// (detail/video_plugin.h, plugin/video.cpp), loaded on first use; the options are checked here,
// without it.
#include "take/video.h"

#include <cmath>
#include <sstream>

#include "core/error.h"
#include "core/plugin.h"
#include "take/detail/video_plugin.h"
#include "take/timecode.h"

namespace fs = std::filesystem;

namespace previz::take {

namespace detail {

const VideoPlugin& videoPlugin() {
  return pluginInterface<VideoPlugin>("previz_video", "previz_video_plugin",
                                      "video files and live cameras: FFmpeg, OpenCV's videoio");
}

}  // namespace detail

namespace {

// "29.97", "25" rather than std::to_string's "29.970000".
std::string number(double value) {
  std::ostringstream s;
  s << value;
  return s.str();
}

}  // namespace

// ---- options --------------------------------------------------------------------------------

void VideoWriterOptions::validate() const {
  if (codec != "ffv1" && codec != "h264" && codec != "prores")
    throw Error("video: codec must be ffv1, h264 or prores (got '" + codec + "')", fieldContext("codec"));
  if (!(fps > 0) || !std::isfinite(fps))
    throw Error("video: fps must be > 0 (got " + number(fps) + ")", fieldContext("fps"));
  if (crf < 0 || crf > 51)
    throw Error("video: crf must be in 0..51 (got " + std::to_string(crf) + ")", fieldContext("crf"));
  if (threads < 0)
    throw Error("video: threads must be >= 0 (got " + std::to_string(threads) + ")", fieldContext("threads"));
  if (start_timecode.empty()) return;
  const auto tc = parseTimecode(start_timecode);
  if (!tc)
    throw Error("video: start_timecode must be HH:MM:SS:FF or HH:MM:SS;FF (got '" + start_timecode + "')",
                fieldContext("start_timecode"));
  try {
    timecodeToFrames(*tc, fps);
  } catch (const Error& e) {
    throw Error("video: start_timecode " + e.message(), fieldContext("start_timecode"));
  }
  // FFmpeg's muxers accept drop frame only at exactly 30000/1001 and 60000/1001 (and would
  // silently write no timecode otherwise).
  if (tc->drop_frame && detail::ntscRateNumerator(fps) == 0)
    throw Error("video: a drop-frame start_timecode needs fps 29.97 or 59.94 (got " + number(fps) + ")",
                fieldContext("start_timecode"));
}

// ---- writer, probe, reader: the plugin's ------------------------------------------------------

struct VideoWriter::Impl {
  std::unique_ptr<detail::VideoFileWriter> writer;
};

VideoWriter::VideoWriter(const fs::path& path, cv::Size size, const VideoWriterOptions& options)
    : impl_(std::make_unique<Impl>()) {
  options.validate();
  impl_->writer = detail::videoPlugin().open_writer(path, size, options);
}
VideoWriter::~VideoWriter() = default;
VideoWriter::VideoWriter(VideoWriter&&) noexcept = default;
VideoWriter& VideoWriter::operator=(VideoWriter&&) noexcept = default;
void VideoWriter::write(const cv::Mat& bgr) { impl_->writer->write(bgr); }
void VideoWriter::close() { impl_->writer->close(); }
long long VideoWriter::framesWritten() const { return impl_->writer->framesWritten(); }

VideoProbe probeVideo(const fs::path& path) { return detail::videoPlugin().probe(path); }

struct VideoReader::Impl {
  fs::path path;
  std::unique_ptr<detail::VideoFileReader> reader;
};

VideoReader::VideoReader(const fs::path& path, int prefetch) : impl_(std::make_unique<Impl>()) {
  impl_->path = path;
  impl_->reader = detail::videoPlugin().open_reader(path, prefetch);
}
VideoReader::~VideoReader() = default;
VideoReader::Frame VideoReader::read(long long index) { return impl_->reader->read(index); }
long long VideoReader::decodableFrames() { return impl_->reader->decodableFrames(); }
const fs::path& VideoReader::path() const { return impl_->path; }

}  // namespace previz::take
