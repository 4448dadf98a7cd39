// The batch plan (see manifest.h).
#include "batch/manifest.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <map>
#include <set>
#include <sstream>

#include "batch/hash.h"
#include "core/error.h"
#include "core/io.h"
#include "core/names.h"
#include "core/rig.h"
#include "take/take.h"

namespace previz::batch {
namespace fs = std::filesystem;

namespace {

// Every regular file under a folder, sorted (so the inputs list is reproducible).
void listFiles(const fs::path& dir, std::vector<fs::path>& files) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) return;
  std::vector<fs::path> found;
  for (const auto& entry : fs::recursive_directory_iterator(dir, ec))
    if (entry.is_regular_file(ec)) found.push_back(entry.path());
  std::sort(found.begin(), found.end());
  files.insert(files.end(), found.begin(), found.end());
}

InputFile checksum(const fs::path& file) {
  std::error_code ec;
  if (!fs::is_regular_file(file, ec)) throw Error("input file is missing", fileContext(file));
  return {file.string(), fs::file_size(file, ec), hashFile(file)};
}

nlohmann::json inputsJson(const std::vector<InputFile>& inputs) {
  nlohmann::json j = nlohmann::json::array();
  for (const InputFile& f : inputs)
    j.push_back({{"path", f.path}, {"size", f.size}, {"fnv1a64", f.fnv1a64}});
  return j;
}

std::string replaceAll(std::string text, const std::string& from, const std::string& to) {
  for (size_t at = text.find(from); at != std::string::npos; at = text.find(from, at + to.size()))
    text.replace(at, from.size(), to);
  return text;
}

// `previz carve` for one shard of a take (carving/run.h; outputs: docs/formats.md, "Carve
// output"). The report is written last, so it is the marker.
StagePlan carveStage(const Manifest& m, const TakePlan& take) {
  StagePlan s;
  s.name = "carve";
  const std::string out = (take.work / "carve").string();
  s.command = {"{previz}", "carve", "--take", take.dir.string(), "--rig", m.rig.string(),
               "--out", "{job}/" + out, "--shard", "{shard_index}/{shard_count}",
               "--voxel", nlohmann::json(m.settings["voxel_m"].get<double>()).dump(),
               "--point-spacing", nlohmann::json(m.settings["point_spacing_m"].get<double>()).dump(),
               "--threads", std::to_string(m.settings["threads"].get<int>()), "--quiet", "--json"};
  if (!take.main_poses.empty()) {
    s.command.push_back("--main-poses");
    s.command.push_back(take.main_poses.string());
  }
  if (!take.depth_cameras.empty()) {
    std::string list;
    for (const std::string& name : take.depth_cameras) list += (list.empty() ? "" : ",") + name;
    s.command.push_back("--depth-cameras");
    s.command.push_back(list);
  }
  const bool refine = m.settings.value("refine", false) && !take.main_camera.empty();
  if (refine) s.command.push_back("--refine");
  if (!take.main_camera.empty()) {
    s.outputs.push_back(out + "/depth/{frame}.exr");
    s.outputs.push_back(out + "/depth/{frame}.png");
  }
  if (refine) {
    s.outputs.push_back(out + "/depth_refined/{frame}.exr");
    s.outputs.push_back(out + "/depth_refined/{frame}.png");
  }
  for (const std::string& name : take.depth_cameras) {
    s.outputs.push_back(out + "/depth_cameras/" + name + "/{frame}.exr");
    s.outputs.push_back(out + "/depth_cameras/" + name + "/{frame}.png");
  }
  for (const char* f : {"/mesh/{frame}.ply", "/mesh/{frame}.obj", "/points/{frame}.ply",
                        "/points/{frame}.pcd", "/report/{frame}.json"})
    s.outputs.push_back(out + f);
  return s;
}

// `previz track` for one shard of a take (tracking/run.h; docs/formats.md, "Tracking"): frame
// files, every frame tracked on its own so its poses do not depend on the sharding (the same
// frame gives the same bytes from any shard, backend or resume), a frame already written kept.
// One file per frame, written atomically: it is the marker.
StagePlan trackStage(const Manifest& m, const TakePlan& take) {
  StagePlan s;
  s.name = "track";
  const std::string out = (take.work / "track").string();
  s.command = {"{previz}", "track", "--take", take.dir.string(), "--rig", m.rig.string(),
               "--props", m.props.string(), "--out", "{job}/" + out, "--shard", "{shard_index}/{shard_count}",
               "--frame-files", "--threads", std::to_string(m.settings["threads"].get<int>()), "--quiet", "--json"};
  if (!take.main_poses.empty()) {
    s.command.push_back("--main-poses");
    s.command.push_back(take.main_poses.string());
  }
  s.outputs.push_back(out + "/frames/{frame}.json");
  return s;
}

}  // namespace

