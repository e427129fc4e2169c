#include "estimators/alarm_bounds.hpp"

#include <algorithm>
#include <cmath>
#include <exception>
#include <limits>
#include <stdexcept>

#include "estimators/thermal_discretisation.hpp"

namespace pumptherm::estimators {

LagBias::LagBias(double lag_s, double period_s) {
  if (!(lag_s >= 0.0) || !(period_s > 0.0)) {
    throw std::invalid_argument("LagBias: the lag must be >= 0 s and the period > 0 s");
  }
  const auto n = static_cast<std::size_t>(std::llround(lag_s / period_s));
  window_degC_.assign(n, std::numeric_limits<double>::quiet_NaN());
}

double LagBias::Step(double reading_degC) {
  bias_K_ = 0.0;
  if (window_degC_.empty()) return bias_K_;
  // window_degC_[next_] is the reading of round(lag / period) steps ago.
  const double then_degC = window_degC_[next_];
  window_degC_[next_] = reading_degC;
  next_ = (next_ + 1) % window_degC_.size();
  const double rise_K = reading_degC - then_degC;  // NaN when either is unknown
  if (rise_K > 0.0) bias_K_ = rise_K;
  return bias_K_;
}

ThermalInputs WorseInputs(const ThermalInputs& a, const ThermalInputs& b) {
  ThermalInputs w;
  w.speed_rpm = std::max(std::abs(a.speed_rpm), std::abs(b.speed_rpm));
  w.id_A = std::max(std::abs(a.id_A), std::abs(b.id_A));
  w.iq_A = std::max(std::abs(a.iq_A), std::abs(b.iq_A));
  w.ambient_degC = std::max(a.ambient_degC, b.ambient_degC);
  w.coolant_degC = std::max(a.coolant_degC, b.coolant_degC);
  return w;
}

ThermalInputs WorstInputs(const ThermalInputs& held, const SilenceWorstLoad& worst) {
  ThermalInputs w = held;
  w.iq_A = std::max(worst.max_current_A, std::hypot(held.id_A, held.iq_A));
  w.id_A = 0.0;
  w.speed_rpm = std::max(worst.max_speed_rpm, std::abs(held.speed_rpm));
  return w;
}

SilenceBound::SilenceBound(const SilenceWorstLoad& worst, double delay_s)
    : worst_(worst), delay_s_(delay_s) {
  if (!(delay_s >= 0.0) || !(worst.max_current_A >= 0.0) || !(worst.max_speed_rpm >= 0.0)) {
    throw std::invalid_argument(
        "SilenceBound: the delay, the largest current and the largest speed must be >= 0");
  }
}

bool SilenceBound::Propagate(const ThermalModel& model, const ThermalInputs& in, double dt_s,
                             Eigen::VectorXd& x) {
  try {
    // One zero-order-hold step over dt_s: exact for a network linear in the temperatures
    // (copper's temperature coefficient is part of a), as the state restore after a gap.
    ThermalLinearModel lin;
    model.Linearise(in, x, lin);
    ThermalDiscreteModel d;
    DiscretiseZoh(lin.a_per_s, dt_s, d);
    x = d.ad * x + d.phi_s * lin.f_K_per_s;
  } catch (const std::exception&) {
    return false;
  }
  return x.allFinite();
}

void SilenceBound::Begin(const Eigen::VectorXd& x_degC, const ThermalInputs& in, double start_s,
                         const Eigen::VectorXd& now_degC, double now_s) {
  start_degC_ = x_degC;
  start_inputs_ = in;
  start_s_ = start_s;
  bound_degC_.resize(0);
  EndWorstCase();
  from_degC_ = now_degC;
  from_inputs_ = in;
  from_s_ = now_s;
}

void SilenceBound::Reset() {
  start_degC_.resize(0);
  bound_degC_.resize(0);
  from_degC_.resize(0);
  EndWorstCase();
}

void SilenceBound::EndWorstCase() {
  worst_now_degC_.resize(0);
  worst_then_degC_.resize(0);
  acting_ = false;
}

bool SilenceBound::RunWorstTo(const ThermalModel& model, double to_s, Eigen::VectorXd& x,
                              double& at_s) const {
  if (!(to_s > at_s)) return true;
  const bool ok = Propagate(model, worst_inputs_, to_s - at_s, x);
  at_s = to_s;
  return ok;
}

void SilenceBound::StepWorstCase(const ThermalModel& model, double end_s, double min_silence_s) {
  if (!(worst_.max_current_A > 0.0) || from_degC_.size() == 0) return;
  if (worst_now_degC_.size() != from_degC_.size()) {
    // The silence's first step: from the estimate after the last step with inputs (the load may
    // have risen right after it).
    worst_inputs_ = WorstInputs(from_inputs_, worst_);
    worst_now_degC_ = worst_then_degC_ = from_degC_;
    now_s_ = then_s_ = from_s_;
  }
  // Stepped on from where each stands (re-linearised at each step: exact for a network linear
  // in its temperatures, and close for one that is not).
  if (!RunWorstTo(model, end_s, worst_now_degC_, now_s_) ||
      !RunWorstTo(model, end_s - delay_s_, worst_then_degC_, then_s_)) {
    EndWorstCase();
    from_degC_.resize(0);  // nothing to restart it from until the next step with inputs
    return;
  }
  acting_ = end_s - from_s_ > min_silence_s;
}

void SilenceBound::Step(const ThermalModel& model, const ThermalInputs& in, bool fresh,
                        const Eigen::VectorXd& x_degC,
                        const Eigen::Ref<const Eigen::VectorXd>& sd_K, double end_s,
                        double period_s, double min_silence_s, double k) {
  if (!fresh) {
    if (bound_degC_.size() > 0 && !Propagate(model, in, period_s, bound_degC_))
      bound_degC_.resize(0);
    StepWorstCase(model, end_s, min_silence_s);
    return;
  }
  EndWorstCase();
  // The silence: the steps between the last one with inputs and this one.
  const double since_s = end_s - start_s_;
  if (start_degC_.size() == x_degC.size() && since_s - period_s > min_silence_s) {
    // The frames are back: the silence and this step again, at the worse of the two loads.
    Eigen::VectorXd b = start_degC_;
    const bool ok = Propagate(model, WorseInputs(start_inputs_, in), since_s, b);
    if (ok && (bound_degC_.size() != b.size()))
      bound_degC_ = b;
    else if (ok)
      bound_degC_ = bound_degC_.cwiseMax(b);
  } else if (bound_degC_.size() > 0 && !Propagate(model, in, period_s, bound_degC_)) {
    bound_degC_.resize(0);
  }
  if (bound_degC_.size() == x_degC.size()) {
    const Eigen::VectorXd upper =
        x_degC + k * sd_K.unaryExpr([](double s) { return std::isfinite(s) ? s : 0.0; });
    if ((bound_degC_.array() <= upper.array()).all()) bound_degC_.resize(0);
  }
  start_degC_ = from_degC_ = x_degC;
  start_inputs_ = from_inputs_ = in;
  start_s_ = from_s_ = end_s;
}

void WithoutBoundaryPaths(ThermalLinearModel& lin, double boundary_degC) {
  for (Eigen::Index i = 0; i < lin.a_per_s.rows(); ++i) {
    const double leak_per_s = std::min(lin.a_per_s.row(i).sum(), 0.0);
    lin.a_per_s(i, i) -= leak_per_s;
    lin.f_K_per_s(i) += leak_per_s * boundary_degC;
  }
}

void BlindBound::Step(const ThermalModel& model, const ThermalInputs& in, double period_s,
                      const Eigen::VectorXd& estimate_degC) {
  if (bound_degC_.size() != model.StateCount()) bound_degC_ = estimate_degC;
  try {
    model.Linearise(in, bound_degC_, lin_);
    WithoutBoundaryPaths(lin_, in.ambient_degC);
    ThermalDiscreteModel d;
    DiscretiseZoh(lin_.a_per_s, period_s, d);
    bound_degC_ = d.ad * bound_degC_ + d.phi_s * lin_.f_K_per_s;
  } catch (const std::exception&) {
    bound_degC_.setConstant(std::numeric_limits<double>::quiet_NaN());
  }
}

InsideHeatBound::InsideHeatBound(const ThermalModel& model, int measured, int rotor,
                                 double history_s, double sample_s)
    : sample_s_(sample_s) {
  if (!(history_s > 0.0) || !(sample_s > 0.0)) {
    throw std::invalid_argument("InsideHeatBound: the history and the sample period must be > 0 s");
  }
  const auto kept = static_cast<std::size_t>(std::ceil(history_s / sample_s)) + 2;
  kept_s_.assign(kept, std::numeric_limits<double>::quiet_NaN());
  kept_W_.assign(kept, 0.0);
  const int n = model.StateCount();
  if (measured < 0 || rotor < 0 || measured == rotor || measured >= n || rotor >= n) return;
  // Conduction alone: at standstill every loss is zero (so is copper's temperature term), and
  // the network's a is the conductances over the capacities.
  ThermalInputs in;
  in.ambient_degC = in.coolant_degC = 20.0;
  ThermalLinearModel lin;
  try {
    model.Linearise(in, Eigen::VectorXd::Constant(n, 20.0), lin);
  } catch (const std::exception&) {
    return;  // no bound for a network that cannot be linearised at rest
  }
  const Eigen::VectorXd& cap = model.Capacities_J_per_K();
  Eigen::MatrixXd heat = Eigen::MatrixXd::Zero(n, 2);  // 1 W on the rotor, 1 W on the measured
  heat(rotor, 0) = 1.0 / cap(rotor);
  heat(measured, 1) = 1.0 / cap(measured);
  const Eigen::FullPivLU<Eigen::MatrixXd> lu(lin.a_per_s);
  if (!lu.isInvertible()) return;  // no path to the boundary: no steady state
  const Eigen::MatrixXd rise = -lu.solve(heat);
  // Only raises: a node that heating the rotor would warm less than heating the frame is left.
  gain_K_per_W_ = (rise.col(0) - rise.col(1)).cwiseMax(0.0);
  if (!gain_K_per_W_.allFinite()) gain_K_per_W_.resize(0);
}

void InsideHeatBound::Reset() {
  std::fill(kept_s_.begin(), kept_s_.end(), std::numeric_limits<double>::quiet_NaN());
  next_ = 0;
  last_kept_s_ = -std::numeric_limits<double>::infinity();
  latched_ = false;
  base_W_ = heat_W_ = 0.0;
}

double InsideHeatBound::KeptAt(double t_s) const {
  double best_s = -std::numeric_limits<double>::infinity(), best_W = 0.0;
  double oldest_s = std::numeric_limits<double>::infinity(), oldest_W = 0.0;
  for (std::size_t k = 0; k < kept_s_.size(); ++k) {
    const double s = kept_s_[k];
    if (std::isnan(s)) continue;
    if (s < oldest_s) {
      oldest_s = s;
      oldest_W = kept_W_[k];
    }
    if (s <= t_s && s > best_s) {
      best_s = s;
      best_W = kept_W_[k];
    }
  }
  return std::isfinite(best_s) ? best_W : oldest_W;
}

void InsideHeatBound::Step(double now_s, double frame_path_W, InsideHeatVerdict verdict,
                           double onset_s) {
  const bool known = std::isfinite(frame_path_W);
  if (known && now_s - last_kept_s_ >= sample_s_) {
    kept_s_[next_] = now_s;
    kept_W_[next_] = frame_path_W;
    next_ = (next_ + 1) % kept_s_.size();
    last_kept_s_ = now_s;
  }
  if (verdict == InsideHeatVerdict::kFramePath) latched_ = false;
  if (verdict == InsideHeatVerdict::kInside && !latched_ && known) {
    // From the fitted onset: the heat found before it is the pump's usual model error.
    latched_ = true;
    base_W_ = KeptAt(std::isnan(onset_s) ? -std::numeric_limits<double>::infinity() : onset_s);
  }
  if (!latched_ || gain_K_per_W_.size() == 0) {
    heat_W_ = 0.0;
  } else if (known) {
    heat_W_ = std::max(frame_path_W - base_W_, 0.0);
  }
}

}  // namespace pumptherm::estimators
