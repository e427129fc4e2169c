#include "estimators/kalman_filter.hpp"

#include <cmath>

#include "estimators/kalman_filter_fixed.hpp"

namespace pumptherm::estimators {
namespace {

// The dynamic-size path (state counts without a fixed-size one: the disturbance-state filter
// with the voltage rows has 14) takes its products column by column and skips the zero
// coefficients of A_D and C: their augmented states are constants or first-order processes and
// a measurement reads a few states, so most coefficients are zero, and at these sizes Eigen's
// general product spends most of its time packing. The sums are the same equations.

/// out = s m^T for a square s (n x n) and m (r x n): out.col(i) = sum_k m(i, k) s.col(k).
void TimesTransposed(const Eigen::MatrixXd& s, const Eigen::MatrixXd& m, Eigen::MatrixXd& out) {
  const Eigen::Index n = s.rows();
  out.resize(n, m.rows());
  for (Eigen::Index i = 0; i < m.rows(); ++i) {
    auto col = out.col(i);
    col.setZero();
    for (Eigen::Index k = 0; k < n; ++k) {
      const double v = m(i, k);
      if (v != 0.0) col += v * s.col(k);
    }
  }
}

/// m v for m (r x n) and v (n), skipping m's zeros.
void TimesVector(const Eigen::MatrixXd& m, const Eigen::VectorXd& v, Eigen::VectorXd& out) {
  out.setZero(m.rows());
  for (Eigen::Index k = 0; k < m.cols(); ++k) {
    for (Eigen::Index i = 0; i < m.rows(); ++i) {
      const double a = m(i, k);
      if (a != 0.0) out(i) += a * v(k);
    }
  }
}

/// s += sum_r a.col(r) b.col(r)^T (n x n, rank m).
void AddOuterProducts(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b, Eigen::MatrixXd& s) {
  for (Eigen::Index j = 0; j < s.cols(); ++j) {
    auto col = s.col(j);
    for (Eigen::Index r = 0; r < a.cols(); ++r) col += b(j, r) * a.col(r);
  }
}

}  // namespace

KalmanFilter::KalmanFilter(int n)
    : x_(Eigen::VectorXd::Zero(n)),
      xtmp_(n),
      s_(Eigen::MatrixXd::Identity(n, n)),
      ntmp_(n, n),
      ntmp2_(n, n) {}

void KalmanFilter::Reset(const Eigen::VectorXd& x, const Eigen::MatrixXd& s) {
  x_ = x;
  s_ = s;
  const Eigen::Index n = x.size();
  xtmp_.resize(n);
  ntmp_.resize(n, n);
  ntmp2_.resize(n, n);
}

void KalmanFilter::AddVariance(int i, double var) {
  if (i < 0 || i >= x_.size() || !(var > 0.0) || !std::isfinite(var)) return;
  s_(i, i) += var;
}

void KalmanFilter::Predict(const Eigen::MatrixXd& ad, const Eigen::VectorXd& bu,
                           const Eigen::MatrixXd& sp) {
  if (detail::PredictFixedSize(ad, bu, sp, x_, s_)) return;
  // x = A_D x + bu; S = A_D S A_D^T + Sp as W = (S A_D^T)^T = A_D S, then W A_D^T (eqs. 30-31).
  TimesVector(ad, x_, xtmp_);
  x_ = xtmp_ + bu;
  TimesTransposed(s_, ad, ntmp_);
  ntmp2_ = ntmp_.transpose();
  TimesTransposed(ntmp2_, ad, s_);
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
  if (detail::UpdateFixedSize(c, y, sm, form, x_, s_, k_, report_)) return report_;
  innov_cov_.resize(m, m);
  s_inv_nu_.resize(m);

  TimesVector(c, x_, nu_);
  nu_ = y - nu_;
  TimesTransposed(s_, c, sct_);  // S- C^T (n x m)
  for (Eigen::Index j = 0; j < m; ++j) {
    for (Eigen::Index i = 0; i < m; ++i) innov_cov_(i, j) = c.row(i).dot(sct_.col(j));
  }
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
  for (Eigen::Index r = 0; r < m; ++r) x_ += nu_(r) * k_.col(r);  // eq. 32

  // T = [I - K C] S- = S- - K (S- C^T)^T: eq. 33, the textbook form.
  ntmp_ = s_;
  ksm_ = -k_;
  AddOuterProducts(ksm_, sct_, ntmp_);
  if (form == CovarianceUpdate::kJoseph) {
    // [I - K C] S- [I - K C]^T + K Sm K^T = T - (T C^T) K^T + (K Sm) K^T = T + G K^T with
    // G = K Sm - T C^T (n x m): the Joseph form in O(n^2 m).
    TimesTransposed(ntmp_, c, sct_);
    ksm_.noalias() = k_ * sm;
    ksm_ -= sct_;
    AddOuterProducts(ksm_, k_, ntmp_);
    // Remove the rounding asymmetry.
    s_ = 0.5 * (ntmp_ + ntmp_.transpose());
  } else {
    s_ = ntmp_;
  }
  return report_;
}

}  // namespace pumptherm::estimators
