#pragma once
// The stage's camera tracker feeding the main camera's pose and lens (docs/formats.md "Camera
// tracker"): FreeD D1 or OpenTrackIO over UDP (unicast, or OpenTrackIO's multicast
// 239.135.1.x:55555), or a recording of such a stream, decoded by tracking/opentrackio.h.
//
//   TrackerReceiver  datagrams -> TrackerSample (arrival time + decoded sample), every datagram
//                    it cannot use counted by reason; a non-blocking poll with a timeout
//   TrackerMatcher   samples -> the pose at a video frame's instant: by timecode when the frame
//                    and the samples have one, else by arrival time - delay; translation and
//                    encoders interpolated linearly, rotation by slerp, between the two samples
//                    that bracket the instant; no bracket within max_gap_s = no pose (never
//                    extrapolated)
//   TrackerInput     both, plus the stage's frame in the world (T_world_stage), the mount's
//                    offset from the lens (T_tracker_cam, `previz tracker align`) and the lens
//                    table: the main camera of a frame, what `previz run --tracker` uses
//   recordings       every datagram with its arrival time as JSON lines (`previz tracker record`),
//                    played back at rate (`previz tracker replay`) or fed to TrackerInput
//                    directly with its recorded arrival times (deterministic: tests, re-runs)
//
// Poses: T_world_cam = T_world_stage · T_stage_tracker · T_tracker_cam (docs/conventions.md).
// Times: seconds on the receiver's clock ("arrival"), where a take's frame f is at
// f / fps + frame_zero_s.
#include <array>
#include <chrono>
#include <cstdint>
#include <deque>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "calib/lens_table.h"
#include "core/camera.h"
#include "core/pose.h"
#include "core/rig.h"
#include "take/take.h"
#include "tracking/opentrackio.h"

namespace previz::live {

// --tracker freed://HOST:PORT | otio://HOST:PORT | FILE.jsonl (a recording). HOST numeric IPv4:
// 0.0.0.0 (every interface), a unicast address of this machine, or a multicast group (224..239.x:
// joined; OpenTrackIO's is 239.135.1.x:55555). Throws Error naming 'flag' with what is expected.
struct TrackerUrl {
  enum class Kind { kUdp, kRecording };
  Kind kind = Kind::kUdp;
  tracking::StreamProtocol protocol = tracking::StreamProtocol::kFreeD;  // kUdp
  std::string host;
  int port = 0;
  bool multicast = false;
  std::filesystem::path file;  // kRecording
  std::string text;            // as given
};
TrackerUrl parseTrackerUrl(const std::string& text, const std::string& flag = "--tracker");
std::string protocolScheme(tracking::StreamProtocol protocol);  // "freed", "otio"

// Every datagram's fate. A datagram is either accepted or counted under exactly one fault;
// an accepted sample may then be counted (and not used) as repeated, out_of_order or late.
struct TrackerCounts {
  long long datagrams = 0, accepted = 0;
  long long malformed = 0, truncated = 0, bad_checksum = 0, oversize = 0, unsupported = 0;
  long long other_source = 0;  // another FreeD camera id / OpenTrackIO sourceNumber than asked for
  long long repeated = 0;      // the same sequence number (OpenTrackIO) again, or the same bytes
                               // (FreeD) within half a period (a camera at rest repeats its bytes)
  long long out_of_order = 0;  // a sequence number or sample instant before the last one used
  long long late = 0;          // arrived after a frame at or past its instant had been posed
  long long missing = 0;       // gaps: sequence numbers skipped (OpenTrackIO), or FreeD arrival
                               // gaps longer than 1.5 median periods (counted per period lost)
  long long frames_posed = 0, frames_without_pose = 0;
  long long used() const { return accepted - repeated - out_of_order - late; }
  nlohmann::json toJson() const;
};

struct TrackerSample {
  double arrival_s = 0;  // receiver clock
  tracking::CameraSample sample;
};

struct TrackerOptions {
  Pose T_world_stage = Pose::Identity();  // the tracker's stage frame in previz's world
  Pose T_tracker_cam = Pose::Identity();  // the lens (entrance pupil, OpenCV axes) in the tracked body's frame
  double delay_s = 0;       // sample instant = arrival - delay (matching by arrival)
  double max_gap_s = 0.1;   // bracketing samples further apart than this: no pose
  double wait_s = 0.25;     // a frame waits this long past its instant + delay for the sample after it
  double first_wait_s = 5;  // ... and this long for the stream's first packet
  std::string match = "auto";  // "auto" (timecode when both have one), "arrival", "timecode"
  // FreeD's 24-bit encoder words -> normalised 0..1: (raw - lo) / (hi - lo).
  std::array<double, 2> freed_zoom_raw{0, 16777215}, freed_focus_raw{0, 16777215};
  int source_number = -1;   // use only this FreeD camera id / OpenTrackIO sourceNumber (-1: any)
  size_t max_samples = 4096;  // kept for matching (older ones are dropped first)
  void validate() const;      // throws Error naming the field
};
// tracker.json (docs/formats.md "Camera tracker"): {"format": "previz-tracker", "version": 1,
// "T_world_stage", "T_tracker_cam", "delay_s", ...options}. Unknown keys are refused.
TrackerOptions trackerOptionsFromJson(const nlohmann::json& j, const std::string& file = {});
nlohmann::json trackerOptionsToJson(const TrackerOptions& options);
TrackerOptions readTrackerConfig(const std::filesystem::path& path);

// Decodes datagrams of one protocol into samples; counts what it cannot use. Never throws on a
// datagram. The socket (when opened) is non-blocking: poll() waits at most its timeout.
class TrackerReceiver {
 public:
  // No socket: fed by feed() (recordings, tests).
  TrackerReceiver(tracking::StreamProtocol protocol, const TrackerOptions& options);
  // Binds HOST:PORT (port 0: any free one; a multicast group is joined). Throws Error naming
  // the address.
  TrackerReceiver(const TrackerUrl& url, const TrackerOptions& options);
  ~TrackerReceiver();
  TrackerReceiver(const TrackerReceiver&) = delete;
  TrackerReceiver& operator=(const TrackerReceiver&) = delete;

