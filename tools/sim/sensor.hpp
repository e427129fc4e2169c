#pragma once
/// Imperfect measurement models shared by the plant simulators
/// (../shared/reference/realistic-signals.md): ADC quantisation, white noise, a constant
/// offset and a first-order thermal lag. Deterministic for a given seed.

#include <cstdint>
#include <random>

namespace pumptherm::sim {

/// Rounds `value` to the nearest multiple of `lsb` (an ADC or display resolution) and clamps it
/// to [min, max] (the converter's range). `lsb` <= 0 leaves the value unquantised.
double Quantise(double value, double lsb, double min, double max) noexcept;

/// Settings of one measured channel. Units are those of the channel (A, V, degC).
struct SensorConfig {
  double noise_sd = 0.0;  ///< standard deviation of white noise added per sample
  double offset = 0.0;    ///< constant offset added to every sample
  double lsb = 0.0;       ///< quantisation step; 0 = none
  double min = -1e300;    ///< range of the converter
  double max = 1e300;
  double lag_tau_s = 0.0;  ///< first-order lag time constant; 0 = none
};

/// One measured channel: lag (exact first-order discretisation), then offset, noise and
/// quantisation. The lag state starts at the first true value it sees.
class Sensor {
 public:
  Sensor(const SensorConfig& config, std::uint64_t seed) : config_(config), rng_(seed) {}

  /// Measurement of `true_value` after `dt_s` seconds since the previous call.
  double Measure(double true_value, double dt_s);

  /// The lagged (not yet noisy) value, for truth files.
  double lagged() const { return lagged_; }

 private:
  SensorConfig config_;
  std::mt19937_64 rng_;
  std::normal_distribution<double> normal_{0.0, 1.0};
  bool started_ = false;
  double lagged_ = 0.0;
};

}  // namespace pumptherm::sim
