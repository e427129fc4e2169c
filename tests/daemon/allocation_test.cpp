// "Heap allocations per frame in steady state: zero", as a test: this executable
// replaces the global operator new/delete with counting ones, runs a multi-pump recording (the
// plant simulator's demo: three pumps, 100 Hz fast telemetry and 10 Hz status, generated at
// build time) through the offline pipeline's per-frame path (daemon/offline.cpp RunOffline:
// parse the candump line, Gateway::OnFrame, Gateway::Advance into a sink that writes nothing),
// and counts the allocations after a warm-up of 60 s of log time. The counted part holds
// thermal steps, alarm evaluations, forecasts, CAN outputs, LCM encodings and health messages;
// one case adds the MQTT sink as the live loop calls it (MqttSink::Offer and Health after each
// Advance), its broker absent so that its queues fill and drop. Only the loop's thread is
// counted: the sink's own thread (encoding, connecting) may allocate.
#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <memory>
#include <new>
#include <string>
#include <vector>

#include "daemon/config.hpp"
#include "daemon/gateway.hpp"
#include "daemon/mqtt_sink.hpp"
#include "daemon/resources.hpp"
#include "protocol/candump_log.hpp"

// What is counted: in a plain build, malloc, calloc and realloc themselves are interposed
// (glibc lets an executable define them; __libc_* are the real ones), which sees operator new
// (libstdc++'s goes through malloc) and Eigen's dynamic matrices (Eigen calls std::malloc, not
// operator new). Under AddressSanitizer, which owns malloc, only operator new is counted (the
// replaced operators below): Eigen's allocations are then not seen, so the plain build is the
// authoritative run (CI runs both).
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#define PUMPTHERM_COUNT_MALLOC 0
#elif defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer) || \
    __has_feature(memory_sanitizer)
#define PUMPTHERM_COUNT_MALLOC 0
#else
#define PUMPTHERM_COUNT_MALLOC 1
#endif
#else
#define PUMPTHERM_COUNT_MALLOC 1
#endif

namespace {
// Per thread: the loop's thread counts, other threads (the MQTT sink's) do not.
thread_local bool g_counting = false;
std::atomic<std::uint64_t> g_allocations{0};
std::atomic<std::uint64_t> g_bytes{0};
// PUMPTHERM_ABORT_ON_ALLOCATION=1 aborts at the first counted allocation (run under gdb to see
// where it comes from).
bool g_abort = false;

void Count(std::size_t n) {
  if (g_counting) {
    g_allocations.fetch_add(1, std::memory_order_relaxed);
    g_bytes.fetch_add(n, std::memory_order_relaxed);
    if (g_abort) std::abort();
  }
}

void* Allocate(std::size_t n, std::size_t align) {
  if (!PUMPTHERM_COUNT_MALLOC) Count(n);
  void* p = nullptr;
  if (align <= alignof(std::max_align_t)) {
    p = std::malloc(n == 0 ? 1 : n);
  } else if (posix_memalign(&p, align, n == 0 ? align : n) != 0) {
    p = nullptr;
  }
  return p;
}
}  // namespace

#if PUMPTHERM_COUNT_MALLOC
extern "C" void* __libc_malloc(std::size_t size);
extern "C" void* __libc_calloc(std::size_t n, std::size_t size);
extern "C" void* __libc_realloc(void* p, std::size_t size);
extern "C" void* malloc(std::size_t size) {
  Count(size);
  return __libc_malloc(size);
}
extern "C" void* calloc(std::size_t n, std::size_t size) {
  Count(n * size);
  return __libc_calloc(n, size);
}
extern "C" void* realloc(void* p, std::size_t size) {
  Count(size);
  return __libc_realloc(p, size);
}
#endif

