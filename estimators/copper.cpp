#include "estimators/copper.hpp"

namespace pumptherm::estimators {

double ResistanceAt(const CopperLaw& law, double t_degC) noexcept {
  return law.r0_ohm * (1.0 + law.alpha_per_K * (t_degC - law.t0_degC));
}

double TemperatureAt(const CopperLaw& law, double r_ohm) noexcept {
  return (r_ohm / law.r0_ohm - 1.0) / law.alpha_per_K + law.t0_degC;
}

}  // namespace pumptherm::estimators
