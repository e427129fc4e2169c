#include "estimators/readings/winding_resistance_reading.hpp"

#include <cmath>

namespace pumptherm::estimators {

void WindingResistanceReading::Prepare(const IdentifierOutput& id) {
  degC_ = sd_K_ = std::nan("");
  const ResistanceEstimate& r = id.estimate;
  if (std::isnan(id.sample_age_s)) {
    status_.Reset(ReadingState::kAbsent);
    return;
  }
  if (r.status != ResistanceStatus::kTracking) {
    status_.Reset(ReadingState::kNotIdentified);
    return;
  }
  if (!(id.sample_age_s <= config_.stale_after_s)) {
    status_.Reset(ReadingState::kStale);
    return;
  }
  degC_ = r.winding_degC;
  sd_K_ = r.winding_sd_K;
  status_.Reset(config_.fuse ? ReadingState::kRejected : ReadingState::kNotFused);
  status_.observation = degC_;
  // The identifier's 1-sigma and the model's own add in quadrature: independent.
  status_.sd_K = std::hypot(sd_K_, config_.model_sd_K);
}

void WindingResistanceReading::Offer(ThermalReadings& readings) const {
  if (!Offered()) return;
  readings.winding_degC = degC_;
  readings.winding_sd_K = status_.sd_K;
}

void WindingResistanceReading::Record(const ReadingRow& row) {
  // Offered but without a row in the filter (the disturbance-state filter takes none): not fused.
  if (Offered()) status_.Record(row, ReadingState::kNotFused);
}

}  // namespace pumptherm::estimators
