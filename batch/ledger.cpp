// Per-shard ledgers (see ledger.h).
#include "batch/ledger.h"

#include <algorithm>
#include <optional>
#include <stdexcept>

#include "batch/hash.h"
#include "core/error.h"
#include "core/io.h"

namespace previz::batch {
namespace fs = std::filesystem;

fs::path ledgerPath(const Manifest& manifest, int shard) {
  return manifest.job_dir / "ledger" / (std::to_string(shard) + ".json");
}

Ledger readLedger(const Manifest& manifest, int shard) {
  Ledger ledger;
  ledger.manifest_hash = manifest.hash;
  ledger.shard = shard;
  const fs::path file = ledgerPath(manifest, shard);
  std::error_code ec;
  if (!fs::is_regular_file(file, ec)) return ledger;
  nlohmann::json j;
  try {
    j = readJsonFile(file);
  } catch (const Error&) {
    return ledger;  // a damaged ledger proves nothing: every frame is checked again
  }
  // Every number checked before it is converted: a "frame" of 1e10 or a "size" of -1.5 were
  // undefined behaviour in get<int>() / get<std::uintmax_t>(), a non-string "manifest_hash" a
  // type_error out of here (fuzz/batch_ledger.cpp). Anything malformed is a damaged ledger.
  if (!j.is_object() || !j.contains("manifest_hash") || !j["manifest_hash"].is_string() ||
      j["manifest_hash"].get<std::string>() != manifest.hash || !j.contains("shard") || jsonInt(j["shard"]) != shard)
    return ledger;
  try {
    for (const auto& fj : j.at("frames")) {
      std::vector<LedgerFile> files;
      for (const auto& f : fj.at("files")) {
        if (!f.at("size").is_number_unsigned()) throw std::invalid_argument("size");
        files.push_back({f.at("path").get<std::string>(), f.at("size").get<std::uintmax_t>(),
                         f.at("fnv1a64").get<std::string>()});
      }
      const std::optional<int> frame = jsonInt(fj.at("frame"));
      if (!frame) throw std::invalid_argument("frame");
      ledger.frames[*frame] = std::move(files);
    }
  } catch (const std::exception&) {
    ledger.frames.clear();
  }
  return ledger;
}

void writeLedger(const Manifest& manifest, const Ledger& ledger) {
  nlohmann::json frames = nlohmann::json::array();
  for (const auto& [frame, files] : ledger.frames) {
    nlohmann::json fj = nlohmann::json::array();
    for (const LedgerFile& f : files)
      fj.push_back({{"path", f.path}, {"size", f.size}, {"fnv1a64", f.fnv1a64}});
    frames.push_back({{"frame", frame}, {"files", fj}});
  }
  writeJsonAtomic(ledgerPath(manifest, ledger.shard),
                  {{"format", "previz batch ledger"},
                   {"manifest_hash", ledger.manifest_hash},
                   {"shard", ledger.shard},
                   {"frames", frames}},
                  1);
}

std::string checkLedgerFile(const Manifest& manifest, const LedgerFile& file) {
  const fs::path p = manifest.job_dir / file.path;
  std::error_code ec;
  if (!fs::is_regular_file(p, ec)) return file.path + " is missing";
  const std::uintmax_t size = fs::file_size(p, ec);
  if (size != file.size)
    return file.path + " has " + std::to_string(size) + " bytes, the ledger " + std::to_string(file.size);
  const std::string h = hashFile(p);
  if (h != file.fnv1a64) return file.path + " checksum " + h + " differs from the ledger's " + file.fnv1a64;
  return "";
}

std::string ShardCheck::state() const {
  if (!bad.empty()) return "corrupt";
  if (missing.empty()) return "done";
  return done.empty() ? "missing" : "partial";
}

ShardCheck checkShard(const Manifest& manifest, int shard) {
  const ShardPlan& plan = manifest.shards.at(static_cast<size_t>(shard));
  const Ledger ledger = readLedger(manifest, shard);
  ShardCheck check;
  check.shard = shard;
  for (int f : plan.frames) {
    const auto it = ledger.frames.find(f);
    if (it == ledger.frames.end()) {
      check.missing.push_back(f);
      continue;
    }
    std::string why;
    for (const LedgerFile& file : it->second) {
      why = checkLedgerFile(manifest, file);
      if (!why.empty()) break;
    }
    if (why.empty()) {
      check.done.push_back(f);
    } else {
      check.bad.push_back({f, why});
    }
  }
  return check;
}

}  // namespace previz::batch
