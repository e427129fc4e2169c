// A second sender on the bus (docs/threat-model.md, "CAN"): the gateway's own output IDs heard
// from elsewhere, a pump's message faster than its cycle, a broken rolling counter; counted,
// raised as each pump's second-sender warning, and named in the journal.
#include <fmt/format.h>

#include "daemon/gateway.hpp"
#include "daemon/gateway_detail.hpp"
#include "daemon/log.hpp"

namespace pumptherm::daemon {

using gateway_detail::RouteKey;

void Gateway::AddOwnIds(const PumpIo& io, std::size_t p) {
  const PumpConfig& pc = config_.pumps[p];
  for (const OutputPlan& plan : io.outputs) {
    const auto& msg = dbc_.messages[static_cast<std::size_t>(plan.message_index)];
    const std::uint32_t id = mapping_.CanId(dbc_, plan.message_index, pc.node_id);
    own_ids_[RouteKey(io.iface, msg.extended, id)] = static_cast<std::uint32_t>(p);
  }
  if (config_.gateway.heartbeat_period_s > 0.0)
    own_ids_.try_emplace(RouteKey(io.iface, false, config_.gateway.heartbeat_id), kNoPump);
}

void Gateway::CheckSecondSender(std::size_t iface, const Route& r, const protocol::TimedFrame& tf,
                                const double* inputs) {
  const InputMessage& im = inputs_[r.message];
  InputChecks& c = io_[r.pump].checks[r.message];
  if (c.rate.OnFrame(tf.time_us)) {
    SecondSender(
        iface, r.pump, SecondSenderKind::kTooFast, tf,
        fmt::format("{:.1f} frames/s, where its cycle of {:.0f} ms allows {:.1f}",
                    c.rate.last_rate_Hz(), c.rate.cycle_s() * 1e3, 1.0 / c.rate.cycle_s()));
  }
  const double counter = inputs[static_cast<std::size_t>(protocol::MappingInput::kRollingCounter)];
  if (im.rolling_counter && c.counter.OnCounter(tf.time_us, counter)) {
    SecondSender(iface, r.pump, SecondSenderKind::kCounter, tf,
                 "its rolling counter repeated or ran back 3 times within 10 s");
  }
}

void Gateway::SecondSender(std::size_t iface, std::uint32_t pump, SecondSenderKind kind,
                           const protocol::TimedFrame& tf, const std::string& what) {
  ++counters_.rx_second_sender;
  ++counter_.counters(iface).rx_second_sender;
  const auto k = static_cast<std::size_t>(kind);
  const auto clear_us =
      static_cast<std::int64_t>(config_.alarms.monitor.second_sender_clear_s * 1e6);
  for (std::size_t p = 0; p < pumps_.size(); ++p) {
    if (pump != kNoPump ? p != pump : io_[p].iface != iface) continue;
    PumpIo& io = io_[p];
    pumps_[p]->RaiseSecondSender(tf.time_us);
    MarkDue(p);
    // Named once per kind while it lasts (the warning's quiet time), every frame counted.
    const bool quiet = io.second_sender_seen_us[k] < 0 ||
                       tf.time_us < io.second_sender_seen_us[k] ||
                       tf.time_us - io.second_sender_seen_us[k] >= clear_us;
    io.second_sender_seen_us[k] = tf.time_us;
    if (!quiet) continue;
    const std::string& name = pumps_[p]->config().name;
    const std::string& bus = counter_.interfaces()[iface].name;
    const std::string id = fmt::format("{:X}", tf.frame.id);
    LogFields(
        LogLevel::kWarning,
        {{"PUMP", name}, {"CAN_ID", id}, {"KIND", SecondSenderKindName(kind)}, {"INTERFACE", bus}},
        "pump {}: a second sender on the bus: ID {} on {}: {} (counted in rx_second_sender; "
        "docs/threat-model.md)",
        name, id, bus, what);
  }
}

}  // namespace pumptherm::daemon
