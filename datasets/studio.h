#pragma once
// The content of the synthetic studio: the green cyclorama, the actor, the tagged prop, the
// calibration boards and the virtual (CG) set, each as primitives of a Scene at a time t.
// Everything here is deterministic given StudioConfig (seed included).
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/board.h"
#include "core/mesh.h"
#include "core/pose.h"
#include "datasets/scene.h"

namespace previz::synth {

using previz::TriangleMesh;
// Nearest ray–mesh intersection (Möller–Trumbore, brute force; for tests). +inf if none.
double intersectMesh(const TriangleMesh& mesh, const Ray& ray);

// A tag on a prop. Tag frame (AprilTag's convention): origin at the tag centre, x right and
// y down as the tag is read, z into the tag (so the visible face looks along -z).
// size_m is the edge of the tag's outer black border, as libapriltag's tagsize.
struct PropTag {
  std::string family = "tag36h11";
  int id = 0;
  double size_m = 0.12;
  Pose T_prop_tag = Pose::Identity();
};
struct PropSpec {
  int id = 0;
  std::string name = "crate";
  Eigen::Vector3d box_size_m = Eigen::Vector3d(0.3, 0.3, 0.3);  // prop frame at the box centre
  std::vector<PropTag> tags;
};

// What the stage is dressed in: a green or a blue cyclorama, or no screen at all (a set: a
// painted-panel wall and a wooden floor on the same surfaces, keyed by difference against a
// clean plate). The geometry, the lights and the shadows are the same in all three.
enum class Backdrop { kGreen, kBlue, kSet };
const char* toString(Backdrop backdrop);
Backdrop backdropFromString(const std::string& name);  // "green" | "blue" | "set"; throws Error

struct StudioConfig {
  std::uint64_t seed = 1;
  double stage_size_m = 4.0;       // square acting area centred on the world origin
  double cyc_size_m = 16.0;        // green floor extent (square); beyond it: dark studio
  double wall_height_m = 4.5;      // two green walls, at y = +cyc/2 ... see studio.cpp
  double take_duration_s = 10.0;   // actor and prop paths are parametrised over this
  bool with_actor = true;
  bool with_prop = true;
  Backdrop backdrop = Backdrop::kGreen;
};

class Studio {
 public:
  explicit Studio(const StudioConfig& config);

  // Scene at time t (seconds from the take start) with the given layers (scene.h Layer).
  // Boards are added by the caller with makeBoard().
  Scene sceneAt(double time_s, unsigned layers) const;

  // True actor geometry at time t: closed triangle mesh of every body part, fine enough that
  // it lies within 0.3 mm of the analytic surface the renderer traces.
  TriangleMesh actorMesh(double time_s) const;
  // Axis-aligned world bounds of the actor at time t (for camera aiming and tests).
  Eigen::AlignedBox3d actorBounds(double time_s) const;

  const PropSpec& prop() const { return prop_; }
  Pose T_world_prop(double time_s) const;

  const StudioConfig& config() const { return config_; }

 private:
  StudioConfig config_;
  PropSpec prop_;
};

// A flat printed board (white margin + pattern, see core/board.h) placed at T_world_board.
// Pattern pixels are exact: black/white edges lie where boardPoints() says they do.
std::shared_ptr<const Primitive> makeBoard(const BoardSpec& spec, const Pose& T_world_board);

// Default boards used by the synthetic takes (sizes suited to a 1–3 m working distance).
BoardSpec defaultBoard(BoardType type);

}  // namespace previz::synth
