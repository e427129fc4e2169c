// pumptherm clear-trip: clears a pump's latched trip through the gateway the way its
// configuration authorises: over LCM with a command signed with the operator's own key,
// reporting the gateway's signed answer (docs/threat-model.md; docs/lcm.md, "Clearing a trip"),
// or with a PUMP_CLEAR frame on the pump's CAN interface, reporting the gateway's GW_ALARM level
// before and after (docs/protocol.md).
#include <fmt/core.h>
#include <poll.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
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
  std::string gateway;
  std::string gateway_key;
  std::string url;
  std::string prefix;
  std::string node;
  std::string comment;
  std::string shared_key;
  std::string source;
  std::string via = "auto";
  double timeout_s = 5.0;
};

/// The operator's key unless --key names another: ~/.config/pumptherm/operator.key.
std::string DefaultKeyFile() {
  const char* config_home = std::getenv("XDG_CONFIG_HOME");
  const char* home = std::getenv("HOME");
  if (config_home && *config_home) return std::string(config_home) + "/pumptherm/operator.key";
  return std::string(home ? home : ".") + "/.config/pumptherm/operator.key";
}

/// What the command needs, from the daemon's configuration and the options over it.
struct Settings {
  std::string url, prefix = "PUMPTHERM", gateway = "pumptherm", gateway_key, key_file;
  std::string shared_key, key_group, source = "operator";  // the earlier scheme (migration)
};

/// The options over `s` (the configuration's settings, or the defaults).
Settings Override(Settings s, const ClearTripOptions& o) {
  if (!o.url.empty()) s.url = o.url;
  if (!o.prefix.empty()) s.prefix = o.prefix;
  if (!o.gateway.empty()) s.gateway = o.gateway;
  if (!o.gateway_key.empty()) s.gateway_key = o.gateway_key;
  s.key_file = o.key_file.empty() ? DefaultKeyFile() : o.key_file;
  if (!o.shared_key.empty()) s.shared_key = o.shared_key;
  if (!o.source.empty()) s.source = o.source;
  return s;
}

