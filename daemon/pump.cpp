#include "daemon/pump.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace pumptherm::daemon {
namespace {

/// The identifier's settings for this motor: its magnet's coefficient, when the motor file
/// states one, scales the flux's drift (the identifier's magnet hypotheses).
estimators::ResistanceIdentifierConfig IdentifierConfig(const estimators::MotorDescription& motor) {
  estimators::ResistanceIdentifierConfig c;
  if (motor.magnet.Given())
    c.flux_temperature_coefficient_per_K = motor.magnet.flux_temperature_coefficient_per_K;
  return c;
}

/// A long silence (an offline log's gap) is stepped over at once instead of step by step.
constexpr std::int64_t kMaxStepsPerAdvance = 600;

}  // namespace

estimators::PumpEstimatorConfig EstimatorConfig(const PumpConfig& c, double thermal_period_s) {
  estimators::PumpEstimatorConfig e;
  e.measured_node = c.measured_node;
  e.frame_sensor_lag_s = c.frame_sensor_lag_s;
  if (c.disturbance_states_explicit) e.disturbance_states = c.disturbance_states;
  e.winding.fuse = c.fuse_winding;
  e.winding.model_sd_K = c.winding_sd_K;
  e.magnet.magnet_node = c.magnet_node;
  e.magnet.min_sd_K = c.magnet_min_sd_K;
  e.magnet.max_winding_gain = c.magnet_max_winding_gain;
  e.rotor_node = c.rotor_node;
  e.voltage.fuse = c.voltage_reading;
  // The loss scale starts at the stated sd and may stay that wide (its stationary sd).
  e.disturbance.loss_scale_initial_sd = c.model_losses_sd_rel;
  e.disturbance.loss_scale_max_sd =
      std::max(e.disturbance.loss_scale_max_sd, c.model_losses_sd_rel);
  e.alarms = c.alarms.monitor;
  for (const auto& [node, levels] : c.alarms.levels) e.levels[node] = levels.limits;
  e.period_s = thermal_period_s;
  return e;
}

Pump::Pump(const PumpConfig& config, const estimators::MotorDescription& motor,
           std::shared_ptr<const estimators::ThermalModel> model, double thermal_period_s)
    : config_(config),
      model_(std::move(model)),
      motor_(motor),
      period_s_(thermal_period_s),
      period_us_(static_cast<std::int64_t>(std::llround(thermal_period_s * 1e6))),
      identifier_(motor_, IdentifierConfig(motor_)) {
  // Levels are named with their own line; the estimator checks them again.
  for (const auto& [node, lc] : config_.alarms.levels) {
    const std::string problem = estimators::UnknownLevelNode(*model_, node);
    if (!problem.empty()) {
      throw std::invalid_argument(
          fmt::format("pump '{}': alarm levels (line {}) for {}", config_.name, lc.line, problem));
    }
  }
  if (period_us_ <= 0) throw std::invalid_argument("thermal period must be positive");
  try {
    estimator_ = std::make_unique<estimators::PumpEstimator>(
        EstimatorConfig(config_, thermal_period_s), motor_, *model_);
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(
        fmt::format("pump '{}' (line {}): {}", config_.name, config_.line, e.what()));
  }
}

void Pump::CountLostFrames(double counter) {
  if (!std::isfinite(counter)) return;
  if (std::isfinite(last_counter_)) {
    const int expected = (static_cast<int>(last_counter_) + 1) % 16;
    const int got = static_cast<int>(counter);
    counters_.lost_frames += static_cast<std::uint64_t>((got - expected + 16) % 16);
  }
  last_counter_ = counter;
}

void Pump::OnCurrents(std::int64_t t_us, double id_A, double iq_A, double w_e, double counter) {
  ++counters_.fast_frames;
  NoteFastFrame(t_us);
  if (!std::isfinite(id_A) || !std::isfinite(iq_A)) {
    ++counters_.rejected_values;
    return;
  }
  if (std::isfinite(w_e)) w_e_rad_per_s_ = w_e;
  CountLostFrames(counter);
  // Thermal inputs: losses go with the square of the currents, so the period's mean squares.
  const double speed = std::isfinite(w_e_rad_per_s_)
                           ? estimators::MechanicalSpeed_rpm(motor_, w_e_rad_per_s_)
                           : speed_rpm_;
  if (std::isfinite(speed)) {
    sum_id2_ += id_A * id_A;
    sum_iq2_ += iq_A * iq_A;
    sum_iq_ += iq_A;
    sum_speed_ += speed;
    ++n_inputs_;
  }
  protocol::DqPair pair;
  if (pairing_.OnCurrents(t_us, id_A, iq_A, counter, pair)) Identify(pair);
  counters_.unpaired = pairing_.unpaired();
}

