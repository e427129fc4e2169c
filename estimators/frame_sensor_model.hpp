#pragma once
/// The frame sensor as states of an augmented thermal filter, built once for every filter that
/// reads it (the disturbance-state virtual sensor, the mismatch test): the sensor's first-order
/// lag s (tau ds/dt = T - s, when it has one; the state right after the network's nodes) and
/// its constant calibration offset b; the reading is y = s + b (or T + b without a lag).
///
/// Pure library; no allocation after construction.

#include <Eigen/Dense>
#include <cmath>
#include <string>

#include "estimators/thermal_model.hpp"

namespace pumptherm::estimators {

class FrameSensorModel {
 public:
  /// The sensor on `node` of `model` with a lag of `lag_s` (0: none). Throws
  /// std::invalid_argument, naming `who`, for a node that is not a node with heat capacity of
  /// the model or a negative lag.
  FrameSensorModel(const ThermalModel& model, const std::string& node, double lag_s,
                   const char* who);

  int node() const { return node_; }      ///< the node the sensor sits on
  int lag() const { return lag_; }        ///< the lag state (n), -1 without a lag
  int sensor() const { return sensor_; }  ///< the state the reading follows: lag or node
  int offset() const { return offset_; }  ///< the offset state, once placed (-1 before)
  bool has_lag() const { return lag_ >= 0; }
  /// A sensor with a lag gets `lag_s` (> 0) from now (AddLagRow writes it); false, nothing
  /// changed, for a sensor without a lag state or a lag that is not positive.
  bool SetLag(double lag_s) {
    if (lag_ < 0 || !(lag_s > 0.0) || !std::isfinite(lag_s)) return false;
    lag_s_ = lag_s;
    return true;
  }
  /// The nodes and the lag: the block discretised together (the lag is part of the ZOH).
  int TemperatureStates() const { return lag_ >= 0 ? nodes_ + 1 : nodes_; }
  /// Places the offset state at `index` (past the temperature states).
  void PlaceOffset(int index) { offset_ = index; }

  /// The lag's row of the continuous temperature block `a_per_s` (TemperatureStates() square):
  /// ds/dt = (T - s) / tau. Nothing without a lag.
  void AddLagRow(Eigen::MatrixXd& a_per_s) const;
  /// Row `row` of `c` (columns: the filter's states) set to the reading y = s + b.
  void SetReadingRow(Eigen::MatrixXd& c, int row) const;
  /// The temperature states of `x` at `x0_degC` and the offset at 0; in `s` the nodes and the
  /// lag share one level of sd `common_sd_K` plus `spread_sd_K` each on their own, and the
  /// offset has `offset_sd_K`. Entries of other states are left as they are.
  void SetInitial(double x0_degC, double common_sd_K, double spread_sd_K, double offset_sd_K,
                  Eigen::VectorXd& x, Eigen::MatrixXd& s) const;
  /// The reading the state `x` predicts (s + b) and its variance under `p`.
  double PredictedReading_degC(const Eigen::VectorXd& x) const { return x(sensor_) + x(offset_); }
  double PredictedReadingVar_K2(const Eigen::MatrixXd& p) const {
    return p(sensor_, sensor_) + 2.0 * p(sensor_, offset_) + p(offset_, offset_);
  }

 private:
  int nodes_ = 0;
  int node_ = -1, lag_ = -1, sensor_ = -1, offset_ = -1;
  double lag_s_ = 0.0;
};

}  // namespace pumptherm::estimators
