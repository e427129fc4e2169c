#pragma once
/// One pump's estimation, from one thermal period's inputs to one result (docs/architecture.md,
/// "The pump estimator"): the readings (the frame sensor, the magnet from the identified flux,
/// the winding from the identified resistance; one file each under estimators/readings/), one
/// thermal observer (the virtual thermal sensor of Saheba et al. 2010, or the same network with
/// its model error in states made for it), the model-mismatch test, the bounds the alarm levels
/// act on, the alarms and the time-to-trip forecast. The daemon (daemon/pump.cpp) pairs and
/// averages the frames, runs the resistance identifier at telemetry rate and calls Step() once
/// per period; `pumptherm estimate` and the benchmarks call the same.
///
/// Pure library: no I/O, no clock (time enters in PumpPeriod), no configuration parsing. No
/// allocation per step once the operating point is steady (the naming fit of the mismatch test
/// and a re-discretisation may allocate).

#include <Eigen/Dense>
#include <cstdint>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "estimators/alarm_values.hpp"
#include "estimators/alarms.hpp"
#include "estimators/disturbance_sensor.hpp"
#include "estimators/kalman_virtual_sensor.hpp"
#include "estimators/mismatch_detector.hpp"
#include "estimators/motor.hpp"
#include "estimators/pump_period.hpp"
#include "estimators/readings/frame_reading.hpp"
#include "estimators/readings/magnet_flux_reading.hpp"
#include "estimators/readings/voltage_reading.hpp"
#include "estimators/readings/winding_resistance_reading.hpp"
#include "estimators/thermal_model.hpp"
#include "estimators/thermal_observer.hpp"
#include "estimators/trip_forecast.hpp"

