// The gateway's terminal output: the systemd status line and the per-pump table.
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <ctime>
#include <limits>

#include "daemon/gateway.hpp"
#include "daemon/operator_text.hpp"

namespace pumptherm::daemon {

std::string Gateway::StatusLine() const {
  int warnings = 0;
  int trips = 0;
  int never_heard = 0;
  for (const auto& p : pumps_) {
    warnings += p->snapshot().alarm.level == estimators::AlarmLevel::kWarning;
    trips += p->snapshot().alarm.level == estimators::AlarmLevel::kTrip;
    never_heard += p->last_frame_us() < 0;
  }
  std::uint64_t error_frames = 0;
  for (const auto& c : counter_.interfaces()) error_frames += c.rx_error_frames;
  std::string line = fmt::format("{} pumps, {} warning, {} trip", pumps_.size(), warnings, trips);
  if (never_heard > 0) line += fmt::format(", {} never heard", never_heard);
  line += fmt::format("; {}; {} unknown, {} bad length, {} error frames", counter_.StatusLine(),
                      counters_.rx_unknown_id, counters_.rx_bad_length, error_frames);
  if (!config_.lcm.url.empty()) {
    line += fmt::format("; lcm {} sent, {} failed", counters_.lcm_published, counters_.lcm_failed);
  }
  const GatewayCounters& c = counters_;
  if (c.clears_accepted + c.clears_refused + c.clears_rate_limited > 0) {
    line += fmt::format("; clears {} accepted, {} refused ({} unsigned or forged)",
                        c.clears_accepted, c.clears_refused, c.clears_unauthenticated);
  }
  if (c.rx_second_sender > 0)
    line += fmt::format("; {} frames from a second sender", c.rx_second_sender);
  return line;
}

namespace {

/// The table's Rs as published (estimators::PublishedIdentification): the pump filter's with the
/// voltage fused, else the identifier's; "held" while the identifier holds an old value (it would
/// read as current), "-" before identification, "implaus." outside the motor's plausible band.
template <typename Num>
std::string RsCell(const PumpSnapshot& s, Num num) {
  using S = estimators::ResistanceStatus;
  const estimators::PublishedIdentification& id = s.identification;
  if (id.status == S::kImplausible) return "implaus.";
  if (id.status == S::kHeld || id.status == S::kNotIdentifiable) return "held";
  return num(id.resistance_ohm, 4);
}

/// The table's alarm column; a pump never heard from says so with its alarm.
std::string TableAlarmCell(const Pump& p, const std::string& alarm) {
  if (p.last_frame_us() < 0) return "never heard; " + alarm;
  return p.snapshot().initialised || p.snapshot().alarm.trip_latched ? alarm : "no estimate yet";
}

}  // namespace

// Columns named as docs/daemon.md "Names" says them to people: the frame sensor's reading (the
// measured node's sensor), the hottest node's estimate, the winding from resistance.
std::string Gateway::PumpTable() const {
  std::string out =
      fmt::format("{:<12} {:>7} {:>13} {:>20} {:>14} {:>8}  {}\n", "pump", "r/min", "sensor, degC",
                  "hottest node, degC", "winding from R", "Rs, ohm", "alarm; cause");
  for (const auto& p : pumps_) {
    const PumpSnapshot& s = p->snapshot();
    int hottest = -1;
    for (std::size_t i = 0; i < s.node_degC.size(); ++i) {
      if (std::isfinite(s.node_degC[i]) &&
          (hottest < 0 || s.node_degC[i] > s.node_degC[static_cast<std::size_t>(hottest)])) {
        hottest = static_cast<int>(i);
      }
    }
    auto num = [](double v, int prec) {
      return std::isfinite(v) ? fmt::format("{:.{}f}", v, prec) : std::string("-");
    };
    std::string alarm = s.alarm.level == estimators::AlarmLevel::kNone
                            ? std::string("normal")
                            : estimators::AlarmLevelName(s.alarm.level);
    if (s.alarm.level != estimators::AlarmLevel::kNone) {
      const std::string node = NodeWords(AlarmNodeName(s.alarm.node, p->model().StateNames()));
      alarm += fmt::format(" ({}{})", ReasonWords(s.alarm.reason), node.empty() ? "" : ", " + node);
    }
    if (s.alarm.trip_latched) alarm += " latched";
    const std::string cause =
        CauseText(s.mismatch.state, s.mismatch.effect, s.mismatch.value, p->config().measured_node);
    if (!cause.empty()) alarm += "; " + cause.substr(0, cause.find(" ("));
    const std::string sensor =
        fmt::format("{} {}", p->config().measured_node, num(s.frame_measured_degC, 1));
    const std::string hot =
        hottest >= 0
            ? fmt::format("{} {}", p->model().StateNames()[static_cast<std::size_t>(hottest)],
                          num(s.node_degC[static_cast<std::size_t>(hottest)], 1))
            : "-";
    out += fmt::format("{:<12} {:>7} {:>13} {:>20} {:>14} {:>8}  {}\n", p->config().name,
                       num(s.speed_rpm, 0), sensor, hot, num(s.winding_resistance_degC, 1),
                       RsCell(s, num), TableAlarmCell(*p, alarm));
  }
  return out;
}

}  // namespace pumptherm::daemon
