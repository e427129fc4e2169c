#pragma once
/// Overtemperature and health alarms of one pump: levels with hysteresis and a hold
/// time on estimated and measured temperatures, rate of rise, stale telemetry, implausible
/// sensor (out of range, stuck, disagreeing with the model), estimator not converged, and the
/// time-to-trip forecast. Pure logic: time enters as an argument, nothing is logged.
///
/// Semantics (docs/daemon.md, "The pipeline, per pump" and "Alarm rule"):
/// - A condition must hold continuously for `hold_s` before its alarm asserts (a single noisy
///   sample never trips). The hold counts the time spent in a level's band or above: a value
///   moving between the warning and the trip band keeps the warning's hold running. A warning
///   clears when the value falls below its level minus `hysteresis_K` (after the same hold); a
///   trip latches until Clear() is called and its condition is gone.
/// - NaN inputs mean "not measured yet": they neither assert nor clear anything, and a pending
///   hold keeps its start (a lost sample never restarts a pending trip).
/// - Stale telemetry and sensor faults follow `hold_s` like every other condition.
/// - The published state is the most severe active alarm (trip over warning; among equals the
///   one raised first), plus a bit set of every active reason.

#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

namespace pumptherm::estimators {

enum class AlarmLevel : std::uint8_t { kNone = 0, kWarning = 1, kTrip = 2 };

/// Reason codes as published on CAN (pumptherm.dbc AlarmReason) and LCM (alarm_condition_t
/// REASON_*): the values are part of the interface; do not renumber.
enum class AlarmReason : std::uint8_t {
  kNone = 0,
  kEstimatedOverTemperature = 1,  ///< a node's estimate above its warning or trip level
  kMeasuredOverTemperature = 2,   ///< the measured sensor above its level
  kRateOfRise = 3,                ///< a node warming faster than allowed
  kStaleTelemetry = 4,            ///< no telemetry for longer than allowed
  kImplausibleSensor = 5,         ///< sensor out of range, stuck, or disagreeing with the model
  kEstimatorNotConverged = 6,     ///< an estimator has not converged (or lost convergence)
  kForecast = 7,                  ///< time to trip at the present load below the horizon
  kSensorFault = 8,               ///< the measured sensor failed (missing, stuck, out of range,
                                  ///< jumping), found without trusting its readings; it is
                                  ///< left out of the filter meanwhile
  kSafetyStateLost = 9,  ///< the saved latched trips and clear counters were damaged or missing
                         ///< at start: latched until an operator clears it
  kSecondSender = 10,    ///< frames of this pump's IDs that its drive (or the gateway) did not
                         ///< send: its own IDs from elsewhere, too fast, a broken rolling counter
};
inline constexpr std::size_t kAlarmReasonCount = 11;

/// What is wrong with the measured sensor, judged from evidence that does not rest on its
/// reading being right (its frame's age, its noise, physics' bounds on its value and steps).
enum class SensorFault : std::uint8_t {
  kNone = 0,
  kMissing = 1,     ///< no reading for longer than `stale_after_s` (its frame stopped)
  kStuck = 2,       ///< the reading has not moved by one bit for `flat_after_s` (no noise left)
  kOutOfRange = 3,  ///< outside [sensor_min_degC, sensor_max_degC]
  kJumping = 4,     ///< a step between readings larger than `max_step_K` (faster than physics)
};
const char* SensorFaultName(SensorFault fault);

/// Name of a reason code ("estimated_over_temperature", ...), for logs.
const char* AlarmReasonName(AlarmReason reason);
const char* AlarmLevelName(AlarmLevel level);

/// Levels of one temperature (a node estimate or a measured sensor), degC.
struct TemperatureLimits {
  double warning_degC = std::numeric_limits<double>::infinity();
  double trip_degC = std::numeric_limits<double>::infinity();
};

struct AlarmConfig {
  double hysteresis_K = 2.0;  ///< a warning clears below level - hysteresis
  double hold_s = 2.0;        ///< a condition must persist this long to (de)assert
  /// Rate of rise: warning above this many K per minute, measured over `rate_window_s`.
  double max_rise_K_per_min = std::numeric_limits<double>::infinity();
  double rate_window_s = 60.0;
  double stale_after_s = 2.0;      ///< telemetry older than this: stale (warning)
  double sensor_min_degC = -40.0;  ///< plausible range of the measured sensor
  double sensor_max_degC = 250.0;
  /// Stuck: the sensor's value unchanged for this long while the model's estimate of the same
  /// node moved by more than `stuck_model_move_K`.
  double stuck_after_s = 120.0;
  double stuck_model_move_K = 2.0;
  /// Sensor fault "stuck": the raw reading bit-for-bit unchanged this long (a live RTD's noise
  /// moves its last digit; 0 = off). Valid for a sensor whose noise is not far below its
  /// resolution.
  double flat_after_s = 30.0;
  /// Sensor fault "jumping": one reading differing from the previous one (at most
  /// `stale_after_s` before it) by more than this (K); the sensor stays out for
  /// `jump_recover_s` after the last such step.
  double max_step_K = 5.0;
  double jump_recover_s = 30.0;
  /// Disagreement: normalised innovation squared above this (chi-square, 1 dof: 10.83 is the
  /// 0.1 % tail) for `disagree_hold_s`.
  double nis_limit = 10.83;
  double disagree_hold_s = 30.0;
  /// Offset: the reading stepped away from the frame by more than this in total, K (the
  /// disturbance-state filter takes a step of the reading faster than the frame can move as a
  /// step of the sensor's offset, DisturbanceThermalSensor::SteppedOffset_K): implausible
  /// sensor, "offset". A Class-A RTD is within 0.35 K at 100 degC (IEC 60751); 0 = off.
  double max_sensor_offset_K = 1.0;
  double not_converged_grace_s = 600.0;  ///< after start, "not converged" is not yet an alarm
  double forecast_horizon_s = 600.0;     ///< warn when time to trip drops below this
  /// Off-delay of the forecast warning: it clears only after the forecast has stayed beyond the
  /// horizon this long (a load alternating faster than this does not make it chatter; ISA-18.2
  /// off-delay).
  double forecast_clear_s = 60.0;
  /// Off-delay of the sensor-fault alarm: a sensor back from a fault clears it only after
  /// reading well this long (one status frame through a lossy link is no recovery). The filter
  /// takes the sensor back at once; this is the alarm only.
  double sensor_fault_clear_s = 30.0;
  /// A second-sender warning clears after this long without new evidence of one (s).
  double second_sender_clear_s = 600.0;
  /// During a telemetry silence the levels act on the worst case of the motor's largest current
  /// as it was this long ago (s; AlarmValues): a trip comes this long (plus the hold) after the
  /// earliest moment any load the drive allows could have crossed the level, never later, and
  /// a shorter silence trips nothing. 0: on the worst case itself.
  double silence_delay_s = 25.0;
  int sensor_node = -1;  ///< node index the measured sensor sits on (reports)
  /// Levels act on an upper bound of each estimate, mean + k sd (docs/daemon.md, "Alarm rule"):
  /// k for the trip and for the warning level.
  double trip_sd_factor = 2.0;
  double warning_sd_factor = 0.0;
};

/// What the pipeline knows at one alarm evaluation.
struct AlarmInputs {
  /// Temperatures watched for over-temperature and rate of rise, one per configured node (NaN =
  /// not known yet). Order and count as in AlarmMonitor's constructor.
  const double* node_degC = nullptr;
  /// Standard deviations of those temperatures, K (nullptr or NaN entries: taken as 0).
  const double* node_sd_K = nullptr;
  double sensor_degC = std::numeric_limits<double>::quiet_NaN();        ///< the measured node
  double sensor_model_degC = std::numeric_limits<double>::quiet_NaN();  ///< model estimate there
  double sensor_nis = std::numeric_limits<double>::quiet_NaN();         ///< last innovation test
  /// How far the sensor's reading stepped away from the frame, K (NaN: not estimated).
  double sensor_offset_K = std::numeric_limits<double>::quiet_NaN();
  double telemetry_age_s = 0.0;                   ///< time since the last telemetry frame
  SensorFault sensor_fault = SensorFault::kNone;  ///< from SensorHealth
  double sensor_raw_degC =
      std::numeric_limits<double>::quiet_NaN();  ///< last reading, even if faulty
  bool estimators_converged = true;
  double time_to_trip_s = std::numeric_limits<double>::infinity();  ///< from the forecast
  int time_to_trip_node = -1;
};

/// The published alarm state of one pump.
struct AlarmState {
  AlarmLevel level = AlarmLevel::kNone;
  AlarmReason reason = AlarmReason::kNone;
  int node = -1;  ///< node index (-1: the pump as a whole)
  double value =
      std::numeric_limits<double>::quiet_NaN();  ///< value that raised it (unit per reason)
  /// For an estimated over-temperature: the upper bound of the estimate, value + k sd, that
  /// crossed the level when it was raised (degC); NaN otherwise.
  double bound = std::numeric_limits<double>::quiet_NaN();
  std::uint16_t active_reasons = 0;  ///< bit (1 << reason) for every active alarm
  bool trip_latched = false;
  double time_to_trip_s = std::numeric_limits<double>::infinity();
  /// Field by field, a NaN value equal to a NaN value (nothing changed).
  bool operator==(const AlarmState& o) const {
    auto same = [](double a, double b) { return a == b || (std::isnan(a) && std::isnan(b)); };
    return level == o.level && reason == o.reason && node == o.node && same(value, o.value) &&
           same(bound, o.bound) && active_reasons == o.active_reasons &&
           trip_latched == o.trip_latched && same(time_to_trip_s, o.time_to_trip_s);
  }
};

/// One active alarm condition.
struct AlarmCondition {
  AlarmLevel level = AlarmLevel::kNone;
  AlarmReason reason = AlarmReason::kNone;
  const char* detail = "";  ///< e.g. "stuck" for an implausible sensor
  int node = -1;            ///< node index (-1: the pump as a whole)
  double value = std::numeric_limits<double>::quiet_NaN();      ///< value when it was raised
  double threshold = std::numeric_limits<double>::quiet_NaN();  ///< level it crossed (degC)
  double raised_at_s = 0.0;
  bool latched = false;
};

class AlarmMonitor {
 public:
  /// `limits[i]` applies to node i; the sensor's own over-temperature check uses
  /// `sensor_limits`. Throws std::invalid_argument for trip below warning or a negative
  /// hysteresis/hold.
  AlarmMonitor(AlarmConfig config, std::vector<TemperatureLimits> limits,
               TemperatureLimits sensor_limits);

