#pragma once
// The compositor's files: reading the engine's CG frames (cg/color, cg/depth, cg/camera.json of
// a take) and writing composites, debug layers and video. Layout: docs/formats.md ("Composite
// output"). Every image is written atomically (core/io.h); the video is written by OpenCV's
// VideoWriter (in the previz_composite_video plugin, composite/detail/video_plugin.h, loaded
// with the first video frame) to a temporary beside the target and renamed when closed.
#include <filesystem>
#include <memory>
#include <string>

#include <opencv2/core.hpp>

#include "composite/compositor.h"
#include "core/camera.h"

namespace previz::composite {

// The CG camera of a take: cg/camera.json's "camera" (an ideal pinhole, rig.json camera
// format). Throws Error naming the file and the field, or when it has distortion.
Camera readCgCamera(const std::filesystem::path& camera_json);

struct CgFrame {
  cv::Mat color;  // CV_32FC3 linear R G B
  cv::Mat depth;  // CV_32FC1 metres, +inf = nothing
};
// <cg_dir>/color/%06d.exr (channels R, G, B) and <cg_dir>/depth/%06d.exr (Z). Throws Error
// naming the file and the frame when one is missing, unreadable, lacks a channel, or the two
// differ in size from each other or from 'expected' (when not empty).
CgFrame readCgFrame(const std::filesystem::path& cg_dir, int frame, cv::Size expected = {});

struct OutputOptions {
  std::filesystem::path out;     // folder (created)
  bool png = true;               // composite/%06d.png (8-bit sRGB)
  bool exr = false;              // composite/%06d.exr (linear R G B, HALF)
  bool layers = false;           // layers/{alpha,actor_depth,cg_depth}/%06d.exr + previews, front
  std::string video;             // file name under 'out' (e.g. "composite.mp4"); "" = no video
  std::string fourcc = "mp4v";   // VideoWriter codec; "MJPG" for .avi
  double fps = 24.0;
  // Depth previews' colour scale (metres).
  double preview_near_m = 2.0, preview_far_m = 12.0;
  void validate() const;         // throws Error naming the field
};

// Writes one frame's outputs: the composite (PNG / EXR), the debug layers and a video frame.
// The layers need the CompositeResult made with debug_layers = true (throws otherwise).
class CompositeWriter {
 public:
  explicit CompositeWriter(const OutputOptions& options);
  ~CompositeWriter();  // closes the video
  CompositeWriter(const CompositeWriter&) = delete;
  CompositeWriter& operator=(const CompositeWriter&) = delete;

  const OutputOptions& options() const;
  void write(int frame, const CompositeResult& result);
  // Finishes the video (renamed into place); idempotent. Throws Error naming the file when the
  // writer could not be opened for this codec.
  void close();
  // Paths of one frame's files (not the video).
  std::vector<std::filesystem::path> outputs(int frame) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace previz::composite
