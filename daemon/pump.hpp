#pragma once
/// One pump's estimation pipeline: the decoded telemetry in SI units goes to the resistance
/// identifier at telemetry rate and to the virtual thermal sensor once per thermal period
/// (timed by the frames' timestamps), then to the alarm monitor and the time-to-trip forecast.
/// No I/O here: the gateway decodes frames and publishes what this produces.

#include <Eigen/Dense>
#include <cstdint>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "daemon/config.hpp"
#include "estimators/alarm_bounds.hpp"
#include "estimators/alarms.hpp"
#include "estimators/disturbance_sensor.hpp"
#include "estimators/kalman_virtual_sensor.hpp"
#include "estimators/mismatch_detector.hpp"
#include "estimators/motor.hpp"
#include "estimators/resistance_identifier.hpp"
#include "estimators/thermal_discretisation.hpp"
#include "estimators/thermal_model.hpp"
#include "estimators/trip_forecast.hpp"

namespace pumptherm::daemon {

inline constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
inline constexpr double kInf = std::numeric_limits<double>::infinity();
/// Range of a believable node estimate: absolute zero to well above where copper melts
/// (1085 degC). Outside it (or non-finite) the filter is reset, never published.
inline constexpr double kMinEstimate_degC = -273.15;
inline constexpr double kMaxEstimate_degC = 1000.0;

/// Counters of one pump's inputs (what was dropped is counted, never silent).
struct PumpCounters {
  std::uint64_t fast_frames = 0;
  std::uint64_t status_frames = 0;
  std::uint64_t samples = 0;          ///< paired current+voltage samples identified
  std::uint64_t unpaired = 0;         ///< half-samples whose partner never came
  std::uint64_t lost_frames = 0;      ///< gaps in the rolling counter
  std::uint64_t rejected_values = 0;  ///< NaN/Inf or out-of-range decoded values
  std::uint64_t thermal_steps = 0;
  std::uint64_t filter_resets = 0;  ///< estimate left [kMinEstimate_degC, kMaxEstimate_degC]
};

/// Everything published about one pump at one moment.
struct PumpSnapshot {
  std::int64_t time_us = 0;
  bool initialised = false;       ///< false until the first thermal step and after a
                                  ///< filter reset: publish "n/a"
  std::vector<double> node_degC;  ///< per thermal state (model order); NaN before init
  std::vector<double> node_sd_K;
  /// The filter has converged since its (re)start, judged as the alarms judge it (the standard
  /// filter's largest sd below 5 K): the published sds may stay larger by design (a rotor the
  /// frame barely sees, a worst case while running blind) without the filter still settling.
  bool filter_converged = false;
  estimators::ResistanceEstimate resistance;
  double winding_resistance_degC = kNaN;  ///< NaN unless the identifier is tracking
  /// Magnet temperature from the identified back-EMF (Pump::BackEmfMeasurement) at the
  /// filter's winding temperature, and its sd: NaN unless the motor states a magnet law and
  /// the identification is fresh, usable and at speed.
  double magnet_flux_degC = kNaN;
  double magnet_flux_sd_K = kNaN;
  double frame_measured_degC = kNaN;  ///< the frame sensor as fused (NaN: not fused)
  estimators::SensorFault sensor_fault = estimators::SensorFault::kNone;
  /// The frame sensor's calibration offset as the disturbance-state filter estimates it, K (NaN
  /// without that filter); how many steps of it the filter has found (a reading stepping faster
  /// than the frame can move), the last one and their sum since the filter started, K.
  double sensor_offset_K = kNaN;
  std::uint64_t sensor_steps = 0;
  double last_sensor_step_K = kNaN;
  double stepped_offset_K = kNaN;
  double ambient_degC = kNaN;
  double speed_rpm = kNaN;
  double innovation_K = kNaN;
  double nis = kNaN;
  estimators::AlarmState alarm;
  int time_to_trip_node = -1;            ///< state index the forecast is about (-1: none)
  std::uint64_t alarm_changes = 0;       ///< increments whenever `alarm` changes
  estimators::MismatchFinding mismatch;  ///< is the model right? (docs/daemon.md, "Model mismatch")
  std::uint64_t mismatch_changes = 0;    ///< increments when its state or effect changes
};

/// Saved state of one pump (the state store writes it; docs/daemon.md "State").
struct PumpSavedState {
  std::string model_name;
  std::int64_t time_us = 0;
  Eigen::VectorXd x_degC;
  Eigen::MatrixXd s_K2;
  estimators::ThermalInputs inputs;  ///< the last inputs (held while the daemon is down)
  estimators::ResistanceIdentifierState resistance;
  bool trip_latched = false;
  /// Latched trips, restored latched: the alarm node's name (a model node,
  /// "winding_resistance" or "sensor") and the value that raised it, degC.
  struct LatchedTrip {
    std::string node;
    double value_degC = kNaN;
  };
  std::vector<LatchedTrip> latched_trips;
  /// The frame sensor's offset as the disturbance-state filter had it, its sd and the sum of its
  /// steps, K (NaN: not saved; the offset then starts again from its prior).
  double sensor_offset_K = kNaN;
  double sensor_offset_sd_K = kNaN;
  double stepped_offset_K = kNaN;
  /// The disturbance-state filter's whole state and covariance (the nodes, the sensor's lag and
  /// offset, the disturbances and biases); empty: not saved (no such filter, an older file, or
  /// one of another configuration), and the filter restarts from the nodes with its disturbances
  /// at their priors.
  Eigen::VectorXd disturbance_x;
  Eigen::MatrixXd disturbance_s;
};

class Pump {
 public:
  /// Throws std::invalid_argument naming the pump and the problem (unknown measured node, a
  /// level for a node the model lacks, bad estimator settings).
  Pump(const PumpConfig& config, const estimators::MotorDescription& motor,
       std::shared_ptr<const estimators::ThermalModel> model, double thermal_period_s);
  /// How many numbers the disturbance-state filter's saved state has (0: the pump publishes the
  /// standard filter, none are saved).
  int DisturbanceStateCount() const {
    return config_.disturbance_states ? robust_.StateCount() : 0;
  }

