// The gateway's LCM messages (docs/lcm.md): a pump's temperatures, telemetry and alarm, and the
// gateway's health; and the journal line of a model-mismatch verdict.
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <ctime>
#include <limits>

#include "daemon/alarm_journal.hpp"
#include "daemon/gateway.hpp"
#include "daemon/gateway_detail.hpp"
#include "daemon/log.hpp"
#include "pumptherm/alarm_t.hpp"
#include "pumptherm/gateway_health_t.hpp"
#include "pumptherm/telemetry_t.hpp"
#include "pumptherm/temperatures_t.hpp"

namespace pumptherm::daemon {

using gateway_detail::Encode;
using protocol::MappingInput;

std::vector<std::uint8_t> Gateway::EncodeTemperatures(const Pump& pump) const {
  pumptherm::temperatures_t m;
  FillTemperatures(pump, m);
  return Encode(m);
}

void Gateway::FillTemperatures(const Pump& pump, pumptherm::temperatures_t& m) const {
  const PumpSnapshot& s = pump.snapshot();
  m.utime = s.time_us + wall_offset_us_;
  m.pump = pump.config().name;
  FillLcm(Source(pump), m);
  const auto& names = pump.model().StateNames();
  m.num_nodes = static_cast<std::int32_t>(names.size());
  m.node_names = names;
  m.node_degC = s.node_degC;
  m.node_sd_K = s.node_sd_K;
}

std::vector<std::uint8_t> Gateway::EncodeTelemetry(std::size_t p) const {
  pumptherm::telemetry_t m;
  FillTelemetry(p, m);
  return Encode(m);
}

void Gateway::FillTelemetry(std::size_t p, pumptherm::telemetry_t& m) const {
  const PumpIo& io = io_[p];
  const Pump& pump = *pumps_[p];
  auto at = [&](MappingInput i) { return io.inputs[static_cast<std::size_t>(i)]; };
  m.utime = io.inputs_us + wall_offset_us_;
  m.pump = pump.config().name;
  m.node_id = static_cast<std::int32_t>(pump.config().node_id);
  m.id_A = at(MappingInput::kIdA);
  m.iq_A = at(MappingInput::kIqA);
  m.ud_V = at(MappingInput::kUdV);
  m.uq_V = at(MappingInput::kUqV);
  m.speed_rpm = at(MappingInput::kSpeedMechRpm);
  const double counter = at(MappingInput::kRollingCounter);
  m.rolling_counter = static_cast<std::int16_t>(std::isfinite(counter) ? counter : -1);
  const double state = at(MappingInput::kDriveState);
  m.drive_state = static_cast<std::int8_t>(std::isfinite(state) ? state : -1);
  m.frame_sensor_degC = at(MappingInput::kFrameSensorDegC);
  m.ambient_degC = at(MappingInput::kAmbientDegC);
  m.coolant_degC = kNaN;
  m.dc_link_V = at(MappingInput::kDcLinkV);
  m.status_age_s =
      io.status_us >= 0 ? static_cast<double>(io.inputs_us - io.status_us) * 1e-6 : kNaN;
}

void Gateway::LogMismatch(const Pump& pump) const {
  const JournalEntry entry = DiagnosisEntry(pump.config().name, pump.snapshot().mismatch,
                                            pump.config().measured_node, wall_offset_us_);
  LogLine(entry.level, entry.text, entry.fields);
}

std::vector<std::uint8_t> Gateway::EncodeAlarm(const Pump& pump) const {
  pumptherm::alarm_t m;
  FillAlarm(pump, m);
  return Encode(m);
}

void Gateway::FillAlarm(const Pump& pump, pumptherm::alarm_t& m) const {
  const PumpSnapshot& s = pump.snapshot();
  m.utime = s.time_us + wall_offset_us_;
  m.pump = pump.config().name;
  FillLcm(Source(pump), m);
  const auto& names = pump.model().StateNames();
  // Assigned in place (no temporary strings): no allocation once the strings have held as much.
  auto set_node_name = [&](std::string& out, int node) {
    if (node >= 0 && node < static_cast<int>(names.size())) {
      out = names[static_cast<std::size_t>(node)];
    } else if (node == static_cast<int>(names.size())) {
      out = "winding_resistance";
    } else {
      out.clear();
    }
  };
  if (std::isfinite(s.alarm.time_to_trip_s)) {
    set_node_name(m.forecast_node, s.time_to_trip_node);
  } else {
    m.forecast_node.clear();
  }
  pump.ActiveConditions(conditions_);
  m.conditions.resize(conditions_.size());
  for (std::size_t k = 0; k < conditions_.size(); ++k) {
    const auto& c = conditions_[k];
    pumptherm::alarm_condition_t& ac = m.conditions[k];
    ac.level = static_cast<std::int8_t>(c.level);
    ac.reason = static_cast<std::int8_t>(c.reason);
    if (c.node < 0) {
      if (c.reason == estimators::AlarmReason::kStaleTelemetry) {
        ac.node = "telemetry";
      } else {
        ac.node.clear();
      }
    } else {
      set_node_name(ac.node, c.node);
    }
    const bool temp = c.reason == estimators::AlarmReason::kEstimatedOverTemperature ||
                      c.reason == estimators::AlarmReason::kMeasuredOverTemperature;
    ac.value_degC = temp ? c.value : kNaN;
    ac.threshold_degC = c.threshold;
    ac.rate_K_per_s = c.reason == estimators::AlarmReason::kRateOfRise ? c.value / 60.0 : kNaN;
    ac.since_utime = static_cast<std::int64_t>(c.raised_at_s * 1e6) + wall_offset_us_;
    ac.latched = c.latched;
  }
  m.num_conditions = static_cast<std::int32_t>(m.conditions.size());
}

std::vector<std::uint8_t> Gateway::EncodeHealth(std::int64_t now_us) const {
  pumptherm::gateway_health_t m;
  FillHealth(now_us, m);
  return Encode(m);
}

namespace {
std::int8_t LcmBusState(BusState state) {
  using H = pumptherm::interface_health_t;
  switch (state) {
    case BusState::kErrorActive:
      return H::BUS_STATE_ERROR_ACTIVE;
    case BusState::kErrorWarning:
      return H::BUS_STATE_ERROR_WARNING;
    case BusState::kErrorPassive:
      return H::BUS_STATE_ERROR_PASSIVE;
    case BusState::kBusOff:
      return H::BUS_STATE_BUS_OFF;
    case BusState::kUnknown:
      break;
  }
  return H::BUS_STATE_UNKNOWN;
}
}  // namespace

void Gateway::FillHealth(std::int64_t now_us, pumptherm::gateway_health_t& m) const {
  m.utime = now_us + wall_offset_us_;
  m.uptime_s = static_cast<double>(now_us - start_us_) * 1e-6;
  m.num_pumps = static_cast<std::int32_t>(pumps_.size());
  m.lcm_publish_failures = static_cast<std::int64_t>(counters_.lcm_failed);
  m.clears_accepted = static_cast<std::int64_t>(counters_.clears_accepted);
  m.clears_refused = static_cast<std::int64_t>(counters_.clears_refused);
  m.clears_unauthenticated = static_cast<std::int64_t>(counters_.clears_unauthenticated);
  m.mqtt_enabled = mqtt_health_.enabled;
  m.mqtt_connected = mqtt_health_.connected;
  m.mqtt_dropped = static_cast<std::int64_t>(mqtt_health_.dropped);
  m.mqtt_alarms_dropped = static_cast<std::int64_t>(mqtt_health_.alarms_dropped);
  const auto& interfaces = counter_.interfaces();
  m.interfaces.resize(interfaces.size());
  for (std::size_t k = 0; k < interfaces.size(); ++k) {
    const auto& c = interfaces[k];
    pumptherm::interface_health_t& h = m.interfaces[k];
    h.name = c.name;
    h.bus_state = c.up ? LcmBusState(c.bus_state) : pumptherm::interface_health_t::BUS_STATE_DOWN;
    h.rx_frames_per_s = kNaN;
    h.tx_frames_per_s = kNaN;
    h.rx_frames = static_cast<std::int64_t>(c.rx_frames);
    h.tx_frames = static_cast<std::int64_t>(c.tx_frames);
    h.rx_dropped = static_cast<std::int64_t>(c.rx_queue_drops);
    h.tx_dropped = static_cast<std::int64_t>(c.tx_dropped);
    h.rx_rejected = static_cast<std::int64_t>(counters_.rx_bad_length + counters_.rx_unknown_id);
    h.error_frames = static_cast<std::int64_t>(c.rx_error_frames);
    h.reopens = static_cast<std::int64_t>(c.reopens);
    h.rx_second_sender = static_cast<std::int64_t>(c.rx_second_sender);
  }
  m.num_interfaces = static_cast<std::int32_t>(m.interfaces.size());
}

}  // namespace pumptherm::daemon
