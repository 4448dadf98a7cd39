#pragma once
// Green-screen chroma keyer: soft alpha and a binary silhouette per camera frame, and spill
// suppression of the main plate for the compositor. The screen colour is estimated per camera,
// from a clean plate when given, else from the frame itself; the key is robust to uneven light
// and to the actor's shadows on the floor (a shadowed screen is still screen).
#include <string>

#include <opencv2/core.hpp>

namespace previz::carving {

struct KeyerOptions {
  // Silhouette = alpha above this after cleaning.
  double silhouette_threshold = 0.5;
  // Connected specks of the silhouette smaller than this (px) are removed, and holes smaller than
  // this are filled; thin limbs are never eroded (no opening).
  int min_blob_px = 64;
  int min_hole_px = 64;
  // Garbage matte: pixels that are not screen-like AND connected to the image border through
  // non-screen pixels only (studio walls, rigging above the cyclorama) are dropped.
  bool garbage_matte = true;
  void validate() const;  // throws Error naming the field
};

// What the keyer knows about one camera's screen (estimated once per camera, then reused).
struct ScreenModel {
  cv::Vec3f key_color;           // linear RGB of the lit screen, channel order B, G, R
  cv::Mat illumination;          // optional per-pixel screen brightness (CV_32FC1, from a clean plate)
  bool from_clean_plate = false;
};

struct KeyResult {
  cv::Mat alpha;       // CV_32FC1 in [0, 1]: 1 = foreground
  cv::Mat silhouette;  // CV_8UC1, 255 inside, 0 outside
};

class Keyer {
 public:
  explicit Keyer(const KeyerOptions& options = {});
  // Screen model from a clean plate (the empty stage from this camera).
  void setCleanPlate(const cv::Mat& bgr8);
  // Estimated from the frame when no clean plate / model was set; 'source' names the frame in
  // errors (wrong type, empty image).
  KeyResult key(const cv::Mat& bgr8, const std::string& source = {});
  const ScreenModel& screen() const { return screen_; }
  bool hasScreen() const { return has_screen_; }

 private:
  KeyerOptions options_;
  ScreenModel screen_;
  bool has_screen_ = false;
};

// Spill suppression for the main plate: the screen's green cast removed from the foreground
// (8-bit BGR in, 8-bit BGR out), given the camera's screen model.
cv::Mat despill(const cv::Mat& bgr8, const ScreenModel& screen);

}  // namespace previz::carving
