#pragma once
/// The vocabulary of the model discrepancy workflow (docs/discrepancy.md): small physical
/// extensions of a thermal model, each with one or two parameters and a neutral value at which it
/// changes nothing.
///
/// Model effects are applied by editing the model file: the effect's parameters are added to
/// `[parameters]` and the affected capacity, resistance or loss becomes an expression of them, so
/// a fit changes only parameter values and the edited file loads wherever a model file does
/// (ThermalModel::Parse, every tool, the daemon). Sensor effects (`sensor_lag`,
/// `sensor_offset`) act on one measured series; in the model file they are recorded as
/// parameters only (the schema has no sensors).
///
/// | effect | parameters (neutral) | equation |
/// | --- | --- | --- |
/// | frame_thermal_mass | frame_extra_capacity_J_per_K (0) | C_frame' = C_frame + dC |
/// | frame_ambient_resistance | frame_resistance_scale (1) | R_fb' = s R_fb, every frame-boundary
/// edge | | speed_dependent_cooling | cooling_speed_gain_per_krpm (0) | R_c' = R_c / max(1 + g
/// abs(n)/1000, 0.05), every edge to a boundary | | winding_conductance | winding_resistance_scale
/// (1) | R_w' = s R_w, the edge between two winding nodes | | copper_temperature_coefficient |
/// copper_alpha_delta_per_K (0) | alpha' = alpha + d_alpha (copper loss terms) | | iron_loss_scale
/// | iron_loss_scale (1) | P_Fe' = s P_Fe (loss terms named iron*) | | rotor_loss |
/// rotor_loss_W_per_krpm2 (0) | P_rotor = k (n/1000)^2 on the rotor node | | sensor_lag |
/// sensor_lag_s (0) | tau dy/dt = T - y (exact for inputs held over a step) | | sensor_offset |
/// sensor_offset_K (0) | y = T + b |
///
/// Pure library: parses and writes text handed to it, no I/O.

#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace pumptherm::estimators {

/// One parameter of an effect.
struct EffectParameterSpec {
  std::string name;      ///< name in the model's [parameters] (units in the name)
  double neutral = 0.0;  ///< value at which the effect changes nothing
  double lower = 0.0;    ///< physical bounds for fitting
  double upper = 0.0;
  double typical = 1.0;  ///< magnitude of a noticeable effect (fit scaling)
};

/// One effect of the vocabulary.
struct EffectSpec {
  std::string name;
  bool sensor = false;  ///< acts on one measured series, not on the network
  std::string meaning;  ///< one line: what is physically missing
  std::vector<EffectParameterSpec> parameters;
};

/// Every effect, in the order of the table above.
const std::vector<EffectSpec>& EffectVocabulary();

/// The effect called `name`, or nullptr.
const EffectSpec* FindEffect(std::string_view name);

/// An effect instance: which effect, its parameter values (in EffectSpec order) and, for sensor
/// effects, the node whose measured series it acts on.
struct Effect {
  std::string name;
  std::vector<double> values;
  std::string node;  ///< sensor effects only
};

/// Where a model's effects attach, resolved from its file (names are the file's node names).
struct EffectTargets {
  std::string frame;               ///< node `frame`, else the first capacitive node with an edge
                                   ///< to a boundary that is not the rotor
  std::string rotor;               ///< node `rotor`, `pm` or `magnet`, else one containing `rotor`
  std::vector<int> frame_edges;    ///< indices of the [[edge]]s between frame and a boundary
  std::vector<int> cooling_edges;  ///< the cooling path: every [[edge]] to ambient or coolant
  std::string cooled;              ///< the nodes on the cooling path, "a, b" (for readings)
  int winding_edge = -1;           ///< [[edge]] joining two temperature nodes of the copper loss
  std::vector<int> copper_losses;  ///< [[loss]]es with temperature nodes and a positive coefficient
  std::vector<int> iron_losses;    ///< [[loss]]es whose name starts with "iron"
};

/// Resolves the targets. Throws ThermalModelError when the text is not TOML.
EffectTargets FindEffectTargets(std::string_view toml_text, const std::string& source);

/// Why `effect` cannot be applied to a model with these targets (empty: it can).
std::string EffectNotApplicable(const EffectSpec& effect, const EffectTargets& targets);

/// Returns the model text with the model effects of `effects` added (sensor effects are recorded
/// as parameters `sensor_lag_s__<node>`, `sensor_offset_K__<node>`). Each effect may appear
/// once (sensor effects once per node). The model's name gains "+effects". Throws
/// ThermalModelError: not TOML, unknown effect, wrong number of values, an effect that does not
/// apply, a parameter name already taken. With `table_directory` set, relative `file` paths of
/// [[table]]s are made absolute from it, so the text loads from any directory.
std::string ApplyModelEffects(std::string_view toml_text, const std::string& source,
                              const std::vector<Effect>& effects,
                              const std::string& table_directory = {});

/// Applies a sensor effect to the series `value` (one measured node) sampled at `time_s`
/// (strictly increasing, same length): sensor_offset adds b; sensor_lag filters with the exact
/// response of tau dy/dt = T - y to T varying linearly over each step, e = exp(-dt/tau):
///     y(k) = T(k) + e (y(k-1) - T(k-1)) - (T(k) - T(k-1)) (tau/dt) (1 - e),   y(0) = T(0).
/// Model effects are ignored. Throws std::invalid_argument for a wrong number of values.
void ApplySensorEffect(const Effect& effect, const std::vector<double>& time_s,
                       std::vector<double>& value);

/// A sentence saying what the fitted values mean physically, e.g. "2.7 kJ/K more heat capacity
/// on the frame, about 5.9 kg of steel".
std::string PhysicalReading(const Effect& effect, const EffectTargets& targets);

}  // namespace pumptherm::estimators
