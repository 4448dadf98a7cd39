// The camera tracker's input to the live frame (live/tracker.h).
#include "live/tracker.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <random>
#include <sstream>
#include <thread>

#include <Eigen/Geometry>

#include "core/error.h"
#include "core/io.h"
#include "core/stats.h"
#include "take/timecode.h"

namespace previz::live {

using tracking::CameraSample;
using tracking::PacketFault;
using tracking::StreamProtocol;

namespace {

using Clock = std::chrono::steady_clock;

[[noreturn]] void badUrl(const std::string& text, const std::string& flag, const std::string& why) {
  throw Error(flag + ": " + why + " (got '" + text +
                  "'; expected freed://HOST:PORT, otio://HOST:PORT with a numeric IPv4 HOST — 0.0.0.0 for every "
                  "interface, a multicast group such as OpenTrackIO's 239.135.1.1:55555 — or a recording FILE.jsonl)",
              fieldContext(flag));
}

std::string hex(const std::vector<std::uint8_t>& b) {
  static const char* digits = "0123456789abcdef";
  std::string s(2 * b.size(), '0');
  for (size_t i = 0; i < b.size(); ++i) {
    s[2 * i] = digits[b[i] >> 4];
    s[2 * i + 1] = digits[b[i] & 15];
  }
  return s;
}

std::optional<std::vector<std::uint8_t>> unhex(const std::string& s) {
  if (s.size() % 2) return std::nullopt;
  std::vector<std::uint8_t> b(s.size() / 2);
  auto v = [](char c) -> int {
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    return -1;
  };
  for (size_t i = 0; i < b.size(); ++i) {
    const int hi = v(s[2 * i]), lo = v(s[2 * i + 1]);
    if (hi < 0 || lo < 0) return std::nullopt;
    b[i] = static_cast<std::uint8_t>(hi * 16 + lo);
  }
  return b;
}

std::optional<CameraSample> decode(StreamProtocol protocol, const std::uint8_t* d, size_t n, PacketFault* fault,
                                   std::string* why) {
  return protocol == StreamProtocol::kFreeD ? tracking::decodeFreeDCamera(d, n, fault, why)
                                            : tracking::decodeOpenTrackIoCamera(d, n, fault, why);
}

double normalised(std::uint32_t raw, const std::array<double, 2>& range) {
  return (double(raw) - range[0]) / (range[1] - range[0]);
}

Pose interpolatePose(const Pose& a, const Pose& b, double s) {
  Pose T = Pose::Identity();
  T.linear() = Eigen::Quaterniond(a.linear()).slerp(s, Eigen::Quaterniond(b.linear())).toRotationMatrix();
  T.translation() = (1 - s) * a.translation() + s * b.translation();
  return T;
}

}  // namespace

std::string protocolScheme(StreamProtocol protocol) { return protocol == StreamProtocol::kFreeD ? "freed" : "otio"; }

TrackerUrl parseTrackerUrl(const std::string& text, const std::string& flag) {
  TrackerUrl u;
  u.text = text;
  const size_t scheme_end = text.find("://");
  if (scheme_end == std::string::npos) {
    if (text.size() > 6 && text.substr(text.size() - 6) == ".jsonl") {
      u.kind = TrackerUrl::Kind::kRecording;
      u.file = text;
      if (!std::filesystem::exists(u.file)) throw Error(flag + ": no recording '" + text + "'", fileContext(text, flag));
      return u;
    }
    badUrl(text, flag, "neither a URL nor a .jsonl recording");
  }
  const std::string scheme = text.substr(0, scheme_end);
  if (scheme == "freed") u.protocol = StreamProtocol::kFreeD;
  else if (scheme == "otio" || scheme == "opentrackio") u.protocol = StreamProtocol::kOpenTrackIo;
  else badUrl(text, flag, "unknown scheme '" + scheme + "'");
  const std::string rest = text.substr(scheme_end + 3);
  const size_t colon = rest.rfind(':');
  if (colon == std::string::npos || colon == 0) badUrl(text, flag, "no HOST:PORT");
  u.host = rest.substr(0, colon);
  const std::string port = rest.substr(colon + 1);
  if (port.empty() || port.size() > 5 || port.find_first_not_of("0123456789") != std::string::npos)
    badUrl(text, flag, "the port is not a number 1..65535");
  u.port = std::stoi(port);
  if (u.port < 1 || u.port > 65535) badUrl(text, flag, "the port is not a number 1..65535");
  in_addr a{};
  if (inet_pton(AF_INET, u.host.c_str(), &a) != 1) badUrl(text, flag, "the host '" + u.host + "' is not a numeric IPv4 address");
  const std::uint32_t first = ntohl(a.s_addr) >> 24;
  u.multicast = first >= 224 && first <= 239;
  if (first >= 240 && u.host != "255.255.255.255") badUrl(text, flag, "the host is a reserved address");
  return u;
}

nlohmann::json TrackerCounts::toJson() const {
  return {{"datagrams", datagrams}, {"accepted", accepted},     {"used", used()},
          {"malformed", malformed}, {"truncated", truncated},   {"bad_checksum", bad_checksum},
          {"oversize", oversize},   {"unsupported", unsupported}, {"other_source", other_source},
          {"repeated", repeated},   {"out_of_order", out_of_order}, {"late", late},
          {"missing", missing},     {"frames_posed", frames_posed}, {"frames_without_pose", frames_without_pose}};
}

void TrackerOptions::validate() const {
  auto bad = [](const std::string& field, const std::string& what) {
    throw Error("tracker: " + field + " " + what, fieldContext(field));
  };
  if (!(delay_s > -1 && delay_s < 10)) bad("delay_s", "must be within (-1, 10) s (got " + std::to_string(delay_s) + ")");
  if (!(max_gap_s > 0 && max_gap_s < 10)) bad("max_gap_s", "must be within (0, 10) s (got " + std::to_string(max_gap_s) + ")");
  if (!(wait_s >= 0 && wait_s < 60)) bad("wait_s", "must be within [0, 60) s");
  if (!(first_wait_s >= 0 && first_wait_s < 600)) bad("first_wait_s", "must be within [0, 600) s");
  if (match != "auto" && match != "arrival" && match != "timecode") bad("match", "must be auto, arrival or timecode (got '" + match + "')");
  if (!(freed_zoom_raw[1] > freed_zoom_raw[0])) bad("freed_zoom_raw", "must be [lo, hi] with hi > lo");
  if (!(freed_focus_raw[1] > freed_focus_raw[0])) bad("freed_focus_raw", "must be [lo, hi] with hi > lo");
  if (max_samples < 4) bad("max_samples", "must be >= 4");
  for (const auto& [name, T] : {std::pair<const char*, const Pose*>{"T_world_stage", &T_world_stage}, {"T_tracker_cam", &T_tracker_cam}}) {
    const Eigen::Matrix3d R = T->linear();
    if (!T->matrix().allFinite() || (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() > 1e-6 ||
        R.determinant() < 0)
      bad(name, "is not a rigid motion");
  }
}

nlohmann::json trackerOptionsToJson(const TrackerOptions& o) {
  return {{"format", "previz-tracker"},
          {"version", 1},
          {"T_world_stage", poseToJson(o.T_world_stage)},
          {"T_tracker_cam", poseToJson(o.T_tracker_cam)},
          {"delay_s", o.delay_s},
          {"max_gap_s", o.max_gap_s},
          {"wait_s", o.wait_s},
          {"first_wait_s", o.first_wait_s},
          {"match", o.match},
          {"freed_zoom_raw", o.freed_zoom_raw},
          {"freed_focus_raw", o.freed_focus_raw},
          {"source_number", o.source_number}};
}

TrackerOptions trackerOptionsFromJson(const nlohmann::json& j, const std::string& file) {
  TrackerOptions o;
  if (!j.is_object()) throw Error("tracker config: not a JSON object", fileContext(file));
  for (const auto& [key, value] : j.items()) {
    try {
      if (key == "format") {
        if (value != "previz-tracker") throw Error("format must be \"previz-tracker\"");
      } else if (key == "version") {
        if (value != 1) throw Error("version must be 1");
      } else if (key == "T_world_stage") o.T_world_stage = poseFromJson(value, key);
      else if (key == "T_tracker_cam") o.T_tracker_cam = poseFromJson(value, key);
      else if (key == "delay_s") o.delay_s = value.get<double>();
      else if (key == "max_gap_s") o.max_gap_s = value.get<double>();
      else if (key == "wait_s") o.wait_s = value.get<double>();
      else if (key == "first_wait_s") o.first_wait_s = value.get<double>();
      else if (key == "match") o.match = value.get<std::string>();
      else if (key == "freed_zoom_raw") o.freed_zoom_raw = value.get<std::array<double, 2>>();
      else if (key == "freed_focus_raw") o.freed_focus_raw = value.get<std::array<double, 2>>();
      else if (key == "source_number") o.source_number = jsonInt(value, ErrorContext{});
      else if (key == "report" || key == "sigma") continue;  // `tracker align` writes its evidence beside
      else throw Error("unknown key");
    } catch (const Error& e) {
      throw Error(std::string("tracker config: ") + e.what(), fileContext(file, key));
    } catch (const std::exception& e) {
      throw Error(std::string("tracker config: ") + e.what(), fileContext(file, key));
    }
  }
  try {
    o.validate();
  } catch (const Error& e) {
    throw Error(e.what(), fileContext(file, e.context().field));
  }
  return o;
}

TrackerOptions readTrackerConfig(const std::filesystem::path& path) {
  return trackerOptionsFromJson(readJsonFile(path), path.string());
}

// ---- receiver ------------------------------------------------------------------------------

TrackerReceiver::TrackerReceiver(StreamProtocol protocol, const TrackerOptions& options)
    : protocol_(protocol), options_(options), zero_(Clock::now()) {}

TrackerReceiver::TrackerReceiver(const TrackerUrl& url, const TrackerOptions& options)
    : protocol_(url.protocol), options_(options), zero_(Clock::now()), buffer_(65536) {
  if (url.kind != TrackerUrl::Kind::kUdp) throw Error("tracker: a socket needs a freed:// or otio:// URL", fieldContext("--tracker"));
  fd_ = ::socket(AF_INET, SOCK_DGRAM, 0);
  if (fd_ < 0) throw Error(std::string("tracker: cannot open a UDP socket: ") + std::strerror(errno));
  const int yes = 1;
  ::setsockopt(fd_, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof(yes));
  // A burst at camera-tracker rates (240 Hz) must not overflow the default buffer (capped by
  // net.core.rmem_max).
  const int buffer = 1 << 20;
  ::setsockopt(fd_, SOL_SOCKET, SO_RCVBUF, &buffer, sizeof(buffer));
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_port = htons(static_cast<std::uint16_t>(url.port));
  inet_pton(AF_INET, url.multicast ? "0.0.0.0" : url.host.c_str(), &a.sin_addr);
  auto fail = [&](const std::string& what) {
    const std::string why = std::strerror(errno);
    ::close(fd_);
    fd_ = -1;
    throw Error("tracker: cannot " + what + " " + url.host + ":" + std::to_string(url.port) + ": " + why,
                fieldContext("--tracker"));
  };
  if (::bind(fd_, reinterpret_cast<const sockaddr*>(&a), sizeof(a)) != 0) fail("bind");
  if (url.multicast) {
    ip_mreq m{};
    inet_pton(AF_INET, url.host.c_str(), &m.imr_multiaddr);
    m.imr_interface.s_addr = htonl(INADDR_ANY);
    if (::setsockopt(fd_, IPPROTO_IP, IP_ADD_MEMBERSHIP, &m, sizeof(m)) != 0) fail("join the multicast group");
  }
  sockaddr_in bound{};
  socklen_t len = sizeof(bound);
  ::getsockname(fd_, reinterpret_cast<sockaddr*>(&bound), &len);
  port_ = ntohs(bound.sin_port);
}

TrackerReceiver::~TrackerReceiver() {
  if (fd_ >= 0) ::close(fd_);
}

double TrackerReceiver::now_s() const { return std::chrono::duration<double>(Clock::now() - zero_).count(); }

int TrackerReceiver::poll(int timeout_ms) {
  if (fd_ < 0) return 0;
  int count = 0;
  for (;;) {
    pollfd p{fd_, POLLIN, 0};
    const int ready = ::poll(&p, 1, count == 0 ? std::max(0, timeout_ms) : 0);
    if (ready <= 0 || !(p.revents & POLLIN)) break;
    // One byte more than the largest datagram either protocol allows: a longer one shows as
    // oversize rather than being cut to a valid-looking length.
    const ssize_t n = ::recv(fd_, buffer_.data(), buffer_.size(), MSG_DONTWAIT | MSG_TRUNC);
    if (n < 0) break;
    const double t = now_s();
    const size_t size = std::min(static_cast<size_t>(n), buffer_.size());
    if (keep_datagrams_) datagrams_.push_back({t, std::vector<std::uint8_t>(buffer_.begin(), buffer_.begin() + size)});
    if (static_cast<size_t>(n) > buffer_.size()) {  // longer than any UDP payload we keep
      ++counts_.datagrams;
      ++counts_.oversize;
    } else {
      feed(buffer_.data(), size, t);
    }
    ++count;
  }
  return count;
}

void TrackerReceiver::feed(const std::uint8_t* data, size_t size, double arrival_s) {
  ++counts_.datagrams;
  PacketFault fault = PacketFault::kNone;
  std::string why;
  std::optional<CameraSample> s = decode(protocol_, data, size, &fault, &why);
  if (!s) {
    switch (fault) {
      case PacketFault::kTruncated: ++counts_.truncated; break;
      case PacketFault::kBadChecksum: ++counts_.bad_checksum; break;
      case PacketFault::kOversize: ++counts_.oversize; break;
      case PacketFault::kUnsupported: ++counts_.unsupported; break;
      default: ++counts_.malformed; break;
    }
    return;
  }
  ++counts_.accepted;
  if (options_.source_number >= 0 && s->source_number != options_.source_number) {
    ++counts_.other_source;
    --counts_.accepted;
    return;
  }
  // Repeats, order and gaps. OpenTrackIO numbers its samples; FreeD does not, so a repeat is
  // the same bytes again and a gap is a silence longer than 1.5 of the stream's median period.
  const std::vector<std::uint8_t> bytes(data, data + size);
  if (s->sequence) {
    const std::uint32_t seq = *s->sequence;
    if (last_sequence_) {
      const std::int64_t d = static_cast<std::int32_t>(seq - *last_sequence_);  // wraps
      if (d == 0) {
        ++counts_.repeated;
        return;
      }
      if (d < 0) {
        ++counts_.out_of_order;
        return;
      }
      counts_.missing += d - 1;
    }
    last_sequence_ = seq;
  } else {
    // A camera at rest sends the same bytes every period: only the same bytes again within half
    // a period (the network duplicating a datagram) are a repeat.
    const double period = intervals_.size() >= 8 ? median(intervals_) : 0.004;
    if (bytes == last_bytes_ && last_arrival_ && arrival_s - *last_arrival_ < 0.5 * period) {
      ++counts_.repeated;
      return;
    }
    if (last_arrival_) {
      const double dt = arrival_s - *last_arrival_;
      if (dt < 0) {
        ++counts_.out_of_order;
        return;
      }
      if (intervals_.size() >= 8) {
        const double period = median(intervals_);
        if (period > 0 && dt > 1.5 * period) counts_.missing += std::max<long long>(1, std::llround(dt / period) - 1);
      }
      if (intervals_.size() < 64) intervals_.push_back(dt);
    }
  }
  if (s->sample_time_s) {
    if (last_sample_time_ && *s->sample_time_s < *last_sample_time_) {
      ++counts_.out_of_order;
      return;
    }
    last_sample_time_ = s->sample_time_s;
  }
  last_bytes_ = bytes;
  last_arrival_ = arrival_s;
  // FreeD's encoder words in the normalised 0..1 the lens table (and OpenTrackIO) use.
  if (s->zoom_raw) s->zoom = normalised(*s->zoom_raw, options_.freed_zoom_raw);
  if (s->focus_raw) s->focus = normalised(*s->focus_raw, options_.freed_focus_raw);
  ready_.push_back({arrival_s, std::move(*s)});
}

std::vector<TrackerSample> TrackerReceiver::take() {
  std::vector<TrackerSample> out;
  out.swap(ready_);
  return out;
}

std::vector<std::pair<double, std::vector<std::uint8_t>>> TrackerReceiver::takeDatagrams() {
  std::vector<std::pair<double, std::vector<std::uint8_t>>> out;
  out.swap(datagrams_);
  return out;
}

// ---- matcher -------------------------------------------------------------------------------

TrackerMatcher::TrackerMatcher(const TrackerOptions& options) : options_(options) {}

void TrackerMatcher::insert(std::deque<Keyed>& v, Keyed k) {
  auto it = std::upper_bound(v.begin(), v.end(), k.key, [](double key, const Keyed& x) { return key < x.key; });
  v.insert(it, std::move(k));
  while (v.size() > options_.max_samples) v.pop_front();
}

void TrackerMatcher::add(const TrackerSample& s, TrackerCounts& counts) {
  const double key = s.arrival_s - options_.delay_s;
  std::optional<double> tc_key;
  if (s.sample.timecode) {
    const tracking::SampleTimecode& c = *s.sample.timecode;
    // Samples per timecode frame: the sample rate over the timecode rate (at least 1).
    int spf = 1;
    if (s.sample.sample_rate_num > 0)
      spf = std::max(1, static_cast<int>(std::lround(double(s.sample.sample_rate_num) / s.sample.sample_rate_denom /
                                                     (double(c.rate_num) / c.rate_denom))));
    tc_key = c.seconds_of_day(spf);
  }
  // A sample for an instant already posed comes too late to be used.
  if (key <= consumed_arrival_ && (!tc_key || *tc_key <= consumed_timecode_)) {
    ++counts.late;
    return;
  }
  Keyed k{key, s.sample.T_stage_tracker, s.sample.zoom, s.sample.focus};
  insert(by_arrival_, k);
  if (tc_key) {
    k.key = *tc_key;
    insert(by_timecode_, k);
  }
}

bool TrackerMatcher::hasSampleAfter(double instant, bool by_timecode) const {
  const std::deque<Keyed>& v = by_timecode ? by_timecode_ : by_arrival_;
  return !v.empty() && v.back().key >= instant;
}

std::optional<TrackerPose> TrackerMatcher::interpolate(const std::deque<Keyed>& v, double t, double max_gap,
                                                       std::string* why) {
  auto no = [&](const std::string& text) -> std::optional<TrackerPose> {
    if (why) *why = text;
    return std::nullopt;
  };
  if (v.empty()) return no("no sample received");
  auto after = std::lower_bound(v.begin(), v.end(), t, [](const Keyed& x, double key) { return x.key < key; });
  if (after == v.end()) return no("no sample after the frame's instant (the stream stopped or is behind)");
  if (after->key == t) {
    TrackerPose p;
    p.T_stage_tracker = after->T;
    p.zoom = after->zoom;
    p.focus = after->focus;
    p.instant_s = t;
    return p;
  }
  if (after == v.begin()) return no("no sample before the frame's instant (the stream started after it)");
  const Keyed& b = *after;
  const Keyed& a = *(after - 1);
  const double gap = b.key - a.key;
  if (gap > max_gap) {
    char s[160];
    std::snprintf(s, sizeof(s), "the samples around the frame's instant are %.1f ms apart (more than max_gap_s %.1f ms)",
                  1e3 * gap, 1e3 * max_gap);
    return no(s);
  }
  const double s = gap > 0 ? (t - a.key) / gap : 0;
  TrackerPose p;
  p.T_stage_tracker = interpolatePose(a.T, b.T, s);
  if (a.zoom && b.zoom) p.zoom = (1 - s) * *a.zoom + s * *b.zoom;
  if (a.focus && b.focus) p.focus = (1 - s) * *a.focus + s * *b.focus;
  p.gap_s = gap;
  p.instant_s = t;
  return p;
}

std::optional<TrackerPose> TrackerMatcher::poseAt(double frame_arrival_s, std::optional<double> frame_tc,
                                                  std::string* why) {
  const bool tc = options_.match != "arrival" && frame_tc && !by_timecode_.empty();
  if (options_.match == "timecode" && !tc) {
    if (why) *why = frame_tc ? "no sample carries a timecode (--tracker-match timecode)" : "the take has no timecode (--tracker-match timecode)";
    return std::nullopt;
  }
  std::optional<TrackerPose> p = tc ? interpolate(by_timecode_, *frame_tc, options_.max_gap_s, why)
                                    : interpolate(by_arrival_, frame_arrival_s, options_.max_gap_s, why);
  if (tc) consumed_timecode_ = std::max(consumed_timecode_, *frame_tc);
  else consumed_arrival_ = std::max(consumed_arrival_, frame_arrival_s);
  if (p) p->by_timecode = tc;
  // Samples far behind the instant are of no further use.
  std::deque<Keyed>& v = tc ? by_timecode_ : by_arrival_;
  const double keep_from = (tc ? *frame_tc : frame_arrival_s) - 2.0;
  while (v.size() > 2 && v[1].key < keep_from) v.pop_front();
  return p;
}

// ---- recordings ----------------------------------------------------------------------------

std::string recordingText(const TrackerRecording& r, const TrackerOptions& options) {
  std::string out = nlohmann::json{{"format", "previz-tracker-recording"},
                                   {"version", 1},
                                   {"protocol", protocolScheme(r.protocol)},
                                   {"url", r.url},
                                   {"started_unix_ms", r.started_unix_ms},
                                   {"pose", "T_stage_tracker: the tracked body (OpenCV axes) in the tracker's stage frame, metres"},
                                   {"time", "arrival_s: seconds on the receiver's clock"}}
                        .dump() +
                    "\n";
  for (const RecordedDatagram& d : r.datagrams) {
    nlohmann::json j = {{"arrival_s", d.arrival_s}, {"size", d.bytes.size()}, {"bytes", hex(d.bytes)}};
    PacketFault fault = PacketFault::kNone;
    std::string why;
    std::optional<CameraSample> s = decode(r.protocol, d.bytes.data(), d.bytes.size(), &fault, &why);
    if (!s) {
      j["fault"] = tracking::toString(fault);
      j["why"] = why;
    } else {
      j["source"] = s->source_number;
      if (s->sequence) j["sequence"] = *s->sequence;
      j["T_stage_tracker"] = poseToJson(s->T_stage_tracker);
      j["pan_tilt_roll_deg"] = {s->pan_tilt_roll_deg.x(), s->pan_tilt_roll_deg.y(), s->pan_tilt_roll_deg.z()};
      j["position_m"] = {s->position_m.x(), s->position_m.y(), s->position_m.z()};
      if (s->zoom_raw) {
        j["zoom_raw"] = *s->zoom_raw;
        j["zoom"] = normalised(*s->zoom_raw, options.freed_zoom_raw);
      } else if (s->zoom) {
        j["zoom"] = *s->zoom;
      }
      if (s->focus_raw) {
        j["focus_raw"] = *s->focus_raw;
        j["focus"] = normalised(*s->focus_raw, options.freed_focus_raw);
      } else if (s->focus) {
        j["focus"] = *s->focus;
      }
      if (s->sample_time_s) j["sample_time_s"] = *s->sample_time_s;
      if (s->timecode) {
        take::Timecode tc;
        tc.hours = s->timecode->hours;
        tc.minutes = s->timecode->minutes;
        tc.seconds = s->timecode->seconds;
        tc.frames = s->timecode->frames;
        tc.drop_frame = s->timecode->drop_frame;
        j["timecode"] = take::formatTimecode(tc);
        j["sub_frame"] = s->timecode->sub_frame;
      }
    }
    out += j.dump() + "\n";
  }
  return out;
}

void writeRecording(const std::filesystem::path& path, const TrackerRecording& r, const TrackerOptions& options) {
  writeFileAtomic(path, recordingText(r, options));
}

TrackerRecording readRecording(const std::filesystem::path& path) {
  TrackerRecording r;
  std::istringstream in(readTextFile(path));
  int line_no = 0;
  bool header = false;
  double last = -1e300;
  for (std::string line; std::getline(in, line);) {
    ++line_no;
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    const ErrorContext c = fileContext(path.string(), "line " + std::to_string(line_no));
    const nlohmann::json j = nlohmann::json::parse(line, nullptr, false);
    if (j.is_discarded() || !j.is_object()) throw Error("tracker recording: not a JSON object", c);
    try {
      if (!header) {
        if (j.value("format", "") != "previz-tracker-recording")
          throw Error("the first line is not a previz-tracker-recording header");
        const std::string p = j.at("protocol").get<std::string>();
        if (p == "freed") r.protocol = StreamProtocol::kFreeD;
        else if (p == "otio") r.protocol = StreamProtocol::kOpenTrackIo;
        else throw Error("protocol must be freed or otio (got '" + p + "')");
        r.url = j.value("url", "");
        if (j.contains("started_unix_ms")) {
          // An integer that fits: 1.7e23 was undefined behaviour in get<long long>()
          // (fuzz/tracker_recording.cpp).
          const nlohmann::json& ms = j["started_unix_ms"];
          if (!ms.is_number_integer() ||
              (ms.is_number_unsigned() && ms.get<std::uint64_t>() > std::uint64_t{std::numeric_limits<long long>::max()}))
            throw Error("started_unix_ms must be an integer (milliseconds)");
          r.started_unix_ms = ms.get<long long>();
        }
        header = true;
        continue;
      }
      RecordedDatagram d;
      d.arrival_s = j.at("arrival_s").get<double>();
      const std::optional<std::vector<std::uint8_t>> b = unhex(j.at("bytes").get<std::string>());
      if (!b) throw Error("bytes is not hexadecimal");
      d.bytes = *b;
      if (!std::isfinite(d.arrival_s) || d.arrival_s < last) throw Error("arrival_s is not in increasing order");
      last = d.arrival_s;
      r.datagrams.push_back(std::move(d));
    } catch (const Error& e) {
      throw Error(std::string("tracker recording: ") + e.what(), c);
    } catch (const std::exception& e) {
      throw Error(std::string("tracker recording: ") + e.what(), c);
    }
  }
  if (!header) throw Error("tracker recording: empty file", fileContext(path.string()));
  return r;
}

int replayRecording(const TrackerRecording& r, const std::string& host, int port, double speed,
                    const std::function<bool()>& stop) {
  if (!(speed > 0)) throw Error("tracker replay: speed must be > 0", fieldContext("--speed"));
  tracking::UdpSender sender(host, port);
  if (r.datagrams.empty()) return 0;
  const Clock::time_point start = Clock::now();
  const double t0 = r.datagrams.front().arrival_s;
  for (const RecordedDatagram& d : r.datagrams) {
    if (stop && stop()) break;
    const auto due = start + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>((d.arrival_s - t0) / speed));
    std::this_thread::sleep_until(due);
    sender.send(d.bytes.data(), d.bytes.size());
  }
  return sender.sent();
}

// ---- simulation ----------------------------------------------------------------------------

void TrackerSimulation::validate() const {
  auto bad = [](const std::string& field, const std::string& what) {
    throw Error("tracker simulate: " + field + " " + what, fieldContext(field));
  };
  if (!(rate_hz > 0 && rate_hz <= 10000)) bad("rate_hz", "must be in (0, 10000]");
  if (!(end_s > start_s)) bad("end_s", "must be after start_s");
  if (!(delay_s >= 0 && jitter_s >= 0 && jitter_s < 0.5 / rate_hz + delay_s)) bad("jitter_s", "must be >= 0 and small");
  if (!(loss >= 0 && loss < 1)) bad("loss", "must be in [0, 1)");
  if ((zoom && !(*zoom >= 0 && *zoom <= 1)) || (focus && !(*focus >= 0 && *focus <= 1)))
    bad("zoom", "and focus must be in [0, 1]");
  if (!start_timecode.empty() && !take::parseTimecode(start_timecode)) bad("start_timecode", "is not HH:MM:SS:FF");
}

TrackerRecording simulateTracker(const std::function<Pose(double)>& T_world_cam_at, const TrackerSimulation& sim) {
  sim.validate();
  TrackerRecording r;
  r.protocol = sim.protocol;
  r.url = "simulated";
  std::mt19937_64 rng(sim.seed);
  std::uniform_real_distribution<double> jitter(-sim.jitter_s, sim.jitter_s), u(0, 1);
  const std::string source_id = tracking::urnUuidFromName("previz-simulated-tracker-" + std::to_string(sim.seed));
  std::optional<long long> tc0;
  if (!sim.start_timecode.empty()) tc0 = take::timecodeToFrames(*take::parseTimecode(sim.start_timecode), sim.timecode_fps);
  const Pose T_stage_world = sim.T_world_stage.inverse();
  const Pose T_cam_tracker = sim.T_tracker_cam.inverse();
  const long long n = static_cast<long long>(std::floor((sim.end_s - sim.start_s) * sim.rate_hz + 1e-9)) + 1;
  for (long long k = 0; k < n; ++k) {
    const double t = sim.start_s + k / sim.rate_hz;
    // Draw every random number for every sample (lost or not): a sample's jitter does not
    // depend on whether an earlier one was lost.
    const double arrival = t + sim.delay_s + jitter(rng);
    const bool lost = u(rng) < sim.loss;
    std::mt19937_64 id_rng(sim.seed * 1000003ull + static_cast<std::uint64_t>(k));
    if (lost) continue;
    const Pose T_stage_tracker = T_stage_world * T_world_cam_at(t) * T_cam_tracker;
    RecordedDatagram d;
    d.arrival_s = arrival;
    if (sim.protocol == StreamProtocol::kFreeD) {
      auto raw = [](std::optional<double> v) {
        return v ? static_cast<std::uint32_t>(std::llround(*v * 16777215.0)) : 0u;
      };
      const tracking::FreeDBytes b = tracking::encodeFreeDCamera(sim.source_number, T_stage_tracker, raw(sim.zoom), raw(sim.focus));
      d.bytes.assign(b.begin(), b.end());
    } else {
      tracking::OpenTrackIoCameraFields f;
      f.source_id = source_id;
      f.sample_id = tracking::urnUuidRandom(id_rng);
      f.source_number = sim.source_number;
      f.sequence = static_cast<std::uint32_t>(k);
      f.sample_time_s = std::max(0.0, t);
      f.rate_num = static_cast<int>(std::lround(sim.rate_hz * 1000));
      f.rate_denom = 1000;
      f.zoom = sim.zoom;
      f.focus = sim.focus;
      if (tc0) {
        // The timecode frame this sample falls in, and its place inside it (subFrame).
        const double frames = t * sim.timecode_fps;
        const long long whole = static_cast<long long>(std::floor(frames + 1e-9));
        const int spf = std::max(1, static_cast<int>(std::lround(sim.rate_hz / sim.timecode_fps)));
        // Timecode is a time of day: it wraps at midnight (the schema's hours are 0..23).
        const long long per_day = 86400LL * static_cast<long long>(std::max(1.0, std::round(sim.timecode_fps)));
        const take::Timecode tc = take::framesToTimecode(((*tc0 + whole) % per_day + per_day) % per_day, sim.timecode_fps);
        tracking::SampleTimecode c;
        c.hours = tc.hours;
        c.minutes = tc.minutes;
        c.seconds = tc.seconds;
        c.frames = tc.frames;
        c.rate_num = static_cast<int>(std::lround(sim.timecode_fps));
        c.rate_denom = 1;
        c.sub_frame = static_cast<int>(std::lround((frames - whole) * spf));
        if (c.sub_frame >= spf) c.sub_frame = spf - 1;
        f.timecode = c;
      }
      const tracking::OtrkEncoding enc = sim.cbor ? tracking::OtrkEncoding::kCbor : tracking::OtrkEncoding::kJson;
      d.bytes = tracking::encodeOtrk(tracking::encodeOtrkPayload(tracking::openTrackIoCameraSample(f, T_stage_tracker), enc),
                                     enc, static_cast<std::uint16_t>(k & 0xFFFF));
    }
    r.datagrams.push_back(std::move(d));
  }
  std::stable_sort(r.datagrams.begin(), r.datagrams.end(),
                   [](const RecordedDatagram& a, const RecordedDatagram& b) { return a.arrival_s < b.arrival_s; });
  return r;
}

// ---- input ---------------------------------------------------------------------------------

std::optional<double> FrameClock::timecodeOf(int frame) const {
  if (!tc0_s) return std::nullopt;
  return *tc0_s + (frame - first_frame) / std::max(1.0, std::round(fps));
}

FrameClock frameClock(const take::Take& streams, const std::string& main_camera) {
  FrameClock c;
  c.fps = streams.fps() > 0 ? streams.fps() : 24;
  if (!streams.frames().empty()) c.first_frame = streams.frames().front();
  if (!streams.has(main_camera)) return c;
  const take::CameraStream& st = streams.stream(main_camera);
  const std::optional<take::Timecode> tc = take::parseTimecode(st.start_timecode);
  if (!tc || st.source_frames.empty()) return c;
  try {
    // The start timecode is the stream's first source frame's; take frame = source - offset.
    const long long frames = take::timecodeToFrames(*tc, c.fps) + (c.first_frame + st.offset - st.source_frames.front());
    c.tc0_s = double(frames) / std::max(1.0, std::round(c.fps));
  } catch (const Error&) {
    c.tc0_s.reset();  // a label the rate does not have: match by arrival
  }
  return c;
}

TrackerInput::TrackerInput(const TrackerUrl& url, const TrackerOptions& options, const Camera& plate,
                           std::optional<calib::LensTable> lens)
    : url_(url), options_(options), plate_(plate), lens_(std::move(lens)), matcher_(options) {
  options_.validate();
  if (url.kind == TrackerUrl::Kind::kRecording) {
    recording_ = readRecording(url.file);
    receiver_ = std::make_unique<TrackerReceiver>(recording_.protocol, options_);
    frame_zero_s_ = 0;  // a recording's clock is the take's: frame f at f / fps
  } else {
    receiver_ = std::make_unique<TrackerReceiver>(url, options_);
  }
}

TrackerInput::~TrackerInput() = default;

void TrackerInput::pump(double until_arrival_s, bool by_timecode, double instant_key) {
  if (url_.kind == TrackerUrl::Kind::kRecording) {
    // Deliver what had arrived by then, and keep going until the sample after the instant is
    // in (a live loop would have waited for it), at most wait_s past the instant.
    while (next_datagram_ < recording_.datagrams.size()) {
      const RecordedDatagram& d = recording_.datagrams[next_datagram_];
      if (d.arrival_s > until_arrival_s && matcher_.hasSampleAfter(instant_key, by_timecode)) break;
      if (d.arrival_s > until_arrival_s + options_.wait_s) break;
      receiver_->feed(d.bytes.data(), d.bytes.size(), d.arrival_s);
      ++next_datagram_;
      for (const TrackerSample& s : receiver_->take()) matcher_.add(s, receiver_->counts());
    }
    return;
  }
  // A socket: poll until the sample after the instant is in, or the wait is over.
  const double deadline = (first_arrival_s_ ? until_arrival_s + options_.wait_s : receiver_->now_s() + options_.first_wait_s);
  for (;;) {
    receiver_->poll(first_arrival_s_ && matcher_.hasSampleAfter(instant_key, by_timecode) ? 0 : 2);
    for (const TrackerSample& s : receiver_->take()) {
      if (!first_arrival_s_) {
        first_arrival_s_ = s.arrival_s;
        // The first sample is taken to be frame 0's: frame instants count from its instant.
        frame_zero_s_ = s.arrival_s - options_.delay_s;
      }
      matcher_.add(s, receiver_->counts());
    }
    if (first_arrival_s_ && matcher_.hasSampleAfter(instant_key, by_timecode)) return;
    if (receiver_->now_s() >= deadline) return;
  }
}

RigCamera TrackerInput::mainAt(int frame, double frame_time_s, std::optional<double> frame_tc, const RigCamera& rig_main) {
  const bool use_tc = options_.match != "arrival" && frame_tc.has_value() &&
                      (options_.match == "timecode" || receiver_->protocol() == StreamProtocol::kOpenTrackIo);
  // The instant on the arrival clock: sample instants are arrival - delay.
  auto instant = [&] { return frame_zero_s_ + frame_time_s; };
  pump(instant() + options_.delay_s, use_tc, use_tc ? *frame_tc : instant());
  std::string why;
  std::optional<TrackerPose> p = matcher_.poseAt(instant(), use_tc ? frame_tc : std::nullopt, &why);
  for (const TrackerSample& s : receiver_->take()) matcher_.add(s, receiver_->counts());
  ErrorContext c;
  c.camera = rig_main.camera.name;
  c.frame = frame;
  c.field = "--tracker";
  if (!p) {
    ++receiver_->counts().frames_without_pose;
    throw Error("no tracker pose: " + why, c);
  }
  RigCamera rc = rig_main;
  rc.T_world_cam = options_.T_world_stage * p->T_stage_tracker * options_.T_tracker_cam;
  if (lens_) {
    if (!p->zoom || !p->focus) {
      ++receiver_->counts().frames_without_pose;
      throw Error("no tracker lens state: the samples carry no zoom/focus encoders but a lens table was given", c);
    }
    // One camera per encoder state (to 1e-6), so the loop's CG distortion map is rebuilt only
    // when the lens really moves.
    const std::pair<long long, long long> key{std::llround(*p->focus * 1e6), std::llround(*p->zoom * 1e6)};
    auto it = lens_cache_.find(key);
    if (it == lens_cache_.end()) {
      Camera cam = lens_->at(key.first * 1e-6, key.second * 1e-6).camera;
      if (cam.width != plate_.width || cam.height != plate_.height)
        cam = cam.scaled(double(plate_.width) / cam.width, double(plate_.height) / cam.height);
      cam.width = plate_.width;
      cam.height = plate_.height;
      cam.name = rig_main.camera.name;
      if (lens_cache_.size() > 256) lens_cache_.clear();
      it = lens_cache_.emplace(key, cam).first;
    }
    rc.camera = it->second;
  }
  ++receiver_->counts().frames_posed;
  gaps_s_.push_back(p->gap_s);
  return rc;
}

nlohmann::json TrackerInput::summary() const {
  nlohmann::json j = {{"url", url_.text},
                      {"protocol", protocolScheme(receiver_->protocol())},
                      {"counts", receiver_->counts().toJson()},
                      {"delay_s", options_.delay_s},
                      {"match", options_.match},
                      {"frame_zero_s", frame_zero_s_}};
  if (!gaps_s_.empty()) j["median_bracket_ms"] = 1e3 * median(gaps_s_);
  return j;
}

}  // namespace previz::live
