#pragma once
// A take re-written with its camera streams in another form (take/stream_writer.h): videos,
// other sequence patterns and start numbers, bit depths, timecode, cameras that started late.
// Everything but cams/ and out/ is copied; take.json is written last (its presence marks a
// complete take) with the offsets the new form needs, so the take model reads every camera back
// at the same take frames. `previz take convert` and `previz bench take` run it.
#include <filesystem>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "take/stream_writer.h"

namespace previz::take {

struct ConvertOptions {
  // The form: format, pattern, first_number, start_timecode (of take frame 0); fps = the take's.
  StreamWriterOptions writer;
  std::map<std::string, int> late_frames;  // camera -> its new stream starts at this take frame
  std::vector<std::string> cameras;        // empty = every camera of the take
};

struct ConvertSummary {
  std::map<std::string, std::string> streams;  // camera -> its new stream (take.json "sources" form)
  std::map<std::string, long long> offsets;    // take.json "offsets" written
  std::vector<std::string> left_out;           // "camera: why" (no usable stream)
  long long frames_written = 0;
};

// Throws Error naming the file and camera when a frame cannot be read (a conversion drops
// nothing silently), when no camera has a usable stream (before anything is written) or the
// output is a take already; an output folder the conversion made is removed when it throws.
// Cameras left out (no usable stream) are listed in the summary.
ConvertSummary convertTake(const std::filesystem::path& in, const std::filesystem::path& out,
                           const ConvertOptions& options,
                           const std::function<void(long long done, long long total)>& progress = {});

}  // namespace previz::take