void PlanOptions::validate() const {
  if (takes.empty()) throw Error("batch plan: at least one take is needed", fieldContext("--takes"));
  if (rig.empty()) throw Error("batch plan: a rig file is needed", fieldContext("--rig"));
  if (out.empty()) throw Error("batch plan: a job folder is needed", fieldContext("--out"));
  if (quality != "preview" && quality != "post")
    throw Error("batch plan: quality must be preview or post (got '" + quality + "')",
                fieldContext("--quality"));
  if (voxel_m < 0 || !std::isfinite(voxel_m))
    throw Error("batch plan: voxel_m must be > 0, or 0 for the quality's (got " +
                    std::to_string(voxel_m) + ")", fieldContext("--voxel"));
  if (frames_per_shard < 0)
    throw Error("batch plan: frames_per_shard must be >= 1, or 0 for the quality's",
                fieldContext("--frames-per-shard"));
  if (shards_per_take < 0)
    throw Error("batch plan: shards_per_take must be >= 1, or 0 to use frames_per_shard",
                fieldContext("--shards-per-take"));
  if (threads < 0) throw Error("batch plan: threads must be >= 0", fieldContext("--threads"));
  if (previz.empty()) throw Error("batch plan: the previz executable is unknown", fieldContext("previz"));
}

int Manifest::frameCount() const {
  int n = 0;
  for (const TakePlan& t : takes) n += static_cast<int>(t.frames.size());
  return n;
}

std::vector<std::string> Manifest::command(const ShardPlan& shard, const StagePlan& stage) const {
  std::vector<std::string> argv;
  for (const std::string& token : stage.command) {
    std::string t = replaceAll(token, "{previz}", previz.string());
    t = replaceAll(t, "{job}", job_dir.string());
    t = replaceAll(t, "{shard_index}", std::to_string(shard.index));
    t = replaceAll(t, "{shard_count}", std::to_string(shard.count));
    argv.push_back(t);
  }
  return argv;
}

std::vector<fs::path> Manifest::outputs(const TakePlan& take, const StagePlan& stage, int frame) const {
  std::vector<fs::path> paths;
  for (const std::string& pattern : stage.outputs)
    paths.push_back(job_dir / replaceAll(pattern, "{frame}", frameStem(frame)));
  return paths;
}

nlohmann::json Manifest::toJson() const {
  nlohmann::json takes_json = nlohmann::json::array();
  for (const TakePlan& t : takes) {
    nlohmann::json stages = nlohmann::json::array();
    for (const StagePlan& s : t.stages)
      stages.push_back({{"name", s.name}, {"command", s.command}, {"outputs", s.outputs}});
    takes_json.push_back({{"name", t.name}, {"dir", t.dir.string()}, {"frames", t.frames},
                          {"main_poses", t.main_poses.string()}, {"main_camera", t.main_camera},
                          {"depth_cameras", t.depth_cameras}, {"work", t.work.string()}, {"stages", stages}});
  }
  nlohmann::json shards_json = nlohmann::json::array();
  for (const ShardPlan& s : shards) {
    const TakePlan& t = takes[s.take];
    nlohmann::json commands = nlohmann::json::array();
    nlohmann::json expected = nlohmann::json::array();
    for (const StagePlan& stage : t.stages) {
      commands.push_back(command(s, stage));
      for (int f : s.frames)
        for (const fs::path& p : outputs(t, stage, f))
          expected.push_back(fs::relative(p, job_dir).string());
    }
    shards_json.push_back({{"id", s.id}, {"take", t.name}, {"index", s.index},
                           {"count", s.count}, {"frames", s.frames}, {"commands", commands},
                           {"outputs", expected}});
  }
  return {{"format", "previz batch manifest"},
          {"format_version", 1},
          {"previz_version", PREVIZ_VERSION},
          {"job_dir", job_dir.string()},
          {"previz", previz.string()},
          {"quality", quality},
          {"settings", settings},
          {"rig", rig.string()},
          {"props", props.string()},
          {"inputs", inputsJson(inputs)},
          {"inputs_hash", inputs_hash},
          {"settings_hash", settings_hash},
          {"hash", hash},
          {"takes", takes_json},
          {"shards", shards_json}};
}

