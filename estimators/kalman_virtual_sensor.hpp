#pragma once
/// The virtual thermal sensor: the thermal network (ThermalModel) run as a Kalman filter
/// (Saheba et al. 2010, IEEE CSM 30(1), section "Virtual thermal sensor", eqs. 18-34), measuring
/// any subset of the nodes with capacity and, optionally, a few extra measurements with their own
/// variances: the winding temperature from resistance identification (Han et al. 2019 eq. 3, a
/// row of the model's winding weights) or a node's temperature from another estimator (the
/// magnet's from its flux linkage).
///
/// One Step() per period: the time update with the inputs held over the period (exact ZOH,
/// eqs. 20-21, re-discretised only when the operating point moves), then the measurement update
/// with whatever was measured at the end of the period (NaN = not measured this time).

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "estimators/kalman_filter.hpp"
#include "estimators/thermal_discretisation.hpp"
#include "estimators/thermal_model.hpp"
#include "estimators/thermal_observer.hpp"

namespace pumptherm::estimators {

/// Row of an extra measurement that reads the model's winding weights (the mean temperature of
/// the copper, ThermalModel::WindingWeights) instead of one node.
inline constexpr int kWindingWeightsRow = -1;

/// One extra measurement of one step: a temperature of one node (or of the winding weights)
/// with its own standard deviation. With a winding_gain g the row reads the node plus g times
/// the winding temperature (ThermalModel::WindingWeights): the back-EMF seen through an
/// identified line uq = Rs iq + w psi_f depends on the magnet and, through Rs, on the winding.
struct NodeMeasurement {
  int state = kWindingWeightsRow;  ///< state index, or kWindingWeightsRow
  double value_degC = std::numeric_limits<double>::quiet_NaN();  ///< NaN = not measured
  double sd_K = std::numeric_limits<double>::quiet_NaN();        ///< > 0 when value is finite
  double winding_gain = 0.0;  ///< g above (a node row only), dimensionless
};

/// A small fixed-capacity list of extra measurements: no allocation when filled every step.
class NodeMeasurements {
 public:
  static constexpr int kCapacity = 4;
  /// Appends one measurement. Returns false (and drops it) when the list is full.
  bool Add(int state, double value_degC, double sd_K, double winding_gain = 0.0) noexcept {
    if (size_ >= kCapacity) return false;
    items_[static_cast<std::size_t>(size_++)] =
        NodeMeasurement{state, value_degC, sd_K, winding_gain};
    return true;
  }
  void Clear() noexcept { size_ = 0; }
  int size() const noexcept { return size_; }
  const NodeMeasurement& operator[](int i) const { return items_[static_cast<std::size_t>(i)]; }

 private:
  std::array<NodeMeasurement, kCapacity> items_{};
  int size_ = 0;
};

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
  /// As a ThermalObserver: the node the magnet reading measures (empty: no magnet row) and
  /// whether the winding reading has a row (the model must have a winding). The frame reading
  /// reads the first of `measured_nodes`.
  std::string magnet_node;
  bool winding_reading = true;
  /// Least sd of the magnet reading, K (the identifier's covariance sees its noise, not its slow
  /// error: without a bias state that error is taken as white noise of this sd).
  double magnet_min_sd_K = 0.0;
};

class VirtualThermalSensor : public ThermalObserver {
 public:
  /// Throws std::invalid_argument naming a measured node or a magnet node that is not a node
  /// with capacity, or a non-positive standard deviation. Keeps a reference to `model`, which
  /// must outlive it.
  VirtualThermalSensor(const ThermalModel& model, VirtualSensorConfig config);

  /// Starts from `x0_degC` (n) with the configured initial covariance.
  void Initialise(const Eigen::VectorXd& x0_degC);
  /// Continues from a saved estimate `x_degC` (n) and covariance `s_K2` (n x n), e.g. restored
  /// by the daemon after a restart. Throws std::invalid_argument when !CanRestore.
  void Restore(const Eigen::VectorXd& x_degC, const Eigen::MatrixXd& s_K2) override;

