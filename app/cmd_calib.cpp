// previz calib: calibrate a camera's intrinsics from images (or a video) of a board, and print
// boards. Thin: read inputs, call calib/ (detect, focus, selection, intrinsics, frontal,
// validation, report), write the camera and the report.
#include <algorithm>
#include <filesystem>
#include <iostream>
#include <memory>

#include <nlohmann/json.hpp>

#include "app/commands.h"
#include "app/progress.h"
#include "calib/board_print.h"
#include "calib/detect.h"
#include "calib/focus.h"
#include "calib/frontal.h"
#include "calib/intrinsics.h"
#include "calib/report.h"
#include "calib/selection.h"
#include "calib/validation.h"
#include "calib/pipeline.h"
#include "core/camera_io.h"
#include "core/error.h"
#include "core/io.h"
#include "core/rig.h"
#include "take/sequence.h"
#include "take/take.h"
#include "take/video.h"

namespace previz::app {
namespace {

namespace fs = std::filesystem;

struct CalibArgs {
  // intrinsics
  std::string images, board, out, report, lock, loss = "huber", select_method = "uncertainty";
  std::string model = "brown-conrady";  // calib intrinsics --model
  std::string layout;  // calib board --layout
  std::string camera_name;
  int select = 0;
  int refine = 0;
  double loss_scale_px = 1.0;
  bool keep_soft = false;
  bool not_srgb = false;
  bool no_cross_validate = false;
  bool json = false;
  bool quiet = false;
  // board
  double dpi = 300;
  std::string board_out;
};

// Where the images come from: a folder of image files (every image, sorted by name: a calibration
// folder often holds more than one numbered set, left01.. and right01..) or one video file, read
// as the take model reads cameras (take/take.h: any bit depth to 8-bit sRGB; a video as far as
// it decodes, not as far as its header claims). Frames are read on demand.
class ImageSource {
 public:
  explicit ImageSource(const std::string& path) : path_(path) {
    ErrorContext context;
    context.file = path;
    if (fs::is_directory(path_)) {
      for (const auto& entry : fs::directory_iterator(path_)) {
        if (entry.is_regular_file() && take::isImageExtension(entry.path())) files_.push_back(entry.path());
      }
      std::sort(files_.begin(), files_.end());
      if (files_.empty()) throw Error("calib: no image files (png, jpg, tif, exr, bmp) in the folder", context);
      count_ = static_cast<int>(files_.size());
    } else if (fs::is_regular_file(path_) && take::isImageExtension(path_)) {
      files_.push_back(path_);  // one image
      count_ = 1;
    } else if (fs::is_regular_file(path_)) {
      try {
        video_ = std::make_unique<take::VideoReader>(path_, 4);
        count_ = static_cast<int>(video_->decodableFrames());
      } catch (const Error& e) {
        throw Error(std::string("calib: not a folder of images and not a video that decodes: ") + e.message(), context);
      }
      if (count_ <= 0) throw Error("calib: no frame of the video decodes", context);
    } else {
      throw Error("calib: no such folder or video", context);
    }
  }
  int size() const { return count_; }
  std::string name(int i) const {
    return files_.empty() ? "frame " + std::to_string(i) : files_[i].filename().string();
  }
  // Throws Error naming the file (and the video frame) when it cannot be read.
  cv::Mat read(int i) {
    if (!files_.empty()) return take::readImage8(files_[i]);
    take::VideoReader::Frame f = video_->read(i);
    if (!f.ok()) {
      ErrorContext context;
      context.file = path_.string();
      context.frame = i;
      throw Error("calib: " + f.error, context);
    }
    return f.bgr;
  }

