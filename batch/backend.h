#pragma once
// Where shards run, behind one interface: `local` (a process pool on this machine) and `slurm`
// (one `sbatch --array` job whose array task ids are shard ids). Both run the same task
// (`previz batch task JOBDIR --shard K`, batch/task.h), so their outputs are the same files.
// Every submission is appended to JOBDIR/submissions.jsonl.
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "batch/manifest.h"

namespace previz::batch {

struct Submission {
  std::string backend;     // "local" | "slurm"
  std::string job_id;      // Slurm job id; local: "local-<unix ms>"
  std::vector<int> shards;
  long long submitted_unix_ms = 0;
};

// Progress of a run: shards done / failed of total, frames finished so far.
struct Progress {
  int shards_total = 0, shards_done = 0, shards_failed = 0, shards_running = 0;
  int frames_total = 0, frames_done = 0;
  double elapsed_s = 0;
};

class Backend {
 public:
  virtual ~Backend() = default;
  virtual std::string name() const = 0;
  // Runs (local: to the end) or queues (slurm) the shards.
  virtual Submission submit(const Manifest& manifest, const std::vector<int>& shards) = 0;
  // Scheduler state of each shard of the batch's submissions that the scheduler still knows
  // (e.g. PENDING, RUNNING, CANCELLED, FAILED, COMPLETED); empty for local.
  virtual std::map<int, std::string> schedulerStates(const Manifest& manifest) = 0;
};

struct LocalOptions {
  int jobs = 1;  // processes at a time
  // Threads per task (OMP_NUM_THREADS); 0 = the machine's cores / jobs, at least 1.
  int threads_per_job = 0;
  std::function<void(const Progress&)> progress;
};
std::unique_ptr<Backend> makeLocalBackend(const LocalOptions& options);

struct SlurmOptions {
  std::string partition;      // "" = the cluster's default
  int max_running = 0;        // --array=...%N (0 = no limit)
  int cpus_per_task = 1;
  std::string time_limit;     // --time (empty = the partition's)
  std::string sbatch = "sbatch", squeue = "squeue", sacct = "sacct";
};
std::unique_ptr<Backend> makeSlurmBackend(const SlurmOptions& options);

// The batch's submissions, oldest first.
std::vector<Submission> readSubmissions(const Manifest& manifest);
void appendSubmission(const Manifest& manifest, const Submission& submission);

// Slurm's --array list for shard ids: "0-3,6,8-9".
std::string arrayList(std::vector<int> shards);

}  // namespace previz::batch
