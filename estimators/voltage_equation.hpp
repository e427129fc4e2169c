#pragma once
/// The drive's q-axis voltage as a function of the winding and magnet temperatures: the
/// steady-state voltage equation of a surface PM motor (Han, Xiong, Mao 2019 eq. 6; eq. 5 with
/// diq/dt = 0) with the copper law (eq. 2) and the magnet law (estimators/magnet.hpp), each
/// scaled by a calibration error of its reference value, and a residual voltage offset:
///
///     uq - w Ld id - e(id, iq) = R0 (1 + dR) (1 + alpha (Tw - T0)) iq
///                                + w psi0 (1 + dpsi) (1 + beta (1 + dbeta) (Tm - T0m)) + u0
///
/// where e is the drive's known voltage error (dead time; MotorDescription::voltage_error_V),
/// dR and dpsi the relative errors of the nameplate's R0 and psi0 for this pump, dbeta that of
/// the magnet's temperature coefficient (a grade's datasheet value: tens of percent), and u0 what
/// is left of the voltage error (a constant offset with the sign of iq). It is linear in Tw and Tm
/// at a given (iq, w), which is what lets the thermal filter take uq as a measurement of its
/// winding and magnet nodes (an extended Kalman row: QAxisGradient at the estimate).
///
/// The d axis, ud = R id - w Lq iq (eq. 5), carries R id: nothing under id = 0 control, so the
/// daemon does not read it.
///
/// Pure: no I/O, no allocation.

#include "estimators/motor.hpp"

namespace pumptherm::estimators {

/// The copper and magnet laws' reference values of one motor.
struct VoltageLaw {
  double r0_ohm = 0.0;
  double t0_degC = 0.0;
  double alpha_per_K = 0.0;
  double psi0_Wb = 0.0;
  double magnet_t0_degC = 0.0;
  double beta_per_K = 0.0;  ///< the magnet's relative flux change per K (negative)
};

/// The laws of `motor` (the magnet's reference at the copper's T0 when it states no magnet law,
/// and beta 0: the flux then does not move with temperature).
VoltageLaw VoltageLawOf(const MotorDescription& motor) noexcept;

/// Where the equation is evaluated: the period's mean q current and electrical speed.
struct QAxisPoint {
  double iq_A = 0.0;
  double w_rad_per_s = 0.0;
};

/// The quantities the equation depends on.
struct QAxisState {
  double winding_degC = 0.0;
  double magnet_degC = 0.0;
  double dr = 0.0;     ///< relative error of R0
  double dpsi = 0.0;   ///< relative error of psi0
  double dbeta = 0.0;  ///< relative error of the magnet's temperature coefficient
  double u0_V = 0.0;   ///< residual voltage offset (with the sign of iq)
};

/// The equation's partial derivatives at a state.
struct QAxisGradient {
  double winding_V_per_K = 0.0;
  double magnet_V_per_K = 0.0;
  double dr_V = 0.0;
  double dpsi_V = 0.0;
  double dbeta_V = 0.0;
  double u0 = 0.0;  ///< sign(iq)
};

/// The right-hand side above, V.
double QAxisVoltage_V(const VoltageLaw& law, const QAxisPoint& p, const QAxisState& s) noexcept;
/// Its gradient at `s`.
QAxisGradient QAxisGradientAt(const VoltageLaw& law, const QAxisPoint& p,
                              const QAxisState& s) noexcept;
/// The known terms taken off the reported uq: w Ld id and the drive's voltage error e(id, iq),
/// V.
double QAxisKnownTerms_V(const MotorDescription& motor, double id_A, double iq_A,
                         double w_rad_per_s) noexcept;

}  // namespace pumptherm::estimators