  /// Evaluates at time `now_s` (monotonic, s). Returns the new state.
  const AlarmState& Step(double now_s, const AlarmInputs& in);

  /// Clears every latched trip. A trip re-asserts (after hold) if its condition is still there.
  /// Returns true when a trip was latched.
  bool Clear();
  /// Clears the latched trip of one node (`node` as in LatchedTrip: a node index, kSensorTrip or
  /// kStateLostTrip). Returns false (nothing changes) when that one was not latched.
  bool Clear(int node);

  /// Latches the trip "the safety state was lost" (reason kSafetyStateLost, the pump as a
  /// whole) at `now_s`; it stays until cleared.
  void LatchStateLost(double now_s);
  /// Evidence of a second sender on this pump's CAN IDs at `now_s`: a warning (reason
  /// kSecondSender) at once, which clears `second_sender_clear_s` after the last evidence.
  void RaiseSecondSender(double now_s);

  const AlarmState& state() const { return state_; }

  /// Latched trips, for saving across a restart: `node` is the node index (as in the
  /// constructor's `limits`) or kSensorTrip for the measured sensor's own level.
  static constexpr int kSensorTrip = -1;
  static constexpr int kStateLostTrip = -2;  ///< the safety state was lost (LatchStateLost)
  struct LatchedTrip {
    int node = kSensorTrip;
    double value = std::numeric_limits<double>::quiet_NaN();  ///< degC that raised it
  };
  /// Every latched trip (allocates; for saving state, not per step).
  std::vector<LatchedTrip> LatchedTrips() const;
  /// Re-latches a trip saved by LatchedTrips() (after a restart), raised at `now_s`: it stays
  /// latched until Clear(), as if it had never stopped. Returns false (nothing changes) for a
  /// node index out of range or a non-finite value.
  bool RestoreLatchedTrip(const LatchedTrip& trip, double now_s);

