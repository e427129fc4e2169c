#include "estimators/alarms.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace pumptherm::estimators {
namespace {

bool Known(double v) { return !std::isnan(v); }

}  // namespace

const char* AlarmReasonName(AlarmReason reason) {
  switch (reason) {
    case AlarmReason::kNone:
      return "none";
    case AlarmReason::kEstimatedOverTemperature:
      return "estimated_over_temperature";
    case AlarmReason::kMeasuredOverTemperature:
      return "measured_over_temperature";
    case AlarmReason::kRateOfRise:
      return "rate_of_rise";
    case AlarmReason::kStaleTelemetry:
      return "stale_telemetry";
    case AlarmReason::kImplausibleSensor:
      return "implausible_sensor";
    case AlarmReason::kEstimatorNotConverged:
      return "estimator_not_converged";
    case AlarmReason::kForecast:
      return "forecast";
    case AlarmReason::kSensorFault:
      return "sensor_fault";
    case AlarmReason::kSafetyStateLost:
      return "safety_state_lost";
    case AlarmReason::kSecondSender:
      return "second_sender";
  }
  return "unknown";
}

const char* SensorFaultName(SensorFault fault) {
  switch (fault) {
    case SensorFault::kNone:
      return "none";
    case SensorFault::kMissing:
      return "missing";
    case SensorFault::kStuck:
      return "stuck";
    case SensorFault::kOutOfRange:
      return "out of range";
    case SensorFault::kJumping:
      return "jumping";
  }
  return "unknown";
}

const char* AlarmLevelName(AlarmLevel level) {
  switch (level) {
    case AlarmLevel::kNone:
      return "none";
    case AlarmLevel::kWarning:
      return "warning";
    case AlarmLevel::kTrip:
      return "trip";
  }
  return "unknown";
}

AlarmMonitor::AlarmMonitor(AlarmConfig config, std::vector<TemperatureLimits> limits,
                           TemperatureLimits sensor_limits)
    : config_(config), limits_(std::move(limits)), sensor_limits_(sensor_limits) {
  auto check = [](const TemperatureLimits& l, const char* what) {
    if (l.trip_degC < l.warning_degC) {
      throw std::invalid_argument(std::string(what) + ": trip level below warning level");
    }
  };
  for (const auto& l : limits_) check(l, "node limits");
  check(sensor_limits_, "sensor limits");
  if (!(config_.hysteresis_K >= 0.0) || !(config_.hold_s >= 0.0) ||
      !(config_.rate_window_s > 0.0) || !(config_.forecast_clear_s >= 0.0) ||
      !(config_.sensor_fault_clear_s >= 0.0)) {
    throw std::invalid_argument(
        "alarm config: hysteresis, hold and clear delays must be >= 0, window > 0");
  }
  over_.resize(limits_.size());
  rise_.resize(limits_.size());
  window_start_degC_.assign(limits_.size(), std::nan(""));
  window_start_s_.assign(limits_.size(), 0.0);
  rise_K_per_min_.assign(limits_.size(), std::nan(""));
}

void AlarmMonitor::Update(Channel& ch, AlarmLevel want, double value, double now_s, double hold_s,
                          double clear_hold_s) {
  if (clear_hold_s < 0.0) clear_hold_s = hold_s;
  if (ch.latched && want < AlarmLevel::kTrip) want = AlarmLevel::kTrip;
  // A trip cleared while its condition is still there latches again at once.
  if (want == AlarmLevel::kTrip && ch.level == AlarmLevel::kTrip) ch.latched = true;
  // Each level's hold counts the time spent in its band or above, so a value moving between
  // the warning and the trip band keeps the warning's hold running.
  for (const AlarmLevel band : {AlarmLevel::kWarning, AlarmLevel::kTrip}) {
    double& since = ch.band_since_s[static_cast<std::size_t>(band)];
    if (want < band) {
      since = std::nan("");
    } else if (std::isnan(since)) {
      since = now_s;
    }
  }
  AlarmLevel reached = ch.level;
  for (const AlarmLevel band : {AlarmLevel::kWarning, AlarmLevel::kTrip}) {
    const double since = ch.band_since_s[static_cast<std::size_t>(band)];
    if (band > reached && !std::isnan(since) && now_s - since >= hold_s) reached = band;
  }
  if (reached > ch.level) {
    ch.level = reached;
    ch.below_since_s = std::nan("");
    ch.value = value;
    ch.raised_at_s = now_s;
    if (reached == AlarmLevel::kTrip) ch.latched = true;
    return;
  }
  if (want >= ch.level) {
    ch.below_since_s = std::nan("");
    return;
  }
  if (std::isnan(ch.below_since_s)) ch.below_since_s = now_s;
  if (now_s - ch.below_since_s >= clear_hold_s) {
    ch.level = want;
    ch.below_since_s = std::nan("");
  }
}

