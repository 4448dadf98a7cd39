// Writing one camera's stream (see stream_writer.h).
#include "take/stream_writer.h"

#include <cmath>

#include "core/error.h"
#include "core/io.h"
#include "core/names.h"
#include "core/srgb.h"
#include "take/detail/files.h"
#include "take/sequence.h"
#include "take/timecode.h"
#include "take/video.h"

namespace previz::take {
namespace fs = std::filesystem;

namespace {

std::string extensionOf(const std::string& format) {
  if (format == "png" || format == "png16") return ".png";
  if (format == "jpg") return ".jpg";
  if (format == "tif16") return ".tif";
  if (format == "exr") return ".exr";
  if (format == "ffv1") return ".mkv";
  if (format == "h264") return ".mp4";
  if (format == "prores") return ".mov";
  throw Error("format must be png|jpg|png16|tif16|exr|ffv1|h264|prores (got '" + format + "')", fieldContext("format"));
}

// The picture before 8-bit quantisation when given, else the 8-bit codes, as sRGB-coded floats.
cv::Mat encodedOf(const cv::Mat& bgr8, const cv::Mat& encoded) {
  if (!encoded.empty()) return encoded;
  cv::Mat f;
  bgr8.convertTo(f, CV_32FC3, 1.0 / 255.0);
  return f;
}

}  // namespace

void StreamWriterOptions::validate() const {
  extensionOf(format);
  if (!(fps > 0) || !std::isfinite(fps)) throw Error("fps must be > 0", fieldContext("fps"));
  if (first_number < 0) throw Error("first_number must be >= 0", fieldContext("first_number"));
  if (!start_timecode.empty() && !parseTimecode(start_timecode))
    throw Error("start_timecode must be HH:MM:SS:FF (got '" + start_timecode + "')", fieldContext("start_timecode"));
  if (!pattern.empty() && !parsePattern(pattern))
    throw Error("pattern needs one frame field (%04d, %d or ####): '" + pattern + "'", fieldContext("pattern"));
}

bool StreamWriterOptions::isVideo() const { return format == "ffv1" || format == "h264" || format == "prores"; }

StreamPlacement placeStream(const StreamWriterOptions& base, long long first_frame) {
  base.validate();
  StreamPlacement p;
  p.writer = base;
  const bool carries_timecode = base.isVideo() || base.format == "exr";
  if (!base.start_timecode.empty() && carries_timecode) {
    const Timecode tc = *parseTimecode(base.start_timecode);
    p.writer.start_timecode = formatTimecode(
        framesToTimecode(timecodeToFrames(tc, base.fps) + first_frame, base.fps, tc.drop_frame));
    return p;
  }
  p.writer.start_timecode.clear();
  if (base.isVideo()) {
    if (first_frame != 0) p.offset = -first_frame;
  } else {
    p.writer.first_number = base.first_number + first_frame;
    if (base.first_number != 0) p.offset = base.first_number;
  }
  return p;
}

struct StreamWriter::Impl {
  StreamWriterOptions options;
  fs::path take_dir, dir;
  std::string camera;
  cv::Size size;
  SequencePattern pattern;
  std::unique_ptr<VideoWriter> video;
  fs::path video_path;
  long long written = 0;
  long long tc_first = 0;  // frames since midnight of start_timecode
  bool drop_frame = false;
};

StreamWriter::StreamWriter(const fs::path& take_dir, const std::string& camera, cv::Size size,
                           const StreamWriterOptions& options)
    : impl_(std::make_unique<Impl>()) {
  options.validate();
  Impl& m = *impl_;
  m.options = options;
  m.take_dir = take_dir;
  m.camera = camera;
  m.size = size;
  if (!options.start_timecode.empty()) {
    const Timecode tc = *parseTimecode(options.start_timecode);
    m.tc_first = timecodeToFrames(tc, options.fps);
    m.drop_frame = tc.drop_frame;
  }
  if (options.isVideo()) {
    m.video_path = take_dir / "cams" / (camera + extensionOf(options.format));
    VideoWriterOptions vo;
    vo.codec = options.format;
    vo.fps = options.fps;
    vo.start_timecode = options.start_timecode;
    m.video = std::make_unique<VideoWriter>(m.video_path, size, vo);
  } else {
    const std::string text =
        detail::replaceAll(options.pattern.empty() ? std::string(kFramePattern) : options.pattern, "{camera}", camera) +
        extensionOf(options.format);
    m.pattern = *parsePattern(text);
    m.dir = take_dir / "cams" / camera;
  }
}

StreamWriter::~StreamWriter() = default;
StreamWriter::StreamWriter(StreamWriter&&) noexcept = default;
StreamWriter& StreamWriter::operator=(StreamWriter&&) noexcept = default;

void StreamWriter::write(const cv::Mat& bgr8, const cv::Mat& encoded) {
  Impl& m = *impl_;
  if (bgr8.type() != CV_8UC3 || bgr8.size() != m.size) {
    ErrorContext c = fieldContext("frame");
    c.camera = m.camera;
    throw Error("stream writer: expected an 8-bit BGR frame of " + std::to_string(m.size.width) + "x" +
                    std::to_string(m.size.height),
                c);
  }
  if (m.video) {
    m.video->write(bgr8);
    ++m.written;
    return;
  }
  const fs::path path = m.dir / m.pattern.fileName(m.options.first_number + m.written);
  const std::string& f = m.options.format;
  if (f == "png" || f == "jpg") {
    writeImageAtomic(path, bgr8);
  } else if (f == "png16" || f == "tif16") {
    cv::Mat wide;
    encodedOf(bgr8, encoded).convertTo(wide, CV_16UC3, 65535.0);  // rounded, saturated
    writeImageAtomic(path, wide);
  } else {  // exr: linear light, R G B
    const cv::Mat enc = encodedOf(bgr8, encoded);
    ExrImage exr;
    exr.image.create(enc.size(), CV_32FC3);
    for (int y = 0; y < enc.rows; ++y) {
      const float* in = enc.ptr<float>(y);
      float* out = exr.image.ptr<float>(y);
      for (int x = 0; x < enc.cols; ++x)
        for (int c = 0; c < 3; ++c) out[3 * x + c] = static_cast<float>(srgbDecode(in[3 * x + 2 - c]));
    }
    exr.channels = {"R", "G", "B"};
    if (!m.options.start_timecode.empty())
      exr.timecode = formatTimecode(framesToTimecode(m.tc_first + m.written, m.options.fps, m.drop_frame));
    writeExr(path, exr);
  }
  ++m.written;
}

void StreamWriter::skip() {
  if (impl_->video) {
    ErrorContext c = fileContext(impl_->video_path.string());
    c.camera = impl_->camera;
    throw Error("a video has no holes: frame " + std::to_string(impl_->written) + " of the stream is missing", c);
  }
  ++impl_->written;
}

void StreamWriter::close() {
  if (impl_->video) impl_->video->close();
}

std::string StreamWriter::source() const {
  const Impl& m = *impl_;
  if (m.video) return m.video_path.lexically_relative(m.take_dir).string();
  return (m.dir / m.pattern.str()).lexically_relative(m.take_dir).string();
}

long long StreamWriter::framesWritten() const { return impl_->written; }

}  // namespace previz::take
