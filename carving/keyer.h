#pragma once
// Green- or blue-screen chroma keyer: soft alpha and a binary silhouette per camera frame, and
// spill suppression of the main plate for the compositor. A blue screen is keyed exactly as a
// green one with the blue and green channels swapped: every rule below is symmetric in the two
// other channels, so "green" reads "the screen's channel" throughout. The screen colour is estimated per camera,
// from a clean plate when given, else from the frame itself; the key is robust to uneven light
// and to the actor's shadows on the floor (a shadowed screen is still screen).
//
// How a pixel is decided (keyer.cpp has the details):
//  1. One pass classifies every pixel as screen, garbage, foreground or unknown. Screen is judged
//     on chroma normalised by brightness, q = (G - max(R, B)) / G in linear light, which a shadow
//     (a scale of the screen colour) leaves unchanged; computed on the 8-bit codes (SIMD).
//     Garbage is what lies beyond the screen (the dark studio over a cyclorama; in the synthetic
//     studio a third of some witnesses' actor pixels stand in front of it): with a clean plate,
//     the plate's non-screen region connected to the border, keyed by difference against the
//     plate; without one, pixels of the colour of the non-screen band along the image border,
//     connected to the border through such pixels (so the actor in front of it is kept) or to
//     the zone remembered from earlier frames (gaps the actor encloses). Unknown pixels in a
//     cluster within 3 x 3 with background all round are sensor noise and become background.
//  2. Pixels at a transition (unknown, or a neighbour of another class) get a two-colour alpha:
//     the local background B (mean of the background neighbours, or the plate scaled by the
//     neighbours' shadow factor) and the pure foreground F (mean of the best-fitting foreground
//     neighbours nearly as far from B as the farthest: one pixel alone carries its noise); alpha
//     is the projection of C - B on F - B in linear light (how anti-aliasing and lenses mix).
//  3. Silhouette = alpha >= threshold; a pixel near one half is decided by its 3 x 3 mean alpha
//     (for a straight edge that tells on which side the pixel's centre lies, its own alpha does
//     not). Then connected components: specks and holes smaller than the options' sizes are
//     removed / filled (no morphological opening: thin limbs survive).
// No screen (Backdrop::kNone): step 1 is a difference against the clean plate instead. The
// frame's exposure relative to the plate is the median ratio of their brightness (the actor
// covers a minority of a witness frame); a pixel within the noise tolerance (from the plate's
// and the frame's estimated sensor noise) of the plate at that exposure is background; one that
// is the plate darkened by a factor in [min_shadow, 1] with its colour kept is a shadow, also
// background; twice the tolerance away from both is foreground; between is unknown. Steps 2 and
// 3 are the same, with the plate as the local background.
// One Keyer per camera: the screen model is estimated once (plate or first frame) and reused; a
// Keyer keeps per-camera state and scratch, so key cameras in parallel with one Keyer each.
#include <cstdint>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