AlarmLevel AlarmMonitor::OverLevel(const Channel& ch, double w, double t,
                                   const TemperatureLimits& lim) const {
  if (std::isnan(t) || std::isnan(w)) return ch.level;
  const double h = config_.hysteresis_K;
  if (t >= lim.trip_degC) return AlarmLevel::kTrip;
  if (ch.level == AlarmLevel::kTrip && t > lim.trip_degC - h) return AlarmLevel::kTrip;
  if (w >= lim.warning_degC) return AlarmLevel::kWarning;
  if (ch.level >= AlarmLevel::kWarning && w > lim.warning_degC - h) return AlarmLevel::kWarning;
  return AlarmLevel::kNone;
}

namespace {

/// mean + k sd; an unknown sd counts as 0 (the mean alone).
double UpperBound(double mean_degC, const double* sd_K, std::size_t i, double k) {
  const double sd = sd_K != nullptr && std::isfinite(sd_K[i]) ? sd_K[i] : 0.0;
  return mean_degC + k * sd;
}

}  // namespace

const AlarmState& AlarmMonitor::Step(double now_s, const AlarmInputs& in) {
  if (std::isnan(start_s_)) start_s_ = now_s;
  const double hold = config_.hold_s;

  for (std::size_t i = 0; i < limits_.size(); ++i) {
    const double t = in.node_degC ? in.node_degC[i] : std::nan("");
    // NaN: not known now; the channel and its pending holds stay as they are.
    if (Known(t)) {
      const double w = UpperBound(t, in.node_sd_K, i, config_.warning_sd_factor);
      const double u = UpperBound(t, in.node_sd_K, i, config_.trip_sd_factor);
      const AlarmLevel before = over_[i].level;
      Update(over_[i], OverLevel(over_[i], w, u, limits_[i]), t, now_s, hold);
      if (over_[i].level > before) over_[i].bound = over_[i].level == AlarmLevel::kTrip ? u : w;
    }
    // Rate of rise over consecutive windows of rate_window_s.
    if (Known(t)) {
      if (std::isnan(window_start_degC_[i])) {
        window_start_degC_[i] = t;
        window_start_s_[i] = now_s;
      } else if (now_s - window_start_s_[i] >= config_.rate_window_s) {
        rise_K_per_min_[i] = (t - window_start_degC_[i]) / (now_s - window_start_s_[i]) * 60.0;
        window_start_degC_[i] = t;
        window_start_s_[i] = now_s;
      }
    }
    const double r = rise_K_per_min_[i];
    if (Known(r)) {
      const bool over = r > config_.max_rise_K_per_min;
      const bool still =
          rise_[i].level != AlarmLevel::kNone && r > 0.8 * config_.max_rise_K_per_min;
      Update(rise_[i], (over || still) ? AlarmLevel::kWarning : AlarmLevel::kNone, r, now_s, 0.0);
    }
  }

  if (Known(in.sensor_degC)) {
    Update(sensor_over_, OverLevel(sensor_over_, in.sensor_degC, in.sensor_degC, sensor_limits_),
           in.sensor_degC, now_s, hold);
  }
  Update(stale_,
         in.telemetry_age_s > config_.stale_after_s ? AlarmLevel::kWarning : AlarmLevel::kNone,
         in.telemetry_age_s, now_s, hold);
  StepSensor(now_s, in);
  const bool not_converged =
      !in.estimators_converged && now_s - start_s_ >= config_.not_converged_grace_s;
  Update(converged_, not_converged ? AlarmLevel::kWarning : AlarmLevel::kNone, 0.0, now_s, hold);

  {
    const double ttt = in.time_to_trip_s;
    AlarmLevel want = AlarmLevel::kNone;
    if (ttt < config_.forecast_horizon_s) want = AlarmLevel::kWarning;
    if (forecast_.level != AlarmLevel::kNone && ttt < 1.1 * config_.forecast_horizon_s) {
      want = AlarmLevel::kWarning;
    }
    if (Known(ttt)) Update(forecast_, want, ttt, now_s, hold, config_.forecast_clear_s);
    if (forecast_.level != AlarmLevel::kNone && in.time_to_trip_node >= 0)
      forecast_node_ = in.time_to_trip_node;
  }
  if (second_sender_.level != AlarmLevel::kNone &&
      !(now_s - second_sender_last_s_ < config_.second_sender_clear_s)) {
    second_sender_.level = AlarmLevel::kNone;
  }

  Compose(in.time_to_trip_s);
  return state_;
}

