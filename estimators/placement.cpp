#include "estimators/placement.hpp"

#include <stdexcept>

#include "estimators/kalman_filter.hpp"
#include "estimators/thermal_discretisation.hpp"

namespace pumptherm::estimators {

double MeanPosteriorTrace(const std::vector<Eigen::MatrixXd>& ads, int steps,
                          const Eigen::MatrixXd& c, const Eigen::MatrixXd& sp,
                          const Eigen::MatrixXd& sm, const Eigen::MatrixXd& s0,
                          const Eigen::MatrixXd& w) {
  if (ads.empty() || steps <= 0) throw std::invalid_argument("MeanPosteriorTrace: empty window");
  const Eigen::Index n = s0.rows();
  KalmanFilter kf(static_cast<int>(n));
  kf.Reset(Eigen::VectorXd::Zero(n), s0);
  const Eigen::VectorXd zero_u = Eigen::VectorXd::Zero(n);
  const Eigen::VectorXd zero_y = Eigen::VectorXd::Zero(c.rows());
  double sum = 0.0;
  const int segments = static_cast<int>(ads.size());
  for (int k = 0; k < steps; ++k) {
    const int seg = std::min(segments - 1, k * segments / steps);
    // Eq. 37 is the time update followed by the measurement update of the covariance; the
    // Joseph-form update with the optimal gain equals it.
    kf.Predict(ads[static_cast<std::size_t>(seg)], zero_u, sp);
    kf.Update(c, zero_y, sm);
    sum += (w * kf.Covariance()).trace();
  }
  return sum / steps;
}

std::vector<PlacementRow> SensorPlacement(const ThermalModel& model,
                                          const PlacementConfig& config) {
  const int n = model.StateCount();
  if (config.operating_points.empty()) {
    throw std::invalid_argument("SensorPlacement: no operating point");
  }
  Eigen::VectorXd scale = config.scale_K.size() == 0 ? Eigen::VectorXd::Ones(n) : config.scale_K;
  if (scale.size() != n || (scale.array() == 0.0).any()) {
    throw std::invalid_argument("SensorPlacement: the scale needs one non-zero value per state");
  }
  std::vector<Eigen::MatrixXd> ads;
  ThermalLinearModel lin;
  ThermalDiscreteModel d;
  const Eigen::VectorXd inv = scale.cwiseInverse();
  for (const ThermalInputs& op : config.operating_points) {
    model.Linearise(op, lin);
    DiscretiseZoh(lin.a_per_s, config.dt_s, d);
    // Nondimensional states x' = T x: A_D' = T A_D T^-1.
    ads.push_back(inv.asDiagonal() * d.ad * scale.asDiagonal());
  }
  const Eigen::MatrixXd sp =
      (config.process_sd_K * config.process_sd_K) * inv.cwiseAbs2().asDiagonal().toDenseMatrix();
  const Eigen::MatrixXd s0 =
      (config.initial_sd_K * config.initial_sd_K) * inv.cwiseAbs2().asDiagonal().toDenseMatrix();
  const Eigen::MatrixXd sm =
      Eigen::MatrixXd::Constant(1, 1, config.measurement_sd_K * config.measurement_sd_K);
  const Eigen::MatrixXd w_all = Eigen::MatrixXd::Identity(n, n);
  Eigen::MatrixXd w_wind = Eigen::MatrixXd::Zero(n, n);
  for (int s = 0; s < n; ++s) {
    if (model.WindingWeights()(s) > 0.0) w_wind(s, s) = 1.0;
  }
  std::vector<PlacementRow> rows;
  for (int s = 0; s < n; ++s) {
    Eigen::MatrixXd c = Eigen::MatrixXd::Zero(1, n);
    c(0, s) = scale(s);  // y = x_s = scale_s x'_s
    PlacementRow row;
    row.node = model.StateNames()[static_cast<std::size_t>(s)];
    row.mse_all = MeanPosteriorTrace(ads, config.steps, c, sp, sm, s0, w_all);
    row.mse_windings = MeanPosteriorTrace(ads, config.steps, c, sp, sm, s0, w_wind);
    rows.push_back(row);
  }
  return rows;
}

}  // namespace pumptherm::estimators
