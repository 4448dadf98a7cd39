// The per-frame carving job (see run.h).
#include "carving/run.h"
#include "carving/volume.h"

#include <omp.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <set>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/error.h"
#include "core/io.h"
#include "core/mesh.h"
#include "core/names.h"
#include "core/stopwatch.h"
#include "core/threads.h"

namespace previz::carving {
namespace fs = std::filesystem;

namespace {

// Whole string to int, or nullopt.
std::optional<int> toInt(const std::string& text) {
  if (text.empty()) return std::nullopt;
  size_t used = 0;
  try {
    const long v = std::stol(text, &used);
    if (used != text.size() || v < std::numeric_limits<int>::min() ||
        v > std::numeric_limits<int>::max())
      return std::nullopt;
    return static_cast<int>(v);
  } catch (const std::exception&) {
    return std::nullopt;
  }
}

// Temporaries that an interrupted writer left beside an output (core/io.h names them
// ".<file>.tmp.<pid>.…", pointcloud.cpp ".<file>.pcl.<pid>.…"): removed when their process is
// gone, so a redone frame leaves a clean folder. A live writer's temporary is left alone.
void removeLeftovers(const fs::path& output) {
  std::error_code ec;
  const fs::path dir = output.parent_path();
  if (!fs::is_directory(dir, ec)) return;
  const std::string name = output.filename().string();
  for (const char* tag : {".tmp.", ".pcl."}) {
    const std::string prefix = "." + name + tag;
    for (const auto& entry : fs::directory_iterator(dir, ec)) {
      const std::string f = entry.path().filename().string();
      if (f.compare(0, prefix.size(), prefix) != 0) continue;
      const std::string rest = f.substr(prefix.size());
      const std::optional<int> pid = toInt(rest.substr(0, rest.find('.')));
      if (pid && (*pid == ::getpid() || fs::exists("/proc/" + std::to_string(*pid), ec))) continue;
      fs::remove(entry.path(), ec);
    }
  }
}

// 8-bit preview: near = warm, far = cool (turbo colour map over the frame's depth range),
// black where empty. For eyes only; the EXR holds the numbers.
cv::Mat depthPreview(const cv::Mat& depth, double lo, double hi) {
  cv::Mat t(depth.size(), CV_8UC1, cv::Scalar(0));
  cv::Mat valid(depth.size(), CV_8UC1, cv::Scalar(0));
  const double span = hi > lo ? hi - lo : 1.0;
  for (int y = 0; y < depth.rows; ++y) {
    const float* d = depth.ptr<float>(y);
    uchar* o = t.ptr<uchar>(y);
    uchar* v = valid.ptr<uchar>(y);
    for (int x = 0; x < depth.cols; ++x) {
      if (!std::isfinite(d[x])) continue;
      o[x] = cv::saturate_cast<uchar>(40 + 215 * (hi - d[x]) / span);
      v[x] = 255;
    }
  }
  cv::Mat colour;
  cv::applyColorMap(t, colour, cv::COLORMAP_TURBO);
  cv::Mat preview(depth.size(), CV_8UC3, cv::Scalar::all(0));
  colour.copyTo(preview, valid);
  return preview;
}

// One frame's silhouettes, in the job's input-camera order.
struct FrameInputs {
  std::vector<cv::Mat> silhouettes;  // CV_8UC1 255/0; empty where dropped
  std::vector<std::string> dropped;  // "" = used, else why
  // With refine_depth: the plates (8-bit BGR; empty where unreadable, with the reason).
  std::vector<cv::Mat> plates;
  std::vector<std::string> plate_missing;
};

}  // namespace

FrameRange parseFrameRange(const std::string& text) {
  const auto bad = [&]() {
    return Error("expected A:B (A inclusive, B exclusive), A:, :B or A with frame numbers >= 0 "
                 "and A < B (got '" + text + "')",
                 fieldContext("--frames"));
  };
  FrameRange range;
  const size_t colon = text.find(':');
  if (colon == std::string::npos) {
    const auto a = toInt(text);
    if (!a || *a < 0) throw bad();
    range.first = *a;
    range.end = *a + 1;
    return range;
  }
  const std::string a = text.substr(0, colon), b = text.substr(colon + 1);
  if (a.empty() && b.empty()) throw bad();
  if (!a.empty()) {
    const auto v = toInt(a);
    if (!v || *v < 0) throw bad();
    range.first = *v;
  }
  if (!b.empty()) {
    const auto v = toInt(b);
    if (!v || *v <= range.first) throw bad();
    range.end = *v;
  }
  return range;
}

Shard parseShard(const std::string& text) {
  const size_t slash = text.find('/');
  if (slash != std::string::npos) {
    const auto i = toInt(text.substr(0, slash)), n = toInt(text.substr(slash + 1));
    if (i && n && *n >= 1 && *i >= 0 && *i < *n) return Shard{*i, *n};
  }
  throw Error("expected i/n with 0 <= i < n, e.g. 0/4 (got '" + text + "')",
              fieldContext("--shard"));
}

void RunOptions::validate() const {
  if (out.empty()) throw Error("carve: an output folder is required", fieldContext("--out"));
  hull.validate();
  keyer.validate();
  points.validate();
  if (shard.count < 1 || shard.index < 0 || shard.index >= shard.count)
    throw Error("carve: shard index must be in [0, count) (got " + std::to_string(shard.index) +
                    "/" + std::to_string(shard.count) + ")",
                fieldContext("shard"));
  if (frames.first < 0 || (frames.end >= 0 && frames.end <= frames.first))
    throw Error("carve: frame range must have 0 <= first < end", fieldContext("frames"));
  if (!(carve_threshold > 0 && carve_threshold < 1))
    throw Error("carve: carve_threshold must be in (0, 1) (got " + std::to_string(carve_threshold) + ")",
                fieldContext("carve_threshold"));
  if (voxel_cells < 0 || voxel_cells > 4096)
    throw Error("carve: voxel_cells must be in [0, 4096] (got " + std::to_string(voxel_cells) + ")",
                fieldContext("voxel_cells"));
  if (voxel_cells > 0 && !volume_from_silhouettes)
    throw Error("carve: voxel_cells sizes cells from a found volume (volume_from_silhouettes)",
                fieldContext("voxel_cells"));
  if (refine_depth) {
    refine.validate();
    photo_hull.validate();
  }
}

nlohmann::json DepthReport::toJson() const {
  return {{"camera", camera}, {"silhouette", silhouette}, {"pixels", pixels}, {"min_m", min_m},
          {"max_m", max_m}};
}

nlohmann::json FrameReport::toJson() const {
  nlohmann::json dropped = nlohmann::json::array();
  for (const DroppedCamera& d : cameras_dropped)
    dropped.push_back({{"camera", d.camera}, {"frame", frame}, {"reason", d.reason}});
  nlohmann::json extras = nlohmann::json::array();
  for (const DepthReport& d : extra_depths) extras.push_back(d.toJson());
  return {{"frame", frame},
          {"cameras_used", cameras_used},
          {"cameras_dropped", dropped},
          {"depth_camera", depth_camera},
          {"depth_silhouette", depth_silhouette},
          {"cells", {{"surface", surface_cells}, {"inside", inside_cells}, {"tested", cells_tested}}},
          {"volume_m3", volume_m3},
          {"depth_pixels", depth_pixels},
          {"depth_min_m", depth_min_m},
          {"depth_max_m", depth_max_m},
          {"extra_depths", extras},
          {"refine", refine_source.empty()
                         ? nlohmann::json(nullptr)
                         : nlohmann::json{{"source", refine_source},
                                          {"method", refine_method},
                                          {"pixels", refine_pixels},
                                          {"moved", refine_moved},
                                          {"free_space", refine_free_space},
                                          {"witnesses", refine_witnesses},
                                          {"gains_estimated", refine_gains_estimated},
                                          {"ms", refine_ms}}},
          {"mesh_vertices", mesh_vertices},
          {"mesh_faces", mesh_faces},
          {"points", points},
          {"ms", {{"key", key_ms}, {"carve", carve_ms}, {"depth", depth_ms}, {"mesh", mesh_ms},
                  {"export", export_ms}, {"total", total_ms}}}};
}

struct CarveJob::Impl {
  const Take& take;
  RunOptions options;
  std::vector<std::string> carve_names;
  std::string depth_name;
  std::vector<std::string> extra_depth_names;  // more cameras to write depth for
  // Carve cameras, then the depth camera and the extra depth cameras not among them.
  std::vector<std::string> input_names;
  // Keying is a function of the frame alone, so that a resumed or sharded run writes what an
  // uninterrupted one does (scripts/killtest.sh). A Keyer carried across frames is not: it
  // takes its screen model from the first frame it keys and remembers garbage zones from every
  // frame since (carving/keyer.h), so frame 4 keyed after frames 1..3 differed from frame 4
  // keyed first by a resumed run (by 42 of 10668 surface cells). Each frame gets a fresh Keyer
  // per camera, set up from the clean plate when there is one, else primed by keying the
  // camera's reference frame (its first readable take frame) — the same for every run.
  std::vector<KeyerOptions> keyer_options;  // per input camera
  std::vector<cv::Mat> clean_plates;        // per input camera (empty: none)
  std::vector<cv::Mat> reference_frames;    // per input camera without a clean plate
  std::vector<std::string> reference_sources;
  // Per input camera: why it is dropped for the whole take ("" = used), e.g. a clean plate the
  // keyer cannot use (another size, unreadable): the camera is left out, the take goes on.
  std::vector<std::string> unusable;
  std::unique_ptr<Carver> carver;
  nlohmann::json config;                 // what a finished frame's report must match

