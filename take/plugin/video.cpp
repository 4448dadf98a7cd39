// The previz_video plugin (take/detail/video_plugin.h): the writer, probe and reader of
// take/video.h and the live capture of take/live.h, on FFmpeg's libavcodec / libavformat and
// OpenCV's FFmpeg backend (videoio). Errors are previz::Error, as video.h says.
#include <unistd.h>

#include <atomic>
#include <cmath>
#include <condition_variable>
#include <map>
#include <mutex>
#include <optional>
#include <thread>

#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

extern "C" {
#include <libavcodec/avcodec.h>
#include <libavformat/avformat.h>
#include <libavutil/opt.h>
#include <libavutil/pixdesc.h>
#include <libswscale/swscale.h>
}

#include "core/error.h"
#include "core/plugin.h"
#include "take/detail/video_plugin.h"

namespace fs = std::filesystem;

namespace previz::take {

namespace {

// ---- libav plumbing -------------------------------------------------------------------------

// OpenCV's FFmpeg backend sets the same level when it first opens a file; before that (a
// writer or a probe first) libav would print x264's statistics and every demuxer warning.
// Failures reach the caller as Error, with av_strerror's text.
void quietLibav() {
  static std::once_flag once;
  std::call_once(once, [] { av_log_set_level(AV_LOG_ERROR); });
}

std::string avError(int code) {
  char text[AV_ERROR_MAX_STRING_SIZE] = {};
  av_strerror(code, text, sizeof text);
  return text;
}

void check(int ret, const std::string& what, const fs::path& path) {
  if (ret < 0) throw Error(what + ": " + avError(ret), fileContext(path.string()));
}

struct InputDeleter {
  void operator()(AVFormatContext* c) const { avformat_close_input(&c); }
};
struct OutputDeleter {
  void operator()(AVFormatContext* c) const {
    if (c->pb && !(c->oformat->flags & AVFMT_NOFILE)) avio_closep(&c->pb);
    avformat_free_context(c);
  }
};
struct CodecDeleter {
  void operator()(AVCodecContext* c) const { avcodec_free_context(&c); }
};
struct FrameDeleter {
  void operator()(AVFrame* f) const { av_frame_free(&f); }
};
struct PacketDeleter {
  void operator()(AVPacket* p) const { av_packet_free(&p); }
};
struct SwsDeleter {
  void operator()(SwsContext* s) const { sws_freeContext(s); }
};
using InputPtr = std::unique_ptr<AVFormatContext, InputDeleter>;
using OutputPtr = std::unique_ptr<AVFormatContext, OutputDeleter>;
using CodecPtr = std::unique_ptr<AVCodecContext, CodecDeleter>;
using FramePtr = std::unique_ptr<AVFrame, FrameDeleter>;
using PacketPtr = std::unique_ptr<AVPacket, PacketDeleter>;
using SwsPtr = std::unique_ptr<SwsContext, SwsDeleter>;

AVRational frameRate(double fps) {
  if (const int numerator = detail::ntscRateNumerator(fps)) return AVRational{numerator, 1001};
  return av_d2q(fps, 1000000);
}

struct CodecChoice {
  const char* encoder;
  AVPixelFormat pix_fmt;
};

CodecChoice codecChoice(const std::string& codec) {
  if (codec == "ffv1") return {"ffv1", AV_PIX_FMT_BGR0};
  if (codec == "h264") return {"libx264", AV_PIX_FMT_YUV420P};
  return {"prores_ks", AV_PIX_FMT_YUV422P10LE};
}

// A temporary beside the target, removed unless kept (the writer renamed it into place).
struct TempFile {
  fs::path path;
  bool kept = false;
  ~TempFile() {
    std::error_code ec;
    if (!kept && !path.empty()) fs::remove(path, ec);
  }
};

fs::path temporaryBeside(const fs::path& path) {
  static std::atomic<unsigned long> counter{0};
  return path.parent_path() / ("." + path.filename().string() + ".tmp." + std::to_string(::getpid()) +
                               "." + std::to_string(counter.fetch_add(1)));
}

// ---- writer ---------------------------------------------------------------------------------

class FileWriter final : public detail::VideoFileWriter {
 public:
  fs::path path;
  cv::Size size;
  VideoWriterOptions options;
  // Declared before the libav objects so that it is destroyed after them: the file is closed
  // before the temporary is removed.
  TempFile temp;
  OutputPtr format;
  CodecPtr encoder;
  AVStream* stream = nullptr;  // owned by format
  FramePtr bgr_frame;          // a padded copy of the caller's image (swscale's SIMD reads past rows)
  FramePtr frame;              // what the encoder gets
  PacketPtr packet;
  SwsPtr sws;                  // BGR24 -> yuv (h264, prores)
  long long frames = 0;
  bool closed = false;
  bool failed = false;

