#include "estimators/resistance_equation.hpp"

#include <cmath>
#include <limits>

namespace pumptherm::estimators {

TwoPointResult IdentifyTwoPoint(const QAxisPoint& p1, const QAxisPoint& p2) noexcept {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double a = p2.iq_A * p1.w_r_rad_per_s;
  const double b = p1.iq_A * p2.w_r_rad_per_s;
  const double den = a - b;
  if (!(std::abs(den) > 1e-12 * (std::abs(a) + std::abs(b))) || p2.w_r_rad_per_s == 0.0) {
    return {nan, nan, false};
  }
  const double rs = (p2.uq_V * p1.w_r_rad_per_s - p1.uq_V * p2.w_r_rad_per_s) / den;
  const double psi = (p2.uq_V - rs * p2.iq_A) / p2.w_r_rad_per_s;
  const bool ok = std::isfinite(rs) && std::isfinite(psi);
  return {ok ? rs : nan, ok ? psi : nan, ok};
}

}  // namespace pumptherm::estimators
