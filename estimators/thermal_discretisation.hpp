#pragma once
/// Exact zero-order-hold discretisation of the linearised thermal network.
///
/// Saheba et al. 2010 (IEEE CSM 30(1)), eqs. 20-21:
///     A_D = exp(A tau)           B_D u = (integral_0^tau exp(A s) ds) B u
/// computed together from one matrix exponential of the augmented matrix
///     exp([[A, I], [0, 0]] tau) = [[A_D, Phi], [0, I]],   Phi = integral_0^tau exp(A s) ds
/// (Van Loan, "Computing integrals involving the matrix exponential", IEEE TAC 23(3), 1978).
/// With the forcing f of ThermalLinearModel held over the step, x(k+1) = A_D x(k) + Phi f.

#include <Eigen/Dense>

#include "estimators/thermal_model.hpp"

namespace pumptherm::estimators {

/// A_D (n x n) and Phi (n x n, s) of one discretisation.
struct ThermalDiscreteModel {
  Eigen::MatrixXd ad;     ///< exp(a tau), eq. 20
  Eigen::MatrixXd phi_s;  ///< integral_0^tau exp(a s) ds, eq. 21 without B
  double dt_s = 0.0;
};

/// Discretises `a_per_s` (n x n) over `dt_s` > 0 into `out` (eqs. 20-21). Allocates.
/// Throws std::invalid_argument when dt_s is not positive and finite.
void DiscretiseZoh(const Eigen::MatrixXd& a_per_s, double dt_s, ThermalDiscreteModel& out);

/// Keeps one discretisation and redoes it only when the operating point moves: when the period
/// changes, or when the continuous matrix a has moved from the one last discretised, a0, so far
/// that || a0^-1 (a - a0) ||_F > `relative_tolerance` (the copper resistance and speed-dependent
/// resistances move a; eqs. 12-16). The measure is relative to a0^-1, the network's own
/// steady-state gain, rather than to ||a0||: the stiff internal conductances dominate ||a0||, yet
/// the copper-loss feedback that they dwarf decides the winding temperature. A stale a then
/// errs in steady state by about that fraction of the temperatures. The forcing f is applied
/// exactly at every step.
class ThermalDiscretiser {
 public:
  explicit ThermalDiscretiser(double relative_tolerance = 1e-3)
      : relative_tolerance_(relative_tolerance) {}

  /// Brings the discretisation up to date with `lin` over `dt_s`. Returns true when it was
  /// recomputed. No allocation when it was not.
  bool Update(const ThermalLinearModel& lin, double dt_s);

  /// x(k+1) = A_D x(k) + Phi f into `x_next` (no allocation when sized).
  void Propagate(const Eigen::VectorXd& x_degC, const ThermalLinearModel& lin,
                 Eigen::VectorXd& x_next_degC) const;

  const ThermalDiscreteModel& Current() const { return discrete_; }
  long Recomputations() const { return recomputations_; }

 private:
  /// || a0^-1 (a - a0) ||_F against the last discretised a0 (same shape).
  double RelativeChange(const Eigen::MatrixXd& a_per_s);

  double relative_tolerance_;
  Eigen::MatrixXd a_last_, a_last_inv_, diff_, rel_;
  ThermalDiscreteModel discrete_;
  long recomputations_ = 0;
};

}  // namespace pumptherm::estimators