namespace previz::carving {

// The backdrop a camera is keyed against.
enum class Backdrop {
  kAuto,   // green or blue, whichever screen the clean plate (else the first frame) shows; no
           // screen in the clean plate: kNone
  kGreen,
  kBlue,   // keyed as green with the blue and green channels swapped (the model is symmetric)
  kNone,   // no screen (a set, a room): keyed by difference against the camera's clean plate
};
const char* toString(Backdrop backdrop);
// "auto" | "green" | "blue" | "none"; throws Error naming the value.
Backdrop backdropFromString(const std::string& name);

struct KeyerOptions {
  Backdrop backdrop = Backdrop::kAuto;
  // Silhouette = alpha at or above this after cleaning.
  double silhouette_threshold = 0.5;
  // Connected specks of the silhouette smaller than this (px) are removed, and holes smaller than
  // this are filled; thin limbs are never eroded (no opening).
  int min_blob_px = 64;
  int min_hole_px = 64;
  // Garbage matte: pixels that are not screen, look like the non-screen surroundings (studio
  // walls, rigging above the cyclorama) AND are connected to the image border through such
  // pixels are background. With a clean plate: the plate's border-connected non-screen region,
  // keyed by difference against the plate.
  bool garbage_matte = true;
  // Without a clean plate: remember the garbage zone found in earlier frames of this camera, so
  // that the surroundings seen through a gap enclosed by the actor are keyed once they have been
  // seen connected to the border. For static cameras; set false for a moving camera.
  bool remember_garbage_zone = true;
  // Half-size of the window (px) in which an edge pixel looks for its pure foreground and
  // background colours; 2 covers a 1-px anti-aliased edge plus ~1 px of defocus.
  int edge_radius_px = 2;
  // Difference (8-bit levels, max over channels) below which a pixel equals the clean plate in
  // the plate's garbage region; raise it with sensor noise (about 4 sigma).
  int plate_tolerance = 10;
  // Fill KeyResult::alpha (CV_32FC1). Carving needs only the silhouette: false saves writing
  // the float image (~0.1 ms of a witness camera's ~2 ms, ~0.5 ms of the main camera's).
  bool soft_alpha = true;
  // Difference keying (no screen): a pixel that is its plate colour darkened by a factor in
  // [min_shadow, 1] within noise is a shadow on the set, background. Deeper is foreground (dark
  // hair over an oak floor is the floor darkened 3-4x, with the floor's hue). Set it to the
  // lights' deepest shadow, fill / (fill + key): the synthetic studio's is 0.43.
  double min_shadow = 0.4;
  // ... and keeps the plate's hue: around a shadow pixel (5 x 5), the mean of the candidates'
  // residuals to the darkened plate is within noise and this many levels per channel (coloured
  // fill light shifts a real shadow's hue a little; a costume is off the same way everywhere).
  double shadow_hue_levels = 3;
  int threads = 0;  // OpenMP threads for one key() call (0 = OpenMP's default)
  // Region keying, for consecutive frames of a live loop (0 = off: every frame keyed whole). The
  // actor covers 2-5 % of a witness frame and moves a few pixels a frame, so a frame is keyed
  // only inside the boxes of the last frame's silhouette parts (each connected part: the actor,
  // a prop across the stage), grown by this margin (px), boxes that overlap merged; everywhere
  // else is background. One box around actor and prop together held half as many pixels again
  // on the live bench take. The frame is keyed whole instead (KeyStats::whole_frame says why)
  // when there is no earlier silhouette, when the silhouette reaches a region's edge (it may go
  // on past it), when every 8th row probed outside the regions shows clear foreground (an actor
  // walking in, a prop put down; 3 pixels in a row), and every region_full_every frames (what
  // the probe cannot see: something under 8 rows tall, or of the surroundings' own colour). Call
  // resetRegion() when frames stop being consecutive (a gap, a seek).
  int region_margin_px = 0;
  int region_full_every = 24;  // 0 = never
  // Which of those frames (frames keyed modulo region_full_every): a loop keying several cameras
  // staggers them, so that no frame pays for every camera's whole key at once.
  int region_full_phase = 0;
  void validate() const;  // throws Error naming the field
};

// Colour of the non-screen surroundings seen along the image border (no clean plate): linear
// chromaticity r = R / S, b = B / S with S = R + G + B, and the brightest S it reaches. Up to
// three colours (a studio's black drapes; a turntable's wall above it and a black band beside).
struct GarbageMode {
  float r = 0, b = 0;        // median chromaticity
  float tolerance = 0;       // accepted |r - r0|, |b - b0|
  float max_sum = 0;         // brightest accepted S (linear)
};
struct GarbageModel {
  bool valid = false;
  int count = 0;             // modes in use
  GarbageMode modes[3];
};

// What the keyer knows about one camera's screen (estimated once per camera, then reused).
// Colours here are in the keyer's working order: B, G, R for a green screen, G, B, R for a blue
// one (the screen's channel is always the second), and so is the plate.
struct ScreenModel {
  Backdrop backdrop = Backdrop::kGreen;  // green or blue (never kAuto once estimated)
  cv::Vec3f key_color;          // linear colour of the lit screen (working order)
  float key_q = 0;              // (S - max of the others) / S of key_color: the screen's chroma
  bool from_clean_plate = false;
  // Clean plate only: the plate (CV_8UC3); its linear green (CV_32FC1: the screen's
  // illumination, uneven light and falloff included); the garbage zone (CV_8UC1, 255 =
  // non-screen region connected to the border, dilated by the edge radius so the cyclorama's
  // anti-aliased rim is keyed by difference too); and, per pixel, the 8-bit green range a frame
  // pixel may have to be screen (CV_8UC2: darkest shadow .. slight brightening of the plate;
  // min > max inside the garbage zone).
  cv::Mat plate;
  cv::Mat illumination;
  cv::Mat garbage_zone;
  cv::Mat plate_green_range;
  GarbageModel garbage;         // no clean plate: re-estimated on every frame
  // Difference keying: the plate's sensor noise (grey levels, estimated from the plate) and the
  // last frame's exposure relative to the plate (its robust median ratio).
  float plate_noise = 0;
  float exposure_gain = 1;
};

struct KeyStats {
  int unknown_px = 0;      // pixels given a two-colour alpha
  int lone_unknown_px = 0; // unknown pixels in clusters within 3 x 3 among background (sensor noise)
  int garbage_px = 0;      // pixels dropped by the garbage matte
  int specks_removed = 0;  // silhouette components removed (smaller than min_blob_px)
  int holes_filled = 0;    // holes filled (smaller than min_hole_px)
  int shadow_px = 0;       // difference keying: pixels taken for shadows on the set
  // Region keying (KeyerOptions::region_margin_px): false when only the regions were keyed;
  // true with the reason when the whole frame was.
  bool whole_frame = true;
  std::string whole_frame_reason;
  int keyed_px = 0;        // the regions' pixels, or the frame's when it was keyed whole
};

struct KeyResult {
  cv::Mat alpha;       // CV_32FC1 in [0, 1] (1 = foreground), 8-bit steps; empty if !soft_alpha
  cv::Mat silhouette;  // CV_8UC1, 255 inside, 0 outside
  KeyStats stats;
};

namespace detail {
struct LonePixel {  // an unknown pixel taken for sensor noise (keyer.cpp)
  int x, y;
  std::uint8_t cls;  // the background class it becomes
};
}  // namespace detail

class Keyer {
 public:
  explicit Keyer(const KeyerOptions& options = {});
  // Screen model from a clean plate (the empty stage from this camera, CV_8UC3 sRGB). Frames
  // keyed afterwards must have the plate's size. 'source' names the plate in errors.
  void setCleanPlate(const cv::Mat& bgr8, const std::string& source = {});
  // Keys one frame (CV_8UC3 sRGB, B G R). The screen model is estimated from this frame when no
  // clean plate / model was set. 'source' names the frame in errors (wrong type, empty image,
  // size unlike the plate's, no screen found).
  KeyResult key(const cv::Mat& bgr8, const std::string& source = {});
  // The same into 'result', its images reused when they have the frame's size (a live loop's
  // buffers: no allocation, no page faults per frame). Whoever still holds result's images
  // from an earlier frame sees them overwritten.
  void key(const cv::Mat& bgr8, const std::string& source, KeyResult& result);
  // Forgets the last silhouette's region: the next frame is keyed whole.
  void resetRegion();
  const ScreenModel& screen() const { return screen_; }
  bool hasScreen() const { return has_screen_; }
  const KeyerOptions& options() const { return options_; }