  const PumpConfig& config() const { return config_; }
  const estimators::ResistanceIdentifier& identifier() const { return identifier_; }
  const estimators::ThermalModel& model() const { return *model_; }
  const estimators::MotorDescription& motor() const { return motor_; }
  /// Every active alarm condition, most severe first.
  std::vector<estimators::AlarmCondition> ActiveConditions() const {
    return alarms_.ActiveConditions();
  }
  /// The same into `out`: no allocation once `out` has held as many (the gateway's LCM path).
  void ActiveConditions(std::vector<estimators::AlarmCondition>& out) const {
    alarms_.ActiveConditions(out);
  }

  /// Fast telemetry halves (NaN for what the mapping does not carry), paired into one
  /// identifier sample when they arrive within 50 ms of each other with equal rolling counters
  /// (or when either half carries no counter).
  void OnCurrents(std::int64_t t_us, double id_A, double iq_A, double w_e_rad_per_s,
                  double counter);
  void OnVoltages(std::int64_t t_us, double ud_V, double uq_V, double counter);
  /// Slow status (NaN for what is not mapped or not available).
  void OnStatus(std::int64_t t_us, double speed_rpm, double drive_state, double frame_degC,
                double ambient_degC);

  /// Runs every thermal step whose period ended at or before `t_us`, with alarms and the
  /// forecast. Returns true when the alarm state changed.
  bool Advance(std::int64_t t_us);

