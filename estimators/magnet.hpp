#pragma once
/// Magnet temperature from the identified permanent-magnet flux linkage.
///
/// A magnet's remanence, and with it the flux linkage psi_f of a surface PM motor, falls nearly
/// linearly with temperature over the working range (the reversible temperature coefficient of
/// the remanence, beta: sintered NdFeB about -0.1 %/K, Sm2Co17 about -0.03 %/K;
/// docs/virtual-sensor.md, "Magnet temperature from the flux", cites the makers' sheets):
///
///     psi_f(T) = psi_f0 (1 + beta (T - T0))   =>   T = T0 + (psi_f / psi_f0 - 1) / beta
///
/// the same linear law as the copper's (Han, Xiong, Mao 2019 eqs. 2-3), for the flux. Its
/// standard deviation follows to first order: sd_T = sd_psi / (psi_f0 |beta|).
///
/// Pure: no I/O.

#include "estimators/motor.hpp"

namespace pumptherm::estimators {

struct MagnetTemperature {
  double degC;  ///< NaN when the motor states no magnet law or the flux is not finite
  double sd_K;  ///< NaN likewise
};

/// The magnet temperature for an identified flux `flux_Wb` with standard deviation
/// `flux_sd_Wb` (>= 0), by the motor's magnet law (MotorDescription::magnet). Never throws.
MagnetTemperature MagnetTemperatureFromFlux(const MotorDescription& motor, double flux_Wb,
                                            double flux_sd_Wb) noexcept;

/// The flux linkage the law gives at `magnet_degC`, Wb (the inverse; NaN without a law).
double FluxAt_Wb(const MotorDescription& motor, double magnet_degC) noexcept;

}  // namespace pumptherm::estimators
