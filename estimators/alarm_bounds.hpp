#pragma once
/// Upper bounds on node temperatures for the alarm levels where the virtual sensor's estimate is
/// known to run low: a lagging frame sensor while the housing warms (LagBias) and a telemetry
/// silence during which the load may have risen unseen (SilenceBound). Pure logic: time enters
/// as the step count and period, nothing is logged (docs/daemon.md, "Alarm rule").

#include <Eigen/Dense>
#include <cstddef>
#include <vector>

#include "estimators/thermal_model.hpp"

namespace pumptherm::estimators {

/// How far a first-order-lag sensor's reading y trails the temperature T of its node: the lag
/// obeys tau dy/dt = T - y, so T - y = tau dy/dt, and over a steady ramp the rise of the reading
/// over the last tau, y(t) - y(t - tau), equals it exactly. A filter that fuses y as if it were T
/// is pulled low by about this much while the node warms (high while it cools: the safe side,
/// not counted).
class LagBias {
 public:
  /// `lag_s` the sensor's time constant (0: no lag, the bias is always 0), `period_s` the step
  /// period. Keeps round(lag_s / period_s) readings. Throws std::invalid_argument for a negative
  /// lag or a non-positive period.
  LagBias(double lag_s, double period_s);
  /// One step's fused reading (NaN: none this step). Returns the bias, K: y(t) - y(t - tau) when
  /// both are known and positive, else 0 (unknown counts as none: a sensor not fused does not
  /// pull the estimate).
  double Step(double reading_degC);
  /// The last value Step returned, K.
  double bias_K() const { return bias_K_; }

 private:
  std::vector<double> window_degC_;  // ring of the last readings (NaN: none)
  std::size_t next_ = 0;
  double bias_K_ = 0.0;
};

/// After a telemetry silence the estimate has run on with the inputs from before it, so a load
/// that rose during the silence is seen only when the frames return, and the estimate starts
/// from too cold a state. The truth can have run the higher of the loads before and after the
/// silence for all of it: this bound re-runs the silence with those worse inputs from the
/// estimate at its start, then runs on with the live inputs, and is dropped once it no longer
/// lies above the estimate's upper bound (mean + k sd) on any node.
class SilenceBound {
 public:
  /// One thermal step of `period_s` ending at `end_s` (monotonic). `fresh`: this step had
  /// telemetry inputs; `in` its inputs (the held ones when not fresh); `x_degC` and `sd_K` the
  /// estimate after the step (n states); `min_silence_s` a silence shorter than this is not one
  /// (stale_after_s); `k` the factor of the upper bound that ends the bound. A model that cannot
  /// be linearised at these inputs drops the bound (never throws).
  void Step(const ThermalModel& model, const ThermalInputs& in, bool fresh,
            const Eigen::VectorXd& x_degC, const Eigen::Ref<const Eigen::VectorXd>& sd_K,
            double end_s, double period_s, double min_silence_s, double k);
  /// Starts a silence at `start_s` from the estimate `x_degC` with the inputs `in` then held (a
  /// restart: the state saved before it; while the daemon was down the load may have risen
  /// too). The next step with inputs ends it as any silence.
  void Begin(const Eigen::VectorXd& x_degC, const ThermalInputs& in, double start_s);
  /// Forgets everything (the filter was reset).
  void Reset();
  /// The bound, degC per state; size 0 while there is none.
  const Eigen::VectorXd& bound_degC() const { return bound_degC_; }

 private:
  /// `x` run for `dt_s` at `in`; false when the model cannot be linearised there.
  static bool Propagate(const ThermalModel& model, const ThermalInputs& in, double dt_s,
                        Eigen::VectorXd& x);

  Eigen::VectorXd start_degC_;  // the estimate after the last step with inputs
  ThermalInputs start_inputs_;  // that step's inputs (held through the silence)
  double start_s_ = 0.0;        // that step's end
  Eigen::VectorXd bound_degC_;
};

/// While no temperature is measured (the frame sensor failed and no fresh resistance temperature
/// stands in), the levels are checked against the worst case: the model with every heat path to
/// the boundary lost (a cooling failure nothing could see), run from the estimate at the moment
/// the measurements stopped.
class BlindBound {
 public:
  /// One blind step of `period_s` at `in`; the first step after Reset starts from `estimate_degC`.
  /// A model that cannot be linearised at these inputs makes the bound NaN (the levels then see
  /// the estimate alone); never throws.
  void Step(const ThermalModel& model, const ThermalInputs& in, double period_s,
            const Eigen::VectorXd& estimate_degC);
  /// Not blind (any more): no bound.
  void Reset() { bound_degC_.resize(0); }
  /// The bound, degC per state; size 0 while not blind.
  const Eigen::VectorXd& bound_degC() const { return bound_degC_; }

 private:
  ThermalLinearModel lin_;
  Eigen::VectorXd bound_degC_;
};

/// `lin` with its heat paths to the boundary (ambient or coolant at `boundary_degC`) removed: a
/// row of A summing to less than zero leaks heat out of the network (interior conduction sums to
/// zero in each row; a copper temperature coefficient adds to it), so that leak leaves the
/// diagonal and its boundary term leaves f.
void WithoutBoundaryPaths(ThermalLinearModel& lin, double boundary_degC);

/// Inputs at least as heating as both `a` and `b`: each current, the speed and the ambient at
/// the larger magnitude (every loss of the thermal models grows with them).
ThermalInputs WorseInputs(const ThermalInputs& a, const ThermalInputs& b);

}  // namespace pumptherm::estimators
