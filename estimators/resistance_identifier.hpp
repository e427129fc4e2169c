#pragma once
/// Online stator-resistance identifier for a pump motor: the project's estimator, built on the
/// DFRLS idea of Han, Xiong, Mao, Vacuum 169 (2019) 108935 (eqs. 6, 21-23) and completed where
/// the paper leaves things open. docs/resistance-identification.md explains every decision.
///
/// Per raw sample (e.g. every 10 ms) Update() accumulates
///     y = uq - Ls w_r id   and   phi = [iq, w_r]
/// (the q-axis equation of Han 2019 eq. 6 is linear, so block averages satisfy it exactly).
/// When the motor description gives the uq resolution, the quantisation bias of the block mean
/// of uq is removed (estimators/quantisation.hpp, noise from the block's own variance).
/// Every `block_samples` samples the block means enter a Kalman-form discounted least-squares
/// update of x = [Rs, dRs/dt, psi_f, dpsi_f/dt] (measurement row [iq, 0, w_r, 0]) in which
///   - forgetting is process noise added to P (each parameter drifts with a rate that itself
///     wanders and decays with rate_time_constant_s, as a temperature approaching equilibrium
///     does), not a division by lambda, so P cannot wind up, and between load changes the
///     resistance follows the trend learnt from earlier load changes;
///   - the weight Lambda is the paper's four levels but on the normalised innovation
///     |eps| / sqrt(phi^T P phi + r) instead of |eps| / |y| (eq. 23 rejects nearly every sample
///     under realistic noise); Lambda = 0 leaves theta unchanged;
///   - an excitation monitor (exponentially weighted information on Rs with psi_f and a
///     constant voltage offset free, i.e. the Schur complement of the moments of [iq, w_r, 1])
///     decides whether Rs can be told apart from psi_f and from an inverter voltage offset;
///     when it cannot, Rs is held and only psi_f is tracked;
///   - when the motor description gives the inverter's voltage error, it is subtracted from
///     each block mean of uq before identification;
///   - two such filters run side by side, one per hypothesis about the magnet: steady (its flux
///     barely drifts) and drifting (the rotor warming or cooling). Between load changes a drift
///     of uq is resistance under the first and mostly flux under the second; each load change
///     tells them apart, so their probabilities are updated with the innovations of load-change
///     blocks only (multiple-model estimation, Magill 1965; Bar-Shalom, Li, Kirubarajan 2001,
///     sec. 11.6), and the output is their probability-weighted mixture;
///   - the estimate is checked against a plausible band from the motor description;
///   - between load changes a drift of uq at constant current and speed is resistance or flux
///     and no data tell which (a magnet warming 1 K moves uq 40 mV at rated speed, a winding
///     warming 1 K about 1 mV/A): the drift not predicted by the trend known at the last load
///     change, over iq, bounds what the winding may have done unseen. Weighted by the drifting
///     magnet's probability it enters the winding temperature's 1-sigma, and above drift_hold_K
///     the status is `held`; there the drifting-magnet filter's flux is freed to take the drift
///     (covariance matching), and the next load change re-opens its Rs along the line the old
///     current fixed. A hypothesis whose filter cannot explain the blocks between load changes
///     while the other can is refuted there and then;
///   - where the data make it identifiable (iq varying independently of w_r and of a constant,
///     e.g. a run-up then load changes at speed, or iq changing sign), an inverter voltage
///     offset u0 sign(iq) is estimated by windowed least squares beside the filters;
///   - `tracking` needs evidence: identifiable now, a 1-sigma of the winding temperature
///     (covariance plus an allowance for unmodelled voltage error over the current excitation
///     plus the unexplained drift) within half of tracking_bound_K, and innovations consistent
///     with their variance.
/// Every output carries one ResistanceStatus and the winding temperature's 1-sigma.
///
/// Pure: no I/O, no clock (time enters as dt_s), no allocation after construction.

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <string_view>

#include "estimators/motor.hpp"

