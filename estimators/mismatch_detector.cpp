#include "estimators/mismatch_detector.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <cmath>
#include <exception>
#include <stdexcept>

namespace pumptherm::estimators {
namespace {

/// Largest frame-to-ambient resistance scale reported: beyond it the fitted conductance change
/// (theta -> -1) no longer tells the size.
constexpr double kMaxResistanceScale = 20.0;

/// Hypotheses of the naming fit, in column-block order.
/// kAmbientRamp is the unmeasured ambient reaching its size linearly over `ambient_ramp_s`.
enum Hypothesis : int {
  kCooling = 0,
  kRotor,
  kLoss,
  kAmbient,
  kAmbientRamp,
  kOffset,
  kLag,
  kHypotheses
};

/// The lag fit's range: a quarter to ten times the configured lag, or, with none configured,
/// kShortestLag_s to kLongestLag_s (an RTD in a housing lags some 5 to 120 s); kNoLag_s stands
/// for no lag (far below a period: the lag state is the node).
constexpr double kMaxLagScale = 10.0;
constexpr double kShortestLag_s = 1.0;
constexpr double kLongestLag_s = 600.0;
constexpr double kNoLag_s = 0.05;

MismatchEffect EffectOf(int h) {
  switch (h) {
    case kCooling:
      return MismatchEffect::kFrameAmbientResistance;
    case kRotor:
      return MismatchEffect::kRotorLoss;
    case kLoss:
      return MismatchEffect::kLossScale;
    case kAmbient:
    case kAmbientRamp:
      return MismatchEffect::kUnmeasuredAmbient;
    case kLag:
      return MismatchEffect::kSensorLag;
    default:
      return MismatchEffect::kSensorOffset;
  }
}

/// Standard normal upper quantile z with Q(z) = p, by bisection on erfc (p in (0, 0.5)).
double NormalUpperQuantile(double p) {
  double lo = 0.0, hi = 40.0;
  for (int i = 0; i < 200; ++i) {
    const double mid = 0.5 * (lo + hi);
    if (0.5 * std::erfc(mid / std::sqrt(2.0)) > p)
      lo = mid;
    else
      hi = mid;
  }
  return 0.5 * (lo + hi);
}

}  // namespace

const char* MismatchStateName(MismatchState state) {
  switch (state) {
    case MismatchState::kConsistent:
      return "consistent";
    case MismatchState::kLearning:
      return "learning";
    case MismatchState::kPlantChange:
      return "plant_change";
    case MismatchState::kSensorFaultSuspected:
      return "sensor_fault_suspected";
    case MismatchState::kUnexplained:
      return "unexplained";
  }
  return "unknown";
}

const char* MismatchEffectName(MismatchEffect effect) {
  switch (effect) {
    case MismatchEffect::kNone:
      return "none";
    case MismatchEffect::kFrameAmbientResistance:
      return "frame_ambient_resistance";
    case MismatchEffect::kRotorLoss:
      return "rotor_loss";
    case MismatchEffect::kLossScale:
      return "loss_scale";
    case MismatchEffect::kUnmeasuredAmbient:
      return "unmeasured_ambient";
    case MismatchEffect::kSensorOffset:
      return "sensor_offset";
    case MismatchEffect::kSensorStuck:
      return "sensor_stuck";
    case MismatchEffect::kSensorLag:
      return "sensor_lag";
  }
  return "unknown";
}

std::string DescribeFinding(const MismatchFinding& f) {
  if (f.state == MismatchState::kConsistent) return "consistent";
  if (f.state == MismatchState::kLearning) return "learning";
  if (f.state == MismatchState::kUnexplained) return "model mismatch, effect not named yet";
  const double v = f.value;
  switch (f.effect) {
    case MismatchEffect::kFrameAmbientResistance:
      // At the cap the fit says only that the conductance is (nearly) gone.
      return fmt::format("frame-to-ambient resistance x{:.1f}{} ({})", v,
                         v >= kMaxResistanceScale ? " or more" : "",
                         v >= 2.0  ? "cooling lost"
                         : v > 1.0 ? "cooling reduced"
                                   : "cooling improved");
    case MismatchEffect::kRotorLoss:
      return fmt::format("rotor loss {:+.1f} W (heat inside the rotor: bearing, gas friction)", v);
    case MismatchEffect::kLossScale:
      return fmt::format("losses x{:.2f} ({:+.0f} %)", v, (v - 1.0) * 100.0);
    case MismatchEffect::kUnmeasuredAmbient:
      return fmt::format(
          "boundary {:+.1f} K not seen by the ambient sensor (unmeasured ambient change)", v);
    case MismatchEffect::kSensorOffset:
      return fmt::format("sensor offset {:+.1f} K (sensor fault suspected: offset or jump)", v);
    case MismatchEffect::kSensorStuck:
      return fmt::format("sensor stuck at {:.1f} degC (sensor fault suspected)", v);
    case MismatchEffect::kSensorLag:
      return fmt::format("sensor lag {:.0f} s (not the configured one)", v);
    case MismatchEffect::kNone:
      break;
  }
  return "model mismatch, effect not named";
}

double ChiSquareQuantile(double dof, double p_upper) {
  const double z = NormalUpperQuantile(p_upper);
  const double h = 2.0 / (9.0 * dof);
  const double c = 1.0 - h + z * std::sqrt(h);
  return dof * c * c * c;
}

MismatchDetector::MismatchDetector(const ThermalModel& model, MismatchDetectorConfig config)
    : model_(model),
      config_(std::move(config)),
      sensor_model_(model, config_.measured_node, config_.sensor_lag_s, "mismatch detector"),
      discretiser_(1e-3),
      filter_(0),
      fit_disc_(1e-3) {
  const auto& c = config_;
  rotor_ = c.rotor_node.empty() ? -1 : model_.StateIndex(c.rotor_node);
  magnet_ = c.magnet_node.empty() ? -1 : model_.StateIndex(c.magnet_node);
  if (!(c.magnet_sd_K > 0.0) || !(c.magnet_period_s > 0.0)) {
    throw std::invalid_argument(
        "mismatch detector: magnet_sd_K and magnet_period_s must be positive");
  }
  if (!(c.measurement_sd_K > 0.0) || !(c.process_sd_K > 0.0) || !(c.sensor_offset_sd_K > 0.0) ||
      !(c.initial_sd_K >= 0.0) || !(c.initial_spread_sd_K > 0.0) || !(c.window_s > 0.0) ||
      !(c.false_alarm_probability > 0.0 && c.false_alarm_probability < 0.5) ||
      !(c.fit_window_s > c.window_s) || !(c.fit_onset_step_s > 0.0) || !(c.refit_period_s > 0.0) ||
      !(c.ambient_ramp_s >= 0.0) || c.stuck_samples < 2 || !(c.lag_min_ratio >= 1.0) ||
      !(c.lag_min_s > 0.0) || !(c.lag_fit_probability > 0.0 && c.lag_fit_probability < 0.5)) {
    throw std::invalid_argument(
        "mismatch detector: settings must be positive (window < fit window)");
  }
  n_ = model_.StateCount();
  // The nodes, the sensor's lag and its offset (FrameSensorModel): the offset right after them.
  sensor_model_.PlaceOffset(sensor_model_.TemperatureStates());
  frame_ = sensor_model_.node();
  lag_ = sensor_model_.lag();
  bias_ = sensor_model_.offset();
  sensor_ = sensor_model_.sensor();
  n_aug_ = bias_ + 1;
  // d f / d T_boundary: how one kelvin more on every boundary heats each node (K/s per K).
  ThermalInputs a;
  ThermalInputs b = a;
  b.ambient_degC += 1.0;
  b.coolant_degC += 1.0;
  const Eigen::VectorXd x25 = Eigen::VectorXd::Constant(n_, 25.0);
  model_.Linearise(a, x25, lin_);
  boundary_K_per_s_per_K_ = -lin_.f_K_per_s;
  model_.Linearise(b, x25, lin_);
  boundary_K_per_s_per_K_ += lin_.f_K_per_s;
  const int nb = n_aug_ - 1;
  lin_block_.a_per_s = Eigen::MatrixXd::Zero(nb, nb);
  lin_block_.f_K_per_s = Eigen::VectorXd::Zero(nb);
  sensor_model_.AddLagRow(lin_block_.a_per_s);
  ad_ = Eigen::MatrixXd::Identity(n_aug_, n_aug_);
  sp_ = Eigen::MatrixXd::Zero(n_aug_, n_aug_);
  bu_ = Eigen::VectorXd::Zero(n_aug_);
  c_ = Eigen::MatrixXd::Zero(1, n_aug_);
  sensor_model_.SetReadingRow(c_, 0);
  sm_ = Eigen::MatrixXd::Constant(1, 1, c.measurement_sd_K * c.measurement_sd_K);
  y_ = Eigen::VectorXd::Zero(1);
  x_nodes_ = Eigen::VectorXd::Zero(n_);
  filter_ = KalmanFilter(n_aug_);
  // FitLag's layout: the nodes, a lag state, the offset; each mapped to the filter's state that
  // starts it (the lag state to the sensor's state: the lag, or the node without one).
  const int nl = n_ + 2;
  fit_map_.resize(static_cast<std::size_t>(nl));
  for (int j = 0; j < n_; ++j) fit_map_[static_cast<std::size_t>(j)] = j;
  fit_map_[static_cast<std::size_t>(n_)] = sensor_;
  fit_map_[static_cast<std::size_t>(n_ + 1)] = bias_;
  fit_lag_lin_.a_per_s = Eigen::MatrixXd::Zero(n_ + 1, n_ + 1);
  fit_lag_lin_.f_K_per_s = Eigen::VectorXd::Zero(n_ + 1);
  fit_ad_ = Eigen::MatrixXd::Identity(nl, nl);
  fit_bu_ = Eigen::VectorXd::Zero(nl);
  fit_sp_ = Eigen::MatrixXd::Zero(nl, nl);
  fit_c_ = Eigen::MatrixXd::Zero(1, nl);
  fit_c_(0, n_) = fit_c_(0, n_ + 1) = 1.0;
  fit_x0_ = Eigen::VectorXd::Zero(nl);
  fit_p0_ = Eigen::MatrixXd::Zero(nl, nl);
  fit_filter_ = KalmanFilter(nl);
  Initialise(25.0, 0.0);
}

void MismatchDetector::Initialise(double x0_degC, double now_s) {
  Eigen::MatrixXd s = Eigen::MatrixXd::Zero(n_aug_, n_aug_);
  Eigen::VectorXd x = Eigen::VectorXd::Zero(n_aug_);
  sensor_model_.SetInitial(x0_degC, config_.initial_sd_K, config_.initial_spread_sd_K,
                           config_.sensor_offset_sd_K, x, s);
  filter_.Reset(x, s);
  start_s_ = now_s;
  passing_since_s_ = now_s;
  refilling_ = false;
  nis_count_ = nis_next_ = 0;
  nis_sum_ = 0.0;
  size_ = head_ = 0;
  finding_ = MismatchFinding{};
  finding_.threshold = threshold_;
}

void MismatchDetector::Linearise(const ThermalInputs& in, const Eigen::VectorXd& x_aug) {
  x_nodes_ = x_aug.head(n_);
  model_.Linearise(in, x_nodes_, lin_);
  lin_block_.a_per_s.topLeftCorner(n_, n_) = lin_.a_per_s;
  lin_block_.f_K_per_s.head(n_) = lin_.f_K_per_s;
}

const MismatchFinding& MismatchDetector::Step(const ThermalInputs& in, double dt_s,
                                              double measured_degC, double now_s,
                                              double magnet_degC) {
  // Health is data: a period, inputs or a state the model cannot take refuse the step (counted,
  // nothing changes).
  if (!(dt_s > 0.0) || !std::isfinite(dt_s) || !model_.AcceptsInputs(in) ||
      !filter_.State().allFinite()) {
    ++refused_steps_;
    return finding_;
  }
  const int window = std::max(1, static_cast<int>(std::lround(config_.window_s / dt_s)));
  if (static_cast<int>(nis_.size()) != window) {
    // Sized on the first step (and if the period ever changes): the window and history in steps.
    nis_.assign(static_cast<std::size_t>(window), 0.0);
    nis_count_ = nis_next_ = 0;
    nis_sum_ = 0.0;
    threshold_ = ChiSquareQuantile(window, config_.false_alarm_probability);
    cap_ = static_cast<int>(std::lround(config_.fit_window_s / dt_s)) + 1;
    h_in_.assign(static_cast<std::size_t>(cap_), ThermalInputs{});
    h_dt_.assign(static_cast<std::size_t>(cap_), 0.0);
    h_y_ = h_nu_ = h_s_ = h_t_ = h_m_ = h_xm_ = h_dt_;
    h_xpre_.setZero(n_aug_, cap_);
    h_k_.setZero(n_aug_, cap_);
    const int onset_step =
        std::max(1, static_cast<int>(std::lround(config_.fit_onset_step_s / dt_s)));
    const int onsets = cap_ / onset_step + window + 1;
    fit_onsets_.reserve(static_cast<std::size_t>(onsets));
    fit_e_.setZero(n_aug_, onsets * kHypotheses);
    fit_u_col_.setZero(n_aug_);
    fit_phiu_.setZero(n_aug_, kHypotheses);
    fit_frame_unit_.setZero(n_aug_);
    fit_onset_offset_K_.setZero(onsets);
    fit_a_.setZero(onsets * kHypotheses);
    fit_b_.setZero(onsets * kHypotheses);
    fit_me_.setZero(onsets * kHypotheses);
    fit_mee_.setZero(onsets * kHypotheses);
    fit_mre_.setZero(onsets * kHypotheses);
    fit_veto_.assign(static_cast<std::size_t>(onsets * kHypotheses), 0);
    size_ = head_ = 0;
  }
  const int nb = n_aug_ - 1;
  // History: the state before the step, which the naming fit linearises at.
  const int slot = head_;
  try {
    Linearise(in, filter_.State());
  } catch (const std::exception&) {
    ++refused_steps_;  // a massless sub-network singular at this operating point
    return finding_;
  }
  h_xpre_.col(slot) = filter_.State();
  discretiser_.Update(lin_block_, dt_s);
  const ThermalDiscreteModel& d = discretiser_.Current();
  ad_.topLeftCorner(nb, nb) = d.ad;
  bu_.head(nb).noalias() = d.phi_s * lin_block_.f_K_per_s;
  const double q = config_.process_sd_K * config_.process_sd_K * dt_s;
  for (int i = 0; i < n_; ++i) sp_(i, i) = q;
  filter_.Predict(ad_, bu_, sp_);

  double nu = std::numeric_limits<double>::quiet_NaN(), s_nu = 1.0;
  h_k_.col(slot).setZero();
  if (std::isfinite(measured_degC)) {
    y_(0) = measured_degC;
    const KalmanUpdateReport& r = filter_.Update(c_, y_, sm_);
    if (r.ok && r.measurements == 1) {
      nu = r.innovation(0);
      s_nu = r.innovation_var(0);
      h_k_.col(slot) = filter_.Gain().col(0);
      nis_sum_ += r.nis - nis_[static_cast<std::size_t>(nis_next_)];
      nis_[static_cast<std::size_t>(nis_next_)] = r.nis;
      nis_next_ = (nis_next_ + 1) % window;
      nis_count_ = std::min(nis_count_ + 1, window);
      if (nis_next_ == 0) {  // re-sum once per window: no drift from the running sum
        nis_sum_ = 0.0;
        for (double v : nis_) nis_sum_ += v;
      }
    }
  }
  h_in_[static_cast<std::size_t>(slot)] = in;
  h_dt_[static_cast<std::size_t>(slot)] = dt_s;
  h_y_[static_cast<std::size_t>(slot)] = measured_degC;
  h_nu_[static_cast<std::size_t>(slot)] = nu;
  h_s_[static_cast<std::size_t>(slot)] = s_nu;
  h_t_[static_cast<std::size_t>(slot)] = now_s;
  h_m_[static_cast<std::size_t>(slot)] =
      magnet_ >= 0 ? magnet_degC : std::numeric_limits<double>::quiet_NaN();
  h_xm_[static_cast<std::size_t>(slot)] = magnet_ >= 0 ? filter_.State()(magnet_) : 0.0;
  head_ = (head_ + 1) % cap_;
  size_ = std::min(size_ + 1, cap_);

  finding_.window_nis = nis_sum_;
  finding_.threshold = threshold_;
  if (refilling_) {  // a lag adopted: the verdict stands until a window of it is judged
    if (nis_count_ < window) return finding_;
    refilling_ = false;
  }
  if (now_s - start_s_ < config_.settle_s || nis_count_ < window) {
    finding_.state = MismatchState::kLearning;
    return finding_;
  }
  const bool failing = nis_sum_ > threshold_;
  const bool fault_state = finding_.state == MismatchState::kPlantChange ||
                           finding_.state == MismatchState::kSensorFaultSuspected ||
                           finding_.state == MismatchState::kUnexplained;
  if (failing) {
    passing_since_s_ = now_s;
    if (!fault_state) {
      finding_.state = MismatchState::kUnexplained;
      finding_.effect = MismatchEffect::kNone;
      finding_.value = finding_.onset_s = std::numeric_limits<double>::quiet_NaN();
      finding_.detected_s = now_s;
      last_fit_s_ = -std::numeric_limits<double>::infinity();
      int first = -1;
      if (Stuck(&first)) Fit(now_s);
    }
    const bool named = finding_.state != MismatchState::kUnexplained;
    const bool onset_in_window =
        !(now_s - finding_.onset_s > config_.fit_window_s - config_.window_s);
    const bool due = named ? now_s - last_fit_s_ >= config_.refit_period_s && onset_in_window
                           : now_s - finding_.detected_s >= config_.name_after_s;
    if (due) Fit(now_s);
  } else if (!fault_state || now_s - passing_since_s_ >= config_.clear_after_s) {
    finding_ = MismatchFinding{};
    finding_.state = MismatchState::kConsistent;
    finding_.window_nis = nis_sum_;
    finding_.threshold = threshold_;
  }
  return finding_;
}

bool MismatchDetector::AdoptSensorLag(double lag_s) {
  if (!sensor_model_.SetLag(lag_s)) return false;
  config_.sensor_lag_s = lag_s;
  sensor_model_.AddLagRow(lin_block_.a_per_s);
  // The filter as it would be had it read the history with this lag (its lag state and frame
  // were estimated with the other one), and a history that starts now: the stored gains and
  // innovations belong to the other lag, and a fit on them would name its misfit.
  if (size_ >= 2) {
    try {
      HistoryNis(lag_s, (head_ - size_ + cap_) % cap_);
      Eigen::VectorXd x = filter_.State();
      Eigen::MatrixXd p = filter_.Covariance();
      const int nl = n_ + 2;
      for (int j = 0; j < nl; ++j) {
        const int a = fit_map_[static_cast<std::size_t>(j)];
        x(a) = fit_filter_.State()(j);
        for (int k = 0; k < nl; ++k)
          p(a, fit_map_[static_cast<std::size_t>(k)]) = fit_filter_.Covariance()(j, k);
      }
      if (x.allFinite() && p.allFinite()) filter_.Reset(x, p);
    } catch (const std::exception&) {
      ++refused_steps_;  // the history met an operating point the model cannot linearise
    }
  }
  size_ = head_ = 0;
  std::fill(nis_.begin(), nis_.end(), 0.0);
  nis_count_ = nis_next_ = 0;
  nis_sum_ = 0.0;
  refilling_ = true;
  return true;
}

bool MismatchDetector::Stuck(int* first) const {
  int count = 0;
  double v = std::numeric_limits<double>::quiet_NaN();
  for (int i = 0; i < size_; ++i) {
    const int k = (head_ - 1 - i + 2 * cap_) % cap_;
    const double y = h_y_[static_cast<std::size_t>(k)];
    if (!std::isfinite(y)) continue;
    if (count == 0) v = y;
    if (y != v) break;
    ++count;
    *first = k;
  }
  return count >= config_.stuck_samples;
}

bool MismatchDetector::LinearColumn(int h) const {
  // The lag is fitted by FitLag, not as a column; the ambient ramp only when configured.
  return h != kLag && (h != kAmbientRamp || config_.ambient_ramp_s > 0.0);
}

double MismatchDetector::AmbientRamp(double since_onset_s) const {
  if (!(config_.ambient_ramp_s > 0.0)) return 0.0;
  return std::clamp(since_onset_s / config_.ambient_ramp_s, 0.0, 1.0);
}

void MismatchDetector::EffectForcing(int h, const ThermalInputs& in, const Eigen::VectorXd& x_aug,
                                     double frame_degC, Eigen::VectorXd& u) {
  u.setZero();
  switch (h) {
    case kCooling:  // heat from a relative change theta of the frame's boundary conductance
      u(frame_) = boundary_K_per_s_per_K_(frame_) * (in.ambient_degC - frame_degC);
      break;
    case kRotor:
      if (rotor_ >= 0) u(rotor_) = 1.0 / model_.Capacities_J_per_K()(rotor_);
      break;
    case kLoss: {  // the losses' share of dx/dt: (a x + f) with and without load
      x_nodes_ = x_aug.head(n_);
      model_.Linearise(in, x_nodes_, fit_lin_);
      u.head(n_).noalias() = fit_lin_.a_per_s * x_nodes_;
      u.head(n_) += fit_lin_.f_K_per_s;
      ThermalInputs idle = in;
      idle.speed_rpm = idle.id_A = idle.iq_A = 0.0;
      model_.Linearise(idle, x_nodes_, lin_zero_);
      u.head(n_).noalias() -= lin_zero_.a_per_s * x_nodes_;
      u.head(n_) -= lin_zero_.f_K_per_s;
      break;
    }
    case kAmbient:
    case kAmbientRamp:  // scaled by the ramp per onset in FitOnsets
      u.head(n_) = boundary_K_per_s_per_K_;
      break;
    default:
      break;
  }
}

void MismatchDetector::FitOnsets(int window) {
  // Every step over the last NIS window (a fault found fast started recently), every
  // fit_onset_step_s before it.
  fit_onsets_.clear();
  const int onset_step = std::max(
      1, static_cast<int>(std::lround(config_.fit_onset_step_s /
                                      h_dt_[static_cast<std::size_t>((head_ - 1 + cap_) % cap_)])));
  const int fine_from = std::max(0, size_ - window);
  for (int i = 0; i < fine_from; i += onset_step) fit_onsets_.push_back(i);
  for (int i = fine_from; i < size_; ++i) fit_onsets_.push_back(i);
}

void MismatchDetector::Fit(double now_s) {
  try {
    FitNow(now_s);
  } catch (const std::exception&) {
    ++refused_steps_;  // the history met an operating point the model cannot linearise: no name
    last_fit_s_ = now_s;
  }
}

void MismatchDetector::FitNow(double now_s) {
  last_fit_s_ = now_s;
  int stuck_first = -1;
  if (Stuck(&stuck_first)) {
    finding_.state = MismatchState::kSensorFaultSuspected;
    finding_.effect = MismatchEffect::kSensorStuck;
    finding_.value = h_y_[static_cast<std::size_t>(stuck_first)];
    finding_.onset_s = h_t_[static_cast<std::size_t>(stuck_first)];
    finding_.likelihood_ratio = std::numeric_limits<double>::quiet_NaN();
    return;
  }
  const int nb = n_aug_ - 1;
  FitOnsets(static_cast<int>(nis_.size()));
  const int onsets =
      std::min(static_cast<int>(fit_onsets_.size()), static_cast<int>(fit_e_.cols()) / kHypotheses);
  fit_e_.setZero();
  fit_a_.setZero();
  fit_b_.setZero();
  fit_me_.setZero();
  fit_mee_.setZero();
  fit_mre_.setZero();
  const int oldest = (head_ - size_ + cap_) % cap_;
  for (int o = 0; o < onsets; ++o) {
    const int k = (oldest + fit_onsets_[static_cast<std::size_t>(o)]) % cap_;
    fit_onset_offset_K_(o) = h_xpre_(bias_, k);
  }
  // The onset's time: the step before the onset's first step (its heat acts over that step).
  auto onset_t_s = [&](int o) {
    const int k = (oldest + fit_onsets_[static_cast<std::size_t>(o)]) % cap_;
    return h_t_[static_cast<std::size_t>(k)] - h_dt_[static_cast<std::size_t>(k)];
  };
  int active = 0;
  // The magnet channel: one sample per magnet_period_s, r = reading - the filter's estimate.
  const int magnet_every = std::max(
      1, static_cast<int>(std::lround(config_.magnet_period_s /
                                      h_dt_[static_cast<std::size_t>((head_ - 1 + cap_) % cap_)])));
  double magnet_sum_r = 0.0, magnet_sum_rr = 0.0;
  int magnet_samples = 0;
  std::fill(fit_veto_.begin(), fit_veto_.end(), 0);
  for (int i = 0; i < size_; ++i) {
    const int k = (oldest + i) % cap_;
    const auto ks = static_cast<std::size_t>(k);
    const ThermalInputs& in = h_in_[ks];
    fit_x_ = h_xpre_.col(k);
    Linearise(in, fit_x_);
    fit_disc_.Update(lin_block_, h_dt_[ks]);
    const ThermalDiscreteModel& d = fit_disc_.Current();
    // The frame temperature for the cooling regressor: the reading less the sensor offset the
    // filter had estimated before the onset (the low-noise filter's own frame estimate lags a
    // changed plant, and its offset state soaks up the fault after the onset: on the demo's lost
    // cooling it reached 28 K and turned the regressor's sign). Here the raw reading; each
    // onset's column adds its offset's share, fit_frame_unit_ per kelvin.
    const double y = h_y_[ks];
    const bool reading = std::isfinite(y);
    for (int h = 0; h < kHypotheses; ++h) {
      if (!LinearColumn(h)) continue;
      EffectForcing(h, in, fit_x_, reading ? y : fit_x_(frame_), fit_u_col_);
      fit_phiu_.col(h).setZero();
      fit_phiu_.col(h).head(nb).noalias() = d.phi_s * fit_u_col_.head(nb);
    }
    fit_frame_unit_.setZero();
    if (reading) {
      fit_frame_unit_.head(nb) = d.phi_s.col(frame_) * boundary_K_per_s_per_K_(frame_);
    }
    while (active < onsets && fit_onsets_[static_cast<std::size_t>(active)] <= i) ++active;
    const bool measured = std::isfinite(h_nu_[ks]);
    for (int o = 0; o < active; ++o) {
      const double ramp = AmbientRamp(h_t_[ks] - onset_t_s(o));
      for (int h = 0; h < kHypotheses; ++h) {
        if (!LinearColumn(h)) continue;
        const int col = o * kHypotheses + h;
        auto e = fit_e_.col(col);
        fit_tmp_ = e.head(nb);
        e.head(nb).noalias() = d.ad * fit_tmp_;
        e += (h == kAmbientRamp ? ramp : 1.0) * fit_phiu_.col(h);
        if (h == kCooling) e += fit_onset_offset_K_(o) * fit_frame_unit_;
        double g = e(sensor_) + e(bias_);
        if (h == kOffset) g += 1.0;
        if (!measured) continue;
        fit_a_(col) += g * h_nu_[ks] / h_s_[ks];
        fit_b_(col) += g * g / h_s_[ks];
        e.noalias() -= h_k_.col(k) * g;
      }
    }
    if (magnet_ >= 0 && i % magnet_every == 0 && std::isfinite(h_m_[ks])) {
      const double r = h_m_[ks] - h_xm_[ks];
      magnet_sum_r += r;
      magnet_sum_rr += r * r;
      ++magnet_samples;
      for (int col = 0; col < active * kHypotheses; ++col) {
        const double em = fit_e_(magnet_, col);  // after the update: truth less estimate, per unit
        fit_me_(col) += em;
        fit_mee_(col) += em * em;
        fit_mre_(col) += r * em;
      }
    }
  }
  AddMagnetChannel(onsets * kHypotheses, magnet_sum_r, magnet_sum_rr, magnet_samples);
  FitLag(oldest);
  Choose(onsets, oldest);
}

double MismatchDetector::HistoryNis(double lag_s, int oldest) {
  // The nominal filter re-run over the history with its sensor given the lag `lag_s` (states:
  // the nodes, the lag, the offset, whether or not the configuration has a lag), from the state
  // it had at the history's start and its present covariance; the lag state starts where the
  // filter's sensor state was.
  const int nl = n_ + 2;
  for (int j = 0; j < nl; ++j) {
    fit_x0_(j) = h_xpre_(fit_map_[static_cast<std::size_t>(j)], oldest);
    for (int k = 0; k < nl; ++k) {
      fit_p0_(j, k) = filter_.Covariance()(fit_map_[static_cast<std::size_t>(j)],
                                           fit_map_[static_cast<std::size_t>(k)]);
    }
  }
  fit_filter_.Reset(fit_x0_, fit_p0_);
  fit_lag_lin_.a_per_s(n_, frame_) = 1.0 / lag_s;
  fit_lag_lin_.a_per_s(n_, n_) = -1.0 / lag_s;
  double sum = 0.0;
  int readings = 0;
  for (int i = 0; i < size_; ++i) {
    const auto ks = static_cast<std::size_t>((oldest + i) % cap_);
    x_nodes_ = fit_filter_.State().head(n_);
    model_.Linearise(h_in_[ks], x_nodes_, fit_lin_);
    fit_lag_lin_.a_per_s.topLeftCorner(n_, n_) = fit_lin_.a_per_s;
    fit_lag_lin_.f_K_per_s.head(n_) = fit_lin_.f_K_per_s;
    fit_lag_disc_.Update(fit_lag_lin_, h_dt_[ks]);
    const ThermalDiscreteModel& d = fit_lag_disc_.Current();
    fit_ad_.topLeftCorner(n_ + 1, n_ + 1) = d.ad;
    fit_bu_.head(n_ + 1).noalias() = d.phi_s * fit_lag_lin_.f_K_per_s;
    const double q = config_.process_sd_K * config_.process_sd_K * h_dt_[ks];
    for (int j = 0; j < n_; ++j) fit_sp_(j, j) = q;
    fit_filter_.Predict(fit_ad_, fit_bu_, fit_sp_);
    if (!std::isfinite(h_y_[ks])) continue;
    y_(0) = h_y_[ks];
    const KalmanUpdateReport& r = fit_filter_.Update(fit_c_, y_, sm_);
    if (r.ok && r.measurements == 1) {
      sum += r.nis;
      ++readings;
    }
  }
  lag_readings_ = readings;
  return sum;
}

void MismatchDetector::FitLag(int oldest) {
  // The lag is no onset effect (a wrong lag acts on every ramp of the reading) and no small one
  // (90 s for 30 s configured is 1/tau two thirds smaller): its size is found by the lag that
  // minimises the history's NIS (golden section on log tau), and its likelihood ratio is the NIS
  // it removes, the same sum the other hypotheses' l approximates to first order.
  lag_fit_s_ = std::numeric_limits<double>::quiet_NaN();
  lag_l_ = -1.0;
  if (size_ < 2) return;
  const double tau = config_.sensor_lag_s;
  const bool configured = tau > 0.0;
  // Without a lag configured the baseline is a lag far below the step (the same reading).
  const double base = HistoryNis(configured ? tau : kNoLag_s, oldest);
  constexpr double kGolden = 0.6180339887498949;
  double lo = std::log(configured ? tau / 4.0 : kShortestLag_s);
  double hi = std::log(configured ? kMaxLagScale * tau : kLongestLag_s);
  double a = hi - kGolden * (hi - lo), b = lo + kGolden * (hi - lo);
  double fa = HistoryNis(std::exp(a), oldest), fb = HistoryNis(std::exp(b), oldest);
  for (int it = 0; it < 12; ++it) {
    if (fa <= fb) {
      hi = b;
      b = a;
      fb = fa;
      a = hi - kGolden * (hi - lo);
      fa = HistoryNis(std::exp(a), oldest);
    } else {
      lo = a;
      a = b;
      fa = fb;
      b = lo + kGolden * (hi - lo);
      fb = HistoryNis(std::exp(b), oldest);
    }
  }
  const double best = std::min(fa, fb);
  if (!std::isfinite(base) || !std::isfinite(best)) return;  // a history the filter cannot run
  lag_fit_s_ = std::exp(fa <= fb ? a : b);

  // A lag within lag_min_ratio of the configured one is the configured one: the fit is not told
  // from whatever else the model misses (a lost cooling's first minutes fit 24-39 s for 30 s).
  // Without one configured, a fitted lag below lag_min_s is none.
  const double ratio = lag_fit_s_ / tau;
  if (configured && ratio < config_.lag_min_ratio && ratio > 1.0 / config_.lag_min_ratio) return;
  if (!configured && lag_fit_s_ < config_.lag_min_s) return;
  // And the history must fit that lag as a model that holds (its NIS within the chi-square
  // quantile of its readings): a plant change present since before the history (a cooling lost
  // from the start) is fitted best by some lag too, but far from well.
  if (best > ChiSquareQuantile(std::max(lag_readings_, 1), config_.lag_fit_probability)) return;
  lag_l_ = std::max(base - best, 0.0);
}

void MismatchDetector::AddMagnetChannel(int columns, double sum_r, double sum_rr, int samples) {
  if (samples < 2) return;
  // Least squares of r = theta e + b + noise with b unknown: the sums about their means.
  const double w = 1.0 / (config_.magnet_sd_K * config_.magnet_sd_K);
  const double mean_r = sum_r / samples;
  const double rr = sum_rr - sum_r * mean_r;
  const double limit = ChiSquareQuantile(samples - 1, config_.magnet_veto_probability);
  for (int col = 0; col < columns; ++col) {
    const double re = fit_mre_(col) - mean_r * fit_me_(col);
    const double ee = fit_mee_(col) - fit_me_(col) * fit_me_(col) / samples;
    fit_a_(col) += w * re;
    fit_b_(col) += w * ee;
    if (!(fit_b_(col) > 0.0)) continue;
    // The magnet samples' residual at the size fitted on both channels.
    const double theta = fit_a_(col) / fit_b_(col);
    const double chi = w * (rr - 2.0 * theta * re + theta * theta * ee);
    fit_veto_[static_cast<std::size_t>(col)] = chi > limit ? 1 : 0;
  }
}

void MismatchDetector::Choose(int onsets, int oldest) {
  double best_per_h[kHypotheses];
  int col_per_h[kHypotheses];
  for (int h = 0; h < kHypotheses; ++h) {
    best_per_h[h] = -1.0;
    col_per_h[h] = -1;
  }
  // Columns the magnet channel contradicts are left out, unless it contradicts every one.
  bool any_kept = false;
  for (int col = 0; col < onsets * kHypotheses; ++col) {
    any_kept = any_kept || (fit_b_(col) > 0.0 && !fit_veto_[static_cast<std::size_t>(col)]);
  }
  for (int col = 0; col < onsets * kHypotheses; ++col) {
    const int h = col % kHypotheses;
    if ((h == kRotor && rotor_ < 0) || h == kLag || !(fit_b_(col) > 0.0)) continue;
    if (any_kept && fit_veto_[static_cast<std::size_t>(col)]) continue;
    const double l = fit_a_(col) * fit_a_(col) / fit_b_(col);
    if (l > best_per_h[h]) {
      best_per_h[h] = l;
      col_per_h[h] = col;
    }
  }
  if (lag_l_ > 0.0) {  // FitLag's, its onset the history's start (column kLag of onset 0)
    best_per_h[kLag] = lag_l_;
    col_per_h[kLag] = kLag;
  }
  int h = -1;
  for (int j = 0; j < kHypotheses; ++j) {
    if (col_per_h[j] >= 0 && (h < 0 || best_per_h[j] > best_per_h[h])) h = j;
  }
  if (h < 0) return;
  // The runner-up is the best of the other effects (the ambient's two forms are one effect).
  int second = -1;
  for (int j = 0; j < kHypotheses; ++j) {
    if (col_per_h[j] < 0 || EffectOf(j) == EffectOf(h)) continue;
    if (second < 0 || best_per_h[j] > best_per_h[second]) second = j;
  }
  const int best = col_per_h[h];
  const double theta = fit_b_(best) > 0.0 ? fit_a_(best) / fit_b_(best) : 0.0;
  finding_.effect = EffectOf(h);
  finding_.state = h == kOffset || h == kLag ? MismatchState::kSensorFaultSuspected
                                             : MismatchState::kPlantChange;
  finding_.likelihood_ratio = best_per_h[h];
  finding_.runner_up = second >= 0 ? EffectOf(second) : MismatchEffect::kNone;
  finding_.runner_up_ratio = second >= 0 ? best_per_h[second] : 0.0;
  const int onset = fit_onsets_[static_cast<std::size_t>(best / kHypotheses)];
  finding_.onset_s = h_t_[static_cast<std::size_t>((oldest + onset) % cap_)];
  switch (h) {
    case kCooling:
      finding_.value = 1.0 / std::max(1.0 + theta, 1.0 / kMaxResistanceScale);
      break;  // R'/R = G/G'
    case kLoss:
      finding_.value = 1.0 + theta;
      break;
    case kLag:
      finding_.value = lag_fit_s_;
      break;
    default:
      finding_.value = theta;
      break;
  }
}

}  // namespace pumptherm::estimators
