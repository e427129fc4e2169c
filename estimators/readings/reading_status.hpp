#pragma once
/// What became of one reading in one step of the pump estimator (in the manner of PX4 EKF2's
/// aid-source status): the value offered, its sd, the innovation and its variance, the test
/// ratio, and whether it was fused or why not. Every reading fills one every step.

#include <cstdint>
#include <limits>

#include "estimators/thermal_observer.hpp"

namespace pumptherm::estimators {

/// Whether a reading was fused this step, or why not. Codes are published (CSV, LCM); do not
/// renumber.
enum class ReadingState : std::uint8_t {
  kFused = 0,          ///< it entered the update
  kAbsent = 1,         ///< no reading (none yet, not configured, or not mapped)
  kSensorFault = 2,    ///< the frame sensor has a fault (SensorHealth): left out
  kStale = 3,          ///< the source is older than allowed
  kNotIdentified = 4,  ///< the identifier's status does not give one (not tracking, no line)
  kTooSlow = 5,        ///< below the speed at which it carries information
  kGated = 6,          ///< above its gate (the winding's weight in the magnet row)
  kNotFused = 7,       ///< computed and published, but not fused by configuration or filter
  kRejected = 8,       ///< invalid (an sd that is not positive and finite), or the update failed
};
inline constexpr int kReadingStateCount = 9;

/// "fused", "absent", "sensor_fault", ...
const char* ReadingStateName(ReadingState state);

struct ReadingStatus {
  ReadingState state = ReadingState::kAbsent;
  double observation = std::numeric_limits<double>::quiet_NaN();  ///< the value offered
  double sd_K = std::numeric_limits<double>::quiet_NaN();         ///< its sd as offered
  double innovation_K = std::numeric_limits<double>::quiet_NaN();
  double innovation_var_K2 = std::numeric_limits<double>::quiet_NaN();
  /// innovation^2 / its variance (the row's NIS; chi-square with 1 dof when consistent).
  double test_ratio = std::numeric_limits<double>::quiet_NaN();

  /// A new step: not fused, nothing offered.
  void Reset(ReadingState why) { *this = ReadingStatus{why}; }
  /// The offered reading's row after the update: fused with its innovation, else `otherwise`.
  void Record(const ReadingRow& row, ReadingState otherwise) {
    if (!row.fused) {
      state = otherwise;
      return;
    }
    state = ReadingState::kFused;
    innovation_K = row.innovation_K;
    innovation_var_K2 = row.innovation_var_K2;
    test_ratio = row.innovation_var_K2 > 0.0 ? row.Nis() : std::numeric_limits<double>::quiet_NaN();
  }
  bool fused() const { return state == ReadingState::kFused; }
};

}  // namespace pumptherm::estimators
