// FreeD D1 datagrams as previz receives them (tracking/stream.h decodeFreeD for prop poses,
// tracking/opentrackio.h decodeFreeDCamera for a camera tracker feeding live/), then the pose.
// Decoders never throw: any exception is a finding here.
#include "fuzz/fuzz_common.h"
#include "tracking/opentrackio.h"
#include "tracking/stream.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size) {
  std::string why;
  if (const auto packet = previz::tracking::decodeFreeD(data, size, &why)) previz::tracking::poseFromFreeD(*packet);
  previz::tracking::PacketFault fault = previz::tracking::PacketFault::kNone;
  previz::tracking::decodeFreeDCamera(data, size, &fault, &why);
  previz::tracking::toString(fault);
  return 0;
}
