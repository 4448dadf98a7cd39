#pragma once
// Pose streaming to render engines over UDP: FreeD D1 (the camera-tracking protocol every engine
// reads; one FreeD camera id per prop) and OpenTrackIO-style JSON; and a receiver that parses both
// back (for tests and `previz track --listen`-style checks), rejecting and counting malformed
// datagrams without ever failing on them.
//
// FreeD D1 packet, 29 bytes (docs/formats.md, "Tracking"):
//   [0] 0xD1  [1] camera id  [2..4] pan  [5..7] tilt  [8..10] roll   (signed 24-bit big-endian,
//   degrees x 32768)  [11..13] X  [14..16] Y  [17..19] Z   (signed 24-bit big-endian, mm x 64)
//   [20..22] zoom  [23..25] focus (unsigned 24-bit)  [26..27] spare  [28] checksum =
//   (0x40 - sum of bytes 0..27) mod 256.
// Angles of a pose: R_world_prop = Rz(pan) Ry(tilt) Rx(roll) (world z up), pan in (-180, 180],
// tilt in [-90, 90]; X Y Z = the prop centre in world millimetres.
#include <array>
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/pose.h"
#include "tracking/tracker.h"

namespace previz::tracking {

// The integer fields of a D1 packet, as on the wire.
struct FreeDPacket {
  std::uint8_t camera_id = 0;
  std::int32_t pan = 0, tilt = 0, roll = 0;  // degrees x 32768
  std::int32_t x = 0, y = 0, z = 0;          // mm x 64
  std::uint32_t zoom = 0, focus = 0;         // 24-bit
  std::uint16_t spare = 0;
};
constexpr int kFreeDPacketSize = 29;
using FreeDBytes = std::array<std::uint8_t, kFreeDPacketSize>;

// Throws Error when a field does not fit its 24 bits (e.g. a position beyond +-131 m).
FreeDBytes encodeFreeD(const FreeDPacket& packet);
// nullopt with 'why' set on a wrong length, a wrong message type or a bad checksum.
std::optional<FreeDPacket> decodeFreeD(const std::uint8_t* data, size_t size, std::string* why = nullptr);

// Pose <-> packet (angles and position quantized to the packet's units).
FreeDPacket freeDFromPose(int camera_id, const Pose& T_world_prop);
Pose poseFromFreeD(const FreeDPacket& packet);
// Pan, tilt, roll (degrees) of a rotation, as above.
Eigen::Vector3d panTiltRollDeg(const Eigen::Matrix3d& R);
Eigen::Matrix3d rotationFromPanTiltRoll(const Eigen::Vector3d& pan_tilt_roll_deg);

// OpenTrackIO 1.0.1 sample for one prop of one frame (docs/formats.md, "Tracking"): valid against
// the SMPTE schema; PoseStreamer sends it behind the 16-byte OTrk header (tracking/opentrackio.h).
nlohmann::json openTrackIoSample(const PropResult& prop, int frame, double time_s, double fps,
                                 const std::string& source);

enum class StreamProtocol { kFreeD, kOpenTrackIo };

// host:port with a numeric IPv4 host (e.g. 127.0.0.1:40000); throws Error naming 'flag'.
std::pair<std::string, int> parseHostPort(const std::string& text, const std::string& flag = "--udp");

class UdpSender {
 public:
  UdpSender(const std::string& host, int port);  // throws Error on a bad address / socket error
  ~UdpSender();
  UdpSender(const UdpSender&) = delete;
  UdpSender& operator=(const UdpSender&) = delete;
  // Sends one datagram; returns false (and counts it) when the OS refuses it.
  bool send(const void* data, size_t size);
  int sent() const { return sent_; }
  int failed() const { return failed_; }

 private:
  int fd_ = -1;
  std::array<std::uint8_t, 16> addr_{};
  int sent_ = 0, failed_ = 0;
};

// Streams a tracker's frames: per tracked prop one FreeD packet (camera id = prop id, which must
// be 0..255) or one OpenTrackIO JSON datagram. Lost props send nothing in FreeD (a stale pose is
// never sent as live) and a sample with status "lost" and no transform in OpenTrackIO.
class PoseStreamer {
 public:
  PoseStreamer(const std::string& host, int port, StreamProtocol protocol, double fps,
               std::string source = "previz");
  void send(const TrackFrame& frame);
  int sent() const { return sender_.sent(); }
  int failed() const { return sender_.failed(); }

 private:
  UdpSender sender_;
  StreamProtocol protocol_;
  double fps_;
  std::string source_;
  std::uint16_t sequence_ = 0;  // OpenTrackIO header's sequence number, one per datagram
};

// Binds a UDP socket on a loopback or numeric address (port 0 = any free port) and parses what
// arrives. Everything it cannot parse is counted by reason, never thrown.
class StreamReceiver {
 public:
  explicit StreamReceiver(const std::string& host = "127.0.0.1", int port = 0);
  ~StreamReceiver();
  StreamReceiver(const StreamReceiver&) = delete;
  StreamReceiver& operator=(const StreamReceiver&) = delete;
  int port() const { return port_; }

  // Waits up to timeout_ms for datagrams and parses every one that is there; returns how many
  // datagrams were read.
  int poll(int timeout_ms);

  struct Received {
    std::vector<std::uint8_t> bytes;  // the datagram as received
    std::optional<FreeDPacket> freed;
    std::optional<nlohmann::json> otio;  // parsed JSON object
  };
  const std::vector<Received>& accepted() const { return accepted_; }
  int rejected() const { return rejected_; }
  const std::map<std::string, int>& rejectedBy() const { return rejected_by_; }

 private:
  void parse(const std::uint8_t* data, size_t size);
  int fd_ = -1;
  int port_ = 0;
  std::vector<Received> accepted_;
  int rejected_ = 0;
  std::map<std::string, int> rejected_by_;
};

}  // namespace previz::tracking
