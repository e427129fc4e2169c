// Building the gateway from its configuration: the DBC and mapping, the input messages, and per
// pump its motor, thermal model, output plans and input routes.
#include <fmt/format.h>
#include <fmt/ranges.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <set>
#include <utility>

#include "daemon/gateway.hpp"
#include "daemon/gateway_detail.hpp"
#include "daemon/log.hpp"
#include "daemon/resources.hpp"
#include "protocol/lcm/channels.hpp"

namespace pumptherm::daemon {
namespace {

using gateway_detail::RouteKey;
using protocol::MappingInput;

bool IsCurrentInput(MappingInput i) { return i == MappingInput::kIdA || i == MappingInput::kIqA; }
bool IsVoltageInput(MappingInput i) { return i == MappingInput::kUdV || i == MappingInput::kUqV; }
bool IsStatusInput(MappingInput i) {
  return i == MappingInput::kSpeedMechRpm || i == MappingInput::kDriveState ||
         i == MappingInput::kFrameSensorDegC || i == MappingInput::kAmbientDegC ||
         i == MappingInput::kDcLinkV;
}

/// DBC warnings logged one by one at start; the rest are counted.
constexpr std::size_t kMaxReportedDbcProblems = 20;

}  // namespace

namespace {

/// A configuration error at `line` of the configuration, naming its key; line 0: a key not
/// given in the file, whose default is at fault.
ConfigError KeyError(const DaemonConfig& config, int line, const std::string& key,
                     const std::string& what) {
  if (line <= 0)
    return ConfigError(
        fmt::format("{}: key '{}' (not set: its default): {}", config.source, key, what));
  return ConfigError(fmt::format("{}:{}: key '{}': {}", config.source, line, key, what));
}

/// "the model's nodes: frame, stator, winding, rotor".
std::string NodeList(const estimators::ThermalModel& model) {
  std::string list;
  for (const auto& n : model.StateNames()) list += (list.empty() ? "" : ", ") + n;
  return list;
}

}  // namespace

Gateway::Gateway(const DaemonConfig& config)
    : config_(config),
      counter_(config.gateway),
      clear_auth_(config.gateway.name, config.lcm.channel_prefix, config.clear_auth.window_s) {
  // Without pumps the gateway only counts frames: no frame layout is needed.
  if (config_.pumps.empty()) return;
  LoadFrameLayout();
  IndexInputMessages();
  std::map<std::string, std::shared_ptr<const estimators::ThermalModel>> models;
  for (std::size_t p = 0; p < config_.pumps.size(); ++p) AddPump(p, models);
  channel_health_ = lcm_channels::GatewayHealthChannelName(config_.lcm.channel_prefix);
}

void Gateway::LoadFrameLayout() {
  std::string dbc_path;
  try {
    dbc_path = ResolveResource(ResourceKind::kDbc, config_.dbc.file, config_.dbc.base_dir);
    dbc_ = protocol::ParseDbc(ReadTextFile(dbc_path), dbc_path);
  } catch (const std::exception& e) {
    throw KeyError(config_, config_.dbc.file_line, "dbc.file", e.what());
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
  std::string mapping_path;
  try {
    mapping_path = ResolveResource(ResourceKind::kDbc, config_.dbc.mapping, config_.dbc.base_dir);
    mapping_ =
        protocol::ParseMapping(ReadTextFile(mapping_path), mapping_path, dbc_, MappingOutputs());
  } catch (const std::exception& e) {
    throw KeyError(config_, config_.dbc.mapping_line, "dbc.mapping", e.what());
  }
  for (const std::string& d : mapping_.deprecations) Log(LogLevel::kWarning, "{}", d);
  CheckOutputSignals(dbc_path, mapping_path);
  codec_ = std::make_unique<protocol::DbcCodec>(dbc_);
  std::size_t max_signals = 1;
  for (const auto& m : dbc_.messages) max_signals = std::max(max_signals, m.signals.size());
  values_.assign(max_signals, kNaN);
}

void Gateway::IndexInputMessages() {
  for (std::size_t i = 0; i < protocol::kMappingInputCount; ++i) {
    const auto& ref = mapping_.inputs[i];
    if (!ref) continue;
    const auto input = static_cast<MappingInput>(i);
    auto it = std::find_if(inputs_.begin(), inputs_.end(), [&](const InputMessage& m) {
      return m.message_index == ref->message_index;
    });
    if (it == inputs_.end()) {
      inputs_.push_back(InputMessage{ref->message_index, {}});
      it = inputs_.end() - 1;
    }
    it->signals.push_back({input, ref->signal_index, ref->scale, ref->offset});
    it->currents = it->currents || IsCurrentInput(input);
    it->voltages = it->voltages || IsVoltageInput(input);
    it->status = it->status || IsStatusInput(input);
    it->clear = it->clear || input == MappingInput::kAlarmClear;
    it->rolling_counter = it->rolling_counter || input == MappingInput::kRollingCounter;
  }
  for (InputMessage& m : inputs_) {
    const auto& msg = dbc_.messages[static_cast<std::size_t>(m.message_index)];
    // A command (PUMP_CLEAR) has a cycle time in the DBC but is sent when a button is pressed.
    if (!m.clear && msg.cycle_time_ms && *msg.cycle_time_ms > 0)
      m.cycle_s = *msg.cycle_time_ms / 1e3;
  }
}

void Gateway::AddPump(std::size_t p, ModelCache& models) {
  const PumpConfig& pc = config_.pumps[p];
  const std::string key = fmt::format("pump[{}]", p);
  if (pc.node_id >= mapping_.node_id_limit) {
    throw KeyError(config_, pc.LineOf("node_id"), key + ".node_id",
                   fmt::format("{} is not below the mapping's node_id_limit {}", pc.node_id,
                               mapping_.node_id_limit));
  }
  bool known_interface = config_.interfaces.empty();
  for (const auto& i : config_.interfaces)
    known_interface = known_interface || i.name == pc.interface;
  if (!known_interface || pc.interface.empty()) {
    throw KeyError(config_, pc.LineOf("interface"), key + ".interface",
                   fmt::format("'{}' is not a configured [[can]] interface", pc.interface));
  }
  const estimators::MotorDescription motor = LoadPumpMotor(pc, key);
  const std::shared_ptr<const estimators::ThermalModel> model = LoadPumpModel(pc, key, models);
  CheckPumpNodes(pc, key, *model);
  try {
    pumps_.push_back(std::make_unique<Pump>(pc, motor, model, config_.gateway.thermal_period_s));
  } catch (const std::exception& e) {
    throw KeyError(config_, pc.line, key, e.what());
  }
  if (!pc.disturbance_states_explicit && !pumps_.back()->disturbance_states()) {
    Log(LogLevel::kNotice,
        "pump {}: standard filter published: the boundary of model {} reaches other nodes than "
        "'{}' "
        "(disturbance_states = true overrides)",
        pc.name, model->Name(), pc.measured_node);
  }
  CheckNodeOutputs(pc, key, *model);
  PumpIo io;
  io.iface = counter_.Interface(pc.interface);
  for (double& v : io.inputs) v = kNaN;
  BuildOutputPlans(io, *model);
  AddRoutes(io, p, key);
  for (const InputMessage& m : inputs_)
    io.checks.push_back({RateCheck(m.cycle_s), CounterCheck(16, m.cycle_s)});
  AddOwnIds(io, p);
  const std::string& prefix = config_.lcm.channel_prefix;
  io.channel_telemetry =
      lcm_channels::PumpChannelName(prefix, pc.name, lcm_channels::PumpChannel::kTelemetry);
  io.channel_temperatures =
      lcm_channels::PumpChannelName(prefix, pc.name, lcm_channels::PumpChannel::kTemperatures);
  io.channel_alarm =
      lcm_channels::PumpChannelName(prefix, pc.name, lcm_channels::PumpChannel::kAlarm);
  io_.push_back(std::move(io));
}

estimators::MotorDescription Gateway::LoadPumpMotor(const PumpConfig& pc,
                                                    const std::string& key) const {
  try {
    if (!estimators::MotorPresetText(pc.motor).empty()) return estimators::MotorPreset(pc.motor);
    const std::string path = ResolveResource(ResourceKind::kMotor, pc.motor, config_.dbc.base_dir);
    return estimators::ParseMotorDescription(ReadTextFile(path), path);
  } catch (const std::exception& e) {
    throw KeyError(config_, pc.LineOf("motor"), key + ".motor", e.what());
  }
}

std::shared_ptr<const estimators::ThermalModel> Gateway::LoadPumpModel(const PumpConfig& pc,
                                                                       const std::string& key,
                                                                       ModelCache& models) const {
  try {
    const std::string path =
        ResolveResource(ResourceKind::kModel, pc.thermal_model, config_.dbc.base_dir);
    auto it = models.find(path);
    if (it == models.end()) {
      it = models
               .emplace(
                   path,
                   std::make_shared<const estimators::ThermalModel>(estimators::ThermalModel::Parse(
                       ReadTextFile(path), path,
                       estimators::ThermalModelFiles{DirectoryOf(path), &ReadTextFile})))
               .first;
    }
    return it->second;
  } catch (const std::exception& e) {
    throw KeyError(config_, pc.LineOf("thermal_model"), key + ".thermal_model", e.what());
  }
}

void Gateway::BuildOutputPlans(PumpIo& io, const estimators::ThermalModel& model) const {
  // One plan per output message.
  auto plan_for = [&](int message_index) -> OutputPlan& {
    for (auto& plan : io.outputs) {
      if (plan.message_index == message_index) return plan;
    }
    const auto& msg = dbc_.messages[static_cast<std::size_t>(message_index)];
    OutputPlan plan;
    plan.message_index = message_index;
    auto over = config_.output_periods_s.find(msg.name);
    const double period_s = over != config_.output_periods_s.end() ? over->second
                            : msg.cycle_time_ms && *msg.cycle_time_ms > 0
                                ? *msg.cycle_time_ms / 1000.0
                                : 1.0;
    plan.period_us = std::max<std::int64_t>(1000, std::llround(period_s * 1e6));
    io.outputs.push_back(std::move(plan));
    return io.outputs.back();
  };
  for (const auto& [key, ref] : mapping_.outputs) {
    OutputPlan& plan = plan_for(ref.message_index);
    plan.signals.push_back({ref.signal_index, OutputSource::kField, FindPublishedField(key), -1,
                            ref.scale, ref.offset});
    plan.alarm = plan.alarm || key == kAlarmLevelKey;
    plan.node_table = plan.node_table || key == protocol::kNodeIndexKey;
  }
  for (const auto& [node, ref] : mapping_.node_temperatures) {
    OutputPlan& plan = plan_for(ref.message_index);
    // A node this pump's model does not have stays "not available" in the frame.
    plan.signals.push_back({ref.signal_index, OutputSource::kNode, nullptr, model.StateIndex(node),
                            ref.scale, ref.offset});
  }
  for (auto& plan : io.outputs) {
    // A node-indexed message sends its nodes one after another, spread over the period: each
    // node once per period, and no burst of frames on one ID.
    const auto nodes = static_cast<std::int64_t>(model.StateNames().size());
    if (plan.node_table && nodes > 0)
      plan.period_us = std::max<std::int64_t>(1000, plan.period_us / nodes);
    const auto& msg = dbc_.messages[static_cast<std::size_t>(plan.message_index)];
    const int rc = msg.FindSignal("RollingCounter");
    const bool mapped = std::any_of(plan.signals.begin(), plan.signals.end(),
                                    [&](const OutputSignal& s) { return s.signal_index == rc; });
    if (rc >= 0 && !mapped)
      plan.signals.push_back({rc, OutputSource::kRollingCounter, nullptr, -1, 1.0, 0.0});
  }
}

void Gateway::AddRoutes(const PumpIo& io, std::size_t p, const std::string& key) {
  const PumpConfig& pc = config_.pumps[p];
  for (std::size_t m = 0; m < inputs_.size(); ++m) {
    const auto& msg = dbc_.messages[static_cast<std::size_t>(inputs_[m].message_index)];
    const std::uint32_t id = mapping_.CanId(dbc_, inputs_[m].message_index, pc.node_id);
    const auto route_key = RouteKey(io.iface, msg.extended, id);
    if (routes_.count(route_key)) {
      throw KeyError(config_, pc.line, key + ".node_id",
                     fmt::format("CAN ID {:X} on '{}' is already used", id, pc.interface));
    }
    const Route route{static_cast<std::uint32_t>(p), static_cast<std::uint32_t>(m)};
    routes_[route_key] = route;
    if (!msg.extended && id < kStandardIds) {
      if (standard_routes_.size() < (io.iface + 1) * kStandardIds) {
        standard_routes_.resize((io.iface + 1) * kStandardIds, Route{kNoPump, 0});
      }
      standard_routes_[io.iface * kStandardIds + id] = route;
    }
  }
}

void Gateway::CheckPumpNodes(const PumpConfig& pc, const std::string& key,
                             const estimators::ThermalModel& model) const {
  const std::pair<const char*, const std::string*> nodes[] = {{"measured_node", &pc.measured_node},
                                                              {"magnet_node", &pc.magnet_node},
                                                              {"rotor_node", &pc.rotor_node}};
  for (const auto& [name, node] : nodes) {
    if (node->empty() || model.StateIndex(*node) >= 0) continue;
    throw KeyError(config_, pc.LineOf(name), key + "." + name,
                   fmt::format("'{}' is not a node with heat capacity of model {} (its nodes: {})",
                               *node, model.Name(), NodeList(model)));
  }
  for (const auto& [node, levels] : pc.alarms.levels) {
    if (node == "sensor" || node == "winding_resistance" || model.StateIndex(node) >= 0) continue;
    const std::string what = fmt::format(
        "pump '{}' (model {}) has no node '{}' (its nodes: {}; also 'sensor' and "
        "'winding_resistance')",
        pc.name, model.Name(), node, NodeList(model));
    // Levels that are not in the file (a tool's what-if levels) have no line to name.
    if (levels.line <= 0) throw ConfigError(fmt::format("levels for '{}': {}", node, what));
    throw KeyError(config_, levels.line, levels.key.empty() ? "alarms.levels." + node : levels.key,
                   what);
  }
}

void Gateway::CheckOutputSignals(const std::string& dbc_path,
                                 const std::string& mapping_path) const {
  // What the configuration would send wrong: a value the gateway does not know goes out as
  // the signal's "not available" raw value, and without one as raw 0 (a number: -50 degC on
  // the shipped temperature signals); a message without a cycle time goes out every second.
  struct Use {
    std::string key;  // the mapping's key
    const protocol::SignalRef* ref;
  };
  std::vector<Use> uses;
  // Outputs that always have a value (a status, a count, the node index of the frame) need no
  // reserved raw value: the others are NaN while unknown (before the first estimate, a stale
  // reading).
  for (const auto& [key, ref] : mapping_.outputs) {
    const PublishedField* field = FindPublishedField(key);
    if (field == nullptr || field->always_known) continue;
    uses.push_back({"outputs." + key, &ref});
  }
  for (const auto& [node, ref] : mapping_.node_temperatures)
    uses.push_back({"outputs.nodes." + node, &ref});
  std::vector<std::string> missing;
  for (const auto& u : uses) {
    const auto& msg = dbc_.messages[static_cast<std::size_t>(u.ref->message_index)];
    if (!msg.signals[static_cast<std::size_t>(u.ref->signal_index)].not_available_raw)
      missing.push_back(fmt::format("{}.{} ({})", msg.name, u.ref->signal, u.key));
  }
  if (!missing.empty()) {
    constexpr std::size_t kListed = 6;
    const std::size_t count = missing.size();
    if (count > kListed) {
      missing.resize(kListed);
      missing.push_back(fmt::format("and {} more", count - kListed));
    }
    throw KeyError(
        config_, config_.dbc.file_line, "dbc.file",
        fmt::format("{}: {} output signal{} without a \"not available\" raw value (attribute "
                    "GenSigSNA), {}: while unknown (before the first estimate, a stale reading) "
                    "{} would go out as raw 0, a number; declare BA_DEF_ SG_ \"GenSigSNA\" and "
                    "its BA_ for each (docs/protocol.md, \"Not available\"; the mapping is {})",
                    dbc_path, count, count == 1 ? "" : "s", fmt::join(missing, ", "),
                    count == 1 ? "it" : "they", mapping_path));
  }
  std::set<int> messages;
  for (const auto& u : uses) messages.insert(u.ref->message_index);
  for (const auto& [key, ref] : mapping_.outputs) messages.insert(ref.message_index);
  // An override of a message the gateway does not send would change nothing, silently.
  for (const auto& [name, period_s] : config_.output_periods_s) {
    const protocol::DbcMessage* msg = dbc_.FindMessage(name);
    if (msg != nullptr && messages.contains(static_cast<int>(msg - dbc_.messages.data()))) continue;
    std::vector<std::string> names;
    for (int m : messages) names.push_back(dbc_.messages[static_cast<std::size_t>(m)].name);
    const auto line = config_.output_period_lines.find(name);
    throw KeyError(config_, line == config_.output_period_lines.end() ? 0 : line->second,
                   "output_periods_s." + name,
                   fmt::format("{} is not a message the gateway sends (its output messages: {})",
                               name, fmt::join(names, ", ")));
  }
  std::vector<std::string> no_cycle;
  for (int m : messages) {
    const auto& msg = dbc_.messages[static_cast<std::size_t>(m)];
    if (config_.output_periods_s.contains(msg.name)) continue;
    if (!msg.cycle_time_ms || *msg.cycle_time_ms <= 0) no_cycle.push_back(msg.name);
  }
  if (!no_cycle.empty()) {
    throw KeyError(
        config_, config_.dbc.file_line, "dbc.file",
        fmt::format("{}: output message{} {} ha{} no cycle time (attribute GenMsgCycleTime, "
                    "neither its BA_ nor a default above 0): the gateway would send {} every "
                    "1 s; add the attribute, or set output_periods_s.{} = SECONDS in the "
                    "configuration",
                    dbc_path, no_cycle.size() == 1 ? "" : "s", fmt::join(no_cycle, ", "),
                    no_cycle.size() == 1 ? "s" : "ve", no_cycle.size() == 1 ? "it" : "them",
                    no_cycle.front()));
  }
}

void Gateway::CheckNodeOutputs(const PumpConfig& pc, const std::string& key,
                               const estimators::ThermalModel& model) const {
  const auto& names = model.StateNames();
  const bool node_table = mapping_.output(protocol::kNodeIndexKey) != nullptr;
  for (std::size_t i = 0; i < names.size(); ++i) {
    if (!node_table && !mapping_.node_temperatures.contains(names[i])) {
      throw ConfigError(fmt::format(
          "{}:{}: key '{}.thermal_model': node '{}' of {} has no CAN output: map "
          "outputs.node_index "
          "and node_temp_degC (a node-indexed message such as GW_NODE_TEMP) or outputs.nodes.{}",
          config_.source, pc.line, key, names[i], pc.thermal_model, names[i]));
    }
    if (mapping_.output("alarm_node") && i >= kAlarmNodeWindingRes) {
      throw ConfigError(fmt::format(
          "{}:{}: key '{}.thermal_model': node '{}' of {} cannot be named by alarm_node: indices "
          "0 to {} name model nodes ({} the winding from resistance, {} none)",
          config_.source, pc.line, key, names[i], pc.thermal_model, kAlarmNodeWindingRes - 1,
          kAlarmNodeWindingRes, kAlarmNodeWindingRes + 1));
    }
  }
}

}  // namespace pumptherm::daemon
