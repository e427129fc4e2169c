#include "estimators/resistance_rls.hpp"

#include <cmath>

namespace pumptherm::estimators {

double Han2019Weight(double eps_V, double y_V) noexcept {
  const double e = std::abs(eps_V);
  const double y = std::abs(y_V);
  if (!(e < 1e-2 * y)) return 0.0;  // untrusted (also catches NaN)
  if (e >= 1e-4 * y) return 0.1;    // low confidence
  if (e >= 1e-5 * y) return 0.5;    // high confidence
  return 1.0;                       // fully trusted
}

DiscountedRls::DiscountedRls(const RlsConfig& config, const Eigen::Vector2d& theta0, double p0)
    : config_(config) {
  state_.theta = theta0;
  state_.p = p0 * Eigen::Matrix2d::Identity();
}

RlsStep DiscountedRls::Update(const Eigen::Vector2d& phi, double y_V) noexcept {
  const double eps = y_V - phi.dot(state_.theta);
  const double weight =
      config_.weighting == RlsWeighting::kHan2019FourLevel ? Han2019Weight(eps, y_V) : 1.0;
  return UpdateWeighted(phi, y_V, weight);
}

RlsStep DiscountedRls::UpdateWeighted(const Eigen::Vector2d& phi, double y_V,
                                      double weight) noexcept {
  ++state_.samples;
  const double eps = y_V - phi.dot(state_.theta);
  if (!(weight > 0.0) || !std::isfinite(eps) || !phi.allFinite()) {
    // Lambda = 0: no information, no change (see the header: no covariance windup).
    ++state_.rejected;
    return {eps, 0.0};
  }
  const double lambda = config_.forgetting;
  const Eigen::Vector2d p_phi = state_.p * phi;
  const double denom = lambda / weight + phi.dot(p_phi);
  const Eigen::Vector2d gain = p_phi / denom;  // eq. 21, K(k)
  state_.theta += gain * eps;
  // P(k) = (P - K phi^T P) / lambda; P phi = p_phi and P is symmetric, so K phi^T P = K p_phi^T.
  state_.p = (state_.p - gain * p_phi.transpose()) / lambda;
  state_.p = 0.5 * (state_.p + state_.p.transpose()).eval();  // keep it symmetric in rounding
  return {eps, weight};
}

}  // namespace pumptherm::estimators
