#include "daemon/gateway.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <ctime>
#include <limits>
#include <map>
#include <sstream>
#include <toml++/toml.h>

#include "daemon/log.hpp"
#include "daemon/resources.hpp"
#include "pumptherm/alarm_t.hpp"
#include "pumptherm/gateway_health_t.hpp"
#include "pumptherm/telemetry_t.hpp"
#include "pumptherm/temperatures_t.hpp"
#include "protocol/lcm/channels.hpp"

namespace pumptherm::daemon {
namespace {

/// Whether the alarm state is worth sending: with an estimate, with a latched trip (also while
/// the filter has none), or with any condition raised (a pump never heard from is stale).
bool AlarmKnown(const PumpSnapshot& s) {
  return s.initialised || s.alarm.trip_latched || s.alarm.level != estimators::AlarmLevel::kNone;
}

/// The journal's line for an alarm change: the worst level with its reason, node and value, every
/// active reason, and which reasons were raised and cleared since `logged_reasons` (the set the
/// previous line showed), e.g. "alarm trip (estimated_over_temperature, winding, value 121.30);
/// active: estimated_over_temperature, forecast; raised: estimated_over_temperature".
std::string AlarmChangeText(const estimators::AlarmState& a, std::uint16_t logged_reasons,
                            const std::vector<std::string>& node_names) {
  std::string out = fmt::format("alarm {} ({}", estimators::AlarmLevelName(a.level),
                                estimators::AlarmReasonName(a.reason));
  if (a.node >= 0 && static_cast<std::size_t>(a.node) < node_names.size()) {
    out += ", " + node_names[static_cast<std::size_t>(a.node)];
  } else if (a.node >= 0 && static_cast<std::size_t>(a.node) == node_names.size()) {
    out += ", winding_resistance";  // the alarm inputs' last entry: the winding from resistance
  }
  if (std::isfinite(a.value)) out += fmt::format(", value {:.2f}", a.value);
  out += ")";
  auto list = [](std::uint16_t bits) {
    std::string s;
    for (std::size_t r = 1; r < estimators::kAlarmReasonCount; ++r) {
      if (bits & (1u << r)) {
        s += (s.empty() ? "" : ", ") + std::string(estimators::AlarmReasonName(static_cast<estimators::AlarmReason>(r)));
      }
    }
    return s;
  };
  const std::uint16_t raised = a.active_reasons & static_cast<std::uint16_t>(~logged_reasons);
  const std::uint16_t cleared = logged_reasons & static_cast<std::uint16_t>(~a.active_reasons);
  if (a.active_reasons) out += "; active: " + list(a.active_reasons);
  if (raised) out += "; raised: " + list(raised);
  if (cleared) out += "; cleared: " + list(cleared);
  if (a.trip_latched) out += "; trip latched";
  return out;
}

using protocol::MappingInput;
using protocol::MappingOutput;

constexpr std::uint64_t RouteKey(std::size_t iface, bool extended, std::uint32_t id) {
  return (static_cast<std::uint64_t>(iface) << 33) | (static_cast<std::uint64_t>(extended) << 32) | id;
}

bool IsCurrentInput(MappingInput i) {
  return i == MappingInput::kIdA || i == MappingInput::kIqA;
}
bool IsVoltageInput(MappingInput i) {
  return i == MappingInput::kUdV || i == MappingInput::kUqV;
}
bool IsStatusInput(MappingInput i) {
  return i == MappingInput::kSpeedMechRpm || i == MappingInput::kDriveState ||
         i == MappingInput::kFrameTempDegC || i == MappingInput::kAmbientTempDegC ||
         i == MappingInput::kDcLinkV;
}

template <typename Message>
std::vector<std::uint8_t> Encode(const Message& m) {
  std::vector<std::uint8_t> bytes(static_cast<std::size_t>(m.getEncodedSize()));
  m.encode(bytes.data(), 0, static_cast<int>(bytes.size()));
  return bytes;
}

/// Encodes `m` into `bytes` (resized; no allocation once it has held a message this large).
template <typename Message>
void EncodeInto(const Message& m, std::vector<std::uint8_t>& bytes) {
  bytes.resize(static_cast<std::size_t>(m.getEncodedSize()));
  m.encode(bytes.data(), 0, static_cast<int>(bytes.size()));
}

/// DBC warnings logged one by one at start; the rest are counted.
constexpr std::size_t kMaxReportedDbcProblems = 20;

}  // namespace

Gateway::Gateway(const DaemonConfig& config)
    : config_(config), counter_(config.gateway), clear_auth_(config.clear_auth.window_s) {
  auto fail = [&](int line, const std::string& key, const std::string& what) -> ConfigError {
    return ConfigError(fmt::format("{}:{}: key '{}': {}", config_.source, line, key, what));
  };
  // Without pumps the gateway only counts frames: no frame layout is needed.
  if (config_.pumps.empty()) return;
  // The frame layout: DBC and mapping.
  std::string dbc_path;
  try {
    dbc_path = ResolveResource(ResourceKind::kDbc, config_.dbc.file, config_.dbc.base_dir);
    dbc_ = protocol::ParseDbc(ReadTextFile(dbc_path), dbc_path);
  } catch (const std::exception& e) {
    throw fail(0, "dbc.file", e.what());
  }
  // Statements the reader skipped and other oddities: the rest of the DBC is in use.
  for (std::size_t i = 0; i < dbc_.problems.size() && i < kMaxReportedDbcProblems; ++i) {
    const auto& p = dbc_.problems[i];
    Log(LogLevel::kWarning, "{}:{}:{}: {}", dbc_path, p.line, p.column, p.message);
  }
  if (dbc_.problems.size() > kMaxReportedDbcProblems) {
    Log(LogLevel::kWarning, "{}: {} more DBC warnings (pumptherm dbc check lists them)", dbc_path,
        dbc_.problems.size() - kMaxReportedDbcProblems);
  }
  try {
    const std::string path = ResolveResource(ResourceKind::kDbc, config_.dbc.mapping, config_.dbc.base_dir);
    mapping_ = protocol::ParseMapping(ReadTextFile(path), path, dbc_);
  } catch (const std::exception& e) {
    throw fail(0, "dbc.mapping", e.what());
  }
  codec_ = std::make_unique<protocol::DbcCodec>(dbc_);
  std::size_t max_signals = 1;
  for (const auto& m : dbc_.messages) max_signals = std::max(max_signals, m.signals.size());
  values_.assign(max_signals, kNaN);

  // Input messages and the inputs each carries.
  for (std::size_t i = 0; i < protocol::kMappingInputCount; ++i) {
    const auto& ref = mapping_.inputs[i];
    if (!ref) continue;
    const auto input = static_cast<MappingInput>(i);
    auto it = std::find_if(inputs_.begin(), inputs_.end(),
                           [&](const InputMessage& m) { return m.message_index == ref->message_index; });
    if (it == inputs_.end()) {
      inputs_.push_back(InputMessage{ref->message_index, {}});
      it = inputs_.end() - 1;
    }
    it->signals.push_back({input, ref->signal_index, ref->scale, ref->offset});
    it->currents = it->currents || IsCurrentInput(input);
    it->voltages = it->voltages || IsVoltageInput(input);
    it->status = it->status || IsStatusInput(input);
    it->clear = it->clear || input == MappingInput::kAlarmClear;
  }

  // Pumps.
  std::map<std::string, std::shared_ptr<const estimators::ThermalModel>> models;
  for (std::size_t p = 0; p < config_.pumps.size(); ++p) {
    const PumpConfig& pc = config_.pumps[p];
    const std::string key = fmt::format("pump[{}]", p);
    if (pc.node_id >= mapping_.node_id_limit) {
      throw fail(pc.line, key + ".node_id",
                 fmt::format("{} is not below the mapping's node_id_limit {}", pc.node_id, mapping_.node_id_limit));
    }
    bool known_interface = config_.interfaces.empty();
    for (const auto& i : config_.interfaces) known_interface = known_interface || i.name == pc.interface;
    if (!known_interface || pc.interface.empty()) {
      throw fail(pc.line, key + ".interface", fmt::format("'{}' is not a configured [[can]] interface", pc.interface));
    }
    estimators::MotorDescription motor;
    try {
      if (!estimators::MotorPresetText(pc.motor).empty()) {
        motor = estimators::MotorPreset(pc.motor);
      } else {
        const std::string path = ResolveResource(ResourceKind::kMotor, pc.motor, config_.dbc.base_dir);
        motor = estimators::ParseMotorDescription(ReadTextFile(path), path);
      }
    } catch (const std::exception& e) {
      throw fail(pc.line, key + ".motor", e.what());
    }
    std::shared_ptr<const estimators::ThermalModel> model;
    try {
      const std::string path = ResolveResource(ResourceKind::kModel, pc.thermal_model, config_.dbc.base_dir);
      auto it = models.find(path);
      if (it == models.end()) {
        it = models.emplace(path, std::make_shared<const estimators::ThermalModel>(
                                      estimators::ThermalModel::Parse(
                                      ReadTextFile(path), path,
                                      estimators::ThermalModelFiles{DirectoryOf(path), &ReadTextFile})))
                 .first;
      }
      model = it->second;
    } catch (const std::exception& e) {
      throw fail(pc.line, key + ".thermal_model", e.what());
    }
    try {
      pumps_.push_back(std::make_unique<Pump>(pc, motor, model, config_.gateway.thermal_period_s));
    } catch (const std::exception& e) {
      throw fail(pc.line, key, e.what());
    }
    if (!pc.disturbance_states_explicit && !pumps_.back()->config().disturbance_states) {
      Log(LogLevel::kNotice,
          "pump {}: standard filter published: the boundary of model {} reaches other nodes than '{}' "
          "(disturbance_states = true overrides)",
          pc.name, model->Name(), pc.measured_node);
    }
    CheckNodeOutputs(pc, key, *model);
    PumpIo io;
    io.iface = counter_.Interface(pc.interface);
    for (double& v : io.inputs) v = kNaN;
    // Output plans, one per output message.
    auto plan_for = [&](int message_index) -> OutputPlan& {
      for (auto& plan : io.outputs) {
        if (plan.message_index == message_index) return plan;
      }
      const auto& msg = dbc_.messages[static_cast<std::size_t>(message_index)];
      OutputPlan plan;
      plan.message_index = message_index;
      auto over = config_.output_periods_s.find(msg.name);
      const double period_s = over != config_.output_periods_s.end() ? over->second
                              : msg.cycle_time_ms && *msg.cycle_time_ms > 0 ? *msg.cycle_time_ms / 1000.0
                                                                             : 1.0;
      plan.period_us = std::max<std::int64_t>(1000, std::llround(period_s * 1e6));
      io.outputs.push_back(std::move(plan));
      return io.outputs.back();
    };
    for (std::size_t o = 0; o < protocol::kMappingOutputCount; ++o) {
      const auto& ref = mapping_.outputs[o];
      if (!ref) continue;
      OutputPlan& plan = plan_for(ref->message_index);
      plan.signals.push_back({ref->signal_index, OutputSource::kMapped, static_cast<MappingOutput>(o), -1,
                              ref->scale, ref->offset});
      plan.alarm = plan.alarm || static_cast<MappingOutput>(o) == MappingOutput::kAlarmLevel;
      plan.node_table = plan.node_table || static_cast<MappingOutput>(o) == MappingOutput::kNodeIndex;
    }
    for (const auto& [node, ref] : mapping_.node_temperatures) {
      OutputPlan& plan = plan_for(ref.message_index);
      // A node this pump's model does not have stays "not available" in the frame.
      plan.signals.push_back({ref.signal_index, OutputSource::kNode, MappingOutput::kWindingResTempDegC,
                              model->StateIndex(node), ref.scale, ref.offset});
    }
    for (auto& plan : io.outputs) {
      // A node-indexed message sends its nodes one after another, spread over the period: each
      // node once per period, and no burst of frames on one ID.
      const auto nodes = static_cast<std::int64_t>(model->StateNames().size());
      if (plan.node_table && nodes > 0) plan.period_us = std::max<std::int64_t>(1000, plan.period_us / nodes);
      const auto& msg = dbc_.messages[static_cast<std::size_t>(plan.message_index)];
      const int rc = msg.FindSignal("RollingCounter");
      const bool mapped = std::any_of(plan.signals.begin(), plan.signals.end(),
                                      [&](const OutputSignal& s) { return s.signal_index == rc; });
      if (rc >= 0 && !mapped) plan.signals.push_back({rc, OutputSource::kRollingCounter, MappingOutput::kUptimeS, -1, 1.0, 0.0});
    }
    // Routes of this pump's input frames.
    for (std::size_t m = 0; m < inputs_.size(); ++m) {
      const auto& msg = dbc_.messages[static_cast<std::size_t>(inputs_[m].message_index)];
      const std::uint32_t id = mapping_.CanId(dbc_, inputs_[m].message_index, pc.node_id);
      const auto route_key = RouteKey(io.iface, msg.extended, id);
      if (routes_.count(route_key)) {
        throw fail(pc.line, key + ".node_id", fmt::format("CAN ID {:X} on '{}' is already used", id, pc.interface));
      }
      routes_[route_key] = Route{static_cast<std::uint32_t>(p), static_cast<std::uint32_t>(m)};
    }
    const std::string& prefix = config_.lcm.channel_prefix;
    io.channel_telemetry = lcm_channels::PumpChannelName(prefix, pc.name, lcm_channels::PumpChannel::kTelemetry);
    io.channel_temperatures = lcm_channels::PumpChannelName(prefix, pc.name, lcm_channels::PumpChannel::kTemperatures);
    io.channel_alarm = lcm_channels::PumpChannelName(prefix, pc.name, lcm_channels::PumpChannel::kAlarm);
    io_.push_back(std::move(io));
  }
  channel_health_ = lcm_channels::GatewayHealthChannelName(config_.lcm.channel_prefix);
}

std::size_t Gateway::Interface(std::string_view name) { return counter_.Interface(name); }

void Gateway::OnFrame(std::size_t iface, const protocol::TimedFrame& tf) {
  counter_.OnFrame(iface, tf);
  if (tf.frame.error || tf.frame.remote) return;
  const auto it = routes_.find(RouteKey(iface, tf.frame.extended, tf.frame.id));
  if (it == routes_.end()) {
    ++counters_.rx_unknown_id;
    WarnUnconfiguredNode(iface, tf);
    return;
  }
  const Route r = it->second;
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
                  at(MappingInput::kFrameTempDegC), at(MappingInput::kAmbientTempDegC));
  }
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
    const std::uint32_t node = tf.frame.id - msg.id;
    const std::uint64_t key = (static_cast<std::uint64_t>(iface) << 32) | node;
    auto [it, first] = unconfigured_warned_us_.try_emplace(key, tf.time_us);
    if (!first && tf.time_us - it->second < kWarnEvery_us && tf.time_us >= it->second) return;
    it->second = tf.time_us;
    std::string silent;
    for (std::size_t p = 0; p < pumps_.size(); ++p) {
      if (io_[p].iface != iface || io_[p].inputs_us >= 0 || io_[p].status_us >= 0) continue;
      silent += fmt::format("{}{} (node_id {})", silent.empty() ? "" : ", ", pumps_[p]->config().name,
                            pumps_[p]->config().node_id);
    }
    const std::string& name = counter_.interfaces()[iface].name;
    Log(LogLevel::kWarning, "{}: {} frames (ID {:X}) from node ID {}, which no pump on {} has; {}", name,
        msg.name, tf.frame.id, node, name,
        silent.empty() ? "every pump configured there is heard from"
                       : "not heard from yet there: " + silent + " - is its node_id wrong?");
    return;
  }
}

