#include "estimators/kalman_filter.hpp"

namespace pumptherm::estimators {

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

void KalmanFilter::Predict(const Eigen::MatrixXd& ad, const Eigen::VectorXd& bu,
                           const Eigen::MatrixXd& sp) {
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
  sct_.resize(n, m);
  innov_cov_.resize(m, m);
  k_.resize(n, m);
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
