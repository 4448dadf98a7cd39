// Issue 6 item 4: FreeD D1 packets round-trip bit for bit through UDP on the loopback and the
// receiver; malformed datagrams (wrong length, bad checksum, wrong type, garbage) are rejected and
// counted, never crash it. OpenTrackIO samples (behind their OTrk header) round-trip too. Sockets: 127.0.0.1 only.
#include <gtest/gtest.h>

#include <random>

#include "core/error.h"
#include "tracking/opentrackio.h"
#include "tracking/stream.h"

namespace previz::tracking {
namespace {

Pose somePose(std::mt19937& rng) {
  std::uniform_real_distribution<double> u(-1, 1);
  Pose T = Pose::Identity();
  T.linear() = rotationFromPanTiltRoll(Eigen::Vector3d(179.9 * u(rng), 89 * u(rng), 179.9 * u(rng)));
  T.translation() = Eigen::Vector3d(5 * u(rng), 5 * u(rng), 1.5 + u(rng));
  return T;
}

TEST(FreeD, KnownPacketLayout) {
  FreeDPacket p;
  p.camera_id = 7;
  p.pan = 90 * 32768;        // 90 degrees
  p.tilt = -1;
  p.roll = 0x123456;
  p.x = 1000 * 64;           // 1 m
  p.y = -64;
  p.z = 0;
  p.zoom = 0xABCDEF;
  p.focus = 1;
  p.spare = 0xBEEF;
  const FreeDBytes b = encodeFreeD(p);
  const FreeDBytes expected = {0xD1, 0x07, 0x2D, 0x00, 0x00, 0xFF, 0xFF, 0xFF, 0x12, 0x34, 0x56, 0x00, 0xFA, 0x00, 0xFF,
                               0xFF, 0xC0, 0x00, 0x00, 0x00, 0xAB, 0xCD, 0xEF, 0x00, 0x00, 0x01, 0xBE, 0xEF, 0x00};
  for (int i = 0; i < 28; ++i) EXPECT_EQ(b[i], expected[i]) << "byte " << i;
  unsigned sum = 0;
  for (int i = 0; i < 28; ++i) sum += b[i];
  EXPECT_EQ(b[28], static_cast<std::uint8_t>((0x40 - sum) & 0xFF));
  const auto back = decodeFreeD(b.data(), b.size());
  ASSERT_TRUE(back);
  EXPECT_EQ(back->pan, p.pan);
  EXPECT_EQ(back->tilt, -1);
  EXPECT_EQ(back->y, -64);
  EXPECT_EQ(back->zoom, 0xABCDEFu);
  EXPECT_EQ(back->spare, 0xBEEF);
}

TEST(FreeD, PacketsRoundTripBitForBitThroughTheReceiver) {
  StreamReceiver receiver("127.0.0.1", 0);
  UdpSender sender("127.0.0.1", receiver.port());
  std::mt19937 rng(6);
  std::vector<FreeDBytes> sent;
  std::vector<Pose> poses;
  for (int i = 0; i < 200; ++i) {
    poses.push_back(somePose(rng));
    sent.push_back(encodeFreeD(freeDFromPose(i % 256, poses.back())));
    ASSERT_TRUE(sender.send(sent.back().data(), sent.back().size()));
    if (i % 50 == 49) receiver.poll(10);
  }
  for (int tries = 0; tries < 50 && receiver.accepted().size() < sent.size(); ++tries) receiver.poll(100);
  ASSERT_EQ(receiver.accepted().size(), sent.size());
  EXPECT_EQ(receiver.rejected(), 0);
  for (size_t i = 0; i < sent.size(); ++i) {
    const auto& r = receiver.accepted()[i];
    ASSERT_TRUE(r.freed);
    EXPECT_EQ(r.bytes, std::vector<std::uint8_t>(sent[i].begin(), sent[i].end()));
    EXPECT_EQ(encodeFreeD(*r.freed), sent[i]);  // parse + re-encode gives the same bits
    // And the pose within the packet's quantization (1/64 mm, 1/32768 degree per angle).
    const Pose back = poseFromFreeD(*r.freed);
    EXPECT_LT(translationDistance(back, poses[i]), 0.5 / 64 / 1000 * std::sqrt(3.0) + 1e-12);
    EXPECT_LT(rotationDistance(back, poses[i]), 3 * 0.5 / 32768 * M_PI / 180 + 1e-12);
  }
}

TEST(FreeD, MalformedPacketsAreRejectedAndCounted) {
  StreamReceiver receiver("127.0.0.1", 0);
  UdpSender sender("127.0.0.1", receiver.port());
  std::mt19937 rng(1);
  const FreeDBytes good = encodeFreeD(freeDFromPose(3, somePose(rng)));
  FreeDBytes bad_sum = good;
  bad_sum[28] ^= 0x01;
  FreeDBytes flipped = good;
  flipped[12] ^= 0x80;  // a data bit: the checksum no longer matches
  int got = 0;
  sender.send(good.data(), 28);   // short
  std::vector<std::uint8_t> longer(good.begin(), good.end());
  longer.push_back(0);
  sender.send(longer.data(), longer.size());  // long
  sender.send(bad_sum.data(), bad_sum.size());
  sender.send(flipped.data(), flipped.size());
  sender.send(good.data(), 0);  // empty
  // Random garbage of random lengths, some starting like a D1 or a JSON object.
  int garbage = 0;
  for (int i = 0; i < 300; ++i) {
    std::vector<std::uint8_t> g(std::uniform_int_distribution<int>(1, 2000)(rng));
    for (auto& b : g) b = static_cast<std::uint8_t>(rng());
    if (i % 3 == 0) g[0] = 0xD1;
    if (i % 3 == 1) g[0] = '{';
    if (g.size() == 29 && g[0] == 0xD1) continue;  // could be valid by chance (1/256)
    sender.send(g.data(), g.size());
    ++garbage;
    if (garbage % 20 == 0) got += receiver.poll(10);  // drain: loopback drops what overflows its buffer
  }
  sender.send(good.data(), good.size());
  const int expected_total = 5 + garbage + 1;
  for (int tries = 0; tries < 50 && got < expected_total; ++tries) got += receiver.poll(100);
  ASSERT_EQ(got, expected_total);
  ASSERT_EQ(receiver.accepted().size(), 1u);
  EXPECT_EQ(encodeFreeD(*receiver.accepted()[0].freed), good);
  EXPECT_EQ(receiver.rejected(), expected_total - 1);
  const auto& by = receiver.rejectedBy();
  EXPECT_EQ(by.at("freed: bad checksum"), 2);
  EXPECT_GE(by.at("freed: wrong length (28 bytes, D1 is 29)"), 1);
  EXPECT_GE(by.at("freed: wrong length (30 bytes, D1 is 29)"), 1);
  EXPECT_EQ(by.at("empty datagram"), 1);
  EXPECT_GE(by.at("json: not valid JSON"), 1);
}

TEST(FreeD, OutOfRangeValuesAreErrorsNotWrapAround) {
  Pose far = Pose::Identity();
  far.translation() = Eigen::Vector3d(200, 0, 0);  // 200 m > 131 m
  EXPECT_THROW(freeDFromPose(0, far), Error);
  EXPECT_THROW(freeDFromPose(256, Pose::Identity()), Error);
  FreeDPacket p;
  p.x = 1 << 23;
  EXPECT_THROW(encodeFreeD(p), Error);
}

TEST(OpenTrackIo, SamplesRoundTripAndLostPropsCarryNoTransform) {
  StreamReceiver receiver("127.0.0.1", 0);
  PoseStreamer streamer("127.0.0.1", receiver.port(), StreamProtocol::kOpenTrackIo, 24.0);
  std::mt19937 rng(2);
  TrackFrame f;
  f.frame = 12;
  f.time_s = 0.5;
  PropResult a;
  a.id = 0;
  a.name = "crate";
  a.tracked = true;
  a.T_world_prop = somePose(rng);
  a.cameras = {"witness01", "witness02"};
  PropResult b;
  b.id = 1;
  b.name = "plate";
  f.props = {a, b};
  streamer.send(f);
  for (int tries = 0; tries < 50 && receiver.accepted().size() < 2; ++tries) receiver.poll(100);
  ASSERT_EQ(receiver.accepted().size(), 2u);
  const nlohmann::json& ja = *receiver.accepted()[0].otio;
  EXPECT_EQ(ja["protocol"]["name"], "OpenTrackIO");
  EXPECT_EQ(ja["timing"]["sequenceNumber"], 12);
  EXPECT_EQ(ja["timing"]["sampleTimestamp"]["nanoseconds"], 500000000);
  EXPECT_EQ(ja["tracker"]["status"], "tracked");
  const auto& tr = ja["transforms"][0];
  Pose back = Pose::Identity();
  // OpenTrackIO's rotation: intrinsic Z-X-Y (schema "transforms"), of the prop frame as it is.
  back.linear() = rotationFromZxyDeg(
      Eigen::Vector3d(tr["rotation"]["pan"].get<double>(), tr["rotation"]["tilt"].get<double>(), tr["rotation"]["roll"].get<double>()));
  back.translation() = Eigen::Vector3d(tr["translation"]["x"].get<double>(), tr["translation"]["y"].get<double>(),
                                       tr["translation"]["z"].get<double>());
  EXPECT_LT(translationDistance(back, a.T_world_prop), 1e-12);
  EXPECT_LT(rotationDistance(back, a.T_world_prop), 1e-9);
  const nlohmann::json& jb = *receiver.accepted()[1].otio;
  EXPECT_EQ(jb["tracker"]["status"], "lost");
  EXPECT_FALSE(jb.contains("transforms"));  // the schema wants >= 1 transform when the key is there
  // The datagrams carry the 16-byte OTrk header with a Fletcher-16 checksum.
  const std::vector<std::uint8_t>& bytes = receiver.accepted()[0].bytes;
  ASSERT_GT(bytes.size(), 16u);
  EXPECT_EQ(std::string(bytes.begin(), bytes.begin() + 4), "OTrk");
  EXPECT_EQ(bytes[5], 0x01);
  EXPECT_EQ(((bytes[12] << 8) | bytes[13]) & 0x7FFF, static_cast<int>(bytes.size()) - 16);
  EXPECT_EQ(fletcher16(bytes.data(), 14, bytes.data() + 16, bytes.size() - 16), (bytes[14] << 8) | bytes[15]);
  EXPECT_EQ(ja["sourceId"].get<std::string>().rfind("urn:uuid:", 0), 0u);
  // FreeD sends nothing for a lost prop.
  StreamReceiver r2("127.0.0.1", 0);
  PoseStreamer freed("127.0.0.1", r2.port(), StreamProtocol::kFreeD, 24.0);
  freed.send(f);
  int got = 0;
  for (int tries = 0; tries < 5; ++tries) got += r2.poll(50);
  EXPECT_EQ(got, 1);
  EXPECT_EQ(r2.accepted()[0].freed->camera_id, 0);
}

TEST(Stream, HostPortParsing) {
  EXPECT_EQ(parseHostPort("127.0.0.1:40000"), std::make_pair(std::string("127.0.0.1"), 40000));
  EXPECT_THROW(parseHostPort("localhost:40000"), Error);
  EXPECT_THROW(parseHostPort("127.0.0.1"), Error);
  EXPECT_THROW(parseHostPort("127.0.0.1:0"), Error);
  EXPECT_THROW(parseHostPort("127.0.0.1:70000"), Error);
  EXPECT_THROW(parseHostPort("127.0.0.1:12ab"), Error);
}

}  // namespace
}  // namespace previz::tracking
