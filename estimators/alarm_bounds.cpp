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

void SilenceBound::Begin(const Eigen::VectorXd& x_degC, const ThermalInputs& in, double start_s) {
  start_degC_ = x_degC;
  start_inputs_ = in;
  start_s_ = start_s;
  bound_degC_.resize(0);
}

void SilenceBound::Reset() {
  start_degC_.resize(0);
  bound_degC_.resize(0);
}

void SilenceBound::Step(const ThermalModel& model, const ThermalInputs& in, bool fresh,
                        const Eigen::VectorXd& x_degC,
                        const Eigen::Ref<const Eigen::VectorXd>& sd_K, double end_s,
                        double period_s, double min_silence_s, double k) {
  if (!fresh) {
    if (bound_degC_.size() > 0 && !Propagate(model, in, period_s, bound_degC_))
      bound_degC_.resize(0);
    return;
  }
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
  start_degC_ = x_degC;
  start_inputs_ = in;
  start_s_ = end_s;
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

}  // namespace pumptherm::estimators