// operator new/delete through Allocate: counted here under a sanitizer, else by malloc above.
void* operator new(std::size_t n) {
  if (void* p = Allocate(n, 0)) return p;
  throw std::bad_alloc();
}
void* operator new[](std::size_t n) {
  if (void* p = Allocate(n, 0)) return p;
  throw std::bad_alloc();
}
void* operator new(std::size_t n, std::align_val_t a) {
  if (void* p = Allocate(n, static_cast<std::size_t>(a))) return p;
  throw std::bad_alloc();
}
void* operator new[](std::size_t n, std::align_val_t a) {
  if (void* p = Allocate(n, static_cast<std::size_t>(a))) return p;
  throw std::bad_alloc();
}
void* operator new(std::size_t n, const std::nothrow_t&) noexcept { return Allocate(n, 0); }
void* operator new[](std::size_t n, const std::nothrow_t&) noexcept { return Allocate(n, 0); }
// Our operator new allocates with malloc, so free is the matching release (GCC cannot see that
// through the replaced operators).
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }
void operator delete(void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete[](void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete(void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }
#pragma GCC diagnostic pop

namespace pumptherm::daemon {
namespace {

/// The offline sink with no output files: counts, writes nothing (as RunOffline's LogSink
/// without --output-log and --lcm-log).
struct NullSink : OutputSink {
  std::uint64_t frames = 0, lcm = 0;
  void SendFrame(std::size_t, std::int64_t, const protocol::CanFrame&) override { ++frames; }
  bool PublishLcm(const std::string&, std::int64_t, const std::vector<std::uint8_t>&) override {
    ++lcm;
    return true;
  }
};

/// A loopback TCP port nothing listens on (bound, then closed: a connect is refused).
int ClosedPort() {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t n = sizeof a;
  ::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a);
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &n);
  ::close(fd);
  return ntohs(a.sin_port);
}

/// The demo's configuration over the pipeline recording; `disturbance_states` switches every
/// pump to the disturbance-state filter; `with_mqtt` adds the MQTT sink (broker absent, small
/// queues so that they overflow in the counted window).
void ExpectNoAllocationPerFrame(bool disturbance_states, bool with_mqtt = false) {
  const std::string config_path =
      std::string(PUMPTHERM_SOURCE_DIR) + "/tools/demo/pumpthermd-demo.toml";
  DaemonConfig config = LoadConfig(config_path);
  for (auto& pump : config.pumps) pump.disturbance_states = disturbance_states;
  Gateway gateway(config);
  std::unique_ptr<MqttSink> mqtt;
  if (with_mqtt) {
    config.mqtt = MqttConfig{};
    config.mqtt.enabled = true;
    config.mqtt.host = "127.0.0.1";
    config.mqtt.port = ClosedPort();
    config.mqtt.queue_steps = 4;
    config.mqtt.alarm_queue_steps = 2;
    mqtt = std::make_unique<MqttSink>(config.mqtt, "alloc", gateway, false);
  }
  std::ifstream in(PUMPTHERM_ALLOCATION_RECORDING);
  ASSERT_TRUE(in) << PUMPTHERM_ALLOCATION_RECORDING
                  << ": cannot open (built by vcan_pipeline_recording)";
  std::vector<std::string> lines;
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  ASSERT_GT(lines.size(), 50000U);

  // The counting allocator is the one in use (else zero below would prove nothing).
  static std::vector<int>* volatile probe = nullptr;
  g_counting = true;
  probe = new std::vector<int>(1000);
  g_counting = false;
  ASSERT_GE(g_allocations.load(), 1U) << "the counting allocator is not in use";
  std::printf("counting %s\n",
              PUMPTHERM_COUNT_MALLOC
                  ? "malloc, calloc, realloc (and so operator new and Eigen)"
                  : "operator new only (sanitizer build: Eigen's malloc not seen)");
  delete probe;
  g_allocations = 0;
  g_bytes = 0;
  g_abort = std::getenv("PUMPTHERM_ABORT_ON_ALLOCATION") != nullptr;

  NullSink sink;
  std::string last_interface;
  std::size_t iface = 0;
  std::int64_t start_us = -1, last_us = -1;
  std::uint64_t counted_frames = 0, counted_outputs = 0, counted_lcm = 0;
  std::uint64_t steps_before = 0;
  constexpr std::int64_t kWarmUpUs = 60'000'000;
  for (const std::string& line : lines) {
    const protocol::CandumpParse p = protocol::ParseCandumpLine(line);
    ASSERT_TRUE(p.ok || p.skip) << line;
    if (p.skip) continue;
    if (p.record.interface != last_interface) {
      last_interface = p.record.interface;
      iface = gateway.Interface(last_interface);
    }
    const std::int64_t now = std::max(p.record.time_us, last_us);
    if (start_us < 0) start_us = now;
    if (!g_counting && now - start_us >= kWarmUpUs) {
      for (const auto& pump : gateway.pumps()) steps_before += pump->counters().thermal_steps;
      counted_outputs = sink.frames;
      counted_lcm = sink.lcm;
      g_counting = true;
    }
    gateway.OnFrame(iface, protocol::TimedFrame{now, p.record.frame});
    gateway.Advance(now, sink);
    if (mqtt) {
      mqtt->Offer(gateway);
      gateway.SetMqttHealth(mqtt->Health());
    }
    last_us = now;
    if (g_counting) ++counted_frames;
  }
  g_counting = false;
  std::uint64_t steps = 0;
  for (const auto& pump : gateway.pumps()) steps += pump->counters().thermal_steps;
  steps -= steps_before;
  counted_outputs = sink.frames - counted_outputs;
  counted_lcm = sink.lcm - counted_lcm;
  std::printf(
      "counted %llu frames (%.1f s of log, %zu pumps): %llu thermal steps, %llu CAN outputs, "
      "%llu LCM messages; %llu heap allocations (%llu bytes)\n",
      static_cast<unsigned long long>(counted_frames),
      static_cast<double>(last_us - start_us - kWarmUpUs) * 1e-6, gateway.pumps().size(),
      static_cast<unsigned long long>(steps), static_cast<unsigned long long>(counted_outputs),
      static_cast<unsigned long long>(counted_lcm),
      static_cast<unsigned long long>(g_allocations.load()),
      static_cast<unsigned long long>(g_bytes.load()));
  // The counted window must hold everything the steady state does, or zero means nothing.
  ASSERT_GT(counted_frames, 20000U);
  ASSERT_GE(steps, 3U * 30U);
  ASSERT_GT(counted_outputs, 1000U);
  ASSERT_GT(counted_lcm, 3U * 3U * 30U);
  if (mqtt) {
    const MqttCounts c = mqtt->counts();
    std::printf("mqtt (broker absent): %llu steps dropped, %llu alarm transitions dropped\n",
                static_cast<unsigned long long>(c.dropped),
                static_cast<unsigned long long>(c.alarms_dropped));
    ASSERT_GT(c.dropped, 3U * 30U);  // Offer queued every step and the full ring dropped
  }
  EXPECT_EQ(g_allocations.load(), 0U)
      << "heap allocations in the per-frame path after warm-up ("
      << static_cast<double>(g_allocations.load()) / static_cast<double>(counted_frames)
      << " per frame); PUMPTHERM_ABORT_ON_ALLOCATION=1 under gdb shows where";
}

TEST(Allocation, NoHeapAllocationPerFrameInSteadyState) { ExpectNoAllocationPerFrame(false); }

TEST(Allocation, NoHeapAllocationPerFrameWithDisturbanceStates) {
  ExpectNoAllocationPerFrame(true);
}

TEST(Allocation, NoHeapAllocationPerFrameWithTheMqttSink) {
  ExpectNoAllocationPerFrame(false, true);
}

}  // namespace
}  // namespace pumptherm::daemon
