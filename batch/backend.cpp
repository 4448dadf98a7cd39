// Local and Slurm backends (see backend.h).
#include "batch/backend.h"

#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <fstream>
#include <sstream>

#include "batch/ledger.h"
#include "batch/process.h"
#include "batch/task.h"
#include "core/error.h"
#include "core/io.h"
#include "core/stopwatch.h"
#include "core/threads.h"

namespace previz::batch {
namespace fs = std::filesystem;

namespace {

std::vector<std::string> taskCommand(const Manifest& m, int shard) {
  return {m.previz.string(), "batch", "task", m.job_dir.string(), "--shard", std::to_string(shard)};
}

int countLedgerFrames(const Manifest& m, const std::vector<int>& shards) {
  int n = 0;
  for (int s : shards) n += static_cast<int>(readLedger(m, s).frames.size());
  return n;
}

class LocalBackend : public Backend {
 public:
  explicit LocalBackend(const LocalOptions& o) : o_(o) {
    if (o_.jobs < 1) {
      ErrorContext c;
      c.field = "--jobs";
      throw Error("batch: jobs must be >= 1 (got " + std::to_string(o_.jobs) + ")", c);
    }
  }
  std::string name() const override { return "local"; }

  Submission submit(const Manifest& m, const std::vector<int>& shards) override {
    Submission sub{"local", "local-" + std::to_string(unixMs()), shards, unixMs()};
    appendSubmission(m, sub);
    // The machine's cores, not defaultThreadCount(): this divides the whole machine among jobs
    // and sets each job's OMP_NUM_THREADS, so its own must not count.
    const int threads = o_.threads_per_job > 0 ? o_.threads_per_job : std::max(1, coreCount() / o_.jobs);
    const Stopwatch t0;
    Progress p;
    p.shards_total = static_cast<int>(shards.size());
    for (int s : shards) p.frames_total += static_cast<int>(m.shards.at(s).frames.size());
    const int frames_before = countLedgerFrames(m, shards);
    std::map<pid_t, int> running;
    size_t next = 0;
    auto report = [&]() {
      p.shards_running = static_cast<int>(running.size());
      p.frames_done = countLedgerFrames(m, shards) - frames_before;
      p.elapsed_s = t0.seconds();
      if (o_.progress) o_.progress(p);
    };
    while (next < shards.size() || !running.empty()) {
      while (next < shards.size() && static_cast<int>(running.size()) < o_.jobs) {
        const int s = shards[next++];
        ProcessSpec spec;
        spec.argv = taskCommand(m, s);
        spec.stdout_path = shardLogDir(m) / (std::to_string(s) + ".task.out");
        spec.stderr_path = shardLogDir(m) / (std::to_string(s) + ".task.log");
        spec.env["OMP_NUM_THREADS"] = std::to_string(threads);
        running[startProcess(spec)] = s;
      }
      report();
      int status = 0;
      const pid_t pid = waitpid(-1, &status, 0);
      if (pid < 0) {
        if (errno == EINTR) continue;
        throw Error("batch: waitpid failed while running shards");
      }
      if (!running.count(pid)) continue;
      running.erase(pid);
      (exitStatus(status) == 0 ? p.shards_done : p.shards_failed)++;
      report();
    }
    return sub;
  }

  std::map<int, std::string> schedulerStates(const Manifest&) override { return {}; }

 private:
  LocalOptions o_;
};

std::string trim(const std::string& s) {
  const size_t a = s.find_first_not_of(" \t\r\n");
  if (a == std::string::npos) return "";
  return s.substr(a, s.find_last_not_of(" \t\r\n") - a + 1);
}

class SlurmBackend : public Backend {
 public:
  explicit SlurmBackend(const SlurmOptions& o) : o_(o) {
    ErrorContext c;
    if (o_.cpus_per_task < 1 || o_.max_running < 0) {
      c.field = o_.cpus_per_task < 1 ? "--cpus-per-task" : "--max-running";
      throw Error("batch: cpus per task must be >= 1 and max running >= 0 (got " +
                      std::to_string(o_.cpus_per_task) + ", " + std::to_string(o_.max_running) + ")", c);
    }
  }
  std::string name() const override { return "slurm"; }

  Submission submit(const Manifest& m, const std::vector<int>& shards) override {
    if (shards.empty()) throw Error("batch: no shards to submit");
    const fs::path dir = m.job_dir / "slurm";
    fs::create_directories(dir / "logs");
    // The array task's script: the task itself, with OpenMP on the cores Slurm gave it.
    const fs::path script = dir / "task.sh";
    std::string text = "#!/bin/sh\n# previz batch: one Slurm array task = one shard (docs/formats.md, \"Batch\")\n"
                       "export OMP_NUM_THREADS=\"${SLURM_CPUS_PER_TASK:-1}\"\n"
                       "exec '" + m.previz.string() + "' batch task '" + m.job_dir.string() +
                       "' --shard \"$SLURM_ARRAY_TASK_ID\"\n";
    writeFileAtomic(script, text);
    fs::permissions(script, fs::perms::owner_all | fs::perms::group_read | fs::perms::others_read);
    std::string array = arrayList(shards);
    if (o_.max_running > 0) array += "%" + std::to_string(o_.max_running);
    std::vector<std::string> argv = {o_.sbatch, "--parsable", "--array=" + array,
                                     "--job-name=previz-" + m.hash.substr(0, 8),
                                     "--cpus-per-task=" + std::to_string(o_.cpus_per_task),
                                     "--chdir=" + m.job_dir.string(),
                                     "--output=" + (dir / "logs" / "%A_%a.out").string()};
    if (!o_.partition.empty()) argv.push_back("--partition=" + o_.partition);
    if (!o_.time_limit.empty()) argv.push_back("--time=" + o_.time_limit);
    argv.push_back(script.string());
    std::string out;
    const int rc = captureOutput(argv, out, false);
    const std::string id = trim(out.substr(0, out.find(';')));
    if (rc != 0 || id.empty() || !std::all_of(id.begin(), id.end(), ::isdigit))
      throw Error("sbatch failed (exit " + std::to_string(rc) + "): " + trim(out), fileContext(o_.sbatch));
    Submission sub{"slurm", id, shards, unixMs()};
    appendSubmission(m, sub);
    return sub;
  }