  FileWriter(const fs::path& target, cv::Size image_size, const VideoWriterOptions& opts)
      : path(target), size(image_size), options(opts) {
    quietLibav();
    const std::string file = path.string();
    if (size.width <= 0 || size.height <= 0)
      throw Error("video size must be positive (got " + std::to_string(size.width) + "x" +
                      std::to_string(size.height) + ")", fileContext(file));
    const CodecChoice choice = codecChoice(options.codec);
    if (choice.pix_fmt != AV_PIX_FMT_BGR0 && (size.width % 2 || size.height % 2))
      throw Error(options.codec + " needs an even width and height (got " + std::to_string(size.width) + "x" +
                      std::to_string(size.height) + ")", fileContext(file, "codec"));
    const AVCodec* codec = avcodec_find_encoder_by_name(choice.encoder);
    if (!codec)
      throw Error(std::string("this FFmpeg build has no encoder '") + choice.encoder + "' (codec " +
                      options.codec + ")", fileContext(file, "codec"));

    // The container is chosen by the target's name; the bytes go to the temporary.
    AVFormatContext* raw = nullptr;
    const int ret = avformat_alloc_output_context2(&raw, nullptr, nullptr, file.c_str());
    if (ret < 0 || !raw)
      throw Error("no container for the extension '" + path.extension().string() + "' (.mkv, .mov, .mp4, .avi)",
                  fileContext(file));
    format.reset(raw);

    encoder.reset(avcodec_alloc_context3(codec));
    if (!encoder) throw Error("cannot allocate the " + options.codec + " encoder", fileContext(file));
    const AVRational rate = frameRate(options.fps);
    encoder->width = size.width;
    encoder->height = size.height;
    encoder->pix_fmt = choice.pix_fmt;
    encoder->time_base = av_inv_q(rate);
    encoder->framerate = rate;
    encoder->thread_count = options.threads;
    if (options.codec == "ffv1") {
      // Level 3: slices (multithreaded coding) with CRCs; GOP 1: every frame a keyframe, so a
      // seek lands exactly and a damaged frame spoils no other.
      encoder->level = 3;
      encoder->gop_size = 1;
    } else {
      // OpenCV's reader converts yuv with swscale's default, BT.601 limited range; the writer
      // uses the same so that BGR comes back as close as the codec allows, and says so.
      encoder->colorspace = AVCOL_SPC_SMPTE170M;
      encoder->color_range = AVCOL_RANGE_MPEG;
      if (options.codec == "h264")
        check(av_opt_set(encoder->priv_data, "crf", std::to_string(options.crf).c_str(), 0), "setting crf", path);
    }
    if (format->oformat->flags & AVFMT_GLOBALHEADER) encoder->flags |= AV_CODEC_FLAG_GLOBAL_HEADER;
    check(avcodec_open2(encoder.get(), codec, nullptr), "opening the " + options.codec + " encoder", path);

    stream = avformat_new_stream(format.get(), nullptr);
    if (!stream) throw Error("cannot add a video stream", fileContext(file));
    check(avcodec_parameters_from_context(stream->codecpar, encoder.get()), "setting the stream's parameters", path);
    stream->time_base = encoder->time_base;
    stream->avg_frame_rate = rate;
    stream->r_frame_rate = rate;
    if (!options.start_timecode.empty()) {
      // Matroska keeps the stream's tag; MOV/MP4 write a tmcd track from the format's (or the
      // stream's) "timecode" entry.
      av_dict_set(&stream->metadata, "timecode", options.start_timecode.c_str(), 0);
      av_dict_set(&format->metadata, "timecode", options.start_timecode.c_str(), 0);
    }

    std::error_code ec;
    if (!path.parent_path().empty()) fs::create_directories(path.parent_path(), ec);
    if (ec) throw Error("cannot create folder '" + path.parent_path().string() + "': " + ec.message(), fileContext(file));
    temp.path = temporaryBeside(path);
    check(avio_open(&format->pb, temp.path.c_str(), AVIO_FLAG_WRITE), "cannot create the temporary file", path);
    // A muxer refuses a codec it has no tag for here (FFV1 in .mp4): say which.
    check(avformat_write_header(format.get(), nullptr),
          "writing the " + path.extension().string() + " header (can it hold " + options.codec + "? .mkv holds every codec)",
          path);

    frame.reset(av_frame_alloc());
    packet.reset(av_packet_alloc());
    if (!frame || !packet) throw Error("out of memory", fileContext(file));
    frame->format = choice.pix_fmt;
    frame->width = size.width;
    frame->height = size.height;
    check(av_frame_get_buffer(frame.get(), 0), "allocating a frame", path);
    if (choice.pix_fmt != AV_PIX_FMT_BGR0) {
      bgr_frame.reset(av_frame_alloc());
      if (!bgr_frame) throw Error("out of memory", fileContext(file));
      bgr_frame->format = AV_PIX_FMT_BGR24;
      bgr_frame->width = size.width;
      bgr_frame->height = size.height;
      check(av_frame_get_buffer(bgr_frame.get(), 0), "allocating a frame", path);
      sws.reset(sws_getContext(size.width, size.height, AV_PIX_FMT_BGR24, size.width, size.height, choice.pix_fmt,
                               SWS_BICUBIC | SWS_ACCURATE_RND | SWS_FULL_CHR_H_INP, nullptr, nullptr, nullptr));
      if (!sws) throw Error("cannot convert BGR to " + std::string(av_get_pix_fmt_name(choice.pix_fmt)), fileContext(file));
      const int* bt601 = sws_getCoefficients(SWS_CS_ITU601);
      sws_setColorspaceDetails(sws.get(), bt601, /*srcRange full*/ 1, bt601, /*dstRange limited*/ 0, 0, 1 << 16, 1 << 16);
    }
  }

