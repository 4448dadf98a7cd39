// OpenTrackIO datagrams as live/'s camera-tracker receiver decodes them (tracking/opentrackio.h
// decodeOpenTrackIoCamera: 16-byte OTrk header, Fletcher-16, JSON or CBOR payload, sample
// fields), and the payload alone as a parsed sample (cameraSampleFromOpenTrackIo).
// Decoders never throw: any exception is a finding here.
#include <nlohmann/json.hpp>

#include "fuzz/fuzz_common.h"
#include "tracking/opentrackio.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size) {
  std::string why;
  previz::tracking::PacketFault fault = previz::tracking::PacketFault::kNone;
  if (const auto sample = previz::tracking::decodeOpenTrackIoCamera(data, size, &fault, &why))
    if (sample->timecode) sample->timecode->seconds_of_day();
  // The bytes after the header as a JSON sample, whatever the header says (checksums make the
  // fuzzer's path to the sample fields long).
  if (size > previz::tracking::kOtrkHeaderSize) {
    const nlohmann::json j = nlohmann::json::parse(data + previz::tracking::kOtrkHeaderSize, data + size, nullptr, false);
    if (!j.is_discarded()) previz::tracking::cameraSampleFromOpenTrackIo(j, &why);
  }
  return 0;
}