  std::map<int, std::string> schedulerStates(const Manifest& m) override {
    std::map<int, std::string> states;
    std::vector<std::string> ids;
    for (const Submission& s : readSubmissions(m))
      if (s.backend == "slurm") ids.push_back(s.job_id);
    if (ids.empty()) return states;
    std::string list;
    for (const std::string& id : ids) list += (list.empty() ? "" : ",") + id;
    // Finished tasks from accounting first (when the cluster keeps it), then the queue, which
    // is the truth for pending and running tasks. Later submissions override earlier ones.
    std::string out;
    if (captureOutput({o_.sacct, "-n", "-P", "-X", "-j", list, "-o", "JobID,State"}, out) == 0) {
      std::istringstream in(out);
      for (std::string line; std::getline(in, line);) parseLine(line, '|', states);
    }
    if (captureOutput({o_.squeue, "-h", "-r", "-t", "all", "-j", list, "-o", "%i|%T"}, out) == 0) {
      std::istringstream in(out);
      for (std::string line; std::getline(in, line);) parseLine(line, '|', states);
    }
    return states;
  }

 private:
  // "123_4|RUNNING" -> states[4] = RUNNING ("CANCELLED by 0" -> CANCELLED).
  static void parseLine(const std::string& line, char sep, std::map<int, std::string>& states) {
    const size_t bar = line.find(sep);
    if (bar == std::string::npos) return;
    const std::string id = trim(line.substr(0, bar));
    std::string state = trim(line.substr(bar + 1));
    state = state.substr(0, state.find(' '));
    const size_t us = id.find('_');
    if (us == std::string::npos) return;
    const std::string task = id.substr(us + 1);
    if (task.empty() || !std::all_of(task.begin(), task.end(), ::isdigit)) return;  // "[3-5]"
    states[std::stoi(task)] = state;
  }

  SlurmOptions o_;
};

}  // namespace

std::unique_ptr<Backend> makeLocalBackend(const LocalOptions& options) {
  return std::make_unique<LocalBackend>(options);
}
std::unique_ptr<Backend> makeSlurmBackend(const SlurmOptions& options) {
  return std::make_unique<SlurmBackend>(options);
}

std::vector<Submission> readSubmissions(const Manifest& m) {
  std::vector<Submission> subs;
  const fs::path file = m.job_dir / "submissions.jsonl";
  std::ifstream in(file);
  for (std::string line; std::getline(in, line);) {
    if (trim(line).empty()) continue;
    try {
      const nlohmann::json j = nlohmann::json::parse(line);
      if (j.value("manifest_hash", "") != m.hash) continue;  // an earlier plan's
      // Numbers checked first: a float beyond int / long long was undefined behaviour in get<>()
      // (fuzz/batch_ledger.cpp).
      if (!j.at("submitted_unix_ms").is_number_integer())
        throw Error("submitted_unix_ms must be an integer", fileContext(file, "submitted_unix_ms"));
      subs.push_back({j.at("backend").get<std::string>(), j.at("job_id").get<std::string>(),
                      jsonInts(j.at("shards"), fileContext(file, "shards")), j.at("submitted_unix_ms").get<long long>()});
    } catch (const nlohmann::json::exception& e) {
      throw Error(std::string("malformed submission line: ") + e.what(), fileContext(file));
    }
  }
  return subs;
}

void appendSubmission(const Manifest& m, const Submission& s) {
  const fs::path file = m.job_dir / "submissions.jsonl";
  std::string text;
  std::error_code ec;
  if (fs::is_regular_file(file, ec)) text = readTextFile(file);
  text += nlohmann::json({{"backend", s.backend}, {"job_id", s.job_id}, {"shards", s.shards},
                          {"submitted_unix_ms", s.submitted_unix_ms}, {"manifest_hash", m.hash}})
              .dump() + "\n";
  writeFileAtomic(file, text);
}

std::string arrayList(std::vector<int> shards) {
  std::sort(shards.begin(), shards.end());
  shards.erase(std::unique(shards.begin(), shards.end()), shards.end());
  std::string out;
  for (size_t i = 0; i < shards.size();) {
    size_t j = i;
    while (j + 1 < shards.size() && shards[j + 1] == shards[j] + 1) ++j;
    if (!out.empty()) out += ",";
    out += std::to_string(shards[i]);
    if (j > i) out += "-" + std::to_string(shards[j]);
    i = j + 1;
  }
  return out;
}

}  // namespace previz::batch
