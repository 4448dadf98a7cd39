// Issue 32: the camera tracker's packets. OpenTrackIO's 16-byte header and Fletcher-16 as the
// SMPTE reference computes them, camera samples (JSON and CBOR) and FreeD D1 camera packets
// round-tripping to the pose within the wire's precision, the ZXY angle convention, and
// decoders that say why a packet is refused instead of throwing.
#include <gtest/gtest.h>

#include <random>

#include "core/error.h"
#include "tracking/opentrackio.h"

namespace previz::tracking {
namespace {

Pose somePose(std::mt19937& rng) {
  std::uniform_real_distribution<double> u(-1, 1);
  Pose T = Pose::Identity();
  T.linear() = (Eigen::AngleAxisd(M_PI * u(rng), Eigen::Vector3d::UnitZ()) *
                Eigen::AngleAxisd(0.45 * M_PI * u(rng), Eigen::Vector3d::UnitX()) *
                Eigen::AngleAxisd(M_PI * u(rng), Eigen::Vector3d::UnitY()))
                   .toRotationMatrix();
  T.translation() = Eigen::Vector3d(5 * u(rng), 5 * u(rng), 1.5 + u(rng));
  return T;
}

// The values below were printed by the reference opentrackio_lib.fletcher16 (sums mod 256, not
// the textbook's mod 255): with a stand-in cbor2 module in sys.modules,
//   L.fletcher16(b'abcde'), L.fletcher16(b'abcdef'), L.fletcher16(bytes((i*7+3)&255 for i in range(1000)))
// -> c3ef 1855 58ec.
TEST(OpenTrackIo, Fletcher16MatchesTheSmpteReference) {
  const std::string abcde = "abcde";
  EXPECT_EQ(fletcher16(reinterpret_cast<const std::uint8_t*>(abcde.data()), abcde.size()), 0xC3EF);
  const std::string abcdef = "abcdef";
  EXPECT_EQ(fletcher16(reinterpret_cast<const std::uint8_t*>(abcdef.data()), abcdef.size()), 0x1855);
  std::vector<std::uint8_t> ramp(1000);
  for (size_t i = 0; i < ramp.size(); ++i) ramp[i] = static_cast<std::uint8_t>(i * 7 + 3);
  EXPECT_EQ(fletcher16(ramp.data(), ramp.size()), 0x58EC);
  // Split anywhere: the same sums.
  EXPECT_EQ(fletcher16(ramp.data(), 14, ramp.data() + 14, ramp.size() - 14), fletcher16(ramp.data(), ramp.size()));
}

TEST(OpenTrackIo, HeaderLayoutIsTheSpecsBigEndianSixteenBytes) {
  const std::vector<std::uint8_t> payload = {'{', '}'};
  const std::vector<std::uint8_t> d = encodeOtrk(payload, OtrkEncoding::kCbor, 0x1234);
  ASSERT_EQ(d.size(), 18u);
  EXPECT_EQ(std::string(d.begin(), d.begin() + 4), "OTrk");
  EXPECT_EQ(d[4], 0);
  EXPECT_EQ(d[5], 0x02);
  EXPECT_EQ(d[6], 0x12);
  EXPECT_EQ(d[7], 0x34);
  for (int i = 8; i < 12; ++i) EXPECT_EQ(d[i], 0) << "segment offset byte " << i;
  EXPECT_EQ(d[12], 0x80);  // last segment, length 2
  EXPECT_EQ(d[13], 0x02);
  EXPECT_EQ((d[14] << 8) | d[15], fletcher16(d.data(), 14, payload.data(), payload.size()));
  EXPECT_THROW(encodeOtrk(std::vector<std::uint8_t>(kOtrkMaxPayload + 1, 'x'), OtrkEncoding::kJson, 0), Error);
}

TEST(OpenTrackIo, ZxyAnglesRoundTripAndMeanWhatTheSchemaSays) {
  // pan = tilt = roll = 0: the camera looks along stage +y, x to its right, z up; in OpenCV axes
  // (x right, y down, z forward) that is R_stage_tracker = [x | -z | y].
  const Eigen::Matrix3d R0 = trackerRotationFromZxy(Eigen::Vector3d::Zero());
  EXPECT_LT((R0.col(0) - Eigen::Vector3d::UnitX()).norm(), 1e-15);
  EXPECT_LT((R0.col(1) + Eigen::Vector3d::UnitZ()).norm(), 1e-15);
  EXPECT_LT((R0.col(2) - Eigen::Vector3d::UnitY()).norm(), 1e-15);
  // Pan 90 degrees turns it to look along -x (right-handed about z up); tilt 30 looks up.
  const Eigen::Matrix3d Rp = trackerRotationFromZxy(Eigen::Vector3d(90, 0, 0));
  EXPECT_LT((Rp.col(2) + Eigen::Vector3d::UnitX()).norm(), 1e-12);
  const Eigen::Matrix3d Rt = trackerRotationFromZxy(Eigen::Vector3d(0, 30, 0));
  EXPECT_NEAR(Rt.col(2).z(), 0.5, 1e-12);
  std::mt19937 rng(3);
  for (int i = 0; i < 1000; ++i) {
    const Pose T = somePose(rng);
    const Eigen::Vector3d a = zxyFromTrackerRotation(T.linear());
    EXPECT_LT((trackerRotationFromZxy(a) - T.linear()).cwiseAbs().maxCoeff(), 1e-12);
    EXPECT_LE(std::abs(a[1]), 90.0);
  }
}

TEST(OpenTrackIo, CameraSamplesRoundTripInJsonAndCbor) {
  std::mt19937 rng(4);
  std::mt19937_64 ids(5);
  for (OtrkEncoding enc : {OtrkEncoding::kJson, OtrkEncoding::kCbor}) {
    for (int i = 0; i < 200; ++i) {
      const Pose T = somePose(rng);
      OpenTrackIoCameraFields f;
      f.source_id = urnUuidFromName("stage A");
      f.sample_id = urnUuidRandom(ids);
      f.sequence = 1000 + i;
      f.sample_time_s = 1700000000.0 + i / 240.0;
      f.rate_num = 240;
      f.zoom = 0.25;
      f.focus = 0.75;
      SampleTimecode tc;
      tc.hours = 1;
      tc.frames = 5;
      tc.sub_frame = 3;
      f.timecode = tc;
      const std::vector<std::uint8_t> d =
          encodeOtrk(encodeOtrkPayload(openTrackIoCameraSample(f, T), enc), enc, static_cast<std::uint16_t>(i));
      PacketFault fault;
      std::string why;
      const std::optional<CameraSample> s = decodeOpenTrackIoCamera(d.data(), d.size(), &fault, &why);
      ASSERT_TRUE(s) << why;
      EXPECT_EQ(fault, PacketFault::kNone);
      EXPECT_LT(translationDistance(s->T_stage_tracker, T), 1e-12);
      EXPECT_LT(rotationDistance(s->T_stage_tracker, T), 1e-9);
      EXPECT_EQ(*s->sequence, 1000u + i);
      EXPECT_NEAR(*s->sample_time_s, f.sample_time_s, 1e-6);
      EXPECT_EQ(*s->zoom, 0.25);
      EXPECT_EQ(*s->focus, 0.75);
      ASSERT_TRUE(s->timecode);
      EXPECT_EQ(s->timecode->sub_frame, 3);
      EXPECT_EQ(s->source_id, f.source_id);
    }
  }
}

TEST(OpenTrackIo, UrnUuidsHaveTheSchemasForm) {
  std::mt19937_64 ids(1);
  for (const std::string& u : {urnUuidFromName("a"), urnUuidFromName("previz:take"), urnUuidRandom(ids)}) {
    ASSERT_EQ(u.size(), 45u) << u;
    EXPECT_EQ(u.rfind("urn:uuid:", 0), 0u);
    for (size_t i = 9; i < u.size(); ++i) {
      if (i == 17 || i == 22 || i == 27 || i == 32) EXPECT_EQ(u[i], '-') << u;
      else EXPECT_TRUE((u[i] >= '0' && u[i] <= '9') || (u[i] >= 'a' && u[i] <= 'f')) << u;
    }
  }
  EXPECT_EQ(urnUuidFromName("a"), urnUuidFromName("a"));
  EXPECT_NE(urnUuidFromName("a"), urnUuidFromName("b"));
}

// FreeD D1 carries 1/32768 degree and 1/64 mm: a camera pose comes back within that.
TEST(FreeDCamera, PoseAndEncodersRoundTripWithinTheWiresQuantization) {
  std::mt19937 rng(7);
  for (int i = 0; i < 500; ++i) {
    const Pose T = somePose(rng);
    const FreeDBytes b = encodeFreeDCamera(3, T, 0x123456, 0xABCDEF);
    PacketFault fault;
    const std::optional<CameraSample> s = decodeFreeDCamera(b.data(), b.size(), &fault);
    ASSERT_TRUE(s);
    EXPECT_EQ(s->source_number, 3);
    EXPECT_LT(translationDistance(s->T_stage_tracker, T), 0.5 / 64 / 1000 * std::sqrt(3.0) + 1e-12);
    EXPECT_LT(rotationDistance(s->T_stage_tracker, T), 3 * 0.5 / 32768 * M_PI / 180 + 1e-12);
    EXPECT_EQ(*s->zoom_raw, 0x123456u);
    EXPECT_EQ(*s->focus_raw, 0xABCDEFu);
  }
}

TEST(Decoders, SayWhyAPacketIsRefused) {
  const FreeDBytes good = encodeFreeDCamera(1, Pose::Identity(), 0, 0);
  PacketFault f;
  FreeDBytes bad = good;
  bad[5] ^= 1;
  EXPECT_FALSE(decodeFreeDCamera(bad.data(), bad.size(), &f));
  EXPECT_EQ(f, PacketFault::kBadChecksum);
  EXPECT_FALSE(decodeFreeDCamera(good.data(), 20, &f));
  EXPECT_EQ(f, PacketFault::kTruncated);
  std::vector<std::uint8_t> longer(good.begin(), good.end());
  longer.push_back(0);
  EXPECT_FALSE(decodeFreeDCamera(longer.data(), longer.size(), &f));
  EXPECT_EQ(f, PacketFault::kOversize);

  OpenTrackIoCameraFields fields;
  fields.source_id = urnUuidFromName("s");
  fields.sample_id = urnUuidFromName("t");
  const std::vector<std::uint8_t> d =
      encodeOtrk(encodeOtrkPayload(openTrackIoCameraSample(fields, Pose::Identity()), OtrkEncoding::kJson),
                 OtrkEncoding::kJson, 1);
  std::vector<std::uint8_t> e = d;
  e[30] ^= 0x20;
  EXPECT_FALSE(decodeOpenTrackIoCamera(e.data(), e.size(), &f));
  EXPECT_EQ(f, PacketFault::kBadChecksum);
  EXPECT_FALSE(decodeOpenTrackIoCamera(d.data(), d.size() - 1, &f));
  EXPECT_EQ(f, PacketFault::kTruncated);
  EXPECT_FALSE(decodeOpenTrackIoCamera(d.data(), 10, &f));
  EXPECT_EQ(f, PacketFault::kTruncated);
  std::vector<std::uint8_t> big(1600, 'x');
  EXPECT_FALSE(decodeOpenTrackIoCamera(big.data(), big.size(), &f));
  EXPECT_EQ(f, PacketFault::kOversize);
  // A checksum-valid header around a payload that is JSON but no sample.
  const std::string not_sample = R"({"protocol": {"name": "OpenTrackIO", "version": [1, 0, 1]}})";
  const std::vector<std::uint8_t> n = encodeOtrk(std::vector<std::uint8_t>(not_sample.begin(), not_sample.end()),
                                                 OtrkEncoding::kJson, 2);
  std::string why;
  EXPECT_FALSE(decodeOpenTrackIoCamera(n.data(), n.size(), &f, &why));
  EXPECT_EQ(f, PacketFault::kMalformed);
  EXPECT_NE(why.find("transforms"), std::string::npos) << why;
}

}  // namespace
}  // namespace previz::tracking
