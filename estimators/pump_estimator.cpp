#include "estimators/pump_estimator.hpp"

#include <fmt/format.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <complex>
#include <stdexcept>

#include "estimators/magnet.hpp"

namespace pumptherm::estimators {
namespace {

/// Per state, its excess over the ambient per kelvin of the measured node's along the model's
/// slowest decay at rest (speed and currents 0): the shape a pump's temperatures take as it
/// cools after a stop, once the faster modes have died out. Empty where the model gives none (no
/// measured node, a slowest mode that is no real decay, or one the measured node has no part in).
Eigen::VectorXd RestDecayShape(const ThermalModel& model, int measured) {
  const int n = model.StateCount();
  if (measured < 0 || measured >= n) return {};
  ThermalLinearModel lin;
  const ThermalInputs rest;
  try {
    model.Linearise(rest, Eigen::VectorXd::Constant(n, rest.ambient_degC), lin);
  } catch (const std::exception&) {
    return {};
  }
  if (!lin.a_per_s.allFinite()) return {};
  const Eigen::EigenSolver<Eigen::MatrixXd> eig(lin.a_per_s);
  if (eig.info() != Eigen::Success) return {};
  Eigen::Index slowest = 0;
  eig.eigenvalues().real().maxCoeff(&slowest);
  const std::complex<double> rate = eig.eigenvalues()(slowest);
  if (!(rate.real() < 0.0) || std::abs(rate.imag()) > 1e-9 * std::abs(rate.real())) return {};
  const Eigen::VectorXd v = eig.eigenvectors().col(slowest).real();
  if (!(std::abs(v(measured)) > 1e-6 * v.cwiseAbs().maxCoeff())) return {};
  const Eigen::VectorXd shape = v / v(measured);
  return shape.allFinite() ? shape : Eigen::VectorXd{};
}

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();
/// Largest settling sd of a converged observer (ThermalObserver::SettlingSd_K).
constexpr double kConvergedSd_K = 5.0;

/// The node where heat inside the rotor appears: as configured, else the magnet's node (the
/// magnet sits on the rotor), else the estimators' default ("rotor", absent: no rotor heat).
std::string RotorNode(const PumpEstimatorConfig& c) {
  if (!c.rotor_node.empty()) return c.rotor_node;
  if (!c.magnet.magnet_node.empty()) return c.magnet.magnet_node;
  return DisturbanceSensorConfig{}.rotor_node;
}

/// The magnet node where the model has it (else none: the reading is published, not fused).
std::string MagnetNodeIn(const PumpEstimatorConfig& c, const ThermalModel& model) {
  return model.StateIndex(c.magnet.magnet_node) >= 0 ? c.magnet.magnet_node : std::string();
}

/// The node whose temperature the flux follows: the magnet's, else the rotor's; empty when the
/// model has neither.
std::string VoltageMagnetNode(const PumpEstimatorConfig& c, const ThermalModel& model) {
  const std::string magnet = MagnetNodeIn(c, model);
  if (!magnet.empty()) return magnet;
  const std::string rotor = RotorNode(c);
  return model.StateIndex(rotor) >= 0 ? rotor : std::string();
}

/// The identifier's identification as published: its status, no values. A held Rs is the
/// winding's resistance at the hold, and the winding warms on; a converging or held line's flux
/// carries the inverter's offset, which its sd does not count; and while it tracks, its Rs can
/// still lie outside its +-2 sd most of the time (a warming magnet, the inverter's error) and its
/// flux always: they are a diagnostic (the CSV's identifier columns), not the identification.
PublishedIdentification IdentifiedBy(const ResistanceEstimate& r) {
  PublishedIdentification id;
  id.status = r.status;
  // While Rs cannot be told apart from psi_f, Rs is held and the flux is still tracked.
  id.flux_status =
      r.status == ResistanceStatus::kNotIdentifiable ? ResistanceStatus::kTracking : r.status;
  return id;
}

/// sqrt(a^2 var_x + b^2 var_y + 2 a b cov_xy), the first-order sd of a product's value.
double ProductSd(double a, double var_x, double b, double var_y, double cov_xy) {
  return std::sqrt(std::max(a * a * var_x + b * b * var_y + 2.0 * a * b * cov_xy, 0.0));
}

/// Whether the disturbance-state filter takes the drive's voltage: asked for, a motor with R0
/// and psi0, a magnet node.
bool TakesVoltage(const PumpEstimatorConfig& c, const MotorDescription& motor,
                  const ThermalModel& model) {
  return c.voltage.fuse && motor.copper.r0_ohm > 0.0 && motor.flux_Wb > 0.0 &&
         !VoltageMagnetNode(c, model).empty();
}

/// Without the voltage rows nothing learns psi0, and the back-EMF line takes the nameplate's: its
/// bias is then psi0's tolerance through the magnet law (20 K for 2 % at -0.1 %/K), a constant
/// the run-up of a cold start teaches the filter (every node known). The bias state's stationary
/// sd becomes that tolerance, with a correlation time that keeps the short-term drift of the
/// line's anchor (min_sd_K over magnet_bias_tau_s): same variance growth per second.
void LineBiasCoversPsi0(const PumpEstimatorConfig& c, const MotorDescription& motor,
                        DisturbanceSensorConfig& d) {
  const double law_per_K = std::abs(motor.magnet.flux_temperature_coefficient_per_K);
  if (!(law_per_K > 0.0) || !(d.magnet_bias_sd_K > 0.0)) return;
  const double tolerance_K = c.psi0_sd_rel / law_per_K;
  if (!(tolerance_K > d.magnet_bias_sd_K)) return;
  const double widening = tolerance_K / d.magnet_bias_sd_K;
  d.magnet_bias_tau_s *= widening * widening;
  d.magnet_bias_sd_K = tolerance_K;
}

std::unique_ptr<ThermalObserver> MakeObserver(const PumpEstimatorConfig& c,
                                              const MotorDescription& motor,
                                              const ThermalModel& model, bool disturbance) {
  if (disturbance) {
    DisturbanceSensorConfig d = c.disturbance;
    d.measured_node = c.measured_node;
    d.sensor_lag_s = c.frame_sensor_lag_s;
    d.rotor_node = RotorNode(c);
    // Not turning: below a hundredth of rated speed, where a drive's speed estimate at rest reads.
    d.rotor_heat_min_speed_rpm = 0.01 * std::max(motor.rated_speed_rpm, 0.0);
    d.winding_measurement_sd_K = c.winding.model_sd_K;
    // The identified winding is not fused here: its errors while tracking (7-9 K on the demo)
    // are beyond a bias state (docs/virtual-sensor.md). The magnet reading's error is mostly a
    // slow bias (nameplate flux, inverter voltage error): the least sd of the published magnet
    // becomes the stationary sd of a bias state.
    d.winding_reading = false;
    d.magnet_node = MagnetNodeIn(c, model);
    d.magnet_bias_sd_K = c.magnet.min_sd_K;
    d.voltage_reading = TakesVoltage(c, motor, model);
    if (!d.voltage_reading) LineBiasCoversPsi0(c, motor, d);
    if (d.voltage_reading) {
      d.voltage_law = VoltageLawOf(motor);
      d.voltage_magnet_node = VoltageMagnetNode(c, model);
      d.r0_sd_rel = c.r0_sd_rel;
      d.psi0_sd_rel = c.psi0_sd_rel;
    }
    return std::make_unique<DisturbanceThermalSensor>(model, d);
  }
  VirtualSensorConfig v = c.standard;
  v.measured_nodes = {c.measured_node};
  v.winding_measurement_sd_K = c.winding.model_sd_K;
  v.winding_reading = c.winding.fuse;
  v.magnet_node = MagnetNodeIn(c, model);
  v.magnet_min_sd_K = c.magnet.min_sd_K;
  return std::make_unique<VirtualThermalSensor>(model, v);
}

MismatchDetectorConfig MismatchConfig(const PumpEstimatorConfig& c, const ThermalModel& model) {
  MismatchDetectorConfig m = c.mismatch;
  m.measured_node = c.measured_node;
  m.sensor_lag_s = c.frame_sensor_lag_s;
  m.rotor_node = RotorNode(c);
  // The magnet from the flux helps name an effect (heat inside the rotor or not).
  m.magnet_node = c.mismatch_magnet ? MagnetNodeIn(c, model) : std::string();
  return m;
}

MagnetFluxReadingConfig MagnetConfig(const PumpEstimatorConfig& c) {
  MagnetFluxReadingConfig m = c.magnet;
  m.stale_after_s = c.alarms.stale_after_s;
  m.period_s = c.period_s;
  return m;
}

WindingResistanceReadingConfig WindingConfig(const PumpEstimatorConfig& c) {
  WindingResistanceReadingConfig w = c.winding;
  w.stale_after_s = c.alarms.stale_after_s;
  return w;
}

bool ResolveDisturbance(const PumpEstimatorConfig& c, const ThermalModel& model) {
  // By default only where its frame-path heat can stand for every change on the cooling path
  // (docs/virtual-sensor.md, "Disturbance states", per model).
  if (c.disturbance_states) return *c.disturbance_states;
  return BoundaryOnlyThrough(model, c.measured_node);
}

/// The nodes of the inside-heat bound: for the disturbance-state filter only (the frame-path heat
/// it finds is what may lie inside), the measured node and the rotor's.
InsideHeatNodes InsideNodes(const PumpEstimatorConfig& c, const ThermalModel& model,
                            bool disturbance) {
  InsideHeatNodes nodes;
  if (!disturbance || !c.inside_heat_bound) return nodes;
  nodes.measured = model.StateIndex(c.measured_node);
  nodes.rotor = model.StateIndex(RotorNode(c));
  nodes.history_s = c.mismatch.fit_window_s;
  return nodes;
}

/// What a finding says about heat inside: a plant change named as rotor heat is inside; one
/// named on the frame path (cooling, ambient) is not. Every loss scaled is left to the filter's
/// loss-scale state (it covers +40 % losses), and lost cooling is named `loss_scale` first in most
/// runs: taken as inside, the bound put the cooling's frame-path heat on the rotor until the right
/// name came (docs/virtual-sensor.md, "Heat inside, from the frame alone").
InsideHeatVerdict InsideVerdictOf(const MismatchFinding& f) {
  if (f.state != MismatchState::kPlantChange) return InsideHeatVerdict::kUnchanged;
  switch (f.effect) {
    case MismatchEffect::kRotorLoss:
      return InsideHeatVerdict::kInside;
    case MismatchEffect::kFrameAmbientResistance:
    case MismatchEffect::kUnmeasuredAmbient:
      return InsideHeatVerdict::kFramePath;
    default:
      return InsideHeatVerdict::kUnchanged;
  }
}

/// Whether a finding changed enough to be announced: its state or effect (refits that only move
/// the size or the fitted start are published, not announced).
bool NewVerdict(const MismatchFinding& a, const MismatchFinding& b) {
  return a.state != b.state || a.effect != b.effect;
}

}  // namespace

bool InEstimateRange(const Eigen::Ref<const Eigen::VectorXd>& x_degC) {
  return x_degC.size() == 0 ||
         (x_degC.maxCoeff() <= kMaxEstimate_degC && x_degC.minCoeff() >= kMinEstimate_degC);
}

std::string UnknownLevelNode(const ThermalModel& model, const std::string& node) {
  if (node == kSensorLevelsNode || node == kWindingResistanceNode || model.StateIndex(node) >= 0)
    return {};
  std::string list;
  for (const auto& n : model.StateNames()) list += (list.empty() ? "" : ", ") + n;
  return fmt::format(
      "node '{}', which model '{}' does not have as a node with heat capacity (it has: {}; "
      "also '{}' and '{}')",
      node, model.Name(), list, kSensorLevelsNode, kWindingResistanceNode);
}

PumpEstimator::PumpEstimator(const PumpEstimatorConfig& config, const MotorDescription& motor,
                             const ThermalModel& model)
    : config_(config),
      motor_(motor),
      model_(model),
      disturbance_states_(ResolveDisturbance(config, model)),
      observer_(MakeObserver(config, motor, model, disturbance_states_)),
      frame_(config.alarms),
      magnet_(motor, model, MagnetConfig(config)),
      winding_(WindingConfig(config)),
      voltage_(motor, config.voltage),
      mismatch_(model, MismatchConfig(config, model)),
      alarms_(MakeAlarms()),
      values_(model, config.alarms, observer_->ModelsSensorLag() ? 0.0 : config.frame_sensor_lag_s,
              config.period_s, SilenceWorstLoad{motor.max_current_A, motor.rated_speed_rpm},
              InsideNodes(config, model, disturbance_states_)),
      forecast_(model.StateCount()) {
  estimate_.frame_sensor_lag_s = config_.frame_sensor_lag_s;
  if (!(config_.period_s > 0.0)) throw std::invalid_argument("thermal period must be positive");
  if (!config_.rotor_node.empty() && model_.StateIndex(config_.rotor_node) < 0) {
    throw std::invalid_argument(
        fmt::format("rotor_node '{}' is not a node with heat capacity of model '{}'",
                    config_.rotor_node, model_.Name()));
  }
  measured_state_ = model_.StateIndex(config_.measured_node);
  rest_decay_shape_ = RestDecayShape(model_, measured_state_);
  if (observer_->TakesVoltage())
    voltage_magnet_state_ = model_.StateIndex(VoltageMagnetNode(config_, model_));
  voltage_magnet_weights_ = Eigen::VectorXd::Zero(observer_->NodeCount());
  if (voltage_magnet_state_ >= 0 && voltage_magnet_state_ < observer_->NodeCount())
    voltage_magnet_weights_(voltage_magnet_state_) = 1.0;
  const int n = model_.StateCount();
  const auto nn = static_cast<std::size_t>(n);
  x_degC_ = Eigen::VectorXd::Zero(n);
  sd_K_ = Eigen::VectorXd::Zero(n);
  found_heat_.f_K_per_s = Eigen::VectorXd::Zero(n);
  estimate_.node_degC.assign(nn, kNaN);
  estimate_.node_sd_K.assign(nn, kNaN);
  estimate_.node_filter_sd_K.assign(nn, kNaN);
  alarm_values_.assign(nn + 1, kNaN);
  alarm_sd_.assign(nn + 1, kNaN);
  // The last, the winding from resistance, keeps the band rule: no bound acts on it.
  alarm_rules_.assign(nn + 1, AlarmRule::kBand);
  for (const auto& name : model_.StateNames()) {
    auto it = config_.levels.find(name);
    trip_degC_.push_back(it == config_.levels.end() ? kInf : it->second.trip_degC);
  }
}

AlarmMonitor PumpEstimator::MakeAlarms() const {
  for (const auto& [node, limits] : config_.levels) {
    const std::string problem = UnknownLevelNode(model_, node);
    if (!problem.empty()) throw std::invalid_argument("alarm levels for " + problem);
  }
  AlarmConfig ac = config_.alarms;
  ac.sensor_node = model_.StateIndex(config_.measured_node);
  auto limits_of = [&](const std::string& node) {
    auto it = config_.levels.find(node);
    return it == config_.levels.end() ? TemperatureLimits{} : it->second;
  };
  std::vector<TemperatureLimits> limits;
  for (const auto& n : model_.StateNames()) limits.push_back(limits_of(n));
  limits.push_back(limits_of(kWindingResistanceNode));
  return AlarmMonitor(ac, limits, limits_of(kSensorLevelsNode));
}

bool PumpEstimator::StartIfNeeded(const PumpPeriod& p) {
  if (initialised_) return true;
  const double measured = frame_.offered_degC();
  const double x0 = std::isfinite(measured) ? measured : p.ambient_degC;
  if (!std::isfinite(x0)) return false;  // no temperature at all yet: nothing to estimate
  // A pump at rest whose frame is at the ambient has been off long enough to be at the frame's
  // temperature throughout: the natural moment to learn its R0 and psi0 from the run-up.
  const double rated_rpm = motor_.rated_speed_rpm;
  const bool at_rest = rated_rpm > 0.0 && std::abs(p.inputs.speed_rpm) < 0.1 * rated_rpm;
  const bool cold = std::isfinite(measured) && std::isfinite(p.ambient_degC) &&
                    std::abs(measured - p.ambient_degC) <= config_.cold_start_band_K && at_rest;
  estimate_.start = cold ? EstimateStart::kCold : EstimateStart::kWarm;
  estimate_.start_span_K = 0.0;
  voltage_fused_us_ = -1;
  estimate_.calibrated_at_cold_start = cold;
  ++estimate_.starts;
  if (cold) {
    StartCold(x0, measured - p.ambient_degC);
  } else {
    observer_->Initialise(x0);
    if (at_rest && std::isfinite(measured) && std::isfinite(p.ambient_degC))
      WidenForARun(measured - p.ambient_degC);
  }
  mismatch_.Initialise(x0, static_cast<double>(p.end_us) * 1e-6);
  initialised_ = true;
  return true;
}

void PumpEstimator::PrepareReadings(const PumpPeriod& p) {
  readings_ = ThermalReadings{};
  frame_.Offer(readings_);
  winding_.Prepare(p.identifier);
  winding_.Offer(readings_);
  magnet_.Prepare(p.identifier, p.mean_iq_A, ElectricalSpeed_rad_per_s(motor_, p.inputs.speed_rpm));
  // The voltage itself, not the identifier's back-EMF line fitted to the same samples: the two
  // would count one measurement twice. Without the frame's level the voltage is left out
  // (VoltageReading::Prepare) and the line stands in for it, as for an observer without voltage.
  // A period left out for a load change inside it gets the line only while the filter knows
  // psi0 no better than the line does: the line takes the nameplate's flux, anchored within its
  // bias sd. Once the voltage rows have learnt psi0 more closely (a cold start), a single line
  // would move the magnet by the nameplate's error (10 K per percent of flux) for good.
  held_magnet_ = VoltageMagnet{};
  if (observer_->TakesVoltage()) {
    const bool frame_failed = frame_.fault() != SensorFault::kNone;
    voltage_.Prepare(p.drive, frame_failed);
    voltage_.Offer(readings_);
    // Without the frame the voltage is no row, but the calibration it taught the filter still
    // holds: the magnet it gives with that calibration stands in for the line, which would
    // take the nameplate's R0 and psi0 (a 10-16 K bias on a motor 1.6 % off its flux) and,
    // fused in the periods between, kick a filter that has no frame to hold it.
    if (frame_failed) {
      HoldMagnet();
      if (held_magnet_.Valid()) {
        readings_.magnet_degC = held_magnet_.z_degC;
        readings_.magnet_sd_K = held_magnet_.sd_K;
        readings_.magnet_winding_gain = held_magnet_.winding_gain;
      }
      return;
    }
  }
  // The line gives the magnet through the motor file's law too: once that law is given up
  // (MagnetLawCheck), nothing reads the magnet from the flux.
  // After a cold start the rows learnt psi0 against known temperatures, however closely: the
  // line's anchor is the nameplate's flux, which is no closer than its tolerance.
  const bool gated = observer_->TakesVoltage() && voltage_.status().state == ReadingState::kGated;
  const bool rows_anchor = FluxKnownBetterThanTheLine() || estimate_.calibrated_at_cold_start;
  if (!voltage_.Offered() && !(gated && rows_anchor) && !estimate_.magnet_law_suspect)
    magnet_.Offer(readings_);
}

Eigen::VectorXd PumpEstimator::HalfRunSpan_K(double frame_excess_K) const {
  if (rest_decay_shape_.size() != model_.StateCount() ||
      !(frame_excess_K > config_.cold_start_warm_frame_K))
    return {};
  return 0.5 * (rest_decay_shape_.array() - 1.0) * frame_excess_K;
}

void PumpEstimator::StartCold(double frame_degC, double frame_excess_K) {
  // A frame warmer than the ambient by more than the sensors disagree is still cooling from a
  // run, and the nodes that cool slower than it (a rotor in vacuum) are warmer still: taken at
  // the frame's temperature, a rotor 10 K warm teaches psi0 a flux 1 % low, and the magnet reads
  // 10 K cold until the magnet law check blames the motor file. Each node lies between the
  // frame's temperature (a pump that never ran) and the model's decay at rest (one that
  // stopped): the middle, within half that span, one unknown for all of them (how long ago it
  // stopped: the decay's amplitude), besides the cold start's own sd per node.
  const Eigen::VectorXd half_span_K = HalfRunSpan_K(frame_excess_K);
  if (half_span_K.size() == 0) {
    observer_->InitialiseKnown(frame_degC, config_.cold_start_sd_K);
    return;
  }
  const int n = model_.StateCount();
  const double sd2 = config_.cold_start_sd_K * config_.cold_start_sd_K;
  const Eigen::MatrixXd s_K2 =
      sd2 * Eigen::MatrixXd::Identity(n, n) + half_span_K * half_span_K.transpose();
  observer_->InitialiseNodes(Eigen::VectorXd::Constant(n, frame_degC) + half_span_K, s_K2);
  estimate_.start_span_K = 2.0 * half_span_K.maxCoeff();
}

void PumpEstimator::WidenForARun(double frame_excess_K) {
  // A warm start at rest: the frame warm from a run, or a pump warm throughout (a bake, a
  // uniform start). The nodes stay at the frame's temperature, as a warm start takes them, but
  // the slower ones may be warmer by up to the model's decay at rest: their sd spans it. Not with
  // the voltage rows: their magnet is published with the nameplate's tolerance until a cold
  // start, which covers a warm rotor, and a rotor that open lets the run-up take the flux's
  // deficit for heat.
  if (observer_->TakesVoltage()) return;
  const Eigen::VectorXd half_span_K = HalfRunSpan_K(frame_excess_K);
  if (half_span_K.size() == 0) return;
  const int n = model_.StateCount();
  const Eigen::VectorXd x = observer_->State();  // copies: Restore starts the filter afresh
  Eigen::MatrixXd s = observer_->Covariance();
  s.topLeftCorner(n, n) += half_span_K * half_span_K.transpose();
  observer_->Restore(x, s);
  estimate_.start_span_K = 2.0 * half_span_K.maxCoeff();
}

void PumpEstimator::HoldMagnet() {
  if (voltage_magnet_state_ < 0 || estimate_.magnet_law_suspect) return;
  held_magnet_ = voltage_.CalibratedMagnet(observer_->VoltageCalibration(),
                                           observer_->Weighted_degC(model_.WindingWeights()));
}

double PumpEstimator::UncalibratedMagnetSd_K() const {
  // Until the filter has learnt psi0 against known temperatures (a cold start, in this run or
  // the saved one), the back-EMF line anchors it to the nameplate within the line's bias sd and
  // the filter's sd says psi0 is known; but this pump's flux may be anywhere within the
  // nameplate's tolerance, so the flux tells the magnet no better than psi0_sd_rel through the
  // magnet law (20 K for 2 % at -0.1 %/K). A law without temperature coefficient, or one given
  // up (MagnetLawCheck), makes the voltage no measurement of the magnet, and the filter's own sd
  // stands.
  // After a cold start the filter's own sd stands once the voltage has measured the flux (the
  // line's nameplate anchor is not fused then: PrepareReadings), however closely the rows pinned
  // psi0 (a frame still warm from a run leaves the magnet's temperature, and psi0, only as known
  // as the cold start's span).
  const bool flux_measured = voltage_fused_us_ >= 0 || FluxKnownBetterThanTheLine();
  if (!observer_->TakesVoltage() || estimate_.magnet_law_suspect ||
      (estimate_.calibrated_at_cold_start && flux_measured))
    return 0.0;
  const double law_per_K = std::abs(motor_.magnet.flux_temperature_coefficient_per_K);
  return law_per_K > 0.0 ? config_.psi0_sd_rel / law_per_K : 0.0;
}

bool PumpEstimator::LineCalibrated() const {
  // A filter that follows the line's bias learns it at a cold start (every node known), as the
  // voltage rows learn psi0; without one its bias stays psi0's tolerance, 20 K for han2019-tmp.
  return estimate_.calibrated_at_cold_start || std::isnan(observer_->MagnetBiasSd_K(0.0));
}

bool PumpEstimator::FluxKnownBetterThanTheLine() const {
  // The line's anchor as a relative flux: its bias sd (K) times the magnet law's coefficient.
  const double anchor_rel =
      config_.magnet.min_sd_K * std::abs(motor_.magnet.flux_temperature_coefficient_per_K);
  return observer_->VoltageCalibration().dpsi_sd < anchor_rel;
}

void PumpEstimator::RecordReadings(const ObserverReport& report) {
  frame_.Record(report.frame);
  winding_.Record(report.winding);
  magnet_.Record(report.magnet);
  voltage_.Record(report.voltage, observer_->TakesVoltage());
  estimate_.frame_reading = frame_.status();
  estimate_.winding_reading = winding_.status();
  estimate_.magnet_reading = magnet_.status();
  estimate_.voltage_reading = voltage_.status();
}

bool PumpEstimator::Step(const PumpPeriod& p) {
  const std::uint64_t before = estimate_.alarm_changes;
  const bool link_silent = !(p.fast_age_s <= config_.alarms.stale_after_s);
  frame_.Prepare(static_cast<double>(p.end_us) * 1e-6, link_silent);
  last_inputs_ = p.inputs;
  estimate_.resistance = p.identifier.estimate;
  // The identifier's until the filter's is current (PublishFromVoltage).
  estimate_.identification = IdentifiedBy(estimate_.resistance);
  if (!StartIfNeeded(p)) {
    StepWithoutEstimate(p);
    return estimate_.alarm_changes != before;
  }
  PrepareReadings(p);
  // A sensor back from a jump beyond physics may read at a new offset.
  if (frame_.BackFromJump()) observer_->ReopenSensorOffset();
  observer_->SetMagnetObserved(observer_->TakesVoltage() && UncalibratedMagnetSd_K() == 0.0);
  const ObserverReport& report = observer_->Step(p.inputs, p.dt_s, readings_);
  counters_.rejected_readings += static_cast<std::uint64_t>(report.rejected_readings);
  if (report.refused) {
    ++counters_.refused_steps;
    return false;
  }
  RecordReadings(report);
  if (report.voltage.fused) voltage_fused_us_ = p.end_us;
  ++counters_.steps;
  CheckModel(p, frame_.offered_degC());
  const bool diverged = Diverged();
  PublishNodes(diverged);
  MagnetLawCheck(p.dt_s);
  PublishReadings(p, report);
  StepBounds(p, diverged);
  StepAlarms(p, diverged);
  return estimate_.alarm_changes != before;
}

void PumpEstimator::CheckModel(const PumpPeriod& p, double measured_degC) {
  // The magnet temperature of this step's back-EMF row at the filter's winding estimate; with
  // the voltage reading, the magnet it gives at the filter's winding and calibration.
  // None once the magnet law is given up (MagnetLawCheck): the flux no longer gives the magnet.
  const double magnet_degC =
      estimate_.magnet_law_suspect ? kNaN
      : observer_->TakesVoltage()
          ? voltage_.MagnetAt_degC(*observer_, model_, voltage_magnet_state_)
          : magnet_.MagnetAt_degC(observer_->Weighted_degC(model_.WindingWeights()));
  const std::uint64_t refused = mismatch_.refused_steps();
  const MismatchFinding& f = mismatch_.Step(p.inputs, p.dt_s, measured_degC,
                                            static_cast<double>(p.end_us) * 1e-6, magnet_degC);
  counters_.mismatch_refused += mismatch_.refused_steps() - refused;
  if (NewVerdict(f, estimate_.mismatch)) ++estimate_.mismatch_changes;
  estimate_.mismatch = f;
  AdoptNamedSensorLag();
}

void PumpEstimator::AdoptNamedSensorLag() {
  // A lag the diagnosis fitted against the whole history (docs/virtual-sensor.md, "The sensor's
  // lag") is the sensor's: read with the configured one, a fast rise of the frame reads late.
  const MismatchFinding& f = estimate_.mismatch;
  if (!config_.adopt_named_sensor_lag || f.effect != MismatchEffect::kSensorLag ||
      f.state != MismatchState::kSensorFaultSuspected || !(f.value > 0.0) ||
      f.value == estimate_.frame_sensor_lag_s) {
    return;
  }
  TakeSensorLag(f.value, false);
}

void PumpEstimator::TakeSensorLag(double lag_s, bool restored) {
  if (!observer_->AdoptSensorLag(lag_s)) return;  // no lag state: the filter has none to set
  mismatch_.AdoptSensorLag(lag_s);
  estimate_.frame_sensor_lag_s = lag_s;
  estimate_.frame_sensor_lag_restored = restored;
  ++estimate_.sensor_lag_changes;
}

// A filter driven outside any physical range is no estimate. The copper loss grows with the
// temperature (Saheba 2010 eqs. 12-16), so currents far above any rating, held while the frame
// sensor is silent, make the linearised network unstable and the estimate runs away to Inf
// within minutes. Then nothing is published as a temperature ("n/a", alarms see unknown nodes
// and an unconverged filter, a latched trip stays), the state is not saved, and the next step
// starts the filter again.
bool PumpEstimator::Diverged() {
  const int n = model_.StateCount();
  for (int i = 0; i < n; ++i) {
    x_degC_(i) = observer_->Node_degC(i);
    sd_K_(i) = observer_->NodeSd_K(i);
  }
  const bool diverged = !x_degC_.allFinite() || !sd_K_.allFinite() || !InEstimateRange(x_degC_);
  if (diverged) {
    ++counters_.filter_resets;
    initialised_ = false;
  }
  return diverged;
}

void PumpEstimator::PublishNodes(bool diverged) {
  for (int i = 0; i < x_degC_.size(); ++i) {
    const auto k = static_cast<std::size_t>(i);
    estimate_.node_degC[k] = diverged ? kNaN : x_degC_(i);
    estimate_.node_filter_sd_K[k] = estimate_.node_sd_K[k] = diverged ? kNaN : sd_K_(i);
  }
  // The magnet's node is published no narrower than psi0's calibration allows (the levels on it
  // act on that); the bounds of the blind and silent stretches start from the filter's own sd,
  // which carries the thermal model's knowledge of that node.
  if (!diverged && voltage_magnet_state_ >= 0) {
    double& sd = estimate_.node_sd_K[static_cast<std::size_t>(voltage_magnet_state_)];
    sd = std::max(sd, UncalibratedMagnetSd_K());
  }
  estimate_.initialised = !diverged;
  estimate_.filter_converged = !diverged && observer_->SettledWithin(kConvergedSd_K);
}

void PumpEstimator::PublishReadings(const PumpPeriod& p, const ObserverReport& report) {
  estimate_.time_us = p.end_us;
  estimate_.identifier_winding_degC = winding_.degC();
  estimate_.calibration = observer_->VoltageCalibration();
  if (observer_->TakesVoltage() && frame_.fault() == SensorFault::kNone) {
    PublishFromVoltage(p);
  } else {
    // The identifier's own winding temperature takes the nameplate's R0, and its Rs while it
    // tracks can be off by several of its sds as the magnet warms: a diagnostic only (the CSV's
    // identifier_winding_degC), never the published winding from resistance.
    estimate_.winding_resistance_degC = estimate_.winding_resistance_sd_K = kNaN;
    estimate_.magnet_flux_degC = estimate_.magnet_flux_sd_K = kNaN;
    // With the voltage taken, the line (the nameplate's flux) is never published: a period
    // without the held magnet (a load change inside it) publishes none.
    if (estimate_.initialised && held_magnet_.Valid()) {
      PublishHeldMagnet();
    } else if (estimate_.initialised && !observer_->TakesVoltage() && LineCalibrated()) {
      magnet_.Publish(*observer_, estimate_.magnet_flux_degC, estimate_.magnet_flux_sd_K);
    }
  }
  if (estimate_.magnet_law_suspect) estimate_.magnet_flux_degC = estimate_.magnet_flux_sd_K = kNaN;
  estimate_.frame_measured_degC = frame_.offered_degC();
  estimate_.sensor_fault = frame_.fault();
  estimate_.ambient_degC = p.inputs.ambient_degC;
  estimate_.speed_rpm = p.inputs.speed_rpm;
  const ReadingRow& row = report.frame;
  const bool frame_row = row.fused && row.innovation_var_K2 > 0.0;
  estimate_.innovation_K = frame_row ? row.innovation_K : kNaN;
  estimate_.nis = frame_row ? row.Nis() : kNaN;
  estimate_.sensor_offset_K = observer_->SensorOffset_K();
  estimate_.sensor_steps = static_cast<std::uint64_t>(observer_->SensorSteps());
  estimate_.last_sensor_step_K = observer_->LastSensorStep_K();
  estimate_.stepped_offset_K = observer_->SteppedOffset_K();
}

void PumpEstimator::MagnetLawCheck(double dt_s) {
  const double heat_W = observer_->RotorHeat_W();
  const double sd_W = observer_->RotorHeatSd_W();
  estimate_.rotor_heat_W = heat_W;
  estimate_.rotor_heat_sd_W = sd_W;
  // Heat the model lacks warms the rotor; nothing inside a pump in vacuum cools it by watts
  // the model does not have. A rotor the magnet reads colder than that is a magnet whose flux
  // falls less per kelvin than the motor file says: each kelvin it warms reads as less.
  // Beyond rotor_heat_found_sds of its prior sd, d_r's variance is held at (d_r / that)^2 by
  // design: a heat that large is beyond doubt without counting its sds.
  const DisturbanceSensorConfig& d = config_.disturbance;
  const bool beyond = heat_W < -config_.magnet_law_sds * sd_W ||
                      heat_W < -d.rotor_heat_found_sds * d.rotor_heat_sd_W;
  const bool colder = observer_->TakesVoltage() && frame_.fault() == SensorFault::kNone &&
                      heat_W < -config_.magnet_law_heat_W && beyond;
  magnet_colder_s_ = colder ? magnet_colder_s_ + dt_s : 0.0;
  if (!estimate_.magnet_law_suspect && magnet_colder_s_ >= config_.magnet_law_after_s) {
    estimate_.magnet_law_suspect = true;
    ++estimate_.magnet_law_changes;
    observer_->FreeMagnetLaw();
  }
}

void PumpEstimator::PublishHeldMagnet() {
  // The reading at the filter's winding, with the winding's uncertainty through its gain.
  const Eigen::VectorXd& w = model_.WindingWeights();
  const double g = held_magnet_.winding_gain;
  estimate_.magnet_flux_degC = held_magnet_.MagnetAt_degC(observer_->Weighted_degC(w));
  estimate_.magnet_flux_sd_K =
      std::sqrt(held_magnet_.sd_K * held_magnet_.sd_K + g * g * observer_->WeightedVariance_K2(w));
}

void PumpEstimator::PublishFromVoltage(const PumpPeriod& p) {
  PumpEstimate& e = estimate_;
  e.winding_resistance_degC = e.winding_resistance_sd_K = kNaN;
  e.magnet_flux_degC = e.magnet_flux_sd_K = kNaN;
  // Without a fresh voltage (a silent drive) nothing of the filter's is current: the identifier's
  // identification, set at the step's start, stays published (IdentifiedBy: its status alone).
  if (!e.initialised) return;
  const bool fresh =
      voltage_fused_us_ >= 0 &&
      static_cast<double>(p.end_us - voltage_fused_us_) * 1e-6 <= config_.alarms.stale_after_s;
  if (!fresh) return;
  // A model without winding weights has no winding from resistance (NaN), the flux still.
  const Eigen::VectorXd& w = model_.WindingWeights();
  const bool has_winding = w.sum() > 0.0;
  const double winding_degC = has_winding ? observer_->Weighted_degC(w) : kNaN;
  const double winding_var_K2 = has_winding ? observer_->WeightedVariance_K2(w) : kNaN;
  PublishFusedTemperatures(winding_degC, winding_var_K2);
  PublishFusedIdentification(winding_degC, winding_var_K2);
}

void PumpEstimator::PublishFusedTemperatures(double winding_degC, double winding_var_K2) {
  PumpEstimate& e = estimate_;
  // The flux follows the magnet: its node, as the filter has it with the voltage, while psi0 is
  // known (a flux with psi0 a nameplate's few percent off tells the magnet no better than the
  // thermal model does).
  if (UncalibratedMagnetSd_K() == 0.0) {
    e.magnet_flux_degC = observer_->Node_degC(voltage_magnet_state_);
    e.magnet_flux_sd_K = observer_->NodeSd_K(voltage_magnet_state_);
  }
  // The resistance follows the copper: the winding weights, while R0 is known (a resistance
  // with R0 a nameplate's few percent off tells the winding no better than the frame does).
  // R0's relative error as a winding temperature: R = R0 (1 + dR)(1 + alpha (Tw - T0)).
  const auto& cu = motor_.copper;
  const double calibration_sd_K =
      e.calibration.dr_sd * (1.0 + cu.alpha_per_K * (winding_degC - cu.t0_degC)) / cu.alpha_per_K;
  if (!(calibration_sd_K <= config_.max_calibration_sd_K)) return;
  e.winding_resistance_degC = winding_degC;
  // The nodes' sd floor (model error no state represents) applies to the winding too.
  const double floor_K = observer_->SdFloor_K();
  e.winding_resistance_sd_K = std::sqrt(winding_var_K2 + floor_K * floor_K);
}

void PumpEstimator::PublishFusedIdentification(double winding_degC, double winding_var_K2) {
  PublishedIdentification& id = estimate_.identification;
  id = {};
  const ThermalObserver::Calibration& c = estimate_.calibration;
  using Entry = ThermalObserver::CalibrationEntry;
  // Rs = R0 (1 + dr)(1 + alpha (Tw - T0)) (Han 2019 eq. 2) at the filter's winding.
  const auto& cu = motor_.copper;
  const double copper = 1.0 + cu.alpha_per_K * (winding_degC - cu.t0_degC);
  id.resistance_ohm = cu.r0_ohm * (1.0 + c.dr) * copper;
  id.resistance_sd_ohm = ProductSd(
      cu.r0_ohm * copper, c.dr_sd * c.dr_sd, cu.r0_ohm * (1.0 + c.dr) * cu.alpha_per_K,
      winding_var_K2, observer_->CalibrationCovariance(Entry::kR0, model_.WindingWeights()));
  // psi_f = psi0 (1 + dpsi)(1 + beta (Tm - T0)) at the filter's magnet node.
  if (voltage_magnet_state_ >= 0 && motor_.magnet.Given()) {
    const int m = voltage_magnet_state_;
    const double beta = motor_.magnet.flux_temperature_coefficient_per_K;
    const double magnet = FluxAt_Wb(motor_, observer_->State()(m)) / motor_.flux_Wb;
    id.flux_Wb = motor_.flux_Wb * (1.0 + c.dpsi) * magnet;
    id.flux_sd_Wb =
        ProductSd(motor_.flux_Wb * magnet, c.dpsi_sd * c.dpsi_sd,
                  motor_.flux_Wb * (1.0 + c.dpsi) * beta, observer_->Covariance()(m, m),
                  observer_->CalibrationCovariance(Entry::kPsi0, voltage_magnet_weights_));
  }
  id.status = std::isfinite(estimate_.winding_resistance_degC) ? ResistanceStatus::kTracking
                                                               : ResistanceStatus::kConverging;
  id.flux_status = std::isfinite(estimate_.magnet_flux_degC) ? ResistanceStatus::kTracking
                                                             : ResistanceStatus::kConverging;
  // Not yet calibrated, each is left out, as the temperature it gives: R0 or psi0 still near the
  // nameplate's tolerance, the value would wander from the truth by more than its sd says.
  if (id.status != ResistanceStatus::kTracking) id.resistance_ohm = id.resistance_sd_ohm = kNaN;
  if (id.flux_status != ResistanceStatus::kTracking) id.flux_Wb = id.flux_sd_Wb = kNaN;
  if (fused_status_ != id.status && (fused_status_ == ResistanceStatus::kConverging ||
                                     fused_status_ == ResistanceStatus::kTracking))
    ++estimate_.r0_changes;
  fused_status_ = id.status;
}

void PumpEstimator::NoteIdentifier(const ResistanceEstimate& resistance) {
  estimate_.resistance = resistance;
  estimate_.identification = IdentifiedBy(resistance);
}

void PumpEstimator::StepBounds(const PumpPeriod& p, bool diverged) {
  // Blind: the sensor itself failed and no other reading stands in. A silent link alone is
  // stale telemetry (the estimate runs on with the last inputs), but it does not end a blind
  // stretch that began before it. The magnet held from the voltage stands in only while its sd
  // is within the line's anchor (a calibration learnt at a cold start): with a calibration still
  // a nameplate's few percent, the rotor it gives is too vague to see a lost cooling, and the
  // worst case must run. The line counts whenever it is fused: the filter follows its bias as a
  // slow state, so a lost cooling still shows in the rotor it gives.
  const bool measured_again =
      frame_.fault() == SensorFault::kNone || std::isfinite(winding_.degC()) ||
      (magnet_.Offered() && !observer_->TakesVoltage()) ||
      (held_magnet_.Valid() && held_magnet_.sd_K <= config_.magnet.min_sd_K);
  AlarmValuesStep s;
  s.end_us = p.end_us;
  s.period_s = config_.period_s;
  s.inputs = &p.inputs;
  s.fresh_inputs = p.fresh_inputs;
  s.blind = !diverged && !measured_again &&
            (frame_.alarm_fault() != SensorFault::kNone || values_.Blind());
  s.fault = frame_.fault();
  s.reading_changed_s = frame_.health().changed_s();
  s.x_degC = &x_degC_;
  s.sd_K = &sd_K_;
  s.valid = !diverged;
  s.lagging_degC = observer_->ModelsSensorLag() ? kNaN : frame_.offered_degC();
  s.stale_after_s = config_.alarms.stale_after_s;
  s.trip_sd_factor = config_.alarms.trip_sd_factor;
  s.frame_path_heat_W = FramePathHeat_W();
  s.inside_verdict = InsideVerdictOf(estimate_.mismatch);
  s.inside_onset_s = estimate_.mismatch.onset_s;
  values_.Step(s);
  for (int i = 0; i < x_degC_.size(); ++i) {
    const auto k = static_cast<std::size_t>(i);
    const auto [value_degC, rule] = values_.ValueAndRule(i, x_degC_(i));
    alarm_values_[k] = diverged ? kNaN : value_degC;
    alarm_rules_[k] = diverged ? AlarmRule::kBand : rule;
    alarm_sd_[k] = estimate_.node_sd_K[k];
    const double top_degC = diverged ? kNaN : values_.BandTop_degC(i, value_degC);
    estimate_.node_sd_K[k] = values_.PublishedSd_K(i, alarm_sd_[k], top_degC - x_degC_(i));
  }
  alarm_values_.back() = estimate_.winding_resistance_degC;
}

double PumpEstimator::FramePathHeat_W() {
  if (!disturbance_states_ || measured_state_ < 0) return kNaN;
  // The heat the observer has found, per node (ThermalObserver::AddFoundHeat, K/s), at the
  // measured node: its frame-path heat.
  found_heat_.f_K_per_s.setZero();
  observer_->AddFoundHeat(found_heat_);
  return found_heat_.f_K_per_s(measured_state_) * model_.Capacities_J_per_K()(measured_state_);
}

void PumpEstimator::StepAlarms(const PumpPeriod& p, bool diverged) {
  int ttt_node = -1;
  const double ttt = diverged ? kNaN
                              : forecast_.TimeToTrip_s(model_, p.inputs, x_degC_, trip_degC_,
                                                       observer_.get(), &ttt_node);
  estimate_.time_to_trip_node = ttt_node;
  AlarmInputs ai;
  ai.sensor_degC = frame_.offered_degC();
  ai.sensor_raw_degC = frame_.raw_degC();
  ai.sensor_fault = frame_.alarm_fault();
  ai.sensor_model_degC = measured_state_ >= 0 && !diverged ? x_degC_(measured_state_) : kNaN;
  ai.sensor_nis = estimate_.nis;
  ai.sensor_offset_K =
      observer_->EstimatesSensorOffset() && !diverged ? estimate_.stepped_offset_K : kNaN;
  ai.estimators_converged = estimate_.filter_converged;
  ai.time_to_trip_s = ttt;
  ai.time_to_trip_node = ttt_node;
  ai.telemetry_age_s = p.telemetry_age_s;
  ai.node_degC = alarm_values_.data();
  ai.node_sd_K = alarm_sd_.data();
  // A model the plant no longer follows makes the filter disagree with a sound sensor: the
  // disagreement test is held (neither raised nor cleared) while the mismatch test blames the
  // plant, has not named the cause yet, or is still learning (it cannot tell them apart then).
  const auto ms = estimate_.mismatch.state;
  if (ms == MismatchState::kPlantChange || ms == MismatchState::kUnexplained ||
      ms == MismatchState::kLearning) {
    ai.sensor_nis = kNaN;
  }
  // The identifier's health is published with its estimate (status) but is no alarm: its
  // winding is fused only while it is tracking, so an identifier still converging costs
  // accuracy, not safety.
  const AlarmState before = estimate_.alarm;
  estimate_.alarm = alarms_.Step(static_cast<double>(p.end_us) * 1e-6, ai);
  const auto& now = estimate_.alarm;
  // A change worth publishing at once: level, reason, node, the set of active reasons, latch.
  if (now.level != before.level || now.reason != before.reason || now.node != before.node ||
      now.active_reasons != before.active_reasons || now.trip_latched != before.trip_latched) {
    ++estimate_.alarm_changes;
  }
  if (now.level != before.level || now.reason != before.reason || now.node != before.node) {
    const auto node = static_cast<std::size_t>(now.node);
    estimate_.alarm_rule = now.reason == AlarmReason::kEstimatedOverTemperature && now.node >= 0 &&
                                   node < alarm_rules_.size()
                               ? alarm_rules_[node]
                               : AlarmRule::kBand;
  }
}

// The drive's frames arrive but no temperature has yet (no status frame: neither the frame
// sensor nor the ambient), so the filter cannot start. The sensor's absence while the drive
// speaks is still a sensor fault, and it goes out with the pump's other conditions; no node is
// known.
void PumpEstimator::StepWithoutEstimate(const PumpPeriod& p) {
  std::fill(alarm_values_.begin(), alarm_values_.end(), kNaN);
  AlarmInputs ai;
  ai.node_degC = alarm_values_.data();
  ai.sensor_fault = frame_.alarm_fault();
  ai.telemetry_age_s = p.telemetry_age_s;
  ai.estimators_converged = false;
  estimate_.sensor_fault = frame_.fault();
  RunAlarmsOnly(p.end_us, ai);
}

bool PumpEstimator::StepNeverHeard(std::int64_t t_us, double silence_s) {
  std::fill(alarm_values_.begin(), alarm_values_.end(), kNaN);  // nothing known of any node
  AlarmInputs ai;
  ai.node_degC = alarm_values_.data();
  ai.telemetry_age_s = silence_s;
  return RunAlarmsOnly(t_us, ai);
}

bool PumpEstimator::RunAlarmsOnly(std::int64_t t_us, const AlarmInputs& ai) {
  const AlarmState before = estimate_.alarm;
  estimate_.alarm = alarms_.Step(static_cast<double>(t_us) * 1e-6, ai);
  estimate_.time_us = t_us;  // the alarm's time (LCM utime, CSV row)
  if (estimate_.alarm == before) return false;
  ++estimate_.alarm_changes;
  return true;
}

PumpEstimatorState PumpEstimator::Save() const {
  PumpEstimatorState s;
  s.model_name = model_.Name();
  s.time_us = estimate_.time_us;
  // A restart goes on from what was published.
  const int n = model_.StateCount();
  s.x_degC = observer_->State().head(n);
  s.s_K2 = observer_->Covariance().topLeftCorner(n, n);
  s.inputs = last_inputs_;
  if (observer_->EstimatesSensorOffset() && initialised_) {
    // A sensor that stepped stays known as such across a restart.
    s.sensor_offset_K = observer_->SensorOffset_K();
    s.sensor_offset_sd_K = observer_->SensorOffsetSd_K();
    s.stepped_offset_K = observer_->SteppedOffset_K();
  }
  if (observer_->StateCount() > n && initialised_) {
    // And what the filter found about the plant (lost cooling, heat inside): restarted at its
    // priors, the interior took the slack of a fault for minutes (docs/daemon.md, "State").
    s.observer_x = observer_->State();
    s.observer_s = observer_->Covariance();
    s.cold_started = estimate_.calibrated_at_cold_start;
    if (estimate_.magnet_law_suspect)
      s.magnet_law_given_up_per_K = motor_.magnet.flux_temperature_coefficient_per_K;
    if (estimate_.frame_sensor_lag_s != config_.frame_sensor_lag_s) {
      s.taken_sensor_lag_s = estimate_.frame_sensor_lag_s;
      s.taken_over_configured_lag_s = config_.frame_sensor_lag_s;
    }
    s.losses_sd_rel = config_.disturbance.loss_scale_initial_sd;
  }
  const auto& names = model_.StateNames();
  for (const auto& t : alarms_.LatchedTrips()) {
    const std::string node = t.node == AlarmMonitor::kSensorTrip ? std::string(kSensorLevelsNode)
                             : t.node == AlarmMonitor::kStateLostTrip ? std::string(kStateLostNode)
                             : t.node < static_cast<int>(names.size())
                                 ? names[static_cast<std::size_t>(t.node)]
                                 : std::string(kWindingResistanceNode);
    s.latched_trips.push_back({node, t.value});
  }
  return s;
}

namespace {

/// A damaged or forged file must not become a published estimate: temperatures in the
/// believable range, variances not negative, inputs finite (they are held while down), a saved
/// sensor offset whole (all three finite, its sd positive).
bool PlausibleState(const PumpEstimatorState& state, const ThermalModel& model) {
  const int n = model.StateCount();
  if (state.model_name != model.Name() || state.x_degC.size() != n || state.s_K2.rows() != n ||
      state.s_K2.cols() != n || !state.x_degC.allFinite() || !state.s_K2.allFinite()) {
    return false;
  }
  const auto& in = state.inputs;
  if (!InEstimateRange(state.x_degC) || (n > 0 && state.s_K2.diagonal().minCoeff() < 0.0) ||
      !std::isfinite(in.speed_rpm) || !std::isfinite(in.id_A) || !std::isfinite(in.iq_A) ||
      !std::isfinite(in.ambient_degC) || !std::isfinite(in.coolant_degC)) {
    return false;
  }
  const bool lag_saved =
      !std::isnan(state.taken_sensor_lag_s) || !std::isnan(state.taken_over_configured_lag_s);
  // The diagnosis names up to ten times the configured lag, beyond any lag a configuration takes.
  if (lag_saved && !(state.taken_sensor_lag_s > 0.0 && std::isfinite(state.taken_sensor_lag_s) &&
                     state.taken_over_configured_lag_s >= 0.0 &&
                     std::isfinite(state.taken_over_configured_lag_s))) {
    return false;
  }
  if (!std::isnan(state.losses_sd_rel) &&
      !(state.losses_sd_rel > 0.0 && std::isfinite(state.losses_sd_rel))) {
    return false;
  }
  const bool offset_saved = !std::isnan(state.sensor_offset_K);
  return !offset_saved ||
         (std::isfinite(state.sensor_offset_K) && std::isfinite(state.stepped_offset_K) &&
          std::isfinite(state.sensor_offset_sd_K) && state.sensor_offset_sd_K > 0.0);
}

}  // namespace

bool PumpEstimator::Restore(const PumpEstimatorState& state, std::int64_t now_us) {
  if (!PlausibleState(state, model_)) return false;
  const int n = model_.StateCount();
  // The observer's whole state: taken when it fits this configuration (another count of states
  // is another configuration: the nodes alone are restored); damaged, refused.
  // A state saved after the magnet law was given up holds a flux that no longer follows the
  // magnet: it fits only while the motor file states the law given up (a corrected file starts
  // its calibration afresh).
  const bool law_given_up = !std::isnan(state.magnet_law_given_up_per_K);
  const bool law_kept = !law_given_up || state.magnet_law_given_up_per_K ==
                                             motor_.magnet.flux_temperature_coefficient_per_K;
  const bool whole = observer_->StateCount() > n &&
                     state.observer_x.size() == observer_->StateCount() &&
                     state.observer_s.rows() == observer_->StateCount() &&
                     state.observer_s.cols() == observer_->StateCount() && law_kept;
  if (whole && !observer_->CanRestore(state.observer_x, state.observer_s)) return false;
  std::vector<AlarmMonitor::LatchedTrip> trips;
  if (!TripIndices(state, trips)) return false;
  Eigen::VectorXd x = state.x_degC;
  Eigen::MatrixXd s = state.s_K2;
  const double gap_s = static_cast<double>(now_us - state.time_us) * 1e-6;
  // The time the daemon was down, the inputs then held, with the standard filter's process
  // noise over it (the nodes, for an observer restored from them).
  if (gap_s > 0.0 && !PredictOverGap(model_, state.inputs, gap_s, config_.standard, x, s)) {
    return false;
  }
  if (!x.allFinite() || !s.allFinite() || !InEstimateRange(x)) return false;
  // A lag taken before the restart is the sensor's while the configuration still says the lag
  // it was taken over; read over the time down with it (the mismatch test starts afresh below,
  // with it).
  if (whole && config_.adopt_named_sensor_lag && state.taken_sensor_lag_s > 0.0 &&
      state.taken_over_configured_lag_s == config_.frame_sensor_lag_s) {
    TakeSensorLag(state.taken_sensor_lag_s, true);
  }
  // A calibration from a cold start holds only while the state that carries it was kept.
  const bool restored_whole = RestoreObserver(state, whole, gap_s, x, s);
  estimate_.calibrated_at_cold_start = restored_whole && state.cold_started;
  if (restored_whole && law_given_up) {
    estimate_.magnet_law_suspect = true;
    observer_->RestoreMagnetLawGivenUp();
  }
  // Losses stated to be further off the model's than when the state was saved: the operator's
  // word for this pump's model, which the saved loss scale did not have.
  const double stated = config_.disturbance.loss_scale_initial_sd;
  const double saved = std::isnan(state.losses_sd_rel)
                           ? DisturbanceSensorConfig{}.loss_scale_initial_sd
                           : state.losses_sd_rel;
  const bool widen = restored_whole && stated > saved;
  if (widen) observer_->WidenLossScale(stated);
  estimate_.losses_sd_widened_from = widen ? saved : kNaN;
  estimate_.losses_sd_widened_to = widen ? stated : kNaN;
  estimate_.start = EstimateStart::kRestored;
  ++estimate_.starts;
  // The time the daemon was down is a telemetry silence: the load may have risen in it.
  values_.BeginSilence(state.x_degC, state.inputs, static_cast<double>(state.time_us) * 1e-6, x,
                       static_cast<double>(now_us) * 1e-6);
  // The mismatch test starts afresh (learning) from the restored level, and with it the
  // inside-heat bound it latched.
  values_.ForgetInsideHeat();
  mismatch_.Initialise(n > 0 ? x(std::max(measured_state_, 0)) : 25.0,
                       static_cast<double>(now_us) * 1e-6);
  last_inputs_ = state.inputs;
  initialised_ = true;
  for (int i = 0; i < n; ++i) {
    const auto k = static_cast<std::size_t>(i);
    estimate_.node_degC[k] = observer_->Node_degC(i);
    estimate_.node_filter_sd_K[k] = estimate_.node_sd_K[k] = observer_->NodeSd_K(i);
  }
  estimate_.initialised = true;
  estimate_.filter_converged = observer_->SettledWithin(kConvergedSd_K);
  estimate_.time_us = now_us;
  Relatch(trips, now_us);
  return true;
}

bool PumpEstimator::RestoreObserver(const PumpEstimatorState& state, bool whole, double gap_s,
                                    const Eigen::VectorXd& x, const Eigen::MatrixXd& s) {
  const bool offset_saved = !std::isnan(state.sensor_offset_K);
  if (whole) {
    // Aged over the time down with what it had found (the frame-path heat of lost cooling goes
    // on heating), the inputs held; no reading, so no step test against the saved one.
    observer_->Restore(state.observer_x, state.observer_s);
    observer_->RestoreSteppedOffset(offset_saved ? state.stepped_offset_K : 0.0);
    if (gap_s <= 0.0) return true;
    const ObserverReport& report = observer_->Step(state.inputs, gap_s, ThermalReadings{});
    const int n = model_.StateCount();
    if (!report.refused && observer_->State().allFinite() && observer_->Covariance().allFinite() &&
        InEstimateRange(observer_->State().head(n))) {
      return true;
    }
  }
  // From the restored nodes, the rest at its prior (an older file, another configuration, a
  // state that aged out of range).
  observer_->InitialiseNodes(x, s);
  if (offset_saved) {
    observer_->RestoreSensorOffset(state.sensor_offset_K, state.sensor_offset_sd_K,
                                   state.stepped_offset_K);
  }
  return false;
}

bool PumpEstimator::TripIndices(const PumpEstimatorState& state,
                                std::vector<AlarmMonitor::LatchedTrip>& out) const {
  // Alarm node names -> the monitor's indices (model nodes, then the winding resistance).
  out.clear();
  for (const auto& t : state.latched_trips) {
    const std::optional<int> node = LatchIndex(t.node);
    if (!node || !std::isfinite(t.value_degC)) return false;
    out.push_back({*node, t.value_degC});
  }
  return true;
}

std::optional<int> PumpEstimator::LatchIndex(const std::string& name) const {
  if (name == kWindingResistanceNode) return model_.StateCount();
  if (name == kSensorLevelsNode) return AlarmMonitor::kSensorTrip;
  if (name == kStateLostNode) return AlarmMonitor::kStateLostTrip;
  const int node = model_.StateIndex(name);
  return node < 0 ? std::nullopt : std::optional<int>(node);
}

void PumpEstimator::LatchStateLost(std::int64_t t_us) {
  alarms_.LatchStateLost(static_cast<double>(t_us) * 1e-6);
  estimate_.alarm = alarms_.state();
  ++estimate_.alarm_changes;
}

void PumpEstimator::RaiseSecondSender(std::int64_t t_us) {
  const AlarmState before = alarms_.state();
  alarms_.RaiseSecondSender(static_cast<double>(t_us) * 1e-6);
  if (alarms_.state() == before) return;
  estimate_.alarm = alarms_.state();
  ++estimate_.alarm_changes;
}

void PumpEstimator::Relatch(const std::vector<AlarmMonitor::LatchedTrip>& trips,
                            std::int64_t now_us) {
  for (const auto& t : trips) alarms_.RestoreLatchedTrip(t, static_cast<double>(now_us) * 1e-6);
  if (!trips.empty()) {
    estimate_.alarm = alarms_.state();
    ++estimate_.alarm_changes;
  }
}

bool PumpEstimator::RestoreLatchedTrips(const PumpEstimatorState& state, std::int64_t now_us) {
  std::vector<AlarmMonitor::LatchedTrip> trips;
  if (!TripIndices(state, trips)) return false;
  Relatch(trips, now_us);
  return true;
}

}  // namespace pumptherm::estimators