  // Sends one frame (nullptr: flush) and writes every packet the encoder has ready.
  void encode(const AVFrame* f) {
    check(avcodec_send_frame(encoder.get(), f), "encoding frame " + std::to_string(frames), path);
    for (;;) {
      const int ret = avcodec_receive_packet(encoder.get(), packet.get());
      if (ret == AVERROR(EAGAIN) || ret == AVERROR_EOF) return;
      check(ret, "encoding", path);
      // One frame long, so that the container's duration covers the last frame.
      if (packet->duration == 0) packet->duration = 1;
      av_packet_rescale_ts(packet.get(), encoder->time_base, stream->time_base);
      packet->stream_index = stream->index;
      check(av_interleaved_write_frame(format.get(), packet.get()), "writing a packet", path);
    }
  }

  void write(const cv::Mat& bgr) override {
    const std::string file = path.string();
    if (closed) throw Error("write after close()", fileContext(file));
    if (failed) throw Error("the writer failed earlier; the file is not written", fileContext(file));
    ErrorContext context = fileContext(file);
    context.frame = static_cast<int>(frames);
    if (bgr.type() != CV_8UC3 || bgr.size() != size)
      throw Error("the image is " + cv::typeToString(bgr.type()) + " " + std::to_string(bgr.cols) + "x" +
                      std::to_string(bgr.rows) + "; the video takes CV_8UC3 " + std::to_string(size.width) + "x" +
                      std::to_string(size.height), context);
    failed = true;  // until this frame is through
    check(av_frame_make_writable(frame.get()), "preparing a frame", path);
    if (sws) {
      cv::Mat padded(size, CV_8UC3, bgr_frame->data[0], static_cast<size_t>(bgr_frame->linesize[0]));
      bgr.copyTo(padded);
      sws_scale(sws.get(), bgr_frame->data, bgr_frame->linesize, 0, size.height, frame->data, frame->linesize);
    } else {
      cv::Mat bgr0(size, CV_8UC4, frame->data[0], static_cast<size_t>(frame->linesize[0]));
      cv::cvtColor(bgr, bgr0, cv::COLOR_BGR2BGRA);
    }
    frame->pts = frames;
    encode(frame.get());
    ++frames;
    failed = false;
  }

  long long framesWritten() const override { return frames; }

