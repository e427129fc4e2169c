// The CAN loop's step time with the MQTT sink on and its broker absent, against no sink
// (docs/mqtt.md, "The loop's timing with the broker gone"): a candump recording through the
// per-frame path the daemon runs (parse, Gateway::OnFrame, Gateway::Advance into a sink that
// writes nothing, and with the sink MqttSink::Offer, which the live loop calls after each
// Advance), each frame's step timed with the steady clock. The sink's broker is a loopback
// port nothing listens on, so its thread keeps reconnecting with backoff and its queue drops the
// oldest step, as live with the broker stopped. Given a port, a third kind of run sends to a
// broker listening there (plain MQTT on loopback: the broker running). Runs alternate (none,
// absent[, present], twice) so that drift of the machine's load shows as a difference between
// runs of one kind. Prints one
// JSON object per run: p50, p99, p99.9 and max of all frames' step time, and of the frames whose
// Advance made a thermal step (the Offer's copies happen there), in microseconds.
//
//   mqtt_loop_bench LOG [CONFIG [BROKER_PORT]]   (CONFIG: the demo's configuration)
#include <arpa/inet.h>
#include <fmt/format.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include "daemon/config.hpp"
#include "daemon/gateway.hpp"
#include "daemon/mqtt_sink.hpp"
#include "protocol/candump_log.hpp"

namespace pd = pumptherm::daemon;

namespace {

struct NullSink : pd::OutputSink {
  void SendFrame(std::size_t, std::int64_t, const pumptherm::protocol::CanFrame&) override {}
  bool PublishLcm(const std::string&, std::int64_t, const std::vector<std::uint8_t>&) override {
    return true;
  }
};

/// A loopback TCP port nothing listens on (bound, then closed: connect is refused).
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

double Percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  const auto k = static_cast<std::size_t>(q * static_cast<double>(v.size() - 1));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

std::string Figures(const std::vector<double>& us) {
  return fmt::format(
      R"({{"n": {}, "p50_us": {:.2f}, "p99_us": {:.2f}, "p999_us": {:.2f}, "max_us": {:.1f}}})",
      us.size(), Percentile(us, 0.5), Percentile(us, 0.99), Percentile(us, 0.999),
      us.empty() ? 0.0 : *std::max_element(us.begin(), us.end()));
}

/// The sink's broker: none (no sink), a closed port (absent), or a broker on this port.
void Run(const std::vector<std::string>& lines, pd::DaemonConfig config, int broker_port) {
  const bool with_sink = broker_port != 0;
  if (with_sink) {
    config.mqtt = pd::MqttConfig{};
    config.mqtt.enabled = true;
    config.mqtt.host = "127.0.0.1";
    config.mqtt.port = broker_port > 0 ? broker_port : ClosedPort();
  }
  pd::Gateway gateway(config);
  std::unique_ptr<pd::MqttSink> sink;
  if (with_sink) sink = std::make_unique<pd::MqttSink>(config.mqtt, "bench", gateway, false);
  NullSink out;
  std::vector<double> all_us, step_us;
  all_us.reserve(lines.size());
  std::string last_interface;
  std::size_t iface = 0;
  std::int64_t last_us = -1;
  std::uint64_t steps = 0;
  for (const std::string& line : lines) {
    const auto t0 = std::chrono::steady_clock::now();
    const pumptherm::protocol::CandumpParse p = pumptherm::protocol::ParseCandumpLine(line);
    if (!p.ok) continue;
    if (p.record.interface != last_interface) {
      last_interface = p.record.interface;
      iface = gateway.Interface(last_interface);
    }
    const std::int64_t now = std::max(p.record.time_us, last_us);
    gateway.OnFrame(iface, pumptherm::protocol::TimedFrame{now, p.record.frame});
    gateway.Advance(now, out);
    if (sink) {
      sink->Offer(gateway);
      gateway.SetMqttHealth(sink->Health());
    }
    const auto t1 = std::chrono::steady_clock::now();
    last_us = now;
    const double us = std::chrono::duration<double, std::micro>(t1 - t0).count();
    all_us.push_back(us);
    std::uint64_t s = 0;
    for (const auto& pump : gateway.pumps()) s += pump->counters().thermal_steps;
    if (s != steps) step_us.push_back(us);
    steps = s;
  }
  const pd::MqttHealth h = sink ? sink->Health() : pd::MqttHealth{};
  fmt::print(
      R"({{"mqtt": "{}", "frames": {}, "thermal_steps": {}, "mqtt_dropped": {}, "all": {}, "step_frames": {}}})"
      "\n",
      !with_sink        ? "none"
      : broker_port > 0 ? "broker present"
                        : "broker absent",
      all_us.size(), steps, h.dropped, Figures(all_us), Figures(step_us));
  if (sink) sink->Stop(0.0);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    fmt::print(stderr, "usage: mqtt_loop_bench LOG [CONFIG [BROKER_PORT]]\n");
    return 2;
  }
  const std::string config_path =
      argc > 2 ? argv[2] : std::string(PUMPTHERM_SOURCE_DIR) + "/tools/demo/pumpthermd-demo.toml";
  const pd::DaemonConfig config = pd::LoadConfig(config_path);
  std::ifstream in(argv[1]);
  if (!in) {
    fmt::print(stderr, "{}: cannot open\n", argv[1]);
    return 1;
  }
  std::vector<std::string> lines;
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  // With a port, a broker listening there (plain MQTT on loopback) joins the alternation.
  const int port = argc > 3 ? std::atoi(argv[3]) : 0;
  for (int k = 0; k < 2; ++k) {
    Run(lines, config, 0);
    Run(lines, config, -1);
    if (port > 0) Run(lines, config, port);
  }
  return 0;
}