  Impl(const Take& t, const RunOptions& o) : take(t), options(o) {}

  fs::path path(const char* folder, int frame, const char* ext) const {
    return options.out / folder / (frameStem(frame) + ext);
  }

  // Every input camera's silhouette (mask, or key of its plate), in parallel over cameras.
  // Errors stay per camera: no exception crosses the OpenMP region (STYLE.md rule 11).
  FrameInputs readSilhouettes(int frame) {
    const int n = static_cast<int>(input_names.size());
    FrameInputs in;
    in.silhouettes.resize(n);
    in.dropped.resize(n);
    if (options.refine_depth) {
      in.plates.resize(n);
      in.plate_missing.resize(n);
    }
    const int threads = resolveThreads(options.hull.threads);
#pragma omp parallel for schedule(dynamic) num_threads(threads)
    for (int i = 0; i < n; ++i) {
      if (!unusable[i].empty()) {
        in.dropped[i] = unusable[i];
        continue;
      }
      try {
        const CameraFrame input = take.read(input_names[i], frame);
        if (!input.ok()) {
          in.dropped[i] = input.dropped;
        } else if (take.hasMasks()) {
          in.silhouettes[i] = input.mask;
          if (options.refine_depth) {
            const CameraFrame plate = take.readPlate(input_names[i], frame);
            in.plates[i] = plate.image;
            in.plate_missing[i] = plate.dropped;
          }
        } else {
          if (options.refine_depth) in.plates[i] = input.image;
          const std::string source = take.source(input_names[i], frame);
          Keyer keyer(keyer_options[i]);
          if (!clean_plates[i].empty()) keyer.setCleanPlate(clean_plates[i], "clean plate of " + input_names[i]);
          else if (!reference_frames[i].empty()) (void)keyer.key(reference_frames[i], reference_sources[i]);
          in.silhouettes[i] = keyer.key(input.image, source).silhouette;
        }
      } catch (const std::exception& e) {
        in.dropped[i] = std::string("keying failed: ") + e.what();
      }
      if (in.dropped[i].empty() && in.silhouettes[i].empty())
        in.dropped[i] = "keying gave no silhouette";
    }
    return in;
  }