  /// Clears latched trips (from an accepted clear command). Returns true if one was latched.
  bool ClearTrips() { return alarms_.Clear(); }
  /// Clears the latched trip of one alarm node (LatchIndex()). Returns true if it was latched.
  bool ClearTrip(int node) { return alarms_.Clear(node); }
  /// The alarm monitor's index of alarm node `name` (a model node, "sensor",
  /// "winding_resistance", "safety_state_lost"), or nullopt for a name this pump lacks.
  std::optional<int> LatchIndex(const std::string& name) const;
  /// Latches the trip "safety state lost" at `now_us` (the gateway, at start, when the latched
  /// trips and clear counters saved could not be read); published at once.
  void LatchStateLost(std::int64_t now_us);
  /// Evidence of a second sender on this pump's CAN IDs at `now_us`: a warning, published at once.
  void RaiseSecondSender(std::int64_t now_us);

  const PumpSnapshot& snapshot() const { return snapshot_; }
  const PumpCounters& counters() const { return counters_; }
  /// Time of the last telemetry frame (fast or status), us; -1 before any.
  std::int64_t last_frame_us() const { return last_frame_us_; }
  /// Whether a frame was heard and the thermal steps run (false before the first frame).
  bool heard() const { return heard_; }
  /// For a pump never heard from: runs its alarms (once per thermal period) with every input
  /// `t_us - since_us` old, so that after `stale_after_s` it raises stale telemetry like a pump
  /// that fell silent. Returns whether the alarm changed. No effect once a frame was heard.
  bool CheckNeverHeard(std::int64_t since_us, std::int64_t t_us);
  /// The earliest time (us) at which Advance or CheckNeverHeard has work: the end of the next
  /// thermal period; INT64_MIN when due at once (a first frame not yet advanced to, or a pump
  /// never heard from whose silence is not yet timed). Before it, both change nothing.
  std::int64_t NextDueUs() const;

  PumpSavedState Save() const;
  /// Continues from `state` saved at state.time_us, aged to `now_us` by the thermal model with
  /// the last inputs held (a motor that kept running stays hot) and the covariance grown by the
  /// process noise over the gap; latched trips latch again (until cleared). Returns false
  /// (nothing changes) when the state does not fit this pump's model or names an alarm node it
  /// lacks.
  bool Restore(const PumpSavedState& state, std::int64_t now_us);
  /// Latches again only the trips of `state` (when its filter state cannot be used: the filter
  /// starts cold, the trips stay latched until cleared). Returns false (nothing changes) when a
  /// trip names an alarm node this pump lacks or has a non-finite value.
  bool RestoreLatchedTrips(const PumpSavedState& state, std::int64_t now_us);

