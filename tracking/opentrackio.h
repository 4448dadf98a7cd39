#pragma once
// OpenTrackIO (SMPTE RIS OSVP, protocol 1.0.1) on the wire, and camera-tracker samples in FreeD
// D1 and OpenTrackIO decoded to one protocol-neutral form. The FreeD packet codec itself is
// tracking/stream.h's (one codec); this file adds what a *camera* tracker means by it.
//
// OpenTrackIO datagram = 16-byte header + payload (docs/formats.md "Camera tracker"):
//   [0..3] "OTrk"  [4] reserved 0  [5] encoding (0x01 JSON, 0x02 CBOR)  [6..7] sequence number
//   [8..11] segment offset  [12..13] last-segment flag (bit 15) | payload length (15 bits)
//   [14..15] Fletcher-16 over bytes 0..13 and the payload (sums mod 256, as the SMPTE reference
//   opentrackio_lib.py fletcher16 computes them); every field big-endian. At most 1500 bytes a
//   datagram (the reference's OTRK_MTU); previz sends one segment a sample and reads only
//   single-segment samples (a segmented one is counted, not reassembled).
//
// Angles and axes (OpenTrackIO's schema, "transforms"): the stage frame has z up, right-handed;
// a camera with pan = tilt = roll = 0 looks along stage +y with x to its right and z up; the
// rotation is intrinsic Z-X-Y: R_stage_otcam = Rz(pan) Rx(tilt) Ry(roll), degrees; translation in
// metres; the transforms of a sample compose left to right. previz reads a camera's FreeD D1
// the same way (FreeD does not fix its axes; this is the reading of pan about the vertical, tilt
// about the camera's horizontal axis, roll about its optical axis), with X Y Z the stage position
// in millimetres. The pose previz works with, T_stage_tracker, uses OpenCV camera axes (x right,
// y down, z forward) for the tracked body, so that T_tracker_cam = identity when the tracker
// reports the lens itself (docs/conventions.md).
#include <array>
#include <cstdint>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include "core/pose.h"
#include "tracking/stream.h"