void Gateway::CheckNodeOutputs(const PumpConfig& pc, const std::string& key,
                               const estimators::ThermalModel& model) const {
  const auto& names = model.StateNames();
  const bool node_table = mapping_.output(MappingOutput::kNodeIndex).has_value();
  for (std::size_t i = 0; i < names.size(); ++i) {
    if (!node_table && !mapping_.node_temperatures.contains(names[i])) {
      throw ConfigError(fmt::format(
          "{}:{}: key '{}.thermal_model': node '{}' of {} has no CAN output: map outputs.node_index "
          "and node_temp_degC (a node-indexed message such as GW_NODE_TEMP) or outputs.nodes.{}",
          config_.source, pc.line, key, names[i], pc.thermal_model, names[i]));
    }
    if (mapping_.output(MappingOutput::kAlarmNode) && i >= kAlarmNodeWindingRes) {
      throw ConfigError(fmt::format(
          "{}:{}: key '{}.thermal_model': node '{}' of {} cannot be named by alarm_node: indices "
          "0 to {} name model nodes ({} the winding from resistance, {} none)",
          config_.source, pc.line, key, names[i], pc.thermal_model, kAlarmNodeWindingRes - 1,
          kAlarmNodeWindingRes, kAlarmNodeWindingRes + 1));
    }
  }
}

