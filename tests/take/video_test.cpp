// Video files and timecode (take/video.h, take/timecode.h): SMPTE timecode arithmetic, a
// writer whose FFV1 round-trips 8-bit BGR bit for bit, exact seeks (FFV1, and H.264 with
// B-frames and one GOP over the whole clip), files cut short, and what it says about bad input.
// Figures quoted below come from
//   cmake --build build --target take_tests && build/tests/take/take_tests --gtest_filter='Video*'
#include "take/video.h"

#include <algorithm>
#include <chrono>
#include <fstream>
#include <numeric>
#include <random>
#include <thread>

#include <gtest/gtest.h>

#include "core/error.h"
#include "scratch.h"
#include "take/timecode.h"

namespace previz::take {
namespace {

namespace fs = std::filesystem;

// Textured 8-bit BGR: noise (fixed seed per frame) over gradients that move with the frame,
// so that every frame differs from its neighbours everywhere.
cv::Mat textured(int frame, cv::Size size = {320, 180}, int noise = 256) {
  cv::Mat img(size, CV_8UC3);
  cv::RNG rng(0x5eed0000u + static_cast<unsigned>(frame));
  rng.fill(img, cv::RNG::UNIFORM, 0, noise);
  for (int y = 0; y < size.height; ++y) {
    auto* row = img.ptr<cv::Vec3b>(y);
    for (int x = 0; x < size.width; ++x) {
      const int gradient[3] = {(x + 3 * frame) & 255, (y + 5 * frame) & 255, ((x + y) / 2 + 7 * frame) & 255};
      for (int c = 0; c < 3; ++c) row[x][c] = cv::saturate_cast<uchar>(row[x][c] / 2 + gradient[c] / 2);
    }
  }
  return img;
}

void writeVideo(const fs::path& path, int frames, const VideoWriterOptions& options, cv::Size size = {320, 180},
                int noise = 256) {
  VideoWriter writer(path, size, options);
  for (int i = 0; i < frames; ++i) writer.write(textured(i, size, noise));
  writer.close();
}

std::vector<long long> shuffledIndices(long long n, unsigned seed) {
  std::vector<long long> order(static_cast<size_t>(n));
  std::iota(order.begin(), order.end(), 0);
  std::shuffle(order.begin(), order.end(), std::mt19937(seed));
  return order;
}

std::vector<std::string> folderEntries(const fs::path& dir) {
  std::vector<std::string> names;
  for (const auto& e : fs::directory_iterator(dir)) names.push_back(e.path().filename().string());
  std::sort(names.begin(), names.end());
  return names;
}

double msSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

// ---- timecode -------------------------------------------------------------------------------

TEST(Timecode, ParsesFormatsAndCountsNonDropFrame) {
  const auto tc = parseTimecode("01:00:00:05");
  ASSERT_TRUE(tc);
  EXPECT_EQ(tc->hours, 1);
  EXPECT_EQ(tc->minutes, 0);
  EXPECT_EQ(tc->seconds, 0);
  EXPECT_EQ(tc->frames, 5);
  EXPECT_FALSE(tc->drop_frame);
  EXPECT_EQ(formatTimecode(*tc), "01:00:00:05");
  EXPECT_EQ(timecodeToFrames(*tc, 24), 3600 * 24 + 5);
  EXPECT_EQ(timecodeToFrames(*tc, 25), 3600 * 25 + 5);
  // 23.976 counts at its nominal 24.
  EXPECT_EQ(timecodeToFrames(*tc, 24000.0 / 1001), 3600 * 24 + 5);
  EXPECT_EQ(formatTimecode(framesToTimecode(3600 * 24 + 5, 24)), "01:00:00:05");
  EXPECT_EQ(formatTimecode(framesToTimecode(0, 30)), "00:00:00:00");
  for (long long f = 0; f < 24 * 3600 * 2; f += 7)
    ASSERT_EQ(timecodeToFrames(framesToTimecode(f, 24), 24), f) << f;
}

TEST(Timecode, DropFrameSkipsTwoLabelsEachMinuteButEveryTenthAt2997) {
  const double ntsc = 30000.0 / 1001;
  const auto tc = parseTimecode("00:01:00;02");
  ASSERT_TRUE(tc);
  EXPECT_TRUE(tc->drop_frame);
  EXPECT_EQ(formatTimecode(*tc), "00:01:00;02");
  EXPECT_EQ(timecodeToFrames(*tc, ntsc), 1800);
  EXPECT_EQ(timecodeToFrames(*parseTimecode("00:00:59;29"), ntsc), 1799);
  EXPECT_EQ(timecodeToFrames(*parseTimecode("00:10:00;00"), ntsc), 17982);  // minute 10 keeps ;00
  EXPECT_EQ(timecodeToFrames(*parseTimecode("01:00:00;00"), ntsc), 107892);  // 3600 s * 29.97
  EXPECT_TRUE(parseTimecode("00:01:00.02")->drop_frame);
  EXPECT_EQ(formatTimecode(framesToTimecode(1800, ntsc, true)), "00:01:00;02");
  EXPECT_EQ(formatTimecode(framesToTimecode(17982, ntsc, true)), "00:10:00;00");
  // Every frame of two hours round-trips, and consecutive frames have consecutive labels.
  for (const double fps : {ntsc, 60000.0 / 1001}) {
    for (long long f = 0; f < static_cast<long long>(fps * 7200); ++f) {
      const Timecode t = framesToTimecode(f, fps, true);
      ASSERT_EQ(timecodeToFrames(t, fps), f) << formatTimecode(t);
    }
  }
  // 59.94 drops four labels.
  EXPECT_EQ(timecodeToFrames(*parseTimecode("00:01:00;04"), 60000.0 / 1001), 3600);
}

TEST(Timecode, MalformedStringsAreRefused) {
  for (const char* bad : {"", "1:00:00:00", "01:00:00", "01:60:00:00", "01:00:60:00", "01-00-00-00",
                          "01;00;00;00", "01:00:00:00 ", " 01:00:00:00", "aa:bb:cc:dd", "01:00:00:0",
                          "01:00:00:-1", "01:00:00:0005", "01:00:00,05"})
    EXPECT_FALSE(parseTimecode(bad)) << "'" << bad << "'";
}

TEST(Timecode, FramesAtOrAboveTheRateAndBadRatesThrowNamingTimecode) {
  const auto expectTimecodeError = [](auto&& call) {
    try {
      call();
      ADD_FAILURE() << "no Error";
    } catch (const Error& e) {
      EXPECT_EQ(e.context().field, "timecode") << e.what();
    }
  };
  expectTimecodeError([] { timecodeToFrames(*parseTimecode("00:00:00:24"), 24); });
  expectTimecodeError([] { timecodeToFrames(*parseTimecode("00:00:00:05"), 0); });
  expectTimecodeError([] { timecodeToFrames(*parseTimecode("00:00:00:05"), -25); });
  expectTimecodeError([] { timecodeToFrames(*parseTimecode("00:01:00;00"), 30000.0 / 1001); });  // dropped label
  expectTimecodeError([] { timecodeToFrames(*parseTimecode("00:00:01;00"), 25); });  // drop frame at 25
  expectTimecodeError([] { framesToTimecode(10, 0); });
  expectTimecodeError([] { framesToTimecode(-1, 24); });
}

// ---- writer options and atomicity ----------------------------------------------------------

TEST(VideoWriter, OptionsValidateNamesTheField) {
  const auto fieldOf = [](VideoWriterOptions o) {
    try {
      o.validate();
    } catch (const Error& e) {
      return e.context().field;
    }
    return std::string("(valid)");
  };
  VideoWriterOptions o;
  EXPECT_EQ(fieldOf(o), "(valid)");
  o.codec = "vp9";
  EXPECT_EQ(fieldOf(o), "codec");
  o = {};
  o.fps = 0;
  EXPECT_EQ(fieldOf(o), "fps");
  o = {};
  o.crf = 60;
  EXPECT_EQ(fieldOf(o), "crf");
  o = {};
  o.start_timecode = "1:00:00:00";
  EXPECT_EQ(fieldOf(o), "start_timecode");
  o.start_timecode = "01:00:00:24";  // frames field at 24 fps
  EXPECT_EQ(fieldOf(o), "start_timecode");
  o.start_timecode = "01:00:00;05";  // drop frame at 24 fps
  EXPECT_EQ(fieldOf(o), "start_timecode");
  o.fps = 29.97;
  EXPECT_EQ(fieldOf(o), "(valid)");
}

TEST(VideoWriter, DestroyedWithoutCloseOrAfterAnErrorLeavesNoFileAndNoTemporary) {
  const fs::path dir = test::scratchDir("take", "writer_atomic");
  {
    VideoWriter writer(dir / "abandoned.mkv", {64, 48});
    for (int i = 0; i < 3; ++i) writer.write(textured(i, {64, 48}));
    EXPECT_EQ(folderEntries(dir).size(), 1u);  // the temporary, beside the target
  }
  EXPECT_TRUE(folderEntries(dir).empty());
  {
    VideoWriter writer(dir / "wrong_size.mkv", {64, 48});
    writer.write(textured(0, {64, 48}));
    try {
      writer.write(textured(1, {32, 48}));
      ADD_FAILURE() << "no Error for a wrong-size frame";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("wrong_size.mkv"), std::string::npos) << e.what();
    }
  }
  EXPECT_TRUE(folderEntries(dir).empty());
  VideoWriterOptions h264;
  h264.codec = "h264";
  EXPECT_THROW(VideoWriter(dir / "odd.mp4", {63, 48}, h264), Error);
  EXPECT_THROW(VideoWriter(dir / "unknown.xyz", {64, 48}), Error);
  EXPECT_THROW(VideoWriter(dir / "ffv1.mp4", {64, 48}), Error);  // refused by the muxer, after the temporary exists
  EXPECT_TRUE(folderEntries(dir).empty());
  writeVideo(dir / "kept.mkv", 3, {}, {64, 48});
  EXPECT_EQ(folderEntries(dir), std::vector<std::string>{"kept.mkv"});
}

// ---- FFV1 -----------------------------------------------------------------------------------

// 320x180, 30 frames of noise: 5.2 MB as .mkv (FFV1 cannot compress noise).
TEST(VideoReader, Ffv1MkvRoundTripsBitExactlySequentiallyAndInRandomOrder) {
  const fs::path dir = test::scratchDir("take", "ffv1");
  const fs::path file = dir / "A.mkv";
  VideoWriterOptions options;
  options.start_timecode = "01:00:00:05";
  writeVideo(file, 30, options);
  std::cout << "[ figures  ] " << file.filename() << " " << fs::file_size(file) << " bytes\n";

  const VideoProbe probe = probeVideo(file);
  EXPECT_EQ(probe.codec, "ffv1");
  EXPECT_EQ(probe.pix_fmt, "bgr0");
  EXPECT_EQ(probe.bit_depth, 8);
  EXPECT_EQ(probe.width, 320);
  EXPECT_EQ(probe.height, 180);
  EXPECT_DOUBLE_EQ(probe.fps, 24);
  EXPECT_EQ(probe.packets, 30);
  EXPECT_NEAR(probe.duration_s, 30 / 24.0, 1e-3);
  EXPECT_EQ(probe.timecode, "01:00:00:05");
  EXPECT_TRUE(probe.demux_error.empty()) << probe.demux_error;

  for (const int prefetch : {0, 4}) {
    VideoReader sequential(file, prefetch);
    for (int i = 0; i < 30; ++i) {
      const auto f = sequential.read(i);
      ASSERT_TRUE(f.ok()) << i << ": " << f.error;
      ASSERT_EQ(f.bgr.type(), CV_8UC3);
      EXPECT_EQ(cv::norm(f.bgr, textured(i), cv::NORM_INF), 0) << "frame " << i << " prefetch " << prefetch;
    }
    EXPECT_FALSE(sequential.read(30).ok());

    VideoReader random(file, prefetch);
    int exact = 0;
    for (const long long i : shuffledIndices(30, 7)) {
      const auto f = random.read(i);
      ASSERT_TRUE(f.ok()) << i << ": " << f.error;
      exact += cv::norm(f.bgr, textured(static_cast<int>(i)), cv::NORM_INF) == 0;
    }
    EXPECT_EQ(exact, 30) << "prefetch " << prefetch;
    EXPECT_EQ(random.decodableFrames(), 30);
  }
}

TEST(VideoReader, ConcurrentReadersOfOneVideoGetExactFrames) {
  const fs::path file = test::scratchDir("take", "concurrent") / "A.mkv";
  writeVideo(file, 30, {});
  VideoReader reader(file, 3);
  std::vector<int> exact(3, 0);
  std::vector<std::thread> threads;
  for (int t = 0; t < 3; ++t) {
    threads.emplace_back([&, t] {
      // One thread reads in order (the prefetch path), two jump around (seeks).
      const auto order = shuffledIndices(30, 100 + t);
      for (long long k = 0; k < 30; ++k) {
        const long long i = t == 0 ? k : order[static_cast<size_t>(k)];
        const auto f = reader.read(i);
        exact[t] += f.ok() && cv::norm(f.bgr, textured(static_cast<int>(i)), cv::NORM_INF) == 0;
      }
    });
  }
  for (auto& th : threads) th.join();
  EXPECT_EQ(exact, std::vector<int>(3, 30));
}

TEST(VideoProbe, MovCarriesTheStartTimecodeInItsTmcdTrack) {
  const fs::path dir = test::scratchDir("take", "mov");
  const fs::path file = dir / "A.mov";
  VideoWriterOptions options;
  options.start_timecode = "01:00:00:05";
  try {
    writeVideo(file, 10, options);
  } catch (const Error& e) {
    std::cout << "[ note     ] FFV1 refused in .mov (" << e.what() << "); ProRes instead\n";
    options.codec = "prores";
    writeVideo(file, 10, options);
  }
  const VideoProbe probe = probeVideo(file);
  std::cout << "[ figures  ] A.mov " << probe.codec << " " << fs::file_size(file) << " bytes\n";
  EXPECT_EQ(probe.timecode, "01:00:00:05");
  EXPECT_EQ(probe.packets, 10);
  EXPECT_DOUBLE_EQ(probe.fps, 24);

  // ProRes 4:2:2 10-bit in .mov, drop-frame timecode at 29.97.
  options.codec = "prores";
  options.fps = 29.97;
  options.start_timecode = "00:01:00;02";
  writeVideo(dir / "B.mov", 4, options);
  const VideoProbe prores = probeVideo(dir / "B.mov");
  EXPECT_EQ(prores.codec, "prores");
  EXPECT_EQ(prores.pix_fmt, "yuv422p10le");
  EXPECT_EQ(prores.bit_depth, 10);
  EXPECT_NEAR(prores.fps, 30000.0 / 1001, 1e-9);
  EXPECT_EQ(prores.timecode, "00:01:00;02");
}

// ---- H.264 ----------------------------------------------------------------------------------

// x264's defaults (keyint 250, 3 B-frames): the 48 frames are one GOP, so every seek past frame
// 0 decodes forward from the keyframe through reordered B-frames. Random-order reads equal the
// sequential reads of the same frames bit for bit (both decode the same stream): seeks are
// exact. 320x180 crf 18: 48 frames of noisy texture ~ 0.6 MB .mp4.
TEST(VideoReader, H264RandomOrderReadsEqualSequentialReads) {
  const fs::path dir = test::scratchDir("take", "h264");
  for (const std::string ext : {".mp4", ".mkv"}) {
    const fs::path file = dir / ("A" + ext);
    VideoWriterOptions options;
    options.codec = "h264";
    options.start_timecode = "10:00:00:00";
    writeVideo(file, 48, options, {320, 180}, 64);
    const VideoProbe probe = probeVideo(file);
    EXPECT_EQ(probe.codec, "h264");
    EXPECT_EQ(probe.pix_fmt, "yuv420p");
    EXPECT_EQ(probe.packets, 48);
    EXPECT_EQ(probe.timecode, "10:00:00:00") << ext;

    std::vector<cv::Mat> source, sequential;
    for (int i = 0; i < 48; ++i) source.push_back(textured(i, {320, 180}, 64));
    VideoReader reader(file, 4);
    double own_min = 1e9, margin_min = 1e9;  // PSNR against its source frame, and less the best other
    for (int i = 0; i < 48; ++i) {
      auto f = reader.read(i);
      ASSERT_TRUE(f.ok()) << ext << " " << i << ": " << f.error;
      const double own = cv::PSNR(f.bgr, source[static_cast<size_t>(i)]);
      double other = 0;
      for (int j = 0; j < 48; ++j)
        if (j != i) other = std::max(other, cv::PSNR(f.bgr, source[static_cast<size_t>(j)]));
      own_min = std::min(own_min, own);
      margin_min = std::min(margin_min, own - other);
      sequential.push_back(f.bgr);
    }
    std::cout << "[ figures  ] A" << ext << " " << fs::file_size(file) << " bytes, PSNR against its own source "
              << "frame >= " << own_min << " dB, >= " << margin_min << " dB above any other frame's\n";
    // Sequential decoding gives the right frames: each is closest to its own source frame.
    EXPECT_GT(own_min, 25);
    EXPECT_GT(margin_min, 1);

    for (const int prefetch : {0, 4}) {
      VideoReader random(file, prefetch);
      int exact = 0;
      for (const long long i : shuffledIndices(48, 11)) {
        const auto f = random.read(i);
        ASSERT_TRUE(f.ok()) << ext << " " << i << ": " << f.error;
        const bool same = cv::norm(f.bgr, sequential[static_cast<size_t>(i)], cv::NORM_INF) == 0;
        EXPECT_TRUE(same) << ext << " frame " << i << " prefetch " << prefetch;
        exact += same;
      }
      EXPECT_EQ(exact, 48) << ext;
      EXPECT_EQ(random.decodableFrames(), 48) << ext;
    }
  }
}

// ---- damaged and wrong files ---------------------------------------------------------------

// Files cut short (a card that filled up, a copy interrupted), 40 frames each. FFV1 .mkv cut to
// 80 % (7.0 MB to 5.6 MB): 32 packets, all 32 decode. H.264 .avi cut to 85 %: 35 packets, 35
// decode; the index at the end is gone, so OpenCV's seeks land anywhere or fail; the reader
// notices (frame counter, timestamps) and decodes in order instead, so random reads still equal
// sequential ones.
TEST(VideoReader, FileCutShortIsReadAsFarAsItDecodesAndSaysWhereItEnds) {
  const fs::path dir = test::scratchDir("take", "truncated");
  struct Case {
    std::string name, codec;
    int percent;
  };
  for (const Case& c : {Case{"cut.mkv", "ffv1", 80}, Case{"cut.avi", "h264", 85}}) {
    const fs::path whole = dir / ("whole" + fs::path(c.name).extension().string());
    VideoWriterOptions options;
    options.codec = c.codec;
    writeVideo(whole, 40, options);
    const auto size = fs::file_size(whole);
    const fs::path cut = dir / c.name;
    {
      std::ifstream in(whole, std::ios::binary);
      std::string bytes(static_cast<size_t>(size * c.percent / 100), '\0');
      in.read(bytes.data(), static_cast<std::streamsize>(bytes.size()));
      std::ofstream(cut, std::ios::binary).write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    }
    const VideoProbe probe = probeVideo(cut);
    EXPECT_LT(probe.packets, 40) << c.name;
    EXPECT_GT(probe.packets, 40 * c.percent / 100 - 10) << c.name;

    std::vector<cv::Mat> sequential;
    {
      VideoReader reader(cut, 4);
      for (VideoReader::Frame f; (f = reader.read(static_cast<long long>(sequential.size()))).ok();)
        sequential.push_back(f.bgr);
    }
    const auto decoded = static_cast<long long>(sequential.size());
    VideoReader reader(cut, 0);
    const long long decodable = reader.decodableFrames();
    std::cout << "[ figures  ] " << c.name << ": " << size << " bytes cut to " << fs::file_size(cut) << ", "
              << probe.packets << " packets, decodableFrames " << decodable << ", sequential reading decodes "
              << decoded << "\n";
    EXPECT_EQ(decodable, decoded) << c.name;
    EXPECT_LT(decodable, 40) << c.name;
    EXPECT_GT(decodable, 0) << c.name;
    if (c.codec == "ffv1") {
      for (long long i = 0; i < decoded; ++i)
        EXPECT_EQ(cv::norm(sequential[static_cast<size_t>(i)], textured(static_cast<int>(i)), cv::NORM_INF), 0) << i;
    }

    const std::string where = "the video ends at frame " + std::to_string(decoded);
    const auto last = reader.read(39);
    EXPECT_TRUE(last.bgr.empty());
    EXPECT_NE(last.error.find(where), std::string::npos) << last.error;

    // A fresh reader, jumping around before it knows where the video ends. The .avi's last
    // decodable packet is cut: FFmpeg's H.264 decoder conceals what is missing, not the same way on
    // every decode (~54 dB apart), so that frame need only be nearer its own sequential read than
    // any other frame; every other frame is bit-exact.
    VideoReader fresh(cut, 0);
    int exact = 0;
    for (const long long i : shuffledIndices(40, 3)) {
      const auto f = fresh.read(i);
      if (i >= decoded) {
        EXPECT_NE(f.error.find(where), std::string::npos) << c.name << " frame " << i << ": " << f.error;
        continue;
      }
      ASSERT_TRUE(f.ok()) << c.name << " frame " << i << ": " << f.error;
      const cv::Mat& truth = sequential[static_cast<size_t>(i)];
      if (c.codec == "h264" && i == decoded - 1) {
        const double own = cv::PSNR(f.bgr, truth);
        for (const cv::Mat& other : sequential) {
          if (&other == &truth) continue;
          EXPECT_GT(own, cv::PSNR(f.bgr, other)) << c.name << " frame " << i;
        }
        ++exact;
      } else {
        exact += cv::norm(f.bgr, truth, cv::NORM_INF) == 0;
      }
    }
    EXPECT_EQ(exact, decoded) << c.name;
  }
}

TEST(VideoReader, NotAVideoThrowsErrorNamingTheFile) {
  const fs::path dir = test::scratchDir("take", "not_video");
  const fs::path text = dir / "notes.mkv";
  std::ofstream(text) << "This is a camera report, not a video.\nA001C003 take 4\n";
  for (const fs::path& p : {text, dir / "missing.mkv"}) {
    try {
      probeVideo(p);
      ADD_FAILURE() << "probeVideo: no Error for " << p;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(p.filename().string()), std::string::npos) << e.what();
    }
    try {
      VideoReader reader(p);
      ADD_FAILURE() << "VideoReader: no Error for " << p;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(p.filename().string()), std::string::npos) << e.what();
    }
  }
}

