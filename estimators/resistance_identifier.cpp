#include "estimators/resistance_identifier.hpp"

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "estimators/quantisation.hpp"

namespace pumptherm::estimators {
namespace {

constexpr double kSecondsPerHour = 3600.0;
// Share of the needed information one block must add to count as a fresh load change.
constexpr double kFreshExcitationShare = 0.01;
// Normalised innovation at which a block is rejected; also the cap of its evidence.
constexpr double kMaxEvidenceZ = 6.0;
// Smoothing of the unexplained drift of uq, s (a few blocks: noise down, little lag).
constexpr double kDriftSmoothing_s = 20.0;

// Four confidence levels in the spirit of Han 2019 eq. 23, on the normalised innovation
// z = |eps| / sqrt(S) (S = phi^T P phi + r, the innovation variance) instead of |eps| / |y|.
double NormalisedWeight(double z) noexcept {
  if (!(z < kMaxEvidenceZ)) return 0.0;  // untrusted (also NaN)
  if (z >= 4.0) return 0.1;              // low confidence
  if (z >= 3.0) return 0.5;              // high confidence
  return 1.0;                            // fully trusted
}

bool IsFinite(const DqSample& s) noexcept {
  return std::isfinite(s.id_A) && std::isfinite(s.iq_A) && std::isfinite(s.ud_V) &&
         std::isfinite(s.uq_V) && std::isfinite(s.w_r_rad_per_s);
}

}  // namespace

std::string_view ToString(ResistanceStatus status) noexcept {
  switch (status) {
    case ResistanceStatus::kInitialising:
      return "initialising";
    case ResistanceStatus::kConverging:
      return "converging";
    case ResistanceStatus::kTracking:
      return "tracking";
    case ResistanceStatus::kNotIdentifiable:
      return "not_identifiable";
    case ResistanceStatus::kImplausible:
      return "implausible";
    case ResistanceStatus::kInvalidInput:
      return "invalid_input";
    case ResistanceStatus::kHeld:
      return "held";
  }
  return "unknown";
}

ResistanceIdentifier::ResistanceIdentifier(const MotorDescription& motor,
                                           const ResistanceIdentifierConfig& config)
    : motor_(motor), config_(config) {
  if (config.block_samples < 1 || !(config.current_noise_A > 0.0) ||
      !(config.voltage_noise_V > 0.0) || !(config.speed_noise_rpm >= 0.0) ||
      !(config.excitation_window_s > 0.0) || !(config.identifiable_sigma_rel > 0.0) ||
      !(config.tracking_bound_K > 0.0) || !(config.voltage_error_allowance_V >= 0.0) ||
      !(config.consistency_window_s > 0.0) || !(config.max_consistency_nis > 0.0) ||
      !(config.initial_resistance_sigma_rel > 0.0) || !(config.initial_flux_sigma_rel > 0.0) ||
      !(config.winding_drift_K_per_sqrt_h >= 0.0) || !(config.magnet_drift_K_per_sqrt_h >= 0.0) ||
      !(config.winding_rate_walk_K_per_h_per_sqrt_h >= 0.0) ||
      !(config.steady_winding_drift_K_per_sqrt_h >= 0.0) ||
      !(config.steady_winding_rate_walk_K_per_h_per_sqrt_h >= 0.0) ||
      !(config.magnet_rate_walk_K_per_h_per_sqrt_h >= 0.0) ||
      !(config.steady_magnet_drift_K_per_sqrt_h >= 0.0) ||
      !(config.steady_magnet_rate_walk_K_per_h_per_sqrt_h >= 0.0) ||
      !(config.steady_magnet_prior >= 0.0 && config.steady_magnet_prior < 1.0) ||
      !(config.hypothesis_probability_floor >= 0.0 && config.hypothesis_probability_floor < 0.5) ||
      !(config.load_change_A > 0.0) || !(config.rate_time_constant_s > 0.0) ||
      !(config.min_current_A >= 0.0) || !(config.idle_current_A >= 0.0) ||
      !(config.drift_hold_K > 0.0) || !(config.offset_identifiable_sd_V > 0.0) ||
      config.reacquire_after_rejections < 1) {
    throw std::invalid_argument("ResistanceIdentifierConfig: a value is out of range");
  }
  const double dr_per_K = motor.copper.r0_ohm * motor.copper.alpha_per_K;
  const double dpsi_per_K = motor.flux_Wb * config.flux_temperature_coefficient_per_K;
  const double h = kSecondsPerHour;
  // Intensities: variance growth per second of each random walk (ohm^2/s, ohm^2/s^3, ...).
  // The winding's walk per hypothesis: under a steady magnet every uq drift at constant current
  // is resistance, so the winding may move fast (a cooling failure); under a drifting magnet
  // a fast winding would take the magnet's drift, so it stays slow.
  const double w_drift[kMagnetHypotheses] = {config.steady_winding_drift_K_per_sqrt_h,
                                             config.winding_drift_K_per_sqrt_h};
  const double w_rate_walk[kMagnetHypotheses] = {config.steady_winding_rate_walk_K_per_h_per_sqrt_h,
                                                 config.winding_rate_walk_K_per_h_per_sqrt_h};
  const double drift[kMagnetHypotheses] = {config.steady_magnet_drift_K_per_sqrt_h,
                                           config.magnet_drift_K_per_sqrt_h};
  const double rate_walk[kMagnetHypotheses] = {config.steady_magnet_rate_walk_K_per_h_per_sqrt_h,
                                               config.magnet_rate_walk_K_per_h_per_sqrt_h};
  speed_noise_rad_per_s_ = ElectricalSpeed_rad_per_s(motor, config.speed_noise_rpm);
  w_scale_rad_per_s_ = ElectricalSpeed_rad_per_s(motor, motor.rated_speed_rpm);
  r_min_ohm_ = PlausibleMinResistance_ohm(motor);
  r_max_ohm_ = PlausibleMaxResistance_ohm(motor);
  for (int j = 0; j < kMagnetHypotheses; ++j) {
    q_resistance_ohm2_per_s_[j] = std::pow(dr_per_K * w_drift[j], 2) / h;
    q_resistance_rate_ohm2_per_s3_[j] = std::pow(dr_per_K * w_rate_walk[j] / h, 2) / h;
    q_flux_Wb2_per_s_[j] = std::pow(dpsi_per_K * drift[j], 2) / h;
    q_flux_rate_Wb2_per_s3_[j] = std::pow(dpsi_per_K * rate_walk[j] / h, 2) / h;
    // Initial covariance: nameplate uncertainty; rates start at zero with the stationary
    // spread of their decaying random walk (q tau / 2).
    Eigen::Matrix4d& p0 = p0_[j];
    p0.setZero();
    p0(kStateResistance, kStateResistance) =
        std::pow(config.initial_resistance_sigma_rel * motor.copper.r0_ohm, 2);
    p0(kStateFlux, kStateFlux) = std::pow(config.initial_flux_sigma_rel * motor.flux_Wb, 2);
    p0(kStateResistanceRate, kStateResistanceRate) =
        q_resistance_rate_ohm2_per_s3_[j] * config.rate_time_constant_s / 2.0;
    // A steady magnet's rate walk may be 0; keep P0 positive definite with a floor far below
    // anything measurable (1e-9 of the drifting hypothesis' spread of 1 K/h).
    p0(kStateFluxRate, kStateFluxRate) =
        std::max(q_flux_rate_Wb2_per_s3_[j] * config.rate_time_constant_s / 2.0,
                 std::pow(1e-9 * dpsi_per_K / h, 2));
  }
  Reset();
}

Eigen::Matrix3d MomentsFromTwoRegressors(const Eigen::Matrix2d& moments) {
  Eigen::Matrix3d m = Eigen::Matrix3d::Zero();
  m.topLeftCorner<2, 2>() = moments;
  return m;
}

ResistanceIdentifierState StateFromSingleFilter(const Eigen::Vector4d& x, const Eigen::Matrix4d& p,
                                                const Eigen::Matrix3d& moments,
                                                std::uint64_t blocks, int consecutive_rejections,
                                                const ResistanceIdentifierConfig& config) {
  ResistanceIdentifierState s;
  for (auto& h : s.hypotheses) {
    h.x = x;
    h.p = p;
    h.consecutive_rejections = consecutive_rejections;
  }
  s.hypotheses[kSteadyMagnet].probability = config.steady_magnet_prior;
  s.hypotheses[kDriftingMagnet].probability = 1.0 - config.steady_magnet_prior;
  s.moments = moments;
  s.blocks = blocks;
  return s;
}

void ResistanceIdentifier::ClearBlock() noexcept {
  block_count_ = 0;
  block_duration_s_ = 0.0;
  sum_iq_A_ = sum_id_A_ = sum_w_rad_per_s_ = sum_y_V_ = 0.0;
  uq_first_V_ = sum_duq_V_ = sum_duq2_V2_ = 0.0;
}

void ResistanceIdentifier::ClearDriftAndOffset() noexcept {
  anchor_pending_ = false;
  flux_freed_ = false;
  last_block_w_rad_per_s_ = 0.0;
  offset_moments_.setZero();
  offset_rhs_.setZero();
  offset_V_ = std::numeric_limits<double>::quiet_NaN();
  offset_sd_V_ = std::numeric_limits<double>::quiet_NaN();
}

void ResistanceIdentifier::Reset() noexcept {
  state_ = ResistanceIdentifierState{};
  for (int j = 0; j < kMagnetHypotheses; ++j) {
    ResistanceHypothesisState& hyp = state_.hypotheses[j];
    hyp.x.setZero();
    hyp.x(kStateResistance) = motor_.copper.r0_ohm;
    hyp.x(kStateFlux) = motor_.flux_Wb;
    hyp.p = p0_[j];
  }
  state_.hypotheses[kSteadyMagnet].probability = config_.steady_magnet_prior;
  state_.hypotheses[kDriftingMagnet].probability = 1.0 - config_.steady_magnet_prior;
  ClearBlock();
  last_block_iq_A_ = std::numeric_limits<double>::quiet_NaN();
  mean_nis_ = 1.0;
  hypothesis_nis_ = {1.0, 1.0};
  allowance_ohm_ = 0.0;
  ClearDriftAndOffset();
  estimate_ = ResistanceEstimate{};
  Mix();
  Publish(ResistanceStatus::kInitialising, 0.0, 0.0);
}

bool ResistanceIdentifier::Restore(const ResistanceIdentifierState& state) noexcept {
  if (!state.moments.allFinite() || !state.anchor.allFinite() || !(state.drift_ohm >= 0.0) ||
      !std::isfinite(state.drift_ohm) || !std::isfinite(state.drift_V)) {
    return false;
  }
  double total = 0.0;
  for (const ResistanceHypothesisState& h : state.hypotheses) {
    if (!h.x.allFinite() || !h.p.allFinite() || h.consecutive_rejections < 0 ||
        !(h.probability >= 0.0 && h.probability <= 1.0)) {
      return false;
    }
    const Eigen::LLT<Eigen::Matrix4d> llt(h.p);
    if (llt.info() != Eigen::Success) return false;  // not positive definite
    total += h.probability;
  }
  ResistanceIdentifierState s = state;
  if (!SteadyOn()) {
    s.hypotheses[kSteadyMagnet].probability = 0.0;
    total = s.hypotheses[kDriftingMagnet].probability;
  }
  if (!(total > 0.0)) return false;
  for (ResistanceHypothesisState& h : s.hypotheses) h.probability /= total;
  state_ = s;
  ClearBlock();
  last_block_iq_A_ = std::numeric_limits<double>::quiet_NaN();
  mean_nis_ = 1.0;
  hypothesis_nis_ = {1.0, 1.0};
  // Without a saved anchor the drift is measured from the restored state on.
  ClearDriftAndOffset();
  anchor_pending_ = !state_.anchor_valid;
  // The allowance at the restored excitation (only the window's spread of iq is used here).
  allowance_ohm_ = 0.0;
  const Excitation ex = AssessExcitation(0.0, 0.0);
  if (ex.spread_A > 0.0) allowance_ohm_ = config_.voltage_error_allowance_V / ex.spread_A;
  Mix();
  Publish(state_.blocks == 0 ? ResistanceStatus::kInitialising : ResistanceStatus::kConverging, 0.0,
          0.0);
  return true;
}

void ResistanceIdentifier::Mix() noexcept {
  x_.setZero();
  for (const ResistanceHypothesisState& h : state_.hypotheses) x_ += h.probability * h.x;
  p_.setZero();
  for (const ResistanceHypothesisState& h : state_.hypotheses) {
    const Eigen::Vector4d d = h.x - x_;
    p_ += h.probability * (h.p + d * d.transpose());
  }
}

void ResistanceIdentifier::Publish(ResistanceStatus status, double eps_V, double weight) noexcept {
  estimate_.resistance_ohm = x_(kStateResistance);
  estimate_.flux_Wb = x_(kStateFlux);
  estimate_.winding_degC = TemperatureAt(motor_.copper, estimate_.resistance_ohm);
  estimate_.resistance_sigma_ohm = std::sqrt(std::max(p_(kStateResistance, kStateResistance), 0.0));
  estimate_.winding_sd_K = WindingSd_K();
  estimate_.flux_sd_Wb = std::sqrt(std::max(p_(kStateFlux, kStateFlux), 0.0));
  estimate_.innovation_V = eps_V;
  estimate_.weight = weight;
  estimate_.mean_nis = mean_nis_;
  estimate_.steady_magnet_probability = state_.hypotheses[kSteadyMagnet].probability;
  estimate_.unexplained_drift_K =
      state_.anchor_valid ? EffectiveDriftOhm() / (motor_.copper.r0_ohm * motor_.copper.alpha_per_K)
                          : std::numeric_limits<double>::quiet_NaN();
  estimate_.voltage_offset_V = offset_V_;
  estimate_.voltage_offset_sd_V = offset_sd_V_;
  estimate_.status = status;
}

ResistanceEstimate ResistanceIdentifier::Update(const DqSample& s, double dt_s) noexcept {
  if (!IsFinite(s) || !std::isfinite(dt_s) || dt_s < 0.0) {
    ResistanceEstimate out = estimate_;
    out.status = ResistanceStatus::kInvalidInput;
    return out;
  }
  // q-axis equation (Han 2019 eq. 6) with the Ls w_r id term moved to the output.
  sum_y_V_ += s.uq_V - motor_.inductance_H * s.w_r_rad_per_s * s.id_A;
  sum_iq_A_ += s.iq_A;
  sum_id_A_ += s.id_A;
  sum_w_rad_per_s_ += s.w_r_rad_per_s;
  if (block_count_ == 0) uq_first_V_ = s.uq_V;
  const double duq = s.uq_V - uq_first_V_;
  sum_duq_V_ += duq;
  sum_duq2_V2_ += duq * duq;
  block_duration_s_ += dt_s;
  if (++block_count_ >= config_.block_samples) ProcessBlock();
  return estimate_;
}

void ResistanceIdentifier::ProcessBlock() noexcept {
  const double n = block_count_;
  const double iq = sum_iq_A_ / n;
  const double w = sum_w_rad_per_s_ / n;
  double y = sum_y_V_ / n;
  const double dt = block_duration_s_;
  if (motor_.uq_resolution_V > 0.0 && block_count_ >= 2) {
    // Quantisation bias of the mean of uq (estimators/quantisation.hpp): a known periodic
    // function of the true mean, with the noise from this block's own variance (Sheppard).
    const double uq_mean = uq_first_V_ + sum_duq_V_ / n;
    const double uq_var = (sum_duq2_V2_ - sum_duq_V_ * sum_duq_V_ / n) / (n - 1.0);
    y += CorrectQuantisedMean(uq_mean, uq_var, block_count_, motor_.uq_resolution_V) - uq_mean;
  }
  // The inverter's voltage error (motor description), on the block means: within a block the
  // current barely moves, and one evaluation a block keeps the per-sample cost unchanged.
  y -= VoltageErrorQ_V(motor_, sum_id_A_ / n, iq);
  ClearBlock();
  ++state_.blocks;
  const double previous_iq = last_block_iq_A_;
  last_block_iq_A_ = iq;
  // A load change: the blocks whose innovations tell the magnet hypotheses apart.
  const bool load_change = std::abs(iq - previous_iq) > config_.load_change_A;  // false for NaN

  // Variance of the block-mean output error: voltage noise plus the regressor noise carried
  // through the model (errors in variables), each divided by the samples averaged.
  const double r = (std::pow(config_.voltage_noise_V, 2) +
                    std::pow(x_(kStateResistance) * config_.current_noise_A, 2) +
                    std::pow(x_(kStateFlux) * speed_noise_rad_per_s_, 2)) /
                   n;

  // Time update. Each parameter is an integrated, decaying random walk:
  //   theta' = theta + dt rate,  rate' = a rate,  a = exp(-dt / tau),
  // with process noise added to P (this replaces the 1/lambda of Han 2019 eq. 21 and is
  // bounded: P grows at most linearly while nothing is learnt, never exponentially).
  const double a = std::exp(-dt / config_.rate_time_constant_s);
  Eigen::Matrix4d f = Eigen::Matrix4d::Identity();
  f(kStateResistance, kStateResistanceRate) = dt;
  f(kStateFlux, kStateFluxRate) = dt;
  f(kStateResistanceRate, kStateResistanceRate) = a;
  f(kStateFluxRate, kStateFluxRate) = a;
  // Idle: with |iq| below idle_current_A there is no copper loss to drive the winding's
  // temperature and no resistive drop to see it by. The trend learnt under load no longer
  // applies (the winding cools), so Rs is held where it is, not extrapolated: its rate is
  // dropped (zero rows in F) and re-opened to its stationary prior for the next load.
  const bool idle = std::abs(iq) < config_.idle_current_A;
  if (idle) {
    f(kStateResistance, kStateResistanceRate) = 0.0;
    f(kStateResistanceRate, kStateResistanceRate) = 0.0;
  }

  // Excitation monitor: exponentially weighted moments of [iq, w_r, 1] over blocks.
  const Eigen::Vector3d v(iq, w, 1.0);
  const double decay = std::exp(-dt / config_.excitation_window_s);
  state_.moments = decay * state_.moments + v * v.transpose();
  if (!idle) UpdateOffset(iq, w, y, decay, r);
  const Excitation ex = AssessExcitation(iq, w);
  const double sigma_target = config_.identifiable_sigma_rel * motor_.copper.r0_ohm;
  const double info_needed = r / (sigma_target * sigma_target);
  // A load change makes the block count at once (its information is not spent on psi_f while
  // the window catches up): its iq's distance from the window's iq at this speed.
  const auto enough = [&](double info) {
    return info > 0.0 &&
           (info >= info_needed || ex.block_info >= kFreshExcitationShare * info_needed);
  };
  // separable: Rs apart from psi_f (Han 2019 eq. 6 as it stands); identifiable: also apart from
  // a constant voltage offset (the inverter's error at one sign of iq). Only the second moves Rs.
  const bool separable = !idle && enough(ex.info_two);
  const bool identifiable = separable && enough(ex.info_three);
  if (identifiable && ex.spread_A > 0.0)
    allowance_ohm_ = config_.voltage_error_allowance_V / ex.spread_A;
  // Too little current for the voltage model (dead-time knee): no measurement update.
  const bool measure = !(std::abs(iq) < config_.min_current_A);
  // A load change that identifies Rs ends the stretch in which a drift of uq could be either
  // resistance or flux. Until then the two hypotheses read a drift not predicted at the last
  // one differently: the steady magnet as resistance (its filter follows it), the drifting
  // magnet, once the drift exceeds drift_hold_K, mostly as flux, which may then move as fast as
  // the data say. The next load change shows which reading was right (Bayes' rule below).
  const bool fresh_change = load_change && identifiable && measure;
  const double hold_ohm = config_.drift_hold_K * motor_.copper.r0_ohm * motor_.copper.alpha_per_K;
  const bool drifted = state_.anchor_valid && !fresh_change && state_.drift_ohm > hold_ohm;
  if (state_.anchor_valid) state_.anchor = f * state_.anchor;
  // Where the drifting magnet's flux was freed, the winding may still have done part of the
  // drift unseen: re-open its Rs by the drift along the line the previous current fixed
  // (y = iq Rs + w_r psi_f at that iq), so that this load change, not the priors, decides how
  // much was resistance.
  if (fresh_change && flux_freed_ && state_.anchor_valid && state_.drift_ohm > 0.0) {
    ReopenAlongLine(previous_iq, last_block_w_rad_per_s_, state_.drift_ohm * state_.drift_ohm);
  }

  // Measurement row: y = iq Rs + w_r psi_f (Han 2019 eq. 6), h = [iq, 0, w_r, 0].
  const Eigen::Vector4d hrow(iq, 0.0, w, 0.0);
  std::array<double, kMagnetHypotheses> log_likelihood{};
  std::array<double, kMagnetHypotheses> eps_V{};
  std::array<double, kMagnetHypotheses> weight_of{};
  std::array<double, kMagnetHypotheses> z_of{};
  for (int j = 0; j < kMagnetHypotheses; ++j) {
    if (j == kSteadyMagnet && !SteadyOn()) continue;
    Eigen::Vector4d& x = state_.hypotheses[j].x;
    Eigen::Matrix4d& p = state_.hypotheses[j].p;
    Eigen::Matrix4d q = Eigen::Matrix4d::Zero();
    const auto add_pair = [&](int pos, int rate, double q_pos, double q_rate) {
      q(pos, pos) = q_pos * dt + q_rate * dt * dt * dt / 3.0;
      q(pos, rate) = q(rate, pos) = q_rate * dt * dt / 2.0;
      q(rate, rate) = q_rate * dt;
    };
    add_pair(kStateResistance, kStateResistanceRate, q_resistance_ohm2_per_s_[j],
             q_resistance_rate_ohm2_per_s3_[j]);
    add_pair(kStateFlux, kStateFluxRate, q_flux_Wb2_per_s_[j], q_flux_rate_Wb2_per_s3_[j]);
    // Beyond drift_hold_K the drifting magnet's flux may move as fast as the data say.
    const bool free_flux = drifted && j == kDriftingMagnet;
    const bool hold_rs = !identifiable;
    x = f * x;
    p = f * p * f.transpose() + q;
    if (idle)
      p(kStateResistanceRate, kStateResistanceRate) =
          p0_[j](kStateResistanceRate, kStateResistanceRate);
    // Bound the growth while nothing is learnt: scale row and column i together (a congruence
    // with a diagonal matrix), which keeps P symmetric positive definite.
    for (int i = 0; i < 4; ++i) {
      const double cap = 4.0 * p0_[j](i, i);
      if (p(i, i) > cap) {
        const double k = std::sqrt(cap / p(i, i));
        p.row(i) *= k;
        p.col(i) *= k;
      }
    }
    eps_V[j] = y - hrow.dot(x);
    if (!measure) continue;
    Eigen::Vector4d p_h = p * hrow;
    double s = hrow.dot(p_h) + r;
    if (free_flux && std::abs(w) > 0.0 && eps_V[j] * eps_V[j] > s) {
      // The flux alone explains the drift here, at whatever rate the magnet heats: the
      // innovation's excess over its predicted variance becomes flux process noise (covariance
      // matching, Mehra, IEEE Trans. Autom. Control 17 (1972) 693, sec. IV), so the filter stays
      // consistent instead of rejecting the data.
      p(kStateFlux, kStateFlux) += (eps_V[j] * eps_V[j] - s) / (w * w);
      flux_freed_ = true;
      p_h = p * hrow;
      s = hrow.dot(p_h) + r;
    }
    const double z = std::abs(eps_V[j]) / std::sqrt(s);
    z_of[j] = z;
    // Gaussian likelihood of the innovation; z capped at the rejection level so that one
    // outlying block cannot rule a hypothesis out.
    const double z_capped = std::min(z, kMaxEvidenceZ);
    log_likelihood[j] = -0.5 * z_capped * z_capped - 0.5 * std::log(s);
    const double weight = NormalisedWeight(z);
    weight_of[j] = weight;
    if (weight > 0.0) {
      const double r_eff = r / weight;  // Lambda divides the measurement variance (eq. 21)
      Eigen::Vector4d gain = p_h / (hrow.dot(p_h) + r_eff);
      if (hold_rs) {
        // Rs and psi_f cannot be told apart: hold Rs and its rate (Schmidt "consider" update:
        // their gain rows are zero, but their covariance and correlations are updated, so the
        // next load change still corrects Rs through the correlation with psi_f).
        gain(kStateResistance) = 0.0;
        gain(kStateResistanceRate) = 0.0;
      }
      x += gain * eps_V[j];
      // Joseph form P = (I - K h^T) P (I - K h^T)^T + K r K^T, valid for any gain (Bucy &
      // Joseph 1968; Simon, "Optimal State Estimation", 2006, eq. 5.19); keeps P symmetric PSD.
      const Eigen::Matrix4d a_mat = Eigen::Matrix4d::Identity() - gain * hrow.transpose();
      p = a_mat * p * a_mat.transpose() + r_eff * gain * gain.transpose();
      p = 0.5 * (p + p.transpose()).eval();
    }
    // A run of rejected or down-weighted blocks (z >= 3; 0.3 % of blocks by chance) says the
    // model no longer fits (a stale restored state, a motor swap, a held Rs that the data
    // contradict while this hypothesis' flux is stiff): re-open P.
    if (weight >= 1.0) {
      state_.hypotheses[j].consecutive_rejections = 0;
    } else if (++state_.hypotheses[j].consecutive_rejections >=
               config_.reacquire_after_rejections) {
      p = p0_[j];
      state_.hypotheses[j].consecutive_rejections = 0;
    }
  }
  // Probabilities of the hypotheses (Bayes' rule on load-change blocks; between load changes
  // both explain uq equally well, one with Rs and one with psi_f, and the tighter one would win
  // for no physical reason). A floor keeps a hypothesis that was wrong revivable.
  // Only where Rs is identifiable: while it is held, the stiffer filter mispredicts the held
  // part, which is no evidence about the magnet.
  if (SteadyOn() && measure && identifiable && load_change) {
    const double top = std::max(log_likelihood[kSteadyMagnet], log_likelihood[kDriftingMagnet]);
    double total = 0.0;
    for (int j = 0; j < kMagnetHypotheses; ++j) {
      state_.hypotheses[j].probability *= std::exp(log_likelihood[j] - top);
      total += state_.hypotheses[j].probability;
    }
    for (int j = 0; j < kMagnetHypotheses; ++j) {
      double& mu = state_.hypotheses[j].probability;
      mu = total > 0.0 ? mu / total
                       : (j == kSteadyMagnet ? config_.steady_magnet_prior
                                             : 1.0 - config_.steady_magnet_prior);
      mu = std::max(mu, config_.hypothesis_probability_floor);
    }
    const double sum = state_.hypotheses[kSteadyMagnet].probability +
                       state_.hypotheses[kDriftingMagnet].probability;
    for (int j = 0; j < kMagnetHypotheses; ++j) state_.hypotheses[j].probability /= sum;
  }
  last_z_ = z_of;
  const double keep = std::exp(-dt / config_.consistency_window_s);
  if (measure) RefuteInconsistent(keep);
  Mix();
  const int best =
      state_.hypotheses[kSteadyMagnet].probability >= state_.hypotheses[kDriftingMagnet].probability
          ? kSteadyMagnet
          : kDriftingMagnet;
  const bool anchored = fresh_change || anchor_pending_;
  if (anchored) {
    state_.anchor = x_;
    state_.anchor_valid = true;
    state_.drift_V = 0.0;
    anchor_pending_ = false;
    flux_freed_ = false;
  }
  if (state_.anchor_valid && !idle && !anchored) UpdateDrift(y, hrow, dt);
  last_block_w_rad_per_s_ = w;
  if (measure) {
    // Residual consistency of the hypothesis reported: the EW mean of z^2 (1 when the model and
    // its variances explain the data; capped so that one outlier is not a minute of doubt).
    const double z_capped = std::min(z_of[best], kMaxEvidenceZ);
    mean_nis_ = keep * mean_nis_ + (1.0 - keep) * z_capped * z_capped;
  }
  Publish(Classify(measure && separable, measure && identifiable), eps_V[best], weight_of[best]);
}

void ResistanceIdentifier::RefuteInconsistent(double keep) noexcept {
  // A hypothesis whose filter cannot explain the blocks between load changes within its own
  // variances (EW mean NIS above max_consistency_nis) while the other's can is refuted by those
  // blocks: a magnet heating several K/min moves uq by 0.1-0.2 V/min, which the steady magnet
  // could only read as a winding changing by tens of K/min. Its probability goes to the floor.
  // (Where both fit, only load changes decide, as above.)
  if (!SteadyOn()) return;
  for (int j = 0; j < kMagnetHypotheses; ++j) {
    const double z = std::min(last_z_[j], kMaxEvidenceZ);
    hypothesis_nis_[j] = keep * hypothesis_nis_[j] + (1.0 - keep) * z * z;
  }
  // Refuted: above the limit while the other is within half of it (a margin, so that two
  // filters that both struggle, e.g. with a flux step both reject, do not take turns).
  const double limit = config_.max_consistency_nis;
  const auto refutes = [&](int a, int b) {
    return hypothesis_nis_[a] > limit && hypothesis_nis_[b] <= 0.5 * limit;
  };
  int refuted = -1;
  if (refutes(kSteadyMagnet, kDriftingMagnet)) refuted = kSteadyMagnet;
  if (refutes(kDriftingMagnet, kSteadyMagnet)) refuted = kDriftingMagnet;
  if (refuted < 0) return;
  const double floor = config_.hypothesis_probability_floor;
  if (state_.hypotheses[refuted].probability <= floor) return;
  // The refuted filter continues from the other's state (as the mixing step of the interacting
  // multiple-model filter does, Bar-Shalom, Li, Kirubarajan 2001, sec. 11.6.6), so that it is
  // judged afresh at the next load changes instead of from a state its model could not follow.
  ResistanceHypothesisState& lost = state_.hypotheses[refuted];
  const ResistanceHypothesisState& won = state_.hypotheses[1 - refuted];
  lost.x = won.x;
  lost.p = won.p;
  lost.consecutive_rejections = won.consecutive_rejections;
  lost.probability = floor;
  state_.hypotheses[1 - refuted].probability = 1.0 - floor;
  hypothesis_nis_[refuted] = hypothesis_nis_[1 - refuted];
}

void ResistanceIdentifier::UpdateDrift(double y, const Eigen::Vector4d& hrow, double dt) noexcept {
  // uq itself against the anchor's prediction (Han 2019 eq. 6 at this block's iq and w_r), not
  // the filters' estimate, which lags or rejects the data when neither model fits. Smoothed
  // over kDriftSmoothing_s: a block mean carries ~2 mV of noise, 0.6 mV after smoothing.
  const double keep = std::exp(-dt / kDriftSmoothing_s);
  state_.drift_V = keep * state_.drift_V + (1.0 - keep) * (y - hrow.dot(state_.anchor));
  state_.drift_ohm = std::abs(state_.drift_V) / std::max(std::abs(hrow(0)), 1e-3);
}

void ResistanceIdentifier::ReopenAlongLine(double iq, double w, double var_ohm2) noexcept {
  // Direction that moves Rs by 1 ohm and psi_f by -iq/w_r, leaving iq Rs + w_r psi_f at the old
  // operating point unchanged; adding var n n^T keeps P symmetric positive definite. Only the
  // drifting magnet's filter: the steady one read the drift as resistance, and the load change
  // is to test that reading, not to absorb its error.
  // At most 3x the nameplate variance: the bound on P's growth (4x) scales Rs' row and column
  // alone, which would break the line's correlation and leave the flux free to take the step.
  Eigen::Vector4d n(1.0, 0.0, 0.0, 0.0);
  if (std::abs(w) > 0.0 && std::isfinite(iq)) n(kStateFlux) = -iq / w;
  const double var =
      std::min(var_ohm2, 3.0 * p0_[kDriftingMagnet](kStateResistance, kStateResistance));
  state_.hypotheses[kDriftingMagnet].p += var * n * n.transpose();
}

void ResistanceIdentifier::UpdateOffset(double iq, double w, double y, double decay,
                                        double r) noexcept {
  // Least squares of y = Rs iq + psi_f w_r + u0 sign(iq) over the window's blocks (the static
  // form of Han 2019 eq. 6 with the dead-time term): u0 is separable where iq varies
  // independently of w_r and of sign(iq), i.e. where the Schur complement of the sign's moment
  // is positive. w_r is scaled to the rated speed to keep the moments conditioned.
  const Eigen::Vector3d v(iq, w / w_scale_rad_per_s_, iq >= 0.0 ? 1.0 : -1.0);
  offset_moments_ = decay * offset_moments_ + v * v.transpose();
  offset_rhs_ = decay * offset_rhs_ + v * y;
  offset_V_ = offset_sd_V_ = std::numeric_limits<double>::quiet_NaN();
  const Eigen::Matrix3d& m = offset_moments_;
  const double det = m(0, 0) * m(1, 1) - m(0, 1) * m(0, 1);
  const double trace = m(0, 0) + m(1, 1);
  if (!(det > 1e-12 * trace * trace)) return;
  // Schur complement m22 - c^T A^-1 c with A the [iq, w_r] block and c its column to the sign.
  const double c0 = m(0, 2), c1 = m(1, 2);
  const double info =
      m(2, 2) - (m(1, 1) * c0 * c0 - 2.0 * m(0, 1) * c0 * c1 + m(0, 0) * c1 * c1) / det;
  if (!(info > 0.0)) return;
  const double sd = std::sqrt(r / info);
  if (!(sd <= config_.offset_identifiable_sd_V)) return;
  const Eigen::Vector3d theta = offset_moments_.ldlt().solve(offset_rhs_);
  if (!theta.allFinite()) return;
  offset_V_ = theta(2);
  offset_sd_V_ = sd;
}

ResistanceIdentifier::Excitation ResistanceIdentifier::AssessExcitation(double iq,
                                                                        double w) const noexcept {
  // Information on Rs with the other regressors free: the Schur complement of the moments
  // (the residual sum of squares of iq regressed on them). w_r is scaled to the rated speed so
  // that [w_r, 1], collinear at constant speed, stay well conditioned; a ridge of 1e-9 of the
  // trace keeps that block invertible (it counts slightly less of iq as explained).
  const Eigen::Matrix3d& m = state_.moments;
  Excitation ex;
  const double s_ii = m(0, 0);
  const double s_iw = m(0, 1);
  const double s_ww = m(1, 1);
  ex.info_two = s_ww > 0.0 ? s_ii - s_iw * s_iw / s_ww : s_ii;
  const double ws = w_scale_rad_per_s_;
  const double a = s_ww / (ws * ws), b = m(1, 2) / ws, c = m(2, 2);
  const double ridge = 1e-9 * (a + c) + 1e-300;
  const double det = (a + ridge) * (c + ridge) - b * b;
  const double g0 = s_iw / ws, g1 = m(0, 2);
  if (!(det > 0.0)) {
    ex.info_three = 0.0;
    return ex;
  }
  // coefficients of iq on [w_r / ws, 1]
  const double k0 = ((c + ridge) * g0 - b * g1) / det;
  const double k1 = ((a + ridge) * g1 - b * g0) / det;
  ex.info_three = std::max(s_ii - (k0 * g0 + k1 * g1), 0.0);
  const double predicted = k0 * w / ws + k1;
  ex.block_info = (iq - predicted) * (iq - predicted);
  ex.spread_A = c > 0.0 ? std::sqrt(ex.info_three / c) : 0.0;
  return ex;
}

double ResistanceIdentifier::EffectiveDriftOhm() const noexcept {
  // Under the steady magnet the drift is resistance, which its filter followed; under the
  // drifting magnet it may be any split of resistance and flux: the drift counts by the
  // probability of the drifting magnet.
  if (!state_.anchor_valid) return 0.0;
  const double steady = SteadyOn() ? state_.hypotheses[kSteadyMagnet].probability : 0.0;
  return std::sqrt(std::max(1.0 - steady, 0.0)) * state_.drift_ohm;
}

double ResistanceIdentifier::WindingSd_K() const noexcept {
  const double drift = EffectiveDriftOhm();
  const double var = std::max(p_(kStateResistance, kStateResistance), 0.0) +
                     allowance_ohm_ * allowance_ohm_ + drift * drift;
  return std::sqrt(var) / (motor_.copper.r0_ohm * motor_.copper.alpha_per_K);
}

ResistanceStatus ResistanceIdentifier::Classify(bool separable, bool identifiable) const noexcept {
  const double rs = x_(kStateResistance);
  if (!(rs >= r_min_ohm_ && rs <= r_max_ohm_)) return ResistanceStatus::kImplausible;
  if (!separable) return ResistanceStatus::kNotIdentifiable;
  if (!identifiable) return ResistanceStatus::kHeld;
  // uq drifted at constant current by more than the bound allows since the last load change.
  const double hold_ohm = config_.drift_hold_K * motor_.copper.r0_ohm * motor_.copper.alpha_per_K;
  if (EffectiveDriftOhm() > hold_ohm) return ResistanceStatus::kHeld;
  // Evidence, not a small covariance alone: the 2-sigma of the winding temperature within the
  // bound, and residuals consistent with the variances that gave it.
  if (2.0 * WindingSd_K() > config_.tracking_bound_K || mean_nis_ > config_.max_consistency_nis) {
    return ResistanceStatus::kConverging;
  }
  return ResistanceStatus::kTracking;
}

}  // namespace pumptherm::estimators
