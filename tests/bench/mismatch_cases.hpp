#pragma once
// The fault cases of the mismatch figures (tests/bench/mismatch_matrix.cpp) and of the detector's
// and the disturbance filter's unit tests: tmp-generic as the truth, a turbo pump's load
// (run-up, then gas-load steps every 10 min), the frame RTD with lag, noise, quantisation and a
// calibration offset; from `fault_s` on, the truth is changed by one fault. The daemon's pump
// estimator (estimators/pump_estimator.hpp, its settings for such a pump) runs on the same data,
// once with each observer.
#include <Eigen/Dense>
#include <cmath>
#include <fstream>
#include <limits>
#include <memory>
#include <random>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "estimators/disturbance_sensor.hpp"
#include "estimators/kalman_virtual_sensor.hpp"
#include "estimators/mismatch_detector.hpp"
#include "estimators/model_effects.hpp"
#include "estimators/motor.hpp"
#include "estimators/pump_estimator.hpp"
#include "estimators/thermal_model.hpp"
#include "tools/sim/sensor.hpp"
#include "tools/sim/thermal_plant.hpp"

namespace mismatch_cases {

namespace pe = pumptherm::estimators;

enum class Fault {
  kNone,
  kCoolingLost,
  kRotorLoss,
  kLosses40,
  kAmbientRise,
  kSensorOffset,
  kSensorStuck,
  /// Extra heat on the rotor node of any size at any speed, a step or a ramp (CaseSpec::
  /// rotor_heat_W, rotor_heat_ramp_s), put into the plant directly: a bearing or a rubbing
  /// rotor, heat that the model's losses do not follow.
  kRotorHeat
};

inline const char* FaultName(Fault f) {
  switch (f) {
    case Fault::kNone:
      return "no fault";
    case Fault::kCoolingLost:
      return "cooling lost (frame-ambient R x4)";
    case Fault::kRotorLoss:
      return "extra rotor loss +6 W";
    case Fault::kLosses40:
      return "losses +40 %";
    case Fault::kAmbientRise:
      return "unmeasured ambient +8 K";
    case Fault::kSensorOffset:
      return "frame sensor offset +3 K";
    case Fault::kSensorStuck:
      return "frame sensor stuck";
    case Fault::kRotorHeat:
      return "extra rotor heat (size, shape)";
  }
  return "?";
}

/// The effect a right answer names.
inline pe::MismatchEffect ExpectedEffect(Fault f) {
  switch (f) {
    case Fault::kNone:
      return pe::MismatchEffect::kNone;
    case Fault::kCoolingLost:
      return pe::MismatchEffect::kFrameAmbientResistance;
    case Fault::kRotorLoss:
      return pe::MismatchEffect::kRotorLoss;
    case Fault::kLosses40:
      return pe::MismatchEffect::kLossScale;
    case Fault::kAmbientRise:
      return pe::MismatchEffect::kUnmeasuredAmbient;
    case Fault::kSensorOffset:
      return pe::MismatchEffect::kSensorOffset;
    case Fault::kSensorStuck:
      return pe::MismatchEffect::kSensorStuck;
    case Fault::kRotorHeat:
      return pe::MismatchEffect::kRotorLoss;
  }
  return pe::MismatchEffect::kNone;
}

inline std::string ReadFile(const std::string& path) {
  std::ifstream f(path);
  if (!f) throw std::runtime_error("cannot read " + path);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

inline std::string Replace(std::string text, const std::string& from, const std::string& to) {
  const auto at = text.find(from);
  if (at == std::string::npos) throw std::runtime_error("model text lacks '" + from + "'");
  return text.replace(at, from.size(), to);
}

/// The truth model after the fault (the nominal text for faults outside the network).
inline std::string FaultedModelText(const std::string& nominal, Fault f) {
  switch (f) {
    case Fault::kCoolingLost:
      return Replace(nominal, "resistance_K_per_W = 0.6 ", "resistance_K_per_W = 2.4 ");
    case Fault::kRotorLoss:  // +6 W at rated speed, on the rotor node
      return Replace(nominal, "rotor_eddy_W = 3.0", "rotor_eddy_W = 9.0");
    case Fault::kLosses40: {
      std::string t = Replace(nominal, "r0_ohm = 0.28 ", "r0_ohm = 0.392 ");
      t = Replace(t, "kh_W_s = 0.025", "kh_W_s = 0.035");
      t = Replace(t, "ke_W_s2 = 9.0e-5", "ke_W_s2 = 1.26e-4");
      t = Replace(t, "rotor_eddy_W = 3.0", "rotor_eddy_W = 4.2");
      return Replace(t, "rotor_share = 0.05", "rotor_share = 0.07");
    }
    default:
      return nominal;
  }
}

struct CaseSpec {
  /// The model (truth and filters), a file `<model>.toml` in the model directory. tmp-generic's
  /// faults are edits of its text (the figures of docs/virtual-sensor.md); any other model's are
  /// effects of the discrepancy vocabulary (FaultedModelTextByEffects), its measured node and
  /// rotor are the effects' targets, and "losses +40 %" does not apply (no copper loss scale).
  std::string model = "tmp-generic";
  /// Where relative [[table]] paths of the model resolve from; empty = the model directory.
  std::string tables_dir;
  /// The speed after the run-up (any model; 0 = tmp-generic's 21000 r/min, another model's
  /// [operating_range] speed) and, for any other model, the largest q current (the steps of
  /// LoadCurrent_A scaled to it; 0 = its [operating_range]'s largest iq).
  double speed_rpm = 0.0;
  double iq_max_A = 0.0;
  double rotor_loss_W = 6.0;  ///< the extra rotor loss at that speed (other models)
  /// Fault::kRotorHeat: the extra heat on the rotor, W, and the time it takes to rise linearly
  /// to it from the fault's start (0: a step).
  double rotor_heat_W = 6.0;
  double rotor_heat_ramp_s = 0.0;
  bool inside_heat_bound = true;  ///< PumpEstimatorConfig::inside_heat_bound
  /// A constant gas-load current after the run-up instead of LoadCurrent_A's steps (scaled as
  /// they are), A; 0 = the steps. Without load changes the losses' scale is hardly seen.
  double constant_iq_A = 0.0;
  double sensor_offset_K = 3.0;  ///< the reading's step in the sensor-offset case
  /// A restart at this time (0: none) from the nodes alone: the disturbance-state filter starts
  /// again from its own node estimate and covariance with its disturbances at their priors, as
  /// Pump::Restore does with a state file that lacks them (no time down).
  double restart_s = 0.0;
  /// The restart at restart_s is a new process instead: the disturbance-state filter's whole
  /// saved state restored into a new pump estimator (time down 0), configured with the lag
  /// `restart_configured_lag_s` (negative: as before).
  bool restart_whole = false;
  double restart_configured_lag_s = -1.0;
  bool restart_forgets_lag = false;  ///< the saved state without the lag taken (an older file)
  double ambient_ramp_s = 600.0;     ///< the unmeasured ambient's rise time (0: a step)
  double fit_ambient_ramp_s = 0.0;   ///< the detector's ramp hypothesis (0: the step only)
  Fault fault = Fault::kNone;
  double fault_s = 3600.0;
  double duration_s = 10800.0;
  double dt_s = 1.0;
  std::uint64_t seed = 1;
  double sensor_lag_s = 30.0;
  /// The lag the estimator is configured with (negative: sensor_lag_s, the truth's), and
  /// whether it takes a lag its diagnosis names (PumpEstimatorConfig::adopt_named_sensor_lag).
  double configured_lag_s = -1.0;
  bool adopt_named_sensor_lag = true;
  double truth_process_sd_K = 0.005;  ///< per sqrt(s), as the plant simulator's default
  /// The resistance-based winding temperature for the disturbance filter: the truth's winding
  /// (ThermalModel::WindingWeights) plus white noise of this sd, once per step; 0 = not fused.
  double winding_noise_sd_K = 0.0;
  /// The magnet temperature from the flux for the disturbance filter: the truth's rotor plus
  /// white noise of this sd plus a slow bias (first-order Gauss-Markov, stationary sd
  /// `magnet_bias_sd_K`, correlation `magnet_bias_tau_s`, started from its stationary law) as
  /// the flux gives (nameplate flux, inverter voltage error); 0 = not fused.
  double magnet_noise_sd_K = 0.0;
  double magnet_bias_sd_K = 2.0;
  double magnet_bias_tau_s = 1800.0;
  bool magnet_to_detector = true;  ///< the magnet reading also in the detector's naming fit
  /// The frame sensor's health test for a frozen reading (AlarmConfig::flat_after_s; 0: off, the
  /// frozen reading is fused and left to the mismatch test).
  double flat_after_s = 30.0;
};

struct CaseResult {
  double detect_delay_s = std::numeric_limits<double>::quiet_NaN();  ///< after the fault
  double name_delay_s = std::numeric_limits<double>::quiet_NaN();  ///< first named, after the fault
  pe::MismatchFinding at_naming;
  /// After the fault: from when on the expected effect was named at every step to the end (NaN:
  /// not named right at the end).
  double right_from_s = std::numeric_limits<double>::quiet_NaN();
  pe::MismatchFinding at_end;
  int false_alarms = 0;  ///< transitions into a fault state before the fault began
  double first_false_s = std::numeric_limits<double>::quiet_NaN();
  std::vector<std::string> nodes;
  std::vector<double> max_error_K;       ///< published filter, after the first 300 s
  std::vector<double> coverage;          ///< share of steps with |error| <= 2 sd, after 300 s
  std::vector<double> dist_max_error_K;  ///< the same for the disturbance-state filter
  std::vector<double> dist_coverage;
  std::vector<double> dist_max_sd_K;   ///< its largest reported sd per node, after 300 s
  std::vector<double> dist_mean_sd_K;  ///< its mean reported sd per node, after 300 s
  /// The disturbance filter after the fault's start (and after 300 s): share of steps covered,
  /// largest |error| (NaN without a fault).
  std::vector<double> dist_coverage_after_fault;
  std::vector<double> dist_max_error_after_fault_K;
  /// Its largest upper bound x + 2 sd (the published sd) and the truth's largest value, per
  /// node, after 300 s: what a trip level at x + 2 sd would see on this run.
  std::vector<double> dist_max_upper_degC;
  std::vector<double> truth_max_degC;
  /// The lag the disturbance filter reads the sensor with at the end, s, and whether a restart
  /// restored it (PumpEstimate::frame_sensor_lag_s, frame_sensor_lag_restored).
  double dist_sensor_lag_at_end_s = 0.0;
  bool dist_sensor_lag_restored = false;
  int dist_sensor_steps = 0;          ///< steps of the sensor's offset the disturbance filter found
  double detector_step_max_us = 0.0;  ///< not filled here (timed by the benchmark)
};

/// The gas-load current at time t: run-up at 3 A for 120 s, then steps every 10 minutes.
inline double LoadCurrent_A(double t_s) {
  static const double kSteps[] = {1.5, 2.5, 3.5, 2.0, 4.0, 3.0, 1.8, 3.2};
  if (t_s < 120.0) return 3.0;
  const int k = static_cast<int>((t_s - 120.0) / 600.0) % 8;
  return kSteps[k];
}

inline pe::MismatchDetectorConfig DetectorConfig(double sensor_lag_s) {
  pe::MismatchDetectorConfig c;
  c.sensor_lag_s = sensor_lag_s;
  c.measurement_sd_K = std::sqrt(0.05 * 0.05 + 0.1 * 0.1 / 12.0);  // noise and 0.1 K steps
  return c;
}

/// Whether a fault can be made on a model other than tmp-generic.
inline bool FaultAppliesToAnyModel(Fault f) { return f != Fault::kLosses40; }

/// The extra rotor heat of Fault::kRotorHeat `since_fault_s` after the fault's start, W.
inline double RotorHeat_W(const CaseSpec& spec, double since_fault_s) {
  if (since_fault_s <= 0.0) return 0.0;
  if (!(spec.rotor_heat_ramp_s > 0.0)) return spec.rotor_heat_W;
  return spec.rotor_heat_W * std::min(since_fault_s / spec.rotor_heat_ramp_s, 1.0);
}

/// A fault of the network as effects of the discrepancy vocabulary (docs/discrepancy.md), for
/// any model: cooling lost = every frame-boundary resistance x4, extra rotor loss = `rotor_loss_W`
/// at `speed_rpm` (k (n/1000)^2 on the rotor); the faults outside the network leave the model as
/// it is (relative table paths made absolute from `tables_dir` either way). Throws
/// std::invalid_argument for losses +40 %.
inline std::string FaultedModelTextByEffects(const std::string& nominal, const std::string& source,
                                             Fault f, double rotor_loss_W, double speed_rpm,
                                             const std::string& tables_dir) {
  std::vector<pe::Effect> effects;
  if (f == Fault::kCoolingLost) effects.push_back({"frame_ambient_resistance", {4.0}, {}});
  if (f == Fault::kRotorLoss) {
    const double krpm = speed_rpm / 1000.0;
    effects.push_back({"rotor_loss", {rotor_loss_W / (krpm * krpm)}, {}});
  }
  if (f == Fault::kLosses40)
    throw std::invalid_argument("losses +40 % is made for tmp-generic only");
  return pe::ApplyModelEffects(nominal, source, effects, tables_dir);
}

/// The pump estimator of a case: the daemon's settings for a pump whose frame sensor sits on
/// `frame_node` with the case's lag, the magnet reading fused into `rotor_node` when the case
/// emulates one, the observer forced to `disturbance`.
inline pe::PumpEstimatorConfig EstimatorConfig(const CaseSpec& spec,
                                               const pe::MotorDescription& motor,
                                               const std::string& frame_node,
                                               const std::string& rotor_node, bool disturbance,
                                               const pe::VirtualSensorConfig& vts_config,
                                               const pe::DisturbanceSensorConfig& dc) {
  pe::PumpEstimatorConfig c;
  c.measured_node = frame_node;
  c.frame_sensor_lag_s = spec.configured_lag_s >= 0.0 ? spec.configured_lag_s : spec.sensor_lag_s;
  c.adopt_named_sensor_lag = spec.adopt_named_sensor_lag;
  c.rotor_node = rotor_node;
  c.disturbance_states = disturbance;
  if (spec.magnet_noise_sd_K > 0.0) c.magnet.magnet_node = rotor_node;
  c.winding.fuse = spec.winding_noise_sd_K > 0.0;
  if (spec.winding_noise_sd_K > 0.0) c.winding.model_sd_K = spec.winding_noise_sd_K;
  c.standard = vts_config;
  c.disturbance = dc;
  // The pump sets the magnet reading's bias sd from its least sd (magnet_min_sd_K). The cases'
  // reading is a calibrated line: psi0 known within that bias (not the nameplate's 2 %, which
  // would widen the bias state to psi0's tolerance).
  c.magnet.min_sd_K = dc.magnet_bias_sd_K;
  c.psi0_sd_rel = dc.magnet_bias_sd_K * std::abs(motor.magnet.flux_temperature_coefficient_per_K);
  // Nor does the emulated line carry an inverter voltage error (the line's bias is constant
  // over speed): no state for one.
  c.disturbance.line_voltage_error_sd_V = 0.0;
  // The cases emulate the identifier's outputs, not the drive's voltages: the magnet reading
  // from the back-EMF line is the one to fuse.
  c.voltage.fuse = false;
  c.alarms.flat_after_s = spec.flat_after_s;
  c.mismatch.ambient_ramp_s = spec.fit_ambient_ramp_s;
  if (!spec.magnet_to_detector) c.mismatch_magnet = false;
  c.inside_heat_bound = spec.inside_heat_bound;
  return c;
}

/// The identifier's outputs that give the case's emulated readings: the winding from
/// resistance (tracking, the truth's winding plus white noise of `winding_sd_K`; NaN: none) and
/// the back-EMF line whose magnet reading (estimators/readings/magnet_flux_reading.hpp) is
/// `magnet_degC` with white sd `magnet_sd_K` (NaN: none), at mean q current `iq_A` and
/// electrical speed `w_rad_per_s`.
inline pe::IdentifierOutput EmulatedIdentifier(const pe::MotorDescription& motor,
                                               double winding_degC, double winding_sd_K,
                                               double magnet_degC, double magnet_sd_K,
                                               double winding_true_degC) {
  pe::IdentifierOutput id;
  id.sample_age_s = id.block_age_s = 0.0;
  id.estimate.status =
      std::isfinite(winding_degC) ? pe::ResistanceStatus::kTracking : pe::ResistanceStatus::kHeld;
  id.estimate.winding_degC = winding_degC;
  id.estimate.winding_sd_K = std::isfinite(winding_degC) ? winding_sd_K : 0.0;
  // E = psi_f + Rs iq/w with psi_f at the magnet reading and Rs at the true winding: the
  // reading z = Tm + g Tw of the back-EMF row then is the magnet reading plus g times the
  // winding, as a real identifier's line would give it.
  const auto& cu = motor.copper;
  const double psi0_beta = motor.flux_Wb * motor.magnet.flux_temperature_coefficient_per_K;
  id.estimate.resistance_ohm =
      cu.r0_ohm * (1.0 + cu.alpha_per_K * (winding_true_degC - cu.t0_degC));
  id.estimate.flux_Wb = std::isfinite(magnet_degC)
                            ? motor.flux_Wb + psi0_beta * (magnet_degC - motor.magnet.t0_degC)
                            : std::nan("");
  const double sd_Wb = magnet_sd_K * std::abs(psi0_beta);
  id.p(pe::kStateFlux, pe::kStateFlux) = sd_Wb * sd_Wb;
  if (!std::isfinite(magnet_degC)) id.block_age_s = std::nan("");  // no line: no reading
  return id;
}

/// Runs one case. `model_dir` holds `<spec.model>.toml`. Two pump estimators run on the same
/// data: the standard filter's (CaseResult::max_error_K, coverage) and the disturbance-state
/// filter's (dist_*, and the mismatch test's verdicts).
inline CaseResult RunCase(const CaseSpec& spec, const std::string& model_dir,
                          pe::VirtualSensorConfig vts_config = {},
                          pe::DisturbanceSensorConfig dc = {}) {
  const bool tmp = spec.model == "tmp-generic";
  const std::string source = model_dir + "/" + spec.model + ".toml";
  const std::string tables_dir = spec.tables_dir.empty() ? model_dir : spec.tables_dir;
  const std::string raw_text = ReadFile(source);
  // Relative table paths made absolute, so that the nominal and the faulted text load alike.
  const std::string nominal_text =
      tmp ? raw_text : pe::ApplyModelEffects(raw_text, source, {}, tables_dir);
  const pe::ThermalModelFiles files{tables_dir, ReadFile};
  const auto nominal = pe::ThermalModel::Parse(nominal_text, spec.model, files);
  // tmp-generic: the load of the published figures (21000 r/min unless the case says).
  double speed_rpm = spec.speed_rpm > 0.0 ? spec.speed_rpm : 21000.0, iq_scale = 1.0;
  std::string frame_node = "frame", rotor_node = "rotor";
  if (!tmp) {
    const pe::ThermalOperatingRange* range = nominal.OperatingRange();
    speed_rpm = spec.speed_rpm > 0.0 ? spec.speed_rpm : range ? range->speed_rpm : 0.0;
    const double iq_max_A = spec.iq_max_A > 0.0             ? spec.iq_max_A
                            : range && !range->iq_A.empty() ? range->iq_A.back()
                                                            : 0.0;
    if (!(speed_rpm > 0.0) || !(iq_max_A > 0.0)) {
      throw std::invalid_argument(spec.model +
                                  " has no [operating_range]: give its speed and largest iq");
    }
    iq_scale = iq_max_A / 4.0;
    const pe::EffectTargets targets = pe::FindEffectTargets(nominal_text, source);
    frame_node = targets.frame;
    rotor_node = targets.rotor;
  }
  const auto faulted = pe::ThermalModel::Parse(
      tmp ? FaultedModelText(nominal_text, spec.fault)
          : FaultedModelTextByEffects(nominal_text, source, spec.fault, spec.rotor_loss_W,
                                      speed_rpm, tables_dir),
      spec.model + "+fault", files);
  const int n = nominal.StateCount();
  const double ambient = 22.0;
  pumptherm::sim::ThermalPlantConfig pc;
  pc.process_sd_K = spec.truth_process_sd_K;
  auto plant = std::make_unique<pumptherm::sim::ThermalPlant>(
      nominal, Eigen::VectorXd::Constant(n, ambient), pc, spec.seed);
  std::mt19937_64 rng(spec.seed * 7919 + 1);
  pumptherm::sim::SensorConfig sc;
  sc.noise_sd = 0.05;
  sc.lsb = 0.1;
  sc.lag_tau_s = spec.sensor_lag_s;
  sc.offset = std::uniform_real_distribution<double>(-0.35, 0.35)(rng);
  pumptherm::sim::Sensor sensor(sc, spec.seed * 31 + 5);
  std::normal_distribution<double> normal(0.0, 1.0);

  const pe::MotorDescription motor = pe::MotorPreset("han2019-tmp");
  pe::PumpEstimator standard(
      EstimatorConfig(spec, motor, frame_node, rotor_node, false, vts_config, dc), motor, nominal);
  auto dist = std::make_unique<pe::PumpEstimator>(
      EstimatorConfig(spec, motor, frame_node, rotor_node, true, vts_config, dc), motor, nominal);
  const int rotor = nominal.StateIndex(rotor_node);
  const int frame = nominal.StateIndex(frame_node);
  std::mt19937_64 magnet_rng(spec.seed * 104729 +
                             3);  // its own: the other cases' draws stay as they were
  std::normal_distribution<double> magnet_normal(0.0, 1.0);
  double magnet_bias_K = spec.magnet_bias_sd_K * magnet_normal(magnet_rng);
  CaseResult r;
  r.nodes = nominal.StateNames();
  r.max_error_K.assign(static_cast<std::size_t>(n), 0.0);
  r.coverage.assign(static_cast<std::size_t>(n), 0.0);
  r.dist_max_error_K.assign(static_cast<std::size_t>(n), 0.0);
  r.dist_coverage.assign(static_cast<std::size_t>(n), 0.0);
  r.dist_max_sd_K.assign(static_cast<std::size_t>(n), 0.0);
  r.dist_mean_sd_K.assign(static_cast<std::size_t>(n), 0.0);
  r.dist_max_error_after_fault_K.assign(static_cast<std::size_t>(n), 0.0);
  r.dist_coverage_after_fault.assign(static_cast<std::size_t>(n), 0.0);
  r.dist_max_upper_degC.assign(static_cast<std::size_t>(n),
                               -std::numeric_limits<double>::infinity());
  r.truth_max_degC.assign(static_cast<std::size_t>(n), -std::numeric_limits<double>::infinity());
  std::vector<long> dist_covered(static_cast<std::size_t>(n), 0);
  std::vector<long> covered(static_cast<std::size_t>(n), 0);
  std::vector<long> covered_after(static_cast<std::size_t>(n), 0);
  long counted = 0, counted_after = 0;
  Eigen::VectorXd extra_heat_W = Eigen::VectorXd::Zero(n);
  bool faulted_now = false;
  double stuck_value = std::numeric_limits<double>::quiet_NaN();
  bool was_fault_state = false;
  for (double t = spec.dt_s; t <= spec.duration_s + 1e-9; t += spec.dt_s) {
    if (!faulted_now && t > spec.fault_s) {
      faulted_now = true;
      plant = std::make_unique<pumptherm::sim::ThermalPlant>(faulted, plant->State_degC(), pc,
                                                             spec.seed + 99);
    }
    pe::ThermalInputs in;
    in.speed_rpm = std::min(t / 120.0, 1.0) * speed_rpm;
    in.iq_A =
        iq_scale * (spec.constant_iq_A > 0.0 && t >= 120.0 ? spec.constant_iq_A : LoadCurrent_A(t));
    in.ambient_degC = in.coolant_degC = ambient;
    pe::ThermalInputs truth_in = in;
    if (faulted_now && spec.fault == Fault::kAmbientRise) {
      const double ramp = spec.ambient_ramp_s > 0.0  // 8 K over 10 minutes by default
                              ? std::min((t - spec.fault_s) / spec.ambient_ramp_s, 1.0)
                              : 1.0;
      truth_in.ambient_degC = truth_in.coolant_degC = ambient + 8.0 * ramp;
    }
    if (faulted_now && spec.fault == Fault::kRotorHeat && rotor >= 0) {
      // Held over the step at its value in the middle of it.
      extra_heat_W(rotor) = RotorHeat_W(spec, t - 0.5 * spec.dt_s - spec.fault_s);
      plant->SetExtraHeat_W(extra_heat_W);
    }
    const Eigen::VectorXd& x = plant->Step(truth_in, spec.dt_s);
    double y = sensor.Measure(x(frame), spec.dt_s);
    if (faulted_now && spec.fault == Fault::kSensorOffset) y += spec.sensor_offset_K;
    if (faulted_now && spec.fault == Fault::kSensorStuck) {
      if (std::isnan(stuck_value)) stuck_value = y;
      y = stuck_value;
    }
    const double winding_true = nominal.WindingWeights().dot(x);
    const double winding = spec.winding_noise_sd_K > 0.0
                               ? winding_true + spec.winding_noise_sd_K * normal(rng)
                               : std::numeric_limits<double>::quiet_NaN();
    double magnet = std::numeric_limits<double>::quiet_NaN();
    if (spec.magnet_noise_sd_K > 0.0) {
      const double a = std::exp(-spec.dt_s / spec.magnet_bias_tau_s);
      magnet_bias_K = a * magnet_bias_K +
                      spec.magnet_bias_sd_K * std::sqrt(1.0 - a * a) * magnet_normal(magnet_rng);
      magnet = x(rotor) + magnet_bias_K + spec.magnet_noise_sd_K * magnet_normal(magnet_rng);
    }
    pe::PumpPeriod p;
    p.end_us = static_cast<std::int64_t>(std::llround(t * 1e6));
    p.dt_s = spec.dt_s;
    p.inputs = in;
    p.fresh_inputs = true;
    p.mean_iq_A = in.iq_A;
    p.ambient_degC = ambient;
    p.fast_age_s = 0.0;
    p.identifier = EmulatedIdentifier(motor, winding, spec.winding_noise_sd_K, magnet,
                                      spec.magnet_noise_sd_K, winding_true);
    const bool restart =
        spec.restart_s > 0.0 && t >= spec.restart_s && t < spec.restart_s + spec.dt_s;
    if (restart && spec.restart_whole) {
      pe::PumpEstimatorState saved = dist->Save();
      if (spec.restart_forgets_lag) {
        saved.taken_sensor_lag_s = saved.taken_over_configured_lag_s =
            std::numeric_limits<double>::quiet_NaN();
      }
      CaseSpec again = spec;
      if (spec.restart_configured_lag_s >= 0.0)
        again.configured_lag_s = spec.restart_configured_lag_s;
      dist = std::make_unique<pe::PumpEstimator>(
          EstimatorConfig(again, motor, frame_node, rotor_node, true, vts_config, dc), motor,
          nominal);
      if (!dist->Restore(saved, saved.time_us))
        throw std::runtime_error("the saved state was not restored");
    } else if (restart) {
      // A restart from the nodes alone (a state file without the filter's whole state).
      for (pe::PumpEstimator* e : {&standard, dist.get()}) {
        pe::PumpEstimatorState saved = e->Save();
        saved.observer_x.resize(0);
        saved.observer_s.resize(0, 0);
        saved.sensor_offset_K = std::numeric_limits<double>::quiet_NaN();
        e->Restore(saved, saved.time_us);
      }
    }
    for (pe::PumpEstimator* e : {&standard, dist.get()}) {
      e->OnFrameReading(p.end_us, y);
      e->Step(p);
    }
    const pe::MismatchFinding& f = dist->estimate().mismatch;
    const bool named = f.state == pe::MismatchState::kPlantChange ||
                       f.state == pe::MismatchState::kSensorFaultSuspected;
    const bool fault_state = named || f.state == pe::MismatchState::kUnexplained;
    if (named && std::isnan(r.name_delay_s) && t > spec.fault_s) {
      r.name_delay_s = t - spec.fault_s;
      r.at_naming = f;
    }
    if (t > spec.fault_s) {
      const bool right = named && f.effect == ExpectedEffect(spec.fault);
      if (!right) {
        r.right_from_s = std::numeric_limits<double>::quiet_NaN();
      } else if (std::isnan(r.right_from_s)) {
        r.right_from_s = t - spec.fault_s;
      }
    }
    if (fault_state && !was_fault_state) {
      if (t <= spec.fault_s || spec.fault == Fault::kNone) {
        ++r.false_alarms;
        if (std::isnan(r.first_false_s)) r.first_false_s = t;
      } else if (std::isnan(r.detect_delay_s)) {
        r.detect_delay_s = t - spec.fault_s;
      }
    }
    was_fault_state = fault_state;
    if (t > 300.0) {
      ++counted;
      const bool after = t > spec.fault_s;
      counted_after += after ? 1 : 0;
      for (int i = 0; i < n; ++i) {
        const auto k = static_cast<std::size_t>(i);
        const auto& se = standard.estimate();
        const double err = se.node_degC[k] - x(i);
        auto& m = r.max_error_K[k];
        m = std::max(m, std::abs(err));
        if (std::abs(err) <= 2.0 * se.node_sd_K[k]) ++covered[k];
        const auto& de = dist->estimate();
        const double derr = de.node_degC[k] - x(i);
        auto& dm = r.dist_max_error_K[k];
        dm = std::max(dm, std::abs(derr));
        if (std::abs(derr) <= 2.0 * de.node_sd_K[k]) ++dist_covered[k];
        auto& ms = r.dist_max_sd_K[k];
        ms = std::max(ms, de.node_sd_K[k]);
        r.dist_mean_sd_K[k] += de.node_sd_K[k];
        r.dist_max_upper_degC[k] =
            std::max(r.dist_max_upper_degC[k], de.node_degC[k] + 2.0 * de.node_sd_K[k]);
        r.truth_max_degC[k] = std::max(r.truth_max_degC[k], x(i));
        if (after) {
          auto& da = r.dist_max_error_after_fault_K[k];
          da = std::max(da, std::abs(derr));
          if (std::abs(derr) <= 2.0 * de.node_sd_K[k]) ++covered_after[k];
        }
      }
    }
  }
  for (int i = 0; i < n; ++i) {
    const auto k = static_cast<std::size_t>(i);
    r.coverage[k] = counted > 0 ? static_cast<double>(covered[k]) / counted : 0.0;
    r.dist_coverage[k] = counted > 0 ? static_cast<double>(dist_covered[k]) / counted : 0.0;
    r.dist_mean_sd_K[k] = counted > 0 ? r.dist_mean_sd_K[k] / counted : 0.0;
    if (counted_after > 0) {
      r.dist_coverage_after_fault[k] = static_cast<double>(covered_after[k]) / counted_after;
    } else {
      r.dist_coverage_after_fault[k] = r.dist_max_error_after_fault_K[k] =
          std::numeric_limits<double>::quiet_NaN();
    }
  }
  r.at_end = dist->estimate().mismatch;
  r.dist_sensor_lag_at_end_s = dist->estimate().frame_sensor_lag_s;
  r.dist_sensor_lag_restored = dist->estimate().frame_sensor_lag_restored;
  r.dist_sensor_steps = static_cast<int>(dist->estimate().sensor_steps);
  return r;
}

}  // namespace mismatch_cases
