// The published fields (daemon/published_fields.hpp): one row each; the CAN encoder, the LCM
// messages and the offline CSV read them from here.
#include "daemon/published_fields.hpp"

#include <fmt/format.h>

#include <array>
#include <cmath>
#include <iterator>
#include <type_traits>
#include <vector>

namespace pumptherm::daemon {
namespace {

using estimators::AlarmReason;
using estimators::PumpEstimate;
using Kind = CsvFormat::Kind;
using T = pumptherm::temperatures_t;
using A = pumptherm::alarm_t;

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

const PumpEstimate& E(const FieldSource& s) { return *s.estimate; }

/// The identification as published (PublishedIdentification): the pump filter's with the
/// voltage as a reading, else the identifier's.
const estimators::PublishedIdentification& Id(const FieldSource& s) { return E(s).identification; }
/// Whether the alarm state is worth sending: with an estimate, with a latched trip (also while
/// the filter has none), or with any condition raised (a pump never heard from is stale).
bool AlarmKnown(const FieldSource& s) {
  const PumpEstimate& e = E(s);
  return e.initialised || e.alarm.trip_latched || e.alarm.level != estimators::AlarmLevel::kNone;
}

double Code(auto v) { return static_cast<double>(v); }

double NodeValue(const FieldSource& s, const std::vector<double>& values) {
  return E(s).initialised && s.node >= 0 && static_cast<std::size_t>(s.node) < values.size()
             ? values[static_cast<std::size_t>(s.node)]
             : kNaN;
}

double AlarmNode(const FieldSource& s) {
  // The model's node index (as node_index), or the winding temperature from resistance.
  const PumpEstimate& e = E(s);
  if (!e.initialised ||
      (e.alarm.node < 0 && e.alarm.reason != AlarmReason::kEstimatedOverTemperature))
    return kNaN;
  const auto count = static_cast<int>(e.node_degC.size());
  return e.alarm.node >= 0 && e.alarm.node < count ? Code(e.alarm.node)
                                                   : Code(kAlarmNodeWindingRes);
}

double AlarmValue(const FieldSource& s) {
  const auto r = E(s).alarm.reason;
  const bool temp =
      r == AlarmReason::kEstimatedOverTemperature || r == AlarmReason::kMeasuredOverTemperature;
  return E(s).initialised && temp ? E(s).alarm.value : kNaN;
}

// The CSV's words for codes (docs/daemon.md, "Names"; the numbers are what CAN and LCM carry).
constexpr std::array<std::string_view, 3> kLevelWords{"normal", "warning", "trip"};

void Append(std::string& out, std::string_view word) { out += word; }

/// A journal-style name with its spaces as underscores ("out of range" -> "out_of_range").
void AppendWord(std::string& out, std::string_view name) {
  for (const char c : name) out += c == ' ' ? '_' : c;
}

void LevelWord(const FieldSource& s, std::string& out) {
  if (!AlarmKnown(s)) return;
  const auto level = static_cast<std::size_t>(E(s).alarm.level);
  if (level < kLevelWords.size()) Append(out, kLevelWords[level]);
}

void ReasonWord(const FieldSource& s, std::string& out) {
  if (AlarmKnown(s)) AppendWord(out, estimators::AlarmReasonName(E(s).alarm.reason));
}

/// For an estimated over-temperature, the rule that set the value its level acted on
/// (estimators::AlarmRule); not available for any other alarm or none.
double AlarmRuleCode(const FieldSource& s) {
  const bool temp = AlarmKnown(s) && E(s).alarm.reason == AlarmReason::kEstimatedOverTemperature;
  return temp ? Code(E(s).alarm_rule) : kNaN;
}

void AlarmRuleWord(const FieldSource& s, std::string& out) {
  if (std::isfinite(AlarmRuleCode(s))) Append(out, estimators::AlarmRuleName(E(s).alarm_rule));
}

/// The alarm's node by name: a model node, `winding_resistance`, or empty for none.
void AlarmNodeWord(const FieldSource& s, std::string& out) {
  const double code = AlarmNode(s);
  if (!std::isfinite(code)) return;
  const auto k = static_cast<std::size_t>(code);
  if (k == kAlarmNodeWindingRes) {
    Append(out, "winding_resistance");
  } else if (s.model != nullptr && k < s.model->StateNames().size()) {
    Append(out, s.model->StateNames()[k]);
  } else {
    fmt::format_to(std::back_inserter(out), "node{}", k);
  }
}

/// Every active reason's word, joined by '+' (empty: none active).
void ActiveReasonsWord(const FieldSource& s, std::string& out) {
  const unsigned bits = E(s).alarm.active_reasons;
  bool first = true;
  for (unsigned r = 0; r < 16; ++r) {
    if ((bits & (1U << r)) == 0) continue;
    if (!first) out += '+';
    first = false;
    AppendWord(out, estimators::AlarmReasonName(static_cast<AlarmReason>(r)));
  }
}

double FilterStatus(const FieldSource& s) {
  const PumpEstimate& e = E(s);
  if (!e.initialised) return T::FILTER_NOT_STARTED;
  if (!e.filter_converged) return T::FILTER_CONVERGING;
  if (std::isfinite(e.nis) && e.nis > s.nis_limit) return T::FILTER_REJECTING;
  return T::FILTER_TRACKING;
}

// clang-format off
/// The fields, in the CSV's column order. Columns: name (mapping key), unit, default DBC
/// message and signal, LCM field, CSV column and format, value, CSV word, old key.
const std::array kFields = std::to_array<PublishedField>({
  {"winding_resistance_degC", "degC", "GW_TEMPS_A", "WindingResistance_degC",
   &T::winding_resistance_degC,
   "winding_resistance_degC", {Kind::kFixed, 4},
   [](const FieldSource& s) { return E(s).winding_resistance_degC; }, nullptr,
   "winding_res_temp_degC"},
  {"magnet_flux_degC", "degC", "GW_IDENT", "MagnetFlux_degC", &T::magnet_flux_degC,
   "magnet_flux_degC", {Kind::kFixed, 4},
   [](const FieldSource& s) { return E(s).magnet_flux_degC; }, nullptr, "magnet_flux_temp_degC"},
  {"magnet_flux_sd_K", "K", "GW_IDENT_SD", "MagnetFluxSd_K", &T::magnet_flux_sd_K,
   "magnet_flux_sd_K", {Kind::kFixed, 4},
   [](const FieldSource& s) { return E(s).magnet_flux_sd_K; }},
  {"resistance_ohm", "ohm", "GW_IDENT", "Resistance_ohm", &T::resistance_ohm, "resistance_ohm",
   {Kind::kFixed, 6},
   [](const FieldSource& s) { return Id(s).resistance_ohm; },
   nullptr, "rs_ohm"},
  {"resistance_sd_ohm", "ohm", "", "", &T::resistance_sd_ohm, "resistance_sd_ohm",
   {Kind::kGeneral, 3},
   [](const FieldSource& s) { return Id(s).resistance_sd_ohm; }},
  {"flux_Wb", "Wb", "GW_IDENT", "Flux_Wb", &T::flux_Wb, "flux_Wb", {Kind::kFixed, 7},
   [](const FieldSource& s) { return Id(s).flux_Wb; }},
  {"ident_status", "", "GW_IDENT", "RsStatus", &T::ident_status, "ident_status", {Kind::kWord, 0},
   [](const FieldSource& s) { return Code(Id(s).status); },
   [](const FieldSource& s, std::string& out) { Append(out, estimators::ToString(Id(s).status)); },
   "rs_status", true},
  {"frame_sensor_degC", "degC", "", "", {}, "frame_sensor_degC", {Kind::kFixed, 2},
   [](const FieldSource& s) { return E(s).frame_measured_degC; }, nullptr,
   "frame_measured_degC"},
  {"ambient_degC", "degC", "", "", {}, "ambient_degC", {Kind::kFixed, 2},
   [](const FieldSource& s) { return E(s).ambient_degC; }},
  {"speed_rpm", "rpm", "", "", {}, "speed_rpm", {Kind::kFixed, 1},
   [](const FieldSource& s) { return E(s).speed_rpm; }},
  {"nis", "", "", "", &T::nis, "nis", {Kind::kFixed, 3},
   [](const FieldSource& s) { return E(s).nis; }},
  {"alarm_level", "", "GW_ALARM", "AlarmLevel", &A::level, "alarm_level", {Kind::kWord, 0},
   [](const FieldSource& s) { return AlarmKnown(s) ? Code(E(s).alarm.level) : kNaN; },
   LevelWord},
  {"alarm_reason", "", "GW_ALARM", "AlarmReason", {}, "alarm_reason", {Kind::kWord, 0},
   [](const FieldSource& s) { return AlarmKnown(s) ? Code(E(s).alarm.reason) : kNaN; },
   ReasonWord},
  {"alarm_node", "", "GW_ALARM", "AlarmNode", {}, "alarm_node", {Kind::kWord, 0},
   AlarmNode, AlarmNodeWord},
  {"alarm_value_degC", "degC", "GW_ALARM", "AlarmValue_degC", {}, "", {}, AlarmValue},
  {"time_to_trip_s", "s", "GW_ALARM", "TimeToTrip_s", &A::time_to_trip_s, "time_to_trip_s",
   {Kind::kFixedOrEmpty, 0},
   [](const FieldSource& s) { return E(s).alarm.time_to_trip_s; }},
  {"alarm_active_reasons", "", "", "", {}, "alarm_active_reasons", {Kind::kWord, 0},
   [](const FieldSource& s) { return Code(E(s).alarm.active_reasons); }, ActiveReasonsWord, {},
   true},
  {"sensor_fault", "", "", "", {}, "sensor_fault", {Kind::kWord, 0},
   [](const FieldSource& s) { return Code(E(s).sensor_fault); },
   [](const FieldSource& s, std::string& out) {
     AppendWord(out, estimators::SensorFaultName(E(s).sensor_fault));
   }, {}, true},
  {"winding_resistance_sd_K", "K", "GW_IDENT_SD", "WindingResistanceSd_K",
   &T::winding_resistance_sd_K,
   "winding_resistance_sd_K", {Kind::kFixed, 4},
   // Only with the temperature it belongs to.
   [](const FieldSource& s) {
     return std::isfinite(E(s).winding_resistance_degC) ? E(s).winding_resistance_sd_K : kNaN;
   },
   nullptr, "winding_res_sd_K"},
  {"flux_sd_Wb", "Wb", "", "", &T::flux_sd_Wb, "flux_sd_Wb", {Kind::kGeneral, 3},
   [](const FieldSource& s) { return Id(s).flux_sd_Wb; }},
  {"mismatch_state", "", "GW_ALARM", "MismatchState", &A::mismatch_state, "mismatch_state",
   {Kind::kWord, 0},
   [](const FieldSource& s) { return E(s).initialised ? Code(E(s).mismatch.state) : kNaN; },
   [](const FieldSource& s, std::string& out) {
     Append(out, estimators::MismatchStateName(E(s).mismatch.state));
   }},
  {"mismatch_effect", "", "GW_ALARM", "MismatchEffect", &A::mismatch_effect, "mismatch_effect",
   {Kind::kWord, 0},
   [](const FieldSource& s) { return E(s).initialised ? Code(E(s).mismatch.effect) : kNaN; },
   [](const FieldSource& s, std::string& out) {
     Append(out, estimators::MismatchEffectName(E(s).mismatch.effect));
   }},
  {"mismatch_value", "", "", "", &A::mismatch_value, "mismatch_value", {Kind::kFixed, 3},
   [](const FieldSource& s) { return E(s).mismatch.value; }},
  {"frame_sensor_offset_K", "K", "", "", {}, "frame_sensor_offset_K", {Kind::kFixed, 3},
   [](const FieldSource& s) { return E(s).sensor_offset_K; }},
  {"identifier_winding_degC", "degC", "", "", {}, "identifier_winding_degC", {Kind::kFixed, 4},
   [](const FieldSource& s) { return E(s).identifier_winding_degC; }},
  // The identifier's own status (the paper's method beside the pump filter's identification).
  {"identifier_status", "", "", "", {}, "identifier_status", {Kind::kWord, 0},
   [](const FieldSource& s) { return Code(E(s).resistance.status); },
   [](const FieldSource& s, std::string& out) {
     Append(out, estimators::ToString(E(s).resistance.status));
   }, {}, true},
  {"voltage_reading", "", "", "", {}, "voltage_reading", {Kind::kWord, 0},
   [](const FieldSource& s) { return Code(E(s).voltage_reading.state); },
   [](const FieldSource& s, std::string& out) {
     Append(out, estimators::ReadingStateName(E(s).voltage_reading.state));
   },
   {}, true},
  {"r0_error", "", "", "", {}, "r0_error", {Kind::kGeneral, 4},
   [](const FieldSource& s) { return E(s).calibration.dr; }},
  {"psi0_error", "", "", "", {}, "psi0_error", {Kind::kGeneral, 4},
   [](const FieldSource& s) { return E(s).calibration.dpsi; }},
  {"voltage_offset_V", "V", "", "", {}, "voltage_offset_V", {Kind::kFixed, 4},
   [](const FieldSource& s) { return E(s).calibration.u0_V; }},
  {"alarm_rule", "", "", "", {}, "alarm_rule", {Kind::kWord, 0}, AlarmRuleCode, AlarmRuleWord},
  {"flux_status", "", "GW_IDENT", "FluxStatus", {}, "", {},
   [](const FieldSource& s) { return Code(Id(s).flux_status); }, nullptr, {}, true},
  {"mismatch_since_us", "us", "", "", &A::mismatch_since_utime, "", {},
   // Since the Unix epoch (the pipeline's clock is monotonic live); 0: none.
   [](const FieldSource& s) {
     const double onset_s = E(s).mismatch.onset_s;
     return std::isfinite(onset_s) ? std::floor(onset_s * 1e6) + s.wall_offset_us : 0.0;
   }, nullptr, {}, true},
  {"filter_status", "", "", "", &T::filter_status, "", {}, FilterStatus, nullptr, {}, true},
  {"uptime_s", "s", "GW_HEALTH", "Uptime_s", {}, "", {},
   [](const FieldSource& s) { return s.uptime_s; }, nullptr, {}, true},
  {"frame_rate_Hz", "Hz", "GW_HEALTH", "FrameRate_Hz", {}, "", {},
   [](const FieldSource& s) { return s.frame_rate_Hz; }, nullptr, {}, true},
  {"drops", "", "GW_HEALTH", "Drops", {}, "", {},
   [](const FieldSource& s) { return s.lost_frames; }, nullptr, {}, true},
  {"bus_state", "", "GW_HEALTH", "BusState", {}, "", {},
   [](const FieldSource& s) { return s.bus_state; }, nullptr, {}, true},
  {protocol::kNodeIndexKey, "", "GW_NODE_TEMP", "NodeIndex", {}, "", {},
   [](const FieldSource& s) { return s.node >= 0 ? Code(s.node) : kNaN; }, nullptr, {}, true},
  {protocol::kNodeCountKey, "", "GW_NODE_TEMP", "NodeCount", {}, "", {},
   [](const FieldSource& s) { return Code(E(s).node_degC.size()); }, nullptr, {}, true},
  {protocol::kNodeTempKey, "degC", "GW_NODE_TEMP", "NodeTemp_degC", {}, "", {},
   [](const FieldSource& s) { return NodeValue(s, E(s).node_degC); }},
  {protocol::kNodeSdKey, "K", "GW_NODE_TEMP", "NodeSd_K", {}, "", {},
   [](const FieldSource& s) { return NodeValue(s, E(s).node_sd_K); }},
});
// clang-format on

std::vector<protocol::OutputSpec> MakeMappingOutputs() {
  // Every field may be mapped to a signal; those with a default go where the DBC has it.
  std::vector<protocol::OutputSpec> out;
  for (const PublishedField& f : kFields)
    out.push_back({f.name, f.dbc_message, f.dbc_signal, f.old_key});
  return out;
}

void AppendCell(const PublishedField& f, const FieldSource& s, std::string& out) {
  out += ',';
  if (f.csv.kind == Kind::kWord) {
    f.word(s, out);
    return;
  }
  const double v = f.value(s);
  if (!std::isfinite(v) && f.csv.kind == Kind::kFixedOrEmpty) return;
  if (!std::isfinite(v) && f.csv.kind == Kind::kInteger) {
    fmt::format_to(std::back_inserter(out), "{}", v);  // nan, inf
    return;
  }
  switch (f.csv.kind) {
    case Kind::kFixed:
    case Kind::kFixedOrEmpty:
      fmt::format_to(std::back_inserter(out), "{:.{}f}", v, f.csv.digits);
      break;
    case Kind::kGeneral:
      fmt::format_to(std::back_inserter(out), "{:.{}g}", v, f.csv.digits);
      break;
    case Kind::kInteger:
      fmt::format_to(std::back_inserter(out), "{}", static_cast<long long>(v));
      break;
    default:
      break;
  }
}

template <typename Message>
void Fill(const FieldSource& source, Message& m) {
  for (const PublishedField& f : kFields) {
    std::visit(
        [&](auto member) {
          using M = decltype(member);
          if constexpr (std::is_same_v<M, double Message::*>) {
            m.*member = f.value(source);
          } else if constexpr (std::is_same_v<M, std::int8_t Message::*>) {
            // A code that is not available: -1 (LCM integers have no NaN; docs/lcm.md).
            const double v = f.value(source);
            m.*member = std::isfinite(v) ? static_cast<std::int8_t>(v) : std::int8_t{-1};
          } else if constexpr (std::is_same_v<M, std::int64_t Message::*>) {
            const double v = f.value(source);
            m.*member = std::isfinite(v) ? static_cast<std::int64_t>(v) : std::int64_t{0};
          }
        },
        f.lcm);
  }
}

}  // namespace

std::span<const PublishedField> PublishedFields() { return kFields; }

const PublishedField* FindPublishedField(std::string_view name) {
  for (const PublishedField& f : kFields) {
    if (f.name == name) return &f;
  }
  return nullptr;
}

std::span<const protocol::OutputSpec> MappingOutputs() {
  static const std::vector<protocol::OutputSpec> outputs = MakeMappingOutputs();
  return outputs;
}

void FillLcm(const FieldSource& source, pumptherm::temperatures_t& m) { Fill(source, m); }
void FillLcm(const FieldSource& source, pumptherm::alarm_t& m) { Fill(source, m); }

std::string CsvHeader() {
  std::string out;
  for (const PublishedField& f : kFields) {
    if (f.csv.kind == Kind::kNone) continue;
    out += ',';
    out += f.csv_column;
  }
  return out;
}

void AppendCsvRow(const FieldSource& source, std::string& out) {
  for (const PublishedField& f : kFields) {
    if (f.csv.kind != Kind::kNone) AppendCell(f, source, out);
  }
}

}  // namespace pumptherm::daemon
