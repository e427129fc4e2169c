#pragma once
/// Online stator-resistance identifier for a pump motor: the project's estimator, built on the
/// DFRLS idea of Han, Xiong, Mao, Vacuum 169 (2019) 108935 (eqs. 6, 21-23) and completed where
/// the paper leaves things open. docs/resistance-identification.md explains every decision.
///
/// Per raw sample (e.g. every 10 ms) Update() accumulates
///     y = uq - Ls w_r id   and   phi = [iq, w_r]
/// (the q-axis equation of Han 2019 eq. 6 is linear, so block averages satisfy it exactly).
/// Every `block_samples` samples the block means enter a Kalman-form discounted least-squares
/// update of x = [Rs, dRs/dt, psi_f, dpsi_f/dt] (measurement row [iq, 0, w_r, 0]) in which
///   - forgetting is process noise added to P (each parameter drifts with a rate that itself
///     wanders and decays with rate_time_constant_s, as a temperature approaching equilibrium
///     does), not a division by lambda, so P cannot wind up, and between load changes the
///     resistance follows the trend learnt from earlier load changes;
///   - the weight Lambda is the paper's four levels but on the normalised innovation
///     |eps| / sqrt(phi^T P phi + r) instead of |eps| / |y| (eq. 23 rejects nearly every sample
///     under realistic noise); Lambda = 0 leaves theta unchanged;
///   - an excitation monitor (exponentially weighted information on Rs with psi_f free, i.e.
///     the Schur complement of the regressor moments) decides whether Rs and psi_f can be told
///     apart; when they cannot, Rs is held and only psi_f is tracked;
///   - the estimate is checked against a plausible band from the motor description.
/// Every output carries one ResistanceStatus.
///
/// Pure: no I/O, no clock (time enters as dt_s), no allocation after construction.

#include <Eigen/Core>
#include <cstdint>
#include <string_view>

#include "estimators/motor.hpp"

namespace pumptherm::estimators {

/// Indices of the identifier's state vector.
inline constexpr int kStateResistance = 0;
inline constexpr int kStateResistanceRate = 1;
inline constexpr int kStateFlux = 2;
inline constexpr int kStateFluxRate = 3;

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
};

/// Lower-case name of a status ("tracking", "not_identifiable", ...).
std::string_view ToString(ResistanceStatus status) noexcept;

/// Tuning of the identifier; the defaults suit the Han 2019 TMP at 10 ms sampling with the
/// noise of ../shared/reference/realistic-signals.md.
struct ResistanceIdentifierConfig {
  int block_samples = 100;                ///< raw samples averaged per update (10 ms -> 1 s)
  double current_noise_A = 0.01;          ///< rms noise of one raw iq sample
  double voltage_noise_V = 0.02;          ///< rms noise of one raw uq sample
  double speed_noise_rpm = 1.0;           ///< rms noise of one raw mechanical speed sample
  double winding_drift_K_per_sqrt_h = 1.0;   ///< random walk of the winding temperature
  double winding_rate_walk_K_per_h_per_sqrt_h = 10.0;  ///< random walk of its rate of change
  double magnet_drift_K_per_sqrt_h = 0.1;    ///< random walk of the magnet temperature
  double magnet_rate_walk_K_per_h_per_sqrt_h = 1.0;    ///< random walk of its rate of change
  double rate_time_constant_s = 3600.0;      ///< rates decay towards zero with this constant
  double flux_temperature_coefficient_per_K = -1e-3;  ///< NdFeB, d(psi_f)/psi_f per K
  double initial_resistance_sigma_rel = 0.1;  ///< nameplate Rs uncertainty (relative, 1 sigma)
  double initial_flux_sigma_rel = 0.05;       ///< nameplate psi_f uncertainty (relative)
  double excitation_window_s = 600.0;     ///< time constant of the excitation monitor
  double identifiable_sigma_rel = 0.005;  ///< Rs std (relative) the window must support
  double converged_sigma_rel = 0.003;     ///< Rs std (relative) for "tracking"
  int reacquire_after_rejections = 30;    ///< consecutive rejected blocks before P is re-opened
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
  double innovation_V = 0.0;          ///< eps of the last block update
  double weight = 0.0;                ///< Lambda of the last block update
  ResistanceStatus status = ResistanceStatus::kInitialising;
};

/// Everything needed to continue later, as plain data (the daemon's state store saves it).
struct ResistanceIdentifierState {
  /// [Rs ohm, dRs/dt ohm/s, psi_f Wb, dpsi_f/dt Wb/s], indexed by kState*.
  Eigen::Vector4d x = Eigen::Vector4d::Zero();
  Eigen::Matrix4d p = Eigen::Matrix4d::Zero();      ///< covariance of x, 4x4
  Eigen::Matrix2d moments = Eigen::Matrix2d::Zero();  ///< EW moments of [iq, w_r] over blocks
  std::uint64_t blocks = 0;                         ///< block updates since start or reset
  int consecutive_rejections = 0;
};

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
  /// non-finite values or a covariance that is not positive definite. A restored estimate that
  /// no longer fits the motor is rejected block after block; after reacquire_after_rejections
  /// blocks the covariance is re-opened and the estimate converges again.
  bool Restore(const ResistanceIdentifierState& state) noexcept;

  const MotorDescription& motor() const { return motor_; }
  const ResistanceIdentifierConfig& config() const { return config_; }

 private:
  void ProcessBlock() noexcept;
  ResistanceStatus Classify(bool identifiable) const noexcept;
  void Publish(ResistanceStatus status, double eps_V, double weight) noexcept;

  MotorDescription motor_;
  ResistanceIdentifierConfig config_;
  ResistanceIdentifierState state_;
  ResistanceEstimate estimate_;
  // Block accumulator (not part of the saved state: at most one block is lost on restore).
  int block_count_ = 0;
  double block_duration_s_ = 0.0;
  double sum_iq_A_ = 0.0;
  double sum_w_rad_per_s_ = 0.0;
  double sum_y_V_ = 0.0;
  // Derived constants.
  double q_resistance_ohm2_per_s_ = 0.0;    // random walk of Rs
  double q_resistance_rate_ohm2_per_s3_ = 0.0;  // random walk of dRs/dt
  double q_flux_Wb2_per_s_ = 0.0;
  double q_flux_rate_Wb2_per_s3_ = 0.0;
  Eigen::Matrix4d p0_ = Eigen::Matrix4d::Zero();
  double speed_noise_rad_per_s_ = 0.0;
  double r_min_ohm_ = 0.0;
  double r_max_ohm_ = 0.0;
};

}  // namespace pumptherm::estimators