Manifest planBatch(const PlanOptions& options) {
  options.validate();
  Manifest m;
  m.job_dir = fs::absolute(options.out).lexically_normal();
  m.previz = fs::absolute(options.previz).lexically_normal();
  m.quality = options.quality;
  m.rig = fs::absolute(options.rig).lexically_normal();
  if (!options.props.empty()) m.props = fs::absolute(options.props).lexically_normal();

  // Quality presets (docs/formats.md, "Batch"): preview = coarse cells for a quick look; post =
  // carve's own finest default and a dense point cloud.
  const bool post = options.quality == "post";
  const double voxel_m = options.voxel_m > 0 ? options.voxel_m : (post ? 0.005 : 0.02);
  const double spacing_m = options.point_spacing_m >= 0 ? options.point_spacing_m : (post ? 0.005 : 0.0);
  const int per_shard = options.frames_per_shard > 0 ? options.frames_per_shard : (post ? 5 : 20);
  const bool refine = options.refine < 0 ? post : options.refine > 0;
  m.settings = {{"voxel_m", voxel_m},
                {"point_spacing_m", spacing_m},
                {"frames_per_shard", per_shard},
                {"shards_per_take", options.shards_per_take},
                {"threads", options.threads},
                {"depth_cameras", options.depth_cameras},
                {"refine", refine},
                {"stages", m.props.empty() ? nlohmann::json{"carve"} : nlohmann::json{"carve", "track"}}};

  const Rig rig = readRig(m.rig);
  std::vector<std::string> depth_cameras;  // besides the main camera
  {
    std::vector<std::string> named;
    if (options.depth_cameras == "all") {
      for (const RigCamera& rc : rig.cameras) named.push_back(rc.camera.name);
    } else if (options.depth_cameras != "main") {
      std::stringstream in(options.depth_cameras);
      for (std::string name; std::getline(in, name, ',');) {
        if (name.empty()) continue;
        bool known = false;
        for (const RigCamera& rc : rig.cameras) known = known || rc.camera.name == name;
        if (!known)
          throw Error("batch plan: depth camera '" + name + "' is not in the rig",
                      fieldContext("--depth-cameras"));
        named.push_back(name);
      }
    }
    for (const std::string& name : named) {
      const RigCamera* rc = nullptr;
      for (const RigCamera& c : rig.cameras)
        if (c.camera.name == name) rc = &c;
      if (rc->role != kMainRole &&
          std::find(depth_cameras.begin(), depth_cameras.end(), name) == depth_cameras.end())
        depth_cameras.push_back(name);
    }
  }
  std::vector<fs::path> input_files = {m.rig};
  if (!m.props.empty()) input_files.push_back(m.props);
  if (!options.main_poses.empty()) input_files.push_back(fs::absolute(options.main_poses).lexically_normal());

  std::map<std::string, fs::path> names;
  for (const fs::path& given : options.takes) {
    TakePlan t;
    t.dir = fs::absolute(given).lexically_normal();
    if (t.dir.filename().empty()) t.dir = t.dir.parent_path();
    std::error_code ec;
    if (!fs::is_directory(t.dir, ec)) throw Error("take folder does not exist", fileContext(t.dir));
    t.name = t.dir.filename().string();
    if (names.count(t.name))
      throw Error("two takes share the folder name '" + t.name + "' (" + names[t.name].string() +
                      "); names must be unique in a batch", fileContext(t.dir));
    names[t.name] = t.dir;
    take::TakeOptions streams;
    for (const RigCamera& rc : rig.cameras) streams.cameras.push_back(rc.camera.name);
    const take::Take streams_of(t.dir, streams);
    // The frames `previz carve` selects (carving/take.cpp reads the take through the same model);
    // the task checks that they agree, so a difference cannot pass unnoticed.
    t.frames = streams_of.frames();
    if (t.frames.empty())
      throw Error("no frames: no rig camera has a readable stream (take/take.h: cams/<camera>/ sequences, "
                  "cams/<camera>.mkv|.mov|..., take.json \"sources\")",
                  fileContext(t.dir));
    for (const RigCamera& rc : rig.cameras)
      if (rc.role == kMainRole) t.main_camera = rc.camera.name;
    if (!t.main_camera.empty()) t.depth_cameras = depth_cameras;
    if (!options.main_poses.empty()) {
      t.main_poses = fs::absolute(options.main_poses).lexically_normal();
    } else if (fs::is_regular_file(t.dir / "truth" / "main_poses.jsonl", ec)) {
      t.main_poses = t.dir / "truth" / "main_poses.jsonl";
      input_files.push_back(t.main_poses);
    }
    t.work = fs::path("work") / t.name;
    // What the stages read: plates, clean plates, the take's own description.
    listFiles(t.dir / "cams", input_files);
    // Streams take.json places outside cams/ (a folder or file elsewhere).
    const fs::path cams = t.dir / "cams";
    for (const std::string& name : streams_of.cameras()) {
      const take::CameraStream& s = streams_of.stream(name);
      if (s.kind == take::SourceKind::kNone) continue;
      const fs::path rel = s.path.lexically_relative(cams);
      if (!rel.empty() && *rel.begin() != "..") continue;
      if (s.kind == take::SourceKind::kSequence) {
        for (long long f : s.source_frames) input_files.push_back(s.path / s.pattern.fileName(f));
      } else {
        input_files.push_back(s.path);
      }
    }
    listFiles(t.dir / "clean", input_files);
    if (fs::is_regular_file(t.dir / "take.json", ec)) input_files.push_back(t.dir / "take.json");
    m.takes.push_back(std::move(t));
  }
  for (TakePlan& t : m.takes) {
    t.stages.push_back(carveStage(m, t));
    if (!m.props.empty()) t.stages.push_back(trackStage(m, t));
  }

  for (const fs::path& f : input_files) m.inputs.push_back(checksum(f));
  m.inputs_hash = hashText(inputsJson(m.inputs).dump());
  nlohmann::json shaping = m.settings;
  for (const TakePlan& t : m.takes) {
    nlohmann::json stages = nlohmann::json::array();
    for (const StagePlan& s : t.stages) stages.push_back({{"command", s.command}, {"outputs", s.outputs}});
    shaping["takes"].push_back({{"name", t.name}, {"frames", t.frames}, {"stages", stages}});
  }
  m.settings_hash = hashText(shaping.dump());
  m.hash = hashText(m.inputs_hash + m.settings_hash);

  // Shards: n per take, round robin over the take's frames (carve's --shard i/n).
  for (size_t ti = 0; ti < m.takes.size(); ++ti) {
    const TakePlan& t = m.takes[ti];
    const int frames = static_cast<int>(t.frames.size());
    int n = options.shards_per_take > 0 ? options.shards_per_take : (frames + per_shard - 1) / per_shard;
    n = std::max(1, std::min(n, frames));
    for (int i = 0; i < n; ++i) {
      ShardPlan s;
      s.id = static_cast<int>(m.shards.size());
      s.take = static_cast<int>(ti);
      s.index = i;
      s.count = n;
      for (int k = i; k < frames; k += n) s.frames.push_back(t.frames[k]);
      m.shards.push_back(std::move(s));
    }
  }
  return m;
}