namespace pumptherm::estimators {

/// Range of a believable node estimate: absolute zero to well above where copper melts
/// (1085 degC). Outside it (or non-finite) the filter is reset, never published.
inline constexpr double kMinEstimate_degC = -273.15;
inline constexpr double kMaxEstimate_degC = 1000.0;
/// Name of the alarm pseudo-node of the resistance-based winding temperature.
inline constexpr const char* kWindingResistanceNode = "winding_resistance";
/// Name of the alarm levels of the measured sensor itself.
inline constexpr const char* kSensorLevelsNode = "sensor";
/// Name of the latched trip "the safety state was lost" (AlarmMonitor::kStateLostTrip).
inline constexpr const char* kStateLostNode = "safety_state_lost";

struct PumpEstimatorConfig {
  std::string measured_node = "frame";  ///< the node the frame sensor measures
  double frame_sensor_lag_s = 0.0;      ///< its first-order lag
  /// Once the model diagnosis names the sensor's lag (`sensor_lag`), the filter and the
  /// diagnosis read the sensor with the fitted lag (a filter that models the lag; until a
  /// restart: it is not saved).
  bool adopt_named_sensor_lag = true;
  /// The observer: the disturbance-state filter (true), the standard one (false), or (unset)
  /// the disturbance-state filter where its frame-path heat can stand for every change on the
  /// cooling path (BoundaryOnlyThrough), else the standard one.
  std::optional<bool> disturbance_states;
  WindingResistanceReadingConfig winding;  ///< fuse, model_sd_K (stale_after_s from `alarms`)
  /// The drive's q-axis voltage as a reading (the observers that take it: the disturbance-state
  /// filter), and the priors of this pump's R0 and psi0 against the motor's nameplate.
  VoltageReadingConfig voltage;
  double r0_sd_rel = 0.03;
  double psi0_sd_rel = 0.02;
  /// The winding from resistance is published from the voltage reading while R0 is known to
  /// this (its sd, as a winding temperature, K): after a cold start or a saved calibration.
  double max_calibration_sd_K = 3.0;
  /// A start with the pump at rest (below a tenth of rated speed) and its frame within this of
  /// the ambient is a cold start: every node at the frame's temperature within cold_start_sd_K.
  double cold_start_band_K = 3.0;
  double cold_start_sd_K = 2.0;
  /// A frame warmer than the ambient by more than this at a cold start is still cooling from a
  /// run: the nodes that cool slowest (a rotor in vacuum) are warmer than it by the model's
  /// decay at rest (RestDecayShape), and each node's prior spans from the frame's temperature
  /// (a pump that never ran, the two sensors disagreeing) to that. Within it, the two sensors'
  /// disagreement alone (the frame sensor's offset prior, 2 sd).
  double cold_start_warm_frame_K = 1.0;
  MagnetFluxReadingConfig magnet;  ///< magnet_node, min_sd_K, max_winding_gain (the rest set here)
  /// The node of the rotor-heat state and of the rotor-loss hypothesis; empty: the magnet's
  /// node, else "rotor" where the model has it.
  std::string rotor_node;
  AlarmConfig alarms;
  /// Levels per model node name, kSensorLevelsNode and kWindingResistanceNode.
  std::map<std::string, TemperatureLimits> levels;
  double period_s = 1.0;  ///< the thermal period (the steps' nominal length)
  /// Tuning of the two observers beyond what the pump sets (nodes, lag, readings): the
  /// defaults are what the daemon ships; benchmarks and tests vary them.
  VirtualSensorConfig standard;
  DisturbanceSensorConfig disturbance;
  MismatchDetectorConfig mismatch;
  /// The magnet reading also enters the mismatch test's naming fit (a second channel).
  bool mismatch_magnet = true;
  /// The inside-heat bound (InsideHeatBound, estimators/alarm_bounds.hpp) with the
  /// disturbance-state filter; off only to measure what it does.
  bool inside_heat_bound = true;
  /// The magnet law check (MagnetLawCheck): with the voltage fused, a rotor heat below
  /// -magnet_law_heat_W and below -magnet_law_sds of its sd (or beyond the disturbance filter's
  /// found-heat limit, where its sd is held wide by design) for magnet_law_after_s running says
  /// the magnet from the flux reads the rotor colder than the model's rotor losses make it (a
  /// magnet law steeper than the magnet's, or rotor losses the model has too high).
  double magnet_law_heat_W = 2.0;
  double magnet_law_sds = 2.0;
  double magnet_law_after_s = 300.0;
};

/// The identification the gateway publishes as Rs, psi_f and their status (CAN GW_IDENT, LCM,
/// the CSV's resistance_ohm, flux_Wb, ident_status). With the drive's voltage as a reading it is
/// the pump filter's: Rs = R0 (1 + dr)(1 + alpha (Tw - T0)) (Han 2019 eq. 2) at its winding and
/// psi_f = psi0 (1 + dpsi)(1 + beta (Tm - T0)) at its magnet, with sds to first order;
/// `tracking` while the winding from resistance is published, `converging` while R0 is not yet
/// known to max_calibration_sd_K (a start with the current constant cannot tell R0 from the
/// inverter's offset: a load change pins it). Without the voltage reading, while the voltage is
/// stale or the frame sensor has failed, and before the first step after a restart: the
/// identifier's (Han 2019's DFRLS) status, and no values (they are not within their sds of the
/// truth, even while it tracks). NaN: not identified.
struct PublishedIdentification {
  double resistance_ohm = std::numeric_limits<double>::quiet_NaN();
  double resistance_sd_ohm = std::numeric_limits<double>::quiet_NaN();
  double flux_Wb = std::numeric_limits<double>::quiet_NaN();
  double flux_sd_Wb = std::numeric_limits<double>::quiet_NaN();
  ResistanceStatus status = ResistanceStatus::kInitialising;
  /// The flux's own: tracked while the resistance is held or cannot be identified.
  ResistanceStatus flux_status = ResistanceStatus::kInitialising;
};

/// Everything published about one pump at one moment (fields declared for CAN, LCM, CSV and
/// state in daemon/published_fields.cpp).
/// How the estimate last started: at rest at the ambient (its calibration learnt in the run-up),
/// warm, or from a saved state.
enum class EstimateStart : std::uint8_t { kNone, kCold, kWarm, kRestored };

struct PumpEstimate {
  std::int64_t time_us = 0;
  /// False until the first step and after a filter reset: publish "not available".
  bool initialised = false;
  std::vector<double> node_degC;         ///< per state (model order); NaN before init
  std::vector<double> node_sd_K;         ///< published: widened to the bounds the levels act on
  std::vector<double> node_filter_sd_K;  ///< the observer's own
  /// The filter has converged since its (re)start, judged as the alarms judge it
  /// (ThermalObserver::SettlingSd_K below 5 K).
  bool filter_converged = false;
  ResistanceEstimate resistance;           ///< the identifier's at the period's end
  PublishedIdentification identification;  ///< what is published as Rs and psi_f
  /// The winding temperature the resistance reflects (the model's winding weights) and its sd:
  /// with the drive's voltage as a reading, the observer's (fresh voltage, R0 known to
  /// max_calibration_sd_K). NaN otherwise (the identifier's own is identifier_winding_degC).
  double winding_resistance_degC = std::numeric_limits<double>::quiet_NaN();
  double winding_resistance_sd_K = std::numeric_limits<double>::quiet_NaN();
  /// The magnet's temperature from its flux and its sd: with the voltage reading, the
  /// observer's magnet node (fresh voltage); else from the identifier's back-EMF line at the
  /// filter's winding estimate. NaN otherwise.
  double magnet_flux_degC = std::numeric_limits<double>::quiet_NaN();
  double magnet_flux_sd_K = std::numeric_limits<double>::quiet_NaN();
  /// The resistance identifier's own winding temperature (Han 2019 eq. 3; NaN unless it tracks,
  /// fresh): the paper's method, beside the fused one.
  double identifier_winding_degC = std::numeric_limits<double>::quiet_NaN();
  /// This pump's R0 and psi0 against the nameplate and the voltage offset, as the observer
  /// estimates them (NaN without the voltage reading).
  ThermalObserver::Calibration calibration;
  double frame_measured_degC = std::numeric_limits<double>::quiet_NaN();  ///< as fused
  SensorFault sensor_fault = SensorFault::kNone;
  /// The frame sensor's offset as the filter estimates it, K (NaN without it), the steps of it
  /// found, the last one and their sum since the filter started, K.
  double sensor_offset_K = std::numeric_limits<double>::quiet_NaN();
  std::uint64_t sensor_steps = 0;
  double last_sensor_step_K = std::numeric_limits<double>::quiet_NaN();
  double stepped_offset_K = std::numeric_limits<double>::quiet_NaN();
  double ambient_degC = std::numeric_limits<double>::quiet_NaN();
  double speed_rpm = std::numeric_limits<double>::quiet_NaN();
  double innovation_K = std::numeric_limits<double>::quiet_NaN();  ///< the frame row's
  double nis = std::numeric_limits<double>::quiet_NaN();           ///< the frame row's
  ReadingStatus frame_reading, winding_reading, magnet_reading, voltage_reading;
  AlarmState alarm;
  /// For an estimated over-temperature, the rule that set the value its level acted on when
  /// the alarm was raised (the band x + k sd, or the bound that raised the value: blind,
  /// silence, inside heat, a lagging sensor).
  AlarmRule alarm_rule = AlarmRule::kBand;
  int time_to_trip_node = -1;          ///< state index the forecast is about (-1: none)
  std::uint64_t alarm_changes = 0;     ///< increments whenever `alarm` changes
  MismatchFinding mismatch;            ///< is the model right? (docs/daemon.md)
  std::uint64_t mismatch_changes = 0;  ///< increments when its state or effect changes
  /// The frame sensor's lag the filter reads it with, s: the configured one, or the one the
  /// diagnosis named and the filter took (adopt_named_sensor_lag); sensor_lag_changes counts
  /// those.
  double frame_sensor_lag_s = 0.0;
  std::uint64_t sensor_lag_changes = 0;
  /// The lag taken came from a saved state (the run before the restart named it).
  bool frame_sensor_lag_restored = false;
  /// At a restore where the configuration states the losses further off the model's than the
  /// saved state did (model_losses_sd_rel): the sd it was saved with and the one the loss scale
  /// was widened to; NaN otherwise.
  double losses_sd_widened_from = std::numeric_limits<double>::quiet_NaN();
  double losses_sd_widened_to = std::numeric_limits<double>::quiet_NaN();
  EstimateStart start = EstimateStart::kNone;
  /// R0 and psi0 (or, without the voltage rows, the back-EMF line's bias) were learnt at a cold
  /// start, in this run or the restored one's (docs/virtual-sensor.md).
  bool calibrated_at_cold_start = false;
  /// At a start at rest with the frame still warm from a run (cold_start_warm_frame_K), the most
  /// any node may be warmer than the frame, K (0: none): a cold start's nodes start within that
  /// span, a warm start's (without the voltage rows) have their sd widened by it.
  double start_span_K = 0.0;
  std::uint64_t starts = 0;  ///< increments at every start, restart after a reset, or restore
  /// Increments when the fused identification turns from `converging` to `tracking` (R0 became
  /// known to max_calibration_sd_K: a load change pinned it, and the winding from resistance is
  /// published from then on) or back (R0's sd, as a winding temperature, grew past it again).
  std::uint64_t r0_changes = 0;
  /// The heat inside the rotor the filter finds beyond the model's, W, and its sd (NaN without
  /// the disturbance states).
  double rotor_heat_W = std::numeric_limits<double>::quiet_NaN();
  double rotor_heat_sd_W = std::numeric_limits<double>::quiet_NaN();
  /// With the voltage fused, the filter has needed a negative rotor heat beyond its sd for
  /// magnet_law_after_s: the magnet from the flux reads the rotor colder than the model lets it
  /// be, as a motor file's magnet law steeper than the magnet's does (NdFeB's -0.1 %/K on a
  /// SmCo magnet). From then on the filter gives that law up (ThermalObserver::FreeMagnetLaw)
  /// and no magnet from the flux is published; a state saved after it restores it set while the
  /// motor file states the same law.
  bool magnet_law_suspect = false;
  /// Increments when the check sets magnet_law_suspect (not when a restore does: the journal
  /// said it in the run that found it).
  std::uint64_t magnet_law_changes = 0;
};

/// Counters of what the estimator refused (never silent).
struct PumpEstimatorCounters {
  std::uint64_t steps = 0;              ///< thermal steps run
  std::uint64_t refused_steps = 0;      ///< inputs or a period the model cannot take
  std::uint64_t rejected_readings = 0;  ///< readings left out as invalid
  std::uint64_t mismatch_refused = 0;   ///< steps the mismatch test refused
  std::uint64_t filter_resets = 0;  ///< the estimate left [kMinEstimate_degC, kMaxEstimate_degC]
};

/// The estimator's saved state (the daemon writes it; docs/daemon.md "State").
struct PumpEstimatorState {
  std::string model_name;
  std::int64_t time_us = 0;
  Eigen::VectorXd x_degC;  ///< the nodes
  Eigen::MatrixXd s_K2;    ///< their covariance
  ThermalInputs inputs;    ///< the last inputs (held while the daemon is down)
  /// Latched trips: the alarm node's name (a model node, kWindingResistanceNode or
  /// kSensorLevelsNode) and the value that raised it, degC.
  struct LatchedTrip {
    std::string node;
    double value_degC = std::numeric_limits<double>::quiet_NaN();
  };
  std::vector<LatchedTrip> latched_trips;
  /// The frame sensor's offset, its sd and the sum of its steps, K (NaN: not saved).
  double sensor_offset_K = std::numeric_limits<double>::quiet_NaN();
  double sensor_offset_sd_K = std::numeric_limits<double>::quiet_NaN();
  double stepped_offset_K = std::numeric_limits<double>::quiet_NaN();
  /// The observer's whole state and covariance when it holds more than the nodes (the
  /// disturbance-state filter); empty: not saved (an older file, another configuration).
  Eigen::VectorXd observer_x;
  Eigen::MatrixXd observer_s;
  /// Whether the filter's calibration (R0, psi0) was learnt from a cold start (with the whole
  /// state only).
  bool cold_started = false;
  /// The magnet law the check gave up (MagnetLawCheck), per K (NaN: none): with it, the saved
  /// state's flux no longer follows the magnet. Restored only while the motor file still states
  /// that law; once it states another, the saved calibration is not taken.
  double magnet_law_given_up_per_K = std::numeric_limits<double>::quiet_NaN();
  /// The frame sensor's lag the filter took from the diagnosis, s, and the lag configured when
  /// it did (NaN: none taken). Restored with the whole state while that lag is still the one
  /// configured: a configuration changed since (to the lag named, or another) is the operator's.
  double taken_sensor_lag_s = std::numeric_limits<double>::quiet_NaN();
  double taken_over_configured_lag_s = std::numeric_limits<double>::quiet_NaN();
  /// How far the losses were stated to be off the model's when it was saved (the loss scale's
  /// start sd, DisturbanceSensorConfig::loss_scale_initial_sd; NaN: an older file, which had
  /// 0.1). A configuration that states more since widens the restored loss scale to it.
  double losses_sd_rel = std::numeric_limits<double>::quiet_NaN();
};

class PumpEstimator {
 public:
  /// Keeps references to `motor` and `model`, which must outlive it. Throws
  /// std::invalid_argument naming the problem (an unknown node, a level for a node the model
  /// lacks, a motor without the magnet law a magnet node needs, bad settings).
  PumpEstimator(const PumpEstimatorConfig& config, const MotorDescription& motor,
                const ThermalModel& model);
  PumpEstimator(const PumpEstimator&) = delete;
  PumpEstimator& operator=(const PumpEstimator&) = delete;