  /// Every active condition, most severe first (allocates; for publishing, not per frame).
  std::vector<AlarmCondition> ActiveConditions() const;
  /// The same into `out` (cleared first): no allocation once `out` has held as many.
  void ActiveConditions(std::vector<AlarmCondition>& out) const;

 private:
  /// One alarm condition with hold time and latch.
  struct Channel {
    AlarmLevel level = AlarmLevel::kNone;  ///< asserted level
    /// Start of the present run at or above warning ([1]) and at or above trip ([2]); NaN: not
    /// in that band now. [0] is unused.
    std::array<double, 3> band_since_s{std::numeric_limits<double>::quiet_NaN(),
                                       std::numeric_limits<double>::quiet_NaN(),
                                       std::numeric_limits<double>::quiet_NaN()};
    /// Start of the present run below the asserted level (NaN: not below it).
    double below_since_s = std::numeric_limits<double>::quiet_NaN();
    double value = std::numeric_limits<double>::quiet_NaN();
    double bound = std::numeric_limits<double>::quiet_NaN();  ///< see AlarmState::bound
    double raised_at_s = 0.0;
    bool latched = false;
  };
  /// Moves `ch` toward `want` (with hold), `want` computed by the caller with hysteresis.
  /// Moves `ch` towards `want`: up after `hold_s` in the band, down after `clear_hold_s` below it
  /// (negative: `hold_s`).
  void Update(Channel& ch, AlarmLevel want, double value, double now_s, double hold_s,
              double clear_hold_s = -1.0);
  void StepSensor(double now_s, const AlarmInputs& in);
  /// The level `ch` should be at: `warn_degC` against the warning level, `trip_degC` against the
  /// trip level (both the value itself for a measured sensor), with hysteresis.
  AlarmLevel OverLevel(const Channel& ch, double warn_degC, double trip_degC,
                       const TemperatureLimits& lim) const;
  /// The published state from the channels (most severe first). Does not allocate.
  void Compose(double time_to_trip_s);
  /// Calls f(channel, reason, detail, node, threshold) for every active channel, in a fixed order.
  template <typename F>
  void ForEachActive(F&& f) const;

