#include "tools/sim/thermal_plant.hpp"

#include <cmath>
#include <stdexcept>

namespace pumptherm::sim {

ThermalPlant::ThermalPlant(const estimators::ThermalModel& model, const Eigen::VectorXd& x0_degC,
                           ThermalPlantConfig config, std::uint64_t seed)
    : model_(model), config_(config), x_(x0_degC), next_(x0_degC.size()), rng_(seed) {}

const Eigen::VectorXd& ThermalPlant::Step(const estimators::ThermalInputs& inputs, double dt_s) {
  model_.Linearise(inputs, x_, lin_);
  if (extra_K_per_s_.size() > 0) lin_.f_K_per_s += extra_K_per_s_;
  discretiser_.Update(lin_, dt_s);
  discretiser_.Propagate(x_, lin_, next_);
  const double sd = config_.process_sd_K * std::sqrt(dt_s / config_.process_period_s);
  for (Eigen::Index i = 0; i < next_.size(); ++i) next_(i) += sd * normal_(rng_);
  x_ = next_;
  return x_;
}

void ThermalPlant::SetExtraHeat_W(const Eigen::VectorXd& heat_W) {
  if (heat_W.size() == 0) {
    extra_K_per_s_.resize(0);
    return;
  }
  if (heat_W.size() != x_.size() || !heat_W.allFinite()) {
    throw std::invalid_argument("ThermalPlant::SetExtraHeat_W: need one finite heat per state");
  }
  extra_K_per_s_ = heat_W.cwiseQuotient(model_.Capacities_J_per_K());
}

}  // namespace pumptherm::sim