  void close() override {
    if (closed) return;
    const std::string file = path.string();
    if (failed) throw Error("the writer failed earlier; the file is not written", fileContext(file));
    failed = true;
    encode(nullptr);
    check(av_write_trailer(format.get()), "writing the container trailer", path);
    check(avio_closep(&format->pb), "closing the temporary file", path);
    std::error_code ec;
    fs::rename(temp.path, path, ec);
    if (ec) throw Error("cannot move the temporary file into place: " + ec.message(), fileContext(file));
    temp.kept = true;
    closed = true;
    failed = false;
  }
};

// ---- probe ----------------------------------------------------------------------------------

VideoProbe probeFile(const fs::path& path) {
  quietLibav();
  const std::string file = path.string();
  AVFormatContext* raw = nullptr;
  const int opened = avformat_open_input(&raw, file.c_str(), nullptr, nullptr);
  if (opened < 0) throw Error("cannot open as a video: " + avError(opened), fileContext(file));
  InputPtr input(raw);
  check(avformat_find_stream_info(input.get(), nullptr), "not a video (no stream information)", path);
  const int index = av_find_best_stream(input.get(), AVMEDIA_TYPE_VIDEO, -1, -1, nullptr, 0);
  if (index < 0) throw Error("not a video: no video stream", fileContext(file));
  const AVStream* stream = input->streams[index];
  const AVCodecParameters* par = stream->codecpar;

  VideoProbe probe;
  probe.codec = avcodec_get_name(par->codec_id);
  const auto pix_fmt = static_cast<AVPixelFormat>(par->format);
  if (const char* name = av_get_pix_fmt_name(pix_fmt)) probe.pix_fmt = name;
  if (const AVPixFmtDescriptor* desc = av_pix_fmt_desc_get(pix_fmt)) probe.bit_depth = desc->comp[0].depth;
  probe.width = par->width;
  probe.height = par->height;
  const AVRational rate = stream->avg_frame_rate.num > 0 ? stream->avg_frame_rate : stream->r_frame_rate;
  if (rate.num > 0 && rate.den > 0) probe.fps = av_q2d(rate);
  probe.header_frames = stream->nb_frames > 0 ? stream->nb_frames : -1;
  if (input->duration != AV_NOPTS_VALUE)
    probe.duration_s = static_cast<double>(input->duration) / AV_TIME_BASE;
  else if (stream->duration != AV_NOPTS_VALUE)
    probe.duration_s = static_cast<double>(stream->duration) * av_q2d(stream->time_base);

  // Where containers keep the start timecode: the video stream's tag (Matroska), the format's,
  // or the tmcd data stream of MOV/MP4.
  const AVDictionaryEntry* tc = av_dict_get(stream->metadata, "timecode", nullptr, 0);
  if (!tc) tc = av_dict_get(input->metadata, "timecode", nullptr, 0);
  for (unsigned i = 0; !tc && i < input->nb_streams; ++i)
    tc = av_dict_get(input->streams[i]->metadata, "timecode", nullptr, 0);
  if (tc) probe.timecode = tc->value;

  // Demux to the end without decoding; a file cut short stops at the read error.
  PacketPtr packet(av_packet_alloc());
  if (!packet) throw Error("out of memory", fileContext(file));
  for (;;) {
    const int ret = av_read_frame(input.get(), packet.get());
    if (ret == AVERROR(EAGAIN)) continue;
    if (ret == AVERROR_EOF) break;
    if (ret < 0) {
      probe.demux_error = avError(ret);
      break;
    }
    if (packet->stream_index == index) ++probe.packets;
    av_packet_unref(packet.get());
  }
  return probe;
}

// ---- reader --------------------------------------------------------------------------------

constexpr long long kUnknown = -1;

// One cv::VideoCapture and what is known of its position. A frame's index is its place in
// decoding order from the start of the file; a position is "known" only when reached that way
// or by a seek that was checked. Not thread-safe: FileReader lends it to one thread at a
// time. Never throws: OpenCV's exceptions count as frames that do not decode.
class Decoder {
 public:
  explicit Decoder(const fs::path& path) : path_(path) {
    try {
      open();
    } catch (const cv::Exception& e) {
      throw Error(std::string("cannot open as a video: ") + e.what(), fileContext(path.string()));
    }
    if (!capture_.isOpened()) throw Error("cannot open as a video (OpenCV's FFmpeg backend)", fileContext(path.string()));
    fps_ = capture_.get(cv::CAP_PROP_FPS);
  }

