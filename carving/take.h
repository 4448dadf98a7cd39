#pragma once
// Reading a take for carving: the rig (rig.json, or another tool's text rows of 3x4 projection
// matrices or K R t), the cameras' streams through the take model (take/take.h: image
// sequences of any pattern, videos, offsets and timecode, clean plates), optional external
// mattes <masks>/<cam>/%06d.png (> 127 = inside; they replace keying) and optional per-frame
// poses of the main camera. A camera whose frame is missing, unreadable or of the wrong size is
// dropped for that frame with the reason, never fatal. Layout: docs/formats.md ("Take folder",
// "Carve output").
#include <filesystem>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/rig.h"
#include "take/take.h"

namespace previz::carving {

struct TakeSource {
  std::filesystem::path take_dir;    // cams/ (take/take.h), clean/, take.json
  // rig.json (by extension .json), else text rows, one camera a line: "name p11 .. p34"
  // (projection rows, P = K [R | t]) or "name k11 .. k33 r11 .. r33 t1 t2 t3" (K R t rows),
  // told apart by the count of numbers. Rows carry no image size: each camera takes the size
  // of its first frame (or mask) found in the take.
  std::filesystem::path rig_path;
  std::filesystem::path masks_dir;   // optional: <masks_dir>/<cam>/%06d.png
  // Optional JSON lines {"frame": f, "T_world_cam": {"R", "t"}} for the main camera when it
  // moves (the format of a synthetic take's truth/main_poses.jsonl and of `previz track
  // camera`'s camera_poses.jsonl); frames not listed keep the rig's pose, frames it marks lost or
  // bad drop the main camera for that frame (read() says why).
  std::filesystem::path main_poses;
};

// One camera's input for one frame.
struct CameraFrame {
  std::string camera;
  int frame = 0;
  cv::Mat image;        // 8-bit BGR plate (only read when the take has no masks)
  cv::Mat mask;         // CV_8UC1, 255 inside / 0 outside (only with masks)
  std::string dropped;  // "" = usable; else why the camera is dropped for this frame
  bool ok() const { return dropped.empty(); }
};

class Take {
 public:
  // Throws Error naming the take folder, the rig file (and its field) or the poses file.
  explicit Take(const TakeSource& source);

  const TakeSource& source() const { return source_; }
  const Rig& rig() const { return rig_; }
  // "rig.json", "projection rows" or "K R t rows".
  const std::string& rigFormat() const { return rig_format_; }
  bool hasMasks() const { return !source_.masks_dir.empty(); }
  bool hasMainPoses() const { return !source_.main_poses.empty(); }

  // Frame numbers of the take, ascending: every take frame any rig camera has (take/take.h), or
  // mask with masks, and 0 .. frames-1 from take.json when it has them.
  const std::vector<int>& frames() const { return frames_; }

  // The take model over the rig's cameras (streams, offsets, timecode).
  const take::Take& streams() const { return *streams_; }
  // Where a camera's frame comes from, for messages: "cams/A/000012.png", "cams/A.mkv frame 14".
  std::string source(const std::string& camera, int frame) const;
  std::filesystem::path maskPath(const std::string& camera, int frame) const;

  // The camera's clean plate (empty stage, 8-bit BGR) or an empty Mat when there is none
  // (take::Take::cleanPlate). Throws Error naming the file when one exists but cannot be used.
  cv::Mat cleanPlate(const std::string& camera) const;

  // Reads one camera's frame (its mask with masks, else its plate). Never throws for a bad
  // frame: the reason goes to CameraFrame::dropped. Throws only for a camera not in the rig.
  CameraFrame read(const std::string& camera, int frame) const;

  // Reads one camera's plate whether or not the take has masks (depth
  // refinement compares plates); never throws for a bad frame, as read().
  CameraFrame readPlate(const std::string& camera, int frame) const;

  // The camera's linear gain from take.json "camera_gains" (a synthetic take's per-camera
  // brightness); 0 = unknown when the take does not say (refinement then estimates it).
  double gain(const std::string& camera) const;

  // The camera as it was at that frame (the main camera's pose from main_poses when given).
  RigCamera cameraAt(const std::string& camera, int frame) const;

 private:
  CameraFrame plate(const RigCamera& rc, int frame) const;
  // Not ok() for the main camera at a frame its poses file marks lost or bad.
  CameraFrame unposed(const std::string& camera, int frame) const;

  TakeSource source_;
  std::shared_ptr<const take::Take> streams_;
  Rig rig_;
  std::string rig_format_;
  std::vector<int> frames_;
  std::map<int, Pose> main_poses_;
  std::map<int, std::string> main_lost_;  // frame -> why the poses file has no pose there
  std::map<std::string, double> gains_;
  std::string main_name_;
};

}  // namespace previz::carving