  int port() const { return port_; }
  tracking::StreamProtocol protocol() const { return protocol_; }
  // Seconds on the receiver's clock (steady clock since construction).
  double now_s() const;
  // Reads every datagram waiting, waiting up to timeout_ms for the first; returns how many.
  int poll(int timeout_ms);
  // One datagram as if it arrived at arrival_s.
  void feed(const std::uint8_t* data, size_t size, double arrival_s);
  // Samples accepted since the last call (in arrival order).
  std::vector<TrackerSample> take();
  // Every datagram received (with poll) since the last call, for recordings.
  void keepDatagrams(bool keep) { keep_datagrams_ = keep; }
  std::vector<std::pair<double, std::vector<std::uint8_t>>> takeDatagrams();
  const TrackerCounts& counts() const { return counts_; }
  TrackerCounts& counts() { return counts_; }

 private:
  tracking::StreamProtocol protocol_;
  TrackerOptions options_;
  int fd_ = -1, port_ = 0;
  std::chrono::steady_clock::time_point zero_;
  std::vector<TrackerSample> ready_;
  TrackerCounts counts_;
  bool keep_datagrams_ = false;
  std::vector<std::pair<double, std::vector<std::uint8_t>>> datagrams_;
  std::vector<std::uint8_t> buffer_;
  // Sequence and repeat checks.
  std::optional<std::uint32_t> last_sequence_;
  std::optional<double> last_sample_time_;
  std::vector<std::uint8_t> last_bytes_;
  std::optional<double> last_arrival_;
  std::vector<double> intervals_;  // FreeD arrival intervals (the median period for gaps)
};

// The pose (in the stage frame) and lens encoders at an instant.
struct TrackerPose {
  Pose T_stage_tracker = Pose::Identity();
  std::optional<double> zoom, focus;  // normalised
  bool by_timecode = false;
  double gap_s = 0;        // between the bracketing samples
  double instant_s = 0;    // the instant asked for, on the clock used
};

class TrackerMatcher {
 public:
  explicit TrackerMatcher(const TrackerOptions& options);
  // Adds samples (any order); a sample at or before an instant already posed is late: counted
  // in 'counts' and not used.
  void add(const TrackerSample& s, TrackerCounts& counts);
  // Whether a sample keyed after 'instant_s' is there (by arrival, or by timecode).
  bool hasSampleAfter(double instant_s, bool by_timecode) const;
  // The pose at a frame: frame_arrival_s on the receiver's clock (matched with arrival - delay),
  // frame_timecode_s (seconds of day, when the frame has a timecode). nullopt with 'why' when no
  // two samples bracket the instant within max_gap_s. Marks the instant as consumed.
  std::optional<TrackerPose> poseAt(double frame_arrival_s, std::optional<double> frame_timecode_s,
                                    std::string* why);
  size_t size() const { return by_arrival_.size(); }