namespace pumptherm::estimators {

/// Indices of the identifier's state vector.
inline constexpr int kStateResistance = 0;
inline constexpr int kStateResistanceRate = 1;
inline constexpr int kStateFlux = 2;
inline constexpr int kStateFluxRate = 3;

/// Indices of the magnet hypotheses (one filter each).
inline constexpr int kSteadyMagnet = 0;    ///< the flux barely drifts
inline constexpr int kDriftingMagnet = 1;  ///< the flux drifts with the magnet temperature
inline constexpr int kMagnetHypotheses = 2;

/// Health of a resistance estimate. Numeric values are stable (they appear in CSV output).
enum class ResistanceStatus : std::uint8_t {
  kInitialising = 0,     ///< fewer than one block seen since start or reset: nameplate values
  kConverging = 1,       ///< identifiable, but the Rs standard deviation is above the target
  kTracking = 2,         ///< identifiable, converged, inside the plausible band
  kNotIdentifiable = 3,  ///< iq and w_r carry no independent information (or |iq| is below
                         ///< min_current_A or idle_current_A): Rs held (psi_f tracked unless
                         ///< below min_current_A)
  kImplausible = 4,      ///< the Rs estimate is outside the plausible band of the motor
  kInvalidInput = 5,     ///< this sample had a NaN or infinite value and was ignored
  kHeld = 6,             ///< the regressors vary, but iq does not vary independently of a
                         ///< constant (constant current during a run-up): Rs cannot be told
                         ///< from an inverter voltage offset; or uq drifted at constant current
                         ///< by more than drift_hold_K of winding since the last load change
                         ///< (resistance or flux, no data tell): Rs is held (psi_f tracked)
};

/// Lower-case name of a status ("tracking", "not_identifiable", ...).
std::string_view ToString(ResistanceStatus status) noexcept;

/// Tuning of the identifier; the defaults suit the Han 2019 TMP at 10 ms sampling with the
/// noise of ../shared/reference/realistic-signals.md.
struct ResistanceIdentifierConfig {
  int block_samples = 100;        ///< raw samples averaged per update (10 ms -> 1 s)
  double current_noise_A = 0.01;  ///< rms noise of one raw iq sample
  double voltage_noise_V = 0.02;  ///< rms noise of one raw uq sample
  double speed_noise_rpm = 1.0;   ///< rms noise of one raw mechanical speed sample
  /// Drifting-magnet hypothesis: random walk of the winding temperature, and of its rate.
  double winding_drift_K_per_sqrt_h = 1.0;
  double winding_rate_walk_K_per_h_per_sqrt_h = 10.0;
  /// Steady-magnet hypothesis: the same two, loose enough for a winding heating several K/min
  /// (with the flux steady, a uq drift at constant current can only be resistance).
  double steady_winding_drift_K_per_sqrt_h = 3.0;
  double steady_winding_rate_walk_K_per_h_per_sqrt_h = 100.0;
  /// Drifting-magnet hypothesis: random walk of the magnet temperature, and of its rate.
  double magnet_drift_K_per_sqrt_h = 0.1;
  double magnet_rate_walk_K_per_h_per_sqrt_h = 3.0;
  /// Steady-magnet hypothesis: the same two, small.
  double steady_magnet_drift_K_per_sqrt_h = 0.01;
  double steady_magnet_rate_walk_K_per_h_per_sqrt_h = 0.01;
  /// Prior probability of the steady magnet (0 = that filter is off: one filter, drifting).
  /// Favoured because a wrong "steady" is refuted by the first load change after a flux drift,
  /// while a wrong "drifting" is only less precise and is refuted slowly.
  double steady_magnet_prior = 0.9;
  double hypothesis_probability_floor = 1e-6;  ///< no hypothesis is ever ruled out for good
  /// A block whose mean iq differs from the previous block's by more than this is a load change:
  /// its innovations update the hypotheses' probabilities (block noise of iq is ~1 mA).
  double load_change_A = 0.02;
  double rate_time_constant_s = 3600.0;  ///< rates decay towards zero with this constant
  double flux_temperature_coefficient_per_K = -1e-3;  ///< NdFeB, d(psi_f)/psi_f per K
  double initial_resistance_sigma_rel = 0.1;  ///< nameplate Rs uncertainty (relative, 1 sigma)
  double initial_flux_sigma_rel = 0.05;       ///< nameplate psi_f uncertainty (relative)
  double excitation_window_s = 600.0;         ///< time constant of the excitation monitor
  double identifiable_sigma_rel = 0.005;      ///< Rs std (relative) the window must support
  /// "tracking" only while twice the winding temperature's 1-sigma is within this bound, K.
  double tracking_bound_K = 2.0;
  /// Voltage error left after compensation that may vary with the current (the dead-time
  /// shape near its knee, converter non-linearity), V. Over the window's spread of iq it is a
  /// resistance error that no covariance shows; it enters winding_sd_K.
  double voltage_error_allowance_V = 2e-4;
  /// Residual consistency: time constant of the mean of the squared normalised innovation,
  /// and the level above which the model is taken not to explain the data (expected 1).
  double consistency_window_s = 60.0;
  double max_consistency_nis = 4.0;
  /// Consecutive rejected or down-weighted blocks (z >= 3) before P is re-opened.
  int reacquire_after_rejections = 30;
  /// Unexplained drift of uq since the last load change (against the trend then known), over
  /// iq, in K of winding, above which the status is `held` (weighted by the drifting magnet's
  /// probability) and the drifting-magnet filter's flux is freed to take the drift.
  double drift_hold_K = 1.0;
  /// Rms of the voltage offset the window must support before it is reported, V.
  double offset_identifiable_sd_V = 0.01;
  /// Blocks whose mean |iq| is below this are not used at all (0 = use all). The inverter's
  /// dead-time voltage error is nearly constant (absorbed into psi_f) only well above its
  /// knee; below it, its slope against iq looks like resistance. About 3x the drive's knee.
  double min_current_A = 0.0;
  /// Blocks whose mean |iq| is below this count as idle (no copper loss, no resistive drop to
  /// see): Rs is held without extrapolating its rate, the rate is dropped, psi_f is tracked,
  /// and the status is not_identifiable (0 = off).
  double idle_current_A = 0.2;
};

/// One raw telemetry sample in SI units.
struct DqSample {
  double id_A = 0.0;
  double iq_A = 0.0;
  double ud_V = 0.0;
  double uq_V = 0.0;
  double w_r_rad_per_s = 0.0;  ///< electrical angular speed
};

/// The identifier's output after each sample.
struct ResistanceEstimate {
  double resistance_ohm = 0.0;        ///< Rs estimate (held while not identifiable)
  double flux_Wb = 0.0;               ///< psi_f estimate
  double winding_degC = 0.0;          ///< Han 2019 eq. 3 applied to resistance_ohm
  double resistance_sigma_ohm = 0.0;  ///< sqrt(P_RR)
  /// 1-sigma of winding_degC, K: sqrt(P_RR + allowance^2) / (R0 alpha) (Han 2019 eq. 3),
  /// the allowance being voltage_error_allowance_V over the window's spread of iq.
  double winding_sd_K = 0.0;
  double flux_sd_Wb = 0.0;    ///< sqrt(P_psi psi)
  double innovation_V = 0.0;  ///< eps of the last block update
  double weight = 0.0;        ///< Lambda of the last block update
  /// EW mean of the squared normalised innovation over consistency_window_s (1 when the
  /// residuals match their variance; above max_consistency_nis: no "tracking").
  double mean_nis = 1.0;
  double steady_magnet_probability = 0.0;  ///< probability of the steady-magnet hypothesis
  /// Drift of uq at constant current since the last load change that the trend then known does
  /// not predict, over |iq|, in K of winding (Han 2019 eq. 3): what the winding may have done
  /// unseen (0 right after a load change; NaN before the first one).
  double unexplained_drift_K = 0.0;
  /// Inverter voltage offset u0 in uq = Rs iq + w_r psi_f + u0 sign(iq), V, by least squares
  /// over excitation_window_s, and its 1-sigma; NaN while the window cannot separate it from
  /// Rs and psi_f (offset_identifiable_sd_V). After the motor file's voltage error is removed.
  double voltage_offset_V = 0.0;
  double voltage_offset_sd_V = 0.0;
  ResistanceStatus status = ResistanceStatus::kInitialising;
};

/// One magnet hypothesis' filter, as plain data.
struct ResistanceHypothesisState {
  /// [Rs ohm, dRs/dt ohm/s, psi_f Wb, dpsi_f/dt Wb/s], indexed by kState*.
  Eigen::Vector4d x = Eigen::Vector4d::Zero();
  Eigen::Matrix4d p = Eigen::Matrix4d::Zero();  ///< covariance of x, 4x4
  double probability = 0.0;                     ///< of this hypothesis, 0..1
  int consecutive_rejections = 0;
};

/// Everything needed to continue later, as plain data (the daemon's state store saves it).
struct ResistanceIdentifierState {
  std::array<ResistanceHypothesisState, kMagnetHypotheses> hypotheses;  ///< by kSteadyMagnet...
  /// EW moments of the block means [iq A, w_r rad/s, 1], 3x3 (the (2,2) element is the EW
  /// block count).
  Eigen::Matrix3d moments = Eigen::Matrix3d::Zero();
  std::uint64_t blocks = 0;  ///< block updates since start or reset
  /// The mixture's x after the last load change, propagated since with its rates: what the
  /// unexplained drift is measured against. anchor_valid false (e.g. a state file without it):
  /// the drift is measured from the first block after Restore.
  Eigen::Vector4d anchor = Eigen::Vector4d::Zero();
  bool anchor_valid = false;
  double drift_V = 0.0;    ///< unexplained drift of uq against the anchor, smoothed, V
  double drift_ohm = 0.0;  ///< |drift_V| over |iq| at the last block, ohm (>= 0)
};

/// Moments saved by an identifier without the constant regressor ([iq, w_r] only, 2x2) as
/// the 3x3 moments: the constant's row and column are zero (no evidence on an offset yet).
Eigen::Matrix3d MomentsFromTwoRegressors(const Eigen::Matrix2d& moments);

/// A state of the single-filter identifier (pumpthermd saved state version 1: one x, one P)
/// carried over: both hypotheses continue from it, with the prior probabilities of `config`.
ResistanceIdentifierState StateFromSingleFilter(const Eigen::Vector4d& x, const Eigen::Matrix4d& p,
                                                const Eigen::Matrix3d& moments,
                                                std::uint64_t blocks, int consecutive_rejections,
                                                const ResistanceIdentifierConfig& config);

class ResistanceIdentifier {
 public:
  /// Starts from the motor's nameplate (R0 at T0, psi_f). Throws std::invalid_argument when the
  /// config is out of range (block_samples < 1, a non-positive noise or window).
  ResistanceIdentifier(const MotorDescription& motor, const ResistanceIdentifierConfig& config);