daemon::DaemonConfig LoadDaemonConfig(const ClearTripOptions& o) {
  try {
    return daemon::LoadConfig(o.config);
  } catch (const daemon::ConfigError& e) {
    throw InputError(fmt::format(
        "{} (without the configuration, give --url, --gateway and --gateway-key)", e.what()));
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
  s.url = c.lcm.url;
  s.prefix = c.lcm.channel_prefix;
  s.gateway = c.gateway.name;
  if (!c.gateway.signing_key_file.empty())
    s.gateway_key = daemon::PublicKeyPathOf(c.gateway.signing_key_file);
  if (c.clear_auth.allow_shared_key) s.shared_key = c.clear_auth.key_file;
  s.key_group = c.clear_auth.key_group;
  if (!c.alarms.clear_lcm_sources.empty()) s.source = c.alarms.clear_lcm_sources.front();
  s = Override(s, o);
  if (s.url.empty())
    throw InputError(fmt::format("{}: LCM is off (lcm.url is empty); give --url", o.config));
  if (s.gateway_key.empty()) {
    throw InputError(fmt::format(
        "{}: no gateway.signing_key_file: LCM clears are off in this configuration (or give "
        "--gateway-key)",
        o.config));
  }
  return s;
}

std::int64_t ClearTripNowUs() {
  timespec ts{};
  clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000 + ts.tv_nsec / 1000;
}

int Report(const std::string& pump, const daemon::ClearExchange& x, const Settings& s,
           double timeout_s) {
  if (!x.reply) {
    if (x.untrusted_replies > 0) {
      fmt::print(stderr,
                 "{}: an answer '{}' came, but not signed by the key of {}: not from gateway "
                 "'{}'\n",
                 pump, x.untrusted_reason, s.gateway_key, s.gateway);
    } else {
      fmt::print(stderr,
                 "{}: no answer from gateway '{}' within {} s on {}: it answers only commands "
                 "signed by a key it lists (its journal says why it refused one), or it is not "
                 "running there with this pump\n",
                 pump, s.gateway, timeout_s, s.url);
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

/// Signs `m` with the operator's key (or, for a migration, the shared key).
void SignFor(const Settings& s, const daemon::PublicKey& gateway, pumptherm::alarm_clear_t& m) {
  if (!s.shared_key.empty()) {
    if (const std::string problem = daemon::ClearKeyFileProblem(s.shared_key, s.key_group);
        !problem.empty()) {
      throw InputError(problem);
    }
    try {
      daemon::SignCommandShared(daemon::ReadClearKeyFile(s.shared_key), s.source, s.prefix, m);
    } catch (const std::runtime_error& e) {
      throw InputError(e.what());
    }
    return;
  }
  if (const std::string problem =
          daemon::SecretKeyFileProblem(s.key_file, daemon::KeyOwner::kCaller);
      !problem.empty()) {
    throw InputError(fmt::format("{} (pumptherm keygen {} makes your key)", problem, s.key_file));
  }
  try {
    daemon::SignCommand(daemon::ReadSecretKeyFile(s.key_file), gateway, s.prefix, m);
  } catch (const std::runtime_error& e) {
    throw InputError(e.what());
  }
}

int RunLcmClear(const ClearTripOptions& o, const Settings& s) {
  daemon::PublicKey gateway{};
  try {
    gateway = daemon::ReadPublicKeyFile(s.gateway_key);
  } catch (const std::runtime_error& e) {
    throw InputError(fmt::format("the gateway's public key: {}", e.what()));
  }
  pumptherm::alarm_clear_t m;
  m.gateway = s.gateway;
  m.pump = o.pump;
  m.node = o.node;
  m.comment = o.comment;
  m.utime = ClearTripNowUs();
  m.counter = m.utime;  // grows by itself while this host's clock does
  SignFor(s, gateway, m);
  lcm::LCM lcm(s.url);
  if (!lcm.good()) throw std::runtime_error("LCM: cannot start with URL '" + s.url + "'");
  const daemon::ClearExchange x = daemon::SendClear(lcm, s.prefix, gateway, m, o.timeout_s);
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
  // Another host without the daemon's configuration: LCM with the URL and the gateway given.
  if (!o.url.empty() && !o.gateway_key.empty() && ::access(o.config.c_str(), F_OK) != 0) {
    if (o.via == "can") throw InputError("--via can needs the daemon's configuration (-c)");
    if (o.gateway.empty()) throw InputError("--gateway NAME: the gateway's gateway.name");
    return RunLcmClear(o, Override(Settings{}, o));
  }
  const daemon::DaemonConfig c = LoadDaemonConfig(o);
  const daemon::PumpConfig& pump = FindPump(c, o);
  // --url/--gateway-key on the command line stand for the configuration's LCM settings.
  daemon::DaemonConfig routed = c;
  if (!o.url.empty()) routed.lcm.url = o.url;
  if (!o.gateway_key.empty() && routed.gateway.signing_key_file.empty())
    routed.gateway.signing_key_file = o.gateway_key;
  const ClearRouteChoice route = ChooseClearRoute(routed, pump, o.via);
  if (route.route == ClearRoute::kCan) return RunCanClear(o, c, pump, route.interface);
  return RunLcmClear(o, Resolve(o, c));
}

const SubcommandRegistrar kClearTripRegistrar{
    "clear-trip",
    "Clear a pump's latched trip through the gateway (signed LCM command, or PUMP_CLEAR on CAN)",
    [](CLI::App& app) -> std::function<int()> {
      auto o = std::make_shared<ClearTripOptions>();
      app.add_option("pump", o->pump, "Pump name from the daemon configuration")->required();
      app.add_option("-c,--config", o->config,
                     "The daemon configuration: LCM URL, prefix, gateway name and key")
          ->capture_default_str();
      app.add_option("--key", o->key_file,
                     "Your secret key (pumptherm keygen; default: "
                     "~/.config/pumptherm/operator.key)");
      app.add_option("--gateway", o->gateway,
                     "The gateway's name (default: gateway.name of the configuration)");
      app.add_option("--gateway-key", o->gateway_key,
                     "The gateway's public key file (default: gateway.signing_key_file + .pub)");
      app.add_option("--url", o->url, "LCM URL (default: lcm.url of the configuration)");
      app.add_option("--prefix", o->prefix,
                     "LCM channel prefix (default: lcm.channel_prefix, or PUMPTHERM)");
      app.add_option("--node", o->node,
                     "Alarm node whose latched trip to clear (default: every latched trip)");
      app.add_option("--shared-key", o->shared_key,
                     "Sign with the shared key of the earlier scheme instead (migration; the "
                     "gateway needs alarms.clear_allow_shared_key)");
      app.add_option("--source", o->source,
                     "With --shared-key: the source to claim (default: the first of "
                     "alarms.clear_lcm_sources)");
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
          "Without the configuration file, --url, --gateway and --gateway-key are needed (LCM).\n"
          "On CAN there is no answer: the command reports the gateway's GW_ALARM level before the\n"
          "clear and after it (the trip gone within --timeout-s: exit 0).\n"
          "Example (with your key listed in the gateway's alarms.clear_operators):\n"
          "  pumptherm clear-trip tmp1 --comment 'bearing replaced'");
      return [o] { return RunClearTrip(*o); };
    }};

}  // namespace
}  // namespace pumptherm::tools