 private:
  struct Keyed {
    double key;
    Pose T;
    std::optional<double> zoom, focus;
  };
  static std::optional<TrackerPose> interpolate(const std::deque<Keyed>& v, double t, double max_gap, std::string* why);
  void insert(std::deque<Keyed>& v, Keyed k);
  TrackerOptions options_;
  std::deque<Keyed> by_arrival_, by_timecode_;
  double consumed_arrival_ = -1e300, consumed_timecode_ = -1e300;
};

// A recording (JSON lines): a header line {"format": "previz-tracker-recording", "version": 1,
// "protocol", "url", "started_unix_ms"} then one line a datagram {"arrival_s", "bytes" (hex),
// "size", and either "fault" + "why" or the decoded "source", "sequence", "T_stage_tracker",
// "pan_tilt_roll_deg", "position_m", "zoom", "focus", "zoom_raw", "focus_raw", "sample_time_s",
// "timecode"}. Replay uses "bytes"; the rest is for people and tools.
struct RecordedDatagram {
  double arrival_s = 0;
  std::vector<std::uint8_t> bytes;
};
struct TrackerRecording {
  tracking::StreamProtocol protocol = tracking::StreamProtocol::kFreeD;
  std::string url;
  long long started_unix_ms = 0;
  std::vector<RecordedDatagram> datagrams;  // in arrival order
};
std::string recordingText(const TrackerRecording& recording, const TrackerOptions& options);
void writeRecording(const std::filesystem::path& path, const TrackerRecording& recording,
                    const TrackerOptions& options);  // atomic
TrackerRecording readRecording(const std::filesystem::path& path);  // throws Error naming file and line

// Plays a recording to HOST:PORT at its recorded rate (speed 2 = twice as fast); returns the
// datagrams sent. 'stop' (optional) is asked between datagrams.
int replayRecording(const TrackerRecording& recording, const std::string& host, int port, double speed,
                    const std::function<bool()>& stop = {});

// A synthetic camera tracker (tests, `previz tracker simulate`): the true pose of the lens at
// any instant, sampled at rate_hz from start_s to end_s, each sample encoded as the protocol
// sends it, arriving delay_s (+ uniform jitter) later, a fraction lost, all from the seed.
struct TrackerSimulation {
  tracking::StreamProtocol protocol = tracking::StreamProtocol::kFreeD;
  double rate_hz = 60;
  double start_s = 0, end_s = 1;
  double delay_s = 0.040;
  double jitter_s = 0.002;  // arrival jitter, uniform in [-jitter, +jitter]
  double loss = 0.01;       // fraction of datagrams lost
  std::uint64_t seed = 1;
  Pose T_world_stage = Pose::Identity();
  Pose T_tracker_cam = Pose::Identity();
  std::optional<double> zoom, focus;  // normalised encoders (FreeD: raw = round(v * 16777215))
  std::string start_timecode;         // OpenTrackIO: the timecode of instant 0 ("" = none)
  double timecode_fps = 24;
  bool cbor = false;                  // OpenTrackIO payload in CBOR
  int source_number = 1;
  void validate() const;
};
TrackerRecording simulateTracker(const std::function<Pose(double)>& T_world_cam_at, const TrackerSimulation& sim);

// The instants of a take's frames as the tracker matches them: frame f at (f - first frame) /
// fps on the take's clock, and its timecode (seconds of day, at the nominal rate) when the main
// camera's stream has a start timecode: that timecode + (f - its first source frame + offset).
struct FrameClock {
  double fps = 24;
  int first_frame = 0;
  std::optional<double> tc0_s;  // timecode of first_frame
  double timeOf(int frame) const { return (frame - first_frame) / fps; }
  std::optional<double> timecodeOf(int frame) const;
};
FrameClock frameClock(const take::Take& streams, const std::string& main_camera);

// What `previz run --tracker` uses: a receiver (socket or recording) and a matcher. For each
// frame, the main camera: pose from the tracker, lens from the table at the sample's encoders
// (when a table is given; scaled to the plate's size) else the rig's.
class TrackerInput {
 public:
  // plate: the main camera as the rig has it (size, name, fallback lens). lens: optional.
  TrackerInput(const TrackerUrl& url, const TrackerOptions& options, const Camera& plate,
               std::optional<calib::LensTable> lens = std::nullopt);
  ~TrackerInput();
  // The main camera at take frame 'frame' whose instant is frame_time_s on the take's clock
  // (frame / fps; + the options' frame zero) and, when the take has timecode, frame_timecode_s.
  // Live sockets: waits (polling) for the sample after the instant, at most wait_s past it.
  // Throws Error (camera, frame, "no tracker pose: ...") when there is none.
  RigCamera mainAt(int frame, double frame_time_s, std::optional<double> frame_timecode_s, const RigCamera& rig_main);
  const TrackerCounts& counts() const { return receiver_->counts(); }
  int port() const { return receiver_->port(); }  // the socket's (0 for a recording)
  nlohmann::json summary() const;
  // Seconds on the tracker's clock at which take frame 0 is (recordings: 0; sockets: set at
  // the first packet as its arrival - delay, i.e. the first sample is taken to be frame 0's).
  double frameZero() const { return frame_zero_s_; }

 private:
  void pump(double until_arrival_s, bool by_timecode, double instant_key);
  TrackerUrl url_;
  TrackerOptions options_;
  Camera plate_;
  std::optional<calib::LensTable> lens_;
  std::unique_ptr<TrackerReceiver> receiver_;
  TrackerMatcher matcher_;
  TrackerRecording recording_;
  size_t next_datagram_ = 0;
  std::optional<double> first_arrival_s_;
  double frame_zero_s_ = 0;
  std::vector<double> gaps_s_;
  std::map<std::pair<long long, long long>, Camera> lens_cache_;
};

}  // namespace previz::live
