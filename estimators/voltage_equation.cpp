#include "estimators/voltage_equation.hpp"

#include <cmath>

namespace pumptherm::estimators {

VoltageLaw VoltageLawOf(const MotorDescription& motor) noexcept {
  VoltageLaw law;
  law.r0_ohm = motor.copper.r0_ohm;
  law.t0_degC = motor.copper.t0_degC;
  law.alpha_per_K = motor.copper.alpha_per_K;
  law.psi0_Wb = motor.flux_Wb;
  law.magnet_t0_degC = motor.magnet.Given() ? motor.magnet.t0_degC : motor.copper.t0_degC;
  law.beta_per_K = motor.magnet.Given() ? motor.magnet.flux_temperature_coefficient_per_K : 0.0;
  return law;
}

double QAxisVoltage_V(const VoltageLaw& law, const QAxisPoint& p, const QAxisState& s) noexcept {
  const double r =
      law.r0_ohm * (1.0 + s.dr) * (1.0 + law.alpha_per_K * (s.winding_degC - law.t0_degC));
  const double beta = law.beta_per_K * (1.0 + s.dbeta);
  const double psi =
      law.psi0_Wb * (1.0 + s.dpsi) * (1.0 + beta * (s.magnet_degC - law.magnet_t0_degC));
  const double sign = p.iq_A > 0.0 ? 1.0 : p.iq_A < 0.0 ? -1.0 : 0.0;
  return r * p.iq_A + p.w_rad_per_s * psi + sign * s.u0_V;
}

QAxisGradient QAxisGradientAt(const VoltageLaw& law, const QAxisPoint& p,
                              const QAxisState& s) noexcept {
  QAxisGradient g;
  g.winding_V_per_K = law.r0_ohm * (1.0 + s.dr) * law.alpha_per_K * p.iq_A;
  const double beta = law.beta_per_K * (1.0 + s.dbeta);
  const double rise_K = s.magnet_degC - law.magnet_t0_degC;
  g.magnet_V_per_K = p.w_rad_per_s * law.psi0_Wb * (1.0 + s.dpsi) * beta;
  g.dr_V = law.r0_ohm * (1.0 + law.alpha_per_K * (s.winding_degC - law.t0_degC)) * p.iq_A;
  g.dpsi_V = p.w_rad_per_s * law.psi0_Wb * (1.0 + beta * rise_K);
  g.dbeta_V = p.w_rad_per_s * law.psi0_Wb * (1.0 + s.dpsi) * law.beta_per_K * rise_K;
  g.u0 = p.iq_A > 0.0 ? 1.0 : p.iq_A < 0.0 ? -1.0 : 0.0;
  return g;
}

double QAxisKnownTerms_V(const MotorDescription& motor, double id_A, double iq_A,
                         double w_rad_per_s) noexcept {
  return w_rad_per_s * motor.inductance_H * id_A + VoltageErrorQ_V(motor, id_A, iq_A);
}

}  // namespace pumptherm::estimators