  /// A frame sensor reading received at `t_us` (NaN: its "not available").
  void OnFrameReading(std::int64_t t_us, double degC) {
    frame_.OnReading(static_cast<double>(t_us) * 1e-6, degC);
  }
  /// One thermal period. Returns whether the alarm state changed.
  bool Step(const PumpPeriod& period);
  /// The alarms alone at `t_us` for a pump never heard from, its inputs `silence_s` old: after
  /// stale_after_s it raises stale telemetry like a pump that fell silent. Returns whether the
  /// alarm state changed.
  bool StepNeverHeard(std::int64_t t_us, double silence_s);
  /// Clears latched trips. Returns true if one was latched.
  bool ClearTrips() { return alarms_.Clear(); }
  /// Clears the latched trip of one alarm node (LatchIndex()). Returns true if it was latched.
  bool ClearTrip(int node) { return alarms_.Clear(node); }
  /// The alarm monitor's index of alarm node `name` (a model node, kSensorLevelsNode,
  /// kWindingResistanceNode, kStateLostNode), or nullopt for a name this pump lacks.
  std::optional<int> LatchIndex(const std::string& name) const;
  /// Latches the trip "safety state lost" at `t_us` (at start, when the latched trips and clear
  /// counters saved could not be read); published at once.
  void LatchStateLost(std::int64_t t_us);
  /// Evidence of a second sender on this pump's CAN IDs at `t_us`: a warning, published at once.
  void RaiseSecondSender(std::int64_t t_us);
  /// The identifier's estimate published between steps (after a restart, before the first).
  void NoteIdentifier(const ResistanceEstimate& resistance);

