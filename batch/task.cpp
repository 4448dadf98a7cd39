// One shard's work (see task.h).
#include "batch/task.h"

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <set>

#include "batch/hash.h"
#include "batch/ledger.h"
#include "batch/process.h"
#include "core/error.h"
#include "core/io.h"
#include "core/stopwatch.h"

namespace previz::batch {
namespace fs = std::filesystem;

long long unixMs() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

fs::path shardStatePath(const Manifest& manifest, int shard) {
  return manifest.job_dir / "state" / (std::to_string(shard) + ".json");
}
fs::path shardLogDir(const Manifest& manifest) { return manifest.job_dir / "logs"; }

namespace {

void writeState(const Manifest& m, int shard, const std::string& state, long long started,
                const TaskResult* r) {
  nlohmann::json j = {{"shard", shard},
                      {"state", state},
                      {"host", [] {
                         char name[256] = {0};
                         gethostname(name, sizeof(name) - 1);
                         return std::string(name);
                       }()},
                      {"pid", static_cast<int>(::getpid())},
                      {"started_unix_ms", started},
                      {"manifest_hash", m.hash}};
  if (const char* id = std::getenv("SLURM_JOB_ID")) j["slurm_job_id"] = id;
  if (r) {
    nlohmann::json inv = nlohmann::json::array();
    for (const auto& [f, why] : r->invalidated) inv.push_back({{"frame", f}, {"why", why}});
    j["ended_unix_ms"] = unixMs();
    j["invalidated"] = inv;
    j["recorded"] = r->recorded;
    j["unfinished"] = r->unfinished;
    j["stage_errors"] = r->stage_errors;
    j["stage_ms"] = r->stage_ms;
    j["total_ms"] = r->total_ms;
  }
  writeJsonAtomic(shardStatePath(m, shard), j);
}

}  // namespace

TaskResult runShardTask(const Manifest& m, int shard_id) {
  const Stopwatch t0;
  const long long started = unixMs();  // before the input checksums: they are the task's overhead
  if (shard_id < 0 || shard_id >= static_cast<int>(m.shards.size())) {
    ErrorContext c;
    c.field = "--shard";
    throw Error("shard " + std::to_string(shard_id) + " is not in the manifest (0.." +
                    std::to_string(m.shards.size() - 1) + ")", c);
  }
  const ShardPlan& shard = m.shards[static_cast<size_t>(shard_id)];
  const TakePlan& take = m.takes[static_cast<size_t>(shard.take)];
  requireUnchangedInputs(m, &take);
  writeState(m, shard_id, "running", started, nullptr);

  TaskResult r;
  r.shard = shard_id;
  Ledger ledger = readLedger(m, shard_id);

  // Frames whose recorded files no longer match go back to their stages: removing each stage's
  // marker makes the stage redo the frame (and only it).
  for (auto it = ledger.frames.begin(); it != ledger.frames.end();) {
    std::string why;
    for (const LedgerFile& f : it->second) {
      why = checkLedgerFile(m, f);
      if (!why.empty()) break;
    }
    if (why.empty()) {
      ++it;
      continue;
    }
    for (const StagePlan& stage : take.stages) {
      std::error_code ec;
      fs::remove(m.outputs(take, stage, it->first).back(), ec);
    }
    r.invalidated.push_back({it->first, why});
    it = ledger.frames.erase(it);
  }
  // Drop entries of frames the plan does not give this shard (none, unless edited by hand).
  const std::set<int> planned(shard.frames.begin(), shard.frames.end());
  for (auto it = ledger.frames.begin(); it != ledger.frames.end();)
    it = planned.count(it->first) ? std::next(it) : ledger.frames.erase(it);
  writeLedger(m, ledger);

  const Stopwatch ts;
  for (const StagePlan& stage : take.stages) {
    const std::string stem = std::to_string(shard_id) + "." + stage.name;
    ProcessSpec spec;
    spec.argv = m.command(shard, stage);
    spec.stdout_path = shardLogDir(m) / (stem + ".json");
    spec.stderr_path = shardLogDir(m) / (stem + ".log");
    const int rc = runProcess(spec);
    if (rc != 0) {
      r.stage_errors.push_back(stage.name + ": exit " + std::to_string(rc) + " (log: " +
                               spec.stderr_path.string() + ")");
      continue;
    }
    // carve --json names the frames it selected: they must be the plan's.
    try {
      const nlohmann::json out = nlohmann::json::parse(readTextFile(spec.stdout_path));
      if (out.contains("frames_selected") && out["frames_selected"].get<std::vector<int>>() != shard.frames)
        r.stage_errors.push_back(stage.name + ": selected frames " + out["frames_selected"].dump() +
                                 " differ from the plan's " + nlohmann::json(shard.frames).dump());
    } catch (const std::exception& e) {
      r.stage_errors.push_back(stage.name + ": unreadable --json summary in " +
                               spec.stdout_path.string() + ": " + e.what());
    }
  }
  r.stage_ms = ts.ms();

  // Newly finished frames: every output of every stage present and non-empty (each stage
  // writes its marker last and atomically, so a present marker means a complete frame).
  for (int f : shard.frames) {
    if (ledger.frames.count(f)) continue;
    std::vector<LedgerFile> files;
    bool finished = true;
    for (const StagePlan& stage : take.stages) {
      for (const fs::path& p : m.outputs(take, stage, f)) {
        std::error_code ec;
        if (!fs::is_regular_file(p, ec) || fs::file_size(p, ec) == 0) {
          finished = false;
          break;
        }
        files.push_back({fs::relative(p, m.job_dir).string(), fs::file_size(p, ec), hashFile(p)});
      }
      if (!finished) break;
    }
    if (finished) {
      ledger.frames[f] = std::move(files);
      r.recorded.push_back(f);
    } else {
      r.unfinished.push_back(f);
    }
  }
  writeLedger(m, ledger);
  r.total_ms = t0.ms();
  writeState(m, shard_id, r.complete() ? "done" : "failed", started, &r);
  return r;
}

}  // namespace previz::batch