  long long next() const { return next_; }       // the frame decoded next (kUnknown: unknown)
  long long endSeen() const { return end_seen_; }  // where decoding in order stopped (kUnknown: never)

  // Decodes frame next() (which must be known). False at the end of what decodes.
  bool decodeNext(cv::Mat& image) {
    const long long index = next_;
    if (!read(image)) {
      if (end_seen_ == kUnknown || index < end_seen_) end_seen_ = index;
      next_ = kUnknown;
      return false;
    }
    if (index == 1 && !ts_offset_) {
      if (const auto ts = timestampFrame()) ts_offset_ = *ts - 1;
    }
    next_ = index + 1;
    return true;
  }

  // Decodes frame 'index' exactly. OpenCV's seek (av_seek_frame to a keyframe at least 16
  // frames before, then decoding forward, counting frames from the timestamps) is exact for the
  // files tests/take/video_test.cpp checks: FFV1, H.264 with B-frames over one or several GOPs,
  // ProRes; .mkv, .mp4, .mov, .avi. Where it misses (it clamps to the header's frame count, gives
  // up when no timestamp lands before the target, and cannot seek a file whose index was cut
  // off: an .avi cut short), either its frame counter or the frame's timestamp says so, and the
  // frame is decoded forward from the start instead: slow, but exact by definition. False when
  // the seek found no frame (which may be wrong: see FileReader::read).
  bool seek(long long index, cv::Mat& image) {
    if (!calibrated_) calibrate(image);
    bool ok = false;
    try {
      ok = capture_.set(cv::CAP_PROP_POS_FRAMES, static_cast<double>(index));
    } catch (const cv::Exception&) {
      ok = false;
    }
    if (!ok || !read(image)) {
      next_ = kUnknown;
      return false;
    }
    if (landedOn(index)) {
      next_ = index + 1;
      return true;
    }
    return decodeFromStart(index, image);
  }

  // Reopens the file and decodes forward to frame 'index'.
  bool decodeFromStart(long long index, cv::Mat& image) {
    if (!restart()) return false;
    while (decodeNext(image))
      if (next_ == index + 1) return true;
    return false;
  }

  bool restart() {
    next_ = kUnknown;
    try {
      if (!open()) return false;
    } catch (const cv::Exception&) {
      return false;
    }
    next_ = 0;
    return true;
  }

 private:
  bool open() {
    return capture_.open(path_.string(), cv::CAP_FFMPEG, {cv::CAP_PROP_HW_ACCELERATION, cv::VIDEO_ACCELERATION_NONE});
  }

  bool read(cv::Mat& image) {
    try {
      image = cv::Mat();  // a fresh buffer: frames handed out must not share one
      return capture_.read(image) && !image.empty();
    } catch (const cv::Exception&) {
      return false;
    }
  }

  // The frame number the last frame's timestamp gives (OpenCV's own mapping: time * fps).
  // OpenCV reports 0 ms for a frame without a timestamp (those drained from the decoder at the
  // end of the file): none then.
  std::optional<long long> timestampFrame() {
    const double ms = capture_.get(cv::CAP_PROP_POS_MSEC);
    if (ms == 0 || !(fps_ > 0)) return std::nullopt;
    return std::llround(ms * fps_ / 1000.0);
  }

  // Frame 1's timestamp, decoded in order, fixes the offset of timestamps to indices (B-frame
  // delay in .avi; frame 0's timestamp is not used: OpenCV takes the packet's dts for a 0 pts).
  void calibrate(cv::Mat& scratch) {
    calibrated_ = true;
    if (!ts_offset_) decodeFromStart(1, scratch);
  }

  bool landedOn(long long index) {
    if (std::llround(capture_.get(cv::CAP_PROP_POS_FRAMES)) != index + 1) return false;
    const auto ts = timestampFrame();
    return !ts_offset_ || !ts || *ts - *ts_offset_ == index;
  }

  fs::path path_;
  cv::VideoCapture capture_;
  double fps_ = 0;
  long long next_ = 0;
  long long end_seen_ = kUnknown;
  bool calibrated_ = false;
  std::optional<long long> ts_offset_;  // timestamp frame - index
};

class FileReader final : public detail::VideoFileReader {
 public:
  fs::path path;
  int prefetch = 0;

