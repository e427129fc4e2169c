// pumptherm watch: the live view of every pump from the gateway's LCM messages, from any host
// that receives the LCM group (the daemon's lcm.url with ttl=1 reaches the LAN segment): one line
// per pump, or `watch PUMP` for everything known of one pump. The URL and channel prefix come
// from the gateway's configuration, as for `pumptherm clear-trip`.
#include <fmt/core.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <lcm/lcm-cpp.hpp>
#include <map>
#include <memory>
#include <optional>

#include "daemon/clear_keys.hpp"
#include "daemon/config.hpp"
#include "protocol/lcm/channels.hpp"
#include "pumptherm/gateway_digest_t.hpp"
#include "tools/pumptherm/subcommand.hpp"
#include "tools/pumptherm/watch.hpp"
#include "tools/pumptherm/watch_digest.hpp"

namespace pumptherm::tools {
namespace {

struct WatchOptions {
  std::string pump;  ///< empty: every pump, one line each
  std::string config = "/etc/pumptherm/pumpthermd.toml";
  std::string url;
  std::string old_url;  ///< --lcm-url, the earlier name of --url
  std::string prefix;
  double period_s = 5.0;
  int count = 0;
  double stale_after_s = 15.0;
  std::string gateway_key;  // the gateway's public key file: mark what it did not sign
};

/// Where to listen: from the options, over the gateway's configuration when it can be read.
struct WatchSettings {
  std::string url, prefix{lcm_channels::kDefaultPrefix};
  std::map<std::string, std::string> measured_nodes;  ///< pump -> the node its sensor measures
};

WatchSettings Resolve(const WatchOptions& o) {
  WatchSettings s;
  s.url = o.url;
  // A host without the gateway's configuration: the URL given is enough.
  if (!o.url.empty() && ::access(o.config.c_str(), F_OK) != 0) {
    if (!o.prefix.empty()) s.prefix = o.prefix;
    return s;
  }
  daemon::DaemonConfig c;
  try {
    c = daemon::LoadConfig(o.config);
  } catch (const daemon::ConfigError& e) {
    throw InputError(fmt::format("{} (without the configuration, give --url)", e.what()));
  }
  if (s.url.empty()) s.url = c.lcm.url;
  if (s.url.empty())
    throw InputError(fmt::format("{}: LCM is off (lcm.url is empty); give --url", o.config));
  s.prefix = o.prefix.empty() ? c.lcm.channel_prefix : o.prefix;
  for (const auto& p : c.pumps) s.measured_nodes[p.name] = p.measured_node;
  return s;
}

std::int64_t NowUs() {
  return std::chrono::duration_cast<std::chrono::microseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

struct Receiver {
  PumpWatch watch;
  std::unique_ptr<DigestCheck> check;  // with --gateway-key
  void OnTemps(const lcm::ReceiveBuffer* rbuf, const std::string& channel,
               const pumptherm::temperatures_t* m) {
    watch.OnTemperatures(*m, NowUs());
    if (check) check->OnMessage(channel, rbuf->data, rbuf->data_size, NowUs());
  }
  void OnAlarm(const lcm::ReceiveBuffer* rbuf, const std::string& channel,
               const pumptherm::alarm_t* m) {
    watch.OnAlarm(*m, NowUs());
    if (check) check->OnMessage(channel, rbuf->data, rbuf->data_size, NowUs());
  }
  void OnDigest(const lcm::ReceiveBuffer*, const std::string&,
                const pumptherm::gateway_digest_t* d) {
    if (check) check->OnDigest(*d, NowUs());
  }
  void OnTelemetry(const lcm::ReceiveBuffer*, const std::string&, const pumptherm::telemetry_t* m) {
    watch.OnTelemetry(*m, NowUs());
  }
};

/// Per pump: whether the gateway signed its latest TEMPS and ALARM (--gateway-key).
std::map<std::string, std::string> SignatureMarks(const Receiver& rx, const std::string& prefix) {
  using lcm_channels::PumpChannel;
  using V = DigestCheck::Verdict;
  std::map<std::string, std::string> marks;
  if (!rx.check) return marks;
  for (const std::string& pump : rx.watch.Pumps()) {
    const V t =
        rx.check->Latest(lcm_channels::PumpChannelName(prefix, pump, PumpChannel::kTemperatures));
    const V a = rx.check->Latest(lcm_channels::PumpChannelName(prefix, pump, PumpChannel::kAlarm));
    if (t == V::kNotSigned || a == V::kNotSigned) {
      marks[pump] = "NOT FROM THE GATEWAY (no signed digest lists it)";
    } else if (!rx.check->any_digest()) {
      marks[pump] = "unverified (no signed digest from the gateway yet)";
    } else if ((t == V::kSigned || t == V::kNone) && (a == V::kSigned || a == V::kNone)) {
      marks[pump] = "signed";
    } else {
      marks[pump] = "signature pending";
    }
  }
  return marks;
}

int RunWatch(WatchOptions o) {
  if (!(o.period_s > 0.0)) throw InputError("--period-s must be positive");
  if (!o.old_url.empty()) {
    fmt::print(stderr, "watch: --lcm-url is now called --url (as in clear-trip)\n");
    if (o.url.empty()) o.url = o.old_url;
  }
  const WatchSettings s = Resolve(o);
  if (!lcm_channels::IsValidPrefix(s.prefix))
    throw InputError("--prefix: invalid channel prefix '" + s.prefix + "'");
  lcm::LCM lcm(s.url);
  if (!lcm.good()) throw std::runtime_error("LCM: cannot start with URL '" + s.url + "'");
  Receiver rx;
  for (const auto& [pump, node] : s.measured_nodes) rx.watch.SetMeasuredNode(pump, node);
  if (!o.gateway_key.empty()) {
    try {
      rx.check = std::make_unique<DigestCheck>(daemon::ReadPublicKeyFile(o.gateway_key), s.prefix);
    } catch (const std::runtime_error& e) {
      throw InputError(fmt::format("--gateway-key: {}", e.what()));
    }
    lcm.subscribe(lcm_channels::GatewayDigestChannelName(s.prefix), &Receiver::OnDigest, &rx);
  }
  using lcm_channels::PumpChannel;
  lcm.subscribe(lcm_channels::AllPumpsPattern(s.prefix, PumpChannel::kTemperatures),
                &Receiver::OnTemps, &rx);
  lcm.subscribe(lcm_channels::AllPumpsPattern(s.prefix, PumpChannel::kAlarm), &Receiver::OnAlarm,
                &rx);
  lcm.subscribe(lcm_channels::AllPumpsPattern(s.prefix, PumpChannel::kTelemetry),
                &Receiver::OnTelemetry, &rx);
  fmt::print("watching {}{} on {} (every {} s; Ctrl-C ends)\n", s.prefix,
             o.pump.empty() ? "" : "/" + o.pump, s.url.empty() ? "LCM's default URL" : s.url,
             o.period_s);
  std::fflush(stdout);
  const auto period_us = static_cast<std::int64_t>(o.period_s * 1e6);
  std::int64_t next_us = NowUs() + period_us;
  for (int shown = 0; o.count == 0 || shown < o.count;) {
    const std::int64_t wait_us = next_us - NowUs();
    if (wait_us > 0) {
      if (lcm.handleTimeout(static_cast<int>(std::max<std::int64_t>(1, wait_us / 1000))) < 0) {
        throw std::runtime_error("LCM: receive failed");
      }
      continue;
    }
    const std::int64_t now = NowUs();
    if (rx.watch.PumpCount() == 0) {
      fmt::print("no pumptherm messages yet under {}/<pump>/TEMPS, ALARM or TELEMETRY\n", s.prefix);
    } else if (o.pump.empty()) {
      fmt::print("\n{}", rx.watch.Table(now, o.stale_after_s, SignatureMarks(rx, s.prefix)));
    } else {
      const auto marks = SignatureMarks(rx, s.prefix);
      const auto mark = marks.find(o.pump);
      fmt::print("\n{}{}", rx.watch.Detail(o.pump, now, o.stale_after_s),
                 mark == marks.end() ? std::string() : "messages: " + mark->second + "\n");
    }
    std::fflush(stdout);
    ++shown;
    next_us += period_us;
  }
  return (o.pump.empty() ? rx.watch.PumpCount() > 0 : rx.watch.Has(o.pump)) ? 0 : 1;
}

const SubcommandRegistrar kWatchRegistrar{
    "watch",
    "live view of every pump (or of one) from the gateway's LCM messages (any host on the LAN)",
    [](CLI::App& app) {
      auto o = std::make_shared<WatchOptions>();
      app.add_option("pump", o->pump,
                     "show everything known of this pump (default: one line per pump)");
      app.add_option("-c,--config", o->config,
                     "the gateway's configuration: LCM URL, channel prefix, measured nodes")
          ->capture_default_str();
      app.add_option("--url", o->url, "LCM URL (default: lcm.url of the configuration)");
      app.add_option("--lcm-url", o->old_url, "the earlier name of --url")->group("");
      app.add_option("--prefix", o->prefix,
                     "channel prefix (default: lcm.channel_prefix of the configuration, or "
                     "PUMPTHERM)");
      app.add_option("--period-s", o->period_s, "seconds between views")->capture_default_str();
      app.add_option("--count", o->count, "views to print, then exit (0: until interrupted)")
          ->capture_default_str();
      app.add_option("--stale-after-s", o->stale_after_s,
                     "mark a pump STALE after this long silent")
          ->capture_default_str();
      app.add_option("--gateway-key", o->gateway_key,
                     "the gateway's public key file (gateway.signing_key_file + .pub): mark each "
                     "pump whose messages the gateway's signed digests do not list");
      app.footer(
          "Examples:\n"
          "  pumptherm watch                  (on the gateway: its configuration's URL)\n"
          "  pumptherm watch pump3 --period-s 2\n"
          "  pumptherm watch --url 'udpm://239.255.76.67:7667?ttl=1'   (another host)\n"
          "Without the configuration file, --url is needed.\n"
          "Exit status: 0 after --count views with a pump (the pump) heard, 1 if none was, 2 bad "
          "input.");
      return [o] { return RunWatch(*o); };
    }};

}  // namespace
}  // namespace pumptherm::tools
