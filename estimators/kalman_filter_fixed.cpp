#include "estimators/kalman_filter_fixed.hpp"

#include <type_traits>

#include "estimators/kalman_filter_fixed/fixed_size.hpp"

namespace pumptherm::estimators::detail {
namespace {

/// Calls f(std::integral_constant<int, N>{}) when n is one of the fixed sizes N (4 to 11, or the
/// range the build chose: the top-level CMakeLists.txt); false when it is not.
template <int N = PUMPTHERM_KALMAN_FIXED_FIRST, class F>
bool WithFixedSize(Eigen::Index n, F&& f) {
  if constexpr (N > PUMPTHERM_KALMAN_FIXED_LAST) {
    return false;
  } else {
    if (n != N) return WithFixedSize<N + 1>(n, f);
    f(std::integral_constant<int, N>{});
    return true;
  }
}

}  // namespace

bool HasFixedSize(Eigen::Index n) {
  return WithFixedSize(n, [](auto) {});
}

bool PredictFixedSize(const Eigen::MatrixXd& ad, const Eigen::VectorXd& bu,
                      const Eigen::MatrixXd& sp, Eigen::VectorXd& x, Eigen::MatrixXd& s) {
  return WithFixedSize(
      x.size(), [&](auto size) { FixedSize<decltype(size)::value>::Predict(ad, bu, sp, x, s); });
}

bool UpdateFixedSize(const Eigen::MatrixXd& c, const Eigen::VectorXd& y, const Eigen::MatrixXd& sm,
                     CovarianceUpdate form, Eigen::VectorXd& x, Eigen::MatrixXd& s,
                     Eigen::MatrixXd& k, KalmanUpdateReport& report) {
  bool fixed = false;
  WithFixedSize(x.size(), [&](auto size) {
    fixed = FixedSize<decltype(size)::value>::Update(c.rows(), c, y, sm, form, x, s, k, report);
  });
  return fixed;
}

}  // namespace pumptherm::estimators::detail
