#pragma once
/// Plant simulator of a turbo-molecular-pump motor drive for testing resistance identification:
/// the SPMSM of Han, Xiong, Mao, Vacuum 169 (2019) 108935 (Table 1: 1 pole pair, 21000 r/min,
/// psi_f 0.0182 Wb, Rs 0.28 ohm, Ls 0.24 mH) under id = 0 control, sampled every 10 ms.
///
/// True q-axis voltage (Han 2019 eq. 4 with id = 0 held by the current loop):
///     uq = Rs(Tw) iq + Ls diq/dt + w_r (Ls id + psi_f(Tm)),   ud = Rs id - Ls w_r iq
/// with Rs(Tw) from the copper law (eq. 2) at the winding temperature the caller sets, and
/// psi_f falling with the magnet temperature when flux drift is on.
///
/// Imperfections (../shared/reference/realistic-signals.md; levels in
/// docs/resistance-identification.md): white noise and 12-bit quantisation on currents
/// (+/-20 A) and voltages (+/-DC link), a per-phase current offset that appears in dq as a
/// ripple at electrical frequency, speed-estimate noise, and switchable disturbances: magnet
/// flux drift, inverter dead-time voltage error, mechanical speed ripple (not in the speed
/// estimate), and gas-load steps. Deterministic for a given seed.

#include <cstdint>
#include <functional>
#include <random>

#include "estimators/motor.hpp"

namespace pumptherm::sim {

/// Settings of the TMP drive plant. Defaults: the Han 2019 motor, 8-minute ramp, 24 h run.
struct TmpDriveConfig {
  estimators::MotorDescription motor;  ///< the true plant (R0/T0/alpha, psi_f at T0, Ls, p)
  double sample_period_s = 0.01;
  double duration_s = 480.0 + 24.0 * 3600.0;  ///< ramp, then 24 h at rated speed
  double ramp_s = 480.0;                      ///< 0 to rated speed, linear (Han 2019 sec. 4.2)
  double ramp_current_A = 6.0;                ///< iq accelerating the rotor during the ramp
  double load_current_A = 2.0;                ///< iq at rated speed in vacuum (drag)

  // Measurement chain.
  double current_noise_A = 0.01;  ///< rms white noise on id and iq
  double current_range_A = 20.0;  ///< 12-bit ADC over +/- this range (9.8 mA per step)
  double phase_offset_A = 0.005;  ///< per-phase offset -> dq ripple at electrical frequency
  double voltage_noise_V = 0.01;  ///< rms jitter of the commanded ud, uq
  double dc_link_V = 48.0;        ///< 12-bit over +/- this range (23 mV per step)
  double speed_noise_rpm = 1.0;   ///< rms noise of the drive's speed estimate
  int adc_bits = 12;

  // Disturbances, each switched on separately.
  bool flux_drift = false;
  double flux_temperature_coefficient_per_K = -1e-3;  ///< NdFeB, relative to psi_f at T0
  bool dead_time = false;
  double dead_time_V = 0.2;       ///< voltage error along the current vector at high current
  double dead_time_knee_A = 0.5;  ///< current magnitude where the error reaches 76 % (tanh)
  bool speed_ripple = false;
  double speed_ripple_rpm = 3.0;  ///< amplitude of the mechanical ripple
  double speed_ripple_hz = 0.37;
  bool load_steps = false;
  double load_step_mean_interval_s = 600.0;  ///< exponential intervals between gas-load changes
  double load_min_A = 1.0;                   ///< gas-load current range at rated speed
  double load_max_A = 4.0;
  double current_response_s = 0.2;  ///< time constant of iq following a load change

  /// Winding and magnet temperature trajectories (degC) against time (s); the test sets them.
  std::function<double(double)> winding_degC = [](double) { return 27.2; };
  std::function<double(double)> magnet_degC = [](double) { return 27.2; };
  /// Scripted gas-load current (A) against time (s) after the ramp; when set it replaces the
  /// random load steps and the constant load current.
  std::function<double(double)> load_profile_A;
  std::uint64_t seed = 1;
};

/// One sample: what the drive reports, and the truth behind it.
struct TmpDriveSample {
  double time_s = 0.0;
  // Reported (noisy, quantised).
  double id_A = 0.0;
  double iq_A = 0.0;
  double ud_V = 0.0;
  double uq_V = 0.0;
  double speed_rpm = 0.0;  ///< mechanical
  // Truth.
  double true_iq_A = 0.0;
  double load_target_A = 0.0;  ///< the torque current the load asks for (changes at load steps)
  double true_speed_rpm = 0.0;
  double true_resistance_ohm = 0.0;
  double true_flux_Wb = 0.0;
  double true_winding_degC = 0.0;
  double true_magnet_degC = 0.0;
};

/// The plant, advanced one sample per Step().
class TmpDrive {
 public:
  explicit TmpDrive(TmpDriveConfig config);

  /// True while time < duration_s.
  bool Running() const { return k_ * config_.sample_period_s < config_.duration_s; }

  /// The sample at time k * sample_period_s, then advances k.
  TmpDriveSample Step();

  const TmpDriveConfig& config() const { return config_; }

 private:
  double Noise(double sd) { return sd > 0.0 ? sd * normal_(rng_) : 0.0; }

  TmpDriveConfig config_;
  std::mt19937_64 rng_;
  std::mt19937_64 load_rng_;  // separate stream: switching noise on does not move load steps
  std::normal_distribution<double> normal_{0.0, 1.0};
  std::uint64_t k_ = 0;
  double iq_A_ = 0.0;
  double load_target_A_ = 0.0;
  double next_load_change_s_ = 0.0;
  double angle_rad_ = 0.0;
  double offset_phase_rad_ = 0.0;
};

}  // namespace pumptherm::sim
