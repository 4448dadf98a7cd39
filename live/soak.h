#pragma once
// The live loop under faults for thousands of frames (`previz soak`): FrameLoop + TakeReader
// (live/frame_loop.h, live/inputs.h) over a take played in a loop, the main camera's pose from a
// camera tracker (live/tracker.h, OpenTrackIO), outputs written as `previz run` writes them
// (composite PNG + depth EXR, into a ring of slots so the disk use stays flat), with faults
// injected on a schedule that repeats every `period` frames:
//
//   witness_unplugged   a witness's frame files gone for a while      -> camera dropped (reason)
//   witness_corrupt     a witness frame's PNG bytes damaged           -> camera dropped (reason)
//   witness_truncated   a witness frame's PNG cut in half             -> camera dropped (reason)
//   main_corrupt        the main plate's PNG damaged                  -> frame failed (reason)
//   main_truncated      the main plate's PNG cut in half              -> frame failed (reason)
//   camera_late         a witness shows the frame 2 before, then in sync again: its frames carry
//                       the take frame they show (a genlocked camera's timecode), the reader
//                       compares it with the frame set's  -> camera dropped ("late by 2 frames")
//   tracker_loss        tracker datagrams lost, shorter than the matcher bridges (max_gap_s)
//                                                                     -> counted missing, frames posed
//   tracker_outage      tracker datagrams lost for longer             -> counted missing, frames
//                                                                        failed "no tracker pose"
//   tracker_reorder     two datagrams swapped on the way              -> counted out_of_order
//   disk_full           every write fails (core/io.h setWriteFaultHook: half a temporary, then
//                       ENOSPC)                                       -> write skipped (reason), the
//                       loop goes on, no output file half-written or left behind
//
// The faults act on a working copy of the take (OUT/take: the input is never modified) and on
// the tracker's recording (OUT/tracker.jsonl). Every fault is matched afterwards to what the loop
// reported, frame by frame (SoakFault::matched), every report to a fault (nothing unexplained),
// and every frame is accounted for: frames in = processed + failed (each failed one with its
// reason). RSS is sampled after every frame; its growth from the window after warm-up to the
// last window must stay within max_rss_growth. The result explains itself (SoakReport::
// fullReport, toJson) and is written to OUT/soak.json with a plot OUT/soak.svg.
#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "live/frame_loop.h"
#include "live/tracker.h"

namespace previz::live {

struct SoakOptions {
  std::filesystem::path take;  // a take folder with cg/ (played in a loop)
  std::filesystem::path rig;   // default: TAKE/truth/rig.json
  std::filesystem::path out;   // working copy of the take, outputs, soak.json, soak.svg
  int frames = 5000;
  int period = 500;            // the fault schedule repeats every this many frames (>= 100)
  int warmup_frames = 500;     // RSS reference: the window that starts here
  int rss_window = 250;        // frames in the reference and the last window (medians)
  double max_rss_growth = 0.05;
  int output_slots = 64;       // frame n's outputs go to slot n % output_slots
  double fps = 24;             // the take's frames are 1 / fps apart on the tracker's clock
  double tracker_rate_hz = 60;
  FrameLoopOptions loop;
  void validate() const;       // throws Error naming the field
};

// One injected fault and what the loop did about it.
struct SoakFault {
  std::string kind;            // see the table above
  std::string camera;          // the camera faulted ("" for tracker and disk faults)
  int first_frame = 0;         // soak frames [first_frame, end_frame)
  int end_frame = 0;
  int datagrams = 0;           // tracker faults: datagrams lost, or pairs swapped
  std::string expected;        // the handling the loop must show
  std::string observed;        // what it showed (counts, first reason)
  bool matched = false;
  nlohmann::json toJson() const;
};

struct SoakEvent {
  int frame = 0;
  std::string camera;          // dropped camera; "" for a failed frame or a skipped write
  std::string file;            // skipped write: the file
  std::string reason;
};

struct SoakFrame {
  int frame = 0, take_frame = 0;
  bool failed = false;
  double ms = 0;               // read + stages + write, wall time
  double cpu_ms = 0;           // the same span's CPU time, every thread: on a shared machine
                               // wall time also measures the other jobs
  double rss_mib = 0;          // after the frame
};

struct SoakReport {
  std::string take, resolution;
  int frames_in = 0, frames_processed = 0, frames_failed = 0;
  std::vector<SoakFault> faults;
  std::vector<SoakEvent> failed;          // frames not composited: frame, reason
  std::vector<SoakEvent> dropped;         // cameras dropped: frame, camera, reason
  std::vector<SoakEvent> skipped_writes;  // frame, file, reason
  std::vector<SoakEvent> unexplained;     // a report no fault accounts for (or a fault not handled)
  TrackerCounts tracker;
  std::vector<SoakFrame> frame_log;
  // RSS (MiB): medians of the reference window (after warm-up) and of the last window.
  double rss_start_mib = 0, rss_end_mib = 0, rss_max_mib = 0, rss_growth = 0, max_rss_growth = 0.05;
  double ms_median = 0, ms_p99 = 0, ms_max = 0;
  double cpu_ms_median = 0, cpu_ms_p99 = 0, cpu_ms_max = 0;
  // Outputs: every file in the ring read back whole (PNG decoded, EXR read) and found to be the
  // last frame written to its slot; temporaries left beside them.
  int output_files = 0, outputs_complete = 0;
  std::vector<std::string> output_problems;
  double wall_s = 0;

  bool accounted() const { return frames_in == frames_processed + frames_failed; }
  bool faultsMatched() const;
  bool rssOk() const { return rss_growth <= max_rss_growth; }
  bool outputsOk() const { return output_problems.empty() && outputs_complete == output_files; }
  bool ok() const { return accounted() && faultsMatched() && unexplained.empty() && rssOk() && outputsOk(); }
  nlohmann::json toJson() const;  // without the per-frame log unless asked
  nlohmann::json toJson(bool with_frames) const;
  std::string fullReport() const;  // for a person: every fault, the figures, what failed
};

struct SoakProgress {
  int frame = 0, frames = 0;
  double ms = 0, rss_mib = 0;
  int failed = 0, dropped = 0, skipped_writes = 0;
};

// Runs the soak; writes OUT/soak.json and OUT/soak.svg. Throws Error (file, camera, frame) only
// for what stops it from starting (a take it cannot read, options); faults are reported.
SoakReport runSoak(const SoakOptions& options, const std::function<void(const SoakProgress&)>& progress = {});

// The plot: RSS (MiB) and frame time (ms) over the frames, failed frames and fault windows
// marked. SVG, written atomically.
void writeSoakPlot(const SoakReport& report, const std::filesystem::path& svg);

}  // namespace previz::live
