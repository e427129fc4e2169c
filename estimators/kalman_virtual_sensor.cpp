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
  if (!config_.magnet_node.empty()) {
    magnet_state_ = model_.StateIndex(config_.magnet_node);
    if (magnet_state_ < 0) {
      throw std::invalid_argument(
          fmt::format("magnet node '{}' is not a node with heat capacity of model '{}'",
                      config_.magnet_node, model_.Name()));
    }
  }
  const int n = model_.StateCount();
  bu_.resize(n);
  sp_.resize(n, n);
  sw_.resize(n);
  BuildObserverRows();
  Initialise(Eigen::VectorXd::Constant(n, 25.0));
}

void VirtualThermalSensor::BuildObserverRows() {
  const int n = model_.StateCount();
  int m = measured_states_.empty() ? 0 : 1;
  if (config_.winding_reading && model_.WindingWeights().sum() > 0.0) row_w_ = m++;
  if (magnet_state_ >= 0) row_m_ = m++;
  obs_c_ = Eigen::MatrixXd::Zero(m, n);
  obs_sm_ = Eigen::MatrixXd::Zero(m, m);
  obs_y_ = Eigen::VectorXd::Zero(m);
  obs_c0_ = Eigen::MatrixXd::Zero(0, n);
  obs_sm0_ = Eigen::MatrixXd::Zero(0, 0);
  obs_y0_ = Eigen::VectorXd::Zero(0);
}

void VirtualThermalSensor::Initialise(double x0_degC) {
  Initialise(Eigen::VectorXd::Constant(model_.StateCount(), x0_degC));
}

void VirtualThermalSensor::InitialiseKnown(double x0_degC, double sd_K) {
  const int n = model_.StateCount();
  filter_.Reset(Eigen::VectorXd::Constant(n, x0_degC),
                Eigen::MatrixXd::Identity(n, n) * (sd_K * sd_K));
}

bool VirtualThermalSensor::CanRestore(const Eigen::VectorXd& x, const Eigen::MatrixXd& s) const {
  const int n = model_.StateCount();
  return x.size() == n && s.rows() == n && s.cols() == n && x.allFinite() && s.allFinite() &&
         (n == 0 || s.diagonal().minCoeff() >= 0.0);
}

void VirtualThermalSensor::Restore(const Eigen::VectorXd& x_degC, const Eigen::MatrixXd& s_K2) {
  if (!CanRestore(x_degC, s_K2)) {
    throw std::invalid_argument(
        "VirtualThermalSensor::Restore: need n finite temperatures and an n x n covariance");
  }
  filter_.Reset(x_degC, s_K2);
}

double VirtualThermalSensor::WeightedVariance_K2(const Eigen::VectorXd& w) const {
  sw_.noalias() = filter_.Covariance() * w;
  return std::max(w.dot(sw_), 0.0);
}

double VirtualThermalSensor::SettlingSd_K() const {
  const int n = model_.StateCount();
  return n > 0 ? std::sqrt(std::max(filter_.Covariance().diagonal().maxCoeff(), 0.0)) : 0.0;
}

bool VirtualThermalSensor::Predict(const ThermalInputs& inputs, double dt_s) {
  try {
    // Terms that read node temperatures are evaluated at the current estimate.
    model_.Linearise(inputs, filter_.State(), lin_);
  } catch (const std::exception&) {
    return false;  // a massless sub-network singular at this operating point
  }
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
  return true;
}

const ObserverReport& VirtualThermalSensor::Step(const ThermalInputs& inputs, double dt_s,
                                                 const ThermalReadings& r) {
  obs_report_ = ObserverReport{};
  if (!(dt_s > 0.0) || !std::isfinite(dt_s) || !model_.AcceptsInputs(inputs) ||
      !Predict(inputs, dt_s)) {
    report_ = KalmanUpdateReport{};
    report_.ok = false;
    report_.refused = true;
    obs_report_.update = &report_;
    obs_report_.refused = true;
    return obs_report_;
  }
  const int n = model_.StateCount();
  const bool frame = !measured_states_.empty() && std::isfinite(r.frame_degC);
  const double winding_sd_K =
      r.winding_sd_K > 0.0 ? r.winding_sd_K : config_.winding_measurement_sd_K;
  const bool winding_finite = row_w_ >= 0 && std::isfinite(r.winding_degC);
  const bool winding = winding_finite && std::isfinite(winding_sd_K);
  const bool magnet_finite = row_m_ >= 0 && std::isfinite(r.magnet_degC);
  const double magnet_sd_K = std::max(r.magnet_sd_K, config_.magnet_min_sd_K);
  const bool magnet = magnet_finite && magnet_sd_K > 0.0 && std::isfinite(magnet_sd_K) &&
                      std::isfinite(r.magnet_winding_gain);
  obs_report_.rejected_readings = (winding_finite && !winding) + (magnet_finite && !magnet);
  if (!frame && !winding && !magnet) {
    report_ = filter_.Update(obs_c0_, obs_y0_, obs_sm0_, config_.covariance_update);
    report_.refused = false;
    obs_report_.update = &report_;
    return obs_report_;
  }
  obs_c_.setZero();
  obs_sm_.setIdentity();  // a missing reading: a zero row of unit variance (no effect)
  obs_y_.setZero();
  if (frame) {
    obs_c_(0, measured_states_[0]) = 1.0;
    obs_sm_(0, 0) = config_.measurement_sd_K * config_.measurement_sd_K;
    obs_y_(0) = r.frame_degC;
  }
  if (winding) {
    obs_c_.row(row_w_) = model_.WindingWeights().transpose();
    obs_sm_(row_w_, row_w_) = winding_sd_K * winding_sd_K;
    obs_y_(row_w_) = r.winding_degC;
  }
  if (magnet) {
    obs_c_.row(row_m_).head(n) = r.magnet_winding_gain * model_.WindingWeights().transpose();
    obs_c_(row_m_, magnet_state_) += 1.0;
    obs_sm_(row_m_, row_m_) = magnet_sd_K * magnet_sd_K;
    obs_y_(row_m_) = r.magnet_degC;
  }
  report_ = filter_.Update(obs_c_, obs_y_, obs_sm_, config_.covariance_update);
  report_.refused = false;
  obs_report_.update = &report_;
  if (!report_.ok) return obs_report_;
  auto row = [&](ReadingRow& out, int i) {
    out.fused = true;
    out.innovation_K = report_.innovation(i);
    out.innovation_var_K2 = report_.innovation_var(i);
  };
  if (frame) row(obs_report_.frame, 0);
  if (winding) row(obs_report_.winding, row_w_);
  if (magnet) row(obs_report_.magnet, row_m_);
  return obs_report_;
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
  if (!Predict(inputs, dt_s)) {
    report_.measurements = 0;
    report_.nis = 0.0;
    report_.ok = false;
    report_.refused = true;
    report_.rejected_measurements = 0;
    return report_;
  }
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