 private:
  fs::path path_;
  std::vector<fs::path> files_;
  std::unique_ptr<take::VideoReader> video_;
  int count_ = 0;
};

int runIntrinsics(const CalibArgs& a) {
  const BoardSpec board = readBoard(a.board);
  calib::PipelineOptions pipeline;
  pipeline.board_source = a.board;
  calib::IntrinsicsOptions& solve = pipeline.solve;
  solve.locks = calib::IntrinsicLocks::parse(a.lock);
  try {
    // "rational" is Brown-Conrady with k4 k5 k6 free (OpenCV's CALIB_RATIONAL_MODEL).
    if (a.model == "rational" || a.model == "brown-rational") {
      solve.model = LensModel::kBrownConrady;
      solve.locks.rational = true;
    } else {
      solve.model = lensModelFromString(a.model);
    }
  } catch (const Error& e) {
    ErrorContext context;
    context.field = "--model";
    throw Error("calib: " + e.message(), context);
  }
  solve.loss = calib::robustLossFromString(a.loss);
  solve.loss_scale_px = a.loss_scale_px;
  solve.camera_name = a.camera_name.empty() ? fs::path(a.out).stem().string() : a.camera_name;
  pipeline.selection.method = calib::selectionMethodFromString(a.select_method);
  pipeline.select = a.select;
  pipeline.refine = a.refine;
  pipeline.reject_soft = !a.keep_soft;
  pipeline.cross_validate = !a.no_cross_validate;
  pipeline.detect.linear_light = !a.not_srgb;
  if (a.refine < 0) {
    ErrorContext context;
    context.field = "--refine";
    throw Error("calib: --refine must be >= 0", context);
  }
  pipeline.validate();

  // Detect -> reject soft -> select -> solve -> refine -> uncertainty -> cross-validate
  // (calib/pipeline.h), the images read in order from the folder or video.
  ImageSource source(a.images);
  calib::ImageSet images;
  images.source = a.images;
  images.count = source.size();
  images.read = [&](int i) { return source.read(i); };
  images.name = [&](int i) { return source.name(i); };
  ProgressLine progress("calib detect", source.size(), a.quiet);
  calib::PipelineResult run = calib::calibratePipeline(images, board, pipeline, [&](int done) { progress.update(done); });
  for (const std::string& line : run.log) std::cerr << (line.back() == '\n' ? line : "calib: " + line + "\n");
  calib::CalibReport& report = run.report;

  // 6. Write the camera (previz JSON + OpenCV YAML beside it) and the report.
  const fs::path out(a.out);
  writeJsonAtomic(out, cameraToJson(report.result.camera));
  fs::path yaml = out;
  yaml.replace_extension(".yaml");
  writeOpenCvCamera(report.result.camera, yaml);
  fs::path stem = a.report.empty() ? fs::path(out).replace_extension("") : fs::path(a.report);
  const calib::ReportFiles files = calib::writeCalibReport(report, stem);
  std::cerr << report.result.fullReport();
  std::cerr << "calib: wrote " << out.string() << ", " << yaml.string() << ", " << files.json.string()
            << " and pictures beside it\n";
  if (a.json) {
    nlohmann::json j = calib::reportToJson(report);
    j["command"] = "calib intrinsics";
    j["out"] = out.string();
    j["opencv_yaml"] = yaml.string();
    j["report"] = files.json.string();
    j["unreadable"] = run.unreadable;
    std::cout << j.dump() << "\n";
  }
  return 0;
}

// previz calib detect: what a user runs first on photos of a board. Per image the board points
// found, the tags decoded (AprilGrid: with their bit errors) and why nothing was found where
// nothing was; an image that cannot be read is reported and skipped. Exit 1 when no image shows
// the board.
int runDetect(const CalibArgs& a) {
  const BoardSpec board = readBoard(a.board);
  ImageSource source(a.images);
  calib::DetectOptions detect;
  detect.linear_light = !a.not_srgb;
  detect.measure_focus = false;
  nlohmann::json images = nlohmann::json::array();
  int found = 0;
  for (int i = 0; i < source.size(); ++i) {
    nlohmann::json j{{"image", source.name(i)}};
    try {
      const cv::Mat image = source.read(i);
      const calib::ViewObservations v = calib::detectBoard(image, board, detect, source.name(i));
      j["width"] = image.cols;
      j["height"] = image.rows;
      nlohmann::json points = nlohmann::json::array(), tags = nlohmann::json::array();
      for (const calib::Observation& o : v.points) points.push_back({{"id", o.id}, {"x", o.px.x()}, {"y", o.px.y()}});
      int bit_errors = 0, unused = 0;
      for (const calib::DecodedTag& tag : v.tags) {
        nlohmann::json tj{{"id", tag.id}, {"bit_errors", tag.bit_errors}, {"used", tag.used}};
        if (!tag.used) tj["why_not"] = tag.why_not;
        tags.push_back(tj);
        bit_errors += tag.bit_errors > 0;
        unused += !tag.used;
      }
      j["points"] = points;
      if (board.type == BoardType::kAprilGrid) j["tags"] = tags;
      j["found"] = v.found();
      if (!v.found()) j["why_not"] = v.failure;
      found += v.found();
      std::cerr << "calib detect: " << source.name(i) << ": ";
      if (v.found()) {
        std::cerr << v.points.size() << " points";
        if (board.type == BoardType::kAprilGrid)
          std::cerr << ", " << v.tags.size() << " tags decoded (" << bit_errors << " with bit errors, " << unused
                    << " not used)";
      } else {
        std::cerr << "no board: " << v.failure;
      }
      std::cerr << "\n";
    } catch (const Error& e) {
      j["found"] = false;
      j["why_not"] = e.what();
      std::cerr << "calib detect: " << source.name(i) << ": skipped: " << e.what() << "\n";
    }
    images.push_back(j);
  }
  std::cerr << "calib detect: board found in " << found << " of " << source.size() << " images\n";
  if (a.json)
    std::cout << nlohmann::json{{"command", "calib detect"}, {"board", boardToJson(board)}, {"images", images},
                                {"found", found}}
                     .dump()
              << "\n";
  return found > 0 ? 0 : 1;
}

int runBoard(const CalibArgs& a) {
  BoardSpec board = readBoard(a.board);
  if (!a.layout.empty()) {
    if (board.type != BoardType::kAprilGrid)
      throw Error("--layout applies to aprilgrid boards only (this board is a " + std::string(toString(board.type)) + ")",
                  fieldContext("--layout"));
    if (a.layout == "kalibr") {
      board.layout = AprilGridLayout::kKalibr;
      board.tag_border_cells = 2;  // as Kalibr prints its tags
    } else if (a.layout == "previz") {
      board.layout = AprilGridLayout::kPreviz;
    } else {
      throw Error("--layout must be kalibr or previz (got '" + a.layout + "')", fieldContext("--layout"));
    }
  }
  const calib::PrintedBoard printed = calib::printBoard(board, a.dpi, a.board_out);
  std::cerr << "calib board: " << printed.png.string() << " (" << printed.png_size.width << " x "
            << printed.png_size.height << " px at " << a.dpi << " dpi, " << printed.width_mm
            << " x " << printed.height_mm << " mm), " << printed.svg.string() << ", "
            << printed.json.string()
            << (printed.kalibr_yaml.empty() ? std::string() : ", " + printed.kalibr_yaml.string() + " (Kalibr's target file)")
            << (board.type == BoardType::kAprilGrid ? std::string("; ") + toString(board.layout) + " layout, tag border " +
                                                          std::to_string(board.tag_border_cells) + " cells"
                                                    : std::string())
            << "; print at 100 %\n";
  if (a.json) {
    std::cout << nlohmann::json{{"command", "calib board"}, {"png", printed.png.string()},
                                {"svg", printed.svg.string()}, {"json", printed.json.string()},
                                {"width_mm", printed.width_mm}, {"height_mm", printed.height_mm},
                                {"kalibr_yaml", printed.kalibr_yaml.empty() ? nlohmann::json(nullptr)
                                                                            : nlohmann::json(printed.kalibr_yaml.string())}}
                     .dump()
              << "\n";
  }
  return 0;
}

}  // namespace

Runner addCalibCommand(CLI::App& app) {
  auto a = std::make_shared<CalibArgs>();
  CLI::App* cmd = app.add_subcommand("calib", "Calibrate camera intrinsics from board images; print boards");
  cmd->require_subcommand(1);

  CLI::App* in = cmd->add_subcommand(
      "intrinsics", "Calibrate one camera from a folder of images or a video of a board");
  in->add_option("--images", a->images, "Folder of images (png, jpg, tif, bmp) or a video file")->required();
  in->add_option("--board", a->board, "Board description (board JSON, docs/formats.md)")->required();
  in->add_option("--out", a->out, "Camera JSON to write (OpenCV YAML and the report go beside it)")->required();
  in->add_option("--report", a->report, "Report file stem (default: --out without extension)");
  in->add_option("--name", a->camera_name, "Camera name (default: --out's stem)");
  in->add_option("--select", a->select, "Calibrate from the N most useful views (0 = all)")->capture_default_str();
  in->add_option("--select-method", a->select_method,
                 "uncertainty | information | plane-angles | random | sequential")
      ->capture_default_str();
  in->add_option("--refine", a->refine, "Rounds of frontal refinement (Datta et al. 2009; 0 = none)")
      ->capture_default_str();
  in->add_option("--model", a->model,
                 "Lens model: brown (Brown-Conrady k1 k2 p1 p2 k3, OpenCV's calibrateCamera), rational "
                 "(Brown-Conrady with k4 k5 k6 free, OpenCV's CALIB_RATIONAL_MODEL) or fisheye "
                 "(Kannala-Brandt k1..k4, OpenCV's fisheye module, Kalibr's equidistant)")
      ->capture_default_str();
  in->add_option("--lock", a->lock,
                 "Held parameters, comma-separated: fix_focal, fix_aspect, fix_principal_point, "
                 "fix_k1, fix_k2, fix_k3, fix_k4 (fisheye or rational), fix_k5, fix_k6 (rational), fix_tangential, "
                 "fix_radial, fix_distortion, free_skew");
  in->add_option("--loss", a->loss, "Robust loss: huber | cauchy | none")->capture_default_str();
  in->add_option("--loss-scale", a->loss_scale_px, "Robust loss scale, px")->capture_default_str();
  in->add_flag("--keep-soft", a->keep_soft, "Keep views the focus measure calls soft");
  in->add_flag("--not-srgb", a->not_srgb,
               "Images are not sRGB-encoded: refine corners on the raw 8-bit values (calib/detect.h)");
  in->add_flag("--no-cross-validate", a->no_cross_validate, "Skip the two-halves cross-validation");
  in->add_flag("--json", a->json, "Print the report JSON on stdout");
  in->add_flag("--quiet", a->quiet, "No progress line");

  CLI::App* bd = cmd->add_subcommand("board", "Write a printable board: PNG at a DPI, SVG in mm, board JSON");
  bd->add_option("--board", a->board, "Board description (board JSON, or Kalibr's target YAML)")->required();
  bd->add_option("--layout", a->layout,
                 "AprilGrid: kalibr (Kalibr's print: tag 0 bottom left, 2-cell tag borders; also writes "
                 "<stem>.yaml for Kalibr) or previz (the board file's own layout by default)");
  bd->add_option("--dpi", a->dpi, "Print resolution, dots per inch")->capture_default_str();
  bd->add_option("--out", a->board_out, "Output stem: <stem>.png, <stem>.svg, <stem>.json")->required();
  bd->add_flag("--json", a->json, "Print a JSON summary on stdout");

  CLI::App* dt = cmd->add_subcommand(
      "detect", "Find the board in images (a folder, one image or a video): per image the points, the tags "
                "decoded with their bit errors, and why not where none were");
  dt->add_option("--images", a->images, "Folder of images, one image (8 or 16 bit) or a video file")->required();
  dt->add_option("--board", a->board, "Board description (board JSON, or Kalibr's target YAML)")->required();
  dt->add_flag("--not-srgb", a->not_srgb, "8-bit images are not sRGB-encoded (refine corners on the codes)");
  dt->add_flag("--json", a->json, "Everything found as JSON on stdout");

  Runner lens = addLensCommand(*cmd);
  CLI::App* ln = cmd->get_subcommand("lens");

  return [a, in, bd, dt, ln, lens]() {
    if (in->parsed()) return runIntrinsics(*a);
    if (dt->parsed()) return runDetect(*a);
    if (bd->parsed()) return runBoard(*a);
    if (ln->parsed()) return lens();
    return 2;
  };
}

}  // namespace previz::app
