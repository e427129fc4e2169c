#pragma once
/// Recursive least squares for the SPMSM q-axis voltage model, exactly as Han, Xiong, Mao,
/// Vacuum 169 (2019) 108935 write it (the "paper's algorithm", kept as-is for comparison):
///
///     y(k) = phi(k)^T theta + e(k),  phi = [iq, w_r]^T,  y = uq - Ls w_r id,
///     theta = [Rs, psi_f]^T                                               (eqs. 6, 9-12)
///     eps(k)   = y(k) - phi(k)^T theta(k-1)                               (eq. 22)
///     K(k)     = P(k-1) phi(k) [lambda/Lambda(k) + phi(k)^T P(k-1) phi(k)]^-1
///     theta(k) = theta(k-1) + K(k) eps(k)
///     P(k)     = (1/lambda) [I - K(k) phi(k)^T] P(k-1)                    (eq. 21)
///
/// with the four-level weighting Lambda(eps, y) of eq. 23. Lambda = lambda = 1 is plain RLS;
/// Lambda = 1, lambda < 1 is RLS with forgetting; eq. 23 with lambda = 0.9995 is DFRLS.
///
/// What the paper leaves open, decided here: when Lambda(k) = 0 the gain bracket is infinite,
/// so K = 0 and eq. 21 would still divide P by lambda, inflating the covariance on every
/// rejected sample (windup: after n rejections P has grown by lambda^-n). A rejected sample
/// carries no information, so it changes nothing: theta and P are left as they were.
///
/// Fixed-size Eigen, no allocation; Update() is noexcept and costs a few tens of nanoseconds.

#include <Eigen/Core>
#include <cstdint>

namespace pumptherm::estimators {

/// Index of the resistance in theta.
inline constexpr int kThetaResistance = 0;
/// Index of the flux linkage in theta.
inline constexpr int kThetaFlux = 1;

/// How each sample is weighted (Lambda in eq. 21).
enum class RlsWeighting {
  kUnity,            ///< Lambda = 1 for every sample
  kHan2019FourLevel  ///< Han 2019 eq. 23, thresholds relative to |y|
};

/// Settings of the recursion.
struct RlsConfig {
  double forgetting = 1.0;  ///< lambda in (0, 1]
  RlsWeighting weighting = RlsWeighting::kUnity;

  /// Plain RLS: lambda = Lambda = 1.
  static RlsConfig Plain() { return {1.0, RlsWeighting::kUnity}; }
  /// RLS with forgetting: Lambda = 1.
  static RlsConfig Forgetting(double lambda = 0.9995) { return {lambda, RlsWeighting::kUnity}; }
  /// DFRLS: eq. 23 weighting with lambda = 0.9995 (Han 2019 section 3.3).
  static RlsConfig Dfrls(double lambda = 0.9995) {
    return {lambda, RlsWeighting::kHan2019FourLevel};
  }
};

/// The recursion's state as a plain struct (for saving and restoring).
struct RlsState {
  Eigen::Vector2d theta = Eigen::Vector2d::Zero();  ///< [Rs ohm, psi_f Wb]
  Eigen::Matrix2d p = Eigen::Matrix2d::Zero();      ///< covariance P, 2x2, theta's units squared
  std::uint64_t samples = 0;                        ///< samples offered
  std::uint64_t rejected = 0;                       ///< samples with Lambda = 0
};

/// What one update did.
struct RlsStep {
  double prediction_error = 0.0;  ///< eps(k) of eq. 22, V
  double weight = 0.0;            ///< Lambda(k) used
};

/// Han 2019 eq. 23: Lambda from the prediction deviation `eps` and the output `y` (both V).
double Han2019Weight(double eps_V, double y_V) noexcept;

/// RLS / RLS with forgetting / DFRLS (Han 2019 eq. 21).
class DiscountedRls {
 public:
  /// Starts at `theta0` = [Rs ohm, psi_f Wb] with covariance `p0` I.
  DiscountedRls(const RlsConfig& config, const Eigen::Vector2d& theta0, double p0);

  /// One sample: regressor phi = [iq A, w_r rad/s], output y = uq - Ls w_r id (V).
  /// A non-finite input is treated as a rejected sample (Lambda = 0).
  RlsStep Update(const Eigen::Vector2d& phi, double y_V) noexcept;

  /// One sample with an externally chosen weight Lambda >= 0 (0 rejects the sample).
  RlsStep UpdateWeighted(const Eigen::Vector2d& phi, double y_V, double weight) noexcept;

  const Eigen::Vector2d& theta() const { return state_.theta; }
  const Eigen::Matrix2d& covariance() const { return state_.p; }
  const RlsConfig& config() const { return config_; }
  RlsState Save() const { return state_; }
  void Restore(const RlsState& state) { state_ = state; }

 private:
  RlsConfig config_;
  RlsState state_;
};

}  // namespace pumptherm::estimators