  AlarmConfig config_;
  std::vector<TemperatureLimits> limits_;
  TemperatureLimits sensor_limits_;
  std::vector<Channel> over_;  // per node
  std::vector<Channel> rise_;  // per node
  Channel sensor_over_;
  Channel stale_;
  Channel sensor_fault_;
  SensorFault sensor_fault_kind_ = SensorFault::kNone;  // the fault that raised sensor_fault_
  Channel stuck_;
  Channel disagree_;
  Channel offset_;
  Channel converged_;
  Channel forecast_;
  Channel state_lost_;     // latched trip: the safety state was lost
  Channel second_sender_;  // warning: another sender on this pump's IDs
  double second_sender_last_s_ = std::numeric_limits<double>::quiet_NaN();
  // Rate of rise: per node, the value at the start of the current window.
  std::vector<double> window_start_degC_;
  std::vector<double> window_start_s_;
  std::vector<double> rise_K_per_min_;
  // Stuck detection.
  double stuck_value_ = std::numeric_limits<double>::quiet_NaN();
  double stuck_since_s_ = 0.0;
  double stuck_model_min_ = 0.0;
  double stuck_model_max_ = 0.0;
  double start_s_ = std::numeric_limits<double>::quiet_NaN();
  int forecast_node_ = -1;
  AlarmState state_;
};

/// Health of the measured sensor from evidence that does not rest on its readings being right:
/// the age of its last reading, whether its noise still moves the last digit, physical bounds
/// on its value and on a step between two readings. A sensor with a fault must not be fused.
/// Pure logic: times are arguments (s, monotonic).
class SensorHealth {
 public:
  /// Uses `stale_after_s`, `sensor_min_degC`, `sensor_max_degC`, `flat_after_s`, `max_step_K`,
  /// `jump_recover_s`.
  explicit SensorHealth(const AlarmConfig& config);
  /// One reading (degC) received at `t_s`; NaN (the sensor's "not available") is ignored, so
  /// its age grows.
  void OnReading(double t_s, double value_degC);
  /// The fault at `now_s` (kNone: usable), most fundamental first: missing, out of range,
  /// jumping, stuck.
  SensorFault Fault(double now_s) const;
  /// Last reading (NaN before any), whatever its health.
  double last_degC() const { return last_degC_; }
  /// Time of the last reading (NaN before any).
  double last_s() const { return last_s_; }
  /// Time the reading last changed (NaN before any): a stuck sensor's reading has been flat
  /// since then.
  double changed_s() const { return changed_s_; }

 private:
  AlarmConfig config_;
  double last_degC_ = std::numeric_limits<double>::quiet_NaN();
  double last_s_ = std::numeric_limits<double>::quiet_NaN();
  double changed_s_ = std::numeric_limits<double>::quiet_NaN();
  double jump_until_s_ = -std::numeric_limits<double>::infinity();
};

}  // namespace pumptherm::estimators