  const PumpEstimate& estimate() const { return estimate_; }
  const PumpEstimatorCounters& counters() const { return counters_; }
  /// The observer the estimate is published from (whichever it is).
  const ThermalObserver& observer() const { return *observer_; }
  /// The inputs of the last thermal step.
  const ThermalInputs& last_inputs() const { return last_inputs_; }
  /// Whether it is the disturbance-state filter (the configuration's choice, resolved).
  bool disturbance_states() const { return disturbance_states_; }
  const ThermalModel& model() const { return model_; }
  const PumpEstimatorConfig& config() const { return config_; }
  /// Every active alarm condition, most severe first, into `out` (no allocation once `out`
  /// has held as many).
  void ActiveConditions(std::vector<AlarmCondition>& out) const { alarms_.ActiveConditions(out); }

  PumpEstimatorState Save() const;
  /// Continues from `state` saved at state.time_us, aged to `now_us` by the observer with the
  /// last inputs held (a motor that kept running stays hot; the disturbances it had found go
  /// on); latched trips latch again. Returns false (nothing changes) when the state does not
  /// fit this pump or is damaged.
  bool Restore(const PumpEstimatorState& state, std::int64_t now_us);
  /// Latches again only the trips of `state` (when its filter state cannot be used). Returns
  /// false (nothing changes) when a trip names an alarm node this pump lacks or has a
  /// non-finite value.
  bool RestoreLatchedTrips(const PumpEstimatorState& state, std::int64_t now_us);