void Pump::OnVoltages(std::int64_t t_us, double ud_V, double uq_V, double counter) {
  ++counters_.fast_frames;
  NoteFastFrame(t_us);
  if (!std::isfinite(ud_V) || !std::isfinite(uq_V)) {
    ++counters_.rejected_values;
    return;
  }
  protocol::DqPair pair;
  if (pairing_.OnVoltages(t_us, ud_V, uq_V, counter, pair)) Identify(pair);
  counters_.unpaired = pairing_.unpaired();
}

void Pump::NoteFastFrame(std::int64_t t_us) {
  if (t_us != last_fast_us_) previous_fast_us_ = last_fast_us_;
  last_frame_us_ = last_fast_us_ = t_us;
}

std::int64_t Pump::LastAtOrBefore(std::int64_t last_us, std::int64_t previous_us,
                                  std::int64_t t_us) {
  // A step that runs after a later frame came in (offline, the first frame after a silence
  // brings the steps of the silence) must see the frame before it.
  return last_us <= t_us ? last_us : previous_us;
}

void Pump::Identify(const protocol::DqPair& pair) {
  estimators::DqSample s;
  s.id_A = pair.id_A;
  s.iq_A = pair.iq_A;
  s.ud_V = pair.ud_V;
  s.uq_V = pair.uq_V;
  s.w_r_rad_per_s = std::isfinite(w_e_rad_per_s_)
                        ? w_e_rad_per_s_
                        : estimators::ElectricalSpeed_rad_per_s(motor_, speed_rpm_);
  if (!std::isfinite(s.w_r_rad_per_s)) {
    ++counters_.rejected_values;
    return;
  }
  double dt_s =
      last_sample_us_ < 0 ? 0.01 : static_cast<double>(pair.t_us - last_sample_us_) * 1e-6;
  if (!(dt_s > 0.0)) dt_s = 1e-4;  // two samples in one timestamp tick
  last_sample_us_ = pair.t_us;
  identifier_.Update(s, dt_s);
  ++drive_.n;
  drive_.id += s.id_A;
  drive_.iq += s.iq_A;
  drive_.iq2 += s.iq_A * s.iq_A;
  if (std::isfinite(drive_.last_iq)) {
    drive_.diq2 += (s.iq_A - drive_.last_iq) * (s.iq_A - drive_.last_iq);
    ++drive_.differences;
  }
  drive_.last_iq = s.iq_A;
  drive_.ud += s.ud_V;
  drive_.uq += s.uq_V;
  drive_.w += s.w_r_rad_per_s;
  ++counters_.samples;
  if (identifier_.blocks() != identifier_blocks_) {
    identifier_blocks_ = identifier_.blocks();
    flux_block_us_ = pair.t_us;
  }
}

void Pump::OnStatus(std::int64_t t_us, double speed_rpm, double /*drive_state*/, double frame_degC,
                    double ambient_degC) {
  ++counters_.status_frames;
  if (t_us != last_status_us_) previous_status_us_ = last_status_us_;
  last_frame_us_ = last_status_us_ = t_us;
  if (std::isfinite(speed_rpm)) speed_rpm_ = speed_rpm;
  estimator_->OnFrameReading(t_us, frame_degC);
  if (std::isfinite(ambient_degC)) ambient_degC_ = ambient_degC;
}

bool Pump::CheckNeverHeard(std::int64_t since_us, std::int64_t t_us) {
  if (last_frame_us_ >= 0 || since_us < 0) return false;
  if (next_step_us_ >= 0 && t_us < next_step_us_) return false;
  next_step_us_ = t_us + period_us_;
  return estimator_->StepNeverHeard(t_us, static_cast<double>(t_us - since_us) * 1e-6);
}

std::int64_t Pump::NextDueUs() const {
  const bool first_frame = last_frame_us_ >= 0 && !heard_;
  if (first_frame || next_step_us_ < 0) return std::numeric_limits<std::int64_t>::min();
  return next_step_us_;
}

bool Pump::Advance(std::int64_t t_us) {
  if (last_frame_us_ < 0) return false;
  if (next_step_us_ < 0 || !heard_) next_step_us_ = last_frame_us_ + period_us_;
  heard_ = true;
  const std::uint64_t before = snapshot().alarm_changes;
  if (t_us >= next_step_us_) {
    const std::int64_t steps = (t_us - next_step_us_) / period_us_ + 1;
    if (steps > kMaxStepsPerAdvance) next_step_us_ += (steps - 1) * period_us_;
    while (t_us >= next_step_us_) {
      ThermalStep(next_step_us_, period_s_);
      next_step_us_ += period_us_;
    }
    SyncCounters();
  }
  return snapshot().alarm_changes != before;
}

void Pump::SyncCounters() {
  const auto& e = estimator_->counters();
  counters_.thermal_steps = e.steps;
  counters_.filter_resets = e.filter_resets;
}

