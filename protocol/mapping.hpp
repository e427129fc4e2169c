#pragma once
/// The signal mapping: which DBC message and signal carries each estimator input and output.
///
/// The frame layout is configuration: a pump controller with its own DBC needs only its own
/// mapping. The mapping is TOML (a file of its own, or a table inside the daemon config):
///
///     node_id_limit = 16                  # pumps have node IDs 0..15
///     [inputs]
///     id_A = { message = "PUMP_FAST_I", signal = "Id_A" }
///     speed_elec_rad_per_s = { message = "PUMP_FAST_I", signal = "SpeedElec_rad_per_s" }
///     frame_sensor_degC = { message = "PUMP_STATUS", signal = "FrameSensor_degC", scale = 1.0,
///     offset = 0.0 } [outputs] winding_resistance_degC = { message = "GW_TEMPS_A", signal =
///     "WindingResistance_degC" } node_index = { message = "GW_NODE_TEMP", signal = "NodeIndex" } #
///     node-indexed message: node_temp_degC = { message = "GW_NODE_TEMP", signal = "NodeTemp_degC"
///     }  # any model's nodes [outputs.nodes]                     # thermal-model node name ->
///     signal, degC frame = { message = "GW_TEMPS_A", signal = "Frame_degC" }
///
/// Node ID rule: the DBC defines each message for node ID 0; pump n uses CAN ID = DBC ID + n,
/// with 0 <= n < node_id_limit (docs/protocol.md). Each mapped message therefore owns a block of
/// node_id_limit IDs, and the blocks must not overlap.
///
/// Names of protocol version "pumptherm 2" (docs/protocol.md, "Protocol versions"): a mapping
/// that still uses an input key or an output key of before, or a signal of pumptherm.dbc by its
/// name in "pumptherm 1", is read as the current one and the change is listed in
/// SignalMapping::deprecations; a DBC that still has a signal's "pumptherm 1" name (a site's
/// copy) gets its defaults bound to that name, also listed.
///
/// Value rule: estimator value = scale * DBC value + offset (defaults 1 and 0), so a DBC in other
/// units (mA, rpm for an electrical speed, ...) maps without recompiling.

#include <toml++/toml.h>

#include <array>
#include <cstdint>
#include <map>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>

#include "protocol/dbc.hpp"

namespace pumptherm::protocol {

/// What the daemon reads from a pump drive. Speeds: electrical angular speed (pole pairs times
/// mechanical, rad/s) and mechanical speed (r/min); at least one of the two must be mapped.
enum class MappingInput {
  kIdA,               ///< id_A: d-axis current, amplitude-invariant dq, A
  kIqA,               ///< iq_A: q-axis current, A
  kUdV,               ///< ud_V: d-axis voltage, V
  kUqV,               ///< uq_V: q-axis voltage, V
  kSpeedElecRadPerS,  ///< speed_elec_rad_per_s: electrical speed, rad/s
  kSpeedMechRpm,      ///< speed_mech_rpm: mechanical speed, r/min
  kRollingCounter,    ///< rolling_counter: counter of the fast telemetry frames
  kDriveState,        ///< drive_state: 0 stopped, 1 accelerating, 2 steady, 3 braking, 4 fault
  kFrameSensorDegC,   ///< frame_sensor_degC: frame temperature sensor (frame_temp_degC before)
  kAmbientDegC,       ///< ambient_degC: ambient or coolant temperature (ambient_temp_degC before)
  kDcLinkV,           ///< dc_link_V: DC-link voltage
  kAlarmClear,        ///< alarm_clear: a command frame; 1 clears the pump's latched trips
};
inline constexpr std::size_t kMappingInputCount = 12;

/// An output its user publishes (the daemon declares them in daemon/published_fields.cpp): its
/// mapping key, the DBC message and signal it goes to when the mapping names none (taken only
/// where the DBC has both; empty: none), and a key it had before (still read, reported as
/// deprecated; empty: none).
struct OutputSpec {
  std::string_view key;
  std::string_view default_message;
  std::string_view default_signal;
  std::string_view old_key;
};

/// The node-indexed message's keys: node_index is its multiplexer (the frame carries the
/// thermal model's node with this index, model order, so any model's nodes reach the bus; the
/// nodes are sent in turn, each once per period); node_temp_degC, node_sd_K and node_count go
/// in the same message.
inline constexpr std::string_view kNodeIndexKey = "node_index";
inline constexpr std::string_view kNodeTempKey = "node_temp_degC";
inline constexpr std::string_view kNodeSdKey = "node_sd_K";
inline constexpr std::string_view kNodeCountKey = "node_count";

/// The TOML key of an input.
std::string_view MappingInputName(MappingInput input) noexcept;

/// One binding, resolved against the DBC.
struct SignalRef {
  std::string message;
  std::string signal;
  int message_index = -1;  ///< into Dbc::messages
  int signal_index = -1;   ///< into DbcMessage::signals
  double scale = 1.0;      ///< estimator value = scale * DBC value + offset
  double offset = 0.0;
};

/// A validated mapping.
struct SignalMapping {
  std::array<std::optional<SignalRef>, kMappingInputCount> inputs;
  /// Output key -> signal: every output the mapping names, and every declared default the DBC
  /// has (OutputSpec).
  std::map<std::string, SignalRef, std::less<>> outputs;
  std::map<std::string, SignalRef, std::less<>> node_temperatures;  ///< node name -> signal, degC
  std::uint32_t node_id_limit = 16;
  /// One line per deprecated key or signal name the file used (source:line:column, old and
  /// current name), and per default bound to a signal's old name in the DBC; the caller reports
  /// them. The old names still work.
  std::vector<std::string> deprecations;

  const std::optional<SignalRef>& input(MappingInput i) const noexcept {
    return inputs[static_cast<std::size_t>(i)];
  }
  /// The signal of output `key`, or nullptr.
  const SignalRef* output(std::string_view key) const noexcept {
    auto it = outputs.find(key);
    return it == outputs.end() ? nullptr : &it->second;
  }
  /// CAN ID of DBC message `message_index` for the pump with `node_id` (DBC ID + node_id).
  /// Throws std::out_of_range if node_id >= node_id_limit.
  std::uint32_t CanId(const Dbc& dbc, int message_index, std::uint32_t node_id) const;
};

/// An error in a mapping, naming where (source:line:column) and the key.
class MappingError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// Parses and validates a mapping from TOML text; `outputs` are the output keys its user knows
/// (empty: a reader of the inputs alone; the [outputs] table is then not read).
/// `source_name` labels errors. Throws MappingError for a TOML syntax error, an unknown key, a
/// missing message/signal key, a message or signal the DBC does not have, a missing required
/// input (id_A, iq_A, ud_V, uq_V and one speed), node_index without node_temp_degC (or the
/// reverse) or node outputs outside node_index's message, a node_id_limit outside 1..65536, or
/// ID blocks that overflow or overlap.
SignalMapping ParseMapping(std::string_view toml_text, std::string_view source_name, const Dbc& dbc,
                           std::span<const OutputSpec> outputs);

/// The same, from a table already parsed (e.g. the `[mapping]` table of the daemon config);
/// errors name the table's source file, line and column.
SignalMapping MappingFromTable(const toml::table& table, const Dbc& dbc,
                               std::span<const OutputSpec> outputs);

}  // namespace pumptherm::protocol