 private:
  void CheckLevels() const;
  AlarmMonitor MakeAlarms() const;
  /// Starts the observer and the mismatch test when they have not (false: nothing to start
  /// from yet).
  bool StartIfNeeded(const PumpPeriod& period);
  /// Takes a sensor lag the diagnosis named into the filter and the diagnosis.
  void AdoptNamedSensorLag();
  /// Reads the frame sensor with `lag_s` from now, in the filter and the mismatch test (a filter
  /// without a lag state: nothing); `restored`: the lag came from a saved state.
  void TakeSensorLag(double lag_s, bool restored);
  /// The filter's psi0 is known more closely than the back-EMF line's nameplate anchor.
  bool FluxKnownBetterThanTheLine() const;
  /// Whether the back-EMF line's magnet is published without the voltage rows: its bias was
  /// learnt at a cold start, or the filter takes the line as unbiased.
  bool LineCalibrated() const;
  /// The least sd of the magnet's node while psi0 is not learnt (0 once it is, or without the
  /// voltage reading).
  double UncalibratedMagnetSd_K() const;
  void PrepareReadings(const PumpPeriod& period);
  /// Half of how much warmer than the frame each node may be, the frame `frame_excess_K` above
  /// the ambient at rest after a run (the model's decay at rest); empty: none (the frame within
  /// cold_start_warm_frame_K, or a model without that decay).
  Eigen::VectorXd HalfRunSpan_K(double frame_excess_K) const;
  /// A cold start from the frame's reading and its excess over the ambient.
  void StartCold(double frame_degC, double frame_excess_K);
  /// At a warm start at rest, the slower nodes' sd widened by the model's decay at rest.
  void WidenForARun(double frame_excess_K);
  void HoldMagnet();
  void RecordReadings(const ObserverReport& report);
  /// The mismatch test on this step; counts a changed verdict.
  void CheckModel(const PumpPeriod& period, double measured_degC);
  /// Whether the estimate left every physical range (the filter is then reset and counted).
  bool Diverged();
  void PublishNodes(bool diverged);
  void PublishReadings(const PumpPeriod& period, const ObserverReport& report);
  /// The winding from resistance and the magnet from flux as the voltage reading gives them.
  void PublishFromVoltage(const PumpPeriod& period);
  void PublishFusedTemperatures(double winding_degC, double winding_var_K2);
  void PublishFusedIdentification(double winding_degC, double winding_var_K2);
  void PublishHeldMagnet();
  /// Runs the magnet law check over a period of `dt_s` (PumpEstimatorConfig::magnet_law_*).
  void MagnetLawCheck(double dt_s);
  /// The bounds the levels act on, the alarm values and the published sds.
  void StepBounds(const PumpPeriod& period, bool diverged);
  /// The observer's frame-path heat, W (NaN: not the disturbance-state filter).
  double FramePathHeat_W();
  /// The forecast and the alarms; counts a change worth publishing.
  void StepAlarms(const PumpPeriod& period, bool diverged);
  /// A period with telemetry but no temperature to start the filter from: the alarms alone.
  void StepWithoutEstimate(const PumpPeriod& period);
  /// The alarms alone with `ai` at `t_us` (no estimate); true if the alarm state changed.
  bool RunAlarmsOnly(std::int64_t t_us, const AlarmInputs& ai);
  bool TripIndices(const PumpEstimatorState& state,
                   std::vector<AlarmMonitor::LatchedTrip>& out) const;
  void Relatch(const std::vector<AlarmMonitor::LatchedTrip>& trips, std::int64_t now_us);
  /// The observer from `state`: its whole state when `whole` (saved and fitting), aged over
  /// `gap_s`; else (or when that ages out of range) from the restored nodes `x`, `s` with the
  /// saved sensor offset. True when the whole state was kept.
  bool RestoreObserver(const PumpEstimatorState& state, bool whole, double gap_s,
                       const Eigen::VectorXd& x, const Eigen::MatrixXd& s);

