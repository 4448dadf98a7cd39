// Camera tracker benchmark (issue 32 item 4): receive-to-pose latency and CPU per packet at
// 240 Hz, FreeD D1 and OpenTrackIO (JSON and CBOR).
//  - decode: Google Benchmark of one datagram through the receiver (decode, checks, counts) and
//    into the matcher, CPU per packet;
//  - stream: a sender thread sends 240 Hz over loopback UDP for 2 s; the receiving thread polls,
//    decodes, adds to the matcher and asks for the pose at the newest sample's instant; latency
//    = pose ready - sendto() of that datagram (one steady clock, one process), CPU = the
//    receiving thread's CPU time over the packets it handled.
// Besides Google Benchmark's table, one JSON line per case:
//   {"stage": "tracker_decode" | "tracker_receive_to_pose", "size": "<protocol>@240Hz", "ms": median,
//    "ms_p99", "ms_max", "cpu_us_per_packet", "packets", "lost"}
#include <benchmark/benchmark.h>

#include <time.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <thread>
#include <vector>

#include "core/cpu_time.h"

#include "live/tracker.h"

namespace {

using previz::Pose;
using previz::live::TrackerCounts;
using previz::live::TrackerMatcher;
using previz::live::TrackerOptions;
using previz::live::TrackerReceiver;
using previz::live::TrackerSample;
using previz::live::TrackerUrl;
using previz::tracking::StreamProtocol;
namespace tr = previz::tracking;
using Clock = std::chrono::steady_clock;

enum Kind { kFreeD = 0, kOtioJson = 1, kOtioCbor = 2 };
const char* kindName(int k) { return k == kFreeD ? "freed" : k == kOtioJson ? "otio_json" : "otio_cbor"; }

Pose poseAt(int i) {
  Pose T = Pose::Identity();
  T.linear() = Eigen::AngleAxisd(0.001 * i, Eigen::Vector3d(0.2, 1, 0.1).normalized()).toRotationMatrix();
  T.translation() = Eigen::Vector3d(0.001 * i, -4, 1.6);
  return T;
}

std::vector<std::uint8_t> packet(int kind, int i) {
  if (kind == kFreeD) {
    const tr::FreeDBytes b = tr::encodeFreeDCamera(1, poseAt(i), 8388608, 4194304);
    return std::vector<std::uint8_t>(b.begin(), b.end());
  }
  tr::OpenTrackIoCameraFields f;
  f.source_id = tr::urnUuidFromName("bench");
  f.sample_id = tr::urnUuidFromName("bench" + std::to_string(i));
  f.sequence = i;
  f.sample_time_s = 1.7e9 + i / 240.0;
  f.rate_num = 240;
  f.zoom = 0.5;
  f.focus = 0.25;
  const tr::OtrkEncoding e = kind == kOtioCbor ? tr::OtrkEncoding::kCbor : tr::OtrkEncoding::kJson;
  return tr::encodeOtrk(tr::encodeOtrkPayload(tr::openTrackIoCameraSample(f, poseAt(i)), e), e, i & 0xFFFF);
}

using previz::threadCpuMs;

double quantile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<size_t>(q * (v.size() - 1) + 0.5))];
}

void BM_Decode(benchmark::State& state) {
  const int kind = static_cast<int>(state.range(0));
  std::vector<std::vector<std::uint8_t>> packets;
  for (int i = 0; i < 4096; ++i) packets.push_back(packet(kind, i));
  TrackerOptions o;
  TrackerReceiver r(kind == kFreeD ? StreamProtocol::kFreeD : StreamProtocol::kOpenTrackIo, o);
  TrackerMatcher m(o);
  size_t i = 0;
  const double cpu0 = threadCpuMs();
  long long n = 0;
  for (auto _ : state) {
    const std::vector<std::uint8_t>& p = packets[i++ % packets.size()];
    r.feed(p.data(), p.size(), n / 240.0);
    for (const TrackerSample& s : r.take()) m.add(s, r.counts());
    ++n;
  }
  const double cpu_us = 1e3 * (threadCpuMs() - cpu0) / std::max<long long>(1, n);
  state.counters["cpu_us_per_packet"] = cpu_us;
  std::printf("{\"stage\":\"tracker_decode\",\"size\":\"%s\",\"ms\":%.6f,\"cpu_us_per_packet\":%.3f,\"bytes\":%zu,\"packets\":%lld}\n",
              kindName(kind), cpu_us * 1e-3, cpu_us, packets[0].size(), n);
}
BENCHMARK(BM_Decode)->Arg(kFreeD)->Arg(kOtioJson)->Arg(kOtioCbor)->Iterations(20000);