fs::path manifestPath(const fs::path& job_dir) { return job_dir / "manifest.json"; }

void writeManifest(const Manifest& manifest) {
  writeJsonAtomic(manifestPath(manifest.job_dir), manifest.toJson());
}

Manifest manifestFromJson(const nlohmann::json& j, const std::string& file) {
  ErrorContext c;
  c.file = file;
  try {
    if (j.value("format", "") != "previz batch manifest")
      throw Error("not a previz batch manifest (\"format\" is not \"previz batch manifest\")", c);
    Manifest m;
    m.job_dir = j.at("job_dir").get<std::string>();
    m.previz = j.at("previz").get<std::string>();
    m.quality = j.at("quality").get<std::string>();
    m.settings = j.at("settings");
    m.rig = j.at("rig").get<std::string>();
    m.props = j.at("props").get<std::string>();
    // Numbers are checked before they are converted: a float beyond the type (a size of -1.5, a
    // frame of 1e10) was undefined behaviour in get<>() (fuzz/batch_manifest.cpp).
    const auto field = [&](const std::string& name) {
      ErrorContext fc = c;
      fc.field = name;
      return fc;
    };
    for (const auto& f : j.at("inputs")) {
      if (!f.at("size").is_number_unsigned()) throw Error("inputs: size must be an integer >= 0", field("inputs.size"));
      m.inputs.push_back({f.at("path").get<std::string>(), f.at("size").get<std::uintmax_t>(),
                          f.at("fnv1a64").get<std::string>()});
    }
    m.inputs_hash = j.at("inputs_hash").get<std::string>();
    m.settings_hash = j.at("settings_hash").get<std::string>();
    m.hash = j.at("hash").get<std::string>();
    for (const auto& tj : j.at("takes")) {
      TakePlan t;
      t.name = tj.at("name").get<std::string>();
      t.dir = tj.at("dir").get<std::string>();
      t.frames = jsonInts(tj.at("frames"), field("takes.frames"));
      t.main_poses = tj.at("main_poses").get<std::string>();
      t.main_camera = tj.at("main_camera").get<std::string>();
      t.depth_cameras = tj.value("depth_cameras", std::vector<std::string>{});
      t.work = tj.at("work").get<std::string>();
      for (const auto& sj : tj.at("stages"))
        t.stages.push_back({sj.at("name").get<std::string>(),
                            sj.at("command").get<std::vector<std::string>>(),
                            sj.at("outputs").get<std::vector<std::string>>()});
      m.takes.push_back(std::move(t));
    }
    std::map<std::string, int> take_index;
    for (size_t i = 0; i < m.takes.size(); ++i) take_index[m.takes[i].name] = static_cast<int>(i);
    for (const auto& sj : j.at("shards")) {
      ShardPlan s;
      s.id = jsonInt(sj.at("id"), field("shards.id"));
      const std::string take = sj.at("take").get<std::string>();
      if (!take_index.count(take)) throw Error("shard names an unknown take '" + take + "'", c);
      s.take = take_index[take];
      s.index = jsonInt(sj.at("index"), field("shards.index"));
      s.count = jsonInt(sj.at("count"), field("shards.count"));
      s.frames = jsonInts(sj.at("frames"), field("shards.frames"));
      if (s.id != static_cast<int>(m.shards.size())) throw Error("shard ids must be 0, 1, 2, ... in order", c);
      m.shards.push_back(std::move(s));
    }
    return m;
  } catch (const nlohmann::json::exception& e) {
    throw Error(std::string("malformed batch manifest: ") + e.what(), c);
  }
}

