// pumptherm replay LOG --config FILE [--levels NODE=W/T ...] [--pace X]: the daemon's pipeline
// (daemon::Gateway and RunOffline, as `pumpthermd -r` runs it) over a past recording with
// what-if alarm levels; per pump, when each alarm would have fired, the margin to each level and
// the time to trip at the worst moment. With --pace it publishes on LCM as it goes, so that
// `pumptherm watch` and pumptherm-spy follow the recording.
#include <fmt/chrono.h>
#include <fmt/core.h>

#include <CLI/CLI.hpp>
#include <cmath>
#include <ctime>
#include <fstream>
#include <lcm/lcm-cpp.hpp>
#include <limits>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "daemon/config.hpp"
#include "daemon/gateway.hpp"
#include "daemon/log.hpp"
#include "daemon/offline.hpp"
#include "tools/pumptherm/subcommand.hpp"

namespace pumptherm::tools {
namespace {

using daemon::DaemonConfig;
using daemon::Gateway;
using daemon::PumpSnapshot;

constexpr double kReplayNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();
/// Alarm changes listed per pump; the rest are counted.
constexpr std::size_t kListedEvents = 8;

struct ReplayOptions {
  std::string log;
  std::string config;
  std::vector<std::string> levels;  // [PUMP:]NODE=W/T
  double pace = 0.0;
  std::string lcm_url;
};

/// One --levels entry: NODE=W/T, W or T may be empty (unchanged), PUMP: restricts it to a pump.
struct LevelOverride {
  std::string pump;  // empty: every pump
  std::string node;
  double warning_degC = kReplayNaN, trip_degC = kReplayNaN;
};

double ParseLevel(const std::string& text, const std::string& arg) {
  if (text.empty()) return kReplayNaN;
  std::size_t used = 0;
  double v = kReplayNaN;
  try {
    v = std::stod(text, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used != text.size() || !std::isfinite(v))
    throw InputError(fmt::format("--levels {}: '{}' is not a temperature in degC", arg, text));
  return v;
}

LevelOverride ParseOverride(const std::string& arg) {
  LevelOverride o;
  const auto eq = arg.find('=');
  const auto slash = arg.find('/', eq == std::string::npos ? 0 : eq);
  if (eq == std::string::npos || slash == std::string::npos)
    throw InputError(
        fmt::format("--levels {}: expected NODE=WARNING/TRIP in degC (winding=95/115, sensor=/80, "
                    "pump3:winding=90/110)",
                    arg));
  std::string node = arg.substr(0, eq);
  if (const auto colon = node.find(':'); colon != std::string::npos) {
    o.pump = node.substr(0, colon);
    node = node.substr(colon + 1);
  }
  o.node = node;
  o.warning_degC = ParseLevel(arg.substr(eq + 1, slash - eq - 1), arg);
  o.trip_degC = ParseLevel(arg.substr(slash + 1), arg);
  if (o.node.empty()) throw InputError(fmt::format("--levels {}: no node name", arg));
  if (std::isnan(o.warning_degC) && std::isnan(o.trip_degC))
    throw InputError(fmt::format("--levels {}: neither a warning nor a trip level", arg));
  return o;
}

/// The configuration's levels with the overrides applied (a trip alone also warns at its level,
/// as in the configuration file).
void ApplyLevels(DaemonConfig& config, const std::vector<LevelOverride>& overrides) {
  for (const auto& o : overrides) {
    bool found = o.pump.empty();
    for (auto& pc : config.pumps) {
      if (!o.pump.empty() && pc.name != o.pump) continue;
      found = true;
      auto& l = pc.alarms.levels[o.node];
      if (!std::isnan(o.trip_degC)) l.limits.trip_degC = o.trip_degC;
      if (!std::isnan(o.warning_degC)) {
        l.limits.warning_degC = o.warning_degC;
      } else if (!(l.limits.warning_degC <= l.limits.trip_degC)) {
        l.limits.warning_degC = l.limits.trip_degC;
      }
      if (l.limits.trip_degC < l.limits.warning_degC)
        throw InputError(fmt::format("--levels: {} of {}: trip {} degC below warning {} degC",
                                     o.node, pc.name, l.limits.trip_degC, l.limits.warning_degC));
    }
    if (!found)
      throw InputError(fmt::format("--levels: no pump '{}' in {}", o.pump, config.source));
  }
}

/// The closest a value came to one level: least margin (level - bound, K) and when.
struct Margin {
  double least_K = kInf;
  double at_s = kReplayNaN;
  double first_crossed_s = kReplayNaN;  ///< when the bound first reached the level
};

/// Per level node of one pump, over the replay.
struct NodeWatch {
  std::string node;
  int state = -1;  ///< model node index; -1: "sensor" or "winding_resistance"
  estimators::TemperatureLimits limits;
  double peak_degC = -kInf, peak_at_s = kReplayNaN;
  Margin warning, trip;
  double time_to_trip_at_worst_s = kReplayNaN;
};

struct PumpWatch {
  std::vector<std::string> events;
  std::uint64_t event_count = 0;
  std::uint64_t alarm_changes = 0;
  estimators::AlarmLevel level = estimators::AlarmLevel::kNone;
  estimators::AlarmReason reason = estimators::AlarmReason::kNone;
  int node = -1;
  double first_warning_s = kReplayNaN, first_trip_s = kReplayNaN;
  double least_ttt_s = kInf, least_ttt_at_s = kReplayNaN;
  std::vector<NodeWatch> nodes;
};

/// The value and sd the levels of `w` act on at this step (NaN: not known now).
void ValueOf(const PumpSnapshot& s, const NodeWatch& w, double& x, double& sd) {
  x = kReplayNaN;
  sd = 0.0;
  if (w.state >= 0) {
    if (!s.initialised) return;
    x = s.node_degC[static_cast<std::size_t>(w.state)];
    sd = s.node_sd_K[static_cast<std::size_t>(w.state)];
  } else if (w.node == "sensor") {
    x = s.frame_measured_degC;
  } else {
    x = s.winding_resistance_degC;
  }
}

void Track(Margin& m, double margin_K, double t_s) {
  if (margin_K < m.least_K) {
    m.least_K = margin_K;
    m.at_s = t_s;
  }
  if (margin_K <= 0 && std::isnan(m.first_crossed_s)) m.first_crossed_s = t_s;
}

class Watcher {
 public:
  Watcher(const Gateway& gateway) {
    for (const auto& p : gateway.pumps()) {
      PumpWatch pw;
      for (const auto& [node, lc] : p->config().alarms.levels) {
        NodeWatch w;
        w.node = node;
        w.state = p->model().StateIndex(node);
        w.limits = lc.limits;
        pw.nodes.push_back(w);
      }
      pumps_.push_back(std::move(pw));
    }
  }

  void Step(const Gateway& g, std::int64_t now_us) {
    if (start_us_ < 0) start_us_ = now_us;
    const double t = static_cast<double>(now_us - start_us_) * 1e-6;
    for (std::size_t p = 0; p < pumps_.size(); ++p) {
      const auto& pump = *g.pumps()[p];
      const PumpSnapshot& s = pump.snapshot();
      PumpWatch& pw = pumps_[p];
      Events(pump, s, t, pw);
      const auto& m = pump.config().alarms.monitor;
      for (NodeWatch& w : pw.nodes) {
        double x, sd;
        ValueOf(s, w, x, sd);
        if (!std::isfinite(x)) continue;
        if (x > w.peak_degC) {
          w.peak_degC = x;
          w.peak_at_s = t;
        }
        const double sd_used = std::isfinite(sd) ? sd : 0.0;
        if (std::isfinite(w.limits.warning_degC))
          Track(w.warning, w.limits.warning_degC - (x + m.warning_sd_factor * sd_used), t);
        if (std::isfinite(w.limits.trip_degC)) {
          const double before = w.trip.least_K;
          Track(w.trip, w.limits.trip_degC - (x + m.trip_sd_factor * sd_used), t);
          if (w.trip.least_K < before) w.time_to_trip_at_worst_s = s.alarm.time_to_trip_s;
        }
      }
      if (std::isfinite(s.alarm.time_to_trip_s) && s.alarm.time_to_trip_s < pw.least_ttt_s) {
        pw.least_ttt_s = s.alarm.time_to_trip_s;
        pw.least_ttt_at_s = t;
      }
    }
  }

  const std::vector<PumpWatch>& pumps() const { return pumps_; }
  std::int64_t start_us() const { return start_us_; }

 private:
  void Events(const daemon::Pump& pump, const PumpSnapshot& s, double t, PumpWatch& pw) {
    if (s.alarm_changes == pw.alarm_changes) return;
    pw.alarm_changes = s.alarm_changes;
    if (s.alarm.level == pw.level && s.alarm.reason == pw.reason && s.alarm.node == pw.node) return;
    pw.level = s.alarm.level;
    pw.reason = s.alarm.reason;
    pw.node = s.alarm.node;
    // A trip is also a warning (as the alarm level counts): the first moment at either.
    if (s.alarm.level >= estimators::AlarmLevel::kWarning && std::isnan(pw.first_warning_s))
      pw.first_warning_s = t;
    if (s.alarm.level == estimators::AlarmLevel::kTrip && std::isnan(pw.first_trip_s))
      pw.first_trip_s = t;
    ++pw.event_count;
    if (pw.events.size() >= kListedEvents) return;
    const auto& names = pump.model().StateNames();
    std::string node = "-";
    if (s.alarm.node >= 0 && static_cast<std::size_t>(s.alarm.node) < names.size())
      node = names[static_cast<std::size_t>(s.alarm.node)];
    else if (s.alarm.node >= 0)
      node = "winding_resistance";
    pw.events.push_back(fmt::format(
        "{:.0f} s {} ({}, {}, value {:.2f})", t, estimators::AlarmLevelName(s.alarm.level),
        estimators::AlarmReasonName(s.alarm.reason), node, s.alarm.value));
  }

  std::vector<PumpWatch> pumps_;
  std::int64_t start_us_ = -1;
};

std::string Seconds(double s) {
  return std::isnan(s) ? std::string("never") : fmt::format("{:.0f} s", s);
}

std::string MarginText(const Margin& m, const char* what, double level) {
  if (!std::isfinite(level)) return "";
  if (!std::isfinite(m.least_K)) return fmt::format("{} {:.1f}: no value", what, level);
  return fmt::format(
      "{} {:.1f}: least margin {:+.2f} K at {:.0f} s{}", what, level, m.least_K, m.at_s,
      std::isnan(m.first_crossed_s) ? std::string()
                                    : fmt::format(", reached at {:.0f} s", m.first_crossed_s));
}

void PrintReport(const Gateway& g, const Watcher& w, const daemon::OfflineResult& r) {
  const double duration_s = static_cast<double>(r.last_us - r.first_us) * 1e-6;
  std::string start = "s since the recording's start";
  if (r.time_base == protocol::CandumpTimeBase::kAbsolute && w.start_us() >= 0) {
    const std::time_t t0 = static_cast<std::time_t>(w.start_us() / 1000000);
    start = fmt::format("s since {:%Y-%m-%d %H:%M:%S} UTC", fmt::gmtime(t0));
  }
  fmt::print("replay: {} frames, {:.0f} s; times in {}\n", r.frames, duration_s, start);
  for (std::size_t p = 0; p < g.pumps().size(); ++p) {
    const auto& pump = *g.pumps()[p];
    const PumpWatch& pw = w.pumps()[p];
    const auto& pm = pump.config().alarms.monitor;
    fmt::print("\n{} (node {} on {}; trip on x + {} sd, warning on x + {} sd)\n",
               pump.config().name, pump.config().node_id, pump.config().interface,
               pm.trip_sd_factor, pm.warning_sd_factor);
    fmt::print("  first warning (or trip): {}; first trip: {}\n", Seconds(pw.first_warning_s),
               Seconds(pw.first_trip_s));
    for (const auto& e : pw.events) fmt::print("    {}\n", e);
    if (pw.event_count > pw.events.size())
      fmt::print("    ... {} more alarm changes\n", pw.event_count - pw.events.size());
    for (const NodeWatch& n : pw.nodes) {
      fmt::print("  {}: peak {}\n", n.node,
                 std::isfinite(n.peak_degC)
                     ? fmt::format("{:.2f} degC at {:.0f} s", n.peak_degC, n.peak_at_s)
                     : std::string("never known"));
      if (const auto t = MarginText(n.warning, "warning", n.limits.warning_degC); !t.empty())
        fmt::print("    {}\n", t);
      if (const auto t = MarginText(n.trip, "trip", n.limits.trip_degC); !t.empty())
        fmt::print("    {}; forecast time to trip then: {}\n", t,
                   std::isfinite(n.time_to_trip_at_worst_s)
                       ? fmt::format("{:.0f} s", n.time_to_trip_at_worst_s)
                       : std::string("none (no trip ahead at that load)"));
    }
    fmt::print("  least forecast time to trip: {}\n",
               std::isfinite(pw.least_ttt_s)
                   ? fmt::format("{:.0f} s at {:.0f} s", pw.least_ttt_s, pw.least_ttt_at_s)
                   : std::string("none (no trip ahead at any moment)"));
  }
}

int RunReplay(const ReplayOptions& o) {
  DaemonConfig config;
  try {
    config = daemon::LoadConfig(o.config);
  } catch (const daemon::ConfigError& e) {
    throw InputError(e.what());
  }
  std::vector<LevelOverride> overrides;
  for (const auto& l : o.levels) overrides.push_back(ParseOverride(l));
  ApplyLevels(config, overrides);
  if (config.pumps.empty()) throw InputError(fmt::format("{}: no [[pump]] to replay", o.config));
  std::unique_ptr<Gateway> gateway;
  try {
    gateway = std::make_unique<Gateway>(config);
  } catch (const daemon::ConfigError& e) {
    throw InputError(e.what());
  }
  daemon::OfflineOptions offline;
  offline.pace = o.pace;
  std::unique_ptr<lcm::LCM> lcm;
  if (o.pace > 0.0) {
    const std::string url = o.lcm_url.empty() ? config.lcm.url : o.lcm_url;
    if (url.empty())
      throw InputError("--pace publishes on LCM: give --lcm-url or set lcm.url in " + o.config);
    lcm = std::make_unique<lcm::LCM>(url);
    if (!lcm->good()) throw std::runtime_error(fmt::format("LCM: cannot open '{}'", url));
    offline.lcm_publish = lcm.get();
    fmt::print(stderr, "replay: publishing on {} at {}x (pumptherm watch --lcm-url '{}')\n", url,
               o.pace, url);
  }
  Watcher watcher(*gateway);
  offline.after_advance = [&](const Gateway& g, std::int64_t now) { watcher.Step(g, now); };
  std::ifstream in = daemon::OpenLog(o.log);
  const daemon::OfflineResult r = daemon::RunOffline(in, o.log, *gateway, offline);
  daemon::RequireFrames(r, o.log);
  PrintReport(*gateway, watcher, r);
  return 0;
}

const SubcommandRegistrar kReplayRegistrar{
    "replay",
    "the daemon's pipeline over a past recording with what-if alarm levels: when each alarm "
    "would have fired, margins, time to trip",
    [](CLI::App& app) {
      auto o = std::make_shared<ReplayOptions>();
      app.add_option("LOG", o->log, "candump recording (any format pumpthermd -r reads)")
          ->required();
      app.add_option("--config", o->config, "the daemon's configuration (pumps, models, levels)")
          ->required();
      app.add_option("--levels", o->levels,
                     "what-if levels, degC: NODE=WARNING/TRIP for every pump, PUMP:NODE=W/T for "
                     "one; either may be left empty (sensor=/80); repeatable");
      app.add_option("--pace", o->pace,
                     "log seconds per wall second, publishing on LCM as it goes (0: as fast as "
                     "possible, no LCM)")
          ->check(CLI::NonNegativeNumber);
      app.add_option("--lcm-url", o->lcm_url,
                     "with --pace: LCM URL (default: the config's lcm.url)");
      app.footer(
          "Times are seconds since the recording's first frame. A margin is the level minus the\n"
          "bound the level acts on (estimate + k sd, alarms.trip_sd_factor and\n"
          "warning_sd_factor); negative: the level was reached. Example:\n"
          "  pumptherm replay demo.log --config pumpthermd.toml --levels winding=95/110\n"
          "  pumptherm replay demo.log --config pumpthermd.toml --pace 20 &\n"
          "  pumptherm watch --lcm-url 'udpm://239.255.76.67:7667?ttl=0'");
      return [o] { return RunReplay(*o); };
    }};

}  // namespace
}  // namespace pumptherm::tools
