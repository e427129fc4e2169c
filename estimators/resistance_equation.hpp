#pragma once
/// Equation-based identification from two operating points (Han, Xiong, Mao, Vacuum 169 (2019)
/// 108935, eqs. 7-8): one point during the acceleration (iq_m at w_r1), one at steady speed
/// (iq_0 at w_r2), with id = 0 (or uq already corrected by -Ls w_r id):
///
///     uq1 = Rs iq_m + w_r1 psi_f,   uq2 = Rs iq_0 + w_r2 psi_f                  (eq. 7)
///     Rs    = (uq2 w_r1 - uq1 w_r2) / (iq_0 w_r1 - iq_m w_r2)
///     psi_f = (uq2 - Rs iq_0) / w_r2                                            (eq. 8)

namespace pumptherm::estimators {

/// One steady operating point of the q-axis voltage equation.
struct QAxisPoint {
  double iq_A = 0.0;           ///< q-axis current
  double uq_V = 0.0;           ///< q-axis voltage, minus Ls w_r id when id is not zero
  double w_r_rad_per_s = 0.0;  ///< electrical angular speed
};

/// Result of eq. 8; `valid` is false when the two points are (nearly) linearly dependent
/// (|iq_0 w_r1 - iq_m w_r2| below 1e-12 of its terms) or w_r2 is zero, and the values are NaN.
struct TwoPointResult {
  double resistance_ohm = 0.0;
  double flux_Wb = 0.0;
  bool valid = false;
};

/// Han 2019 eq. 8 from the acceleration point `p1` and the steady point `p2`.
TwoPointResult IdentifyTwoPoint(const QAxisPoint& p1, const QAxisPoint& p2) noexcept;

}  // namespace pumptherm::estimators
