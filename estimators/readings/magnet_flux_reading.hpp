#pragma once
/// The magnet's temperature from the identified back-EMF as a reading of the pump estimator
/// (docs/virtual-sensor.md, "Magnet temperature from the flux").
///
/// The resistance identifier fits the line uq/w = psi_f + Rs iq/w (Han et al. 2019 eq. 6 with
/// id = 0). Between load changes it cannot split the two terms: while it holds Rs and the
/// winding heats, psi_f absorbs the resistive drop. Their sum at the period's iq,
/// E = psi_f + Rs iq/w, is what it sees well. With the copper law R = R0 (1 + alpha (Tw - T0))
/// (Han 2019 eq. 2) and the magnet law psi = psi0 (1 + beta (Tm - T0m)) (estimators/magnet.hpp),
/// E is linear in both temperatures:
///     z = T0m + (E - psi0 - R0 iq/w) / (psi0 beta) + g T0 = Tm + g Tw,
///     g = R0 alpha iq / (w psi0 beta),
/// a reading of the magnet node plus g times the winding, which the filter takes as one row. Its
/// white sd is E's (from the identifier's covariance of [Rs, psi_f]) over psi0 |beta|.
///
/// Start: the identifier's line fitted to data (not its nameplate, not invalid input), fresh
/// (its last block at most stale_after_s + one period old), at a tenth of rated speed or more.
/// Gate: |g| at most max_winding_gain (under load the reading is mostly the winding's resistive
/// drop, where the identifier's errors would move the winding, not the magnet). Stop: either
/// condition lost.

#include <string>

#include "estimators/motor.hpp"
#include "estimators/pump_period.hpp"
#include "estimators/readings/reading_status.hpp"
#include "estimators/thermal_model.hpp"
#include "estimators/thermal_observer.hpp"

namespace pumptherm::estimators {

struct MagnetFluxReadingConfig {
  std::string magnet_node;  ///< the node the reading is fused into (empty: published only)
  /// Least sd of the published magnet temperature, K (the identifier's covariance sees its
  /// noise, not the nameplate flux's error or the inverter's voltage error).
  double min_sd_K = 3.0;
  double max_winding_gain = 0.15;  ///< the gate on |g|
  double stale_after_s = 2.0;      ///< with one period more: the identifier's line is fresh
  double period_s = 1.0;
};

class MagnetFluxReading {
 public:
  /// Throws std::invalid_argument when `magnet_node` is set but is not a node with heat
  /// capacity of `model`, or the motor states no magnet law (MotorDescription::magnet).
  MagnetFluxReading(const MotorDescription& motor, const ThermalModel& model,
                    MagnetFluxReadingConfig config);

  /// This step's reading from the identifier's line at the period's mean iq `mean_iq_A` and
  /// electrical speed `w_rad_per_s`.
  void Prepare(const IdentifierOutput& identifier, double mean_iq_A, double w_rad_per_s);
  /// The reading into `readings` when it is fused (a magnet node, started, within its gate).
  void Offer(ThermalReadings& readings) const;
  void Record(const ReadingRow& row);
  /// A reading was offered this step (a temperature is measured: not blind).
  bool Offered() const { return offered_; }
  /// The magnet temperature this step's reading gives at a winding temperature `winding_degC`
  /// (z - g Tw), for the mismatch test's naming fit (its gate does not apply there: the fit
  /// takes the reading's slow error as a constant over its window); NaN without a reading or a
  /// magnet node.
  double MagnetAt_degC(double winding_degC) const;
  /// The magnet temperature at the observer's winding estimate and its sd,
  /// var = max(sd_z, min_sd_K)^2 + g^2 w^T S w (w: the model's winding weights); with a bias
  /// state in the observer, corrected by the bias it estimates and var = sd_z^2 + sd_b^2 +
  /// g^2 w^T S w. NaN without a reading within its gate.
  void Publish(const ThermalObserver& observer, double& degC, double& sd_K) const;
  const ReadingStatus& status() const { return status_; }
  /// The node it is fused into (-1: none).
  int magnet_state() const { return magnet_state_; }

 private:
  const MotorDescription& motor_;
  const ThermalModel& model_;
  MagnetFluxReadingConfig config_;
  int magnet_state_ = -1;
  double z_degC_ = std::numeric_limits<double>::quiet_NaN();
  double gain_ = 0.0;
  double voltage_gain_ = 0.0;  ///< K per V of the drive's q-voltage error
  double z_sd_K_ = std::numeric_limits<double>::quiet_NaN();
  bool gated_ = false;
  bool offered_ = false;
  ReadingStatus status_;
};

}  // namespace pumptherm::estimators