  // The carving cameras' silhouettes (the first carve_names.size() inputs), dropped ones empty.
  Silhouettes carving(const FrameInputs& in) const {
    Silhouettes sil;
    for (size_t j = 0; j < carve_names.size(); ++j) {
      sil.masks.push_back(in.dropped[j].empty() ? in.silhouettes[j] : cv::Mat());
      sil.dropped.push_back(in.dropped[j]);
    }
    return sil;
  }

  // The hull from the carving cameras (the first carve_names.size() inputs).
  VisualHull carve(int frame, const FrameInputs& in) {
    const Silhouettes sil = carving(in);
    try {
      return carver->carve(sil);
    } catch (const Error& e) {
      ErrorContext c = e.context();
      c.frame = frame;
      throw Error("carving failed: " + e.message(), c);
    }
  }

  size_t inputIndex(const std::string& name) const {
    return static_cast<size_t>(std::find(input_names.begin(), input_names.end(), name) -
                               input_names.begin());
  }

  // Where camera 'name''s hull depth goes: depth/ for the depth camera, depth_cameras/<cam>/
  // for the others.
  fs::path depthPath(const std::string& name, int frame, const char* ext) const {
    if (name == depth_name) return path("depth", frame, ext);
    return options.out / "depth_cameras" / name / (frameStem(frame) + ext);
  }

