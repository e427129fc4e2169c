#pragma once
/// Motor description: the electrical parameters the resistance identifier needs.
///
/// The file format is TOML (docs/resistance-identification.md, "Motor description file"):
///
///     name = "han2019-tmp"
///     pole_pairs = 1
///     rated_speed_rpm = 21000.0
///     flux_Wb = 0.0182              # permanent-magnet flux linkage psi_f at t0_degC
///     inductance_H = 0.24e-3        # Ls (d and q axis, surface PM)
///     [resistance]
///     r0_ohm = 0.28                 # phase resistance at t0_degC (Han 2019 eq. 2)
///     t0_degC = 27.2
///     alpha_per_K = 4.1e-3
///     plausible_min_degC = -20.0    # band outside which an identified Rs is "implausible"
///     plausible_max_degC = 180.0
///     [drive]                       # optional: how the drive reports its signals
///     max_current_A = 15.0          # the drive's current limit, |i_dq| (optional)
///     uq_resolution_V = 0.0234375   # step of the reported uq (codes at multiples of it)
///     voltage_error_V = 0.15        # inverter dead-time voltage error (optional)
///     voltage_error_knee_A = 0.5    # its tanh knee (optional; 0 = sign(i))
///     [magnet]                      # optional: how the flux falls with magnet temperature
///     t0_degC = 27.2                # temperature at which flux_Wb holds
///     flux_temperature_coefficient_per_K = -1.0e-3  # reversible coefficient of the remanence
///
/// Every key is required except `name`, the two plausibility keys and the [drive] and
/// [magnet] tables (both keys of [magnet] are required when it is given);
/// unknown keys are errors (a misspelt key must not silently fall back to a default).

#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "estimators/copper.hpp"

namespace pumptherm::estimators {

/// A motor description that does not parse or is out of range. The message names the source,
/// the line (when known) and the key.
class MotorDescriptionError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// How the magnet flux linkage depends on the magnet temperature (estimators/magnet.hpp):
/// psi_f(T) = flux_Wb (1 + flux_temperature_coefficient_per_K (T - t0_degC)).
struct MagnetLaw {
  double t0_degC = 0.0;                             ///< where the motor's flux_Wb holds
  double flux_temperature_coefficient_per_K = 0.0;  ///< < 0; 0 = no law given
  bool Given() const noexcept { return flux_temperature_coefficient_per_K != 0.0; }
};

/// Electrical description of a surface permanent-magnet synchronous motor.
struct MotorDescription {
  std::string name;                   ///< free text, e.g. "han2019-tmp"
  int pole_pairs = 1;                 ///< electrical speed = pole_pairs * mechanical speed
  double rated_speed_rpm = 0.0;       ///< mechanical, r/min
  double flux_Wb = 0.0;               ///< PM flux linkage psi_f (amplitude-invariant dq)
  double inductance_H = 0.0;          ///< Ls, equal on d and q axes
  CopperLaw copper;                   ///< R0, T0, alpha of Han 2019 eq. 2
  double plausible_min_degC = -20.0;  ///< lower end of the plausible winding temperature
  double plausible_max_degC = 180.0;  ///< upper end of the plausible winding temperature
  /// Step of the reported q-axis voltage, V: the drive's command or ADC resolution (codes at
  /// integer multiples of it). The identifier removes the quantisation bias of its block means
  /// with it (estimators/quantisation.hpp). 0 = not known: no correction.
  double uq_resolution_V = 0.0;
  /// The magnet's temperature law; not Given() when the file has no [magnet] table (then no
  /// magnet temperature is derived from the flux).
  MagnetLaw magnet;
  /// Inverter voltage error (dead time, switch drops) along the current vector, V: the drive
  /// applies u - u_err tanh(|i| / knee) i / |i| when asked for u. The identifier adds it back
  /// to the reported uq before identification. 0 = not known: nothing compensated.
  double voltage_error_V = 0.0;
  /// Current magnitude at which that error reaches 76 % (tanh), A; 0 = the plain sign(i) term.
  double voltage_error_knee_A = 0.0;
  /// The largest current the drive lets the motor draw: the magnitude of the dq current vector,
  /// sqrt(id^2 + iq^2) (amplitude-invariant: the phase currents' peak), A. While a pump's
  /// telemetry is silent the alarms assume it may draw this (docs/daemon.md, "The pipeline, per
  /// pump"). 0 = not known: a silence is judged only once its frames return.
  double max_current_A = 0.0;
};

/// The q-axis share of the inverter voltage error at currents (id, iq), V:
/// voltage_error_V tanh(|i| / knee) iq / |i| (iq / |i| alone for knee 0); 0 at zero current.
double VoltageErrorQ_V(const MotorDescription& motor, double id_A, double iq_A) noexcept;

/// Parses a motor description from TOML `text`; `source` names it in errors (a path or
/// "preset han2019-tmp"). Throws MotorDescriptionError naming source, line and key for a
/// syntax error, a missing, unknown or mistyped key, or a value out of range
/// (pole_pairs < 1, non-positive speed, flux, inductance, r0 or alpha, empty band, a
/// uq_resolution_V outside (0, 10] V, a voltage_error_V outside [0, 5] V, a knee outside
/// [0, 100] A or without voltage_error_V, a max_current_A outside (0, 10000] A, a magnet
/// coefficient outside [-5e-3, -1e-5] per K).
MotorDescription ParseMotorDescription(std::string_view text, std::string_view source);

/// The TOML text of a built-in preset, or an empty view when `name` is not a preset.
std::string_view MotorPresetText(std::string_view name) noexcept;

/// Names of the built-in presets ("han2019-tmp": Han, Xiong, Mao 2019, Table 1).
std::vector<std::string> MotorPresetNames();

/// The parsed built-in preset `name`; throws MotorDescriptionError for an unknown name.
MotorDescription MotorPreset(std::string_view name);

/// Electrical angular speed w_r in rad/s from a mechanical speed in r/min.
double ElectricalSpeed_rad_per_s(const MotorDescription& motor, double speed_rpm) noexcept;
/// The inverse: mechanical speed, r/min, of an electrical angular speed `w_rad_per_s`.
double MechanicalSpeed_rpm(const MotorDescription& motor, double w_rad_per_s) noexcept;

/// Resistance band [R(plausible_min_degC), R(plausible_max_degC)] (Han 2019 eq. 2), ohm.
double PlausibleMinResistance_ohm(const MotorDescription& motor) noexcept;
double PlausibleMaxResistance_ohm(const MotorDescription& motor) noexcept;

}  // namespace pumptherm::estimators
