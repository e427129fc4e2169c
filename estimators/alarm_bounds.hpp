#pragma once
/// Upper bounds on node temperatures for the alarm levels where the virtual sensor's estimate is
/// known to run low: a lagging frame sensor while the housing warms (LagBias) and a telemetry
/// silence during which the load may have risen unseen (SilenceBound). Pure logic: time enters
/// as the step count and period, nothing is logged (docs/daemon.md, "Alarm rule").

#include <Eigen/Dense>
#include <cstddef>
#include <limits>
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

/// What the model-mismatch test says about heat inside the pump, for InsideHeatBound.
enum class InsideHeatVerdict {
  kUnchanged,  ///< nothing new (consistent, learning, not named yet, a sensor fault)
  kInside,     ///< a plant change named as heat on the rotor (rotor_loss)
  kFramePath,  ///< a plant change named on the frame path (cooling, an unmeasured ambient)
};

/// Heat the model lacks that the frame sensor sees may be on the frame path (lost cooling, an
/// unmeasured ambient) or inside the pump (a bearing, gas friction, eddy currents: heat on the
/// rotor). Where the boundary reaches the network through the measured node alone
/// (BoundaryOnlyThrough), the two heat the frame alike at steady state, and the frame-path heat
/// of the disturbance-state filter (a fast random walk) takes either at once: heat on the rotor
/// leaves its estimate low by about K_i W (K below) while its rotor-heat state keeps its prior
/// (docs/virtual-sensor.md, "Heat inside, from the frame alone").
///
/// Once the mismatch test names heat inside, this bound is the nodes as they would be if the
/// frame-path heat found since the fitted onset, W = max(d_f(t) - d_f(onset), 0), were on the
/// rotor instead: x_i + K_i W with K = G_rotor - G_measured, where G_j = -A^-1 e_j / C_j is the
/// network's steady-state rise per watt put on node j (A at standstill: conduction alone; C_j
/// node j's heat capacity). Steady-state gains also hold through the rise: the rotor's excess
/// over the frame is proportional to the heat leaving it, which is what reaches the frame and
/// what d_f follows. The bound is the rotor hypothesis's central value, not a worst case, so
/// the published band reaches past it by the filter's own 2 sd (AlarmValues::PublishedSd_K). It
/// holds (latched) until the test names a frame-path cause or the filter restarts: the test
/// clears hours into a lasting fault (its low-noise filter adapts), the heat stays.
///
/// Pure logic; allocates at construction only.
class InsideHeatBound {
 public:
  /// Gains from `model` between `rotor` and `measured` (state indices; either negative or both
  /// the same: no bound). The fitted onset may lie up to `history_s` back (the test's fit
  /// window); d_f is kept every `sample_s` to find it. Throws std::invalid_argument for a
  /// history or a sample period that is not positive.
  InsideHeatBound(const ThermalModel& model, int measured, int rotor, double history_s,
                  double sample_s);
  /// One step ending at `now_s` (monotonic) with the filter's frame-path heat `frame_path_W`
  /// (NaN: none this step) and the test's `verdict` with its fitted onset `onset_s` (NaN: none,
  /// the oldest kept value is taken).
  void Step(double now_s, double frame_path_W, InsideHeatVerdict verdict, double onset_s);
  /// Forgets everything (the filter was reset or restarted).
  void Reset();
  bool latched() const { return latched_; }
  /// The heat the bound puts on the rotor, W (0 when not latched).
  double heat_W() const { return heat_W_; }
  /// How far node i's bound lies above its estimate, K (>= 0).
  double shift_K(int i) const {
    return gain_K_per_W_.size() > i ? gain_K_per_W_(i) * heat_W_ : 0.0;
  }
  /// K per watt, per state (empty: no bound for this model).
  const Eigen::VectorXd& gain_K_per_W() const { return gain_K_per_W_; }

 private:
  /// The kept frame-path heat at the latest sample at or before `t_s` (the oldest when none is).
  double KeptAt(double t_s) const;

  Eigen::VectorXd gain_K_per_W_;
  double sample_s_ = 10.0;
  std::vector<double> kept_s_, kept_W_;  ///< a ring (time NaN: empty)
  std::size_t next_ = 0;
  double last_kept_s_ = -std::numeric_limits<double>::infinity();
  bool latched_ = false;
  double base_W_ = 0.0, heat_W_ = 0.0;
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
