// FreeD D1 and OpenTrackIO-style JSON over UDP (see stream.h).
#include "tracking/stream.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstring>
#include <sstream>

#include <Eigen/Geometry>

#include "core/error.h"
#include "core/units.h"
#include "tracking/opentrackio.h"

namespace previz::tracking {

namespace {

constexpr std::uint8_t kD1 = 0xD1;
constexpr std::int32_t kMin24 = -(1 << 23), kMax24 = (1 << 23) - 1;

void put24(std::uint8_t* p, std::int32_t v) {
  const std::uint32_t u = static_cast<std::uint32_t>(v) & 0xFFFFFFu;
  p[0] = static_cast<std::uint8_t>(u >> 16);
  p[1] = static_cast<std::uint8_t>(u >> 8);
  p[2] = static_cast<std::uint8_t>(u);
}
std::int32_t getSigned24(const std::uint8_t* p) {
  std::int32_t v = (p[0] << 16) | (p[1] << 8) | p[2];
  if (v & 0x800000) v -= 0x1000000;
  return v;
}
std::uint32_t getUnsigned24(const std::uint8_t* p) {
  return (static_cast<std::uint32_t>(p[0]) << 16) | (static_cast<std::uint32_t>(p[1]) << 8) | p[2];
}
std::uint8_t checksum(const std::uint8_t* p) {
  unsigned sum = 0;
  for (int i = 0; i < kFreeDPacketSize - 1; ++i) sum += p[i];
  return static_cast<std::uint8_t>((0x40u - sum) & 0xFFu);
}

std::int32_t quantize(double value, double scale, const char* field) {
  const double q = std::round(value * scale);
  if (!(q >= kMin24 && q <= kMax24)) {
    ErrorContext c;
    c.field = field;
    std::ostringstream s;
    s << "FreeD: " << field << " = " << value << " does not fit the packet's 24 bits";
    throw Error(s.str(), c);
  }
  return static_cast<std::int32_t>(q);
}

sockaddr_in toSockaddr(const std::string& host, int port) {
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(static_cast<std::uint16_t>(port));
  if (inet_pton(AF_INET, host.c_str(), &a.sin_addr) != 1)
    throw Error("expected a numeric IPv4 address, got '" + host + "'");
  return a;
}

}  // namespace

FreeDBytes encodeFreeD(const FreeDPacket& p) {
  auto check24 = [](std::int32_t v, const char* f) {
    if (v < kMin24 || v > kMax24) throw Error(std::string("FreeD: ") + f + " out of 24-bit range");
  };
  check24(p.pan, "pan");
  check24(p.tilt, "tilt");
  check24(p.roll, "roll");
  check24(p.x, "x");
  check24(p.y, "y");
  check24(p.z, "z");
  if (p.zoom > 0xFFFFFFu || p.focus > 0xFFFFFFu) throw Error("FreeD: zoom/focus out of 24-bit range");
  FreeDBytes b{};
  b[0] = kD1;
  b[1] = p.camera_id;
  put24(&b[2], p.pan);
  put24(&b[5], p.tilt);
  put24(&b[8], p.roll);
  put24(&b[11], p.x);
  put24(&b[14], p.y);
  put24(&b[17], p.z);
  put24(&b[20], static_cast<std::int32_t>(p.zoom));
  put24(&b[23], static_cast<std::int32_t>(p.focus));
  b[26] = static_cast<std::uint8_t>(p.spare >> 8);
  b[27] = static_cast<std::uint8_t>(p.spare);
  b[28] = checksum(b.data());
  return b;
}

std::optional<FreeDPacket> decodeFreeD(const std::uint8_t* d, size_t size, std::string* why) {
  auto reject = [&](const std::string& reason) -> std::optional<FreeDPacket> {
    if (why) *why = reason;
    return std::nullopt;
  };
  if (size != kFreeDPacketSize) return reject("freed: wrong length (" + std::to_string(size) + " bytes, D1 is 29)");
  if (d[0] != kD1) return reject("freed: not a D1 message");
  if (checksum(d) != d[28]) return reject("freed: bad checksum");
  FreeDPacket p;
  p.camera_id = d[1];
  p.pan = getSigned24(d + 2);
  p.tilt = getSigned24(d + 5);
  p.roll = getSigned24(d + 8);
  p.x = getSigned24(d + 11);
  p.y = getSigned24(d + 14);
  p.z = getSigned24(d + 17);
  p.zoom = getUnsigned24(d + 20);
  p.focus = getUnsigned24(d + 23);
  p.spare = static_cast<std::uint16_t>((d[26] << 8) | d[27]);
  return p;
}

Eigen::Vector3d panTiltRollDeg(const Eigen::Matrix3d& R) {
  // R = Rz(pan) Ry(tilt) Rx(roll): R(2,0) = -sin(tilt).
  const double tilt = std::asin(std::clamp(-R(2, 0), -1.0, 1.0));
  double pan, roll;
  if (std::abs(R(2, 0)) < 1 - 1e-12) {
    pan = std::atan2(R(1, 0), R(0, 0));
    roll = std::atan2(R(2, 1), R(2, 2));
  } else {  // gimbal lock: put everything in pan
    pan = std::atan2(-R(0, 1), R(1, 1));
    roll = 0;
  }
  return Eigen::Vector3d(degrees(pan), degrees(tilt), degrees(roll));
}

Eigen::Matrix3d rotationFromPanTiltRoll(const Eigen::Vector3d& ptr) {
  const Eigen::Vector3d r(radians(ptr[0]), radians(ptr[1]), radians(ptr[2]));
  return (Eigen::AngleAxisd(r[0], Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(r[1], Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(r[2], Eigen::Vector3d::UnitX()))
      .toRotationMatrix();
}

FreeDPacket freeDFromPose(int camera_id, const Pose& T) {
  if (camera_id < 0 || camera_id > 255) {
    ErrorContext c;
    c.field = "camera_id";
    throw Error("FreeD: camera id (prop id) must be 0..255, got " + std::to_string(camera_id), c);
  }
  const Eigen::Vector3d a = panTiltRollDeg(T.linear());
  const Eigen::Vector3d mm = 1000.0 * T.translation();
  FreeDPacket p;
  p.camera_id = static_cast<std::uint8_t>(camera_id);
  p.pan = quantize(a[0], 32768.0, "pan");
  p.tilt = quantize(a[1], 32768.0, "tilt");
  p.roll = quantize(a[2], 32768.0, "roll");
  p.x = quantize(mm.x(), 64.0, "x");
  p.y = quantize(mm.y(), 64.0, "y");
  p.z = quantize(mm.z(), 64.0, "z");
  return p;
}

Pose poseFromFreeD(const FreeDPacket& p) {
  Pose T = Pose::Identity();
  T.linear() = rotationFromPanTiltRoll(Eigen::Vector3d(p.pan, p.tilt, p.roll) / 32768.0);
  T.translation() = Eigen::Vector3d(p.x, p.y, p.z) / 64.0 / 1000.0;
  return T;
}

nlohmann::json openTrackIoSample(const PropResult& prop, int frame, double time_s, double fps,
                                 const std::string& source) {
  // OpenTrackIO 1.0.1 (schema.json): ids are urn:uuid (the source's from its name, the sample's
  // from the source, frame and prop: stable across runs), timestamps non-negative, and a lost
  // prop has no "transforms" at all (the schema wants at least one when the key is there).
  const double t = std::max(0.0, time_s);
  const double secs = std::floor(t);
  long long ns = std::llround((t - secs) * 1e9), s = static_cast<long long>(secs);
  if (ns >= 1000000000LL) {
    ns -= 1000000000LL;
    ++s;
  }
  nlohmann::json j = {
      {"protocol", {{"name", "OpenTrackIO"}, {"version", {1, 0, 1}}}},
      {"sourceId", urnUuidFromName(source)},
      {"sampleId", urnUuidFromName(source + "#" + std::to_string(frame) + "#" + std::to_string(prop.id))},
      {"sourceNumber", std::max(0, prop.id)},
      {"timing",
       {{"mode", "internal"},
        {"sampleTimestamp", {{"seconds", s}, {"nanoseconds", ns}}},
        {"sampleRate", {{"num", static_cast<long long>(std::llround(fps * 1000))}, {"denom", 1000}}},
        {"sequenceNumber", std::max(0, frame)}}},
      {"tracker", {{"status", prop.tracked ? "tracked" : "lost"}, {"notes", prop.name.empty() ? "prop" : prop.name}}},
  };
  if (prop.tracked) {
    const Eigen::Vector3d a = zxyDegFromRotation(prop.T_world_prop.linear());
    const Eigen::Vector3d tr = prop.T_world_prop.translation();
    j["transforms"] = {{{"id", prop.name.empty() ? "prop" : prop.name},
                        {"translation", {{"x", tr.x()}, {"y", tr.y()}, {"z", tr.z()}}},
                        {"rotation", {{"pan", a[0]}, {"tilt", a[1]}, {"roll", a[2]}}}}};
    j["custom"] = {{"previz",
                    {{"prop_id", prop.id},
                     {"sigma_position_mm", 1e3 * prop.measured.sigma_position_m},
                     {"sigma_rotation_deg", degrees(prop.measured.sigma_rotation_rad)},
                     {"cameras", prop.cameras}}}};
  }
  return j;
}

std::pair<std::string, int> parseHostPort(const std::string& text, const std::string& flag) {
  ErrorContext c;
  c.field = flag;
  const auto colon = text.rfind(':');
  if (colon == std::string::npos || colon == 0)
    throw Error("expected HOST:PORT with a numeric IPv4 host, e.g. 127.0.0.1:40000 (got '" + text + "')", c);
  const std::string host = text.substr(0, colon);
  int port = -1;
  try {
    size_t used = 0;
    port = std::stoi(text.substr(colon + 1), &used);
    if (used != text.size() - colon - 1) port = -1;
  } catch (const std::exception&) {
    port = -1;
  }
  in_addr a{};
  if (port < 1 || port > 65535 || inet_pton(AF_INET, host.c_str(), &a) != 1)
    throw Error("expected HOST:PORT with a numeric IPv4 host and a port 1..65535 (got '" + text + "')", c);
  return {host, port};
}

UdpSender::UdpSender(const std::string& host, int port) {
  const sockaddr_in a = toSockaddr(host, port);
  static_assert(sizeof(a) <= sizeof(addr_), "address buffer");
  std::memcpy(addr_.data(), &a, sizeof(a));
  fd_ = ::socket(AF_INET, SOCK_DGRAM, 0);
  if (fd_ < 0) throw Error(std::string("UDP: cannot open a socket: ") + std::strerror(errno));
}

UdpSender::~UdpSender() {
  if (fd_ >= 0) ::close(fd_);
}

bool UdpSender::send(const void* data, size_t size) {
  sockaddr_in a;
  std::memcpy(&a, addr_.data(), sizeof(a));
  const ssize_t n = ::sendto(fd_, data, size, 0, reinterpret_cast<const sockaddr*>(&a), sizeof(a));
  if (n != static_cast<ssize_t>(size)) {
    ++failed_;
    return false;
  }
  ++sent_;
  return true;
}

PoseStreamer::PoseStreamer(const std::string& host, int port, StreamProtocol protocol, double fps, std::string source)
    : sender_(host, port), protocol_(protocol), fps_(fps), source_(std::move(source)) {}

void PoseStreamer::send(const TrackFrame& frame) {
  for (const PropResult& p : frame.props) {
    if (protocol_ == StreamProtocol::kFreeD) {
      if (!p.tracked) continue;
      const FreeDBytes b = encodeFreeD(freeDFromPose(p.id, p.T_world_prop));
      sender_.send(b.data(), b.size());
    } else {
      const std::vector<std::uint8_t> d =
          encodeOtrk(encodeOtrkPayload(openTrackIoSample(p, frame.frame, frame.time_s, fps_, source_), OtrkEncoding::kJson),
                     OtrkEncoding::kJson, sequence_++);
      sender_.send(d.data(), d.size());
    }
  }
}

StreamReceiver::StreamReceiver(const std::string& host, int port) {
  const sockaddr_in a = toSockaddr(host, port);
  fd_ = ::socket(AF_INET, SOCK_DGRAM, 0);
  if (fd_ < 0) throw Error(std::string("UDP: cannot open a socket: ") + std::strerror(errno));
  // A render engine's burst of packets must not overflow the default buffer (the kernel caps it
  // at net.core.rmem_max).
  const int buffer = 4 << 20;
  ::setsockopt(fd_, SOL_SOCKET, SO_RCVBUF, &buffer, sizeof(buffer));
  if (::bind(fd_, reinterpret_cast<const sockaddr*>(&a), sizeof(a)) != 0) {
    const std::string why = std::strerror(errno);
    ::close(fd_);
    fd_ = -1;
    throw Error("UDP: cannot bind " + host + ":" + std::to_string(port) + ": " + why);
  }
  sockaddr_in bound{};
  socklen_t len = sizeof(bound);
  ::getsockname(fd_, reinterpret_cast<sockaddr*>(&bound), &len);
  port_ = ntohs(bound.sin_port);
}

StreamReceiver::~StreamReceiver() {
  if (fd_ >= 0) ::close(fd_);
}

int StreamReceiver::poll(int timeout_ms) {
  int count = 0;
  std::vector<std::uint8_t> buf(65536);
  for (;;) {
    pollfd p{fd_, POLLIN, 0};
    const int ready = ::poll(&p, 1, count == 0 ? timeout_ms : 0);
    if (ready <= 0 || !(p.revents & POLLIN)) break;
    const ssize_t n = ::recv(fd_, buf.data(), buf.size(), MSG_DONTWAIT);
    if (n < 0) break;
    parse(buf.data(), static_cast<size_t>(n));
    ++count;
  }
  return count;
}

void StreamReceiver::parse(const std::uint8_t* data, size_t size) {
  auto reject = [&](const std::string& why) {
    ++rejected_;
    ++rejected_by_[why];
  };
  if (size > 0 && data[0] == kD1) {
    std::string why;
    auto p = decodeFreeD(data, size, &why);
    if (!p) return reject(why);
    accepted_.push_back({std::vector<std::uint8_t>(data, data + size), p, std::nullopt});
    return;
  }
  if (size >= 4 && data[0] == 'O' && data[1] == 'T' && data[2] == 'r' && data[3] == 'k') {
    if (size < static_cast<size_t>(kOtrkHeaderSize)) return reject("opentrackio: truncated header");
    const size_t payload = ((data[12] << 8) | data[13]) & 0x7FFF;
    if (kOtrkHeaderSize + payload != size) return reject("opentrackio: length does not match the header");
    if (fletcher16(data, 14, data + kOtrkHeaderSize, payload) != ((data[14] << 8) | data[15]))
      return reject("opentrackio: bad checksum");
    const std::uint8_t* p = data + kOtrkHeaderSize;
    nlohmann::json j;
    try {  // nlohmann throws on some inputs even with exceptions off (huge CBOR lengths)
      j = data[5] == 2 ? nlohmann::json::from_cbor(p, p + payload, true, false)
                       : nlohmann::json::parse(p, p + payload, nullptr, false);
    } catch (const std::exception&) {
      return reject("json: not valid JSON or CBOR");
    }
    if (j.is_discarded() || !j.is_object()) return reject("json: not valid JSON");
    if (!j.contains("protocol") || !j["protocol"].is_object() || j["protocol"].value("name", "") != "OpenTrackIO")
      return reject("json: not an OpenTrackIO sample");
    accepted_.push_back({std::vector<std::uint8_t>(data, data + size), std::nullopt, std::move(j)});
    return;
  }
  if (size > 0 && data[0] == '{') {
    nlohmann::json j = nlohmann::json::parse(data, data + size, nullptr, false);
    if (j.is_discarded() || !j.is_object()) return reject("json: not valid JSON");
    if (!j.contains("protocol") || !j["protocol"].is_object() || j["protocol"].value("name", "") != "OpenTrackIO")
      return reject("json: not an OpenTrackIO sample");
    accepted_.push_back({std::vector<std::uint8_t>(data, data + size), std::nullopt, std::move(j)});
    return;
  }
  reject(size == 0 ? "empty datagram" : "unknown datagram");
}

}  // namespace previz::tracking
