#include "estimators/kalman_filter.hpp"

#include <cmath>
#include <type_traits>

namespace pumptherm::estimators {
namespace {

// Fixed-size versions for the state counts of the shipped models (4: tmp-generic,
// 7: saheba2010-*), of the mismatch test on them (5-6: a sensor's lag and offset added) and of
// tmp-generic's disturbance-state filter (8-11 with its added states):
// Eigen unrolls fixed-size products on the stack, where its dynamic-size products spend most of
// their instructions dispatching and packing (docs/virtual-sensor.md, benchmark). They map the
// dynamic members in place (column-major, contiguous) and compute the same equations.

template <int N>
void PredictFixed(const Eigen::MatrixXd& ad, const Eigen::VectorXd& bu, const Eigen::MatrixXd& sp,
                  Eigen::VectorXd& x, Eigen::MatrixXd& s) {
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
  const M ikc = M::Identity() - gain * cr;
  if (form == CovarianceUpdate::kJoseph) {
    const M t = ikc * sx;
    M sn = t * ikc.transpose();
    sn += (r * gain) * gain.transpose();
    sx = 0.5 * (sn + sn.transpose());
  } else {
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
  const M ikc = M::Identity() - gain * cm;
  if (form == CovarianceUpdate::kJoseph) {
    const M t = ikc * sx;
    M sn = t * ikc.transpose();
    sn += gain * r * gain.transpose();
    sx = 0.5 * (sn + sn.transpose());
  } else {
    const M t = ikc * sx;  // eq. 33
    sx = t;
  }
}

/// The fixed-size update for n states and m measurements, if there is one.
template <int N>
bool UpdateFixedN(Eigen::Index m, const Eigen::MatrixXd& c, const Eigen::VectorXd& y,
                  const Eigen::MatrixXd& sm, CovarianceUpdate form, Eigen::VectorXd& x,
                  Eigen::MatrixXd& s, Eigen::MatrixXd& k, KalmanUpdateReport& report) {
  if (m == 1) UpdateFixed1<N>(c, y, sm, form, x, s, k, report);
  if (m == 2) UpdateFixed<N, 2>(c, y, sm, form, x, s, k, report);
  if (m == 3) UpdateFixed<N, 3>(c, y, sm, form, x, s, k, report);
  return m >= 1 && m <= 3;
}

/// Calls f(std::integral_constant<int, N>{}) when n is one of the fixed sizes N (4 to 11);
/// false when it is not.
template <int N = 4, class F>
bool WithFixedSize(Eigen::Index n, F&& f) {
  if constexpr (N > 11) {
    return false;
  } else {
    if (n != N) return WithFixedSize<N + 1>(n, f);
    f(std::integral_constant<int, N>{});
    return true;
  }
}

}  // namespace

KalmanFilter::KalmanFilter(int n)
    : x_(Eigen::VectorXd::Zero(n)),
      xtmp_(n),
      s_(Eigen::MatrixXd::Identity(n, n)),
      ntmp_(n, n),
      ntmp2_(n, n),
      ikc_(n, n) {}

void KalmanFilter::Reset(const Eigen::VectorXd& x, const Eigen::MatrixXd& s) {
  x_ = x;
  s_ = s;
  const Eigen::Index n = x.size();
  xtmp_.resize(n);
  ntmp_.resize(n, n);
  ntmp2_.resize(n, n);
  ikc_.resize(n, n);
}

void KalmanFilter::AddVariance(int i, double var) {
  if (i < 0 || i >= x_.size() || !(var > 0.0) || !std::isfinite(var)) return;
  s_(i, i) += var;
}

void KalmanFilter::Predict(const Eigen::MatrixXd& ad, const Eigen::VectorXd& bu,
                           const Eigen::MatrixXd& sp) {
  if (WithFixedSize(x_.size(),
                    [&](auto size) { PredictFixed<decltype(size)::value>(ad, bu, sp, x_, s_); })) {
    return;
  }
  xtmp_.noalias() = ad * x_;
  x_ = xtmp_ + bu;
  ntmp_.noalias() = ad * s_;
  s_.noalias() = ntmp_ * ad.transpose();
  s_ += sp;
}

const KalmanUpdateReport& KalmanFilter::Update(const Eigen::MatrixXd& c, const Eigen::VectorXd& y,
                                               const Eigen::MatrixXd& sm, CovarianceUpdate form) {
  const Eigen::Index m = c.rows();
  const Eigen::Index n = x_.size();
  report_.measurements = static_cast<int>(m);
  report_.ok = true;
  report_.nis = 0.0;
  report_.innovation.resize(m);
  report_.innovation_var.resize(m);
  if (m == 0) return report_;
  k_.resize(n, m);
  bool fixed = false;
  WithFixedSize(n, [&](auto size) {
    fixed = UpdateFixedN<decltype(size)::value>(m, c, y, sm, form, x_, s_, k_, report_);
  });
  if (fixed) return report_;
  sct_.resize(n, m);
  innov_cov_.resize(m, m);
  kt_.resize(m, n);
  ksm_.resize(n, m);
  nu_.resize(m);
  s_inv_nu_.resize(m);

  nu_.noalias() = -c * x_;
  nu_ += y;
  sct_.noalias() = s_ * c.transpose();
  innov_cov_.noalias() = c * sct_;
  innov_cov_ += sm;
  report_.innovation = nu_;
  report_.innovation_var = innov_cov_.diagonal();
  llt_.compute(innov_cov_);
  if (llt_.info() != Eigen::Success) {
    report_.ok = false;
    return report_;
  }
  // K^T = (C S- C^T + Sm)^-1 C S-  (eq. 34, transposed; S- symmetric).
  kt_ = sct_.transpose();
  llt_.solveInPlace(kt_);
  k_ = kt_.transpose();
  s_inv_nu_ = nu_;
  llt_.solveInPlace(s_inv_nu_);
  report_.nis = nu_.dot(s_inv_nu_);

  x_.noalias() += k_ * nu_;  // eq. 32
  ikc_.setIdentity();
  ikc_.noalias() -= k_ * c;
  if (form == CovarianceUpdate::kJoseph) {
    ntmp_.noalias() = ikc_ * s_;
    s_.noalias() = ntmp_ * ikc_.transpose();
    ksm_.noalias() = k_ * sm;
    s_.noalias() += ksm_ * k_.transpose();
    // Remove the rounding asymmetry.
    ntmp_ = s_.transpose();
    s_ += ntmp_;
    s_ *= 0.5;
  } else {
    ntmp_.noalias() = ikc_ * s_;  // eq. 33
    s_ = ntmp_;
  }
  return report_;
}

}  // namespace pumptherm::estimators
