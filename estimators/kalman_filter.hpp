#pragma once
/// Discrete linear Kalman filter (Saheba et al. 2010, IEEE CSM 30(1), eqs. 18-34).
///
///   model        x(n+1) = A_D x(n) + B_D u(n) + w(n),   y(n) = C x(n) + v(n)      (18-19)
///   time update  x-(n) = A_D x^(n-1) + B_D u(n-1),  S-(n) = A_D S^(n-1) A_D^T + Sp   (30-31)
///   gain         K(n) = S-(n) C^T [C S-(n) C^T + Sm]^-1                            (34)
///   measurement  x^(n) = x-(n) + K(n) [y(n) - C x-(n)]                             (32)
///   covariance   S^(n) = [I - K C] S-(n) [I - K C]^T + K Sm K^T  (Joseph form)
/// The paper writes eq. 33 as S^ = [I - K C] S-; the Joseph form is algebraically equal for the
/// optimal gain and stays symmetric and positive semi-definite under rounding (Bucy and Joseph,
/// "Filtering for stochastic processes with applications to guidance", 1968; Simon, "Optimal
/// State Estimation", Wiley 2006, eq. 5.19). Both are offered; the Joseph form is the default.
///
/// Health is data: each update reports the innovation y - C x-, its covariance's diagonal and the
/// normalised innovation squared NIS = nu^T S_nu^-1 nu (chi-square with m degrees of freedom when
/// the filter is consistent).
///
/// Workspaces are members: after the first step of a given measurement count no step allocates.

#include <Eigen/Cholesky>
#include <Eigen/Dense>
#include <vector>

namespace pumptherm::estimators {

enum class CovarianceUpdate { kJoseph, kTextbook };

/// What one measurement update found.
struct KalmanUpdateReport {
  Eigen::VectorXd innovation;      ///< y - C x- (m), in the measurement's unit
  Eigen::VectorXd innovation_var;  ///< diagonal of C S- C^T + Sm (m)
  double nis = 0.0;                ///< nu^T (C S- C^T + Sm)^-1 nu
  int measurements = 0;            ///< m; 0 when nothing was measured (no update done)
  bool ok = true;  ///< false when the innovation covariance was not positive definite
  /// The step was refused (non-finite inputs or period): nothing changed, nothing was measured.
  bool refused = false;
  /// Extra measurements left out as invalid (a state the model lacks, an sd that is not positive
  /// and finite, a non-finite winding gain).
  int rejected_measurements = 0;
};

class KalmanFilter {
 public:
  /// A filter of `n` states with x = 0, S = I.
  explicit KalmanFilter(int n = 0);

  /// Sets the state estimate and its covariance (n, n x n).
  void Reset(const Eigen::VectorXd& x, const Eigen::MatrixXd& s);

  /// Time update (eqs. 30-31): x = A_D x + bu, S = A_D S A_D^T + Sp. `ad` n x n, `bu` n (the
  /// already formed B_D u), `sp` n x n.
  void Predict(const Eigen::MatrixXd& ad, const Eigen::VectorXd& bu, const Eigen::MatrixXd& sp);

  /// As above, for process noise uncorrelated between the states (Sp diagonal, `sp_diagonal`
  /// n) and an A_D whose rows from `coupled_rows` on are diagonal (their states constants or
  /// first-order processes of their own), as its caller built it: the filter does not search
  /// A_D for them (checked in builds with assertions).
  void Predict(const Eigen::MatrixXd& ad, const Eigen::VectorXd& bu,
               const Eigen::VectorXd& sp_diagonal, Eigen::Index coupled_rows);

  /// Measurement update (eqs. 32-34) with `c` (m x n), `y` (m), `sm` (m x m). When the
  /// innovation covariance is not positive definite the state is left alone and ok = false.
  const KalmanUpdateReport& Update(const Eigen::MatrixXd& c, const Eigen::VectorXd& y,
                                   const Eigen::MatrixXd& sm,
                                   CovarianceUpdate form = CovarianceUpdate::kJoseph);

  /// Adds `var` to the variance of state `i` (a jump of that state, of that variance, between
  /// the last prediction and the next update). Ignores an index out of range or a var <= 0.
  void AddVariance(int i, double var);

  const Eigen::VectorXd& State() const { return x_; }
  const Eigen::MatrixXd& Covariance() const { return s_; }
  /// The gain of the last update (n x m).
  const Eigen::MatrixXd& Gain() const { return k_; }
  const KalmanUpdateReport& LastUpdate() const { return report_; }

 private:
  /// innov_cov_inv_ = innov_cov_^-1 (Cholesky); false when innov_cov_ is not positive definite.
  bool InvertInnovationCovariance();
  /// x = A_D x + bu, S = A_D S A_D^T by blocks (the dynamic-size path, without Sp).
  void PropagateByBlocks(const Eigen::MatrixXd& ad, const Eigen::VectorXd& bu,
                         Eigen::Index coupled_rows);
  /// The same with the states' count N known at compile time (Eigen::Dynamic: at run time).
  template <int N>
  void PropagateByBlocks(const Eigen::MatrixXd& ad, const Eigen::VectorXd& bu,
                         Eigen::Index coupled_rows);
  /// The measurement update's dynamic-size path, column by column (N as above).
  template <int N>
  void UpdateByColumns(const Eigen::MatrixXd& c, const Eigen::VectorXd& y,
                       const Eigen::MatrixXd& sm, CovarianceUpdate form);
  /// The Joseph form's S += (H K^T + K H^T) / 2 from h_ and k_ (N as above).
  template <int N>
  void AddJosephTerms();

  Eigen::VectorXd x_, xtmp_;
  Eigen::MatrixXd s_, ntmp_;
  Eigen::VectorXd d_tail_;    ///< A_D's diagonal after its coupled rows
  Eigen::MatrixXd sp_dense_;  ///< a diagonal Sp for the fixed-size paths
  Eigen::MatrixXd sct_, innov_cov_, innov_cov_inv_, k_;
  Eigen::MatrixXd h_;  ///< the covariance update's factor: K Sy - 2 S- C^T (Joseph), -K (textbook)
  Eigen::VectorXd nu_, s_inv_nu_;
  std::vector<Eigen::Index> active_;  ///< A_D's nonzero columns in its coupled rows
  Eigen::LLT<Eigen::MatrixXd> llt_;   ///< for more than four readings
  KalmanUpdateReport report_;
};

}  // namespace pumptherm::estimators