  std::mutex mutex;
  std::condition_variable changed;
  // Used outside the lock by whoever set 'decoding' (the worker or one read()); its position is
  // read under the lock only while no one holds it.
  Decoder decoder;
  bool decoding = false;
  int readers_waiting = 0;       // read() calls waiting for the decoder: the worker leaves it to them
  long long wanted = -1;         // the last frame asked for; the worker decodes to wanted + prefetch
  long long end = kUnknown;      // how many frames decode, once known
  std::map<long long, cv::Mat> ready;  // decoded frames >= wanted
  bool stop = false;
  std::thread worker;

  // Decoding forward this far is as cheap as a seek (which decodes from 16 frames before, or
  // from a keyframe further back) and always exact.
  static constexpr long long kMaxDecodeForward = 16;

  FileReader(const fs::path& p, int prefetch_frames)
      : path(p), prefetch(std::max(0, prefetch_frames)), decoder(existingFile(p)) {
    if (prefetch > 0) worker = std::thread([this] { run(); });
  }

  ~FileReader() override {
    {
      std::lock_guard<std::mutex> lock(mutex);
      stop = true;
    }
    changed.notify_all();
    if (worker.joinable()) worker.join();
  }

  static const fs::path& existingFile(const fs::path& p) {
    if (!fs::is_regular_file(p)) throw Error("no such video file", fileContext(p.string()));
    return p;
  }

  // Runs 'op' on the decoder with the lock released; the caller holds the lock and no one holds
  // the decoder. What the decoder learnt about the end is kept.
  template <class Op>
  bool withDecoder(std::unique_lock<std::mutex>& lock, Op op) {
    decoding = true;
    lock.unlock();
    const bool ok = op();
    lock.lock();
    decoding = false;
    const long long seen = decoder.endSeen();
    if (seen != kUnknown && (end == kUnknown || seen < end)) end = seen;
    changed.notify_all();
    return ok;
  }

  void waitForDecoder(std::unique_lock<std::mutex>& lock) {
    ++readers_waiting;
    changed.wait(lock, [this] { return !decoding; });
    if (--readers_waiting == 0) changed.notify_all();  // the worker may go on
  }

  void decodeNext(std::unique_lock<std::mutex>& lock) {
    const long long index = decoder.next();
    cv::Mat image;
    if (withDecoder(lock, [&] { return decoder.decodeNext(image); }) && index >= wanted)
      ready[index] = std::move(image);
  }

  void run() {
    std::unique_lock<std::mutex> lock(mutex);
    for (;;) {
      changed.wait(lock, [this] {
        if (stop) return true;
        if (decoding || readers_waiting > 0) return false;
        const long long next = decoder.next();
        return next != kUnknown && next <= wanted + prefetch && (end == kUnknown || next < end);
      });
      if (stop) return;
      decodeNext(lock);
    }
  }

  std::string endMessage(long long index) const {
    return "the video ends at frame " + std::to_string(end) + " (" + std::to_string(end) +
           " frames decode; frame " + std::to_string(index) + " asked)";
  }

  VideoReader::Frame read(long long index) override {
    VideoReader::Frame out;
    if (index < 0) {
      out.error = "frame " + std::to_string(index) + " does not exist";
      return out;
    }
    std::unique_lock<std::mutex> lock(mutex);
    wanted = index;
    ready.erase(ready.begin(), ready.lower_bound(index));
    changed.notify_all();
    for (;;) {
      if (end != kUnknown && index >= end) {
        out.error = endMessage(index);
        return out;
      }
      if (auto it = ready.find(index); it != ready.end()) {
        out.bgr = std::move(it->second);
        ready.erase(it);
        return out;
      }
      if (decoding) {
        waitForDecoder(lock);  // it may bring this frame, or move the decoder: decide again
        continue;
      }
      const long long next = decoder.next();
      if (next != kUnknown && index >= next && index - next <= kMaxDecodeForward) {
        decodeNext(lock);
        continue;
      }
      ready.clear();
      cv::Mat image;
      if (withDecoder(lock, [&] { return decoder.seek(index, image); })) {
        out.bgr = std::move(image);
        return out;
      }
      break;
    }
    // The seek found no frame: past the end, or a seek that fails where decoding in order
    // does find the frame (an .avi cut short); the end, found by decoding, tells which.
    lock.unlock();
    long long frames = 0;
    try {
      frames = decodableFrames();
    } catch (const Error& e) {
      out.error = "frame " + std::to_string(index) + " does not decode (" + e.message() + ")";
      return out;
    }
    lock.lock();
    if (index >= frames) {
      out.error = endMessage(index);
      return out;
    }
    while (decoding) waitForDecoder(lock);
    ready.clear();
    cv::Mat image;
    if (withDecoder(lock, [&] { return decoder.decodeFromStart(index, image); }))
      out.bgr = std::move(image);
    else
      out.error = "frame " + std::to_string(index) + " does not decode";
    return out;
  }