 private:
  void ThermalStep(std::int64_t step_end_us);
  /// The period's inputs into `in` (mean squared currents, mean speed, the latest ambient; held
  /// when no fast frame came) and the mean iq; false while nothing is known to step on.
  bool PeriodInputs(estimators::ThermalInputs& in, double& mean_iq_A);
  /// One step of the disturbance-state filter, its nodes and its sensor offset into the snapshot.
  void StepRobust(const estimators::ThermalInputs& in, double measured,
                  estimators::SensorFault fault);
  /// Whether the published filter left any physical range (it is then reset and counted).
  bool ResetIfDiverged(const Eigen::VectorXd& x, const Eigen::MatrixXd& s);
  /// The published nodes and sds into the snapshot (NaN when diverged); returns the standard
  /// filter's largest node sd (convergence is judged on it).
  double PublishNodes(bool diverged, const Eigen::VectorXd& x, const Eigen::MatrixXd& s);
  /// The alarm step on `ai` (the caller's sensor, convergence and forecast inputs; the node
  /// values, the telemetry age and the plant-blamed hold added here).
  void StepAlarms(std::int64_t end_us, estimators::AlarmInputs& ai);
  /// This step's magnet measurement from the identifier's line at the period's mean iq and
  /// electrical speed `w_rad_per_s` (NaN value when unusable); see pump.cpp.
  void BackEmfMeasurement(std::int64_t step_end_us, double iq_A, double w_rad_per_s);
  /// The magnet temperature at the filter's (updated) winding estimate into the snapshot.
  void PublishMagnetTemperature();
  /// The disturbance-state filter's readings of this step: the frame and the back-EMF magnet row.
  estimators::DisturbanceReadings RobustReadings(double frame_degC) const;
  /// This step's extra filter measurements: the winding from resistance, the magnet from flux.
  const estimators::NodeMeasurements& ExtraMeasurements(double winding_res_degC);
  /// Runs the mismatch test on this step's inputs and reading; counts a changed verdict.
  void CheckModel(const estimators::ThermalInputs& in, double measured_degC, std::int64_t end_us);
  double TimeToTrip_s(const estimators::ThermalInputs& in, int* node);
  void Identify(std::int64_t t_us);
  void NoteFastFrame(std::int64_t t_us);
  /// The latest of two frame times (`last_us`, the one before it `previous_us`) not after `t_us`.
  static std::int64_t LastAtOrBefore(std::int64_t last_us, std::int64_t previous_us,
                                     std::int64_t t_us);
  /// The disturbance-state filter from `state`: its whole saved state aged over `gap_s` when
  /// `whole` (checked by the caller), else the restored nodes `x`, `s` with the disturbances at
  /// their priors and the saved sensor offset.
  void RestoreDisturbanceFilter(const PumpSavedState& state, bool whole, double gap_s,
                                const Eigen::VectorXd& x, const Eigen::MatrixXd& s);
  bool TripIndices(const PumpSavedState& state,
                   std::vector<estimators::AlarmMonitor::LatchedTrip>& out) const;
  void Relatch(const std::vector<estimators::AlarmMonitor::LatchedTrip>& trips,
               std::int64_t now_us);
  /// The resistance-based winding temperature if the identifier tracks and its last sample is
  /// at most `stale_after_s` old at `t_us`, else NaN.
  double FreshWindingResistance_degC(std::int64_t t_us) const;
  /// Advances (or, when not `blind`, drops) the worst-case bound used for the levels while no
  /// temperature is measured; `fault` the frame sensor's, `end_us` the step's end.
  void StepBlindBound(bool blind, estimators::SensorFault fault,
                      const estimators::ThermalInputs& in, std::int64_t end_us);
  /// Keeps the estimate the blind bound starts from, after the step ending at `end_us`, in the
  /// ring of recent ones; `valid` false forgets them all (the filter was reset).
  void RememberEstimate(std::int64_t end_us, bool valid);
  /// Steps the lagging reading's bias (`lagging_degC`: the fused reading the estimate follows
  /// without modelling its lag, else NaN) and the silence bound (`fresh_inputs`: this step had
  /// telemetry; `x` the estimate after it).
  void StepAlarmsWithoutEstimate(std::int64_t end_us, estimators::SensorFault fault);
  /// The alarms alone at `t_us` (no estimate): stamps the snapshot, counts a change; true if
  /// the alarm state changed.
  bool StepAlarmsOnly(std::int64_t t_us, const estimators::AlarmInputs& ai);
  /// This step's magnet temperature from the flux is fused (fresh, below the gain limit).
  bool MagnetReadingUsed() const;
  void StepAlarmBounds(bool diverged, bool fresh_inputs, double lagging_degC,
                       const estimators::ThermalInputs& in, const Eigen::VectorXd& x);
  /// The value state `i`'s levels act on, from its estimate and the bounds.
  double AlarmValue_degC(int i, double estimate_degC) const;
  /// The sd published for a node whose filter sd is `filter_sd_K` and whose alarm value lies
  /// `above_K` above its estimate (NaN or <= 0: none).
  static double PublishedSd_K(double filter_sd_K, double above_K);
  /// The sensor fault to alarm on: `fault`, except a missing sensor while the fast frames are
  /// silent too (the link, not the sensor).
  estimators::SensorFault SensorFaultAlarm(estimators::SensorFault fault, std::int64_t t_us) const;
  /// Age of the oldest input kind that has arrived at least once (fast frames, status), s.
  double TelemetryAge_s(std::int64_t t_us) const;

