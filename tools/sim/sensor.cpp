#include "tools/sim/sensor.hpp"

#include <algorithm>
#include <cmath>

namespace pumptherm::sim {

double Quantise(double value, double lsb, double min, double max) noexcept {
  double q = lsb > 0.0 ? std::round(value / lsb) * lsb : value;
  return std::clamp(q, min, max);
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
