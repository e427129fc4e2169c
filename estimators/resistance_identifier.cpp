#include "estimators/resistance_identifier.hpp"

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace pumptherm::estimators {
namespace {

constexpr double kSecondsPerHour = 3600.0;
// Share of the needed information one block must add to count as a fresh load change.
constexpr double kFreshExcitationShare = 0.01;

// Four confidence levels in the spirit of Han 2019 eq. 23, on the normalised innovation
// z = |eps| / sqrt(S) (S = phi^T P phi + r, the innovation variance) instead of |eps| / |y|.
double NormalisedWeight(double z) noexcept {
  if (!(z < 6.0)) return 0.0;  // untrusted (also NaN)
  if (z >= 4.0) return 0.1;    // low confidence
  if (z >= 3.0) return 0.5;    // high confidence
  return 1.0;                  // fully trusted
}

bool IsFinite(const DqSample& s) noexcept {
  return std::isfinite(s.id_A) && std::isfinite(s.iq_A) && std::isfinite(s.ud_V) &&
         std::isfinite(s.uq_V) && std::isfinite(s.w_r_rad_per_s);
}

}  // namespace

std::string_view ToString(ResistanceStatus status) noexcept {
  switch (status) {
    case ResistanceStatus::kInitialising: return "initialising";
    case ResistanceStatus::kConverging: return "converging";
    case ResistanceStatus::kTracking: return "tracking";
    case ResistanceStatus::kNotIdentifiable: return "not_identifiable";
    case ResistanceStatus::kImplausible: return "implausible";
    case ResistanceStatus::kInvalidInput: return "invalid_input";
  }
  return "unknown";
}

ResistanceIdentifier::ResistanceIdentifier(const MotorDescription& motor,
                                           const ResistanceIdentifierConfig& config)
    : motor_(motor), config_(config) {
  if (config.block_samples < 1 || !(config.current_noise_A > 0.0) ||
      !(config.voltage_noise_V > 0.0) || !(config.speed_noise_rpm >= 0.0) ||
      !(config.excitation_window_s > 0.0) || !(config.identifiable_sigma_rel > 0.0) ||
      !(config.converged_sigma_rel > 0.0) || !(config.initial_resistance_sigma_rel > 0.0) ||
      !(config.initial_flux_sigma_rel > 0.0) || !(config.winding_drift_K_per_sqrt_h >= 0.0) ||
      !(config.magnet_drift_K_per_sqrt_h >= 0.0) ||
      !(config.winding_rate_walk_K_per_h_per_sqrt_h >= 0.0) ||
      !(config.magnet_rate_walk_K_per_h_per_sqrt_h >= 0.0) || !(config.rate_time_constant_s > 0.0) ||
      !(config.min_current_A >= 0.0) || !(config.idle_current_A >= 0.0) ||
      config.reacquire_after_rejections < 1) {
    throw std::invalid_argument("ResistanceIdentifierConfig: a value is out of range");
  }
  const double dr_per_K = motor.copper.r0_ohm * motor.copper.alpha_per_K;
  const double dpsi_per_K = motor.flux_Wb * config.flux_temperature_coefficient_per_K;
  const double h = kSecondsPerHour;
  // Intensities: variance growth per second of each random walk (ohm^2/s, ohm^2/s^3, ...).
  q_resistance_ohm2_per_s_ = std::pow(dr_per_K * config.winding_drift_K_per_sqrt_h, 2) / h;
  q_resistance_rate_ohm2_per_s3_ =
      std::pow(dr_per_K * config.winding_rate_walk_K_per_h_per_sqrt_h / h, 2) / h;
  q_flux_Wb2_per_s_ = std::pow(dpsi_per_K * config.magnet_drift_K_per_sqrt_h, 2) / h;
  q_flux_rate_Wb2_per_s3_ = std::pow(dpsi_per_K * config.magnet_rate_walk_K_per_h_per_sqrt_h / h, 2) / h;
  speed_noise_rad_per_s_ = ElectricalSpeed_rad_per_s(motor, config.speed_noise_rpm);
  r_min_ohm_ = PlausibleMinResistance_ohm(motor);
  r_max_ohm_ = PlausibleMaxResistance_ohm(motor);
  // Initial covariance: nameplate uncertainty; rates start at zero with the stationary spread of
  // their decaying random walk (q tau / 2).
  p0_.setZero();
  p0_(kStateResistance, kStateResistance) =
      std::pow(config.initial_resistance_sigma_rel * motor.copper.r0_ohm, 2);
  p0_(kStateFlux, kStateFlux) = std::pow(config.initial_flux_sigma_rel * motor.flux_Wb, 2);
  p0_(kStateResistanceRate, kStateResistanceRate) =
      q_resistance_rate_ohm2_per_s3_ * config.rate_time_constant_s / 2.0;
  p0_(kStateFluxRate, kStateFluxRate) = q_flux_rate_Wb2_per_s3_ * config.rate_time_constant_s / 2.0;
  Reset();
}

void ResistanceIdentifier::Reset() noexcept {
  state_ = ResistanceIdentifierState{};
  state_.x.setZero();
  state_.x(kStateResistance) = motor_.copper.r0_ohm;
  state_.x(kStateFlux) = motor_.flux_Wb;
  state_.p = p0_;
  block_count_ = 0;
  block_duration_s_ = 0.0;
  sum_iq_A_ = sum_w_rad_per_s_ = sum_y_V_ = 0.0;
  estimate_ = ResistanceEstimate{};
  Publish(ResistanceStatus::kInitialising, 0.0, 0.0);
}

bool ResistanceIdentifier::Restore(const ResistanceIdentifierState& state) noexcept {
  if (!state.x.allFinite() || !state.p.allFinite() || !state.moments.allFinite() ||
      state.consecutive_rejections < 0) {
    return false;
  }
  const Eigen::LLT<Eigen::Matrix4d> llt(state.p);
  if (llt.info() != Eigen::Success) return false;  // not positive definite
  state_ = state;
  block_count_ = 0;
  block_duration_s_ = 0.0;
  sum_iq_A_ = sum_w_rad_per_s_ = sum_y_V_ = 0.0;
  Publish(state_.blocks == 0 ? ResistanceStatus::kInitialising : ResistanceStatus::kConverging,
          0.0, 0.0);
  return true;
}

void ResistanceIdentifier::Publish(ResistanceStatus status, double eps_V, double weight) noexcept {
  estimate_.resistance_ohm = state_.x(kStateResistance);
  estimate_.flux_Wb = state_.x(kStateFlux);
  estimate_.winding_degC = TemperatureAt(motor_.copper, estimate_.resistance_ohm);
  estimate_.resistance_sigma_ohm =
      std::sqrt(std::max(state_.p(kStateResistance, kStateResistance), 0.0));
  estimate_.innovation_V = eps_V;
  estimate_.weight = weight;
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
  sum_w_rad_per_s_ += s.w_r_rad_per_s;
  block_duration_s_ += dt_s;
  if (++block_count_ >= config_.block_samples) ProcessBlock();
  return estimate_;
}

void ResistanceIdentifier::ProcessBlock() noexcept {
  const double n = block_count_;
  const double iq = sum_iq_A_ / n;
  const double w = sum_w_rad_per_s_ / n;
  const double y = sum_y_V_ / n;
  const double dt = block_duration_s_;
  block_count_ = 0;
  block_duration_s_ = 0.0;
  sum_iq_A_ = sum_w_rad_per_s_ = sum_y_V_ = 0.0;
  ++state_.blocks;

  Eigen::Vector4d& x = state_.x;
  Eigen::Matrix4d& p = state_.p;
  // Variance of the block-mean output error: voltage noise plus the regressor noise carried
  // through the model (errors in variables), each divided by the samples averaged.
  const double r = (std::pow(config_.voltage_noise_V, 2) +
                    std::pow(x(kStateResistance) * config_.current_noise_A, 2) +
                    std::pow(x(kStateFlux) * speed_noise_rad_per_s_, 2)) /
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
  Eigen::Matrix4d q = Eigen::Matrix4d::Zero();
  const auto add_pair = [&](int pos, int rate, double q_pos, double q_rate) {
    q(pos, pos) = q_pos * dt + q_rate * dt * dt * dt / 3.0;
    q(pos, rate) = q(rate, pos) = q_rate * dt * dt / 2.0;
    q(rate, rate) = q_rate * dt;
  };
  add_pair(kStateResistance, kStateResistanceRate, q_resistance_ohm2_per_s_,
           q_resistance_rate_ohm2_per_s3_);
  add_pair(kStateFlux, kStateFluxRate, q_flux_Wb2_per_s_, q_flux_rate_Wb2_per_s3_);
  // Idle: with |iq| below idle_current_A there is no copper loss to drive the winding's
  // temperature and no resistive drop to see it by. The trend learnt under load no longer
  // applies (the winding cools), so Rs is held where it is, not extrapolated: its rate is
  // dropped (zero rows in F) and re-opened to its stationary prior for the next load.
  const bool idle = std::abs(iq) < config_.idle_current_A;
  if (idle) {
    f(kStateResistance, kStateResistanceRate) = 0.0;
    f(kStateResistanceRate, kStateResistanceRate) = 0.0;
  }
  x = f * x;
  p = f * p * f.transpose() + q;
  if (idle) p(kStateResistanceRate, kStateResistanceRate) = p0_(kStateResistanceRate, kStateResistanceRate);
  // Bound the growth while nothing is learnt: scale row and column i together (a congruence
  // with a diagonal matrix), which keeps P symmetric positive definite.
  for (int i = 0; i < 4; ++i) {
    const double cap = 4.0 * p0_(i, i);
    if (p(i, i) > cap) {
      const double k = std::sqrt(cap / p(i, i));
      p.row(i) *= k;
      p.col(i) *= k;
    }
  }

  // Excitation monitor: exponentially weighted moments of [iq, w_r]; the information on Rs
  // with psi_f free is the Schur complement S_ii - S_iw^2 / S_ww of the regressor moments.
  const Eigen::Vector2d v(iq, w);
  const double decay = std::exp(-dt / config_.excitation_window_s);
  state_.moments = decay * state_.moments + v * v.transpose();
  const double s_ii = state_.moments(0, 0);
  const double s_iw = state_.moments(0, 1);
  const double s_ww = state_.moments(1, 1);
  const double info_r = s_ww > 0.0 ? s_ii - s_iw * s_iw / s_ww : s_ii;  // A^2 (block units)
  const double sigma_target = config_.identifiable_sigma_rel * motor_.copper.r0_ohm;
  const double info_needed = r / (sigma_target * sigma_target);
  // Information this block alone adds: its iq's distance from the window's iq at this speed
  // (Schur complement of the previous moments updated by one block). A load change makes the
  // block count at once, so its information is not spent on psi_f while the window catches up.
  const double mean_iq = s_ww > 0.0 ? s_iw / s_ww * w : 0.0;
  const double block_info = (iq - mean_iq) * (iq - mean_iq);
  const bool identifiable = !idle && info_r > 0.0 &&
                            (info_r >= info_needed || block_info >= kFreshExcitationShare * info_needed);

  // Measurement row: y = iq Rs + w_r psi_f (Han 2019 eq. 6), h = [iq, 0, w_r, 0].
  const Eigen::Vector4d hrow(iq, 0.0, w, 0.0);
  const double eps = y - hrow.dot(x);
  if (std::abs(iq) < config_.min_current_A) {
    // Too little current for the voltage model (dead-time knee): no measurement update.
    Publish(Classify(false), eps, 0.0);
    return;
  }
  const Eigen::Vector4d p_h = p * hrow;
  const double s = hrow.dot(p_h) + r;
  const double weight = NormalisedWeight(std::abs(eps) / std::sqrt(s));
  if (weight > 0.0) {
    const double r_eff = r / weight;  // Lambda divides the measurement variance (eq. 21)
    Eigen::Vector4d gain = p_h / (hrow.dot(p_h) + r_eff);
    if (!identifiable) {
      // Rs and psi_f cannot be told apart: hold Rs and its rate (Schmidt "consider" update:
      // their gain rows are zero, but their covariance and correlations are updated, so the
      // next load change still corrects Rs through the correlation with psi_f).
      gain(kStateResistance) = 0.0;
      gain(kStateResistanceRate) = 0.0;
    }
    x += gain * eps;
    // Joseph form P = (I - K h^T) P (I - K h^T)^T + K r K^T, valid for any gain (Bucy & Joseph
    // 1968; Simon, "Optimal State Estimation", 2006, eq. 5.19); keeps P symmetric PSD.
    const Eigen::Matrix4d a_mat = Eigen::Matrix4d::Identity() - gain * hrow.transpose();
    p = a_mat * p * a_mat.transpose() + r_eff * gain * gain.transpose();
    p = 0.5 * (p + p.transpose()).eval();
    state_.consecutive_rejections = 0;
  } else if (++state_.consecutive_rejections >= config_.reacquire_after_rejections) {
    // The model no longer fits (a stale restored state, a motor swap): re-open P.
    p = p0_;
    state_.consecutive_rejections = 0;
  }
  Publish(Classify(identifiable), eps, weight);
}

ResistanceStatus ResistanceIdentifier::Classify(bool identifiable) const noexcept {
  const double rs = state_.x(kStateResistance);
  if (!(rs >= r_min_ohm_ && rs <= r_max_ohm_)) return ResistanceStatus::kImplausible;
  if (!identifiable) return ResistanceStatus::kNotIdentifiable;
  if (std::sqrt(state_.p(kStateResistance, kStateResistance)) > config_.converged_sigma_rel * motor_.copper.r0_ohm) {
    return ResistanceStatus::kConverging;
  }
  return ResistanceStatus::kTracking;
}

}  // namespace pumptherm::estimators
