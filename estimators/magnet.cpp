#include "estimators/magnet.hpp"

#include <cmath>
#include <limits>

namespace pumptherm::estimators {

MagnetTemperature MagnetTemperatureFromFlux(const MotorDescription& motor, double flux_Wb,
                                            double flux_sd_Wb) noexcept {
  constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
  const MagnetLaw& law = motor.magnet;
  if (!law.Given() || !std::isfinite(flux_Wb) || !std::isfinite(flux_sd_Wb) || flux_sd_Wb < 0.0) {
    return {kNaN, kNaN};
  }
  const double beta = law.flux_temperature_coefficient_per_K;
  return {law.t0_degC + (flux_Wb / motor.flux_Wb - 1.0) / beta,
          flux_sd_Wb / (motor.flux_Wb * std::abs(beta))};
}

double FluxAt_Wb(const MotorDescription& motor, double magnet_degC) noexcept {
  const MagnetLaw& law = motor.magnet;
  if (!law.Given()) return std::numeric_limits<double>::quiet_NaN();
  return motor.flux_Wb *
         (1.0 + law.flux_temperature_coefficient_per_K * (magnet_degC - law.t0_degC));
}

}  // namespace pumptherm::estimators