  // As a ThermalObserver: its state is the nodes alone.
  int NodeCount() const override { return model_.StateCount(); }
  int StateCount() const override { return model_.StateCount(); }
  void Initialise(double x0_degC) override;
  void InitialiseKnown(double x0_degC, double sd_K) override;
  void InitialiseNodes(const Eigen::VectorXd& x_degC, const Eigen::MatrixXd& s_K2) override {
    Restore(x_degC, s_K2);
  }
  /// One period with the readings as rows: the frame (the first measured node), the winding
  /// (the winding weights, with the reading's sd, else winding_measurement_sd_K) and the magnet
  /// (its node plus g times the winding); every row is in every update once any reading is, a
  /// missing one as a zero row (no effect, no allocation). An invalid reading (an sd that is
  /// not positive and finite, a non-finite gain) is left out and counted.
  const ObserverReport& Step(const ThermalInputs& inputs, double dt_s,
                             const ThermalReadings& readings) override;
  const Eigen::VectorXd& State() const override { return filter_.State(); }
  const Eigen::MatrixXd& Covariance() const override { return filter_.Covariance(); }
  bool CanRestore(const Eigen::VectorXd& x, const Eigen::MatrixXd& s) const override;
  double NodeSd_K(int i) const override {
    return std::sqrt(std::max(filter_.Covariance()(i, i), 0.0));
  }
  double WeightedVariance_K2(const Eigen::VectorXd& w) const override;
  /// The largest node sd.
  double SettlingSd_K() const override;

  /// Advances one period of `dt_s` with `inputs` held over it, then corrects with
  /// `measured_degC` (one per configured measured node, NaN = not measured; these rows come
  /// first in the report) and every entry of `extra` whose value is finite (in list order).
  /// Returns the update's report; health is data, nothing is thrown: non-finite inputs or a
  /// period that is not positive and finite refuse the step (report.refused, nothing changes);
  /// an extra measurement of a state that does not exist, or with a finite value and an sd that
  /// is not positive and finite or a non-finite winding gain, is left out and counted
  /// (report.rejected_measurements). An extra measurement that reads the winding weights (its
  /// row, or a non-zero winding gain) is skipped when the model has no winding. No allocation
  /// once the operating point and the count of valid measurements are steady.
  const KalmanUpdateReport& Step(const ThermalInputs& inputs, double dt_s,
                                 const Eigen::VectorXd& measured_degC,
                                 const NodeMeasurements& extra);
  /// The same with one extra measurement: `winding_degC` (the resistance-based winding
  /// temperature, NaN = none) with standard deviation `winding_sd_K` (NaN or not positive: the
  /// configured winding_measurement_sd_K).
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
  /// Whether extra measurement `e` enters the update; `rejected` is set when it is invalid.
  bool Uses(const NodeMeasurement& e, bool* rejected = nullptr) const;
  /// The time update of one period; false when the model cannot be linearised there.
  bool Predict(const ThermalInputs& inputs, double dt_s);
  /// The observer's rows (frame, winding, magnet) sized once.
  void BuildObserverRows();

  const ThermalModel& model_;
  VirtualSensorConfig config_;
  std::vector<int> measured_states_;
  ThermalLinearModel lin_;
  ThermalDiscretiser discretiser_;
  KalmanFilter filter_;
  KalmanUpdateReport report_;  // the last step's (the filter's update plus the step's own health)
  Eigen::VectorXd bu_;
  Eigen::MatrixXd sp_;
  Eigen::MatrixXd c_;
  Eigen::VectorXd y_;
  Eigen::MatrixXd sm_;
  NodeMeasurements winding_only_;
  double sp_dt_s_ = -1.0;
  // As a ThermalObserver: fixed rows (frame, then winding, then magnet) and their report.
  int magnet_state_ = -1;
  int row_w_ = -1, row_m_ = -1;
  Eigen::MatrixXd obs_c_, obs_sm_, obs_c0_, obs_sm0_;
  Eigen::VectorXd obs_y_, obs_y0_;
  ObserverReport obs_report_;
  mutable Eigen::VectorXd sw_;
};

/// The estimate `x` (degC) and its covariance `s` (K^2) carried over `gap_s` with the inputs `in`
/// held: the exact zero-order-hold time update (Saheba 2010 eqs. 30-31) over the whole gap, with
/// the process noise of `config` as a random walk over it. For a restart after the daemon was
/// down. False (x and s unchanged) when the model cannot be linearised at these inputs.
bool PredictOverGap(const ThermalModel& model, const ThermalInputs& in, double gap_s,
                    const VirtualSensorConfig& config, Eigen::VectorXd& x, Eigen::MatrixXd& s);

}  // namespace pumptherm::estimators