  struct HullDepth {
    cv::Mat depth;
    double lo = std::numeric_limits<double>::infinity(), hi = -lo;  // finite range
  };

  // Hull depth of camera 'name' at its pose for this frame, inside its silhouette (every pixel
  // where it is dropped, or without depth_inside_silhouette): EXR and preview.
  HullDepth writeHullDepth(const std::string& name, int frame, const VisualHull& hull,
                           const FrameInputs& in, DepthReport& r) {
    const size_t d = inputIndex(name);
    r.camera = name;
    cv::Mat sil;  // empty = every pixel
    if (!options.depth_inside_silhouette) {
      r.silhouette = "none: depth wherever the ray meets the hull";
    } else if (!in.dropped[d].empty()) {
      r.silhouette = "none: " + name + " dropped (" + in.dropped[d] + ")";
    } else {
      sil = in.silhouettes[d];
      r.silhouette = take.hasMasks() ? "mask" : "key";
    }
    HullDepth h;
    h.depth = carver->depth(hull, take.cameraAt(name, frame), sil);
    for (int y = 0; y < h.depth.rows; ++y) {
      const float* p = h.depth.ptr<float>(y);
      for (int x = 0; x < h.depth.cols; ++x) {
        if (!std::isfinite(p[x])) continue;
        ++r.pixels;
        h.lo = std::min<double>(h.lo, p[x]);
        h.hi = std::max<double>(h.hi, p[x]);
      }
    }
    if (r.pixels > 0) {
      r.min_m = h.lo;
      r.max_m = h.hi;
    }
    writeDepthExr(depthPath(name, frame, ".exr"), h.depth,
                  {{"previz:camera", name}, {"previz:frame", std::to_string(frame)},
                   {"previz:source", "visual hull (previz carve)"}});
    writeImageAtomic(depthPath(name, frame, ".png"), depthPreview(h.depth, h.lo, h.hi));
    return h;
  }

