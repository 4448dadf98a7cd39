#pragma once
// The plan of a batch: every take split into shards of frames, the command each stage of a
// shard runs, the files each frame must end with, and checksums of every input and of the
// settings. `previz batch plan` writes it (JOBDIR/manifest.json); every later verb and every
// task reads it, and refuses to go on when an input changed since (docs/formats.md, "Batch").
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace previz::batch {

struct PlanOptions {
  std::vector<std::filesystem::path> takes;  // take folders (carving/take.h layout)
  std::filesystem::path rig;                 // rig.json for every take
  std::filesystem::path props;               // optional props.json (checksummed, for tracking)
  // Main camera poses (JSON lines {frame, T_world_cam}) for every take; empty: each take's
  // truth/main_poses.jsonl when it has one, else the rig's static main pose.
  std::filesystem::path main_poses;
  std::string quality = "preview";  // "preview" | "post" (docs/formats.md, "Batch")
  double voxel_m = 0;               // 0 = the quality's
  double point_spacing_m = -1;      // < 0 = the quality's
  int frames_per_shard = 0;         // 0 = the quality's
  int shards_per_take = 0;          // > 0 overrides frames_per_shard
  int threads = 0;                  // carve --threads in each task (0 = the task's cores)
  // Cameras besides the main one whose hull depth sequence is written (carve --depth-cameras):
  // "all" = every rig camera, "main" = none more, or names a,b,c.
  std::string depth_cameras = "all";
  // The main camera's refined depth layer too (carve --refine: photo hull, depth_refined/):
  // -1 = the quality's (post: yes, preview: no), 0 = no, 1 = yes.
  int refine = -1;
  std::filesystem::path out;        // JOBDIR
  std::filesystem::path previz;     // the previz executable tasks run (absolute)
  void validate() const;            // throws Error naming the field
};

// One stage of every shard of a take: a command (argv; {shard_index} and {shard_count} are
// replaced per shard) and the files it leaves per frame (paths relative to JOBDIR, {frame} =
// %06d). The last output is the stage's marker: removing it makes the stage redo the frame.
struct StagePlan {
  std::string name;
  std::vector<std::string> command;
  std::vector<std::string> outputs;
};

struct TakePlan {
  std::string name;                   // folder name, unique in the batch
  std::filesystem::path dir;          // absolute
  std::vector<int> frames;            // ascending
  std::filesystem::path main_poses;   // "" = the rig's static pose
  std::string main_camera;            // rig camera with role "main" ("" = none: no depth)
  std::vector<std::string> depth_cameras;  // more cameras with depth (none without a main one)
  std::filesystem::path work;         // JOBDIR-relative folder of the stages' outputs
  std::vector<StagePlan> stages;
};

struct ShardPlan {
  int id = 0;        // index in Manifest::shards = Slurm array task id
  int take = 0;      // index in Manifest::takes
  int index = 0;     // --shard index/count of the take's stage commands
  int count = 1;
  std::vector<int> frames;
};

struct InputFile {
  std::string path;  // absolute
  std::uintmax_t size = 0;
  std::string fnv1a64;
};

struct Manifest {
  std::filesystem::path job_dir;  // absolute
  std::filesystem::path previz;
  std::string quality;
  nlohmann::json settings;        // every setting that shapes an output
  std::filesystem::path rig, props;
  std::vector<InputFile> inputs;
  std::string inputs_hash, settings_hash, hash;
  std::vector<TakePlan> takes;
  std::vector<ShardPlan> shards;

  int frameCount() const;
  // argv of a stage of a shard, placeholders replaced.
  std::vector<std::string> command(const ShardPlan& shard, const StagePlan& stage) const;
  // Absolute paths of every stage's outputs for one frame of the take, marker of each stage last
  // among that stage's.
  std::vector<std::filesystem::path> outputs(const TakePlan& take, const StagePlan& stage,
                                             int frame) const;
  std::filesystem::path path(const std::string& relative) const { return job_dir / relative; }
  nlohmann::json toJson() const;
};

// Builds the plan: lists each take's frames, checksums the inputs. Throws Error naming the take,
// file or field. Writes nothing.
Manifest planBatch(const PlanOptions& options);

std::filesystem::path manifestPath(const std::filesystem::path& job_dir);
void writeManifest(const Manifest& manifest);  // JOBDIR/manifest.json, atomically
Manifest readManifest(const std::filesystem::path& job_dir);
Manifest manifestFromJson(const nlohmann::json& j, const std::string& file);

struct InputChange {
  std::string path;
  std::string what;  // "missing", "size 123 -> 456", "content changed (checksum a -> b)"
};
// Re-checksums every input of the manifest; with 'take', only the files of that take and those
// of no take (rig, props, main poses): what one shard's task reads.
std::vector<InputChange> changedInputs(const Manifest& manifest, const TakePlan* take = nullptr);
// Throws Error naming the first changed file (and how many more) unless nothing changed.
void requireUnchangedInputs(const Manifest& manifest, const TakePlan* take = nullptr);

}  // namespace previz::batch
