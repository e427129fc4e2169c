#pragma once
/// The frame sensor as a reading of the pump estimator: its health judged from evidence that
/// does not trust the reading (SensorHealth: its age, its noise, physics' bounds on its value
/// and steps), and the reading offered to the thermal filter only while it has no fault.
///
/// Start: the first reading. Gate: none here (the filter's own step test takes a reading that
/// steps faster than the frame can move as a step of the sensor's offset). Stop: a fault, for as
/// long as SensorHealth finds it.

#include "estimators/alarms.hpp"
#include "estimators/readings/reading_status.hpp"
#include "estimators/thermal_observer.hpp"

namespace pumptherm::estimators {

class FrameReading {
 public:
  /// Uses the sensor-health settings of `config` (AlarmConfig: stale_after_s, flat_after_s, the
  /// plausible range, max_step_K, jump_recover_s).
  explicit FrameReading(const AlarmConfig& config) : health_(config) {}

  /// A reading received at `t_s` (NaN: the sensor's "not available"; its age then grows).
  void OnReading(double t_s, double degC) { health_.OnReading(t_s, degC); }
  /// This step's reading at `now_s`. `link_silent`: every frame of the pump has been silent too
  /// (then a missing sensor is the link's outage, stale telemetry, not a sensor fault).
  void Prepare(double now_s, bool link_silent);
  /// The reading into `readings` (NaN while it has a fault).
  void Offer(ThermalReadings& readings) const { readings.frame_degC = offered_degC_; }
  /// The update's row for it, after a step that was not refused.
  void Record(const ReadingRow& row);

  /// The sensor was left out for a jump beyond physics at the last recorded step and has no
  /// fault now: its first reading back may open a step of the offset.
  bool BackFromJump() const {
    return last_fault_ == SensorFault::kJumping && fault_ == SensorFault::kNone;
  }
  SensorFault fault() const { return fault_; }
  /// The fault the alarms see (a missing sensor on a silent link is none: stale telemetry).
  SensorFault alarm_fault() const { return alarm_fault_; }
  /// The last reading whatever its health (NaN while it is missing) and the one offered.
  double raw_degC() const { return raw_degC_; }
  double offered_degC() const { return offered_degC_; }
  const SensorHealth& health() const { return health_; }
  const ReadingStatus& status() const { return status_; }

 private:
  SensorHealth health_;
  SensorFault fault_ = SensorFault::kNone;
  SensorFault last_fault_ = SensorFault::kNone;  ///< at the last recorded step
  SensorFault alarm_fault_ = SensorFault::kNone;
  double raw_degC_ = std::numeric_limits<double>::quiet_NaN();
  double offered_degC_ = std::numeric_limits<double>::quiet_NaN();
  ReadingStatus status_;
};

}  // namespace pumptherm::estimators
