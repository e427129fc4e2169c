#include "estimators/readings/magnet_flux_reading.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace pumptherm::estimators {
namespace {

/// Whether the identifier's back-EMF line E = psi_f + Rs iq/w is fitted to data: not the
/// nameplate (initialising) and not from invalid input. It is usable whatever the split between
/// its two terms: at constant current a falling flux (a heating magnet) can move Rs out of its
/// plausible band (implausible) or be held (held, not identifiable) while E still follows uq/w.
bool LineUsable(ResistanceStatus s) {
  return s != ResistanceStatus::kInitialising && s != ResistanceStatus::kInvalidInput;
}

}  // namespace

MagnetFluxReading::MagnetFluxReading(const MotorDescription& motor, const ThermalModel& model,
                                     MagnetFluxReadingConfig config)
    : motor_(motor), model_(model), config_(std::move(config)) {
  if (config_.magnet_node.empty()) return;
  magnet_state_ = model_.StateIndex(config_.magnet_node);
  if (magnet_state_ < 0) {
    throw std::invalid_argument(
        fmt::format("magnet_node '{}' is not a node with heat capacity of model '{}'",
                    config_.magnet_node, model_.Name()));
  }
  if (!motor_.magnet.Given()) {
    throw std::invalid_argument(
        fmt::format("magnet_node '{}' is set but motor '{}' states no [magnet] table (t0_degC, "
                    "flux_temperature_coefficient_per_K) to turn the flux into a temperature",
                    config_.magnet_node, motor_.name));
  }
}

void MagnetFluxReading::Prepare(const IdentifierOutput& id, double iq_A, double w) {
  z_degC_ = std::nan("");
  gated_ = offered_ = false;
  status_.Reset(ReadingState::kAbsent);
  if (!motor_.magnet.Given()) return;
  const ResistanceEstimate& r = id.estimate;
  const bool fresh = id.block_age_s <= config_.stale_after_s + config_.period_s;
  // Below a tenth of rated speed the back-EMF is too small to tell the magnet's 0.1 %/K.
  const double w_min = 0.1 * ElectricalSpeed_rad_per_s(motor_, motor_.rated_speed_rpm);
  if (!fresh) {
    status_.state = std::isnan(id.block_age_s) ? ReadingState::kAbsent : ReadingState::kStale;
    return;
  }
  if (!LineUsable(r.status)) {
    status_.state = ReadingState::kNotIdentified;
    return;
  }
  if (!std::isfinite(iq_A) || !(std::abs(w) >= w_min)) {
    status_.state = ReadingState::kTooSlow;
    return;
  }
  const Eigen::Matrix4d& p = id.p;
  const double u = iq_A / w;  // s A / rad: the resistance's weight in E
  const double var_e = p(kStateFlux, kStateFlux) + u * u * p(kStateResistance, kStateResistance) +
                       2.0 * u * p(kStateResistance, kStateFlux);
  const double e = r.flux_Wb + r.resistance_ohm * u;
  const double psi0_beta = motor_.flux_Wb * motor_.magnet.flux_temperature_coefficient_per_K;
  const auto& cu = motor_.copper;
  // A model without a winding cannot take the Rs term: then the flux alone (g = 0).
  const bool winding = model_.WindingWeights().sum() > 0.0;
  gain_ = winding ? cu.r0_ohm * cu.alpha_per_K * u / psi0_beta : 0.0;
  gated_ = std::abs(gain_) > config_.max_winding_gain;
  voltage_gain_ = 1.0 / (w * psi0_beta);  // an error e on uq moves E by e/w
  const double drop = winding ? cu.r0_ohm * u : r.resistance_ohm * u;
  z_degC_ = motor_.magnet.t0_degC + (e - drop - motor_.flux_Wb) / psi0_beta + gain_ * cu.t0_degC;
  z_sd_K_ = std::sqrt(std::max(var_e, 0.0)) / std::abs(psi0_beta);
  status_.observation = z_degC_;
  status_.sd_K = z_sd_K_;
  offered_ = magnet_state_ >= 0 && std::isfinite(z_degC_) && !gated_;
  status_.state = gated_     ? ReadingState::kGated
                  : offered_ ? ReadingState::kRejected  // until the update says it was fused
                             : ReadingState::kNotFused;
}

void MagnetFluxReading::Offer(ThermalReadings& readings) const {
  if (!offered_) return;
  readings.magnet_degC = z_degC_;
  readings.magnet_sd_K = z_sd_K_;
  readings.magnet_winding_gain = gain_;
  readings.magnet_voltage_gain_K_per_V = voltage_gain_;
}

void MagnetFluxReading::Record(const ReadingRow& row) {
  if (offered_) status_.Record(row, ReadingState::kRejected);
}

double MagnetFluxReading::MagnetAt_degC(double winding_degC) const {
  if (!std::isfinite(z_degC_) || magnet_state_ < 0) return std::nan("");
  return z_degC_ - gain_ * winding_degC;
}

void MagnetFluxReading::Publish(const ThermalObserver& observer, double& degC, double& sd_K) const {
  degC = sd_K = std::nan("");
  if (!std::isfinite(z_degC_) || gated_) return;
  // A filter with a bias state follows the line's bias (the nameplate's psi0 and the inverter's
  // error): the line is published corrected by it, with its sd. A filter without one takes the
  // anchor as the bias.
  const double bias_sd_K = observer.MagnetBiasSd_K(voltage_gain_);
  const bool bias_state = std::isfinite(bias_sd_K);
  const double bias_K = bias_state ? observer.MagnetBias_K(voltage_gain_) : 0.0;
  const double z_sd_K =
      bias_state ? std::hypot(z_sd_K_, bias_sd_K) : std::max(z_sd_K_, config_.min_sd_K);
  const Eigen::VectorXd& w = model_.WindingWeights();
  const double winding_degC = observer.Weighted_degC(w);
  degC = z_degC_ - bias_K - gain_ * winding_degC;
  sd_K = std::sqrt(z_sd_K * z_sd_K + gain_ * gain_ * observer.WeightedVariance_K2(w));
}

}  // namespace pumptherm::estimators
