#pragma once
/// Thermal truth for the virtual-sensor experiments: a ThermalModel integrated exactly over each
/// step (ZOH, Saheba et al. 2010 eqs. 20-21) with Gaussian process noise added to every state,
/// as in the model of eq. 18. Deterministic for a given seed.

#include <Eigen/Dense>
#include <cstdint>
#include <random>

#include "estimators/thermal_discretisation.hpp"
#include "estimators/thermal_model.hpp"

namespace pumptherm::sim {

struct ThermalPlantConfig {
  /// Standard deviation of the process noise per state, K per `process_period_s` (variance
  /// scaled with the step length). 0 = the noiseless model.
  double process_sd_K = 0.0894;
  double process_period_s = 1.0;
};

class ThermalPlant {
 public:
  /// Keeps a reference to `model`, which must outlive the plant. Starts at `x0_degC` (n).
  ThermalPlant(const estimators::ThermalModel& model, const Eigen::VectorXd& x0_degC,
               ThermalPlantConfig config, std::uint64_t seed);

  /// Advances `dt_s` with `inputs` held, returns the new state temperatures (degC).
  const Eigen::VectorXd& Step(const estimators::ThermalInputs& inputs, double dt_s);
  /// Heat the model lacks, W per state (n; held over each step until set again): a fault that
  /// changes with time (a bearing's heat rising on the rotor) without re-parsing the model. An
  /// empty vector: none. Throws std::invalid_argument for another size or a non-finite value.
  void SetExtraHeat_W(const Eigen::VectorXd& heat_W);

  const Eigen::VectorXd& State_degC() const { return x_; }
  /// All node temperatures (massless ones solved) at the last inputs.
  Eigen::VectorXd AllTemperatures_degC(const estimators::ThermalInputs& inputs) const {
    return model_.AllTemperatures_degC(inputs, x_);
  }

 private:
  const estimators::ThermalModel& model_;
  ThermalPlantConfig config_;
  estimators::ThermalLinearModel lin_;
  estimators::ThermalDiscretiser discretiser_{1e-6};
  Eigen::VectorXd x_, next_;
  Eigen::VectorXd extra_K_per_s_;  ///< SetExtraHeat_W over the capacities (empty: none)
  std::mt19937_64 rng_;
  std::normal_distribution<double> normal_{0.0, 1.0};
};

}  // namespace pumptherm::sim
