#include "estimators/readings/voltage_reading.hpp"

#include <cmath>
#include <limits>

namespace pumptherm::estimators {
namespace {

/// z = Tm + gain Tw from uq at a calibration: the equation is linear in Tw and Tm (its gradient
/// in them does not depend on them), so it is solved at the laws' reference temperatures.
VoltageMagnet SolveMagnet(const VoltageLaw& law, const QAxisPoint& p, QAxisState s, double uq_V) {
  s.winding_degC = law.t0_degC;
  s.magnet_degC = law.magnet_t0_degC;
  const QAxisGradient g = QAxisGradientAt(law, p, s);
  VoltageMagnet m;
  if (!(std::abs(g.magnet_V_per_K) > 0.0)) return m;
  m.winding_gain = g.winding_V_per_K / g.magnet_V_per_K;
  m.z_degC = law.magnet_t0_degC + m.winding_gain * law.t0_degC +
             (uq_V - QAxisVoltage_V(law, p, s)) / g.magnet_V_per_K;
  m.sd_K = 0.0;
  return m;
}

double Finite(double v) { return std::isfinite(v) ? v : 0.0; }

/// The equation's calibration terms as the observer has them (dbeta 0 where it has none).
QAxisState CalibratedState(const ThermalObserver::Calibration& c) {
  QAxisState s;
  s.dr = c.dr;
  s.dpsi = c.dpsi;
  s.dbeta = Finite(c.dbeta);
  s.u0_V = c.u0_V;
  return s;
}

}  // namespace

VoltageReading::VoltageReading(const MotorDescription& motor, VoltageReadingConfig config)
    : motor_(motor), law_(VoltageLawOf(motor)), config_(config) {}

void VoltageReading::Prepare(const DriveAverages& d, bool frame_failed) {
  offered_ = false;
  frame_failed_ = frame_failed;
  uq_V_ = std::nan("");
  status_.Reset(ReadingState::kAbsent);
  if (d.samples <= 0) return;
  ReadingState state = ReadingState::kRejected;  // usable, until the update says it was fused
  if (d.samples < config_.min_samples || !std::isfinite(d.uq_V) || !std::isfinite(d.iq_A) ||
      !std::isfinite(d.w_rad_per_s) || !std::isfinite(d.id_A)) {
    state = ReadingState::kStale;
  } else if (!(d.iq_change_sd_A <= config_.max_iq_change_sd_A) ||
             !(std::abs(d.iq_A) >= config_.min_current_A)) {
    state = ReadingState::kGated;  // a load change inside the period, or too little current
  } else {
    uq_V_ = d.uq_V - QAxisKnownTerms_V(motor_, d.id_A, d.iq_A, d.w_rad_per_s);
    uq_sd_V_ = config_.uq_noise_V / std::sqrt(static_cast<double>(d.samples));
    iq_A_ = d.iq_A;
    w_rad_per_s_ = d.w_rad_per_s;
  }
  if (frame_failed) {
    status_.state = ReadingState::kSensorFault;
    return;
  }
  if (state != ReadingState::kRejected) {
    status_.state = state;
    return;
  }
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
  if (frame_failed_ || !std::isfinite(uq_V_) || magnet_state < 0 ||
      !(std::abs(w_rad_per_s_) > 0.0) || law_.beta_per_K == 0.0) {
    return std::nan("");
  }
  const ThermalObserver::Calibration c = observer.VoltageCalibration();
  if (!std::isfinite(c.dr)) return std::nan("");
  const double winding_degC = observer.Weighted_degC(model.WindingWeights());
  return SolveMagnet(law_, QAxisPoint{iq_A_, w_rad_per_s_}, CalibratedState(c), uq_V_)
      .MagnetAt_degC(winding_degC);
}

VoltageMagnet VoltageReading::CalibratedMagnet(const ThermalObserver::Calibration& c,
                                               double winding_degC) const {
  VoltageMagnet m;
  if (!std::isfinite(uq_V_) || !(std::abs(w_rad_per_s_) > 0.0) || law_.beta_per_K == 0.0 ||
      !std::isfinite(c.dr) || !std::isfinite(c.dpsi) || !std::isfinite(c.u0_V) ||
      !std::isfinite(winding_degC)) {
    return m;
  }
  const QAxisPoint p{iq_A_, w_rad_per_s_};
  const QAxisState s = CalibratedState(c);
  m = SolveMagnet(law_, p, s, uq_V_);
  if (!std::isfinite(m.z_degC)) return VoltageMagnet{};
  const double magnet_degC = m.MagnetAt_degC(winding_degC);
  // Each calibration term moved by its sd: how far the magnet at this winding moves with it.
  double var_K2 = 0.0;
  const auto add = [&](double QAxisState::*term, double sd) {
    if (!(std::isfinite(sd) && sd > 0.0)) return;
    QAxisState moved = s;
    moved.*term += sd;
    const double d = SolveMagnet(law_, p, moved, uq_V_).MagnetAt_degC(winding_degC) - magnet_degC;
    var_K2 += std::isfinite(d) ? d * d : std::numeric_limits<double>::infinity();
  };
  add(&QAxisState::dr, c.dr_sd);
  add(&QAxisState::dpsi, c.dpsi_sd);
  add(&QAxisState::dbeta, c.dbeta_sd);
  add(&QAxisState::u0_V, c.u0_sd_V);
  const double noise_K = uq_sd_V_ / std::abs(QAxisGradientAt(law_, p, s).magnet_V_per_K);
  m.sd_K = std::sqrt(var_K2 + noise_K * noise_K);
  return m;
}

}  // namespace pumptherm::estimators
