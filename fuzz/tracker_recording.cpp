// Camera-tracker recordings (live/tracker.h readRecording: a header line then one JSON line per
// datagram with its hex "bytes"), then every datagram through the receiver as a replay feeds it.
#include "fuzz/fuzz_common.h"
#include "live/tracker.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, size_t size) {
  return previz::fuzz::guarded([&] {
    const previz::fuzz::TempPath file("recording.jsonl");
    previz::fuzz::writeBytes(file.path(), data, size);
    const previz::live::TrackerRecording recording = previz::live::readRecording(file.path());
    previz::live::TrackerReceiver receiver(recording.protocol, previz::live::TrackerOptions{});
    for (const auto& d : recording.datagrams) receiver.feed(d.bytes.data(), d.bytes.size(), d.arrival_s);
  });
}
