#include "estimators/disturbance_sensor.hpp"

#include <fmt/core.h>

#include <cmath>
#include <stdexcept>

namespace pumptherm::estimators {
DisturbanceThermalSensor::DisturbanceThermalSensor(const ThermalModel& model, DisturbanceSensorConfig config)
    : model_(model), config_(std::move(config)), discretiser_(1e-3), filter_(0) {
  const auto& c = config_;
  frame_ = model_.StateIndex(c.measured_node);
  if (frame_ < 0) {
    throw std::invalid_argument(fmt::format(
        "disturbance sensor: measured node '{}' is not a node with heat capacity of model '{}'",
        c.measured_node, model_.Name()));
  }
  if (!(c.measurement_sd_K > 0.0) || !(c.sensor_lag_s >= 0.0) || !(c.sensor_offset_sd_K > 0.0) ||
      !(c.node_process_sd_K > 0.0) || !(c.frame_heat_sd_W > 0.0) || !(c.rotor_heat_sd_W > 0.0) ||
      !(c.rotor_heat_tau_s > 0.0) || !(c.winding_measurement_sd_K > 0.0) || !(c.loss_scale_sd >= 0.0) || !(c.sd_floor_K >= 0.0) || !(c.initial_spread_sd_K > 0.0)) {
    throw std::invalid_argument("disturbance sensor: standard deviations and times must be positive");
  }
  rotor_ = c.rotor_node.empty() ? -1 : model_.StateIndex(c.rotor_node);
  n_ = model_.StateCount();
  int k = n_;
  if (c.sensor_lag_s > 0.0) lag_ = k++;
  df_ = k++;
  if (rotor_ >= 0) dr_ = k++;
  if (c.loss_scale_sd > 0.0) ls_ = k++;
  bias_ = k++;
  n_aug_ = k;
  // The nodes and the sensor lag are discretised together (exact ZOH); the disturbances are held
  // over a step and enter through that discretisation's Phi (Step()), so the matrix exponential is
  // redone only when the network moves, as in VirtualThermalSensor.
  const int nb = lag_ >= 0 ? n_ + 1 : n_;
  lin_block_.a_per_s = Eigen::MatrixXd::Zero(nb, nb);
  lin_block_.f_K_per_s = Eigen::VectorXd::Zero(nb);
  const Eigen::VectorXd& cap = model_.Capacities_J_per_K();
  heat_in_ = Eigen::MatrixXd::Zero(nb, 3);  // K/s per unit of d_f, d_r, s
  phi_heat_ = Eigen::MatrixXd::Zero(nb, 3);
  heat_in_(frame_, 0) = 1.0 / cap(frame_);
  if (dr_ >= 0) heat_in_(rotor_, 1) = 1.0 / cap(rotor_);
  if (lag_ >= 0) {
    lin_block_.a_per_s(lag_, frame_) = 1.0 / c.sensor_lag_s;
    lin_block_.a_per_s(lag_, lag_) = -1.0 / c.sensor_lag_s;
  }
  ad_ = Eigen::MatrixXd::Identity(n_aug_, n_aug_);
  sp_ = Eigen::MatrixXd::Zero(n_aug_, n_aug_);
  bu_ = Eigen::VectorXd::Zero(n_aug_);
  c_ = Eigen::MatrixXd::Zero(1, n_aug_);
  c_(0, lag_ >= 0 ? lag_ : frame_) = 1.0;
  c_(0, bias_) = 1.0;
  sm_ = Eigen::MatrixXd::Constant(1, 1, c.measurement_sd_K * c.measurement_sd_K);
  y_ = Eigen::VectorXd::Zero(1);
  c0_ = Eigen::MatrixXd::Zero(0, n_aug_);
  cw_ = Eigen::MatrixXd::Zero(1, n_aug_);
  cw_.row(0).head(n_) = model_.WindingWeights().transpose();
  const double var_w = c.winding_measurement_sd_K * c.winding_measurement_sd_K;
  smw_ = Eigen::MatrixXd::Constant(1, 1, var_w);
  c2_ = Eigen::MatrixXd::Zero(2, n_aug_);
  c2_.row(0) = c_.row(0);
  c2_.row(1) = cw_.row(0);
  sm2_ = Eigen::MatrixXd::Zero(2, 2);
  sm2_(0, 0) = sm_(0, 0);
  sm2_(1, 1) = var_w;
  yw_ = Eigen::VectorXd::Zero(1);
  y2_ = Eigen::VectorXd::Zero(2);
  x_nodes_ = Eigen::VectorXd::Zero(n_);
  filter_ = KalmanFilter(n_aug_);
  Initialise(25.0);
}

void DisturbanceThermalSensor::Initialise(double x0_degC) {
  const auto& c = config_;
  const int temps = lag_ >= 0 ? n_ + 1 : n_;  // nodes and the lag: one common level
  Eigen::MatrixXd s = Eigen::MatrixXd::Zero(n_aug_, n_aug_);
  for (int i = 0; i < temps; ++i) {
    const int ii = i < n_ ? i : lag_;
    for (int j = 0; j < temps; ++j) s(ii, j < n_ ? j : lag_) = c.initial_sd_K * c.initial_sd_K;
    s(ii, ii) += c.initial_spread_sd_K * c.initial_spread_sd_K;
  }
  s(df_, df_) = 1.0;  // W^2: a watt either way at the start
  if (dr_ >= 0) s(dr_, dr_) = c.rotor_heat_sd_W * c.rotor_heat_sd_W;
  if (ls_ >= 0) s(ls_, ls_) = 0.01;  // 10 % either way at the start
  s(bias_, bias_) = c.sensor_offset_sd_K * c.sensor_offset_sd_K;
  Eigen::VectorXd x = Eigen::VectorXd::Zero(n_aug_);
  x.head(n_).setConstant(x0_degC);
  if (lag_ >= 0) x(lag_) = x0_degC;
  filter_.Reset(x, s);
}

double DisturbanceThermalSensor::NodeSd_K(int i) const {
  const double v = std::max(filter_.Covariance()(i, i), 0.0);
  return std::sqrt(v + config_.sd_floor_K * config_.sd_floor_K);
}

void DisturbanceThermalSensor::Nodes(Eigen::VectorXd& x_degC, Eigen::VectorXd& sd_K) const {
  for (int i = 0; i < n_; ++i) {
    x_degC(i) = filter_.State()(i);
    sd_K(i) = NodeSd_K(i);
  }
}

void DisturbanceThermalSensor::AddDisturbanceForcing(ThermalLinearModel& lin) const {
  const Eigen::VectorXd& cap = model_.Capacities_J_per_K();
  lin.f_K_per_s(frame_) += filter_.State()(df_) / cap(frame_);
  if (dr_ >= 0) lin.f_K_per_s(rotor_) += filter_.State()(dr_) / cap(rotor_);
}

const KalmanUpdateReport& DisturbanceThermalSensor::Step(const ThermalInputs& in, double dt_s,
                                                         double measured_degC, double winding_degC) {
  if (!(dt_s > 0.0) || !std::isfinite(dt_s)) {
    throw std::domain_error("disturbance sensor: the period must be positive and finite");
  }
  const auto& c = config_;
  const int nb = static_cast<int>(lin_block_.f_K_per_s.size());
  x_nodes_ = filter_.State().head(n_);
  model_.Linearise(in, x_nodes_, lin_);
  lin_block_.a_per_s.topLeftCorner(n_, n_) = lin_.a_per_s;
  lin_block_.f_K_per_s.head(n_) = lin_.f_K_per_s;
  if (ls_ >= 0) {
    // The losses' share of dx/dt at the estimate: (a x + f) under load minus at rest.
    ThermalInputs idle = in;
    idle.speed_rpm = idle.id_A = idle.iq_A = 0.0;
    model_.Linearise(idle, x_nodes_, lin_idle_);
    auto col = heat_in_.col(2).head(n_);
    col.noalias() = lin_.a_per_s * x_nodes_;
    col += lin_.f_K_per_s;
    col.noalias() -= lin_idle_.a_per_s * x_nodes_;
    col -= lin_idle_.f_K_per_s;
  }
  discretiser_.Update(lin_block_, dt_s);
  const ThermalDiscreteModel& d = discretiser_.Current();
  ad_.topLeftCorner(nb, nb) = d.ad;
  bu_.head(nb).noalias() = d.phi_s * lin_block_.f_K_per_s;
  // Disturbances held over the step: x(k+1) += Phi b d (eq. 21 with d as an input).
  phi_heat_.noalias() = d.phi_s * heat_in_;
  ad_.col(df_).head(nb) = phi_heat_.col(0);
  if (dr_ >= 0) {
    ad_.col(dr_).head(nb) = phi_heat_.col(1);
    ad_(dr_, dr_) = std::exp(-dt_s / c.rotor_heat_tau_s);
  }
  if (ls_ >= 0) ad_.col(ls_).head(nb) = phi_heat_.col(2);
  const double q = c.node_process_sd_K * c.node_process_sd_K * dt_s;
  for (int i = 0; i < n_; ++i) sp_(i, i) = q;
  sp_(df_, df_) = c.frame_heat_sd_W * c.frame_heat_sd_W * dt_s;
  if (dr_ >= 0) {  // Gauss-Markov: variance 2 sigma^2 dt / tau per step keeps sigma stationary
    sp_(dr_, dr_) = 2.0 * c.rotor_heat_sd_W * c.rotor_heat_sd_W * dt_s / c.rotor_heat_tau_s;
  }
  if (ls_ >= 0) sp_(ls_, ls_) = c.loss_scale_sd * c.loss_scale_sd * dt_s;
  filter_.Predict(ad_, bu_, sp_);
  const bool frame = std::isfinite(measured_degC);
  const bool winding = std::isfinite(winding_degC) && model_.WindingWeights().sum() > 0.0;
  if (frame && winding) {
    y2_(0) = measured_degC;
    y2_(1) = winding_degC;
    return filter_.Update(c2_, y2_, sm2_);
  }
  if (winding) {
    yw_(0) = winding_degC;
    return filter_.Update(cw_, yw_, smw_);
  }
  if (!frame) return filter_.Update(c0_, y0_, sm0_);
  y_(0) = measured_degC;
  return filter_.Update(c_, y_, sm_);
}

}  // namespace pumptherm::estimators
