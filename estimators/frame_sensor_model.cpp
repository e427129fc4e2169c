#include "estimators/frame_sensor_model.hpp"

#include <fmt/core.h>

#include <stdexcept>

namespace pumptherm::estimators {

FrameSensorModel::FrameSensorModel(const ThermalModel& model, const std::string& node, double lag_s,
                                   const char* who)
    : nodes_(model.StateCount()), node_(model.StateIndex(node)), lag_s_(lag_s) {
  if (node_ < 0) {
    throw std::invalid_argument(
        fmt::format("{}: measured node '{}' is not a node with heat capacity of model '{}'", who,
                    node, model.Name()));
  }
  if (!(lag_s >= 0.0))
    throw std::invalid_argument(fmt::format("{}: the sensor lag must be >= 0 s", who));
  if (lag_s > 0.0) lag_ = nodes_;
  sensor_ = lag_ >= 0 ? lag_ : node_;
}

void FrameSensorModel::AddLagRow(Eigen::MatrixXd& a_per_s) const {
  if (lag_ < 0) return;
  a_per_s(lag_, node_) = 1.0 / lag_s_;
  a_per_s(lag_, lag_) = -1.0 / lag_s_;
}

void FrameSensorModel::SetReadingRow(Eigen::MatrixXd& c, int row) const {
  c.row(row).setZero();
  c(row, sensor_) = 1.0;
  c(row, offset_) = 1.0;
}

void FrameSensorModel::SetInitial(double x0_degC, double common_sd_K, double spread_sd_K,
                                  double offset_sd_K, Eigen::VectorXd& x,
                                  Eigen::MatrixXd& s) const {
  const int temps = TemperatureStates();
  x.head(temps).setConstant(x0_degC);
  x(offset_) = 0.0;
  s.topLeftCorner(temps, temps).setConstant(common_sd_K * common_sd_K);
  s.topLeftCorner(temps, temps).diagonal().array() += spread_sd_K * spread_sd_K;
  s(offset_, offset_) = offset_sd_K * offset_sd_K;
}

}  // namespace pumptherm::estimators
