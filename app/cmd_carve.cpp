// previz carve: key (or take the mattes of) every witness, carve the actor's visual hull and
// write per frame the main view's depth, the hull mesh and point cloud, and a report line.
// Resumable and shardable; the job itself is carving/run.h, this only parses and prints.
#include <iostream>
#include <sstream>

#include <nlohmann/json.hpp>

#include "app/commands.h"
#include "app/options.h"
#include "app/progress.h"
#include "carving/run.h"
#include "carving/take.h"
#include "core/error.h"
#include "core/leftovers.h"

namespace previz::app {
namespace {

struct CarveArgs {
  std::string take, rig, out, masks, main_poses;
  std::string frames, shard = "0/1", volume, depth_camera, depth_cameras, cameras;
  int voxel_cells = 0;
  double voxel_m = 0.005;
  int k = 0;
  double carve_threshold = 0.5;
  int min_views = 2;
  int threads = 0;
  double point_spacing_m = 0;
  bool no_points = false;
  bool depth_everywhere = false;
  bool refine = false;
  bool json = false;
  bool quiet = false;
};

// "x0,y0,z0,x1,y1,z1" (metres, world) -> box; throws naming --volume.
Eigen::AlignedBox3d parseVolume(const std::string& text) {
  const std::string form = "x0,y0,z0,x1,y1,z1 in metres with x0 < x1, y0 < y1, z0 < z1";
  const std::vector<double> v = parseNumbers(text, 6, "--volume", form);
  if (!(v[0] < v[3] && v[1] < v[4] && v[2] < v[5]))
    throw Error("expected " + form + " (got '" + text + "')", fieldContext("--volume"));
  return Eigen::AlignedBox3d(Eigen::Vector3d(v[0], v[1], v[2]), Eigen::Vector3d(v[3], v[4], v[5]));
}

int runCarve(const CarveArgs& a) {
  carving::RunOptions o;
  o.out = a.out;
  if (!a.frames.empty()) o.frames = carving::parseFrameRange(a.frames);
  o.shard = carving::parseShard(a.shard);
  o.hull.voxel_m = a.voxel_m;
  o.hull.k = a.k;
  o.carve_threshold = a.carve_threshold;
  o.hull.min_views = a.min_views;
  o.hull.threads = a.threads;
  if (a.volume == "auto") {
    o.volume_from_silhouettes = true;
  } else if (!a.volume.empty()) {
    o.hull.volume = parseVolume(a.volume);
  }
  o.voxel_cells = a.voxel_cells;
  o.depth_camera = a.depth_camera;
  o.carve_cameras = splitList(a.cameras);
  o.depth_inside_silhouette = !a.depth_everywhere;
  o.refine_depth = a.refine;
  o.refine.threads = a.threads;
  o.photo_hull.refine.threads = a.threads;
  o.points.spacing_m = a.point_spacing_m;
  o.write_points = !a.no_points;
  o.validate();

  const carving::Take take({a.take, a.rig, a.masks, a.main_poses});
  if (a.depth_cameras == "all") {
    for (const RigCamera& rc : take.rig().cameras) o.extra_depth_cameras.push_back(rc.camera.name);
  } else {
    o.extra_depth_cameras = splitList(a.depth_cameras);
  }
  // Unsharded, this process is the folder's only writer: the temporaries of a carve killed
  // before (kill -9: carve.jsonl's; frames' own go as they are redone) are removed. Shards may
  // write the folder from other hosts, whose live processes a pid cannot tell.
  if (a.shard == "0/1") removeLeftoverTemporaries(o.out, false);
  carving::CarveJob job(take, o);
  const std::vector<int> selected = job.selectedFrames();
  int to_carve = 0;
  for (int f : selected) to_carve += job.finished(f) ? 0 : 1;
  if (!a.quiet) {
    std::cerr << "carve: " << selected.size() << " frames selected (" << selected.size() - to_carve
              << " already finished), " << job.carveCameras().size() << " carving cameras ("
              << take.rigFormat() << (take.hasMasks() ? ", masks" : ", keyed") << "), depth for "
              << (job.depthCamera().empty() ? std::string("no camera") : job.depthCamera());
    for (const std::string& name : job.extraDepthCameras()) std::cerr << ", " << name;
    std::cerr << "\n";
  }
  ProgressLine progress("carve", to_carve, a.quiet);
  const carving::RunSummary s = job.run([&](int done, int) { progress.update(done); });

  nlohmann::json dropped = nlohmann::json::array();
  for (const carving::FrameReport& r : s.carved) {
    for (const carving::DroppedCamera& d : r.cameras_dropped) {
      dropped.push_back({{"camera", d.camera}, {"frame", r.frame}, {"reason", d.reason}});
      // Always printed (--quiet only silences the progress line): a person must see it.
      std::cerr << "carve: frame " << r.frame << ": camera '" << d.camera << "' dropped: " << d.reason << "\n";
    }
  }
  nlohmann::json failed = nlohmann::json::array();
  for (const carving::FailedFrame& f : s.failed) {
    failed.push_back({{"frame", f.frame}, {"reason", f.reason}});
    std::cerr << "carve: frame " << f.frame << " failed: " << f.reason << "\n";
  }
  const double fps = s.ms > 0 ? 1000.0 * s.carved.size() / s.ms : 0.0;
  std::cerr << "carve: " << s.carved.size() << " carved, " << s.skipped.size() << " skipped (finished), "
            << s.failed.size() << " failed, " << fps << " fps -> " << a.out << "\n";
  if (a.json) {
    nlohmann::json j = {{"command", "carve"},
                        {"out", a.out},
                        {"frames_selected", s.selected},
                        {"carved", s.carved.size()},
                        {"skipped", s.skipped},
                        {"failed", failed},
                        {"dropped", dropped},
                        {"depth_camera", job.depthCamera()},
                        {"extra_depth_cameras", job.extraDepthCameras()},
                        {"refine", o.refine_depth},
                        {"carve_cameras", job.carveCameras()},
                        {"ms", s.ms},
                        {"fps", fps}};
    std::cout << j.dump() << "\n";
  }
  return s.failed.empty() ? 0 : 1;
}

}  // namespace

Runner addCarveCommand(CLI::App& app) {
  auto a = std::make_shared<CarveArgs>();
  CLI::App* cmd = app.add_subcommand(
      "carve", "Carve the actor's visual hull per frame: main-view depth, mesh, point cloud "
               "(docs/formats.md, \"Carve output\")");
  cmd->add_option("--take", a->take, "Take folder (cams/: image sequences of any pattern or videos per camera, take.json; optional clean/; docs/formats.md \"Take folder\")")
      ->required();
  cmd->add_option("--rig", a->rig,
                  "rig.json, or text rows of 3x4 projection matrices (name p11..p34) or K R t")
      ->required();
  cmd->add_option("--out", a->out, "Output folder")->required();
  cmd->add_option("--frames", a->frames, "Frames A:B (A inclusive, B exclusive), A:, :B or A");
  cmd->add_option("--shard", a->shard, "Shard i/n: every n-th selected frame from the i-th")
      ->capture_default_str();
  cmd->add_option("--k", a->k, "A cell survives outside the silhouette of at most k cameras")
      ->capture_default_str();
  cmd->add_option("--carve-threshold", a->carve_threshold,
                  "Alpha at which a carving camera's key counts a pixel inside (below 0.5: partly covered edge "
                  "pixels too, a hull that stays around the object when many views intersect)")
      ->capture_default_str();
  cmd->add_option("--voxel", a->voxel_m, "Finest cell edge, metres")->capture_default_str();
  cmd->add_option("--volume", a->volume,
                  "Carved volume x0,y0,z0,x1,y1,z1 (world, metres; default the 4 x 4 x 2.5 m stage), or 'auto': "
                  "found from the first frame's silhouettes in the rig's own units (cameras looking inward)");
  cmd->add_option("--voxel-cells", a->voxel_cells,
                  "With --volume auto: finest cell = the found volume's longest edge / N (any units; overrides --voxel)");
  cmd->add_option("--min-views", a->min_views, "Cameras that must see a cell for it to survive")
      ->capture_default_str();
  cmd->add_option("--masks", a->masks,
                  "Mattes DIR/<cam>/%06d.png (> 127 = inside) instead of keying");
  cmd->add_option("--main-poses", a->main_poses,
                  "JSON lines {frame, T_world_cam} of a moving main camera (e.g. truth/main_poses.jsonl)");
  cmd->add_option("--depth-camera", a->depth_camera,
                  "Camera to write depth for (default: the rig's main camera)");
  cmd->add_option("--depth-cameras", a->depth_cameras,
                  "Also write hull depth for cameras a,b,c (or 'all': every rig camera) in "
                  "depth_cameras/<cam>/");
  cmd->add_option("--cameras", a->cameras, "Carving cameras a,b,c (default: every witness)");
  cmd->add_flag("--depth-everywhere", a->depth_everywhere,
                "Depth wherever a ray meets the hull, not only inside the depth camera's silhouette");
  cmd->add_flag("--refine", a->refine,
                "Also write depth_refined/: depth beyond the visual hull by photo-consistency of "
                "the plates, the witnesses' own refined depths carving free space (photo hull; "
                "needs the cameras' plates, also with --masks)");
  cmd->add_option("--point-spacing", a->point_spacing_m,
                  "Point cloud: also sample faces this densely, metres (0 = mesh vertices)")
      ->capture_default_str();
  cmd->add_flag("--no-points", a->no_points,
                "Write no point cloud (points/): PCL, which the point cloud is written with, is then not loaded");
  cmd->add_option("--threads", a->threads, "OpenMP threads (0 = all cores)")->capture_default_str();
  cmd->add_flag("--json", a->json, "Print a JSON summary on stdout");
  cmd->add_flag("--quiet", a->quiet, "No progress line");
  return [a]() { return runCarve(*a); };
}

}  // namespace previz::app
