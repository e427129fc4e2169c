// libFuzzer target: frames through one pump's whole pipeline step, as the daemon runs it
// (daemon/gateway.hpp: decode through the shipped DBC and mapping, resistance identification,
// virtual thermal sensor, alarms, forecast, CAN and LCM encoding), on arbitrary frame sequences.
//
// Input: records of [selector][dt lo][dt hi][len][payload bytes...]. The selector picks the CAN
// ID (the pump's PUMP_FAST_I, PUMP_FAST_U, PUMP_STATUS, PUMP_CLEAR, another node's or an unknown
// ID; bit 7 marks the frame CAN FD, bit 6 sends it as remote, bit 5 as extended), dt is the time
// step in milliseconds (little-endian, modulo 5001; selector bit 4 makes it go backwards), len the
// payload length (mod 65); a payload cut short by the end of the input is what it is.
//
// Findings: a crash, a sanitizer report, an exception out of OnFrame/Advance (documented never
// to throw), a published temperatures_t message while the pump is not initialised, a
// non-finite node temperature or standard deviation in an initialised snapshot, or an alarm
// level outside the enum.
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <string>

#include "daemon/config.hpp"
#include "daemon/gateway.hpp"

namespace {

using namespace pumptherm;
using namespace pumptherm::daemon;

const char kConfig[] = R"(
[gateway]
heartbeat_period_s = 1.0

[[can]]
interface = "can0"

[alarms]
hold_s = 2
clear_can_interfaces = ["can0"]

[[pump]]
name = "tmp1"
node_id = 1
interface = "can0"
motor = "han2019-tmp"
thermal_model = "tmp-generic"
measured_node = "frame"
)";

struct CheckingSink : OutputSink {
  const Gateway* gateway = nullptr;
  void SendFrame(std::size_t, std::int64_t, const protocol::CanFrame& f) override {
    if (f.len > 64) std::abort();
  }
  bool PublishLcm(const std::string& channel, std::int64_t,
                  const std::vector<std::uint8_t>&) override {
    // Temperatures are published only once the filter has run (docs/daemon.md).
    if (channel.size() >= 6 && channel.compare(channel.size() - 6, 6, "/TEMPS") == 0) {
      if (!gateway->pumps()[0]->snapshot().initialised) std::abort();
    }
    return true;
  }
};

const DaemonConfig& Config() {
  static const DaemonConfig config =
      ParseConfig(kConfig, std::string(PUMPTHERM_SOURCE_DIR_DEFAULT) + "/fuzz.toml");
  return config;
}

void CheckSnapshot(const Pump& pump) {
  const PumpSnapshot& s = pump.snapshot();
  if (s.initialised) {
    for (std::size_t i = 0; i < s.node_degC.size(); ++i) {
      if (!std::isfinite(s.node_degC[i]) || !std::isfinite(s.node_sd_K[i]) ||
          s.node_sd_K[i] < 0.0) {
        std::fprintf(stderr, "pipeline_step_fuzz: state %zu at %lld us: %g degC, sd %g K\n", i,
                     static_cast<long long>(s.time_us), s.node_degC[i], s.node_sd_K[i]);
        std::abort();
      }
    }
  }
  const int level = static_cast<int>(s.alarm.level);
  if (level < 0 || level > 2) std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  // Per input a fresh gateway, so that every run starts from the same state.
  Gateway gateway(Config());
  CheckingSink sink;
  sink.gateway = &gateway;
  const std::size_t iface = gateway.Interface("can0");
  constexpr std::uint32_t kIds[] = {0x101, 0x111, 0x181, 0x701, 0x100, 0x182, 0x7F0, 0x123};
  std::int64_t t_us = 1'700'000'000'000'000;
  std::size_t pos = 0;
  while (pos + 4 <= size) {
    const std::uint8_t sel = data[pos];
    // At most 5 s per record: longer gaps only repeat thermal steps (slow under the sanitizers);
    // 5 s is past the stale-telemetry time, and a thousand records reach an hour and more.
    const unsigned dt_ms = (data[pos + 1] | (static_cast<unsigned>(data[pos + 2]) << 8)) % 5001;
    std::size_t len = data[pos + 3] % 65;
    pos += 4;
    t_us += (sel & 0x10) ? -static_cast<std::int64_t>(dt_ms) * 1000
                         : static_cast<std::int64_t>(dt_ms) * 1000;
    protocol::TimedFrame tf;
    tf.time_us = t_us;
    tf.frame.id = kIds[sel % 8];
    tf.frame.fd = (sel & 0x80) != 0;
    tf.frame.remote = (sel & 0x40) != 0 && !tf.frame.fd;
    tf.frame.extended = (sel & 0x20) != 0;
    if (!tf.frame.fd && len > 8) len = 8;
    if (len > size - pos) len = size - pos;
    for (std::size_t i = 0; i < len; ++i) tf.frame.data[i] = data[pos + i];
    tf.frame.len = static_cast<std::uint8_t>(len);
    pos += len;
    gateway.OnFrame(iface, tf);
    gateway.Advance(t_us, sink);
    CheckSnapshot(*gateway.pumps()[0]);
  }
  return 0;
}
