#pragma once
/// The definitions of FixedSize<N> (fixed_size.hpp), included only by the states_N.cpp files that
/// instantiate them.

#include <Eigen/Dense>

#include "estimators/kalman_filter_fixed/fixed_size.hpp"

namespace pumptherm::estimators::detail {

// Fixed-size versions for the state counts of the shipped models (4: tmp-generic,
// 7: saheba2010-*), of the mismatch test on them (5-6: a sensor's lag and offset added) and of
// tmp-generic's disturbance-state filter (8-11 with its added states):
// Eigen unrolls fixed-size products on the stack, where its dynamic-size products spend most of
// their instructions dispatching and packing (docs/virtual-sensor.md, benchmark). They map the
// dynamic members in place (column-major, contiguous) and compute the same equations.

template <int N>
void FixedSize<N>::Predict(const Eigen::MatrixXd& ad, const Eigen::VectorXd& bu,
                           const Eigen::MatrixXd& sp, Eigen::VectorXd& x, Eigen::MatrixXd& s) {
  using M = Eigen::Matrix<double, N, N>;
  using V = Eigen::Matrix<double, N, 1>;
  const Eigen::Map<const M> a(ad.data());
  Eigen::Map<V> xm(x.data());
  Eigen::Map<M> sm(s.data());
  const V xn = a * xm + Eigen::Map<const V>(bu.data());
  xm = xn;
  const M as = a * sm;
  sm.noalias() = as * a.transpose();
  sm += Eigen::Map<const M>(sp.data());
}

/// One scalar measurement (m = 1): the innovation covariance is a number, so its "Cholesky
/// solve" is a division (fails, like LLT, when it is not positive).
template <int N>
void UpdateFixed1(const Eigen::MatrixXd& c, const Eigen::VectorXd& y, const Eigen::MatrixXd& sm,
                  CovarianceUpdate form, Eigen::VectorXd& x, Eigen::MatrixXd& s, Eigen::MatrixXd& k,
                  KalmanUpdateReport& report) {
  using M = Eigen::Matrix<double, N, N>;
  using V = Eigen::Matrix<double, N, 1>;
  using R = Eigen::Matrix<double, 1, N>;
  const Eigen::Map<const R> cr(c.data());
  Eigen::Map<V> xm(x.data());
  Eigen::Map<M> sx(s.data());
  const double nu = y(0) - cr.dot(xm.transpose());
  const V h = sx * cr.transpose();
  const double r = sm(0, 0);
  const double s_nu = cr.dot(h.transpose()) + r;
  report.innovation(0) = nu;
  report.innovation_var(0) = s_nu;
  if (!(s_nu > 0.0)) {
    report.ok = false;
    return;
  }
  const V gain = h / s_nu;  // eq. 34
  report.nis = nu * nu / s_nu;
  xm += gain * nu;  // eq. 32
  k = gain;
  if (form == CovarianceUpdate::kJoseph) {
    // The Joseph form as S- + (H K^T + K H^T) / 2 with H = K s_nu - 2 S- c^T (KalmanFilter's
    // dynamic path derives it): O(N^2) instead of two N x N products.
    const V hj = gain * s_nu - 2.0 * h;
    const M sn = sx + 0.5 * (hj * gain.transpose() + gain * hj.transpose());
    sx = 0.5 * (sn + sn.transpose());
  } else {
    const M ikc = M::Identity() - gain * cr;
    const M t = ikc * sx;  // eq. 33
    sx = t;
  }
}

/// Mm measurements at once (Mm x Mm innovation covariance, Cholesky).
template <int N, int Mm>
void UpdateFixed(const Eigen::MatrixXd& c, const Eigen::VectorXd& y, const Eigen::MatrixXd& sm,
                 CovarianceUpdate form, Eigen::VectorXd& x, Eigen::MatrixXd& s, Eigen::MatrixXd& k,
                 KalmanUpdateReport& report) {
  using M = Eigen::Matrix<double, N, N>;
  using V = Eigen::Matrix<double, N, 1>;
  using G = Eigen::Matrix<double, N, Mm>;
  using Sq = Eigen::Matrix<double, Mm, Mm>;
  using Y = Eigen::Matrix<double, Mm, 1>;
  const Eigen::Map<const Eigen::Matrix<double, Mm, N>> cm(c.data());
  Eigen::Map<V> xm(x.data());
  Eigen::Map<M> sx(s.data());
  const Eigen::Map<const Sq> r(sm.data());
  const Y nu = Eigen::Map<const Y>(y.data()) - cm * xm;
  const G sct = sx * cm.transpose();
  const Sq innov = cm * sct + r;
  report.innovation = nu;
  report.innovation_var = innov.diagonal();
  const Eigen::LLT<Sq> llt(innov);
  if (llt.info() != Eigen::Success) {
    report.ok = false;
    return;
  }
  const G gain = llt.solve(sct.transpose()).transpose();  // eq. 34
  report.nis = nu.dot(llt.solve(nu));
  xm += gain * nu;  // eq. 32
  k = gain;
  if (form == CovarianceUpdate::kJoseph) {
    // S- + (H K^T + K H^T) / 2 with H = K Sy - 2 S- C^T, as in UpdateFixed1.
    const G hj = gain * innov - 2.0 * sct;
    const M sn = sx + 0.5 * (hj * gain.transpose() + gain * hj.transpose());
    sx = 0.5 * (sn + sn.transpose());
  } else {
    const M ikc = M::Identity() - gain * cm;
    const M t = ikc * sx;  // eq. 33
    sx = t;
  }
}

template <int N>
bool FixedSize<N>::Update(Eigen::Index m, const Eigen::MatrixXd& c, const Eigen::VectorXd& y,
                          const Eigen::MatrixXd& sm, CovarianceUpdate form, Eigen::VectorXd& x,
                          Eigen::MatrixXd& s, Eigen::MatrixXd& k, KalmanUpdateReport& report) {
  if (m == 1) UpdateFixed1<N>(c, y, sm, form, x, s, k, report);
  if (m == 2) UpdateFixed<N, 2>(c, y, sm, form, x, s, k, report);
  if (m == 3) UpdateFixed<N, 3>(c, y, sm, form, x, s, k, report);
  return m >= 1 && m <= 3;
}

}  // namespace pumptherm::estimators::detail
