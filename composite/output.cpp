// Composite files (see output.h).
#include "composite/output.h"

#include <unistd.h>

#include <cstdio>

#include <opencv2/imgproc.hpp>

#include "composite/detail/video_plugin.h"
#include "core/error.h"
#include "core/io.h"
#include "core/names.h"
#include "core/plugin.h"
#include "core/rig.h"

namespace previz::composite {
namespace fs = std::filesystem;
namespace {

ErrorContext fileFrame(const fs::path& file, int frame) {
  ErrorContext c;
  c.file = file.string();
  c.frame = frame;
  return c;
}

const char* const kPixelOrigin = "pixel (0,0) is the centre of the top-left pixel";

}  // namespace

Camera readCgCamera(const fs::path& camera_json) {
  const nlohmann::json j = readJsonFile(camera_json);
  if (!j.contains("camera")) {
    ErrorContext c;
    c.file = camera_json.string();
    c.field = "camera";
    throw Error("CG camera file has no 'camera'", c);
  }
  Camera cam = cameraFromJson(j.at("camera"), camera_json.string());
  if (!cam.dist.isZero()) {
    ErrorContext c;
    c.file = camera_json.string();
    c.field = "camera.distortion";
    throw Error("the CG camera must be an ideal pinhole (zero distortion)", c);
  }
  return cam;
}

CgFrame readCgFrame(const fs::path& cg_dir, int frame, cv::Size expected) {
  const fs::path color_path = cg_dir / "color" / (frameStem(frame) + ".exr");
  const fs::path depth_path = cg_dir / "depth" / (frameStem(frame) + ".exr");
  CgFrame out;
  const auto withFrame = [&](const fs::path& path, auto&& fn) {
    try {
      fn();
    } catch (const Error& e) {
      ErrorContext c = e.context();
      if (c.file.empty()) c.file = path.string();
      c.frame = frame;
      throw Error("CG frame: " + e.message(), c);
    }
  };
  withFrame(color_path, [&] {
    const ExrImage exr = readExr(color_path);
    int idx[3] = {-1, -1, -1};
    for (size_t i = 0; i < exr.channels.size(); ++i) {
      if (exr.channels[i] == "R") idx[0] = static_cast<int>(i);
      if (exr.channels[i] == "G") idx[1] = static_cast<int>(i);
      if (exr.channels[i] == "B") idx[2] = static_cast<int>(i);
    }
    if (idx[0] < 0 || idx[1] < 0 || idx[2] < 0)
      throw Error("CG colour needs channels R, G, B", fileFrame(color_path, frame));
    if (exr.channels.size() == 3 && idx[0] == 0 && idx[1] == 1 && idx[2] == 2) {
      out.color = exr.image;
    } else {
      std::vector<cv::Mat> planes;
      cv::split(exr.image, planes);
      cv::merge(std::vector<cv::Mat>{planes[idx[0]], planes[idx[1]], planes[idx[2]]}, out.color);
    }
  });
  withFrame(depth_path, [&] { out.depth = readDepthExr(depth_path); });
  if (out.color.size() != out.depth.size())
    throw Error("CG colour and depth differ in size", fileFrame(depth_path, frame));
  if (!expected.empty() && out.color.size() != expected)
    throw Error("CG frame is " + std::to_string(out.color.cols) + "x" + std::to_string(out.color.rows) +
                    ", the CG camera is " + std::to_string(expected.width) + "x" + std::to_string(expected.height),
                fileFrame(color_path, frame));
  return out;
}

void OutputOptions::validate() const {
  ErrorContext c;
  if (out.empty()) {
    c.field = "out";
    throw Error("composite output: an output folder is required", c);
  }
  if (!(fps > 0)) {
    c.field = "fps";
    throw Error("composite output: fps must be > 0", c);
  }
  if (!video.empty() && fourcc.size() != 4) {
    c.field = "fourcc";
    throw Error("composite output: fourcc must have 4 characters (got '" + fourcc + "')", c);
  }
  if (!(preview_far_m > preview_near_m)) {
    c.field = "preview_far_m";
    throw Error("composite output: preview_far_m must be > preview_near_m", c);
  }
}

struct CompositeWriter::Impl {
  OutputOptions options;
  std::unique_ptr<detail::VideoOut> video;  // OpenCV's VideoWriter, in its plugin
  fs::path video_tmp, video_path;
  int video_frames = 0;
};

CompositeWriter::CompositeWriter(const OutputOptions& options) : impl_(std::make_unique<Impl>()) {
  options.validate();
  impl_->options = options;
  fs::create_directories(options.out);
  if (!options.video.empty()) {
    impl_->video_path = options.out / options.video;
    // The temporary keeps the extension: VideoWriter picks the container by it.
    impl_->video_tmp = options.out / ("." + impl_->video_path.stem().string() + ".tmp." +
                                      std::to_string(::getpid()) + impl_->video_path.extension().string());
  }
}

CompositeWriter::~CompositeWriter() {
  try {
    close();
  } catch (const std::exception&) {
    // Destructors never throw; close() explicitly to see the error.
  }
}

const OutputOptions& CompositeWriter::options() const { return impl_->options; }

std::vector<fs::path> CompositeWriter::outputs(int frame) const {
  const OutputOptions& o = impl_->options;
  const std::string s = frameStem(frame);
  std::vector<fs::path> p;
  if (o.png) p.push_back(o.out / "composite" / (s + ".png"));
  if (o.exr) p.push_back(o.out / "composite" / (s + ".exr"));
  if (o.layers) {
    for (const char* layer : {"alpha", "actor_depth", "cg_depth"}) p.push_back(o.out / "layers" / layer / (s + ".exr"));
    p.push_back(o.out / "layers" / "actor_depth" / (s + ".png"));
    p.push_back(o.out / "layers" / "cg_depth" / (s + ".png"));
    p.push_back(o.out / "layers" / "front" / (s + ".png"));
  }
  return p;
}

void CompositeWriter::write(int frame, const CompositeResult& r) {
  const OutputOptions& o = impl_->options;
  const std::string s = frameStem(frame);
  const std::map<std::string, std::string> attrs = {{"previz:frame", std::to_string(frame)},
                                                    {"previz:pixel_origin", kPixelOrigin}};
  if (o.png) writeImageAtomic(o.out / "composite" / (s + ".png"), r.bgr);
  if ((o.exr || o.layers) && r.linear.empty())
    throw Error("composite output: EXR and layers need the debug layers of the composite",
                fileFrame(o.out, frame));
  if (o.exr) {
    ExrImage exr;
    std::vector<cv::Mat> bgr;
    cv::split(r.linear, bgr);
    cv::merge(std::vector<cv::Mat>{bgr[2], bgr[1], bgr[0]}, exr.image);
    exr.channels = {"R", "G", "B"};
    exr.half = true;
    exr.attributes = attrs;
    exr.attributes["previz:color"] = "linear RGB (the plate's light), no encoding";
    writeExr(o.out / "composite" / (s + ".exr"), exr);
  }
  if (o.layers) {
    ExrImage alpha;
    alpha.image = r.layer_alpha;
    alpha.channels = {"A"};
    alpha.attributes = attrs;
    alpha.attributes["previz:layer"] = "effective alpha = key alpha x depth weight";
    writeExr(o.out / "layers" / "alpha" / (s + ".exr"), alpha);
    std::map<std::string, std::string> a = attrs;
    a["previz:layer"] = "actor depth used by the compositor (main view, +inf unknown)";
    writeDepthExr(o.out / "layers" / "actor_depth" / (s + ".exr"), r.layer_actor_depth, a);
    a["previz:layer"] = "CG depth distorted to the main lens (nearest sample)";
    writeDepthExr(o.out / "layers" / "cg_depth" / (s + ".exr"), r.layer_cg_depth, a);
    writeImageAtomic(o.out / "layers" / "actor_depth" / (s + ".png"),
                     depthPreview(r.layer_actor_depth, o.preview_near_m, o.preview_far_m));
    writeImageAtomic(o.out / "layers" / "cg_depth" / (s + ".png"),
                     depthPreview(r.layer_cg_depth, o.preview_near_m, o.preview_far_m));
    writeImageAtomic(o.out / "layers" / "front" / (s + ".png"), frontPreview(r.layer_front));
  }
  if (!impl_->video_tmp.empty()) {
    if (!impl_->video) {
      const detail::VideoPlugin& plugin = pluginInterface<detail::VideoPlugin>(
          "previz_composite_video", "previz_composite_video_plugin", "composite video: OpenCV's videoio");
      impl_->video = plugin.open(impl_->video_tmp.string(), o.fourcc, o.fps, r.bgr.size());
      if (!impl_->video) {
        ErrorContext c;
        c.file = impl_->video_path.string();
        c.field = "fourcc";
        throw Error("cannot open a video writer for codec '" + o.fourcc + "' (try MJPG with a .avi file)", c);
      }
    }
    impl_->video->write(r.bgr);
    ++impl_->video_frames;
  }
}

void CompositeWriter::close() {
  if (!impl_->video) return;
  impl_->video->release();
  impl_->video.reset();
  std::error_code ec;
  fs::rename(impl_->video_tmp, impl_->video_path, ec);
  if (ec) {
    ErrorContext c;
    c.file = impl_->video_path.string();
    throw Error("cannot move the finished video into place: " + ec.message(), c);
  }
}

}  // namespace previz::composite
