#pragma once
// One shard's work, the same on every backend (`previz batch task JOBDIR --shard K`, run by the
// local pool or as a Slurm array task): check the inputs against the manifest, send every frame
// whose ledger entry no longer matches back to its stage (remove the stage's marker), run the
// stages' commands (each skips its finished frames), then record each newly finished frame's
// files in the ledger and the run in JOBDIR/state/<shard>.json.
#include <string>
#include <vector>

#include "batch/manifest.h"

namespace previz::batch {

struct TaskResult {
  int shard = 0;
  std::vector<std::pair<int, std::string>> invalidated;  // frames sent back: why
  std::vector<int> recorded;                             // newly written to the ledger
  std::vector<int> unfinished;                           // still not finished after the run
  std::vector<std::string> stage_errors;                 // "carve: exit 1 (log: ...)"
  double stage_ms = 0;                                   // time in the stage commands
  double total_ms = 0;
  bool complete() const { return unfinished.empty() && stage_errors.empty(); }
};

TaskResult runShardTask(const Manifest& manifest, int shard);

std::filesystem::path shardStatePath(const Manifest& manifest, int shard);
std::filesystem::path shardLogDir(const Manifest& manifest);

// Milliseconds since the Unix epoch (state files, submissions).
long long unixMs();

}  // namespace previz::batch
