#include "tools/pumptherm/watch.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <cmath>

#include "estimators/alarms.hpp"
#include "estimators/resistance_identifier.hpp"

namespace pumptherm::tools {
namespace {

std::string Num(double v, int precision) {
  return std::isfinite(v) ? fmt::format("{:.{}f}", v, precision) : std::string("-");
}

std::string Age(std::int64_t now_us, std::int64_t rx_us) {
  if (rx_us < 0) return "-";
  return fmt::format("{:.0f}s", std::max(0.0, static_cast<double>(now_us - rx_us) * 1e-6));
}

std::string FilterStatusName(int status) {
  switch (status) {
    case pumptherm::temperatures_t::FILTER_NOT_STARTED:
      return "not_started";
    case pumptherm::temperatures_t::FILTER_CONVERGING:
      return "converging";
    case pumptherm::temperatures_t::FILTER_TRACKING:
      return "tracking";
    case pumptherm::temperatures_t::FILTER_REJECTING:
      return "rejecting";
    case pumptherm::temperatures_t::FILTER_FAULT:
      return "fault";
    default:
      return fmt::format("code{}", status);
  }
}

std::string LevelName(int level) {
  switch (level) {
    case pumptherm::alarm_t::LEVEL_NORMAL:
      return "normal";
    case pumptherm::alarm_t::LEVEL_WARNING:
      return "WARNING";
    case pumptherm::alarm_t::LEVEL_TRIP:
      return "TRIP";
    default:
      return fmt::format("level{}", level);
  }
}

std::string Nodes(const pumptherm::temperatures_t& t) {
  std::string out;
  for (int i = 0; i < t.num_nodes; ++i) {
    const auto k = static_cast<std::size_t>(i);
    if (!out.empty()) out += "  ";
    out += fmt::format("{} {}±{}", t.node_names[k], Num(t.node_degC[k], 1),
                       Num(2.0 * t.node_sd_K[k], 1));
  }
  return out.empty() ? "-" : out;
}

std::string Alarm(const pumptherm::alarm_t& a, bool heard) {
  if (!heard) return "-";
  std::string out = LevelName(a.level);
  for (const auto& c : a.conditions) {
    out += fmt::format(" [{} {}{}{}]", LevelName(c.level), AlarmReasonLabel(c.reason),
                       c.node.empty() ? "" : " " + c.node, c.latched ? " LATCHED" : "");
  }
  if (std::isfinite(a.time_to_trip_s)) {
    out += fmt::format(" trip in {:.0f}s ({})", a.time_to_trip_s, a.forecast_node);
  }
  return out;
}

}  // namespace

std::string IdentStatusName(int status) {
  using S = estimators::ResistanceStatus;
  if (status < 0 || status > static_cast<int>(S::kHeld)) return fmt::format("code{}", status);
  return std::string(estimators::ToString(static_cast<S>(status)));
}

std::string AlarmReasonLabel(int reason) {
  if (reason < 0 || static_cast<std::size_t>(reason) >= estimators::kAlarmReasonCount) {
    return fmt::format("reason{}", reason);
  }
  return estimators::AlarmReasonName(static_cast<estimators::AlarmReason>(reason));
}

void PumpWatch::OnTemperatures(const pumptherm::temperatures_t& m, std::int64_t now_us) {
  Entry& e = pumps_[m.pump];
  e.temps = m;
  e.temps_rx_us = now_us;
}

void PumpWatch::OnAlarm(const pumptherm::alarm_t& m, std::int64_t now_us) {
  Entry& e = pumps_[m.pump];
  e.alarm = m;
  e.alarm_rx_us = now_us;
}

std::vector<std::string> PumpWatch::Pumps() const {
  std::vector<std::string> out;
  for (const auto& [name, e] : pumps_) out.push_back(name);
  return out;
}

std::string PumpWatch::Table(std::int64_t now_us, double stale_after_s,
                             const std::map<std::string, std::string>& marks) const {
  std::string out = fmt::format("{:<12} {:>6} {:<26} {:<16} {}\n", "pump", "age",
                                "winding_R_C±2sd (status)", "filter (NIS)", "alarm");
  for (const auto& [name, e] : pumps_) {
    const std::int64_t last = std::max(e.temps_rx_us, e.alarm_rx_us);
    const bool stale = static_cast<double>(now_us - last) * 1e-6 > stale_after_s;
    const bool temps = e.temps_rx_us >= 0;
    const std::string winding =
        temps ? fmt::format("{}±{} ({})", Num(e.temps.resistance_winding_degC, 1),
                            Num(2.0 * e.temps.resistance_winding_sd_K, 1),
                            IdentStatusName(e.temps.ident_status))
              : "-";
    const std::string filter =
        temps ? fmt::format("{} ({})", FilterStatusName(e.temps.filter_status), Num(e.temps.nis, 1))
              : "-";
    const auto mark = marks.find(name);
    out += fmt::format("{:<12} {:>6} {:<26} {:<16} {}{}{}\n", name, Age(now_us, last), winding,
                       filter, Alarm(e.alarm, e.alarm_rx_us >= 0), stale ? "  STALE (silent)" : "",
                       mark == marks.end() ? "" : "  " + mark->second);
    if (temps) out += fmt::format("{:<12} nodes degC±2sd: {}\n", "", Nodes(e.temps));
  }
  return out;
}

}  // namespace pumptherm::tools
