// Batch ledgers and submissions (batch/ledger.h readLedger: JOBDIR/ledger/0.json, batch/backend.h
// readSubmissions: JOBDIR/submissions.jsonl): the same bytes through both, for a manifest whose
// hash is "fuzz" (the ledger's "manifest_hash" must say so to be read at all).
#include "batch/backend.h"
#include "batch/ledger.h"
#include "fuzz/fuzz_common.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size) {
  const previz::fuzz::TempPath dir("job");
  previz::batch::Manifest manifest;
  manifest.job_dir = dir.path();
  manifest.hash = "fuzz";
  previz::fuzz::writeBytes(previz::batch::ledgerPath(manifest, 0), data, size);
  previz::fuzz::writeBytes(dir.path() / "submissions.jsonl", data, size);
  previz::fuzz::guarded([&] { previz::batch::readLedger(manifest, 0); });
  previz::fuzz::guarded([&] { previz::batch::readSubmissions(manifest); });
  return 0;
}