  /// Feeds one raw sample taken `dt_s` after the previous one. Non-finite values are rejected
  /// (status kInvalidInput, nothing changes). Never throws, never allocates.
  ResistanceEstimate Update(const DqSample& sample, double dt_s) noexcept;

  /// The last output (kInitialising before the first block).
  const ResistanceEstimate& estimate() const { return estimate_; }

  /// Back to the nameplate, as after construction.
  void Reset() noexcept;

  ResistanceIdentifierState Save() const { return state_; }
  /// Continues from a saved state. Returns false (and changes nothing) when the state has
  /// non-finite values, a covariance that is not positive definite, probabilities outside
  /// 0..1 or summing to zero, or negative counters. Probabilities are renormalised (and the
  /// steady one set to 0 when steady_magnet_prior is 0). A restored estimate that no longer
  /// fits the motor is rejected block after block; after reacquire_after_rejections blocks the
  /// covariance is re-opened and the estimate converges again.
  bool Restore(const ResistanceIdentifierState& state) noexcept;

  /// Probability-weighted mixture of the hypotheses' states, and its covariance
  /// (sum_j mu_j (P_j + (x_j - x)(x_j - x)^T)); what the estimate reports.
  const Eigen::Vector4d& x() const { return x_; }
  const Eigen::Matrix4d& p() const { return p_; }

