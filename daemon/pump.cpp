#include "daemon/pump.hpp"

#include <fmt/format.h>

#include <cmath>
#include <numbers>
#include <stdexcept>

namespace pumptherm::daemon {
namespace {

constexpr double kRadPerSPerRpm = 2.0 * std::numbers::pi / 60.0;
/// Largest gap between the two halves of one fast sample.
constexpr std::int64_t kPairWindowUs = 50'000;
/// Name of the pseudo-node for the resistance-based winding temperature in alarm levels.
constexpr const char* kWindingResistanceNode = "winding_resistance";
/// Forecast integration step and limit.
constexpr double kForecastStep_s = 10.0;
constexpr double kForecastLimit_s = 6.0 * 3600.0;
/// Largest node standard deviation of a converged virtual sensor.
constexpr double kConvergedSd_K = 5.0;

estimators::VirtualSensorConfig SensorConfig(const PumpConfig& c) {
  estimators::VirtualSensorConfig v;
  v.measured_nodes = {c.measured_node};
  v.winding_measurement_sd_K = c.winding_sd_K;
  return v;
}

estimators::MismatchDetectorConfig MismatchConfig(const PumpConfig& c) {
  estimators::MismatchDetectorConfig m;
  m.measured_node = c.measured_node;
  m.sensor_lag_s = c.frame_sensor_lag_s;
  return m;
}

estimators::DisturbanceSensorConfig RobustConfig(const PumpConfig& c) {
  estimators::DisturbanceSensorConfig d;
  d.measured_node = c.measured_node;
  d.sensor_lag_s = c.frame_sensor_lag_s;
  d.winding_measurement_sd_K = c.winding_sd_K;
  return d;
}

/// Whether a finding changed enough to be announced: its state or effect (refits that only move
/// the size or the fitted start are published on LCM, not announced).
bool NewVerdict(const estimators::MismatchFinding& a, const estimators::MismatchFinding& b) {
  return a.state != b.state || a.effect != b.effect;
}

}  // namespace

Pump::Pump(const PumpConfig& config, const estimators::MotorDescription& motor,
           std::shared_ptr<const estimators::ThermalModel> model, double thermal_period_s)
    : config_(config),
      model_(std::move(model)),
      motor_(motor),
      period_s_(thermal_period_s),
      period_us_(static_cast<std::int64_t>(std::llround(thermal_period_s * 1e6))),
      identifier_(motor, estimators::ResistanceIdentifierConfig{}),
      sensor_(*model_, SensorConfig(config)),
      alarms_([&] {
        // Validate levels against the model before the monitor is built.
        const auto& names = model_->StateNames();
        for (const auto& [node, lc] : config.alarms.levels) {
          if (node == "sensor" || node == kWindingResistanceNode) continue;
          if (model_->StateIndex(node) < 0) {
            std::string list;
            for (const auto& n : names) list += (list.empty() ? "" : ", ") + n;
            throw std::invalid_argument(fmt::format(
                "pump '{}': alarm levels (line {}) for node '{}', which model '{}' does not have "
                "as a node with heat capacity (it has: {}; also 'sensor' and '{}')",
                config.name, lc.line, node, model_->Name(), list, kWindingResistanceNode));
          }
        }
        estimators::AlarmConfig ac = config.alarms.monitor;
        ac.sensor_node = model_->StateIndex(config.measured_node);
        std::vector<estimators::TemperatureLimits> limits;
        for (const auto& n : names) {
          auto it = config.alarms.levels.find(n);
          limits.push_back(it == config.alarms.levels.end() ? estimators::TemperatureLimits{}
                                                            : it->second.limits);
        }
        auto w = config.alarms.levels.find(kWindingResistanceNode);
        limits.push_back(w == config.alarms.levels.end() ? estimators::TemperatureLimits{}
                                                         : w->second.limits);
        auto s = config.alarms.levels.find("sensor");
        return estimators::AlarmMonitor(
            ac, limits, s == config.alarms.levels.end() ? estimators::TemperatureLimits{} : s->second.limits);
      }()),
      mismatch_(*model_, MismatchConfig(config)),
      robust_(*model_, RobustConfig(config)) {
  measured_state_ = model_->StateIndex(config_.measured_node);
  const int n = model_->StateCount();
  snapshot_.node_degC.assign(static_cast<std::size_t>(n), kNaN);
  snapshot_.node_sd_K.assign(static_cast<std::size_t>(n), kNaN);
  alarm_values_.assign(static_cast<std::size_t>(n) + 1, kNaN);
  alarm_sd_.assign(static_cast<std::size_t>(n) + 1, kNaN);
  forecast_x_.resize(n);
  robust_x_.resize(n);
  robust_sd_.resize(n);
  forecast_next_.resize(n);
  if (period_us_ <= 0) throw std::invalid_argument("thermal period must be positive");
}

void Pump::OnCurrents(std::int64_t t_us, double id_A, double iq_A, double w_e, double counter) {
  ++counters_.fast_frames;
  last_frame_us_ = t_us;
  if (!std::isfinite(id_A) || !std::isfinite(iq_A)) {
    ++counters_.rejected_values;
    return;
  }
  if (std::isfinite(w_e)) w_e_rad_per_s_ = w_e;
  if (std::isfinite(counter)) {
    if (std::isfinite(last_counter_)) {
      const int expected = (static_cast<int>(last_counter_) + 1) % 16;
      const int got = static_cast<int>(counter);
      counters_.lost_frames += static_cast<std::uint64_t>((got - expected + 16) % 16);
    }
    last_counter_ = counter;
  }
  // Thermal inputs: losses go with the square of the currents, so the period's mean squares.
  double speed = std::isfinite(w_e_rad_per_s_)
                     ? w_e_rad_per_s_ / (motor_.pole_pairs * kRadPerSPerRpm)
                     : speed_rpm_;
  if (std::isfinite(speed)) {
    sum_id2_ += id_A * id_A;
    sum_iq2_ += iq_A * iq_A;
    sum_speed_ += speed;
    ++n_inputs_;
  }
  if (currents_.t_us >= 0) ++counters_.unpaired;  // its voltages never came
  currents_ = Half{t_us, id_A, iq_A, w_e, counter};
  if (voltages_.t_us >= 0 && std::abs(voltages_.t_us - t_us) <= kPairWindowUs &&
      (voltages_.counter == counter || std::isnan(counter) || std::isnan(voltages_.counter))) {
    Identify(std::max(t_us, voltages_.t_us));
  }
}

void Pump::OnVoltages(std::int64_t t_us, double ud_V, double uq_V, double counter) {
  ++counters_.fast_frames;
  last_frame_us_ = t_us;
  if (!std::isfinite(ud_V) || !std::isfinite(uq_V)) {
    ++counters_.rejected_values;
    return;
  }
  if (voltages_.t_us >= 0) ++counters_.unpaired;
  voltages_ = Half{t_us, ud_V, uq_V, kNaN, counter};
  if (currents_.t_us >= 0 && std::abs(currents_.t_us - t_us) <= kPairWindowUs &&
      (currents_.counter == counter || std::isnan(counter) || std::isnan(currents_.counter))) {
    Identify(std::max(t_us, currents_.t_us));
  }
}

void Pump::Identify(std::int64_t t_us) {
  estimators::DqSample s;
  s.id_A = currents_.a;
  s.iq_A = currents_.b;
  s.ud_V = voltages_.a;
  s.uq_V = voltages_.b;
  s.w_r_rad_per_s = std::isfinite(w_e_rad_per_s_) ? w_e_rad_per_s_
                                                  : speed_rpm_ * motor_.pole_pairs * kRadPerSPerRpm;
  currents_ = Half{};
  voltages_ = Half{};
  if (!std::isfinite(s.w_r_rad_per_s)) {
    ++counters_.rejected_values;
    return;
  }
  double dt_s = last_sample_us_ < 0 ? 0.01 : static_cast<double>(t_us - last_sample_us_) * 1e-6;
  if (!(dt_s > 0.0)) dt_s = 1e-4;  // two samples in one timestamp tick
  last_sample_us_ = t_us;
  identifier_.Update(s, dt_s);
  ++counters_.samples;
}

void Pump::OnStatus(std::int64_t t_us, double speed_rpm, double /*drive_state*/,
                    double frame_degC, double ambient_degC) {
  ++counters_.status_frames;
  last_frame_us_ = t_us;
  if (std::isfinite(speed_rpm)) speed_rpm_ = speed_rpm;
  if (std::isfinite(frame_degC)) {
    frame_degC_ = frame_degC;
    frame_us_ = t_us;
  }
  if (std::isfinite(ambient_degC)) ambient_degC_ = ambient_degC;
}

bool Pump::Advance(std::int64_t t_us) {
  if (last_frame_us_ < 0) return false;
  if (next_step_us_ < 0) next_step_us_ = last_frame_us_ + period_us_;
  const std::uint64_t before = snapshot_.alarm_changes;
  if (t_us >= next_step_us_) {
    const std::int64_t steps = (t_us - next_step_us_) / period_us_ + 1;
    if (steps > 600) {
      // A long silence (offline log gap): one exact step over it instead of thousands.
      next_step_us_ += (steps - 1) * period_us_;
    }
    while (t_us >= next_step_us_) {
      ThermalStep(next_step_us_);
      next_step_us_ += period_us_;
    }
  }
  return snapshot_.alarm_changes != before;
}

void Pump::ThermalStep(std::int64_t end_us) {
  estimators::ThermalInputs in = held_inputs_;
  if (n_inputs_ > 0) {
    in.id_A = std::sqrt(sum_id2_ / n_inputs_);
    in.iq_A = std::sqrt(sum_iq2_ / n_inputs_);
    in.speed_rpm = sum_speed_ / n_inputs_;
    have_inputs_ = true;
    sum_id2_ = sum_iq2_ = sum_speed_ = 0.0;
    n_inputs_ = 0;
  } else if (!have_inputs_ && std::isfinite(speed_rpm_)) {
    // Status frames but no fast telemetry: the speed is known, the currents are not (taken 0).
    in.speed_rpm = speed_rpm_;
    have_inputs_ = true;
  }
  if (std::isfinite(ambient_degC_)) in.ambient_degC = in.coolant_degC = ambient_degC_;
  if (!have_inputs_) return;
  const double stale_s = config_.alarms.monitor.stale_after_s;
  const bool frame_fresh =
      frame_us_ >= 0 && static_cast<double>(end_us - frame_us_) * 1e-6 <= stale_s + period_s_;
  const double measured = frame_fresh ? frame_degC_ : kNaN;
  if (!initialised_) {
    const double x0 = std::isfinite(measured) ? measured : ambient_degC_;
    if (!std::isfinite(x0)) return;  // no temperature at all yet: wait
    sensor_.Initialise(Eigen::VectorXd::Constant(model_->StateCount(), x0));
    mismatch_.Initialise(x0, static_cast<double>(end_us) * 1e-6);
    robust_.Initialise(x0);
    initialised_ = true;
  }
  held_inputs_ = in;
  const estimators::ResistanceEstimate& r = identifier_.estimate();
  const bool tracking = r.status == estimators::ResistanceStatus::kTracking;
  const double winding_res = tracking ? r.winding_degC : kNaN;
  measurement_(0) = measured;  // a member: a temporary VectorXd would allocate every step
  const estimators::KalmanUpdateReport* report = nullptr;
  try {
    report = &sensor_.Step(in, period_s_, measurement_, config_.fuse_winding ? winding_res : kNaN);
    if (config_.disturbance_states) {
      // Frame only: with the identified winding fused, the demo's nodes were 9-40 K off (its
      // rotor heat state takes the winding reading's error; docs/virtual-sensor.md).
      robust_.Step(in, period_s_, measured, kNaN);
      robust_.Nodes(robust_x_, robust_sd_);
    }
  } catch (const std::exception&) {
    ++counters_.rejected_values;
    return;
  }
  ++counters_.thermal_steps;
  CheckModel(in, measured, end_us);

  const bool robust = config_.disturbance_states;
  const Eigen::VectorXd& x = robust ? robust_x_ : sensor_.Estimate_degC();
  const Eigen::MatrixXd& s = sensor_.Covariance_K2();
  // A filter driven outside any physical range is no estimate. The copper loss grows with the
  // temperature (Saheba 2010 eqs. 12-16), so currents far above any rating, held while the
  // frame sensor is silent, make the linearised network unstable and the estimate runs away
  // to Inf within minutes (found by pipeline_step_fuzz). Then nothing is published as a
  // temperature ("n/a", alarms see unknown nodes and an unconverged filter, a latched trip
  // stays), the state is not saved, and the next step starts the filter again.
  const bool diverged = !x.allFinite() || !s.diagonal().allFinite() ||
                        (x.size() > 0 && (x.maxCoeff() > kMaxEstimate_degC || x.minCoeff() < kMinEstimate_degC));
  if (diverged) {
    ++counters_.filter_resets;
    initialised_ = false;
  }
  double max_sd = diverged ? kInf : 0.0;
  for (int i = 0; i < x.size(); ++i) {
    snapshot_.node_degC[static_cast<std::size_t>(i)] = diverged ? kNaN : x(i);
    snapshot_.node_sd_K[static_cast<std::size_t>(i)] =
        diverged ? kNaN : robust ? robust_sd_(i) : std::sqrt(std::max(s(i, i), 0.0));
    // Convergence is judged on the standard filter: the disturbance-state filter's rotor sd
    // stays large by design (heat inside is barely seen), which is not a filter still settling.
    if (!diverged) max_sd = std::max(max_sd, std::sqrt(std::max(s(i, i), 0.0)));
  }
  snapshot_.time_us = end_us;
  snapshot_.initialised = !diverged;
  snapshot_.resistance = r;
  snapshot_.winding_resistance_degC = winding_res;
  snapshot_.frame_measured_degC = measured;
  snapshot_.ambient_degC = in.ambient_degC;
  snapshot_.speed_rpm = in.speed_rpm;
  // The frame sensor's own innovation test (its row comes first when it was measured).
  double nis = kNaN;
  snapshot_.innovation_K = kNaN;
  if (std::isfinite(measured) && report->measurements > 0 && report->innovation_var(0) > 0.0) {
    snapshot_.innovation_K = report->innovation(0);
    nis = report->innovation(0) * report->innovation(0) / report->innovation_var(0);
  }
  snapshot_.nis = nis;

  int ttt_node = -1;
  const double ttt = diverged ? kNaN : TimeToTrip_s(in, &ttt_node);
  snapshot_.time_to_trip_node = ttt_node;

  for (int i = 0; i < x.size(); ++i) {
    alarm_values_[static_cast<std::size_t>(i)] = diverged ? kNaN : x(i);
    alarm_sd_[static_cast<std::size_t>(i)] = snapshot_.node_sd_K[static_cast<std::size_t>(i)];
  }
  alarm_values_.back() = winding_res;
  estimators::AlarmInputs ai;
  ai.node_degC = alarm_values_.data();
  ai.node_sd_K = alarm_sd_.data();
  ai.sensor_degC = measured;
  ai.sensor_model_degC = measured_state_ >= 0 && !diverged ? x(measured_state_) : kNaN;
  // A model the plant no longer follows makes the filter disagree with a sound sensor: the
  // disagreement test is held (neither raised nor cleared) while the mismatch test blames the
  // plant or has not named the cause yet.
  const auto ms = snapshot_.mismatch.state;
  const bool plant_blamed = ms == estimators::MismatchState::kPlantChange ||
                            ms == estimators::MismatchState::kUnexplained;
  ai.sensor_nis = plant_blamed ? kNaN : nis;
  ai.telemetry_age_s = static_cast<double>(end_us - last_frame_us_) * 1e-6;
  // The alarms rest on the virtual sensor: it must have converged. The identifier's health is
  // published with its estimate (status) but is no alarm: the filter uses its winding
  // temperature only while it is tracking, so an identifier still converging (a pump whose load
  // has not changed yet) costs accuracy, not safety.
  ai.estimators_converged = max_sd < kConvergedSd_K;
  ai.time_to_trip_s = ttt;
  ai.time_to_trip_node = ttt_node;
  const estimators::AlarmState before = snapshot_.alarm;
  snapshot_.alarm = alarms_.Step(static_cast<double>(end_us) * 1e-6, ai);
  const auto& now = snapshot_.alarm;
  // A change worth publishing at once: level, reason, node, the set of active reasons, latch.
  if (now.level != before.level || now.reason != before.reason || now.node != before.node ||
      now.active_reasons != before.active_reasons || now.trip_latched != before.trip_latched) {
    ++snapshot_.alarm_changes;
  }
}

void Pump::CheckModel(const estimators::ThermalInputs& in, double measured_degC, std::int64_t end_us) {
  try {
    const estimators::MismatchFinding& f =
        mismatch_.Step(in, period_s_, measured_degC, static_cast<double>(end_us) * 1e-6);
    if (NewVerdict(f, snapshot_.mismatch)) ++snapshot_.mismatch_changes;
    snapshot_.mismatch = f;
  } catch (const std::exception&) {
    ++counters_.rejected_values;
  }
}

double Pump::TimeToTrip_s(const estimators::ThermalInputs& in, int* node) {
  *node = -1;
  const auto& names = model_->StateNames();
  bool any = false;
  for (const auto& n : names) {
    auto it = config_.alarms.levels.find(n);
    any = any || (it != config_.alarms.levels.end() && std::isfinite(it->second.limits.trip_degC));
  }
  if (!any) return std::numeric_limits<double>::infinity();
  auto trip_of = [&](std::size_t i) {
    auto it = config_.alarms.levels.find(names[i]);
    return it == config_.alarms.levels.end() ? std::numeric_limits<double>::infinity()
                                             : it->second.limits.trip_degC;
  };
  forecast_x_ = config_.disturbance_states ? robust_x_ : sensor_.Estimate_degC();
  for (std::size_t i = 0; i < names.size(); ++i) {
    if (forecast_x_(static_cast<Eigen::Index>(i)) >= trip_of(i)) {
      *node = static_cast<int>(i);
      return 0.0;
    }
  }
  try {
    // The steady state at these inputs, A x + f = 0 (ThermalModel::SteadyState_degC), into
    // members: no allocation per step. A singular A gives non-finite values: no forecast.
    model_->Linearise(in, forecast_lin_);
    if (config_.disturbance_states) robust_.AddDisturbanceForcing(forecast_lin_);
    forecast_lu_.compute(forecast_lin_.a_per_s);
    forecast_ss_.noalias() = forecast_lu_.solve(forecast_lin_.f_K_per_s);
    forecast_ss_ = -forecast_ss_;
    if (!forecast_ss_.allFinite()) return std::numeric_limits<double>::infinity();
    bool reaches = false;
    for (std::size_t i = 0; i < names.size(); ++i) reaches = reaches || forecast_ss_(static_cast<Eigen::Index>(i)) >= trip_of(i);
    if (!reaches) return std::numeric_limits<double>::infinity();
    model_->Linearise(in, forecast_x_, forecast_lin_);
    if (config_.disturbance_states) robust_.AddDisturbanceForcing(forecast_lin_);
    forecast_disc_.Update(forecast_lin_, kForecastStep_s);
  } catch (const std::exception&) {
    return std::numeric_limits<double>::infinity();
  }
  for (double t = 0.0; t < kForecastLimit_s; t += kForecastStep_s) {
    forecast_disc_.Propagate(forecast_x_, forecast_lin_, forecast_next_);
    for (std::size_t i = 0; i < names.size(); ++i) {
      const auto k = static_cast<Eigen::Index>(i);
      const double trip = trip_of(i);
      if (forecast_next_(k) >= trip) {
        *node = static_cast<int>(i);
        const double frac = (trip - forecast_x_(k)) / (forecast_next_(k) - forecast_x_(k));
        return t + kForecastStep_s * std::clamp(frac, 0.0, 1.0);
      }
    }
    forecast_x_.swap(forecast_next_);
  }
  return std::numeric_limits<double>::infinity();
}

PumpSavedState Pump::Save() const {
  PumpSavedState s;
  s.model_name = model_->Name();
  s.time_us = snapshot_.time_us;
  s.x_degC = sensor_.Estimate_degC();
  s.s_K2 = sensor_.Covariance_K2();
  s.inputs = held_inputs_;
  s.resistance = identifier_.Save();
  s.trip_latched = snapshot_.alarm.trip_latched;
  const auto& names = model_->StateNames();
  for (const auto& t : alarms_.LatchedTrips()) {
    const std::string node = t.node == estimators::AlarmMonitor::kSensorTrip ? std::string("sensor")
                             : t.node < static_cast<int>(names.size())
                                 ? names[static_cast<std::size_t>(t.node)]
                                 : std::string(kWindingResistanceNode);
    s.latched_trips.push_back({node, t.value});
  }
  return s;
}

bool Pump::Restore(const PumpSavedState& state, std::int64_t now_us) {
  const int n = model_->StateCount();
  if (state.model_name != model_->Name() || state.x_degC.size() != n || state.s_K2.rows() != n ||
      state.s_K2.cols() != n || !state.x_degC.allFinite() || !state.s_K2.allFinite()) {
    return false;
  }
  // A damaged or forged file must not become a published estimate: temperatures in the
  // believable range, variances not negative, inputs finite (they are held while down).
  const auto& in = state.inputs;
  if ((n > 0 && (state.x_degC.maxCoeff() > kMaxEstimate_degC || state.x_degC.minCoeff() < kMinEstimate_degC)) ||
      (n > 0 && state.s_K2.diagonal().minCoeff() < 0.0) || !std::isfinite(in.speed_rpm) ||
      !std::isfinite(in.id_A) || !std::isfinite(in.iq_A) || !std::isfinite(in.ambient_degC) ||
      !std::isfinite(in.coolant_degC)) {
    return false;
  }
  // Alarm node names -> the monitor's indices (model nodes, then the winding resistance).
  std::vector<estimators::AlarmMonitor::LatchedTrip> trips;
  for (const auto& t : state.latched_trips) {
    int node = estimators::AlarmMonitor::kSensorTrip;
    if (t.node == kWindingResistanceNode) {
      node = n;
    } else if (t.node != "sensor") {
      node = model_->StateIndex(t.node);
      if (node < 0) return false;
    }
    if (!std::isfinite(t.value_degC)) return false;
    trips.push_back({node, t.value_degC});
  }
  Eigen::VectorXd x = state.x_degC;
  Eigen::MatrixXd s = state.s_K2;
  const double gap_s = static_cast<double>(now_us - state.time_us) * 1e-6;
  if (gap_s > 0.0) {
    try {
      estimators::ThermalLinearModel lin;
      model_->Linearise(state.inputs, x, lin);
      estimators::ThermalDiscreteModel d;
      estimators::DiscretiseZoh(lin.a_per_s, gap_s, d);
      x = d.ad * x + d.phi_s * lin.f_K_per_s;
      // Process noise of the filter's defaults (0.0894 K per second as a random walk).
      const estimators::VirtualSensorConfig defaults;
      const double q = defaults.process_sd_K * defaults.process_sd_K * gap_s / defaults.process_period_s;
      s = d.ad * s * d.ad.transpose() + q * Eigen::MatrixXd::Identity(n, n);
    } catch (const std::exception&) {
      return false;
    }
  }
  if (!x.allFinite() || !s.allFinite() ||
      (n > 0 && (x.maxCoeff() > kMaxEstimate_degC || x.minCoeff() < kMinEstimate_degC))) {
    return false;
  }
  if (!identifier_.Restore(state.resistance)) return false;
  // Published at once: the first GW_IDENT after a restart may go out before the first thermal
  // step (seen in the system test: Rs "not available" right after kill -9).
  snapshot_.resistance = identifier_.estimate();
  sensor_.Restore(x, s);
  // The mismatch test starts afresh (learning) from the restored level.
  mismatch_.Initialise(n > 0 ? x(std::max(measured_state_, 0)) : 25.0, static_cast<double>(now_us) * 1e-6);
  robust_.Initialise(n > 0 ? x(std::max(measured_state_, 0)) : 25.0);
  held_inputs_ = state.inputs;
  have_inputs_ = true;
  initialised_ = true;
  for (int i = 0; i < n; ++i) {
    snapshot_.node_degC[static_cast<std::size_t>(i)] = x(i);
    snapshot_.node_sd_K[static_cast<std::size_t>(i)] = std::sqrt(std::max(s(i, i), 0.0));
  }
  snapshot_.initialised = true;
  snapshot_.time_us = now_us;
  for (const auto& t : trips) alarms_.RestoreLatchedTrip(t, static_cast<double>(now_us) * 1e-6);
  if (!trips.empty()) {
    snapshot_.alarm = alarms_.state();
    ++snapshot_.alarm_changes;
  }
  return true;
}

}  // namespace pumptherm::daemon