  PumpConfig config_;
  std::shared_ptr<const estimators::ThermalModel> model_;
  estimators::MotorDescription motor_;
  double period_s_;
  std::int64_t period_us_;
  estimators::ResistanceIdentifier identifier_;
  estimators::VirtualThermalSensor sensor_;
  estimators::AlarmMonitor alarms_;
  estimators::SensorHealth sensor_health_;
  estimators::SensorFault last_fault_ = estimators::SensorFault::kNone;  ///< at the last step
  estimators::MismatchDetector mismatch_;
  estimators::DisturbanceThermalSensor robust_;  // published when config_.disturbance_states
  Eigen::VectorXd robust_x_, robust_sd_;
  int measured_state_ = -1;
  int magnet_state_ = -1;                // state the magnet temperature is fused into (-1: none)
  std::uint64_t identifier_blocks_ = 0;  // block updates seen, to time the flux's freshness
  std::int64_t flux_block_us_ = -1;      // time of the identifier's last block update
  estimators::NodeMeasurements extra_;
  // This step's back-EMF measurement: z = T_magnet + gain T_winding, sd_K (NaN z: none).
  double magnet_z_degC_ = kNaN, magnet_gain_ = 0.0, magnet_z_sd_K_ = kNaN;
  bool magnet_gated_ = false;      ///< |magnet_gain_| above magnet_max_winding_gain: not used
  Eigen::VectorXd winding_cov_;    // S w, for the winding estimate's variance
  std::vector<int> level_states_;  // state index of each alarm node (n states + winding)
  PumpCounters counters_;
  PumpSnapshot snapshot_;

  // Pairing of the fast halves.
  struct Half {
    std::int64_t t_us = -1;
    double a = kNaN, b = kNaN, c = kNaN;
    double counter = kNaN;
  };
  Half currents_, voltages_;
  double last_counter_ = kNaN;
  std::int64_t last_sample_us_ = -1;
  double w_e_rad_per_s_ = kNaN;  // latest electrical speed (fast frame or status)

  // Status values.
  double ambient_degC_ = kNaN;
  double speed_rpm_ = kNaN;
  std::int64_t last_frame_us_ = -1;
  std::int64_t last_fast_us_ = -1;
  std::int64_t previous_fast_us_ = -1;  // the fast frame time before last_fast_us_
  std::int64_t last_status_us_ = -1;
  std::int64_t previous_status_us_ = -1;

  // Inputs averaged over the current thermal period.
  double sum_id2_ = 0.0, sum_iq2_ = 0.0, sum_speed_ = 0.0, sum_iq_ = 0.0;
  int n_inputs_ = 0;
  estimators::ThermalInputs held_inputs_;
  bool have_inputs_ = false;
  std::int64_t next_step_us_ = -1;
  bool heard_ = false;  // a frame was heard (Advance runs thermal steps from then on)
  bool initialised_ = false;

  Eigen::VectorXd measurement_ = Eigen::VectorXd::Constant(1, kNaN);  // the frame sensor, per step

  // Forecast.
  estimators::TripForecast forecast_{model_->StateCount()};
  std::vector<double> trip_degC_;  // per node, for the forecast (infinity: no trip level)
  std::vector<double> alarm_values_;
  estimators::BlindBound blind_;  // worst-case bound while blind
  // The blind bound's starting estimates of the last steps (columns, a ring; time -1: none), long
  // enough to reach back to before a reading that was found stuck.
  Eigen::MatrixXd recent_degC_;
  std::vector<std::int64_t> recent_us_;
  std::size_t recent_next_ = 0;
  Eigen::VectorXd blind_start_degC_;  // the one of them a blind bound starts from
  std::vector<double> alarm_sd_;      // their standard deviations (the winding's: none, NaN)
  estimators::LagBias lag_bias_;      // the frame reading's lag, added to the levels' values
  estimators::SilenceBound silence_;  // the load that may have risen in a telemetry silence
};

}  // namespace pumptherm::daemon
