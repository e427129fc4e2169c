#include "tools/pumptherm/clear_can.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <span>
#include <vector>

#include "daemon/published_fields.hpp"
#include "protocol/codec.hpp"
#include "tools/pumptherm/subcommand.hpp"

namespace pumptherm::tools {
namespace {

bool Contains(const std::vector<std::string>& v, const std::string& x) {
  return std::find(v.begin(), v.end(), x) != v.end();
}

const char* LevelName(GatewayAlarmLevel l) {
  switch (l) {
    case GatewayAlarmLevel::kNormal:
      return "normal";
    case GatewayAlarmLevel::kWarning:
      return "warning";
    case GatewayAlarmLevel::kTrip:
      return "trip";
  }
  return "?";
}

}  // namespace

ClearRouteChoice ChooseClearRoute(const daemon::DaemonConfig& c, const daemon::PumpConfig& pump,
                                  std::string_view via) {
  const bool lcm_ok = !c.lcm.url.empty() && !c.gateway.signing_key_file.empty();
  const bool can_ok =
      !pump.interface.empty() && Contains(pump.alarms.clear_can_interfaces, pump.interface);
  if (via == "lcm" || (via == "auto" && lcm_ok)) {
    if (!lcm_ok) {
      throw InputError(
          fmt::format("{}: LCM clears need lcm.url and gateway.signing_key_file (or give --url and "
                      "--gateway-key)",
                      c.source));
    }
    return {ClearRoute::kLcm, {}};
  }
  if (via == "can" || via == "auto") {
    if (!can_ok) {
      throw InputError(fmt::format(
          "{}: pump '{}' is on interface '{}', which is not in alarms.clear_can_interfaces{}: the "
          "gateway would "
          "refuse a CAN clear{}",
          c.source, pump.name, pump.interface,
          pump.alarms.clear_can_interfaces.empty() ? " (empty)" : "",
          via == "auto" ? "; and LCM clears need lcm.url and gateway.signing_key_file" : ""));
    }
    return {ClearRoute::kCan, pump.interface};
  }
  throw InputError(fmt::format("--via {}: expected lcm, can or auto", via));
}

protocol::CanFrame EncodeClearFrame(const protocol::Dbc& dbc,
                                    const protocol::SignalMapping& mapping, std::uint32_t node_id) {
  const auto& ref = mapping.input(protocol::MappingInput::kAlarmClear);
  if (!ref)
    throw InputError("the signal mapping has no alarm_clear: this frame set has no CAN clear");
  if (node_id >= mapping.node_id_limit) {
    throw InputError(fmt::format("node ID {} is not below the mapping's node_id_limit {}", node_id,
                                 mapping.node_id_limit));
  }
  const protocol::DbcMessage& m = dbc.messages[static_cast<std::size_t>(ref->message_index)];
  // Signals other than the clear are sent as "not available"; the clear as the DBC value that
  // the mapping turns into 1 (estimator value = scale * DBC value + offset).
  std::vector<double> values(m.signals.size(), std::nan(""));
  values[static_cast<std::size_t>(ref->signal_index)] = (1.0 - ref->offset) / ref->scale;
  protocol::CanFrame f;
  f.id = mapping.CanId(dbc, ref->message_index, node_id);
  f.extended = m.extended;
  f.len = static_cast<std::uint8_t>(m.size_bytes);
  const auto r =
      protocol::MessageCodec(m).Encode(values, std::span<std::uint8_t>(f.data.data(), f.len));
  if (r.status != protocol::CodecStatus::kOk) {
    throw InputError(fmt::format("{}: cannot encode {}", dbc.file_name, m.name));
  }
  return f;
}

std::optional<GatewayAlarmLevel> AlarmLevelOf(const protocol::Dbc& dbc,
                                              const protocol::SignalMapping& mapping,
                                              std::uint32_t node_id,
                                              const protocol::CanFrame& frame) {
  const protocol::SignalRef* ref = mapping.output(daemon::kAlarmLevelKey);
  if (!ref || node_id >= mapping.node_id_limit) return std::nullopt;
  const protocol::DbcMessage& m = dbc.messages[static_cast<std::size_t>(ref->message_index)];
  if (frame.id != mapping.CanId(dbc, ref->message_index, node_id) || frame.extended != m.extended) {
    return std::nullopt;
  }
  std::vector<double> values(m.signals.size());
  const protocol::MessageCodec codec(m);
  if (codec.Decode(std::span<const std::uint8_t>(frame.data.data(), frame.len), values) !=
      protocol::CodecStatus::kOk) {
    return std::nullopt;
  }
  const double v = ref->scale * values[static_cast<std::size_t>(ref->signal_index)] + ref->offset;
  if (!std::isfinite(v) || v < 0.0 || v > 2.0) return std::nullopt;
  return static_cast<GatewayAlarmLevel>(std::lround(v));
}

std::pair<int, std::string> DescribeCanClear(const std::string& pump, const std::string& interface,
                                             const CanClearOutcome& o, double waited_s) {
  const std::string before = o.before ? LevelName(*o.before) : "not seen";
  if (!o.after) {
    return {1,
            fmt::format(
                "{}: PUMP_CLEAR sent on {}, but no GW_ALARM of this pump came back within {} s (is "
                "pumpthermd running and sending on {}?)",
                pump, interface, waited_s, interface)};
  }
  const std::string after = LevelName(*o.after);
  if (*o.after != GatewayAlarmLevel::kTrip) {
    const bool was_trip = o.before == GatewayAlarmLevel::kTrip;
    return {0,
            fmt::format("{}: PUMP_CLEAR sent on {}; the gateway's GW_ALARM: {} before, {} after{}",
                        pump, interface, before, after,
                        was_trip ? ": trip cleared" : " (there was no trip to clear)")};
  }
  return {
      1,
      fmt::format(
          "{}: PUMP_CLEAR sent on {}; the gateway's GW_ALARM still says trip after {} s: refused "
          "(the gateway does not list {} in alarms.clear_can_interfaces, or another clear came "
          "within 2 s) or the condition is still present; the gateway's journal says which",
          pump, interface, waited_s, interface)};
}

}  // namespace pumptherm::tools
