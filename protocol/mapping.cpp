#include "protocol/mapping.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <optional>
#include <vector>

namespace pumptherm::protocol {

namespace {

constexpr std::array<std::string_view, kMappingInputCount> kInputNames = {"id_A",
                                                                          "iq_A",
                                                                          "ud_V",
                                                                          "uq_V",
                                                                          "speed_elec_rad_per_s",
                                                                          "speed_mech_rpm",
                                                                          "rolling_counter",
                                                                          "drive_state",
                                                                          "frame_sensor_degC",
                                                                          "ambient_degC",
                                                                          "dc_link_V",
                                                                          "alarm_clear"};

/// Input keys of before protocol version "pumptherm 2", still read: old key, index of the current.
struct OldInputKey {
  std::string_view key;
  MappingInput input;
};
constexpr std::array<OldInputKey, 2> kOldInputKeys = {{
    {"frame_temp_degC", MappingInput::kFrameSensorDegC},
    {"ambient_temp_degC", MappingInput::kAmbientDegC},
}};

/// Signals of protocol/pumptherm.dbc renamed by its version "pumptherm 2" (one name per quantity,
/// docs/daemon.md "Names"): message, the name in "pumptherm 1", the name now.
struct SignalRename {
  std::string_view message;
  std::string_view before;
  std::string_view now;
};
constexpr std::array<SignalRename, 5> kSignalRenames = {{
    {"PUMP_STATUS", "FrameTemp_degC", "FrameSensor_degC"},
    {"PUMP_STATUS", "AmbientTemp_degC", "Ambient_degC"},
    {"GW_TEMPS_A", "WindingRes_degC", "WindingResistance_degC"},
    {"GW_IDENT", "Rs_ohm", "Resistance_ohm"},
    {"GW_IDENT_SD", "WindingResSd_K", "WindingResistanceSd_K"},
}};

/// The other name of signal `signal` of message `message` across the rename (its current name
/// for a "pumptherm 1" name, and the reverse); empty when it was not renamed.
std::string_view RenamedSignal(std::string_view message, std::string_view signal) {
  for (const SignalRename& r : kSignalRenames) {
    if (r.message != message) continue;
    if (r.before == signal) return r.now;
    if (r.now == signal) return r.before;
  }
  return {};
}

std::string Where(const toml::source_region& r) {
  const std::string file = r.path ? *r.path : std::string("<mapping>");
  return fmt::format("{}:{}:{}", file, r.begin.line, r.begin.column);
}

/// Index into `names` of input key `k`; nullopt when unknown.
template <std::size_t N>
std::optional<std::size_t> KeyIndex(std::string_view k,
                                    const std::array<std::string_view, N>& names) {
  const auto it = std::find(names.begin(), names.end(), k);
  if (it == names.end()) return std::nullopt;
  return static_cast<std::size_t>(it - names.begin());
}

[[noreturn]] void Fail(const toml::node& at, const std::string& key, const std::string& what) {
  throw MappingError(fmt::format("{}: key {}: {}", Where(at.source()), key, what));
}

double NumberOr(const toml::table& t, std::string_view name, double fallback,
                const std::string& key) {
  const toml::node* n = t.get(name);
  if (n == nullptr) return fallback;
  if (auto v = n->value<double>()) {
    if (!std::isfinite(*v)) Fail(*n, key + "." + std::string(name), "must be finite");
    return *v;
  }
  Fail(*n, key + "." + std::string(name), "expected a number");
}

/// The signal `ref` names in message `m`, or else its name across the rename (recorded in
/// `deprecations`); -1 when the message has neither.
int FindSignalOrRenamed(const DbcMessage& m, SignalRef& ref, const toml::node& at,
                        const std::string& key, const Dbc& dbc,
                        std::vector<std::string>* deprecations) {
  const int index = m.FindSignal(ref.signal);
  if (index >= 0) return index;
  const std::string_view other = RenamedSignal(ref.message, ref.signal);
  if (other.empty()) return -1;
  const int other_index = m.FindSignal(std::string(other));
  if (other_index < 0) return -1;
  // The DBC has the old name (a site's copy of "pumptherm 1"), or the mapping has it.
  const bool dbc_is_older = std::any_of(
      kSignalRenames.begin(), kSignalRenames.end(),
      [&](const SignalRename& r) { return r.message == ref.message && r.before == other; });
  deprecations->push_back(
      dbc_is_older
          ? fmt::format("{}: key {}: {} has signal {} of {} under its name before protocol "
                        "version \"pumptherm 2\": read as {}",
                        Where(at.source()), key, dbc.file_name, ref.signal, ref.message, other)
          : fmt::format("{}: key {}: signal {} of {} is {} in {} (protocol version \"pumptherm "
                        "2\" renamed it): read as {}",
                        Where(at.source()), key, ref.signal, ref.message, other, dbc.file_name,
                        other));
  ref.signal = std::string(other);
  return other_index;
}

SignalRef Resolve(const toml::node& node, const std::string& key, const Dbc& dbc,
                  std::vector<std::string>* deprecations) {
  const toml::table* t = node.as_table();
  if (t == nullptr) Fail(node, key, "expected a table { message = \"...\", signal = \"...\" }");
  for (const auto& [k, v] : *t) {
    if (k != "message" && k != "signal" && k != "scale" && k != "offset") {
      Fail(v, key + "." + std::string(k.str()), "unknown key (message, signal, scale, offset)");
    }
  }
  SignalRef ref;
  const toml::node* msg = t->get("message");
  const toml::node* sig = t->get("signal");
  if (msg == nullptr || !msg->is_string())
    Fail(node, key + ".message", "expected the DBC message name");
  if (sig == nullptr || !sig->is_string())
    Fail(node, key + ".signal", "expected the DBC signal name");
  ref.message = **msg->as_string();
  ref.signal = **sig->as_string();
  const DbcMessage* m = dbc.FindMessage(ref.message);
  if (m == nullptr) {
    Fail(*msg, key + ".message",
         fmt::format("unknown message {} in {}", ref.message, dbc.file_name));
  }
  ref.message_index = static_cast<int>(m - dbc.messages.data());
  ref.signal_index = FindSignalOrRenamed(*m, ref, *sig, key, dbc, deprecations);
  if (ref.signal_index < 0) {
    Fail(*sig, key + ".signal",
         fmt::format("unknown signal {} in message {} of {}", ref.signal, ref.message,
                     dbc.file_name));
  }
  ref.scale = NumberOr(*t, "scale", 1.0, key);
  ref.offset = NumberOr(*t, "offset", 0.0, key);
  return ref;
}

/// The input of key `k` (its current key, or an old one, recorded in `deprecations`); nullopt
/// when unknown.
std::optional<std::size_t> FindInput(std::string_view k, const toml::node& at,
                                     std::vector<std::string>* deprecations) {
  if (const auto index = KeyIndex(k, kInputNames)) return index;
  for (const OldInputKey& o : kOldInputKeys) {
    if (o.key != k) continue;
    deprecations->push_back(fmt::format("{}: key inputs.{} is deprecated: it is now inputs.{}",
                                        Where(at.source()), k, MappingInputName(o.input)));
    return static_cast<std::size_t>(o.input);
  }
  return std::nullopt;
}

void ResolveInputs(const toml::table& root, SignalMapping& mapping, const Dbc& dbc) {
  const toml::node* n = root.get("inputs");
  if (n == nullptr) return;
  const toml::table* t = n->as_table();
  if (t == nullptr) Fail(*n, "inputs", "expected a table");
  for (const auto& [k, v] : *t) {
    const std::string key = fmt::format("inputs.{}", k.str());
    const std::optional<std::size_t> index = FindInput(k.str(), v, &mapping.deprecations);
    if (!index) {
      std::string known;
      for (auto name : kInputNames) known += fmt::format("{}{}", known.empty() ? "" : ", ", name);
      Fail(v, key, fmt::format("unknown inputs (known: {})", known));
    }
    if (mapping.inputs[*index]) {
      Fail(v, key,
           fmt::format("inputs.{} is given twice (under its old and its current name)",
                       kInputNames[*index]));
    }
    mapping.inputs[*index] = Resolve(v, key, dbc, &mapping.deprecations);
  }
}

/// The output spec of key `k` (its current key, or an old one, recorded in `deprecations`);
/// nullptr when unknown.
const OutputSpec* FindOutput(std::string_view k, std::span<const OutputSpec> outputs,
                             const toml::node& at, std::vector<std::string>* deprecations) {
  for (const OutputSpec& o : outputs) {
    if (o.key == k) return &o;
  }
  for (const OutputSpec& o : outputs) {
    if (o.old_key.empty() || o.old_key != k) continue;
    deprecations->push_back(fmt::format("{}: key outputs.{} is deprecated: it is now outputs.{}",
                                        Where(at.source()), k, o.key));
    return &o;
  }
  return nullptr;
}

/// The [outputs] table: named outputs, the nested `nodes` table (into `nested_nodes`), and the
/// `defaults` switch (into `defaults`).
void ResolveOutputs(const toml::table& root, std::span<const OutputSpec> outputs,
                    SignalMapping& mapping, const Dbc& dbc, const toml::table** nested_nodes,
                    bool* defaults) {
  const toml::node* n = root.get("outputs");
  if (n == nullptr || outputs.empty()) return;  // a reader of the inputs alone
  const toml::table* t = n->as_table();
  if (t == nullptr) Fail(*n, "outputs", "expected a table");
  for (const auto& [k, v] : *t) {
    const std::string key = fmt::format("outputs.{}", k.str());
    if (k == "nodes") {
      *nested_nodes = v.as_table();
      if (*nested_nodes == nullptr)
        Fail(v, key, "expected a table of node name = { message, signal }");
      continue;
    }
    if (k == "defaults") {
      if (!v.is_boolean()) Fail(v, key, "expected true or false");
      *defaults = **v.as_boolean();
      continue;
    }
    const OutputSpec* spec = FindOutput(k.str(), outputs, v, &mapping.deprecations);
    if (spec == nullptr) {
      std::string known;
      for (const OutputSpec& o : outputs)
        known += fmt::format("{}{}", known.empty() ? "" : ", ", o.key);
      Fail(v, key, fmt::format("unknown outputs (known: {}, nodes, defaults)", known));
    }
    if (mapping.outputs.contains(spec->key))
      Fail(
          v, key,
          fmt::format("outputs.{} is given twice (under its old and its current name)", spec->key));
    mapping.outputs.emplace(std::string(spec->key), Resolve(v, key, dbc, &mapping.deprecations));
  }
}

/// The declared default binding of every output the mapping does not name, where the DBC has
/// that message and signal (or the signal under its "pumptherm 1" name: a site's copy of the
/// DBC from before the rename, recorded in the mapping's deprecations).
void BindDefaults(std::span<const OutputSpec> outputs, const Dbc& dbc, SignalMapping& mapping) {
  for (const OutputSpec& o : outputs) {
    if (o.default_message.empty() || mapping.outputs.contains(o.key)) continue;
    const DbcMessage* m = dbc.FindMessage(std::string(o.default_message));
    if (m == nullptr) continue;
    std::string_view name = o.default_signal;
    int signal = m->FindSignal(std::string(name));
    if (signal < 0) {
      name = RenamedSignal(o.default_message, o.default_signal);
      if (name.empty()) continue;
      signal = m->FindSignal(std::string(name));
      if (signal < 0) continue;
      mapping.deprecations.push_back(fmt::format(
          "{}: message {} has signal {}, the name before protocol version \"pumptherm 2\" (now "
          "{}): output {} goes to it",
          dbc.file_name, o.default_message, name, o.default_signal, o.key));
    }
    SignalRef ref;
    ref.message = std::string(o.default_message);
    ref.signal = std::string(name);
    ref.message_index = static_cast<int>(m - dbc.messages.data());
    ref.signal_index = signal;
    mapping.outputs.emplace(std::string(o.key), ref);
  }
}

/// The node-indexed message: node_index with node_temp_degC, node_sd_K and node_count in the
/// same message, so one frame says which node its temperature belongs to.
void CheckNodeTable(const toml::table& table, const SignalMapping& mapping) {
  const SignalRef* index = mapping.output(kNodeIndexKey);
  const SignalRef* temp = mapping.output(kNodeTempKey);
  const toml::node* outputs = table.get("outputs");
  const toml::node& where = outputs != nullptr ? *outputs : static_cast<const toml::node&>(table);
  if ((index != nullptr) != (temp != nullptr)) {
    Fail(where, "outputs", "node_index and node_temp_degC go together (a node-indexed message)");
  }
  for (std::string_view o : {kNodeTempKey, kNodeSdKey, kNodeCountKey}) {
    const SignalRef* r = mapping.output(o);
    if (r && (!index || r->message_index != index->message_index)) {
      Fail(where, fmt::format("outputs.{}", o), "must be in the message of outputs.node_index");
    }
  }
}

}  // namespace

std::string_view MappingInputName(MappingInput input) noexcept {
  return kInputNames[static_cast<std::size_t>(input)];
}

std::uint32_t SignalMapping::CanId(const Dbc& dbc, int message_index, std::uint32_t node_id) const {
  if (node_id >= node_id_limit) {
    throw std::out_of_range(
        fmt::format("node ID {} not below node_id_limit {}", node_id, node_id_limit));
  }
  return dbc.messages.at(static_cast<std::size_t>(message_index)).id + node_id;
}

SignalMapping MappingFromTable(const toml::table& table, const Dbc& dbc,
                               std::span<const OutputSpec> outputs) {
  SignalMapping mapping;
  for (const auto& [k, v] : table) {
    if (k != "node_id_limit" && k != "inputs" && k != "outputs") {
      Fail(v, std::string(k.str()), "unknown key (node_id_limit, inputs, outputs)");
    }
  }
  if (const toml::node* n = table.get("node_id_limit")) {
    const auto v = n->value<std::int64_t>();
    if (!v || *v < 1 || *v > 65536)
      Fail(*n, "node_id_limit", "expected an integer from 1 to 65536");
    mapping.node_id_limit = static_cast<std::uint32_t>(*v);
  }
  ResolveInputs(table, mapping, dbc);
  const toml::table* nodes = nullptr;
  bool defaults = true;
  ResolveOutputs(table, outputs, mapping, dbc, &nodes, &defaults);
  if (defaults) BindDefaults(outputs, dbc, mapping);
  if (nodes != nullptr) {
    for (const auto& [k, v] : *nodes) {
      mapping.node_temperatures.emplace(
          std::string(k.str()),
          Resolve(v, fmt::format("outputs.nodes.{}", k.str()), dbc, &mapping.deprecations));
    }
  }

  CheckNodeTable(table, mapping);

  // The estimators cannot run without the dq quantities and a speed.
  std::vector<std::string> missing;
  for (MappingInput i :
       {MappingInput::kIdA, MappingInput::kIqA, MappingInput::kUdV, MappingInput::kUqV}) {
    if (!mapping.input(i)) missing.emplace_back(MappingInputName(i));
  }
  if (!mapping.input(MappingInput::kSpeedElecRadPerS) &&
      !mapping.input(MappingInput::kSpeedMechRpm)) {
    missing.emplace_back("speed_elec_rad_per_s or speed_mech_rpm");
  }
  if (!missing.empty()) {
    std::string list;
    for (const auto& m : missing) list += fmt::format("{}{}", list.empty() ? "" : ", ", m);
    const toml::node* inputs = table.get("inputs");
    Fail(inputs != nullptr ? *inputs : static_cast<const toml::node&>(table), "inputs",
         "missing required input " + list);
  }

  // Every mapped message owns IDs [id, id + node_id_limit); they must fit and not overlap.
  std::vector<int> used;
  const auto note = [&](const SignalRef& r) {
    if (std::find(used.begin(), used.end(), r.message_index) == used.end()) {
      used.push_back(r.message_index);
    }
  };
  for (const auto& r : mapping.inputs) {
    if (r) note(*r);
  }
  for (const auto& [key, r] : mapping.outputs) note(r);
  for (const auto& [name, r] : mapping.node_temperatures) note(r);
  for (std::size_t a = 0; a < used.size(); ++a) {
    const DbcMessage& ma = dbc.messages[static_cast<std::size_t>(used[a])];
    const std::uint64_t top = std::uint64_t{ma.id} + mapping.node_id_limit - 1;
    if (top > (ma.extended ? 0x1FFFFFFFu : 0x7FFu)) {
      Fail(table, "node_id_limit",
           fmt::format("message {} (ID {:#x}) plus node IDs up to {} leaves the {}-bit ID range",
                       ma.name, ma.id, mapping.node_id_limit - 1, ma.extended ? 29 : 11));
    }
    for (std::size_t b = a + 1; b < used.size(); ++b) {
      const DbcMessage& mb = dbc.messages[static_cast<std::size_t>(used[b])];
      if (ma.extended != mb.extended) continue;
      const std::uint32_t lo = std::min(ma.id, mb.id);
      const std::uint32_t hi = std::max(ma.id, mb.id);
      if (hi - lo < mapping.node_id_limit) {
        Fail(table, "node_id_limit",
             fmt::format("messages {} ({:#x}) and {} ({:#x}) are closer than node_id_limit {}: "
                         "one pump's frame would carry another's ID",
                         ma.name, ma.id, mb.name, mb.id, mapping.node_id_limit));
      }
    }
  }
  return mapping;
}

SignalMapping ParseMapping(std::string_view toml_text, std::string_view source_name, const Dbc& dbc,
                           std::span<const OutputSpec> outputs) {
  toml::table table;
  try {
    table = toml::parse(toml_text, source_name);
  } catch (const toml::parse_error& e) {
    throw MappingError(fmt::format("{}: {}", Where(e.source()), e.description()));
  }
  return MappingFromTable(table, dbc, outputs);
}

}  // namespace pumptherm::protocol
