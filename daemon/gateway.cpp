// The gateway's frame path: frames routed to their pumps and decoded into inputs, and the
// time-driven work (thermal steps, output frames, LCM, health) run when it is due. Construction
// is in gateway_setup.cpp, the outputs' encoding in gateway_can_out.cpp and gateway_lcm.cpp,
// alarm clears in gateway_clear.cpp, the terminal tables in gateway_table.cpp and the saved state
// in gateway_state.cpp.
#include "daemon/gateway.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "daemon/alarm_journal.hpp"
#include "daemon/gateway_detail.hpp"
#include "daemon/log.hpp"

namespace pumptherm::daemon {
namespace {

using gateway_detail::EncodeInto;
using gateway_detail::RouteKey;
using protocol::MappingInput;

}  // namespace

std::size_t Gateway::Interface(std::string_view name) { return counter_.Interface(name); }

void Gateway::OnFrame(std::size_t iface, const protocol::TimedFrame& tf) {
  counter_.OnFrame(iface, tf);
  if (tf.frame.error || tf.frame.remote) return;
  const Route r = FindRoute(iface, tf.frame);
  if (r.pump == kNoPump) {
    // The gateway never receives the frames it sends: one of its own IDs is someone else's.
    if (const auto own = own_ids_.find(RouteKey(iface, tf.frame.extended, tf.frame.id));
        own != own_ids_.end()) {
      SecondSender(iface, own->second, SecondSenderKind::kOwnId, tf,
                   "a frame of the gateway's own output ID, which it did not send");
      return;
    }
    ++counters_.rx_unknown_id;
    WarnUnconfiguredNode(iface, tf);
    return;
  }
  const InputMessage& im = inputs_[r.message];
  const auto& codec = codec_->message(static_cast<std::size_t>(im.message_index));
  if (codec.Decode(std::span<const std::uint8_t>(tf.frame.data.data(), tf.frame.len), values_) !=
      protocol::CodecStatus::kOk) {
    ++counters_.rx_bad_length;
    return;
  }
  double v[protocol::kMappingInputCount];
  for (double& x : v) x = kNaN;
  PumpIo& io = io_[r.pump];
  for (const InputSignal& s : im.signals) {
    const double x = s.scale * values_[static_cast<std::size_t>(s.signal_index)] + s.offset;
    v[static_cast<std::size_t>(s.input)] = x;
    io.inputs[static_cast<std::size_t>(s.input)] = x;
  }
  io.inputs_us = tf.time_us;
  CheckSecondSender(iface, r, tf, v);
  Pump& pump = *pumps_[r.pump];
  auto at = [&](MappingInput i) { return v[static_cast<std::size_t>(i)]; };
  if (im.currents) {
    pump.OnCurrents(tf.time_us, at(MappingInput::kIdA), at(MappingInput::kIqA),
                    at(MappingInput::kSpeedElecRadPerS), at(MappingInput::kRollingCounter));
  }
  if (im.voltages) {
    pump.OnVoltages(tf.time_us, at(MappingInput::kUdV), at(MappingInput::kUqV),
                    im.currents ? at(MappingInput::kRollingCounter) : kNaN);
  }
  if (im.clear) {
    // A command, not telemetry. Held buttons repeat it: act at most every 2 s.
    const double c = at(MappingInput::kAlarmClear);
    if (c >= 0.5 && (io.last_clear_us < 0 || tf.time_us - io.last_clear_us >= 2'000'000)) {
      io.last_clear_us = tf.time_us;
      io.clear_repeat_logged = false;
      Clear(pump.config().name, "can:" + counter_.interfaces()[iface].name, "PUMP_CLEAR frame");
    } else if (c >= 0.5) {
      RateLimitedClear(io, pump.config().name, counter_.interfaces()[iface].name);
    }
    return;
  }
  if (im.status) {
    io.status_us = tf.time_us;
    pump.OnStatus(tf.time_us, at(MappingInput::kSpeedMechRpm), at(MappingInput::kDriveState),
                  at(MappingInput::kFrameSensorDegC), at(MappingInput::kAmbientDegC));
  }
  // A pump's first frame starts its thermal steps and outputs at the next Advance.
  if (!pump.heard() && pump.last_frame_us() >= 0) MarkDue(r.pump);
}

Gateway::Route Gateway::FindRoute(std::size_t iface, const protocol::CanFrame& f) const {
  if (!f.extended && f.id < kStandardIds) {
    const std::size_t k = iface * kStandardIds + f.id;
    return k < standard_routes_.size() ? standard_routes_[k] : Route{kNoPump, 0};
  }
  const auto it = routes_.find(RouteKey(iface, f.extended, f.id));
  return it == routes_.end() ? Route{kNoPump, 0} : it->second;
}

void Gateway::WarnUnconfiguredNode(std::size_t iface, const protocol::TimedFrame& tf) {
  constexpr std::int64_t kWarnEvery_us = 60'000'000;
  for (const InputMessage& im : inputs_) {
    const auto& msg = dbc_.messages[static_cast<std::size_t>(im.message_index)];
    if (msg.extended != tf.frame.extended || tf.frame.id < msg.id ||
        tf.frame.id - msg.id >= mapping_.node_id_limit) {
      continue;
    }
    ++counters_.rx_unconfigured_node;
    if (!config_.gateway.warn_unconfigured_nodes) return;
    const std::uint32_t node = tf.frame.id - msg.id;
    const std::uint64_t key = (static_cast<std::uint64_t>(iface) << 32) | node;
    auto [it, first] = unconfigured_warned_us_.try_emplace(key, tf.time_us);
    if (!first && tf.time_us - it->second < kWarnEvery_us && tf.time_us >= it->second) return;
    it->second = tf.time_us;
    std::string silent;
    for (std::size_t p = 0; p < pumps_.size(); ++p) {
      if (io_[p].iface != iface || io_[p].inputs_us >= 0 || io_[p].status_us >= 0) continue;
      silent += fmt::format("{}{} (node_id {})", silent.empty() ? "" : ", ",
                            pumps_[p]->config().name, pumps_[p]->config().node_id);
    }
    const std::string& name = counter_.interfaces()[iface].name;
    Log(LogLevel::kWarning, "{}: {} frames (ID {:X}) from node ID {}, which no pump on {} has; {}",
        name, msg.name, tf.frame.id, node, name,
        silent.empty() ? "every pump configured there is heard from"
                       : "not heard from yet there: " + silent + " - is its node_id wrong?");
    return;
  }
}

void Gateway::Advance(std::int64_t now_us, OutputSink& sink) {
  last_now_us_ = now_us;
  if (now_us < next_due_us_) return;
  if (start_us_ < 0) {
    start_us_ = now_us;
    next_health_us_ = now_us;
  }
  // The summary of refused clears held back is at most one health period late (Advance runs at
  // least that often).
  ReportRefusedClearsHeldBack(now_us);
  std::int64_t next_due_us = std::numeric_limits<std::int64_t>::max();
  for (std::size_t p = 0; p < pumps_.size(); ++p) {
    if (io_[p].due_us <= now_us) {
      AdvancePump(p, now_us, sink);
      io_[p].due_us = PumpDueUs(p);
    }
    next_due_us = std::min(next_due_us, io_[p].due_us);
  }
  AdvanceHealth(now_us, sink);
  next_due_us_ = std::min(next_due_us, next_health_us_);
}

void Gateway::MarkAllDue() {
  for (PumpIo& io : io_) io.due_us = kDueNow;
  next_due_us_ = kDueNow;
}

std::int64_t Gateway::PumpDueUs(std::size_t p) const {
  const Pump& pump = *pumps_[p];
  const PumpIo& io = io_[p];
  std::int64_t due = pump.NextDueUs();
  const bool never_heard = pump.last_frame_us() < 0;
  // A silent pump without an alarm sends nothing (AdvancePump): only its silence is timed.
  if (never_heard && pump.snapshot().alarm.level == estimators::AlarmLevel::kNone) return due;
  if (pump.snapshot().alarm_changes != io.alarm_changes_sent ||
      pump.snapshot().mismatch_changes != io.mismatch_changes_logged ||
      pump.snapshot().sensor_steps != io.sensor_steps_logged ||
      pump.snapshot().starts != io.starts_logged ||
      pump.snapshot().r0_changes != io.r0_changes_logged ||
      pump.snapshot().magnet_law_changes != io.magnet_law_logged ||
      pump.snapshot().sensor_lag_changes != io.sensor_lag_logged) {
    return kDueNow;
  }
  for (const OutputPlan& plan : io.outputs) {
    if (never_heard && !plan.alarm) continue;
    due = std::min(due, plan.next_due_us < 0 ? kDueNow : plan.next_due_us);
  }
  return std::min(due, io.next_lcm_us < 0 ? kDueNow : io.next_lcm_us);
}

void Gateway::AdvancePump(std::size_t p, std::int64_t now_us, OutputSink& sink) {
  const auto lcm_period_us = static_cast<std::int64_t>(std::llround(config_.lcm.period_s * 1e6));
  Pump& pump = *pumps_[p];
  PumpIo& io = io_[p];
  pump.Advance(now_us);
  const bool latched = pump.snapshot().alarm.trip_latched;
  if (latched && !io.trip_latched) ++counters_.trip_latches;
  io.trip_latched = latched;
  // A pump never heard from raises stale telemetry after stale_after_s, as one that fell silent;
  // only its alarm frames go out (nothing else is known of it).
  const bool never_heard = pump.last_frame_us() < 0;
  if (never_heard && !pump.CheckNeverHeard(start_us_, now_us) &&
      pump.snapshot().alarm.level == estimators::AlarmLevel::kNone) {
    return;
  }
  const bool alarm_changed = pump.snapshot().alarm_changes != io.alarm_changes_sent;
  for (OutputPlan& plan : io.outputs) {
    if (never_heard && !plan.alarm) continue;
    if (plan.next_due_us < 0) plan.next_due_us = now_us;
    if (now_us >= plan.next_due_us || (plan.alarm && alarm_changed)) {
      Emit(p, plan, now_us, sink);
      plan.next_due_us += plan.period_us;
      if (plan.next_due_us <= now_us) plan.next_due_us = now_us + plan.period_us;
    }
  }
  if (io.next_lcm_us < 0) io.next_lcm_us = now_us;
  const std::string& name = pump.config().name;
  auto publish = [&](const std::string& channel) {
    if (sink.PublishLcm(channel, now_us, lcm_bytes_)) {
      ++counters_.lcm_published;
    } else {
      ++counters_.lcm_failed;
    }
  };
  auto publish_alarm = [&] {
    FillAlarm(pump, io.alarm_msg);
    EncodeInto(io.alarm_msg, lcm_bytes_);
    publish(io.channel_alarm);
  };
  if (alarm_changed) {
    io.alarm_changes_sent = pump.snapshot().alarm_changes;
    publish_alarm();
    const auto& a = pump.snapshot().alarm;
    pump.ActiveConditions(conditions_);
    const JournalEntry entry = AlarmEntry(
        {name, &a, conditions_, &pump.model().StateNames(), io.logged_active_reasons,
         &pump.config().alarms.monitor, pump.config().measured_node, &pump.snapshot().mismatch,
         wall_offset_us_, pump.motor().max_current_A, pump.snapshot().alarm_rule});
    LogLine(entry.level, entry.text, entry.fields);
    io.logged_active_reasons = a.active_reasons;
  }
  if (pump.snapshot().starts != io.starts_logged) {
    io.starts_logged = pump.snapshot().starts;
    const JournalEntry entry = StartEntry(name, pump.snapshot(), !pump.config().magnet_node.empty(),
                                          pump.estimator().observer().TakesVoltage());
    LogLine(entry.level, entry.text, entry.fields);
  }
  if (pump.snapshot().r0_changes != io.r0_changes_logged) {
    io.r0_changes_logged = pump.snapshot().r0_changes;
    const JournalEntry entry = R0Entry(
        name, pump.snapshot(), pump.motor().copper, pump.estimator().config().max_calibration_sd_K,
        pump.estimator().observer().Weighted_degC(pump.model().WindingWeights()));
    LogLine(entry.level, entry.text, entry.fields);
  }
  if (pump.snapshot().magnet_law_changes != io.magnet_law_logged) {
    io.magnet_law_logged = pump.snapshot().magnet_law_changes;
    const JournalEntry entry = MagnetLawEntry(
        name, pump.snapshot(), pump.motor().magnet.flux_temperature_coefficient_per_K);
    LogLine(entry.level, entry.text, entry.fields);
  }
  if (pump.snapshot().mismatch_changes != io.mismatch_changes_logged) {
    io.mismatch_changes_logged = pump.snapshot().mismatch_changes;
    LogMismatch(pump);
  }
  if (pump.snapshot().sensor_lag_changes != io.sensor_lag_logged) {
    io.sensor_lag_logged = pump.snapshot().sensor_lag_changes;
    const std::string& sensor = pump.config().measured_node;
    LogFields(LogLevel::kWarning, {{"PUMP", name}, {"NODE", sensor}},
              "{}: {} sensor read with a lag of {:.0f} s {}, the lag the model diagnosis "
              "fitted (configured {:g} s; kept across restarts while that is configured): set "
              "frame_sensor_lag_s = {:.0f}",
              name, sensor, pump.snapshot().frame_sensor_lag_s,
              pump.snapshot().frame_sensor_lag_restored ? "as before the restart" : "from now",
              pump.config().frame_sensor_lag_s, pump.snapshot().frame_sensor_lag_s);
  }
  if (pump.snapshot().sensor_steps != io.sensor_steps_logged) {
    io.sensor_steps_logged = pump.snapshot().sensor_steps;
    const std::string& sensor = pump.config().measured_node;
    LogFields(LogLevel::kWarning, {{"PUMP", name}, {"NODE", sensor}},
              "{}: {} sensor reading stepped {:+.1f} K, faster than the {} can move: taken as a "
              "step of the sensor's offset (now {:+.1f} K)",
              name, sensor, pump.snapshot().last_sensor_step_K, sensor,
              pump.snapshot().sensor_offset_K);
  }
  if (now_us >= io.next_lcm_us) {
    FillTelemetry(p, io.telemetry_msg);
    EncodeInto(io.telemetry_msg, lcm_bytes_);
    publish(io.channel_telemetry);
    if (pump.snapshot().initialised) {
      FillTemperatures(pump, io.temperatures_msg);
      EncodeInto(io.temperatures_msg, lcm_bytes_);
      publish(io.channel_temperatures);
    }
    if (!alarm_changed) publish_alarm();
    io.next_lcm_us += lcm_period_us;
    if (io.next_lcm_us <= now_us) io.next_lcm_us = now_us + lcm_period_us;
  }
}

void Gateway::AdvanceHealth(std::int64_t now_us, OutputSink& sink) {
  if (now_us < next_health_us_) return;
  for (std::size_t p = 0; p < pumps_.size(); ++p) {
    PumpIo& io = io_[p];
    const auto& c = pumps_[p]->counters();
    const std::uint64_t frames = c.fast_frames + c.status_frames;
    if (io.last_health_us >= 0 && now_us > io.last_health_us) {
      io.frame_rate_Hz = static_cast<double>(frames - io.frames_at_last_health) /
                         (static_cast<double>(now_us - io.last_health_us) * 1e-6);
    }
    io.frames_at_last_health = frames;
    io.last_health_us = now_us;
  }
  FillHealth(now_us, health_msg_);
  EncodeInto(health_msg_, lcm_bytes_);
  if (sink.PublishLcm(channel_health_, now_us, lcm_bytes_)) {
    ++counters_.lcm_published;
  } else {
    ++counters_.lcm_failed;
  }
  next_health_us_ =
      now_us + static_cast<std::int64_t>(std::llround(config_.lcm.health_period_s * 1e6));
}

}  // namespace pumptherm::daemon