  const MotorDescription& motor() const { return motor_; }
  const ResistanceIdentifierConfig& config() const { return config_; }
  /// Block updates since start, reset or restore (a new one means a fresh estimate).
  std::uint64_t blocks() const noexcept { return state_.blocks; }

 private:
  void ProcessBlock() noexcept;
  void Mix() noexcept;
  bool SteadyOn() const noexcept { return config_.steady_magnet_prior > 0.0; }
  void ClearBlock() noexcept;
  struct Excitation {
    double info_two = 0.0;    // information on Rs with psi_f free, A^2 (block units)
    double info_three = 0.0;  // the same with a constant offset free as well
    double block_info = 0.0;  // this block's squared distance from the window's prediction
    double spread_A = 0.0;    // rms of iq about that prediction over the window
  };
  Excitation AssessExcitation(double iq, double w) const noexcept;
  ResistanceStatus Classify(bool separable, bool identifiable) const noexcept;
  double WindingSd_K() const noexcept;
  void Publish(ResistanceStatus status, double eps_V, double weight) noexcept;
  void ClearDriftAndOffset() noexcept;
  void RefuteInconsistent(double keep) noexcept;
  void UpdateDrift(double y, const Eigen::Vector4d& hrow, double dt) noexcept;
  double EffectiveDriftOhm() const noexcept;
  void ReopenAlongLine(double iq, double w, double var_ohm2) noexcept;
  void UpdateOffset(double iq, double w, double y, double decay, double r) noexcept;