void Gateway::RateLimitedClear(PumpIo& io, const std::string& pump, const std::string& iface) {
  ++counters_.clears_rate_limited;
  if (io.clear_repeat_logged) return;  // a held button: one line per burst, every repeat counted
  io.clear_repeat_logged = true;
  Log(LogLevel::kNotice,
      "pump {}: PUMP_CLEAR from can:{} within 2 s of the last one ignored (rate limit; further "
      "repeats are counted, not logged)", pump, iface);
}

double Gateway::OutputValue(std::size_t p, MappingOutput output, int node) const {
  const Pump& pump = *pumps_[p];
  const PumpSnapshot& s = pump.snapshot();
  const bool ident = s.resistance.status != estimators::ResistanceStatus::kInitialising &&
                     s.resistance.status != estimators::ResistanceStatus::kInvalidInput;
  switch (output) {
    case MappingOutput::kWindingResTempDegC: return s.winding_resistance_degC;
    case MappingOutput::kMagnetFluxTempDegC: return s.magnet_flux_degC;
    case MappingOutput::kRsOhm: return ident ? s.resistance.resistance_ohm : kNaN;
    case MappingOutput::kFluxWb: return ident ? s.resistance.flux_Wb : kNaN;
    case MappingOutput::kWindingResSdK: return ident ? s.resistance.winding_sd_K : kNaN;
    case MappingOutput::kMagnetFluxSdK: return s.magnet_flux_sd_K;
    case MappingOutput::kRsStatus: return static_cast<double>(s.resistance.status);
    case MappingOutput::kFluxStatus:
      // While Rs cannot be told apart from psi_f, Rs is held and the flux is still tracked.
      return static_cast<double>(s.resistance.status == estimators::ResistanceStatus::kNotIdentifiable
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
      if (!s.initialised || (s.alarm.node < 0 && s.alarm.reason != estimators::AlarmReason::kEstimatedOverTemperature)) return kNaN;
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
    case MappingOutput::kFrameRateHz: return io_[p].frame_rate_Hz;
    case MappingOutput::kDrops: return static_cast<double>(pump.counters().lost_frames);
    case MappingOutput::kNodeIndex: return node >= 0 ? static_cast<double>(node) : kNaN;
    case MappingOutput::kNodeCount: return static_cast<double>(s.node_degC.size());
    case MappingOutput::kNodeTempDegC:
      return s.initialised && node >= 0 && static_cast<std::size_t>(node) < s.node_degC.size()
                 ? s.node_degC[static_cast<std::size_t>(node)]
                 : kNaN;
    case MappingOutput::kNodeSdK:
      return s.initialised && node >= 0 && static_cast<std::size_t>(node) < s.node_sd_K.size()
                 ? s.node_sd_K[static_cast<std::size_t>(node)]
                 : kNaN;
    case MappingOutput::kBusState: {
      // The DBC's VAL_ table: 0 error active (also warning and unknown), 1 passive, 2 bus off, 3 down.
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

void Gateway::EmitFrame(std::size_t p, OutputPlan& plan, int node, std::int64_t time_us, OutputSink& sink) {
  const auto& msg = dbc_.messages[static_cast<std::size_t>(plan.message_index)];
  const auto& codec = codec_->message(static_cast<std::size_t>(plan.message_index));
  std::fill(values_.begin(), values_.begin() + static_cast<std::ptrdiff_t>(codec.signal_count()), kNaN);
  const PumpSnapshot& s = pumps_[p]->snapshot();
  for (const OutputSignal& o : plan.signals) {
    double v = kNaN;
    switch (o.source) {
      case OutputSource::kMapped: v = OutputValue(p, o.output, node); break;
      case OutputSource::kNode:
        v = s.initialised && o.state >= 0 ? s.node_degC[static_cast<std::size_t>(o.state)] : kNaN;
        break;
      case OutputSource::kRollingCounter: v = plan.counter; break;
    }
    values_[static_cast<std::size_t>(o.signal_index)] = std::isnan(v) ? v : (v - o.offset) / o.scale;
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

void Gateway::Advance(std::int64_t now_us, OutputSink& sink) {
  if (start_us_ < 0) {
    start_us_ = now_us;
    next_health_us_ = now_us;
  }
  last_now_us_ = now_us;
  const auto lcm_period_us = static_cast<std::int64_t>(std::llround(config_.lcm.period_s * 1e6));
  for (std::size_t p = 0; p < pumps_.size(); ++p) {
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
      continue;
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
      Log(a.level == estimators::AlarmLevel::kNone ? LogLevel::kNotice : LogLevel::kWarning, "pump {}: {}",
          name, AlarmChangeText(a, io.logged_active_reasons, pump.model().StateNames()));
      io.logged_active_reasons = a.active_reasons;
    }
    if (pump.snapshot().mismatch_changes != io.mismatch_changes_logged) {
      io.mismatch_changes_logged = pump.snapshot().mismatch_changes;
      LogMismatch(pump);
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
  if (now_us >= next_health_us_) {
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
    next_health_us_ = now_us + static_cast<std::int64_t>(std::llround(config_.lcm.health_period_s * 1e6));
  }
}

std::vector<std::uint8_t> Gateway::EncodeTemperatures(const Pump& pump) const {
  pumptherm::temperatures_t m;
  FillTemperatures(pump, m);
  return Encode(m);
}

void Gateway::FillTemperatures(const Pump& pump, pumptherm::temperatures_t& m) const {
  const PumpSnapshot& s = pump.snapshot();
  m.utime = s.time_us + wall_offset_us_;
  m.pump = pump.config().name;
  const auto& r = s.resistance;
  const bool ident = r.status != estimators::ResistanceStatus::kInitialising;
  m.resistance_ohm = ident ? r.resistance_ohm : kNaN;
  m.resistance_sd_ohm = ident ? r.resistance_sigma_ohm : kNaN;
  m.flux_Wb = ident ? r.flux_Wb : kNaN;
  m.flux_sd_Wb = ident ? r.flux_sd_Wb : kNaN;
  m.magnet_flux_degC = s.magnet_flux_degC;
  m.magnet_flux_sd_K = s.magnet_flux_sd_K;
  m.resistance_winding_degC = s.winding_resistance_degC;
  // The identifier's 1-sigma of eq. 3's temperature (covariance and voltage-error allowance).
  m.resistance_winding_sd_K = std::isfinite(s.winding_resistance_degC) ? r.winding_sd_K : kNaN;
  m.ident_status = static_cast<std::int8_t>(r.status);
  const auto& names = pump.model().StateNames();
  m.num_nodes = static_cast<std::int32_t>(names.size());
  m.node_names = names;
  m.node_degC = s.node_degC;
  m.node_sd_K = s.node_sd_K;
  m.nis = s.nis;
  double max_sd = 0.0;
  for (double sd : s.node_sd_K) max_sd = std::max(max_sd, sd);
  if (!s.initialised) {
    m.filter_status = pumptherm::temperatures_t::FILTER_NOT_STARTED;
  } else if (max_sd > 5.0) {
    m.filter_status = pumptherm::temperatures_t::FILTER_CONVERGING;
  } else if (std::isfinite(s.nis) && s.nis > pump.config().alarms.monitor.nis_limit) {
    m.filter_status = pumptherm::temperatures_t::FILTER_REJECTING;
  } else {
    m.filter_status = pumptherm::temperatures_t::FILTER_TRACKING;
  }
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
  m.frame_degC = at(MappingInput::kFrameTempDegC);
  m.ambient_degC = at(MappingInput::kAmbientTempDegC);
  m.coolant_degC = kNaN;
  m.dc_link_V = at(MappingInput::kDcLinkV);
  m.status_age_s = io.status_us >= 0 ? static_cast<double>(io.inputs_us - io.status_us) * 1e-6 : kNaN;
}

void Gateway::LogMismatch(const Pump& pump) const {
  const estimators::MismatchFinding& f = pump.snapshot().mismatch;
  const bool fault = f.state == estimators::MismatchState::kPlantChange ||
                     f.state == estimators::MismatchState::kSensorFaultSuspected ||
                     f.state == estimators::MismatchState::kUnexplained;
  std::string since;
  if (std::isfinite(f.onset_s)) {
    const auto t = static_cast<std::time_t>(std::floor(f.onset_s));
    std::tm tm{};
    gmtime_r(&t, &tm);
    since = fmt::format(" since {:02}:{:02}:{:02} UTC", tm.tm_hour, tm.tm_min, tm.tm_sec);
  }
  Log(fault ? LogLevel::kWarning : LogLevel::kNotice, "pump {}: model {}: {}{} (window NIS {:.0f}, limit {:.0f})",
      pump.config().name, estimators::MismatchStateName(f.state), estimators::DescribeFinding(f), since,
      f.window_nis, f.threshold);
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
  m.level = static_cast<std::int8_t>(s.alarm.level);
  m.time_to_trip_s = s.alarm.time_to_trip_s;
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
  m.mismatch_state = static_cast<std::int8_t>(s.mismatch.state);
  m.mismatch_effect = static_cast<std::int8_t>(s.mismatch.effect);
  m.mismatch_value = s.mismatch.value;
  m.mismatch_since_utime = std::isfinite(s.mismatch.onset_s) ? static_cast<std::int64_t>(s.mismatch.onset_s * 1e6) : 0;
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
    case BusState::kErrorActive: return H::BUS_STATE_ERROR_ACTIVE;
    case BusState::kErrorWarning: return H::BUS_STATE_ERROR_WARNING;
    case BusState::kErrorPassive: return H::BUS_STATE_ERROR_PASSIVE;
    case BusState::kBusOff: return H::BUS_STATE_BUS_OFF;
    case BusState::kUnknown: break;
  }
  return H::BUS_STATE_UNKNOWN;
}
}  // namespace

void Gateway::FillHealth(std::int64_t now_us, pumptherm::gateway_health_t& m) const {
  m.utime = now_us + wall_offset_us_;
  m.uptime_s = static_cast<double>(now_us - start_us_) * 1e-6;
  m.num_pumps = static_cast<std::int32_t>(pumps_.size());
  m.lcm_publish_failures = static_cast<std::int64_t>(counters_.lcm_failed);
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
  }
  m.num_interfaces = static_cast<std::int32_t>(m.interfaces.size());
}

bool Gateway::Clear(const std::string& pump_name, const std::string& source, const std::string& comment) {
  for (auto& pump : pumps_) {
    if (pump->config().name != pump_name) continue;
    const auto& a = pump->config().alarms;
    bool allowed = false;
    if (source.rfind("can:", 0) == 0) {
      const std::string iface = source.substr(4);
      allowed = std::find(a.clear_can_interfaces.begin(), a.clear_can_interfaces.end(), iface) !=
                a.clear_can_interfaces.end();
    } else {
      // A source name alone proves nothing: LCM clears go through ClearFromLcm.
      ++counters_.clears_refused;
      ++counters_.clears_unauthenticated;
      Log(LogLevel::kWarning, "pump {}: alarm clear from '{}' refused (no authentication code){}",
          pump_name, source, comment.empty() ? "" : ": " + comment);
      return false;
    }
    if (!allowed) {
      ++counters_.clears_refused;
      Log(LogLevel::kWarning, "pump {}: alarm clear from '{}' refused (not a configured source){}",
          pump_name, source, comment.empty() ? "" : ": " + comment);
      return false;
    }
    ++counters_.clears_accepted;
    const bool was = pump->ClearTrips();
    Log(LogLevel::kNotice, "pump {}: alarm clear from '{}' accepted ({}){}", pump_name, source,
        was ? "latched trip cleared" : "nothing was latched", comment.empty() ? "" : ": " + comment);
    return true;
  }
  ++counters_.clears_refused;
  Log(LogLevel::kWarning, "alarm clear for unknown pump '{}' from '{}' ignored", pump_name, source);
  return false;
}

std::string Gateway::StatusLine() const {
  int warnings = 0;
  int trips = 0;
  int never_heard = 0;
  for (const auto& p : pumps_) {
    warnings += p->snapshot().alarm.level == estimators::AlarmLevel::kWarning;
    trips += p->snapshot().alarm.level == estimators::AlarmLevel::kTrip;
    never_heard += p->last_frame_us() < 0;
  }
  std::uint64_t error_frames = 0;
  for (const auto& c : counter_.interfaces()) error_frames += c.rx_error_frames;
  std::string line = fmt::format("{} pumps, {} warning, {} trip", pumps_.size(), warnings, trips);
  if (never_heard > 0) line += fmt::format(", {} never heard", never_heard);
  line += fmt::format("; {}; {} unknown, {} bad length, {} error frames", counter_.StatusLine(),
                      counters_.rx_unknown_id, counters_.rx_bad_length, error_frames);
  if (!config_.lcm.url.empty()) {
    line += fmt::format("; lcm {} sent, {} failed", counters_.lcm_published, counters_.lcm_failed);
  }
  return line;
}

namespace {

/// The table's Rs: "-" before identification and while the estimate is outside the motor's
/// plausible band (its number then says nothing of the winding).
template <typename Num>
std::string RsCell(const estimators::ResistanceEstimate& r, Num num) {
  using S = estimators::ResistanceStatus;
  if (r.status == S::kInitialising) return "-";
  if (r.status == S::kImplausible) return "implaus.";
  return num(r.resistance_ohm, 4);
}

/// The table's alarm column; a pump never heard from says so with its alarm.
std::string TableAlarmCell(const Pump& p, const std::string& alarm) {
  if (p.last_frame_us() < 0) return "never heard; " + alarm;
  return p.snapshot().initialised || p.snapshot().alarm.trip_latched ? alarm : "no estimate yet";
}

}  // namespace

std::string Gateway::PumpTable() const {
  std::string out = fmt::format("{:<12} {:>8} {:>9} {:>9} {:>9} {:>9} {:>8}  {}\n", "pump", "speed",
                                "frame_C", "hottest", "at_C", "wind_R_C", "Rs_ohm", "alarm");
  for (const auto& p : pumps_) {
    const PumpSnapshot& s = p->snapshot();
    int hottest = -1;
    for (std::size_t i = 0; i < s.node_degC.size(); ++i) {
      if (std::isfinite(s.node_degC[i]) && (hottest < 0 || s.node_degC[i] > s.node_degC[static_cast<std::size_t>(hottest)])) {
        hottest = static_cast<int>(i);
      }
    }
    auto num = [](double v, int prec) { return std::isfinite(v) ? fmt::format("{:.{}f}", v, prec) : std::string("-"); };
    std::string alarm = estimators::AlarmLevelName(s.alarm.level);
    if (s.alarm.level != estimators::AlarmLevel::kNone) {
      alarm += fmt::format(" ({})", estimators::AlarmReasonName(s.alarm.reason));
    }
    if (s.alarm.trip_latched) alarm += " LATCHED";
    out += fmt::format("{:<12} {:>8} {:>9} {:>9} {:>9} {:>9} {:>8}  {}\n", p->config().name,
                       num(s.speed_rpm, 0), num(s.frame_measured_degC, 1),
                       hottest >= 0 ? p->model().StateNames()[static_cast<std::size_t>(hottest)] : "-",
                       hottest >= 0 ? num(s.node_degC[static_cast<std::size_t>(hottest)], 1) : "-",
                       num(s.winding_resistance_degC, 1),
                       RsCell(s.resistance, num), TableAlarmCell(*p, alarm));
  }
  return out;
}

namespace {

/// The filter's and the identifier's state of one pump into its saved table.
void InsertEstimate(const PumpSavedState& s, std::int64_t wall_offset_us, toml::table& t) {
  t.insert("time_us", s.time_us + wall_offset_us);
  toml::array x, cov;
  for (int i = 0; i < s.x_degC.size(); ++i) x.push_back(s.x_degC(i));
  for (int i = 0; i < s.s_K2.rows(); ++i) {
    for (int j = 0; j < s.s_K2.cols(); ++j) cov.push_back(s.s_K2(i, j));
  }
  t.insert("x_degC", x);
  t.insert("s_K2", cov);
  t.insert("inputs", toml::table{{"speed_rpm", s.inputs.speed_rpm}, {"id_A", s.inputs.id_A},
                                 {"iq_A", s.inputs.iq_A}, {"ambient_degC", s.inputs.ambient_degC},
                                 {"coolant_degC", s.inputs.coolant_degC}});
  // Per magnet hypothesis (steady, then drifting): x (4), P (16, row-major), probability,
  // consecutive rejections.
  toml::array rx, rp, rprob, rrej, rm;
  for (const auto& h : s.resistance.hypotheses) {
    for (int i = 0; i < 4; ++i) rx.push_back(h.x(i));
    for (int i = 0; i < 16; ++i) rp.push_back(h.p(i / 4, i % 4));
    rprob.push_back(h.probability);
    rrej.push_back(h.consecutive_rejections);
  }
  // Excitation moments of [iq, w_r, 1] (9, row-major); files with 4 ([iq, w_r]) still load.
  for (int i = 0; i < 9; ++i) rm.push_back(s.resistance.moments(i / 3, i % 3));
  t.insert("resistance_x", rx);
  t.insert("resistance_p", rp);
  t.insert("resistance_probability", rprob);
  t.insert("resistance_rejections", rrej);
  t.insert("resistance_moments", rm);
  t.insert("resistance_blocks", static_cast<std::int64_t>(s.resistance.blocks));
}

/// The latched trips of one saved pump (two parallel arrays; both absent: none). False for a
/// damaged pair.
bool ReadLatchedTrips(const toml::table& t, std::vector<PumpSavedState::LatchedTrip>& out) {
  out.clear();
  const toml::array* nodes = t["latched_trip_nodes"].as_array();
  const toml::array* values = t["latched_trip_values_degC"].as_array();
  if (!nodes && !values) return true;
  if (!nodes || !values || nodes->size() != values->size()) return false;
  for (std::size_t k = 0; k < nodes->size(); ++k) {
    const auto node = (*nodes)[k].value<std::string>();
    const auto value = (*values)[k].value<double>();
    if (!node || !value || !std::isfinite(*value)) return false;
    out.push_back({*node, *value});
  }
  return true;
}

}  // namespace

std::string Gateway::SaveState() const {
  toml::table root;
  // Version 2: the resistance identifier's two magnet hypotheses (version 1: one filter).
  root.insert("version", 2);
  toml::table pumps;
  for (const auto& p : pumps_) {
    const PumpSavedState s = p->Save();
    // A pump whose filter was just reset has no estimate to save, but its latched trips are.
    const bool estimate = p->snapshot().initialised;
    if (!estimate && s.latched_trips.empty()) continue;
    toml::table t;
    t.insert("model", s.model_name);
    if (estimate) InsertEstimate(s, wall_offset_us_, t);
    // Two parallel arrays (toml++ 3.3 misprints an array of tables nested this deep).
    toml::array trip_nodes, trip_values;
    for (const auto& trip : s.latched_trips) {
      trip_nodes.push_back(trip.node);
      trip_values.push_back(trip.value_degC);
    }
    t.insert("latched_trip_nodes", std::move(trip_nodes));
    t.insert("latched_trip_values_degC", std::move(trip_values));
    pumps.insert(p->config().name, std::move(t));
  }
  root.insert("pump", std::move(pumps));
  clear_auth_.Save(root);
  std::ostringstream ss;
  ss << "# pumpthermd saved state: written atomically; safe to delete (the daemon starts cold).\n"
     << root << "\n";
  return ss.str();
}

int Gateway::RestoreState(const std::string& text, std::int64_t now_us, std::string* warning) {
  toml::table root;
  try {
    root = toml::parse(std::string_view(text), std::string_view("saved state"));
  } catch (const toml::parse_error& e) {
    *warning = fmt::format("saved state does not parse (line {}): {}; starting cold",
                           e.source().begin.line, e.description());
    return 0;
  }
  // The clear counters have their own version: taken whatever the pumps' state holds.
  std::string clear_warning = clear_auth_.Restore(root);
  // Version 1 (before the identifier's magnet hypotheses) is read too: its one filter
  // becomes both hypotheses, with the prior probabilities.
  const std::int64_t version = root["version"].value_or<std::int64_t>(0);
  if (version != 1 && version != 2) {
    *warning = "saved state has an unknown version; starting cold";
    return 0;
  }
  const std::size_t hypotheses = version == 1 ? 1 : estimators::kMagnetHypotheses;
  int restored = 0;
  std::string ignored;
  std::string relatched;
  const toml::table* pumps = root["pump"].as_table();
  for (auto& pump : pumps_) {
    const toml::table* t = pumps ? (*pumps)[pump->config().name].as_table() : nullptr;
    if (!t) continue;
    auto numbers = [&](const char* key, std::size_t n, std::vector<double>& out) {
      const toml::array* a = (*t)[key].as_array();
      if (!a || a->size() != n) return false;
      out.clear();
      for (const auto& e : *a) {
        auto v = e.value<double>();
        if (!v || !std::isfinite(*v)) return false;
        out.push_back(*v);
      }
      return true;
    };
    const int n = pump->model().StateCount();
    PumpSavedState s;
    s.model_name = (*t)["model"].value_or(std::string());
    // Saved in wall time (it outlives this boot); the pipeline runs on its own clock.
    const std::int64_t saved_wall_us = (*t)["time_us"].value_or<std::int64_t>(0);
    s.time_us = saved_wall_us - wall_offset_us_;
    // Latched trips (absent in files written before they were saved: none latched).
    if (!ReadLatchedTrips(*t, s.latched_trips)) {
      ignored += (ignored.empty() ? "" : ", ") + pump->config().name;
      continue;
    }
    std::vector<double> x, cov, rx, rp, rm, rprob, rrej;
    bool ok = numbers("x_degC", static_cast<std::size_t>(n), x) &&
              numbers("s_K2", static_cast<std::size_t>(n * n), cov) &&
              numbers("resistance_x", 4 * hypotheses, rx) && numbers("resistance_p", 16 * hypotheses, rp) &&
              (numbers("resistance_moments", 9, rm) || numbers("resistance_moments", 4, rm)) && saved_wall_us > 0 &&
              s.time_us <= now_us + 60'000'000;
    if (ok && version == 2) {
      ok = numbers("resistance_probability", hypotheses, rprob) &&
           numbers("resistance_rejections", hypotheses, rrej);
    }
    if (ok) {
      s.x_degC = Eigen::Map<const Eigen::VectorXd>(x.data(), n);
      s.s_K2 = Eigen::Map<const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>(cov.data(), n, n);
      s.inputs.speed_rpm = (*t)["inputs"]["speed_rpm"].value_or(0.0);
      s.inputs.id_A = (*t)["inputs"]["id_A"].value_or(0.0);
      s.inputs.iq_A = (*t)["inputs"]["iq_A"].value_or(0.0);
      s.inputs.ambient_degC = (*t)["inputs"]["ambient_degC"].value_or(25.0);
      s.inputs.coolant_degC = (*t)["inputs"]["coolant_degC"].value_or(25.0);
      Eigen::Matrix3d moments;
      if (rm.size() == 9) {
        for (int i = 0; i < 9; ++i) moments(i / 3, i % 3) = rm[static_cast<std::size_t>(i)];
      } else {
        Eigen::Matrix2d two;
        for (int i = 0; i < 4; ++i) two(i / 2, i % 2) = rm[static_cast<std::size_t>(i)];
        moments = estimators::MomentsFromTwoRegressors(two);
      }
      const auto blocks = static_cast<std::uint64_t>((*t)["resistance_blocks"].value_or<std::int64_t>(0));
      const auto hx = [&](std::size_t j) {
        Eigen::Vector4d v;
        for (std::size_t i = 0; i < 4; ++i) v(static_cast<Eigen::Index>(i)) = rx[4 * j + i];
        return v;
      };
      const auto hp = [&](std::size_t j) {
        Eigen::Matrix4d m;
        for (std::size_t i = 0; i < 16; ++i) m(static_cast<Eigen::Index>(i / 4), static_cast<Eigen::Index>(i % 4)) = rp[16 * j + i];
        return m;
      };
      if (version == 1) {
        s.resistance = estimators::StateFromSingleFilter(
            hx(0), hp(0), moments, blocks, (*t)["resistance_rejections"].value_or(0),
            pump->identifier().config());
      } else {
        for (std::size_t j = 0; j < hypotheses; ++j) {
          auto& h = s.resistance.hypotheses[j];
          h.x = hx(j);
          h.p = hp(j);
          h.probability = rprob[j];
          // Rejection counts are small integers; anything else is damage.
          const double rej = rrej[j];
          ok = ok && rej >= 0.0 && rej <= 1e6 && rej == std::floor(rej);
          h.consecutive_rejections = ok ? static_cast<int>(rej) : 0;
        }
        s.resistance.moments = moments;
        s.resistance.blocks = blocks;
      }
      ok = ok && pump->Restore(s, std::max(now_us, s.time_us));
    }
    if (ok) {
      ++restored;
      continue;
    }
    ignored += (ignored.empty() ? "" : ", ") + pump->config().name;
    // The filter starts cold, but a latched trip must survive every restart path (a clock far
    // behind the saved time, a damaged filter state, a pump saved while its filter was reset).
    if (!s.latched_trips.empty() && pump->RestoreLatchedTrips(s, now_us)) {
      relatched += fmt::format("{}{} ({} trip(s))", relatched.empty() ? "" : ", ", pump->config().name,
                               s.latched_trips.size());
    }
  }
  if (!ignored.empty()) {
    *warning = fmt::format("saved state of pump(s) {} does not fit the configuration or is damaged; "
                           "they start cold", ignored);
    if (!relatched.empty()) *warning += fmt::format("; latched again: {}", relatched);
  }
  if (!clear_warning.empty()) *warning += (warning->empty() ? "" : "; ") + clear_warning;
  return restored;
}

}  // namespace pumptherm::daemon
