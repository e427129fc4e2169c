#include "daemon/alarm_journal.hpp"

#include <fmt/format.h>

#include <cmath>

namespace pumptherm::daemon {
namespace {

using estimators::AlarmCondition;
using estimators::AlarmLevel;
using estimators::AlarmReason;
using estimators::MismatchEffect;
using estimators::MismatchFinding;
using estimators::MismatchState;

/// A number with the digits a reader needs: "120", "0.5", "2.5" (shortest, at most 4 figures).
std::string Short(double v) { return fmt::format("{:.4g}", v); }

/// A node as a person reads it: the model's name, or "winding from resistance".
std::string NodeWords(int node, const std::vector<std::string>& names) {
  return daemon::NodeWords(AlarmNodeName(node, names));
}

bool IsTemperature(const AlarmCondition& c) {
  switch (c.reason) {
    case AlarmReason::kEstimatedOverTemperature:
    case AlarmReason::kMeasuredOverTemperature:
    case AlarmReason::kSensorFault:
      return true;
    case AlarmReason::kImplausibleSensor:
      return std::string_view(c.detail) == "stuck";
    default:
      return false;
  }
}

std::string SensorFaultText(const AlarmCondition& c, const std::string& sensor,
                            const estimators::AlarmConfig& k) {
  const std::string_view kind = c.detail;
  std::string why;
  if (kind == "missing") {
    why = fmt::format("missing (no reading for {} s)", Short(k.stale_after_s));
  } else if (kind == "stuck") {
    why = fmt::format("stuck (unchanged to the last bit for {} s)", Short(k.flat_after_s));
  } else if (kind == "out of range") {
    why = fmt::format("out of range ({} to {} degC)", Short(k.sensor_min_degC),
                      Short(k.sensor_max_degC));
  } else if (kind == "jumping") {
    why = fmt::format("jumping (a step above {} K between readings)", Short(k.max_step_K));
  } else {
    why = std::string(kind);
  }
  std::string out = fmt::format("{} sensor fault: {}", sensor, why);
  if (std::isfinite(c.value)) out += fmt::format(", last reading {:.1f} degC", c.value);
  return out + "; left out of the estimate";
}

std::string ImplausibleText(const AlarmCondition& c, const std::string& sensor,
                            const estimators::AlarmConfig& k) {
  const std::string_view kind = c.detail;
  if (kind == "stuck") {
    return fmt::format("{} sensor stuck at {:.1f} degC for {} s while the model moved over {} K",
                       sensor, c.value, Short(k.stuck_after_s), Short(k.stuck_model_move_K));
  }
  if (kind == "offset") {
    return fmt::format(
        "{} sensor offset {:+.1f} K (limit {} K): its reading stepped faster than the {} can move",
        sensor, c.value, Short(k.max_sensor_offset_K), sensor);
  }
  return fmt::format("{} sensor disagrees with the model for {} s (NIS {:.1f} > {})", sensor,
                     Short(k.disagree_hold_s), c.value, Short(k.nis_limit));
}

/// What the condition says, with its value in its unit.
std::string ConditionText(const AlarmCondition& c, const std::vector<std::string>& names,
                          const estimators::AlarmConfig& k, std::int64_t wall_offset_us) {
  const std::string node = NodeWords(c.node, names);
  const std::string sensor = c.node >= 0 ? node : std::string("frame");
  switch (c.reason) {
    case AlarmReason::kMeasuredOverTemperature:
      return fmt::format("{} sensor {:.1f} degC >= {} degC", sensor, c.value, Short(c.threshold));
    case AlarmReason::kRateOfRise:
      return fmt::format("{} rising {:.1f} K/min (limit {} K/min)", node, c.value,
                         Short(k.max_rise_K_per_min));
    case AlarmReason::kStaleTelemetry:
      // The age was taken when the warning was raised; the last frame's time stays true on
      // every later line of the same silence.
      if (std::isfinite(c.value)) {
        const auto last_us =
            static_cast<std::int64_t>(std::floor((c.raised_at_s - c.value) * 1e6)) + wall_offset_us;
        return fmt::format("no telemetry since {} (limit {} s)", LocalTimeText(last_us),
                           Short(k.stale_after_s));
      }
      return fmt::format("no telemetry (limit {} s)", Short(k.stale_after_s));
    case AlarmReason::kImplausibleSensor:
      return ImplausibleText(c, sensor, k);
    case AlarmReason::kEstimatorNotConverged:
      return "the estimate has not converged (a node's sd above 5 K)";
    case AlarmReason::kForecast:
      return fmt::format("{} reaches its trip level in {} at the present load (horizon {})",
                         node.empty() ? "a node" : node, DurationText(c.value),
                         DurationText(k.forecast_horizon_s));
    case AlarmReason::kSensorFault:
      return SensorFaultText(c, sensor, k);
    case AlarmReason::kSafetyStateLost:
      return "the saved latched trips and clear counters were lost at start: latched until an "
             "operator clears it";
    case AlarmReason::kSecondSender:
      return "frames on this pump's IDs that neither its drive nor the gateway sent";
    case AlarmReason::kEstimatedOverTemperature:
    case AlarmReason::kNone:
      break;
  }
  return "";
}

/// What an estimated over-temperature's value is, by the rule that set it.
std::string_view RuleValueWords(estimators::AlarmRule rule) {
  switch (rule) {
    case estimators::AlarmRule::kBand:
      return "estimate";
    case estimators::AlarmRule::kLaggingSensor:
      return "estimate raised by the sensor's lag";
    case estimators::AlarmRule::kInsideHeat:
      return "estimate with the heat found inside on the rotor";
    case estimators::AlarmRule::kBlind:
      return "blind worst case of an unseen cooling failure";
    case estimators::AlarmRule::kSilence:
      return "worst case of the load the telemetry silence may hide";
  }
  return "estimate";
}

/// The estimated over-temperature: "winding 121.3 degC (bound 126.1 = estimate + 2 sd) >= 120
/// degC"; the bound shown when the rule's estimate + k sd lies above the value. Where a bound
/// raised the value, it says which: "(bound 126.1 = blind worst case of an unseen cooling
/// failure + 2 sd)".
std::string OverTemperatureText(const estimators::AlarmState& a, const AlarmCondition& c,
                                const std::vector<std::string>& names,
                                const estimators::AlarmConfig& k, estimators::AlarmRule rule) {
  std::string out = NodeWords(c.node, names);
  const double factor = a.level == AlarmLevel::kTrip ? k.trip_sd_factor : k.warning_sd_factor;
  if (std::isfinite(a.value)) out += fmt::format(" {:.1f} degC", a.value);
  if (std::isfinite(a.bound) && a.bound > a.value) {
    out +=
        fmt::format(" (bound {:.1f} = {} + {} sd)", a.bound, RuleValueWords(rule), Short(factor));
  } else if (std::isfinite(a.value) && std::isfinite(c.threshold) && a.value < c.threshold) {
    // The bound is not known (a trip latched again after a restart keeps only its value), but
    // it reached the level: say so rather than "116.8 degC >= 120 degC".
    return out +
           fmt::format(" with estimate + {} sd >= {} degC", Short(factor), Short(c.threshold));
  }
  if (std::isfinite(c.threshold)) out += fmt::format(" >= {} degC", Short(c.threshold));
  return out;
}

std::string ReasonList(std::uint16_t bits) {
  std::string s;
  for (std::size_t r = 1; r < estimators::kAlarmReasonCount; ++r) {
    if (bits & (1u << r)) s += (s.empty() ? "" : ", ") + ReasonWords(static_cast<AlarmReason>(r));
  }
  return s;
}

/// " since 2026-01-01 00:04:01 UTC" (the fitted start), " (found 2026-...)" when only the
/// detection is known, "" when neither.
std::string SinceText(const MismatchFinding& f, std::int64_t wall_offset_us) {
  auto unix_us = [&](double s) {
    return static_cast<std::int64_t>(std::floor(s * 1e6)) + wall_offset_us;
  };
  if (std::isfinite(f.onset_s)) return " since " + LocalTimeText(unix_us(f.onset_s));
  if (std::isfinite(f.detected_s)) return " (found " + LocalTimeText(unix_us(f.detected_s)) + ")";
  // (A finding without a fitted start says when it was found, not when its cause began.)
  return "";
}

std::string CauseField(const MismatchFinding& f) {
  return f.effect != MismatchEffect::kNone ? estimators::MismatchEffectName(f.effect)
                                           : estimators::MismatchStateName(f.state);
}

std::string CauseText(const MismatchFinding& f, std::string_view measured_node) {
  return daemon::CauseText(f.state, f.effect, f.value, measured_node);
}

/// An estimated over-temperature raised on the worst case of a telemetry silence (its rule),
/// while the telemetry is silent, on a motor whose largest current is stated: the levels act on
/// that current's worst case (AlarmValues). Running blind through a silence of the status frames
/// alone, the blind worst case is the rule, and the line names that instead.
bool SilenceWorstCase(const AlarmLineInputs& in) {
  const estimators::AlarmState& a = *in.state;
  const auto bit = [](AlarmReason r) {
    return static_cast<std::uint16_t>(1u << static_cast<unsigned>(r));
  };
  return in.rule == estimators::AlarmRule::kSilence && in.silence_worst_current_A > 0.0 &&
         a.level != AlarmLevel::kNone && !in.conditions.empty() &&
         in.conditions.front().reason == AlarmReason::kEstimatedOverTemperature &&
         (a.active_reasons & bit(AlarmReason::kStaleTelemetry)) != 0;
}

}  // namespace

JournalEntry AlarmEntry(const AlarmLineInputs& in) {
  const estimators::AlarmState& a = *in.state;
  const std::vector<std::string>& names = *in.node_names;
  const estimators::AlarmConfig& k = *in.config;
  JournalEntry e;
  // The journal's priority follows the level: a trip is an error (`journalctl -p err` lists
  // every trip), a warning a warning, the return to normal a notice.
  e.level = a.level == AlarmLevel::kTrip   ? LogLevel::kError
            : a.level == AlarmLevel::kNone ? LogLevel::kNotice
                                           : LogLevel::kWarning;
  const std::string level =
      a.level == AlarmLevel::kNone ? "normal" : estimators::AlarmLevelName(a.level);
  e.fields.push_back({"PUMP", std::string(in.pump)});
  e.fields.push_back({"LEVEL", level});
  e.fields.push_back({"REASON", estimators::AlarmReasonName(a.reason)});
  e.text = fmt::format("{}: {}: ", in.pump, level);
  if (a.level == AlarmLevel::kNone || in.conditions.empty()) {
    e.text += "no alarm";
  } else {
    const AlarmCondition& c = in.conditions.front();
    e.text += c.reason == AlarmReason::kEstimatedOverTemperature
                  ? OverTemperatureText(a, c, names, k, in.rule)
                  : ConditionText(c, names, k, in.wall_offset_us);
    if (const std::string node = AlarmNodeName(c.node, names); !node.empty())
      e.fields.push_back({"NODE", node});
    const double value = c.reason == AlarmReason::kEstimatedOverTemperature ? a.value : c.value;
    if (IsTemperature(c) && std::isfinite(value))
      e.fields.push_back({"VALUE_DEGC", fmt::format("{:.2f}", value)});
    if (std::isfinite(c.threshold)) e.fields.push_back({"THRESHOLD_DEGC", Short(c.threshold)});
    // A trip latched again after a restart keeps only its value: its rule is not known either.
    if (c.reason == AlarmReason::kEstimatedOverTemperature && std::isfinite(a.bound))
      e.fields.push_back({"RULE", estimators::AlarmRuleName(in.rule)});
  }
  if (SilenceWorstCase(in)) {
    e.text += fmt::format(
        "; cause: no telemetry: the level acts on the worst case of the drive's largest current "
        "({} A) since the last frame",
        Short(in.silence_worst_current_A));
    e.fields.push_back({"CAUSE", "telemetry_silence"});
  } else if (in.mismatch != nullptr && DiagnosisBlames(in.mismatch->state)) {
    e.text += "; cause: " + CauseText(*in.mismatch, in.measured_node) +
              SinceText(*in.mismatch, in.wall_offset_us);
    e.fields.push_back({"CAUSE", CauseField(*in.mismatch)});
  }
  const auto worst_bit = static_cast<std::uint16_t>(1u << static_cast<unsigned>(a.reason));
  const std::uint16_t others = a.active_reasons & static_cast<std::uint16_t>(~worst_bit);
  const std::uint16_t raised = a.active_reasons & static_cast<std::uint16_t>(~in.logged_reasons);
  const std::uint16_t cleared = in.logged_reasons & static_cast<std::uint16_t>(~a.active_reasons);
  if (others) e.text += "; also active: " + ReasonList(others);
  if (raised) e.text += "; raised: " + ReasonList(raised);
  if (cleared) e.text += "; cleared: " + ReasonList(cleared);
  if (a.trip_latched) e.text += "; trip latched until cleared";
  return e;
}

JournalEntry DiagnosisEntry(std::string_view pump, const MismatchFinding& f,
                            std::string_view measured_node, std::int64_t wall_offset_us) {
  JournalEntry e;
  e.fields.push_back({"PUMP", std::string(pump)});
  e.fields.push_back({"DIAGNOSIS", estimators::MismatchStateName(f.state)});
  const std::string test = fmt::format("window NIS {:.0f} {} {:.0f}", f.window_nis,
                                       f.window_nis > f.threshold ? ">" : "<=", f.threshold);
  if (DiagnosisBlames(f.state) && f.effect == MismatchEffect::kNone) {
    e.level = LogLevel::kWarning;
    const std::string found =
        std::isfinite(f.detected_s)
            ? ", found " + LocalTimeText(static_cast<std::int64_t>(std::floor(f.detected_s * 1e6)) +
                                         wall_offset_us)
            : "";
    e.text = fmt::format(
        "{}: diagnosis: the model no longer explains the {} sensor ({}){}; cause not named yet",
        pump, measured_node, test, found);
    e.fields.push_back({"CAUSE", CauseField(f)});
  } else if (DiagnosisBlames(f.state)) {
    e.level = LogLevel::kWarning;
    e.text =
        fmt::format("{}: diagnosis: {}{}; the model no longer explains the {} sensor ({})", pump,
                    CauseText(f, measured_node), SinceText(f, wall_offset_us), measured_node, test);
    e.fields.push_back({"CAUSE", CauseField(f)});
  } else if (f.state == MismatchState::kLearning) {
    e.text = fmt::format(
        "{}: diagnosis: learning (the model test judges after its first minutes of data)", pump);
  } else {
    e.text = fmt::format("{}: diagnosis: the model explains the {} sensor ({})", pump,
                         measured_node, test);
  }
  return e;
}

namespace {

std::string_view StartName(estimators::EstimateStart start) {
  switch (start) {
    case estimators::EstimateStart::kCold:
      return "cold";
    case estimators::EstimateStart::kWarm:
      return "warm";
    case estimators::EstimateStart::kRestored:
      return "restored";
    case estimators::EstimateStart::kNone:
      break;
  }
  return "none";
}

}  // namespace

JournalEntry StartEntry(std::string_view pump, const estimators::PumpEstimate& e, bool calibrated,
                        bool voltage) {
  JournalEntry j;
  j.fields.push_back({"PUMP", std::string(pump)});
  j.fields.push_back({"START", std::string(StartName(e.start))});
  std::string what;
  if (e.start == estimators::EstimateStart::kRestored) {
    what = "estimate restored from the saved state";
    // What the filter had found about the losses stays; only their sd widens.
    if (std::isfinite(e.losses_sd_widened_to)) {
      what += fmt::format(
          ", its loss scale widened to the {:g} now stated (model_losses_sd_rel; saved with {:g}); "
          "what the filter had learnt stays, so it covers less than a start at {:g} would",
          e.losses_sd_widened_to, e.losses_sd_widened_from, e.losses_sd_widened_to);
    }
  } else {
    // A frame still warm from a run: the nodes that cool slower start warmer than it.
    const bool cold = e.start == estimators::EstimateStart::kCold;
    const std::string warm_frame =
        e.start_span_K > 0.0
            ? fmt::format(
                  "; the frame still warm from a run, so the nodes that cool slower {} "
                  "up to {:.1f} K above it",
                  cold ? "are taken between its temperature and" : "may be", e.start_span_K)
            : std::string();
    what = fmt::format(
        "estimate started {} (frame {:.1f} degC, ambient {:.1f} degC, {:.0f} r/min{})",
        StartName(e.start), e.frame_measured_degC, e.ambient_degC, e.speed_rpm, warm_frame);
  }
  const bool fresh_cold = e.start == estimators::EstimateStart::kCold && voltage;
  if (calibrated && fresh_cold) {
    what +=
        ": this pump's psi0 is learnt in the run-up, its R0 at the first load change (the "
        "winding from resistance waits for it)";
  } else if (calibrated) {
    what += e.calibrated_at_cold_start
                ? ": this pump's R0 and psi0 are learnt from a cold start"
                : ": the magnet from the flux waits for a cold start (the pump at rest at the "
                  "ambient) to learn this pump's psi0, and its node is published with the "
                  "nameplate flux's tolerance until then";
  }
  j.text = fmt::format("{}: {}", pump, what);
  return j;
}

JournalEntry R0Entry(std::string_view pump, const estimators::PumpEstimate& e,
                     const estimators::CopperLaw& copper, double max_calibration_sd_K,
                     double winding_degC) {
  JournalEntry j;
  j.fields.push_back({"PUMP", std::string(pump)});
  const auto& c = e.calibration;
  if (e.identification.status == estimators::ResistanceStatus::kTracking) {
    j.text = fmt::format(
        "{}: R0 learnt: {:.4f} ohm at {:.1f} degC, {:+.1f} % against the nameplate (sd {:.1f} %); "
        "the winding from resistance is published from now ({:.1f} degC)",
        pump, copper.r0_ohm * (1.0 + c.dr), copper.t0_degC, 100.0 * c.dr, 100.0 * c.dr_sd,
        e.winding_resistance_degC);
  } else {
    // R = R0 (1 + dR)(1 + alpha (Tw - T0)): R0's relative sd is more kelvin in a warmer winding.
    j.text = fmt::format(
        "{}: R0's sd ({:.1f} %) grew past {:.1f} K of winding at {:.1f} degC: the winding from "
        "resistance is withheld until a load change pins R0 again",
        pump, 100.0 * c.dr_sd, max_calibration_sd_K, winding_degC);
  }
  return j;
}

JournalEntry MagnetLawEntry(std::string_view pump, const estimators::PumpEstimate& e,
                            double law_per_K) {
  JournalEntry j;
  j.level = LogLevel::kWarning;
  j.fields.push_back({"PUMP", std::string(pump)});
  j.text = fmt::format(
      "{}: the magnet from the flux reads the rotor colder than the thermal model's rotor "
      "losses make it (the filter needs {:.1f} W, sd {:.1f} W, of rotor heat to follow it): "
      "either the motor file's magnet law ({:+.3f} %/K) is steeper than this magnet's (NdFeB "
      "about -0.09 to -0.13 %/K, SmCo -0.03 to -0.05 %/K), or the thermal model's rotor "
      "losses are too high. The estimate gives that law up from now on (kept across restarts "
      "while the motor file states it): the voltage reads the winding through its resistance "
      "alone, the rotor is the thermal model's with a wider sd, and no magnet from the flux is "
      "published (a failed frame sensor then leaves the pump blind); check the magnet's "
      "flux_temperature_coefficient_per_K in the motor file and the rotor's losses in the "
      "thermal model",
      pump, e.rotor_heat_W, e.rotor_heat_sd_W, 100.0 * law_per_K);
  return j;
}

}  // namespace pumptherm::daemon
