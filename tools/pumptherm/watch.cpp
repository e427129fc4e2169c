#include "tools/pumptherm/watch.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <cmath>
#include <string_view>

#include "daemon/operator_text.hpp"
#include "estimators/alarms.hpp"
#include "estimators/mismatch_detector.hpp"
#include "estimators/resistance_identifier.hpp"

namespace pumptherm::tools {
namespace {

using daemon::DurationText;
using daemon::LocalTimeText;

std::string Num(double v, int precision) {
  return std::isfinite(v) ? fmt::format("{:.{}f}", v, precision) : std::string("-");
}

/// "63.0 ±3.1": an estimate with its +-2 sd band, degC to 0.1 K.
std::string Band(double x_degC, double sd_K) {
  if (!std::isfinite(x_degC)) return "-";
  return std::isfinite(sd_K) ? fmt::format("{:.1f} ±{:.1f}", x_degC, 2.0 * sd_K)
                             : fmt::format("{:.1f}", x_degC);
}

std::string FilterStatusName(int status) {
  switch (status) {
    case pumptherm::temperatures_t::FILTER_NOT_STARTED:
      return "not started";
    case pumptherm::temperatures_t::FILTER_CONVERGING:
      return "converging";
    case pumptherm::temperatures_t::FILTER_TRACKING:
      return "tracking";
    case pumptherm::temperatures_t::FILTER_REJECTING:
      return "rejecting the sensor";
    case pumptherm::temperatures_t::FILTER_FAULT:
      return "fault";
    default:
      return fmt::format("code {}", status);
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
      return fmt::format("level {}", level);
  }
}

/// Whether there is a time to trip to show: finite, and the pump not tripped already.
bool HasTimeToTrip(const pumptherm::alarm_t& a) {
  return std::isfinite(a.time_to_trip_s) && a.level != pumptherm::alarm_t::LEVEL_TRIP;
}

/// What a condition is, in a few words: "winding 121.3 degC", "frame sensor fault".
std::string ConditionShort(const pumptherm::alarm_condition_t& c, const pumptherm::alarm_t& a) {
  const std::string node = daemon::NodeWords(c.node);
  switch (c.reason) {
    case 1:
      return fmt::format("{} {} degC", node, Num(c.value_degC, 1));
    case 2:
      return fmt::format("{} sensor {} degC", node, Num(c.value_degC, 1));
    case 3:
      return fmt::format("{} rising {} K/min", node, Num(c.rate_K_per_s * 60.0, 1));
    case 5:
      return fmt::format("{} sensor implausible", node);
    case 7:
      return HasTimeToTrip(a) ? fmt::format("trip in {}", DurationText(a.time_to_trip_s))
                              : fmt::format("forecast ({})", node);
    case 8:
      return fmt::format("{} sensor fault", node);
    default:
      return AlarmReasonLabel(c.reason);
  }
}

/// What a condition is in the fewest words (the one-line view): "winding", "frame sensor fault".
std::string ConditionWords(const pumptherm::alarm_condition_t& c, const pumptherm::alarm_t& a) {
  const std::string node = daemon::NodeWords(c.node);
  switch (c.reason) {
    case 1:
      return node;
    case 2:
      return node + " sensor";
    case 3:
      return node + " rising";
    case 7:
      return HasTimeToTrip(a) ? "trip in " + DurationText(a.time_to_trip_s) : "forecast";
    default:
      return ConditionShort(c, a);
  }
}

/// The alarm cell of the one-line view: "normal", "TRIP winding latched +1" (the values are in
/// the hottest column and in the detail view).
std::string AlarmCell(const pumptherm::alarm_t& a, bool heard) {
  if (!heard) return "-";
  std::string out = LevelName(a.level);
  if (a.conditions.empty()) return out;
  const auto& worst = a.conditions.front();
  out += " " + ConditionWords(worst, a);
  if (worst.latched) out += " latched";
  if (a.conditions.size() > 1) out += fmt::format(" +{}", a.conditions.size() - 1);
  return out;
}

/// The diagnosis' state and effect as the estimators' enumerations (out of range: none).
estimators::MismatchState StateOf(const pumptherm::alarm_t& a) {
  return a.mismatch_state >= 0 && a.mismatch_state <= 4
             ? static_cast<estimators::MismatchState>(a.mismatch_state)
             : estimators::MismatchState::kLearning;
}
estimators::MismatchEffect EffectOf(const pumptherm::alarm_t& a) {
  return a.mismatch_effect >= 0 && a.mismatch_effect < estimators::kMismatchEffectCount
             ? static_cast<estimators::MismatchEffect>(a.mismatch_effect)
             : estimators::MismatchEffect::kNone;
}

/// The diagnosis in words, with since when (`long_form`: the whole cause and the date).
std::string Diagnosis(const pumptherm::alarm_t& a, const std::string& measured_node,
                      bool long_form) {
  const estimators::MismatchState state = StateOf(a);
  if (!daemon::DiagnosisBlames(state)) {
    return state == estimators::MismatchState::kLearning ? "model learning" : "model consistent";
  }
  std::string cause = daemon::CauseText(state, EffectOf(a), a.mismatch_value, measured_node);
  if (!long_form) cause = cause.substr(0, cause.find(" ("));
  if (a.mismatch_since_utime > 0) {
    const std::string since = LocalTimeText(a.mismatch_since_utime);
    // The one-line view keeps the clock time ("2026-01-01 00:04:01 UTC" -> "00:04").
    cause += " since " + (long_form ? since : since.substr(11, 5));
  }
  return cause;
}

/// The hottest node's name and band, "rotor 63.0 ±3.1".
std::string Hottest(const pumptherm::temperatures_t& t) {
  int best = -1;
  for (int i = 0; i < t.num_nodes && i < static_cast<int>(t.node_degC.size()); ++i) {
    const auto k = static_cast<std::size_t>(i);
    if (std::isfinite(t.node_degC[k]) &&
        (best < 0 || t.node_degC[k] > t.node_degC[static_cast<std::size_t>(best)])) {
      best = i;
    }
  }
  if (best < 0) return "-";
  const auto k = static_cast<std::size_t>(best);
  return t.node_names[k] + " " + Band(t.node_degC[k], t.node_sd_K[k]);
}

/// `s` cut to `width` columns (counting the "±" as one), "..." marking the cut.
std::string Fit(const std::string& s, std::size_t width) {
  std::size_t cols = 0;
  for (std::size_t i = 0; i < s.size(); ++i) {
    if ((static_cast<unsigned char>(s[i]) & 0xC0) == 0x80) continue;  // UTF-8 continuation
    if (++cols > width) {
      std::size_t cut = i;
      for (int k = 0; k < 3 && cut > 0; ++k) {
        do --cut;
        while (cut > 0 && (static_cast<unsigned char>(s[cut]) & 0xC0) == 0x80);
      }
      return s.substr(0, cut) + "...";
    }
  }
  return s;
}

/// `s` left-aligned in `width` columns ("±" counts as one column).
std::string Pad(const std::string& s, std::size_t width) {
  std::size_t cols = 0;
  for (char c : s) cols += (static_cast<unsigned char>(c) & 0xC0) != 0x80;
  return s + std::string(cols < width ? width - cols : 0, ' ');
}

std::string AgeText(std::int64_t now_us, std::int64_t rx_us) {
  if (rx_us < 0) return "-";
  return fmt::format("{:.0f} s", std::max(0.0, static_cast<double>(now_us - rx_us) * 1e-6));
}

}  // namespace

std::string IdentStatusName(int status) {
  using S = estimators::ResistanceStatus;
  if (status < 0 || status > static_cast<int>(S::kHeld)) return fmt::format("code {}", status);
  std::string s(estimators::ToString(static_cast<S>(status)));
  std::replace(s.begin(), s.end(), '_', ' ');
  return s;
}

std::string AlarmReasonLabel(int reason) {
  if (reason < 0 || static_cast<std::size_t>(reason) >= estimators::kAlarmReasonCount) {
    return fmt::format("reason {}", reason);
  }
  return daemon::ReasonWords(static_cast<estimators::AlarmReason>(reason));
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

void PumpWatch::OnTelemetry(const pumptherm::telemetry_t& m, std::int64_t now_us) {
  Entry& e = pumps_[m.pump];
  e.telemetry = m;
  e.telemetry_rx_us = now_us;
}

void PumpWatch::SetMeasuredNode(const std::string& pump, const std::string& node) {
  measured_nodes_[pump] = node;
}

std::vector<std::string> PumpWatch::Pumps() const {
  std::vector<std::string> out;
  for (const auto& [name, e] : pumps_) out.push_back(name);
  return out;
}

// Columns: pump 12, age 10, alarm 28, hottest 21, diagnosis the rest of kWatchColumns. With
// --gateway-key, a pump whose messages the gateway signed ends its row with "signed"; any other
// mark takes the diagnosis's place.
std::string PumpWatch::Table(std::int64_t now_us, double stale_after_s,
                             const std::map<std::string, std::string>& marks) const {
  constexpr std::size_t kPump = 12, kAge = 10, kAlarm = 28, kHot = 21;
  constexpr std::size_t kDiagnosis = kWatchColumns - kPump - kAge - kAlarm - kHot - 4;
  constexpr std::string_view kSignedMark = "  signed";
  std::string out = fmt::format("{:<12} {:>10} {:<28} {:<21} {}\n", "pump", "age", "alarm",
                                "hottest, degC ±2 sd", "diagnosis");
  for (const auto& [name, e] : pumps_) {
    const std::int64_t last = std::max({e.temps_rx_us, e.alarm_rx_us, e.telemetry_rx_us});
    const bool stale = static_cast<double>(now_us - last) * 1e-6 > stale_after_s;
    const auto node = measured_nodes_.find(name);
    const std::string measured = node == measured_nodes_.end() ? e.measured_node : node->second;
    const std::string age = (stale ? "STALE " : "") + AgeText(now_us, last);
    const auto mark = marks.find(name);
    const bool is_signed = mark != marks.end() && mark->second == "signed";
    const std::string diagnosis = e.alarm_rx_us >= 0 ? Diagnosis(e.alarm, measured, false) : "-";
    const std::string last_cell = mark != marks.end() && !is_signed
                                      ? Fit("! " + mark->second, kDiagnosis)
                                  : is_signed ? Pad(Fit(diagnosis, kDiagnosis - kSignedMark.size()),
                                                    kDiagnosis - kSignedMark.size()) +
                                                    std::string(kSignedMark)
                                              : Fit(diagnosis, kDiagnosis);
    const std::string line =
        fmt::format("{} {:>10} {} {} {}", Pad(Fit(name, kPump), kPump), age,
                    Pad(Fit(AlarmCell(e.alarm, e.alarm_rx_us >= 0), kAlarm), kAlarm),
                    Pad(Fit(e.temps_rx_us >= 0 ? Hottest(e.temps) : "-", kHot), kHot), last_cell);
    out += line + "\n";
  }
  return out;
}

std::string PumpWatch::Detail(const std::string& pump, std::int64_t now_us,
                              double stale_after_s) const {
  const auto it = pumps_.find(pump);
  if (it == pumps_.end()) return fmt::format("{}: no message yet\n", pump);
  const Entry& e = it->second;
  const auto node = measured_nodes_.find(pump);
  const std::string measured = node == measured_nodes_.end() ? e.measured_node : node->second;
  const std::int64_t last = std::max({e.temps_rx_us, e.alarm_rx_us, e.telemetry_rx_us});
  const bool stale = static_cast<double>(now_us - last) * 1e-6 > stale_after_s;
  std::string out = fmt::format("{}: last message {} ago{}\n", pump, AgeText(now_us, last),
                                stale ? " - STALE: the gateway has gone silent" : "");
  const pumptherm::alarm_t& a = e.alarm;
  if (e.alarm_rx_us >= 0) {
    out += fmt::format("alarm: {}\n", LevelName(a.level));
    for (const auto& c : a.conditions) {
      out += fmt::format("  {:<8} {}{}", LevelName(c.level), ConditionShort(c, a),
                         c.reason == 1 || c.reason == 2
                             ? fmt::format(" when raised, level {} degC", Num(c.threshold_degC, 0))
                             : std::string());
      if (c.since_utime > 0) out += "; since " + LocalTimeText(c.since_utime);
      out += c.latched ? ", latched\n" : "\n";
    }
    const bool cause = daemon::DiagnosisBlames(StateOf(a)) && !a.conditions.empty();
    if (cause) out += "  cause: " + Diagnosis(a, measured, true) + "\n";
    if (HasTimeToTrip(a))
      out += fmt::format("time to trip at the present load: {} ({})\n",
                         DurationText(a.time_to_trip_s), a.forecast_node);
    if (!cause) out += "diagnosis: " + Diagnosis(a, measured, true) + "\n";
  }
  if (e.temps_rx_us >= 0) {
    const pumptherm::temperatures_t& t = e.temps;
    out += fmt::format("estimate, degC (±2 sd): filter {}, NIS {}\n",
                       FilterStatusName(t.filter_status), Num(t.nis, 1));
    for (int i = 0; i < t.num_nodes && i < static_cast<int>(t.node_degC.size()); ++i) {
      const auto k = static_cast<std::size_t>(i);
      const double x = t.node_degC[k], w = 2.0 * t.node_sd_K[k];
      out += fmt::format("  {:<16} {:<14} {}\n", t.node_names[k], Band(x, t.node_sd_K[k]),
                         std::isfinite(x) && std::isfinite(w)
                             ? fmt::format("({:.1f} to {:.1f})", x - w, x + w)
                             : std::string());
    }
  }
  out += "direct readings:\n";
  if (e.telemetry_rx_us >= 0) {
    const pumptherm::telemetry_t& m = e.telemetry;
    out += fmt::format("  {:<24} {} degC\n", measured + " sensor", Num(m.frame_sensor_degC, 1));
    out += fmt::format("  {:<24} {} degC\n", "ambient", Num(m.ambient_degC, 1));
    out +=
        fmt::format("  {:<24} {} r/min, iq {} A\n", "speed", Num(m.speed_rpm, 0), Num(m.iq_A, 2));
  } else {
    out += "  (no TELEMETRY message yet)\n";
  }
  if (e.temps_rx_us >= 0) {
    const pumptherm::temperatures_t& t = e.temps;
    const std::string ident = IdentStatusName(t.ident_status);
    out += fmt::format(
        "  {:<24} {}\n", "winding from resistance",
        std::isfinite(t.winding_resistance_degC)
            ? fmt::format("{} degC (identification {})",
                          Band(t.winding_resistance_degC, t.winding_resistance_sd_K), ident)
            : fmt::format("not available (identification {})", ident));
    out += fmt::format("  {:<24} {}\n", "magnet from flux",
                       std::isfinite(t.magnet_flux_degC)
                           ? Band(t.magnet_flux_degC, t.magnet_flux_sd_K) + " degC"
                           : std::string("not available"));
  }
  return out;
}

}  // namespace pumptherm::tools
