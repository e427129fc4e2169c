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

/// The load a telemetry silence may hide at its worst: the motor's largest current all on the q
/// axis (the copper loss goes with |i|^2, the rotor's with |iq|) at its largest speed, the
/// ambient held (SilenceBound).
struct SilenceWorstLoad {
  /// |i_dq| the drive allows, A (MotorDescription::max_current_A); 0: not known, no worst case
  /// while silent.
  double max_current_A = 0.0;
  /// The largest speed, r/min (the motor's rated speed); a larger held speed is kept.
  double max_speed_rpm = 0.0;
};

/// The inputs of `held` with the currents and the speed raised to `worst`: iq the larger of
/// max_current_A and |i| held, id 0, the speed the larger of max_speed_rpm and |speed| held.
ThermalInputs WorstInputs(const ThermalInputs& held, const SilenceWorstLoad& worst);

/// A telemetry silence hides the load: the estimate runs on with the inputs from before it.
/// Two bounds cover what the truth may have done meanwhile (docs/daemon.md, "The pipeline, per
/// pump"):
///  - while silent, the worst case: the model from the estimate at the silence's start, run at
///    the motor's largest current and speed (WorstInputs; a thermal network is cooperative and
///    every loss grows with the current and the speed, so no load the drive allows heats any
///    node more). The levels act on it as it was `delay_s` earlier (delayed_worst_degC): the
///    trip comes `delay_s` after the earliest moment any allowed load could have crossed the
///    level, never later, and a silence shorter than that never trips. The published band
///    reaches the worst case now (worst_degC). Both end when the frames return;
///  - once the frames are back, a load that rose during the silence is seen, and the estimate
///    starts from too cold a state. The truth can have run the higher of the loads before and
///    after the silence for all of it: this bound (bound_degC) re-runs the silence with those
///    worse inputs from the estimate at its start, then runs on with the live inputs, and is
///    dropped once it no longer lies above the estimate's upper bound (mean + k sd) on any node.
class SilenceBound {
 public:
  /// `worst` the load a silence may hide (max_current_A 0: no worst case while silent);
  /// `delay_s` (>= 0) how long after the worst case the levels act on it.
  explicit SilenceBound(const SilenceWorstLoad& worst = {}, double delay_s = 0.0);
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
  /// too). The next step with inputs ends it as any silence. The worst case while silent starts
  /// at `now_s` from `now_degC` (the state aged to the restart): the time down is judged once
  /// the frames are back, as any silence, and a restart alone trips nothing.
  void Begin(const Eigen::VectorXd& x_degC, const ThermalInputs& in, double start_s,
             const Eigen::VectorXd& now_degC, double now_s);
  /// Forgets everything (the filter was reset).
  void Reset();
  /// The bound after a silence, degC per state; size 0 while there is none.
  const Eigen::VectorXd& bound_degC() const { return bound_degC_; }
  /// While silent for longer than min_silence_s: the worst case now, degC per state (size 0:
  /// none).
  const Eigen::VectorXd& worst_degC() const { return acting_ ? worst_now_degC_ : none_; }
  /// The worst case as it was delay_s ago, degC per state (size 0: none yet): what the levels
  /// act on while silent.
  const Eigen::VectorXd& delayed_worst_degC() const {
    return acting_ && then_s_ > from_s_ ? worst_then_degC_ : none_;
  }

 private:
  /// `x` run for `dt_s` at `in`; false when the model cannot be linearised there.
  static bool Propagate(const ThermalModel& model, const ThermalInputs& in, double dt_s,
                        Eigen::VectorXd& x);
  /// One silent step ending at `end_s`: both worst-case trajectories run on.
  void StepWorstCase(const ThermalModel& model, double end_s, double min_silence_s);
  /// `x`, at time `at_s`, run at the worst inputs to `to_s` (nothing when not later).
  bool RunWorstTo(const ThermalModel& model, double to_s, Eigen::VectorXd& x, double& at_s) const;
  void EndWorstCase();

  SilenceWorstLoad worst_;
  double delay_s_ = 0.0;
  Eigen::VectorXd start_degC_;  // the estimate after the last step with inputs
  ThermalInputs start_inputs_;  // that step's inputs (held through the silence)
  double start_s_ = 0.0;        // that step's end
  Eigen::VectorXd bound_degC_;
  // The worst case while silent: where it starts (the estimate after the last step with inputs,
  // or at a restart), and its runs to now and to delay_s earlier, each with the time it has
  // been run to.
  Eigen::VectorXd from_degC_;
  ThermalInputs from_inputs_;
  double from_s_ = 0.0;
  ThermalInputs worst_inputs_;
  Eigen::VectorXd worst_now_degC_, worst_then_degC_, none_;
  double now_s_ = 0.0, then_s_ = 0.0;
  bool acting_ = false;
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
