// The gateway's CAN output: each output signal's value from the published fields
// (daemon/published_fields.hpp), and the frames of an output plan encoded and handed to the sink.
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "daemon/gateway.hpp"
#include "daemon/gateway_detail.hpp"

namespace pumptherm::daemon {

FieldSource Gateway::Source(const Pump& pump) const {
  FieldSource f;
  f.estimate = &pump.snapshot();
  f.model = &pump.model();
  f.nis_limit = pump.config().alarms.monitor.nis_limit;
  f.wall_offset_us = static_cast<double>(wall_offset_us_);
  return f;
}

FieldSource Gateway::Source(std::size_t p, int node) const {
  const Pump& pump = *pumps_[p];
  FieldSource f = Source(pump);
  f.node = node;
  f.uptime_s =
      last_now_us_ >= start_us_ ? static_cast<double>(last_now_us_ - start_us_) * 1e-6 : 0.0;
  f.frame_rate_Hz = io_[p].frame_rate_Hz;
  f.lost_frames = static_cast<double>(pump.counters().lost_frames);
  // The DBC's VAL_ table: 0 error active (also warning and unknown), 1 passive, 2 bus off, 3 down.
  const InterfaceCounters& c = counter_.interfaces()[io_[p].iface];
  f.bus_state = !c.up                                    ? 3.0
                : c.bus_state == BusState::kBusOff       ? 2.0
                : c.bus_state == BusState::kErrorPassive ? 1.0
                                                         : 0.0;
  return f;
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
  const FieldSource source = Source(p, node);
  for (const OutputSignal& o : plan.signals) {
    double v = kNaN;
    switch (o.source) {
      case OutputSource::kField:
        v = o.field->value(source);
        break;
      case OutputSource::kNode:
        v = s.initialised && o.state >= 0 ? s.node_degC[static_cast<std::size_t>(o.state)] : kNaN;
        break;
      case OutputSource::kRollingCounter:
        v = plan.counter;
        break;
    }
    // A value that is not finite (none yet, no trip foreseen) goes out as "not available".
    values_[static_cast<std::size_t>(o.signal_index)] =
        std::isfinite(v) ? (v - o.offset) / o.scale : kNaN;
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