// ---- speed (figures only; the machine's load decides them) ---------------------------------

// 1280x720, 24 frames: decode ms per frame with no prefetch, the caller's wait per frame when it
// spends the same time again on each frame while the worker decodes ahead, and the cost of a
// random read (a seek: OpenCV lands 16 frames early and decodes forward, even for FFV1).
TEST(VideoReader, PrefetchedAndUnprefetchedReadsAgreeAt720p) {
  const fs::path dir = test::scratchDir("take", "speed");
  const cv::Size hd(1280, 720);
  constexpr int kFrames = 24;
  for (const std::string codec : {"ffv1", "h264"}) {
    const fs::path file = dir / ("A." + codec + ".mkv");
    VideoWriterOptions options;
    options.codec = codec;
    const auto t_write = std::chrono::steady_clock::now();
    writeVideo(file, kFrames, options, hd, 64);
    const double write_ms = msSince(t_write) / kFrames;

    VideoReader plain(file, 0);
    std::vector<cv::Mat> frames;
    const auto t0 = std::chrono::steady_clock::now();
    for (int i = 0; i < kFrames; ++i) frames.push_back(plain.read(i).bgr);
    const double decode_ms = msSince(t0) / kFrames;

    VideoReader ahead(file, 4);
    double wait_ms = 0;
    int same = 0;
    for (int i = 0; i < kFrames; ++i) {
      const auto t = std::chrono::steady_clock::now();
      const auto f = ahead.read(i);
      wait_ms += msSince(t);
      same += f.ok() && cv::norm(f.bgr, frames[static_cast<size_t>(i)], cv::NORM_INF) == 0;
      std::this_thread::sleep_for(std::chrono::duration<double, std::milli>(decode_ms));  // the caller's work
    }
    EXPECT_EQ(same, kFrames) << codec;

    VideoReader jumping(file, 0);
    int exact = 0;
    const auto t_seek = std::chrono::steady_clock::now();
    const auto order = shuffledIndices(kFrames, 5);
    for (size_t k = 0; k < 6; ++k) {
      const auto f = jumping.read(order[k]);
      exact += f.ok() && cv::norm(f.bgr, frames[static_cast<size_t>(order[k])], cv::NORM_INF) == 0;
    }
    const double seek_ms = msSince(t_seek) / 6;
    EXPECT_EQ(exact, 6) << codec;
    std::cout << "[ figures  ] 1280x720 " << codec << ": " << fs::file_size(file) / kFrames << " bytes/frame, encode "
              << write_ms << " ms/frame, decode " << decode_ms << " ms/frame, wait with prefetch 4 "
              << wait_ms / kFrames << " ms/frame, random read " << seek_ms << " ms\n";
  }
}

}  // namespace
}  // namespace previz::take