  PumpEstimatorConfig config_;
  const MotorDescription& motor_;
  const ThermalModel& model_;
  bool disturbance_states_ = false;
  std::unique_ptr<ThermalObserver> observer_;
  FrameReading frame_;
  MagnetFluxReading magnet_;
  WindingResistanceReading winding_;
  VoltageReading voltage_;
  int voltage_magnet_state_ = -1;           ///< the node the flux follows (-1: no voltage reading)
  Eigen::VectorXd voltage_magnet_weights_;  ///< that node as weights over the nodes
  /// The magnet from the period's voltage at the held calibration, while the frame sensor has
  /// failed (invalid otherwise): fused and published instead of the identifier's line.
  VoltageMagnet held_magnet_;
  std::int64_t voltage_fused_us_ = -1;  ///< the last step that fused the voltage
  /// The last of `converging` and `tracking` the fused identification had (r0_changes).
  ResistanceStatus fused_status_ = ResistanceStatus::kInitialising;
  double magnet_colder_s_ = 0.0;  ///< how long the magnet law check has run negative
  MismatchDetector mismatch_;
  AlarmMonitor alarms_;
  AlarmValues values_;
  TripForecast forecast_;
  std::vector<double> trip_degC_;  ///< per node, for the forecast (infinity: no trip level)
  int measured_state_ = -1;
  /// Per node, its excess over the ambient per kelvin of the frame's along the model's slowest
  /// decay at rest (empty: the model has none to give).
  Eigen::VectorXd rest_decay_shape_;
  bool initialised_ = false;
  ThermalInputs last_inputs_;  ///< the last step's (saved: held while the daemon is down)
  ThermalReadings readings_;
  Eigen::VectorXd x_degC_, sd_K_;     ///< the observer's nodes and sds this step
  ThermalLinearModel found_heat_;     ///< the observer's found heat (f only, n)
  std::vector<double> alarm_values_;  ///< per alarm node (n states + the winding)
  std::vector<double> alarm_sd_;
  std::vector<AlarmRule> alarm_rules_;  ///< per alarm node, the rule that set its value
  PumpEstimate estimate_;
  PumpEstimatorCounters counters_;
};

/// Whether every temperature of `x_degC` lies in [kMinEstimate_degC, kMaxEstimate_degC] (NaN
/// values are for the caller's finiteness test).
bool InEstimateRange(const Eigen::Ref<const Eigen::VectorXd>& x_degC);

/// Why alarm levels cannot be set for `node` of `model` (empty: they can): a model node with
/// heat capacity, kSensorLevelsNode or kWindingResistanceNode.
std::string UnknownLevelNode(const ThermalModel& model, const std::string& node);

}  // namespace pumptherm::estimators
