#include "estimators/disturbance_sensor.hpp"

#include <fmt/core.h>

#include <cmath>
#include <stdexcept>

namespace pumptherm::estimators {
DisturbanceThermalSensor::DisturbanceThermalSensor(const ThermalModel& model,
                                                   DisturbanceSensorConfig config)
    : model_(model), config_(std::move(config)), discretiser_(1e-3), filter_(0) {
  const auto& c = config_;
  frame_ = model_.StateIndex(c.measured_node);
  if (frame_ < 0) {
    throw std::invalid_argument(fmt::format(
        "disturbance sensor: measured node '{}' is not a node with heat capacity of model '{}'",
        c.measured_node, model_.Name()));
  }
  if (!(c.measurement_sd_K > 0.0) || !(c.sensor_step_noise_sd_K > 0.0) ||
      !(c.sensor_lag_s >= 0.0) || !(c.sensor_offset_sd_K > 0.0) || !(c.node_process_sd_K > 0.0) ||
      !(c.frame_heat_sd_W > 0.0) || !(c.rotor_heat_sd_W > 0.0) || !(c.rotor_heat_tau_s > 0.0) ||
      !(c.winding_measurement_sd_K > 0.0) || !(c.loss_scale_sd >= 0.0) ||
      !(c.loss_scale_max_sd > 0.0) || !(c.sd_floor_K >= 0.0) || !(c.initial_spread_sd_K > 0.0) ||
      !(c.winding_bias_sd_K >= 0.0) || !(c.winding_bias_tau_s > 0.0) ||
      !(c.magnet_bias_sd_K >= 0.0) || !(c.magnet_bias_tau_s > 0.0) ||
      !(c.magnet_min_white_sd_K > 0.0) || !(c.sensor_step_gate_sd >= 0.0)) {
    throw std::invalid_argument(
        "disturbance sensor: standard deviations and times must be positive");
  }
  rotor_ = c.rotor_node.empty() ? -1 : model_.StateIndex(c.rotor_node);
  if (!c.magnet_node.empty()) {
    magnet_ = model_.StateIndex(c.magnet_node);
    if (magnet_ < 0) {
      throw std::invalid_argument(fmt::format(
          "disturbance sensor: magnet node '{}' is not a node with heat capacity of model '{}'",
          c.magnet_node, model_.Name()));
    }
  }
  const bool has_winding = c.winding_reading && model_.WindingWeights().sum() > 0.0;
  n_ = model_.StateCount();
  int k = n_;
  if (c.sensor_lag_s > 0.0) lag_ = k++;
  df_ = k++;
  if (rotor_ >= 0) dr_ = k++;
  if (c.loss_scale_sd > 0.0) ls_ = k++;
  bias_ = k++;
  if (has_winding && c.winding_bias_sd_K > 0.0) wb_ = k++;
  if (magnet_ >= 0 && c.magnet_bias_sd_K > 0.0) mb_ = k++;
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
  sensor_ = lag_ >= 0 ? lag_ : frame_;
  c_(0, sensor_) = 1.0;
  c_(0, bias_) = 1.0;
  sm_ = Eigen::MatrixXd::Constant(1, 1, c.measurement_sd_K * c.measurement_sd_K);
  y_ = Eigen::VectorXd::Zero(1);
  c0_ = Eigen::MatrixXd::Zero(0, n_aug_);
  BuildRows();
  x_nodes_ = Eigen::VectorXd::Zero(n_);
  filter_ = KalmanFilter(n_aug_);
  gauss_markov_.assign(static_cast<std::size_t>(n_aug_),
                       {std::numeric_limits<double>::quiet_NaN(), 1.0});
  Initialise(25.0);
}

// The rows of the update: the frame, then the winding (the model's winding weights plus its
// bias), then the magnet (its node plus its bias; the winding gain is added per step). Every
// row is present in every update once any reading is; a missing reading's row is zero, so the
// matrices keep their size and the step allocates nothing.
void DisturbanceThermalSensor::BuildRows() {
  const bool has_winding = config_.winding_reading && model_.WindingWeights().sum() > 0.0;
  int m = 1;
  if (has_winding) row_w_ = m++;
  if (magnet_ >= 0) row_m_ = m++;
  c_all_ = Eigen::MatrixXd::Zero(m, n_aug_);
  sm_all_ = Eigen::MatrixXd::Zero(m, m);
  y_all_ = Eigen::VectorXd::Zero(m);
  cw_row_ = Eigen::MatrixXd::Zero(1, n_aug_);
  cm_row_ = Eigen::MatrixXd::Zero(1, n_aug_);
  if (has_winding) {
    cw_row_.row(0).head(n_) = model_.WindingWeights().transpose();
    if (wb_ >= 0) cw_row_(0, wb_) = 1.0;
  }
  if (magnet_ >= 0) {
    cm_row_(0, magnet_) = 1.0;
    if (mb_ >= 0) cm_row_(0, mb_) = 1.0;
  }
}

void DisturbanceThermalSensor::GaussMarkov(int state, double sd, double tau_s, double dt_s) {
  // Exact discretisation of db/dt = -b/tau + w with stationary sd: a = e^(-dt/tau), q = sd^2 (1 -
  // a^2). tau is the state's own setting, so a changes only with the period.
  auto& [dt_last_s, a_last] = gauss_markov_[static_cast<std::size_t>(state)];
  if (dt_s != dt_last_s) {
    dt_last_s = dt_s;
    a_last = std::exp(-dt_s / tau_s);
  }
  const double a = a_last;
  ad_(state, state) = a;
  sp_(state, state) = sd * sd * (1.0 - a * a);
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
  if (wb_ >= 0) s(wb_, wb_) = c.winding_bias_sd_K * c.winding_bias_sd_K;
  if (mb_ >= 0) s(mb_, mb_) = c.magnet_bias_sd_K * c.magnet_bias_sd_K;
  Eigen::VectorXd x = Eigen::VectorXd::Zero(n_aug_);
  x.head(n_).setConstant(x0_degC);
  if (lag_ >= 0) x(lag_) = x0_degC;
  filter_.Reset(x, s);
  frame_fused_last_ = reopen_offset_ = false;
  stepped_offset_K_ = 0.0;
  last_reading_degC_ = std::numeric_limits<double>::quiet_NaN();
}

void DisturbanceThermalSensor::Initialise(const Eigen::VectorXd& x_degC,
                                          const Eigen::MatrixXd& s_K2) {
  if (x_degC.size() != n_ || s_K2.rows() != n_ || s_K2.cols() != n_ || !x_degC.allFinite() ||
      !s_K2.allFinite()) {
    throw std::invalid_argument(
        "DisturbanceThermalSensor::Initialise: need n finite temperatures and an n x n covariance");
  }
  Initialise(x_degC(frame_));  // the disturbances' and biases' priors
  Eigen::VectorXd x = filter_.State();
  Eigen::MatrixXd s = filter_.Covariance();
  x.head(n_) = x_degC;
  s.topLeftCorner(n_, n_) = s_K2;
  if (lag_ >= 0) {
    x(lag_) = x_degC(frame_);
    s.block(lag_, 0, 1, n_) = s_K2.row(frame_);
    s.block(0, lag_, n_, 1) = s_K2.col(frame_);
    s(lag_, lag_) = s_K2(frame_, frame_);
  }
  filter_.Reset(x, s);
}

void DisturbanceThermalSensor::RestoreSensorOffset(double offset_K, double sd_K, double stepped_K) {
  if (!std::isfinite(offset_K) || !std::isfinite(stepped_K) || !(sd_K > 0.0) ||
      !std::isfinite(sd_K)) {
    throw std::invalid_argument(
        "DisturbanceThermalSensor::RestoreSensorOffset: need a finite offset and step sum and a "
        "positive sd");
  }
  Eigen::VectorXd x = filter_.State();
  Eigen::MatrixXd s = filter_.Covariance();
  x(bias_) = offset_K;
  s.row(bias_).setZero();
  s.col(bias_).setZero();
  s(bias_, bias_) = sd_K * sd_K;
  filter_.Reset(x, s);
  stepped_offset_K_ = stepped_K;
}

bool DisturbanceThermalSensor::CanRestore(const Eigen::VectorXd& x,
                                          const Eigen::MatrixXd& s) const {
  return x.size() == n_aug_ && s.rows() == n_aug_ && s.cols() == n_aug_ && x.allFinite() &&
         s.allFinite() && (n_aug_ == 0 || s.diagonal().minCoeff() >= 0.0);
}

void DisturbanceThermalSensor::Restore(const Eigen::VectorXd& x, const Eigen::MatrixXd& s,
                                       double stepped_K) {
  if (!CanRestore(x, s) || !std::isfinite(stepped_K)) {
    throw std::invalid_argument(
        "DisturbanceThermalSensor::Restore: need the filter's finite state and covariance (its "
        "state count) and a finite step sum");
  }
  Initialise(x(frame_));  // forgets the last reading: no step test against a reading before
  filter_.Reset(x, 0.5 * (s + s.transpose()));
  stepped_offset_K_ = stepped_K;
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
                                                         double measured_degC,
                                                         double winding_degC) {
  DisturbanceReadings r;
  r.frame_degC = measured_degC;
  r.winding_degC = winding_degC;
  return Step(in, dt_s, r);
}

const KalmanUpdateReport& DisturbanceThermalSensor::Step(const ThermalInputs& in, double dt_s,
                                                         const DisturbanceReadings& r) {
  // Health is data: a period or inputs the model cannot take refuse the step (nothing changes).
  if (!(dt_s > 0.0) || !std::isfinite(dt_s) || !model_.AcceptsInputs(in)) {
    refused_.measurements = 0;
    refused_.ok = false;
    refused_.refused = true;
    return refused_;
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
  if (ls_ >= 0) {  // its walk near zero is loss_scale_sd: 2 sigma^2 / tau = loss_scale_sd^2
    const double sigma = c.loss_scale_max_sd;
    GaussMarkov(ls_, sigma, 2.0 * sigma * sigma / (c.loss_scale_sd * c.loss_scale_sd), dt_s);
  }
  if (wb_ >= 0) GaussMarkov(wb_, c.winding_bias_sd_K, c.winding_bias_tau_s, dt_s);
  if (mb_ >= 0) GaussMarkov(mb_, c.magnet_bias_sd_K, c.magnet_bias_tau_s, dt_s);
  filter_.Predict(ad_, bu_, sp_);
  const bool frame = std::isfinite(r.frame_degC);
  if (frame) OpenOffsetOnStep(r.frame_degC);
  frame_fused_last_ = frame;
  const bool winding = row_w_ >= 0 && std::isfinite(r.winding_degC);
  const bool magnet =
      row_m_ >= 0 && std::isfinite(r.magnet_degC) && std::isfinite(r.magnet_winding_gain);
  if (!frame && !winding && !magnet) return filter_.Update(c0_, y0_, sm0_);
  // A missing reading: a zero row, zero innovation, unit variance (no gain, no effect).
  c_all_.setZero();
  sm_all_.setZero();
  y_all_.setZero();
  sm_all_(0, 0) = 1.0;
  if (frame) {
    c_all_.row(0) = c_.row(0);
    sm_all_(0, 0) = sm_(0, 0);
    y_all_(0) = r.frame_degC;
  }
  if (row_w_ >= 0) {
    sm_all_(row_w_, row_w_) = 1.0;
    if (winding) {
      c_all_.row(row_w_) = cw_row_.row(0);
      sm_all_(row_w_, row_w_) = c.winding_measurement_sd_K * c.winding_measurement_sd_K;
      y_all_(row_w_) = r.winding_degC;
    }
  }
  if (row_m_ >= 0) {
    sm_all_(row_m_, row_m_) = 1.0;
    if (magnet) {
      // z = T_magnet + g T_winding + bias + white noise.
      c_all_.row(row_m_) = cm_row_.row(0);
      c_all_.row(row_m_).head(n_) += r.magnet_winding_gain * model_.WindingWeights().transpose();
      const double sd = std::isfinite(r.magnet_sd_K)
                            ? std::max(r.magnet_sd_K, c.magnet_min_white_sd_K)
                            : c.magnet_min_white_sd_K;
      sm_all_(row_m_, row_m_) = sd * sd;
      y_all_(row_m_) = r.magnet_degC;
    }
  }
  const KalmanUpdateReport& report = filter_.Update(c_all_, y_all_, sm_all_);
  if (frame) RememberReading(r.frame_degC);
  return report;
}

double DisturbanceThermalSensor::PredictedReading_degC() const {
  return filter_.State()(sensor_) + filter_.State()(bias_);
}

double DisturbanceThermalSensor::PredictedReadingVar_K2() const {
  const Eigen::MatrixXd& p = filter_.Covariance();
  return p(sensor_, sensor_) + 2.0 * p(sensor_, bias_) + p(bias_, bias_);
}

// The step between two readings against the step the filter predicted between them: the
// reading's own increment, so a filter still far from a reading it has only begun to follow (a
// restart, a cold start) sees no step where the sensor is steady.
void DisturbanceThermalSensor::OpenOffsetOnStep(double frame_degC) {
  const double gate = config_.sensor_step_gate_sd;
  const bool comparable =
      (frame_fused_last_ || reopen_offset_) && std::isfinite(last_reading_degC_);
  reopen_offset_ = false;
  if (!(gate > 0.0) || !comparable) return;
  const double step =
      (frame_degC - last_reading_degC_) - (PredictedReading_degC() - last_predicted_degC_);
  // Two readings' white noise, and what the prediction since the last update added to the
  // uncertainty.
  const double noise = config_.sensor_step_noise_sd_K;
  const double var =
      2.0 * noise * noise + std::max(PredictedReadingVar_K2() - last_predicted_var_K2_, 0.0);
  if (!(step * step > gate * gate * var)) return;
  filter_.AddVariance(bias_, step * step);
  ++sensor_steps_;
  last_sensor_step_K_ = step;
  stepped_offset_K_ += step;
}

void DisturbanceThermalSensor::RememberReading(double frame_degC) {
  last_reading_degC_ = frame_degC;
  last_predicted_degC_ = PredictedReading_degC();
  last_predicted_var_K2_ = PredictedReadingVar_K2();
}

bool BoundaryOnlyThrough(const ThermalModel& model, const std::string& measured_node) {
  const int measured = model.StateIndex(measured_node);
  if (measured < 0) return false;
  ThermalInputs in;
  in.ambient_degC = in.coolant_degC = 20.0;
  const Eigen::VectorXd x = Eigen::VectorXd::Constant(model.StateCount(), 20.0);
  ThermalLinearModel cold, warm;
  model.Linearise(in, x, cold);
  in.ambient_degC = in.coolant_degC = 21.0;
  model.Linearise(in, x, warm);
  // The losses are the same in both (same speed, currents and temperatures), so the difference
  // is C^-1 B_b per kelvin of boundary.
  const Eigen::VectorXd d = (warm.f_K_per_s - cold.f_K_per_s).cwiseAbs();
  const double scale = d.maxCoeff();
  for (int i = 0; i < d.size(); ++i) {
    if (i != measured && d(i) > 1e-9 * scale) return false;
  }
  return d(measured) > 0.0;
}

}  // namespace pumptherm::estimators