  // Depth for the extra depth cameras, then for the depth camera (and its refined layer).
  void writeDepth(int frame, const VisualHull& hull, const FrameInputs& in, FrameReport& report) {
    for (const std::string& name : extra_depth_names) {
      report.extra_depths.emplace_back();
      writeHullDepth(name, frame, hull, in, report.extra_depths.back());
    }
    DepthReport main;
    const HullDepth h = writeHullDepth(depth_name, frame, hull, in, main);
    report.depth_silhouette = main.silhouette;
    report.depth_pixels = main.pixels;
    report.depth_min_m = main.min_m;
    report.depth_max_m = main.max_m;
    const cv::Mat& depth = h.depth;
    const double lo = h.lo, hi = h.hi;
    const size_t d = inputIndex(depth_name);
    if (!options.refine_depth) return;

    // The second layer: beyond the hull by photo-consistency. Without the depth camera's plate
    // (or its silhouette) it is the hull depth, and the report says why.
    cv::Mat refined = depth;
    const std::string why = !in.dropped[d].empty()       ? depth_name + " dropped"
                            : !in.plates[d].empty()      ? std::string()
                            : !in.plate_missing[d].empty() ? in.plate_missing[d]
                                                           : depth_name + " has no plate";
    if (!options.depth_inside_silhouette) {
      report.refine_source = "none: depth everywhere (no silhouette to refine in)";
    } else if (!why.empty()) {
      report.refine_source = "none: " + why;
    } else {
      std::vector<Plate> witness_plates(carve_names.size());
      std::vector<cv::Mat> witness_masks(carve_names.size());
      for (size_t j = 0; j < carve_names.size(); ++j) {
        if (!in.dropped[j].empty() || in.plates[j].empty()) continue;
        witness_plates[j] = Plate{in.plates[j], take.gain(carve_names[j])};
        witness_masks[j] = in.silhouettes[j];
      }
      PhotoHullOptions photo = options.photo_hull;
      photo.refine = options.refine;
      PhotoHullStats photo_stats;
      refined = photoHullDepth(*carver, hull, take.cameraAt(depth_name, frame),
                               Plate{in.plates[d], take.gain(depth_name)}, depth, witness_plates,
                               witness_masks, photo, &photo_stats);
      const RefineStats& stats = photo_stats.depth;
      report.refine_source = "plates";
      report.refine_method = photo.rounds > 0 ? "photo hull" : "photo-consistency";
      report.refine_pixels = stats.pixels;
      report.refine_moved = stats.moved;
      report.refine_free_space = photo_stats.free_space;
      report.refine_witnesses = stats.witnesses_used;
      report.refine_gains_estimated = stats.gains_estimated;
      report.refine_ms = photo_stats.ms;
    }
    writeDepthExr(path("depth_refined", frame, ".exr"), refined,
                  {{"previz:camera", depth_name}, {"previz:frame", std::to_string(frame)},
                   {"previz:source", report.refine_source != "plates"
                                         ? "visual hull (previz carve --refine: " + report.refine_source + ")"
                                         : "visual hull refined by " + report.refine_method + " (previz carve --refine)"}});
    writeImageAtomic(path("depth_refined", frame, ".png"), depthPreview(refined, lo, hi));
  }
};

CarveJob::CarveJob(const Take& take, const RunOptions& options)
    : impl_(std::make_unique<Impl>(take, options)) {
  Impl& m = *impl_;
  m.options.validate();
  const Rig& rig = take.rig();

  if (m.options.carve_cameras.empty()) {
    for (const RigCamera& rc : rig.cameras)
      if (rc.role == "witness") m.carve_names.push_back(rc.camera.name);
  } else {
    for (const std::string& name : m.options.carve_cameras) {
      rig.at(name);  // throws naming the camera
      if (std::find(m.carve_names.begin(), m.carve_names.end(), name) == m.carve_names.end())
        m.carve_names.push_back(name);
    }
  }
  if (m.carve_names.size() < 2)
    throw Error("carve: at least 2 carving cameras are needed (the rig has " +
                    std::to_string(m.carve_names.size()) + " with role 'witness')",
                fieldContext("carve_cameras"));

  m.depth_name = m.options.depth_camera;
  if (m.depth_name.empty()) {
    for (const RigCamera& rc : rig.cameras)
      if (rc.role == kMainRole) m.depth_name = rc.camera.name;
  } else {
    rig.at(m.depth_name);
  }

  for (const std::string& name : m.options.extra_depth_cameras) {
    rig.at(name);  // throws naming the camera
    if (m.depth_name.empty())
      throw Error("carve: extra depth cameras need a depth camera (the rig has no camera with "
                  "role 'main'; give --depth-camera)",
                  fieldContext("extra_depth_cameras"));
    if (name != m.depth_name && std::find(m.extra_depth_names.begin(), m.extra_depth_names.end(),
                                          name) == m.extra_depth_names.end())
      m.extra_depth_names.push_back(name);
  }

  m.input_names = m.carve_names;
  std::vector<std::string> depth_names = m.extra_depth_names;
  if (!m.depth_name.empty()) depth_names.insert(depth_names.begin(), m.depth_name);
  for (const std::string& name : depth_names)
    if (std::find(m.input_names.begin(), m.input_names.end(), name) == m.input_names.end())
      m.input_names.push_back(name);

  m.unusable.assign(m.input_names.size(), "");
  if (!take.hasMasks()) {
    for (size_t i = 0; i < m.input_names.size(); ++i) {
      const std::string& name = m.input_names[i];
      KeyerOptions keyer = m.options.keyer;
      if (i < m.carve_names.size()) keyer.silhouette_threshold = m.options.carve_threshold;
      m.keyer_options.push_back(keyer);
      m.clean_plates.emplace_back();
      m.reference_frames.emplace_back();
      m.reference_sources.emplace_back();
      try {
        const cv::Mat clean = take.cleanPlate(name);
        if (!clean.empty()) {
          Keyer(keyer).setCleanPlate(clean, "clean plate of " + name);  // refused here, once
          m.clean_plates.back() = clean;
        }
      } catch (const Error& e) {
        m.unusable[i] = std::string("clean plate unusable: ") + e.what();
      }
      if (m.unusable[i].empty() && m.clean_plates.back().empty()) {
        for (int f : take.frames()) {
          const CameraFrame ref = take.read(name, f);
          if (!ref.ok() || ref.image.empty()) continue;
          m.reference_frames.back() = ref.image;
          m.reference_sources.back() = take.source(name, f) + " (the keyer's reference frame)";
          break;
        }
      }
    }
  }

  std::vector<RigCamera> cameras;
  for (const std::string& name : m.carve_names) cameras.push_back(rig.at(name));
  nlohmann::json volume_from = "given";
  if (m.options.volume_from_silhouettes) {
    int first = -1;
    for (int f : take.frames())
      if (m.options.frames.contains(f)) {
        first = f;
        break;
      }
    if (first < 0) throw Error("carve: no frame selected to find the volume from", fieldContext("frames"));
    const FrameInputs in = m.readSilhouettes(first);
    const Silhouettes sil = m.carving(in);
    FoundVolume found;
    try {
      found = volumeFromSilhouettes(cameras, sil, m.options.hull);
    } catch (const Error& e) {
      ErrorContext c = e.context();
      c.frame = first;
      throw Error("carve: finding the volume: " + e.message(), c);
    }
    m.options.hull.volume = found.box;
    if (m.options.voxel_cells > 0) m.options.hull.voxel_m = found.box.sizes().maxCoeff() / m.options.voxel_cells;
    volume_from = {{"frame", first}, {"look_at", {found.look_at.x(), found.look_at.y(), found.look_at.z()}},
                   {"radius", found.radius}, {"voxel_cells", m.options.voxel_cells}};
  }
  m.carver = std::make_unique<Carver>(std::move(cameras), m.options.hull);

  const HullOptions& h = m.options.hull;
  m.config = {{"voxel_m", h.voxel_m},
              {"k", h.k},
              {"min_views", h.min_views},
              {"carve_threshold", m.options.carve_threshold},
              {"volume", {h.volume.min().x(), h.volume.min().y(), h.volume.min().z(),
                          h.volume.max().x(), h.volume.max().y(), h.volume.max().z()}},
              {"volume_from", volume_from},
              {"carve_cameras", m.carve_names},
              {"depth_camera", m.depth_name},
              {"extra_depth_cameras", m.extra_depth_names},
              {"depth_inside_silhouette", m.options.depth_inside_silhouette},
              {"silhouettes", take.hasMasks() ? "masks" : "keyer"},
              {"main_poses", take.hasMainPoses()},
              {"rig_format", take.rigFormat()},
              {"points", {{"spacing_m", m.options.points.spacing_m},
                          {"estimate_normals", m.options.points.estimate_normals}}}};
  // Only when off, so that frames carved before the option existed still count as finished.
  if (!m.options.write_points) m.config["points"]["written"] = false;
  if (m.options.refine_depth) {
    const RefineOptions& r = m.options.refine;
    m.config["refine"] = {{"search_m", r.search_m}, {"step_m", r.step_m}, {"agree", r.agree},
                          {"best_of", r.best_of}, {"visibility_m", r.visibility_m},
                          {"veto", r.veto}, {"veto_m", r.veto_m}, {"margin", r.margin}};
    const PhotoHullOptions& p = m.options.photo_hull;
    m.config["refine"]["photo_hull"] = {{"rounds", p.rounds}, {"free_m", p.free_m},
                                        {"free_views", p.free_views}, {"hidden_m", p.hidden_m},
                                        {"witness_stride", p.witness_stride},
                                        {"air_search_m", p.air_search_m},
                                        {"seen_veto", p.seen_veto}, {"seen_m", p.seen_m},
                                        {"edge_jump_m", p.edge_jump_m},
                                        {"edge_alpha", p.edge_alpha},
                                        {"edge_contrast", p.edge_contrast}};
  }
}

CarveJob::~CarveJob() = default;

const RunOptions& CarveJob::options() const { return impl_->options; }
const std::vector<std::string>& CarveJob::carveCameras() const { return impl_->carve_names; }
const std::string& CarveJob::depthCamera() const { return impl_->depth_name; }
const std::vector<std::string>& CarveJob::extraDepthCameras() const {
  return impl_->extra_depth_names;
}

std::vector<int> CarveJob::selectedFrames() const {
  const RunOptions& o = impl_->options;
  std::vector<int> in_range;
  for (int f : impl_->take.frames())
    if (o.frames.contains(f)) in_range.push_back(f);
  std::vector<int> selected;
  for (size_t i = 0; i < in_range.size(); ++i)
    if (static_cast<int>(i % o.shard.count) == o.shard.index) selected.push_back(in_range[i]);
  return selected;
}

fs::path CarveJob::reportPath(int frame) const { return impl_->path("report", frame, ".json"); }

std::vector<fs::path> CarveJob::outputs(int frame) const {
  const Impl& m = *impl_;
  std::vector<fs::path> paths;
  if (!m.depth_name.empty()) {
    paths.push_back(m.path("depth", frame, ".exr"));
    paths.push_back(m.path("depth", frame, ".png"));
    if (m.options.refine_depth) {
      paths.push_back(m.path("depth_refined", frame, ".exr"));
      paths.push_back(m.path("depth_refined", frame, ".png"));
    }
    for (const std::string& name : m.extra_depth_names) {
      paths.push_back(m.depthPath(name, frame, ".exr"));
      paths.push_back(m.depthPath(name, frame, ".png"));
    }
  }
  paths.push_back(m.path("mesh", frame, ".ply"));
  paths.push_back(m.path("mesh", frame, ".obj"));
  if (m.options.write_points) {
    paths.push_back(m.path("points", frame, ".ply"));
    paths.push_back(m.path("points", frame, ".pcd"));
  }
  paths.push_back(reportPath(frame));
  return paths;
}

bool CarveJob::finished(int frame) const {
  std::error_code ec;
  for (const fs::path& p : outputs(frame))
    if (!fs::is_regular_file(p, ec) || fs::file_size(p, ec) == 0) return false;
  try {
    const nlohmann::json report = nlohmann::json::parse(readTextFile(reportPath(frame)));
    return report.value("frame", -1) == frame && report.contains("config") &&
           report["config"] == impl_->config;
  } catch (const std::exception&) {
    return false;  // unreadable report: redo the frame
  }
}

FrameReport CarveJob::runFrame(int frame) {
  Impl& m = *impl_;
  const Stopwatch t0;
  for (const fs::path& p : outputs(frame)) removeLeftovers(p);
  FrameReport report;
  report.frame = frame;
  report.depth_camera = m.depth_name;

  const FrameInputs in = m.readSilhouettes(frame);
  report.key_ms = t0.ms();
  for (size_t i = 0; i < m.input_names.size(); ++i) {
    if (in.dropped[i].empty()) {
      report.cameras_used.push_back(m.input_names[i]);
    } else {
      report.cameras_dropped.push_back({m.input_names[i], in.dropped[i]});
    }
  }
  // A hull from fewer cameras than min_views is empty: the frame failed, it is not carved.
  int carving_usable = 0;
  std::string why;
  for (size_t i = 0; i < m.carve_names.size(); ++i) {
    if (in.dropped[i].empty()) ++carving_usable;
    else why += (why.empty() ? "" : "; ") + m.carve_names[i] + ": " + in.dropped[i];
  }
  if (carving_usable < m.options.hull.min_views) {
    ErrorContext c;
    c.frame = frame;
    throw Error("only " + std::to_string(carving_usable) + " of " + std::to_string(m.carve_names.size()) +
                    " carving cameras usable, the hull needs " + std::to_string(m.options.hull.min_views) +
                    (why.empty() ? std::string() : " (" + why + ")"),
                c);
  }

  const Stopwatch t1;
  const VisualHull hull = m.carve(frame, in);
  report.carve_ms = t1.ms();
  report.surface_cells = static_cast<long long>(hull.surface.size());
  report.inside_cells = static_cast<long long>(hull.inside.size());
  for (long long c : hull.stats.cells_tested) report.cells_tested += c;
  const double v0 = hull.voxel_m * hull.voxel_m * hull.voxel_m;
  for (const HullCell& c : hull.inside) report.volume_m3 += v0 * std::pow(8.0, c.level);
  report.volume_m3 += 0.5 * v0 * static_cast<double>(hull.surface.size());

  const Stopwatch t2;
  if (!m.depth_name.empty()) m.writeDepth(frame, hull, in, report);
  report.depth_ms = t2.ms();

  // Geometry for post.
  const Stopwatch t3;
  const TriangleMesh mesh = m.carver->mesh(hull);
  report.mesh_ms = t3.ms();
  const Stopwatch t4;
  writePly(mesh, m.path("mesh", frame, ".ply"));
  writeObj(mesh, m.path("mesh", frame, ".obj"));
  if (m.options.write_points) {
    const SurfacePoints points = surfacePoints(mesh, m.options.points);
    writePointCloudPly(points, m.path("points", frame, ".ply"));
    writePointCloudPcd(points, m.path("points", frame, ".pcd"));
    report.points = static_cast<long long>(points.size());
  }
  report.mesh_vertices = static_cast<long long>(mesh.vertices.size());
  report.mesh_faces = static_cast<long long>(mesh.faces.size());
  report.export_ms = t4.ms();
  report.total_ms = t0.ms();

  // The report last: its presence (with the same config) marks the frame finished.
  nlohmann::json line = report.toJson();
  line["config"] = m.config;
  writeFileAtomic(reportPath(frame), line.dump() + "\n");
  return report;
}

RunSummary CarveJob::run(const std::function<void(int, int)>& progress) {
  const Stopwatch t0;
  RunSummary summary;
  summary.selected = selectedFrames();
  std::vector<int> to_carve;
  for (int f : summary.selected) (finished(f) ? summary.skipped : to_carve).push_back(f);
  int done = 0;
  for (int f : to_carve) {
    try {
      summary.carved.push_back(runFrame(f));
    } catch (const std::exception& e) {
      // A frame that cannot be carved is reported and left unfinished; the take goes on.
      summary.failed.push_back({f, e.what()});
    }
    ++done;
    if (progress) progress(done, static_cast<int>(to_carve.size()));
  }

  // carve.jsonl: every finished frame of the take (all shards), in frame order.
  std::string lines;
  for (int f : impl_->take.frames()) {
    if (!finished(f)) continue;
    try {
      lines += nlohmann::json::parse(readTextFile(reportPath(f))).dump() + "\n";
    } catch (const std::exception&) {
    }
  }
  writeFileAtomic(impl_->options.out / "carve.jsonl", lines);
  summary.ms = t0.ms();
  return summary;
}

}  // namespace previz::carving
