#pragma once
/// The daemon's configuration file (TOML; documented in docs/configuration.md, an example in
/// systemd/pumpthermd.toml). Loading validates everything; an error names file, line and key.

#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

namespace pumptherm::daemon {

/// A configuration error; what() reads "FILE:LINE: key 'KEY': PROBLEM".
class ConfigError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// One SocketCAN interface the daemon listens and sends on.
struct InterfaceConfig {
  std::string name;                 ///< e.g. "can0" or "vcan0"
  bool error_frames = false;        ///< subscribe to error frames (bus state)
};

struct GatewayConfig {
  std::string name = "pumptherm";   ///< shown in the status line and logs
  std::uint32_t heartbeat_id = 0x7F0;     ///< 11-bit CAN ID of the heartbeat frame
  double heartbeat_period_s = 1.0;        ///< 0 disables the heartbeat
  double status_period_s = 2.0;           ///< systemd STATUS= and journal summary period
};

struct DaemonConfig {
  std::string source;               ///< file it came from, for messages
  GatewayConfig gateway;
  std::vector<InterfaceConfig> interfaces;
};

/// Parses configuration text; `source` names it in errors. Throws ConfigError.
DaemonConfig ParseConfig(const std::string& text, const std::string& source);

/// Reads and parses a configuration file. Throws ConfigError (also when unreadable).
DaemonConfig LoadConfig(const std::string& path);

}  // namespace pumptherm::daemon
