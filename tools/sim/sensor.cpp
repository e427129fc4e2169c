#include "tools/sim/sensor.hpp"

#include <algorithm>
#include <cmath>

namespace pumptherm::sim {

double Quantise(double value, double lsb, double min, double max) noexcept {
  if (!(lsb > 0.0)) return std::clamp(value, min, max);
  // A decimal step (0.1, 0.01 = 1/k): n / k is the double nearest the decimal n * lsb (21.7),
  // where n * lsb carries the step's binary error (21.700000000000003) into every CSV.
  const double per_unit = std::round(1.0 / lsb);
  const double n = std::round(value / lsb);
  const bool decimal = per_unit >= 1.0 && std::abs(per_unit * lsb - 1.0) < 1e-12;
  return std::clamp(decimal ? n / per_unit : n * lsb, min, max);
}

double Sensor::Measure(double true_value, double dt_s) {
  if (!started_ || config_.lag_tau_s <= 0.0) {
    lagged_ = true_value;
    started_ = true;
  } else {
    // Exact zero-order-hold step of tau dy/dt = u - y.
    const double a = std::exp(-std::max(dt_s, 0.0) / config_.lag_tau_s);
    lagged_ = a * lagged_ + (1.0 - a) * true_value;
  }
  double y = lagged_ + config_.offset;
  if (config_.noise_sd > 0.0) y += config_.noise_sd * normal_(rng_);
  return Quantise(y, config_.lsb, config_.min, config_.max);
}

}  // namespace pumptherm::sim