namespace previz::tracking {

constexpr int kOtrkHeaderSize = 16;
constexpr int kOtrkMaxDatagram = 1500;  // opentrackio_lib.py OTRK_MTU
constexpr int kOtrkMaxPayload = kOtrkMaxDatagram - kOtrkHeaderSize;
constexpr int kOtrkMulticastPort = 55555;  // 239.135.1.x:55555 (opentrackio_lib.py)
enum class OtrkEncoding : std::uint8_t { kJson = 0x01, kCbor = 0x02 };

// Fletcher-16 of a followed by b (sum1, sum2 mod 256; result sum2 << 8 | sum1).
std::uint16_t fletcher16(const std::uint8_t* a, size_t a_size, const std::uint8_t* b = nullptr, size_t b_size = 0);

// One datagram: header + payload. Throws Error when the payload exceeds kOtrkMaxPayload.
std::vector<std::uint8_t> encodeOtrk(const std::vector<std::uint8_t>& payload, OtrkEncoding encoding,
                                     std::uint16_t sequence);
// The payload of a sample in the given encoding (JSON text or CBOR, nlohmann's RFC 8949 writer).
std::vector<std::uint8_t> encodeOtrkPayload(const nlohmann::json& sample, OtrkEncoding encoding);

// Why a datagram was not used; the receiver counts each.
enum class PacketFault {
  kNone,
  kMalformed,    // not a packet of the protocol (type, identifier), or a payload that is not a sample
  kTruncated,    // shorter than its header or length field says
  kBadChecksum,
  kOversize,     // longer than the protocol allows (FreeD 29 bytes, OpenTrackIO 1500)
  kUnsupported,  // a segmented OpenTrackIO sample, an unknown encoding
};
const char* toString(PacketFault fault);

// An SMPTE timecode with its rate and the sample's sub-frame (OpenTrackIO timing.timecode).
struct SampleTimecode {
  int hours = 0, minutes = 0, seconds = 0, frames = 0;
  int rate_num = 24, rate_denom = 1;
  int sub_frame = 0;
  bool drop_frame = false;
  // Seconds since 00:00:00:00 of the frame start plus sub_frame / subframes_per_frame of a frame
  // (non-drop counting; drop-frame labels are rejected upstream where it matters).
  double seconds_of_day(int subframes_per_frame = 1) const;
};

// A camera tracker's sample as decoded, in the stage frame (see the top of this file).
struct CameraSample {
  StreamProtocol protocol = StreamProtocol::kFreeD;
  int source_number = 0;              // FreeD camera id, OpenTrackIO sourceNumber
  std::string source_id;              // OpenTrackIO sourceId (urn:uuid:...), "" for FreeD
  std::optional<std::uint32_t> sequence;  // OpenTrackIO timing.sequenceNumber (else the header's)
  Pose T_stage_tracker = Pose::Identity();  // OpenCV axes for the tracked body
  Eigen::Vector3d pan_tilt_roll_deg = Eigen::Vector3d::Zero();  // as sent
  Eigen::Vector3d position_m = Eigen::Vector3d::Zero();         // as sent, in metres
  std::optional<double> zoom, focus;  // normalised encoders 0..1 (OpenTrackIO lens.encoders)
  std::optional<std::uint32_t> zoom_raw, focus_raw;  // FreeD's 24-bit encoder words
  std::optional<double> sample_time_s;               // OpenTrackIO timing.sampleTimestamp
  std::optional<SampleTimecode> timecode;             // OpenTrackIO timing.timecode
  int sample_rate_num = 0, sample_rate_denom = 1;     // OpenTrackIO timing.sampleRate (0 = absent)
};

// R = Rz(pan) Rx(tilt) Ry(roll) of a frame as it is (props), and back (pan, roll in
// (-180, 180], tilt in [-90, 90]).
Eigen::Matrix3d rotationFromZxyDeg(const Eigen::Vector3d& pan_tilt_roll_deg);
Eigen::Vector3d zxyDegFromRotation(const Eigen::Matrix3d& R);
// R_stage_tracker (OpenCV body axes) from a camera's ZXY pan/tilt/roll degrees, and back.
Eigen::Matrix3d trackerRotationFromZxy(const Eigen::Vector3d& pan_tilt_roll_deg);
Eigen::Vector3d zxyFromTrackerRotation(const Eigen::Matrix3d& R_stage_tracker);

// Decoders: never throw; on failure return nullopt with the fault and a sentence in 'why'.
std::optional<CameraSample> decodeFreeDCamera(const std::uint8_t* data, size_t size, PacketFault* fault = nullptr,
                                              std::string* why = nullptr);
std::optional<CameraSample> decodeOpenTrackIoCamera(const std::uint8_t* data, size_t size,
                                                    PacketFault* fault = nullptr, std::string* why = nullptr);
// The camera pose and lens of a parsed OpenTrackIO sample (the payload without its header).
std::optional<CameraSample> cameraSampleFromOpenTrackIo(const nlohmann::json& sample, std::string* why = nullptr);

// Encoders: what a camera tracker sends (previz tracker replay, the tests' synthetic studio).
// FreeD: pose (T_stage_tracker, OpenCV body axes) -> angles and millimetres; zoom/focus raw words.
FreeDBytes encodeFreeDCamera(int camera_id, const Pose& T_stage_tracker, std::uint32_t zoom_raw,
                             std::uint32_t focus_raw);

// Deterministic "urn:uuid:..." from a name (64-bit FNV-1a of the name and of its reverse fill
// the 128 bits; version nibble 4, variant 10xx), so one source keeps its id across runs.
std::string urnUuidFromName(const std::string& name);
// A fresh "urn:uuid:..." (version 4) from the caller's generator.
std::string urnUuidRandom(std::mt19937_64& rng);

// One OpenTrackIO camera sample (schema 1.0.1): protocol, sampleId, sourceId, sourceNumber,
// timing (mode internal, sampleRate, sampleTimestamp, sequenceNumber, timecode when given),
// tracker status, one transform "Camera", lens encoders when given.
struct OpenTrackIoCameraFields {
  std::string source_id;     // urn:uuid:...
  std::string sample_id;     // urn:uuid:...
  int source_number = 1;
  std::uint32_t sequence = 0;
  double sample_time_s = 0;  // >= 0
  int rate_num = 60, rate_denom = 1;
  std::optional<SampleTimecode> timecode;
  std::optional<double> zoom, focus;
  std::string status = "tracking";
};
nlohmann::json openTrackIoCameraSample(const OpenTrackIoCameraFields& fields, const Pose& T_stage_tracker);

}  // namespace previz::tracking
