#include "estimators/thermal_discretisation.hpp"

#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <optional>
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

namespace {

/// || a0^-1 (a - a0) ||_F with fixed-size matrices (unrolled products; see kalman_filter.cpp).
template <int N>
double RelativeChangeFixed(const Eigen::MatrixXd& a0_inv, const Eigen::MatrixXd& a0,
                           const Eigen::MatrixXd& a) {
  using M = Eigen::Matrix<double, N, N>;
  const M d = Eigen::Map<const M>(a.data()) - Eigen::Map<const M>(a0.data());
  const M r = Eigen::Map<const M>(a0_inv.data()) * d;
  return r.norm();
}

/// RelativeChangeFixed for the sizes of the shipped models' networks (4: tmp-generic, 7:
/// saheba2010-*) with a sensor's lag and offset added (up to 9); none for other sizes.
template <int N = 4>
std::optional<double> RelativeChangeOfSize(const Eigen::MatrixXd& a0_inv, const Eigen::MatrixXd& a0,
                                           const Eigen::MatrixXd& a) {
  if constexpr (N > 9) {
    return std::nullopt;
  } else {
    if (a.rows() != N) return RelativeChangeOfSize<N + 1>(a0_inv, a0, a);
    return RelativeChangeFixed<N>(a0_inv, a0, a);
  }
}

}  // namespace

double ThermalDiscretiser::RelativeChange(const Eigen::MatrixXd& a_per_s) {
  if (const auto fixed = RelativeChangeOfSize(a_last_inv_, a_last_, a_per_s)) return *fixed;
  diff_ = a_per_s - a_last_;
  rel_.noalias() = a_last_inv_ * diff_;
  return rel_.norm();
}

bool ThermalDiscretiser::Update(const ThermalLinearModel& lin, double dt_s) {
  const bool same_shape =
      a_last_.rows() == lin.a_per_s.rows() && a_last_.cols() == lin.a_per_s.cols();
  if (same_shape && discrete_.dt_s > 0.0 &&
      std::abs(dt_s - discrete_.dt_s) <= 1e-9 * discrete_.dt_s) {
    if (RelativeChange(lin.a_per_s) <= relative_tolerance_) return false;
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
  if (x_degC.size() == 7 && x_next_degC.size() == 7) {
    using M = Eigen::Matrix<double, 7, 7>;
    using V = Eigen::Matrix<double, 7, 1>;
    Eigen::Map<V>(x_next_degC.data()) =
        Eigen::Map<const M>(discrete_.ad.data()) * Eigen::Map<const V>(x_degC.data()) +
        Eigen::Map<const M>(discrete_.phi_s.data()) * Eigen::Map<const V>(lin.f_K_per_s.data());
    return;
  }
  x_next_degC.noalias() = discrete_.ad * x_degC;
  x_next_degC.noalias() += discrete_.phi_s * lin.f_K_per_s;
}

}  // namespace pumptherm::estimators