Manifest readManifest(const fs::path& job_dir) {
  const fs::path file = manifestPath(job_dir);
  std::error_code ec;
  if (!fs::is_regular_file(file, ec))
    throw Error("no batch manifest here (run `previz batch plan --out " + job_dir.string() + "` first)",
                fileContext(file));
  Manifest m = manifestFromJson(readJsonFile(file), file.string());
  // The folder may have moved since planning; outputs live where the manifest is.
  m.job_dir = fs::absolute(job_dir).lexically_normal();
  if (m.job_dir.filename().empty()) m.job_dir = m.job_dir.parent_path();
  return m;
}

namespace {
bool under(const std::string& path, const fs::path& dir) {
  const std::string d = dir.string() + "/";
  return path.compare(0, d.size(), d) == 0;
}
}  // namespace

std::vector<InputChange> changedInputs(const Manifest& manifest, const TakePlan* take) {
  std::vector<InputChange> changes;
  std::error_code ec;
  for (const InputFile& f : manifest.inputs) {
    const bool shared = f.path == manifest.rig.string() || f.path == manifest.props.string() ||
                        (take && f.path == take->main_poses.string());
    if (take && !shared && !under(f.path, take->dir)) {
      bool other_take = false;
      for (const TakePlan& t : manifest.takes) other_take = other_take || under(f.path, t.dir);
      if (other_take) continue;
    }
    if (!fs::is_regular_file(f.path, ec)) {
      changes.push_back({f.path, "missing"});
      continue;
    }
    const std::uintmax_t size = fs::file_size(f.path, ec);
    if (size != f.size) {
      changes.push_back({f.path, "size " + std::to_string(f.size) + " -> " + std::to_string(size) + " bytes"});
      continue;
    }
    const std::string h = hashFile(f.path);
    if (h != f.fnv1a64) changes.push_back({f.path, "content changed (checksum " + f.fnv1a64 + " -> " + h + ")"});
  }
  return changes;
}

void requireUnchangedInputs(const Manifest& manifest, const TakePlan* take) {
  const std::vector<InputChange> changes = changedInputs(manifest, take);
  if (changes.empty()) return;
  std::string more;
  if (changes.size() > 1) more = " (and " + std::to_string(changes.size() - 1) + " more input files)";
  throw Error("input changed since `previz batch plan` (" + changes[0].what + ")" + more +
                  ": refusing to mix old and new outputs; plan again with --force to redo the batch",
              fileContext(changes[0].path));
}

}  // namespace previz::batch
