// Writes the generated part of the seed corpora: valid files from previz's own writers (one
// small rig, lens table, board, props, tracker stream, batch job, images), each into
// <corpus>/<harness>/gen-*. The hand-written seeds (malformed cases from the tests, real files
// of other tools from ../shared/data) sit beside them. Not part of the normal build:
//   cmake --build build --target fuzz_make_seeds && build/fuzz/fuzz_make_seeds fuzz/corpus
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "batch/chan.h"
#include "batch/ledger.h"
#include "batch/manifest.h"
#include "calib/lens_table.h"
#include "core/board.h"
#include "core/camera_io.h"
#include "core/detail/image_codecs.h"
#include "core/io.h"
#include "core/rig.h"
#include "core/rig_import.h"
#include "live/tracker.h"
#include "tracking/opentrackio.h"
#include "tracking/props.h"
#include "tracking/stream.h"

namespace fs = std::filesystem;
using namespace previz;

namespace {

fs::path g_root;

fs::path seed(const std::string& harness, const std::string& name) {
  const fs::path p = g_root / harness / ("gen-" + name);
  fs::create_directories(p.parent_path());
  return p;
}
void bytes(const std::string& harness, const std::string& name, const std::string& b) {
  std::ofstream(seed(harness, name), std::ios::binary) << b;
}
std::string fileText(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

Rig smallRig() {
  Rig rig;
  for (int i = 0; i < 2; ++i) {
    RigCamera rc;
    rc.camera.name = i == 0 ? "main" : "witness01";
    rc.camera.width = 64;
    rc.camera.height = 48;
    rc.camera.fx = rc.camera.fy = 60;
    rc.camera.cx = 31.5;
    rc.camera.cy = 23.5;
    if (i == 1) rc.camera.dist.k1 = -0.1;
    rc.role = i == 0 ? "main" : "witness";
    rc.T_world_cam = lookAt(Eigen::Vector3d(2.0 * i - 1, -3, 1.5), Eigen::Vector3d(0, 0, 1));
    rig.cameras.push_back(rc);
  }
  return rig;
}
Rig noDistortion(Rig rig) {
  for (auto& rc : rig.cameras) rc.camera.dist = {};
  return rig;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s <corpus folder>\n", argv[0]);
    return 2;
  }
  g_root = argv[1];
  const fs::path tmp = fs::temp_directory_path() / ("previz-seeds-" + std::to_string(::getpid()));
  fs::create_directories(tmp);
  const Rig rig = smallRig();

  // core/
  writeRig(rig, seed("rig_json", "rig.json"));
  for (BoardType type : {BoardType::kChessboard, BoardType::kCharuco, BoardType::kAprilGrid, BoardType::kCircles,
                         BoardType::kQuadtree}) {
    BoardSpec b;
    b.type = type;
    if (type == BoardType::kAprilGrid) b.dictionary = "tag36h11";
    if (type == BoardType::kCircles) b.circle_radius_m = 0.015;
    if (type == BoardType::kQuadtree) b.rows = b.cols = 5;
    try {
      writeBoard(b, seed("board_json", std::string(toString(type)) + ".json"));
    } catch (const Error& e) {
      std::fprintf(stderr, "seed board %s: %s\n", toString(type), e.what());
    }
  }
  exportKalibr(noDistortion(rig), seed("kalibr_camchain", "camchain.yaml"));
  {
    const std::vector<fs::path> files = exportColmap(rig, tmp / "colmap");
    bytes("colmap", "model.txt", fileText(tmp / "colmap/cameras.txt") + "=== images.txt\n" +
                                     fileText(tmp / "colmap/images.txt"));
  }
  for (const fs::path& f : exportOpenCv(rig, tmp / "opencv"))
    bytes("opencv_camera", f.filename().string(), fileText(f));
  writeKRtRows(noDistortion(rig), seed("camera_rows", "krt.txt"));
  writeProjectionRows(noDistortion(rig), seed("camera_rows", "projection.txt"));
  {
    std::string lines;
    for (int f = 0; f < 3; ++f)
      lines += nlohmann::json{{"frame", f}, {"state", "tracked"}, {"T_world_cam", poseToJson(rig.cameras[0].T_world_cam)}}.dump() + "\n";
    lines += nlohmann::json{{"frame", 3}, {"state", "lost"}, {"reason", "no tag seen"}}.dump() + "\n";
    bytes("pose_lines", "camera_poses.jsonl", lines);
  }

  // Images: PNG 8/16-bit, grey, alpha; JPEG; EXR float, half, depth, with a timecode.
  {
    cv::Mat bgr(6, 8, CV_8UC3), grey16(6, 8, CV_16UC1), bgra(6, 8, CV_8UC4), grey(6, 8, CV_8UC1);
    cv::randu(bgr, 0, 255);
    cv::randu(grey16, 0, 65535);
    cv::randu(bgra, 0, 255);
    cv::randu(grey, 0, 255);
    bytes("image_decode", "bgr8.png", *detail::encodeImage(".png", bgr));
    bytes("image_decode", "grey16.png", *detail::encodeImage(".png", grey16));
    bytes("image_decode", "bgra8.png", *detail::encodeImage(".png", bgra));
    bytes("image_decode", "grey8.png", *detail::encodeImage(".png", grey));
    bytes("image_decode", "bgr8.jpg", *detail::encodeImage(".jpg", bgr));
    bytes("image_decode", "grey8.jpg", *detail::encodeImage(".jpg", grey));
    cv::Mat rgb32(4, 6, CV_32FC3), z(4, 6, CV_32FC1);
    cv::randu(rgb32, 0.f, 2.f);
    cv::randu(z, 0.5f, 5.f);
    z.at<float>(0, 0) = std::numeric_limits<float>::infinity();
    ExrImage exr{rgb32, {"B", "G", "R"}, {{"previz:pixel_origin", "centre of the top-left pixel"}}};
    writeExr(seed("exr", "float.exr"), exr);
    exr.half = true;
    exr.timecode = "01:00:00:12";
    writeExr(seed("exr", "half_timecode.exr"), exr);
    writeDepthExr(seed("exr", "depth.exr"), z);
  }

  // take/
  bytes("take_json", "take.json",
        nlohmann::json{{"fps", 24}, {"frames", 3}, {"roles", {{"main", "A"}}}, {"offsets", {{"A", 1}}},
                       {"sources", {{"A", "cams/A/a.####.png"}, {"B", "live:0"}, {"C", "cams/{camera}.mov"}}}}
            .dump(2));

  // calib/
  {
    calib::LensTable t;
    t.lens_name = "fuzz 24-70";
    t.width = 64;
    t.height = 48;
    t.sensor_width_mm = 24.9;
    t.sensor_height_mm = 18.7;
    for (double focus : {0.0, 1.0})
      for (double zoom : {0.0, 0.5, 1.0}) {
        calib::LensTableEntry e;
        e.focus = focus;
        e.zoom = zoom;
        e.camera = rig.cameras[1].camera;
        e.camera.fx = e.camera.fy = 50 + 40 * zoom + focus;
        e.entrance_pupil_m = 0.1 * zoom;
        t.entries.push_back(e);
      }
    calib::writeLensTable(seed("lens_table", "lens.json"), t);
    calib::writeUnrealLensFile(seed("lens_unreal", "lens.ulens"), t);
    calib::writeOpenTrackIoLens(seed("lens_opentrackio", "lens.json"), t);
  }

  // tracking/ and live/
  {
    tracking::PropSet props;
    props.props.push_back(tracking::makeBoxProp({}));
    tracking::BoxPropOptions plate;
    plate.prop_id = 1;
    plate.name = "plate";
    plate.first_tag_id = 10;
    plate.faces = {"-z"};
    props.props.push_back(tracking::makeBoxProp(plate));
    tracking::writeProps(props, seed("props_json", "props.json"));

    const Pose T = rig.cameras[0].T_world_cam;
    const tracking::FreeDBytes freed = tracking::encodeFreeDCamera(3, T, 1000, 2000);
    bytes("freed", "camera.bin", std::string(freed.begin(), freed.end()));
    tracking::FreeDPacket p;
    p.camera_id = 1;
    p.pan = 32768 * 10;
    p.x = 64 * 1000;
    const tracking::FreeDBytes prop = tracking::encodeFreeD(p);
    bytes("freed", "prop.bin", std::string(prop.begin(), prop.end()));

    tracking::OpenTrackIoCameraFields fields;
    fields.source_id = tracking::urnUuidFromName("fuzz");
    fields.sample_id = tracking::urnUuidFromName("fuzz sample");
    fields.sequence = 7;
    fields.sample_time_s = 1.5;
    fields.zoom = 0.25;
    fields.focus = 0.75;
    fields.timecode = tracking::SampleTimecode{1, 0, 0, 12, 24, 1, 0, false};
    const nlohmann::json sample = tracking::openTrackIoCameraSample(fields, T);
    live::TrackerRecording rec;
    for (auto enc : {tracking::OtrkEncoding::kJson, tracking::OtrkEncoding::kCbor}) {
      const auto d = tracking::encodeOtrk(tracking::encodeOtrkPayload(sample, enc), enc, 7);
      bytes("opentrackio", enc == tracking::OtrkEncoding::kJson ? "json.bin" : "cbor.bin", std::string(d.begin(), d.end()));
      rec.datagrams.push_back({0.01 * rec.datagrams.size(), d});
    }
    rec.protocol = tracking::StreamProtocol::kOpenTrackIo;
    rec.url = "otio://239.135.1.1:55555";
    live::writeRecording(seed("tracker_recording", "otio.jsonl"), rec, {});
    live::TrackerRecording fr;
    fr.protocol = tracking::StreamProtocol::kFreeD;
    fr.url = "freed://127.0.0.1:40000";
    fr.datagrams.push_back({0.0, std::vector<std::uint8_t>(freed.begin(), freed.end())});
    fr.datagrams.push_back({0.02, std::vector<std::uint8_t>(freed.begin(), freed.end() - 1)});
    live::writeRecording(seed("tracker_recording", "freed.jsonl"), fr, {});
    live::TrackerOptions o;
    o.delay_s = 0.04;
    o.source_number = 3;
    writeJsonAtomic(seed("tracker_config", "tracker.json"), live::trackerOptionsToJson(o));
  }

  // batch/
  {
    std::vector<batch::ChanKey> keys(3);
    for (int i = 0; i < 3; ++i) {
      keys[i].frame = 1001 + i;
      keys[i].translate = Eigen::Vector3d(0.1 * i, 1, 2);
      keys[i].rotate_deg = Eigen::Vector3d(10, 20 * i, -30);
    }
    batch::writeChan(seed("batch_chan", "camera.chan"), keys);

    batch::Manifest m;
    m.job_dir = tmp / "job";
    m.previz = "/usr/local/bin/previz";
    m.quality = "preview";
    m.settings = {{"voxel_m", 0.02}};
    m.rig = "/takes/rig.json";
    m.inputs.push_back({"/takes/rig.json", 1234, "0123456789abcdef"});
    m.inputs_hash = m.settings_hash = m.hash = "fuzz";
    batch::TakePlan take;
    take.name = "take1";
    take.dir = "/takes/take1";
    take.frames = {0, 1, 2, 3};
    take.main_camera = "main";
    take.work = "work/take1";
    take.stages.push_back({"carve", {"{previz}", "carve", "--shard", "{shard_index}/{shard_count}"},
                           {"work/take1/carve/depth/{frame}.exr", "work/take1/carve/done/{frame}.json"}});
    m.takes.push_back(take);
    m.shards.push_back({0, 0, 0, 2, {0, 2}});
    m.shards.push_back({1, 0, 1, 2, {1, 3}});
    writeJsonAtomic(seed("batch_manifest", "manifest.json"), m.toJson());
    batch::Ledger ledger;
    ledger.manifest_hash = "fuzz";
    ledger.frames[0] = {{"work/take1/carve/done/000000.json", 12, "0123456789abcdef"}};
    batch::writeLedger(m, ledger);
    bytes("batch_ledger", "ledger.json", fileText(batch::ledgerPath(m, 0)));
    bytes("batch_prop_track", "poses.jsonl",
          nlohmann::json{{"frame", 0},
                         {"props", {{{"id", 0}, {"name", "crate"}, {"state", "tracked"}, {"T_world_prop", poseToJson(Pose::Identity())}},
                                    {{"id", 1}, {"state", "lost"}}}}}
                  .dump() + "\n");
  }
  fs::remove_all(tmp);
  std::printf("seeds written under %s\n", g_root.c_str());
  return 0;
}
