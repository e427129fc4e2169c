#pragma once
/// Sensor placement by the mean-square estimation error of the Kalman filter (Saheba et al.
/// 2010, IEEE CSM 30(1), eqs. 35-37):
///   MSE = (1/N) sum_n trace(W S^(n))                                              (36)
/// with S^(n) the a posteriori covariance from the Riccati difference equation (37) run with
/// the measurement of one candidate node; A_D takes three values (minimum, intermediate and
/// maximum current), each in effect over one third of the window. States are made
/// nondimensional by dividing by `scale` (the paper uses the final temperature rises of the
/// 50 A run of its Fig. 4), so trace(W T S T) with T = diag(1/scale).

#include <Eigen/Dense>
#include <string>
#include <vector>

#include "estimators/thermal_model.hpp"

namespace pumptherm::estimators {

struct PlacementConfig {
  /// Operating points whose A_D each hold for one third of the window (paper: min, mid, max).
  std::vector<ThermalInputs> operating_points;
  double dt_s = 1.0;                 ///< sampling time tau
  int steps = 5400;                  ///< window length N (all segments together)
  double measurement_sd_K = 0.0557;  ///< Sigma_m^(1/2), eq. 38
  double process_sd_K = 0.0894;      ///< Sigma_p^(1/2) per step, eq. 39
  double initial_sd_K = 10.0;        ///< S(0)^(1/2): the paper's ~10 degC initial errors
  Eigen::VectorXd scale_K;           ///< nondimensionalisation per state (n); empty = 1
};

/// MSE of one candidate.
struct PlacementRow {
  std::string node;
  double mse_all = 0.0;       ///< W = I
  double mse_windings = 0.0;  ///< W = 1 on the winding states (WindingWeights() > 0), else 0
};

/// One row per capacitive node, in state order. Throws std::invalid_argument when there is no
/// operating point or the scale has the wrong size or a zero.
std::vector<PlacementRow> SensorPlacement(const ThermalModel& model, const PlacementConfig& config);

/// The Riccati recursion of eq. 37 for a fixed `c` (m x n), returning the mean of
/// trace(W S^(n)) over the window: the building block of SensorPlacement, public for tests.
/// `ads` holds one A_D per segment.
double MeanPosteriorTrace(const std::vector<Eigen::MatrixXd>& ads, int steps,
                          const Eigen::MatrixXd& c, const Eigen::MatrixXd& sp,
                          const Eigen::MatrixXd& sm, const Eigen::MatrixXd& s0,
                          const Eigen::MatrixXd& w);

}  // namespace pumptherm::estimators
