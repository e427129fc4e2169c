#pragma once
/// The drive's q-axis voltage as a reading of the pump estimator: the period's mean uq, less its
/// known terms (w Ld id and the drive's stated voltage error), at the period's mean iq and
/// electrical speed, taken by the observer as an extended row of its winding and magnet nodes
/// and of this pump's R0 and psi0 (estimators/voltage_equation.hpp: Han et al. 2019 eq. 6 with
/// the copper law, eq. 2, and the magnet law).
///
/// Start: a period with enough paired samples (min_samples) and a finite speed. Gate: no load
/// change inside the period (the sd of iq over it beyond its noise at most max_iq_change_sd_A: the
/// steady-state equation does not hold through the current loop's transient), a current of at
/// least min_current_A, and the observer's own innovation gate. Stop: either lost.

#include <cmath>
#include <limits>

#include "estimators/motor.hpp"
#include "estimators/pump_period.hpp"
#include "estimators/readings/reading_status.hpp"
#include "estimators/thermal_model.hpp"
#include "estimators/thermal_observer.hpp"
#include "estimators/voltage_equation.hpp"

namespace pumptherm::estimators {

/// A reading of the magnet node from one period's voltage: z = Tm + winding_gain Tw, the
/// equation solved for the magnet at a given winding (the form of MagnetFluxReading's row).
struct VoltageMagnet {
  double z_degC = std::numeric_limits<double>::quiet_NaN();
  double sd_K = std::numeric_limits<double>::quiet_NaN();  ///< at a known winding
  double winding_gain = 0.0;
  bool Valid() const { return std::isfinite(z_degC) && std::isfinite(sd_K); }
  /// The magnet the reading gives at a winding temperature, degC.
  double MagnetAt_degC(double winding_degC) const { return z_degC - winding_gain * winding_degC; }
};

struct VoltageReadingConfig {
  bool fuse = true;                  ///< offered to an observer that takes it
  int min_samples = 10;              ///< paired samples a period needs
  double max_iq_change_sd_A = 0.05;  ///< a load change inside the period: left out
  /// A period whose mean |iq| is below this is left out. The equation's residual offset stands
  /// for the inverter's dead-time error, which follows the current's sign at its full size only
  /// above the drive's knee (tenths of an ampere) and is zero without current. A pump at rest
  /// (no current, no speed) would teach the offset that the error is zero, and the run-up's error
  /// along its current would then read as resistance; nor does a row without current carry the
  /// winding (R iq).
  double min_current_A = 0.5;
  double uq_noise_V = 0.01;  ///< rms noise of one sample of the reported uq
};

class VoltageReading {
 public:
  VoltageReading(const MotorDescription& motor, VoltageReadingConfig config);

  /// `frame_failed`: the frame sensor has a fault. The voltage is then left out as a row:
  /// without the frame's level, its innovations would move the frame-path heat and the
  /// calibration states instead of the winding and magnet (the frame drifted 10 K in 10 min on a
  /// stuck sensor). It stays available to CalibratedMagnet().
  void Prepare(const DriveAverages& drive, bool frame_failed);
  /// The magnet this period's voltage gives with the calibration held at `c` (the observer's R0,
  /// psi0, magnet-law and offset errors, learnt while it fused the voltage, not re-learnt here),
  /// at the winding `winding_degC`: for a period whose voltage is not a row because the frame
  /// sensor failed. The identifier's line would take the nameplate instead, 10 K off per
  /// percent of flux. Its sd: the voltage's noise and each calibration term moved by its sd.
  /// Invalid without a voltage, a magnet law or a calibration.
  VoltageMagnet CalibratedMagnet(const ThermalObserver::Calibration& c, double winding_degC) const;
  /// The reading into `readings` when it is fused (started, within its gate).
  void Offer(ThermalReadings& readings) const;
  /// The update's row for it; `taken`: the observer takes the voltage at all.
  void Record(const ReadingRow& row, bool taken);
  bool Offered() const { return offered_; }
  const ReadingStatus& status() const { return status_; }
  /// The magnet temperature this period's voltage gives at the observer's winding estimate and
  /// calibration (the equation solved for Tm), degC; NaN without a reading or a calibration.
  /// For the mismatch test's magnet channel: a reading of the magnet beside the filter.
  double MagnetAt_degC(const ThermalObserver& observer, const ThermalModel& model,
                       int magnet_state) const;

 private:
  const MotorDescription& motor_;
  VoltageLaw law_;
  VoltageReadingConfig config_;
  double uq_V_ = std::numeric_limits<double>::quiet_NaN();  ///< less the known terms
  double uq_sd_V_ = std::numeric_limits<double>::quiet_NaN();
  double iq_A_ = std::numeric_limits<double>::quiet_NaN();
  double w_rad_per_s_ = std::numeric_limits<double>::quiet_NaN();
  bool offered_ = false;
  bool frame_failed_ = false;
  ReadingStatus status_;
};

}  // namespace pumptherm::estimators
