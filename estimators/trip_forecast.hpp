#pragma once
/// Time to trip: how long until a node's estimate reaches its trip level if the present inputs
/// are held, from the thermal network's trajectory (exact zero-order-hold steps of the linearised
/// model, Saheba 2010 eqs. 30-31 without the measurement update). Pure: no clocks, no logging,
/// no allocation per call once sized.

#include <Eigen/Dense>
#include <vector>

#include "estimators/thermal_discretisation.hpp"
#include "estimators/thermal_model.hpp"
#include "estimators/thermal_observer.hpp"

namespace pumptherm::estimators {

class TripForecast {
 public:
  /// Forecast steps and horizon: a trip further away than kLimit_s is "not foreseen" (infinity).
  static constexpr double kStep_s = 10.0;
  static constexpr double kLimit_s = 6.0 * 3600.0;

  /// For a model of `states` states.
  explicit TripForecast(int states);

  /// Seconds until the first node of `x_degC` reaches its level in `trip_degC` (one per state;
  /// infinity: no trip level) with the inputs `in` held; 0 when one is already there, infinity
  /// when none gets there within kLimit_s (first the steady state is checked: a network whose
  /// steady state stays below every level never trips). `node` gets the node that trips first
  /// (-1: none). With `observer`, the heat it has found (ThermalObserver::AddFoundHeat: the
  /// disturbance-state filter's frame path and rotor) is held too. A model that cannot be
  /// linearised or solved at these inputs: infinity.
  double TimeToTrip_s(const ThermalModel& model, const ThermalInputs& in,
                      const Eigen::VectorXd& x_degC, const std::vector<double>& trip_degC,
                      const ThermalObserver* observer, int* node);

 private:
  ThermalLinearModel lin_;
  ThermalDiscretiser disc_{1e-3};
  Eigen::VectorXd x_, next_, steady_;
  Eigen::PartialPivLU<Eigen::MatrixXd> lu_;
};

}  // namespace pumptherm::estimators