  MotorDescription motor_;
  ResistanceIdentifierConfig config_;
  ResistanceIdentifierState state_;
  ResistanceEstimate estimate_;
  // Block accumulator (not part of the saved state: at most one block is lost on restore).
  int block_count_ = 0;
  double block_duration_s_ = 0.0;
  double sum_iq_A_ = 0.0;
  double sum_id_A_ = 0.0;
  double sum_w_rad_per_s_ = 0.0;
  double sum_y_V_ = 0.0;
  double uq_first_V_ = 0.0;  // first uq of the block: the sums below are relative to it
  double sum_duq_V_ = 0.0;   // (exact variance of 100 values near 40 V)
  double sum_duq2_V2_ = 0.0;
  double last_block_iq_A_ = 0.0;  // NaN after start, reset or restore: no load change seen
  double mean_nis_ = 1.0;         // EW mean of the squared normalised innovation (expected 1)
  std::array<double, kMagnetHypotheses> hypothesis_nis_{1.0, 1.0};  // the same per hypothesis
  std::array<double, kMagnetHypotheses> last_z_{};  // normalised innovations of the last block
  double allowance_ohm_ = 0.0;  // voltage_error_allowance_V over the iq spread when last
                                // identified (held with Rs)
  // Unexplained drift (anchor and drift in state_).
  bool anchor_pending_ = false;  // after a restore without an anchor: anchor on the next block
  bool flux_freed_ = false;      // the drifting filter's flux took excess drift since the anchor
  double last_block_w_rad_per_s_ = 0.0;
  // Offset least squares: EW moments of v = [iq, w_r / w_scale, sign(iq)] (3x3) and of v y.
  Eigen::Matrix3d offset_moments_ = Eigen::Matrix3d::Zero();
  Eigen::Vector3d offset_rhs_ = Eigen::Vector3d::Zero();
  double offset_V_ = 0.0;
  double offset_sd_V_ = 0.0;
  // Mixture of the hypotheses (what is published).
  Eigen::Vector4d x_ = Eigen::Vector4d::Zero();
  Eigen::Matrix4d p_ = Eigen::Matrix4d::Zero();
  // Derived constants.
  std::array<double, kMagnetHypotheses> q_resistance_ohm2_per_s_{};        // random walk of Rs
  std::array<double, kMagnetHypotheses> q_resistance_rate_ohm2_per_s3_{};  // of dRs/dt
  std::array<double, kMagnetHypotheses> q_flux_Wb2_per_s_{};
  std::array<double, kMagnetHypotheses> q_flux_rate_Wb2_per_s3_{};
  std::array<Eigen::Matrix4d, kMagnetHypotheses> p0_{};
  double speed_noise_rad_per_s_ = 0.0;
  double w_scale_rad_per_s_ = 1.0;  // rated electrical speed: scale of w_r in the monitor
  double r_min_ohm_ = 0.0;
  double r_max_ohm_ = 0.0;
};

}  // namespace pumptherm::estimators
