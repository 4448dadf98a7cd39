#include "calib/pipeline.h"

#include <algorithm>
#include <exception>

#include "calib/focus.h"
#include "calib/frontal.h"
#include "calib/validation.h"
#include "core/error.h"

namespace previz::calib {

namespace {

[[noreturn]] void failField(const std::string& field, const std::string& what) {
  ErrorContext context;
  context.field = field;
  throw Error("calib: " + field + " " + what, context);
}

}  // namespace

void PipelineOptions::validate() const {
  if (select < 0) failField("select", "must be >= 0 (got " + std::to_string(select) + ")");
  if (refine < 0) failField("refine", "must be >= 0 (got " + std::to_string(refine) + ")");
  if (threads < 1) failField("threads", "must be >= 1 (got " + std::to_string(threads) + ")");
  solve.validate();
  selection.validate();
}

PipelineResult calibratePipeline(const ImageSet& images, const BoardSpec& board, const PipelineOptions& options,
                                 const std::function<void(int)>& progress) {
  options.validate();
  board.validate();
  PipelineResult out;
  CalibReport& report = out.report;
  report.board = board;

  // 1. Detect the board in every image: read in order (one thread), detected in parallel a batch
  // at a time so that a long video never sits in memory whole.
  std::vector<ViewObservations> views(static_cast<size_t>(images.count));
  std::vector<char> unreadable(views.size(), 0);  // per view: its image could not be read
  const int batch = 2 * options.threads;
  std::vector<cv::Mat> held(static_cast<size_t>(batch));
  std::vector<std::string> names(static_cast<size_t>(batch));
  for (int first = 0; first < images.count; first += batch) {
    const int n = std::min(batch, images.count - first);
    for (int k = 0; k < n; ++k) {
      names[k] = images.name(first + k);
      // An image (or a video frame) that cannot be read is skipped and reported, as a long job
      // does with a bad frame: its view says why, and the run goes on with the rest.
      std::string why;
      try {
        held[k] = images.read(first + k);
        if (held[k].empty()) why = "it could not be read";
      } catch (const std::exception& e) {
        held[k] = cv::Mat();
        why = e.what();
      }
      if (!why.empty()) {
        ViewObservations& v = views[first + k];
        v.source = names[k];
        v.failure = "unreadable (skipped): " + why;
        out.unreadable.push_back(names[k]);
        unreadable[first + k] = 1;
      }
    }
    std::vector<std::exception_ptr> errors(static_cast<size_t>(n));
#pragma omp parallel for schedule(dynamic) num_threads(options.threads)
    for (int k = 0; k < n; ++k) {
      if (held[k].empty()) continue;
      try {
        views[first + k] = detectBoard(held[k], board, options.detect, names[k]);
        views[first + k].image_size = held[k].size();
      } catch (...) {
        errors[k] = std::current_exception();
      }
    }
    for (const std::exception_ptr& e : errors)
      if (e) std::rethrow_exception(e);
    if (progress) progress(first + n);
  }
  for (const auto& v : views) out.found += v.found();
  if (static_cast<int>(out.unreadable.size()) == images.count) {
    ErrorContext context;
    context.file = images.source;
    throw Error("calib: none of the " + std::to_string(images.count) + " images could be read (the first: " +
                    views.front().source + ": " + views.front().failure + ")",
                context);
  }
  if (out.found == 0) {
    ErrorContext context;
    context.file = images.source;
    throw Error("calib: the board " + options.board_source + " describes (" + toString(board.type) + ", " +
                    std::to_string(board.rows) + " x " + std::to_string(board.cols) + ") was found in none of the " +
                    std::to_string(views.size()) + " images",
                context);
  }

  // 2. Reject soft views (focus measure).
  out.soft = options.reject_soft ? rejectSoftViews(views) : 0;
  for (size_t i = 0; i < views.size(); ++i) {
    const ViewObservations& v = views[i];
    if (unreadable[i]) out.log.push_back(v.source + ": " + v.failure);
    else if (!v.found()) out.log.push_back("no board in " + v.source + ": " + v.failure);
    else if (v.rejected) out.log.push_back("not using " + v.source + ": " + v.rejected_reason);
  }
  out.log.push_back("board found in " + std::to_string(out.found) + " of " + std::to_string(views.size()) +
                    " images" + (out.soft ? ", " + std::to_string(out.soft) + " too soft" : "") +
                    (out.unreadable.empty() ? "" : ", " + std::to_string(out.unreadable.size()) + " unreadable"));

  // 3. Choose views: a streaming selector linearised at a quick calibration of a spread of them.
  SelectionOptions selection = options.selection;
  selection.views = std::max(1, options.select);
  selection.locks = options.solve.locks;
  selection.model = options.solve.model;
  std::vector<int> solve_index;
  int usable = 0;
  for (const auto& v : views) usable += v.found() && !v.rejected;
  if (options.select > 0 && usable > options.select) {
    std::vector<ViewObservations> spread;
    for (int k = 0, taken = 0; k < static_cast<int>(views.size()); ++k) {
      if (!views[k].found() || views[k].rejected) continue;
      if ((taken++ * 20) % usable < 20) spread.push_back(views[k]);
    }
    try {
      IntrinsicsOptions quick = options.solve;
      quick.compute_covariance = false;
      selection.guess = calibrateIntrinsics(spread, board, quick).camera;
    } catch (const Error& e) {
      out.log.push_back(std::string("selection starts from the nominal guess (quick calibration failed: ") +
                        e.what() + ")");
    }
    ViewSelector selector(board, views.front().image_size, selection);
    for (const auto& v : views) selector.add(v);
    solve_index = selector.selectedIndices();
    report.selection_summary = selector.summary();
    out.log.push_back(report.selection_summary);
    report.selected = solve_index;
  } else {
    for (int i = 0; i < static_cast<int>(views.size()); ++i) solve_index.push_back(i);
  }
  std::vector<ViewObservations> solve_views;
  for (int i : solve_index) solve_views.push_back(views[i]);

  // 4. Solve, 5. refine frontally, 6. say how sure we are.
  report.result = calibrateIntrinsics(solve_views, board, options.solve);
  if (options.refine > 0) {
    FrontalOptions frontal;
    frontal.max_iterations = options.refine;
    frontal.solve = options.solve;
    frontal.detect = options.detect;
    const FrontalResult refined = refineFrontal(
        [&](size_t k) {
          const cv::Mat image = images.read(solve_index[k]);
          if (image.empty()) {
            ErrorContext context;
            context.file = images.name(solve_index[k]);
            throw Error("calib: image could not be read again for the frontal refinement", context);
          }
          return image;
        },
        solve_views, board, report.result, frontal);
    out.log.push_back(refined.report());
    report.frontal = refined.iterations;
    report.result = refined.result;
    solve_views = refined.views;
  }
  UncertaintyOptions uncertainty;
  uncertainty.mode = report.result.joint_covariance.size() > 0 ? UncertaintyMode::kMeanFrames
                                                               : UncertaintyMode::kIntrinsicsOnly;
  if (report.result.covariance_ok) report.uncertainty = projectionUncertainty(report.result, uncertainty);
  if (options.cross_validate) {
    CrossValidationOptions cross;
    cross.solve = options.solve;
    try {
      report.cross_validation = crossValidate(solve_views, board, cross);
      out.log.push_back(report.cross_validation->report());
    } catch (const Error& e) {
      out.log.push_back(std::string("no cross-validation: ") + e.what());
    }
  }
  report.views = std::move(views);
  return out;
}

}  // namespace previz::calib