  // Trusts the container's packet count but verifies the end: walks back from the last packet
  // (1, 2, 4, ... frames) to a frame a seek decodes, then decodes on in order from there to where
  // decoding really stops. Only the tail is decoded. No bisection: a seek that fails is not proof
  // that the frame does not decode (see Decoder::seek), and one that once worked may not again
  // (an .avi cut short), so the answer always comes from decoding in order.
  long long decodableFrames() override {
    {
      std::lock_guard<std::mutex> lock(mutex);
      if (end != kUnknown) return end;
    }
    const long long packets = probeFile(path).packets;
    std::unique_lock<std::mutex> lock(mutex);
    for (;;) {
      if (end != kUnknown) return end;
      if (!decoding) break;
      waitForDecoder(lock);
    }
    ready.clear();
    long long last = -1;  // the last frame a seek decoded
    withDecoder(lock, [&] {
      cv::Mat image;
      for (long long k = packets - 1, step = 1; k >= 0 && last < 0; k -= step, step *= 2)
        if (decoder.seek(k, image)) last = k;
      if (last < 0 && !decoder.restart()) return false;
      while (decoder.decodeNext(image)) {
      }
      return true;
    });
    // The decoder could not go on (the file cannot be reopened).
    if (end == kUnknown) end = last + 1;
    changed.notify_all();
    return end;
  }
};

// ---- live sources ------------------------------------------------------------------------

class Capture final : public detail::LiveCapture {
 public:
  cv::VideoCapture capture;
  double fps() const override { return capture.get(cv::CAP_PROP_FPS); }
  bool grab() override { return capture.grab(); }
  bool read(cv::Mat& frame) override { return capture.read(frame) && !frame.empty(); }
};

// ---- the plugin's interface -------------------------------------------------------------------

std::unique_ptr<detail::VideoFileWriter> openWriter(const fs::path& path, cv::Size size,
                                                    const VideoWriterOptions& options) {
  return std::make_unique<FileWriter>(path, size, options);
}

std::unique_ptr<detail::VideoFileReader> openReader(const fs::path& path, int prefetch) {
  return std::make_unique<FileReader>(path, prefetch);
}

std::unique_ptr<detail::LiveCapture> openLive(const std::string& source) {
  auto c = std::make_unique<Capture>();
  // A device index (OpenCV's choice of backend: V4L2 here), a GStreamer pipeline, a V4L2 device
  // path, or anything FFmpeg opens (files, rtsp://, udp://, ...), each with its backend named.
  // CAP_ANY on a path would also probe the other backends in turn; gPhoto2's enumerates USB and
  // leaks what libusb returns on every open that fails (found by scripts/sanitize.sh).
  const bool index = !source.empty() && source.find_first_not_of("0123456789") == std::string::npos;
  const int backend = source.find('!') != std::string::npos ? cv::CAP_GSTREAMER
                      : source.rfind("/dev/", 0) == 0       ? cv::CAP_V4L2
                                                            : cv::CAP_FFMPEG;
  const bool opened = index ? c->capture.open(std::stoi(source)) : c->capture.open(source, backend);
  if (!opened) return nullptr;
  return c;
}

const detail::VideoPlugin kPlugin{detail::VideoPlugin::kVersion, openWriter, probeFile, openReader, openLive};

}  // namespace

}  // namespace previz::take

PREVIZ_PLUGIN_ENTRY const void* previz_video_plugin(int version) {
  return version == previz::take::kPlugin.version ? &previz::take::kPlugin : nullptr;
}