// 240 Hz for 2 s over loopback.
void streamCase(int kind) {
  TrackerUrl url;
  url.protocol = kind == kFreeD ? StreamProtocol::kFreeD : StreamProtocol::kOpenTrackIo;
  url.host = "127.0.0.1";
  url.port = 0;
  TrackerOptions o;
  TrackerReceiver r(url, o);
  TrackerMatcher m(o);
  const int n = 480;
  std::vector<std::vector<std::uint8_t>> packets;
  for (int i = 0; i < n; ++i) packets.push_back(packet(kind, i));
  std::vector<Clock::time_point> sent(n);
  std::atomic<int> sent_count{0};
  std::thread sender([&] {
    previz::tracking::UdpSender s("127.0.0.1", r.port());
    const Clock::time_point start = Clock::now();
    for (int i = 0; i < n; ++i) {
      std::this_thread::sleep_until(start + std::chrono::microseconds(static_cast<long long>(i * 1e6 / 240)));
      sent[i] = Clock::now();
      s.send(packets[i].data(), packets[i].size());
      sent_count.store(i + 1, std::memory_order_release);
    }
  });
  std::vector<double> latency_ms;
  const double cpu0 = threadCpuMs();
  long long handled = 0;
  const Clock::time_point deadline = Clock::now() + std::chrono::seconds(4);
  while (handled < n && Clock::now() < deadline) {
    if (r.poll(5) == 0) continue;
    for (const TrackerSample& s : r.take()) {
      m.add(s, r.counts());
      ++handled;
      // Which datagram: FreeD carries none of its own numbers, so the x position says it.
      const int i = kind == kFreeD ? static_cast<int>(std::lround(s.sample.position_m.x() * 1000))
                                   : static_cast<int>(*s.sample.sequence);
      std::string why;
      const auto p = m.poseAt(s.arrival_s - o.delay_s, std::nullopt, &why);
      const Clock::time_point ready = Clock::now();
      if (p && i >= 0 && i < sent_count.load(std::memory_order_acquire))
        latency_ms.push_back(std::chrono::duration<double, std::milli>(ready - sent[i]).count());
    }
  }
  const double cpu_ms = threadCpuMs() - cpu0;
  sender.join();
  const TrackerCounts& c = r.counts();
  // CPU per packet includes the poll() wake-ups: the thread's whole CPU over the stream.
  std::printf("{\"stage\":\"tracker_receive_to_pose\",\"size\":\"%s@240Hz\",\"ms\":%.4f,\"ms_p99\":%.4f,\"ms_max\":%.4f,"
              "\"cpu_us_per_packet\":%.2f,\"cpu_percent_of_one_core\":%.3f,\"packets\":%lld,\"lost\":%lld,\"posed\":%zu}\n",
              kindName(kind), quantile(latency_ms, 0.5), quantile(latency_ms, 0.99), quantile(latency_ms, 1.0),
              1e3 * cpu_ms / std::max<long long>(1, handled), 100.0 * cpu_ms / (1e3 * n / 240.0), c.accepted, n - c.datagrams,
              latency_ms.size());
}

}  // namespace

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  benchmark::RunSpecifiedBenchmarks();
  for (int kind : {kFreeD, kOtioJson, kOtioCbor}) streamCase(kind);
  benchmark::Shutdown();
  return 0;
}
