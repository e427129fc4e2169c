// pumptherm watch: the live table of every pump from the gateway's LCM messages, from any host
// that receives the LCM group (the daemon's lcm.url with ttl=1 reaches the LAN segment).
#include <fmt/core.h>

#include <chrono>
#include <cstdio>
#include <lcm/lcm-cpp.hpp>
#include <map>
#include <memory>
#include <optional>

#include "daemon/clear_keys.hpp"
#include "protocol/lcm/channels.hpp"
#include "pumptherm/gateway_digest_t.hpp"
#include "tools/pumptherm/subcommand.hpp"
#include "tools/pumptherm/watch.hpp"
#include "tools/pumptherm/watch_digest.hpp"

namespace pumptherm::tools {
namespace {

struct WatchOptions {
  std::string lcm_url;
  std::string prefix{lcm_channels::kDefaultPrefix};
  double period_s = 5.0;
  int count = 0;
  double stale_after_s = 15.0;
  std::string gateway_key;  // the gateway's public key file: mark what it did not sign
};

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

int RunWatch(const WatchOptions& o) {
  if (!(o.period_s > 0.0)) throw InputError("--period-s must be positive");
  if (!lcm_channels::IsValidPrefix(o.prefix))
    throw InputError("--prefix: invalid channel prefix '" + o.prefix + "'");
  lcm::LCM lcm(o.lcm_url);
  if (!lcm.good()) throw std::runtime_error("LCM: cannot start with URL '" + o.lcm_url + "'");
  Receiver rx;
  if (!o.gateway_key.empty()) {
    try {
      rx.check = std::make_unique<DigestCheck>(daemon::ReadPublicKeyFile(o.gateway_key), o.prefix);
    } catch (const std::runtime_error& e) {
      throw InputError(fmt::format("--gateway-key: {}", e.what()));
    }
    lcm.subscribe(lcm_channels::GatewayDigestChannelName(o.prefix), &Receiver::OnDigest, &rx);
  }
  lcm.subscribe(lcm_channels::AllPumpsPattern(o.prefix, lcm_channels::PumpChannel::kTemperatures),
                &Receiver::OnTemps, &rx);
  lcm.subscribe(lcm_channels::AllPumpsPattern(o.prefix, lcm_channels::PumpChannel::kAlarm),
                &Receiver::OnAlarm, &rx);
  fmt::print("watching {} on {} (a table every {} s; Ctrl-C ends)\n", o.prefix,
             o.lcm_url.empty() ? "LCM's default URL" : o.lcm_url, o.period_s);
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
      fmt::print("no pumptherm messages yet under {}/<pump>/TEMPS or ALARM\n", o.prefix);
    } else {
      fmt::print("\n{}", rx.watch.Table(now, o.stale_after_s, SignatureMarks(rx, o.prefix)));
    }
    std::fflush(stdout);
    ++shown;
    next_us += period_us;
  }
  return rx.watch.PumpCount() > 0 ? 0 : 1;
}

const SubcommandRegistrar kRegistrar{
    "watch", "live table of every pump from the gateway's LCM messages (any host on the LAN)",
    [](CLI::App& app) {
      auto o = std::make_shared<WatchOptions>();
      app.add_option("--lcm-url", o->lcm_url,
                     "LCM URL, as the gateway's lcm.url (default: LCM's default, LCM_DEFAULT_URL)");
      app.add_option("--prefix", o->prefix, "channel prefix, as the gateway's lcm.channel_prefix")
          ->capture_default_str();
      app.add_option("--period-s", o->period_s, "seconds between tables")->capture_default_str();
      app.add_option("--count", o->count, "tables to print, then exit (0: until interrupted)")
          ->capture_default_str();
      app.add_option("--stale-after-s", o->stale_after_s,
                     "mark a pump STALE after this long silent")
          ->capture_default_str();
      app.add_option("--gateway-key", o->gateway_key,
                     "the gateway's public key file (gateway.signing_key_file + .pub): mark each "
                     "pump whose messages the gateway's signed digests do not list");
      app.footer(
          "Example: pumptherm watch --lcm-url 'udpm://239.255.76.67:7667?ttl=1' --period-s 2\n"
          "Exit status: 0 after --count tables with at least one pump heard, 1 if none was heard.");
      return [o] { return RunWatch(*o); };
    }};

}  // namespace
}  // namespace pumptherm::tools
