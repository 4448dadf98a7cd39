#pragma once
// The world's scale against tags of known size: the tags of props.json seen by two or more
// cameras of a rig are triangulated corner by corner, and each tag's four edges, measured in the
// rig's world, are compared with the printed size. A rig whose metres are not metres (another
// tool's millimetres or centimetres, a rig solved on a board of the wrong square size) shows
// here, where the carving cameras would agree with each other regardless. `previz take check`
// reports it.
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "core/rig.h"
#include "tracking/detect.h"
#include "tracking/props.h"

namespace previz::tracking {

// Every camera's image of one frame and the camera as it was then (pose, lens).
struct ScaleFrame {
  int frame = 0;
  std::vector<RigCamera> cameras;
  std::vector<cv::Mat> images;  // empty = no image of that camera
};

struct ScaleCheck {
  int tags = 0;         // tag sightings with all four corners triangulated
  int edges = 0;        // edges measured (4 per tag)
  double ratio = 0;     // median of measured / printed edge length (1: the rig's world is metric)
  double spread = 0;    // median absolute deviation of those ratios
  std::vector<int> frames;  // frames with at least one tag triangulated
  bool measured() const { return edges > 0; }
};

// Throws Error naming the field for bad detector options; frames without a tag seen twice add
// nothing.
ScaleCheck measureScale(const std::vector<ScaleFrame>& frames, const PropSet& props,
                        const DetectorOptions& detector = {});

}  // namespace previz::tracking
