#pragma once
/// One pump of the daemon over a candump recording, exactly as `pumpthermd -r` runs it (its
/// Gateway, its offline loop), writing the daemon's CSV for that pump: what `pumptherm estimate
/// --log` and `pumptherm identify --model --log` run.

#include <limits>
#include <string>

#include "daemon/config.hpp"
#include "estimators/motor.hpp"
#include "tools/pumptherm/recording.hpp"

namespace pumptherm::tools {

/// Pump `name` of the daemon's configuration at `path`, and the configuration itself with only
/// that pump. Throws InputError for a configuration that does not load or has no such pump.
daemon::DaemonConfig ConfigWithPump(const std::string& path, const std::string& name);

struct PumpRecordingRun {
  std::string tool = "pumptherm estimate";  ///< names the run in the daemon's messages
  /// The daemon's configuration file and its pump (both or neither); without them `pump` below.
  std::string config;
  std::string config_pump;
  daemon::PumpConfig pump;        ///< without a configuration: the pump's settings
  double thermal_period_s = 1.0;  ///< without a configuration: the thermal period
  RecordingSource recording;      ///< the log, node ID, interface, DBC and mapping
  /// Subtracted from the Unix time in time_s (NaN: the recording's first whole second).
  double csv_time_origin_s = std::numeric_limits<double>::quiet_NaN();
  std::string csv_file = "-";  ///< the daemon's CSV of the pump ("-": standard output)
};

/// What ran: the configuration (one pump, listening on the recording's interface) and the
/// motor description the daemon loaded for that pump.
struct PumpRecordingResult {
  daemon::DaemonConfig config;
  estimators::MotorDescription motor;
};

/// Runs the pump over the recording into `run.csv_file`. Throws InputError for an unreadable log
/// or configuration, a log without frames, or no thermal step for the pump.
PumpRecordingResult RunPumpOnRecording(const PumpRecordingRun& run);

}  // namespace pumptherm::tools
