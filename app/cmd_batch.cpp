// previz batch: a day's takes for post, on this machine (a process pool) or a Slurm farm.
// plan -> manifest; submit/resume -> shards run `previz batch task`, which runs the stages
// (`previz carve --shard i/n`); status; collect -> sequences for post. The work is batch/; this
// only parses and prints. Formats: docs/formats.md ("Batch").
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <algorithm>
#include <iostream>
#include <set>
#include <thread>

#include <nlohmann/json.hpp>

#include "app/commands.h"
#include "batch/backend.h"
#include "batch/collect.h"
#include "batch/ledger.h"
#include "batch/manifest.h"
#include "batch/task.h"
#include "core/error.h"
#include "core/io.h"
#include "core/leftovers.h"
#include "core/stopwatch.h"

namespace previz::app {
namespace {
namespace fs = std::filesystem;

struct BatchArgs {
  // plan
  std::vector<std::string> takes;
  std::string rig, props, main_poses, quality = "preview", depth_cameras = "all", out;
  double voxel_m = 0, point_spacing_m = -1;
  int frames_per_shard = 0, shards_per_take = 0, threads = 0;
  bool force = false, refine = false, no_refine = false;
  // submit / resume / status / collect / task
  std::string job;
  bool local = false, slurm = false, wait = false;
  int jobs = 1;
  std::string partition, time_limit;
  int max_running = 0, cpus_per_task = 1;
  double poll_s = 2.0;
  int shard = -1;
  bool y_up = false, partial = false;
  int frame_offset = 0;
  bool json = false, quiet = false;
};

std::string selfPath() {
  std::error_code ec;
  const fs::path p = fs::read_symlink("/proc/self/exe", ec);
  if (ec) throw Error("cannot find the previz executable (/proc/self/exe)");
  return p.string();
}

int runPlan(const BatchArgs& a) {
  batch::PlanOptions o;
  for (const std::string& t : a.takes) o.takes.push_back(t);
  o.rig = a.rig;
  o.props = a.props;
  o.main_poses = a.main_poses;
  o.quality = a.quality;
  o.depth_cameras = a.depth_cameras;
  if (a.refine && a.no_refine)
    throw Error("batch plan: --refine or --no-refine, not both", fieldContext("--refine"));
  o.refine = a.refine ? 1 : a.no_refine ? 0 : -1;
  o.voxel_m = a.voxel_m;
  o.point_spacing_m = a.point_spacing_m;
  o.frames_per_shard = a.frames_per_shard;
  o.shards_per_take = a.shards_per_take;
  o.threads = a.threads;
  o.out = a.out;
  o.previz = selfPath();
  const batch::Manifest m = batch::planBatch(o);
  std::error_code ec;
  bool kept = false;
  if (fs::is_regular_file(batch::manifestPath(m.job_dir), ec)) {
    const batch::Manifest old = batch::readManifest(m.job_dir);
    if (old.hash == m.hash) {
      kept = true;
    } else if (!a.force) {
      std::string what = "settings or takes changed";
      const std::vector<batch::InputChange> changes = batch::changedInputs(old);
      if (!changes.empty()) what = "input " + changes[0].path + " changed (" + changes[0].what + ")";
      else if (old.inputs_hash != m.inputs_hash) what = "the list of input files changed";
      throw Error("a different batch is planned here (" + what +
                      "); refusing to mix old and new outputs: use --force to redo it, or another --out",
                  fileContext(batch::manifestPath(m.job_dir)));
    } else {
      // Start over: nothing of the old plan may be taken for the new one.
      for (const char* d : {"work", "ledger", "state", "logs", "slurm"}) fs::remove_all(m.job_dir / d, ec);
      fs::remove(m.job_dir / "submissions.jsonl", ec);
    }
  }
  if (!kept) batch::writeManifest(m);
  std::cerr << "batch plan: " << m.takes.size() << " takes, " << m.frameCount() << " frames, "
            << m.shards.size() << " shards (quality " << m.quality << ", voxel "
            << m.settings["voxel_m"].get<double>() << " m), " << m.inputs.size() << " input files"
            << (kept ? " (already planned, unchanged)" : "") << " -> " << batch::manifestPath(m.job_dir).string()
            << "\n";
  if (a.json)
    std::cout << nlohmann::json({{"command", "batch plan"}, {"manifest", batch::manifestPath(m.job_dir).string()},
                                 {"hash", m.hash}, {"takes", m.takes.size()}, {"frames", m.frameCount()},
                                 {"shards", m.shards.size()}, {"kept", kept}})
                     .dump()
              << "\n";
  return 0;
}

// Shards whose ledger is not complete (missing, partial or corrupt frames).
std::vector<int> unfinishedShards(const batch::Manifest& m) {
  std::vector<int> to_run;
  for (const batch::ShardPlan& s : m.shards)
    if (!batch::checkShard(m, s.id).complete()) to_run.push_back(s.id);
  return to_run;
}

bool schedulerActive(const std::string& state) {
  return state == "PENDING" || state == "RUNNING" || state == "CONFIGURING" || state == "COMPLETING" ||
         state == "SUSPENDED" || state == "REQUEUED" || state == "RESIZING";
}

void printProgress(const batch::Progress& p, bool quiet) {
  if (quiet) return;
  static auto last = std::chrono::steady_clock::now() - std::chrono::seconds(10);
  const bool tty = isatty(2) != 0;
  const auto now = std::chrono::steady_clock::now();
  const bool end = p.shards_done + p.shards_failed == p.shards_total;
  if (!tty && !end && std::chrono::duration<double>(now - last).count() < 5.0) return;
  last = now;
  const double fps = p.elapsed_s > 0 ? p.frames_done / p.elapsed_s : 0.0;
  const double eta = fps > 0 ? (p.frames_total - p.frames_done) / fps : 0.0;
  std::fprintf(stderr, "%s[batch] shards %d/%d done, %d failed, %d running | frames %d/%d | %.2f frames/s | ETA %.1f s%s",
               tty ? "\r" : "", p.shards_done, p.shards_total, p.shards_failed, p.shards_running,
               p.frames_done, p.frames_total, fps, eta, tty ? "   " : "\n");
  if (tty && end) std::fprintf(stderr, "\n");
  std::fflush(stderr);
}

std::unique_ptr<batch::Backend> slurmBackend(const BatchArgs& a) {
  batch::SlurmOptions o;
  o.partition = a.partition;
  o.max_running = a.max_running;
  o.cpus_per_task = a.cpus_per_task;
  o.time_limit = a.time_limit;
  return batch::makeSlurmBackend(o);
}

// Polls the queue until none of the batch's tasks is pending or running.
void waitForSlurm(batch::Backend& backend, const batch::Manifest& m, const BatchArgs& a) {
  const Stopwatch since_start;
  Stopwatch since_print;
  int last_active = -1;
  for (;;) {
    const std::map<int, std::string> states = backend.schedulerStates(m);
    int active = 0, running = 0;
    for (const auto& [shard, state] : states) {
      active += schedulerActive(state) ? 1 : 0;
      running += state == "RUNNING" ? 1 : 0;
    }
    if (!a.quiet && (active != last_active || since_print.seconds() >= 10)) {
      std::fprintf(stderr, "[batch] slurm: %d tasks running, %d pending | elapsed %.1f s\n", running,
                   active - running, since_start.seconds());
      since_print.restart();
      last_active = active;
    }
    if (active == 0) return;
    std::this_thread::sleep_for(std::chrono::duration<double>(a.poll_s));
  }
}

int runSubmit(const BatchArgs& a, bool resume) {
  const batch::Manifest m = batch::readManifest(a.job);
  batch::requireUnchangedInputs(m);
  // What a killed local submission's processes were writing (state, ledgers, outputs): their
  // temporaries go; the tasks about to run redo what they were for. Not after a Slurm
  // submission: its tasks may still write from other hosts, whose pids this host cannot see.
  {
    const std::vector<batch::Submission> subs = batch::readSubmissions(m);
    if (std::none_of(subs.begin(), subs.end(), [](const batch::Submission& s) { return s.backend == "slurm"; }) &&
        !a.slurm)
      removeLeftoverTemporaries(m.job_dir, true);
  }
  bool use_slurm = a.slurm;
  if (resume && !a.slurm && !a.local) {
    const std::vector<batch::Submission> subs = batch::readSubmissions(m);
    use_slurm = !subs.empty() && subs.back().backend == "slurm";
  }
  if (a.slurm && a.local) throw Error("choose one backend: --local or --slurm");
  std::unique_ptr<batch::Backend> backend;
  if (use_slurm) {
    backend = slurmBackend(a);
  } else {
    batch::LocalOptions o;
    o.jobs = a.jobs;
    o.progress = [&](const batch::Progress& p) { printProgress(p, a.quiet); };
    backend = batch::makeLocalBackend(o);
  }
  std::vector<int> to_run = unfinishedShards(m);
  std::vector<int> active;
  if (use_slurm) {
    // Only what is missing: a shard the queue still runs (or will run) is left to it.
    const std::map<int, std::string> states = backend->schedulerStates(m);
    std::vector<int> keep;
    for (int s : to_run) {
      const auto it = states.find(s);
      (it != states.end() && schedulerActive(it->second) ? active : keep).push_back(s);
    }
    to_run = keep;
  }
  const char* verb = resume ? "batch resume" : "batch submit";
  nlohmann::json j = {{"command", verb}, {"backend", backend->name()}, {"shards", to_run},
                      {"still_queued", active}, {"job_id", ""}};
  if (to_run.empty()) {
    std::cerr << verb << ": nothing to do (" << m.shards.size() - active.size() << " shards finished"
              << (active.empty() ? "" : ", " + std::to_string(active.size()) + " still queued") << ")\n";
  } else {
    std::cerr << verb << ": " << to_run.size() << " of " << m.shards.size() << " shards ("
              << batch::arrayList(to_run) << ") on " << backend->name()
              << (use_slurm ? "" : " with " + std::to_string(a.jobs) + " jobs") << "\n";
    const batch::Submission sub = backend->submit(m, to_run);
    j["job_id"] = sub.job_id;
    if (use_slurm) std::cerr << verb << ": Slurm job " << sub.job_id << " (array " << batch::arrayList(to_run) << ")\n";
  }
  if (use_slurm && a.wait) waitForSlurm(*backend, m, a);
  int unfinished = 0;
  if (!use_slurm || a.wait) {
    unfinished = static_cast<int>(unfinishedShards(m).size());
    j["unfinished_shards"] = unfinished;
    std::cerr << verb << ": " << m.shards.size() - unfinished << "/" << m.shards.size() << " shards finished\n";
  }
  if (a.json) std::cout << j.dump() << "\n";
  return unfinished == 0 ? 0 : 1;
}

int runStatus(const BatchArgs& a) {
  const batch::Manifest m = batch::readManifest(a.job);
  const std::vector<batch::InputChange> changes = batch::changedInputs(m);
  const std::vector<batch::Submission> subs = batch::readSubmissions(m);
  std::map<int, std::string> sched;
  for (const batch::Submission& s : subs)
    if (s.backend == "slurm") {
      sched = slurmBackend(a)->schedulerStates(m);
      break;
    }
  nlohmann::json shards = nlohmann::json::array();
  std::map<std::string, int> counts;
  int frames_done = 0;
  for (const batch::ShardPlan& s : m.shards) {
    const batch::ShardCheck c = batch::checkShard(m, s.id);
    std::string last;
    try {
      last = readJsonFile(batch::shardStatePath(m, s.id)).value("state", "");
    } catch (const Error&) {
    }
    const std::string scheduler = sched.count(s.id) ? sched[s.id] : "";
    std::string state = c.state();
    if (state != "done" && schedulerActive(scheduler)) state = scheduler == "RUNNING" ? "running" : "queued";
    counts[state]++;
    frames_done += static_cast<int>(c.done.size());
    nlohmann::json bad = nlohmann::json::array();
    for (const auto& [f, why] : c.bad) bad.push_back({{"frame", f}, {"why", why}});
    shards.push_back({{"shard", s.id}, {"take", m.takes[s.take].name}, {"frames", s.frames}, {"state", state},
                      {"frames_done", c.done.size()}, {"missing", c.missing}, {"corrupt", bad},
                      {"last_task", last}, {"scheduler", scheduler}});
    if (!a.json) {
      std::fprintf(stderr, "shard %3d  %-16s %-8s %zu/%zu frames  task %-8s slurm %s\n", s.id,
                   m.takes[s.take].name.c_str(), state.c_str(), c.done.size(), s.frames.size(),
                   last.empty() ? "-" : last.c_str(), scheduler.empty() ? "-" : scheduler.c_str());
      for (const auto& [f, why] : c.bad) std::fprintf(stderr, "           frame %d: %s\n", f, why.c_str());
    }
  }
  std::string summary;
  for (const auto& [state, n] : counts) summary += (summary.empty() ? "" : ", ") + std::to_string(n) + " " + state;
  std::cerr << "batch status: " << summary << "; " << frames_done << "/" << m.frameCount() << " frames\n";
  for (const batch::InputChange& c : changes)
    std::cerr << "batch status: input changed since plan: " << c.path << " (" << c.what << ")\n";
  if (a.json) {
    nlohmann::json changed = nlohmann::json::array();
    for (const batch::InputChange& c : changes) changed.push_back({{"path", c.path}, {"what", c.what}});
    std::cout << nlohmann::json({{"command", "batch status"}, {"shards", shards}, {"counts", counts},
                                 {"frames_done", frames_done}, {"frames", m.frameCount()},
                                 {"inputs_changed", changed}})
                     .dump()
              << "\n";
  }
  return 0;
}

int runCollect(const BatchArgs& a) {
  const batch::Manifest m = batch::readManifest(a.job);
  batch::requireUnchangedInputs(m);
  batch::CollectOptions o;
  o.out = a.out;
  o.y_up = a.y_up;
  o.frame_offset = a.frame_offset;
  o.partial = a.partial;
  const batch::CollectSummary s = batch::collectBatch(m, o);
  std::cerr << "batch collect: " << s.frames << " frames of " << m.takes.size() << " takes -> " << a.out
            << "/index.html" << (s.missing.empty() ? "" : " (" + std::to_string(s.missing.size()) + " frames missing)")
            << "\n";
  if (a.json) {
    nlohmann::json j = s.toJson();
    j["command"] = "batch collect";
    j["out"] = a.out;
    std::cout << j.dump() << "\n";
  }
  return 0;
}

int runTask(const BatchArgs& a) {
  const batch::Manifest m = batch::readManifest(a.job);
  const batch::TaskResult r = batch::runShardTask(m, a.shard);
  for (const auto& [f, why] : r.invalidated)
    std::cerr << "batch task: shard " << r.shard << " frame " << f << " redone: " << why << "\n";
  for (const std::string& e : r.stage_errors) std::cerr << "batch task: shard " << r.shard << ": " << e << "\n";
  nlohmann::json inv = nlohmann::json::array();
  for (const auto& [f, why] : r.invalidated) inv.push_back({{"frame", f}, {"why", why}});
  std::cout << nlohmann::json({{"command", "batch task"}, {"shard", r.shard}, {"invalidated", inv},
                               {"recorded", r.recorded}, {"unfinished", r.unfinished},
                               {"stage_errors", r.stage_errors}, {"stage_ms", r.stage_ms},
                               {"total_ms", r.total_ms}})
                   .dump()
            << "\n";
  return r.complete() ? 0 : 1;
}

void addSchedulerOptions(CLI::App* cmd, BatchArgs& a) {
  cmd->add_flag("--local", a.local, "Run on this machine: a pool of --jobs processes (the default)");
  cmd->add_option("--jobs", a.jobs, "Local: shards at a time")->capture_default_str();
  cmd->add_flag("--slurm", a.slurm, "Submit one `sbatch --array` job (array task id = shard id)");
  cmd->add_option("--partition", a.partition, "Slurm partition (default: the cluster's default)");
  cmd->add_option("--max-running", a.max_running, "Slurm: at most N array tasks at once (0 = no limit)")
      ->capture_default_str();
  cmd->add_option("--cpus-per-task", a.cpus_per_task, "Slurm: cores per task (OMP_NUM_THREADS)")
      ->capture_default_str();
  cmd->add_option("--time", a.time_limit, "Slurm: time limit per task (sbatch --time)");
  cmd->add_flag("--wait", a.wait, "Slurm: wait until no task of the batch is pending or running");
  cmd->add_option("--poll", a.poll_s, "Slurm --wait: seconds between queue polls")->capture_default_str();
}

}  // namespace

Runner addBatchCommand(CLI::App& app) {
  auto a = std::make_shared<BatchArgs>();
  CLI::App* cmd = app.add_subcommand(
      "batch", "Every take of a day for post, on this machine or a Slurm farm (docs/formats.md, \"Batch\")");
  cmd->require_subcommand(1);

  CLI::App* plan = cmd->add_subcommand("plan", "Split takes into shards; write JOBDIR/manifest.json");
  plan->add_option("--takes", a->takes, "Take folders")->required()->expected(1, -1);
  plan->add_option("--rig", a->rig, "rig.json of the takes")->required();
  plan->add_option("--props", a->props, "props.json (checksummed with the inputs, for tracking)");
  plan->add_option("--main-poses", a->main_poses,
                   "Main camera poses, JSON lines {frame, T_world_cam} (default: each take's "
                   "truth/main_poses.jsonl when present, else the rig's pose)");
  plan->add_option("--quality", a->quality, "preview (voxel 0.02 m) | post (voxel 0.005 m, dense points)")
      ->capture_default_str();
  plan->add_option("--voxel", a->voxel_m, "Override the quality's finest cell edge, metres");
  plan->add_option("--point-spacing", a->point_spacing_m, "Override the quality's point spacing, metres");
  plan->add_option("--frames-per-shard", a->frames_per_shard, "Frames per shard (default: the quality's)");
  plan->add_option("--shards-per-take", a->shards_per_take, "Shards per take (overrides --frames-per-shard)");
  plan->add_option("--threads", a->threads, "Threads of each stage command (0 = the task's cores)")
      ->capture_default_str();
  plan->add_option("--depth-cameras", a->depth_cameras,
                   "Cameras besides the main one with depth sequences: all | main (none more) | a,b,c")
      ->capture_default_str();
  plan->add_flag("--refine", a->refine,
                 "Also the main camera's refined depth (carve --refine, photo hull); default with post");
  plan->add_flag("--no-refine", a->no_refine, "No refined depth, also with post");
  plan->add_option("--out", a->out, "Job folder")->required();
  plan->add_flag("--force", a->force, "Replace a different plan in --out (its outputs are removed)");
  plan->add_flag("--json", a->json, "Print a JSON summary on stdout");

  CLI::App* submit = cmd->add_subcommand("submit", "Run or queue every unfinished shard");
  submit->add_option("job", a->job, "Job folder (with manifest.json)")->required();
  addSchedulerOptions(submit, *a);
  submit->add_flag("--json", a->json, "Print a JSON summary on stdout");
  submit->add_flag("--quiet", a->quiet, "No progress line");

  CLI::App* resume = cmd->add_subcommand(
      "resume", "Submit only what is missing: unfinished or damaged shards the scheduler no longer runs "
                "(backend: the last submission's unless given)");
  resume->add_option("job", a->job, "Job folder")->required();
  addSchedulerOptions(resume, *a);
  resume->add_flag("--json", a->json, "Print a JSON summary on stdout");
  resume->add_flag("--quiet", a->quiet, "No progress line");

  CLI::App* status = cmd->add_subcommand("status", "Per-shard state: ledger, last task, Slurm (squeue/sacct)");
  status->add_option("job", a->job, "Job folder")->required();
  status->add_flag("--json", a->json, "Print the states as JSON on stdout");

  CLI::App* collect = cmd->add_subcommand("collect", "Sequences for post: meshes, points, depth, .chan, HTML");
  collect->add_option("job", a->job, "Job folder")->required();
  collect->add_option("--out", a->out, "Folder to write")->required();
  collect->add_flag("--y-up", a->y_up, "Also write y-up meshes (mesh_yup/) for Maya/Houdini");
  collect->add_option("--frame-offset", a->frame_offset, "Collected frame = take frame + offset (e.g. 1001)")
      ->capture_default_str();
  collect->add_flag("--partial", a->partial, "Collect the finished frames instead of refusing");
  collect->add_flag("--json", a->json, "Print a JSON summary on stdout");

  CLI::App* task = cmd->add_subcommand("task", "Run one shard (what the backends run)");
  task->add_option("job", a->job, "Job folder")->required();
  task->add_option("--shard", a->shard, "Shard id (the Slurm array task id)")->required();

  return [a, plan, submit, resume, status, collect, task]() {
    if (plan->parsed()) return runPlan(*a);
    if (submit->parsed()) return runSubmit(*a, false);
    if (resume->parsed()) return runSubmit(*a, true);
    if (status->parsed()) return runStatus(*a);
    if (collect->parsed()) return runCollect(*a);
    if (task->parsed()) return runTask(*a);
    return 2;
  };
}

}  // namespace previz::app