void AlarmMonitor::StepSensor(double now_s, const AlarmInputs& in) {
  // A failed sensor, found by SensorHealth without trusting its readings.
  if (in.sensor_fault != SensorFault::kNone && sensor_fault_.level == AlarmLevel::kNone) {
    sensor_fault_kind_ = in.sensor_fault;
  }
  Update(sensor_fault_,
         in.sensor_fault != SensorFault::kNone ? AlarmLevel::kWarning : AlarmLevel::kNone,
         in.sensor_raw_degC, now_s, config_.hold_s, config_.sensor_fault_clear_s);
  // Stuck while the model moves: the same raw reading while the estimate of that node (free of
  // the sensor once SensorHealth has left it out) moves.
  const double raw = in.sensor_raw_degC;
  if (Known(raw)) {
    if (raw != stuck_value_) {
      stuck_value_ = raw;
      stuck_since_s_ = now_s;
      stuck_model_min_ = stuck_model_max_ = in.sensor_model_degC;
    } else if (Known(in.sensor_model_degC)) {
      if (std::isnan(stuck_model_min_)) stuck_model_min_ = stuck_model_max_ = in.sensor_model_degC;
      stuck_model_min_ = std::min(stuck_model_min_, in.sensor_model_degC);
      stuck_model_max_ = std::max(stuck_model_max_, in.sensor_model_degC);
    }
    const bool stuck = now_s - stuck_since_s_ >= config_.stuck_after_s &&
                       stuck_model_max_ - stuck_model_min_ > config_.stuck_model_move_K;
    Update(stuck_, stuck ? AlarmLevel::kWarning : AlarmLevel::kNone, raw, now_s, config_.hold_s);
  }
  if (Known(in.sensor_nis)) {
    Update(disagree_, in.sensor_nis > config_.nis_limit ? AlarmLevel::kWarning : AlarmLevel::kNone,
           in.sensor_nis, now_s, config_.disagree_hold_s);
  }
  if (Known(in.sensor_offset_K) && config_.max_sensor_offset_K > 0.0) {
    const bool off = std::abs(in.sensor_offset_K) > config_.max_sensor_offset_K;
    Update(offset_, off ? AlarmLevel::kWarning : AlarmLevel::kNone, in.sensor_offset_K, now_s,
           config_.hold_s);
  }
}

