#pragma once
/// Commissioning a configuration against a recording of the bus it will run on
/// (`pumpthermd --check-config FILE --against LOG`, docs/daemon.md "Commissioning against a
/// recording"). The daemon's own pipeline (Gateway + RunOffline, as `pumpthermd -r`) runs over
/// the recording, and beside it every frame is looked at once:
/// - node IDs heard on each interface against the configured pumps (pumps never heard, nodes
///   heard that no pump has, another gateway's frames on the bus);
/// - each input message's measured period and longest silence per pump, against the DBC's
///   cycle time and `alarms.stale_after_s`;
/// - telemetry outside its plausible range (the DBC signal's declared range, the frame and
///   ambient sensors against `alarms.sensor_min_degC`/`sensor_max_degC`, speeds against the
///   motor's rated speed), with the first line where it happens;
/// - clocks that jump (stamps going back, whole-bus silences) and relative stamps;
/// - the frame sensor's first-order lag fitted per pump (below);
/// - the heat balance: the frame-path heat each pump's disturbance-state filter needed beyond
///   the model, against the model's losses (much of it: model_losses_sd_rel = 0.3 proposed);
/// - every warning the daemon logs on the recording, and the alarms it raises.
/// The result is a short text report: findings marked "change" (the configuration does not fit
/// the bus) or "note", each saying what to change.
///
/// The lag fit: the mismatch test (estimators/mismatch_detector.hpp) runs a low-noise Kalman
/// filter on the nominal model with the sensor's first-order lag, tau dy/dt = T_frame - y, as a
/// state; its innovations are white with the stated variance when the model and tau are right.
/// The pipeline runs once per candidate tau (0 to 120 s), and per pump the sum of the test's
/// NIS over the recording (its 60 s window sums, taken every 60 s, up to the moment every
/// candidate has found the model wrong: a change of the plant, which no lag explains; a wrong
/// lag alone may fail the test earlier) is minimised over tau; the minimum is refined by a parabola
/// through its neighbours, and the taus whose sum is within 3.84 (chi-square, 1 degree of
/// freedom, 95 %) of the minimum are the stated interval, a likelihood-ratio interval that
/// holds as far as the innovations are Gaussian and white. A recording whose frame temperature
/// hardly moves cannot tell the lag: the interval then reaches an end of the grid and no value
/// is proposed.

#include <cstdint>
#include <string>
#include <vector>

#include "daemon/config.hpp"

namespace pumptherm::daemon {

struct CommissionOptions {
  /// Candidate sensor lags, s, in increasing order (empty: no lag fit); a finer grid follows
  /// around each pump's first estimate.
  std::vector<double> lag_grid_s = {0, 10, 20, 30, 45, 60, 90, 120};
};

/// The fitted lag of one pump.
struct LagFit {
  std::string pump;
  bool identified = false;           ///< the interval lies inside the grid
  double lag_s = 0.0;                ///< the refined minimum
  double low_s = 0.0, high_s = 0.0;  ///< the 95 % interval
  double configured_s = 0.0;
  int windows = 0;  ///< NIS windows summed
  /// When every candidate lag had found the model wrong (s since the recording's start; NaN:
  /// never): the windows end there.
  double model_failed_s = 0.0;
};

struct CommissionResult {
  std::string report;                 ///< the text, ending with its verdict line
  std::vector<std::string> changes;   ///< findings that need a change (also in the report)
  std::vector<std::string> notes;     ///< findings worth knowing
  std::vector<LagFit> lags;           ///< per pump, when the grid was not empty
  std::uint64_t frames = 0;           ///< frames in the recording
  std::uint64_t daemon_warnings = 0;  ///< warnings the pipeline logged on the recording
};

/// Runs `config` (already loaded; its DBC, mapping, motors and models are read again) against
/// the candump recording at `log_path` (any format the daemon reads). Throws ConfigError for a
/// configuration the gateway refuses, std::runtime_error naming the file for a log that cannot
/// be read, is empty, or has no frame.
CommissionResult CommissionAgainst(const DaemonConfig& config, const std::string& log_path,
                                   const CommissionOptions& options = {});

}  // namespace pumptherm::daemon
