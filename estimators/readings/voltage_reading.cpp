#include "estimators/readings/voltage_reading.hpp"

#include <cmath>

namespace pumptherm::estimators {

VoltageReading::VoltageReading(const MotorDescription& motor, VoltageReadingConfig config)
    : motor_(motor), law_(VoltageLawOf(motor)), config_(config) {}

void VoltageReading::Prepare(const DriveAverages& d, bool frame_failed) {
  offered_ = false;
  uq_V_ = std::nan("");
  status_.Reset(ReadingState::kAbsent);
  if (d.samples <= 0) return;
  if (frame_failed) {
    status_.state = ReadingState::kSensorFault;
    return;
  }
  if (d.samples < config_.min_samples || !std::isfinite(d.uq_V) || !std::isfinite(d.iq_A) ||
      !std::isfinite(d.w_rad_per_s) || !std::isfinite(d.id_A)) {
    status_.state = ReadingState::kStale;
    return;
  }
  if (!(d.iq_sd_A <= config_.max_iq_sd_A)) {
    status_.state = ReadingState::kGated;  // a load change inside the period
    return;
  }
  uq_V_ = d.uq_V - QAxisKnownTerms_V(motor_, d.id_A, d.iq_A, d.w_rad_per_s);
  uq_sd_V_ = config_.uq_noise_V / std::sqrt(static_cast<double>(d.samples));
  iq_A_ = d.iq_A;
  w_rad_per_s_ = d.w_rad_per_s;
  status_.observation = uq_V_;
  status_.sd_K = std::nan("");  // a voltage: the sd is in V (uq_sd_V_), not K
  offered_ = config_.fuse;
  status_.state = offered_ ? ReadingState::kRejected : ReadingState::kNotFused;
}

void VoltageReading::Offer(ThermalReadings& r) const {
  if (!offered_) return;
  r.uq_V = uq_V_;
  r.uq_sd_V = uq_sd_V_;
  r.iq_A = iq_A_;
  r.w_rad_per_s = w_rad_per_s_;
}

void VoltageReading::Record(const ReadingRow& row, bool taken) {
  if (!offered_) return;
  if (!taken) {
    status_.state = ReadingState::kNotFused;
    return;
  }
  status_.Record(row, ReadingState::kRejected);
}

double VoltageReading::MagnetAt_degC(const ThermalObserver& observer, const ThermalModel& model,
                                     int magnet_state) const {
  if (!std::isfinite(uq_V_) || magnet_state < 0 || !(std::abs(w_rad_per_s_) > 0.0) ||
      law_.beta_per_K == 0.0) {
    return std::nan("");
  }
  const ThermalObserver::Calibration c = observer.VoltageCalibration();
  if (!std::isfinite(c.dr)) return std::nan("");
  const Eigen::VectorXd& w = model.WindingWeights();
  const double winding_degC = observer.Weighted_degC(w);
  // The equation at the magnet's reference temperature, and its slope in Tm: linear in Tm.
  QAxisState s;
  s.winding_degC = winding_degC;
  s.magnet_degC = law_.magnet_t0_degC;
  s.dr = c.dr;
  s.dpsi = c.dpsi;
  s.dbeta = c.dbeta;
  s.u0_V = c.u0_V;
  const QAxisPoint p{iq_A_, w_rad_per_s_};
  const double at_t0 = QAxisVoltage_V(law_, p, s);
  const double slope = QAxisGradientAt(law_, p, s).magnet_V_per_K;
  return law_.magnet_t0_degC + (uq_V_ - at_t0) / slope;
}

}  // namespace pumptherm::estimators
