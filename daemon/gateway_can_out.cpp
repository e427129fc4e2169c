// The gateway's CAN output: each output signal's value from the pump's snapshot, and the frames
// of an output plan encoded and handed to the sink.
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "daemon/gateway.hpp"
#include "daemon/gateway_detail.hpp"

namespace pumptherm::daemon {

using gateway_detail::AlarmKnown;
using protocol::MappingOutput;

double Gateway::OutputValue(std::size_t p, MappingOutput output, int node) const {
  const Pump& pump = *pumps_[p];
  const PumpSnapshot& s = pump.snapshot();
  const bool ident = s.resistance.status != estimators::ResistanceStatus::kInitialising &&
                     s.resistance.status != estimators::ResistanceStatus::kInvalidInput;
  switch (output) {
    case MappingOutput::kWindingResTempDegC:
      return s.winding_resistance_degC;
    case MappingOutput::kMagnetFluxTempDegC:
      return s.magnet_flux_degC;
    case MappingOutput::kRsOhm:
      return ident ? s.resistance.resistance_ohm : kNaN;
    case MappingOutput::kFluxWb:
      return ident ? s.resistance.flux_Wb : kNaN;
    case MappingOutput::kWindingResSdK:
      // Only with the temperature it belongs to (as on LCM and in the CSV).
      return std::isfinite(s.winding_resistance_degC) ? s.resistance.winding_sd_K : kNaN;
    case MappingOutput::kMagnetFluxSdK:
      return s.magnet_flux_sd_K;
    case MappingOutput::kRsStatus:
      return static_cast<double>(s.resistance.status);
    case MappingOutput::kFluxStatus:
      // While Rs cannot be told apart from psi_f, Rs is held and the flux is still tracked.
      return static_cast<double>(s.resistance.status ==
                                         estimators::ResistanceStatus::kNotIdentifiable
                                     ? estimators::ResistanceStatus::kTracking
                                     : s.resistance.status);
    // A latched trip goes out as a trip even while the filter has no estimate (just reset, or
    // restarted with only its trips restored).
    case MappingOutput::kAlarmLevel:
      return AlarmKnown(s) ? static_cast<double>(s.alarm.level) : kNaN;
    case MappingOutput::kAlarmReason:
      return AlarmKnown(s) ? static_cast<double>(s.alarm.reason) : kNaN;
    case MappingOutput::kAlarmNode: {
      // The model's node index (as node_index), or the winding temperature from resistance.
      if (!s.initialised || (s.alarm.node < 0 &&
                             s.alarm.reason != estimators::AlarmReason::kEstimatedOverTemperature))
        return kNaN;
      const auto count = static_cast<int>(pump.model().StateNames().size());
      return s.alarm.node >= 0 && s.alarm.node < count ? static_cast<double>(s.alarm.node)
                                                       : static_cast<double>(kAlarmNodeWindingRes);
    }
    case MappingOutput::kAlarmValueDegC: {
      const auto r = s.alarm.reason;
      const bool temp = r == estimators::AlarmReason::kEstimatedOverTemperature ||
                        r == estimators::AlarmReason::kMeasuredOverTemperature;
      return s.initialised && temp ? s.alarm.value : kNaN;
    }
    case MappingOutput::kTimeToTripS:
      return std::isfinite(s.alarm.time_to_trip_s) ? s.alarm.time_to_trip_s : kNaN;
    case MappingOutput::kMismatchState:
      return s.initialised ? static_cast<double>(s.mismatch.state) : kNaN;
    case MappingOutput::kMismatchEffect:
      return s.initialised ? static_cast<double>(s.mismatch.effect) : kNaN;
    case MappingOutput::kUptimeS:
      return last_now_us_ >= start_us_ ? static_cast<double>(last_now_us_ - start_us_) * 1e-6 : 0.0;
    case MappingOutput::kFrameRateHz:
      return io_[p].frame_rate_Hz;
    case MappingOutput::kDrops:
      return static_cast<double>(pump.counters().lost_frames);
    case MappingOutput::kNodeIndex:
      return node >= 0 ? static_cast<double>(node) : kNaN;
    case MappingOutput::kNodeCount:
      return static_cast<double>(s.node_degC.size());
    case MappingOutput::kNodeTempDegC:
      return s.initialised && node >= 0 && static_cast<std::size_t>(node) < s.node_degC.size()
                 ? s.node_degC[static_cast<std::size_t>(node)]
                 : kNaN;
    case MappingOutput::kNodeSdK:
      return s.initialised && node >= 0 && static_cast<std::size_t>(node) < s.node_sd_K.size()
                 ? s.node_sd_K[static_cast<std::size_t>(node)]
                 : kNaN;
    case MappingOutput::kBusState: {
      // The DBC's VAL_ table: 0 error active (also warning and unknown), 1 passive, 2 bus off, 3
      // down.
      const InterfaceCounters& c = counter_.interfaces()[io_[p].iface];
      if (!c.up) return 3.0;
      if (c.bus_state == BusState::kBusOff) return 2.0;
      return c.bus_state == BusState::kErrorPassive ? 1.0 : 0.0;
    }
  }
  return kNaN;
}

void Gateway::Emit(std::size_t p, OutputPlan& plan, std::int64_t time_us, OutputSink& sink) {
  if (!plan.node_table) {
    EmitFrame(p, plan, -1, time_us, sink);
    return;
  }
  // A node-indexed message: the next node of this pump's model, round robin.
  const auto count = static_cast<int>(pumps_[p]->model().StateNames().size());
  if (plan.next_node >= count) plan.next_node = 0;
  EmitFrame(p, plan, plan.next_node++, time_us, sink);
}

void Gateway::EmitFrame(std::size_t p, OutputPlan& plan, int node, std::int64_t time_us,
                        OutputSink& sink) {
  const auto& msg = dbc_.messages[static_cast<std::size_t>(plan.message_index)];
  const auto& codec = codec_->message(static_cast<std::size_t>(plan.message_index));
  std::fill(values_.begin(), values_.begin() + static_cast<std::ptrdiff_t>(codec.signal_count()),
            kNaN);
  const PumpSnapshot& s = pumps_[p]->snapshot();
  for (const OutputSignal& o : plan.signals) {
    double v = kNaN;
    switch (o.source) {
      case OutputSource::kMapped:
        v = OutputValue(p, o.output, node);
        break;
      case OutputSource::kNode:
        v = s.initialised && o.state >= 0 ? s.node_degC[static_cast<std::size_t>(o.state)] : kNaN;
        break;
      case OutputSource::kRollingCounter:
        v = plan.counter;
        break;
    }
    values_[static_cast<std::size_t>(o.signal_index)] =
        std::isnan(v) ? v : (v - o.offset) / o.scale;
  }
  plan.counter = static_cast<std::uint8_t>((plan.counter + 1) & 0x0F);
  protocol::CanFrame f;
  f.id = mapping_.CanId(dbc_, plan.message_index, pumps_[p]->config().node_id);
  f.extended = msg.extended;
  f.fd = msg.size_bytes > 8;
  f.len = static_cast<std::uint8_t>(codec.min_bytes());
  const auto r = codec.Encode(std::span<const double>(values_.data(), codec.signal_count()),
                              std::span<std::uint8_t>(f.data.data(), f.len));
  counters_.tx_saturated += r.saturated;
  sink.SendFrame(io_[p].iface, time_us, f);
}

}  // namespace pumptherm::daemon
