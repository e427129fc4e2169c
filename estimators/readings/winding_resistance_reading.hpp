#pragma once
/// The winding temperature from the identified stator resistance (Han et al. 2019 eq. 3) as a
/// reading of the pump estimator: a reading of the model's winding weights.
///
/// Start: the identifier `tracking` (identifiable, converged, plausible). Gate: its last sample
/// at most stale_after_s old. Stop: either lost. Published whenever it starts; fused only when
/// configured and the filter has a winding row.

#include "estimators/pump_period.hpp"
#include "estimators/readings/reading_status.hpp"
#include "estimators/thermal_observer.hpp"

namespace pumptherm::estimators {

struct WindingResistanceReadingConfig {
  bool fuse = true;         ///< offered to the filter
  double model_sd_K = 3.0;  ///< the model's own error, in quadrature with the identifier's sd
  double stale_after_s = 2.0;
};

class WindingResistanceReading {
 public:
  explicit WindingResistanceReading(WindingResistanceReadingConfig config) : config_(config) {}

  void Prepare(const IdentifierOutput& identifier);
  void Offer(ThermalReadings& readings) const;
  void Record(const ReadingRow& row);
  /// The winding temperature and the identifier's own sd of it (NaN unless started).
  double degC() const { return degC_; }
  double sd_K() const { return sd_K_; }
  /// A reading was offered this step (a temperature is measured: not blind).
  bool Offered() const { return config_.fuse && std::isfinite(degC_); }
  const ReadingStatus& status() const { return status_; }

 private:
  WindingResistanceReadingConfig config_;
  double degC_ = std::numeric_limits<double>::quiet_NaN();
  double sd_K_ = std::numeric_limits<double>::quiet_NaN();
  ReadingStatus status_;
};

}  // namespace pumptherm::estimators
