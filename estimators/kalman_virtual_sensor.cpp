#include "estimators/kalman_virtual_sensor.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <cmath>
#include <exception>
#include <stdexcept>

namespace pumptherm::estimators {

VirtualThermalSensor::VirtualThermalSensor(const ThermalModel& model, VirtualSensorConfig config)
    : model_(model),
      config_(std::move(config)),
      discretiser_(config_.relinearise_tolerance),
      filter_(model.StateCount()) {
  for (const std::string& node : config_.measured_nodes) {
    const int s = model_.StateIndex(node);
    if (s < 0) {
      throw std::invalid_argument(
          fmt::format("measured node '{}' is not a node with heat capacity of model '{}'", node,
                      model_.Name()));
    }
    measured_states_.push_back(s);
  }
  if (!(config_.measurement_sd_K > 0.0) || !(config_.process_sd_K > 0.0) ||
      !(config_.initial_sd_K >= 0.0) || !(config_.initial_spread_sd_K > 0.0) ||
      !(config_.winding_measurement_sd_K > 0.0) || !(config_.process_period_s > 0.0)) {
    throw std::invalid_argument("virtual sensor: standard deviations and periods must be positive");
  }
  const int n = model_.StateCount();
  bu_.resize(n);
  sp_.resize(n, n);
  Initialise(Eigen::VectorXd::Constant(n, 25.0));
}

void VirtualThermalSensor::Initialise(const Eigen::VectorXd& x0_degC) {
  const int n = model_.StateCount();
  const double common = config_.initial_sd_K * config_.initial_sd_K;
  const double spread = config_.initial_spread_sd_K * config_.initial_spread_sd_K;
  filter_.Reset(x0_degC,
                Eigen::MatrixXd::Constant(n, n, common) + Eigen::MatrixXd::Identity(n, n) * spread);
}

const KalmanUpdateReport& VirtualThermalSensor::Step(const ThermalInputs& inputs, double dt_s,
                                                     const Eigen::VectorXd& measured_degC,
                                                     double winding_degC, double winding_sd_K) {
  winding_only_.Clear();
  // NaN or not positive: the configured winding_measurement_sd_K.
  const double sd = winding_sd_K > 0.0 ? winding_sd_K : config_.winding_measurement_sd_K;
  winding_only_.Add(kWindingWeightsRow, winding_degC, sd);
  return Step(inputs, dt_s, measured_degC, winding_only_);
}

bool VirtualThermalSensor::Uses(const NodeMeasurement& e, bool* rejected) const {
  if (rejected) *rejected = false;
  if (!std::isfinite(e.value_degC)) return false;
  const bool valid =
      (e.state == kWindingWeightsRow || (e.state >= 0 && e.state < model_.StateCount())) &&
      e.sd_K > 0.0 && std::isfinite(e.sd_K) && std::isfinite(e.winding_gain);
  if (!valid) {
    if (rejected) *rejected = true;
    return false;
  }
  const bool reads_winding = e.state == kWindingWeightsRow || e.winding_gain != 0.0;
  return !reads_winding || model_.WindingWeights().sum() > 0.0;
}

const KalmanUpdateReport& VirtualThermalSensor::Step(const ThermalInputs& inputs, double dt_s,
                                                     const Eigen::VectorXd& measured_degC,
                                                     const NodeMeasurements& extra) {
  // Checked before the time update: a refused step changes nothing.
  if (!(dt_s > 0.0) || !std::isfinite(dt_s) || !model_.AcceptsInputs(inputs)) {
    report_.measurements = 0;
    report_.nis = 0.0;
    report_.ok = false;
    report_.refused = true;
    report_.rejected_measurements = 0;
    return report_;
  }
  const int n = model_.StateCount();
  const Eigen::Index sensors =
      std::min(measured_degC.size(), static_cast<Eigen::Index>(measured_states_.size()));
  int m = 0;
  int rejected_count = 0;
  for (Eigen::Index i = 0; i < sensors; ++i) {
    if (std::isfinite(measured_degC(i))) ++m;
  }
  for (int j = 0; j < extra.size(); ++j) {
    bool rejected = false;
    if (Uses(extra[j], &rejected)) ++m;
    rejected_count += rejected;
  }
  // Terms that read node temperatures are evaluated at the current estimate.
  model_.Linearise(inputs, filter_.State(), lin_);
  discretiser_.Update(lin_, dt_s);
  const ThermalDiscreteModel& d = discretiser_.Current();
  bu_.noalias() = d.phi_s * lin_.f_K_per_s;
  if (dt_s != sp_dt_s_) {
    const double var =
        config_.process_sd_K * config_.process_sd_K * dt_s / config_.process_period_s;
    sp_.setIdentity();
    sp_ *= var;
    sp_dt_s_ = dt_s;
  }
  filter_.Predict(d.ad, bu_, sp_);

  c_.resize(m, n);
  y_.resize(m);
  sm_.resize(m, m);
  c_.setZero();
  sm_.setZero();
  int row = 0;
  const double var_m = config_.measurement_sd_K * config_.measurement_sd_K;
  for (Eigen::Index i = 0; i < sensors; ++i) {
    if (!std::isfinite(measured_degC(i))) continue;
    c_(row, measured_states_[static_cast<std::size_t>(i)]) = 1.0;
    y_(row) = measured_degC(i);
    sm_(row, row) = var_m;
    ++row;
  }
  for (int j = 0; j < extra.size(); ++j) {
    const NodeMeasurement& e = extra[j];
    if (!Uses(e)) continue;
    if (e.state == kWindingWeightsRow) {
      c_.row(row) = model_.WindingWeights().transpose();
    } else {
      if (e.winding_gain != 0.0) c_.row(row) = e.winding_gain * model_.WindingWeights().transpose();
      c_(row, e.state) += 1.0;
    }
    y_(row) = e.value_degC;
    sm_(row, row) = e.sd_K * e.sd_K;
    ++row;
  }
  report_ = filter_.Update(c_, y_, sm_, config_.covariance_update);
  report_.refused = false;
  report_.rejected_measurements = rejected_count;
  return report_;
}

bool PredictOverGap(const ThermalModel& model, const ThermalInputs& in, double gap_s,
                    const VirtualSensorConfig& config, Eigen::VectorXd& x, Eigen::MatrixXd& s) {
  try {
    ThermalLinearModel lin;
    model.Linearise(in, x, lin);
    ThermalDiscreteModel d;
    DiscretiseZoh(lin.a_per_s, gap_s, d);
    const double q = config.process_sd_K * config.process_sd_K * gap_s / config.process_period_s;
    x = d.ad * x + d.phi_s * lin.f_K_per_s;
    s = d.ad * s * d.ad.transpose() + q * Eigen::MatrixXd::Identity(s.rows(), s.cols());
  } catch (const std::exception&) {
    return false;
  }
  return true;
}

}  // namespace pumptherm::estimators
