// The take model (take/take.h, take/sequence.h): sequences of any name, start and depth, videos,
// offsets from take.json and timecode, clean plates, and what it says about bad input.
#include "take/take.h"

#include <gtest/gtest.h>

#include <fstream>

#include <opencv2/imgcodecs.hpp>

#include "core/camera_io.h"
#include "core/rig_import.h"
#include "core/error.h"
#include "core/io.h"
#include "core/names.h"
#include "core/srgb.h"
#include "take/sequence.h"
#include "take/video.h"
#include "tests/scratch.h"

namespace previz::take {
namespace {

namespace fs = std::filesystem;

// A textured 8-bit BGR frame that differs per camera and frame.
cv::Mat frameImage(int seed, int frame, cv::Size size = {64, 48}) {
  cv::Mat img(size, CV_8UC3);
  cv::RNG rng(static_cast<std::uint64_t>(seed) * 1000 + frame);
  rng.fill(img, cv::RNG::UNIFORM, 0, 256);
  return img;
}

void touchImage(const fs::path& p, const cv::Mat& img) {
  fs::create_directories(p.parent_path());
  ASSERT_TRUE(cv::imwrite(p.string(), img)) << p;
}

TEST(Sequence, PatternsAreFoundWhateverTheNameStartAndPadding) {
  const fs::path dir = test::scratchDir("take", "patterns");
  for (int f : {1001, 1002, 1003}) touchImage(dir / "vfx" / ("A001C003." + std::to_string(f) + ".png"), frameImage(1, f));
  for (int f = 1; f <= 12; ++f) touchImage(dir / "plain" / (std::to_string(f) + ".jpg"), frameImage(2, f));
  for (int f : {0, 60, 120, 180}) {
    char name[32];
    std::snprintf(name, sizeof(name), "viff%03d.png", f);
    touchImage(dir / "sparse" / name, frameImage(3, f));
  }

  std::vector<FoundSequence> vfx = findSequences(dir / "vfx");
  ASSERT_EQ(vfx.size(), 1u);
  EXPECT_EQ(vfx[0].pattern.str(), "A001C003.%04d.png");
  EXPECT_EQ(vfx[0].frames, (std::vector<long long>{1001, 1002, 1003}));

  std::vector<FoundSequence> plain = findSequences(dir / "plain");
  ASSERT_EQ(plain.size(), 1u);
  EXPECT_EQ(plain[0].pattern.str(), "%d.jpg");
  EXPECT_EQ(plain[0].frames.size(), 12u);

  std::vector<FoundSequence> sparse = findSequences(dir / "sparse");
  ASSERT_EQ(sparse.size(), 1u);
  EXPECT_EQ(sparse[0].pattern.str(), "viff%03d.png");
  const SequenceGaps gaps = sequenceGaps(sparse[0].frames);
  EXPECT_EQ(gaps.step, 60);
  EXPECT_EQ(gaps.missing_count, 0);

  const SequenceGaps hole = sequenceGaps({10, 11, 12, 15, 16});
  EXPECT_EQ(hole.step, 1);
  EXPECT_EQ(hole.missing, (std::vector<long long>{13, 14}));

  // Given patterns, "####" included; a number is read exactly as the pattern writes it.
  const std::optional<SequencePattern> hashes = parsePattern("A001C003.####.exr");
  ASSERT_TRUE(hashes);
  EXPECT_EQ(hashes->str(), "A001C003.%04d.exr");
  EXPECT_EQ(hashes->frameOf("A001C003.1001.exr"), 1001);
  EXPECT_EQ(hashes->frameOf("A001C003.12345.exr"), 12345);  // past the padding
  EXPECT_FALSE(hashes->frameOf("A001C003.101.exr"));
  EXPECT_FALSE(parsePattern("plate.exr"));
  EXPECT_FALSE(parsePattern("a%04d_%04d.png"));
  EXPECT_FALSE(parsePattern("%d.png")->frameOf("01.png"));
}

// core/names.h: previz's own frame name, read back through the take model's patterns.
TEST(Sequence, FramePatternNamesFilesAsFrameStem) {
  const auto pattern = parsePattern(std::string(kFramePattern) + ".png");
  ASSERT_TRUE(pattern);
  for (int f : {0, 7, 42, 999999}) {
    EXPECT_EQ(pattern->fileName(f), frameStem(f) + ".png");
    EXPECT_EQ(pattern->frameOf(frameStem(f) + ".png"), static_cast<long long>(f));
  }
}

// The same 8-bit pictures as a PNG sequence from 1001 (its own numbers), a 16-bit TIFF sequence
// and a float EXR sequence: read back to the same 8-bit values.
TEST(TakeModel, SequencesOfAnyDepthReadAsTheSameEightBitFrames) {
  const fs::path dir = test::scratchDir("take", "depths");
  for (int f = 1001; f <= 1003; ++f) {
    const cv::Mat img = frameImage(7, f);
    touchImage(dir / "cams" / "A" / ("A001C003." + std::to_string(f) + ".png"), img);
    cv::Mat wide;
    img.convertTo(wide, CV_16U, 257.0);
    touchImage(dir / "cams" / "B" / ("B_" + std::to_string(f) + ".tif"), wide);
    // Linear light of the same codes (the EXR reader sRGB-encodes once).
    ExrImage exr;
    cv::Mat lin(img.size(), CV_32FC3);
    for (int y = 0; y < img.rows; ++y)
      for (int x = 0; x < img.cols; ++x)
        for (int c = 0; c < 3; ++c) lin.at<cv::Vec3f>(y, x)[2 - c] = srgb8ToLinear()[img.at<cv::Vec3b>(y, x)[c]];
    exr.image = lin;
    exr.channels = {"R", "G", "B"};
    fs::create_directories(dir / "cams" / "C");
    writeExr(dir / "cams" / "C" / ("C." + std::to_string(f) + ".exr"), exr);
  }
  const Take take(dir);
  ASSERT_EQ(take.cameras(), (std::vector<std::string>{"A", "B", "C"}));
  EXPECT_EQ(take.frames(), (std::vector<int>{1001, 1002, 1003}));
  EXPECT_EQ(take.stream("A").pattern.str(), "A001C003.%04d.png");
  EXPECT_EQ(take.stream("B").bit_depth, 16);
  EXPECT_EQ(take.stream("C").bit_depth, 32);
  for (int f = 1001; f <= 1003; ++f) {
    const FrameSet set = take.readFrameSet(f, {"A", "B", "C"});
    ASSERT_EQ(set.usable(), 3) << set.cameras[0].dropped << set.cameras[1].dropped << set.cameras[2].dropped;
    for (const CameraImage& c : set.cameras) {
      ASSERT_EQ(c.image.type(), CV_8UC3);
      EXPECT_EQ(cv::norm(c.image, frameImage(7, f), cv::NORM_INF), 0) << c.camera << " frame " << f;
    }
  }
  // Out of range and holes are named, not fatal.
  const CameraImage none = take.read("A", 1004);
  EXPECT_FALSE(none.ok());
  EXPECT_NE(none.dropped.find("A001C003.1004.png"), std::string::npos) << none.dropped;
}

TEST(TakeModel, OffsetsFromTakeJsonAndFromTimecodeAlignTheCameras) {
  const fs::path dir = test::scratchDir("take", "offsets");
  // A from file 2 = take frame 0 (take.json); B and C carry EXR timecodes: C starts 3 frames
  // after B, so C's first file is take frame 3 when timecode decides.
  for (int f = 0; f < 6; ++f) touchImage(dir / "cams" / "A" / (std::to_string(f) + ".png"), frameImage(1, f));
  writeJsonAtomic(dir / "take.json", {{"fps", 24}, {"offsets", {{"A", 2}}}});
  for (int f = 0; f < 5; ++f) {
    for (const char* cam : {"B", "C"}) {
      ExrImage exr;
      exr.image = cv::Mat(8, 8, CV_32FC3, cv::Scalar::all(0.2));
      exr.channels = {"R", "G", "B"};
      const int start = std::string(cam) == "B" ? 0 : 3;
      char tc[16];
      std::snprintf(tc, sizeof(tc), "01:00:00:%02d", start + f);
      exr.timecode = tc;
      fs::create_directories(dir / "cams" / cam);
      writeExr(dir / "cams" / cam / (std::to_string(100 + f) + ".exr"), exr);
    }
  }
  {
    // Not every camera has a timecode (A has none): no camera is aligned by it, and B's is noted.
    const Take take(dir);
    EXPECT_EQ(take.stream("A").offset, 2);
    EXPECT_EQ(take.stream("A").offset_from, "take.json");
    EXPECT_EQ(take.read("A", 0).source_frame, 2);
    EXPECT_EQ(take.stream("B").offset_from, "none");
    EXPECT_EQ(take.stream("B").start_timecode, "01:00:00:00");
    EXPECT_FALSE(take.stream("B").notes.empty());
  }
  {
    TakeOptions o;
    o.cameras = {"B", "C"};
    const Take take(dir, o);
    EXPECT_EQ(take.stream("B").offset_from, "timecode");
    EXPECT_EQ(take.stream("B").offset, 100);  // file 100 = take frame 0
    EXPECT_EQ(take.stream("C").offset, 97);   // file 100 = take frame 3
    EXPECT_EQ(take.frames(), (std::vector<int>{0, 1, 2, 3, 4, 5, 6, 7}));
    EXPECT_FALSE(take.read("C", 2).ok());
    EXPECT_TRUE(take.read("C", 3).ok());
    EXPECT_EQ(take.read("C", 3).source_frame, 100);
  }
}

TEST(TakeModel, MalformedTakeJsonIsNamedAndMissingCamerasAreDroppedNotFatal) {
  const fs::path dir = test::scratchDir("take", "bad");
  touchImage(dir / "cams" / "A" / "000000.png", frameImage(1, 0));
  writeJsonAtomic(dir / "take.json", {{"fps", -1}});
  try {
    Take t(dir);
    FAIL() << "negative fps accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.context().field, "fps");
    EXPECT_NE(std::string(e.what()).find("take.json"), std::string::npos) << e.what();
  }
  writeJsonAtomic(dir / "take.json", {{"offsets", {{"A", "two"}}}});
  EXPECT_THROW(Take{dir}, Error);
  writeJsonAtomic(dir / "take.json", nlohmann::json::object());
  TakeOptions o;
  o.cameras = {"A", "ghost"};
  const Take take(dir, o);
  EXPECT_TRUE(take.read("A", 0).ok());
  const CameraImage ghost = take.read("ghost", 0);
  EXPECT_FALSE(ghost.ok());
  EXPECT_NE(ghost.dropped.find("cams/ghost"), std::string::npos) << ghost.dropped;
  // A corrupt file: dropped with the file named.
  std::ofstream(dir / "cams" / "A" / "000001.png") << "not a png";
  const Take again(dir, o);
  const CameraImage bad = again.read("A", 1);
  EXPECT_FALSE(bad.ok());
  EXPECT_NE(bad.dropped.find("000001.png"), std::string::npos) << bad.dropped;
  EXPECT_THROW(Take(dir / "nope"), Error);
}

TEST(TakeModel, CleanPlateIsTheMedianOfAPlateClipAndIsCached) {
  const fs::path dir = test::scratchDir("take", "clean");
  const cv::Size size(64, 48);
  touchImage(dir / "cams" / "A" / "000000.png", frameImage(1, 0, size));
  // A plate clip of 9 frames: the stage plus noise, and in 3 frames someone walks through.
  const cv::Mat stage = frameImage(5, 0, size);
  VideoWriter w(dir / "clean" / "A.mkv", size, VideoWriterOptions{});
  for (int f = 0; f < 9; ++f) {
    cv::Mat img = stage.clone();
    if (f % 3 == 1) img(cv::Rect(10, 10, 20, 20)).setTo(cv::Scalar(0, 0, 255));
    w.write(img);
  }
  w.close();
  const Take take(dir);
  const cv::Mat plate = take.cleanPlate("A");
  ASSERT_EQ(plate.size(), size);
  EXPECT_EQ(cv::norm(plate, stage, cv::NORM_INF), 0);
  EXPECT_TRUE(fs::exists(dir / "out" / "clean" / "A.png"));
  const nlohmann::json info = readJsonFile(dir / "out" / "clean" / "A.json");
  EXPECT_EQ(info.at("frames_used").get<int>(), 9);
  EXPECT_EQ(cv::norm(take.cleanPlate("A"), stage, cv::NORM_INF), 0);  // from the cache
  // A plate of another size than the camera's is named.
  fs::remove(dir / "clean" / "A.mkv");
  touchImage(dir / "clean" / "A.png", frameImage(5, 0, cv::Size(32, 24)));
  try {
    take.cleanPlate("A");
    FAIL() << "wrong-size plate accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.context().camera, "A");
    EXPECT_NE(std::string(e.what()).find("A.png"), std::string::npos) << e.what();
  }
}

// A camera filmed at another rate is left out, named; a timecode that cannot be a label at the
// take's rate is named and not used; the rest of the take reads.
TEST(TakeModel, AnotherFpsOrAnUnreadableTimecodeIsNamedAndTheRestReads) {
  const fs::path dir = test::scratchDir("take", "mismatch");
  const cv::Size size(64, 48);
  for (const auto& [cam, fps] : {std::pair<const char*, double>{"A", 24.0}, {"B", 25.0}}) {
    VideoWriterOptions vo;
    vo.fps = fps;
    VideoWriter w(dir / "cams" / (std::string(cam) + ".mkv"), size, vo);
    for (int f = 0; f < 6; ++f) w.write(frameImage(3, f, size));
    w.close();
  }
  // C: EXR frames whose timecode is drop-frame, which 24 fps has no labels for.
  for (int f = 0; f < 6; ++f) {
    ExrImage exr;
    exr.image = cv::Mat(size, CV_32FC3, cv::Scalar::all(0.3));
    exr.channels = {"R", "G", "B"};
    exr.timecode = "01:00:00;0" + std::to_string(f);
    writeExr(dir / "cams" / "C" / (std::to_string(f) + ".exr"), exr);
  }
  writeJsonAtomic(dir / "take.json", {{"fps", 24}});
  const Take take(dir);
  EXPECT_TRUE(take.stream("A").usable());
  EXPECT_FALSE(take.stream("B").usable());
  EXPECT_NE(take.stream("B").unusable.find("25.000 fps, the take at 24.000"), std::string::npos)
      << take.stream("B").unusable;
  const CameraImage b = take.read("B", 0);
  EXPECT_FALSE(b.ok());
  EXPECT_EQ(b.dropped, take.stream("B").unusable);
  EXPECT_TRUE(take.read("A", 5).ok());
  EXPECT_TRUE(take.read("C", 5).ok());
  bool named = false;
  for (const std::string& n : take.stream("C").notes) named = named || n.find("unreadable timecode") != std::string::npos;
  EXPECT_TRUE(named);
  const nlohmann::json info = take.info();
  std::string mismatches = info["mismatches"].dump();
  EXPECT_NE(mismatches.find("B: the video runs at 25"), std::string::npos) << mismatches;
  EXPECT_NE(mismatches.find("C: unreadable timecode"), std::string::npos) << mismatches;
}

// Containers lie and sequences have holes: the take lists what is really there and names the
// difference; reading past the end or into a hole drops that camera for that frame.
TEST(TakeModel, ACutVideoAndAHoledSequenceListWhatIsThere) {
  const fs::path dir = test::scratchDir("take", "lies");
  const cv::Size size(64, 48);
  {
    VideoWriter w(dir / "cams" / "A.avi", size, VideoWriterOptions{});
    for (int f = 0; f < 20; ++f) w.write(frameImage(4, f, size));
    w.close();
  }
  const std::string bytes = readTextFile(dir / "cams" / "A.avi");
  writeFileAtomic(dir / "cams" / "A.avi", bytes.substr(0, bytes.size() * 7 / 10));
  for (int f = 0; f < 20; ++f)
    if (f != 7) touchImage(dir / "cams" / "B" / (std::to_string(100 + f) + ".png"), frameImage(5, f, size));
  writeJsonAtomic(dir / "take.json", {{"fps", 24}, {"offsets", {{"B", 100}}}});
  const Take take(dir);
  const CameraStream& a = take.stream("A");
  ASSERT_TRUE(a.usable()) << a.unusable;
  const long long decoded = static_cast<long long>(a.source_frames.size());
  EXPECT_GT(decoded, 5);
  EXPECT_LT(decoded, 20);
  const std::string notes = nlohmann::json(a.notes).dump();
  EXPECT_NE(notes.find("20"), std::string::npos) << notes;  // the header's or the packets' claim, named
  EXPECT_NE(notes.find(std::to_string(decoded) + " "), std::string::npos) << notes;
  EXPECT_TRUE(take.read("A", static_cast<int>(decoded) - 1).ok());
  const CameraImage past = take.read("A", 19);
  EXPECT_FALSE(past.ok());
  EXPECT_NE(past.dropped.find("A.avi"), std::string::npos) << past.dropped;
  // B: 19 files, frame 107 missing: named once, not as hundreds of frames.
  EXPECT_EQ(take.stream("B").source_frames.size(), 19u);
  EXPECT_NE(nlohmann::json(take.stream("B").notes).dump().find("1 frame(s) missing"), std::string::npos);
  EXPECT_EQ(take.frames().size(), 20u);  // B's 0..19 and A's first frames
  const CameraImage hole = take.read("B", 7);
  EXPECT_FALSE(hole.ok());
  EXPECT_NE(hole.dropped.find("107.png"), std::string::npos) << hole.dropped;
  EXPECT_TRUE(take.read("B", 8).ok());
}

// `camera import --take`: rows that carry no image size take each camera's from its images in
// the take (Middlebury's K R t rows and views, through take.json "sources").
TEST(TakeModel, ImportedRowsTakeEachCamerasSizeFromTheTake) {
  const fs::path data(PREVIZ_SHARED_DATA);
  ASSERT_TRUE(fs::exists(data / "middlebury-temple" / "templeSR_par.txt")) << "real data missing: " << data;
  const fs::path dir = test::scratchDir("take", "import_sizes");
  writeJsonAtomic(dir / "take.json", {{"sources", {{"*", (data / "middlebury-temple" / "{camera}").string()}}}});
  ImportOptions o;
  o.size_of = [&](const std::string& camera) -> std::optional<std::pair<int, int>> {
    TakeOptions one;
    one.cameras = {camera};
    const Take t(dir, one);
    if (!t.stream(camera).usable()) return std::nullopt;
    return std::make_pair(t.stream(camera).width, t.stream(camera).height);
  };
  const RigImport imported = importKRtRows(data / "middlebury-temple" / "templeSR_par.txt", o);
  ASSERT_EQ(imported.rig.cameras.size(), 16u);
  for (const RigCamera& rc : imported.rig.cameras) {
    EXPECT_EQ(rc.camera.width, 640) << rc.camera.name;
    EXPECT_EQ(rc.camera.height, 480) << rc.camera.name;
  }
  // A camera the take has no image of is named.
  writeJsonAtomic(dir / "take.json", {{"sources", {{"templeSR0001.png", (data / "middlebury-temple" / "templeSR0001.png").string()}}}});
  try {
    importKRtRows(data / "middlebury-temple" / "templeSR_par.txt", o);
    FAIL() << "a camera without a size imported";
  } catch (const Error& e) {
    EXPECT_EQ(e.context().camera, "templeSR0002.png") << e.what();
  }
}

// Real data as it ships (../shared/data): every view of Middlebury's temple and of the Oxford
// dino is a one-frame camera read straight from its folder through a take.json that names the
// files; nothing is renamed or copied.
TEST(TakeModel, RealViewsAreOneFrameCamerasStraightFromTheirFolder) {
  const fs::path data(PREVIZ_SHARED_DATA);
  ASSERT_TRUE(fs::exists(data / "middlebury-temple" / "templeSR_par.txt")) << "real data missing: " << data;
  struct Case {
    const char* folder;
    Rig rig;
    std::string source;  // take.json "sources" for every camera
    cv::Size size;
  };
  std::vector<Case> cases;
  // Temple rows name the views with their file ("templeSR0001.png"), the dino's without (viff000).
  cases.push_back({"middlebury-temple", readKRtRows(data / "middlebury-temple" / "templeSR_par.txt", 640, 480),
                   (data / "middlebury-temple" / "{camera}").string(), {640, 480}});
  cases.push_back({"oxford-dino", readProjectionRows(data / "oxford-dino" / "dino.P.txt", 720, 576),
                   (data / "oxford-dino" / "{camera}.png").string(), {720, 576}});
  for (const Case& c : cases) {
    const fs::path dir = test::scratchDir("take", std::string("real_") + c.folder);
    writeJsonAtomic(dir / "take.json", {{"sources", {{"*", c.source}}}});
    TakeOptions o;
    for (const RigCamera& rc : c.rig.cameras) o.cameras.push_back(rc.camera.name);
    const Take take(dir, o);
    EXPECT_EQ(take.frames(), std::vector<int>{0}) << c.folder;
    for (const RigCamera& rc : c.rig.cameras) {
      const CameraStream& s = take.stream(rc.camera.name);
      EXPECT_EQ(s.kind, SourceKind::kStill) << rc.camera.name;
      EXPECT_EQ(s.found_by, "take.json sources");
      EXPECT_EQ(cv::Size(s.width, s.height), c.size) << rc.camera.name;
      const CameraImage img = take.read(rc.camera.name, 0);
      ASSERT_TRUE(img.ok()) << img.dropped;
      const cv::Mat direct = cv::imread(s.path.string(), cv::IMREAD_COLOR);
      EXPECT_EQ(cv::norm(img.image, direct, cv::NORM_INF), 0) << rc.camera.name;
      EXPECT_FALSE(take.read(rc.camera.name, 1).ok());  // one frame only
    }
    std::printf("{\"stage\": \"take_real\", \"data\": \"%s\", \"cameras\": %zu, \"size\": \"%dx%d\"}\n", c.folder,
                c.rig.cameras.size(), c.size.width, c.size.height);
  }
}

}  // namespace
}  // namespace previz::take
