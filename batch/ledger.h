#pragma once
// Per-shard ledger (JOBDIR/ledger/<shard>.json): for every finished frame of the shard, the size
// and checksum of each output file. A re-run trusts a frame only when its files still match;
// a damaged or missing file sends the frame back to its stage (docs/formats.md, "Batch").
#include <cstdint>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "batch/manifest.h"

namespace previz::batch {

struct LedgerFile {
  std::string path;  // relative to JOBDIR
  std::uintmax_t size = 0;
  std::string fnv1a64;
};

struct Ledger {
  std::string manifest_hash;
  int shard = 0;
  std::map<int, std::vector<LedgerFile>> frames;  // frame -> every output of every stage
};

std::filesystem::path ledgerPath(const Manifest& manifest, int shard);
// The shard's ledger; an absent one, or one written for another manifest hash, is empty.
Ledger readLedger(const Manifest& manifest, int shard);
void writeLedger(const Manifest& manifest, const Ledger& ledger);  // atomically

// Why a ledger entry no longer matches its file ("" = it matches): missing, size, checksum.
std::string checkLedgerFile(const Manifest& manifest, const LedgerFile& file);

// A shard as its ledger and files say.
struct ShardCheck {
  int shard = 0;
  std::vector<int> done;                           // in the ledger, every file matches
  std::vector<std::pair<int, std::string>> bad;    // in the ledger, a file does not match: why
  std::vector<int> missing;                        // not in the ledger
  bool complete() const { return bad.empty() && missing.empty(); }
  // "done" | "corrupt" (a bad frame) | "partial" | "missing" (nothing done)
  std::string state() const;
};
ShardCheck checkShard(const Manifest& manifest, int shard);

}  // namespace previz::batch
