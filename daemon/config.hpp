#pragma once
/// The daemon's configuration file (TOML; every key in docs/daemon.md, an example in
/// systemd/pumpthermd.toml). Loading checks types and ranges and rejects unknown keys; an error
/// names file, line and key. Checks that need the referenced files (model node names, DBC
/// signals) happen when the gateway is built from the configuration, with the same naming.

#include <cstdint>
#include <map>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "daemon/clear_keys.hpp"
#include "estimators/alarms.hpp"

namespace toml {
inline namespace v3 {
class table;
}
}  // namespace toml

namespace pumptherm::daemon {

/// A configuration error; what() reads "FILE:LINE: key 'KEY': PROBLEM".
class ConfigError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// Receive buffer asked for each CAN socket by default (SO_RCVBUF), bytes: the kernel doubles
/// it for its bookkeeping and charges about 1 KiB per queued CAN frame, so 1 MiB holds about
/// 2000 frames, a quarter of a second of a fully loaded 1 Mbit/s bus (docs/daemon.md, "Receive
/// buffer"). Unprivileged sockets get at most net.core.rmem_max (x 2).
inline constexpr std::int64_t kDefaultRxBufferBytes = 1 << 20;
inline constexpr std::int64_t kMinRxBufferBytes = 4096;  ///< below it the kernel's own floor rules
inline constexpr std::int64_t kMaxRxBufferBytes = 256LL << 20;  ///< 256 MiB

/// One SocketCAN interface the daemon listens and sends on.
struct InterfaceConfig {
  std::string name;           ///< e.g. "can0" or "vcan0"
  bool error_frames = false;  ///< subscribe to error frames (bus state)
  /// SO_RCVBUF asked for the socket, bytes; 0 leaves the kernel's default (net.core.rmem_default).
  std::int64_t rx_buffer_bytes = kDefaultRxBufferBytes;
};

/// What a damaged or missing safety state (latched trips and clear counters, docs/daemon.md
/// "State across restarts") does at start.
enum class LostSafetyState {
  kLatch,  ///< every pump starts with a latched trip "safety_state_lost" (the default)
  kWarn,   ///< a warning only; the pumps start unlatched
};

struct GatewayConfig {
  std::string name = "pumptherm";      ///< shown in the status line and logs
  std::uint32_t heartbeat_id = 0x7F0;  ///< 11-bit CAN ID of the heartbeat frame
  double heartbeat_period_s = 1.0;     ///< 0 disables the heartbeat
  double status_period_s = 2.0;        ///< systemd STATUS= and journal summary period
  double thermal_period_s = 1.0;       ///< virtual thermal sensor period (frame time)
  std::string state_directory;         ///< empty: $STATE_DIRECTORY, else no saved state
  double state_save_period_s = 60.0;   ///< how often estimator state is saved
  bool test_hang_switch = false;       ///< tests only: SIGUSR1 makes the loop hang
  /// Warn about frames of node IDs no pump has (a wrong node_id); off where one pump of a
  /// recording of many is run on purpose (`pumptherm estimate`). Counted either way.
  bool warn_unconfigured_nodes = true;
  double test_state_write_pause_s = 0.0;  ///< tests only: pause in the middle of each state write
  /// tests only: pause in the middle of each safety state write (a kill -9 lands in it)
  double test_safety_write_pause_s = 0.0;
  /// The gateway's Ed25519 key (`pumptherm keygen`): signs answers to clears; LCM clears need
  /// it. Empty: none (every LCM clear is refused).
  std::string signing_key_file;
  int signing_key_line = 0;  ///< line of gateway.signing_key_file, for messages
  LostSafetyState lost_safety_state = LostSafetyState::kLatch;
};

/// Where the frame layout comes from.
struct DbcConfig {
  std::string file = "pumptherm.dbc";              ///< path or shipped name
  std::string mapping = "mapping_pumptherm.toml";  ///< path or shipped name of the mapping
  std::string base_dir = ".";                      ///< directory of the config file
  int file_line = 0;     ///< line of `dbc.file` in the config file (0: not given there)
  int mapping_line = 0;  ///< line of `dbc.mapping` (0: not given there)
};

struct LcmConfig {
  std::string url;  ///< empty: LCM off
  std::string channel_prefix = "PUMPTHERM";
  double period_s = 1.0;  ///< temperatures/identification publishing period
  double health_period_s = 5.0;
  /// Interfaces besides this host from which LCM messages are taken (the rest are dropped in the
  /// kernel, docs/threat-model.md "The network boundary"); empty: this host only.
  std::vector<std::string> receive_interfaces;
};

/// The MQTT Sparkplug B sink (docs/mqtt.md, docs/daemon.md "[mqtt]"); off without an [mqtt]
/// table. Paths are absolute (relative ones are taken from the config file's directory).
struct MqttConfig {
  bool enabled = false;  ///< an [mqtt] table was given
  std::string host;      ///< the broker
  int port = 0;          ///< 0: 8883 with TLS, 1883 without
  std::string group_id = "pumptherm";
  std::string edge_node_id;         ///< empty: the gateway's name
  std::string ca_file;              ///< the broker's CA (PEM): TLS on when given
  std::string cert_file, key_file;  ///< this gateway's client certificate and key (PEM), or none
  std::string username;
  std::string password_file;     ///< a file holding the password (LoadCredential=), or none
  bool allow_plaintext = false;  ///< a non-local broker without TLS, said explicitly
  double keepalive_s = 10.0;
  std::size_t queue_steps = 256;         ///< data messages waiting; the oldest dropped
  std::size_t alarm_queue_steps = 1024;  ///< alarm transitions waiting, kept across outages
  int line = 0;                          ///< line of the [mqtt] table
  /// Lines of the file keys (0: not given), for CheckMqttFiles' file:line errors.
  int ca_file_line = 0, cert_file_line = 0, key_file_line = 0, password_file_line = 0;
};

/// Alarm levels of one node (or of the measured sensor, key "sensor").
struct LevelsConfig {
  estimators::TemperatureLimits limits;
  int line = 0;
  std::string key;  ///< e.g. "pump[0].alarms.levels.winding", for messages
};

struct AlarmsConfig {
  estimators::AlarmConfig monitor;  ///< timing and plausibility (sensor_node set per pump)
  std::map<std::string, LevelsConfig> levels;     ///< node name (or "sensor") -> levels
  std::vector<std::string> clear_can_interfaces;  ///< clear command frames accepted from these
  /// Sources a shared-key command may claim (the earlier scheme; migration only).
  std::vector<std::string> clear_lcm_sources;
};

/// One operator's public key (alarms.clear_operators).
struct ClearOperatorConfig {
  std::string name;  ///< who holds the key: the source logged for what it signs
  PublicKey public_key{};
  bool revoked = false;  ///< listed, but refused (logged as a revoked key)
  int line = 0;
};

/// Signed LCM clears (docs/threat-model.md): the operators' keys, the replay window, and the
/// shared key of the earlier scheme.
struct ClearAuthConfig {
  std::vector<ClearOperatorConfig> operators;  ///< whose signed clears are taken
  double window_s = 30.0;  ///< a command's time may be this far from the gateway's clock
  /// The earlier scheme's shared key (migration path): used only with allow_shared_key.
  std::string key_file;
  std::string key_group;          ///< group that owns the shared key file (the operators)
  bool allow_shared_key = false;  ///< alarms.clear_allow_shared_key
  int line = 0;                   ///< line of alarms.clear_key_file, for messages
};

struct PumpConfig {
  std::string name;
  std::uint32_t node_id = 0;
  std::string interface;                      ///< which [[can]] interface (or log interface)
  std::string motor = "han2019-tmp";          ///< motor description: path or preset name
  std::string thermal_model = "tmp-generic";  ///< thermal model: path or shipped name
  std::string measured_node = "frame";        ///< the node the frame sensor measures
  bool fuse_winding = true;                   ///< feed the resistance-based winding temperature
  double winding_sd_K = 3.0;                  ///< its standard deviation in the filter
  /// Node the magnet temperature from the flux is fused into (empty: published, not fused).
  std::string magnet_node;
  /// Node of the rotor-heat state (disturbance filter) and of the rotor-loss hypothesis (mismatch
  /// test); empty: `magnet_node`, else "rotor" where the model has it.
  std::string rotor_node;
  /// Least standard deviation of the magnet temperature from the flux, K, in the filter and as
  /// published: the identifier's covariance sees its noise, not the nameplate flux's error or
  /// the inverter's voltage error.
  double magnet_min_sd_K = 3.0;
  /// The magnet temperature from the flux is used only while the winding's weight in it, |g|
  /// (Pump::BackEmfMeasurement), is at most this (K of reading per K of winding).
  double magnet_max_winding_gain = 0.15;
  double frame_sensor_lag_s = 0.0;  ///< first-order lag of the frame sensor (mismatch test)
  /// Publish the disturbance-state filter's estimates. Unless `disturbance_states_explicit`, the
  /// pump turns it off for a model whose boundary reaches the network through other nodes than
  /// `measured_node` (estimators::BoundaryOnlyThrough).
  bool disturbance_states = true;
  bool disturbance_states_explicit = false;  ///< the config file set `disturbance_states`
  /// Fuse the drive's q-axis voltage into the disturbance-state filter (a row in the winding,
  /// the magnet and this pump's R0, psi0 and voltage offset): the winding from resistance and
  /// the magnet from flux come out of the filter. It trusts the motor file's copper and magnet
  /// laws; false for a motor whose magnet law is not known.
  bool voltage_reading = true;
  /// How far this pump's losses may be off the thermal model's at a start, relative (the filter's
  /// loss scale; with the voltage rows the losses nothing measures: iron, friction): 0.1 for a
  /// model checked against this pump's data, more for one that was not.
  double model_losses_sd_rel = 0.1;
  AlarmsConfig alarms;  ///< the gateway's [alarms] with this pump's overrides
  int line = 0;         ///< line of the [[pump]] table
  /// Line of each key given in the [[pump]] table, for messages about its value.
  std::map<std::string, int, std::less<>> key_lines;
  /// The line of `key` in this pump's table, or the table's line when the key was not given.
  int LineOf(std::string_view key) const {
    const auto it = key_lines.find(key);
    return it == key_lines.end() ? line : it->second;
  }
};

struct DaemonConfig {
  std::string source;  ///< file it came from, for messages
  GatewayConfig gateway;
  DbcConfig dbc;
  LcmConfig lcm;
  MqttConfig mqtt;
  AlarmsConfig alarms;         ///< defaults for every pump
  ClearAuthConfig clear_auth;  ///< from [alarms]: clear_operators, clear_window_s, shared key
  std::map<std::string, double> output_periods_s;  ///< DBC message name -> period override
  std::map<std::string, int> output_period_lines;  ///< DBC message name -> its key's line
  std::vector<InterfaceConfig> interfaces;
  std::vector<PumpConfig> pumps;
};

/// Parses configuration text; `source` names it in errors and its directory is the base of
/// relative paths. Throws ConfigError.
DaemonConfig ParseConfig(const std::string& text, const std::string& source);

/// Reads and parses a configuration file. Throws ConfigError (also when unreadable).
DaemonConfig LoadConfig(const std::string& path);

/// A warning when the file at `path` can be written by others than its owner (group- or
/// world-writable: whoever can write it sets the alarm levels and who may clear trips), e.g.
/// "/etc/pumptherm/pumpthermd.toml is writable by group and others (mode 0666): ...";
/// empty when the mode is tight or the file cannot be stat()ed (LoadConfig reports that).
std::string ConfigPermissionWarning(const std::string& path);

}  // namespace pumptherm::daemon
