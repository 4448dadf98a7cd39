// previz take info | convert: what the take model (take/take.h) finds in a take folder, and a
// take re-written in another form (videos, other sequences, timecode, late cameras).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <map>
#include <memory>
#include <set>

#include <nlohmann/json.hpp>

#include "app/commands.h"
#include "app/options.h"
#include "app/progress.h"
#include "carving/consistency.h"
#include "carving/take.h"
#include "core/error.h"
#include "core/io.h"
#include "take/convert.h"
#include "tracking/props.h"
#include "tracking/scale.h"
#include "take/stream_writer.h"
#include "take/take.h"

namespace previz::app {
namespace {

namespace fs = std::filesystem;

struct InfoArgs {
  std::string take, cameras;
  bool json = false;
};

struct ConvertArgs {
  std::string take, out, cameras, pattern, timecode;
  take::StreamWriterOptions writer;
  std::vector<std::string> lates;
  bool json = false, quiet = false;
};

// `take sync` and `take check`: the take with its rig, as carve reads it.
struct JudgeArgs {
  std::string take, rig, main_poses, masks, cameras, volume, props;
  double scale_tolerance = 0.02;
  carving::ConsistencyOptions options;
  bool write = false, json = false, quiet = false;
};

carving::TakeSource judgeSource(const JudgeArgs& a) {
  carving::TakeSource src;
  src.take_dir = a.take;
  src.rig_path = a.rig.empty() ? fs::path(a.take) / "truth" / "rig.json" : fs::path(a.rig);
  if (!a.main_poses.empty()) src.main_poses = a.main_poses;
  else if (a.rig.empty() && fs::exists(fs::path(a.take) / "truth" / "main_poses.jsonl"))
    src.main_poses = fs::path(a.take) / "truth" / "main_poses.jsonl";
  if (!a.masks.empty()) src.masks_dir = a.masks;
  return src;
}

carving::ConsistencyOptions judgeOptions(const JudgeArgs& a) {
  carving::ConsistencyOptions o = a.options;
  o.cameras = splitList(a.cameras);
  if (!a.volume.empty()) {
    const std::vector<double> v = parseNumbers(a.volume, 6, "--volume", "xmin,ymin,zmin,xmax,ymax,zmax (metres)");
    o.volume = Eigen::AlignedBox3d(Eigen::Vector3d(v[0], v[1], v[2]), Eigen::Vector3d(v[3], v[4], v[5]));
  }
  return o;
}

void addJudgeOptions(CLI::App* cmd, JudgeArgs& a) {
  cmd->add_option("take", a.take, "Take folder")->required();
  cmd->add_option("--rig", a.rig, "Rig of the take (default: the take's truth/rig.json)");
  cmd->add_option("--main-poses", a.main_poses, "Per-frame poses of a moving main camera (JSON lines)");
  cmd->add_option("--masks", a.masks, "Mattes DIR/<cam>/%06d.png instead of keying");
  cmd->add_option("--cameras", a.cameras, "Cameras judged, comma-separated (default: every rig camera)");
  cmd->add_option("--volume", a.volume, "Carving volume xmin,ymin,zmin,xmax,ymax,zmax (default: what every camera sees)");
  cmd->add_option("--search", a.options.search_frames, "Offsets searched: -N .. N frames")->capture_default_str();
  cmd->add_option("--samples", a.options.sample_frames, "Take frames judged")->capture_default_str();
  cmd->add_option("--scale", a.options.scale, "Work at this fraction of the cameras' resolution")->capture_default_str();
  cmd->add_option("--threads", a.options.threads, "OpenMP threads (0 = all cores)")->capture_default_str();
  cmd->add_flag("--json", a.json, "The result as JSON on stdout");
  cmd->add_flag("--quiet", a.quiet, "No progress lines");
}

int runSync(const JudgeArgs& a) {
  const carving::Take t(judgeSource(a));
  const carving::SyncEstimate e = carving::estimateOffsets(t, judgeOptions(a), [&](const std::string& what) {
    if (!a.quiet) std::cerr << "take sync: " << what << "\n";
  });
  bool all_sure = true;
  nlohmann::json offsets = nlohmann::json::object();
  for (const carving::OffsetEstimate& c : e.cameras) {
    std::cerr << "  " << c.camera << ": offset " << c.offset << " (" << c.evidence << ")\n";
    all_sure = all_sure && c.confident;
    if (c.confident) offsets[c.camera] = c.offset;
  }
  nlohmann::json j = e.toJson();
  j["take"] = a.take;
  if (a.write) {
    // Only what the estimate is sure of; take.json offsets and timecode still come first.
    const fs::path path = fs::path(a.take) / "out" / "sync.json";
    writeJsonAtomic(path, {{"offsets", offsets}, {"estimate", j}});
    std::cerr << "take sync: " << offsets.size() << " offsets -> " << path.string() << "\n";
  }
  if (a.json) std::cout << j.dump() << "\n";
  // Exit 3 when a camera could not be told: a script should not take the estimate as whole.
  return all_sure ? 0 : 3;
}

// The world's scale against the take's tags of known size (props.json), on the frames judged.
tracking::ScaleCheck checkScale(const carving::Take& t, const tracking::PropSet& props, const std::vector<int>& frames) {
  std::vector<tracking::ScaleFrame> sf;
  for (int f : frames) {
    tracking::ScaleFrame s;
    s.frame = f;
    for (const RigCamera& rc : t.rig().cameras) {
      s.cameras.push_back(t.cameraAt(rc.camera.name, f));
      const carving::CameraFrame plate = t.readPlate(rc.camera.name, f);
      s.images.push_back(plate.ok() ? plate.image : cv::Mat());
    }
    sf.push_back(std::move(s));
  }
  return tracking::measureScale(sf, props);
}

int runCheck(const JudgeArgs& a) {
  const carving::Take t(judgeSource(a));
  const carving::TakeCheck c = carving::checkTake(t, judgeOptions(a), [&](const std::string& what) {
    if (!a.quiet) std::cerr << "take check: " << what << "\n";
  });
  // Tags of known size, when the take has them.
  const fs::path props_path = a.props.empty() ? fs::path(a.take) / "props.json" : fs::path(a.props);
  nlohmann::json scale = nullptr;
  bool scale_off = false;
  if (fs::exists(props_path)) {
    const tracking::PropSet props = tracking::readProps(props_path);
    bool any_tag = false;
    for (const tracking::PropDef& p : props.props) any_tag = any_tag || !p.tags.empty();
    if (any_tag) {
      if (!a.quiet) std::cerr << "take check: the world's scale against the tags of " << props_path.string() << "\n";
      // Up to 12 frames spread over the whole take (tags are where the props are, not where
      // the sync search needs its margins).
      std::vector<int> frames;
      const std::vector<int>& all = t.frames();
      const size_t n = std::min<size_t>(12, all.size());
      for (size_t i = 0; i < n; ++i) frames.push_back(all[n == 1 ? 0 : i * (all.size() - 1) / (n - 1)]);
      const tracking::ScaleCheck sc = checkScale(t, props, frames);
      scale = {{"props", props_path.string()}, {"tags", sc.tags},   {"edges", sc.edges},
               {"ratio", sc.ratio},            {"spread", sc.spread}, {"frames", sc.frames}};
      if (sc.measured()) {
        scale_off = std::abs(sc.ratio - 1.0) > a.scale_tolerance;
        std::fprintf(stderr, "  world scale: tag edges measure %.4f of their printed size (+- %.4f, %d edges of %d tags)%s\n",
                     sc.ratio, sc.spread, sc.edges, sc.tags,
                     scale_off ? ": FLAGGED, the rig's world is not in metres (units, or the board's square size)" : "");
      } else {
        std::cerr << "  world scale: no tag of " << props_path.string() << " seen whole by two cameras\n";
      }
      scale["flagged"] = scale_off;
    }
  }
  int flagged = 0;
  for (const carving::CameraCheck& cc : c.cameras) {
    char line[200];
    std::snprintf(line, sizeof(line), "  %-12s IoU %.3f  covered %.3f  outside %.3f  ", cc.camera.c_str(), cc.iou,
                  cc.covered, cc.outside);
    std::cerr << line << (cc.flagged ? "FLAGGED (" + cc.cause + "): " + cc.explanation : std::string("ok")) << "\n";
    flagged += cc.flagged ? 1 : 0;
  }
  std::cerr << "take check: " << c.cameras.size() << " cameras over " << c.frames.size() << " frames, " << flagged
            << " flagged; volume " << (c.volume_automatic ? "(automatic) " : "") << c.volume.min().transpose() << " .. "
            << c.volume.max().transpose() << "\n";
  if (a.json) {
    nlohmann::json j = c.toJson();
    j["scale"] = scale;
    std::cout << j.dump() << "\n";
  }
  return flagged || scale_off ? 3 : 0;
}

take::TakeOptions takeOptions(const std::string& cameras) {
  take::TakeOptions o;
  o.cameras = splitList(cameras);
  return o;
}

int runInfo(const InfoArgs& a) {
  const take::Take t(a.take, takeOptions(a.cameras));
  const nlohmann::json info = t.info();
  if (a.json) {
    std::cout << info.dump() << "\n";
  } else {
    std::cerr << "take " << a.take << ": " << t.cameras().size() << " cameras, " << t.frames().size() << " frames";
    if (!t.frames().empty()) std::cerr << " (" << t.frames().front() << ".." << t.frames().back() << ")";
    std::cerr << ", " << t.fps() << " fps (" << t.fpsFrom() << ")"
              << (t.mainCamera().empty() ? "" : ", main '" + t.mainCamera() + "'") << "\n";
    for (const nlohmann::json& c : info["cameras"]) {
      std::cerr << "  " << c["camera"].get<std::string>() << ": " << c["kind"].get<std::string>();
      if (c["kind"] != "none") {
        std::cerr << " " << c["path"].get<std::string>();
        if (c.contains("pattern")) std::cerr << " (" << c["pattern"].get<std::string>() << ")";
        std::cerr << ", " << c["format"].get<std::string>() << " " << c["bit_depth"].get<int>() << "-bit, "
                  << c["width"].get<int>() << "x" << c["height"].get<int>() << ", " << c["frames"].get<size_t>()
                  << " frames";
        if (c.contains("source_range")) std::cerr << " " << c["source_range"][0] << ".." << c["source_range"][1];
        if (c.contains("fps")) std::cerr << " at " << c["fps"].get<double>() << " fps";
        if (!c["start_timecode"].get<std::string>().empty())
          std::cerr << ", timecode " << c["start_timecode"].get<std::string>() << " ("
                    << c["timecode_from"].get<std::string>() << ")";
        std::cerr << ", offset " << c["offset"] << " (" << c["offset_from"].get<std::string>() << ")";
        if (c.contains("take_range")) std::cerr << " -> take frames " << c["take_range"][0] << ".." << c["take_range"][1];
      }
      std::cerr << "\n";
    }
    for (const nlohmann::json& m : info["mismatches"]) std::cerr << "  ! " << m.get<std::string>() << "\n";
  }
  // A take with nothing in it, or a camera that cannot be read at all, is worth a non-zero
  // status to a script.
  if (t.cameras().empty() || t.frames().empty()) {
    std::cerr << "take info: " << a.take << ": " << (t.cameras().empty() ? "no camera found" : "no frame found") << "\n";
    return 3;
  }
  for (const nlohmann::json& c : info["cameras"])
    if (!c["usable"].get<bool>()) return 3;
  return 0;
}

int runConvert(const ConvertArgs& a) {
  take::ConvertOptions o;
  o.writer = a.writer;
  o.writer.pattern = a.pattern;
  o.writer.start_timecode = a.timecode;
  o.cameras = splitList(a.cameras);
  for (const std::string& l : a.lates) {
    const auto [name, frames] = parseNamedInt(l, "--late");
    o.late_frames[name] = frames;
  }
  std::unique_ptr<ProgressLine> line;
  const take::ConvertSummary s = take::convertTake(a.take, a.out, o, [&](long long done, long long total) {
    if (!line) line = std::make_unique<ProgressLine>("take convert", static_cast<int>(total), a.quiet);
    line->update(static_cast<int>(done));
  });
  for (const std::string& why : s.left_out) std::cerr << "take convert: left out " << why << "\n";
  std::cerr << "take convert: " << s.streams.size() << " cameras as " << o.writer.format << " -> " << a.out << "\n";
  if (a.json)
    std::cout << nlohmann::json{{"command", "take convert"}, {"out", a.out}, {"streams", s.streams},
                                {"offsets", s.offsets}, {"left_out", s.left_out}}
                     .dump()
              << "\n";
  return s.left_out.empty() ? 0 : 3;  // a partial conversion is not a quiet success
}

}  // namespace

Runner addTakeCommand(CLI::App& app) {
  CLI::App* cmd = app.add_subcommand(
      "take", "What a take folder holds (streams, frames, timecode), its cameras' sync and agreement, re-writing it");
  cmd->require_subcommand(1);
  auto info = std::make_shared<InfoArgs>();
  CLI::App* i = cmd->add_subcommand(
      "info", "Cameras, their streams (sequence pattern, video, still), size, bit depth, fps, frame range, "
              "timecode, offsets and where each came from, and every mismatch; exit 3 when a camera is unusable");
  i->add_option("take", info->take, "Take folder")->required();
  i->add_option("--cameras", info->cameras, "Cameras to look for, comma-separated (default: every one found)");
  i->add_flag("--json", info->json, "The whole description as JSON on stdout");

  auto conv = std::make_shared<ConvertArgs>();
  CLI::App* c = cmd->add_subcommand(
      "convert", "Re-write a take's camera streams in another form (video, sequence pattern, start number, bit "
                 "depth, timecode), the rest of the take copied; take.json says the new offsets");
  c->add_option("take", conv->take, "Take folder")->required();
  c->add_option("--out", conv->out, "New take folder")->required();
  c->add_option("--format", conv->writer.format, "png|jpg|png16|tif16|exr|ffv1|h264|prores")->capture_default_str();
  c->add_option("--pattern", conv->pattern, "Sequence file pattern ({camera}, %04d or ####; default %06d)");
  c->add_option("--start-number", conv->writer.first_number, "Number of a sequence's first file")
      ->capture_default_str();
  c->add_option("--timecode", conv->timecode, "Timecode of take frame 0 (EXR timeCode, the video container)");
  c->add_option("--late", conv->lates, "NAME=FRAMES: camera NAME started recording FRAMES frames late (repeatable)");
  c->add_option("--cameras", conv->cameras, "Cameras to convert, comma-separated (default: every one found)");
  c->add_flag("--json", conv->json, "Summary as JSON on stdout");
  c->add_flag("--quiet", conv->quiet, "No progress line");

  auto sync = std::make_shared<JudgeArgs>();
  CLI::App* sy = cmd->add_subcommand(
      "sync", "Estimate each camera's frame offset from the silhouettes (its frames against the hull of the "
              "others, +-N frames), with its evidence; exit 3 when a camera cannot be told");
  addJudgeOptions(sy, *sync);
  sy->add_flag("--write", sync->write,
               "Write the sure offsets to <take>/out/sync.json, where the take model reads them (after take.json "
               "offsets and timecode)");
  auto check = std::make_shared<JudgeArgs>();
  CLI::App* ch = cmd->add_subcommand(
      "check", "How much each camera agrees with the hull of the others, per frame; a camera that disagrees "
               "is named with the likely cause (out of sync, image shift, keyer); the world's scale against tags "
               "of known size; exit 3 when a camera or the scale is flagged");
  addJudgeOptions(ch, *check);
  ch->add_option("--props", check->props, "Tags of known size for the world's scale (default: the take's props.json)");
  ch->add_option("--scale-tolerance", check->scale_tolerance, "Flag the world's scale when off by more than this fraction")
      ->capture_default_str();

  return [cmd, i, c, sy, ch, info, conv, sync, check]() {
    if (i->parsed()) return runInfo(*info);
    if (c->parsed()) return runConvert(*conv);
    if (sy->parsed()) return runSync(*sync);
    if (ch->parsed()) return runCheck(*check);
    return 2;
  };
}

}  // namespace previz::app
