// pumptherm clear-trip: clears a pump's latched trip through the gateway the way its
// configuration authorises: over LCM with a command signed with the clear key, reporting the
// gateway's signed answer (docs/threat-model.md; docs/lcm.md, "Clearing a trip"), or with a
// PUMP_CLEAR frame on the pump's CAN interface, reporting the gateway's GW_ALARM level before
// and after (docs/protocol.md).
#include <fmt/core.h>
#include <poll.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <lcm/lcm-cpp.hpp>
#include <memory>
#include <system_error>

#include "daemon/alarm_clear_auth.hpp"
#include "daemon/can_socket.hpp"
#include "daemon/config.hpp"
#include "daemon/published_fields.hpp"
#include "daemon/resources.hpp"
#include "tools/pumptherm/clear_can.hpp"
#include "tools/pumptherm/subcommand.hpp"

namespace pumptherm::tools {
namespace {

using Reply = pumptherm::alarm_clear_reply_t;

struct ClearTripOptions {
  std::string pump;
  std::string config = "/etc/pumptherm/pumpthermd.toml";
  std::string key_file;
  std::string url;
  std::string prefix;
  std::string source;
  std::string node;
  std::string comment;
  std::string via = "auto";
  double timeout_s = 5.0;
};

/// What the command needs, from the daemon's configuration and the options over it.
struct Settings {
  std::string url, prefix = "PUMPTHERM", key_file, key_group, source = "operator";
};

/// Settings from the options alone, for a host without the daemon's configuration.
Settings FromOptions(const ClearTripOptions& o) {
  Settings s;
  s.url = o.url;
  s.key_file = o.key_file;
  if (!o.prefix.empty()) s.prefix = o.prefix;
  if (!o.source.empty()) s.source = o.source;
  return s;
}

daemon::DaemonConfig LoadDaemonConfig(const ClearTripOptions& o) {
  try {
    return daemon::LoadConfig(o.config);
  } catch (const daemon::ConfigError& e) {
    throw InputError(fmt::format("{} (without the configuration, give --url and --key)", e.what()));
  }
}

const daemon::PumpConfig& FindPump(const daemon::DaemonConfig& c, const ClearTripOptions& o) {
  const auto it =
      std::find_if(c.pumps.begin(), c.pumps.end(), [&](const auto& p) { return p.name == o.pump; });
  if (it == c.pumps.end())
    throw InputError(fmt::format("pump '{}' is not configured in {}", o.pump, o.config));
  return *it;
}

Settings Resolve(const ClearTripOptions& o, const daemon::DaemonConfig& c) {
  Settings s;
  s.url = o.url.empty() ? c.lcm.url : o.url;
  s.prefix = o.prefix.empty() ? c.lcm.channel_prefix : o.prefix;
  s.key_file = o.key_file.empty() ? c.clear_auth.key_file : o.key_file;
  s.key_group = c.clear_auth.key_group;
  const auto& sources = c.alarms.clear_lcm_sources;
  s.source = !o.source.empty() ? o.source : sources.empty() ? s.source : sources.front();
  if (s.url.empty())
    throw InputError(fmt::format("{}: LCM is off (lcm.url is empty); give --url", o.config));
  if (s.key_file.empty()) {
    throw InputError(fmt::format(
        "{}: no alarms.clear_key_file: LCM clears are off in this configuration", o.config));
  }
  return s;
}

std::int64_t NowUs() {
  timespec ts{};
  clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000 + ts.tv_nsec / 1000;
}

int Report(const std::string& pump, const daemon::ClearExchange& x, const Settings& s,
           double timeout_s) {
  if (!x.reply) {
    if (x.untrusted_replies > 0) {
      fmt::print(
          stderr,
          "{}: the gateway answered '{}', but not signed with {}: it holds another key (or none)\n",
          pump, x.untrusted_reason, s.key_file);
    } else {
      fmt::print(stderr,
                 "{}: no answer from the gateway within {} s on {} (is pumpthermd running there, "
                 "with this pump?)\n",
                 pump, timeout_s, s.url);
    }
    return 1;
  }
  const Reply& r = *x.reply;
  if (r.result != Reply::RESULT_ACCEPTED) {
    fmt::print(stderr, "{}: the gateway refused the clear: {}\n", pump, r.reason);
    return 1;
  }
  fmt::print("{}: the gateway accepted the clear ({}); trip latched now: {}\n", pump, r.reason,
             r.trip_latched ? "yes" : "no");
  return 0;
}

int RunLcmClear(const ClearTripOptions& o, const Settings& s) {
  if (const std::string problem = daemon::ClearKeyFileProblem(s.key_file, s.key_group);
      !problem.empty()) {
    throw InputError(problem);
  }
  daemon::ClearKey key{};
  try {
    key = daemon::ReadClearKeyFile(s.key_file);
  } catch (const std::runtime_error& e) {
    throw InputError(e.what());
  }
  lcm::LCM lcm(s.url);
  if (!lcm.good()) throw std::runtime_error("LCM: cannot start with URL '" + s.url + "'");
  pumptherm::alarm_clear_t m;
  m.pump = o.pump;
  m.node = o.node;
  m.source = s.source;
  m.comment = o.comment;
  m.utime = NowUs();
  m.counter = m.utime;  // grows by itself, on every host whose clock is inside the window
  daemon::ClearExchange x = daemon::SendClear(lcm, s.prefix, key, m, o.timeout_s);
  // Another sender's clock ran ahead: sign once more above the gateway's last counter.
  if (x.reply && x.reply->result == Reply::RESULT_REPLAYED) {
    m.utime = NowUs();
    m.counter = std::max(m.utime, x.reply->last_counter + 1);
    x = daemon::SendClear(lcm, s.prefix, key, m, o.timeout_s);
  }
  return Report(o.pump, x, s, o.timeout_s);
}

/// Loads the configuration's DBC and mapping, as the gateway does.
std::pair<protocol::Dbc, protocol::SignalMapping> LoadFrameSet(const daemon::DaemonConfig& c) {
  try {
    const std::string dbc_path =
        daemon::ResolveResource(daemon::ResourceKind::kDbc, c.dbc.file, c.dbc.base_dir);
    protocol::Dbc dbc = protocol::ParseDbc(daemon::ReadTextFile(dbc_path), dbc_path);
    const std::string map_path =
        daemon::ResolveResource(daemon::ResourceKind::kDbc, c.dbc.mapping, c.dbc.base_dir);
    protocol::SignalMapping mapping = protocol::ParseMapping(
        daemon::ReadTextFile(map_path), map_path, dbc, daemon::MappingOutputs());
    return {std::move(dbc), std::move(mapping)};
  } catch (const std::exception& e) {
    throw InputError(fmt::format("{}: {}", c.source, e.what()));
  }
}

double MonotonicS() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

/// Reads the pump's GW_ALARM frames until `until_s` (monotonic) or until `stop` is true of a
/// level seen; returns the last level seen.
template <typename Stop>
std::optional<GatewayAlarmLevel> ReadAlarmLevels(daemon::CanSocket& sock, const protocol::Dbc& dbc,
                                                 const protocol::SignalMapping& mapping,
                                                 std::uint32_t node_id, double until_s, Stop stop) {
  std::optional<GatewayAlarmLevel> last;
  for (double now = MonotonicS(); now < until_s; now = MonotonicS()) {
    pollfd pfd{sock.fd(), POLLIN, 0};
    if (::poll(&pfd, 1, static_cast<int>(std::ceil((until_s - now) * 1000.0))) <= 0) continue;
    protocol::TimedFrame tf;
    std::uint32_t drops = 0;
    while (sock.Receive(&tf, &drops) == daemon::RxStatus::kFrame) {
      if (const auto level = AlarmLevelOf(dbc, mapping, node_id, tf.frame)) last = level;
    }
    if (last && stop(*last)) break;
  }
  return last;
}

int RunCanClear(const ClearTripOptions& o, const daemon::DaemonConfig& c,
                const daemon::PumpConfig& pump, const std::string& interface) {
  if (!o.node.empty() || !o.comment.empty()) {
    fmt::print(
        stderr,
        "{}: note: PUMP_CLEAR carries no node and no comment: every latched trip of the pump is "
        "cleared, and the gateway logs the interface as the source\n",
        o.pump);
  }
  const auto [dbc, mapping] = LoadFrameSet(c);
  const protocol::CanFrame clear = EncodeClearFrame(dbc, mapping, pump.node_id);
  daemon::CanSocket sock;
  try {
    sock = daemon::CanSocket::Open(interface, false);
  } catch (const std::system_error& e) {
    throw std::runtime_error(
        fmt::format("{}: cannot open CAN interface '{}' to send PUMP_CLEAR: {}", o.pump, interface,
                    e.code().message()));
  }
  CanClearOutcome outcome;
  // GW_ALARM comes at 10 Hz: the level before the clear, if the gateway is there.
  outcome.before =
      ReadAlarmLevels(sock, dbc, mapping, pump.node_id, MonotonicS() + std::min(1.0, o.timeout_s),
                      [](GatewayAlarmLevel) { return true; });
  if (sock.Send(clear) != daemon::TxStatus::kSent) {
    throw std::runtime_error(
        fmt::format("{}: cannot send PUMP_CLEAR (errno {})", interface, sock.last_errno()));
  }
  // The gateway acts at once, but GW_ALARM shows it from its next thermal step on.
  const double start_s = MonotonicS();
  outcome.after =
      ReadAlarmLevels(sock, dbc, mapping, pump.node_id, start_s + o.timeout_s,
                      [](GatewayAlarmLevel l) { return l != GatewayAlarmLevel::kTrip; });
  const auto [code, text] =
      DescribeCanClear(o.pump, interface, outcome, std::round((MonotonicS() - start_s) * 10) / 10);
  fmt::print(code == 0 ? stdout : stderr, "{}\n", text);
  return code;
}

int RunClearTrip(const ClearTripOptions& o) {
  // Another host without the daemon's configuration: LCM with the URL and key given.
  if (!o.url.empty() && !o.key_file.empty() && ::access(o.config.c_str(), F_OK) != 0) {
    if (o.via == "can") throw InputError("--via can needs the daemon's configuration (-c)");
    return RunLcmClear(o, FromOptions(o));
  }
  const daemon::DaemonConfig c = LoadDaemonConfig(o);
  const daemon::PumpConfig& pump = FindPump(c, o);
  // --url/--key on the command line stand for the configuration's LCM settings.
  daemon::DaemonConfig routed = c;
  if (!o.url.empty()) routed.lcm.url = o.url;
  if (!o.key_file.empty()) routed.clear_auth.key_file = o.key_file;
  const ClearRouteChoice route = ChooseClearRoute(routed, pump, o.via);
  if (route.route == ClearRoute::kCan) return RunCanClear(o, c, pump, route.interface);
  return RunLcmClear(o, Resolve(o, c));
}

const SubcommandRegistrar kRegistrar{
    "clear-trip",
    "Clear a pump's latched trip through the gateway (signed LCM command, or PUMP_CLEAR on CAN)",
    [](CLI::App& app) -> std::function<int()> {
      auto o = std::make_shared<ClearTripOptions>();
      app.add_option("pump", o->pump, "Pump name from the daemon configuration")->required();
      app.add_option("-c,--config", o->config,
                     "The daemon configuration: LCM URL, key file, sources")
          ->capture_default_str();
      app.add_option("--key", o->key_file,
                     "Key file (default: alarms.clear_key_file of the configuration)");
      app.add_option("--url", o->url, "LCM URL (default: lcm.url of the configuration)");
      app.add_option("--prefix", o->prefix,
                     "LCM channel prefix (default: lcm.channel_prefix, or PUMPTHERM)");
      app.add_option("--source", o->source,
                     "Who clears (default: the first of alarms.clear_lcm_sources)");
      app.add_option("--node", o->node, "Node whose trip to clear (default: every latched trip)");
      app.add_option("--comment", o->comment, "Why; the gateway logs it");
      app.add_option(
             "--via", o->via,
             "lcm, can, or auto: LCM when the configuration has lcm.url and a clear key, else CAN "
             "when the pump's interface is in alarms.clear_can_interfaces")
          ->check(CLI::IsMember({"auto", "lcm", "can"}))
          ->capture_default_str();
      app.add_option("--timeout-s", o->timeout_s, "How long to wait for the gateway's answer")
          ->check(CLI::PositiveNumber)
          ->capture_default_str();
      app.footer(
          "Exit codes: 0 the gateway accepted the clear, 1 it refused or did not answer, 2 bad "
          "input.\n"
          "Without the configuration file, --url and --key are needed (LCM).\n"
          "On CAN there is no answer: the command reports the gateway's GW_ALARM level before the\n"
          "clear and after it (the trip gone within --timeout-s: exit 0).\n"
          "Example (as a member of the group that owns the key file):\n"
          "  pumptherm clear-trip tmp1 --comment 'bearing replaced'");
      return [o] { return RunClearTrip(*o); };
    }};

}  // namespace
}  // namespace pumptherm::tools