void AlarmMonitor::Compose(double time_to_trip_s) {
  // Publish the most severe alarm; among equals the one raised first (and among those the first
  // in ActiveConditions' order): the first of ActiveConditions(), found without allocating.
  AlarmState st;
  st.time_to_trip_s = time_to_trip_s;
  double best_raised_s = 0.0;
  ForEachActive([&](const Channel& ch, AlarmReason reason, const char*, int node, double) {
    st.active_reasons |= static_cast<std::uint16_t>(1U << static_cast<unsigned>(reason));
    if (ch.level > st.level || (ch.level == st.level && ch.raised_at_s < best_raised_s)) {
      st.level = ch.level;
      st.reason = reason;
      st.node = node;
      st.value = ch.value;
      st.bound = ch.bound;
      best_raised_s = ch.raised_at_s;
    }
  });
  st.trip_latched = sensor_over_.latched || state_lost_.latched;
  for (const auto& ch : over_) st.trip_latched = st.trip_latched || ch.latched;
  state_ = st;
}

std::vector<AlarmMonitor::LatchedTrip> AlarmMonitor::LatchedTrips() const {
  std::vector<LatchedTrip> out;
  for (std::size_t i = 0; i < over_.size(); ++i) {
    if (over_[i].latched) out.push_back({static_cast<int>(i), over_[i].value});
  }
  if (sensor_over_.latched) out.push_back({kSensorTrip, sensor_over_.value});
  if (state_lost_.latched) out.push_back({kStateLostTrip, 0.0});
  return out;
}

bool AlarmMonitor::RestoreLatchedTrip(const LatchedTrip& trip, double now_s) {
  if (trip.node == kStateLostTrip) {
    LatchStateLost(now_s);
    return true;
  }
  if (!std::isfinite(trip.value) || trip.node < kSensorTrip ||
      trip.node >= static_cast<int>(over_.size())) {
    return false;
  }
  Channel& ch =
      trip.node == kSensorTrip ? sensor_over_ : over_[static_cast<std::size_t>(trip.node)];
  ch.level = AlarmLevel::kTrip;
  ch.band_since_s.fill(std::nan(""));
  ch.below_since_s = std::nan("");
  ch.value = trip.value;
  ch.bound = std::nan("");
  ch.raised_at_s = now_s;
  ch.latched = true;
  Compose(state_.time_to_trip_s);
  return true;
}

template <typename F>
void AlarmMonitor::ForEachActive(F&& f) const {
  auto add = [&](const Channel& ch, AlarmReason reason, const char* detail, int node,
                 double threshold) {
    if (ch.level != AlarmLevel::kNone) f(ch, reason, detail, node, threshold);
  };
  for (std::size_t i = 0; i < over_.size(); ++i) {
    const auto& l = limits_[i];
    add(over_[i], AlarmReason::kEstimatedOverTemperature, "", static_cast<int>(i),
        over_[i].level == AlarmLevel::kTrip ? l.trip_degC : l.warning_degC);
  }
  add(sensor_over_, AlarmReason::kMeasuredOverTemperature, "", config_.sensor_node,
      sensor_over_.level == AlarmLevel::kTrip ? sensor_limits_.trip_degC
                                              : sensor_limits_.warning_degC);
  for (std::size_t i = 0; i < rise_.size(); ++i) {
    add(rise_[i], AlarmReason::kRateOfRise, "", static_cast<int>(i), std::nan(""));
  }
  add(stale_, AlarmReason::kStaleTelemetry, "", -1, std::nan(""));
  add(sensor_fault_, AlarmReason::kSensorFault, SensorFaultName(sensor_fault_kind_),
      config_.sensor_node, std::nan(""));
  add(stuck_, AlarmReason::kImplausibleSensor, "stuck", config_.sensor_node, std::nan(""));
  add(disagree_, AlarmReason::kImplausibleSensor, "disagrees with the model", config_.sensor_node,
      std::nan(""));
  add(offset_, AlarmReason::kImplausibleSensor, "offset", config_.sensor_node, std::nan(""));
  add(converged_, AlarmReason::kEstimatorNotConverged, "", -1, std::nan(""));
  add(forecast_, AlarmReason::kForecast, "", forecast_node_, std::nan(""));
  add(state_lost_, AlarmReason::kSafetyStateLost, "", -1, std::nan(""));
  add(second_sender_, AlarmReason::kSecondSender, "", -1, std::nan(""));
}

