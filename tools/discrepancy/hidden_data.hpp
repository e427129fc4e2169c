#pragma once
/// Data in which an effect is hidden (for the discrepancy tests): a thermal model with
/// effects of the discrepancy vocabulary switched on (estimators/model_effects.hpp) is the truth;
/// a load profile with speed and current both varying drives it; the measured series carry
/// sensor noise and quantisation (../shared/reference/realistic-signals.md). The result is in the
/// workflow's CSV format (tools/discrepancy/data.hpp). Same configuration and seed, same bytes.

#include <cstdint>
#include <string>
#include <vector>

#include "estimators/model_effects.hpp"
#include "estimators/thermal_model.hpp"
#include "tools/discrepancy/data.hpp"

namespace pumptherm::tools::discrepancy {

/// What to generate. Defaults suit the Saheba 2010 machine (3.8 kW, 800 r/min in the paper).
struct HiddenDataConfig {
  std::string model_text;    ///< the model file's text (the workflow's model before effects)
  std::string model_source;  ///< names it in errors
  estimators::ThermalModelFiles files;     ///< how tables the model names are read
  std::vector<estimators::Effect> hidden;  ///< effects switched on in the truth (may be empty)
  std::vector<std::string> measured_nodes{"frame", "yoke", "slot_winding", "end_winding", "rotor"};

  double duration_s = 6.0 * 3600.0;
  double step_s = 10.0;  ///< sample period
  /// Load profile: steps of random length in [segment_min_s, segment_max_s], speed uniform in
  /// [0, max_speed_rpm] (a quarter of the segments at standstill), iq uniform in
  /// [0, max_current_A] with id = 0; the ambient drifts by +/- ambient_drift_K over a day.
  double segment_min_s = 600.0, segment_max_s = 2400.0;
  double max_speed_rpm = 3000.0;
  double max_current_A = 60.0;
  double ambient_degC = 22.0, ambient_drift_K = 1.0;
  double coolant_degC = 40.0;      ///< only written when the model has a coolant
  std::uint64_t profile_seed = 1;  ///< choose a different one for validation data

  // Measurement chain (realistic-signals.md): RTD noise and 0.1 K resolution; 12-bit currents
  // on +/-max range with noise of one step; speed estimate noise; process noise on every state.
  double temperature_noise_K = 0.0557;
  double temperature_lsb_K = 0.1;
  double current_noise_A = 0.03;
  double current_lsb_A = 0.0;  ///< 0: 2 * 1.5 * max_current_A / 4096
  double speed_noise_rpm = 1.0;
  double process_sd_K = 0.01;  ///< per state, per second (ThermalPlant)
  std::uint64_t noise_seed = 7;
};

/// Generates the data set. Throws estimators::ThermalModelError when the model or an effect
/// does not apply, std::invalid_argument for a measured node that is not a state of the model
/// or a bad duration/step.
Data MakeHiddenEffectData(const HiddenDataConfig& config);

}  // namespace pumptherm::tools::discrepancy
