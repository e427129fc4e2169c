#pragma once
/// The Kalman filter's fixed-size paths (estimators/kalman_filter.cpp's KalmanFilter uses them):
/// the same equations on fixed-size Eigen matrices for the small state counts of the shipped
/// models. kalman_filter_fixed.cpp dispatches on the state count; each count's instantiation is a
/// translation unit of its own (kalman_filter_fixed/states_N.cpp): together they take most of
/// the filter's compile time.

#include <Eigen/Dense>

#include "estimators/kalman_filter.hpp"

namespace pumptherm::estimators::detail {

/// Whether the state count `n` has the fixed-size paths.
bool HasFixedSize(Eigen::Index n);

/// Time update x = A x + bu, S = A S A^T + Sp on a fixed size; false (nothing done) when the
/// state count has none.
bool PredictFixedSize(const Eigen::MatrixXd& ad, const Eigen::VectorXd& bu,
                      const Eigen::MatrixXd& sp, Eigen::VectorXd& x, Eigen::MatrixXd& s);

/// Measurement update on a fixed size (the report's innovation vectors sized by the caller, k
/// sized n x m); false (nothing done) when the state or measurement count has none.
bool UpdateFixedSize(const Eigen::MatrixXd& c, const Eigen::VectorXd& y, const Eigen::MatrixXd& sm,
                     CovarianceUpdate form, Eigen::VectorXd& x, Eigen::MatrixXd& s,
                     Eigen::MatrixXd& k, KalmanUpdateReport& report);

}  // namespace pumptherm::estimators::detail
