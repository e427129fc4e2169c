#include "estimators/disturbance_sensor.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <cmath>
#include <exception>
#include <stdexcept>

namespace pumptherm::estimators {
namespace {

/// ad's column `to` (its first phi.rows() rows) = phi times heat's column `from`, over that
/// column's nonzero coefficients in order: the frame's and the rotor's heat enter one node each.
/// The sums are those of the full product (a zero coefficient adds an exact zero).
void PhiTimesColumn(const Eigen::MatrixXd& phi, const Eigen::MatrixXd& heat, Eigen::Index from,
                    Eigen::MatrixXd& ad, Eigen::Index to) {
  const Eigen::Index rows = phi.rows();
  double* out = ad.col(to).data();
  std::fill(out, out + rows, 0.0);
  for (Eigen::Index k = 0; k < rows; ++k) {
    const double h = heat(k, from);
    if (h == 0.0) continue;
    for (Eigen::Index i = 0; i < rows; ++i) out[i] += phi(i, k) * h;
  }
}

}  // namespace

DisturbanceThermalSensor::DisturbanceThermalSensor(const ThermalModel& model,
                                                   DisturbanceSensorConfig config)
    : model_(model),
      config_(std::move(config)),
      sensor_model_(model, config_.measured_node, config_.sensor_lag_s, "disturbance sensor"),
      discretiser_(1e-3),
      filter_(0) {
  const auto& c = config_;
  if (!(c.measurement_sd_K > 0.0) || !(c.sensor_step_noise_sd_K > 0.0) ||
      !(c.sensor_offset_sd_K > 0.0) || !(c.node_process_sd_K > 0.0) || !(c.frame_heat_sd_W > 0.0) ||
      !(c.rotor_heat_sd_W > 0.0) || !(c.rotor_heat_tau_s > 0.0) ||
      !(c.winding_measurement_sd_K > 0.0) || !(c.loss_scale_sd >= 0.0) ||
      !(c.loss_scale_max_sd > 0.0) || !(c.loss_scale_initial_sd > 0.0) ||
      !(c.copper_loss_sd_rel >= 0.0) || !(c.sd_floor_K >= 0.0) || !(c.initial_spread_sd_K > 0.0) ||
      !(c.winding_bias_sd_K >= 0.0) || !(c.winding_bias_tau_s > 0.0) ||
      !(c.magnet_bias_sd_K >= 0.0) || !(c.magnet_bias_tau_s > 0.0) ||
      !(c.magnet_min_white_sd_K > 0.0) || !(c.sensor_step_gate_sd >= 0.0) || !(c.r0_sd_rel > 0.0) ||
      !(c.psi0_sd_rel > 0.0) || !(c.calibration_walk_per_sqrt_h >= 0.0) ||
      !(c.voltage_offset_sd_V > 0.0) || !(c.voltage_offset_tau_s > 0.0) || !(c.uq_min_sd_V > 0.0) ||
      !(c.voltage_gate_sd >= 0.0) || !(c.line_voltage_error_sd_V >= 0.0) ||
      !(c.line_voltage_error_tau_s > 0.0) || !(c.rotor_heat_found_sds >= 0.0) ||
      !(c.free_flux_walk_per_sqrt_s >= 0.0) || !(c.uq_noise_learn_periods >= 0.0)) {
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
  const int frame = sensor_model_.node();
  int k = sensor_model_.TemperatureStates();
  df_ = k++;
  if (rotor_ >= 0) dr_ = k++;
  if (c.loss_scale_sd > 0.0) ls_ = k++;
  sensor_model_.PlaceOffset(k++);
  if (has_winding && c.winding_bias_sd_K > 0.0) wb_ = k++;
  if (magnet_ >= 0 && c.magnet_bias_sd_K > 0.0) mb_ = k++;
  if (mb_ >= 0 && c.line_voltage_error_sd_V > 0.0 && !c.voltage_reading) mu_ = k++;
  if (c.voltage_reading) {
    const std::string& node = !c.voltage_magnet_node.empty() ? c.voltage_magnet_node
                              : !c.magnet_node.empty()       ? c.magnet_node
                                                             : c.rotor_node;
    vmagnet_ = model_.StateIndex(node);
    if (vmagnet_ < 0) {
      throw std::invalid_argument(fmt::format(
          "disturbance sensor: the voltage reading needs the magnet's node; '{}' is not a node "
          "with heat capacity of model '{}'",
          node, model_.Name()));
    }
    const VoltageLaw& law = c.voltage_law;
    if (!(law.r0_ohm > 0.0) || !(law.psi0_Wb > 0.0) || !std::isfinite(law.alpha_per_K) ||
        !std::isfinite(law.beta_per_K) || !std::isfinite(law.t0_degC) ||
        !std::isfinite(law.magnet_t0_degC)) {
      throw std::invalid_argument(
          "disturbance sensor: the voltage reading needs R0 and psi0 above 0 and finite laws");
    }
    dr_state_ = k++;
    dpsi_ = k++;
    dbeta_ = k++;
    u0_ = k++;
  }
  n_aug_ = k;
  // The nodes and the sensor lag are discretised together (exact ZOH); the disturbances are held
  // over a step and enter through that discretisation's Phi (Step()), so the matrix exponential is
  // redone only when the network moves, as in VirtualThermalSensor.
  const int nb = sensor_model_.TemperatureStates();
  lin_block_.a_per_s = Eigen::MatrixXd::Zero(nb, nb);
  lin_block_.f_K_per_s = Eigen::VectorXd::Zero(nb);
  sensor_model_.AddLagRow(lin_block_.a_per_s);
  const Eigen::VectorXd& cap = model_.Capacities_J_per_K();
  heat_in_ = Eigen::MatrixXd::Zero(nb, 4);  // K/s per unit of d_f, d_r, s, dR
  heat_in_(frame, 0) = 1.0 / cap(frame);
  if (dr_ >= 0) heat_in_(rotor_, 1) = 1.0 / cap(rotor_);
  ad_ = Eigen::MatrixXd::Identity(n_aug_, n_aug_);
  sp_ = Eigen::VectorXd::Zero(n_aug_);
  bu_ = Eigen::VectorXd::Zero(n_aug_);
  c0_ = Eigen::MatrixXd::Zero(0, n_aug_);
  BuildRows();
  x_nodes_ = Eigen::VectorXd::Zero(n_);
  sw_ = Eigen::VectorXd::Zero(n_);
  cv_row_ = Eigen::RowVectorXd::Zero(n_aug_);
  row_nonzero_.assign(static_cast<std::size_t>(n_aug_), 0);
  const int aux = n_aug_ - nb;
  aux_cov_ = Eigen::MatrixXd::Zero(aux, aux);
  aux_cross_ = Eigen::MatrixXd::Zero(aux, n_);
  aux_solved_ = Eigen::MatrixXd::Zero(aux, n_);
  aux_ldlt_ = Eigen::LDLT<Eigen::MatrixXd>(aux);
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
  if (dr_state_ >= 0) row_v_ = m++;
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
  sp_(state) = sd * sd * (1.0 - a * a);
}

void DisturbanceThermalSensor::Initialise(double x0_degC) {
  InitialiseWith(x0_degC, config_.initial_sd_K, config_.initial_spread_sd_K);
}

bool DisturbanceThermalSensor::AdoptSensorLag(double lag_s) {
  if (!sensor_model_.SetLag(lag_s)) return false;
  sensor_model_.AddLagRow(lin_block_.a_per_s);  // the next step's discretisation takes it
  return true;
}

void DisturbanceThermalSensor::InitialiseKnown(double x0_degC, double sd_K) {
  InitialiseWith(x0_degC, 0.0, sd_K);
}

void DisturbanceThermalSensor::InitialiseWith(double x0_degC, double common_sd_K,
                                              double spread_sd_K) {
  const auto& c = config_;
  Eigen::MatrixXd s = Eigen::MatrixXd::Zero(n_aug_, n_aug_);
  Eigen::VectorXd x = Eigen::VectorXd::Zero(n_aug_);
  sensor_model_.SetInitial(x0_degC, common_sd_K, spread_sd_K, c.sensor_offset_sd_K, x, s);
  s(df_, df_) = 1.0;  // W^2: a watt either way at the start
  if (dr_ >= 0) s(dr_, dr_) = c.rotor_heat_sd_W * c.rotor_heat_sd_W;
  if (ls_ >= 0) s(ls_, ls_) = c.loss_scale_initial_sd * c.loss_scale_initial_sd;
  if (wb_ >= 0) s(wb_, wb_) = c.winding_bias_sd_K * c.winding_bias_sd_K;
  if (mb_ >= 0) s(mb_, mb_) = c.magnet_bias_sd_K * c.magnet_bias_sd_K;
  if (mu_ >= 0) s(mu_, mu_) = c.line_voltage_error_sd_V * c.line_voltage_error_sd_V;
  VoltagePriors(x, s);
  filter_.Reset(x, s);
  frame_fused_last_ = reopen_offset_ = false;
  voltage_rejected_run_ = 0;
  ForgetVoltageNoise();
  stepped_offset_K_ = 0.0;
  last_reading_degC_ = std::numeric_limits<double>::quiet_NaN();
}

void DisturbanceThermalSensor::InitialiseNodes(const Eigen::VectorXd& x_degC,
                                               const Eigen::MatrixXd& s_K2) {
  if (x_degC.size() != n_ || s_K2.rows() != n_ || s_K2.cols() != n_ || !x_degC.allFinite() ||
      !s_K2.allFinite()) {
    throw std::invalid_argument(
        "DisturbanceThermalSensor::InitialiseNodes: need n finite temperatures and an n x n "
        "covariance");
  }
  const int frame = sensor_model_.node();
  Initialise(x_degC(frame));  // the disturbances' and biases' priors
  Eigen::VectorXd x = filter_.State();
  Eigen::MatrixXd s = filter_.Covariance();
  x.head(n_) = x_degC;
  s.topLeftCorner(n_, n_) = s_K2;
  if (sensor_model_.has_lag()) {
    const int lag = sensor_model_.lag();
    x(lag) = x_degC(frame);
    s.block(lag, 0, 1, n_) = s_K2.row(frame);
    s.block(0, lag, n_, 1) = s_K2.col(frame);
    s(lag, lag) = s_K2(frame, frame);
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
  const int b = sensor_model_.offset();
  Eigen::VectorXd x = filter_.State();
  Eigen::MatrixXd s = filter_.Covariance();
  x(b) = offset_K;
  s.row(b).setZero();
  s.col(b).setZero();
  s(b, b) = sd_K * sd_K;
  filter_.Reset(x, s);
  stepped_offset_K_ = stepped_K;
}

bool DisturbanceThermalSensor::CanRestore(const Eigen::VectorXd& x,
                                          const Eigen::MatrixXd& s) const {
  return x.size() == n_aug_ && s.rows() == n_aug_ && s.cols() == n_aug_ && x.allFinite() &&
         s.allFinite() && (n_aug_ == 0 || s.diagonal().minCoeff() >= 0.0);
}

void DisturbanceThermalSensor::Restore(const Eigen::VectorXd& x, const Eigen::MatrixXd& s) {
  if (!CanRestore(x, s)) {
    throw std::invalid_argument(
        "DisturbanceThermalSensor::Restore: need the filter's finite state and covariance (its "
        "state count)");
  }
  Initialise(x(sensor_model_.node()));  // forgets the last reading: no step test against it
  filter_.Reset(x, 0.5 * (s + s.transpose()));
}

void DisturbanceThermalSensor::RestoreSteppedOffset(double stepped_K) {
  if (!std::isfinite(stepped_K)) {
    throw std::invalid_argument("DisturbanceThermalSensor: the offset's step sum must be finite");
  }
  stepped_offset_K_ = stepped_K;
}

void DisturbanceThermalSensor::VoltagePriors(Eigen::VectorXd& x, Eigen::MatrixXd& s) const {
  if (dr_state_ < 0) return;
  const auto& c = config_;
  x(dr_state_) = x(dpsi_) = x(dbeta_) = x(u0_) = 0.0;
  s(dr_state_, dr_state_) = c.r0_sd_rel * c.r0_sd_rel;
  s(dpsi_, dpsi_) = c.psi0_sd_rel * c.psi0_sd_rel;
  s(dbeta_, dbeta_) = c.magnet_law_sd_rel * c.magnet_law_sd_rel;
  s(u0_, u0_) = c.voltage_offset_sd_V * c.voltage_offset_sd_V;
}

ThermalObserver::Calibration DisturbanceThermalSensor::VoltageCalibration() const {
  Calibration out;
  if (dr_state_ < 0) return out;
  const Eigen::VectorXd& x = filter_.State();
  const Eigen::MatrixXd& p = filter_.Covariance();
  auto sd = [&](int i) { return std::sqrt(std::max(p(i, i), 0.0)); };
  out.dr = x(dr_state_);
  out.dr_sd = sd(dr_state_);
  out.dpsi = x(dpsi_);
  out.dpsi_sd = sd(dpsi_);
  out.dbeta = x(dbeta_);
  out.dbeta_sd = sd(dbeta_);
  out.u0_V = x(u0_);
  out.u0_sd_V = sd(u0_);
  return out;
}

double DisturbanceThermalSensor::CalibrationCovariance(CalibrationEntry entry,
                                                       const Eigen::VectorXd& w) const {
  const int k = entry == CalibrationEntry::kR0 ? dr_state_ : dpsi_;
  if (k < 0) return 0.0;
  return filter_.Covariance().row(k).head(w.size()).dot(w.transpose());
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

double DisturbanceThermalSensor::WeightedVariance_K2(const Eigen::VectorXd& w) const {
  sw_.noalias() = filter_.Covariance().topLeftCorner(n_, n_) * w;
  return std::max(w.dot(sw_), 0.0);
}

double DisturbanceThermalSensor::SettlingSd_K() const {
  // S_nn - S_na S_aa^-1 S_an over the nodes n and the states a past the temperatures.
  const int nb = sensor_model_.TemperatureStates();
  const int aux = n_aug_ - nb;
  const Eigen::MatrixXd& p = filter_.Covariance();
  aux_cov_ = p.block(nb, nb, aux, aux);
  aux_cross_ = p.block(nb, 0, aux, n_);
  aux_ldlt_.compute(aux_cov_);
  aux_solved_ = aux_ldlt_.solve(aux_cross_);
  double largest = 0.0;
  for (int i = 0; i < n_; ++i) {
    // The rotor's temperature integrates the history of its unknown heat, which no present
    // state determines: given the states its sd still grows for hours, by design.
    if (i == rotor_ && dr_ >= 0) continue;
    const double v = p(i, i) - aux_cross_.col(i).dot(aux_solved_.col(i));
    largest = std::max(largest, std::max(v, 0.0));
  }
  return std::sqrt(largest + config_.sd_floor_K * config_.sd_floor_K);
}

bool DisturbanceThermalSensor::SettledWithin(double sd_K) const {
  const Eigen::MatrixXd& p = filter_.Covariance();
  double largest = 0.0;
  for (int i = 0; i < n_; ++i) {
    if (i == rotor_ && dr_ >= 0) continue;  // as in SettlingSd_K
    largest = std::max(largest, p(i, i));
  }
  const double floor2 = config_.sd_floor_K * config_.sd_floor_K;
  if (std::sqrt(largest + floor2) < sd_K) return true;
  return SettlingSd_K() < sd_K;
}

void DisturbanceThermalSensor::AddFoundHeat(ThermalLinearModel& lin) const {
  const Eigen::VectorXd& cap = model_.Capacities_J_per_K();
  const int frame = sensor_model_.node();
  lin.f_K_per_s(frame) += filter_.State()(df_) / cap(frame);
  if (dr_ >= 0) lin.f_K_per_s(rotor_) += filter_.State()(dr_) / cap(rotor_);
}

void DisturbanceThermalSensor::LossColumns() {
  if (dr_state_ >= 0) {
    // With the voltage rows the copper loss is measured, not modelled: the currents are read
    // and the resistance R0 (1 + dR)(1 + alpha (Tw - T0)) is what the rows identify (Han 2019
    // eq. 2). So dR scales the copper loss (its column: the copper's share), and the loss scale
    // s stands for the losses nothing measures (iron, rotor, friction), and for the copper's
    // only by copper_loss_sd_rel / loss_scale_max_sd of it: the copper no longer widens the
    // winding's rise by the whole of s (95 % of the demo's winding variance before).
    heat_in_.col(3).head(n_) = loss_rates_.current_K_per_s;
    if (ls_ >= 0) {
      heat_in_.col(2).head(n_) = loss_rates_.speed_K_per_s;
      heat_in_.col(2).head(n_) +=
          (config_.copper_loss_sd_rel / config_.loss_scale_max_sd) * heat_in_.col(3).head(n_);
      // Once the rows' magnet observes the rotor (psi0 calibrated), the rotor node's losses are
      // the rotor heat state's. Scaled by s as well, a rotor hotter than the model would be
      // explained as every loss higher, and the stator and winding warmed with it. Before (a
      // warm start: the magnet known to psi0's tolerance), nothing tells the rotor's heat from
      // the stator's, and s keeps both.
      if (dr_ >= 0 && magnet_observed_) heat_in_(rotor_, 2) = 0.0;
    }
  } else if (ls_ >= 0) {
    heat_in_.col(2).head(n_) = loss_rates_.current_K_per_s + loss_rates_.speed_K_per_s;
  }
}

bool DisturbanceThermalSensor::Predict(const ThermalInputs& in, double dt_s) {
  const auto& c = config_;
  const int nb = static_cast<int>(lin_block_.f_K_per_s.size());
  x_nodes_ = filter_.State().head(n_);
  try {
    if (ls_ >= 0 || dr_state_ >= 0) {
      model_.Linearise(in, x_nodes_, lin_, loss_rates_);
    } else {
      model_.Linearise(in, x_nodes_, lin_);
    }
  } catch (const std::exception&) {
    return false;  // a massless sub-network singular at this operating point
  }
  lin_block_.a_per_s.topLeftCorner(n_, n_) = lin_.a_per_s;
  lin_block_.f_K_per_s.head(n_) = lin_.f_K_per_s;
  LossColumns();
  discretiser_.Update(lin_block_, dt_s);
  const ThermalDiscreteModel& d = discretiser_.Current();
  ad_.topLeftCorner(nb, nb) = d.ad;
  bu_.head(nb).noalias() = d.phi_s * lin_block_.f_K_per_s;
  // Disturbances held over the step: x(k+1) += Phi b d (eq. 21 with d as an input).
  PhiTimesColumn(d.phi_s, heat_in_, 0, ad_, df_);
  if (dr_ >= 0) {
    const bool turning = std::abs(in.speed_rpm) >= c.rotor_heat_min_speed_rpm;
    heat_in_(rotor_, 1) = turning ? 1.0 / model_.Capacities_J_per_K()(rotor_) : 0.0;
    PhiTimesColumn(d.phi_s, heat_in_, 1, ad_, dr_);
    ad_(dr_, dr_) = std::exp(-dt_s / c.rotor_heat_tau_s);
  }
  if (ls_ >= 0) PhiTimesColumn(d.phi_s, heat_in_, 2, ad_, ls_);
  if (dr_state_ >= 0) PhiTimesColumn(d.phi_s, heat_in_, 3, ad_, dr_state_);
  const double q = c.node_process_sd_K * c.node_process_sd_K * dt_s;
  sp_.head(n_).setConstant(q);
  sp_(df_) = c.frame_heat_sd_W * c.frame_heat_sd_W * dt_s;
  if (dr_ >= 0) {  // Gauss-Markov: variance 2 sigma^2 dt / tau per step keeps sigma stationary
    sp_(dr_) = 2.0 * c.rotor_heat_sd_W * c.rotor_heat_sd_W * dt_s / c.rotor_heat_tau_s;
    sp_(dr_) += RotorHeatDeficit_W2();
  }
  if (ls_ >= 0) {  // its walk near zero is loss_scale_sd: 2 sigma^2 / tau = loss_scale_sd^2
    const double sigma = c.loss_scale_max_sd;
    GaussMarkov(ls_, sigma, 2.0 * sigma * sigma / (c.loss_scale_sd * c.loss_scale_sd), dt_s);
  }
  if (wb_ >= 0) GaussMarkov(wb_, c.winding_bias_sd_K, c.winding_bias_tau_s, dt_s);
  if (mb_ >= 0) GaussMarkov(mb_, c.magnet_bias_sd_K, c.magnet_bias_tau_s, dt_s);
  if (mu_ >= 0) GaussMarkov(mu_, c.line_voltage_error_sd_V, c.line_voltage_error_tau_s, dt_s);
  if (dr_state_ >= 0) {
    const double walk = c.calibration_walk_per_sqrt_h * c.calibration_walk_per_sqrt_h / 3600.0;
    sp_(dr_state_) = sp_(dpsi_) = walk * dt_s;
    if (law_free_) sp_(dpsi_) = c.free_flux_walk_per_sqrt_s * c.free_flux_walk_per_sqrt_s * dt_s;
    sp_(dbeta_) = c.magnet_law_sd_rel > 0.0 ? walk * dt_s : 0.0;
    GaussMarkov(u0_, c.voltage_offset_sd_V, c.voltage_offset_tau_s, dt_s);
  }
  filter_.Predict(ad_, bu_, sp_, nb);  // the rows after the network's: the augmented states'
  return true;
}

const ObserverReport& DisturbanceThermalSensor::Step(const ThermalInputs& in, double dt_s,
                                                     const ThermalReadings& r) {
  report_ = ObserverReport{};
  // Health is data: a period or inputs the model cannot take refuse the step (nothing changes).
  if (!(dt_s > 0.0) || !std::isfinite(dt_s) || !model_.AcceptsInputs(in) || !Predict(in, dt_s)) {
    refused_.measurements = 0;
    refused_.ok = false;
    refused_.refused = true;
    report_.update = &refused_;
    report_.refused = true;
    return report_;
  }
  Used used;
  used.frame = std::isfinite(r.frame_degC);
  if (used.frame) OpenOffsetOnStep(r.frame_degC);
  frame_fused_last_ = used.frame;
  used.winding = row_w_ >= 0 && std::isfinite(r.winding_degC);
  used.magnet = row_m_ >= 0 && std::isfinite(r.magnet_degC) && std::isfinite(r.magnet_winding_gain);
  const bool voltage =
      row_v_ >= 0 && std::isfinite(r.uq_V) && std::isfinite(r.iq_A) && std::isfinite(r.w_rad_per_s);
  if (!voltage) last_innovation_V_ = std::numeric_limits<double>::quiet_NaN();
  used.voltage = voltage && VoltageRow(r);
  report_.rejected_readings += voltage && !used.voltage;
  if (!used.Any()) {
    report_.update = &filter_.Update(c0_, y0_, sm0_);
    return report_;
  }
  FillRows(r, used);
  const KalmanUpdateReport& update = filter_.Update(c_all_, y_all_, sm_all_);
  if (used.frame) RememberReading(r.frame_degC);
  ReportRows(update, used);
  return report_;
}

double DisturbanceThermalSensor::MagnetBias_K(double voltage_gain_K_per_V) const {
  if (mb_ < 0) return 0.0;
  const Eigen::VectorXd& x = filter_.State();
  return x(mb_) + (mu_ >= 0 ? voltage_gain_K_per_V * x(mu_) : 0.0);
}

double DisturbanceThermalSensor::MagnetBiasSd_K(double voltage_gain_K_per_V) const {
  if (mb_ < 0) return std::numeric_limits<double>::quiet_NaN();
  const Eigen::MatrixXd& s = filter_.Covariance();
  double var = s(mb_, mb_);
  if (mu_ >= 0) {
    const double h = voltage_gain_K_per_V;
    var += h * h * s(mu_, mu_) + 2.0 * h * s(mb_, mu_);
  }
  return std::sqrt(std::max(var, 0.0));
}

double DisturbanceThermalSensor::RotorHeatDeficit_W2() const {
  const double sds = config_.rotor_heat_found_sds;
  if (!(sds > 0.0)) return 0.0;
  const double found_W = std::abs(filter_.State()(dr_)) / sds;
  if (!(found_W > config_.rotor_heat_sd_W)) return 0.0;
  return std::max(found_W * found_W - filter_.Covariance()(dr_, dr_), 0.0);
}

bool DisturbanceThermalSensor::VoltageRow(const ThermalReadings& r) {
  // Han 2019 eq. 6 with the copper and magnet laws (estimators/voltage_equation.hpp),
  // linearised at the predicted state: the row is its gradient, the observation uq less the
  // equation at the estimate plus the row times the estimate (an extended Kalman update).
  const Eigen::VectorXd& x = filter_.State();
  const Eigen::VectorXd& w = model_.WindingWeights();
  QAxisState q;
  q.winding_degC = w.dot(x.head(n_));
  q.magnet_degC = x(vmagnet_);
  q.dr = x(dr_state_);
  q.dpsi = x(dpsi_);
  q.dbeta = x(dbeta_);
  q.u0_V = x(u0_);
  const QAxisPoint p{r.iq_A, r.w_rad_per_s};
  const QAxisGradient g = QAxisGradientAt(config_.voltage_law, p, q);
  cv_row_.setZero();
  cv_row_.head(n_) = g.winding_V_per_K * w.transpose();
  cv_row_(vmagnet_) += g.magnet_V_per_K;
  cv_row_(dr_state_) = g.dr_V;
  cv_row_(dpsi_) = g.dpsi_V;
  cv_row_(dbeta_) = g.dbeta_V;
  cv_row_(u0_) = g.u0;
  const double innovation_V = r.uq_V - QAxisVoltage_V(config_.voltage_law, p, q);
  yv_ = innovation_V + cv_row_.dot(x);
  uq_sd_V_ = LearnVoltageNoise(innovation_V, r.uq_sd_V);
  const double gate = config_.voltage_gate_sd;
  if (!(gate > 0.0)) return true;
  const double variance = RowVariance(uq_sd_V_);
  const double beyond = innovation_V * innovation_V - gate * gate * variance;
  if (!(beyond > 0.0)) {
    voltage_rejected_run_ = 0;
    return true;
  }
  const int release = config_.voltage_gate_release_periods;
  if (release <= 0 || ++voltage_rejected_run_ < release) return false;
  // Released: the magnet's variance raised by what puts the row's innovation at the gate. With
  // the calibration learnt, a voltage that stays beyond the gate is heat the model lacks on the
  // magnet's side (the frame watches the rest); the rotor-heat state then follows the magnet.
  // Without the magnet law the flux is psi0's error alone, and that takes the release.
  const int k = law_free_ ? dpsi_ : vmagnet_;
  const double gk = cv_row_(k);
  if (!(std::abs(gk) > 0.0)) return false;
  filter_.AddVariance(k, beyond / (gate * gate * gk * gk));
  return true;
}

namespace {
/// White noise of sd s has a mean absolute value of sqrt(2 / pi) s; its successive differences
/// have sd sqrt(2) s and a mean absolute value of 2 s / sqrt(pi).
constexpr double kAbsPerSd = 0.7978845608028654;
constexpr double kStepPerSd = 1.1283791670955126;
/// One value moves a learnt mean by at most this many times the mean (over the learning
/// periods): a single jump of the estimate (a released gate, a sensor step) is no noise, while a
/// noise ten times the assumed one is learnt within ten periods.
constexpr double kClip = 10.0;
/// The weight of uq_min_sd_V at a start, in periods: the run-up, where psi0 is learnt, takes the
/// noise its first periods show rather than the assumed one.
constexpr double kAssumedPeriods = 2.0;
}  // namespace

void DisturbanceThermalSensor::AbsMean::Reset(double assumed) {
  mean = assumed;
  count = 0.0;
}

void DisturbanceThermalSensor::AbsMean::Add(double value, double periods) {
  // The mean of the values so far while they are fewer than the periods (the assumed one
  // counting as kAssumedPeriods of them), then an exponential average.
  count += 1.0;
  const double weight = std::min(count + kAssumedPeriods, periods);
  mean += (std::min(std::abs(value), kClip * mean) - mean) / weight;
}

double DisturbanceThermalSensor::LearnVoltageNoise(double innovation_V, double reading_sd_V) {
  const double least_V = std::isfinite(reading_sd_V) ? std::max(reading_sd_V, config_.uq_min_sd_V)
                                                     : config_.uq_min_sd_V;
  const double periods = config_.uq_noise_learn_periods;
  if (!(periods > 0.0) || !std::isfinite(innovation_V)) return least_V;
  uq_innovation_.Add(innovation_V, periods);
  if (std::isfinite(last_innovation_V_)) {
    uq_innovation_step_.Add(innovation_V - last_innovation_V_, periods);
  }
  last_innovation_V_ = innovation_V;
  // The innovations themselves overstate the noise by the estimate's slow error; their
  // differences overstate a noise whose successive periods pull apart (a ripple of a few
  // seconds) and cancel the slow error. The smaller of the two.
  const double noise_V =
      std::min(uq_innovation_.mean / kAbsPerSd, uq_innovation_step_.mean / kStepPerSd);
  return std::max(least_V, noise_V);
}

void DisturbanceThermalSensor::ForgetVoltageNoise() {
  uq_innovation_.Reset(kAbsPerSd * config_.uq_min_sd_V);
  uq_innovation_step_.Reset(kStepPerSd * config_.uq_min_sd_V);
  last_innovation_V_ = std::numeric_limits<double>::quiet_NaN();
}

void DisturbanceThermalSensor::WidenLossScale(double sd) {
  if (ls_ < 0 || !(sd > 0.0)) return;
  const double var = filter_.Covariance()(ls_, ls_);
  if (sd * sd > var) filter_.AddVariance(ls_, sd * sd - var);
}

void DisturbanceThermalSensor::FreeMagnetLaw() {
  if (dr_state_ < 0 || law_free_) return;
  Eigen::VectorXd x = filter_.State();
  Eigen::MatrixXd s = filter_.Covariance();
  FoldFluxLaw(x, s);
  if (dr_ >= 0) ForgetRotorHeat(x, s);
  filter_.Reset(x, 0.5 * (s + s.transpose()));
  RestoreMagnetLawGivenUp();
}

void DisturbanceThermalSensor::RestoreMagnetLawGivenUp() {
  if (dr_state_ < 0) return;
  config_.voltage_law.beta_per_K = 0.0;
  law_free_ = true;
  magnet_observed_ = false;
  voltage_rejected_run_ = 0;
}

void DisturbanceThermalSensor::FoldFluxLaw(Eigen::VectorXd& x, Eigen::MatrixXd& s) const {
  // psi0 (1 + dpsi) (1 + beta (1 + dbeta) (Tm - T0m)) = psi0 (1 + dpsi'): the new dpsi' and its
  // gradient in dpsi, Tm and dbeta (estimators/voltage_equation.hpp).
  const VoltageLaw& law = config_.voltage_law;
  const double beta = law.beta_per_K * (1.0 + x(dbeta_));
  const double rise_K = x(vmagnet_) - law.magnet_t0_degC;
  const double factor = 1.0 + beta * rise_K;
  Eigen::MatrixXd t = Eigen::MatrixXd::Identity(n_aug_, n_aug_);
  t.row(dpsi_).setZero();
  t(dpsi_, dpsi_) = factor;
  t(dpsi_, vmagnet_) = (1.0 + x(dpsi_)) * beta;
  t(dpsi_, dbeta_) = (1.0 + x(dpsi_)) * law.beta_per_K * rise_K;
  x(dpsi_) = (1.0 + x(dpsi_)) * factor - 1.0;
  s = t * s * t.transpose();
}

void DisturbanceThermalSensor::ForgetRotorHeat(Eigen::VectorXd& x, Eigen::MatrixXd& s) const {
  // The nodes' steady-state answer to the heat d_r had, from the last period's transition:
  // x = A x + b d_r at rest gives (I - A) dx = b d_r.
  const double heat_W = x(dr_);
  const Eigen::MatrixXd a = ad_.topLeftCorner(n_, n_);
  const Eigen::VectorXd b = ad_.col(dr_).head(n_);
  const Eigen::VectorXd dev_K =
      (Eigen::MatrixXd::Identity(n_, n_) - a).partialPivLu().solve(b) * heat_W;
  if (dev_K.allFinite()) s.topLeftCorner(n_, n_) += dev_K * dev_K.transpose();
  x(dr_) = 0.0;
  s.row(dr_).setZero();
  s.col(dr_).setZero();
  const double sd_W = config_.rotor_heat_sd_W;
  s(dr_, dr_) = sd_W * sd_W + heat_W * heat_W;
}

double DisturbanceThermalSensor::RowVariance(double sd) {
  // c S c^T + sd^2 over the row's nonzero coefficients: it reads a few of the states.
  std::size_t count = 0;
  for (Eigen::Index k = 0; k < cv_row_.size(); ++k) {
    if (cv_row_(k) != 0.0) row_nonzero_[count++] = k;
  }
  const Eigen::MatrixXd& s = filter_.Covariance();
  double quad = 0.0;
  for (std::size_t a = 0; a < count; ++a) {
    const Eigen::Index i = row_nonzero_[a];
    double sum = 0.0;
    for (std::size_t b = 0; b < count; ++b) sum += s(i, row_nonzero_[b]) * cv_row_(row_nonzero_[b]);
    quad += cv_row_(i) * sum;
  }
  return quad + sd * sd;
}

void DisturbanceThermalSensor::FillRows(const ThermalReadings& r, const Used& used) {
  const bool frame = used.frame, winding = used.winding, magnet = used.magnet;
  const auto& c = config_;
  // A missing reading: a zero row, zero innovation, unit variance (no gain, no effect).
  c_all_.setZero();
  sm_all_.setZero();
  y_all_.setZero();
  sm_all_(0, 0) = 1.0;
  if (frame) {
    sensor_model_.SetReadingRow(c_all_, 0);
    sm_all_(0, 0) = c.measurement_sd_K * c.measurement_sd_K;
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
      // z = T_magnet + g T_winding + bias + h e + white noise (h: the voltage gain).
      c_all_.row(row_m_) = cm_row_.row(0);
      c_all_.row(row_m_).head(n_) += r.magnet_winding_gain * model_.WindingWeights().transpose();
      if (mu_ >= 0) c_all_(row_m_, mu_) = r.magnet_voltage_gain_K_per_V;
      const double sd = std::isfinite(r.magnet_sd_K)
                            ? std::max(r.magnet_sd_K, c.magnet_min_white_sd_K)
                            : c.magnet_min_white_sd_K;
      sm_all_(row_m_, row_m_) = sd * sd;
      y_all_(row_m_) = r.magnet_degC;
    }
  }
  if (row_v_ >= 0) {
    sm_all_(row_v_, row_v_) = 1.0;
    if (used.voltage) {
      c_all_.row(row_v_) = cv_row_;
      sm_all_(row_v_, row_v_) = uq_sd_V_ * uq_sd_V_;
      y_all_(row_v_) = yv_;
    }
  }
}

void DisturbanceThermalSensor::ReportRows(const KalmanUpdateReport& update, const Used& used) {
  report_.update = &update;
  if (!update.ok) return;
  auto row = [&](ReadingRow& out, int i) {
    out.fused = true;
    out.innovation_K = update.innovation(i);
    out.innovation_var_K2 = update.innovation_var(i);
  };
  if (used.frame) row(report_.frame, 0);
  if (used.winding) row(report_.winding, row_w_);
  if (used.magnet) row(report_.magnet, row_m_);
  if (used.voltage) row(report_.voltage, row_v_);
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
  const double predicted = sensor_model_.PredictedReading_degC(filter_.State());
  const double step = (frame_degC - last_reading_degC_) - (predicted - last_predicted_degC_);
  // Two readings' white noise, and what the prediction since the last update added to the
  // uncertainty.
  const double noise = config_.sensor_step_noise_sd_K;
  const double var =
      2.0 * noise * noise +
      std::max(sensor_model_.PredictedReadingVar_K2(filter_.Covariance()) - last_predicted_var_K2_,
               0.0);
  if (!(step * step > gate * gate * var)) return;
  filter_.AddVariance(sensor_model_.offset(), step * step);
  ++sensor_steps_;
  last_sensor_step_K_ = step;
  stepped_offset_K_ += step;
}

void DisturbanceThermalSensor::RememberReading(double frame_degC) {
  last_reading_degC_ = frame_degC;
  last_predicted_degC_ = sensor_model_.PredictedReading_degC(filter_.State());
  last_predicted_var_K2_ = sensor_model_.PredictedReadingVar_K2(filter_.Covariance());
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
