// OpenTrackIO transport and camera samples from FreeD D1 / OpenTrackIO (see opentrackio.h).
#include "tracking/opentrackio.h"

#include <cmath>
#include <cstdio>
#include <sstream>

#include <Eigen/Geometry>

#include "core/error.h"
#include "core/io.h"
#include "core/units.h"

namespace previz::tracking {

namespace {

constexpr std::uint8_t kId[4] = {'O', 'T', 'r', 'k'};

void put16(std::uint8_t* p, std::uint32_t v) {
  p[0] = static_cast<std::uint8_t>(v >> 8);
  p[1] = static_cast<std::uint8_t>(v);
}
void put32(std::uint8_t* p, std::uint32_t v) {
  p[0] = static_cast<std::uint8_t>(v >> 24);
  p[1] = static_cast<std::uint8_t>(v >> 16);
  p[2] = static_cast<std::uint8_t>(v >> 8);
  p[3] = static_cast<std::uint8_t>(v);
}
std::uint32_t get16(const std::uint8_t* p) { return (std::uint32_t(p[0]) << 8) | p[1]; }
std::uint32_t get32(const std::uint8_t* p) {
  return (std::uint32_t(p[0]) << 24) | (std::uint32_t(p[1]) << 16) | (std::uint32_t(p[2]) << 8) | p[3];
}

template <class T>
std::optional<T> fail(PacketFault f, const std::string& text, PacketFault* fault, std::string* why) {
  if (fault) *fault = f;
  if (why) *why = text;
  return std::nullopt;
}

// OpenCV body axes (x right, y down, z forward) -> OpenTrackIO camera axes (x right, y forward,
// z up): p_ot = M p_cv.
Eigen::Matrix3d cvToOt() {
  Eigen::Matrix3d M;
  M << 1, 0, 0, 0, 0, 1, 0, -1, 0;
  return M;
}

Eigen::Matrix3d zxy(const Eigen::Vector3d& ptr_deg) {
  const Eigen::Vector3d r(radians(ptr_deg[0]), radians(ptr_deg[1]), radians(ptr_deg[2]));
  return (Eigen::AngleAxisd(r[0], Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(r[1], Eigen::Vector3d::UnitX()) *
          Eigen::AngleAxisd(r[2], Eigen::Vector3d::UnitY()))
      .toRotationMatrix();
}

std::uint64_t fnv1a(const std::string& s) {
  std::uint64_t h = 1469598103934665603ull;
  for (unsigned char c : s) {
    h ^= c;
    h *= 1099511628211ull;
  }
  return h;
}

std::string formatUuid(std::uint64_t hi, std::uint64_t lo) {
  hi = (hi & ~0xF000ull) | 0x4000ull;                              // version 4
  lo = (lo & ~(0xC000000000000000ull)) | 0x8000000000000000ull;  // variant 10xx
  char s[64];
  std::snprintf(s, sizeof(s), "urn:uuid:%08x-%04x-%04x-%04x-%012llx", unsigned(hi >> 32), unsigned((hi >> 16) & 0xFFFF),
                unsigned(hi & 0xFFFF), unsigned(lo >> 48), static_cast<unsigned long long>(lo & 0xFFFFFFFFFFFFull));
  return s;
}

bool isNumber(const nlohmann::json& j, const char* key) { return j.contains(key) && j[key].is_number(); }

}  // namespace

const char* toString(PacketFault fault) {
  switch (fault) {
    case PacketFault::kNone: return "none";
    case PacketFault::kMalformed: return "malformed";
    case PacketFault::kTruncated: return "truncated";
    case PacketFault::kBadChecksum: return "bad_checksum";
    case PacketFault::kOversize: return "oversize";
    case PacketFault::kUnsupported: return "unsupported";
  }
  return "?";
}

std::uint16_t fletcher16(const std::uint8_t* a, size_t a_size, const std::uint8_t* b, size_t b_size) {
  unsigned sum1 = 0, sum2 = 0;
  for (size_t i = 0; i < a_size; ++i) {
    sum1 = (sum1 + a[i]) & 0xFF;
    sum2 = (sum2 + sum1) & 0xFF;
  }
  for (size_t i = 0; i < b_size; ++i) {
    sum1 = (sum1 + b[i]) & 0xFF;
    sum2 = (sum2 + sum1) & 0xFF;
  }
  return static_cast<std::uint16_t>((sum2 << 8) | sum1);
}

std::vector<std::uint8_t> encodeOtrkPayload(const nlohmann::json& sample, OtrkEncoding encoding) {
  if (encoding == OtrkEncoding::kCbor) return nlohmann::json::to_cbor(sample);
  const std::string s = sample.dump();
  return std::vector<std::uint8_t>(s.begin(), s.end());
}

std::vector<std::uint8_t> encodeOtrk(const std::vector<std::uint8_t>& payload, OtrkEncoding encoding,
                                     std::uint16_t sequence) {
  if (payload.size() > static_cast<size_t>(kOtrkMaxPayload))
    throw Error("OpenTrackIO: a sample of " + std::to_string(payload.size()) + " bytes exceeds one datagram's " +
                    std::to_string(kOtrkMaxPayload) + " (previz sends no segmented samples)",
                fieldContext("payload"));
  std::vector<std::uint8_t> d(kOtrkHeaderSize + payload.size());
  std::copy(kId, kId + 4, d.begin());
  d[4] = 0;
  d[5] = static_cast<std::uint8_t>(encoding);
  put16(&d[6], sequence);
  put32(&d[8], 0);  // one segment: offset 0 ...
  put16(&d[12], 0x8000u | static_cast<std::uint32_t>(payload.size()));  // ... and the last one
  std::copy(payload.begin(), payload.end(), d.begin() + kOtrkHeaderSize);
  put16(&d[14], fletcher16(d.data(), 14, payload.data(), payload.size()));
  return d;
}

double SampleTimecode::seconds_of_day(int subframes_per_frame) const {
  const double rate = double(rate_num) / std::max(1, rate_denom);
  const double nominal = std::max(1.0, std::round(rate));
  const double frames_of_day = ((hours * 60.0 + minutes) * 60.0 + seconds) * nominal + frames +
                               double(sub_frame) / std::max(1, subframes_per_frame);
  return frames_of_day / nominal;
}

Eigen::Matrix3d rotationFromZxyDeg(const Eigen::Vector3d& ptr_deg) { return zxy(ptr_deg); }

Eigen::Matrix3d trackerRotationFromZxy(const Eigen::Vector3d& ptr_deg) { return zxy(ptr_deg) * cvToOt(); }

Eigen::Vector3d zxyFromTrackerRotation(const Eigen::Matrix3d& R_stage_tracker) {
  return zxyDegFromRotation(R_stage_tracker * cvToOt().transpose());
}

Eigen::Vector3d zxyDegFromRotation(const Eigen::Matrix3d& R) {
  // R = Rz(p) Rx(t) Ry(r): R(2,1) = sin t, R(0,1) = -sin p cos t, R(1,1) = cos p cos t,
  // R(2,0) = -cos t sin r, R(2,2) = cos t cos r.
  const double tilt = std::asin(std::clamp(R(2, 1), -1.0, 1.0));
  double pan, roll;
  if (std::abs(R(2, 1)) < 1 - 1e-12) {
    pan = std::atan2(-R(0, 1), R(1, 1));
    roll = std::atan2(-R(2, 0), R(2, 2));
  } else {  // looking straight up or down: the roll goes into the pan
    pan = std::atan2(R(1, 0), R(0, 0));
    roll = 0;
  }
  return Eigen::Vector3d(degrees(pan), degrees(tilt), degrees(roll));
}

std::optional<CameraSample> decodeFreeDCamera(const std::uint8_t* data, size_t size, PacketFault* fault,
                                              std::string* why) {
  if (fault) *fault = PacketFault::kNone;
  if (size == 0 || data[0] != 0xD1)
    return fail<CameraSample>(PacketFault::kMalformed, "freed: not a D1 message", fault, why);
  if (size < static_cast<size_t>(kFreeDPacketSize))
    return fail<CameraSample>(PacketFault::kTruncated, "freed: " + std::to_string(size) + " bytes, D1 is 29", fault, why);
  if (size > static_cast<size_t>(kFreeDPacketSize))
    return fail<CameraSample>(PacketFault::kOversize, "freed: " + std::to_string(size) + " bytes, D1 is 29", fault, why);
  std::string reason;
  const std::optional<FreeDPacket> p = decodeFreeD(data, size, &reason);
  if (!p) return fail<CameraSample>(PacketFault::kBadChecksum, reason, fault, why);  // length and type passed
  CameraSample s;
  s.protocol = StreamProtocol::kFreeD;
  s.source_number = p->camera_id;
  s.pan_tilt_roll_deg = Eigen::Vector3d(p->pan, p->tilt, p->roll) / 32768.0;
  s.position_m = Eigen::Vector3d(p->x, p->y, p->z) / 64.0 / 1000.0;
  s.T_stage_tracker.linear() = trackerRotationFromZxy(s.pan_tilt_roll_deg);
  s.T_stage_tracker.translation() = s.position_m;
  s.zoom_raw = p->zoom;
  s.focus_raw = p->focus;
  return s;
}

std::optional<CameraSample> cameraSampleFromOpenTrackIo(const nlohmann::json& j, std::string* why) {
  auto bad = [&](const std::string& text) -> std::optional<CameraSample> {
    if (why) *why = "opentrackio: " + text;
    return std::nullopt;
  };
  if (!j.is_object()) return bad("the payload is not a JSON object");
  const auto protocol = j.find("protocol");
  if (protocol == j.end() || !protocol->is_object() || !protocol->contains("name") || !(*protocol)["name"].is_string() ||
      (*protocol)["name"].get<std::string>() != "OpenTrackIO")
    return bad("protocol.name is not \"OpenTrackIO\"");
  const auto transforms = j.find("transforms");
  if (transforms == j.end() || !transforms->is_array() || transforms->empty())
    return bad("no transforms (a sample without a camera pose)");
  CameraSample s;
  s.protocol = StreamProtocol::kOpenTrackIo;
  // The transforms compose in order, first to last (schema "transforms"); each maps its child
  // frame into its parent with R = Rz(pan) Rx(tilt) Ry(roll) in OpenTrackIO's camera axes.
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  for (const nlohmann::json& tr : *transforms) {
    if (!tr.is_object()) return bad("a transform is not an object");
    Eigen::Vector3d ti = Eigen::Vector3d::Zero(), ptr = Eigen::Vector3d::Zero();
    if (tr.contains("translation")) {
      const nlohmann::json& x = tr["translation"];
      if (!x.is_object()) return bad("transforms[].translation is not an object");
      const char* keys[3] = {"x", "y", "z"};
      for (int k = 0; k < 3; ++k) {
        if (!x.contains(keys[k])) continue;
        if (!isNumber(x, keys[k])) return bad(std::string("transforms[].translation.") + keys[k] + " is not a number");
        ti[k] = x[keys[k]].get<double>();
      }
    }
    if (tr.contains("rotation")) {
      const nlohmann::json& x = tr["rotation"];
      if (!x.is_object()) return bad("transforms[].rotation is not an object");
      const char* keys[3] = {"pan", "tilt", "roll"};
      for (int k = 0; k < 3; ++k) {
        if (!x.contains(keys[k])) continue;
        if (!isNumber(x, keys[k])) return bad(std::string("transforms[].rotation.") + keys[k] + " is not a number");
        ptr[k] = x[keys[k]].get<double>();
      }
    }
    if (!ti.allFinite() || !ptr.allFinite()) return bad("a transform is not finite");
    t = t + R * ti;
    R = R * zxy(ptr);
  }
  s.position_m = t;
  s.T_stage_tracker.linear() = R * cvToOt();
  s.T_stage_tracker.translation() = t;
  s.pan_tilt_roll_deg = zxyFromTrackerRotation(s.T_stage_tracker.linear());
  if (j.contains("sourceNumber"))
    if (const std::optional<int> n = jsonInt(j["sourceNumber"])) s.source_number = *n;
  if (j.contains("sourceId") && j["sourceId"].is_string()) s.source_id = j["sourceId"].get<std::string>();
  if (j.contains("lens") && j["lens"].is_object() && j["lens"].contains("encoders") && j["lens"]["encoders"].is_object()) {
    const nlohmann::json& e = j["lens"]["encoders"];
    if (isNumber(e, "zoom")) s.zoom = e["zoom"].get<double>();
    if (isNumber(e, "focus")) s.focus = e["focus"].get<double>();
    if ((s.zoom && !(*s.zoom >= 0 && *s.zoom <= 1)) || (s.focus && !(*s.focus >= 0 && *s.focus <= 1)))
      return bad("lens.encoders outside 0..1");
  }
  if (j.contains("timing") && j["timing"].is_object()) {
    const nlohmann::json& tm = j["timing"];
    if (tm.contains("sequenceNumber") && tm["sequenceNumber"].is_number_unsigned())
      s.sequence = tm["sequenceNumber"].get<std::uint32_t>();
    if (tm.contains("sampleTimestamp") && tm["sampleTimestamp"].is_object()) {
      const nlohmann::json& ts = tm["sampleTimestamp"];
      if (ts.contains("seconds") && ts["seconds"].is_number_integer() && ts.contains("nanoseconds") &&
          ts["nanoseconds"].is_number_integer())
        s.sample_time_s = double(ts["seconds"].get<long long>()) + 1e-9 * double(ts["nanoseconds"].get<long long>());
    }
    if (tm.contains("sampleRate") && tm["sampleRate"].is_object() && isNumber(tm["sampleRate"], "num") &&
        isNumber(tm["sampleRate"], "denom")) {
      // Checked: a num of 1e300 was undefined behaviour in get<int>() (fuzz/opentrackio.cpp).
      const std::optional<int> num = jsonInt(tm["sampleRate"]["num"]), denom = jsonInt(tm["sampleRate"]["denom"]);
      if (!num || !denom) return bad("timing.sampleRate num and denom must be integers");
      s.sample_rate_num = *num;
      s.sample_rate_denom = std::max(1, *denom);
    }
    if (tm.contains("timecode") && tm["timecode"].is_object()) {
      const nlohmann::json& tc = tm["timecode"];
      SampleTimecode c;
      // Every field checked to be an integer that fits: "hours": 1e10 was undefined behaviour in
      // get<int>() (fuzz/opentrackio.cpp).
      const auto field = [&](const nlohmann::json& o, const char* key, int& out) {
        if (!o.is_object() || !o.contains(key)) return false;
        const std::optional<int> v = jsonInt(o[key]);
        if (v) out = *v;
        return v.has_value();
      };
      const nlohmann::json no_rate;
      const nlohmann::json& rate = tc.contains("frameRate") ? tc["frameRate"] : no_rate;
      if (!field(tc, "hours", c.hours) || !field(tc, "minutes", c.minutes) || !field(tc, "seconds", c.seconds) ||
          !field(tc, "frames", c.frames) || !field(rate, "num", c.rate_num) || !field(rate, "denom", c.rate_denom))
        return bad("timing.timecode lacks hours, minutes, seconds, frames or frameRate (integers)");
      if (tc.contains("subFrame") && !field(tc, "subFrame", c.sub_frame)) return bad("timing.timecode.subFrame is not an integer");
      if (tc.contains("dropFrame")) {
        if (!tc["dropFrame"].is_boolean()) return bad("timing.timecode.dropFrame is not a boolean");
        c.drop_frame = tc["dropFrame"].get<bool>();
      }
      if (c.rate_num <= 0 || c.rate_denom <= 0 || c.hours < 0 || c.minutes < 0 || c.seconds < 0 || c.frames < 0 ||
          c.sub_frame < 0)
        return bad("timing.timecode out of range");
      s.timecode = c;
    }
  }
  return s;
}

std::optional<CameraSample> decodeOpenTrackIoCamera(const std::uint8_t* d, size_t size, PacketFault* fault,
                                                    std::string* why) {
  if (fault) *fault = PacketFault::kNone;
  if (size > static_cast<size_t>(kOtrkMaxDatagram))
    return fail<CameraSample>(PacketFault::kOversize,
                              "opentrackio: " + std::to_string(size) + " bytes, more than a datagram's 1500", fault, why);
  if (size < 4 || !std::equal(kId, kId + 4, d))
    return fail<CameraSample>(PacketFault::kMalformed, "opentrackio: no \"OTrk\" header", fault, why);
  if (size < static_cast<size_t>(kOtrkHeaderSize))
    return fail<CameraSample>(PacketFault::kTruncated, "opentrackio: shorter than the 16-byte header", fault, why);
  const std::uint32_t length_field = get16(d + 12);
  const size_t payload = length_field & 0x7FFF;
  const bool last = (length_field & 0x8000) != 0;
  if (kOtrkHeaderSize + payload > size)
    return fail<CameraSample>(PacketFault::kTruncated,
                              "opentrackio: the header announces " + std::to_string(payload) + " payload bytes, " +
                                  std::to_string(size - kOtrkHeaderSize) + " came",
                              fault, why);
  if (kOtrkHeaderSize + payload < size)
    return fail<CameraSample>(PacketFault::kMalformed, "opentrackio: bytes after the announced payload", fault, why);
  if (fletcher16(d, 14, d + kOtrkHeaderSize, payload) != get16(d + 14))
    return fail<CameraSample>(PacketFault::kBadChecksum, "opentrackio: bad checksum", fault, why);
  if (!last || get32(d + 8) != 0)
    return fail<CameraSample>(PacketFault::kUnsupported, "opentrackio: a segmented sample (not reassembled)", fault, why);
  nlohmann::json j;
  const std::uint8_t* p = d + kOtrkHeaderSize;
  // nlohmann's readers still throw on some inputs with exceptions off (a CBOR length of 2^63:
  // "excessive object size", found by tests/live/tracker_test.cpp's fuzzing): caught here.
  if (d[5] == static_cast<std::uint8_t>(OtrkEncoding::kJson)) {
    try {
      j = nlohmann::json::parse(p, p + payload, nullptr, false);
    } catch (const std::exception&) {
      j = nlohmann::json(nlohmann::json::value_t::discarded);
    }
  } else if (d[5] == static_cast<std::uint8_t>(OtrkEncoding::kCbor)) {
    try {
      j = nlohmann::json::from_cbor(p, p + payload, true, false);
    } catch (const std::exception&) {
      j = nlohmann::json(nlohmann::json::value_t::discarded);
    }
  } else {
    return fail<CameraSample>(PacketFault::kUnsupported, "opentrackio: encoding " + std::to_string(d[5]) + " is not JSON or CBOR",
                              fault, why);
  }
  if (j.is_discarded())
    return fail<CameraSample>(PacketFault::kMalformed,
                              std::string("opentrackio: the payload is not valid ") + (d[5] == 1 ? "JSON" : "CBOR"), fault, why);
  std::string reason;
  std::optional<CameraSample> s;
  try {
    s = cameraSampleFromOpenTrackIo(j, &reason);
  } catch (const std::exception& e) {  // a type nlohmann refuses deep inside: still a bad packet
    reason = std::string("opentrackio: ") + e.what();
  }
  if (!s) return fail<CameraSample>(PacketFault::kMalformed, reason, fault, why);
  if (!s->sequence) s->sequence = get16(d + 6);
  return s;
}

FreeDBytes encodeFreeDCamera(int camera_id, const Pose& T_stage_tracker, std::uint32_t zoom_raw, std::uint32_t focus_raw) {
  FreeDPacket p = freeDFromPose(camera_id, Pose::Identity());  // checks the id
  const Eigen::Vector3d a = zxyFromTrackerRotation(T_stage_tracker.linear());
  const Eigen::Vector3d mm = 1000.0 * T_stage_tracker.translation();
  auto q = [](double v, double scale, const char* field) {
    const double r = std::round(v * scale);
    if (!(r >= -(1 << 23) && r <= (1 << 23) - 1))
      throw Error(std::string("FreeD: ") + field + " does not fit the packet's 24 bits", fieldContext(field));
    return static_cast<std::int32_t>(r);
  };
  p.pan = q(a[0], 32768.0, "pan");
  p.tilt = q(a[1], 32768.0, "tilt");
  p.roll = q(a[2], 32768.0, "roll");
  p.x = q(mm.x(), 64.0, "x");
  p.y = q(mm.y(), 64.0, "y");
  p.z = q(mm.z(), 64.0, "z");
  p.zoom = zoom_raw;
  p.focus = focus_raw;
  return encodeFreeD(p);
}

std::string urnUuidFromName(const std::string& name) {
  return formatUuid(fnv1a(name), fnv1a(std::string(name.rbegin(), name.rend()) + "#previz"));
}

std::string urnUuidRandom(std::mt19937_64& rng) {
  const std::uint64_t hi = rng(), lo = rng();
  return formatUuid(hi, lo);
}

nlohmann::json openTrackIoCameraSample(const OpenTrackIoCameraFields& f, const Pose& T_stage_tracker) {
  const Eigen::Vector3d a = zxyFromTrackerRotation(T_stage_tracker.linear());
  const Eigen::Vector3d t = T_stage_tracker.translation();
  const double secs = std::floor(std::max(0.0, f.sample_time_s));
  long long ns = std::llround((std::max(0.0, f.sample_time_s) - secs) * 1e9);
  long long s = static_cast<long long>(secs);
  if (ns >= 1000000000LL) {
    ns -= 1000000000LL;
    ++s;
  }
  nlohmann::json timing = {{"mode", "internal"},
                           {"sampleRate", {{"num", f.rate_num}, {"denom", f.rate_denom}}},
                           {"sampleTimestamp", {{"seconds", s}, {"nanoseconds", ns}}},
                           {"sequenceNumber", f.sequence}};
  if (f.timecode) {
    const SampleTimecode& c = *f.timecode;
    timing["timecode"] = {{"hours", c.hours},     {"minutes", c.minutes}, {"seconds", c.seconds},
                          {"frames", c.frames},   {"frameRate", {{"num", c.rate_num}, {"denom", c.rate_denom}}},
                          {"subFrame", c.sub_frame}, {"dropFrame", c.drop_frame}};
  }
  nlohmann::json j = {{"protocol", {{"name", "OpenTrackIO"}, {"version", {1, 0, 1}}}},
                      {"sampleId", f.sample_id},
                      {"sourceId", f.source_id},
                      {"sourceNumber", f.source_number},
                      {"timing", timing},
                      {"tracker", {{"status", f.status}}},
                      {"transforms",
                       {{{"id", "Camera"},
                         {"translation", {{"x", t.x()}, {"y", t.y()}, {"z", t.z()}}},
                         {"rotation", {{"pan", a[0]}, {"tilt", a[1]}, {"roll", a[2]}}}}}}};
  if (f.zoom || f.focus) {
    nlohmann::json e = nlohmann::json::object();
    if (f.focus) e["focus"] = *f.focus;
    if (f.zoom) e["zoom"] = *f.zoom;
    j["lens"] = {{"encoders", e}};
  }
  return j;
}

}  // namespace previz::tracking