std::vector<AlarmCondition> AlarmMonitor::ActiveConditions() const {
  std::vector<AlarmCondition> out;
  ActiveConditions(out);
  return out;
}

void AlarmMonitor::ActiveConditions(std::vector<AlarmCondition>& out) const {
  out.clear();
  ForEachActive(
      [&](const Channel& ch, AlarmReason reason, const char* detail, int node, double threshold) {
        out.push_back(
            {ch.level, reason, detail, node, ch.value, threshold, ch.raised_at_s, ch.latched});
      });
  // Most severe first; among equals the one raised first. Insertion sort: stable, and unlike
  // std::stable_sort it needs no temporary buffer (a handful of conditions at most).
  auto before = [](const AlarmCondition& a, const AlarmCondition& b) {
    if (a.level != b.level) return a.level > b.level;
    return a.raised_at_s < b.raised_at_s;
  };
  for (std::size_t i = 1; i < out.size(); ++i) {
    const AlarmCondition c = out[i];
    std::size_t j = i;
    for (; j > 0 && before(c, out[j - 1]); --j) out[j] = out[j - 1];
    out[j] = c;
  }
}

bool AlarmMonitor::Clear() {
  bool any = false;
  auto clear = [&](Channel& ch) {
    any = any || ch.latched;
    ch.latched = false;
  };
  for (auto& ch : over_) clear(ch);
  clear(sensor_over_);
  clear(state_lost_);
  state_lost_.level = AlarmLevel::kNone;  // no condition keeps it: it goes with its latch
  Compose(state_.time_to_trip_s);
  return any;
}

bool AlarmMonitor::Clear(int node) {
  Channel* ch = node == kSensorTrip      ? &sensor_over_
                : node == kStateLostTrip ? &state_lost_
                : node >= 0 && node < static_cast<int>(over_.size())
                    ? &over_[static_cast<std::size_t>(node)]
                    : nullptr;
  if (ch == nullptr || !ch->latched) return false;
  ch->latched = false;
  if (ch == &state_lost_) ch->level = AlarmLevel::kNone;
  Compose(state_.time_to_trip_s);
  return true;
}

void AlarmMonitor::LatchStateLost(double now_s) {
  state_lost_.level = AlarmLevel::kTrip;
  state_lost_.value = std::nan("");
  state_lost_.raised_at_s = now_s;
  state_lost_.latched = true;
  Compose(state_.time_to_trip_s);
}

void AlarmMonitor::RaiseSecondSender(double now_s) {
  second_sender_last_s_ = now_s;
  if (second_sender_.level != AlarmLevel::kNone) return;
  second_sender_.level = AlarmLevel::kWarning;
  second_sender_.value = std::nan("");
  second_sender_.raised_at_s = now_s;
  Compose(state_.time_to_trip_s);
}

SensorHealth::SensorHealth(const AlarmConfig& config) : config_(config) {}

void SensorHealth::OnReading(double t_s, double value_degC) {
  if (std::isnan(value_degC)) return;
  // A step between consecutive readings (not across a silence, in which it may have warmed).
  const bool consecutive = Known(last_s_) && t_s - last_s_ <= config_.stale_after_s;
  if (consecutive && std::abs(value_degC - last_degC_) > config_.max_step_K) {
    jump_until_s_ = t_s + config_.jump_recover_s;
  }
  if (value_degC != last_degC_) changed_s_ = t_s;
  last_degC_ = value_degC;
  last_s_ = t_s;
}

SensorFault SensorHealth::Fault(double now_s) const {
  if (std::isnan(last_s_) || now_s - last_s_ > config_.stale_after_s) return SensorFault::kMissing;
  if (last_degC_ < config_.sensor_min_degC || last_degC_ > config_.sensor_max_degC) {
    return SensorFault::kOutOfRange;
  }
  if (now_s < jump_until_s_) return SensorFault::kJumping;
  if (config_.flat_after_s > 0.0 && now_s - changed_s_ >= config_.flat_after_s)
    return SensorFault::kStuck;
  return SensorFault::kNone;
}

}  // namespace pumptherm::estimators