bool Pump::PeriodInputs(estimators::PumpPeriod& p) {
  estimators::ThermalInputs& in = p.inputs;
  in = held_inputs_;
  p.fresh_inputs = n_inputs_ > 0;
  if (n_inputs_ > 0) {
    in.id_A = std::sqrt(sum_id2_ / n_inputs_);
    in.iq_A = std::sqrt(sum_iq2_ / n_inputs_);
    in.speed_rpm = sum_speed_ / n_inputs_;
    p.mean_iq_A = sum_iq_ / n_inputs_;
    have_inputs_ = true;
    sum_id2_ = sum_iq2_ = sum_speed_ = sum_iq_ = 0.0;
    n_inputs_ = 0;
  } else if (!have_inputs_ && std::isfinite(speed_rpm_)) {
    // Status frames but no fast telemetry: the speed is known, the currents are not (taken 0).
    in.speed_rpm = speed_rpm_;
    have_inputs_ = true;
  }
  if (std::isfinite(ambient_degC_)) in.ambient_degC = in.coolant_degC = ambient_degC_;
  return have_inputs_;
}

estimators::DriveAverages Pump::TakeDriveAverages() {
  estimators::DriveAverages a;
  a.samples = drive_.n;
  if (drive_.n > 0) {
    const double n = drive_.n;
    a.id_A = drive_.id / n;
    a.iq_A = drive_.iq / n;
    a.ud_V = drive_.ud / n;
    a.uq_V = drive_.uq / n;
    a.w_rad_per_s = drive_.w / n;
    // A load change moves iq between the period's first and last samples; the current's noise
    // (and a ripple faster than the samples) moves it from one sample to the next. Successive
    // differences of white noise of sd s have a mean square of 2 s^2 (von Neumann's ratio): what
    // the period's variance has beyond that is the change.
    const double variance_A2 = std::max(drive_.iq2 / n - a.iq_A * a.iq_A, 0.0);
    const double noise_A2 =
        drive_.differences > 0 ? 0.5 * drive_.diq2 / static_cast<double>(drive_.differences) : 0.0;
    a.iq_change_sd_A = std::sqrt(std::max(variance_A2 - noise_A2, 0.0));
  }
  drive_ = DriveSums{};
  return a;
}

estimators::IdentifierOutput Pump::IdentifierAt(std::int64_t t_us) const {
  estimators::IdentifierOutput o;
  o.estimate = identifier_.estimate();
  o.p = identifier_.p();
  if (last_sample_us_ >= 0) o.sample_age_s = static_cast<double>(t_us - last_sample_us_) * 1e-6;
  if (flux_block_us_ >= 0) o.block_age_s = static_cast<double>(t_us - flux_block_us_) * 1e-6;
  return o;
}

void Pump::ThermalStep(std::int64_t end_us, double dt_s) {
  estimators::PumpPeriod p;
  p.drive = TakeDriveAverages();
  if (!PeriodInputs(p)) return;
  held_inputs_ = p.inputs;
  p.end_us = end_us;
  p.dt_s = dt_s;
  p.ambient_degC = ambient_degC_;
  p.telemetry_age_s = TelemetryAge_s(end_us);
  const std::int64_t fast_us = LastAtOrBefore(last_fast_us_, previous_fast_us_, end_us);
  if (fast_us >= 0) p.fast_age_s = static_cast<double>(end_us - fast_us) * 1e-6;
  p.identifier = IdentifierAt(end_us);
  const estimators::PumpEstimatorCounters before = estimator_->counters();
  estimator_->Step(p);
  // Health is data: inputs the model cannot take refuse the step (the mismatch test's too), an
  // invalid reading is left out; all are counted.
  const estimators::PumpEstimatorCounters& after = estimator_->counters();
  counters_.rejected_values += (after.refused_steps - before.refused_steps) +
                               (after.rejected_readings - before.rejected_readings) +
                               (after.mismatch_refused - before.mismatch_refused);
}

double Pump::TelemetryAge_s(std::int64_t t_us) const {
  double age_s = 0.0;
  for (const std::int64_t last_us : {LastAtOrBefore(last_fast_us_, previous_fast_us_, t_us),
                                     LastAtOrBefore(last_status_us_, previous_status_us_, t_us)}) {
    if (last_us >= 0) age_s = std::max(age_s, static_cast<double>(t_us - last_us) * 1e-6);
  }
  return age_s;
}

PumpSavedState Pump::Save() const {
  PumpSavedState s;
  static_cast<estimators::PumpEstimatorState&>(s) = estimator_->Save();
  s.resistance = identifier_.Save();
  return s;
}

bool Pump::Restore(const PumpSavedState& state, std::int64_t now_us) {
  estimators::ResistanceIdentifier identifier = identifier_;
  if (!identifier.Restore(state.resistance)) return false;
  if (!estimator_->Restore(state, now_us)) return false;
  identifier_ = identifier;
  held_inputs_ = state.inputs;
  have_inputs_ = true;
  // Published at once: the first GW_IDENT after a restart may go out before the first thermal
  // step (seen in the system test: Rs "not available" right after kill -9).
  estimator_->NoteIdentifier(identifier_.estimate());
  return true;
}

}  // namespace pumptherm::daemon
