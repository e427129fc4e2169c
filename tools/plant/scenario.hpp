#pragma once
/// Scenario files of the pump plant simulator (`pumptherm plant`): which pumps, on which CAN
/// interface and node ID, which truth thermal model and motor, which load profile, sensors and
/// faults. Format: TOML, every key documented in docs/plant-simulator.md.
///
/// Parsing is pure: the caller hands in the text; model and motor references stay strings until
/// the plant resolves them (cmd_plant.cpp does the file look-ups).

#include <cstdint>
#include <limits>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "estimators/model_effects.hpp"

namespace pumptherm::plant {

/// A scenario that does not parse or is out of range; the message names the source, the line
/// and the key.
class ScenarioError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

inline constexpr double kNotGiven = std::numeric_limits<double>::quiet_NaN();
inline constexpr double kForever = std::numeric_limits<double>::infinity();

/// One segment of a load profile. Over `duration_s` the speed set point ramps linearly from the
/// previous segment's end value to `speed_rpm` and the ambient to `ambient_degC` (NaN = keep);
/// the current set points hold (`iq_A`, `id_A`), and the drive's current follows them with its
/// current-loop time constant.
struct Segment {
  double duration_s = 0.0;
  double speed_rpm = kNotGiven;  ///< mechanical speed at the segment's end
  double iq_A = 0.0;             ///< q-axis current set point (torque: acceleration, gas load)
  /// q-axis set point at the segment's end (NaN = iq_A all along): the set point ramps linearly
  /// from iq_A to it over the segment, a gas load drifting with the pressure.
  double iq_end_A = kNotGiven;
  double id_A = 0.0;                ///< d-axis current set point
  double ambient_degC = kNotGiven;  ///< ambient at the segment's end
  bool step = false;                ///< jump to speed_rpm / ambient_degC at the start instead
  int line = 0;
};

/// Measurement chain of one temperature sensor (../shared/reference/realistic-signals.md).
struct TemperatureSensorSpec {
  std::string node;             ///< model node measured (frame sensor only)
  double noise_sd_K = 0.05;     ///< white noise per sample
  double accuracy_K = 0.35;     ///< offset drawn once per sensor, uniform in +/- accuracy_K
  double offset_K = kNotGiven;  ///< fixed offset instead of the drawn one
  double resolution_K = 0.1;    ///< quantisation step
  double lag_s = 30.0;          ///< first-order lag time constant
};

/// Imperfections of the drive's electrical telemetry (defaults: realistic-signals.md).
struct DriveSpec {
  double current_response_s = 0.2;  ///< time constant of the current loop
  double current_noise_A = 0.01;    ///< rms noise on id, iq
  double current_range_A = 20.0;    ///< ADC range +/- (12 bits)
  double phase_offset_A = 0.005;    ///< per-phase offset -> dq ripple at electrical frequency
  double voltage_noise_V = 0.01;    ///< rms jitter of the commanded ud, uq
  double dc_link_V = 48.0;          ///< DC-link voltage; voltages 12-bit over +/- this
  double dc_link_noise_V = 0.1;     ///< rms noise of the reported DC-link voltage
  double speed_noise_rpm = 1.0;     ///< rms noise of the speed estimate
  double dead_time_V = 0.0;         ///< inverter dead-time error along the current (0 = off)
  double dead_time_knee_A = 0.5;    ///< current where the dead-time error reaches 76 % (tanh)
  std::string magnet_node;          ///< node whose temperature sets the flux (empty = constant)
  double flux_temperature_coefficient_per_K = -1e-3;  ///< NdFeB, relative to flux at T0
  /// Mechanical speed ripple of the rotor: amplitude (0 = off) and frequency. It is in the true
  /// speed behind the back-EMF, not in the drive's speed estimate.
  double speed_ripple_rpm = 0.0;
  double speed_ripple_hz = 0.37;
};

enum class FaultKind {
  kDroppedFrames,   ///< each frame of this pump lost with `probability`
  kStaleSensor,     ///< no PUMP_STATUS frames (the drive stops sending its status)
  kStuckSensor,     ///< the frame sensor value frozen at its value when the fault starts
  kCoolingFailure,  ///< the resistance of edge `edge` of the truth model times `factor`
  kSensorOffset,    ///< `offset_K` added to the frame sensor's reading (a calibration shift)
};

struct Fault {
  FaultKind kind = FaultKind::kDroppedFrames;
  double start_s = 0.0;
  double end_s = kForever;
  double probability = 1.0;  ///< dropped frames only
  std::string edge;          ///< cooling failure: edge name (`name` key, or "a-b" of `between`)
  double factor = 1.0;       ///< cooling failure: resistance multiplier
  double offset_K = 0.0;     ///< sensor offset: added to the frame sensor's reading
  int line = 0;
};

/// A bus-off burst: no frame from any pump on `interface` (empty = every interface).
struct BusOff {
  std::string interface;
  double start_s = 0.0;
  double end_s = 0.0;
  int line = 0;
};

struct PumpSpec {
  std::string name;  ///< used in output file names
  std::string interface = "can0";
  std::uint32_t node_id = 0;
  std::string model;                  ///< truth thermal model: shipped name or path
  std::string motor = "han2019-tmp";  ///< motor preset name or path
  /// The true motor against `motor`'s nameplate (which the daemon is given): its R0 and its
  /// flux at the magnet's reference temperature are these multiples of the nameplate's. R0 also
  /// scales the truth model's copper losses, so losses and resistance agree.
  double motor_r0_scale = 1.0;
  double motor_flux_scale = 1.0;
  double ambient_degC = 25.0;       ///< ambient at t = 0
  double initial_degC = kNotGiven;  ///< every state at t = 0 (NaN = the ambient)
  double process_noise_K = 0.005;   ///< truth process noise per state, K per sqrt(s)
  std::vector<Segment> segments;
  TemperatureSensorSpec frame_sensor;
  TemperatureSensorSpec ambient_sensor;
  DriveSpec drive;
  std::vector<Fault> faults;
  /// Effects of the discrepancy workflow's vocabulary switched on in the truth model (model
  /// effects only; estimators/model_effects.hpp, docs/discrepancy.md): hidden-effect data.
  std::vector<estimators::Effect> effects;
  /// When the effects begin, s (their tables' `start_s`, one for all of a pump's effects): before
  /// it the truth is the model without them, as a fault that begins then (0: from the start).
  double effects_start_s = 0.0;
  int line = 0;
};

/// The levels' node name for the winding temperature from resistance (the copper-loss-weighted
/// mean of the model's nodes), as the daemon's [alarms.levels] names it.
inline constexpr const char* kWindingResistanceLevel = "winding_resistance";

/// Alarm levels used to summarise the truth (not an alarm logic: the daemon has its own).
struct TruthLevels {
  std::string node = kWindingResistanceLevel;  ///< model node, or the copper-loss mean
  double warning_degC = 100.0;
  double trip_degC = 120.0;
};

struct Scenario {
  std::string name;
  std::string description;
  std::string source;  ///< file name, for messages
  double duration_s = 0.0;
  std::uint64_t seed = 1;
  bool can_log = true;  ///< false: thermal-only (no drive, no log; exact inputs)
  std::int64_t start_epoch_us = 1767225600LL * 1000000;  ///< log time of t = 0 (2026-01-01)
  double fast_period_s = 0.01;     ///< PUMP_FAST_I/U period (DBC GenMsgCycleTime 10 ms)
  double status_period_s = 0.1;    ///< PUMP_STATUS period (100 ms)
  double thermal_period_s = 0.1;   ///< truth integration step
  double truth_period_s = 1.0;     ///< truth CSV row period
  double measured_period_s = 1.0;  ///< measured CSV row period
  double jitter_sd_us = 100.0;     ///< rms timestamp jitter
  double jitter_max_us = 400.0;    ///< jitter bound (truncated)
  TruthLevels levels;
  std::vector<PumpSpec> pumps;
  std::vector<BusOff> bus_offs;
};

/// Parses a scenario. `source` names it in errors. Throws ScenarioError (source:line: key) for a
/// TOML syntax error, an unknown, missing or mistyped key, an out-of-range value, two pumps with
/// the same interface and node ID or the same name, a node ID >= 16, or an unknown profile.
Scenario ParseScenario(std::string_view toml_text, const std::string& source);

}  // namespace pumptherm::plant
