#include "tools/sim/tmp_drive.hpp"

#include <cmath>
#include <numbers>

#include "estimators/copper.hpp"
#include "tools/sim/sensor.hpp"

namespace pumptherm::sim {

TmpDrive::TmpDrive(TmpDriveConfig config)
    : config_(std::move(config)),
      rng_(config_.seed),
      load_rng_(config_.seed ^ 0x9e3779b97f4a7c15ULL) {
  load_target_A_ = config_.load_current_A;
  std::exponential_distribution<double> interval(1.0 / config_.load_step_mean_interval_s);
  next_load_change_s_ = config_.ramp_s + interval(load_rng_);
  std::uniform_real_distribution<double> phase(0.0, 2.0 * std::numbers::pi);
  offset_phase_rad_ = phase(rng_);
}

TmpDriveSample TmpDrive::Step() {
  const double dt = config_.sample_period_s;
  const double t = static_cast<double>(k_) * dt;
  ++k_;
  const auto& m = config_.motor;
  const double rated_rpm = m.rated_speed_rpm;

  // Speed set point (what the drive's estimate follows) and the true mechanical speed.
  const bool ramping = t < config_.ramp_s;
  const double set_rpm = ramping ? rated_rpm * t / config_.ramp_s : rated_rpm;
  double true_rpm = set_rpm;
  if (config_.speed_ripple && !ramping) {
    true_rpm +=
        config_.speed_ripple_rpm * std::sin(2.0 * std::numbers::pi * config_.speed_ripple_hz * t);
  }
  const double w = estimators::ElectricalSpeed_rad_per_s(m, true_rpm);

  // Torque-producing current: accelerating current plus drag during the ramp, then the gas load.
  if (config_.load_steps && !ramping) {
    while (t >= next_load_change_s_) {
      std::uniform_real_distribution<double> level(config_.load_min_A, config_.load_max_A);
      std::exponential_distribution<double> interval(1.0 / config_.load_step_mean_interval_s);
      load_target_A_ = level(load_rng_);
      next_load_change_s_ += interval(load_rng_);
    }
  }
  const double speed_fraction = set_rpm / rated_rpm;
  if (config_.load_profile_A && !ramping) load_target_A_ = config_.load_profile_A(t);
  const double target_A =
      ramping ? config_.ramp_current_A + config_.load_current_A * speed_fraction * speed_fraction
              : load_target_A_;
  const double iq_prev = iq_A_;
  if (k_ == 1) {
    iq_A_ = target_A;
  } else {
    iq_A_ += (target_A - iq_A_) * (1.0 - std::exp(-dt / config_.current_response_s));
  }
  const double diq_dt = k_ == 1 ? 0.0 : (iq_A_ - iq_prev) / dt;
  const double id = 0.0;

  // Electrical parameters at the temperatures the caller sets.
  const double tw = config_.winding_degC(t);
  const double tm = config_.magnet_degC(t);
  const double rs = estimators::ResistanceAt(m.copper, tw);
  double psi = m.flux_Wb;
  if (config_.flux_drift) {
    psi *= 1.0 + config_.flux_temperature_coefficient_per_K * (tm - m.copper.t0_degC);
  }

  // True voltages (Han 2019 eq. 4 with did/dt = 0), then what the controller commands.
  double uq = rs * iq_A_ + m.inductance_H * diq_dt + w * (m.inductance_H * id + psi);
  double ud = rs * id - m.inductance_H * w * iq_A_;
  if (config_.dead_time) {
    const double mag = std::hypot(id, iq_A_);
    if (mag > 0.0) {
      const double e = config_.dead_time_V * std::tanh(mag / config_.dead_time_knee_A) / mag;
      uq += e * iq_A_;
      ud += e * id;
    }
  }

  angle_rad_ = std::fmod(angle_rad_ + w * dt, 2.0 * std::numbers::pi);
  const double levels = std::ldexp(1.0, config_.adc_bits);
  const double i_lsb = 2.0 * config_.current_range_A / levels;
  const double u_lsb = 2.0 * config_.dc_link_V / levels;
  const double ripple_q = config_.phase_offset_A * std::cos(angle_rad_ + offset_phase_rad_);
  const double ripple_d = config_.phase_offset_A * std::sin(angle_rad_ + offset_phase_rad_);

  TmpDriveSample s;
  s.time_s = t;
  s.id_A = Quantise(id + ripple_d + Noise(config_.current_noise_A), i_lsb, -config_.current_range_A,
                    config_.current_range_A);
  s.iq_A = Quantise(iq_A_ + ripple_q + Noise(config_.current_noise_A), i_lsb,
                    -config_.current_range_A, config_.current_range_A);
  s.ud_V =
      Quantise(ud + Noise(config_.voltage_noise_V), u_lsb, -config_.dc_link_V, config_.dc_link_V);
  s.uq_V =
      Quantise(uq + Noise(config_.voltage_noise_V), u_lsb, -config_.dc_link_V, config_.dc_link_V);
  s.speed_rpm = set_rpm + Noise(config_.speed_noise_rpm);
  s.true_iq_A = iq_A_;
  s.load_target_A = target_A;
  s.true_speed_rpm = true_rpm;
  s.true_resistance_ohm = rs;
  s.true_flux_Wb = psi;
  s.true_winding_degC = tw;
  s.true_magnet_degC = tm;
  return s;
}

}  // namespace pumptherm::sim
