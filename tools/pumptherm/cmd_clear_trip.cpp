// pumptherm clear-trip: clears a pump's latched trip through the gateway over LCM with a
// command signed with the clear key, and reports the gateway's signed answer
// (docs/threat-model.md; docs/lcm.md, "Clearing a trip").
#include <fmt/core.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <lcm/lcm-cpp.hpp>
#include <memory>

#include "daemon/alarm_clear_auth.hpp"
#include "daemon/config.hpp"
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

Settings Resolve(const ClearTripOptions& o) {
  if (!o.url.empty() && !o.key_file.empty() && ::access(o.config.c_str(), F_OK) != 0) return FromOptions(o);
  Settings s;
  daemon::DaemonConfig c;
  try {
    c = daemon::LoadConfig(o.config);
  } catch (const daemon::ConfigError& e) {
    throw InputError(fmt::format("{} (without the configuration, give --url and --key)", e.what()));
  }
  const bool known = std::any_of(c.pumps.begin(), c.pumps.end(), [&](const auto& p) { return p.name == o.pump; });
  if (!known) throw InputError(fmt::format("pump '{}' is not configured in {}", o.pump, o.config));
  s.url = o.url.empty() ? c.lcm.url : o.url;
  s.prefix = o.prefix.empty() ? c.lcm.channel_prefix : o.prefix;
  s.key_file = o.key_file.empty() ? c.clear_auth.key_file : o.key_file;
  s.key_group = c.clear_auth.key_group;
  const auto& sources = c.alarms.clear_lcm_sources;
  s.source = !o.source.empty() ? o.source : sources.empty() ? s.source : sources.front();
  if (s.url.empty()) throw InputError(fmt::format("{}: LCM is off (lcm.url is empty); give --url", o.config));
  if (s.key_file.empty()) {
    throw InputError(fmt::format("{}: no alarms.clear_key_file: LCM clears are off in this configuration", o.config));
  }
  return s;
}

std::int64_t NowUs() {
  timespec ts{};
  clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000 + ts.tv_nsec / 1000;
}

int Report(const std::string& pump, const daemon::ClearExchange& x, const Settings& s, double timeout_s) {
  if (!x.reply) {
    if (x.untrusted_replies > 0) {
      fmt::print(stderr, "{}: the gateway answered '{}', but not signed with {}: it holds another key (or none)\n",
                 pump, x.untrusted_reason, s.key_file);
    } else {
      fmt::print(stderr, "{}: no answer from the gateway within {} s on {} (is pumpthermd running there, "
                 "with this pump?)\n", pump, timeout_s, s.url);
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

int RunClearTrip(const ClearTripOptions& o) {
  const Settings s = Resolve(o);
  if (const std::string problem = daemon::ClearKeyFileProblem(s.key_file, s.key_group); !problem.empty()) {
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

const SubcommandRegistrar kRegistrar{
    "clear-trip", "Clear a pump's latched trip through the gateway (signed LCM command)",
    [](CLI::App& app) -> std::function<int()> {
      auto o = std::make_shared<ClearTripOptions>();
      app.add_option("pump", o->pump, "Pump name from the daemon configuration")->required();
      app.add_option("-c,--config", o->config, "The daemon configuration: LCM URL, key file, sources")
          ->capture_default_str();
      app.add_option("--key", o->key_file, "Key file (default: alarms.clear_key_file of the configuration)");
      app.add_option("--url", o->url, "LCM URL (default: lcm.url of the configuration)");
      app.add_option("--prefix", o->prefix, "LCM channel prefix (default: lcm.channel_prefix, or PUMPTHERM)");
      app.add_option("--source", o->source, "Who clears (default: the first of alarms.clear_lcm_sources)");
      app.add_option("--node", o->node, "Node whose trip to clear (default: every latched trip)");
      app.add_option("--comment", o->comment, "Why; the gateway logs it");
      app.add_option("--timeout-s", o->timeout_s, "How long to wait for the gateway's answer")
          ->check(CLI::PositiveNumber)
          ->capture_default_str();
      app.footer(
          "Exit codes: 0 the gateway accepted the clear, 1 it refused or did not answer, 2 bad input.\n"
          "Without the configuration file, --url and --key are needed.\n"
          "Example (as a member of the group that owns the key file):\n"
          "  pumptherm clear-trip tmp1 --comment 'bearing replaced'");
      return [o] { return RunClearTrip(*o); };
    }};

}  // namespace
}  // namespace pumptherm::tools