 private:
  KeyerOptions options_;
  ScreenModel screen_;
  bool has_screen_ = false;
  // The frame in working order (blue screen: blue and green swapped; green: the frame itself).
  const cv::Mat& working(const cv::Mat& bgr8);
  void chooseBackdrop(const cv::Mat& bgr8, const std::string& source, bool is_plate);
  Backdrop backdrop_ = Backdrop::kAuto;  // resolved on the plate or the first frame
  cv::Mat swapped_;
  cv::Mat garbage_memory_;  // CV_8UC1: garbage zone of earlier frames (no clean plate)
  // Scratch reused from frame to frame (the hot loops allocate nothing).
  cv::Mat classes_, alpha8_, need_rows_;
  cv::Mat shadow_residual_;  // difference keying: the shadow candidates' residuals
  std::vector<std::vector<cv::Point>> band_refined_, band_seeds_;
  std::vector<std::vector<detail::LonePixel>> band_lone_;
  // Region keying: the next frame's region (empty: key it whole) and frames since the last whole one.
  std::vector<cv::Rect> regions_;  // disjoint
  std::vector<cv::Rect> parts_, region_parts_;  // scratch: the boxes of the silhouette's parts
  long long frames_keyed_ = 0;
  struct Frame;
  // Keys 'region' of the frame into result (stats added to result.stats); 'parts' (if not null)
  // gets the boxes of the silhouette's parts in it, in the region's coordinates.
  void keyRegion(const Frame& f, const cv::Rect& region, KeyResult& result, std::vector<cv::Rect>* parts);
  bool foregroundOutside(const Frame& f, const std::vector<cv::Rect>& regions);
  static bool reachesEdge(const cv::Mat& silhouette, const cv::Rect& region);
};

// Spill suppression for the main plate (8-bit sRGB BGR in and out), given the frame's key (with
// its soft alpha) and the camera's screen model: the
// unpremultiplied foreground colour F, for the compositor's over (alpha F + (1 - alpha) CG).
// Opaque pixels (alpha = 1) are unchanged; on the transition the screen's share is removed,
// F = (C - (1 - alpha) B) / alpha in linear light, B the local screen colour as the keyer saw
// it; where alpha = 0, F is C with green limited to max(R, B) (it is never seen).
cv::Mat despill(const cv::Mat& bgr8, const KeyResult& key, const ScreenModel& screen,
                const KeyerOptions& options = {});
// The same into 'out', reused when it has the frame's size and type (see Keyer::key); 'out'
// must not share the frame's pixels (neighbours are read while it is written).
void despill(const cv::Mat& bgr8, const KeyResult& key, const ScreenModel& screen, const KeyerOptions& options,
             cv::Mat& out);

}  // namespace previz::carving
