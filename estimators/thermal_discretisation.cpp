#include "estimators/thermal_discretisation.hpp"

#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <unsupported/Eigen/MatrixFunctions>

namespace pumptherm::estimators {

void DiscretiseZoh(const Eigen::MatrixXd& a_per_s, double dt_s, ThermalDiscreteModel& out) {
  if (!(dt_s > 0.0) || !std::isfinite(dt_s)) {
    throw std::invalid_argument("DiscretiseZoh: the period must be positive and finite");
  }
  const Eigen::Index n = a_per_s.rows();
  Eigen::MatrixXd aug = Eigen::MatrixXd::Zero(2 * n, 2 * n);
  aug.topLeftCorner(n, n) = a_per_s * dt_s;
  aug.topRightCorner(n, n) = Eigen::MatrixXd::Identity(n, n) * dt_s;
  const Eigen::MatrixXd e = aug.exp();
  out.ad = e.topLeftCorner(n, n);
  out.phi_s = e.topRightCorner(n, n);
  out.dt_s = dt_s;
}

bool ThermalDiscretiser::Update(const ThermalLinearModel& lin, double dt_s) {
  const bool same_shape = a_last_.rows() == lin.a_per_s.rows() && a_last_.cols() == lin.a_per_s.cols();
  if (same_shape && discrete_.dt_s > 0.0 &&
      std::abs(dt_s - discrete_.dt_s) <= 1e-9 * discrete_.dt_s) {
    diff_ = lin.a_per_s - a_last_;
    rel_.noalias() = a_last_inv_ * diff_;
    if (rel_.norm() <= relative_tolerance_) return false;
  }
  DiscretiseZoh(lin.a_per_s, dt_s, discrete_);
  a_last_ = lin.a_per_s;
  Eigen::FullPivLU<Eigen::MatrixXd> lu(a_last_);
  // A singular a (a floating network) has no steady-state gain: fall back to the scale of a.
  a_last_inv_ = lu.isInvertible()
                    ? Eigen::MatrixXd(lu.inverse())
                    : Eigen::MatrixXd(Eigen::MatrixXd::Identity(a_last_.rows(), a_last_.cols()) /
                                      std::max(a_last_.norm(), 1e-300));
  diff_.resize(a_last_.rows(), a_last_.cols());
  rel_.resize(a_last_.rows(), a_last_.cols());
  ++recomputations_;
  return true;
}

void ThermalDiscretiser::Propagate(const Eigen::VectorXd& x_degC, const ThermalLinearModel& lin,
                                   Eigen::VectorXd& x_next_degC) const {
  x_next_degC.noalias() = discrete_.ad * x_degC;
  x_next_degC.noalias() += discrete_.phi_s * lin.f_K_per_s;
}

}  // namespace pumptherm::estimators
