#pragma once
// The intrinsic calibration of one camera as `previz calib intrinsics` runs it, as one library
// call (issue 34): detect the board in every image -> reject soft views (focus measure) ->
// select the most informative views -> solve -> frontal refinement -> uncertainty map ->
// two-halves cross-validation. `previz calib intrinsics` and `previz demo` both call it; what
// each step decided is in the returned report (CalibReport: views with their rejection marks,
// the selected indices and the selector's summary, the frontal rounds, the uncertainty and the
// cross-validation) and in PipelineResult's log lines.
#include <functional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "calib/detect.h"
#include "calib/intrinsics.h"
#include "calib/report.h"
#include "calib/selection.h"
#include "core/board.h"

namespace previz::calib {

struct PipelineOptions {
  DetectOptions detect;
  bool reject_soft = true;      // false: keep views the focus measure calls soft
  int select = 0;               // calibrate from the N most informative views (0 = all)
  SelectionOptions selection;   // method, locks and model are taken from here and `solve`
  int refine = 0;               // rounds of frontal refinement (0 = none)
  IntrinsicsOptions solve;
  bool cross_validate = true;
  int threads = 1;              // board detection in parallel over this many images at a time
  std::string board_source;     // the board file, for messages

  void validate() const;        // throws Error naming the field
};

// The images: how many, the i-th (8-bit grey or BGR; an empty Mat or an exception = unreadable:
// skipped, its view's failure says why, and PipelineResult::unreadable names it) and its name for
// messages. Read in order, from one thread.
struct ImageSet {
  std::string source;  // the folder or video, for messages
  int count = 0;
  std::function<cv::Mat(int)> read;
  std::function<std::string(int)> name;
};

struct PipelineResult {
  CalibReport report;
  int found = 0;                    // images where the board was found
  int soft = 0;                     // of those, rejected as soft
  std::vector<std::string> unreadable;  // images (video frames) that could not be read, skipped
  std::vector<std::string> log;     // what each step decided, one line each (no board in X, ...)
};

// progress(images detected so far). Throws Error when no image can be read or the board is found
// in none (naming the source, the board and the image count) or the solve cannot run (naming the
// views).
PipelineResult calibratePipeline(const ImageSet& images, const BoardSpec& board, const PipelineOptions& options,
                                 const std::function<void(int)>& progress = {});

}  // namespace previz::calib
