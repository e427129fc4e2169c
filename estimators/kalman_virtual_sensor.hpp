#pragma once
/// The virtual thermal sensor: the thermal network (ThermalModel) run as a Kalman filter
/// (Saheba et al. 2010, IEEE CSM 30(1), section "Virtual thermal sensor", eqs. 18-34), measuring
/// any subset of the nodes with capacity and, optionally, the winding temperature from resistance
/// identification (Han et al. 2019 eq. 3) as a second measurement with its own variance.
///
/// One Step() per period: the time update with the inputs held over the period (exact ZOH,
/// eqs. 20-21, re-discretised only when the operating point moves), then the measurement update
/// with whatever was measured at the end of the period (NaN = not measured this time).

#include <Eigen/Dense>
#include <limits>
#include <string>
#include <vector>

#include "estimators/kalman_filter.hpp"
#include "estimators/thermal_discretisation.hpp"
#include "estimators/thermal_model.hpp"

namespace pumptherm::estimators {

/// Covariances and options. Defaults are the paper's (eqs. 38-39).
struct VirtualSensorConfig {
  /// Capacitive nodes that a sensor measures (the frame in the paper).
  std::vector<std::string> measured_nodes{"frame"};
  /// Sigma_m^(1/2) of eq. 38, K: measurement noise of each node sensor.
  double measurement_sd_K = 0.0557;
  /// Sigma_p^(1/2) of eq. 39, K per `process_period_s`: process noise of every state. For other
  /// periods the variance is scaled by dt / process_period_s (a random walk in continuous time).
  double process_sd_K = 0.0894;
  double process_period_s = 1.0;
  /// Standard deviation of the resistance-based winding temperature, K, when it is fused.
  double winding_measurement_sd_K = 2.0;
  /// Initial covariance for unknown initial temperatures, K:
  ///   S(0) = initial_sd_K^2 (1 1^T) + initial_spread_sd_K^2 I,
  /// a large uncertainty common to all nodes (the machine's temperature level) plus a smaller
  /// independent one per node (how far the nodes may be apart). The common part lets one
  /// sensor correct the level of every node at the first update.
  double initial_sd_K = 20.0;
  double initial_spread_sd_K = 5.0;
  /// Relative change of the continuous system matrix that triggers a new discretisation.
  double relinearise_tolerance = 1e-3;
  CovarianceUpdate covariance_update = CovarianceUpdate::kJoseph;
};

class VirtualThermalSensor {
 public:
  /// Throws std::invalid_argument naming a measured node that is not a node with capacity, or
  /// a non-positive standard deviation. Keeps a reference to `model`, which must outlive it.
  VirtualThermalSensor(const ThermalModel& model, VirtualSensorConfig config);

  /// Starts from `x0_degC` (n) with the configured initial covariance.
  void Initialise(const Eigen::VectorXd& x0_degC);
  /// Continues from a saved estimate `x_degC` (n) and covariance `s_K2` (n x n), e.g. restored
  /// by the daemon after a restart.
  void Restore(const Eigen::VectorXd& x_degC, const Eigen::MatrixXd& s_K2) { filter_.Reset(x_degC, s_K2); }

  /// Advances one period of `dt_s` with `inputs` held over it, then corrects with
  /// `measured_degC` (one per configured measured node, NaN = not measured) and, if finite,
  /// `winding_degC` (the resistance-based winding temperature) with standard deviation
  /// `winding_sd_K` (NaN or not positive: winding_measurement_sd_K). Returns the update's report.
  /// No allocation once the operating point and the count of valid measurements are steady.
  /// Throws std::domain_error for non-finite inputs (from the model) or dt_s <= 0.
  const KalmanUpdateReport& Step(const ThermalInputs& inputs, double dt_s,
                                 const Eigen::VectorXd& measured_degC, double winding_degC,
                                 double winding_sd_K = std::numeric_limits<double>::quiet_NaN());

  const Eigen::VectorXd& Estimate_degC() const { return filter_.State(); }
  const Eigen::MatrixXd& Covariance_K2() const { return filter_.Covariance(); }
  const KalmanFilter& Filter() const { return filter_; }
  const ThermalDiscretiser& Discretiser() const { return discretiser_; }
  const ThermalModel& Model() const { return model_; }
  const std::vector<int>& MeasuredStates() const { return measured_states_; }

 private:
  const ThermalModel& model_;
  VirtualSensorConfig config_;
  std::vector<int> measured_states_;
  ThermalLinearModel lin_;
  ThermalDiscretiser discretiser_;
  KalmanFilter filter_;
  Eigen::VectorXd bu_;
  Eigen::MatrixXd sp_;
  Eigen::MatrixXd c_;
  Eigen::VectorXd y_;
  Eigen::MatrixXd sm_;
  double sp_dt_s_ = -1.0;
};

}  // namespace pumptherm::estimators
