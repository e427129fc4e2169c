#pragma once
/// The Kalman filter's fixed-size paths for one state count N (4 to 11): declared here, defined
/// in fixed_size_impl.hpp and instantiated once per N in states_N.cpp, so that each size compiles
/// in a translation unit of its own and the sizes build side by side.

#include <Eigen/Core>

#include "estimators/kalman_filter.hpp"

namespace pumptherm::estimators::detail {

template <int N>
struct FixedSize {
  /// x = A x + bu, S = A S A^T + Sp on N x N matrices mapped in place.
  static void Predict(const Eigen::MatrixXd& ad, const Eigen::VectorXd& bu,
                      const Eigen::MatrixXd& sp, Eigen::VectorXd& x, Eigen::MatrixXd& s);

  /// The measurement update for m = 1, 2 or 3 measurements; false (nothing done) for other m.
  static bool Update(Eigen::Index m, const Eigen::MatrixXd& c, const Eigen::VectorXd& y,
                     const Eigen::MatrixXd& sm, CovarianceUpdate form, Eigen::VectorXd& x,
                     Eigen::MatrixXd& s, Eigen::MatrixXd& k, KalmanUpdateReport& report);
};

extern template struct FixedSize<4>;
extern template struct FixedSize<5>;
extern template struct FixedSize<6>;
extern template struct FixedSize<7>;
extern template struct FixedSize<8>;
extern template struct FixedSize<9>;
extern template struct FixedSize<10>;
extern template struct FixedSize<11>;

}  // namespace pumptherm::estimators::detail
